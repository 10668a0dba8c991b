"""The fast path of robofmu's export library (``robofmu_fmi2.c``, point 4 of its header comment):
fmi2SetReal of inputs, fmi2GetReal, fmi2GetBoolean and fmi2DoStep of an initialized robofmu
slave are served by robofmu's C library through the FMI functions, without pythonfmu's per-call
Python lists, and give exactly what the forwarded path gives.

Every FMU is driven through fmpy's FMU2Slave with the raw FMI functions (statuses as returned,
messages recorded by the test's own logger, loggingOn false unless said). A *twin* is the same
FMU instantiated with ``ROBOFMU_FMI_FAST_PATH=0``: the slave does not register and every call
goes to pythonfmu as before the fast path existed; both are driven with the same calls and
compared bit for bit, statuses and messages included.
"""
from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description

from robofmu.components.fmi.base import BlockSlave
from robofmu.components.robots import available
from robofmu.system import experiment
from robofmu.system.master import Master
from robofmu.system.studies.replica import InProcessDiagram

from fmu_util import ERROR, H, OK, RawInstance, robot_blocks

fmi2LastSuccessfulTime, fmi2Terminated = 2, 3       # fmi2StatusKind

HOT = robot_blocks(kinds=("controller", "plant"))
WITH_BOOLEANS = robot_blocks(kinds=("ik",)) + robot_blocks(kinds=("trajectory", "controller", "plant"),
                                                           robots=["chess"])


@pytest.fixture
def raw(raw_instances):
    """Instances with the fast path on (default) or off (``fast=False``)."""
    def open_(path, name="block", fast=True, **kwargs):
        instance = raw_instances(path, name, fast=fast, **kwargs)
        assert instance.component, instance.messages
        return instance
    return open_


def bits(values) -> np.ndarray:
    """The IEEE 754 bit patterns: equal means bit-identical (-0.0, NaN payloads included)."""
    return np.asarray(values, dtype=np.float64).view(np.uint64)


def frames_dropped(messages) -> list:
    """The messages with a traceback's frames left out (its first and last line kept): the two
    paths reach the block's code through different wrapper frames."""
    kept = []
    for status, category, message in messages:
        head, mark, trace = message.partition("Traceback (most recent call last):")
        lines = trace.strip().splitlines()
        kept.append((status, category, head + mark + (lines[-1] if lines else "")))
    return kept


def starts(r: RawInstance, names) -> np.ndarray:
    return np.array([float(r.variables[n].start) for n in names])


# -- on, and off when it should be -------------------------------------------------------------
@pytest.mark.parametrize("robot, block", HOT)
def test_the_fast_path_serves_the_hot_calls_once_initialized(fmu_root, raw, robot, block):
    r = raw(fmu_root / robot / f"{block}.fmu")
    assert r.fast_path
    inputs, reals = r.names("Real", "input"), r.names("Real")
    assert r.call("fmi2SetupExperiment", 0, 0.0, 0.0, 0, 0.0) == OK
    assert r.call("fmi2EnterInitializationMode") == OK
    assert r.get_real(reals)[0] == OK                       # initialization mode: pythonfmu's
    assert r.call("fmi2ExitInitializationMode") == OK
    assert r.fast_calls == 0
    for k in range(5):
        assert r.set_real(inputs, starts(r, inputs)) == OK
        assert r.get_real(reals)[0] == OK
        assert r.step(k * H) == OK
    assert r.fast_calls == 15
    parameter = r.names("Real", "parameter")[0]
    assert r.get_real([parameter])[0] == OK                 # a Real parameter: read on the fast path too
    assert r.fast_calls == 16
    assert r.call("fmi2Terminate") == OK
    assert r.get_real(reals)[0] == OK and r.set_real(inputs, starts(r, inputs)) == OK     # pythonfmu's
    assert r.fast_calls == 16
    # the only message: a plant driven by its start inputs alone (no torque) may leave its limits
    assert [m for m in r.messages if " limit " not in m[2] or block != "plant"] == []


def test_the_fast_path_can_be_switched_off_and_a_slave_outside_a_fmu_has_none(fmu_root, raw):
    assert not raw(fmu_root / "chess" / "plant.fmu", fast=False).fast_path
    cls = type("robofmu_chess_plant", (BlockSlave,), {"robot_name": "chess", "block_kind": "plant"})
    slave = cls(instance_name="plant")
    assert not slave.fast_path
    slave.setup_experiment(0.0)
    slave.enter_initialization_mode()
    slave.exit_initialization_mode()
    assert slave.do_step(0.0, H) and slave._dirty and slave._inputs_checked      # found finite


# -- the same results as the forwarded path --------------------------------------------------------
@pytest.mark.parametrize("robot, block", HOT + robot_blocks(kinds=("ik",)))
def test_set_get_round_trip_is_exact(fmu_root, raw, robot, block, rng):
    r = raw(fmu_root / robot / f"{block}.fmu")
    assert r.initialize() == OK, r.messages
    inputs = r.names("Real", "input")
    values = starts(r, inputs) * (1 + 1e-3 * rng.standard_normal(len(inputs)))
    values[0] = -0.0
    if len(values) > 1:
        values[1] = 5e-324                                   # subnormal
    assert r.set_real(inputs, values) == OK
    status, back = r.get_real(inputs)
    assert status == OK
    np.testing.assert_array_equal(bits(back), bits(values))
    reversed_inputs = inputs[::-1]                           # any order, any subset, repeated
    status, back = r.get_real(reversed_inputs + inputs[:1])
    np.testing.assert_array_equal(bits(back), bits(list(values[::-1]) + [values[0]]))
    assert r.fast_calls == 3


@pytest.mark.filterwarnings("error::RuntimeWarning")    # an overflow is the FMU's message, not the host's warning
@pytest.mark.parametrize("robot, block", HOT + robot_blocks(kinds=("ik",)))
def test_a_twin_without_the_fast_path_gives_the_same_bits_statuses_and_messages(fmu_root, raw, robot, block, rng):
    path = fmu_root / robot / f"{block}.fmu"
    fast, slow = raw(path, fast=True), raw(path, fast=False)
    assert fast.fast_path and not slow.fast_path
    for r in (fast, slow):
        assert r.initialize() == OK, r.messages
    inputs, reals, booleans = fast.names("Real", "input"), fast.names("Real"), fast.names("Boolean")
    base = starts(fast, inputs)
    t = 0.0
    for k in range(40):
        values = base + 1e-2 * rng.standard_normal(len(inputs))
        if k == 10:
            values[-1] = float("nan")                        # held outputs, then a refused step
        if k == 20:
            values[0] = 1e308                                # an output that would not be finite
        results = []
        for r in (fast, slow):
            got = [r.set_real(inputs, values), r.get_real(reals)]
            if booleans:
                got.append(r.get_boolean(booleans))
            got.append(r.step(t))
            got.append(r.get_real(reals))
            results.append(got)
        (fs, fget, *frest), (ss, sget, *srest) = results
        assert fs == ss == OK
        assert fget[0] == sget[0] and np.array_equal(bits(fget[1]), bits(sget[1])), k
        assert frest[-2] == srest[-2], k                     # the step's status
        assert frest[-1][0] == srest[-1][0] and np.array_equal(bits(frest[-1][1]), bits(srest[-1][1])), k
        if booleans:
            assert frest[0] == srest[0], k
        if frest[-2] == OK:
            t += H
    assert frames_dropped(fast.messages) == frames_dropped(slow.messages)
    assert any(s == "ERROR" and "is not finite; step refused" in m for s, _, m in fast.messages)
    if block == "controller":       # found by the library's check of the outputs: held, reported
        assert any(s == "ERROR" and "would be" in m and "outputs held" in m for s, _, m in fast.messages)
    assert fast.real_status(fmi2LastSuccessfulTime) == slow.real_status(fmi2LastSuccessfulTime)
    assert fast.boolean_status(fmi2Terminated) == slow.boolean_status(fmi2Terminated) == (OK, 1)
    assert fast.fast_calls > 150 and slow.fast_calls == 0


def slave_of(name: str) -> BlockSlave:
    """The slave a robofmu FMU instantiated in this process under ``name`` (one interpreter)."""
    import gc
    (slave,) = [o for o in gc.get_objects() if isinstance(o, BlockSlave) and o.instance_name == name]
    return slave


@pytest.mark.parametrize("failure", ["raises", "not finite"])
def test_a_block_without_feedthrough_whose_outputs_fail_after_its_step_reports_as_its_twin(fmu_root, raw, failure):
    """The plant (no feedthrough) computes its outputs at t + h inside its fast step; when that
    raises or gives a non-finite output, the saved outputs come back and the read that follows
    evaluates and reports them: the same statuses, values and messages as the twin, which
    evaluates them only at the read. Then both recover alike."""
    path = fmu_root / "rrp" / "plant.fmu"
    names = {True: f"fast {failure}", False: f"slow {failure}"}
    fast, slow = raw(path, names[True], fast=True), raw(path, names[False], fast=False)
    for r in (fast, slow):
        assert r.initialize() == OK, r.messages
    inputs, reals = fast.names("Real", "input"), fast.names("Real")
    values = starts(fast, inputs) + 0.5
    slaves = {id(fast): slave_of(names[True]), id(slow): slave_of(names[False])}
    originals = {}

    def broken(slave):
        original = slave.logic.output

        def output(t):
            if failure == "raises":
                raise RuntimeError("the model broke")
            original(t)
            slave.values[slave._output_slots[0]] = float("nan")
        return original, output

    results = {id(fast): [], id(slow): []}
    t = {id(fast): 0.0, id(slow): 0.0}
    for k in range(7):
        for r in (fast, slow):
            slave = slaves[id(r)]
            if k == 2:
                originals[id(r)], output = broken(slave)
                slave.logic.output, slave._output_now = output, output
            if k == 4:
                slave.logic.output = slave._output_now = originals[id(r)]
                del slave.logic.output                         # the class's method again
            got = [r.set_real(inputs, values), r.step(t[id(r)])]
            t[id(r)] += H if got[1] == OK else 0.0
            status, read = r.get_real(reals)
            results[id(r)].append((got, status, bits(read)))
    for (fgot, fstatus, fbits), (sgot, sstatus, sbits) in zip(results[id(fast)], results[id(slow)]):
        assert fgot == sgot and fstatus == sstatus and np.array_equal(fbits, sbits)
    unnamed = lambda r, who: [(st, c, m.replace(names[who], "plant")) for st, c, m in frames_dropped(r.messages)]
    assert unnamed(fast, True) == unnamed(slow, False)
    said = "the model broke" if failure == "raises" else "not finite"
    assert any(s == "ERROR" and said in m for s, _, m in fast.messages), fast.messages
    steps = [got[1] for got, _, _ in results[id(fast)]]
    assert steps[:2] == [OK, OK] and ERROR in steps[2:4] and steps[-1] == OK, steps     # refused, then recovered
    assert fast.fast_calls > 0 and slow.fast_calls == 0


@pytest.mark.parametrize("robot, block", WITH_BOOLEANS)
def test_a_boolean_get(fmu_root, raw, robot, block):
    r = raw(fmu_root / robot / f"{block}.fmu")
    assert r.initialize() == OK, r.messages
    booleans = r.names("Boolean")
    status, values = r.get_boolean(booleans)
    assert status == OK and r.fast_calls == 1
    assert all(value in (0, 1) for value in values)
    settable = r.names("Boolean", "input")
    if settable:                                             # set through pythonfmu, read fast
        for v in (1, 0, 1):
            assert r.set_boolean(settable, [v] * len(settable)) == OK
            assert r.get_boolean(settable) == (OK, [v] * len(settable))
    reachable = [n for n in booleans if n == "reachable"]
    if reachable:                                            # the IK's start pose is reachable
        assert r.get_boolean(reachable) == (OK, [1])
    status, _ = r.get_boolean(booleans + r.names("Real")[:1])     # a Real among them: pythonfmu's
    assert status == ERROR
    assert "do not name Boolean variables" in r.texts("ERROR")[-1]


# -- what still fails, and how ------------------------------------------------------------------------
@pytest.mark.parametrize("robot, block", HOT)
def test_set_real_of_an_output_or_a_boolean_fails_naming_the_variable(fmu_root, raw, robot, block):
    r = raw(fmu_root / robot / f"{block}.fmu")
    assert r.initialize() == OK, r.messages
    inputs, output = r.names("Real", "input"), r.names("Real", "output")[0]
    before = r.get_real(inputs)[1]
    assert r.set_real([inputs[0], output], [1.25, 2.5]) == ERROR
    assert f"fmi2SetReal: value references of ['{output}'] do not name Real inputs" in r.texts("ERROR")[-1]
    np.testing.assert_array_equal(r.get_real(inputs)[1], before)          # nothing written
    parameter = r.names("Real", "parameter")[0]
    assert r.set_real([parameter], [1.0]) == ERROR
    assert f"'{parameter}'" in r.texts("ERROR")[-1]
    booleans = r.names("Boolean")
    if booleans:
        assert r.set_real([booleans[0]], [1.0]) == ERROR
        assert f"'{booleans[0]}'" in r.texts("ERROR")[-1]
    out_of_range = (ctypes.c_uint * 1)(len(r.variables) + 7)
    assert r.call("fmi2SetReal", out_of_range, 1, (ctypes.c_double * 1)(0.0)) == ERROR
    assert f"[{len(r.variables) + 7}]" in r.texts("ERROR")[-1]
    assert r.call("fmi2GetReal", out_of_range, 1, (ctypes.c_double * 1)()) == ERROR
    assert r.set_real(inputs, before) == OK and r.step(0.0) == OK         # still usable
    assert r.fast_calls == 4 and all(s == "ERROR" for s, _, _ in r.messages)


@pytest.mark.parametrize("robot, block", HOT)
def test_a_non_finite_input_fails_the_next_step_with_its_message_logging_off(fmu_root, raw, robot, block):
    r = raw(fmu_root / robot / f"{block}.fmu", logging_on=False)
    assert r.initialize() == OK, r.messages
    inputs = r.names("Real", "input")
    values = starts(r, inputs)
    assert r.step(0.0) == OK
    values[-1] = float("inf")
    assert r.set_real(inputs, values) == OK
    assert r.messages == []
    assert r.step(H) == ERROR
    assert r.messages[-1][0] == "ERROR" and r.messages[-1][1] == "logStatusError"
    assert f"input {inputs[-1]} = inf at t = 0.001 s is not finite; step refused" in r.messages[-1][2]
    assert r.real_status(fmi2LastSuccessfulTime) == (OK, H)
    assert r.boolean_status(fmi2Terminated) == (OK, 1)
    status, _ = r.get_real(r.names("Real", "output"))       # outputs held, one warning
    assert status == OK and r.messages[-1][0] == "WARNING" and "outputs held" in r.messages[-1][2]
    values[-1] = starts(r, inputs)[-1]
    assert r.set_real(inputs, values) == OK and r.step(H) == OK           # usable again
    assert r.real_status(fmi2LastSuccessfulTime) == (OK, 2 * H)
    assert r.fast_calls == 6


def test_reset_constructs_the_slave_anew_and_it_registers_again(fmu_root, raw):
    path = fmu_root / "chess" / "controller.fmu"
    r, fresh = raw(path), raw(path)
    inputs, outputs = r.names("Real", "input"), r.names("Real", "output")
    values = starts(r, inputs) * 1.01

    def run(instance):
        instance.initialize()
        for k in range(5):
            assert instance.set_real(inputs, values) == OK and instance.step(k * H) == OK
        return instance.get_real(outputs)

    first = run(r)
    assert r.call("fmi2Reset") == OK
    assert r.fast_path
    calls = r.fast_calls
    again = run(r)
    assert r.fast_calls == calls + 11
    assert again[0] == OK and np.array_equal(bits(again[1]), bits(first[1]))
    assert np.array_equal(bits(run(fresh)[1]), bits(first[1]))
    assert r.messages == []


# -- FMU state ------------------------------------------------------------------------------------
@pytest.mark.parametrize("robot, block", HOT)
@pytest.mark.parametrize("serialized", [False, True], ids=["state", "serialized"])
def test_state_restore_then_the_same_steps_give_the_same_bits(fmu_root, raw, robot, block, serialized, rng):
    r = raw(fmu_root / robot / f"{block}.fmu")
    assert r.initialize() == OK, r.messages
    inputs, reals = r.names("Real", "input"), r.names("Real")
    base = starts(r, inputs)
    series = [base + 1e-2 * rng.standard_normal(len(inputs)) for _ in range(12)]
    for k in range(5):
        assert r.set_real(inputs, series[k]) == OK and r.step(k * H) == OK
    assert r.set_real(inputs, series[5]) == OK                           # saved with stale outputs
    state = ctypes.c_void_p()
    assert r.call("fmi2GetFMUstate", ctypes.byref(state)) == OK
    if serialized:
        size = ctypes.c_size_t()
        assert r.call("fmi2SerializedFMUstateSize", state, ctypes.byref(size)) == OK
        data = (ctypes.c_char * size.value)()
        assert r.call("fmi2SerializeFMUstate", state, data, size) == OK
        assert r.call("fmi2FreeFMUstate", ctypes.byref(state)) == OK
        state = ctypes.c_void_p()
        assert r.call("fmi2DeSerializeFMUstate", data, size, ctypes.byref(state)) == OK

    def run():
        out = []
        for k in range(5, 12):
            if k > 5:
                assert r.set_real(inputs, series[k]) == OK
            status, values = r.get_real(reals)
            assert status == OK
            out.append(values)
            assert r.step(k * H) == OK
        out.append(r.get_real(reals)[1])
        return np.array(out)

    first = run()
    assert r.call("fmi2SetFMUstate", state) == OK
    again = run()
    np.testing.assert_array_equal(bits(again), bits(first))
    assert r.call("fmi2FreeFMUstate", ctypes.byref(state)) == OK
    assert r.fast_calls == 5 * 2 + 1 + 2 * (2 + 6 * 3 + 1)      # FMU state calls: pythonfmu's
    # the only message: a plant driven by test inputs may leave its limits (rrp's home is on one)
    assert [m for m in r.messages if " limit " not in m[2] or block != "plant"] == []


# -- a host that is not Python --------------------------------------------------------------------
HOST = r"""
#include <dlfcn.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
typedef void* C;
typedef struct {
    void (*logger)(void*, const char*, int, const char*, const char*, ...);
    void* (*allocate)(size_t, size_t);
    void (*free)(void*);
    void* step_finished;
    void* environment;
} Callbacks;
static void logger(void* env, const char* name, int status, const char* category, const char* message, ...)
{
    va_list args;
    va_start(args, message);
    printf("LOG %d %s: ", status, category ? category : "-");
    vprintf(message, args);
    printf("\n");
    va_end(args);
}
#define BIND(ret, name, ...) ret (*name)(__VA_ARGS__) = (ret (*)(__VA_ARGS__))dlsym(h, #name)
int main(int argc, char** argv)
{
    setvbuf(stdout, NULL, _IONBF, 0);
    void* h = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (h == NULL) { printf("dlopen: %s\n", dlerror()); return 1; }
    BIND(C, fmi2Instantiate, const char*, int, const char*, const char*, const Callbacks*, int, int);
    BIND(int, fmi2SetupExperiment, C, int, double, double, int, double);
    BIND(int, fmi2EnterInitializationMode, C);
    BIND(int, fmi2ExitInitializationMode, C);
    BIND(int, fmi2SetReal, C, const unsigned*, size_t, const double*);
    BIND(int, fmi2GetReal, C, const unsigned*, size_t, double*);
    BIND(int, fmi2DoStep, C, double, double, int);
    BIND(void, fmi2FreeInstance, C);
    BIND(int, robofmu_fast_path, C);
    BIND(unsigned long long, robofmu_fast_calls, C);
    Callbacks callbacks = {logger, calloc, free, NULL, NULL};
    C c = fmi2Instantiate("plant", 1, argv[2], argv[3], &callbacks, 0, 0);     /* loggingOn false */
    if (c == NULL) { printf("instantiate failed\n"); return 1; }
    int status = fmi2SetupExperiment(c, 0, 0.0, 0.0, 0, 0.0);
    status |= fmi2EnterInitializationMode(c);
    status |= fmi2ExitInitializationMode(c);
    unsigned in[1] = {(unsigned)atoi(argv[4])}, out[1] = {(unsigned)atoi(argv[5])};
    double value[1] = {0.5}, read[1] = {0.0};
    for (int k = 0; k < 50; ++k) {
        status |= fmi2SetReal(c, in, 1, value);
        status |= fmi2GetReal(c, out, 1, read);
        status |= fmi2DoStep(c, k * 1e-3, 1e-3, 1);
    }
    printf("FAST %d CALLS %llu STATUS %d OUT %.17g\n", robofmu_fast_path(c), robofmu_fast_calls(c), status, read[0]);
    value[0] = NAN;
    status = fmi2SetReal(c, in, 1, value);
    printf("NAN %d\n", status);
    status = fmi2DoStep(c, 0.05, 1e-3, 1);
    printf("REFUSED %d\n", status);
    fmi2FreeInstance(c);
    printf("DONE\n");
    return 0;
}
"""


@pytest.mark.interop
def test_a_host_that_is_not_python_gets_the_same_through_the_fast_path(fmu_root, tmp_path):
    """A C program started with an empty environment (no libpython preloaded, no PATH): robofmu's
    library loads the Python the FMU records, pythonfmu starts the interpreter, the FMI calls come
    from a thread that never ran Python."""
    import subprocess

    from robofmu.system.packaging import doctor
    from robofmu.system.packaging import fmi_export

    library = doctor.libpython()
    if library is None or not library.is_file():
        pytest.skip("this Python has no shared libpython")
    (tmp_path / "host.c").write_text(HOST)
    built = subprocess.run(fmi_export._compiler() + ["-o", str(tmp_path / "host"), str(tmp_path / "host.c"), "-ldl"],
                           capture_output=True, text=True)
    assert built.returncode == 0, built.stderr
    path = fmu_root / "chess" / "plant.fmu"
    md = read_model_description(str(path), validate=False)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    folder = Path(extract(str(path), unzipdir=str(tmp_path / "plant")))
    runs = {}
    for mode in ("1", "0"):
        env = {"ROBOFMU_FMI_FAST_PATH": mode}
        done = subprocess.run([str(tmp_path / "host"), str(folder / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so"),
                               md.guid, (folder / "resources").as_uri(), str(vr["tau[1]"]), str(vr["q[1]"])],
                              capture_output=True, text=True, env=env, timeout=300)
        assert done.returncode == 0 and "DONE" in done.stdout, done.stdout + done.stderr
        runs[mode] = done.stdout.splitlines()
    fast, slow = runs["1"], runs["0"]
    assert fast[0].startswith("FAST 1 CALLS 150 STATUS 0 OUT ")
    assert slow[0].startswith("FAST 0 CALLS 0 STATUS 0 OUT ")
    assert fast[0].split("OUT ")[1] == slow[0].split("OUT ")[1]
    assert fast[1:] == slow[1:]
    assert fast[1:] == ["NAN 0", "LOG 3 logStatusError: plant: input tau[1] = nan at t = 0.05 s is not finite; step refused",
                        "REFUSED 3", "DONE"]


# -- a whole experiment ---------------------------------------------------------------------------
EXPERIMENTS = ["chess-pd", "3rrp-circle", "planar2r-nr", "rpp-bangbang", "rrp-line", "rrp_offset-nr", "ur5-pose",
               "panda-pose"]


@pytest.mark.parametrize("name", EXPERIMENTS)
def test_an_experiment_through_the_fast_path_equals_the_in_process_replica(fmu_root, name, monkeypatch):
    registered = []
    register = BlockSlave._register_fast_path

    def recorded(self):
        registered.append(register(self))
        return registered[-1]

    monkeypatch.setattr(BlockSlave, "_register_fast_path", recorded)
    system = experiment.load(name, fmu_dir=fmu_root)
    h, stop = 0.005, 0.3
    cosim = Master(system).run(stop_time=stop, step=h)
    assert registered and all(registered), registered
    assert len(registered) == len(system.blocks)
    replica = InProcessDiagram(system).sampled(h, stop)
    assert sorted(cosim.columns) == sorted(replica.columns)
    for column in cosim.columns:
        np.testing.assert_array_equal(bits(cosim[column]), bits(replica[column]), err_msg=column)


def test_every_robot_is_covered(fmu_root):
    assert {p.values[0] for p in HOT} == set(available())
    assert {experiment.load(n, fmu_dir=fmu_root).extra["robot"] for n in EXPERIMENTS} == set(available())

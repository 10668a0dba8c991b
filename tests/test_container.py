"""Every robot's whole diagram as one FMU container (fmu-manipulation-toolbox), run by fmpy.

The container must reproduce the master bit for bit: in parallel mode its Jacobi run, in
sequential mode (blocks without feedthrough first) its Gauss-Seidel run, every recorded output
of every block, on one PD experiment per robot. The exceptions are exact and tested as such:
the Newton-Raphson IK's ``iterations`` in sequential mode (its outputs are asked for again after
its step, with the same inputs: a second solve from the converged solution, 0 iterations) and a
PID's integral (advanced with the inputs of t + h: a difference of first order in h).
"""
from __future__ import annotations

import re
import subprocess
import sys
import zipfile
from types import SimpleNamespace

import numpy as np
import pytest

from fmpy import read_model_description, simulate_fmu  # noqa: E402
from fmpy.fmi1 import FMICallException  # noqa: E402
from fmpy.validation import validate_fmu  # noqa: E402

from fmu_util import assert_same_run, robot_experiments  # noqa: E402
from robofmu.system import experiment  # noqa: E402
from robofmu.system.plan import Link, plan  # noqa: E402
from robofmu.system.interop.container import (container_order, export_container,  # noqa: E402
                                      model_identifier, run_container)
from robofmu.system.master import Master, SimulationError  # noqa: E402
from robofmu.system.packaging.validate import problems_of  # noqa: E402

STOP = 0.5              # s
ALGORITHMS = ["gauss-seidel", "jacobi"]
CLI = [sys.executable, "-m", "robofmu.system.cli"]


@pytest.fixture(scope="module")
def containers(fmu_root, tmp_path_factory):
    """containers(name, algorithm, expose_signals=False) -> (System, container path), each built once."""
    folder, cache = tmp_path_factory.mktemp("containers"), {}

    def get(name, algorithm, expose_signals=False):
        key = name, algorithm, expose_signals
        if key not in cache:
            system = experiment.load(name, fmu_dir=fmu_root)
            out = folder / f"{name}-{algorithm}{'-exposed' if expose_signals else ''}.fmu"
            cache[key] = system, export_container(system, out, algorithm, expose_signals=expose_signals)
        return cache[key]

    return get


def wired_signals(system) -> set[str]:
    """``block.output`` of every wired output of the diagram (the sources of its links)."""
    return {f"{link.source}.{link.output}" for link in plan(system).links}


def logged(path, stop_time, **kwargs) -> tuple[list[tuple[int, str]], object]:
    """Run a container with fmpy.simulate_fmu and a logger of our own (as a host does): the
    messages as (fmi2Status, text), and the result (or the exception the run raised)."""
    messages = []

    def logger(env, instance, status, category, message):
        messages.append((status, message.decode(errors="replace")))

    try:
        outcome = simulate_fmu(str(path), stop_time=stop_time, logger=logger, **kwargs)
    except FMICallException as exc:
        outcome = exc
    return messages, outcome


FMI2_OK, FMI2_WARNING, FMI2_ERROR, FMI2_FATAL = 0, 1, 3, 4


@pytest.mark.parametrize("algorithm", ALGORITHMS)
@pytest.mark.parametrize("name", robot_experiments())
def test_the_container_reproduces_the_master_bit_for_bit(containers, name, algorithm):
    """The whole experiment (chess: the gripper closes at 6 s and opens at 11.5 s)."""
    system, path = containers(name, algorithm)
    h = system.step
    boxed = run_container(path, system.stop_time, h)
    master = Master(system).run(system.stop_time, h, algorithm)
    assert sorted(boxed.columns) == sorted(master.columns)          # every output, Booleans included
    np.testing.assert_array_equal(boxed.time, master.time)
    if algorithm == "gauss-seidel" and "ik.residual" in master.columns:   # Newton-Raphson, warm-started:
        assert np.all(boxed["ik.iterations"][1:] == 0.0) and np.max(master["ik.iterations"]) > 0  # solved twice
    assert_same_run(boxed, master, name, skip=("ik.iterations",) if algorithm == "gauss-seidel" else ())
    # not vacuous: the two algorithms give different runs
    other = Master(system).run(STOP, h, ALGORITHMS[1 - ALGORITHMS.index(algorithm)])
    assert np.max(np.abs(other.vector("plant.q") - master.vector("plant.q")[:len(other.time)])) > 1e-9


def test_a_pid_integral_differs_at_first_order_in_sequential_mode(fmu_root, tmp_path):
    """The PID's integral advances over [t, t + h] with the error at t + h in the container, at t in
    the master: the torques differ by about ki h |e(t + h) - e(t)| summed, which halves with h."""
    system = experiment.load("chess-pid-unknown-pawn", fmu_dir=fmu_root)
    differences = []
    for h in (2e-3, 1e-3):
        system.step = h
        path = export_container(system, tmp_path / f"pid-{h:g}.fmu", "gauss-seidel")
        boxed, master = run_container(path, STOP, h), Master(system).run(STOP, h, "gauss-seidel")
        np.testing.assert_array_equal(boxed.vector("ik.q_ref"), master.vector("ik.q_ref"))  # upstream: equal
        differences.append(np.max(np.abs(boxed.vector("controller.tau") - master.vector("controller.tau"))))
    assert 0 < differences[1] < 1e-5
    assert 0.4 < differences[1] / differences[0] < 0.6, differences


@pytest.mark.parametrize("name", robot_experiments())
def test_the_container_is_a_valid_block_with_the_diagram_open_ends_as_ports(containers, name):
    """fmpy validates it; its inputs are the diagram's unwired inputs (with the experiment's values
    as start values), its outputs the unwired outputs, its locals the wired ones."""
    system, path = containers(name, "gauss-seidel")
    assert validate_fmu(str(path)) == []
    md = read_model_description(str(path))
    planned = plan(system)
    sources = {(link.source, link.output) for link in planned.links}
    targets = {(link.target, link.input) for link in planned.links}
    expected = {"input": set(), "output": set(), "local": set()}
    for block, node in planned.nodes.items():
        for v in node.model_description.modelVariables:
            if v.causality == "input" and (block, v.name) not in targets:
                expected["input"].add(f"{block}.{v.name}")
            elif v.causality == "output":
                expected["local" if (block, v.name) in sources else "output"].add(f"{block}.{v.name}")
    found = {c: {v.name for v in md.modelVariables if v.causality == c} for c in expected}
    assert found == expected
    assert md.coSimulation.modelIdentifier == model_identifier(path)
    assert re.fullmatch(r"[A-Za-z_]\w*", model_identifier(path))          # a C identifier, whatever the name
    assert float(md.defaultExperiment.stepSize) == system.step
    assert float(md.defaultExperiment.stopTime) == system.stop_time
    for spec in system.blocks:                         # an input the experiment sets starts there
        for parameter, value in spec.parameters.items():
            for v in md.modelVariables:
                if v.causality == "input" and v.name.split("[")[0] == f"{spec.name}.{parameter}":
                    index = int(v.name[v.name.index("[") + 1:-1]) - 1 if "[" in v.name else None
                    assert float(v.start) == (value[index] if index is not None else value)
    with zipfile.ZipFile(path) as zf:                  # every block's FMU inside, Linux binary included
        names = zf.namelist()
    assert sum(n.endswith("/modelDescription.xml") for n in names) == len(system.blocks)
    assert f"binaries/linux64/{md.coSimulation.modelIdentifier}.so" in names


def test_model_identifier_is_the_file_stem_as_a_c_identifier():
    assert model_identifier("out/chess-pd.fmu") == "chess_pd"
    assert model_identifier("3rrp-circle.fmu") == "_3rrp_circle"
    assert model_identifier("2-link arm.fmu") == "_2_link_arm"


def test_sequential_order_puts_the_blocks_without_feedthrough_first(fmu_root):
    planned = plan(experiment.load("chess-pd", fmu_dir=fmu_root))
    assert container_order(planned) == ["plant", "trajectory", "ik", "controller"]    # plant before its grip's source


def test_blocks_without_feedthrough_feeding_each_other_have_no_sequential_order():
    """A plant-like block A feeding B and B feeding A (neither with feedthrough): whichever steps
    first moves the other's input to t + h, so Gauss-Seidel cannot be reproduced."""
    nodes = {b: SimpleNamespace(feedthrough={"y": set()}) for b in ("a", "b", "c")}
    nodes["c"].feedthrough = {"y": {"u"}}
    cyclic = SimpleNamespace(order=["a", "b", "c"], nodes=nodes,
                             links=[Link("a", "y", "b", "u"), Link("b", "y", "a", "u"), Link("a", "y", "c", "u")])
    with pytest.raises(ValueError, match=r"feed each other \(a, b\).*use jacobi"):
        container_order(cyclic)
    chain = SimpleNamespace(order=["a", "b", "c"], nodes=nodes, links=[Link("a", "y", "b", "u"), Link("b", "y", "c", "u")])
    assert container_order(chain) == ["b", "a", "c"]          # b reads a: b steps first


def test_two_runs_of_one_container_in_one_process_are_identical(containers):
    _, path = containers("chess-pd", "jacobi")
    first, second = run_container(path, 0.1), run_container(path, 0.1)
    np.testing.assert_array_equal(first.data, second.data)


@pytest.mark.parametrize("change, block, time, rows", [
    ({"controller.kp": -1.0}, "controller", 0.0, 0),       # refused at initialization
    ({"controller.kd": 1e308}, "plant", 0.001, 2),          # an infinite torque: the plant refuses its step
])
def test_a_refusing_block_stops_the_container_as_it_stops_the_master(fmu_root, tmp_path, change, block, time, rows):
    """The container passes a block's fmi2Error on, with the block's message: the run stops at the
    master's block and time, with the block's own words and the rows before."""
    broken = experiment.with_parameters(experiment.load("chess-pd", fmu_dir=fmu_root), change)
    with pytest.raises(SimulationError) as master:
        Master(broken).run(0.05, broken.step)
    with pytest.raises(SimulationError) as boxed:
        run_container(export_container(broken, tmp_path / "bad.fmu"), 0.05)
    assert (boxed.value.block, boxed.value.time) == (master.value.block, master.value.time) == (block, time)
    assert str(boxed.value).startswith(f"bad.fmu: {block} at t = {time:g} s: ")
    assert master.value.reason.rsplit(f"{block}: ", 1)[-1] in str(boxed.value)      # the block's own words
    if rows:
        np.testing.assert_array_equal(boxed.value.result.vector("plant.q"), master.value.result.vector("plant.q"))
    else:
        assert boxed.value.result is None


def test_unknown_algorithm_is_refused(fmu_root, tmp_path):
    system = experiment.load("chess-pd", fmu_dir=fmu_root)
    with pytest.raises(ValueError, match="algorithm 'rk4': choose one of gauss-seidel, jacobi"):
        export_container(system, tmp_path / "x.fmu", "rk4")
    assert not (tmp_path / "x.fmu").exists()


def test_the_command_writes_a_container_and_answers_mistakes_in_one_line(fmu_root, tmp_path):
    done = subprocess.run([*CLI, "container", "rrp-line", "--fmus", str(fmu_root), "--out", str(tmp_path / "rrp.fmu"),
                           "--algorithm", "jacobi"], capture_output=True, text=True, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == str(tmp_path / "rrp.fmu") and (tmp_path / "rrp.fmu").is_file()
    assert validate_fmu(str(tmp_path / "rrp.fmu")) == []
    for args, message in ((["no-such-experiment"], "robofmu container: "),
                          (["rrp-line", "--fmus", str(tmp_path / "none")], "--fmus"),
                          (["rrp-line", "--fmus", str(fmu_root), "--out", str(tmp_path / "rrp.fmu" / "x.fmu")],
                           "--out")):
        failed = subprocess.run([*CLI, "container", *args], capture_output=True, text=True, cwd=tmp_path)
        assert failed.returncode == 2, failed.stderr
        assert failed.stderr.startswith("robofmu container: ") and message in failed.stderr
        assert len(failed.stderr.strip().splitlines()) == 1 and "Traceback" not in failed.stderr


# -- what the container logs ---------------------------------------------------------------------------------
@pytest.mark.parametrize("algorithm", ALGORITHMS)
def test_a_successful_run_logs_no_error_level_message(containers, algorithm):
    """fmu-manipulation-toolbox 2.0's runtime logs "Solver configure...." with status fmi2Error at
    every instantiation (compiled in: see robofmu.system.interop.container); robofmu's front library
    passes it on as fmi2OK, with debug logging only. A successful run logs no error-level message,
    debug logging off (a host's default) or on; the runtime's two warnings stay."""
    system, path = containers("chess-pd", algorithm)
    for debug in (False, True):
        messages, result = logged(path, 0.05, step_size=system.step, output_interval=system.step,
                                  debug_logging=debug)
        assert not isinstance(result, Exception), result
        assert len(result) == 51 and result["time"][-1] == pytest.approx(0.05, abs=1e-12)
        assert [text for status, text in messages if status in (FMI2_ERROR, FMI2_FATAL)] == [], debug
        chatter = [status for status, text in messages if text == "Solver configure...."]
        assert chatter == ([FMI2_OK] if debug else []), (debug, chatter)
        warnings = [text for status, text in messages if status == FMI2_WARNING]
        assert warnings[0] == "FMUContainer 'V2.0'" and "mode" in warnings[1], warnings
        assert len(messages) > 30 if debug else len(messages) <= 5              # the debug flag works


def test_the_runtime_alone_logs_its_trace_as_an_error(containers, tmp_path):
    """The negative control: the same container with the runtime put back in the front's place
    logs "Solver configure...." as fmi2Error (what the front library is for)."""
    import zipfile

    from robofmu.system.packaging import fmi_export

    system, path = containers("chess-pd", "jacobi")
    bare = tmp_path / "bare.fmu"
    with zipfile.ZipFile(path) as zin, zipfile.ZipFile(bare, "w") as zout:
        identifier = model_identifier(path)
        runtime = zin.read(f"binaries/linux64/{fmi_export.FRONT_BEHIND}")
        for item in zin.infolist():
            if item.filename == f"binaries/linux64/{identifier}.so":
                zout.writestr(item, runtime)
            elif item.filename != f"binaries/linux64/{fmi_export.FRONT_BEHIND}":
                zout.writestr(item, zin.read(item.filename))
    messages, result = logged(bare, 0.05, step_size=system.step, output_interval=system.step)
    assert not isinstance(result, Exception), result
    assert [text for status, text in messages if status == FMI2_ERROR] == ["Solver configure...."]


def test_a_refused_step_still_logs_its_error(fmu_root, tmp_path):
    """An infinite torque: the plant refuses its step at t = 1 ms; the host gets fmi2Error with the
    plant's own words (those the master reports), after the runtime's known line."""
    broken = experiment.with_parameters(experiment.load("chess-pd", fmu_dir=fmu_root), {"controller.kd": 1e308})
    with pytest.raises(SimulationError) as master:
        Master(broken).run(0.05, broken.step)
    path = export_container(broken, tmp_path / "bad.fmu", "gauss-seidel")
    messages, outcome = logged(path, 0.05, step_size=broken.step, output_interval=broken.step)
    assert isinstance(outcome, FMICallException)
    errors = [text for status, text in messages if status == FMI2_ERROR]
    assert (master.value.block, master.value.time) == ("plant", 0.001)
    words = master.value.reason.rsplit("plant: ", 1)[-1]                     # the block's own words
    assert len(words) > 20
    refused = [text for text in errors if text.startswith("plant.fmu: ") and text.endswith(words)]
    assert len(refused) == 1, errors


# -- the wired signals as outputs ----------------------------------------------------------------------------
@pytest.mark.parametrize("name", robot_experiments())
def test_exposed_signals_are_outputs_equal_to_the_locals_bit_for_bit(containers, name):
    """With expose_signals every wired signal is an output (none is left a local), the inputs and
    the other outputs are unchanged, the FMU is valid for both checkers, and a run records the
    same values as the container without the option records in its locals. An output-only
    recorder (fmpy.simulate_fmu's default) then sees them; without the option it sees none."""
    system, plain = containers(name, "gauss-seidel")
    _, exposed = containers(name, "gauss-seidel", expose_signals=True)
    wired = wired_signals(system)
    assert len(wired) >= 10 and "plant.q[1]" in wired and "controller.tau[1]" in wired
    before, after = (read_model_description(str(p)) for p in (plain, exposed))
    causality = lambda md, c: {v.name for v in md.modelVariables if v.causality == c}     # noqa: E731
    assert causality(before, "local") == wired                                 # as today
    assert causality(after, "local") == set()
    assert causality(after, "output") == causality(before, "output") | wired
    assert causality(after, "input") == causality(before, "input")
    listed = [v.name for v in after.modelVariables if v.causality == "output"]
    assert [u.variable.name for u in after.outputs] == listed                 # ModelStructure/Outputs
    assert [u.variable.name for u in after.initialUnknowns] == listed          # all calculated at start
    by_name = {v.name: v.valueReference for v in before.modelVariables}
    assert all(v.valueReference == by_name[v.name] for v in after.modelVariables)   # same storage
    assert problems_of(exposed) == []                                          # fmpy and fmutool -check

    h, stop = system.step, STOP
    locals_run, outputs_run = run_container(plain, stop, h), run_container(exposed, stop, h)
    assert outputs_run.columns == locals_run.columns
    np.testing.assert_array_equal(outputs_run.data, locals_run.data)
    recorded = simulate_fmu(str(exposed), stop_time=stop, step_size=h, output_interval=h)      # outputs only
    assert wired <= set(recorded.dtype.names)
    for column in wired:
        np.testing.assert_array_equal(recorded[column].astype(float), locals_run[column], err_msg=column)
    assert not wired & set(simulate_fmu(str(plain), stop_time=10 * h, step_size=h, output_interval=h).dtype.names)
    moving = [c for c in wired if np.ptp(locals_run[c]) > 0]
    assert "plant.q[1]" in moving or "plant.q[2]" in moving                    # not vacuous: the arm moves


def test_the_command_exposes_the_signals_on_request(fmu_root, tmp_path):
    out = tmp_path / "rrp.fmu"
    done = subprocess.run([*CLI, "container", "rrp-line", "--fmus", str(fmu_root), "--out", str(out),
                           "--expose-signals"], capture_output=True, text=True, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    md = read_model_description(str(out))
    system = experiment.load("rrp-line", fmu_dir=fmu_root)
    assert wired_signals(system) <= {v.name for v in md.modelVariables if v.causality == "output"}
    assert not [v.name for v in md.modelVariables if v.causality == "local"]
    helped = subprocess.run([*CLI, "container", "--help"], capture_output=True, text=True, cwd=tmp_path)
    assert "--expose-signals" in helped.stdout and "outputs instead of its locals" in " ".join(helped.stdout.split())

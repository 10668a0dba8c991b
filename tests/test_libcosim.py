"""Each chess FMU (and every robot's plant) runs through libcosim (the Open Simulation Platform's
co-simulation library), driven from Python by libcosimpy, alone and all together in one execution.

How the FMUs are loaded: in this very process. libcosimpy calls libcosimc through
``ctypes.CDLL``, which releases the GIL during every call; libcosim extracts each FMU to its own
``/tmp/libcosim_*`` folder, dlopens its binary and calls it from its worker thread. The pythonfmu
binary does not link libpython: it resolves the ``Py*`` symbols from the host process (here the
venv's python, which links libpython3.11.so), finds the interpreter running
(``Py_IsInitialized``) and takes the GIL (``PyGILState_Ensure``). So the FMUs' Python runs on
this interpreter; no subprocess and no ``LD_PRELOAD`` of libpython is needed, here nor in a
child ``sys.executable`` (a non-Python host such as the ``cosim`` CLI would presumably need the
preload, since the FMU binary has no DT_NEEDED entry for libpython; not tested here). All FMU instances of the process, libcosim's
and fmpy's alike, share that one interpreter, and therefore the one ``robofmu.components``
imported first (conftest imports the installed copy; the FMUs check theirs matches).

Things libcosimpy 0.0.6 cannot do directly and how this file copes (see system/interop/libcosim.py):

- There is no direct fmi2GetReal/fmi2SetReal: values are read through observers (last-value,
  time-series) and written as initial values (before the first step) or through the override
  manipulator (applied before each following step).
- ``time_series_real_samples`` drops the last sample when the series starts at step 0 (it counts
  step numbers equal to 0 to trim its buffer); ``CosimRun.series`` calls libcosimc directly.
- The ``connect_*_variables`` methods return libcosimc's raw status (0 = success), not a bool.
- libcosim's console log level defaults to DEBUG (every FMI Library call); CosimRun sets WARNING.
- A FMU failing fmi2ExitInitializationMode makes libcosim throw from its worker thread and the
  C++ runtime calls std::terminate: the whole process aborts (SIGABRT), no Python exception.
  A failing fmi2DoStep, by contrast, is reported (CosimError) and a failing fmi2Instantiate
  too. The abort is demonstrated in a child process (test_failed_initialization_...).
- libcosim's log, FMU messages included, goes to the C++ stdout; a refused step (fmi2Error) comes
  back with the FMU's message: "plant: Model error: plant: input tau[2] = nan ...".
- libcosim's fixed-step algorithm is a Jacobi scheme: connected values are transferred after each
  step, so every connection adds one step of delay (trajectory -> ik -> controller: two).
- Block rates reach libcosim through the OSP export (``OspSystemStructure.xml``, a step size per
  simulator; system/interop/osp.py): a simulator stepped every r base steps has its outputs
  transferred when its step ends, which is the master's Jacobi loop at the same rates (tested to
  1e-12) and a hand-written loop with one controller sample of delay.
"""
from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from fmpy import simulate_fmu  # noqa: E402

from robofmu.components.ik import make_solver  # noqa: E402
from robofmu.components.robots import load_description, load_model  # noqa: E402
from robofmu.system.interop.libcosim import CosimRun  # noqa: E402

STEP = 1e-3            # s, communication step of libcosim's fixed-step algorithm
T_END = 0.2            # s
N_STEPS = 200
A1, A2, A3, A4 = 0.1905, 0.3048, 0.3048, 0.09525     # chess arm link lengths (m)
A_LSPB = 4.5 * 0.15    # m/s^2: first move dz = 0.15 m in 1 s, cruise 1.5 x mean speed, blend T/3


def chess_fk(q):
    """Closed-form TCP position of the chess arm (independent of the Pinocchio model)."""
    q1, q2, q3, q4 = q
    p = A2 * math.cos(q2) + A3 * math.cos(q2 + q3) + A4 * math.cos(q2 + q3 + q4)
    z = A1 + A2 * math.sin(q2) + A3 * math.sin(q2 + q3) + A4 * math.sin(q2 + q3 + q4)
    return np.array([p * math.cos(q1), p * math.sin(q1), z])


def lspb_z(t):
    """z of the first move while it accelerates (t <= 1/3 s)."""
    return 0.5 * A_LSPB * t * t


@pytest.fixture
def cosim():
    """Factory of CosimRun executions (1 ms step), all destroyed at teardown: an execution left
    to the garbage collector could call fmi2FreeInstance at interpreter shutdown."""
    runs = []

    def make():
        run = CosimRun(STEP)
        runs.append(run)
        return run

    yield make
    for run in runs:
        run.close()


def series(run, instance, base):
    """(times, values[k, i]) of every element of vector ``base`` recorded by the time series."""
    cols = []
    for name in run.names(instance, base):
        times, steps, values = run.series(instance, name)
        cols.append(values)
    return np.array(times), np.array(cols).T


def test_libcosim_sees_the_variables_of_each_fmu(cosim, fmu_dir):
    run = cosim()
    for block in ("trajectory", "ik", "controller", "plant"):
        run.add(fmu_dir / f"{block}.fmu", block)
    infos = {s.name.decode(): s.index for s in run.execution.slave_infos()}   # in no set order
    assert infos == {"trajectory": 0, "ik": 1, "controller": 2, "plant": 3}
    assert run.execution.num_slaves() == 4
    v = run.slaves["plant"].variables
    assert (v["q[2]"].type, v["q[2]"].causality) == ("REAL", "OUTPUT")
    assert (v["tau[4]"].type, v["tau[4]"].causality) == ("REAL", "INPUT")
    assert (v["q0[1]"].type, v["q0[1]"].causality) == ("REAL", "PARAMETER")
    assert (v["grip"].type, v["grip"].causality) == ("BOOLEAN", "INPUT")
    assert run.names("ik", "q_ref") == [f"q_ref[{i}]" for i in range(1, 5)]
    assert run.slaves["trajectory"].variables["waypoints"].type == "STRING"


def test_trajectory_lspb_closed_form(cosim, fmu_dir):
    run = cosim()
    run.add(fmu_dir / "trajectory.fmu", "trajectory")
    run.observe_series("trajectory", "x_ref[3]")
    run.step(N_STEPS)
    assert run.execution.status().current_time == 200_000_000          # ns, exactly
    assert run.time == pytest.approx(T_END, abs=1e-15)
    x = run.get("trajectory", "x_ref")
    assert x[0] == pytest.approx(0.21, abs=1e-12)
    assert x[1] == pytest.approx(0.0, abs=1e-12)
    assert x[2] == pytest.approx(0.0135, abs=1e-9)                      # 0.5 a 0.2^2
    assert x[2] == pytest.approx(lspb_z(T_END), abs=1e-12)
    assert run.get("trajectory", "xd_ref")[2] == pytest.approx(A_LSPB * T_END, abs=1e-12)
    assert run.get("trajectory", "xdd_ref")[2] == pytest.approx(A_LSPB, abs=1e-12)
    assert run.get("trajectory", "grip") is False
    times, _, z = run.series("trajectory", "x_ref[3]")
    assert len(times) == N_STEPS + 1                                     # t = 0 .. 0.2
    np.testing.assert_allclose(times, np.arange(N_STEPS + 1) * STEP, atol=1e-12)
    np.testing.assert_allclose(z, [lspb_z(t) for t in times], atol=1e-12)


def test_plant_free_fall_matches_fmpy(cosim, fmu_root, robot):
    path = fmu_root / robot / "plant.fmu"
    n = load_model(robot).n
    run = cosim()
    run.add(path, "plant")                      # tau (and chess's grip): their start values 0 (false)
    run.observe_series("plant", "q")
    run.step(N_STEPS)
    times, q = series(run, "plant", "q")
    assert q.shape == (N_STEPS + 1, n)

    names = [f"q[{i}]" for i in range(1, n + 1)]
    ref = simulate_fmu(str(path), stop_time=T_END, step_size=STEP, output_interval=STEP, output=names)
    q_ref = np.array([ref[name] for name in names]).T
    np.testing.assert_allclose(times, ref["time"], atol=1e-12)
    np.testing.assert_allclose(q, q_ref, rtol=0, atol=1e-9)

    q0 = np.array(load_description(robot).configuration("home"))       # default q0: the robot's home
    if robot == "chess":                                                # = IK of waypoint 1, to round-off
        np.testing.assert_allclose(make_solver(load_model("chess")).position(np.array([0.21, 0.0, 0.0])), q0,
                                   rtol=0, atol=1e-12)
    np.testing.assert_allclose(run.get("plant", "q0"), q0, atol=1e-12)
    np.testing.assert_allclose(q[0], q0, atol=1e-12)
    if np.any(load_model(robot).gravity_torque(q0)):
        assert np.max(np.abs(q[-1] - q0)) > 0.05                        # it really fell
    else:                                                               # 3rrp: a horizontal plane
        np.testing.assert_array_equal(q[-1], q0)                        # at rest, exactly


def test_ik_satisfies_closed_form_fk(cosim, fmu_dir):
    run = cosim()
    run.add(fmu_dir / "ik.fmu", "ik")
    target = np.array([0.2, 0.1, 0.1])
    run.set_initial("ik", "x_ref", target)                              # initial value
    run.step(10)
    q = np.array(run.get("ik", "q_ref"))
    np.testing.assert_allclose(chess_fk(q), target, rtol=0, atol=1e-9)
    assert q[1] + q[2] + q[3] == pytest.approx(-math.pi / 2, abs=1e-12)   # tool pitch
    assert run.get("ik", "reachable") is True
    np.testing.assert_allclose(run.get("ik", "qd_ref"), 0.0, atol=1e-12)

    second = np.array([0.15, -0.12, 0.05])
    run.override("ik", "x_ref", second)                                # override manipulator
    run.step(10)
    q2 = np.array(run.get("ik", "q_ref"))
    np.testing.assert_allclose(chess_fk(q2), second, rtol=0, atol=1e-9)
    assert q2[0] == pytest.approx(math.atan2(-0.12, 0.15), abs=1e-12)
    assert run.time == pytest.approx(20 * STEP, abs=1e-15)


def test_controller_outputs_gravity_torque(cosim, fmu_dir):
    robot = load_model("chess")
    run = cosim()
    run.add(fmu_dir / "controller.fmu", "controller")   # q = q_ref = home, rates 0, default gains (ki = 0)
    run.observe_series("controller", "tau")
    run.step(N_STEPS)
    g0 = robot.gravity_torque(robot.configuration("home"))
    assert np.max(np.abs(g0)) > 1.0                                      # a non-trivial reference
    np.testing.assert_allclose(run.get("controller", "tau"), g0, rtol=0, atol=1e-9)
    _, tau = series(run, "controller", "tau")
    np.testing.assert_allclose(tau, np.tile(g0, (N_STEPS + 1, 1)), rtol=0, atol=1e-9)

    # At rest on the reference (q = q_ref, qd = qd_ref = qdd_ref = 0) tau is g(q) again.
    qs = np.array([0.3, 0.6, -1.9, -0.2])
    run.override("controller", "q", qs)
    run.override("controller", "q_ref", qs)
    run.step(5)
    np.testing.assert_allclose(run.get("controller", "tau"), robot.gravity_torque(qs), rtol=0, atol=1e-9)


def chess_execution(cosim, fmu_dir, q0_second):
    """trajectory -> ik -> controller -> plant -> controller, plus an unconnected second plant."""
    run = cosim()
    for block in ("trajectory", "ik", "controller", "plant"):
        run.add(fmu_dir / f"{block}.fmu", block)
    run.add(fmu_dir / "plant.fmu", "plant2")
    for base in ("x_ref", "xd_ref", "xdd_ref"):
        run.connect("trajectory", base, "ik", base)
    for base in ("q_ref", "qd_ref", "qdd_ref"):
        run.connect("ik", base, "controller", base)
    run.connect("controller", "tau", "plant", "tau")
    run.connect("plant", "q", "controller", "q")
    run.connect("plant", "qd", "controller", "qd")
    run.connect("trajectory", "grip", "plant", "grip")
    run.connect("trajectory", "grip", "controller", "grip")
    run.set_initial("plant2", "q0", q0_second)
    return run


def test_all_fmus_and_a_second_plant_in_one_execution(cosim, fmu_dir):
    robot = load_model("chess")
    q0_second = [0.5, 0.3, -1.0, 0.2]
    run = chess_execution(cosim, fmu_dir, q0_second)
    assert run.execution.num_slaves() == 5
    links = [(("trajectory", "x_ref"), ("ik", "x_ref")), (("ik", "q_ref"), ("controller", "q_ref")),
             (("controller", "tau"), ("plant", "tau")), (("plant", "q"), ("controller", "q")),
             (("plant", "qd"), ("controller", "qd"))]
    for out, inp in links:
        run.observe_series(*out)
        run.observe_series(*inp)
    run.observe_series("plant2", "q")
    run.step(N_STEPS)
    status = run.execution.status()
    assert status.current_time == 200_000_000 and status.error_code == 0

    # every connection delivers the output of the previous communication point (Jacobi)
    for out, inp in links:
        _, y = series(run, *out)
        _, u = series(run, *inp)
        assert y.shape == u.shape == (N_STEPS + 1, y.shape[1])
        np.testing.assert_array_equal(u[1:], y[:-1], err_msg=f"{out} -> {inp}")

    # trajectory: the closed form; ik: FK of its q_ref is the trajectory's x_ref of one step ago
    assert run.get("trajectory", "x_ref")[2] == pytest.approx(0.0135, abs=1e-9)
    np.testing.assert_allclose(run.get("ik", "x_ref"), [0.21, 0.0, lspb_z(T_END - STEP)], atol=1e-12)
    q_ref = np.array(run.get("ik", "q_ref"))
    np.testing.assert_allclose(chess_fk(q_ref), [0.21, 0.0, lspb_z(T_END - STEP)], rtol=0, atol=1e-9)
    assert run.get("ik", "reachable") is True

    # the loop is closed: the plant follows the reference (to the start-up transient and the
    # steps of delay), where free fall from the same start ends centimetres away
    q = np.array(run.get("plant", "q"))
    assert np.linalg.norm(robot.fk(q) - [0.21, 0.0, lspb_z(T_END)]) < 2e-3
    names = [f"q[{i}]" for i in range(1, 5)]
    fall = simulate_fmu(str(fmu_dir / "plant.fmu"), stop_time=T_END, step_size=STEP, output_interval=STEP,
                        output=names)
    q_fall = np.array([fall[n][-1] for n in names])
    assert np.linalg.norm(robot.fk(q_fall) - [0.21, 0.0, lspb_z(T_END)]) > 0.02

    # the second plant: its own q0, its own state, exactly what it does alone under fmpy
    ref = simulate_fmu(str(fmu_dir / "plant.fmu"), stop_time=T_END, step_size=STEP, output_interval=STEP,
                       start_values={f"q0[{i}]": v for i, v in enumerate(q0_second, start=1)}, output=names)
    _, q_second = series(run, "plant2", "q")
    np.testing.assert_allclose(q_second, np.array([ref[n] for n in names]).T, rtol=0, atol=1e-9)
    np.testing.assert_allclose(q_second[0], q0_second, atol=1e-12)
    assert np.max(np.abs(q_second[-1] - q)) > 0.1


def test_connected_inputs_are_consistent_right_after_initialization(cosim, fmu_dir):
    """libcosim reads outputs in Initialization Mode and passes them along the connections
    (FMI 2.0: calculated outputs are valid there); the blocks compute them from the parameters
    and inputs set so far, so the loop starts consistent at t = 0."""
    run = chess_execution(cosim, fmu_dir, [0.0, 0.0, 0.0, 0.0])
    for instance, base in (("ik", "x_ref"), ("ik", "q_ref"), ("controller", "q"), ("plant", "q")):
        run.observe_series(instance, base)
    run.step(1)
    row0 = {key: series(run, *key)[1][0] for key in
            (("ik", "x_ref"), ("ik", "q_ref"), ("controller", "q"), ("plant", "q"))}   # t = 0
    np.testing.assert_allclose(row0["ik", "x_ref"], [0.21, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(chess_fk(row0["ik", "q_ref"]), [0.21, 0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(row0["controller", "q"], row0["plant", "q"], atol=1e-12)


def test_failed_step_raises_with_libcosim_message(cosim, fmu_dir):
    run = cosim()
    run.add(fmu_dir / "plant.fmu", "plant")
    run.step(3)
    run.override("plant", "tau[2]", float("nan"))
    with pytest.raises(RuntimeError, match=r"from t = 0.003 s failed: .*plant: Model error: plant: "
                                           r"input tau\[2\] = nan at t = 0.003 s is not finite; step refused"):
        run.step(3)
    # the FMU returns fmi2Error with its message, which libcosim puts into its error
    assert run.execution.status().current_time == 3_000_000


def test_failed_initialization_aborts_the_process(fmu_dir, tmp_path):
    """libcosim cannot report a failed fmi2ExitInitializationMode to Python: it throws from a
    worker thread and the process dies of std::terminate. Hence this runs in a child process
    (``sys.executable``, the venv's python), which first runs the trajectory normally: a child
    needs no LD_PRELOAD of libpython either. (libcosim's log, FMU messages included, goes to the
    C++ stdout, whose buffer is lost in the abort.)"""
    script = textwrap.dedent("""
        import sys
        import robofmu.components
        from robofmu.system.interop.libcosim import CosimRun
        run = CosimRun(1e-3)
        run.add(sys.argv[1] + "/trajectory.fmu", "trajectory")
        run.step(200)
        print("Z", repr(run.get("trajectory", "x_ref[3]")), flush=True)
        run.close()
        run = CosimRun(1e-3)
        run.add(sys.argv[1] + "/plant.fmu", "plant")
        run.set_initial("plant", "max_substep", -1.0)
        try:
            run.step(1)
        except Exception as exc:
            print("RAISED", exc, flush=True)
        run.close()
        print("SURVIVED", flush=True)
    """)
    env = {k: v for k, v in os.environ.items() if k != "LD_PRELOAD"}
    env["TMPDIR"] = str(tmp_path)   # the aborted libcosim leaves its FMU extraction folder behind
    proc = subprocess.run([sys.executable, "-c", script, str(fmu_dir)],
                          capture_output=True, text=True, timeout=120, env=env)
    z = [line.split()[1] for line in proc.stdout.splitlines() if line.startswith("Z ")]
    assert z and float(z[0]) == pytest.approx(0.0135, abs=1e-9), (proc.stdout, proc.stderr)
    if proc.returncode == 0:        # a libcosim that reports the failure instead (not 0.0.6's)
        assert "RAISED" in proc.stdout and "initialization" in proc.stdout and "SURVIVED" in proc.stdout
    else:                           # libcosimpy 0.0.6's libcosim: std::terminate
        assert proc.returncode == -signal.SIGABRT, proc.stderr
        assert "terminate called after throwing an instance of 'cosim::error'" in proc.stderr
        assert ("Model error: plant: initialization failed: parameter max_substep = -1 s is invalid: "
                "must be > 0") in proc.stderr         # the FMU's fmi2Error message
        assert "SURVIVED" not in proc.stdout
        assert list(tmp_path.glob("libcosim_*"))      # the leftover landed in TMPDIR, not /tmp


# -- block rates through the OSP export (issue 30, point 1; system/interop/osp.py) ---------------
def _slowed(fmu_root, name: str, slow: dict[str, float], delay: int, stop: float):
    """Experiment ``name`` with the blocks of ``slow`` at their sample times (s) and the
    controller's ``delay_steps``."""
    from robofmu.system import experiment

    system = experiment.load(name, fmu_dir=fmu_root)
    for block, sample_time in slow.items():
        system.block(block).sample_time = sample_time
    system.block("controller").parameters["delay_steps"] = delay
    system.stop_time = stop
    return system


EVERY_BLOCK_BUT_THE_PLANT = {"trajectory": 0.004, "ik": 0.004, "controller": 0.004, "fk": 0.004}


@pytest.mark.parametrize("name, slow, delay, stop", [
    ("chess-pd", {"controller": 0.004}, 0, 1.0),
    ("chess-pd", {"controller": 0.003}, 2, 0.5),           # 500 base steps: no whole number of samples
    ("ur5-pose", EVERY_BLOCK_BUT_THE_PLANT, 0, 0.5),       # make bench's multi-rate case
], ids=["chess-pd-controller-4ms", "chess-pd-controller-3ms-d2", "ur5-pose-plant-1ms-rest-4ms"])
def test_libcosim_runs_the_osp_export_at_its_rates_as_the_masters_jacobi_loop(fmu_root, tmp_path, name, slow,
                                                                              delay, stop):
    """libcosim's fixed-step algorithm with a step size per simulator (decimation) is the master's
    Jacobi loop at the same rates: every Real output within 1e-12 of its range, at every base step."""
    from robofmu.system.interop.osp import export_osp, run_osp_libcosim
    from robofmu.system.master import Master

    system = _slowed(fmu_root, name, slow, delay, stop)
    result = run_osp_libcosim(export_osp(system, tmp_path / "osp"))
    jacobi = Master(system).run(algorithm="jacobi")
    assert jacobi.info["sample_times"] == {b.name: slow.get(b.name, system.step) for b in system.blocks}
    np.testing.assert_allclose(result.time, jacobi.time, rtol=0, atol=1e-15)
    assert len(result.columns) > 40 and set(result.columns) <= set(jacobi.columns)
    for column in result.columns:
        scale = max(1.0, np.ptp(jacobi[column]))
        np.testing.assert_allclose(result[column], jacobi[column], rtol=0, atol=1e-12 * scale, err_msg=column)
    # held between samples: the controller's effort changes only at its own samples
    ratio = round(slow["controller"] / system.step)
    tau = np.column_stack([result[c] for c in result.columns if c.startswith("controller.tau[")])
    changes = np.flatnonzero(np.any(np.diff(tau, axis=0) != 0.0, axis=1)) + 1
    assert len(changes) > 50 and not np.any(changes % ratio)
    # the rates and the algorithm are what make it agree: Gauss-Seidel at the same rates, and
    # Jacobi with every block at the base step, are both further off than the tolerance by far
    seidel = Master(system).run(algorithm="gauss-seidel")
    single = Master(_slowed(fmu_root, name, {}, delay, stop)).run(algorithm="jacobi")
    for other in (seidel, single):
        assert np.abs(other["plant.q[2]"] - result["plant.q[2]"]).max() > 1e-7


@pytest.mark.parametrize("delay", [0, 1, 2])
def test_libcosim_holds_a_slow_controllers_effort_one_sample_late(fmu_root, tmp_path, delay):
    """libcosim transfers a decimated simulator's outputs when its step ends: the effort the
    controller (every 4 ms) computes from the plant's state at t_k reaches the plant at t_k+4, and
    is held over its next four steps (over the first sample, the effort of t_0, which
    initialization passed along). That is the hand-written sampled loop of tests/test_multirate.py
    (Pinocchio's CRBA and nonlinear effects for the law, RK4 on ABA at 1 ms for the plant) with
    max(d, 1) samples of delay: the Jacobi exchange's own sample of delay and the controller's d
    coincide for d = 1 (with d >= 1 its effort no longer depends on the inputs of its sample, so
    reading it before they are set loses nothing). The reference q_ref, qd_ref, qdd_ref is libcosim's
    own ik output (one base step late through each feedthrough block)."""
    from test_multirate import _hand_loop

    from robofmu.system.interop.osp import export_osp, run_osp_libcosim

    system = _slowed(fmu_root, "chess-pd", {"controller": 0.004}, delay, 1.0)
    result = run_osp_libcosim(export_osp(system, tmp_path / "osp"))
    gains = system.block("controller").parameters
    assert gains["ki"] == 0.0 and result.time.size == 1001
    q, qd, tau = _hand_loop(result, gains["kp"], gains["kd"], max(delay, 1), 1000)
    n = q.shape[1]
    lc_tau = np.column_stack([result[f"controller.tau[{j + 1}]"] for j in range(n)])
    np.testing.assert_allclose(lc_tau, tau, rtol=0, atol=1e-9 * np.abs(tau).max())
    for j in range(n):
        np.testing.assert_allclose(result[f"plant.q[{j + 1}]"], q[:, j], rtol=0, atol=1e-9)
        np.testing.assert_allclose(result[f"plant.qd[{j + 1}]"], qd[:, j], rtol=0, atol=1e-9)
    # the delay is visible: the loop one sample sooner (the master's Gauss-Seidel, d = 0) is elsewhere
    q_sooner, _, _ = _hand_loop(result, gains["kp"], gains["kd"], max(delay, 1) - 1, 1000)
    assert np.abs(q_sooner - q).max() > 1e-7

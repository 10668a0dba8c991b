"""Block sample rates and the controller's computation delay (issue 30, points 1, 2 and 7).

- single-rate runs of the one-pass planner and the master equal a loop stepped by hand through
  fmpy (:class:`fmu_util.Loop`, the plan's wires and order only), every column bit for bit;
- chess-pd with its controller at 4 ms (the rest at 1 ms) equals a loop written here from
  Pinocchio: the computed-torque law (CRBA and the nonlinear effects) sampled every 4 ms and held,
  the plant's RK4 at 1 ms on Pinocchio's ABA, to 1e-9;
- ``delay_steps`` = 1 outputs exactly the undelayed effort one controller sample later (the
  controller fed by the trajectory and the IK only, so its inputs do not depend on its output),
  and in the closed loop equals the hand-written loop with the same delay;
- a sample time that is no whole multiple of the base step is refused naming block and key, and
  the SSP and container exports refuse a multi-rate experiment in one line.
"""
from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from fmu_util import Loop
from robofmu.components.robots import load_description
from robofmu.system import experiment
from robofmu.system.master import Master
from robofmu.system.plan import DiagramError

CONTROLLER_SAMPLE = 0.004     # s
BASE = 0.001                  # s


def _multirate(fmu_root, delay: int = 0):
    system = experiment.load("chess-pd", fmu_dir=fmu_root)
    system.block("controller").sample_time = CONTROLLER_SAMPLE
    if delay:
        system.block("controller").parameters["delay_steps"] = delay
    return system


@pytest.mark.parametrize("name", ["chess-pd", "ur5-pose"])
def test_single_rate_runs_equal_the_hand_stepped_loop_bit_for_bit(fmu_root, name):
    stop = 0.3
    result = Master(experiment.load(name, fmu_dir=fmu_root)).run(stop_time=stop)
    loop = Loop(name, fmu_root)
    try:
        h = experiment.load(name, fmu_dir=fmu_root).step
        rows = []
        for t in result.time[:-1]:
            loop.t = t                          # the master's points, t0 + k h (not a running sum)
            rows.append(loop.step(h))
        rows.append(loop.exchange())
    finally:
        loop.close()
    assert len(rows) == len(result.time)
    for column in result.columns:
        expected = np.array([float(row[column]) for row in rows])
        np.testing.assert_array_equal(result[column], expected, err_msg=column)


def _pinocchio_chess():
    """chess's URDF through Pinocchio directly, its gravity from the description."""
    description = load_description("chess")
    model = pin.buildModelFromUrdf(str(description.urdf))
    model.gravity.linear = np.array([0.0, 0.0, -description.gravity])
    return model, model.createData(), description


def _hand_loop(result, kp: float, kd: float, delay: int, n_steps: int):
    """chess-pd's controller and plant written out: the law at every 4th base step from the
    plant's state there and the IK's reference there, held (and delayed by ``delay`` samples;
    before sample ``delay`` the effort of sample 0), the plant by classical RK4 over each 1 ms
    on Pinocchio's ABA. The reference (ik.q_ref, qd_ref, qdd_ref) is the run's own: it depends
    on no block of the loop. Returns q, qd (n_steps + 1, n) and the applied tau (n_steps + 1, n)."""
    model, data, _ = _pinocchio_chess()
    n = model.nq
    ref = {base: np.column_stack([result[f"ik.{base}[{j + 1}]"] for j in range(n)])
           for base in ("q_ref", "qd_ref", "qdd_ref")}
    q = np.array([result[f"plant.q[{j + 1}]"][0] for j in range(n)])
    qd = np.zeros(n)
    ratio = round(CONTROLLER_SAMPLE / BASE)
    qs, qds, taus, computed = [q], [qd], [], []
    tau = None

    def f(q, qd, tau):
        return qd, pin.aba(model, data, q, qd, tau).copy()

    for k in range(n_steps + 1):
        if k % ratio == 0:
            e, ed = ref["q_ref"][k] - q, ref["qd_ref"][k] - qd
            mass = pin.crba(model, data, q)
            mass = np.triu(mass) + np.triu(mass, 1).T
            computed.append(mass @ (ref["qdd_ref"][k] + kd * ed + kp * e) + pin.nonLinearEffects(model, data, q, qd))
            tau = computed[max(0, len(computed) - 1 - delay)]
        taus.append(tau)
        if k == n_steps:
            break
        h = BASE
        k1 = f(q, qd, tau)
        k2 = f(q + h / 2 * k1[0], qd + h / 2 * k1[1], tau)
        k3 = f(q + h / 2 * k2[0], qd + h / 2 * k2[1], tau)
        k4 = f(q + h * k3[0], qd + h * k3[1], tau)
        q = q + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        qd = qd + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        qs.append(q)
        qds.append(qd)
    return np.array(qs), np.array(qds), np.array(taus)


@pytest.mark.parametrize("delay", [0, 1])
def test_multirate_chess_pd_equals_a_hand_written_sampled_loop(fmu_root, delay):
    """Controller at 4 ms, the rest at 1 ms, for 1 s (the gripper stays open: no payload yet)."""
    system = _multirate(fmu_root, delay)
    stop = 1.0
    result = Master(system).run(stop_time=stop)
    assert result.info["sample_times"]["controller"] == CONTROLLER_SAMPLE
    assert not result["trajectory.grip"].any()
    gains = system.block("controller").parameters
    assert gains["ki"] == 0.0
    n_steps = round(stop / BASE)
    q, qd, tau = _hand_loop(result, gains["kp"], gains["kd"], delay, n_steps)
    n = q.shape[1]
    master_tau = np.column_stack([result[f"controller.tau[{j + 1}]"] for j in range(n)])
    # zero-order hold: tau changes only at the controller's samples
    changes = np.flatnonzero(np.any(np.diff(master_tau, axis=0) != 0.0, axis=1)) + 1
    assert set(changes) <= set(range(0, n_steps + 1, 4)) and len(changes) > 200
    np.testing.assert_allclose(master_tau, tau, rtol=0, atol=1e-9 * np.abs(tau).max())
    for j in range(n):
        np.testing.assert_allclose(result[f"plant.q[{j + 1}]"], q[:, j], rtol=0, atol=1e-9)
        np.testing.assert_allclose(result[f"plant.qd[{j + 1}]"], qd[:, j], rtol=0, atol=1e-9)
    # the sample time matters: the single-rate run is elsewhere by far more than the tolerance
    single = Master(experiment.load("chess-pd", fmu_dir=fmu_root)).run(stop_time=stop)
    assert np.abs(single["plant.q[2]"] - q[:, 1]).max() > 1e-7


def test_delay_steps_shifts_the_effort_by_exactly_one_controller_sample(fmu_root):
    """The controller fed by trajectory and IK only (q, qd held at home): its inputs do not depend
    on its effort, so d = 1 is d = 0 shifted by one sample (4 base steps), bit for bit."""
    runs = {}
    for delay in (0, 1):
        system = copy.deepcopy(_multirate(fmu_root, delay))
        system.blocks = [b for b in system.blocks if b.name != "plant"]
        system.wires = [w for w in system.wires if "plant" not in (w.src, w.dst)]
        runs[delay] = Master(system, record=["controller.tau"]).run(stop_time=0.5)
    ratio = round(CONTROLLER_SAMPLE / BASE)
    for column in runs[0].columns:
        undelayed, delayed = runs[0][column], runs[1][column]
        np.testing.assert_array_equal(delayed[ratio:], undelayed[:-ratio], err_msg=column)
        np.testing.assert_array_equal(delayed[:ratio], undelayed[:ratio], err_msg=column)    # sample 0's effort
        assert np.abs(undelayed[ratio:] - undelayed[:-ratio]).max() > 0.0    # the shift is visible


def test_a_sample_time_off_the_base_step_is_refused_naming_block_and_key(fmu_root, tmp_path, capsys):
    from robofmu.system.cli import main

    system = _multirate(fmu_root)
    system.block("controller").sample_time = 0.0025
    with pytest.raises(DiagramError) as info:
        Master(system).check()
    assert info.value.problems == ["block 'controller': sample_time = 0.0025 s is not a whole multiple of the "
                                   "base step 0.001 s"]
    file = tmp_path / "slow.toml"
    file.write_text('robot = "chess"\nloop = "computed-torque"\nstop_time = 0.1\nstep = 0.001\n\n'
                    '[[blocks]]\nname = "controller"\nsample_time = 0.0025\n')
    status = main(["run", str(file), "--fmus", str(fmu_root), "--out", str(tmp_path / "out")])
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert status == 2 and len(lines) == 1, lines
    assert "block 'controller': sample_time = 0.0025 s is not a whole multiple of the base step 0.001 s" in lines[0]
    assert str(file) in lines[0]
    # the same file at a multiple runs, the derived controller amended (its fmu and gains kept)
    file.write_text(file.read_text().replace("0.0025", "0.004"))
    loaded = experiment.load(file, fmu_dir=fmu_root)
    controller = loaded.block("controller")
    assert controller.sample_time == 0.004 and controller.fmu == "chess/controller.fmu" and controller.parameters["kp"] > 0
    file.write_text(file.read_text().replace("0.004", "-1"))
    with pytest.raises(experiment.ExperimentError, match=r"blocks\[1\]\.sample_time: must be a time in s > 0"):
        experiment.load(file, fmu_dir=fmu_root)


def test_exports_refuse_a_multirate_experiment_in_one_line(fmu_root, tmp_path):
    from robofmu.system.interop.container import export_container
    from robofmu.system.interop.ssp import export_ssp

    system = _multirate(fmu_root)
    said = ("chess-pd: multi-rate (controller every 0.004 s, the rest every 0.001 s): {} has no standard rate "
            "per component: robofmu exports it single-rate only (`robofmu osp` carries the rates)")
    with pytest.raises(ValueError) as info:
        export_ssp(system, tmp_path / "x.ssp")
    assert str(info.value) == said.format("SSP")
    with pytest.raises(ValueError) as info:
        export_container(system, tmp_path / "x.fmu")
    assert str(info.value) == said.format("an FMU container")
    assert not list(Path(tmp_path).iterdir())
    system.block("controller").sample_time = BASE             # a sample time equal to the step: single-rate
    assert export_ssp(system, tmp_path / "x.ssp").is_file()

"""The monolithic reference (continuous controller) and the co-simulation's convergence to it."""
from __future__ import annotations

import json

import numpy as np
import pytest

from robofmu.components.ik import make_ik
from robofmu.components.robot import Robot
from robofmu.system.convergence import observed_order, sampled_loop, study
from robofmu.system.experiment import load
from robofmu.system.master import Master
from robofmu.system.reference import LoopSetup, MonolithicLoop, discontinuities, reference_run

T_TASK = 13.0
GRIP_CLOSE, GRIP_OPEN = 6.0, 11.5


def sample_times(loop: MonolithicLoop, t_end: float, rng, k: int = 1500) -> np.ndarray:
    """Random times plus every discontinuity and points 1 us either side of each."""
    d = discontinuities(loop.trajectory, t_end)
    t = np.concatenate([[0.0, t_end], rng.uniform(0.0, t_end, k), d, d - 1e-6, d + 1e-6])
    return np.sort(t[(t >= 0.0) & (t <= t_end)])


@pytest.fixture(scope="module")
def perfect_pd():
    return MonolithicLoop(LoopSetup.from_robot("chess", "pd")).solve(T_TASK)


@pytest.fixture(scope="module")
def unknown_pawn_pd():
    return MonolithicLoop(LoopSetup.from_robot("chess", "pd", model_knows_payload=False)).solve(T_TASK)


# -- the reference itself -------------------------------------------------------------------------
def test_discontinuities_of_the_chess_task(perfect_pd):
    d = discontinuities(perfect_pd.trajectory, T_TASK)
    boundaries = [1.0, 1.5, 4.5, 5.0, 6.0, 6.5, 7.5, 8.0, 10.0, 10.5, 11.5, 12.0]
    moves = [(0.0, 1.0), (1.5, 4.5), (5.0, 6.0), (6.5, 7.5), (8.0, 10.0), (10.5, 11.5), (12.0, 13.0)]
    blends = [t for a, b in moves for t in (a + (b - a) / 3, b - (b - a) / 3)]
    np.testing.assert_allclose(d, np.sort(boundaries + blends), atol=1e-12)
    assert d.size == 26 and perfect_pd.stats["pieces"] == 27
    assert GRIP_CLOSE in d and GRIP_OPEN in d


@pytest.mark.parametrize("gains", ["pd", "pid"])
def test_perfect_model_from_rest_on_the_trajectory_tracks_it_exactly(gains, perfect_pd, rng):
    """Exact model, starting at rest on the trajectory: e'' + kd e' + kp e + ki z = 0 from zero
    initial conditions, so q(t) = IK(x_ref(t)) for the whole task, and the torque is the true
    arm's inverse dynamics along the reference (pawn included while gripped)."""
    loop = perfect_pd if gains == "pd" else MonolithicLoop(LoopSetup.from_robot("chess", "pid")).solve(T_TASK)
    t = sample_times(loop, T_TASK, rng)
    e = loop.evaluate(t)
    arm = Robot("chess")
    ik = make_ik(Robot("chess"))
    traj = LoopSetup.from_robot("chess").trajectory()
    q_err = qd_err = tau_err = tcp_err = 0.0
    for k, tk in enumerate(t):
        x, xd, xdd = traj.evaluate(tk)
        q, qd, qdd = ik.solve(x, xd, xdd)
        arm.set_payload(0.03 if traj.grip(tk) else 0.0)
        q_err = max(q_err, np.abs(e["q"][k] - q).max())
        qd_err = max(qd_err, np.abs(e["qd"][k] - qd).max())
        tau_err = max(tau_err, np.abs(e["tau"][k] - arm.inverse_dynamics(q, qd, qdd)).max())
        tcp_err = max(tcp_err, np.linalg.norm(arm.fk(e["q"][k]) - x))
    assert q_err < 1e-8          # rad (observed ~1e-12)
    assert qd_err < 1e-7         # rad/s
    assert tau_err < 1e-6        # N.m
    assert tcp_err < 1e-9        # m
    assert np.abs(e["z"]).max() < 1e-9


def test_unknown_pawn_error_only_while_gripped_and_after(unknown_pawn_pd, perfect_pd, rng):
    t = sample_times(unknown_pawn_pd, T_TASK, rng)
    e = unknown_pawn_pd.evaluate(t)
    err = np.abs(e["q"] - e["q_ref"]).max(axis=1)
    tcp = np.linalg.norm(e["tcp"] - e["x_ref"], axis=1)
    before, held = t <= GRIP_CLOSE, (t > GRIP_CLOSE) & (t < GRIP_OPEN)
    assert err[before].max() < 1e-9
    assert err[held].max() == pytest.approx(1.275e-2, rel=5e-3)     # rad (regression value)
    assert tcp[held].max() == pytest.approx(1.149e-3, rel=5e-3)     # m
    # once the pawn is released the model is exact again: the error decays like exp(-zeta wn t),
    # zeta wn = kd / 2 = 10 1/s, from ~1e-2 rad
    assert err[(t > GRIP_OPEN) & (t < GRIP_OPEN + 0.1)].max() > 1e-3
    assert err[t > GRIP_OPEN + 1.0].max() < 1e-2 * np.exp(-10.0 * 1.0) * 2
    # the pawn pulls the TCP down: a PD loop with an unknown 30 g sags below the reference
    assert (e["tcp"][held, 2] - e["x_ref"][held, 2]).mean() < 0.0


def test_unknown_pawn_static_error_matches_gravity_mismatch():
    """After a long pause with the pawn gripped, PD computed torque settles where
    kp M_model(q) e = g_true(q) - g_model(q): an independent check of the payload handling."""
    setup = LoopSetup.from_robot("chess", "pd", model_knows_payload=False, pause=3.0)
    loop = MonolithicLoop(setup)
    assert loop.trajectory.grip_close_time == pytest.approx(11.0)
    loop.solve(13.9)
    e = loop.evaluate([13.9])
    q = e["q"][0]
    true, model = Robot("chess"), Robot("chess")
    true.set_payload(0.03)
    predicted = np.linalg.solve(model.mass_matrix(q), true.gravity_torque(q) - model.gravity_torque(q)) / setup.kp
    np.testing.assert_allclose(e["q_ref"][0] - q, predicted, atol=1e-10)
    assert np.abs(predicted).max() > 1e-3
    assert np.abs(e["qd"][0]).max() < 1e-9


def test_setup_from_system_reads_block_parameters(fmu_dir):
    pid = LoopSetup.from_system(load("chess-pid-unknown-pawn", fmu_dir=fmu_dir.parent))
    assert (pid.kp, pid.kd, pid.ki) == (600.0, 25.0, 75.0)
    assert pid.model_payload == 0.0 and pid.payload == 0.03
    assert pid.gravity == pid.model_gravity == 9.81
    np.testing.assert_allclose(pid.q0, make_ik(Robot("chess")).position(np.array([0.21, 0.0, 0.0])),
                               atol=1e-15)
    assert pid.grip_close_after_move == 3 and pid.grip_open_after_move == 6
    system = load("chess-pd", fmu_dir=fmu_dir.parent)
    system.block("plant").parameters.update(q0=[0.1, 0.8, -2.3, 0.0], g=9.0)
    pd = LoopSetup.from_system(system)
    assert (pd.kp, pd.kd, pd.ki, pd.model_payload) == (400.0, 20.0, 0.0, 0.03)
    assert pd.gravity == 9.0 and pd.model_gravity == 9.81
    np.testing.assert_array_equal(pd.q0, [0.1, 0.8, -2.3, 0.0])


def test_reference_run_is_recorded_like_a_cosimulation(fmu_dir):
    system = load("chess-pid", fmu_dir=fmu_dir.parent)
    times = np.linspace(0.0, 2.0, 201)
    ref = reference_run(system, times)
    assert ref.vector("plant.q").shape == (201, 4)
    assert ref["controller.tau[2]"].shape == (201,)
    np.testing.assert_allclose(ref.vector("plant.q"), ref.vector("ik.q_ref"), atol=1e-9)


# -- the co-simulation against it ------------------------------------------------------------------
def test_gauss_seidel_and_jacobi_converge_at_first_order(fmu_dir, tmp_path):
    """2 s window, h = 8, 4, 2, 1 ms: the error is O(h) (zero-order hold of the torque, forward
    Euler on the integral, whole-step delays), Jacobi's constant is larger."""
    system = load("chess-pd", fmu_dir=fmu_dir.parent)
    res = study(system, (0.008, 0.004, 0.002, 0.001), tmp_path, stop_time=2.0, progress=None)
    for a in ("gauss-seidel", "jacobi"):
        errs = [r["q_error"] for r in res["rows"] if r["algorithm"] == a]
        assert all(e1 < e0 for e0, e1 in zip(errs, errs[1:]))
        assert 0.9 <= res["orders"][a]["q"] <= 1.2, res["table"]
        assert 0.9 <= res["orders"][a]["tcp"] <= 1.25, res["table"]
    gs = [r for r in res["rows"] if r["algorithm"] == "gauss-seidel"]
    jac = [r for r in res["rows"] if r["algorithm"] == "jacobi"]
    assert all(j["q_error"] > g["q_error"] for g, j in zip(gs, jac))
    assert gs[-1]["q_error"] < 1.5e-3                       # rad at h = 1 ms
    saved = json.loads((tmp_path / "convergence.json").read_text())
    assert saved["orders"]["gauss-seidel"]["q"] == pytest.approx(res["orders"]["gauss-seidel"]["q"])
    assert (tmp_path / "convergence.png").stat().st_size > 1000
    assert "| gauss-seidel | 8 |" in (tmp_path / "convergence.md").read_text()


def test_sampled_loop_converges_at_first_order(perfect_pd):
    steps = (0.008, 0.004, 0.002, 0.001)
    errs = []
    for h in steps:
        r = sampled_loop(perfect_pd.setup, h, 2.0)
        errs.append(np.abs(r.vector("plant.q") - perfect_pd.evaluate(r.time, outputs=False)["q"]).max())
    assert 0.9 <= observed_order(steps, errs) <= 1.1
    assert errs[-1] < 3e-4


def test_gauss_seidel_applies_the_torque_of_the_same_point(fmu_dir):
    """The co-simulation equals an in-process replay of the sampled loop in which the plant
    integrates [t_k, t_k + h] with the torque the controller computed at t_k."""
    system = load("chess-pd", fmu_dir=fmu_dir.parent)
    setup = LoopSetup.from_system(system)
    cosim = Master(system).run(stop_time=0.5, step=0.005)
    replica = sampled_loop(setup, 0.005, 0.5)
    assert cosim.columns == replica.columns
    np.testing.assert_array_equal(cosim.data, replica.data)      # call for call, bit for bit


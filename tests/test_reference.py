"""The in-process diagram: a replica of the master bit for bit, and the monolithic reference
(continuous controller) the co-simulation converges to, for every robot's experiment."""
from __future__ import annotations

import json

import numpy as np
import pytest

from robofmu.components.ik import make_solver
from robofmu.components.robots import load_description, load_model
from robofmu.system.studies.convergence import observed_order, study
from robofmu.system.experiment import load
from robofmu.system.master import Master
from robofmu.system.fmu import block_identity
from robofmu.system.studies.replica import InProcessDiagram

EXPERIMENTS = ["chess-pd", "rrp-line", "rpp-bangbang"]
CHESS_TASK = 13.0
GRIP_CLOSE, GRIP_OPEN = 6.0, 11.5


def sample_times(breaks: np.ndarray, t_end: float, rng, k: int = 1500) -> np.ndarray:
    """Random times plus every breakpoint and points 1 us either side of each."""
    t = np.concatenate([[0.0, t_end], rng.uniform(0.0, t_end, k), breaks, breaks - 1e-6, breaks + 1e-6])
    return np.sort(t[(t >= 0.0) & (t <= t_end)])


@pytest.fixture(scope="module")
def chess_pd(fmu_root):
    diagram = InProcessDiagram(load("chess-pd", fmu_dir=fmu_root))
    return diagram, diagram.monolithic(CHESS_TASK)


@pytest.fixture(scope="module")
def chess_unknown_pawn(fmu_root):
    diagram = InProcessDiagram(load("chess-pd-unknown-pawn", fmu_dir=fmu_root))
    return diagram, diagram.monolithic(CHESS_TASK)


# -- the diagram as the FMUs describe it ---------------------------------------------------------
def test_blocks_come_from_the_fmus_annotations(fmu_root):
    identity = block_identity(fmu_root / "rrp" / "trajectory.fmu")
    assert (identity["robot"], identity["kind"], identity["variant"]) == ("rrp", "trajectory", "line")
    diagram = InProcessDiagram(load("rpp-bangbang", fmu_dir=fmu_root))
    assert diagram.order == ["trajectory", "plant", "controller", "fk"]
    assert type(diagram.blocks["trajectory"]).__name__ == "JointBangBangBlock"


def test_parameters_come_from_the_fmu_start_values_and_the_experiment(fmu_root):
    system = load("chess-pid-unknown-pawn", fmu_dir=fmu_root)
    system.block("plant").parameters.update(q0=[0.1, 0.8, -2.3, 0.0], g=9.0)
    blocks = InProcessDiagram(system).blocks
    controller, plant = blocks["controller"], blocks["plant"]
    assert [controller.get(k) for k in ("kp", "kd", "ki", "payload_mass", "g")] == [600.0, 25.0, 75.0, 0.0, 9.81]
    assert plant.get("payload_mass") == 0.03 and plant.get("g") == 9.0
    np.testing.assert_array_equal(plant.get("q0"), [0.1, 0.8, -2.3, 0.0])
    assert blocks["trajectory"].get("grip_close_after_move") == 3
    home = InProcessDiagram(load("rrp-line", fmu_dir=fmu_root)).blocks["plant"].get("q0")
    np.testing.assert_array_equal(home, load_description("rrp").configuration("home"))


@pytest.mark.parametrize("name", EXPERIMENTS)
def test_in_process_replica_equals_the_master_bit_for_bit(fmu_root, name):
    """The co-simulation equals the in-process Gauss-Seidel loop in which every block advances
    over [t_k, t_k + h] with the inputs of t_k: call for call, bit for bit."""
    system = load(name, fmu_dir=fmu_root)
    cosim = Master(system).run(stop_time=0.5, step=0.005)
    replica = InProcessDiagram(system).sampled(0.005, 0.5)
    assert sorted(cosim.columns) == sorted(replica.columns)
    for column in cosim.columns:
        np.testing.assert_array_equal(cosim[column], replica[column], err_msg=column)
    assert replica.units == cosim.units


# -- the reference itself -------------------------------------------------------------------------
# (chess_pd runs the 13 s chess task once per module, a few seconds: every test using it is slow)
@pytest.mark.slow
def test_breakpoints_of_the_chess_task(chess_pd):
    diagram, mono = chess_pd
    breaks = diagram.blocks["trajectory"].breakpoints()
    boundaries = [0.0, 1.0, 1.5, 4.5, 5.0, 6.0, 6.5, 7.5, 8.0, 10.0, 10.5, 11.5, 12.0, 13.0]
    moves = [(0.0, 1.0), (1.5, 4.5), (5.0, 6.0), (6.5, 7.5), (8.0, 10.0), (10.5, 11.5), (12.0, 13.0)]
    blends = [t for a, b in moves for t in (a + (b - a) / 3, b - (b - a) / 3)]
    np.testing.assert_allclose(breaks, np.sort(boundaries + blends), atol=1e-12)
    assert mono.stats["pieces"] == 27
    assert diagram.blocks["trajectory"].events() == {"grip closes": GRIP_CLOSE, "grip opens": GRIP_OPEN}


@pytest.mark.slow
def test_perfect_model_from_rest_on_the_trajectory_tracks_it_exactly(chess_pd, rng):
    """Exact model, starting at rest on the trajectory: e'' + kd e' + kp e = 0 from zero initial
    conditions, so q(t) = IK(x_ref(t)) for the whole task, and the torque is the true arm's
    inverse dynamics along the reference (pawn included while gripped)."""
    diagram, mono = chess_pd
    trajectory = diagram.blocks["trajectory"]
    t = sample_times(trajectory.breakpoints(), CHESS_TASK, rng)
    ref = mono.evaluate(t)
    arm = load_model("chess")
    ik = make_solver(load_model("chess"))
    q_err = qd_err = tau_err = tcp_err = 0.0
    for k, tk in enumerate(t):
        x, xd, xdd = trajectory.profile.evaluate(tk)
        q, qd, qdd = ik.solve(x, xd, xdd)
        arm.set_payload(0.03 if trajectory.profile.grip(tk) else 0.0)
        q_err = max(q_err, np.abs(ref.vector("plant.q")[k] - q).max())
        qd_err = max(qd_err, np.abs(ref.vector("plant.qd")[k] - qd).max())
        tau_err = max(tau_err, np.abs(ref.vector("controller.tau")[k] - arm.inverse_dynamics(q, qd, qdd)).max())
        tcp_err = max(tcp_err, np.linalg.norm(arm.fk(ref.vector("plant.q")[k]) - x))
    assert q_err < 1e-8          # rad (observed ~1e-12)
    assert qd_err < 1e-7         # rad/s
    assert tau_err < 1e-6        # N.m
    assert tcp_err < 1e-9        # m


@pytest.mark.slow
def test_unknown_pawn_error_only_while_gripped_and_after(chess_unknown_pawn, rng):
    diagram, mono = chess_unknown_pawn
    t = sample_times(diagram.blocks["trajectory"].breakpoints(), CHESS_TASK, rng)
    ref = mono.evaluate(t)
    err = np.abs(ref.vector("plant.q") - ref.vector("ik.q_ref")).max(axis=1)
    arm = load_model("chess")
    tcp = np.array([arm.fk(q) for q in ref.vector("plant.q")])
    x_ref = ref.vector("trajectory.x_ref")
    distance = np.linalg.norm(tcp - x_ref, axis=1)
    before, held = t <= GRIP_CLOSE, (t > GRIP_CLOSE) & (t < GRIP_OPEN)
    assert err[before].max() < 1e-9
    assert err[held].max() == pytest.approx(1.275e-2, rel=5e-3)     # rad (regression value)
    assert distance[held].max() == pytest.approx(1.149e-3, rel=5e-3)     # m
    # once the pawn is released the model is exact again: the error decays like exp(-zeta wn t),
    # zeta wn = kd / 2 = 10 1/s, from ~1e-2 rad
    assert err[(t > GRIP_OPEN) & (t < GRIP_OPEN + 0.1)].max() > 1e-3
    assert err[t > GRIP_OPEN + 1.0].max() < 1e-2 * np.exp(-10.0 * 1.0) * 2
    # the pawn pulls the TCP down: a PD loop with an unknown 30 g sags below the reference
    assert (tcp[held, 2] - x_ref[held, 2]).mean() < 0.0


def test_unknown_pawn_static_error_matches_gravity_mismatch(fmu_root):
    """After a long pause with the pawn gripped, PD computed torque settles where
    kp M_model(q) e = g_true(q) - g_model(q): an independent check of the payload handling."""
    system = load("chess-pd-unknown-pawn", fmu_dir=fmu_root)
    system.block("trajectory").parameters["pause"] = 3.0
    diagram = InProcessDiagram(system)
    diagram.configure()
    assert diagram.blocks["trajectory"].events()["grip closes"] == pytest.approx(11.0)
    ref = diagram.monolithic(13.9).evaluate([13.9])
    q, q_ref = ref.vector("plant.q")[0], ref.vector("ik.q_ref")[0]
    true, model = load_model("chess"), load_model("chess")
    true.set_payload(0.03)
    kp = diagram.blocks["controller"].get("kp")
    predicted = np.linalg.solve(model.mass_matrix(q), true.gravity_torque(q) - model.gravity_torque(q)) / kp
    np.testing.assert_allclose(q_ref - q, predicted, atol=1e-10)
    assert np.abs(predicted).max() > 1e-3
    assert np.abs(ref.vector("plant.qd")[0]).max() < 1e-9


@pytest.mark.parametrize("name", ["rrp-line", "rpp-bangbang"])
def test_exact_model_reference_follows_the_joint_reference(fmu_root, name, rng):
    """Every robot's reference from rest on its trajectory tracks the joint reference exactly."""
    system = load(name, fmu_dir=fmu_root)
    diagram = InProcessDiagram(system)
    mono = diagram.monolithic(system.stop_time)
    roles = system.extra["roles"]
    breaks = np.concatenate([b.breakpoints() for b in diagram.blocks.values()])
    ref = mono.evaluate(sample_times(breaks, system.stop_time, rng, 400))
    assert np.abs(ref.vector(roles["q"]) - ref.vector(roles["q_ref"])).max() < 1e-8


# -- the co-simulation against it ------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.study
def test_gauss_seidel_and_jacobi_converge_at_first_order(fmu_root, tmp_path):
    """2 s window, h = 8, 4, 2, 1 ms: the error is O(h) (zero-order hold of the torque, forward
    Euler on the integral, whole-step delays), Jacobi's constant is larger."""
    system = load("chess-pd", fmu_dir=fmu_root)
    res = study(system, (0.008, 0.004, 0.002, 0.001), tmp_path, stop_time=2.0, progress=None)
    for a in ("gauss-seidel", "jacobi"):
        errs = [r.q_error for r in res.runs_of(a)]
        assert all(e1 < e0 for e0, e1 in zip(errs, errs[1:]))
        assert 0.9 <= res.orders[a].q <= 1.2, res.table
        assert 0.9 <= res.orders[a].tcp <= 1.25, res.table
    gs, jac = res.runs_of("gauss-seidel"), res.runs_of("jacobi")
    assert all(j.q_error > g.q_error for g, j in zip(gs, jac))
    assert gs[-1].q_error < 1.5e-3                          # rad at h = 1 ms
    saved = json.loads((tmp_path / "convergence.json").read_text())
    assert saved["orders"]["gauss-seidel"]["q"] == pytest.approx(res.orders["gauss-seidel"].q)
    assert (tmp_path / "convergence.png").stat().st_size > 1000
    assert "| gauss-seidel | 8 |" in (tmp_path / "convergence.md").read_text()


@pytest.mark.slow
@pytest.mark.study
@pytest.mark.parametrize("name", ["rrp-line", "rpp-bangbang"])
def test_every_robot_converges_to_its_reference_at_first_order(fmu_root, name):
    """Error <= C h at every step and a least-squares order of about 1. The bang-bang switches
    (T/2 = 0.72360 s, T = 1.44721 s) fall between communication points: the sampled controller
    misses the acceleration step for the rest of that step (0.4 ms for h = 1 and 2 ms alike), an
    error proportional to that miss (<= h), which scatters the local order around 1."""
    system = load(name, fmu_dir=fmu_root)
    steps = (0.01, 0.005, 0.002, 0.001)
    res = study(system, steps, None, algorithms=("gauss-seidel", "in-process"), progress=None)
    assert 0.9 <= res.orders["gauss-seidel"].q <= 1.3, res.table
    rows = {a: res.runs_of(a) for a in ("gauss-seidel", "in-process")}
    for row, h in zip(rows["gauss-seidel"], steps):
        assert row.q_error <= 0.1 * h, res.table                # rad or m; C <= 0.1 per second
    assert rows["gauss-seidel"][-1].q_error < 1e-4              # within 0.1 mrad / 0.1 mm at 1 ms
    for gs, replica in zip(rows["gauss-seidel"], rows["in-process"]):
        assert gs.q_error == replica.q_error                    # the replica is the master, bit for bit


@pytest.mark.slow
@pytest.mark.study
def test_in_process_loop_converges_at_first_order(chess_pd):
    diagram, mono = chess_pd
    steps = (0.008, 0.004, 0.002, 0.001)
    errs = []
    for h in steps:
        r = diagram.sampled(h, 2.0)
        errs.append(np.abs(r.vector("plant.q") - mono.evaluate(r.time).vector("plant.q")).max())
    assert 0.9 <= observed_order(steps, errs) <= 1.1
    assert errs[-1] < 3e-4


def test_the_replica_refuses_a_block_with_a_sample_time_of_its_own(fmu_root):
    """The in-process replica and the monolithic reference step every block at the base step: a
    multi-rate experiment (the controller at 4 ms) is refused naming the block, not run wrongly."""
    from dataclasses import replace

    system = load("chess-pd", fmu_dir=fmu_root)
    blocks = [replace(b, sample_time=4 * system.step) if b.name == "controller" else b for b in system.blocks]
    with pytest.raises(ValueError, match="blocks controller have a sample time of their own"):
        InProcessDiagram(replace(system, blocks=blocks))
    same = [replace(b, sample_time=system.step) for b in system.blocks]
    InProcessDiagram(replace(system, blocks=same))            # the base step itself is no other rate

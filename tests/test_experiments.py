"""The closed loops of the new robots through the master (1 ms), against their references."""
from __future__ import annotations

import numpy as np
import pytest

from robofmu.components.robots import load_model
from robofmu.components.trajectory import StraightLine
from robofmu.system import experiment
from robofmu.system.analysis import tracking_metrics
from robofmu.system.master import Master
from robofmu.system.roles import Roles


def run(name, fmu_root):
    system = experiment.load(name, fmu_dir=fmu_root)
    return system, Master(system).run()


def test_rrp_line_keeps_the_tcp_within_0_1_mm_of_the_path(fmu_root):
    system, result = run("rrp-line", fmu_root)
    line = StraightLine([0.125, 0.0, 0.125], -np.array([1.0, 1.0, 2.0]) / np.sqrt(6.0), 0.03125, 0.016, 0.0375)
    assert line.t1 == pytest.approx(0.42667, abs=5e-6) and line.duration == pytest.approx(2.3798, abs=5e-5)
    model = load_model("rrp")
    q = result.vector("plant.q")
    tcp = np.array([model.fk(v) for v in q])
    # distance to the straight line itself (independent of the timing) and to the reference point
    d = tcp - line.start
    off_line = np.linalg.norm(d - np.outer(d @ line.direction, line.direction), axis=1)
    assert off_line.max() < 1e-4
    x_ref = np.array([line.evaluate(t)[0] for t in result.time])
    np.testing.assert_allclose(result.vector("trajectory.x_ref"), x_ref, rtol=0, atol=1e-15)
    assert np.linalg.norm(tcp - x_ref, axis=1).max() < 1e-4
    metrics = tracking_metrics(result, Roles.of(system))              # every task coordinate is a length
    np.testing.assert_allclose(metrics.tcp_error, np.linalg.norm(tcp - x_ref, axis=1), rtol=0, atol=1e-15)
    assert metrics.orientation_error is None
    np.testing.assert_allclose(result.vector("fk.x"), tcp, rtol=0, atol=1e-15)
    np.testing.assert_allclose(tcp[-1], line.end, atol=1e-6)       # at rest at the end of the line
    assert np.abs(result.vector("plant.qd")[-1]).max() < 1e-6
    assert result.units["controller.tau[3]"] == "N" and result.units["plant.q[3]"] == "m"


def test_rpp_bangbang_tracks_within_1_mrad_1_mm_and_ends_at_rest(fmu_root):
    system, result = run("rpp-bangbang", fmu_root)
    roles = Roles.of(system)
    m = tracking_metrics(result, roles)
    assert m.joint_units == ["rad", "m", "m"] and m.effort_units == ["N.m", "N", "N"]
    assert m.max_error.max() < 1e-3
    q_end = result.vector("plant.q")[-1]
    np.testing.assert_allclose(q_end, [np.pi / 2, 2.0, 2.0], atol=1e-6)
    assert np.abs(result.vector("plant.qd")[-1]).max() < 1e-5
    # the reference: synchronized bang-bang, T = 2 sqrt((pi/2) / 3), every joint at T/2 halfway
    T = 2.0 * np.sqrt((np.pi / 2) / 3.0)
    k = int(np.searchsorted(result.time, T / 2)) - 1             # the last point before the switch
    t = result.time[k]
    assert T / 2 - 1e-3 < t < T / 2
    a = 4.0 * np.array([np.pi / 2, 1.0, 1.0]) / T ** 2
    np.testing.assert_allclose(result.vector("trajectory.q_ref")[k], [0, 1, 1] + 0.5 * a * t ** 2, atol=1e-12)
    # the peak efforts are the inverse dynamics along the reference (perfect model), plus the
    # feedback on the tracking error the held effort leaves just after the switch (1 % on q2)
    model = load_model("rpp")
    qdd_ref, qd_ref, q_ref = (result.vector(f"trajectory.{b}") for b in ("qdd_ref", "qd_ref", "q_ref"))
    ideal = np.array([model.inverse_dynamics(*v) for v in zip(q_ref, qd_ref, qdd_ref)])
    np.testing.assert_allclose(m.peak_effort, np.abs(ideal).max(axis=0), rtol=0.015)


# Seed 003: LSPB waypoints through Newton-Raphson IK (warm-started from the last step's solution).
# (experiment, joints at the start, waypoints after the start, segment end times, stop time)
NR_RUNS = {
    "planar2r-nr": ([0.0, 1.0], [[1.2, 0.6], [0.6, 1.2]], [1.0, 3.5], 4.0),
    "rrp_offset-nr": ([0.0, 0.5, 0.5], [[-0.6, 0.4, 1.5], [-0.3, 0.7, 1.2]], [2.0, 4.5], 5.0),
}


@pytest.mark.parametrize("name", sorted(NR_RUNS))
def test_newton_raphson_runs_track_the_waypoints_within_0_1_mm(name, fmu_root):
    q0, waypoints, ends, stop = NR_RUNS[name]
    system, result = run(name, fmu_root)
    assert system.step == 0.001 and system.stop_time == stop and system.algorithm == "gauss-seidel"
    assert [b.name for b in system.blocks] == ["trajectory", "ik", "controller", "plant", "fk"]
    controller = next(b for b in system.blocks if b.name == "controller")
    assert (controller.parameters["kp"], controller.parameters["kd"]) == (400.0, 40.0)
    model = load_model(system.extra["robot"])
    assert len(result.time) == round(stop / 0.001) + 1 and result.time[-1] == pytest.approx(stop)
    x_ref = result.vector("trajectory.x_ref")
    np.testing.assert_allclose(x_ref[0], model.fk(np.array(q0)), atol=1e-15)
    for t, point in zip(ends, waypoints):              # the reference passes through the waypoints
        k = int(np.argmin(np.abs(result.time - t)))
        np.testing.assert_allclose(x_ref[k], point, atol=1e-12)
    # the TCP: the FK block's output is FK of the plant's q, within 0.1 mm of the reference throughout
    tcp = np.array([model.fk(v) for v in result.vector("plant.q")])
    np.testing.assert_allclose(result.vector("fk.x"), tcp, rtol=0, atol=1e-15)
    assert np.linalg.norm(tcp - x_ref, axis=1).max() < 1e-4
    # the IK found a solution at every communication point, in at most 3 Newton iterations after the
    # first point (warm start), to the tolerance of 1e-12 m
    assert result["ik.reachable"].min() == 1.0
    iterations, residual = result["ik.iterations"], result["ik.residual"]
    assert np.all(iterations == np.round(iterations)) and iterations[1:].max() <= 3
    assert residual.max() <= 1e-12
    assert result.units["ik.iterations"] == "1" and result.units["ik.residual"] == "m"
    # it is the robot's own solution: FK(q_ref) is the reference
    np.testing.assert_allclose([model.fk(v) for v in result.vector("ik.q_ref")], x_ref, rtol=0, atol=1e-11)
    # at rest at the last waypoint
    np.testing.assert_allclose(tcp[-1], waypoints[-1], atol=1e-6)
    assert np.abs(result.vector("plant.qd")[-1]).max() < 1e-6
    assert np.abs(result.vector("trajectory.xd_ref")[-1]).max() == 0.0
    assert iterations[-1] == 0                            # at rest: the warm start is already the solution


# -- seed 004: the planar 3-RRP parallel mechanism ---------------------------------------------------------
HOME_POSE = np.array([0.0, 0.0, -np.pi / 3])          # robots.md section 5: q = (0, 120, 240 degrees)


def loop_closure_residual(model, q, pose):
    """Distances (m) of each leg's tip Q_i = r (cos q_i, sin q_i) from its line through Z = (x, y)
    at angle theta + alpha_i, shape (k, 3): zero where q and the pose close the three loops."""
    phi = pose[:, 2:3] + model.alpha
    tip = model.r * np.stack([np.cos(q), np.sin(q)], axis=-1) - pose[:, None, :2]
    return -tip[..., 0] * np.sin(phi) + tip[..., 1] * np.cos(phi)


def circle_phase(t, T=4.0, c=1.5):
    """robots.md's phase: phi 0 -> 2 pi in T by LSPB, cruise rate c times the mean rate."""
    v = c * 2 * np.pi / T
    tb = T - 2 * np.pi / v
    a = v / tb
    t = np.clip(t, 0.0, T)
    return np.where(t < tb, 0.5 * a * t ** 2, np.where(t <= T - tb, 0.5 * a * tb ** 2 + v * (t - tb),
                                                       2 * np.pi - 0.5 * a * (T - t) ** 2))


def check_pose_outputs(model, result):
    """plant.x is FK(plant.q), fk.x the same; the loop closures hold; jacobian.J is J(plant.q)."""
    q, pose = result.vector("plant.q"), result.vector("plant.x")
    np.testing.assert_allclose(pose, model.fk_many(q), rtol=0, atol=1e-15)
    np.testing.assert_allclose(result.vector("fk.x"), pose, rtol=0, atol=1e-15)
    assert np.abs(loop_closure_residual(model, q, pose)).max() < 1e-12
    J = result.vector("jacobian.J").reshape(-1, 3, 3)
    for k in (0, len(q) // 2, len(q) - 1):
        np.testing.assert_allclose(J[k], model.jacobian(q[k]), rtol=0, atol=1e-14)


def test_3rrp_circle_tracks_the_pose_within_0_1_mm_and_0_1_mrad_and_ends_at_rest(fmu_root):
    system, result = run("3rrp-circle", fmu_root)
    assert system.step == 0.001 and system.stop_time == 5.0 and system.algorithm == "gauss-seidel"
    assert [b.name for b in system.blocks] == ["trajectory", "ik", "controller", "plant", "fk", "jacobian"]
    controller = system.block("controller")
    assert (controller.parameters["kp"], controller.parameters["kd"]) == (400.0, 40.0)
    model = load_model("3rrp")
    t = result.time
    assert len(t) == 5001 and t[-1] == pytest.approx(5.0)
    # the reference is robots.md's circle from the home pose, once round in 4 s, then at rest
    phi = circle_phase(t)
    expected = np.stack([0.05 * (1 - np.cos(phi)), 0.05 * np.sin(phi),
                         -np.pi / 3 + np.radians(15.0) * np.sin(phi)], axis=1)
    x_ref = result.vector("trajectory.x_ref")
    np.testing.assert_allclose(x_ref, expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(x_ref[0], HOME_POSE, atol=1e-15)
    np.testing.assert_allclose(model.fk(np.array(model.configuration("home"))), HOME_POSE, atol=1e-15)
    k = int(np.argmin(np.abs(t - 2.0)))                  # halfway: the far side of the circle
    np.testing.assert_allclose(x_ref[k], [0.1, 0.0, -np.pi / 3], atol=1e-12)
    # the IK solved every point, on its own branch: FK(q_ref) is the reference
    assert result["ik.reachable"].min() == 1.0
    np.testing.assert_allclose(model.fk_many(result.vector("ik.q_ref")), x_ref, rtol=0, atol=1e-12)
    # the pose (the plant's output) within 0.1 mm in (x, y) and 0.1 mrad in theta throughout
    pose = result.vector("plant.x")
    position_error = np.linalg.norm(pose[:, :2] - x_ref[:, :2], axis=1)
    angle_error = np.abs(pose[:, 2] - x_ref[:, 2])
    assert position_error.max() < 1e-4 and angle_error.max() < 1e-4
    # the report's task-point error is the distance in (x, y) (m), the angle apart (rad): not one
    # norm over metres and radians
    metrics = tracking_metrics(result, Roles.of(system))
    np.testing.assert_allclose(metrics.tcp_error, position_error, rtol=0, atol=1e-15)
    np.testing.assert_allclose(metrics.orientation_error, angle_error, rtol=0, atol=1e-15)
    check_pose_outputs(model, result)
    # at rest at home at the end
    np.testing.assert_allclose(pose[-1], HOME_POSE, atol=1e-9)
    assert np.abs(result.vector("plant.qd")[-1]).max() < 1e-6
    assert np.abs(result.vector("trajectory.xd_ref")[-1]).max() == 0.0


# Seed 004's four load cases (f_ext = (Fx N, Fy N, Mz N.m)), each under the PD holding home and unactuated.
LOADS = {"fx": [-1e-3, 0.0, 0.0], "fy": [0.0, -1e-3, 0.0], "fxy": [-1e-3, -1e-3, 0.0], "mz": [0.0, 0.0, -1e-3]}
HELD = {"fx": "3rrp-disturbance", "fy": "3rrp-disturbance-fy", "fxy": "3rrp-disturbance-fxy",
        "mz": "3rrp-disturbance-mz"}


def test_3rrp_disturbance_experiments_are_listed_and_built_on_two_bases():
    runnable = experiment.available()
    names = set(HELD.values()) | {f"3rrp-disturbance-unactuated-{case}" for case in LOADS}
    assert names <= set(runnable) and "3rrp-circle" in runnable
    assert "3rrp-held" not in runnable and "3rrp-unactuated" not in runnable      # the abstract bases
    for case, load in LOADS.items():
        held = experiment.load(HELD[case])
        free = experiment.load(f"3rrp-disturbance-unactuated-{case}")
        assert held.block("plant").parameters["f_ext"] == load == free.block("plant").parameters["f_ext"]
        assert held.stop_time == free.stop_time == 5.0 and held.step == free.step == 0.001
        assert "controller" not in [b.name for b in free.blocks]
        assert free.block("plant").parameters["tau"] == [0.0, 0.0, 0.0]
        assert not any(w.dst == "plant" for w in free.wires)          # nothing drives the plant's inputs


@pytest.mark.parametrize("case", sorted(LOADS))
def test_3rrp_disturbance_under_the_pd_deflects_as_the_jacobian_predicts(case, fmu_root):
    """At rest under the load, M(q) kp (q_ref - q) + J^T f = 0 (computed torque, tau = M (kp e -
    kd qd) + N): dq = M(home)^-1 J^T f / kp, the pose change J dq."""
    system, result = run(HELD[case], fmu_root)
    model = load_model("3rrp")
    home = np.array(model.configuration("home"))
    kp = system.block("controller").parameters["kp"]
    assert (kp, system.block("controller").parameters["kd"]) == (400.0, 40.0)
    f = np.array(LOADS[case])
    q, pose = result.vector("plant.q"), result.vector("plant.x")
    # the reference is constant: IK of the home pose
    np.testing.assert_allclose(result.vector("ik.q_ref"), np.tile(home, (len(q), 1)), rtol=0, atol=1e-14)
    np.testing.assert_allclose(pose[0], HOME_POSE, atol=1e-15)
    J = result.vector("jacobian.J")[0].reshape(3, 3)               # the jacobian block's J(home)
    dq = np.linalg.solve(model.mass_matrix(home), J.T @ f) / kp
    predicted = J @ dq
    deflection = pose[-1] - pose[0]
    assert np.linalg.norm(deflection - predicted) < 0.01 * np.linalg.norm(predicted)
    assert np.linalg.norm(q[-1] - home - dq) < 0.01 * np.linalg.norm(dq)
    # settled: at rest, and the last second moves the pose by less than 1e-6 of the deflection
    assert np.abs(result.vector("plant.qd")[-1]).max() < 1e-9
    k = int(np.argmin(np.abs(result.time - 4.0)))
    assert np.abs(pose[-1] - pose[k]).max() < 1e-6 * np.abs(predicted).max()
    check_pose_outputs(model, result)


@pytest.mark.parametrize("case", sorted(LOADS))
def test_3rrp_disturbance_unactuated_starts_with_j_m_inv_jt_f_and_gains_the_work_done(case, fmu_root):
    """From rest with tau = 0 the pose accelerates at J M^-1 J^T f (M = I_O 1 + J^T M_E J; not
    f / m nor Mz / I, the links' inertia is felt at the end effector); the kinetic energy is the
    work the wrench does, f . (pose - pose_0) with theta unwrapped."""
    system, result = run(f"3rrp-disturbance-unactuated-{case}", fmu_root)
    model = load_model("3rrp")
    home = np.array(model.configuration("home"))
    f = np.array(LOADS[case])
    h = system.step
    q, qd, pose = result.vector("plant.q"), result.vector("plant.qd"), result.vector("plant.x")
    np.testing.assert_allclose(pose[0], HOME_POSE, atol=1e-15)
    J = model.jacobian(home)
    predicted = J @ np.linalg.solve(model.mass_matrix(home), J.T @ f)
    # from rest the jerk vanishes (qd = 0): x(h) - x(0) = a h^2 / 2 + O(h^4)
    initial = 2.0 * (pose[1] - pose[0]) / h ** 2
    assert np.linalg.norm(initial - predicted) < 0.01 * np.linalg.norm(predicted)
    # the effective inertia is larger than the end effector's alone
    ee = model.end_effector_inertia
    assert np.all(np.abs(predicted) <= np.abs(f / ee) + 1e-15)
    unwrapped = pose.copy()
    unwrapped[:, 2] = np.unwrap(pose[:, 2])
    work = (unwrapped - unwrapped[0]) @ f
    kinetic = np.array([model.kinetic_energy(a, b) for a, b in zip(q, qd)])
    assert kinetic[-1] > 0 and np.abs(kinetic - work).max() < 1e-9 * kinetic[-1]
    check_pose_outputs(model, result)


def test_3rrp_runs_write_the_mechanism_figure_and_an_unactuated_run_has_no_efforts(fmu_root, tmp_path):
    """robofmu run on 3rrp: the pose (role x) and the mechanism drawn at several instants (the
    model sketches itself);
    an unactuated run (no tau role) has no efforts figure and no peak effort; inputs the
    experiment gives values (plant.tau, plant.f_ext, ik.x_ref) are not warned about."""
    from robofmu.system.run import run_experiment

    free = run_experiment("3rrp-disturbance-unactuated-fxy", tmp_path / "free", fmu_dir=fmu_root,
                          stop_time=0.05, progress=False)
    names = {p.name for p in free.figures}
    assert "mechanism.png" in names and "efforts.png" not in names and "tracking.png" in names
    assert "pose.png" in names                                       # the x role: the plant's pose
    assert free.metrics.peak_effort is None and "| — |" in free.section
    assert not Master(experiment.load("3rrp-disturbance-unactuated-fxy", fmu_dir=fmu_root)).check()
    held = run_experiment("3rrp-disturbance", tmp_path / "held", fmu_dir=fmu_root, stop_time=0.05, progress=False)
    assert {"mechanism.png", "efforts.png"} <= {p.name for p in held.figures}
    assert held.metrics.peak_effort.shape == (3,)
    model = load_model("3rrp")
    drawn = model.sketch(np.array(model.configuration("home")))
    assert [len(drawn[k]) for k in ("links", "passive", "end_effector")] == [3, 3, 1]
    for link, slider in zip(drawn["links"], drawn["passive"]):
        np.testing.assert_allclose(link[1], slider[0])                    # each link's tip starts its slider
        np.testing.assert_allclose(slider[1], HOME_POSE[:2], atol=1e-15)  # and the slider ends at Z
    serial = run_experiment("rrp-line", tmp_path / "serial", fmu_dir=fmu_root, stop_time=0.01, progress=False)
    assert "mechanism.png" not in {p.name for p in serial.figures}       # a serial model draws none


def test_3rrp_unactuated_run_agrees_with_the_independent_lagrange_formulation(fmu_root):
    """The co-simulated plant (actuated coordinates, pose FK(q): loops closed by construction)
    against the model's second formulation (Lagrange with multipliers in maximal coordinates,
    ``independent_dynamics()``) integrated with the same inputs (tau = 0, the run's f_ext), start
    (at rest at home) and step (RK4, 1 ms) over the run: its constraint residual stays at
    round-off and its q(t) matches the plant's. Seen: max |Phi| 6.6e-16 m, max |dq| 8.2e-14 rad
    (the largest of the four load cases: |Phi| 1.1e-14 m under fxy)."""
    from robofmu.system.studies.crosscheck import cross_check

    system, result = run("3rrp-disturbance-unactuated-mz", fmu_root)
    check = cross_check(system, result, Roles.of(system))
    assert check is not None and check.method == "rk4" and check.step == system.step == 0.001
    assert len(check.time) == len(result.time) == 5001 and check.residual_units[0] == "m"
    assert check.joint_units == ["rad"] * 3
    assert check.residual.max() < 1e-12                  # m, |Phi| (brief: 1e-9)
    assert check.joint_difference.max() < 1e-10          # rad (brief: 1e-6)
    theta = np.unwrap(result.vector("plant.x")[:, 2])
    assert abs(theta[-1] - theta[0]) > 5.0                # it did turn (about 7.3 rad)
    assert check.seconds < 10.0


def test_cross_check_needs_a_model_with_a_second_formulation_and_unwired_plant_inputs(fmu_root):
    from robofmu.system.studies.crosscheck import cross_check, has_independent_dynamics

    serial = experiment.load("rrp-line", fmu_dir=fmu_root)
    assert not has_independent_dynamics(Roles.of(serial).model())
    assert cross_check(serial, None, Roles.of(serial)) is None          # before reading any result
    held = experiment.load("3rrp-disturbance", fmu_dir=fmu_root)
    assert has_independent_dynamics(Roles.of(held).model())
    with pytest.raises(ValueError, match="wired"):
        cross_check(held, None, Roles.of(held))

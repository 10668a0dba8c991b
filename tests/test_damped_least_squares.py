"""Damped least-squares IK (components/ik/damped_least_squares.py) on the UR5 (square pose task)
and the Panda (one degree of redundancy), checked against an independent Pinocchio model built
here from the same URDF: pose IK to 1e-9, rates against finite differences and the task twist,
the null-space projector, joint-limit margins, honest statuses (out of reach, singular,
limit-bound), quaternion checks, determinism, a position-only task on a 6-joint arm, and the
square solvers' refusal of pose tasks."""
from __future__ import annotations

import math
import re

import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial.transform import Rotation

from robofmu.components.ik import Unreachable, make_solver, solver_class
from robofmu.components.robots import load_model
from robofmu.components.pose_trajectory import PoseLine

ROBOTS = ("ur5", "panda")
#: The task frame and locked joints, stated here (not read from the descriptions).
FRAME = {"ur5": "tool0", "panda": "panda_hand"}
LOCKED = {"ur5": {}, "panda": {"panda_finger_joint1": 0.02, "panda_finger_joint2": 0.02}}
H = 1e-3                      # s: the step of the path solves
ZERO3 = np.zeros(3)


# -- the independent reference ------------------------------------------------------------------
class Reference:
    """Plain Pinocchio on a model built here from the robot's URDF file (fingers locked for the
    Panda): FK, the pose-task Jacobian [world linear; angular about the frame's own axes] and the
    frame's classical acceleration."""

    def __init__(self, name: str, urdf):
        full = pin.buildModelFromUrdf(str(urdf))
        if LOCKED[name]:
            q_ref = pin.neutral(full)
            ids = []
            for joint, value in LOCKED[name].items():
                j = full.getJointId(joint)
                q_ref[full.joints[j].idx_q] = value
                ids.append(j)
            full = pin.buildReducedModel(full, ids, q_ref)
        self.model, self.data = full, full.createData()
        self.fid = full.getFrameId(FRAME[name])
        self.lower, self.upper = full.lowerPositionLimit.copy(), full.upperPositionLimit.copy()

    def pose(self, q) -> pin.SE3:
        pin.framesForwardKinematics(self.model, self.data, np.asarray(q, dtype=float))
        return self.data.oMf[self.fid].copy()

    def jacobian(self, q) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        linear = pin.computeFrameJacobian(self.model, self.data, q, self.fid, pin.LOCAL_WORLD_ALIGNED)[:3]
        angular = pin.computeFrameJacobian(self.model, self.data, q, self.fid, pin.LOCAL)[3:]
        return np.vstack([linear, angular])

    def acceleration(self, q, qd, qdd) -> tuple[np.ndarray, np.ndarray]:
        """The frame origin's acceleration (world) and the angular acceleration about the frame's
        own axes, R^T omegad (d/dt of R^T omega, since omega x omega = 0)."""
        pin.forwardKinematics(self.model, self.data, np.asarray(q, float), np.asarray(qd, float),
                              np.asarray(qdd, float))
        pin.updateFramePlacements(self.model, self.data)
        a = pin.getFrameClassicalAcceleration(self.model, self.data, self.fid, pin.LOCAL_WORLD_ALIGNED)
        R = self.data.oMf[self.fid].rotation
        return a.linear.copy(), R.T @ a.angular

    def margin(self, q) -> float:
        return float(np.min(np.minimum(q - self.lower, self.upper - q)))


def rotation_angle(Ra, Rb) -> float:
    """The angle (rad) of Ra^T Rb, from its antisymmetric part and trace (accurate near 0)."""
    D = np.asarray(Ra).T @ np.asarray(Rb)
    s = 0.5 * math.sqrt((D[2, 1] - D[1, 2]) ** 2 + (D[0, 2] - D[2, 0]) ** 2 + (D[1, 0] - D[0, 1]) ** 2)
    return math.atan2(s, 0.5 * (np.trace(D) - 1.0))


def target_rotation(quaternion) -> np.ndarray:
    """scipy's rotation matrix of a quaternion (x, y, z, w)."""
    return Rotation.from_quat(np.asarray(quaternion, dtype=float)).as_matrix()


def as_target(M: pin.SE3):
    """(x, quaternion x, y, z, w) of a placement, by scipy."""
    return M.translation.copy(), Rotation.from_matrix(M.rotation).as_quat()


def joints_in(message: str) -> np.ndarray:
    """The joints an Unreachable message reports ('at q = [...]', rounded to 1e-6)."""
    found = re.search(r"at q = \[([^\]]*)\]", message)
    assert found, message
    return np.array([float(v) for v in found.group(1).split(",")])


def solve_target(solver, M: pin.SE3, start=None, xd=ZERO3, omega=ZERO3):
    x, quat = as_target(M)
    solver.start_from(start)
    return solver.solve(x, xd, ZERO3, quat, omega, ZERO3)


# -- fixtures: one path solve per robot ---------------------------------------------------------
@pytest.fixture(scope="module", params=ROBOTS)
def name(request):
    return request.param


_ROBOTS: dict = {}


def robot_of(name):
    if name not in _ROBOTS:
        r = load_model(name)
        _ROBOTS[name] = (r, Reference(name, r.description.urdf))
    return _ROBOTS[name]


def profile_of(r) -> PoseLine:
    home = r.configuration("home")
    M = r.pose(home)
    p = r.description.trajectory.parameters
    quat = Rotation.from_matrix(M.rotation).as_quat()
    return PoseLine(M.translation, p["displacement"], quat, p["rotation"], p["duration"])


def solve_path(r, **overrides):
    """The description's PoseLine solved every H s from 0 to its duration, each solve started
    from the last solution carried forward by its rates."""
    solver = make_solver(r, **overrides)
    profile = profile_of(r)
    steps = int(round(profile.duration / H))
    out = {key: [] for key in ("q", "qd", "qdd", "x", "xd", "xdd", "quat", "omega", "omegad",
                               "iterations", "margin", "position_residual", "orientation_residual")}
    q = qd = qdd = None
    for k in range(steps + 1):
        target = profile.evaluate(k * H)
        solver.start_from(q, qd, qdd, H) if k else solver.start_from(None)
        q, qd, qdd = solver.solve(*target)
        for key, value in zip(("q", "qd", "qdd", "x", "xd", "xdd", "quat", "omega", "omegad"), (q, qd, qdd) + target):
            out[key].append(np.array(value, dtype=float))
        out["iterations"].append(solver.report["iterations"])
        out["margin"].append(solver.report["joint_limit_margin"])
        out["position_residual"].append(solver.report["position_residual"])
        out["orientation_residual"].append(solver.report["orientation_residual"])
    out = {key: np.array(value) for key, value in out.items()}
    out["t"] = np.arange(steps + 1) * H
    out["breakpoints"] = profile.breakpoints
    return out


@pytest.fixture(scope="module")
def path(name):
    r, ref = robot_of(name)
    return r, ref, solve_path(r)


# -- 1. pose IK against the independent model ----------------------------------------------------
def test_path_poses_reached_to_1e_9(path):
    r, ref, p = path
    worst_p = worst_o = 0.0
    for k in range(0, len(p["t"]), 20):
        M = ref.pose(p["q"][k])
        worst_p = max(worst_p, float(np.linalg.norm(M.translation - p["x"][k])))
        worst_o = max(worst_o, rotation_angle(target_rotation(p["quat"][k]), M.rotation))
    assert worst_p < 1e-9 and worst_o < 1e-9, (worst_p, worst_o)
    # warm starts (the predicted start) need at most a few corrections each
    assert np.max(p["iterations"]) <= 3, np.max(p["iterations"])
    assert np.max(p["position_residual"]) <= 1e-10 and np.max(p["orientation_residual"]) <= 1e-10


def test_random_poses_reached_from_a_nearby_start(name):
    r, ref = robot_of(name)
    rng = np.random.default_rng(20240612)
    home = np.array(r.configuration("home"))
    solver = make_solver(r)
    iterations = []
    for _ in range(8):
        q_true = np.clip(home + rng.uniform(-0.4, 0.4, r.n), ref.lower + 0.2, ref.upper - 0.2)
        M = ref.pose(q_true)                                    # the target, by the independent model
        start = q_true + rng.uniform(-0.05, 0.05, r.n)
        q, _, _ = solve_target(solver, M, start)
        reached = ref.pose(q)
        assert np.linalg.norm(reached.translation - M.translation) < 1e-9
        assert rotation_angle(M.rotation, reached.rotation) < 1e-9
        assert solver.report["status"] == 0.0
        iterations.append(solver.report["iterations"])
    # quadratic convergence from 0.05 rad per joint away: a handful of corrections, never 0
    assert 1 <= min(iterations) and max(iterations) <= 6, iterations


# -- 2. rate level ----------------------------------------------------------------------------------
def _interior(p, margin):
    """Indices k with k +- 1 inside (0, T) and t_k farther than ``margin`` from every breakpoint
    of the time law (where qdd, and so the third derivative of q, jumps)."""
    t = p["t"]
    far = np.min(np.abs(t[:, None] - p["breakpoints"][None, :]), axis=1) > margin
    far[0] = far[-1] = False
    return np.flatnonzero(far)


#: Central differences of the path's q and qd at h = 1e-3 err by h^2/6 |d3q/dt3| and h^2/6
#: |d4q/dt4| inside an LSPB piece (the UR5's q is a function of the target pose, its square task;
#: the Panda's null-space coordinate is integrated by the predictor q + h qd + h^2/2 qdd with
#: O(h^3) error per step, the corrections lying in the Jacobian's row space): observed 1.9e-7 rad/s
#: and 3.2e-7 rad/s^2 on the UR5. 2e-6 and 5e-6 leave a margin of about ten and still catch a wrong
#: factor, frame or missing term (errors of 1e-2 or more: |qd| ~ 1 rad/s, |qdd| ~ 2 rad/s^2).
FD_QD, FD_QDD = 2e-6, 5e-6


def _central_differences(p):
    k = _interior(p, 2.5 * H)
    assert len(k) > 1900
    q, qd, qdd = p["q"], p["qd"], p["qdd"]
    err_qd = float(np.max(np.abs((q[k + 1] - q[k - 1]) / (2 * H) - qd[k])))
    err_qdd = float(np.max(np.abs((qd[k + 1] - qd[k - 1]) / (2 * H) - qdd[k])))
    assert np.max(np.abs(qd)) > 0.1 and np.max(np.abs(qdd)) > 0.1     # the check is not vacuous
    return err_qd, err_qdd


def test_rates_match_central_differences(path):
    r, ref, p = path
    err_qd, err_qdd = _central_differences(p)
    assert err_qd < FD_QD, err_qd
    assert err_qdd < FD_QDD, err_qdd


def test_task_velocity_and_acceleration_are_the_reference(path):
    r, ref, p = path
    worst_v = worst_a = 0.0
    for k in range(0, len(p["t"]), 7):
        q, qd, qdd = p["q"][k], p["qd"][k], p["qdd"][k]
        R = ref.pose(q).rotation
        twist = ref.jacobian(q) @ qd
        worst_v = max(worst_v, np.max(np.abs(twist[:3] - p["xd"][k])),
                      np.max(np.abs(twist[3:] - R.T @ p["omega"][k])))
        linear, angular = ref.acceleration(q, qd, qdd)
        worst_a = max(worst_a, np.max(np.abs(linear - p["xdd"][k])),
                      np.max(np.abs(angular - R.T @ p["omegad"][k])))
    assert worst_v < 1e-9, worst_v
    assert worst_a < 1e-9, worst_a


# -- 3. the null space ------------------------------------------------------------------------------
def _posture_difference(r, ref, M, q_start, xd, omega):
    """qd with posture_gain 5 minus qd with posture_gain 0, at the same solution q."""
    slow, fast = make_solver(r, posture_gain=0.0), make_solver(r, posture_gain=5.0)
    q0, qd0, _ = solve_target(slow, M, q_start, xd, omega)
    q5, qd5, _ = solve_target(fast, M, q_start, xd, omega)
    np.testing.assert_array_equal(q0, q5)
    return q0, qd5 - qd0


def test_posture_motion_lies_in_the_null_space():
    r, ref = robot_of("panda")
    rng = np.random.default_rng(7)
    home = np.array(r.configuration("home"))
    for _ in range(5):
        q_true = home + rng.uniform(-0.3, 0.3, r.n)
        q, dq = _posture_difference(r, ref, ref.pose(q_true), q_true, [0.05, -0.1, 0.02], [0.2, 0.0, -0.1])
        J = ref.jacobian(q)
        assert np.linalg.norm(dq) > 1e-3
        assert np.linalg.norm(J @ dq) < 1e-10 * np.linalg.norm(dq)
        # dq = -5 N (q - rest), N = I - J^+ J the orthogonal projector on the null space
        N = np.eye(r.n) - np.linalg.pinv(J) @ J
        np.testing.assert_allclose(dq, -5.0 * N @ (q - home), rtol=0, atol=1e-10 * np.linalg.norm(dq) + 1e-14)
        assert np.linalg.norm(J @ N) < 1e-12


# -- 4. joint limits along the path -------------------------------------------------------------------
def test_path_keeps_clear_of_the_joint_limits(path):
    r, ref, p = path
    margins = np.array([ref.margin(q) for q in p["q"]])
    np.testing.assert_allclose(p["margin"], margins, rtol=0, atol=1e-15)
    assert margins.min() >= 0.1, margins.min()


def test_panda_posture_gain_keeps_the_arm_nearer_home(path):
    """Along the Panda's path the posture term keeps the joints nearer home than without it (the
    null-space motion is the only difference between the two runs)."""
    r, ref, p = path
    if r.n == 6:
        pytest.skip("a square task has no null space")
    free = solve_path(r, posture_gain=0.0, limit_gain=0.0)
    home = np.array(r.configuration("home"))
    held, drift = np.linalg.norm(p["q"][-1] - home), np.linalg.norm(free["q"][-1] - home)
    assert held < drift - 1e-3, (held, drift)


# -- 5. honest statuses -----------------------------------------------------------------------------
@pytest.mark.parametrize("robot", [
    "panda",
    "ur5"])
def test_out_of_reach_target(robot):
    r, ref = robot_of(robot)
    solver = make_solver(r)
    M = ref.pose(r.configuration("home"))
    M.translation = M.translation + np.array([3.0, 0.0, 0.0])
    with pytest.raises(Unreachable, match="not converged") as info:
        solve_target(solver, M)
    report = solver.report
    assert report["status"] == 1.0
    assert report["position_residual"] > 1.0
    assert report["iterations"] == 20.0                 # max_iterations
    # the residuals and margin are those of the joints the message reports (rounded to 1e-6 rad)
    q = joints_in(str(info.value))
    reached = ref.pose(q)
    assert abs(np.linalg.norm(reached.translation - M.translation) - report["position_residual"]) < 1e-4
    assert abs(rotation_angle(M.rotation, reached.rotation) - report["orientation_residual"]) < 1e-4
    assert abs(ref.margin(q) - report["joint_limit_margin"]) < 1e-6


def test_wrist_singularity_is_reported_and_its_rates_bounded():
    r, ref = robot_of("ur5")
    q_sing = np.array(r.configuration("home"))
    q_sing[4] = 0.0                                    # wrist axes 4 and 6 parallel
    J = ref.jacobian(q_sing)
    U, sigma, _ = np.linalg.svd(J)
    assert sigma[-1] < 1e-12
    # a task twist with a component along the lost direction: an undamped inverse would give
    # joint rates of order 1 / sigma_min
    nu = 0.1 * U[:, -1] + 0.05 * U[:, 0]
    R = ref.pose(q_sing).rotation
    solver = make_solver(r)
    seen = []
    jdot_qdot = r.jdot_qdot
    r.jdot_qdot = lambda q, qd: (seen.append(np.array(qd)), jdot_qdot(q, qd))[1]   # spy on qd
    try:
        with pytest.raises(Unreachable, match="singular") as info:
            solve_target(solver, ref.pose(q_sing), q_sing, nu[:3], R @ nu[3:])
    finally:
        del r.jdot_qdot
    report = solver.report
    assert report["status"] == 2.0       # not 1: the rates were finite (else status 1, 'not finite')
    assert report["smallest_singular_value"] < solver.singular_value
    assert abs(report["smallest_singular_value"] - sigma[-1]) < 1e-12
    np.testing.assert_allclose(joints_in(str(info.value)), q_sing, atol=1e-6)
    # damped: every gain sigma / (sigma^2 + lambda^2) <= 1 / (2 lambda), lambda ~ damping = 0.05
    (qd,) = seen
    assert np.all(np.isfinite(qd))
    assert np.linalg.norm(qd) <= np.linalg.norm(nu) / (2 * solver.damping) * (1 + 1e-9), np.linalg.norm(qd)


def _shoulder_wrist(ref, q):
    """The distance from the shoulder (joints 1 and 2 axes) to the wrist point (joints 5 and 6
    axes) of the Panda: a function of q4 only."""
    pin.forwardKinematics(ref.model, ref.data, np.asarray(q, dtype=float))
    return float(np.linalg.norm(ref.data.oMi[2].translation - ref.data.oMi[6].translation))


def test_limit_bound_target_is_refused():
    """A hand pose whose wrist point lies, whatever q7, closer to the shoulder than joint 4 can
    fold within its limits: reachable only with q4 below its lower limit."""
    r, ref = robot_of("panda")
    q_star = np.array(r.configuration("home"))
    q_star[3:6] = -3.6, -2.4, 3.7                       # q4 beyond its lower limit -3.0718
    inside = (q_star >= ref.lower) & (q_star <= ref.upper)
    assert list(np.flatnonzero(~inside)) == [3]
    rng = np.random.default_rng(11)
    for _ in range(3):                                 # the distance is a function of q4 alone
        q = rng.uniform(ref.lower, ref.upper)
        assert abs(_shoulder_wrist(ref, q) - _shoulder_wrist(ref, [0, 0, 0, q[3], 0, 0, 0])) < 1e-12
    closest = min(_shoulder_wrist(ref, [0, 0, 0, a, 0, 0, 0])
                  for a in np.linspace(ref.lower[3], ref.upper[3], 2001))
    M = ref.pose(q_star)
    farthest = 0.0                                     # the wrist point over a whole turn of joint 7
    for a in np.linspace(-math.pi, math.pi, 721):
        q = q_star.copy()
        q[6] = a
        pin.framesForwardKinematics(ref.model, ref.data, q)
        hand_in_6 = ref.data.oMi[6].inverse() * ref.data.oMf[ref.fid]
        wrist = (M * hand_in_6.inverse()).translation
        farthest = max(farthest, float(np.linalg.norm(wrist - ref.data.oMi[2].translation)))
    assert farthest < closest - 0.03, (farthest, closest)
    solver = make_solver(r)
    with pytest.raises(Unreachable) as info:
        solve_target(solver, M)
    report = solver.report
    assert report["status"] in (1.0, 3.0)
    assert report["joint_limit_margin"] == 0.0
    q = joints_in(str(info.value))
    assert abs(q[3] - ref.lower[3]) < 1e-6                 # joint 4 held at its lower limit
    assert report["position_residual"] > 1e-3 or report["orientation_residual"] > 1e-3
    if report["status"] == 3.0:
        assert "panda_joint4" in str(info.value)


def test_limit_bound_message_names_the_joint():
    r, ref = robot_of("panda")
    q_star = np.array(r.configuration("home"))
    q_star[3:6] = -3.6, -2.4, 3.7
    with pytest.raises(Unreachable, match="panda_joint4"):
        solve_target(make_solver(r), ref.pose(q_star))


def test_clipped_on_the_way_but_converged_inside_the_limits_is_accepted():
    r, ref = robot_of("panda")
    q_true = np.array(r.configuration("home"))
    q_true[1], q_true[3] = 0.3, 0.5                      # an equivalent posture lies inside the limits
    solver = make_solver(r)
    try:
        q, _, _ = solve_target(solver, ref.pose(q_true))
    except Unreachable:
        # the returned joints converged and lie ~1 rad inside every limit: none is held at one
        report = solver.report
        assert report["position_residual"] < 1e-10 and report["orientation_residual"] < 1e-10
        assert report["joint_limit_margin"] > 0.9
        raise
    assert np.linalg.norm(ref.pose(q).translation - ref.pose(q_true).translation) < 1e-9


# -- 6. quaternion norm -----------------------------------------------------------------------------
def test_quaternion_norm_is_checked(name):
    r, ref = robot_of(name)
    home = np.array(r.configuration("home"))
    x, quat = as_target(ref.pose(home))
    solver = make_solver(r)
    solver.start_from(home)
    with pytest.raises(ValueError, match=r"quaternion.*norm 1\.5\b") as info:
        solver.solve(x, ZERO3, ZERO3, 1.5 * quat, ZERO3, ZERO3)
    assert not isinstance(info.value, Unreachable)
    solver.start_from(home)
    q_unit, _, _ = solver.solve(x, ZERO3, ZERO3, quat, ZERO3, ZERO3)
    solver.start_from(home)
    q_near, _, _ = solver.solve(x, ZERO3, ZERO3, (1 + 1e-8) * quat, ZERO3, ZERO3)
    assert solver.report["status"] == 0.0
    np.testing.assert_allclose(q_near, q_unit, rtol=0, atol=1e-12)


# -- 7. determinism, no branch flip --------------------------------------------------------------------
def test_path_is_deterministic_and_continuous(path):
    r, ref, p = path
    again = solve_path(r)
    np.testing.assert_array_equal(again["q"], p["q"])
    np.testing.assert_array_equal(again["qd"], p["qd"])
    step = np.max(np.abs(np.diff(p["q"], axis=0)))
    assert step < 0.01, step


# -- 8. a position-only task on six joints --------------------------------------------------------------
@pytest.fixture(scope="module")
def ur5_position(tmp_path_factory):
    text = (load_model("ur5").description.path).read_text()
    position_only = re.sub(r"(?m)^orientation_axes = .*\n", "", text)
    assert "orientation_axes" not in position_only and 'solver = "damped_least_squares"' in position_only
    path = tmp_path_factory.mktemp("ur5_position") / "ur5.toml"
    path.write_text(position_only)
    return load_model(path)


def test_position_task_on_six_joints(ur5_position):
    r = ur5_position
    ref = Reference("ur5", r.description.urdf)
    assert (r.n, r.task_rows, r.orientation_axes) == (6, 3, ())
    rng = np.random.default_rng(3)
    home = np.array(r.configuration("home"))
    for _ in range(5):
        q_true = home + rng.uniform(-0.4, 0.4, 6)
        x = ref.pose(q_true).translation
        solvers = make_solver(r, posture_gain=0.0), make_solver(r, posture_gain=5.0)
        results = []
        for solver in solvers:
            solver.start_from(None)                        # from home
            results.append(solver.solve(x, [0.1, 0.0, -0.05], ZERO3))
            assert solver.report["status"] == 0.0
        (q, qd0, _), (q5, qd5, _) = results
        np.testing.assert_array_equal(q, q5)
        assert np.linalg.norm(ref.pose(q).translation - x) < 1e-9
        J = ref.jacobian(q)[:3]
        np.testing.assert_allclose(J @ qd0, [0.1, 0.0, -0.05], rtol=0, atol=1e-12)
        dq = qd5 - qd0
        assert np.linalg.norm(dq) > 1e-3
        assert np.linalg.norm(J @ dq) < 1e-10 * np.linalg.norm(dq)
        N = np.eye(6) - np.linalg.pinv(J) @ J
        np.testing.assert_allclose(dq, -5.0 * N @ (q - home), rtol=0, atol=1e-10 * np.linalg.norm(dq))


# -- 9. square solvers refuse pose tasks ------------------------------------------------------------------
def test_square_solver_refuses_a_pose_task(name):
    r, _ = robot_of(name)
    with pytest.raises(ValueError, match="damped_least_squares"):
        solver_class("newton_raphson")(r)

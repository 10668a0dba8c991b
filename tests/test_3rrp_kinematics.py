"""The planar 3-RRP mechanism ``3rrp`` (robots.md section 5): its robot model's kinematics, the
closed-form IK solver, the projected dynamics' structure, and the vectorized functions.

References written here, independently of ``components/robots/parallel.py``:

- the loop closures themselves: tip Q_i = r (cos q_i, sin q_i) lies on the line through Z at
  phi_i = theta + alpha_i, i.e. (Q_i - Z) x u_i = 0, and its extension s_i = (Q_i - Z) . u_i;
- central finite differences of J along qd (the matrix Jdot);
- the seed's IK (eqs. 10-21), rewritten in this file's notation: with K_i = x sin phi_i -
  y cos phi_i the seed's point (L_i, M_i) is K_i (-sin phi_i, cos phi_i) - sqrt(r^2 - K_i^2) u_i,
  i.e. the mirror image through O of the tip the '+' branch takes; so its FK is the pose turned
  by pi about O: (-x, -y, theta + pi);
- energy: d/dt KE = qd . (tau + J^T f_ext) under the forward dynamics.

What every robot model promises (J and J-dot q-dot the derivatives of FK, M symmetric positive
definite, Mdot - 2C skew, C qd + g = N, energy conserved without actuation, IK rates along the
reference motion) is checked on this robot too, in test_contract.py.
"""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

from robofmu.components.ik import Unreachable, make_solver
from robofmu.components.robots import load_description, load_model
from robofmu.components.robots.parallel import BRANCHES, Planar3RRP

R = 0.2
ALPHA = np.array([math.pi / 3, math.pi, -math.pi / 3])
HOME = np.radians([0.0, 120.0, 240.0])
REACH = 2 * R / math.sqrt(3)                      # the reachable disc's radius


@pytest.fixture(scope="module")
def model() -> Planar3RRP:
    return load_model("3rrp")


def wrap(a):
    """Angles into (-pi, pi]."""
    return np.remainder(np.asarray(a) + math.pi, 2 * math.pi) - math.pi


def pose_error(a, b):
    """Largest difference of two poses (or arrays of poses), theta compared modulo 2 pi."""
    a, b = np.asarray(a), np.asarray(b)
    d = a - b
    d[..., 2] = wrap(d[..., 2])
    return float(np.max(np.abs(d)))


def closure_residual(q, pose):
    """Largest |(Q_i - Z) x u_i| (m) over the legs: 0 when the loops are closed."""
    q, (x, y, th) = np.asarray(q), pose
    phi = th + ALPHA
    qx, qy = R * np.cos(q) - x, R * np.sin(q) - y
    return float(np.max(np.abs(qx * np.sin(phi) - qy * np.cos(phi))))


def extensions(q, pose):
    x, y, th = pose
    phi = th + ALPHA
    return (R * np.cos(q) - x) * np.cos(phi) + (R * np.sin(q) - y) * np.sin(phi)


def random_poses(rng, count, radius=REACH, model=None):
    """Poses with positions uniform over the disc of ``radius`` and any orientation; with
    ``model`` only the reachable ones (every line within r of O)."""
    rho = radius * np.sqrt(rng.uniform(0, 1, count))
    psi = rng.uniform(-math.pi, math.pi, count)
    poses = np.column_stack([rho * np.cos(psi), rho * np.sin(psi), rng.uniform(-math.pi, math.pi, count)])
    if model is not None:
        poses = poses[np.all(np.abs(model.line_distances_many(poses)) <= R, axis=-1)]
    return poses


def random_configurations(model, rng, count, branch="+++"):
    """Joint configurations of the '+++' branch at random reachable poses, kept away from the
    singularities (every link at least ~6 degrees from perpendicular to its line)."""
    q = model.ik_many(random_poses(rng, 4 * count, model=model), branch)
    pose = model.fk_many(q)
    s = model.passive_joints(q)["psi"]
    keep = np.all(np.abs(np.cos(s)) > 0.1, axis=-1) & np.all(np.isfinite(pose), axis=-1)
    return q[keep][:count]


# -- the description and the home pose --------------------------------------------------------------
def test_description_holds_the_specifications_numbers():
    d = load_description("3rrp")
    mech = d.mechanism
    assert d.urdf is None and d.model_kind == "planar_3rrp"
    assert (mech.r, mech.link_com, mech.link_mass, mech.link_inertia, mech.ee_mass, mech.ee_inertia) == (
        0.2, 0.33, 0.1, 0.00012, 0.2, 0.00005)
    np.testing.assert_allclose(mech.line_offsets, ALPHA, rtol=0, atol=1e-15)
    assert mech.link_inertia_about_origin == pytest.approx(0.00012 + 0.1 * (0.33 * 0.2) ** 2, rel=1e-15)
    np.testing.assert_allclose(d.configuration("home"), HOME, rtol=0, atol=1e-15)
    assert d.task.coordinates == ("x", "y", "theta") and d.task.frame == "end_effector"
    assert (d.gain_set("pd").kp, d.gain_set("pd").kd, d.gain_set("pd").ki) == (400.0, 40.0, 0.0)
    assert d.ik.kind == "planar_3rrp" and d.ik.parameters == {"branch": "+++"}
    assert d.trajectory.kind == "circle"        # 3rrp-circle (robots.md section 5)
    assert d.blocks == ("trajectory", "ik", "controller", "plant", "fk", "jacobian")


def test_model_interface_units_and_limits(model):
    assert (model.n, model.m, model.prismatic) == (3, 3, [False, False, False])
    assert model.task_units(0) == ["m", "m", "rad"] and model.task_units(2) == ["m/s2", "m/s2", "rad/s2"]
    assert model.joint_units(1) == ["rad/s"] * 3 and model.effort_units() == ["N.m"] * 3
    lower, upper = model.position_limits()
    assert np.all(lower == -np.inf) and np.all(upper == np.inf)
    np.testing.assert_array_equal(model.velocity_limits(), [10.0, 10.0, 10.0])
    np.testing.assert_array_equal(model.configuration("home"), HOME)


def test_home_is_the_consistent_pose_0_0_minus_60_degrees(model):
    pose = model.fk(HOME)
    np.testing.assert_allclose(pose, [0.0, 0.0, math.radians(-60.0)], rtol=0, atol=1e-15)
    assert closure_residual(HOME, pose) < 1e-15
    np.testing.assert_allclose(extensions(HOME, pose), [R, R, R], rtol=0, atol=1e-15)
    # the seed's Autolev start, theta = 0 at the same q and Z = 0, leaves every tip off its line
    assert closure_residual(HOME, [0.0, 0.0, 0.0]) == pytest.approx(R * math.sin(math.radians(60)), rel=1e-12)
    np.testing.assert_allclose(model.ik(pose), HOME, rtol=0, atol=1e-15)


# -- forward and inverse kinematics ----------------------------------------------------------------
def test_fk_of_ik_is_the_pose_on_thousands_of_random_reachable_poses(model, rng):
    poses = random_poses(rng, 6000, model=model)
    assert len(poses) > 3000
    q = model.ik_many(poses)
    assert np.all(np.isfinite(q))
    assert pose_error(model.fk_many(q), poses) < 1e-10
    for pose in poses[:500]:                                     # the scalar path too
        qs = model.ik(pose)
        assert pose_error(model.fk(qs), pose) < 1e-10
        assert closure_residual(qs, pose) < 1e-12


def test_fk_closes_the_loops_at_any_configuration(model, rng):
    q = rng.uniform(-2 * math.pi, 2 * math.pi, (3000, 3))
    poses = model.fk_many(q)
    assert np.all(np.isfinite(poses))
    assert max(closure_residual(qi, p) for qi, p in zip(q, poses)) < 1e-14
    # the orientation FK picks: positive total slider extension (the other, theta + pi, closes too)
    s = np.array([extensions(qi, p) for qi, p in zip(q, poses)])
    assert np.all(s.sum(axis=1) > 0)
    assert np.all(np.abs(poses[:, 2]) <= math.pi)


def test_seed_ik_branch_gives_the_pose_turned_by_pi(model, rng):
    """The seed's eqs. 10-21 (see the module docstring): FK of its joint angles is (-x, -y, theta + pi)."""
    poses = random_poses(rng, 3000, model=model)
    for x, y, th in poses[:1000]:
        phi = th + ALPHA
        K = x * np.sin(phi) - y * np.cos(phi)
        root = np.sqrt(R ** 2 - K ** 2)
        L_seed = -K * np.sin(phi) - root * np.cos(phi)
        M_seed = K * np.cos(phi) - root * np.sin(phi)
        q_seed = np.arctan2(M_seed, L_seed)
        assert pose_error(model.fk(q_seed), [-x, -y, th + math.pi]) < 1e-10
        assert closure_residual(q_seed, [x, y, th]) > 1e-6 or math.hypot(x, y) < 1e-6
        assert np.max(np.abs(wrap(q_seed - (model.ik([x, y, th]) + math.pi)))) < 1e-10


def test_branch_plus_has_positive_extensions_inside_r_and_every_branch_closes_the_loops(model, rng):
    inside = random_poses(rng, 2000, radius=0.999 * R)
    q = model.ik_many(inside)
    s = np.array([extensions(qi, p) for qi, p in zip(q, inside)])
    assert np.all(s > 0)
    poses = random_poses(rng, 400, model=model)
    for branch in BRANCHES:
        q = model.ik_many(poses, branch)
        signs = np.array([1.0 if ch == "+" else -1.0 for ch in branch])
        for qi, p in zip(q, poses):
            assert closure_residual(qi, p) < 1e-12
            w = signs * np.sqrt(np.clip(R ** 2 - model.line_distances_many(p) ** 2, 0, None))
            fk = model.fk(qi)
            # FK returns this pose where the branch's extensions sum to more than zero, else the
            # same lines with theta + pi
            if w.sum() > 1e-9:
                assert pose_error(fk, p) < 1e-9, branch
            elif w.sum() < -1e-9:
                assert pose_error(fk, [p[0], p[1], p[2] + math.pi]) < 1e-9, branch


def test_ik_angles_are_wrapped_around_home(model, rng):
    q = model.ik_many(random_poses(rng, 2000, model=model))
    assert np.all(q >= HOME - math.pi) and np.all(q < HOME + math.pi)
    near = np.array([10.0, -10.0, 0.0])
    qn = model.ik(model.fk(HOME), near=near)
    assert np.all(np.abs(qn - near) <= math.pi)
    np.testing.assert_allclose(wrap(qn - HOME), 0.0, atol=1e-14)


def test_workspace_reachable_disc_2r_over_sqrt3_dexterous_disc_r(model):
    thetas = np.linspace(-math.pi, math.pi, 3601)

    def reachable(rho, psi):
        poses = np.column_stack([np.full_like(thetas, rho * math.cos(psi)),
                                 np.full_like(thetas, rho * math.sin(psi)), thetas])
        return np.all(np.isfinite(model.ik_many(poses)), axis=-1)

    for psi in np.linspace(0, 2 * math.pi, 13):
        assert not reachable(REACH * 1.0001, psi).any()          # beyond 2r/sqrt(3): nothing
        assert reachable(0.9999 * R, psi).all()                  # within r: every orientation
        middle = reachable(0.5 * (R + REACH), psi)
        assert middle.any() and not middle.all()                 # between: some orientations
        assert reachable(REACH * (1 - 1e-6), psi).any()
    with pytest.raises(ValueError, match=re.escape("is out of reach: line")) as info:
        model.ik([REACH * 1.001, 0.0, 0.3])
    assert "beyond r = 0.2 m" in str(info.value) and "2r/sqrt(3) = 0.23094 m" in str(info.value)


@pytest.mark.parametrize("q", [ALPHA + np.array([0.0, 2 * math.pi / 3, 4 * math.pi / 3]), np.zeros(3)],
                         ids=["alpha-plus-thirds", "zero"])
def test_direct_singularity_has_no_pose(model, q):
    """sum_i exp(j (q_i - alpha_i)) = 0: every theta closes the loops. q = 0 (all links along x)
    is one: a block whose joint inputs start at 0 cannot evaluate the model there."""
    assert abs(np.exp(1j * (q - ALPHA)).sum()) < 1e-15
    with pytest.raises(ValueError, match="is a direct singularity"):
        model.fk(q)
    with pytest.raises(ValueError, match="is a direct singularity"):
        model.mass_matrix(q)
    assert np.all(np.isnan(model.fk_many(q[None])))
    assert np.all(np.isnan(model.jacobian_many(q[None])))
    assert np.isnan(model.jacobian_determinant_many(q))


def test_the_computed_torque_controller_block_runs_on_the_model_from_home(model):
    """The controller block is not listed yet (its inputs start at q = 0, a direct singularity);
    given inputs at home it computes tau = M (qdd_ref + kd e' + kp e) + N."""
    from robofmu.components.blocks import block_class

    block = block_class("controller")(load_model("3rrp"))
    q, qd = HOME + 0.01, np.array([0.1, -0.2, 0.05])
    ref = HOME + 0.02
    for name, value in (("q_ref", ref), ("qd_ref", np.zeros(3)), ("qdd_ref", np.ones(3)), ("q", q), ("qd", qd)):
        block.set(name, value)
    block.configure()
    block.output(0.0)
    u = 1.0 + 40.0 * (0.0 - qd) + 400.0 * (ref - q)
    np.testing.assert_allclose(block.get("tau"), model.mass_matrix(q) @ u + model.nonlinear_effects(q, qd),
                               rtol=1e-13, atol=0)


# -- Jacobian, its derivative, singularity measures ---------------------------------------------------
def test_jacobian_dot_equals_finite_differences_of_j_along_qd(model, rng):
    """The matrix Jdot (a 3rrp model's own function); Jdot qd = jdot_qdot, which every model's
    test_contract checks against differences of J and of FK."""
    worst_mat = 0.0
    h = 1e-6
    for q in random_configurations(model, rng, 200):
        qd = rng.uniform(-2.0, 2.0, 3)
        fd = (model.jacobian(q + h * qd) - model.jacobian(q - h * qd)) / (2 * h)
        Jdot = model.jacobian_dot(q, qd)
        worst_mat = max(worst_mat, np.linalg.norm(Jdot - fd) / np.linalg.norm(fd))
        np.testing.assert_allclose(Jdot @ qd, model.jdot_qdot(q, qd), rtol=1e-12, atol=1e-14)
    assert worst_mat < 1e-7


def test_passive_joints_are_the_sliders_and_the_tip_revolutes(model, rng):
    h = 1e-6
    for q in random_configurations(model, rng, 100):
        qd = rng.uniform(-2.0, 2.0, 3)
        passive = model.passive_joints(q, qd)
        pose = model.fk(q)
        np.testing.assert_allclose(passive["s"], extensions(q, pose), rtol=0, atol=1e-15)
        np.testing.assert_allclose(wrap(passive["psi"] - (pose[2] + ALPHA - q)), 0.0, atol=1e-14)
        s_fd = (model.slider_extensions_many(q + h * qd) - model.slider_extensions_many(q - h * qd)) / (2 * h)
        np.testing.assert_allclose(passive["sd"], s_fd, rtol=0, atol=1e-7)
        np.testing.assert_allclose(passive["psid"], model.jacobian(q)[2] @ qd - qd, rtol=0, atol=1e-14)


def test_singularity_measures(model, rng):
    Q = random_configurations(model, rng, 300)
    J = model.jacobian_many(Q)
    np.testing.assert_allclose(model.jacobian_determinant_many(Q), np.linalg.det(J), rtol=1e-11, atol=0)
    np.testing.assert_allclose(model.condition_number_many(Q, exact=True), np.linalg.cond(J), rtol=1e-12)
    for L in (1.0, 0.2):
        exact = model.singular_values_many(Q, theta_scale=L, exact=True)
        np.testing.assert_allclose(model.singular_values_many(Q, theta_scale=L), exact, rtol=1e-7, atol=0)
    # at home: det J = r^2 / (3 sin 120 deg); cond = sigma_max / sigma_min
    assert model.jacobian_determinant(HOME) == pytest.approx(R ** 2 / (3 * math.sin(2 * math.pi / 3)), rel=1e-14)
    assert model.condition_number(HOME) == pytest.approx(np.linalg.cond(model.jacobian(HOME)), rel=1e-14)
    # an inverse singularity: a link perpendicular to its line (the line tangent to the circle):
    # Z at distance r from O along line 1's normal; lines 2 and 3 then pass r/2 from O
    theta = 0.3
    phi1 = theta + ALPHA[0]
    tangent = np.array([-R * math.sin(phi1), R * math.cos(phi1), theta])
    q = model.ik(tangent)
    assert closure_residual(q, tangent) < 1e-15
    assert abs(model.jacobian_determinant(q)) < 1e-15
    np.testing.assert_allclose(model.jacobian(q)[:, 0], 0.0, atol=1e-15)       # q1 moves nothing
    assert model.singular_values_many(q)[2] < 1e-15
    assert model.condition_number(q) > 1e14


def test_vectorized_functions_equal_the_scalar_ones(model, rng):
    Q = rng.uniform(-math.pi, 2 * math.pi, (200, 3))
    QD = rng.uniform(-2, 2, (200, 3))
    poses = random_poses(rng, 200, model=model)
    np.testing.assert_allclose(model.fk_many(Q), [model.fk(q) for q in Q], rtol=0, atol=1e-15)
    np.testing.assert_allclose(model.jacobian_many(Q), [model.jacobian(q) for q in Q], rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(model.jdot_qdot_many(Q, QD), [model.jdot_qdot(q, v) for q, v in zip(Q, QD)],
                               rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(model.jacobian_dot_many(Q, QD),
                               [model.jacobian_dot(q, v) for q, v in zip(Q, QD)], rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(model.ik_many(poses), [model.ik(p) for p in poses], rtol=0, atol=1e-15)
    np.testing.assert_allclose(model.jacobian_determinant_many(Q), [model.jacobian_determinant(q) for q in Q],
                               rtol=1e-13, atol=1e-17)
    # any leading shape: a grid
    grid = Q[:24].reshape(2, 3, 4, 3)
    assert model.fk_many(grid).shape == (2, 3, 4, 3) and model.jacobian_many(grid).shape == (2, 3, 4, 3, 3)
    np.testing.assert_array_equal(model.fk_many(grid).reshape(-1, 3), model.fk_many(Q[:24]))


# -- the IK solver ---------------------------------------------------------------------------------------
def test_ik_solver_closed_form_with_rates(model, rng):
    solver = make_solver(model)
    assert solver.kind == "planar_3rrp" and solver.branch == "+++"
    for pose in random_poses(rng, 200, radius=0.9 * R):
        xd, xdd = rng.uniform(-0.1, 0.1, 3), rng.uniform(-0.5, 0.5, 3)
        q, qd, qdd = solver.solve(pose, xd, xdd)
        assert pose_error(model.fk(q), pose) < 1e-12
        np.testing.assert_allclose(model.jacobian(q) @ qd, xd, rtol=0, atol=1e-12)
        np.testing.assert_allclose(model.jacobian(q) @ qdd + model.jdot_qdot(q, qd), xdd, rtol=0, atol=1e-11)
    other = make_solver(model, branch="-++")
    q = other.position(np.array([0.01, 0.02, -1.0]))
    assert closure_residual(q, [0.01, 0.02, -1.0]) < 1e-14
    with pytest.raises(Unreachable, match="is out of reach"):
        solver.position(np.array([0.3, 0.0, 0.0]))
    with pytest.raises(ValueError, match="parameter branch = 'x' is invalid"):
        make_solver(model, branch="x")
    with pytest.raises(ValueError, match="robot 'rrp' is not a planar 3-RRP mechanism"):
        type(solver)(load_model("rrp"))


# -- dynamics ----------------------------------------------------------------------------------------------
def test_mass_matrix_symmetric_positive_definite_and_its_parts(model, rng):
    I_O = 0.00012 + 0.1 * (0.33 * R) ** 2
    ME = np.diag([0.2, 0.2, 0.00005])
    for q in random_configurations(model, rng, 200):
        M = model.mass_matrix(q)
        J = model.jacobian(q)
        np.testing.assert_allclose(M, I_O * np.eye(3) + J.T @ ME @ J, rtol=0, atol=1e-14 * np.abs(M).max())
        np.testing.assert_array_equal(M, M.T)
        assert np.linalg.eigvalsh(M).min() >= I_O * (1 - 1e-12)
    np.testing.assert_array_equal(model.gravity_torque(HOME), np.zeros(3))
    assert model.potential_energy(HOME) == 0.0


def test_energy_balance_under_forward_dynamics(model, rng):
    """d/dt KE = qd . (tau + J^T f_ext) at random states and inputs (a central difference in time
    along the motion)."""
    h = 1e-6
    for q in random_configurations(model, rng, 100):
        qd = rng.uniform(-2, 2, 3)
        tau, f = rng.uniform(-0.01, 0.01, 3), rng.uniform(-0.01, 0.01, 3)
        qdd = model.forward_dynamics(q, qd, tau, f_ext=f)

        def ke(t):
            return model.kinetic_energy(q + qd * t + 0.5 * qdd * t * t, qd + qdd * t)

        power = qd @ (tau + model.jacobian(q).T @ f)
        assert (ke(h) - ke(-h)) / (2 * h) == pytest.approx(power, rel=1e-6, abs=1e-12)
        # inverse dynamics undoes it, the wrench enters as J^T f
        np.testing.assert_allclose(model.inverse_dynamics(q, qd, qdd, f_ext=f), tau, rtol=0, atol=1e-14)
        np.testing.assert_allclose(model.forward_dynamics(q, qd, tau + model.wrench_torque(q, f)), qdd,
                                   rtol=1e-10, atol=1e-10)


def test_payload_and_gravity(model):
    fresh = load_model("3rrp")
    fresh.set_gravity(0.0)
    fresh.set_payload(0.0)                             # nothing to remove: no-op
    with pytest.raises(ValueError, match="describes no payload frame"):
        fresh.set_payload(0.1)
    np.testing.assert_array_equal(fresh.mass_matrix(HOME), model.mass_matrix(HOME))


def test_200_cubed_joint_grid_is_vectorized(model):
    """FK, J and det J over a 200^3 joint grid in chunks: every configuration but the direct
    singularities finite (a smoke test of the vectorized path; timings are in the report)."""
    g = np.linspace(0, 2 * math.pi, 200, endpoint=False)
    first = np.stack(np.meshgrid(g[:10], g, g, indexing="ij"), -1).reshape(-1, 3)     # 1/20 of it
    pose = model.fk_many(first)
    J = model.jacobian_many(first)
    det = model.jacobian_determinant_many(first)
    bad = ~np.isfinite(pose).all(-1)
    assert bad.sum() < 100 and np.all(~np.isfinite(det[bad]))
    assert np.isfinite(J[~bad]).all()

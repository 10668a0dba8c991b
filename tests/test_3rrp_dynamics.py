"""The 3-RRP dynamics twice: Lagrange with multipliers against the robot model's projected form.

Part (a) checks :mod:`robofmu.components.robots.parallel_lagrange` on its own, from the
specification's numbers (robots.md section 5): the constraint Jacobian and the convective term
against finite differences, the KKT solution against the constraints it enforces, statics by
virtual work, the energy balance, energy conservation without actuation or load (relative drift
< 1e-8 over 5 s, RK4 at h = 1 ms), the loop-closure residual (< 1e-9 m) and Baumgarte's law
for an inconsistent start. Part (b) compares it with the robot model (``load_model("3rrp")``,
minimal coordinates q: M(q) = diag(I_O) + J^T M_E J, N = J^T M_E Jdot qd, f_ext entering as
J^T f_ext): q-accelerations at random consistent states and inputs to 1e-9, trajectories over
1 s to 1e-8, and the seed's Autolev start.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from robofmu.components.robots.parallel_lagrange import LINE_OFFSETS, LagrangeRRP3

# ---- specification (robots.md section 5) ---------------------------------------------------
R = 0.2                    # link length (m)
LINK_MASS = 0.1            # kg, each link (this project's choice)
LINK_COM = 0.33            # centre of mass at 0.33 r from O
LINK_INERTIA = 0.00012     # kg m^2 about the link's own centre of mass (IS33 = IT33 = IV33)
EE_MASS = 0.2              # kg, at Z (this project's choice)
EE_INERTIA = 0.00005       # kg m^2 about Z (IE33)
HOME_Q = np.radians([0.0, 120.0, 240.0])
HOME_POSE = np.array([0.0, 0.0, math.radians(-60.0)])

RNG = np.random.default_rng(20260009)


def spec_model(**baumgarte) -> LagrangeRRP3:
    return LagrangeRRP3(R, LINK_MASS, LINK_COM, LINK_INERTIA, EE_MASS, EE_INERTIA, **baumgarte)


LAG = spec_model()


def random_pose(rng=RNG) -> np.ndarray:
    """A pose well inside the dexterous workspace, near the home orientation."""
    rho, ang = 0.5 * R * math.sqrt(rng.uniform()), rng.uniform(-math.pi, math.pi)
    return np.array([rho * math.cos(ang), rho * math.sin(ang), HOME_POSE[2] + rng.uniform(-0.4, 0.4)])


def random_state(rng=RNG) -> tuple[np.ndarray, np.ndarray]:
    """A consistent (p, pd) from Lagrange's own closed-form leg IK (no robot model involved)."""
    pose = random_pose(rng)
    p = np.concatenate([LAG.joints_from_pose(pose), pose])
    pd = LAG.consistent_rates(p, rng.uniform(-1.0, 1.0, 3))
    return p, pd


def task_jacobian(model: LagrangeRRP3, p: np.ndarray) -> np.ndarray:
    """zd = J qd from the constraints alone: J = -Phi_z^-1 Phi_q."""
    A = model.constraint_jacobian(p)
    return -np.linalg.solve(A[:, 3:], A[:, :3])


def cross(a, b) -> float:
    """z component of the planar cross product a x b."""
    return float(a[0] * b[1] - a[1] * b[0])


# ---- (a) the Lagrange formulation on its own --------------------------------------------------
def test_spec_inertia_about_O():
    assert LAG.link_inertia_O == pytest.approx(LINK_INERTIA + LINK_MASS * (LINK_COM * R) ** 2, rel=1e-15)
    assert np.allclose(LAG.mass_matrix(), np.diag([LAG.link_inertia_O] * 3 + [EE_MASS, EE_MASS, EE_INERTIA]))
    assert np.allclose(LINE_OFFSETS, [math.pi / 3, math.pi, -math.pi / 3])


def test_constraints_are_tip_on_line_cross_products():
    for _ in range(20):
        p = RNG.uniform(-3.0, 3.0, 6)
        Q, Z = LAG.tips(p[:3]), p[3:5]
        for i in range(3):
            phi = p[5] + LINE_OFFSETS[i]
            u = np.array([math.cos(phi), math.sin(phi)])
            a = Q[i] - Z
            assert LAG.constraints(p)[i] == pytest.approx(cross(a, u), abs=1e-15)
            assert LAG.slider_extensions(p)[i] == pytest.approx(a @ u, abs=1e-15)


def test_constraint_jacobian_matches_finite_differences():
    eps = 1e-6
    for _ in range(50):
        p = RNG.uniform(-3.0, 3.0, 6)
        p[3:5] *= 0.1
        fd = np.empty((3, 6))
        for k in range(6):
            e = np.zeros(6)
            e[k] = eps
            fd[:, k] = (LAG.constraints(p + e) - LAG.constraints(p - e)) / (2 * eps)
        assert np.allclose(LAG.constraint_jacobian(p), fd, rtol=0, atol=1e-9)


def test_convective_term_matches_finite_differences():
    # (d/dt Phi_p) pd = d^2/ds^2 Phi(p + s pd) at s = 0 = (d/ds Phi_p(p + s pd)) pd
    eps = 1e-5
    for _ in range(50):
        p, pd = RNG.uniform(-3.0, 3.0, 6), RNG.uniform(-2.0, 2.0, 6)
        p[3:5] *= 0.1
        pd[3:5] *= 0.1
        exact = LAG.constraint_convective(p, pd)
        by_jac = (LAG.constraint_jacobian(p + eps * pd) - LAG.constraint_jacobian(p - eps * pd)) @ pd / (2 * eps)
        second = (LAG.constraints(p + eps * pd) - 2 * LAG.constraints(p) + LAG.constraints(p - eps * pd)) / eps ** 2
        assert np.allclose(exact, by_jac, rtol=0, atol=1e-8)
        assert np.allclose(exact, second, rtol=0, atol=2e-5)


def test_consistent_states_close_the_loops():
    for _ in range(50):
        p, pd = random_state()
        phi, phid = LAG.residual(p, pd)
        assert phi < 1e-15 and phid < 1e-14
        assert np.all(LAG.slider_extensions(p) > 0)
        # Newton's pose from q recovers the pose from a nearby guess
        assert np.allclose(LAG.pose_from_joints(p[:3], p[3:] + 0.01), p[3:], rtol=0, atol=1e-14)
        # joint rates from pose rates invert pose rates from joint rates
        assert np.allclose(LAG.joint_rates(p, pd[3:]), pd[:3], rtol=1e-12, atol=1e-14)


def test_accelerations_satisfy_the_constraints_and_newton():
    for _ in range(50):
        p, pd = random_state()
        tau, f = RNG.uniform(-1e-3, 1e-3, 3), RNG.uniform(-1e-2, 1e-2, 3)
        pdd, lam = LAG.solve(p, pd, tau, f)
        # Phidd = Phi_p pdd + (d/dt Phi_p) pd = 0 on a consistent state (Baumgarte terms vanish)
        assert np.allclose(LAG.constraint_jacobian(p) @ pdd + LAG.constraint_convective(p, pd), 0, atol=1e-12)
        # M_p pdd = Q - Phi_p^T lambda
        assert np.allclose(LAG.mass_matrix() @ pdd, LAG.generalized_forces(tau, f)
                           - LAG.constraint_jacobian(p).T @ lam, rtol=0, atol=1e-15)
        # the constraint forces do no work on consistent rates
        assert abs(lam @ LAG.constraint_rates(p, pd)) < 1e-15


def test_multipliers_are_the_slider_normal_forces():
    # -Phi_p^T lambda is what equal and opposite normal forces at the tips do: -lambda_i n_i on the
    # end effector at Q_i (force and moment about Z), +lambda_i n_i on link i at Q_i (moment about O)
    for _ in range(20):
        p, pd = random_state()
        lam = LAG.multipliers(p, pd, RNG.uniform(-1e-3, 1e-3, 3), RNG.uniform(-1e-2, 1e-2, 3))
        phi = p[5] + LINE_OFFSETS
        n = np.column_stack([-np.sin(phi), np.cos(phi)])
        Q, Z = LAG.tips(p[:3]), p[3:5]
        on_ee = -lam[:, None] * n
        expected = np.concatenate([
            [cross(Q[i], lam[i] * n[i]) for i in range(3)],
            on_ee.sum(axis=0),
            [sum(cross(Q[i] - Z, on_ee[i]) for i in range(3))]])
        assert np.allclose(-LAG.constraint_jacobian(p).T @ lam, expected, rtol=1e-12, atol=1e-18)


def test_statics_by_virtual_work():
    # at rest, tau = -J^T f_ext holds the load: no acceleration
    for _ in range(20):
        p, _ = random_state()
        f = RNG.uniform(-1.0, 1.0, 3) * np.array([1e-3, 1e-3, 1e-4])
        tau = -task_jacobian(LAG, p).T @ f
        assert np.allclose(LAG.accelerations(p, np.zeros(6), tau, f), 0, atol=1e-12)
        # without the actuators it moves
        assert np.linalg.norm(LAG.accelerations(p, np.zeros(6), np.zeros(3), f)) > 1e-4


def energy_start() -> tuple[np.ndarray, np.ndarray]:
    """A consistent moving start whose free motion stays clear of singularities for 5 s."""
    pose = np.array([0.01, -0.02, -1.0])
    p = np.concatenate([LAG.joints_from_pose(pose), pose])
    zd = np.array([0.02, -0.01, 0.2])          # m/s, m/s, rad/s
    return p, np.concatenate([LAG.joint_rates(p, zd), zd])


@pytest.mark.slow
def test_energy_conserved_and_loops_closed_without_actuation():
    """RK4, fixed step 1 ms, 5 s, tau = 0, f_ext = 0: |T - T0| / T0 < 1e-8, |Phi| < 1e-9 m."""
    p0, pd0 = energy_start()
    traj = LAG.simulate(p0, pd0, 5.0, h=1e-3, method="rk4")
    T = np.array([LAG.kinetic_energy(p, pd) for p, pd in zip(traj.p, traj.pd)])
    drift = np.max(np.abs(T - T[0])) / T[0]
    residual = np.array([LAG.residual(p, pd) for p, pd in zip(traj.p, traj.pd)])
    cond = max(np.linalg.cond(task_jacobian(LAG, p)) for p in traj.p[::50])
    print(f"\nT0 = {T[0]:.6e} J, energy drift {drift:.2e}, max |Phi| {residual[:, 0].max():.2e} m, "
          f"max |Phid| {residual[:, 1].max():.2e} m/s, max cond(J) {cond:.2f}, "
          f"joint excursions {np.ptp(traj.q, axis=0)} rad")
    assert np.ptp(traj.q, axis=0).min() > 0.3                      # it really moves
    assert cond < 10.0                                             # clear of singularities
    assert drift < 1e-8
    assert residual[:, 0].max() < 1e-9
    assert residual[:, 1].max() < 1e-9


@pytest.mark.slow
def test_loops_stay_closed_without_baumgarte():
    # the residual bound is the integrator's, not the stabilization's doing
    free = spec_model(alpha=0.0, beta=0.0)
    p0, pd0 = energy_start()
    traj = free.simulate(p0, pd0, 5.0, h=1e-3)
    assert max(free.residual(p, pd)[0] for p, pd in zip(traj.p[::10], traj.pd[::10])) < 1e-9


def test_energy_balance_with_actuation_and_load():
    # T(t) - T(0) = integral of (tau . qd + f_ext . zd) dt
    p0, pd0 = energy_start()
    tau = lambda t: 1e-4 * np.array([math.sin(3 * t), math.cos(2 * t), -0.5])  # noqa: E731
    f = lambda t: np.array([2e-3 * math.cos(t), -1e-3, 1e-4 * math.sin(5 * t)])  # noqa: E731
    traj = LAG.simulate(p0, pd0, 1.0, h=1e-3, tau=tau, f_ext=f)
    T = np.array([LAG.kinetic_energy(p, pd) for p, pd in zip(traj.p, traj.pd)])
    P = np.array([LAG.power(pd, tau(t), f(t)) for t, pd in zip(traj.t, traj.pd)])
    h = traj.t[1]
    work = h / 3 * (P[0] + P[-1] + 4 * P[1:-1:2].sum() + 2 * P[2:-1:2].sum())   # Simpson, 1000 intervals
    assert T[-1] - T[0] == pytest.approx(work, rel=1e-9, abs=1e-15)
    assert abs(work) > 1e-2 * T[0]


def test_baumgarte_law_from_an_inconsistent_start():
    # Phidd + 2 alpha Phid + beta^2 Phi = 0 holds exactly on every state; with alpha = beta and
    # Phid(0) = 0: Phi(t) = Phi(0) (1 + beta t) exp(-beta t)
    model = spec_model(alpha=20.0, beta=20.0)
    p, _ = random_state(np.random.default_rng(7))
    p = p + np.array([2e-4, -1e-4, 3e-4, 1e-5, -2e-5, 0.0])
    pd = model.consistent_rates(p, [0.2, -0.1, 0.3])               # Phid(0) = 0
    phi0 = model.constraints(p)
    assert np.linalg.norm(phi0) > 1e-5
    traj = model.simulate(p, pd, 0.4, h=2e-4)
    for k in (0, 250, 500, 1000, 2000):
        t = traj.t[k]
        expected = phi0 * (1 + model.beta * t) * math.exp(-model.beta * t)
        assert np.allclose(model.constraints(traj.p[k]), expected, rtol=0, atol=1e-13)


def test_rk4_and_dop853_agree():
    p0, pd0 = energy_start()
    tau = np.array([1e-4, -2e-4, 5e-5])
    a = LAG.simulate(p0, pd0, 1.0, h=1e-3, tau=tau, method="rk4")
    b = LAG.simulate(p0, pd0, 1.0, h=1e-3, tau=tau, method="DOP853")
    assert np.max(np.abs(a.p - b.p)) < 1e-11


def test_seed_autolev_start_violates_the_loops():
    p_seed = np.concatenate([HOME_Q, [0.0, 0.0, 0.0]])
    # each tip is r sin 60 deg off its line
    assert np.allclose(np.abs(LAG.constraints(p_seed)), R * math.sin(math.pi / 3), rtol=1e-14)
    p_home = np.concatenate([HOME_Q, HOME_POSE])
    assert np.linalg.norm(LAG.constraints(p_home)) < 1e-15
    assert np.allclose(LAG.slider_extensions(p_home), R)
    assert np.allclose(LAG.joints_from_pose(HOME_POSE), [0.0, 2 * math.pi / 3, -2 * math.pi / 3], atol=1e-15)


def test_formulation_does_not_import_the_robot_model():
    # independence: building the formulation (from the description when there is one) never
    # imports components/robots/parallel.py
    import subprocess
    import sys

    code = "\n".join([
        "import sys",
        "from robofmu.components.robots import available",
        "from robofmu.components.robots.parallel_lagrange import LagrangeRRP3",
        "if '3rrp' in available():",
        "    LagrangeRRP3.from_description('3rrp')",
        "print('robofmu.components.robots.parallel' in sys.modules)"])
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


# ---- (b) against the robot model (minimal coordinates, projected) ------------------------------
@pytest.fixture(scope="module")
def model():
    """The robot model of ``3rrp`` (components/robots/parallel.py), imported only here."""
    from robofmu.components.robots import load_model

    return load_model("3rrp")


@pytest.fixture(scope="module")
def lag(model):
    """The Lagrange formulation with the description's numbers (checked against the spec's)."""
    return LagrangeRRP3.from_description("3rrp")


def test_description_holds_the_spec_numbers(lag):
    ref = spec_model()
    for name in ("r", "link_mass", "link_com", "link_inertia", "ee_mass", "ee_inertia", "link_inertia_O"):
        assert getattr(lag, name) == pytest.approx(getattr(ref, name), rel=1e-15), name
    assert np.allclose(lag.line_offsets, LINE_OFFSETS, rtol=0, atol=1e-15)


def model_state(model, q, qd) -> tuple[np.ndarray, np.ndarray]:
    """(p, pd) of the spanning tree from the model's FK and Jacobian: xd = J qd."""
    return np.concatenate([q, model.fk(q)]), np.concatenate([qd, model.jacobian(q) @ qd])


def random_joints(model, rng, max_condition=1e3):
    """q uniform over the joint torus, kept where the model's FK exists and J is conditioned."""
    while True:
        q = rng.uniform(-math.pi, math.pi, 3)
        try:
            model.fk(q)
        except ValueError:                                          # a direct singularity
            continue
        if model.condition_number(q) < max_condition:
            return q


def test_accelerations_agree_at_random_states(model, lag):
    rng = np.random.default_rng(90091)
    worst_abs = worst_rel = worst_pose = worst_phi = 0.0
    for _ in range(500):
        q = random_joints(model, rng)
        qd = rng.uniform(-2.0, 2.0, 3)
        tau = rng.uniform(-1e-3, 1e-3, 3)
        f = rng.uniform(-1.0, 1.0, 3) * np.array([1e-2, 1e-2, 1e-3])
        p, pd = model_state(model, q, qd)
        phi, phid = lag.residual(p, pd)
        worst_phi = max(worst_phi, phi)
        assert phi < 1e-14 and phid < 1e-12                      # the model's FK and J close the loops
        pdd = lag.accelerations(p, pd, tau, f)
        qdd = model.forward_dynamics(q, qd, tau, f)
        err = np.max(np.abs(pdd[:3] - qdd))
        worst_abs = max(worst_abs, err)
        worst_rel = max(worst_rel, err / max(1.0, np.max(np.abs(qdd))))
        assert err <= 1e-9 * max(1.0, np.max(np.abs(qdd)))
        # the pose accelerations are the model's J qdd + Jdot qd
        zdd = model.jacobian(q) @ qdd + model.jdot_qdot(q, qd)
        worst_pose = max(worst_pose, np.max(np.abs(pdd[3:] - zdd)))
        assert np.allclose(pdd[3:], zdd, rtol=1e-9, atol=1e-10)
        # kinetic energy and inverse dynamics
        assert lag.kinetic_energy(p, pd) == pytest.approx(model.kinetic_energy(q, qd), rel=1e-12)
        assert np.allclose(model.inverse_dynamics(q, qd, pdd[:3], f), tau, rtol=0, atol=1e-12)
    print(f"\nqdd: max |difference| {worst_abs:.2e} rad/s^2 (relative {worst_rel:.2e}); pose "
          f"accelerations {worst_pose:.2e}; |Phi| at the model's FK <= {worst_phi:.2e} m")


TRAJECTORY_CASES = [np.random.default_rng(seed) for seed in (501, 502, 503)]


@pytest.mark.parametrize("rng", TRAJECTORY_CASES, ids=["case1", "case2", "case3"])
def test_trajectories_agree_over_one_second(model, lag, rng):
    """Both formulations integrated by DOP853 (rtol 1e-12) and by RK4 at 1 ms: q, qd to 1e-8."""
    from scipy.integrate import solve_ivp

    from robofmu.components.integrators import rk4

    pose = np.array([*rng.uniform(-0.05, 0.05, 2), HOME_POSE[2] + rng.uniform(-0.3, 0.3)])
    q0, qd0 = model.ik(pose), rng.uniform(-0.5, 0.5, 3)
    tau = rng.uniform(-2e-4, 2e-4, 3)
    f = rng.uniform(-1.0, 1.0, 3) * np.array([2e-3, 2e-3, 2e-4])
    p0, pd0 = model_state(model, q0, qd0)

    def minimal(x):
        return np.concatenate([x[3:], model.forward_dynamics(x[:3], x[3:], tau, f)])

    ours = lag.simulate(p0, pd0, 1.0, h=1e-3, tau=tau, f_ext=f, method="DOP853")
    sol = solve_ivp(lambda t, x: minimal(x), (0.0, 1.0), np.concatenate([q0, qd0]), method="DOP853",
                    t_eval=ours.t, rtol=1e-12, atol=1e-14)
    theirs = sol.y.T
    dq, dqd = np.max(np.abs(ours.q - theirs[:, :3])), np.max(np.abs(ours.qd - theirs[:, 3:]))
    dpose = max(np.max(np.abs(model.fk(q) - z)) for q, z in zip(theirs[::10, :3], ours.pose[::10]))

    ours4 = lag.simulate(p0, pd0, 1.0, h=1e-3, tau=tau, f_ext=f, method="rk4")
    x, dq4, dqd4 = np.concatenate([q0, qd0]), 0.0, 0.0
    for k in range(1, 1001):
        x = rk4(minimal, x, 1e-3, 1e-3)
        dq4 = max(dq4, np.max(np.abs(ours4.q[k] - x[:3])))
        dqd4 = max(dqd4, np.max(np.abs(ours4.qd[k] - x[3:])))
    cond = max(model.condition_number(q) for q in theirs[::20, :3])
    print(f"\nDOP853: |dq| {dq:.2e} rad, |dqd| {dqd:.2e} rad/s, |dpose| {dpose:.2e}; RK4 1 ms: |dq| {dq4:.2e}, "
          f"|dqd| {dqd4:.2e}; joint excursion {np.ptp(theirs[:, :3], axis=0).max():.2f} rad, max cond {cond:.1f}")
    assert np.ptp(theirs[:, :3], axis=0).max() > 0.1
    assert dq < 1e-8 and dqd < 1e-8 and dpose < 1e-8
    assert dq4 < 1e-8 and dqd4 < 1e-8
    assert max(lag.residual(p, pd)[0] for p, pd in zip(ours4.p, ours4.pd)) < 1e-9


SEED_LOADS = {"-x": [-1e-3, 0.0, 0.0], "-y": [0.0, -1e-3, 0.0], "-x-y": [-1e-3, -1e-3, 0.0],
              "-z moment": [0.0, 0.0, -1e-3]}


@pytest.mark.parametrize("load", SEED_LOADS.values(), ids=SEED_LOADS.keys())
def test_seed_load_cases_agree_unactuated(model, lag, load):
    """The seed's four disturbance cases from rest at home, no actuation, 5 s: both formulations."""
    from scipy.integrate import solve_ivp

    q0 = model.configuration("home")
    p0, pd0 = model_state(model, q0, np.zeros(3))
    ours = lag.simulate(p0, pd0, 5.0, h=1e-2, f_ext=load, method="DOP853")
    sol = solve_ivp(lambda t, x: np.concatenate([x[3:], model.forward_dynamics(x[:3], x[3:], np.zeros(3), load)]),
                    (0.0, 5.0), np.concatenate([q0, np.zeros(3)]), method="DOP853", t_eval=ours.t,
                    rtol=1e-12, atol=1e-14)
    assert np.max(np.abs(ours.q - sol.y.T[:, :3])) < 1e-8
    assert np.max(np.abs(ours.pose[-1] - ours.pose[0])) > 1e-4            # the load moves it
    assert max(lag.residual(p, pd)[0] for p, pd in zip(ours.p, ours.pd)) < 1e-9


def test_seed_autolev_start_against_the_model(model, lag):
    # the model's FK at the seed's joint angles is (0, 0, -60 degrees): the seed's theta = 0 is off
    pose = model.fk(HOME_Q)
    assert np.allclose(pose, HOME_POSE, rtol=0, atol=1e-15)
    assert np.linalg.norm(lag.constraints(np.concatenate([HOME_Q, pose]))) < 1e-15
    seed = lag.constraints(np.concatenate([HOME_Q, [0.0, 0.0, 0.0]]))
    assert np.min(np.abs(seed)) > 0.17                                    # r sin 60 deg = 0.173 m each


def test_model_offers_this_formulation_as_its_independent_dynamics(model, lag):
    """Planar3RRP.independent_dynamics(): this formulation from the same description (and the
    model's payload, a point mass at Z), with Baumgarte gains as options."""
    other = model.independent_dynamics()
    assert isinstance(other, LagrangeRRP3) and other is not lag
    for name in ("r", "link_mass", "link_com", "link_inertia", "ee_mass", "ee_inertia", "alpha", "beta"):
        assert getattr(other, name) == getattr(lag, name)
    np.testing.assert_array_equal(other.line_offsets, lag.line_offsets)
    assert model.independent_dynamics(alpha=0.0, beta=0.0).beta == 0.0
    # simulate_joints closes the loops at q0 from a start guess and residuals() is residual() along it
    q0 = np.array(model.configuration("home"))
    traj = other.simulate_joints(q0, np.zeros(3), 0.01, h=1e-3, f_ext=[0.0, 0.0, -1e-3],
                                 pose_guess=model.fk(q0) + 1e-3)
    np.testing.assert_allclose(traj.p[0, 3:], model.fk(q0), atol=1e-14)
    phi, phid = other.residuals(traj)
    expected = np.array([other.residual(p, pd) for p, pd in zip(traj.p, traj.pd)])
    np.testing.assert_allclose(np.column_stack([phi, phid]), expected, rtol=1e-12, atol=1e-18)

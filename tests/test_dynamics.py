"""Kinematics and dynamics of the chess arm against a reference built independently of Pinocchio.

The reference model below is written from the arm's specification (standard DH table, link
masses, centres of mass and inertia tensors) and never reads the URDF. Every test compares a
number computed by the robot model (``load_model("chess")``: Pinocchio on the URDF) or by
``Plant`` with a number computed by this reference, or by a solver that does not share code
with the project (scipy, sympy).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from robofmu.components.plant import Plant
from robofmu.components.robots import RobotModel, load_model

# =============================================================================================
# Independent reference model of the chess arm (from the specification, not from the URDF)
# =============================================================================================

D1 = 0.1905  # base height (DH d_1)
A2, A3, A4 = 0.3048, 0.3048, 0.09525  # DH a_2, a_3, a_4
# Standard DH rows (d, a, alpha); theta_i = q_i.
DH = [(D1, 0.0, math.pi / 2), (0.0, A2, 0.0), (0.0, A3, 0.0), (0.0, A4, 0.0)]
MASS = np.array([0.3447302, 0.5261671, 0.5261671, 0.2585477])
# Inertia about each link's centre of mass, in DH frame i.
INERTIA = [
    np.diag([0.000708188, 0.001290541, 0.001205675]),
    np.diag([0.007064321, 0.001363701, 0.006558055]),
    np.diag([0.007064321, 0.001363701, 0.006558055]),
    np.diag([0.00072282, 0.000526751, 0.000579427]),
]
G0 = 9.81  # gravity magnitude, along world -z
N = 4


def dh_transform(theta: float, d: float, a: float, alpha: float) -> np.ndarray:
    """Standard DH link transform Rz(theta) Tz(d) Tx(a) Rx(alpha)."""
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return np.array([
        [ct, -st * ca, st * sa, a * ct],
        [st, ct * ca, -ct * sa, a * st],
        [0.0, sa, ca, d],
        [0.0, 0.0, 0.0, 1.0],
    ])


def dh_frames(q) -> list[np.ndarray]:
    """World poses T_0 .. T_4 of the DH frames (T_0 = identity, the base)."""
    T = [np.eye(4)]
    for qi, (d, a, alpha) in zip(q, DH):
        T.append(T[-1] @ dh_transform(qi, d, a, alpha))
    return T


def fk_closed_form(q) -> np.ndarray:
    """TCP position from the closed form of the specification."""
    q1, q2, q3, q4 = q
    p = A2 * math.cos(q2) + A3 * math.cos(q2 + q3) + A4 * math.cos(q2 + q3 + q4)
    z = D1 + A2 * math.sin(q2) + A3 * math.sin(q2 + q3) + A4 * math.sin(q2 + q3 + q4)
    return np.array([p * math.cos(q1), p * math.sin(q1), z])


def com_positions(T: list[np.ndarray]) -> list[np.ndarray]:
    """World centre of mass of links 1..4: the middle of segment origin(i-1) -> origin(i).

    For link 1 that is (0, 0, d_1/2) on the q1 axis, since origin(1) = (0, 0, d_1).
    """
    return [0.5 * (T[i][:3, 3] + T[i + 1][:3, 3]) for i in range(N)]


def point_jacobian(T: list[np.ndarray], p: np.ndarray, link: int) -> tuple[np.ndarray, np.ndarray]:
    """Geometric Jacobians (Jv, Jw) of a point p rigidly attached to link ``link`` (1-based).

    Revolute joint j turns about z_{j-1} through o_{j-1}: column j of Jv is z_{j-1} x (p - o_{j-1})
    and of Jw is z_{j-1}, for j <= link; joints beyond the link do not move it.
    """
    Jv, Jw = np.zeros((3, N)), np.zeros((3, N))
    for j in range(link):
        z, o = T[j][:3, 2], T[j][:3, 3]
        Jv[:, j] = np.cross(z, p - o)
        Jw[:, j] = z
    return Jv, Jw


def tcp_jacobian_ref(q) -> np.ndarray:
    """Analytic linear TCP Jacobian from the DH frames."""
    T = dh_frames(q)
    return point_jacobian(T, T[N][:3, 3], N)[0]


def mass_matrix_ref(q) -> np.ndarray:
    """M(q) = sum_i m_i Jv_i^T Jv_i + Jw_i^T (R_i I_i R_i^T) Jw_i (COM Jacobians of each link)."""
    T = dh_frames(q)
    M = np.zeros((N, N))
    for i, c in enumerate(com_positions(T)):
        Jv, Jw = point_jacobian(T, c, i + 1)
        R = T[i + 1][:3, :3]
        M += MASS[i] * Jv.T @ Jv + Jw.T @ (R @ INERTIA[i] @ R.T) @ Jw
    return M


def potential_ref(q, g0: float = G0) -> float:
    """V(q) = sum_i m_i g0 z_ci, zero at world z = 0."""
    return float(sum(m * g0 * c[2] for m, c in zip(MASS, com_positions(dh_frames(q)))))


def central_diff(f, x: np.ndarray, eps: float) -> np.ndarray:
    """Central-difference derivative of f at x along each coordinate; result[..., k] = df/dx_k."""
    cols = []
    for k in range(len(x)):
        e = np.zeros_like(x)
        e[k] = eps
        cols.append((np.asarray(f(x + e)) - np.asarray(f(x - e))) / (2 * eps))
    return np.stack(cols, axis=-1)


def gravity_ref(q, g0: float = G0) -> np.ndarray:
    """g(q) = dV/dq by central differences of the reference potential."""
    return central_diff(lambda x: potential_ref(x, g0), np.asarray(q, float), 1e-6)


def mdot_ref(q, qd, eps: float = 1e-6) -> np.ndarray:
    """dM/dt = d/dt M(q + t qd) at t = 0, by a central difference along qd."""
    return (mass_matrix_ref(q + eps * qd) - mass_matrix_ref(q - eps * qd)) / (2 * eps)


def coriolis_ref(q, qd) -> np.ndarray:
    """C(q, qd) qd from Lagrange's equations: Mdot qd - 1/2 d/dq (qd^T M(q) qd).

    (d/dt dL/dqd - dL/dq with L = 1/2 qd^T M qd - V gives M qdd + [this] + g.)
    """
    grad = central_diff(lambda x: qd @ mass_matrix_ref(x) @ qd, q, 1e-6)
    return mdot_ref(q, qd) @ qd - 0.5 * grad


def kinetic_energy_from_link_velocities(q, qd, eps: float = 1e-6) -> float:
    """sum_i 1/2 m_i |v_ci|^2 + 1/2 w_i^T R_i I_i R_i^T w_i, velocities by differencing poses.

    v_ci is d/dt of the COM position along q + t qd; w_i comes from the skew matrix
    Rdot_i R_i^T (both Rdot by central difference), so no Jacobian is involved.
    """
    Tp, Tm, T0 = dh_frames(q + eps * qd), dh_frames(q - eps * qd), dh_frames(q)
    cp, cm = com_positions(Tp), com_positions(Tm)
    ke = 0.0
    for i in range(N):
        v = (cp[i] - cm[i]) / (2 * eps)
        R = T0[i + 1][:3, :3]
        W = (Tp[i + 1][:3, :3] - Tm[i + 1][:3, :3]) / (2 * eps) @ R.T
        W = 0.5 * (W - W.T)
        w = np.array([W[2, 1], W[0, 2], W[1, 0]])
        ke += 0.5 * MASS[i] * v @ v + 0.5 * w @ (R @ INERTIA[i] @ R.T) @ w
    return ke


# =============================================================================================
# Fixtures and samples
# =============================================================================================

RNG = np.random.default_rng(20240607)
Q_SAMPLES = RNG.uniform(-math.pi, math.pi, size=(20, N))
QD_SAMPLES = RNG.uniform(-2.0, 2.0, size=(20, N))


@pytest.fixture
def robot() -> RobotModel:
    return load_model("chess")


def _rel(a, b) -> float:
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))) / np.max(np.abs(b)))


# =============================================================================================
# 1. Kinematics
# =============================================================================================

def test_fk_matches_closed_form(robot):
    err = max(np.max(np.abs(robot.fk(q) - fk_closed_form(q))) for q in Q_SAMPLES)
    assert err < 1e-12, err
    # The DH frames of the reference model agree with the closed form too (sanity of the model).
    err_dh = max(np.max(np.abs(dh_frames(q)[N][:3, 3] - fk_closed_form(q))) for q in Q_SAMPLES)
    assert err_dh < 1e-14, err_dh


def test_jacobian_matches_finite_differences_of_closed_form(robot):
    err = err_ref = 0.0
    for q in Q_SAMPLES:
        J_fd = central_diff(fk_closed_form, q, 1e-6)
        err = max(err, np.max(np.abs(robot.jacobian(q) - J_fd)))
        err_ref = max(err_ref, np.max(np.abs(tcp_jacobian_ref(q) - J_fd)))
    assert err < 1e-7, err
    assert err_ref < 1e-7, err_ref  # validates the analytic reference used below
    err_an = max(np.max(np.abs(robot.jacobian(q) - tcp_jacobian_ref(q))) for q in Q_SAMPLES)
    assert err_an < 1e-12, err_an


def test_jdot_qdot_matches_time_derivative_of_jacobian(robot):
    # Jdot qd = d/dt [J(q + t qd) qd] at t = 0 (analytic reference J, central difference in t).
    eps, err = 1e-6, 0.0
    for q, qd in zip(Q_SAMPLES, QD_SAMPLES):
        ref = (tcp_jacobian_ref(q + eps * qd) @ qd - tcp_jacobian_ref(q - eps * qd) @ qd) / (2 * eps)
        err = max(err, np.max(np.abs(robot.jdot_qdot(q, qd) - ref)))
    assert err < 1e-5, err


# =============================================================================================
# 2. Mass matrix and kinetic energy
# =============================================================================================

def test_mass_matrix_matches_composite_dh_model(robot):
    err = max(_rel(robot.mass_matrix(q), mass_matrix_ref(q)) for q in Q_SAMPLES)
    assert err < 1e-10, err


def test_kinetic_energy_matches_link_velocities(robot):
    err_m = err_pin = 0.0
    for q, qd in zip(Q_SAMPLES, QD_SAMPLES):
        ke_links = kinetic_energy_from_link_velocities(q, qd)
        err_m = max(err_m, abs(0.5 * qd @ robot.mass_matrix(q) @ qd - ke_links) / ke_links)
        err_pin = max(err_pin, abs(robot.kinetic_energy(q, qd) - ke_links) / ke_links)
    assert err_m < 1e-8, err_m
    assert err_pin < 1e-8, err_pin


# =============================================================================================
# 3. Gravity and potential energy
# =============================================================================================

def test_gravity_torque_is_gradient_of_potential(robot):
    err = max(np.max(np.abs(robot.gravity_torque(q) - gravity_ref(q))) for q in Q_SAMPLES)
    assert err < 1e-7, err


def test_potential_energy_matches_com_heights(robot):
    err = max(abs(robot.potential_energy(q) - potential_ref(q)) for q in Q_SAMPLES)
    assert err < 1e-12, err


def test_gravity_follows_set_gravity(robot):
    q = Q_SAMPLES[3]
    robot.set_gravity(3.7)
    assert np.max(np.abs(robot.gravity_torque(q) - gravity_ref(q, 3.7))) < 1e-7
    assert abs(robot.potential_energy(q) - potential_ref(q, 3.7)) < 1e-12
    robot.set_gravity(0.0)
    assert np.max(np.abs(robot.gravity_torque(q))) < 1e-14
    assert robot.potential_energy(q) == pytest.approx(0.0, abs=1e-14)


# =============================================================================================
# 4. Coriolis / centrifugal terms
# =============================================================================================

def test_nonlinear_effects_match_lagrange(robot):
    err = 0.0
    for q, qd in zip(Q_SAMPLES, QD_SAMPLES):
        ref = coriolis_ref(q, qd) + gravity_ref(q)
        err = max(err, np.max(np.abs(robot.nonlinear_effects(q, qd) - ref)))
    assert err < 1e-6, err


def test_coriolis_matrix_consistent_and_skew(robot):
    err_cqd = err_skew = 0.0
    for q, qd in zip(Q_SAMPLES[:8], QD_SAMPLES[:8]):
        C = robot.coriolis_matrix(q, qd)
        err_cqd = max(err_cqd, np.max(np.abs(C @ qd - coriolis_ref(q, qd))))
        S = mdot_ref(q, qd) - 2 * C  # must be skew-symmetric for the Christoffel C
        err_skew = max(err_skew, np.max(np.abs(S + S.T)))
    assert err_cqd < 1e-6, err_cqd
    assert err_skew < 1e-6, err_skew


def _sympy_lagrange_nonlinear():
    """N(q, qd) - g(q) = C(q, qd) qd by Christoffel symbols of a symbolic M(q) (sympy)."""
    import sympy as sp

    q = sp.symbols("q1:5")
    qd = sp.symbols("qd1:5")
    T = sp.eye(4)
    frames = [T]
    for qi, (d, a, alpha) in zip(q, DH):
        ca, sa = (0, 1) if alpha else (1, 0)  # alpha is pi/2 or 0: exact cos/sin
        A = sp.Matrix([
            [sp.cos(qi), -sp.sin(qi) * ca, sp.sin(qi) * sa, a * sp.cos(qi)],
            [sp.sin(qi), sp.cos(qi) * ca, -sp.cos(qi) * sa, a * sp.sin(qi)],
            [0, sa, ca, d],
            [0, 0, 0, 1],
        ])
        T = T * A
        frames.append(T)
    M = sp.zeros(N, N)
    for i in range(N):
        c = (frames[i][:3, 3] + frames[i + 1][:3, 3]) / 2
        Jv = c.jacobian(q)
        Jw = sp.zeros(3, N)
        for j in range(i + 1):
            Jw[:, j] = frames[j][:3, 2]
        R = frames[i + 1][:3, :3]
        M += MASS[i] * Jv.T * Jv + Jw.T * R * sp.Matrix(INERTIA[i]) * R.T * Jw
    # h_k = sum_ij c_ijk qd_i qd_j, c_ijk = 1/2 (dM_kj/dq_i + dM_ki/dq_j - dM_ij/dq_k)
    dM = [M.diff(qk) for qk in q]
    h = [
        sum(sp.Rational(1, 2) * (dM[i][k, j] + dM[j][k, i] - dM[k][i, j]) * qd[i] * qd[j]
            for i in range(N) for j in range(N))
        for k in range(N)
    ]
    return sp.lambdify([q, qd], h, "numpy")


@pytest.mark.slow
def test_nonlinear_effects_match_sympy_christoffel(robot):
    h = _sympy_lagrange_nonlinear()
    err = 0.0
    for q, qd in zip(Q_SAMPLES[:3], QD_SAMPLES[:3]):
        ref = np.array(h(q, qd), float)
        err = max(err, np.max(np.abs(robot.nonlinear_effects(q, qd) - robot.gravity_torque(q) - ref)))
    assert err < 1e-10, err


def test_forward_and_inverse_dynamics_match_reference(robot):
    err_fd = err_id = 0.0
    for q, qd in zip(Q_SAMPLES[:8], QD_SAMPLES[:8]):
        M, n = mass_matrix_ref(q), coriolis_ref(q, qd) + gravity_ref(q)
        qdd = np.array([0.7, -1.3, 2.1, -0.4])
        err_id = max(err_id, np.max(np.abs(robot.inverse_dynamics(q, qd, qdd) - (M @ qdd + n))))
        # forward dynamics checked by its torque residual M qdd + n - tau (M^-1 is ill-scaled:
        # the wrist's inertia is ~1e-3 kg m^2, so comparing accelerations would amplify noise)
        tau = np.array([0.2, 1.5, -0.6, 0.1])
        err_fd = max(err_fd, np.max(np.abs(M @ robot.forward_dynamics(q, qd, tau) + n - tau)))
    assert err_id < 1e-8, err_id
    assert err_fd < 1e-8, err_fd


# =============================================================================================
# 5. Payload (point mass at the TCP)
# =============================================================================================

def test_payload_adds_point_mass_at_tcp(robot):
    mp = 0.03
    for q in Q_SAMPLES[:10]:
        M0, g0 = robot.mass_matrix(q), robot.gravity_torque(q)
        J = tcp_jacobian_ref(q)
        robot.set_payload(mp)
        dM = robot.mass_matrix(q) - M0
        dg = robot.gravity_torque(q) - g0
        assert np.max(np.abs(dM - mp * J.T @ J)) < 1e-13
        assert np.max(np.abs(dg - mp * G0 * J[2])) < 1e-13
        # potential energy gains m g z_tcp
        assert robot.potential_energy(q) == pytest.approx(
            potential_ref(q) + mp * G0 * fk_closed_form(q)[2], abs=1e-12)
        robot.set_payload(0.0)
        assert _rel(robot.mass_matrix(q), mass_matrix_ref(q)) < 1e-10
        assert np.max(np.abs(robot.gravity_torque(q) - gravity_ref(q))) < 1e-7


def test_plant_grip_carries_payload():
    robot = load_model("chess")
    q = Q_SAMPLES[0]
    plant = Plant(robot, q, np.zeros(N), payload_mass=0.03)
    e_open = plant.energy()
    plant.set_grip(True)
    assert plant.energy() - e_open == pytest.approx(0.03 * G0 * fk_closed_form(q)[2], abs=1e-12)
    plant.set_grip(False)
    assert plant.energy() == pytest.approx(potential_ref(q), abs=1e-12)


# =============================================================================================
# 6. Energy conservation of the plant (tau = 0)
# =============================================================================================

@pytest.mark.parametrize("gravity", [0.0, G0])
def test_plant_conserves_energy(gravity):
    robot = load_model("chess")
    robot.set_gravity(gravity)
    q0 = np.array([0.3, 0.4, -0.6, 0.2])
    qd0 = np.array([1.0, -0.8, 1.2, 0.5])
    plant = Plant(robot, q0, qd0, max_substep=1e-3)
    # Initial energy from the independent model, so the plant's energy() is checked as well.
    e0 = 0.5 * qd0 @ mass_matrix_ref(q0) @ qd0 + potential_ref(q0, gravity)
    assert plant.energy() == pytest.approx(e0, rel=1e-10)
    tau, h, drift = np.zeros(N), 1e-3, 0.0
    for k in range(5000):
        plant.step(tau, h, k * h)
        drift = max(drift, abs(plant.energy() - e0) / abs(e0))
    assert np.max(np.abs(plant.qd)) > 0.1  # it really moved
    assert drift < 1e-6, drift


# =============================================================================================
# 7. Convergence of the plant's RK4 against a high-accuracy reference
# =============================================================================================

# Two starts, both held by tau = g(q0) + a small constant. "pick" is a working posture (tool
# vertical, q2 + q3 + q4 = -pi/2): the motion stays gentle (|qd| < 2 rad/s) and the absolute
# error bound applies. "outstretched" (q0 = 0) is far from that: the arm falls and the light
# wrist whips up to ~100 rad/s within the second, so RK4's error constant is ~10^4 times larger
# there; only the convergence order is asserted.
CONVERGENCE_STARTS = {
    "pick": (np.array([0.1, 0.8, -1.6, -0.8]), True),
    "outstretched": (np.zeros(N), False),
}


@pytest.mark.parametrize("start", list(CONVERGENCE_STARTS))
def test_plant_rk4_fourth_order_convergence(start):
    q0, gentle = CONVERGENCE_STARTS[start]
    robot = load_model("chess")
    qd0 = np.array([0.4, -0.3, 0.6, -0.2])
    tau = robot.gravity_torque(q0) + np.array([0.05, 0.1, -0.05, 0.01])
    t_end, h = 1.0, 0.02  # 50 communication steps; every max_substep below divides h

    def f(_, x):
        return np.concatenate([x[N:], robot.forward_dynamics(x[:N], x[N:], tau)])

    ref = solve_ivp(f, (0.0, t_end), np.concatenate([q0, qd0]), method="DOP853",
                    rtol=1e-12, atol=1e-12).y[:, -1]
    substeps = [4e-3, 2e-3, 1e-3, 5e-4]
    errors = []
    for dt in substeps:
        plant = Plant(robot, q0, qd0, max_substep=dt)
        for k in range(round(t_end / h)):
            plant.step(tau, h, k * h)
        errors.append(float(np.max(np.abs(plant.q - ref[:N]))))
    # observed order log2(e(dt) / e(dt/2)); the first pair may still be pre-asymptotic
    orders = [math.log2(errors[i] / errors[i + 1]) for i in range(len(errors) - 1)]
    checked = orders if gentle else orders[1:]
    assert all(3.5 < p < 4.5 for p in checked), (errors, orders)
    if gentle:
        assert errors[2] < 1e-8, errors

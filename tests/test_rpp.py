"""The cylindrical RPP robot (robots.md section 3, seed 001) against references independent of Pinocchio.

Pinocchio runs on ``components/robots/rpp/rpp.urdf`` directly. References: a sympy Lagrange
derivation from the kinetic energies of robots.md, the seed's own printed energies, gravity
forces and frames (transcribed as formulas below, with the worksheet's equation numbers), hand
closed forms, and the synchronized bang-bang computed here with plain numpy.
"""
from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from scipy.integrate import solve_ivp

URDF = Path(__file__).parents[1] / "components/robots/rpp/rpp.urdf"

# ---- specification (robots.md section 3) ---------------------------------------------------
M1, M2, M3 = 10.0, 5.0, 1.0  # kg
R_G1 = 0.5  # G1's distance from the q1 axis (m)
H_G3 = 0.25  # G3 is this far below E on the vertical slide (m)
G0 = 9.81
Q_START = np.array([0.0, 1.0, 1.0])
Q_END = np.array([math.pi / 2, 2.0, 2.0])
A_MAX = np.array([3.0, 4.0, 4.0])

RNG = np.random.default_rng(20260001)
Q_SAMPLES = np.column_stack([RNG.uniform(-math.pi, math.pi, 20), RNG.uniform(0.0, 2.5, 20),
                             RNG.uniform(-1.0, 2.5, 20)])
QD_SAMPLES = RNG.uniform(-2.0, 2.0, (20, 3))


@pytest.fixture(scope="module")
def pinmodel():
    model = pin.buildModelFromUrdf(str(URDF))
    return model, model.createData(), model.getFrameId("tcp")


def pin_mass(model, data, q):
    M = pin.crba(model, data, np.asarray(q, float))
    return np.triu(M) + np.triu(M, 1).T


# =============================================================================================
# References
# =============================================================================================

def lagrange(T, V, q, qd):
    """M = d2T/dqd2, C by Christoffel symbols of M, G = dV/dq (sympy)."""
    import sympy as sp

    M = sp.hessian(T, qd)
    dM = [M.diff(qk) for qk in q]
    n = len(q)
    C = sp.Matrix(n, n, lambda k, j: sum(
        sp.Rational(1, 2) * (dM[i][k, j] + dM[j][k, i] - dM[k][i, j]) * qd[i] for i in range(n)))
    G = sp.Matrix([V.diff(qk) for qk in q])
    return sp.simplify(M), sp.simplify(C), sp.simplify(G)


@lru_cache(maxsize=None)
def symbols():
    import sympy as sp

    q = sp.symbols("q1 q2 q3", real=True)
    qd = sp.symbols("q1d q2d q3d", real=True)
    m1, m2, m3, g = sp.symbols("m1 m2 m3 g", positive=True)
    return q, qd, (m1, m2, m3, g)


@lru_cache(maxsize=None)
def spec_lagrange():
    """From robots.md's energies: T1 = m1 q1d^2/8, T2 = m2 (q2^2 q1d^2 + q2d^2)/2,
    T3 = m3 (q2^2 q1d^2 + q2d^2 + q3d^2)/2; gravity on q3 only (m3 at height q3 - 0.25)."""
    import sympy as sp

    (q1, q2, q3), (q1d, q2d, q3d), (m1, m2, m3, g) = symbols()
    T = (m1 * q1d**2 / 8 + m2 * (q2**2 * q1d**2 + q2d**2) / 2
         + m3 * (q2**2 * q1d**2 + q2d**2 + q3d**2) / 2)
    V = m3 * g * (q3 - sp.Rational(1, 4))
    q, qd, _ = symbols()
    return (T, V) + lagrange(T, V, q, qd)


@lru_cache(maxsize=None)
def seed_lagrange():
    """From the seed's printed energies, eqs. (33)-(35), and gravity forces, eqs. (21)-(23)."""
    import sympy as sp

    (q1, q2, q3), (q1d, q2d, q3d), (m1, m2, m3, g) = symbols()
    T1 = sp.Rational(1, 8) * q1d**2 * m1  # (33): 0.1250000000 (d/dt q1)^2 m1
    T2 = m2 * (q1d**2 * q2**2 + q2d**2) / 2  # (34)
    T3 = m3 * (q3d**2 + q1d**2 * q2**2 + q2d**2) / 2  # (35)
    FqG = sp.Matrix([0, 0, 0]) + sp.Matrix([0, 0, 0]) + sp.Matrix([0, 0, -m3 * g])  # (21)-(23)
    # FqG is the generalized force of gravity (right-hand side); G(q) = -FqG, V = -int FqG dq
    V = -FqG[2] * q3
    q, qd, _ = symbols()
    M, C, G = lagrange(T1 + T2 + T3, V, q, qd)
    return (T1, T2, T3), M, C, G


def closed_form(q, qd, g=G0):
    """M, C, G written out by hand (what both derivations give)."""
    q1, q2, q3 = q
    q1d, q2d, _ = qd
    m23 = M2 + M3
    M = np.diag([M1 / 4 + m23 * q2**2, m23, M3])
    C = np.array([[m23 * q2 * q2d, m23 * q2 * q1d, 0.0],
                  [-m23 * q2 * q1d, 0.0, 0.0],
                  [0.0, 0.0, 0.0]])
    G = np.array([0.0, 0.0, M3 * g])
    return M, C, G


def numeric(expr, q, qd, g=G0):
    import sympy as sp

    qs, qds, (m1, m2, m3, gs) = symbols()
    f = sp.lambdify([qs, qds, m1, m2, m3, gs], expr, "numpy")
    return np.array(f(np.asarray(q, float), np.asarray(qd, float), M1, M2, M3, g), float)


# =============================================================================================
# 1. Kinematics
# =============================================================================================

def fk_closed_form(q):
    q1, q2, q3 = q
    return np.array([-q2 * math.sin(q1), q2 * math.cos(q1), q3])


def test_fk_and_jacobian_match_closed_form(pinmodel):
    model, data, fid = pinmodel
    err = err_j = 0.0
    for q in Q_SAMPLES:
        pin.framesForwardKinematics(model, data, q)
        err = max(err, np.max(np.abs(data.oMf[fid].translation - fk_closed_form(q))))
        J = pin.computeFrameJacobian(model, data, q, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
        q1, q2, _ = q
        J_seed = np.array([[-math.cos(q1) * q2, -math.sin(q1), 0.0],  # the seed's eq. (10)
                           [-math.sin(q1) * q2, math.cos(q1), 0.0],
                           [0.0, 0.0, 1.0]])
        err_j = max(err_j, np.max(np.abs(J[:3] - J_seed)))
        assert np.max(np.abs(J[3:] - [[0, 0, 0], [0, 0, 0], [1, 0, 0]])) == 0.0
    assert err < 1e-15, err
    assert err_j < 1e-15, err_j
    # world frame: at q1 = 0 the radial slide points along +y; q1 turns about +z
    pin.framesForwardKinematics(model, data, np.array([0.0, 1.0, 0.0]))
    assert np.allclose(data.oMf[fid].translation, [0.0, 1.0, 0.0], atol=1e-16, rtol=0)
    pin.framesForwardKinematics(model, data, np.array([math.pi / 2, 1.0, 0.0]))
    assert np.allclose(data.oMf[fid].translation, [-1.0, 0.0, 0.0], atol=1e-15, rtol=0)


# =============================================================================================
# 2. Energies and the dynamic model
# =============================================================================================

def test_kinetic_energy_7_75_J_at_unit_speeds(pinmodel):
    model, data, _ = pinmodel
    q, qd = np.array([0.0, 1.0, 0.0]), np.ones(3)
    assert pin.computeKineticEnergy(model, data, q, qd) == pytest.approx(7.75, abs=1e-14)
    # body by body, from Pinocchio's link velocities: the seed's eqs. (36)-(38)
    pin.forwardKinematics(model, data, q, qd)
    per_body = [0.5 * data.v[i].vector @ model.inertias[i].matrix() @ data.v[i].vector
                for i in (1, 2, 3)]
    assert per_body == pytest.approx([1.25, 5.0, 1.5], abs=1e-14)
    # the same from robots.md's and the seed's energy formulas
    T, *_ = spec_lagrange()
    assert float(numeric(T, q, qd)) == pytest.approx(7.75, abs=1e-14)
    assert [float(numeric(Ti, q, qd)) for Ti in seed_lagrange()[0]] == pytest.approx([1.25, 5.0, 1.5])
    # at an arbitrary configuration and speed too (q1 and q3 do not enter T)
    for q, qd in zip(Q_SAMPLES, QD_SAMPLES):
        assert pin.computeKineticEnergy(model, data, q, qd) == pytest.approx(
            float(numeric(T, q, qd)), rel=1e-13)


def test_seed_expressions_equal_the_spec_derivation():
    import sympy as sp

    _, _, Ms, Cs, Gs = spec_lagrange()
    _, Mseed, Cseed, Gseed = seed_lagrange()
    assert sp.simplify(Ms - Mseed) == sp.zeros(3, 3)
    assert sp.simplify(Cs - Cseed) == sp.zeros(3, 3)
    assert sp.simplify(Gs - Gseed) == sp.zeros(3, 1)
    (q1, q2, q3), (q1d, q2d, q3d), (m1, m2, m3, g) = symbols()
    assert sp.simplify(Ms - sp.diag(m1 / 4 + (m2 + m3) * q2**2, m2 + m3, m3)) == sp.zeros(3, 3)
    assert sp.simplify(Gs - sp.Matrix([0, 0, m3 * g])) == sp.zeros(3, 1)


@pytest.mark.slow
def test_seed_energies_follow_from_its_frames_and_pseudo_inertias():
    """T_i = 1/2 tr(W_i J_i W_i^T) with the seed's M0i (eqs. 3, 5, 7) and J_i_i (27)-(29)."""
    import sympy as sp

    t = sp.Symbol("t")
    (q1, q2, q3), (q1d, q2d, q3d), (m1, m2, m3, g) = symbols()
    f1, f2, f3 = (sp.Function(n)(t) for n in ("q1", "q2", "q3"))
    c, s = sp.cos(f1), sp.sin(f1)
    M01 = sp.Matrix([[c, 0, -s, 0], [s, 0, c, 0], [0, -1, 0, 0], [0, 0, 0, 1]])  # (3)
    M02 = sp.Matrix([[c, -s, 0, -s * f2], [s, c, 0, c * f2], [0, 0, 1, 0], [0, 0, 0, 1]])  # (5)
    M03 = sp.Matrix([[c, -s, 0, -s * f2], [s, c, 0, c * f2], [0, 0, 1, f3], [0, 0, 0, 1]])  # (7)

    def pseudo(m, izz, zg):  # the seed's J_template with only Izz and Zg set, (24)
        return sp.Matrix([[0, 0, 0, 0], [0, 0, 0, 0], [0, 0, izz, m * zg], [0, 0, m * zg, m]])

    subs = {f1.diff(t): q1d, f2.diff(t): q2d, f3.diff(t): q3d}
    back = {f1: q1, f2: q2, f3: q3}

    def energy(M0i, Jii):
        W = sp.simplify(M0i.diff(t) * M0i.inv())
        Ji = M0i * Jii * M0i.T
        return sp.simplify((sp.Rational(1, 2) * (W * Ji * W.T).trace()).subs(subs).subs(back))

    T1, T2, T3 = seed_lagrange()[0]
    assert sp.simplify(energy(M01, pseudo(m1, m1 / 4, sp.Rational(1, 2))) - T1) == 0
    assert sp.simplify(energy(M02, pseudo(m2, 0, 0)) - T2) == 0
    # (29) is typed "Izz=(-0.25^2)*m3", i.e. -0.0625 m3, but printed +0.0625 m3: the z-z
    # second moment never enters a kinetic energy here (no body turns about a horizontal axis)
    for izz in (m3 / 16, -m3 / 16):
        assert sp.simplify(energy(M03, pseudo(m3, izz, -sp.Rational(1, 4))) - T3) == 0
    # the seed's centres of mass (15)-(17) are the URDF's: G1 0.5 m out on the radial axis
    # (M01's z axis), G2 = the radial slide's end at height 0, G3 0.25 m below E
    G1 = (M01 * sp.Matrix([0, 0, sp.Rational(1, 2), 1]))[:3, 0].subs(back)
    assert sp.simplify(G1 - sp.Matrix([-sp.sin(q1) / 2, sp.cos(q1) / 2, 0])) == sp.zeros(3, 1)


def test_mass_coriolis_gravity_match_lagrange(pinmodel):
    model, data, _ = pinmodel
    _, _, Ms, Cs, Gs = spec_lagrange()
    _, Mseed, Cseed, Gseed = seed_lagrange()
    for q, qd in zip(Q_SAMPLES, QD_SAMPLES):
        M = pin_mass(model, data, q)
        C = pin.computeCoriolisMatrix(model, data, q, qd).copy()
        G = pin.computeGeneralizedGravity(model, data, q).copy()
        Mc, Cc, Gc = closed_form(q, qd)
        for Mr, Cr, Gr in ((numeric(Ms, q, qd), numeric(Cs, q, qd), numeric(Gs, q, qd).ravel()),
                           (numeric(Mseed, q, qd), numeric(Cseed, q, qd), numeric(Gseed, q, qd).ravel()),
                           (Mc, Cc, Gc)):
            assert np.max(np.abs(M - Mr)) < 1e-13
            assert np.max(np.abs(C - Cr)) < 1e-13
            assert np.max(np.abs(G - Gr)) < 1e-14
        assert np.max(np.abs(pin.nonLinearEffects(model, data, q, qd) - Cc @ qd - Gc)) < 1e-13
    # g(q) = (0, 0, m3 g): only the vertical slide's mass moves with q3
    assert pin.computeGeneralizedGravity(model, data, Q_START) == pytest.approx([0, 0, 9.81], abs=1e-15)


def test_mdot_minus_2c_is_skew(pinmodel):
    model, data, _ = pinmodel
    eps, err = 1e-6, 0.0
    for q, qd in zip(Q_SAMPLES, QD_SAMPLES):
        Mdot = (pin_mass(model, data, q + eps * qd) - pin_mass(model, data, q - eps * qd)) / (2 * eps)
        # exact: dM11/dt = 2 (m2 + m3) q2 q2d
        Mdot_exact = np.diag([2 * (M2 + M3) * q[1] * qd[1], 0, 0])
        assert np.max(np.abs(Mdot - Mdot_exact)) < 1e-7
        S = Mdot_exact - 2 * pin.computeCoriolisMatrix(model, data, q, qd)
        err = max(err, np.max(np.abs(S + S.T)))
    assert err < 1e-13, err


def test_energy_conserved_under_gravity_with_zero_torque(pinmodel):
    model, data, _ = pinmodel
    q0, qd0 = np.array([0.1, 1.0, 1.5]), np.array([1.0, 0.3, 0.0])

    def f(_, x):
        return np.concatenate([x[3:], pin.aba(model, data, x[:3], x[3:], np.zeros(3))])

    sol = solve_ivp(f, (0.0, 2.0), np.concatenate([q0, qd0]), method="DOP853", rtol=1e-10,
                    atol=1e-12, t_eval=np.linspace(0, 2, 101))
    T, V, *_ = spec_lagrange()
    e = np.array([float(numeric(T, x[:3], x[3:]) + numeric(V, x[:3], x[3:])) for x in sol.y.T])
    assert np.max(np.abs(e - e[0])) / abs(e[0]) < 1e-7
    # q3 falls freely: q3(t) = q3(0) - g t^2 / 2
    assert sol.y[2, -1] == pytest.approx(1.5 - G0 * 2.0**2 / 2, rel=1e-9)


# =============================================================================================
# 3. The synchronized minimum-time bang-bang (robots.md numbers, plain numpy)
# =============================================================================================

def bang_bang(q_start, q_end, a_max):
    dq = q_end - q_start
    t_min = 2.0 * np.sqrt(np.abs(dq) / a_max)
    T = float(np.max(t_min))
    a = 4.0 * dq / T**2  # rescaled so that every joint finishes at T

    def state(t):
        t = min(max(t, 0.0), T)
        if t <= T / 2:
            return q_start + a * t * t / 2, a * t, a
        return q_end - a * (T - t) ** 2 / 2, a * (T - t), -a

    return t_min, T, a, state


def test_bang_bang_numbers():
    t_min, T, a, state = bang_bang(Q_START, Q_END, A_MAX)
    assert np.round(t_min, 4) == pytest.approx([1.4472, 1.0, 1.0], abs=0)
    assert t_min[0] == pytest.approx(1.447202509, abs=1e-9)  # the seed's (42)
    assert T == t_min[0] == pytest.approx(math.sqrt(2 * math.pi / 3), rel=1e-15)
    assert a == pytest.approx([3.0, 6 / math.pi, 6 / math.pi], rel=1e-15)
    assert a[1] == pytest.approx(1.909859318, abs=1e-9)  # the seed's (46)-(47)
    assert a[1] / 2 == pytest.approx(0.9549296590, abs=1e-9)  # the seed's q2/q3 profiles (10 digits)
    assert T / 2 == pytest.approx(0.7236012545, abs=1e-10)  # switch time, the seed's (49)
    peak = a * T / 2
    assert peak == pytest.approx(2 * (Q_END - Q_START) / T, rel=1e-15)
    assert np.round(peak, 4) == pytest.approx([2.1708, 1.3820, 1.3820], abs=0)
    # the profile: from rest to rest, continuous at the switch, within the limits
    q0, qd0, _ = state(0.0)
    qT, qdT, _ = state(T)
    assert np.allclose(q0, Q_START, atol=0) and np.allclose(qd0, 0, atol=0)
    assert np.allclose(qT, Q_END, atol=1e-15) and np.allclose(qdT, 0, atol=1e-15)
    lo, hi = state(T / 2 - 1e-12), state(T / 2 + 1e-12)
    assert np.allclose(lo[0], hi[0], atol=1e-12) and np.allclose(lo[1], hi[1], atol=1e-10)
    assert np.allclose(state(T / 2)[0], (Q_START + Q_END) / 2, atol=1e-15)
    assert np.all(np.abs(a) <= A_MAX * (1 + 1e-15))


# Peak joint efforts of the ideal (model-exact) tracking, N m, N, N:
#   q1: just before the switch, M11 = m1/4 + 6 * 1.5^2 = 16, 16 * 3 + 2 (m2 + m3) q2 q1d q2d = 48 + 54;
#   q2: just after it, -(m2 + m3) (6/pi + q2 q1d^2) = -53.87; q3: m3 (g + 6/pi) on the way up.
PEAK_EFFORTS = [102.0, 53.870656726, 11.719859317]


def test_ideal_efforts_along_the_bang_bang(pinmodel):
    """Inverse dynamics along the reference: Pinocchio's RNEA = closed-form M qdd + C qd + G."""
    model, data, _ = pinmodel
    _, T, _, state = bang_bang(Q_START, Q_END, A_MAX)
    peak, err = np.zeros(3), 0.0
    for t in np.linspace(0.0, T, 401):
        q, qd, qdd = state(t)
        tau = pin.rnea(model, data, q, qd, qdd)
        M, C, G = closed_form(q, qd)
        err = max(err, np.max(np.abs(tau - (M @ qdd + C @ qd + G))))
        peak = np.maximum(peak, np.abs(tau))
    assert err < 1e-12, err
    # for the record (N m, N, N), the jump just after the switch included
    q, qd, qdd = state(T / 2 + 1e-12)
    peak = np.maximum(peak, np.abs(pin.rnea(model, data, q, qd, qdd)))
    assert peak == pytest.approx(PEAK_EFFORTS, rel=1e-9)



def test_the_urdf_places_the_centres_of_mass_where_the_spec_says(pinmodel):
    """G1 at R_G1 from the q1 axis, G3 at H_G3 below E: the URDF's inertial origins."""
    model = pinmodel[0]
    levers = [np.round(np.abs(model.inertias[j].lever), 12).tolist() for j in range(1, model.njoints)]
    assert [0.0, R_G1, 0.0] in levers and [0.0, 0.0, H_G3] in levers, levers


@pytest.mark.slow
def test_the_seed_dynamics_table_agrees_with_the_model():
    """The demo's table: the seed's M, C, G by Lagrange from its energies against the model."""
    from robofmu.system.studies.tables import STUDIES_DIR, dynamics_table

    table = dynamics_table("rpp", STUDIES_DIR / "seed001_energies.toml")
    assert table.largest_difference < 1e-9
    assert "agrees at 50 random configurations" in table.text

"""The RRP arm with a shoulder offset (robots.md section 4, seed 003) against references independent
of Pinocchio.

The robot model (``load_model("rrp_offset")``, Pinocchio on
``components/robots/rrp_offset/rrp_offset.urdf``) is compared with what the specification writes:
its FK (the seed's unknown l3 is the joint coordinate q3), det J, a sympy J-dot (which also
settles the seed's printed entry (2, 2)), a sympy Lagrange derivation of M, C, g from the
specification's three bodies (never from the URDF), scipy for the energy balance. The closed-form
IK (``offset_rrp``) gives the seed's solution, the other branch, and FK(IK(x)) = x.

What every robot model and IK solver promises (J and J-dot q-dot the derivatives of FK, the
dynamics' identities, energy conservation, IK rates along the reference motion) is checked on
this robot too, in test_contract.py.
"""
from __future__ import annotations

import math
import re
import shutil
from functools import lru_cache

import numpy as np
import pytest

import lagrange_checks
from robofmu.components.ik import Unreachable, solver_class
from robofmu.components.robots import ROBOTS_DIR, load_description, load_model
from robofmu.components.robots.description import read
from robofmu.components.trajectory import WaypointTrajectory

# ---- specification (robots.md section 4) ---------------------------------------------------
L1, L2 = 1.0, 0.5          # height of the offset arm, its length (m)
M1, IZZ1 = 1.0, 0.01       # link 1: point mass at the offset arm's end, plus Izz on the q1 axis
M2 = 0.5                   # link 2: point mass at the joint-2 point
M3 = 0.5                   # link 3: point mass at the TCP
G0 = 9.81                  # along -z
Q3_RANGE = (0.05, 2.0)     # the slide's URDF limits (robofmu's choice)
HOME = np.array([0.0, 0.5, 0.5])
TARGET = np.array([-0.6, 0.4, 1.5])
SEED_SOLUTION = (0.178160046146, 0.804633677101, 0.721110255093)

RNG = np.random.default_rng(20260013)
Q_SAMPLES = np.column_stack([RNG.uniform(-2 * math.pi, 2 * math.pi, 20), RNG.uniform(-math.pi, math.pi, 20),
                             RNG.uniform(*Q3_RANGE, 20)])
QD_SAMPLES = RNG.uniform(-2.0, 2.0, (20, 3))


@pytest.fixture(scope="module")
def model():
    return load_model("rrp_offset")


def fk_spec(q):
    q1, q2, l3 = q
    return np.array([-L2 * math.sin(q1) - l3 * math.sin(q2) * math.cos(q1),
                     L2 * math.cos(q1) - l3 * math.sin(q2) * math.sin(q1),
                     L1 + l3 * math.cos(q2)])


@lru_cache(maxsize=None)
def sym():
    """sympy from the specification: FK, J, J-dot; T, V of the three bodies; M, C (Christoffel), g."""
    import sympy as sp

    q = sp.symbols("q1 q2 q3", real=True)
    qd = sp.symbols("q1d q2d q3d", real=True)
    gs = sp.Symbol("g")
    q1, q2, l3 = q
    p = sp.Matrix([-L2 * sp.sin(q1) - l3 * sp.sin(q2) * sp.cos(q1),
                   L2 * sp.cos(q1) - l3 * sp.sin(q2) * sp.sin(q1),
                   L1 + l3 * sp.cos(q2)])
    J = p.jacobian(q)
    Jdot = sum((J.diff(qk) * qdk for qk, qdk in zip(q, qd)), sp.zeros(3, 3))

    def ddt(expr):
        return sum((expr.diff(qk) * qdk for qk, qdk in zip(q, qd)), sp.zeros(*expr.shape))

    arm_end = sp.Matrix([-L2 * sp.sin(q1), L2 * sp.cos(q1), L1])     # links 1 and 2's masses
    v_end, v_tcp = ddt(arm_end), ddt(p)
    T = (sp.Rational(1, 2) * IZZ1 * qd[0] ** 2 + sp.Rational(1, 2) * (M1 + M2) * (v_end.T * v_end)[0]
         + sp.Rational(1, 2) * M3 * (v_tcp.T * v_tcp)[0])
    V = gs * ((M1 + M2) * arm_end[2] + M3 * p[2])
    M = sp.hessian(T, qd)
    dM = [M.diff(qk) for qk in q]
    C = sp.Matrix(3, 3, lambda k, j: sum(
        sp.Rational(1, 2) * (dM[i][k, j] + dM[j][k, i] - dM[k][i, j]) * qd[i] for i in range(3)))
    g = sp.Matrix([V.diff(qk) for qk in q])
    f = lambda e: sp.lambdify([q, qd, gs], e, "numpy")  # noqa: E731
    return {"symbols": (q, qd), "Jdot": Jdot,
            "jdot_qdot": f(Jdot * sp.Matrix(qd)), "M": f(M), "C": f(C), "g": f(g), "T": f(T), "V": f(V)}


def ref(name, q, qd=np.zeros(3), g=G0):
    return np.array(sym()[name](np.asarray(q, float), np.asarray(qd, float), g), float)


# =============================================================================================
# 1. Kinematics
# =============================================================================================

def test_task_and_joints(model):
    assert model.n == 3 and model.m == 3 and model.task_coordinates == ("x", "y", "z")
    assert model.prismatic == [False, False, True]
    assert model.joint_units(0) == ["rad", "rad", "m"] and model.task_units(0) == ["m"] * 3
    lower, upper = model.position_limits()
    assert (lower[2], upper[2]) == Q3_RANGE
    assert load_description("rrp_offset").gravity_direction == (0.0, 0.0, -1.0)


def test_fk_matches_the_specification(model):
    err = max(np.max(np.abs(model.fk(q) - fk_spec(q))) for q in Q_SAMPLES)
    assert err < 1e-12, err
    # frames: the offset arm along +y at q1 = 0, at height l1; positive q2 tips the slide to -x
    np.testing.assert_allclose(model.fk(np.array([0.0, 0.0, 0.3])), [0.0, L2, L1 + 0.3], atol=1e-16)
    np.testing.assert_allclose(model.fk(np.array([0.0, math.pi / 2, 0.3])), [-0.3, L2, L1], atol=1e-15)
    np.testing.assert_allclose(model.fk(np.array([math.pi / 2, 0.0, 0.0])), [-L2, 0.0, L1], atol=1e-15)


def test_jacobian_determinant(model):
    # det J = -q3^2 sin q2: singular where the two IK branches meet (sin q2 = 0)
    for q in Q_SAMPLES:
        assert np.linalg.det(model.jacobian(q)) == pytest.approx(-q[2] ** 2 * math.sin(q[1]), abs=1e-13)


def test_jdot_qdot_matches_sympy(model):
    err_sym = 0.0
    for q, qd in zip(Q_SAMPLES, QD_SAMPLES):
        err_sym = max(err_sym, np.max(np.abs(model.jdot_qdot(q, qd) - ref("jdot_qdot", q, qd).ravel())))
    assert err_sym < 1e-13, err_sym


def test_jdot_entry_2_2():
    """Row 2, column 2 of J-dot (1-based) is d/dt(-l3 cos q2 sin q1): the middle term is
    l3 sin q2 sin q1 q2d. The seed prints l3 sin q2 cos q2 q2d there (docs/departures.md)."""
    import sympy as sp

    (q1, q2, l3), (q1d, q2d, l3d) = sym()["symbols"]
    entry = sym()["Jdot"][1, 1]
    correct = (-l3d * sp.cos(q2) * sp.sin(q1) + l3 * sp.sin(q2) * sp.sin(q1) * q2d
               - l3 * sp.cos(q2) * sp.cos(q1) * q1d)
    assert sp.simplify(entry - correct) == 0
    printed = correct - l3 * sp.sin(q2) * sp.sin(q1) * q2d + l3 * sp.sin(q2) * sp.cos(q2) * q2d
    difference = sp.simplify(printed - entry)
    assert difference != 0
    # e.g. at home moving q2 alone at 1 rad/s: 0.5 sin 0.5 cos 0.5 instead of 0
    value = float(difference.subs({q1: 0, q2: 0.5, l3: 0.5, q1d: 0, q2d: 1, l3d: 0}))
    assert value == pytest.approx(0.5 * math.sin(0.5) * math.cos(0.5), abs=1e-15)


# =============================================================================================
# 2. Dynamics: the three bodies by sympy Lagrange
# =============================================================================================

def test_mass_coriolis_gravity_match_lagrange(model):
    lagrange_checks.assert_mass_coriolis_gravity_match(model, ref, Q_SAMPLES, QD_SAMPLES)


def test_hand_values(model):
    """g = (0, -m3 g q3 sin q2, m3 g cos q2) and, by hand from the TCP's partial velocities
    (dp/dq1 . dp/dq2 = l2 q3 cos q2, dp/dq1 . dp/dq3 = l2 sin q2, dp/dq2 . dp/dq3 = 0):
    M = [[Izz1 + (m1 + m2 + m3) l2^2 + m3 q3^2 sin^2 q2, m3 l2 q3 cos q2, m3 l2 sin q2],
         [m3 l2 q3 cos q2, m3 q3^2, 0], [m3 l2 sin q2, 0, m3]]."""
    for q in Q_SAMPLES:
        _, q2, q3 = q
        s2, c2 = math.sin(q2), math.cos(q2)
        np.testing.assert_allclose(model.gravity_torque(q), [0.0, -M3 * G0 * q3 * s2, M3 * G0 * c2], atol=1e-13)
        M12, M13 = M3 * L2 * q3 * c2, M3 * L2 * s2
        np.testing.assert_allclose(model.mass_matrix(q), [
            [IZZ1 + (M1 + M2 + M3) * L2**2 + M3 * (q3 * s2) ** 2, M12, M13],
            [M12, M3 * q3**2, 0.0],
            [M13, 0.0, M3]], atol=1e-14)
    # link 1 about the q1 axis: Izz1 + m1 l2^2 = 0.26 kg m^2; with the slide upright M11 = 0.51
    assert model.mass_matrix(np.array([0.7, 0.0, 0.8]))[0, 0] == pytest.approx(0.51, abs=1e-15)


def test_energies_match_lagrange(model):
    lagrange_checks.assert_energies_match(model, ref, Q_SAMPLES, QD_SAMPLES)


def test_energy_conserved_under_gravity_with_zero_torque(model):
    lagrange_checks.assert_energy_conserved_without_torque(
        model, ref, q0=np.array([0.2, 0.6, 0.9]), qd0=np.array([1.5, -1.0, 0.3]), duration=1.0)


# =============================================================================================

def solver(m, branch="positive"):
    return solver_class("offset_rrp")(m, branch=branch)


def other_branch(x):
    """The negative branch by hand: s = l3 sin q2 = -sqrt(x^2 + y^2 - l2^2), h = z - l1; then
    (x, y) = R(q1) (-s, l2) is linear in (cos q1, sin q1)."""
    s = -math.sqrt(x[0] ** 2 + x[1] ** 2 - L2**2)
    h = x[2] - L1
    c1, s1 = np.linalg.solve([[-s, -L2], [L2, -s]], x[:2])
    return np.array([math.atan2(s1, c1), math.atan2(s, h), math.hypot(s, h)])


def test_ik_gives_the_seeds_solution_and_the_other_branch(model):
    positive, negative = solver(model, "positive").position(TARGET), solver(model, "negative").position(TARGET)
    np.testing.assert_allclose(positive, SEED_SOLUTION, atol=1e-12, rtol=0)
    np.testing.assert_allclose(negative, other_branch(TARGET), atol=1e-14, rtol=0)
    np.testing.assert_allclose(negative, [1.787427400348, -0.804633677101, 0.721110255093], atol=1e-12, rtol=0)
    for q in (positive, negative, np.array(SEED_SOLUTION)):
        np.testing.assert_allclose(fk_spec(q), TARGET, atol=1e-11, rtol=0)
    for q in (positive, negative):
        np.testing.assert_allclose(model.fk(q), TARGET, atol=1e-12, rtol=0)
        np.testing.assert_allclose(fk_spec(q), TARGET, atol=1e-12, rtol=0)
    # "positive": l3 sin q2 > 0; the extension is the same on both
    assert positive[2] * math.sin(positive[1]) > 0 > negative[2] * math.sin(negative[1])
    assert positive[2] == negative[2] == pytest.approx(math.sqrt(0.52), abs=1e-15)


def test_ik_default_is_the_home_branch(model):
    ik = solver_class("offset_rrp")(model)
    assert ik.values == {"branch": "positive"}      # IK(FK(home)) = home: test_contract.py
    assert (ik.l1, ik.l2) == pytest.approx((L1, L2), abs=1e-15)


def test_ik_round_trip_over_the_workspace(model):
    err = 0.0
    for branch in ("positive", "negative"):
        ik = solver(model, branch)
        for q in Q_SAMPLES:
            x = fk_spec(q)
            if abs(math.sin(q[1])) < 1e-6:
                continue
            got = ik.position(x)
            err = max(err, np.max(np.abs(fk_spec(got) - x)))
            assert Q3_RANGE[0] <= got[2] <= Q3_RANGE[1] and abs(got[1]) <= math.pi
            assert got[2] == pytest.approx(q[2], abs=1e-12)          # l3 is the same on both branches
    assert err < 1e-12, err


def test_ik_round_trip_along_the_reference_motion(model):
    profile = WaypointTrajectory(**load_description("rrp_offset").trajectory.parameters)
    for branch in ("positive", "negative"):
        ik = solver(model, branch)
        err = max(np.max(np.abs(fk_spec(ik.position(profile.evaluate(t)[0])) - profile.evaluate(t)[0]))
                  for t in np.arange(0.0, profile.duration + 1e-9, 1e-3))
        assert err < 1e-12, err


@pytest.mark.parametrize("x, message", [
    ([0.1, 0.1, 1.0], "target (0.1, 0.1, 1) m is out of reach: 0.141421 m from joint 1's axis, inside the "
                      "offset l2 = 0.5 m"),
    ([-3.0, 0.5, 1.0], "target (-3, 0.5, 1) m needs an extension l3 = q3 = 3 m; the slide reaches 0.05 to 2 m"),
    ([-0.01, 0.5, 1.0], "target (-0.01, 0.5, 1) m needs an extension l3 = q3 = 0.01 m; the slide reaches "
                        "0.05 to 2 m"),
])
def test_unreachable_targets_raise(model, x, message):
    for branch in ("positive", "negative"):
        with pytest.raises(Unreachable, match=re.escape(message)):
            solver(model, branch).solve(np.array(x), np.zeros(3), np.zeros(3))


def test_unknown_branch_option(model):
    with pytest.raises(ValueError, match=re.escape(
            "IK solver 'offset_rrp': parameter branch = 'left' is invalid: must be one of "
            "'positive', 'negative'")):
        solver(model, "left")


def test_other_lengths_are_read_from_the_urdf(tmp_path):
    """The solver is generic: a copy with l1 = 0.8 m, l2 = 0.3 m is solved on its own lengths."""
    folder = tmp_path / "rrp_offset"
    shutil.copytree(ROBOTS_DIR / "rrp_offset", folder)
    urdf = folder / "rrp_offset.urdf"
    text = urdf.read_text()
    joint2 = '<origin xyz="0 {} 0" rpy="0 0 0"/>\n    <axis'       # joint 2's origin: the offset arm
    for old, new in (('<origin xyz="0 0 1" rpy', '<origin xyz="0 0 0.8" rpy'),
                     (joint2.format(0.5), joint2.format(0.3))):
        assert text.count(old) == 1
        text = text.replace(old, new)
    urdf.write_text(text)
    robot = load_model(read(folder / "rrp_offset.toml"))
    ik = solver(robot)
    assert (ik.l1, ik.l2) == pytest.approx((0.8, 0.3), abs=1e-15)
    x = np.array([-0.6, 0.4, 1.5])
    np.testing.assert_allclose(robot.fk(ik.position(x)), x, atol=1e-12)
    with pytest.raises(Unreachable, match=re.escape("inside the offset l2 = 0.3 m")):
        ik.position(np.array([0.2, 0.1, 1.0]))


def test_solver_refuses_another_mechanism():
    """rrp has the same joint types (R, R, P) but not this geometry."""
    with pytest.raises(ValueError, match=re.escape("IK solver 'offset_rrp': robot 'rrp' is not this mechanism")):
        solver(load_model("rrp"))
    with pytest.raises(ValueError, match="needs joints revolute, revolute, prismatic"):
        solver(load_model("rpp"))


# =============================================================================================
# 4. The description's tables
# =============================================================================================

def test_reference_motion_starts_at_home_at_rest(model):
    description = load_description("rrp_offset")
    params = description.trajectory.parameters
    assert description.trajectory.kind == "waypoints"
    assert description.configuration("home") == (0.0, 0.5, 0.5)
    first = np.array(params["waypoints"][0])
    np.testing.assert_array_equal(first, fk_spec(HOME))               # to full double precision
    np.testing.assert_array_equal(first, model.fk(HOME))
    assert params["waypoints"][1:] == [[-0.6, 0.4, 1.5], [-0.3, 0.7, 1.2]]
    assert (params["durations"], params["pause"]) == ([2.0, 2.0], 0.5)
    assert "grip_close_after_move" not in params
    profile = WaypointTrajectory(**params)
    assert profile.duration == pytest.approx(4.5, abs=1e-15)           # at rest before the 5 s stop
    np.testing.assert_array_equal(profile.evaluate(0.0)[0], first)


def test_ik_table_and_gains():
    description = load_description("rrp_offset")
    assert description.blocks == ("trajectory", "ik", "controller", "plant", "fk")
    assert description.ik.kind == "newton_raphson"
    assert description.ik.parameters == {"q_guess": [0.0, 0.5, 0.5], "tolerance": 1e-12, "max_iterations": 20}
    assert description.gain_set("pd").as_dict() == {"kp": 400.0, "kd": 40.0, "ki": 0.0}
    assert description.payload is None

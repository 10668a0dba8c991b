"""The planar 2R arm (robots.md section 4, seed 003) against references independent of Pinocchio.

The robot model (``load_model("planar2r")``, Pinocchio on ``components/robots/planar2r/planar2r.urdf``)
is compared with what the specification writes: the FK in the seed's absolute angles
(q2abs = q1 + q2, q2 the URDF's relative joint), det J, a sympy Lagrange derivation of M, C, g
from the two rods (never from the URDF), scipy for the energy balance. The closed-form IK
(``planar_elbow``) gives the seed's two branch solutions and FK(IK(x)) = x.

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
L1, L2 = 1.0, 0.5          # link lengths (m)
M1, M2 = 1.0, 0.5          # thin uniform rods (kg)
G0 = 9.81                  # along -y: the arm moves in the vertical x-y plane
HOME = np.array([0.0, 1.0])                  # q1 = 0, q2abs = 1 rad -> relative q2 = 1 rad
TARGET = np.array([1.2, 0.6])
# the seed's branch solutions for TARGET, in its absolute angles (q1, q2abs)
BRANCH_DOWN = (0.147142165383, 1.135574254309)
BRANCH_UP = (0.780153052619, -0.208279036307)

RNG = np.random.default_rng(20260003)
Q_SAMPLES = RNG.uniform(-2 * math.pi, 2 * math.pi, (20, 2))
QD_SAMPLES = RNG.uniform(-3.0, 3.0, (20, 2))


@pytest.fixture(scope="module")
def model():
    return load_model("planar2r")


def fk_spec(q1, q2abs):
    """The specification's FK, in the seed's absolute angle of link 2."""
    return np.array([L1 * math.cos(q1) + L2 * math.cos(q2abs), L1 * math.sin(q1) + L2 * math.sin(q2abs)])


def fk_urdf(q):
    """The same in the URDF's joint coordinates (relative q2)."""
    return fk_spec(q[0], q[0] + q[1])


# =============================================================================================
# 1. Task space and kinematics
# =============================================================================================

def test_task_has_two_coordinates_in_metres(model):
    description = load_description("planar2r")
    assert model.n == 2 and model.m == 2
    assert model.task_coordinates == ("x", "y") and description.task.axes == (0, 1)
    for order, unit in enumerate(("m", "m/s", "m/s2")):
        assert model.task_units(order) == [unit, unit]
    assert model.prismatic == [False, False] and model.joint_units(0) == ["rad", "rad"]
    assert (description.gravity, description.gravity_direction) == (9.81, (0.0, -1.0, 0.0))
    np.testing.assert_array_equal(np.asarray(model.model.gravity.linear), [0.0, -9.81, 0.0])


def test_fk_matches_the_specification(model):
    err = max(np.max(np.abs(model.fk(q) - fk_urdf(q))) for q in Q_SAMPLES)
    assert err < 1e-12, err
    # q2 is relative: q = (pi/2, -pi/2) puts link 1 up and link 2 along +x
    np.testing.assert_allclose(model.fk(np.array([math.pi / 2, -math.pi / 2])), [L2, L1], atol=1e-15)
    np.testing.assert_allclose(model.fk(HOME), [1 + 0.5 * math.cos(1.0), 0.5 * math.sin(1.0)], atol=1e-16)


def test_jacobian_determinant(model):
    # det J = l1 l2 sin q2 (relative q2): singular stretched out and folded back
    for q in Q_SAMPLES:
        assert np.linalg.det(model.jacobian(q)) == pytest.approx(L1 * L2 * math.sin(q[1]), abs=1e-14)


# =============================================================================================
# 2. Dynamics: the two rods by sympy Lagrange
# =============================================================================================

@lru_cache(maxsize=None)
def lagrange():
    """M = d2T/dqd2, C by Christoffel symbols, g = dV/dq from the specification's two rods in
    the vertical plane (gravity along -y), in the URDF's coordinates (relative q2)."""
    import sympy as sp

    q = sp.symbols("q1 q2", real=True)
    qd = sp.symbols("q1d q2d", real=True)
    gs = sp.Symbol("g")
    a1, a2 = q[0], q[0] + q[1]                    # absolute link angles
    w1, w2 = qd[0], qd[0] + qd[1]
    c1 = sp.Matrix([L1 / 2 * sp.cos(a1), L1 / 2 * sp.sin(a1)])
    c2 = sp.Matrix([L1 * sp.cos(a1) + L2 / 2 * sp.cos(a2), L1 * sp.sin(a1) + L2 / 2 * sp.sin(a2)])

    def ddt(expr):
        return sum((expr.diff(qk) * qdk for qk, qdk in zip(q, qd)), sp.zeros(*expr.shape))

    v1, v2 = ddt(c1), ddt(c2)
    T = (sp.Rational(1, 2) * M1 * (v1.T * v1)[0] + sp.Rational(1, 2) * M1 * L1**2 / 12 * w1**2
         + sp.Rational(1, 2) * M2 * (v2.T * v2)[0] + sp.Rational(1, 2) * M2 * L2**2 / 12 * w2**2)
    V = gs * (M1 * c1[1] + M2 * c2[1])
    M = sp.hessian(T, qd)
    dM = [M.diff(qk) for qk in q]
    C = sp.Matrix(2, 2, lambda k, j: sum(
        sp.Rational(1, 2) * (dM[i][k, j] + dM[j][k, i] - dM[k][i, j]) * qd[i] for i in range(2)))
    g = sp.Matrix([V.diff(qk) for qk in q])
    f = lambda e: sp.lambdify([q, qd, gs], e, "numpy")  # noqa: E731
    return {"M": f(M), "C": f(C), "g": f(g), "T": f(T), "V": f(V)}


def ref(name, q, qd=np.zeros(2), g=G0):
    return np.array(lagrange()[name](np.asarray(q, float), np.asarray(qd, float), g), float)


def test_mass_coriolis_gravity_match_lagrange(model):
    lagrange_checks.assert_mass_coriolis_gravity_match(model, ref, Q_SAMPLES, QD_SAMPLES)


def test_hand_values(model):
    """Stretched out along +x: g = (g (m1 l1/2 + m2 (l1 + l2/2)), g m2 l2/2) = (11.03625, 1.22625) N m;
    M at q2 = 0: M22 = m2 l2^2/3, M12 = M22 + m2 l1 l2/2, M11 = m1 l1^2/3 + m2 (l1^2 + l1 l2 + l2^2/3)."""
    q = np.zeros(2)
    assert model.gravity_torque(q) == pytest.approx([11.03625, 1.22625], abs=1e-13)
    M22 = M2 * L2**2 / 3
    M12 = M22 + M2 * L1 * L2 / 2
    M11 = M1 * L1**2 / 3 + M2 * (L1**2 + L1 * L2 + L2**2 / 3)
    np.testing.assert_allclose(model.mass_matrix(q), [[M11, M12], [M12, M22]], atol=1e-15)
    # hanging straight down: no gravity torque
    np.testing.assert_allclose(model.gravity_torque(np.array([-math.pi / 2, 0.0])), 0.0, atol=1e-14)


def test_energies_match_lagrange(model):
    lagrange_checks.assert_energies_match(model, ref, Q_SAMPLES, QD_SAMPLES)


def test_energy_conserved_under_gravity_with_zero_torque(model):
    lagrange_checks.assert_energy_conserved_without_torque(
        model, ref, q0=np.array([0.3, 0.8]), qd0=np.array([1.0, -2.0]), duration=2.0)


# =============================================================================================

def solver(m, elbow="down"):
    return solver_class("planar_elbow")(m, elbow=elbow)


def test_ik_gives_the_seeds_branch_solutions(model):
    down, up = solver(model, "down").position(TARGET), solver(model, "up").position(TARGET)
    # URDF coordinates: relative q2 = q2abs - q1
    assert down[1] == pytest.approx(0.988432088926, abs=1e-12)
    for q, (q1, q2abs) in ((down, BRANCH_DOWN), (up, BRANCH_UP)):
        assert q[0] == pytest.approx(q1, abs=1e-12)
        assert q[0] + q[1] == pytest.approx(q2abs, abs=1e-12)
        np.testing.assert_allclose(fk_urdf(q), TARGET, atol=1e-12, rtol=0)
        np.testing.assert_allclose(model.fk(q), TARGET, atol=1e-12, rtol=0)
        # and the seed's (q1, q2abs) are solutions of its FK
        np.testing.assert_allclose(fk_spec(q1, q2abs), TARGET, atol=1e-11, rtol=0)
    assert down[1] > 0 > up[1]                          # "down": q2 >= 0; "up": q2 <= 0
    assert up[1] == pytest.approx(-down[1], abs=1e-15)
    # with the target to the right, "up" puts the elbow above the line from the base to it
    elbow = lambda q: L1 * np.array([math.cos(q[0]), math.sin(q[0])])  # noqa: E731
    cross = lambda e: TARGET[0] * e[1] - TARGET[1] * e[0]  # noqa: E731
    assert cross(elbow(up)) > 0 > cross(elbow(down))


def test_ik_default_is_the_home_branch(model):
    ik = solver_class("planar_elbow")(model)
    assert ik.values == {"elbow": "down"}           # IK(FK(home)) = home: test_contract.py


def test_link_lengths_come_from_the_model(model):
    ik = solver(model)
    assert (ik.l1, ik.l2) == pytest.approx((L1, L2), abs=1e-15)


def test_ik_round_trip_over_the_annulus(model):
    err = 0.0
    for elbow in ("down", "up"):
        ik = solver(model, elbow)
        for r, a in zip(RNG.uniform(0.5 + 1e-6, 1.5 - 1e-6, 200), RNG.uniform(-math.pi, math.pi, 200)):
            x = np.array([r * math.cos(a), r * math.sin(a)])
            q = ik.position(x)
            assert np.all(np.abs(q) <= math.pi)
            err = max(err, np.max(np.abs(fk_urdf(q) - x)))
    assert err < 1e-12, err
    # on the edges of the annulus: stretched out (q2 = 0) and folded back (q2 = pi)
    ik = solver(model)
    np.testing.assert_allclose(ik.position(np.array([0.0, 1.5])), [math.pi / 2, 0.0], atol=1e-15)
    np.testing.assert_allclose(ik.position(np.array([0.5, 0.0])), [0.0, math.pi], atol=1e-7)


def test_ik_round_trip_along_the_reference_motion(model):
    params = load_description("planar2r").trajectory.parameters
    profile = WaypointTrajectory(**params)
    for elbow in ("down", "up"):
        ik = solver(model, elbow)
        err = max(np.max(np.abs(fk_urdf(ik.position(profile.evaluate(t)[0])) - profile.evaluate(t)[0]))
                  for t in np.arange(0.0, profile.duration + 1e-9, 1e-3))
        assert err < 1e-12, err


@pytest.mark.parametrize("x, message", [
    ([1.6, 0.0], "target (1.6, 0) m is out of reach: 1.6 m from joint 1's axis, reachable 0.5 to 1.5 m"),
    ([0.3, 0.1], "target (0.3, 0.1) m is out of reach: 0.316228 m from joint 1's axis, reachable 0.5 to 1.5 m"),
    ([0.0, 0.0], "target (0, 0) m is out of reach: 0 m from joint 1's axis"),
])
def test_unreachable_targets_raise(model, x, message):
    for elbow in ("down", "up"):
        with pytest.raises(Unreachable, match=re.escape(message)):
            solver(model, elbow).solve(np.array(x), np.zeros(2), np.zeros(2))


def test_unknown_elbow_option(model):
    with pytest.raises(ValueError, match=re.escape(
            "IK solver 'planar_elbow': parameter elbow = 'sideways' is invalid: must be one of 'down', 'up'")):
        solver(model, "sideways")


def test_other_link_lengths_are_read_from_the_urdf(tmp_path):
    """The solver is generic: a copy with l1 = 0.8 m, l2 = 0.3 m is solved on its own lengths."""
    folder = tmp_path / "planar2r"
    shutil.copytree(ROBOTS_DIR / "planar2r", folder)
    urdf = folder / "planar2r.urdf"
    text = urdf.read_text()
    tcp = '<origin xyz="{} 0 0" rpy="0 0 0"/>\n  </joint>'           # the fixed tcp_joint's origin
    for old, new in (('<origin xyz="1 0 0"', '<origin xyz="0.8 0 0"'), (tcp.format(0.5), tcp.format(0.3))):
        assert text.count(old) == 1
        text = text.replace(old, new)
    urdf.write_text(text)
    robot = load_model(read(folder / "planar2r.toml"))
    ik = solver(robot)
    assert (ik.l1, ik.l2) == pytest.approx((0.8, 0.3), abs=1e-15)
    x = np.array([0.7, 0.5])
    np.testing.assert_allclose(robot.fk(ik.position(x)), x, atol=1e-12)
    with pytest.raises(Unreachable, match=re.escape("reachable 0.5 to 1.1 m")):
        ik.position(np.array([1.2, 0.0]))


def test_solver_refuses_another_mechanism():
    with pytest.raises(ValueError, match="needs 2 revolute joints and 2 task coordinates"):
        solver(load_model("rrp"))


# =============================================================================================
# 4. The description's tables
# =============================================================================================

def test_reference_motion_starts_at_home_at_rest(model):
    description = load_description("planar2r")
    params = description.trajectory.parameters
    assert description.trajectory.kind == "waypoints"
    assert description.configuration("home") == (0.0, 1.0)
    first = np.array(params["waypoints"][0])
    np.testing.assert_array_equal(first, fk_spec(0.0, 1.0))          # to full double precision
    np.testing.assert_array_equal(first, model.fk(HOME))
    assert params["waypoints"][1:] == [[1.2, 0.6], [0.6, 1.2]]
    assert (params["durations"], params["pause"]) == ([1.0, 2.0], 0.5)
    assert "grip_close_after_move" not in params
    profile = WaypointTrajectory(**params)
    assert profile.duration == pytest.approx(3.5, abs=1e-15)           # at rest before the 4 s stop
    x, xd, xdd = profile.evaluate(0.0)
    np.testing.assert_array_equal(x, first)
    np.testing.assert_array_equal(xd, [0.0, 0.0])


def test_ik_table_and_gains():
    description = load_description("planar2r")
    assert description.blocks == ("trajectory", "ik", "controller", "plant", "fk")
    assert description.ik.kind == "newton_raphson"
    assert description.ik.parameters == {"q_guess": [0.0, 1.0], "tolerance": 1e-12, "max_iterations": 20}
    assert description.gain_set("pd").as_dict() == {"kp": 400.0, "kd": 40.0, "ki": 0.0}
    assert description.payload is None

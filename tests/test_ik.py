"""Closed-form chess IK: FK(IK(x)) = x along the task, rates against finite differences.

(Its rates along the description's reference motion, as every IK solver's: test_contract.py.)"""
import math
import re

import numpy as np
import pytest

from robofmu.components.ik import Unreachable, make_solver, solver_class
from robofmu.components.trajectory import WaypointTrajectory

A1, A2, A3, A4 = 0.1905, 0.3048, 0.3048, 0.09525


def fk_closed_form(q):
    """robots.md section 1: p = a2 c2 + a3 c23 + a4 c234."""
    q1, q2, q3, q4 = q
    p = A2 * math.cos(q2) + A3 * math.cos(q2 + q3) + A4 * math.cos(q2 + q3 + q4)
    return np.array([p * math.cos(q1), p * math.sin(q1),
                     A1 + A2 * math.sin(q2) + A3 * math.sin(q2 + q3) + A4 * math.sin(q2 + q3 + q4)])


def ik_reference(x, sign_q2=+1.0):
    """robots.md's printed formulas (acos form of q3). sign_q2 = -1 gives the seed's -w."""
    p = math.hypot(x[0], x[1])
    zp = x[2] + A4
    d = math.hypot(p, zp - A1)
    w = math.atan2(zp - A1, p)
    q2 = sign_q2 * w + math.acos((A2**2 + d**2 - A3**2) / (2 * A2 * d))
    q3 = -q2 - math.acos((p - A2 * math.cos(q2)) / A3)
    return np.array([math.atan2(x[1], x[0]), q2, q3, -math.pi / 2 - q2 - q3])


@pytest.fixture
def ik(chess):
    """The chess arm's solver as its description names it (pitch_elbow, tool down, elbow up)."""
    return make_solver(chess)


@pytest.fixture
def gambit(chess_description):
    assert "profile" not in chess_description.trajectory.parameters
    return WaypointTrajectory(**chess_description.trajectory.parameters)


def test_link_lengths_come_from_the_model(ik):
    assert (ik.a1, ik.a2, ik.a3, ik.a4) == pytest.approx((A1, A2, A3, A4), abs=1e-15)


@pytest.mark.slow
def test_fk_of_ik_along_the_whole_task(ik, gambit):
    worst = 0.0
    for t in np.arange(0.0, 13.0 + 1e-9, 1e-3):
        x = gambit.evaluate(t)[0]
        q = ik.position(x)
        worst = max(worst, np.max(np.abs(fk_closed_form(q) - x)))
        assert q[1] + q[2] + q[3] == pytest.approx(-math.pi / 2, abs=1e-12)   # tool vertical
        np.testing.assert_allclose(q, ik_reference(x), atol=1e-12)
    assert worst < 1e-9


def test_seed_sign_of_q2_misses_by_up_to_019_m(gambit):
    """The seed's q2 = -w + acos(..): FK of it misses the target; documented departure."""
    worst = max(np.max(np.abs(fk_closed_form(ik_reference(gambit.evaluate(t)[0], -1.0))
                              - gambit.evaluate(t)[0])) for t in np.arange(0, 13.0, 0.01))
    assert 0.1 < worst < 0.25


def test_solver_is_the_one_the_description_names(ik, chess_description):
    assert ik.kind == chess_description.ik.kind == "pitch_elbow"
    assert type(ik) is solver_class("pitch_elbow")
    assert ik.values == {"tool_pitch": -math.pi / 2, "elbow": "up"}


def test_elbow_down_branch_also_reaches(chess):
    down = make_solver(chess, elbow="down")
    up = make_solver(chess)
    x = np.array([0.25, 0.1, 0.12])
    np.testing.assert_allclose(fk_closed_form(down.position(x)), x, atol=1e-12)
    assert down.position(x)[2] > 0 > up.position(x)[2]       # elbow bends the other way


def _smooth(t):
    """A smooth task-space path inside the workspace (C-infinity, for finite differences)."""
    return np.array([0.25 + 0.05 * math.sin(1.3 * t), 0.1 * math.cos(0.7 * t), 0.1 + 0.04 * math.sin(2.1 * t)])


def test_rates_match_finite_differences_of_position(ik):
    h = 1e-4
    for t in np.linspace(0.0, 5.0, 23):
        x = _smooth(t)
        xd = (_smooth(t + h) - _smooth(t - h)) / (2 * h)
        xdd = (_smooth(t + h) - 2 * x + _smooth(t - h)) / h**2
        q, qd, qdd = ik.solve(x, xd, xdd)
        qp, qm = ik.position(_smooth(t + h)), ik.position(_smooth(t - h))
        np.testing.assert_allclose(qd, (qp - qm) / (2 * h), atol=1e-6)
        np.testing.assert_allclose(qdd, (qp - 2 * q + qm) / h**2, atol=2e-4)


@pytest.mark.parametrize("x, message", [
    ([0.9, 0.0, 0.1], "out of reach"),
    ([0.0, 0.0, 0.3], "base axis"),
])
def test_unreachable_targets_raise(ik, x, message):
    with pytest.raises(Unreachable, match=message):
        ik.solve(np.array(x), np.zeros(3), np.zeros(3))


def test_unknown_elbow_option(chess):
    message = "IK solver 'pitch_elbow': parameter elbow = 'sideways' is invalid: must be one of 'up', 'down'"
    with pytest.raises(ValueError, match=re.escape(message)):
        make_solver(chess, elbow="sideways")
    with pytest.raises(ValueError, match=re.escape(message)):
        solver_class("pitch_elbow")(chess, tool_pitch=-math.pi / 2, elbow="sideways")


def test_tool_pitch_is_a_parameter(chess):
    """Another tool pitch: q2 + q3 + q4 holds it and FK still reaches the target."""
    ik = solver_class("pitch_elbow")(chess, tool_pitch=-1.2, elbow="up")
    x = np.array([0.25, 0.1, 0.12])
    q = ik.position(x)
    assert q[1] + q[2] + q[3] == pytest.approx(-1.2, abs=1e-12)
    np.testing.assert_allclose(fk_closed_form(q), x, atol=1e-12)


def test_the_spherical_solver_refuses_a_robot_that_is_not_its_mechanism():
    """rrp_offset has the spherical arm's joint types but a shoulder offset: refused at setup,
    naming the FK difference, instead of returning joints whose FK misses the target."""
    from robofmu.components.ik import solver_class
    from robofmu.components.robots import load_model

    with pytest.raises(ValueError, match=r"IK solver 'spherical': robot 'rrp_offset' is not this mechanism "
                                         r"\(its FK differs from the solver's by 0\.564 m"):
        solver_class("spherical")(load_model("rrp_offset"))
    solver_class("spherical")(load_model("rrp"))                    # its own mechanism: accepted

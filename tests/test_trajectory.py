"""LSPB profiles and the queen's-gambit waypoint trajectory, against closed forms."""
import numpy as np
import pytest

from robofmu.components.blocks.text import format_matrix, format_vector, parse_matrix, parse_vector
from robofmu.components.trajectory import WaypointTrajectory, lspb


def test_lspb_closed_form_default_cruise():
    # 1.5x mean speed: blend T/3, acceleration 4.5 dx / T^2, cruise 1.5 dx / T
    x0, x1, T = np.array([0.2]), np.array([0.5]), 2.0
    dx = 0.3
    a = 4.5 * dx / T**2
    x, xd, xdd = lspb(x0, x1, T, 0.5)
    assert x[0] == pytest.approx(0.2 + 0.5 * a * 0.25, abs=1e-15)
    assert xd[0] == pytest.approx(a * 0.5) and xdd[0] == pytest.approx(a)
    x, xd, xdd = lspb(x0, x1, T, 1.0)          # cruising
    assert xd[0] == pytest.approx(1.5 * dx / T) and xdd[0] == 0.0
    assert x[0] == pytest.approx(0.35)          # symmetric profile: half way at half time
    x, xd, xdd = lspb(x0, x1, T, T)
    assert x[0] == pytest.approx(0.5, abs=1e-15) and xd[0] == pytest.approx(0.0, abs=1e-15)


@pytest.mark.parametrize("cruise", [1.2, 1.5, 2.0])
def test_lspb_is_continuous_and_consistent(cruise):
    x0, x1, T = np.array([0.0, 1.0, -0.5]), np.array([1.0, 1.0, 0.25]), 1.7
    ts = np.linspace(0, T, 20001)
    X = np.array([lspb(x0, x1, T, t, cruise)[0] for t in ts])
    V = np.array([lspb(x0, x1, T, t, cruise)[1] for t in ts])
    A = np.array([lspb(x0, x1, T, t, cruise)[2] for t in ts])
    dt = ts[1] - ts[0]
    # velocity is the derivative of position, acceleration the derivative of velocity
    np.testing.assert_allclose(np.gradient(X, dt, axis=0)[1:-1], V[1:-1], atol=2e-4)
    np.testing.assert_allclose(np.trapezoid(A, ts, axis=0), V[-1] - V[0], atol=1e-3)
    assert np.max(np.abs(np.diff(X, axis=0))) < 1e-3           # no jumps in position
    assert np.max(np.abs(np.diff(V, axis=0))) < 1e-2           # nor in velocity
    np.testing.assert_allclose(np.max(np.abs(V), axis=0), cruise * np.abs(x1 - x0) / T, rtol=1e-3)


@pytest.fixture
def gambit(chess_description):
    s = chess_description.trajectory.parameters
    return WaypointTrajectory(s["waypoints"], s["durations"], s["pause"], s["cruise_factor"],
                              s["grip_close_after_move"], s["grip_open_after_move"])


def test_description_holds_the_scenario(chess_description):
    assert chess_description.trajectory.kind == "waypoints"
    assert sorted(chess_description.trajectory.parameters) == [
        "cruise_factor", "durations", "grip_close_after_move", "grip_open_after_move", "pause", "waypoints"]
    s = chess_description.trajectory.parameters
    assert (s["pause"], s["cruise_factor"]) == (0.5, 1.5)
    assert (s["grip_close_after_move"], s["grip_open_after_move"]) == (3, 6)


def test_scenario_timeline(gambit, chess_description):
    assert gambit.duration == pytest.approx(13.0)
    ends = np.cumsum([1, 3, 1, 1, 2, 1, 1]) + 0.5 * np.arange(7)
    np.testing.assert_allclose(gambit.move_ends, ends)
    waypoints = np.array(chess_description.trajectory.parameters["waypoints"])
    for k, t_end in enumerate(ends):
        x, xd, xdd = gambit.evaluate(t_end)
        np.testing.assert_allclose(x, waypoints[k + 1], atol=1e-15)
        np.testing.assert_allclose(xd, 0.0, atol=1e-14)
        # at rest during the following pause
        if k < 6:
            x, xd, _ = gambit.evaluate(t_end + 0.25)
            np.testing.assert_allclose(x, waypoints[k + 1])
            np.testing.assert_allclose(xd, 0.0)
    np.testing.assert_allclose(gambit.evaluate(-1.0)[0], waypoints[0])
    np.testing.assert_allclose(gambit.evaluate(20.0)[0], waypoints[-1])
    # d2 and d4 on the board: files a..h at (-3.5..3.5)*0.06, ranks at 0.12 + (0..7)*0.06
    d2 = (-0.5 * 0.06, 0.12 + 1 * 0.06)
    d4 = (-0.5 * 0.06, 0.12 + 3 * 0.06)
    np.testing.assert_allclose(gambit.evaluate(6.0)[0], [*d2, 0.05], atol=1e-15)
    np.testing.assert_allclose(gambit.evaluate(11.5)[0], [*d4, 0.05], atol=1e-15)


def test_second_move_numbers(gambit):
    # move 2: (0.21, 0, 0.15) -> (-0.03, 0.18, 0.15) in 3 s starting at 1.5 s
    a = 4.5 * np.array([-0.24, 0.18, 0.0]) / 9.0
    x, xd, xdd = gambit.evaluate(1.5 + 0.5)
    np.testing.assert_allclose(xdd, a, atol=1e-15)
    np.testing.assert_allclose(x, [0.21 + 0.5 * a[0] * 0.25, 0.5 * a[1] * 0.25, 0.15], atol=1e-15)
    _, xd, _ = gambit.evaluate(1.5 + 1.5)
    np.testing.assert_allclose(xd, 1.5 * np.array([-0.24, 0.18, 0.0]) / 3.0, atol=1e-15)


def test_breakpoints_reached_by_rounding_evaluate_as_the_exact_instant(gambit):
    # move 2 runs 1.5 .. 4.5 s with blends of 1 s: 3.5 s is the start of its deceleration
    h = 5e-4
    t = h * 6999 + h                           # a master's t_k + h: 3.5000000000000004
    assert t != 3.5
    for a, b in zip(gambit.evaluate(t), gambit.evaluate(3.5)):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(gambit.evaluate(3.5)[2], 0.0)               # still cruising
    assert gambit.evaluate(3.5 + 1e-6)[2][0] > 0.0                             # decelerating
    assert 3.5 in gambit.breakpoints and 2.5 in gambit.breakpoints and 13.0 in gambit.breakpoints


def test_grip_signal(gambit):
    assert not gambit.grip(5.999)
    assert gambit.grip(6.0) and gambit.grip(6.0 - 1e-12)    # communication points land by rounding
    assert gambit.grip(11.49)
    assert not gambit.grip(11.5) and not gambit.grip(13.0)


@pytest.mark.parametrize("kwargs, message", [
    (dict(waypoints=[[0, 0, 0]], durations=[]), "waypoints"),
    (dict(waypoints=[[0, 0, 0], [1, 1, 1]], durations=[1, 2]), "durations"),
    (dict(waypoints=[[0, 0, 0], [1, 1, 1]], durations=[0.0]), "durations"),
    (dict(waypoints=[[0, 0, 0], [1, 1, 1], [2, 2, 2]], durations=[1.0, -1.0]), "durations"),
    (dict(waypoints=[[0, 0, 0], [1, 1, np.nan]], durations=[1.0]), "waypoints"),
    (dict(waypoints=[[0, 0, 0], [1, 1, 1]], durations=[1.0], pause=-0.5), "pause"),
    (dict(waypoints=[[0, 0, 0], [1, 1, 1]], durations=[1.0], cruise_factor=1.0), "cruise_factor"),
    (dict(waypoints=[[0, 0, 0], [1, 1, 1]], durations=[1.0], cruise_factor=2.5), "cruise_factor"),
    (dict(waypoints=[[0, 0, 0], [1, 1, 1]], durations=[1.0], grip_close_after_move=2), "grip_close_after_move"),
])
def test_invalid_trajectory_names_the_argument(kwargs, message):
    with pytest.raises(ValueError, match=message):
        WaypointTrajectory(**kwargs)


def test_parse_round_trip_and_errors():
    rows = [[0.21, 0.0, 0.0], [-0.03, 0.18, 0.15]]
    np.testing.assert_array_equal(parse_matrix(format_matrix(rows), "w", columns=3), rows)
    np.testing.assert_array_equal(parse_vector("1, 3 1", "d"), [1, 3, 1])
    durations = [1.0, 0.1, 1 / 3]
    np.testing.assert_array_equal(parse_vector(format_vector(durations), "d"), durations)   # exact
    with pytest.raises(ValueError, match="waypoints: malformed"):
        parse_matrix("0 0 zero; 1 1 1", "waypoints")
    with pytest.raises(ValueError, match="waypoints: rows must"):
        parse_matrix("0 0 0; 1 1", "waypoints")
    with pytest.raises(ValueError, match="needs 3 values"):
        parse_matrix("0 0; 1 1", "waypoints", columns=3)
    with pytest.raises(ValueError, match="durations: empty"):
        parse_vector("  ", "durations")

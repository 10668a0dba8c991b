"""LSPB profiles and the queen's-gambit waypoint trajectory, against closed forms."""
import numpy as np
import pytest

from robofmu.components.blocks.text import format_matrix, format_vector, parse_matrix, parse_vector
from robofmu.components.time_law import lspb
from robofmu.components.trajectory import WaypointTrajectory


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


# -- parameters whose profile overflows: refused naming the parameters and why --------------------
from robofmu.components.trajectory import Circle, StraightLine, SynchronizedBangBang  # noqa: E402

LINE = dict(start=[0.125, 0.0, 0.125], direction=[0.0, 0.0, -1.0], length=0.03125, v_max=0.016, a_max=0.0375)
CIRCLE = dict(center=[0.0, 0.0], radius=0.05, start_angle=0.0, sense=1, duration=4.0)


@pytest.mark.parametrize("make, message", [
    (lambda: WaypointTrajectory([[0, 0, 0], [0.1, 0, 0]], [1e-300]),
     "durations: move 1 takes 1e-300 s, too short for waypoints rows 1 to 2 (coordinate 1 changes by 0.1): its "
     "acceleration would be inf (not finite); give move 1 more time (durations) or bring the waypoints closer"),
    (lambda: WaypointTrajectory([[0, 0, 0], [1e300, 0, 0], [-1e300, 0, 0]], [1.0, 1e-10]),
     "durations: move 2 takes 1e-10 s, too short for waypoints rows 2 to 3 (coordinate 1 changes by -2e+300): its "
     "cruise speed would be -inf (not finite)"),
    (lambda: WaypointTrajectory([[1e308, 0, 0], [-1e308, 0, 0]], [1.0]),
     "waypoints: rows 1 and 2 are too far apart: coordinate 1 goes from 1e+308 to -1e+308, a change of -inf "
     "(beyond the largest float); bring the waypoints closer"),
    (lambda: WaypointTrajectory([[0, 0, 0], [1, 0, 0], [0, 0, 0]], [1e308, 1e308]),
     "durations, pause: the moves (inf s in all) and pauses (0 s each) add up to inf s, beyond the largest float"),
    (lambda: WaypointTrajectory([[0, 0, 0], [1, 0, 0], [0, 0, 0]], [1e300, 1.0]),
     "durations: move 2 of 1 s starts at t = 1e+300 s, where so short a time is lost in rounding"),
    (lambda: WaypointTrajectory([[0, 0, 0], [1, 0, 0], [0, 0, 0]], [1.0, 1.0], pause=1e308),
     "durations: move 2 of 1 s starts at t = 1e+308 s, where so short a time is lost in rounding (the earlier "
     "durations and pauses are too long beside it)"),
    (lambda: StraightLine(**{**LINE, "length": 1e308, "v_max": 1e-300, "a_max": 1.0}),
     "length = 1e+308 m, v_max = 1e-300 m/s, a_max = 1 m/s2: the line would take inf s (ramps of 1e-300 s, peak "
     "speed 1e-300 m/s), not finite; give a shorter length or larger v_max and a_max"),
    (lambda: StraightLine(**{**LINE, "length": 1e300, "v_max": 1e300, "a_max": 1e-300}),
     "length = 1e+300 m, v_max = 1e+300 m/s, a_max = 1e-300 m/s2: the line would take inf s (ramps of inf s"),
    (lambda: StraightLine(**{**LINE, "start": [0.0, 0.0, -1.7e308], "length": 1e308, "v_max": 1e300,
                              "a_max": 1e300}),
     "start[3] = -1.7e+308 and length = 1e+308 m: the end point's coordinate 3 would be -inf (beyond the largest "
     "float)"),
    (lambda: SynchronizedBangBang([0.0, -1e308], [1.0, 1e308], [1.0, 1.0]),
     "q_start[2] = -1e+308 and q_end[2] = 1e+308 are too far apart: joint 2's move would be inf (beyond the largest "
     "float)"),
    (lambda: SynchronizedBangBang([0.0, 0.0], [1.0, 1e10], [1.0, 1e-300]),
     "a_max[2] = 1e-300 is too small for joint 2's move of 1e+10 (q_start[2] to q_end[2]): it would take inf s "
     "(not finite)"),
    (lambda: Circle(**{**CIRCLE, "duration": 1e-300}),
     "duration = 1e-300 s is too short: once round the circle in it, the phase's acceleration would be inf rad/s2 "
     "(not finite); give a longer duration"),
    (lambda: Circle(**{**CIRCLE, "radius": 1e308}),
     "radius = 1e+308 m and duration = 4 s: the reference's peak speed would be inf (not finite); give a smaller "
     "radius or a longer duration"),
    (lambda: Circle(**{**CIRCLE, "center": [1.79e308, 0.0], "radius": 1e307, "duration": 1e10}),
     "center[1] = 1.79e+308 and radius = 1e+307 m: the circle reaches beyond the largest float"),
    (lambda: Circle(**{**CIRCLE, "duration": 1.0}, offset=[0.5], amplitude=[1e308]),
     "offset[1] = 0.5, amplitude[1] = 1e+308 and duration = 1 s: task coordinate 3 would reach 1e+308, speed inf, "
     "acceleration inf (not finite)"),
], ids=["lspb-tiny-duration", "lspb-huge-waypoints-short-move", "lspb-waypoints-too-far-apart", "lspb-total-inf",
        "lspb-move-lost-in-rounding", "lspb-pause-huge", "line-inf-duration", "line-inf-ramps", "line-end-overflows",
        "bangbang-huge-positions", "bangbang-tiny-a_max", "circle-tiny-duration", "circle-huge-radius",
        "circle-huge-center", "circle-huge-amplitude"])
def test_overflowing_profile_is_refused_naming_the_parameters(make, message):
    with np.errstate(all="raise"):              # and quietly: no floating-point warning on the way
        with pytest.raises(ValueError) as info:
            make()
    assert message in str(info.value)


def test_extreme_but_finite_profiles_are_accepted_with_the_right_numbers():
    """Overflow in an intermediate is not an overflow of the profile: these are finite, and their
    numbers are right (the first two raised OverflowError, the third gave a zero direction)."""
    line = StraightLine(**{**LINE, "v_max": 1e300})          # v_max^2 overflows: never reached (triangular)
    assert line.duration == 2.0 * np.sqrt(0.03125 / 0.0375) and line.v_peak == pytest.approx(np.sqrt(0.03125 * 0.0375))
    bang = SynchronizedBangBang([0.0], [1.7e308], [1.0])     # T^2 overflows
    assert bang.duration == pytest.approx(2.0 * np.sqrt(1.7e308), rel=1e-15)
    np.testing.assert_allclose(bang.acceleration, [1.0], rtol=1e-12)
    q, qd, qdd = bang.evaluate(bang.switch_time)
    np.testing.assert_allclose(q, [0.85e308], rtol=1e-12)        # half way, at the switch: decelerating
    np.testing.assert_allclose(qd, [np.sqrt(1.7e308)], rtol=1e-12)
    np.testing.assert_allclose(qdd, [-1.0], rtol=1e-12)
    for direction, unit in (([1e308, 1e308, 0.0], [np.sqrt(0.5), np.sqrt(0.5), 0.0]), ([1e-320, 0.0, 0.0], [1.0, 0, 0])):
        line = StraightLine(**{**LINE, "direction": direction})
        np.testing.assert_allclose(line.direction, unit, rtol=1e-15)
        np.testing.assert_allclose(line.end, np.array(LINE["start"]) + 0.03125 * np.array(unit), rtol=1e-15)

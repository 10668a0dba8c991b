"""The pose profiles: PoseLine (straight line + slerp on one LSPB or minimum-time trapezoid time
law) and PoseWaypoints (one such move per leg), against scipy's Slerp, closed forms, finite
differences and their end poses."""
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from robofmu.components.pose_trajectory import PoseLine, PoseWaypoints
from robofmu.components.time_law import lspb

#: The ur5-like case: tool z pointing down, turned a quarter about its own z on the way.
UR5_QUATERNION = Rotation.from_matrix([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]).as_quat()
UR5 = dict(start=[0.4, -0.1, 0.3], displacement=[-0.15, 0.20, -0.10], start_quaternion=UR5_QUATERNION,
           rotation=[0.0, 0.0, math.pi / 2], duration=2.0)


def random_cases(n=4, seed=20240611):
    """``n`` pose moves with random start orientations and rotations (angle up to pi), the
    ur5-like one first."""
    rng = np.random.default_rng(seed)
    cases = [(UR5, 1.5)]
    for k in range(n):
        axis = rng.normal(size=3)
        angle = rng.uniform(0.1, math.pi) if k else math.pi          # one exactly half a turn
        cases.append((dict(start=rng.normal(size=3), displacement=rng.normal(size=3),
                           start_quaternion=Rotation.random(random_state=rng).as_quat(),
                           rotation=angle * axis / np.linalg.norm(axis), duration=rng.uniform(0.5, 3.0)),
                      [1.2, 1.5, 2.0, 1.7][k % 4]))
    return cases


CASES = random_cases()
IDS = ["ur5"] + [f"random{k}" for k in range(len(CASES) - 1)]


def angle_between(qa, qb) -> float:
    """The angle (rad) of R_a^T R_b, the rotations of quaternions (x, y, z, w)."""
    return float(np.linalg.norm((Rotation.from_quat(qa).inv() * Rotation.from_quat(qb)).as_rotvec()))


@pytest.mark.parametrize("case, cruise", CASES, ids=IDS)
def test_orientation_is_scipy_slerp_on_the_lspb_time_law(case, cruise):
    line = PoseLine(**case, cruise_factor=cruise)
    T = case["duration"]
    r0 = Rotation.from_quat(case["start_quaternion"])
    r1 = r0 * Rotation.from_rotvec(case["rotation"])                 # rotation in the tool frame
    slerp = Slerp([0.0, 1.0], Rotation.concatenate([r0, r1]))
    ts = np.concatenate([np.linspace(0.0, T, 201), np.random.default_rng(7).uniform(0.0, T, 50)])
    for t in ts:
        s = lspb(np.zeros(1), np.ones(1), T, t, cruise)[0][0]
        x, _, _, q, _, _ = line.evaluate(t)
        assert angle_between(q, slerp([s]).as_quat()[0]) < 1e-12, t
        np.testing.assert_allclose(x, np.asarray(case["start"]) + s * np.asarray(case["displacement"]),
                                   rtol=0, atol=1e-15)


def test_ur5_case_quarter_turn_about_the_tool_axis():
    """The tool turns about its own z (pointing down in the world): omega is along world -z, and
    half way (in s) the orientation is R0 Rz(pi/4)."""
    line = PoseLine(**UR5)
    np.testing.assert_allclose(line.world_rotation, [0.0, 0.0, -math.pi / 2], atol=1e-15)
    _, _, _, q, omega, _ = line.evaluate(1.0)                          # s = 1/2 at T/2 (symmetric LSPB)
    expected = Rotation.from_quat(UR5_QUATERNION) * Rotation.from_rotvec([0.0, 0.0, math.pi / 4])
    assert angle_between(q, expected.as_quat()) < 1e-12
    # cruising: s' = 1.5 / T = 0.75 /s
    np.testing.assert_allclose(omega, [0.0, 0.0, -0.75 * math.pi / 2], atol=1e-15)


def assert_rates_match_central_differences(profile, t: float, h: float) -> None:
    """The profile's velocity, acceleration, angular velocity and acceleration at ``t`` against
    central differences of its position, velocity, orientation and angular velocity (step ``h``),
    to 1e-8 (see test_rates_match_finite_differences)."""
    _, xd, xdd, _, omega, omegad = profile.evaluate(t, snap=False)
    x_p, xd_p, _, q_p, w_p, _ = profile.evaluate(t + h, snap=False)
    x_m, xd_m, _, q_m, w_m, _ = profile.evaluate(t - h, snap=False)
    np.testing.assert_allclose((x_p - x_m) / (2 * h), xd, rtol=0, atol=1e-8)
    np.testing.assert_allclose((xd_p - xd_m) / (2 * h), xdd, rtol=0, atol=1e-8)
    world = (Rotation.from_quat(q_p) * Rotation.from_quat(q_m).inv()).as_rotvec() / (2 * h)
    np.testing.assert_allclose(world, omega, rtol=0, atol=1e-8)
    np.testing.assert_allclose((w_p - w_m) / (2 * h), omegad, rtol=0, atol=1e-8)


@pytest.mark.parametrize("case, cruise", CASES, ids=IDS)
def test_rates_match_finite_differences(case, cruise):
    # Within one LSPB piece s(t) is a quadratic, so p, s' d, R0 Exp(s r) composed as
    # R(t+h) R(t-h)^T = Exp((s(t+h) - s(t-h)) R0 r) and s'' d make central differences exact
    # up to rounding: about eps |value| / h (1e-16 / 1e-5 = 1e-11). 1e-8 leaves margin and
    # would still catch a wrong factor, sign or frame (those err by O(1)).
    line = PoseLine(**case, cruise_factor=cruise)
    T, h = case["duration"], 1e-5
    ts = [t for t in np.linspace(0.0, T, 97)[1:-1] if np.min(np.abs(line.breakpoints - t)) > 2 * h]
    assert len(ts) > 80
    for t in ts:
        assert_rates_match_central_differences(line, t, h)


@pytest.mark.parametrize("case, cruise", CASES, ids=IDS)
def test_rests_at_the_start_before_zero_and_at_the_end_from_duration_on(case, cruise):
    line = PoseLine(**case, cruise_factor=cruise)
    T = case["duration"]
    q0 = np.asarray(case["start_quaternion"]) / np.linalg.norm(case["start_quaternion"])
    end_rotation = Rotation.from_quat(q0) * Rotation.from_rotvec(case["rotation"])
    for t in (T, T + 1e-12, T + 0.5, 10 * T):
        x, xd, xdd, q, omega, omegad = line.evaluate(t)
        np.testing.assert_allclose(x, np.asarray(case["start"]) + case["displacement"], rtol=0, atol=1e-15)
        assert angle_between(q, end_rotation.as_quat()) < 1e-12
        for rate in (xd, xdd, omega, omegad):
            assert np.array_equal(rate, np.zeros(3))
    for t in (-1e-3, -1.0, -100.0):
        x, xd, xdd, q, omega, omegad = line.evaluate(t)
        assert np.array_equal(x, np.asarray(case["start"], dtype=float))
        np.testing.assert_allclose(q, q0, rtol=0, atol=1e-16)
        for rate in (xd, xdd, omega, omegad):
            assert np.array_equal(rate, np.zeros(3))


@pytest.mark.parametrize("case, cruise", CASES, ids=IDS)
def test_quaternion_stays_unit_and_never_flips_sign(case, cruise):
    line = PoseLine(**case, cruise_factor=cruise)
    T = case["duration"]
    qs = np.array([line.evaluate(t)[3] for t in np.linspace(-0.1, T + 0.1, 2001)])
    np.testing.assert_allclose(np.linalg.norm(qs, axis=1), 1.0, rtol=0, atol=1e-15)
    assert np.all(np.einsum("ij,ij->i", qs[1:], qs[:-1]) > 0.0)
    q0 = np.asarray(case["start_quaternion"]) / np.linalg.norm(case["start_quaternion"])
    np.testing.assert_allclose(line.evaluate(0.0)[3], q0, rtol=0, atol=1e-16)   # starts at q0, not -q0


def test_breakpoints_snap_and_evaluate_into():
    line = PoseLine(**UR5)                                              # T = 2, tb = T / 3
    np.testing.assert_allclose(line.breakpoints, [0.0, 2 / 3, 4 / 3, 2.0], rtol=0, atol=1e-15)
    assert line.dim == 3 and line.duration == 2.0
    # at the start instant it already accelerates: s'' = 4.5 / T^2
    np.testing.assert_allclose(line.evaluate(0.0)[2], 4.5 / 4 * np.asarray(UR5["displacement"]), atol=1e-15)
    # within 1e-9 s of the end it is the end (snapped); without snap, still moving
    assert np.array_equal(line.evaluate(2.0 - 1e-10)[1], np.zeros(3))
    assert np.any(line.evaluate(2.0 - 1e-10, snap=False)[2] != 0.0)
    # evaluate_into fills given arrays with the same numbers
    out = [np.full(3, np.nan), np.full(3, np.nan), np.full(3, np.nan), np.full(4, np.nan),
           np.full(3, np.nan), np.full(3, np.nan)]
    for t in (-1.0, 0.3, 1.0, 1.7, 2.5):
        line.evaluate_into(t, *out)
        for got, expected in zip(out, line.evaluate(t)):
            assert np.array_equal(got, expected)


def test_zero_rotation_and_zero_displacement_give_a_constant_pose():
    q0 = Rotation.from_rotvec([0.3, -0.2, 0.9]).as_quat()
    line = PoseLine([0.1, 0.2, 0.3], np.zeros(3), q0, np.zeros(3), 1.5)
    for t in np.linspace(-0.5, 2.0, 101):
        x, xd, xdd, q, omega, omegad = line.evaluate(t)
        assert np.all(np.isfinite(np.concatenate([x, xd, xdd, q, omega, omegad])))
        assert np.array_equal(x, [0.1, 0.2, 0.3])
        np.testing.assert_allclose(q, q0, rtol=0, atol=1e-16)
        for rate in (xd, xdd, omega, omegad):
            assert np.array_equal(rate, np.zeros(3))


def test_quaternion_is_normalised_within_tolerance():
    q0 = Rotation.from_rotvec([0.0, 0.5, 0.0]).as_quat()
    line = PoseLine(np.zeros(3), np.zeros(3), q0 * (1 + 5e-7), np.zeros(3), 1.0)
    assert np.linalg.norm(line.start_quaternion) == pytest.approx(1.0, abs=1e-15)


@pytest.mark.parametrize("change, message", [
    (dict(start_quaternion=[0.0, 0.0, 0.0, 1.5]), r"start_quaternion: must be a unit quaternion.*norm 1\.5"),
    (dict(start_quaternion=[0.0, 0.0, 0.0, 0.0]), r"start_quaternion: .*norm 0"),
    (dict(start_quaternion=[0.0, 0.0, np.nan, 1.0]), r"start_quaternion: every value must be finite"),
    (dict(start_quaternion=[0.0, 0.0, 1.0]), r"start_quaternion: need 4 values"),
    (dict(rotation=[0.0, 3.5, 0.0]), r"rotation: its angle \|rotation\| = 3\.5 rad exceeds pi; give the shortest"),
    (dict(rotation=[0.0, 0.0, np.inf]), r"rotation: every value must be finite"),
    (dict(duration=0.0), r"duration: must be > 0 s, got 0"),
    (dict(duration=1e-310), r"duration = 1e-310 s is too short"),
    (dict(cruise_factor=2.5), r"cruise_factor: must lie in \(1, 2\], got 2\.5"),
    (dict(displacement=[1.0, 2.0]), r"displacement: need 3 values"),
    (dict(displacement=[1e308, 0.0, 0.0], start=[1e308, 0.0, 0.0]), r"start\[1\] = 1e\+308 and displacement\[1\]"),
])
def test_refusals_name_the_parameter(change, message):
    with pytest.raises(ValueError, match=message):
        PoseLine(**{**UR5, "cruise_factor": 1.5, **change})


def test_half_turn_is_accepted():
    line = PoseLine(**{**UR5, "rotation": [math.pi, 0.0, 0.0]})
    end = Rotation.from_quat(UR5_QUATERNION) * Rotation.from_rotvec([math.pi, 0.0, 0.0])
    assert angle_between(line.evaluate(2.0)[3], end.as_quat()) < 1e-12


# --- the minimum-time trapezoid time law ---------------------------------------------------

LIMITED = dict(start=[0.4, -0.1, 0.3], displacement=[-0.15, 0.20, -0.10], start_quaternion=UR5_QUATERNION,
               rotation=[0.0, 0.0, math.pi / 2])
#: (v_max, a_max, omega_max, alpha_max): which limit binds the rate and the acceleration of s.
LIMIT_CASES = {"linear binds": (0.1, 0.4, 5.0, 20.0), "angular binds": (5.0, 20.0, 0.5, 1.0),
               "triangle": (1.0, 0.2, 9.0, 9.0), "mixed": (0.1, 5.0, 5.0, 1.0)}


def minimum_time(distance, angle, v_max, a_max, omega_max, alpha_max):
    """The closed form: s from 0 to 1 at rate <= min(v/|d|, w/|r|), |s''| <= min(a/|d|, alpha/|r|)."""
    rate = min(v_max / distance, omega_max / angle)
    acceleration = min(a_max / distance, alpha_max / angle)
    if rate * rate / acceleration <= 1.0:
        return 1.0 / rate + rate / acceleration, rate / acceleration
    return 2.0 * math.sqrt(1.0 / acceleration), math.sqrt(1.0 / acceleration)


@pytest.mark.parametrize("limits", LIMIT_CASES.values(), ids=LIMIT_CASES)
def test_minimum_time_move_keeps_every_limit_and_reaches_the_binding_ones(limits):
    v_max, a_max, omega_max, alpha_max = limits
    line = PoseLine(**LIMITED, v_max=v_max, a_max=a_max, omega_max=omega_max, alpha_max=alpha_max)
    distance, angle = np.linalg.norm(LIMITED["displacement"]), math.pi / 2
    T, ramp = minimum_time(distance, angle, *limits)
    assert line.duration == pytest.approx(T, rel=1e-14)
    np.testing.assert_allclose(line.breakpoints, np.unique([0.0, ramp, T - ramp, T]), rtol=1e-14, atol=1e-15)
    samples = [line.evaluate(t) for t in np.linspace(0.0, T, 4001)]
    speed = max(np.linalg.norm(v[1]) for v in samples)
    acceleration = max(np.linalg.norm(v[2]) for v in samples)
    turn = max(np.linalg.norm(v[4]) for v in samples)
    turn_acceleration = max(np.linalg.norm(v[5]) for v in samples)
    tight = 1.0 + 1e-12
    assert speed <= v_max * tight and turn <= omega_max * tight
    assert acceleration <= a_max * tight and turn_acceleration <= alpha_max * tight
    # minimum time: one limit of each order is reached (the rate's only if the move cruises)
    assert max(acceleration / a_max, turn_acceleration / alpha_max) == pytest.approx(1.0, rel=1e-12)
    if 2 * ramp < T:
        assert max(speed / v_max, turn / omega_max) == pytest.approx(1.0, rel=1e-12)


@pytest.mark.parametrize("limits", LIMIT_CASES.values(), ids=LIMIT_CASES)
def test_minimum_time_move_is_a_slerp_and_its_rates_match_finite_differences(limits):
    v_max, a_max, omega_max, alpha_max = limits
    line = PoseLine(**LIMITED, v_max=v_max, a_max=a_max, omega_max=omega_max, alpha_max=alpha_max)
    r0 = Rotation.from_quat(LIMITED["start_quaternion"])
    slerp = Slerp([0.0, 1.0], Rotation.concatenate([r0, r0 * Rotation.from_rotvec(LIMITED["rotation"])]))
    d = np.asarray(LIMITED["displacement"])
    h = 1e-5
    for t in np.linspace(0.0, line.duration, 61)[1:-1]:
        if np.min(np.abs(line.breakpoints - t)) < 2 * h:
            continue
        x, _, _, q, _, _ = line.evaluate(t, snap=False)
        s = float(np.dot(x - LIMITED["start"], d) / np.dot(d, d))     # the position says where on the line
        np.testing.assert_allclose(x, np.asarray(LIMITED["start"]) + s * d, rtol=0, atol=1e-15)
        assert angle_between(q, slerp([s]).as_quat()[0]) < 1e-12
        assert_rates_match_central_differences(line, t, h)


def test_a_pure_rotation_or_pure_translation_at_minimum_time():
    turn = PoseLine(**{**LIMITED, "displacement": [0.0, 0.0, 0.0]}, v_max=1e-3, a_max=1e-3, omega_max=1.0,
                    alpha_max=2.0)
    assert turn.duration == pytest.approx(minimum_time(1.0, math.pi / 2, 1e9, 1e9, 1.0, 2.0)[0], rel=1e-14)
    slide = PoseLine(**{**LIMITED, "rotation": [0.0, 0.0, 0.0]}, v_max=0.1, a_max=0.5, omega_max=1e-3,
                     alpha_max=1e-3)
    distance = float(np.linalg.norm(LIMITED["displacement"]))
    assert slide.duration == pytest.approx(minimum_time(distance, 1.0, 0.1, 0.5, 1e9, 1e9)[0], rel=1e-14)


@pytest.mark.parametrize("change, message", [
    (dict(duration=2.0, v_max=0.1), r"give either duration .* or the limits v_max, a_max, omega_max, alpha_max.*"
                                    r"got duration and v_max"),
    (dict(v_max=0.1, a_max=0.4), r"missing: omega_max, alpha_max"),
    (dict(v_max=0.1, a_max=0.4, omega_max=-1.0, alpha_max=1.0), r"omega_max: must be > 0 rad/s, got -1"),
    (dict(v_max=0.1, a_max=0.4, omega_max=1.0, alpha_max=1.0, displacement=[0, 0, 0], rotation=[0, 0, 0]),
     r"displacement and rotation are both zero"),
])
def test_minimum_time_refusals_name_the_parameters(change, message):
    with pytest.raises(ValueError, match=message):
        PoseLine(**{**LIMITED, **change})


# --- pose waypoints ------------------------------------------------------------------------

def pose_rows(seed=5, count=4):
    """``count`` poses: random origins and orientations, every other quaternion given with the
    opposite sign (the same rotation)."""
    rng = np.random.default_rng(seed)
    rows = []
    for k in range(count):
        quaternion = Rotation.random(random_state=rng).as_quat() * (-1.0 if k % 2 else 1.0)
        rows.append([*rng.uniform(-0.5, 0.5, 3), *quaternion])
    return np.array(rows)


ROWS = pose_rows()
DURATIONS = [1.0, 1.5, 0.8]


@pytest.mark.parametrize("pause", [0.0, 0.4])
def test_each_leg_is_a_line_and_scipys_slerp_on_its_lspb_law_with_rests_between(pause):
    profile = PoseWaypoints(ROWS, DURATIONS, pause=pause, cruise_factor=1.6)
    starts = np.concatenate([[0.0], np.cumsum(np.array(DURATIONS) + pause)[:-1]])
    assert profile.duration == pytest.approx(sum(DURATIONS) + 2 * pause, abs=1e-15)
    for i, (t0, T) in enumerate(zip(starts, DURATIONS)):
        rotations = Rotation.from_quat(ROWS[i:i + 2, 3:])                # scipy's slerp: the shortest rotation
        slerp = Slerp([0.0, 1.0], rotations)
        for u in np.linspace(0.0, T, 41)[:-1]:
            s = float(lspb(np.zeros(1), np.ones(1), T, u, 1.6)[0][0])
            x, _, _, q, _, _ = profile.evaluate(t0 + u, snap=False)
            np.testing.assert_allclose(x, ROWS[i, :3] + s * (ROWS[i + 1, :3] - ROWS[i, :3]), rtol=0, atol=1e-14)
            assert angle_between(q, slerp([s]).as_quat()[0]) < 1e-12, (i, u)
        if pause and i < len(DURATIONS) - 1:                             # at rest at the next pose during the pause
            for u in np.linspace(T, T + pause, 7)[:-1]:
                x, xd, xdd, q, omega, omegad = profile.evaluate(t0 + u)
                np.testing.assert_allclose(x, ROWS[i + 1, :3], rtol=0, atol=1e-15)
                assert angle_between(q, ROWS[i + 1, 3:]) < 1e-12
                assert not np.any(np.concatenate([xd, xdd, omega, omegad]))


def test_waypoint_rates_match_finite_differences_and_the_quaternion_never_flips():
    profile = PoseWaypoints(ROWS, DURATIONS, pause=0.3)
    h = 1e-5
    times = np.linspace(-0.2, profile.duration + 0.2, 1501)
    quaternions = np.array([profile.evaluate(t)[3] for t in times])
    assert np.all(np.einsum("ij,ij->i", quaternions[1:], quaternions[:-1]) > 0.0)   # rows' signs alternate
    np.testing.assert_allclose(np.linalg.norm(quaternions, axis=1), 1.0, rtol=0, atol=1e-15)
    checked = 0
    for t in times[::5]:
        if np.min(np.abs(profile.breakpoints - t)) < 2 * h:
            continue
        assert_rates_match_central_differences(profile, t, h)
        checked += 1
    assert checked > 250


def test_waypoints_rest_at_their_first_and_last_pose_and_fill_given_arrays():
    profile = PoseWaypoints(ROWS, DURATIONS, pause=0.3)
    for t, row in ((-1.0, ROWS[0]), (0.0, ROWS[0]), (profile.duration, ROWS[-1]), (99.0, ROWS[-1])):
        x, xd, _, q, omega, _ = profile.evaluate(t)
        np.testing.assert_allclose(x, row[:3], rtol=0, atol=1e-15)
        assert angle_between(q, row[3:]) < 1e-12
        if t != 0.0:
            assert not np.any(xd) and not np.any(omega)
    out = [np.full(3, np.nan), np.full(3, np.nan), np.full(3, np.nan), np.full(4, np.nan),
           np.full(3, np.nan), np.full(3, np.nan)]
    for t in (-1.0, 0.5, 1.1, 1.3, 2.9, 99.0):
        profile.evaluate_into(t, *out)
        for got, expected in zip(out, profile.evaluate(t)):
            assert np.array_equal(got, expected)


@pytest.mark.parametrize("change, message", [
    (dict(waypoints=ROWS[:, :6]), r"waypoints: need at least two poses of 7 values \(x, y, z, qx, qy, qz, qw\)"),
    (dict(waypoints=ROWS[:1]), r"waypoints: need at least two poses"),
    (dict(waypoints=np.vstack([ROWS[:2], [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0]])),
     r"waypoints: row 3: the orientation quaternion .* has norm 2, not 1"),
    (dict(durations=[1.0, 1.0]), r"durations: need one duration per move \(3\), got 2"),
    (dict(durations=[1.0, 0.0, 1.0]), r"durations: every move must take a positive"),
    (dict(pause=-1.0), r"pause: must be >= 0 s"),
    (dict(cruise_factor=1.0), r"cruise_factor: must lie in \(1, 2\]"),
    (dict(waypoints=np.vstack([ROWS[:2], [1e308, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0], [-1e308, 0, 0, 0, 0, 0, 1]])),
     r"waypoints rows 2 to 3, durations\[2\] = 1\.5 s \(move 2\): displacement and duration = 1\.5 s: the peak "
     r"speed would be inf m/s"),
])
def test_waypoint_refusals_name_the_argument(change, message):
    given = {"waypoints": ROWS, "durations": DURATIONS, **change}
    with pytest.raises(ValueError, match=message):
        PoseWaypoints(**given)

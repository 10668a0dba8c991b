"""Limits told as they are (issue 28, point 6): the build's reference check refuses a velocity
excess as a velocity limit (the worst ratio over the whole path, its time, the limit and where it
is set, the time law that fits, which then passes), a position excursion by its deepest point, and
calls a singularity only a singularity."""
from __future__ import annotations

import math
import re
from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest

from robofmu.components.ik import make_solver
from robofmu.components.orientation import quaternion_of
from robofmu.components.pose_trajectory import PoseLine
from robofmu.components.preflight import ReferenceRefused, check_reference, check_references
from robofmu.components.robots import load_description, load_model
from robofmu.components.robots.description import read
from robofmu.components.trajectory import SynchronizedBangBang, slowed

from robot_files import independent_model, set_key

STEP = 1e-3
#: "... at worst 2.01 × the limit (4.37593 rad/s) at t = 0.267 s"
WORST = re.compile(r"at worst ([\d.e+-]+) × the limit \(([\d.e+-]+) (?:rad|m)/s\) at t = ([\d.e+-]+) s")
FIRST = re.compile(r"from t = ([\d.e+-]+) s")


def with_profile(description, **parameters):
    """The description with its reference's parameters changed (dataclasses.replace)."""
    given = {k: v for k, v in description.trajectory.parameters.items() if v is not None}
    given.update(parameters)
    given = {k: v for k, v in given.items() if v is not None}
    return replace(description, trajectory=replace(description.trajectory, parameters=given))


def named(description, profile: str):
    """The description whose reference is its named profile (as the build checks it)."""
    return description.block_of(f"trajectory_{profile}")[2]


def refusal(description, table: str = "trajectory", **check) -> str:
    with pytest.raises(ReferenceRefused) as info:
        check_reference(description, table=table, **check)
    text = info.value.args[0]
    assert "\n" not in text and text.startswith(f"{description.path}: {table}: "), text
    return text


def proposal(text: str, table: str) -> dict:
    """The parameters a velocity refusal proposes: ``give <table>.<key> = <value>, ...``."""
    given = text.split("give ", 1)[1]
    found = {}
    for key, value in re.findall(rf"{re.escape(table)}\.(\w+) = (\[[^\]]*\]|[\d.e+-]+)", given):
        found[key] = [float(v) for v in value.strip("[]").split(",")] if value.startswith("[") else float(value)
    assert found, text
    return found


def pose_path(description):
    """The pose_line of ``description`` solved by its IK solver at 1 ms (an own loop, not the
    build's): times, q (k, n), qd (k, n) and the smallest singular values the solver reports."""
    model = load_model(description)
    home = model.configuration("home")
    given = description.trajectory.parameters
    limits = {k: given[k] for k in ("duration", "v_max", "a_max", "omega_max", "alpha_max") if k in given}
    profile = PoseLine(model.fk(home), given["displacement"], quaternion_of(model.rotation(home)),
                       given["rotation"], **limits)
    solver, solution = make_solver(model), None
    times = np.arange(0.0, profile.duration + STEP / 2, STEP)
    q, qd, sigma = [], [], []
    for t in times:
        solver.start_from(*((None,) if solution is None else (*solution, STEP)))
        solution = solver.solve(*profile.evaluate(t))
        q.append(solution[0])
        qd.append(solution[1])
        sigma.append(solver.report["smallest_singular_value"])
    return times, np.array(q), np.array(qd), np.array(sigma)


def assert_worst(text: str, times, qd, speed, joint: int):
    """The message's worst ratio, its rate and time, and the first crossing are the samples'."""
    ratios = np.abs(qd) / speed
    k, j = np.unravel_index(np.argmax(ratios), ratios.shape)
    assert j == joint, (j, joint)
    ratio, rate, when = WORST.search(text).groups()
    assert float(ratio) == pytest.approx(ratios[k, j], rel=5e-3)
    assert rate == f"{abs(qd[k, j]):.6g}" and when == f"{times[k]:.6g}", text
    first = times[np.flatnonzero(ratios[:, j] > 1.0)[0]]
    assert FIRST.search(text).group(1) == f"{first:.6g}", text
    return ratios[k, j]


# -- the time law's scaling ------------------------------------------------------------------------
def test_slowed_scales_durations_up_and_limits_down_by_the_ratio_and_its_square():
    given = {"duration": 2.0, "durations": [1.0, 1.5], "v_max": 0.5, "a_max": [3.0, 0.2], "omega_max": 1.0,
             "alpha_max": 2.0, "pause": 0.5, "cruise_factor": 1.5, "displacement": [0.1, 0.0, 0.0]}
    # 1.34: 2.68 -> 2.7, 1.34 -> 1.4, 2.01 -> 2.1; 0.5 / 1.34 = 0.373 -> 0.37, 3 / 1.7956 = 1.67 -> 1.6,
    # 0.2 / 1.7956 = 0.1114 -> 0.11, 1 / 1.34 = 0.746 -> 0.74, 2 / 1.7956 = 1.114 -> 1.1
    assert slowed(given, 1.34) == {"duration": 2.7, "durations": [1.4, 2.1], "v_max": 0.37, "a_max": [1.6, 0.11],
                                   "omega_max": 0.74, "alpha_max": 1.1}
    assert slowed({"duration": 2.0}, 1.3) == {"duration": 2.6}            # exact: no rounding up beyond it
    assert slowed({"line": 1.0}, 2.0) == {}


# -- velocity limits -------------------------------------------------------------------------------
@pytest.mark.parametrize("robot, duration, joint", [("ur5", 0.5, 5), ("panda", 0.4, 3)])
def test_a_too_short_pose_line_is_refused_as_a_velocity_limit_and_the_duration_it_proposes_passes(
        robot, duration, joint):
    """The arm's pose line in a quarter of its time: the message names the joint, its URDF limit,
    the worst ratio over the whole path and its time (the IK's rates sampled here at 1 ms), and
    the shortest duration: duration x ratio; the duration it gives passes the check."""
    fast = with_profile(load_description(robot), duration=duration)
    model = load_model(fast)
    times, _, qd, sigma = pose_path(fast)
    speed = model.velocity_limits()
    text = refusal(fast)
    name = model.joint_names[joint]
    assert f"drives joint {joint + 1} ({name}) beyond its velocity limit {speed[joint]:.6g} rad/s (URDF) " in text
    assert "singular" not in text and sigma.min() > 0.02        # a healthy Jacobian: not a singularity
    ratio = assert_worst(text, times, qd, speed, joint)
    assert f"the shortest duration that fits is {duration * ratio:.3g} s" in text, text
    given = proposal(text, "trajectory")
    assert list(given) == ["duration"] and duration * ratio <= given["duration"] <= duration * ratio * 1.1
    found = check_reference(with_profile(fast, duration=given["duration"]))
    assert found.speed_ratio <= 1.0 and found.duration == given["duration"]


def test_the_square_arms_rates_are_the_jacobians_inverse_on_the_twist():
    """UR5 (6 joints, 6 task rows): the worst rate of the refusal is J^-1 (v, omega) of an
    independent Pinocchio model at the solved joints (LOCAL_WORLD_ALIGNED rows: world axes)."""
    fast = with_profile(load_description("ur5"), duration=0.5)
    model, frame = independent_model("ur5")
    data = model.createData()
    times, q, _, _ = pose_path(fast)
    given = fast.trajectory.parameters
    home = load_model("ur5").configuration("home")
    pin.framesForwardKinematics(model, data, np.array(home))
    start = data.oMf[frame]
    profile = PoseLine(start.translation.copy(), given["displacement"], quaternion_of(start.rotation.copy()),
                       given["rotation"], given["duration"])
    qd = []
    for t, joints in zip(times, q):
        _, v, _, _, omega, _ = profile.evaluate(t)
        J = pin.computeFrameJacobian(model, data, joints, frame, pin.LOCAL_WORLD_ALIGNED)
        qd.append(np.linalg.solve(J, np.concatenate([v, omega])))
    assert_worst(refusal(fast), times, np.array(qd), model.velocityLimit, 5)


def test_a_velocity_limit_of_the_toml_is_attributed_to_the_toml(copy_robot):
    """panda_joint4 limited to 0.5 rad/s by [joints.limits]: the refusal names that key, the
    worst ratio against 0.5 rad/s, and the duration it proposes passes."""
    path = copy_robot("panda", lambda d: set_key(d, "joints.limits", {"panda_joint4": {"velocity": 0.5}}))
    described = read(path)
    text = refusal(described)
    times, _, qd, _ = pose_path(described)
    speed = load_model(described).velocity_limits()
    assert speed[3] == 0.5
    assert "joint 4 (panda_joint4) beyond its velocity limit 0.5 rad/s (joints.limits.panda_joint4.velocity) " in text
    assert_worst(text, times, qd, speed, 3)
    given = proposal(text, "trajectory")
    assert check_reference(with_profile(described, **given)).speed_ratio <= 1.0


def test_a_pose_line_at_limits_too_high_gets_the_limits_divided_by_the_ratio_and_its_square():
    """UR5's line at minimum time under limits that drive the wrist too fast: the proposal divides
    v_max and omega_max by the worst ratio r and a_max, alpha_max by r^2 (rounded down), and passes."""
    limits = {"v_max": 1.0, "a_max": 5.0, "omega_max": 6.0, "alpha_max": 20.0}
    fast = with_profile(load_description("ur5"), duration=None, **limits)
    text = refusal(fast)
    times, _, qd, _ = pose_path(fast)
    ratio = assert_worst(text, times, qd, load_model(fast).velocity_limits(), 5)
    given = proposal(text, "trajectory")
    assert set(given) == set(limits)
    for key, value in given.items():
        power = 2 if key in ("a_max", "alpha_max") else 1
        assert 0.9 * limits[key] / ratio ** power <= value <= limits[key] / ratio ** power, key
    assert check_reference(with_profile(fast, **given)).speed_ratio <= 1.0


def test_a_joint_bangbang_too_fast_gets_its_accelerations_divided_by_the_ratio_squared():
    """UR5's joint-space profile with a_max 10 x its own: the worst ratio is the closed form's
    peak rate over the limit (to a sample), named with the profile's key; a_max / r^2 passes."""
    described = load_description("ur5")
    given = described.profiles["joint"].parameters
    fast = replace(described, profiles={**described.profiles, "joint": replace(
        described.profiles["joint"], parameters={**given, "a_max": [30.0] * 6})})
    profile = SynchronizedBangBang(given["q_start"], given["q_end"], [30.0] * 6)
    times = np.arange(0.0, profile.duration + STEP / 2, STEP)
    qd = np.array([profile.evaluate(t)[1] for t in times])
    with pytest.raises(ReferenceRefused) as info:
        check_references(fast)
    text = info.value.args[0]
    assert text.startswith(f"{described.path}: trajectories.joint: "), text
    speed = load_model(described).velocity_limits()
    ratio = assert_worst(text, times, qd, speed, int(np.argmax(np.abs(profile.peak_velocity) / speed)))
    peak = np.max(np.abs(profile.peak_velocity) / speed)        # at T / 2, between two samples
    assert peak * (1 - 2 * STEP / profile.duration) <= ratio <= peak
    a_max = proposal(text, "trajectories.joint")["a_max"]
    assert all(0.9 * 30.0 / ratio ** 2 <= a <= 30.0 / ratio ** 2 for a in a_max)
    assert check_reference(with_profile(named(fast, "joint"), a_max=a_max)).speed_ratio <= 1.0


def test_waypoints_too_fast_get_every_duration_scaled(copy_robot):
    """Panda's pose waypoints in a third of their times: every leg's duration scaled, and passes."""
    described = named(load_description("panda"), "waypoints")
    durations = [d / 3 for d in described.trajectory.parameters["durations"]]
    fast = with_profile(described, durations=durations)
    text = refusal(fast, table="trajectories.waypoints")
    ratio = float(WORST.search(text).group(1))
    given = proposal(text, "trajectories.waypoints")["durations"]
    assert all(d * ratio <= g <= d * ratio * 1.1 for d, g in zip(durations, given))
    assert check_reference(with_profile(fast, durations=given)).speed_ratio <= 1.0


def test_the_line_profile_gets_its_limits_scaled(copy_robot):
    """rrp's line (closed-form IK) at 100 x its speed and 10^4 x its acceleration: v_max / r and
    a_max / r^2 pass."""
    described = load_description("rrp")
    given = described.trajectory.parameters
    fast = with_profile(described, v_max=100 * given["v_max"], a_max=1e4 * given["a_max"])
    text = refusal(fast)
    assert "× the limit" in text and "singular" not in text
    scaled = proposal(text, "trajectory")
    assert set(scaled) == {"v_max", "a_max"}
    assert check_reference(with_profile(fast, **scaled)).speed_ratio <= 1.0


# -- position limits -------------------------------------------------------------------------------
def test_a_pose_path_beyond_a_position_limit_is_told_by_its_deepest_excursion(copy_robot):
    """UR5's wrist_1 limited halfway along its travel: the IK stops on the limit; the refusal
    gives the first sample beyond it and the deepest excursion with its time, from the path solved
    here (its URDF limits, 2 pi, never reached)."""
    described = load_description("ur5")
    times, q, _, _ = pose_path(described)
    model = load_model(described)
    home = np.array(model.configuration("home"))
    travel = q - home
    j = int(np.argmax(np.abs(travel).max(axis=0)))
    extreme = travel[np.argmax(np.abs(travel[:, j])), j]
    limit = float(home[j] + extreme / 2)
    side = "upper" if extreme > 0 else "lower"
    joint = model.joint_names[j]
    path = copy_robot("ur5", lambda d: set_key(d, "joints", {"limits": {joint: {side: limit}}}))
    text = refusal(read(path))
    depth = (q[:, j] - limit) if extreme > 0 else (limit - q[:, j])
    k = int(np.argmax(depth))
    first = times[np.flatnonzero(depth > 0)[0]]
    assert (f"drives joint {j + 1} ({joint}) beyond its {side} limit {limit:.6g} rad (joints.limits.{joint}.{side}) "
            f"from t = {first:.6g} s, at worst to {q[k, j]:.6g} rad ({depth[k]:.3g} rad beyond) at t = {times[k]:.6g} s"
            ) in text, text


# -- singularities ---------------------------------------------------------------------------------
@pytest.mark.parametrize("duration", [2.0, 0.3])
def test_a_path_into_the_wrist_singularity_is_called_a_singularity(duration):
    """UR5's tool moved to the pose of home with q5 = 0 (wrist axes 4 and 6 parallel): the IK's
    smallest singular value falls below singular_value on the way; the refusal says singularity,
    not velocity limit, also when the move is fast enough to break a velocity limit before it."""
    described = load_description("ur5")
    model = load_model(described)
    home = np.array(model.configuration("home"))
    singular = home.copy()
    singular[4] = 0.0
    rotation = pin.log3(model.rotation(home).T @ model.rotation(singular))
    toward = with_profile(described, displacement=(model.fk(singular) - model.fk(home)).tolist(),
                          rotation=rotation.tolist(), duration=duration)
    text = refusal(toward)
    assert "meets a singularity at t = " in text and "velocity limit" not in text, text
    q = np.array(json_list(text.rsplit("at q = ", 1)[1]))
    ref, frame = independent_model("ur5")
    J = pin.computeFrameJacobian(ref, ref.createData(), q, frame, pin.LOCAL_WORLD_ALIGNED)
    assert np.linalg.svd(J, compute_uv=False)[-1] < 0.02 + 1e-5


def json_list(text: str) -> list[float]:
    """The first bracketed list of numbers of ``text``."""
    return [float(v) for v in text[text.index("[") + 1:text.index("]")].split(",")]


def test_an_accepted_path_reports_its_fastest_joint_and_when():
    times, _, qd, _ = pose_path(load_description("ur5"))
    speed = load_model("ur5").velocity_limits()
    ratios = np.abs(qd) / speed
    k, j = np.unravel_index(np.argmax(ratios), ratios.shape)
    found = check_reference(load_description("ur5"))
    assert found.speed_ratio == pytest.approx(ratios[k, j], rel=1e-9)
    assert found.fastest_joint == load_model("ur5").joint_names[j] and math.isclose(found.fastest_time, times[k])


@pytest.mark.parametrize("axes, expected", [([0, 1], (0.5, 2)), ([1, 2], (0.3, 0)), ([0, 2], (0.2, 1)),
                                            ([0, 1, 2], None)])
def test_a_rotation_about_an_axis_the_task_leaves_free_is_told(copy_robot, axes, expected):
    """The UR5's pose line turning tool0 by the rotation vector (0.3, 0.2, 0.5) rad about its own
    axes (a slerp: the body angular velocity keeps that direction, so the turn about each axis is
    that component): a task that leaves an axis free gets the largest such turn named, with its
    axis, and ``robofmu build``'s check says so in a note; a full pose task has nothing to tell."""
    from robofmu.system.packaging.build import checked

    def edit(data):
        set_key(data, "task.orientation_axes", axes)
        set_key(data, "trajectory.rotation", [0.3, 0.2, 0.5])
    described = read(copy_robot("ur5", edit))
    found = check_reference(described)
    lines = []
    checked(described, log=lines.append)
    if expected is None:
        assert found.untracked is None and not any("note:" in line for line in lines)
        return
    angle, axis, when = found.untracked
    assert axis == expected[1] and angle == pytest.approx(expected[0], abs=2e-3)
    assert when == pytest.approx(2.0, abs=0.01)                  # it grows to the line's end
    note = next(line for line in lines if "note:" in line)
    assert (f"turns tool0 by up to {angle:.4g} rad about its own {'xyz'[axis]} axis" in note
            and f"orientation_axes = {axes} leaves free" in note and f"add {axis} to orientation_axes" in note)

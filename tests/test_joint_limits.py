"""Joint limits as data and enforced (issue 22, point 4): the URDF's or the description's limits,
checked along the reference at build (naming joint, limit and time), reported by the plant during a
run, and the controller's efforts clipped where the description asks."""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

from robofmu.components.blocks import make_block
from robofmu.components.preflight import ReferenceRefused, check_reference
from robofmu.components.robots import load_description, load_model
from robofmu.components.robots.description import DescriptionError, read
from robofmu.components.trajectory import SynchronizedBangBang

from robot_files import refusal, set_key


def _rpp_reference(step=1e-3):
    d = load_description("rpp").trajectory.parameters
    profile = SynchronizedBangBang(d["q_start"], d["q_end"], d["a_max"])
    times = np.arange(0.0, profile.breakpoints[-1] + step / 2, step)
    return times, np.array([profile.evaluate(t)[0] for t in times]), np.array([profile.evaluate(t)[1] for t in times])


def test_the_accepted_reference_reports_its_margin_and_speed_against_an_independent_sampling():
    times, q, qd = _rpp_reference()
    model = load_model("rpp")
    lower, upper = model.position_limits()
    found = check_reference(load_description("rpp"))
    assert found.samples == len(times)
    assert found.position_margin == pytest.approx(np.min(np.minimum(q - lower, upper - q)), abs=1e-12)
    assert found.speed_ratio == pytest.approx(np.max(np.abs(qd) / model.velocity_limits()), rel=1e-12)


def test_a_reference_beyond_a_position_limit_is_refused_naming_joint_limit_and_time(copy_robot):
    joint = load_model("rpp").joint_names[1]
    path = copy_robot("rpp", lambda d: set_key(d, "joints", {"limits": {joint: {"upper": 1.5}}}))
    times, q, _ = _rpp_reference()
    first = times[np.flatnonzero(q[:, 1] > 1.5)[0]]          # the first sample beyond it
    deepest = int(np.argmax(q[:, 1]))                         # and the deepest: the worst, not the first
    with pytest.raises(ReferenceRefused, match=re.escape(
            f"{path}: trajectory: the reference drives joint 2 ({joint}) beyond its upper limit 1.5 m "
            f"(joints.limits.{joint}.upper) from t = {first:.6g} s, at worst to {q[deepest, 1]:.6g} m "
            f"({q[deepest, 1] - 1.5:.3g} m beyond) at t = {times[deepest]:.6g} s; ")):
        check_reference(read(path))


def test_a_reference_beyond_a_velocity_limit_is_refused_naming_joint_limit_and_time(copy_robot):
    joint = load_model("rpp").joint_names[0]
    path = copy_robot("rpp", lambda d: set_key(d, "joints", {"limits": {joint: {"velocity": 1.0}}}))
    times, _, qd = _rpp_reference()
    first = times[np.flatnonzero(np.abs(qd[:, 0]) > 1.0)[0]]
    worst = int(np.argmax(np.abs(qd[:, 0])))
    with pytest.raises(ReferenceRefused, match=re.escape(
            f"{path}: trajectory: the reference drives joint 1 ({joint}) beyond its velocity limit 1 rad/s "
            f"(joints.limits.{joint}.velocity) from t = {first:.6g} s, at worst {abs(qd[worst, 0]):.3g} × the limit "
            f"({abs(qd[worst, 0]):.6g} rad/s) at t = {times[worst]:.6g} s; ")):
        check_reference(read(path))


def test_a_task_reference_the_ik_cannot_follow_is_refused_naming_the_time(copy_robot):
    """planar2r's second waypoint moved out of reach (links 1 + 0.5 m): refused at the first
    sample where the Newton-Raphson IK finds no solution."""
    path = copy_robot("planar2r", lambda d: set_key(d, "trajectory.waypoints",
                                                    [d["trajectory"]["waypoints"][0], [1.6, 0.6], [0.6, 1.2]]))
    with pytest.raises(ReferenceRefused, match=r"the IK finds no solution for the reference at t = 0\.\d+ s: "):
        check_reference(read(path))


def test_home_beyond_a_limit_is_refused(copy_robot):
    joint = load_model("panda").joint_names[3]
    path = copy_robot("panda", lambda d: set_key(d, "joints.limits", {joint: {"upper": -2.5}}))
    with pytest.raises(ReferenceRefused, match=re.escape(
            f"configurations.home: puts joint 4 ({joint}) at -2.35619 rad, beyond its upper limit -2.5 rad")):
        check_reference(read(path))


# -- limits as data ------------------------------------------------------------------------------------
_URDF = """<robot name="one">
  <link name="base"/>
  <link name="arm">
    <inertial><origin xyz="0.5 0 0"/><mass value="1.0"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
  </link>
  <link name="tcp"/>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="arm"/><axis xyz="0 0 1"/>
    {limit}
  </joint>
  <joint name="tool" type="fixed"><parent link="arm"/><child link="tcp"/><origin xyz="1 0 0"/></joint>
</robot>
"""

_TOML = """name = "one"
summary = "one revolute joint"
urdf = "one.urdf"
blocks = ["controller", "plant"]
default_gains = "pd"
[task]
frame = "tcp"
coordinates = ["x", "y"]
[configurations]
home = [0.0]
[gains.pd]
kp = 100.0
kd = 20.0
"""


def _one(tmp_path, limit: str, extra: str = ""):
    (tmp_path / "one.urdf").write_text(_URDF.format(limit=limit))
    (tmp_path / "one.toml").write_text(_TOML + extra)
    return load_model(read(tmp_path / "one.toml"))


def test_a_joint_whose_limit_names_no_range_is_unlimited_not_zero(tmp_path):
    """<limit effort velocity/> without lower/upper: the URDF reader gives [0, 0]; robofmu reads no
    position limit (and a velocity or effort of 0 as none)."""
    model = _one(tmp_path, '<limit effort="0" velocity="2.0"/>')
    lower, upper = model.position_limits()
    assert lower.tolist() == [-math.inf] and upper.tolist() == [math.inf]
    assert model.velocity_limits().tolist() == [2.0] and model.effort_limits().tolist() == [math.inf]


def test_the_description_gives_limits_the_urdf_lacks(tmp_path):
    model = _one(tmp_path, '<limit effort="0" velocity="2.0"/>',
                 '[joints.limits.shoulder]\nlower = -1.0\nupper = 2.0\neffort = 5.0\n')
    assert [v.tolist() for v in model.position_limits()] == [[-1.0], [2.0]]
    assert model.effort_limits().tolist() == [5.0] and model.velocity_limits().tolist() == [2.0]


@pytest.mark.parametrize("limits, key, problem", [
    ({"lower": 1.0, "upper": 0.5}, "joints.limits.shoulder.upper", "must exceed lower"),
    ({"velocity": 0.0}, "joints.limits.shoulder.velocity", "must be > 0 (inf: no limit), got 0.0"),
    ({"effort": "lots"}, "joints.limits.shoulder.effort", "must be a number (inf: no limit), got 'lots'"),
    ({"stiffness": 3.0}, "joints.limits.shoulder.stiffness", "unknown key"),
])
def test_malformed_limits_are_refused_naming_the_key(tmp_path, limits, key, problem):
    (tmp_path / "one.urdf").write_text(_URDF.format(limit='<limit lower="-1" upper="1" effort="1" velocity="1"/>'))
    body = "\n".join(f"{k} = {v!r}".replace("'", '"') for k, v in limits.items())
    (tmp_path / "one.toml").write_text(_TOML + f"[joints.limits.shoulder]\n{body}\n")
    assert problem in refusal(tmp_path / "one.toml", key)


def test_limits_of_an_unknown_joint_are_refused(tmp_path):
    with pytest.raises(ValueError, match=r"joints.limits.elbow: no joint 'elbow' in one.urdf \(the model's joints: shoulder\)"):
        _one(tmp_path, '<limit lower="-1" upper="1" effort="1" velocity="1"/>', "[joints.limits.elbow]\nupper = 1.0\n")


def test_saturate_effort_must_be_a_boolean(tmp_path):
    (tmp_path / "one.urdf").write_text(_URDF.format(limit='<limit lower="-1" upper="1" effort="1" velocity="1"/>'))
    (tmp_path / "one.toml").write_text(_TOML + "[joints]\nsaturate_effort = 1\n")
    with pytest.raises(DescriptionError, match="joints.saturate_effort: must be true or false, got 1"):
        read(tmp_path / "one.toml")


# -- during a run ------------------------------------------------------------------------------------
def test_the_plant_flags_a_limit_violation_and_warns_once_per_excursion_naming_joint_and_time(tmp_path):
    """One joint, no gravity along its axis, pushed by a constant torque: q = tau t^2 / (2 I);
    the flag drops at the first communication point past the limit, and comes back after."""
    _one(tmp_path, '<limit lower="-1" upper="0.5" effort="10" velocity="100"/>')
    plant = make_block(read(tmp_path / "one.toml"), "plant")
    warnings = []
    plant.logger = lambda text, *args: warnings.append(text)
    plant.warn = lambda text: warnings.append(text)
    plant.configure()
    inertia = 0.01 + 1.0 * 0.5 ** 2                      # about the joint axis
    tau = 1.0
    plant.set("tau[1]", tau)
    h = 1e-2
    crossing = math.sqrt(2 * inertia * 0.5 / tau)         # q = 0.5 rad
    flags = []
    for k in range(200):
        t = k * h
        plant.output(t)
        flags.append(plant.get("within_limits"))
        plant.advance(t, h)
    first = next(k for k, f in enumerate(flags) if not f)
    assert (first - 1) * h < crossing <= first * h
    assert len(warnings) == 1
    assert re.fullmatch(rf"t = {first * h:.9g} s: joint 1 \(shoulder\) position 0\.5\d* rad is \S+ rad above its "
                        r"upper limit 0\.5 rad", warnings[0]), warnings[0]


def test_the_controller_clips_efforts_to_their_limits_where_the_description_asks(tmp_path):
    _one(tmp_path, '<limit lower="-3" upper="3" effort="2.5" velocity="10"/>', "[joints]\nsaturate_effort = true\n")
    controller = make_block(read(tmp_path / "one.toml"), "controller")
    warnings = []
    controller.warn = lambda text: warnings.append(text)
    controller.configure()
    controller.set("q_ref[1]", 1.0)                       # kp e = 100 rad/s2 times the inertia: > 2.5 N.m
    controller.output(0.0)
    assert controller.get("tau[1]") == 2.5 and controller.get("saturated")
    controller.set("q_ref[1]", 0.001)
    controller.output(0.001)
    inertia = 0.01 + 1.0 * 0.5 ** 2
    assert controller.get("tau[1]") == pytest.approx(inertia * 100.0 * 0.001, rel=1e-12)
    assert not controller.get("saturated")
    assert warnings == ["t = 0 s: joint 1 (shoulder) effort 26 N.m exceeds its limit 2.5 N.m: clipped"]


def test_a_controller_without_saturation_has_no_flag_and_passes_efforts_on():
    names = {v.name for v in make_block("ur5", "controller").variables}
    assert "saturated" not in names and "tau[1]" in names


@pytest.mark.parametrize("robot", ["ur5", "panda"])
def test_an_arms_pose_path_beyond_a_tightened_limit_is_refused_naming_joint_limit_and_time(copy_robot, robot):
    """The arm's pose path solved along (its IK at 1 ms, as the build does); the joint that moves
    most gets an upper (or lower) limit halfway along its travel: the build's check names that
    joint, the limit and the first sample beyond it."""
    from robofmu.components.ik import make_solver
    from robofmu.components.orientation import quaternion_of
    from robofmu.components.pose_trajectory import PoseLine

    model = load_model(robot)
    home = model.configuration("home")
    given = model.description.trajectory.parameters
    profile = PoseLine(model.fk(home), given["displacement"], quaternion_of(model.rotation(home)), given["rotation"],
                       given["duration"])
    solver, solution, path = make_solver(model), None, []
    times = np.arange(0.0, profile.duration + 5e-4, 1e-3)
    for t in times:
        solver.start_from(*((None,) if solution is None else (*solution, 1e-3)))
        solution = solver.solve(*profile.evaluate(t))
        path.append(solution[0])
    travel = np.array(path) - home
    j = int(np.argmax(np.abs(travel).max(axis=0)))
    extreme = travel[np.argmax(np.abs(travel[:, j])), j]
    limit = float(home[j] + extreme / 2)
    side = "upper" if extreme > 0 else "lower"
    joint = model.joint_names[j]
    path = copy_robot(robot, lambda d: d.setdefault("joints", {}).update(limits={joint: {side: limit}}))
    beyond = (travel[:, j] + home[j] > limit) if extreme > 0 else (travel[:, j] + home[j] < limit)
    first = times[np.flatnonzero(beyond)[0]]
    with pytest.raises(ReferenceRefused) as info:
        check_reference(read(path))
    text = info.value.args[0]
    # a square arm's IK follows the path past the limit (the check names it); a redundant arm's IK
    # holds the joint on the limit and stops converging there (its message names it): either way
    # joint, limit and time
    assert f"t = {first:.6g} s" in text and f"joint {j + 1} ({joint})" in text, text
    assert f"{side} limit {limit:.6g} rad" in text, text

"""Robot descriptions (``components/robots/<name>/<name>.toml``): the loader refuses every malformed
file naming the file and the key; every described robot loads; home configurations and units.

Broken descriptions are copies of the real ones (URDF included) edited in ``tmp_path``: read with
tomllib, one key changed, written back by :func:`dump_toml`. A copy left unedited reads back the
same description, so each refusal below is caused by its edit alone.
"""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from robofmu.components.blocks import make_block
from robofmu.components.robots import (ROBOTS_DIR, DescriptionError, RobotModel, available,
                                       load_description, load_model)
from robofmu.components.robots.description import read

from robot_files import del_key, refusal, set_key


# -- a faithful copy -------------------------------------------------------------------------------
def test_an_unedited_copy_reads_back_the_same_description(robot, copy_robot):
    path = copy_robot(robot)
    copy, real = read(path), load_description(robot)
    assert copy.path == path
    if real.urdf is None:                                   # a closed chain
        assert copy.urdf is None
    elif real.urdf.is_relative_to(ROBOTS_DIR):              # beside the TOML: copied with it
        assert copy.urdf == path.parent / real.urdf.name
    else:                                                   # an installed distribution's file
        assert copy.urdf == real.urdf
    for field in ("name", "summary", "blocks", "task", "configurations", "gravity", "gravity_direction",
                  "payload", "gains", "default_gains", "trajectory", "ik", "mechanism", "locked"):
        assert getattr(copy, field) == getattr(real, field), field
    assert load_model(copy).n == load_model(real).n


# -- refusals --------------------------------------------------------------------------------------
@pytest.mark.parametrize("robot, key", [
    ("rrp", "name"), ("chess", "name"), ("rrp", "urdf"), ("rrp", "summary"), ("rrp", "blocks"),
    ("rrp", "task"), ("rrp", "task.frame"), ("chess", "task.frame"), ("rrp", "task.coordinates"),
    ("rrp", "configurations"), ("rrp", "configurations.home"), ("rpp", "configurations.home"),
    ("rrp", "gains"), ("rrp", "gains.pd.kp"), ("rrp", "gains.pd.kd"), ("rrp", "default_gains"),
    ("chess", "payload.mass"),
    ("rrp", "trajectory"), ("rrp", "trajectory.profile"), ("rpp", "trajectory.profile"),
    ("rrp", "ik.solver"),
])
def test_missing_key_is_refused_naming_file_and_key(copy_robot, robot, key):
    path = copy_robot(robot, lambda d: del_key(d, key))
    assert refusal(path, key).endswith(f"{key}: missing")


def test_gain_set_table_without_any_set_is_refused(copy_robot):
    path = copy_robot("rrp", lambda d: set_key(d, "gains", {}))
    assert "needs at least one gain set" in refusal(path, "gains")


@pytest.mark.parametrize("robot, key, value, problem", [
    ("rrp", "name", 3, "must be a non-empty string, got 3"),
    ("rrp", "name", "", "must be a non-empty string"),
    ("rrp", "summary", ["spherical"], "must be a non-empty string"),
    ("rrp", "urdf", 1.5, "must be a non-empty string"),
    ("rrp", "blocks", "plant", "must be a non-empty list of strings, got 'plant'"),
    ("rrp", "blocks", [], "must be a non-empty list of strings"),
    ("rrp", "blocks", ["plant", "teleporter"], "unknown block 'teleporter'"),
    ("rrp", "task", "tcp", "must be a table, got 'tcp'"),
    ("rrp", "task.frame", 0, "must be a non-empty string"),
    ("rrp", "task.coordinates", ["x", 1, "z"], "must be a non-empty list of strings"),
    ("rrp", "task.axes", [0, 1, 5], "must be distinct world axes among 0, 1, 2"),
    ("rrp", "task.axes", [0, 0, 1], "must be distinct world axes among 0, 1, 2"),
    ("rrp", "task.axes", [0, 1], "must have 3 values, got 2"),
    ("rrp", "configurations.home", "zero", "must be a list of finite numbers, got 'zero'"),
    ("rrp", "configurations.home", [0.0, "a", 0.1], "must be a list of finite numbers"),
    ("rrp", "configurations.home", [0.0, float("nan"), 0.1], "must be a list of finite numbers"),
    ("rrp", "configurations.home", [0.0, True, 0.1], "must be a list of finite numbers"),
    ("rrp", "gravity", 9.81, "must be a table, got 9.81"),
    ("rrp", "gravity.magnitude", "9.81", "must be a finite number, got '9.81'"),
    ("rrp", "gravity.magnitude", True, "must be a finite number, got True"),
    ("rrp", "gravity.magnitude", float("inf"), "must be a finite number"),
    ("rrp", "gravity.magnitude", -9.81, "must be >= 0, got -9.81"),
    ("chess", "payload.mass", -0.03, "must be >= 0, got -0.03"),
    ("chess", "payload.frame", ["tcp"], "must be a non-empty string"),
    ("rrp", "gains.pd", 400.0, "must be a table, got 400.0"),
    ("rrp", "gains.pd.kp", "400", "must be a finite number, got '400'"),
    ("rrp", "gains.pd.kd", -40.0, "parameter kd = -40 1/s is invalid: must be > 0"),
    ("chess", "gains.pid.ki", [75.0], "must be a finite number"),
    # the gains' rule (robofmu.components.control.GAINS): kp > 0, kd > 0, ki >= 0
    ("rrp", "gains.pd.kp", 0.0, "parameter kp = 0 1/s2 is invalid: must be > 0"),
    ("rrp", "gains.pd.kd", 0.0, "parameter kd = 0 1/s is invalid: must be > 0"),
    ("chess", "gains.pid.ki", -75.0, "parameter ki = -75 1/s3 is invalid: must be >= 0"),
    ("rrp", "default_gains", 1, "must be a non-empty string, got 1"),
    ("chess", "default_gains", "pdq", "names no gain set of this robot: 'pdq' (its sets: pd, pid)"),
    ("rrp", "trajectory", "line", "must be a table, got 'line'"),
    ("rrp", "trajectory.profile", 1, "must be a non-empty string, got 1"),
    ("rrp", "ik", "spherical", "must be a table, got 'spherical'"),
    ("chess", "ik.solver", "", "must be a non-empty string"),
])
def test_wrong_type_is_refused_naming_file_and_key(copy_robot, robot, key, value, problem):
    path = copy_robot(robot, lambda d: set_key(d, key, value))
    assert problem in refusal(path, key)


@pytest.mark.parametrize("robot, key", [
    ("rrp", "colour"), ("rrp", "task.rotation"), ("rrp", "gravity.dir"), ("rrp", "gains.pd.kx"),
    ("chess", "payload.volume"), ("chess", "gains.pid.kii"),
])
def test_unknown_key_is_refused_naming_file_and_key(copy_robot, robot, key):
    path = copy_robot(robot, lambda d: set_key(d, key, 1.0))
    assert "unknown key (known: " in refusal(path, key)


def test_unknown_profile_and_solver_parameters_are_refused_naming_file_and_key(copy_robot):
    """[trajectory] and [ik] hold the parameters of a registered profile or solver: the block
    (and the solver) that reads them refuses an unknown one, naming the file and the key."""
    path = copy_robot("rrp", lambda d: set_key(d, "trajectory.lenght", 0.03125))
    with pytest.raises(DescriptionError, match=re.escape(f"{path}: trajectory.lenght: unknown parameter 'lenght' (known: a_max, length, v_max)")):
        make_block(read(path), "trajectory")
    path = copy_robot("rpp", lambda d: set_key(d, "trajectory.q_end", [1.0, 2.0]))
    with pytest.raises(DescriptionError, match=re.escape(f"{path}: trajectory.q_end: needs 3 values")):
        make_block(read(path), "trajectory")
    path = copy_robot("chess", lambda d: set_key(d, "ik.wrist", "left"))
    with pytest.raises(DescriptionError, match=re.escape(f"{path}: ik.wrist: unknown parameter 'wrist'")):
        make_block(read(path), "ik")
    path = copy_robot("chess", lambda d: set_key(d, "ik.elbow", "sideways"))
    with pytest.raises(DescriptionError, match=re.escape(f"{path}: ik.elbow: parameter elbow = 'sideways' is invalid")):
        make_block(read(path), "ik")


def test_unknown_profile_and_solver_are_refused_by_the_blocks(copy_robot):
    path = copy_robot("rrp", lambda d: set_key(d, "trajectory.profile", "spline"))
    with pytest.raises(DescriptionError, match=re.escape(f"{path}: trajectory.profile: unknown profile 'spline'; known: ")
                       + ".*line"):
        make_block(read(path), "trajectory")
    path = copy_robot("rrp", lambda d: set_key(d, "ik.solver", "newton"))
    with pytest.raises(DescriptionError, match=re.escape(f"{path}: ik.solver: unknown IK solver 'newton'; known: ")
                       + ".*spherical"):
        make_block(read(path), "ik")


def test_name_must_be_the_files_name(copy_robot):
    path = copy_robot("rrp", stem="other")
    assert "must be the file's name 'other', got 'rrp'" in refusal(path, "name")


def test_urdf_must_exist(copy_robot):
    path = copy_robot("rrp", lambda d: set_key(d, "urdf", "nope.urdf"))
    assert f"no such file {path.parent / 'nope.urdf'}" in refusal(path, "urdf")


@pytest.mark.parametrize("direction, problem", [
    ([0.0, 0.0, -2.0], "must be a unit vector, got length 2"),
    ([0.0, 0.0, 0.0], "must be a unit vector, got length 0"),
    ([0.0, 0.6, -0.7], "must be a unit vector"),
    ([0.0, -1.0], "must have 3 values, got 2"),
    ([0.0, "down", 0.0], "must be a list of finite numbers"),
])
def test_bad_gravity_direction_is_refused(copy_robot, direction, problem):
    path = copy_robot("rrp", lambda d: set_key(d, "gravity.direction", direction))
    assert problem in refusal(path, "gravity.direction")


def test_other_unit_gravity_directions_are_accepted(copy_robot):
    path = copy_robot("rrp", lambda d: set_key(d, "gravity.direction", [0.0, 0.6, -0.8]))
    assert read(path).gravity_direction == (0.0, 0.6, -0.8)
    model = load_model(read(path))
    np.testing.assert_allclose(np.asarray(model.model.gravity.linear), [0.0, 0.6 * 9.81, -0.8 * 9.81],
                               atol=1e-15)


def test_home_of_the_wrong_length_for_the_urdf_is_refused(copy_robot):
    path = copy_robot("rrp", lambda d: set_key(d, "configurations.home", [0.0, 0.0]))
    description = read(path)                   # the TOML alone cannot know the URDF's joints
    with pytest.raises(ValueError) as info:
        load_model(description)
    text = str(info.value)
    assert text.startswith(f"{path}: configurations.home: ")
    assert "needs 3 joint values, one per joint the model moves, in this order: " in text
    assert text.endswith("; got 2: give one value per joint, or lock a joint (joints.locked, joints.chain)")


def test_configurations_of_different_lengths_are_refused(copy_robot):
    path = copy_robot("rrp", lambda d: set_key(d, "configurations.park", [0.0, 0.0]))
    assert "every configuration needs the same number of joints, got [2, 3]" in refusal(
        path, "configurations.home")


@pytest.mark.parametrize("key", ["task.frame", "payload.frame"])
def test_frames_must_exist_in_the_urdf(copy_robot, key):
    path = copy_robot("chess", lambda d: set_key(d, key, "gripper_tip"))
    with pytest.raises(ValueError, match=re.escape(f"{path}: {key}: no frame 'gripper_tip' in chess.urdf")):
        load_model(read(path))


def test_ik_block_needs_an_ik_table_and_the_other_way_round(copy_robot):
    path = copy_robot("rrp", lambda d: del_key(d, "ik"))
    assert "an [ik] table is needed exactly when `blocks` lists 'ik'" in refusal(path, "ik")
    path = copy_robot("rpp", lambda d: set_key(d, "ik", {"solver": "spherical"}))
    assert "an [ik] table is needed exactly when `blocks` lists 'ik'" in refusal(path, "ik")


def test_missing_file_and_bad_syntax_are_named(tmp_path):
    path = tmp_path / "ghost.toml"
    assert "does not exist" in refusal(path, "(file)")
    path.write_text('name = "ghost"\n[task\n')
    refusal(path, "(syntax)")


# -- closed-chain mechanisms ([mechanism] instead of a URDF) -------------------------------------------
@pytest.mark.parametrize("key", [
    "mechanism.kind", "mechanism.r", "mechanism.line_offsets", "mechanism.link_com", "mechanism.link_mass",
    "mechanism.link_inertia", "mechanism.ee_mass", "mechanism.ee_inertia", "mechanism.velocity_limits",
    "task.coordinates",
])
def test_missing_mechanism_key_is_refused_naming_file_and_key(copy_robot, key):
    path = copy_robot("3rrp", lambda d: del_key(d, key))
    assert refusal(path, key).endswith(f"{key}: missing")


@pytest.mark.parametrize("key, value, problem", [
    ("mechanism", "planar_3rrp", "must be a table, got 'planar_3rrp'"),
    ("mechanism.kind", "delta", "unknown mechanism 'delta' (known: planar_3rrp)"),
    ("mechanism.r", 0.0, "must be > 0, got 0.0"),
    ("mechanism.r", "0.2", "must be a finite number"),
    ("mechanism.line_offsets", [0.0, 1.0, 2.0], "must be three directions 120 degrees apart"),
    ("mechanism.line_offsets", [1.0471975511965976, 3.141592653589793], "must have 3 values, got 2"),
    ("mechanism.link_com", 1.5, "must be a fraction of r in [0, 1], got 1.5"),
    ("mechanism.link_mass", -0.1, "must be >= 0, got -0.1"),
    ("mechanism.ee_inertia", float("nan"), "must be a finite number"),
    ("mechanism.velocity_limits", [10.0, 0.0, 10.0], "must all be > 0"),
    ("mechanism.position_lower", [0.0, "a", 0.0], "must be a list of numbers (inf allowed)"),
    ("mechanism.position_upper", [10.0, -10.0, float("inf")], "must exceed position_lower element by element"),
    ("mechanism.colour", 1.0, "unknown key (known: "),
    ("task.axes", [0, 1, 2], "unknown key (known: coordinates, frame)"),
])
def test_bad_mechanism_is_refused_naming_file_and_key(copy_robot, key, value, problem):
    def edit(d):
        set_key(d, key, value)
        if key == "mechanism.position_upper":
            set_key(d, "mechanism.position_lower", [0.0, 0.0, 0.0])
    path = copy_robot("3rrp", edit)
    assert problem in refusal(path, key)


def test_a_robot_has_a_urdf_or_a_mechanism(copy_robot):
    path = copy_robot("3rrp", lambda d: set_key(d, "urdf", "3rrp.urdf"))
    assert "a robot has either a `urdf` or a [mechanism] table, not both" in refusal(path, "mechanism")
    path = copy_robot("3rrp", lambda d: del_key(d, "mechanism"))
    assert refusal(path, "urdf").endswith("urdf: missing")


def test_a_link_without_inertia_about_o_is_refused(copy_robot):
    def massless(d):
        set_key(d, "mechanism.link_mass", 0.0)
        set_key(d, "mechanism.link_inertia", 0.0)
    path = copy_robot("3rrp", massless)
    assert "each link needs a positive moment of inertia about O" in refusal(path, "mechanism.link_inertia")


def test_a_trajectory_table_needs_a_trajectory_block_and_the_other_way_round(copy_robot):
    path = copy_robot("3rrp", lambda d: set_key(d, "blocks", ["ik", "controller", "plant", "fk"]))
    assert "a [trajectory] table is needed exactly when `blocks` lists 'trajectory'" in refusal(path, "trajectory")
    path = copy_robot("3rrp", lambda d: d.pop("trajectory"))
    assert refusal(path, "trajectory").endswith("trajectory: missing")


@pytest.mark.parametrize("key, value, problem", [
    ("configurations.home", [0.0, 2.0], "needs 3 joint values (the mechanism has 3 actuated joints), got 2"),
    ("task.coordinates", ["x", "y"], "needs 3 names (the pose x, y, theta)"),
    ("task.frame", "tcp", "the mechanism's task body is 'end_effector', got 'tcp'"),
    ("gravity.direction", [0.0, -1.0, 0.0], "the mechanism moves in the horizontal x-y plane: gravity must act along z"),
])
def test_the_mechanism_model_refuses_what_the_toml_alone_cannot_check(copy_robot, key, value, problem):
    path = copy_robot("3rrp", lambda d: set_key(d, key, value))
    description = read(path)
    with pytest.raises(DescriptionError) as info:
        load_model(description)
    assert str(info.value).startswith(f"{path}: {key}: ") and problem in str(info.value)


def test_load_model_picks_the_class_by_the_descriptions_kind():
    from robofmu.components.robots import MODEL_CLASSES, model_class
    from robofmu.components.robots.parallel import Planar3RRP
    from robofmu.components.robots.serial import SerialRobot

    assert set(MODEL_CLASSES) == {"serial", "planar_3rrp"}
    assert model_class("serial") is SerialRobot and model_class("planar_3rrp") is Planar3RRP
    assert type(load_model("rrp")) is SerialRobot and type(load_model("3rrp")) is Planar3RRP
    assert load_description("rrp").model_kind == "serial" and load_description("3rrp").model_kind == "planar_3rrp"
    with pytest.raises(ValueError, match="no robot model for kind 'delta'; known: planar_3rrp, serial"):
        model_class("delta")


# -- the described robots --------------------------------------------------------------------------
def test_the_robots_are_described():
    assert available() == ["3rrp", "chess", "panda", "planar2r", "rpp", "rrp", "rrp_offset", "ur5"]


def test_every_described_robot_loads(robot):
    description = load_description(robot)
    assert description.name == robot and description.path == ROBOTS_DIR / robot / f"{robot}.toml"
    model = load_model(robot)
    assert isinstance(model, RobotModel) and model.description is description
    assert model.n == len(description.configuration("home")) == len(model.joint_names)
    assert model.m == len(description.task.coordinates) == len(description.task.axes)
    assert load_model(robot) is not model                   # a new instance each call
    assert {"trajectory", "controller", "plant"} <= set(description.blocks)
    assert ("ik" in description.blocks) == (description.ik is not None)
    for kind in description.blocks:
        block = make_block(robot, kind)
        block.configure()
        block.output(0.0)
        assert np.all(np.isfinite(block.values)), kind
    gains = description.gain_set("pd")
    assert gains.as_dict() == {"kp": gains.kp, "kd": gains.kd, "ki": gains.ki}
    assert description.default_gains in description.gains
    with pytest.raises(ValueError, match="has no gains 'pdq'"):
        description.gain_set("pdq")
    with pytest.raises(ValueError, match="has no configuration 'park'"):
        description.configuration("park")


def test_chess_home_is_the_first_waypoint_at_rest():
    model = load_model("chess")
    first = load_description("chess").trajectory.parameters["waypoints"][0]
    np.testing.assert_allclose(model.fk(model.configuration("home")), first, rtol=0, atol=1e-12)
    q = model.configuration("home")
    assert q[1] + q[2] + q[3] == pytest.approx(-math.pi / 2, abs=1e-12)     # tool pointing down


def test_rrp_home_puts_the_tcp_at_the_line_start():
    model = load_model("rrp")
    np.testing.assert_allclose(model.fk(model.configuration("home")), [0.125, 0.0, 0.125], rtol=0,
                               atol=1e-15)
    np.testing.assert_allclose(load_description("rrp").trajectory.parameters["start"], [0.125, 0.0, 0.125])


def test_rpp_home_is_the_bang_bang_start():
    description = load_description("rpp")
    assert description.configuration("home") == (0.0, 1.0, 1.0)
    assert tuple(description.trajectory.parameters["q_start"]) == (0.0, 1.0, 1.0)
    np.testing.assert_allclose(load_model("rpp").fk(np.array([0.0, 1.0, 1.0])), [0.0, 1.0, 1.0], atol=1e-15)


def test_gravity_and_payload():
    for robot in available():
        d = load_description(robot)
        down = (0.0, -1.0, 0.0) if robot == "planar2r" else (0.0, 0.0, -1.0)   # a vertical x-y plane
        assert (d.gravity, d.gravity_direction) == (9.81, down)
    chess = load_description("chess")
    assert (chess.payload.mass, chess.payload.frame) == (0.03, "tcp")
    assert load_description("rrp").payload is None and load_description("rpp").payload is None
    with pytest.raises(ValueError, match="describes no payload frame"):
        load_model("rrp").set_payload(0.1)


@pytest.mark.parametrize("robot, prismatic", [
    ("chess", [False, False, False, False]), ("rrp", [False, False, True]), ("rpp", [False, True, True]),
])
def test_prismatic_joints_have_si_units(robot, prismatic):
    model = load_model(robot)
    assert model.prismatic == prismatic
    for order, suffix in enumerate(("", "/s", "/s2")):
        assert model.joint_units(order) == [("m" if p else "rad") + suffix for p in prismatic]
        assert model.task_units(order) == ["m" + suffix] * 3
    assert model.effort_units() == ["N" if p else "N.m" for p in prismatic]
    # and the blocks declare them
    plant = make_block(robot, "plant")
    units = {v.name: v.unit for v in plant.variables}
    for j, p in enumerate(prismatic, start=1):
        assert (units[f"tau[{j}]"], units[f"q[{j}]"], units[f"qd[{j}]"]) == (
            ("N", "m", "m/s") if p else ("N.m", "rad", "rad/s"))
    controller = {v.name: v.unit for v in make_block(robot, "controller").variables}
    for j, p in enumerate(prismatic, start=1):
        assert controller[f"qdd_ref[{j}]"] == ("m/s2" if p else "rad/s2")
        assert controller[f"tau[{j}]"] == ("N" if p else "N.m")


# -- URDFs from the wild: what the model refuses at load (and so at build), naming joint or link ---------
def _edited_rrp(copy_robot, old: str, new: str):
    path = copy_robot("rrp")
    urdf = path.parent / "rrp.urdf"
    text = urdf.read_text()
    assert old in text
    urdf.write_text(text.replace(old, new, 1))
    return read(path)


@pytest.mark.parametrize("old, new, message", [
    ('<mass value="0.5"/>', '<mass value="0.0"/>',
     r"rrp.urdf: link 'link2' \(moved by joint 'joint2'\) has no mass \(0 kg\): give it an <inertial> with mass > 0"),
    ('<inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/>',
     '<inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.003"/>',
     r"rrp.urdf: link 'link2' \(moved by joint 'joint2'\) has an inertia no body has \(principal moments 0.001, "
     r"0.001, 0.003 kg m\^2: each must be >= 0 and at most the sum of the other two\)"),
    ('<inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/>',
     '<inertia ixx="-0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/>',
     r"rrp.urdf: link 'link2' \(moved by joint 'joint2'\) has an inertia no body has \(principal moments -0.001, "),
])
def test_a_urdf_the_dynamics_cannot_use_is_refused_naming_joint_or_link(copy_robot, old, new, message):
    description = _edited_rrp(copy_robot, old, new)
    with pytest.raises(ValueError, match=message):
        load_model(description)


def test_a_link_without_an_inertial_is_refused_naming_it(copy_robot):
    """No <inertial> at all: Pinocchio gives the link zero mass (M(q) singular at t = 0)."""
    description = _edited_rrp(copy_robot, '''<inertial>
      <origin xyz="0 0 0" rpy="0 0 0"/>
      <mass value="0.5"/>''', '''<inertial_removed>
      <origin xyz="0 0 0" rpy="0 0 0"/>
      <mass value="0.5"/>''')
    urdf = description.urdf
    text = urdf.read_text()
    start = text.index("<inertial_removed>")
    urdf.write_text(text[:start] + text[text.index("</inertial>", start) + len("</inertial>"):])
    with pytest.raises(ValueError, match=r"link 'link2' \(moved by joint 'joint2'\) has no mass \(0 kg\)"):
        load_model(description)


# -- URDFs of installed distributions, locked joints, pose tasks ----------------------------------------
def test_a_urdf_from_an_installed_distribution_is_found_by_the_end_of_its_path():
    from importlib import metadata
    description = load_description("ur5")
    distribution = metadata.distribution("example-robot-data")
    assert description.urdf.is_file()
    assert description.urdf.as_posix().endswith("/robots/ur_description/urdf/ur5_robot.urdf")
    assert description.urdf.is_relative_to(Path(distribution.locate_file("")))
    assert not description.urdf.is_relative_to(ROBOTS_DIR)        # referenced, never copied


@pytest.mark.parametrize("reference, problem", [
    ({"distribution": "no-such-distribution-robofmu", "path": "a.urdf"},
     "the distribution 'no-such-distribution-robofmu' is not installed (pip install no-such-distribution-robofmu)"),
    ({"distribution": "example-robot-data", "path": "robots/no_such_robot.urdf"},
     "has 0 files whose path ends with 'robots/no_such_robot.urdf'; exactly one is needed"),
    ({"distribution": "example-robot-data", "path": "anymal.urdf"},          # two robots' files
     "has 2 files whose path ends with 'anymal.urdf': "),
    ({"distribution": "example-robot-data"}, "missing"),
    ({"distribution": "example-robot-data", "path": "x.urdf", "version": 6}, "unknown key"),
])
def test_a_distribution_reference_that_finds_no_single_file_is_refused(copy_robot, reference, problem):
    path = copy_robot("ur5", lambda d: set_key(d, "urdf", reference))
    with pytest.raises(DescriptionError) as info:
        read(path)
    assert info.value.path == path and info.value.key.startswith("urdf"), str(info.value)
    assert problem in str(info.value)


@pytest.mark.parametrize("value, problem", [
    ([], "must name at least one axis (leave the key out for a position task)"),
    ([0, 3], "must be distinct axes of the frame among 0, 1, 2, got [0.0, 3.0]"),
    ([1, 1], "must be distinct axes of the frame among 0, 1, 2"),
])
def test_orientation_axes_are_checked(copy_robot, value, problem):
    path = copy_robot("ur5", lambda d: set_key(d, "task.orientation_axes", value))
    assert problem in refusal(path, "task.orientation_axes")


def test_a_pose_task_has_rows_for_its_orientation_axes(copy_robot):
    assert load_description("ur5").task.orientation_axes == (0, 1, 2)
    assert load_model("ur5").task_rows == 6 and load_model("rrp").task_rows == 3
    path = copy_robot("ur5", lambda d: set_key(d, "task.orientation_axes", [0, 1]))
    assert load_model(read(path)).task_rows == 5


def test_locked_joints_leave_the_model_at_their_values():
    import pinocchio as pin
    panda = load_model("panda")
    assert panda.n == 7 and "panda_finger_joint1" not in panda.joint_names
    full = pin.buildModelFromUrdf(str(panda.description.urdf))
    assert full.nq == 9
    q = np.array(panda.description.configuration("home"))
    data = full.createData()
    pin.framesForwardKinematics(full, data, np.concatenate([q, [0.02, 0.02]]))
    for frame in ("panda_leftfinger", "panda_rightfinger", "panda_hand"):
        panda.fk(q)
        mine = panda.data.oMf[panda.model.getFrameId(frame)]
        pin.updateFramePlacements(panda.model, panda.data)
        mine = panda.data.oMf[panda.model.getFrameId(frame)]
        assert np.allclose(mine.homogeneous, data.oMf[full.getFrameId(frame)].homogeneous, atol=1e-15), frame
    # the fingers' masses ride on the hand: the reduced model weighs the same
    assert sum(i.mass for i in panda.model.inertias) == pytest.approx(sum(i.mass for i in full.inertias), rel=1e-14)


@pytest.mark.parametrize("locked, message", [
    ({"panda_thumb": 0.02}, r"joints.locked.panda_thumb: no joint 'panda_thumb' in panda.urdf \(its movable joints: panda_joint1"),
    ({"panda_finger_joint1": 0.05, "panda_finger_joint2": 0.02}, r"joints.locked.panda_finger_joint1: 0.05 lies outside the joint's limits \[0, 0.04\]"),
])
def test_a_locked_joint_must_exist_and_lie_within_its_limits(copy_robot, locked, message):
    path = copy_robot("panda", lambda d: set_key(d, "joints.locked", locked))
    with pytest.raises(ValueError, match=message):
        load_model(read(path))


@pytest.mark.parametrize("robot", ["ur5", "panda"])
def test_pose_jacobian_and_its_derivative_match_finite_differences(robot):
    """Rows: the frame's world velocity, then its angular velocity about its own axes (the body
    angular velocity log3(R(t-h)^T R(t+h)) / 2h); Jdot qd from the derivative of J qd."""
    import pinocchio as pin
    model = load_model(robot)
    rng = np.random.default_rng(7)
    q = model.configuration("home") + rng.normal(scale=0.2, size=model.n)
    qd = rng.normal(size=model.n)
    h = 1e-6
    J = model.jacobian(q)
    linear = (model.fk(q + h * qd) - model.fk(q - h * qd)) / (2 * h)
    angular = pin.log3(model.rotation(q - h * qd).T @ model.rotation(q + h * qd)) / (2 * h)
    assert np.allclose(J @ qd, np.concatenate([linear, angular]), atol=1e-8)
    jdot = (model.jacobian(q + h * qd) - model.jacobian(q - h * qd)) @ qd / (2 * h)
    assert np.allclose(model.jdot_qdot(q, qd), jdot, atol=1e-7)
    derivative = (model.jacobian(q + h * qd) - model.jacobian(q - h * qd)) / (2 * h)
    assert np.allclose(model.jacobian_derivative(q, qd), derivative, atol=1e-8)
    assert np.allclose(model.jacobian_derivative(q, qd) @ qd, model.jdot_qdot(q, qd), atol=1e-12)
    position, rotation, full = model.kinematics(q)
    assert np.allclose(position, model.fk(q), atol=0) and np.allclose(rotation, model.rotation(q), atol=0)
    assert np.allclose(full, J, atol=1e-15)


def test_a_continuous_joint_is_an_unbounded_revolute_joint_with_an_angle_on_the_ports(copy_robot):
    """The same arm with joint2 continuous: one coordinate (an angle, not Pinocchio's cos/sin
    pair), no position limits, the URDF's velocity and effort limits, and the same kinematics and
    dynamics at angles beyond the revolute joint's old range."""
    real = load_model("rrp")
    continuous = load_model(_edited_rrp(copy_robot, '<joint name="joint2" type="revolute">',
                                        '<joint name="joint2" type="continuous">'))
    assert continuous.n == real.n == continuous.model.nq
    lower, upper = continuous.position_limits()
    assert (lower[1], upper[1]) == (-np.inf, np.inf)
    assert lower[[0, 2]].tolist() == real.position_limits()[0][[0, 2]].tolist()
    assert continuous.velocity_limits().tolist() == real.velocity_limits().tolist()
    assert continuous.effort_limits().tolist() == real.effort_limits().tolist()
    q = np.array([0.3, 2.5, 0.1])                            # joint2 beyond its old pi/2
    qd = np.array([0.2, -0.4, 0.05])
    assert np.allclose(continuous.fk(q), real.fk(q), atol=1e-15)
    assert np.allclose(continuous.mass_matrix(q), real.mass_matrix(q), atol=1e-15)
    assert np.allclose(continuous.nonlinear_effects(q, qd), real.nonlinear_effects(q, qd), atol=1e-14)
    # a full turn is the same pose (an angle, not clipped or wrapped)
    assert np.allclose(continuous.fk(q + [0, 2 * np.pi, 0]), real.fk(q), atol=1e-14)


def _unlocked_panda(copy_robot, locked):
    def edit(d):
        d["joints"]["locked"] = locked
        home = d["configurations"]["home"] + ([] if locked else [0.02])     # finger 2 follows finger 1
        d["configurations"] = {"home": home}
    return read(copy_robot("panda", edit))


def test_a_mimic_joint_moves_with_its_leader(copy_robot):
    """The Panda with its fingers free: panda_finger_joint2 mimics panda_finger_joint1
    (multiplier 1), so the arm has 8 coordinates, not 9. Against the URDF read with the mimic
    ignored (9 coordinates) and the constraint q9 = q8 imposed by hand (q_full = S q):
    M = S^T M_full S, N = S^T N_full, the energies equal, and the forward dynamics solve M qdd = tau - N."""
    import pinocchio as pin
    model = load_model(_unlocked_panda(copy_robot, {}))
    assert model.n == 8 and model.joint_names[-1] == "panda_finger_joint1" and model.prismatic[-1]
    full = pin.buildModelFromUrdf(str(model.description.urdf))
    data = full.createData()
    S = np.zeros((9, 8))
    S[:8, :8] = np.eye(8)
    S[8, 7] = 1.0
    rng = np.random.default_rng(3)
    q = np.concatenate([model.configuration("home")[:7] + rng.normal(scale=0.1, size=7), [0.015]])
    qd, tau = rng.normal(size=8), rng.normal(size=8)
    M_full = pin.crba(full, data, S @ q)
    M_full = np.triu(M_full) + np.triu(M_full, 1).T
    assert np.allclose(model.mass_matrix(q), S.T @ M_full @ S, atol=1e-12)
    N_full = pin.nonLinearEffects(full, data, S @ q, S @ qd)
    assert np.allclose(model.nonlinear_effects(q, qd), S.T @ N_full, atol=1e-12)
    assert model.kinetic_energy(q, qd) == pytest.approx(pin.computeKineticEnergy(full, data, S @ q, S @ qd), rel=1e-12)
    assert model.potential_energy(q) == pytest.approx(pin.computePotentialEnergy(full, data, S @ q), rel=1e-12)
    qdd = model.forward_dynamics(q, qd, tau)
    assert np.allclose(model.mass_matrix(q) @ qdd, tau - model.nonlinear_effects(q, qd), atol=1e-10)
    assert model.forward_dynamics_floats(q, qd, tau) == pytest.approx(qdd.tolist(), abs=1e-12)


def test_a_mimic_joint_whose_leader_is_locked_must_be_locked_too(copy_robot):
    description = _unlocked_panda(copy_robot, {"panda_finger_joint1": 0.02})
    with pytest.raises(ValueError, match="joints.locked: joint 'panda_finger_joint2' mimics the locked joint "
                                         "'panda_finger_joint1': lock it too"):
        load_model(description)


def test_named_profiles_are_more_trajectory_fmus_each_reading_its_own_table(copy_robot):
    ur5 = load_description("ur5")
    assert ur5.fmu_blocks == ur5.blocks + ("trajectory_joint",)
    kind, profile, described = ur5.block_of("trajectory_joint")
    assert (kind, profile, described.trajectory) == ("trajectory", "joint", ur5.profiles["joint"])
    assert described.trajectory.kind == "joint_bangbang" and ur5.trajectory.kind == "pose_line"
    assert ur5.block_of("ik") == ("ik", "", ur5)
    block = make_block(described, "trajectory")                 # the joint-space block, its own outputs
    assert "q_ref[6]" in {v.name for v in block.variables} and "x_ref[1]" not in {v.name for v in block.variables}
    with pytest.raises(ValueError, match=r"robot 'ur5' has no block 'trajectory_circle'; its blocks: trajectory, "
                                         r"ik, controller, plant, fk, trajectory_joint"):
        ur5.block_of("trajectory_circle")


@pytest.mark.parametrize("edit, key, problem", [
    (lambda d: d["trajectories"].update({"Fast-Line": d["trajectories"]["joint"]}), "trajectories.Fast-Line",
     "a profile's name is lower-case letters, digits and _ (it names an FMU)"),
    (lambda d: d["trajectories"].update({"slow": {"q_end": [0.0] * 6}}), "trajectories.slow.profile", "missing"),
])
def test_named_profiles_are_checked(copy_robot, edit, key, problem):
    assert problem in refusal(copy_robot("ur5", edit), key)

"""The one checked URDF reader (components/robots/urdf.py) and the serial model built through it.

Refusals on small URDFs written here, each naming the file and the element; a link and a joint of
one name as task frame and as locked joint, a chain of a larger robot (a small tree, then TIAGo's
torso and arm), continuous joints, a mimic tag on a fixed joint, xacro and SRDF states, each
against an independent Pinocchio model of the original URDF or the numbers read here with
ElementTree.
"""
from __future__ import annotations

import math
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pinocchio as pin
import pytest

from robofmu.components.robots import load_model
from robofmu.components.robots.description import read
from robofmu.components.robots.urdf import UrdfError, read_urdf, srdf_states

_INERTIAL = ('<inertial><origin xyz="0 0 0.1"/><mass value="{m}"/>'
             '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.005"/></inertial>')


def _link(name: str, mass: float = 1.0) -> str:
    return f'<link name="{name}">{_INERTIAL.format(m=mass)}</link>'


#: A small tree: base -j1-> l1 -j2-> l2 -tool(fixed)-> tool; l1 -side-> side_link (a branch);
#: l2 -gripper(prismatic)-> gripper, l2 -gripper2(mimic of gripper)-> gripper2. Joint "tool" and
#: link "tool" share a name, as do joint "gripper" and link "gripper".
ARM = f"""<?xml version="1.0"?>
<robot name="arm">
  <link name="base"/>
  {_link("l1", 2.0)}
  {_link("l2", 1.5)}
  {_link("tool", 0.2)}
  {_link("side_link", 0.5)}
  {_link("gripper", 0.1)}
  {_link("gripper2", 0.1)}
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.3"/>
    <axis xyz="0 0 1"/><limit lower="-2.5" upper="2.5" effort="50" velocity="2"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.1 0 0.4" rpy="0 0.2 0"/>
    <axis xyz="0 1 0"/><limit lower="-1.5" upper="1.5" effort="40" velocity="2"/></joint>
  <joint name="tool" type="fixed"><parent link="l2"/><child link="tool"/><origin xyz="0.35 0.02 0" rpy="0.1 0 0.3"/></joint>
  <joint name="side" type="revolute"><parent link="l1"/><child link="side_link"/><origin xyz="0 0.2 0.1"/>
    <axis xyz="1 0 0"/><limit lower="0.2" upper="1.0" effort="5" velocity="1"/></joint>
  <joint name="gripper" type="prismatic"><parent link="l2"/><child link="gripper"/><origin xyz="0.3 0 0.05"/>
    <axis xyz="0 1 0"/><limit lower="0" upper="0.04" effort="10" velocity="0.1"/></joint>
  <joint name="gripper2" type="prismatic"><parent link="l2"/><child link="gripper2"/><origin xyz="0.3 0 -0.05"/>
    <axis xyz="0 -1 0"/><limit lower="0" upper="0.04" effort="10" velocity="0.1"/><mimic joint="gripper"/></joint>
</robot>
"""


def _write(folder: Path, text: str, name: str = "arm.urdf") -> Path:
    path = folder / name
    path.write_text(text)
    return path


def _toml(folder: Path, urdf: str = '"arm.urdf"', frame: str = "tool", home="[0.3, -0.4]", joints: str = "",
          extra: str = "", configurations: str = "") -> Path:
    """A robot TOML beside the URDF: controller, plant and fk blocks, a position task."""
    path = folder / "arm.toml"
    path.write_text(f"""name = "arm"
summary = "test arm"
urdf = {urdf}
{extra}
blocks = ["controller", "plant", "fk"]
default_gains = "pd"

[task]
frame = "{frame}"
coordinates = ["x", "y", "z"]

[joints]
{joints}

[configurations]
home = {home}
{configurations}

[gains.pd]
kp = 100.0
kd = 20.0
""")
    return path


def _refused(tmp_path: Path, text: str, element: str, problem: str) -> str:
    path = _write(tmp_path, text)
    with pytest.raises(UrdfError) as info:
        read_urdf(path)
    message = str(info.value)
    assert message.startswith(f"{path}: {element}: "), message
    assert problem in message and "\n" not in message, message
    assert info.value.path == path and info.value.element == element
    return message


BOMB = ('<?xml version="1.0"?>\n<!DOCTYPE robot [\n<!ENTITY a "aaaaaaaaaa">\n<!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;">\n'
        '<!ENTITY c "&b;&b;&b;&b;&b;&b;&b;&b;">]>\n<robot name="&c;"/>')


@pytest.mark.parametrize("text, element, problem", [
    (BOMB, "line 2", "holds a DTD (<!DOCTYPE>): URDFs need none; remove it"),
    (ARM.replace('<robot name="arm">', '<robot name="arm"><!ENTITY x "y">'), "line 2", "not XML"),
    (ARM.replace('<link name="l1">', '<link name="l1"'), "line 4", "not XML: not well-formed (invalid token)"),
    ('<?xml version="1.0"?><sdf name="x"/>', "<sdf>", "the root element is not <robot>"),
    (ARM.replace(_link("side_link", 0.5), _link("side_link", 0.5) + _link("l1")), "link 'l1'", "defined twice"),
    (ARM.replace('<joint name="side"', '<joint name="j2"'), "joint 'j2'", "defined twice"),
    (ARM.replace('<parent link="l1"/><child link="side_link"/>', '<parent link="l9"/><child link="side_link"/>'),
     "joint 'side'", "names no link 'l9'"),
    (ARM.replace('<parent link="l1"/><child link="side_link"/>', '<parent link="l1"/><child link="l2"/>'),
     "link 'l2'", "is the child of joints 'j2' and 'side'; a link has one parent joint"),
    (ARM.replace('<link name="base"/>', '<link name="base"/><link name="loose"/>'), "robot 'arm'",
     "several root links: 'base', 'loose'"),
    (ARM.replace('ixx="0.01"', 'ixx="nan"', 1), "link 'l1'", "inertial/inertia ixx: 'nan' is not a finite number"),
    (ARM.replace('<mass value="2.0"/>', '<mass value="inf"/>'), "link 'l1'", "inertial/mass value: 'inf' is not a finite"),
    (ARM.replace('<mass value="2.0"/>', '<mass/>'), "link 'l1'", "inertial/mass value: missing"),
    (ARM.replace('<origin xyz="0 0 0.3"/>', '<origin xyz="0 nan 0.3"/>'), "joint 'j1'", "origin xyz: 'nan' is not"),
    (ARM.replace('<axis xyz="0 1 0"/>', '<axis xyz="0 1"/>', 1), "joint 'j2'", "axis xyz: '0 1' is not 3 numbers"),
    (ARM.replace('upper="1.5" effort="40"', 'upper="NaN" effort="40"'), "joint 'j2'", "limit upper: 'NaN' is not"),
    (ARM.replace('<axis xyz="0 0 1"/>', '<axis xyz="0 0 0"/>'), "joint 'j1'",
     "axis xyz 0 0 0 has zero length; give the direction the joint turns about or slides along"),
    (ARM.replace('lower="-1.5" upper="1.5"', 'lower="1.2" upper="-1.2"'), "joint 'j2'",
     "limit lower 1.2 above upper -1.2; swap them"),
    (ARM.replace('effort="40" velocity="2"', 'velocity="2"'), "joint 'j2'", "limit effort: missing"),
    (ARM.replace('type="revolute"', 'type="fixed"').replace('type="prismatic"', 'type="fixed"'), "robot 'arm'",
     "has no movable joint"),
    (ARM.replace('<mimic joint="gripper"/>', '<mimic joint="gripper9"/>'), "joint 'gripper2'", "mimics no joint"),
    (ARM.replace('type="revolute"', 'type="hinge"', 1), "joint 'j1'", "type 'hinge' is no URDF joint type"),
])
def test_a_broken_urdf_is_refused_naming_file_and_element(tmp_path, text, element, problem):
    _refused(tmp_path, text, element, problem)


def test_an_entity_bomb_is_refused_before_anything_is_expanded(tmp_path):
    """Without a DTD the bomb has no entity; the declaration alone is refused (a billion laughs
    would take gigabytes)."""
    laughs = "".join(f'<!ENTITY l{k + 1} "' + f"&l{k};" * 10 + '">\n' for k in range(9))
    text = f'<?xml version="1.0"?>\n<!DOCTYPE r [\n<!ENTITY l0 "lol">\n{laughs}]>\n<robot name="&l9;"/>'
    _refused(tmp_path, text, "line 2", "DTD")


def test_the_reader_gives_joints_links_and_masses_as_data(tmp_path):
    urdf = read_urdf(_write(tmp_path, ARM))
    assert urdf.name == "arm" and urdf.root == "base"
    assert list(urdf.joints) == ["j1", "j2", "tool", "side", "gripper", "gripper2"]
    assert urdf.links == ("base", "l1", "l2", "tool", "side_link", "gripper", "gripper2")
    assert urdf.clashes == ("tool", "gripper", "gripper2")
    assert urdf.frames["tool"] == "tool__link" and urdf.frames["l1"] == "l1"
    assert urdf.total_mass == pytest.approx(2.0 + 1.5 + 0.2 + 0.5 + 0.1 + 0.1, abs=1e-15)
    j2 = urdf.joints["j2"]
    assert (j2.lower, j2.upper, j2.velocity, j2.effort, j2.axis) == (-1.5, 1.5, 2.0, 40.0, (0.0, 1.0, 0.0))
    assert urdf.joints["gripper2"].mimic == "gripper" and not urdf.joints["gripper2"].movable
    assert [j.name for j in urdf.children("l2")] == ["tool", "gripper", "gripper2"]
    assert urdf.leaves() == ["tool", "side_link", "gripper", "gripper2"]
    assert [j.name for j in urdf.chain("base", "tool")] == ["j1", "j2", "tool"]
    assert [j.name for j in urdf.chain("l1", "gripper")] == ["j2", "gripper"]
    with pytest.raises(UrdfError, match=r"link 'side_link': is not below link 'l2'"):
        urdf.chain("l2", "side_link")


def test_continuous_joints_and_a_mimic_on_a_fixed_joint(tmp_path):
    text = ARM.replace('<joint name="j1" type="revolute">', '<joint name="j1" type="continuous">').replace(
        '<joint name="tool" type="fixed"><parent link="l2"/>', '<joint name="tool" type="fixed"><mimic joint="j2"/>'
                                                               '<parent link="l2"/>')
    urdf = read_urdf(_write(tmp_path, text))
    j1 = urdf.joints["j1"]
    assert (j1.type, j1.lower, j1.upper, j1.velocity, j1.effort) == ("continuous", -math.inf, math.inf, 2.0, 50.0)
    assert urdf.joints["tool"].mimic is None
    root = ElementTree.fromstring(urdf.text)
    joints = {j.get("name"): j for j in root.iter("joint")}
    assert joints["j1"].get("type") == "revolute" and joints["j1"].find("limit").get("upper") == "0"
    assert joints["tool"].find("mimic") is None and joints["gripper2"].find("mimic") is not None
    # a model of it: one angle for j1 (Pinocchio's continuous joint would take two), no lock
    # demanded for the fixed joint's mimic; j1 unlimited and beyond +-pi the same pose as the revolute arm's
    model = load_model(read(_toml(tmp_path, home="[0.3, -0.4, 0.5]", joints='locked = { gripper = 0.01, '
                                                                           'gripper2 = 0.01 }')))
    assert model.n == 3 and model.joint_names == ["j1", "j2", "side"]
    lower, upper = model.position_limits()
    assert (lower[0], upper[0]) == (-np.inf, np.inf) and (lower[2], upper[2]) == (0.2, 1.0)
    assert np.allclose(model.fk(np.array([0.3 + 2 * np.pi, -0.4, 0.5])), model.fk(np.array([0.3, -0.4, 0.5])),
                       atol=1e-14)


def _full_fk(path: Path, values: dict[str, float], frame: str) -> pin.SE3:
    """An independent model of the original URDF (Pinocchio's own reader, mimic ignored) at the
    joint values by name: the link frame ``frame`` (BODY), world placement."""
    full = pin.buildModelFromUrdf(str(path))
    q = pin.neutral(full)
    for name, value in values.items():
        joint = full.joints[full.getJointId(name)]
        if joint.nq == 1:
            q[joint.idx_q] = value
        else:                                                  # a continuous joint: (cos, sin)
            q[joint.idx_q:joint.idx_q + 2] = np.cos(value), np.sin(value)
    data = full.createData()
    pin.framesForwardKinematics(full, data, q)
    return data.oMf[full.getFrameId(frame, pin.FrameType.BODY)].copy()


def test_a_name_clash_works_as_task_frame_and_as_locked_joint(tmp_path):
    """Link "tool" (child of fixed joint "tool") is the task frame; joint "gripper" (whose child
    link is "gripper") is locked, its mimic follower with it."""
    path = _write(tmp_path, ARM)
    model = load_model(read(_toml(tmp_path, home="[0.3, -0.4, 0.5]",
                                  joints="locked = { gripper = 0.03, gripper2 = 0.03 }")))
    assert model.joint_names == ["j1", "j2", "side"]
    rng = np.random.default_rng(5)
    for _ in range(5):
        q = np.array([rng.uniform(-2, 2), rng.uniform(-1.4, 1.4), rng.uniform(0.2, 1.0)])
        reference = _full_fk(path, {"j1": q[0], "j2": q[1], "side": q[2], "gripper": 0.03, "gripper2": 0.03}, "tool")
        assert np.allclose(model.pose(q).homogeneous, reference.homogeneous, atol=1e-14)
        assert np.allclose(model.fk(q), reference.translation, atol=1e-14)
    # the gripper's link as the task frame: it rides on l2 where the joint holds it
    gripper = load_model(read(_toml(tmp_path, frame="gripper", home="[0.3, -0.4, 0.5]",
                                    joints="locked = { gripper = 0.03, gripper2 = 0.03 }")))
    q = np.array([0.3, -0.4, 0.5])
    reference = _full_fk(path, {"j1": 0.3, "j2": -0.4, "side": 0.5, "gripper": 0.03, "gripper2": 0.03}, "gripper")
    assert np.allclose(gripper.fk(q), reference.translation, atol=1e-14)


def test_a_task_frame_no_joint_moves_and_a_model_with_no_joint_left_are_refused(tmp_path):
    _write(tmp_path, ARM)
    with pytest.raises(ValueError, match=r"arm.toml: task.frame: no joint moves 'base'"):
        load_model(read(_toml(tmp_path, frame="base", home="[0, 0, 0.5]", joints="locked = { gripper = 0.0, "
                                                                                 "gripper2 = 0.0 }")))
    locked = "locked = { j1 = 0.0, j2 = 0.0, side = 0.5, gripper = 0.0, gripper2 = 0.0 }"
    with pytest.raises(ValueError, match=r"arm.toml: joints.locked: no joint is left to move"):
        load_model(read(_toml(tmp_path, home="[]", joints=locked)))


def test_a_chain_locks_every_joint_off_it_at_its_value(tmp_path):
    """chain = [base, tool]: side (off the chain) at its `locked` value 0.7, the gripper at 0
    clipped into [0, 0.04], its follower with it; FK equals the full model's with those values."""
    path = _write(tmp_path, ARM)
    description = read(_toml(tmp_path, joints='chain = ["base", "tool"]\nlocked = { side = 0.7 }'))
    model = load_model(description)
    assert model.joint_names == ["j1", "j2"]
    for q in ([0.3, -0.4], [-2.0, 1.2]):
        reference = _full_fk(path, {"j1": q[0], "j2": q[1], "side": 0.7, "gripper": 0.0, "gripper2": 0.0}, "tool")
        assert np.allclose(model.pose(np.array(q)).homogeneous, reference.homogeneous, atol=1e-14)
    # the mass off the chain rides on it: the reduced model weighs the whole arm
    assert sum(i.mass for i in model.model.inertias) == pytest.approx(4.4, rel=1e-14)
    # a chain from l1: j1 is above its base, locked at 0 (within its limits); side clipped to 0.2
    above = load_model(read(_toml(tmp_path, home="[-0.4]", joints='chain = ["l1", "tool"]')))
    assert above.joint_names == ["j2"]
    reference = _full_fk(path, {"j1": 0.0, "j2": -0.4, "side": 0.2, "gripper": 0.0, "gripper2": 0.0}, "tool")
    assert np.allclose(above.pose(np.array([-0.4])).homogeneous, reference.homogeneous, atol=1e-14)


@pytest.mark.parametrize("chain, problem", [
    ('["l2", "side_link"]', "link 'side_link': is not below link 'l2'"),
    ('["base", "nowhere"]', "link 'nowhere': no such link"),
    ('["base", "side_link", "tool"]', "must be two link names [base, tip]"),
])
def test_a_chain_that_is_no_chain_is_refused(tmp_path, chain, problem):
    _write(tmp_path, ARM)
    with pytest.raises(ValueError) as info:
        load_model(read(_toml(tmp_path, frame="side_link", home="[0, 0.5]", joints=f"chain = {chain}")))
    assert "arm.toml: joints.chain: " in str(info.value) and problem in str(info.value), str(info.value)


EXAMPLE_ROBOTS = Path(pin.__file__).parents[4] / "share/example-robot-data/robots"


def test_the_torso_and_arm_of_a_mobile_manipulator_as_one_chain(tmp_path):
    """TIAGo (example-robot-data): base_footprint to arm_tool_link keeps the torso lift and the seven
    arm joints; wheels (continuous), head and hand locked. FK equals the full model's (Pinocchio's
    own reader: wheels as cos/sin pairs) with those joints at their values."""
    urdf = EXAMPLE_ROBOTS / "tiago_description/robots/tiago.urdf"
    toml = _toml(tmp_path, urdf='{ distribution = "example-robot-data", path = "tiago_description/robots/tiago.urdf" }',
                 frame="arm_tool_link", home="[0.15, 0.2, -1.3, -0.2, 1.9, -1.5, 1.3, 0.0]",
                 joints='chain = ["base_footprint", "arm_tool_link"]\nlocked = { head_1_joint = 0.3, '
                        'wheel_left_joint = 1.0 }')
    model = load_model(read(toml))
    assert model.joint_names == ["torso_lift_joint"] + [f"arm_{k}_joint" for k in range(1, 8)]
    assert model.prismatic == [True] + [False] * 7
    checked = read_urdf(urdf)
    held = {name: joint.clip(0.0) for name, joint in checked.joints.items() if joint.type != "fixed"}
    held.update(head_1_joint=0.3, wheel_left_joint=1.0)
    rng = np.random.default_rng(11)
    lower, upper = model.position_limits()
    for _ in range(3):
        q = rng.uniform(lower, upper)
        values = dict(held, **dict(zip(model.joint_names, q)))
        reference = _full_fk(urdf, values, "arm_tool_link")
        assert np.allclose(model.pose(q).homogeneous, reference.homogeneous, atol=1e-12)


XACRO = """<?xml version="1.0"?>
<robot xmlns:xacro="http://www.ros.org/wiki/xacro" name="arm">
  <xacro:arg name="reach" default="0.35"/>
  <xacro:arg name="tool_mass" default="0.2"/>
  <xacro:property name="reach" value="$(arg reach)"/>
  <xacro:macro name="rod" params="name mass">
    <link name="${name}"><inertial><origin xyz="0 0 0.1"/><mass value="${mass}"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.005"/></inertial></link>
  </xacro:macro>
  <link name="base"/>
  <xacro:rod name="l1" mass="2.0"/>
  <xacro:rod name="l2" mass="1.5"/>
  <xacro:rod name="tool" mass="$(arg tool_mass)"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.3"/>
    <axis xyz="0 0 1"/><limit lower="-2.5" upper="2.5" effort="50" velocity="2"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.1 0 0.4" rpy="0 0.2 0"/>
    <axis xyz="0 1 0"/><limit lower="-1.5" upper="1.5" effort="40" velocity="2"/></joint>
  <joint name="tool" type="fixed"><parent link="l2"/><child link="tool"/><origin xyz="${reach * 2} 0.02 0"/></joint>
</robot>
"""

BY_HAND = f"""<?xml version="1.0"?>
<robot name="arm">
  <link name="base"/>{_link("l1", 2.0)}{_link("l2", 1.5)}{_link("tool", 0.7)}
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.3"/>
    <axis xyz="0 0 1"/><limit lower="-2.5" upper="2.5" effort="50" velocity="2"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.1 0 0.4" rpy="0 0.2 0"/>
    <axis xyz="0 1 0"/><limit lower="-1.5" upper="1.5" effort="40" velocity="2"/></joint>
  <joint name="tool" type="fixed"><parent link="l2"/><child link="tool"/><origin xyz="0.9 0.02 0"/></joint>
</robot>
"""


def test_a_xacro_robot_with_arguments_is_the_urdf_expanded_by_hand(tmp_path):
    _write(tmp_path, XACRO, "arm.urdf.xacro")
    hand = _write(tmp_path / "..", BY_HAND, "by_hand.urdf")
    description = read(_toml(tmp_path, urdf='"arm.urdf.xacro"', extra='xacro_args = { reach = 0.45, tool_mass = 0.7 }'))
    assert description.xacro_args == {"reach": "0.45", "tool_mass": "0.7"}
    model = load_model(description)
    assert model.urdf.path == tmp_path / "arm.urdf.xacro" and model.urdf.masses["tool"] == 0.7
    independent = pin.buildModelFromUrdf(str(hand))
    data = independent.createData()
    for q in ([0.3, -0.4], [-1.0, 1.1]):
        pin.framesForwardKinematics(independent, data, np.array(q))
        reference = data.oMf[independent.getFrameId("tool", pin.FrameType.BODY)]
        assert np.allclose(model.pose(np.array(q)).homogeneous, reference.homogeneous, atol=1e-15)
        assert np.allclose(model.mass_matrix(np.array(q)), pin.crba(independent, data, np.array(q)), atol=1e-15)
    # the defaults: reach 0.35 (the tool 0.7 m out), mass 0.2
    assert read_urdf(tmp_path / "arm.urdf.xacro").masses["tool"] == 0.2
    with pytest.raises(ValueError, match=r"arm.toml: xacro_args: only for a .xacro urdf"):
        _write(tmp_path, ARM)
        read(_toml(tmp_path, extra='xacro_args = { reach = 0.45 }'))
    with pytest.raises(UrdfError, match=r"arm.urdf.xacro: xacro: does not expand: .*; fix the file or its xacro_args"):
        _write(tmp_path, XACRO.replace("${reach * 2}", "${nowhere * 2}"), "arm.urdf.xacro")
        read_urdf(tmp_path / "arm.urdf.xacro")


SRDF = """<?xml version="1.0"?>
<robot name="arm">
  <group name="arm"><chain base_link="base" tip_link="tool"/></group>
  <group_state name="ready" group="arm"><joint name="j1" value="0.7"/><joint name="j2" value="-0.9"/></group_state>
  <group_state name="ready" group="hand"><joint name="gripper" value="0.02"/></group_state>
  <group_state name="tucked" group="arm"><joint name="j2" value="1.25"/></group_state>
</robot>
"""


def test_an_srdf_state_is_a_named_configuration(tmp_path):
    """home = "srdf:ready": the SRDF's numbers (read here with ElementTree) in the model's joint
    order; side, which the state does not name, at 0 clipped into [0.2, 1]; "tucked" names j2 only."""
    _write(tmp_path, ARM)
    srdf = _write(tmp_path, SRDF, "arm.srdf")
    given = {}
    for state in ElementTree.parse(srdf).getroot().iter("group_state"):
        for joint in state.iter("joint"):
            given.setdefault(state.get("name"), {})[joint.get("name")] = float(joint.get("value"))
    assert srdf_states(srdf) == given
    description = read(_toml(tmp_path, home='"srdf:ready"', extra='srdf = "arm.srdf"',
                             joints='locked = { gripper = 0.02, gripper2 = 0.02 }')
                       .parent / "arm.toml")
    assert description.configuration("home") == (given["ready"]["j1"], given["ready"]["j2"], 0.2)
    # a chain locks the gripper at the value of home's state, not 0
    chained = read(_toml(tmp_path, home='"srdf:ready"', extra='srdf = "arm.srdf"', joints='chain = ["base", "tool"]',
                         configurations='tucked = "srdf:tucked"'))
    assert chained.configuration("home") == (0.7, -0.9) and chained.configuration("tucked") == (0.0, 1.25)
    model = load_model(chained)
    reference = _full_fk(tmp_path / "arm.urdf", {"j1": 0.7, "j2": -0.9, "side": 0.2, "gripper": 0.02,
                                                 "gripper2": 0.02}, "gripper")
    pin.framesForwardKinematics(model.model, model.data, np.array([0.7, -0.9]))
    mine = model.data.oMf[model.model.getFrameId("gripper__link", pin.FrameType.BODY)]
    assert np.allclose(mine.homogeneous, reference.homogeneous, atol=1e-14)


@pytest.mark.parametrize("srdf, key, problem", [
    (SRDF.replace('value="0.7"', 'value="nan"'), "srdf", "group_state 'ready': joint 'j1': value: 'nan' is not a finite"),
    (SRDF.replace('<robot name="arm">', '<!DOCTYPE x []><robot name="arm">'), "srdf", "SRDFs need none"),
    (SRDF.replace('name="ready" group="arm"', 'name="other" group="arm"', 1).replace(
        'name="ready" group="hand"', 'name="hand" group="hand"'), "configurations.home", "no group_state 'ready'"),
    (SRDF.replace('name="j1"', 'name="elbow"'), "configurations.home", "names joint 'elbow', which arm.urdf lacks"),
])
def test_a_broken_srdf_is_refused_naming_the_toml_key_and_the_srdf(tmp_path, srdf, key, problem):
    _write(tmp_path, ARM)
    _write(tmp_path, srdf, "arm.srdf")
    path = _toml(tmp_path, home='"srdf:ready"', extra='srdf = "arm.srdf"', joints='chain = ["base", "tool"]')
    with pytest.raises(ValueError) as info:
        read(path)
    assert str(info.value).startswith(f"{path}: {key}: ") and problem in str(info.value), str(info.value)


def test_a_fmu_carries_the_expanded_urdf_and_the_srdf_and_reads_the_same_robot(tmp_path):
    """stage_robot (what ``robofmu build`` puts in resources/robot/) for a xacro robot with an SRDF
    home: the expanded URDF as arm.urdf (no xacro left), the SRDF as arm.srdf; the description the
    FMU reads from those copies has the same home and the same kinematics as the user's."""
    from robofmu.system.packaging.build import stage_robot

    (tmp_path / "arm.urdf.xacro").write_text(XACRO)
    (tmp_path / "arm.srdf").write_text(SRDF.replace('<joint name="gripper" value="0.02"/>', ""))
    user = read(_toml(tmp_path, urdf='"arm.urdf.xacro"', extra='xacro_args = { reach = 0.45 }\nsrdf = "arm.srdf"',
                      home='"srdf:ready"'))
    folder = tmp_path / "resources" / "robot"
    stage_robot(user, folder)
    assert sorted(p.name for p in folder.iterdir()) == ["arm.srdf", "arm.toml", "arm.urdf"]
    assert "xacro:" not in (folder / "arm.urdf").read_text()
    carried = read(folder / "arm.toml", urdf=folder / "arm.urdf")
    assert carried.srdf == folder / "arm.srdf" and carried.xacro_args == {}
    assert carried.configuration("home") == user.configuration("home") == (0.7, -0.9)
    mine, theirs = load_model(user), load_model(carried)
    q = np.array([0.2, -0.3])
    assert np.array_equal(mine.pose(q).homogeneous, theirs.pose(q).homogeneous)
    assert np.array_equal(mine.mass_matrix(q), theirs.mass_matrix(q))


def test_the_robot_data_hash_of_a_xacro_robot_with_an_srdf_is_the_carried_copies_hash(tmp_path):
    """The hash ``robofmu build`` compares with an FMU's (staleness) covers the URDF the xacro file
    expands to and the SRDF: the user's files and the copies a FMU carries hash alike, and a change
    of the SRDF or of a xacro argument changes it."""
    from robofmu.components import description_hash
    from robofmu.system.packaging.build import stage_robot

    (tmp_path / "arm.urdf.xacro").write_text(XACRO)
    (tmp_path / "arm.srdf").write_text(SRDF.replace('<joint name="gripper" value="0.02"/>', ""))
    toml = _toml(tmp_path, urdf='"arm.urdf.xacro"', extra='xacro_args = { reach = 0.45 }\nsrdf = "arm.srdf"',
                 home='"srdf:ready"')
    user = read(toml)
    folder = tmp_path / "resources" / "robot"
    stage_robot(user, folder)
    carried = read(folder / "arm.toml", urdf=folder / "arm.urdf")
    before = description_hash(user)
    assert description_hash(carried) == before
    (tmp_path / "arm.srdf").write_text((tmp_path / "arm.srdf").read_text() + "\n")
    assert description_hash(read(toml)) != before
    (tmp_path / "arm.srdf").write_text(SRDF.replace('<joint name="gripper" value="0.02"/>', ""))
    assert description_hash(read(toml)) == before
    (tmp_path / "arm.urdf.xacro").write_text(XACRO.replace('name="tool_mass" default="0.2"',
                                                           'name="tool_mass" default="0.3"'))
    assert description_hash(read(toml)) != before           # what the xacro file expands to counts

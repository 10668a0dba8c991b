"""Misuse, issue 29 class 2: broken URDFs (and SRDFs, xacro files) through ``robofmu build
PATH/robot.toml``: one line on stderr (urdfdom's own lines never reach it), exit status 2, the
user's file and the element or key named, no traceback, no FMU written."""
from __future__ import annotations

from pathlib import Path

import pytest
from misuse import assert_refused
from test_urdf_reader import ARM, BOMB, SRDF, XACRO, _toml


def _robot(folder: Path, urdf: str, name: str = "arm.urdf", **toml) -> Path:
    (folder / name).write_text(urdf)
    return _toml(folder, **{"home": "[0.3, -0.4, 0.5]", "joints": "locked = { gripper = 0.01, gripper2 = 0.01 }",
                            **toml})


@pytest.mark.parametrize("urdf, element", [
    ("this is no XML <robot", "line 1"),
    (BOMB, "line 2"),
    (ARM.replace('<link name="side_link">', '<link name="l1">'), "link 'l1'"),
    (ARM.replace('ixx="0.01"', 'ixx="nan"', 1), "link 'l1': inertial/inertia ixx: 'nan' is not a finite number"),
    (ARM.replace('<axis xyz="0 1 0"/>', '<axis xyz="0 0 0"/>', 1), "joint 'j2': axis xyz 0 0 0 has zero length"),
    (ARM.replace('lower="-1.5" upper="1.5"', 'lower="1.2" upper="-1.2"'), "joint 'j2': limit lower 1.2 above upper"),
    (ARM.replace('<parent link="l1"/><child link="side_link"/>', '<parent link="l1"/><child link="l2"/>'),
     "link 'l2': is the child of joints"),
])
def test_a_broken_urdf_is_refused_in_one_line(tmp_path, capfd, urdf, element):
    toml = _robot(tmp_path, urdf)
    assert_refused(capfd, ["build", toml, "--out", tmp_path / "fmus"], f"{tmp_path / 'arm.urdf'}: ", element)
    assert not (tmp_path / "fmus" / "arm").exists() or not list((tmp_path / "fmus" / "arm").iterdir())


@pytest.mark.parametrize("toml, names", [
    ({"frame": "base"}, ["arm.toml: task.frame: no joint moves 'base'"]),
    ({"home": "[]", "joints": "locked = { j1 = 0.0, j2 = 0.0, side = 0.5, gripper = 0.0, gripper2 = 0.0 }"},
     ["arm.toml: joints.locked: no joint is left to move"]),
    ({"home": "[0.3]"}, ["arm.toml: configurations.home: needs 3 joint values"]),
    ({"joints": 'chain = ["l2", "side_link"]'}, ["arm.toml: joints.chain: ", "link 'side_link': is not below link 'l2'"]),
    ({"joints": "locked = { elbow = 0.1 }"}, ["arm.toml: joints.locked.elbow: no joint 'elbow'"]),
])
def test_a_description_its_urdf_refuses_is_refused_in_one_line(tmp_path, capfd, toml, names):
    path = _robot(tmp_path, ARM, **toml)
    assert_refused(capfd, ["build", path, "--out", tmp_path / "fmus"], *names)


def test_a_joint_type_robofmu_does_not_move_is_refused_naming_the_joint(tmp_path, capfd):
    """A floating joint (a mobile base) without a chain that leaves it out."""
    urdf = ARM.replace('<joint name="j1" type="revolute">', '<joint name="j1" type="floating">')
    path = _robot(tmp_path, urdf, home="[-0.4, 0.5]")
    assert_refused(capfd, ["build", path, "--out", tmp_path / "fmus"], str(tmp_path / "arm.urdf"), "joint 'j1'",
                   "floating", "[joints] chain")


def test_urdfdoms_own_complaints_never_reach_stderr(tmp_path, capfd):
    """A visual mesh without a file name: urdfdom prints two lines of its own on stderr (and
    Pinocchio still builds the model; robofmu never reads visuals). With a task frame no joint
    moves, the build's one line is robofmu's refusal alone."""
    urdf = ARM.replace('<link name="base"/>', '<link name="base"><visual><geometry><mesh/></geometry></visual></link>')
    path = _robot(tmp_path, urdf, frame="base")
    assert_refused(capfd, ["build", path, "--out", tmp_path / "fmus"], "arm.toml: task.frame: no joint moves 'base'")


@pytest.mark.parametrize("srdf, names", [
    (SRDF.replace('value="0.7"', 'value="nan"'), ["arm.toml: srdf: ", "arm.srdf: group_state 'ready': joint 'j1'"]),
    (SRDF.replace("<robot", "<robo"), ["arm.toml: srdf: ", "arm.srdf: line"]),
    (SRDF.replace('name="j1"', 'name="elbow"'), ["arm.toml: configurations.home: ", "'elbow'"]),
])
def test_a_broken_srdf_is_refused_in_one_line(tmp_path, capfd, srdf, names):
    (tmp_path / "arm.srdf").write_text(srdf)
    path = _robot(tmp_path, ARM, home='"srdf:ready"', extra='srdf = "arm.srdf"')
    assert_refused(capfd, ["build", path, "--out", tmp_path / "fmus"], *names)


def test_a_xacro_file_that_does_not_expand_is_refused_in_one_line(tmp_path, capfd):
    (tmp_path / "arm.urdf.xacro").write_text(XACRO.replace("${reach * 2}", "${nowhere * 2}"))
    path = _toml(tmp_path, urdf='"arm.urdf.xacro"', home="[0.3, -0.4]", extra='xacro_args = { reach = 0.4 }')
    assert_refused(capfd, ["build", path, "--out", tmp_path / "fmus"], f"{tmp_path / 'arm.urdf.xacro'}: xacro: ")


def test_a_reference_beyond_a_limit_names_the_robots_file(tmp_path, capfd):
    """The reference check's refusal (home beyond a limit here) names the TOML and exits 2."""
    path = _robot(tmp_path, ARM, home="[0.3, -0.4, 1.5]")
    assert_refused(capfd, ["build", path, "--out", tmp_path / "fmus"], f"{path}: ", "beyond its upper limit")

"""``robofmu inspect``: its numbers against an independent Pinocchio model built here from the URDF
file, its structure against the URDF read here with ElementTree.

The tool's pose at home (position, quaternion x y z w), the task Jacobian's smallest singular
value (the task's angular rows are the world-aligned Jacobian's rotated into the tool's axes: the
same singular values), each joint's distance to its limits, the leaves and their chains, the
frames' kinds and the name clashes, the total mass.
"""
from __future__ import annotations

import math
from importlib import metadata
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pinocchio as pin
import pytest

from robofmu.components.robots import load_description
from robofmu.system.cli import main
from robofmu.system.packaging.inspection import inspect, render

from misuse import assert_refused
from robot_files import independent_model

DIST = "example-robot-data"


def urdf_file(tail: str) -> Path:
    files = [f for f in metadata.distribution(DIST).files if str(f).endswith(tail)]
    assert len(files) == 1, files
    return Path(metadata.distribution(DIST).locate_file(files[0]))


def independent_at(model, frame: int, q):
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    placement = data.oMf[frame]
    J = pin.computeFrameJacobian(model, data, q, frame, pin.LOCAL_WORLD_ALIGNED)
    quaternion = pin.Quaternion(placement.rotation).coeffs()          # x, y, z, w
    return placement.translation, quaternion if quaternion[3] >= 0 else -quaternion, J


@pytest.mark.parametrize("robot", ["ur5", "panda"])
def test_a_robot_tomls_tool_at_home_matches_an_independent_model(robot):
    description = load_description(robot)
    model, frame = independent_model(robot)
    q = np.array(description.configuration("home"))
    position, quaternion, J = independent_at(model, frame, q)
    found = inspect(description.path).home
    assert found.source == "the TOML's home" and found.tool == description.task.frame and found.pose
    np.testing.assert_allclose(found.q, q, rtol=0, atol=0)
    np.testing.assert_allclose(found.position, position, rtol=0, atol=1e-12)
    np.testing.assert_allclose(found.quaternion, quaternion, rtol=0, atol=1e-12)
    assert found.sigma_min == pytest.approx(np.linalg.svd(J, compute_uv=False)[-1], rel=1e-10)
    np.testing.assert_allclose(found.lower_gap, q - model.lowerPositionLimit, rtol=0, atol=1e-12)
    np.testing.assert_allclose(found.upper_gap, model.upperPositionLimit - q, rtol=0, atol=1e-12)
    assert found.joints == tuple(model.names[1:])


def test_the_printed_tables_carry_those_numbers(capfd):
    description = load_description("ur5")
    model, frame = independent_model("ur5")
    q = np.array(description.configuration("home"))
    position, quaternion, J = independent_at(model, frame, q)
    capfd.readouterr()
    assert main(["inspect", str(description.path)]) == 0
    out, err = capfd.readouterr()
    assert err == ""
    assert f"position (m): {' '.join(f'{v:.6f}' for v in position)}" in out
    assert f"quaternion (x y z w): {' '.join(f'{v:.6f}' for v in quaternion)}" in out
    assert f"smallest singular value of the task Jacobian: {np.linalg.svd(J, compute_uv=False)[-1]:.4g}" in out
    gap = np.minimum(q - model.lowerPositionLimit, model.upperPositionLimit - q)
    k = int(np.argmin(gap))
    assert f"closest to a limit: {model.names[k + 1]}, {gap[k]:.4g} from its" in out
    assert len(out.splitlines()) < 50                                      # one screen


def _tree(path: Path):
    root = ElementTree.parse(path).getroot()
    joints = {j.get("name"): j for j in root.findall("joint")}
    parent_of = {j.find("child").get("link"): j for j in joints.values()}
    links = [link.get("name") for link in root.findall("link")]
    masses = [float(m.get("value")) for m in root.iterfind("link/inertial/mass")]
    return root, joints, parent_of, links, masses


def test_a_bare_urdf_lists_its_leaves_chains_frames_clashes_and_mass():
    """so100: one leaf (jaw) through six joints; 'gripper' is a joint and a link: both marked."""
    path = urdf_file("so_arm_description/urdf/so100.urdf")
    _, joints, parent_of, links, masses = _tree(path)
    found = inspect(path)
    leaves = [link for link in links if link not in {j.find("parent").get("link") for j in joints.values()}]
    expected = {}
    for leaf in leaves:
        chain, link = [], leaf
        while link in parent_of:
            chain.append(parent_of[link].get("name"))
            link = parent_of[link].find("parent").get("link")
        movable = [j for j in reversed(chain) if joints[j].get("type") != "fixed"]
        if movable:
            expected[leaf] = tuple(movable)
    assert found.leaves == expected == {"jaw": ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex",
                                                "wrist_roll", "gripper")}
    assert found.urdf.clashes == ("gripper",)
    assert found.urdf.total_mass == pytest.approx(math.fsum(masses), rel=1e-12)
    text = render(found)
    assert "links: base, shoulder, upper_arm, lower_arm, wrist, gripper*, jaw" in text
    assert "joints: shoulder_pan, shoulder_lift, elbow_flex, wrist_flex, wrist_roll, gripper*" in text
    assert f"total mass {math.fsum(masses):.4g} kg" in text


def test_a_bare_urdfs_home_is_the_rules_and_its_numbers_an_independent_models():
    """kinova (jaco, three continuous joints) with --frame: the home the rule chose, and at it the
    independent model's pose, singular value; continuous joints shown unbounded."""
    path = urdf_file("kinova_description/robots/kinova.urdf")
    found = inspect(path, "j2s6s200_end_effector")
    home = found.home
    assert home.source.startswith("the posture rule's home")
    model = pin.buildModelFromUrdf(str(path))
    frame = model.getFrameId("j2s6s200_end_effector", pin.FrameType.BODY)
    q = np.concatenate([[math.cos(v), math.sin(v)] if model.joints[j + 1].nq == 2 else [v]
                        for j, v in enumerate(home.q)])
    position, quaternion, J = independent_at(model, frame, q)
    np.testing.assert_allclose(home.position, position, rtol=0, atol=1e-12)
    np.testing.assert_allclose(home.quaternion, quaternion, rtol=0, atol=1e-12)
    assert home.sigma_min == pytest.approx(np.linalg.svd(J, compute_uv=False)[-1], rel=1e-10)
    assert home.sigma_min >= 2.5 * 0.02
    continuous = [j.get("name") for j in ElementTree.parse(path).getroot().findall("joint")
                  if j.get("type") == "continuous"]
    assert len(continuous) == 3
    for name in continuous:
        k = home.joints.index(name)
        assert home.lower_gap[k] == home.upper_gap[k] == math.inf
        assert found.limits[name][:2] == (-math.inf, math.inf)
    assert "continuous (unbounded)" in render(found)


def test_several_leaves_and_no_frame_show_everything_but_the_home():
    found = inspect(urdf_file("kinova_description/robots/kinova.urdf"))
    assert found.home is None and "--frame" in found.why_no_home
    assert sorted(found.leaves) == ["j2s6s200_end_effector", "j2s6s200_link_finger_tip_1", "j2s6s200_link_finger_tip_2"]
    assert "at home: no tool: " in render(found)


def test_a_missing_file_or_frame_is_refused_in_one_line(capfd, tmp_path):
    assert_refused(capfd, ["inspect", tmp_path / "none.urdf"], "none.urdf")
    assert_refused(capfd, ["inspect", f"{DIST}:xarm_description/urdf/xarm7.urdf", "--frame", "nowhere"],
                   "--frame", "nowhere")
    broken = tmp_path / "broken.urdf"
    broken.write_text("<robot name='r'><link name='a'/>")
    assert_refused(capfd, ["inspect", broken], str(broken))

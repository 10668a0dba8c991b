"""``robofmu new`` + ``robofmu build`` + ``robofmu run`` with no hand edits, for arms of
example-robot-data that are not in the package, one per class of issue 28 (the acceptance).

Each robot is written by ``robofmu new`` into a temporary folder, built there, and its
demonstration experiment run through the master at 1 ms. The checks use an independent Pinocchio
model built here from the original URDF (joints off the chain locked by the stated rule: 0
clipped into the limits, a mimic follower with its leader), scipy's rotations and the written
TOML read with tomllib: ``ik.status`` 0 throughout, the reference a straight line and a slerp of
the written move from FK(home), the tool on it within 0.1 mm / 0.5 mrad over the run and 0.01 mm
/ 0.05 mrad at the end, every joint inside its limits, and the home posture by the rule.
"""
from __future__ import annotations

import math
import re
import tomllib
from importlib import metadata
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial.transform import Rotation

from robofmu.system import experiment
from robofmu.system.cli import main
from robofmu.system.master import Master

from misuse import assert_refused

DIST = "example-robot-data"
#: class -> (NAME, URDF path in example-robot-data, --frame or None)
CASES = {
    "7-dof": ("xarm", "xarm_description/urdf/xarm7.urdf", None),
    "gripper-name-clash": ("so100", "so_arm_description/urdf/so100.urdf", "gripper"),
    "5-dof-position": ("so101", "so_arm_description/urdf/so101.urdf", "gripper_frame_link"),
    "one-arm-of-two": ("baxter", "baxter_description/urdf/baxter.urdf", "right_gripper"),
    "torso-lift-and-arm": ("tiago", "tiago_description/robots/tiago_no_hand.urdf", "wrist_ft_tool_link"),
    "continuous-joints": ("jaco", "kinova_description/robots/kinova.urdf", "j2s6s200_end_effector"),
}
MOVABLE = ("revolute", "prismatic", "continuous")


def urdf_file(tail: str) -> Path:
    files = [f for f in metadata.distribution(DIST).files if str(f).endswith(tail)]
    assert len(files) == 1, files
    return Path(metadata.distribution(DIST).locate_file(files[0]))


class Independent:
    """The chain's model built here: Pinocchio from the URDF file, every joint off the path from
    the root to ``tool`` locked at 0 clipped into its limits (a mimic follower at its leader's
    relation), the tool frame found as a link (BODY) even where a joint has its name."""

    def __init__(self, path: Path, tool: str):
        root = ElementTree.parse(path).getroot()
        joints = {j.get("name"): j for j in root.findall("joint")}
        parent_of = {j.find("child").get("link"): j for j in joints.values()}
        on, link = [], tool
        while link in parent_of:
            on.append(parent_of[link].get("name"))
            link = parent_of[link].find("parent").get("link")
        links = {link.get("name"): link for link in root.findall("link")}
        for name in set(links) & set(joints):      # Pinocchio cannot reduce a model whose link and joint share
            renamed = f"{name}__the_link"          # a name: the link renamed here (the task frame is the link)
            links[name].set("name", renamed)
            for j in joints.values():
                for end in (j.find("parent"), j.find("child")):
                    if end.get("link") == name:
                        end.set("link", renamed)
            tool = renamed if tool == name else tool
        full = pin.buildModelFromXML(ElementTree.tostring(root, encoding="unicode"))
        values = {}

        def limits(j):
            limit = j.find("limit")
            if j.get("type") == "continuous" or limit is None:
                return -math.inf, math.inf
            low, high = float(limit.get("lower", 0)), float(limit.get("upper", 0))
            return (-math.inf, math.inf) if low == high == 0 else (low, high)

        for name, j in joints.items():
            if j.get("type") in MOVABLE and name not in on and j.find("mimic") is None:
                values[name] = min(max(0.0, limits(j)[0]), limits(j)[1])
        for name, j in joints.items():
            mimic = j.find("mimic")
            if j.get("type") in MOVABLE and name not in on and mimic is not None:
                leader = values[mimic.get("joint")]
                value = float(mimic.get("multiplier", 1)) * leader + float(mimic.get("offset", 0))
                values[name] = min(max(value, limits(j)[0]), limits(j)[1])
        reference = pin.neutral(full)
        for name, value in values.items():
            joint = full.joints[full.getJointId(name)]
            if joint.nq == 1:
                reference[joint.idx_q] = value
        ids = [full.getJointId(name) for name in values]
        self.model = pin.buildReducedModel(full, ids, reference) if ids else full
        self.data = self.model.createData()
        self.frame = self.model.getFrameId(tool, pin.FrameType.BODY)
        self.names = [self.model.names[j] for j in range(1, self.model.njoints)]
        self.continuous = [self.model.joints[j].nq == 2 for j in range(1, self.model.njoints)]
        self.lower = np.array([-math.inf if c else limits(joints[n])[0] for n, c in zip(self.names, self.continuous)])
        self.upper = np.array([math.inf if c else limits(joints[n])[1] for n, c in zip(self.names, self.continuous)])

    def configuration(self, q) -> np.ndarray:
        """Pinocchio's q of one angle per joint (a continuous joint's (cos, sin))."""
        return np.concatenate([[math.cos(v), math.sin(v)] if c else [v] for v, c in zip(q, self.continuous)])

    def placement(self, q) -> pin.SE3:
        pin.framesForwardKinematics(self.model, self.data, self.configuration(q))
        return self.data.oMf[self.frame].copy()

    def jacobian(self, q) -> np.ndarray:
        """The tool's 6 x n Jacobian, world-aligned (its singular values are the task's: the
        task's angular rows are these rotated into the tool's axes)."""
        J = pin.computeFrameJacobian(self.model, self.data, self.configuration(q), self.frame,
                                     pin.LOCAL_WORLD_ALIGNED)
        return J


@pytest.fixture(scope="module", params=sorted(CASES))
def arm(request, tmp_path_factory):
    """NAME, the folder, the written robot TOML (tomllib), the run's result and the independent
    model, after robofmu new, build and run with no edit."""
    name, tail, frame = CASES[request.param]
    folder = tmp_path_factory.mktemp(name)
    argv = ["new", name, "--urdf", f"{DIST}:{tail}", "--out", str(folder)] + (["--frame", frame] if frame else [])
    assert main(argv) == 0
    assert main(["build", str(folder / f"{name}.toml"), "--out", str(folder / "fmus")]) == 0
    written = tomllib.loads((folder / f"{name}.toml").read_text())
    experiments = sorted(folder.glob(f"{name}-*.toml"))
    assert len(experiments) == 1, experiments
    system = experiment.load(experiments[0], fmu_dir=folder / "fmus")
    result = Master(system).run()
    return name, folder, written, result, Independent(urdf_file(tail), written["task"]["frame"])


@pytest.mark.slow
def test_the_ik_converges_throughout_and_every_joint_stays_inside_its_limits(arm):
    _, _, written, result, model = arm
    assert np.all(result["ik.status"] == 0) and np.all(result["ik.reachable"] == 1)
    q = result.vector("plant.q")
    assert q.shape[1] == len(model.names)
    margin = np.minimum(q - model.lower, model.upper - q)
    assert margin.min() > 0.0, margin.min()
    assert np.all(result["plant.within_limits"] == 1)


@pytest.mark.slow
def test_the_tool_runs_the_written_move_on_its_line_and_slerp(arm):
    """The reference is the written move from FK(home) of the independent model; the tool (its
    FK of the plant's joints) follows it within 0.1 mm / 0.5 mrad, and 0.01 mm / 0.05 mrad at the
    end, where the reference has arrived."""
    _, _, written, result, model = arm
    move = written["trajectory"]
    start = model.placement(written["configurations"]["home"])
    x_ref = result.vector("trajectory.x_ref")
    step = np.array(move["displacement"])                        # a line (position task) or pose_line
    end = start.translation + step
    turn = Rotation.from_rotvec(move["rotation"]) if move["profile"] == "pose_line" else None
    progress = (x_ref - start.translation) @ step / (step @ step)          # s(t) along the line
    on_line = x_ref - start.translation - np.outer(progress, step)
    assert np.abs(on_line).max() < 1e-12 and progress.min() > -1e-12 and abs(progress[-1] - 1.0) < 1e-12
    np.testing.assert_allclose(x_ref[-1], end, rtol=0, atol=1e-12)
    q = result.vector("plant.q")
    position, angle = [], []
    for k in range(0, len(q), 10):
        placement = model.placement(q[k])
        position.append(np.linalg.norm(placement.translation - x_ref[k]))
        if move["profile"] == "pose_line":
            expected = Rotation.from_matrix(start.rotation) * Rotation.from_rotvec(progress[k] * turn.as_rotvec())
            recorded = Rotation.from_quat(result.vector("trajectory.quat_ref")[k])
            assert (recorded.inv() * expected).magnitude() < 1e-9, k
            angle.append((recorded.inv() * Rotation.from_matrix(placement.rotation)).magnitude())
    final = model.placement(q[-1])
    assert max(position) <= 1e-4 and np.linalg.norm(final.translation - end) <= 1e-5, (max(position), final)
    assert max(position) > 1e-8                                  # the loop tracks; no copy of the reference
    if angle:
        R_end = Rotation.from_matrix(start.rotation) * turn
        assert max(angle) <= 5e-4 and (R_end.inv() * Rotation.from_matrix(final.rotation)).magnitude() <= 5e-5


@pytest.mark.slow
def test_home_follows_the_posture_rule_and_the_task_fits_the_chain(arm):
    """Home: every joint at least 15 % of its range inside its limits, the tool at least 10 % of
    the reach above the chain's first joint, the task Jacobian's smallest singular value at least
    2.5 x the IK's 0.02 (the independent model's); a pose task from six joints, else a position."""
    _, _, written, _, model = arm
    home = np.array(written["configurations"]["home"])
    span = model.upper - model.lower
    bounded = np.isfinite(span)
    assert np.all(np.minimum(home - model.lower, model.upper - home)[bounded] >= 0.15 * span[bounded] - 1e-9)
    J = model.jacobian(home)
    pose = len(home) >= 6
    assert ("orientation_axes" in written["task"]) == pose
    sigma = np.linalg.svd(J if pose else J[:3], compute_uv=False)[-1]
    assert sigma >= 2.5 * 0.02, sigma
    base = model.model.jointPlacements[1].translation
    assert model.placement(home).translation[2] - base[2] > 0.0
    assert written["gains"]["pd"] == {"kp": 400.0, "kd": 40.0, "ki": 0.0}
    assert written["ik"]["solver"] == "damped_least_squares"


# -- refusals (fast) ---------------------------------------------------------------------------------
def test_several_leaves_are_listed_and_frame_asked_for(capfd, tmp_path):
    line = assert_refused(capfd, ["new", "jaco", "--urdf", f"{DIST}:kinova_description/robots/kinova.urdf",
                                  "--out", tmp_path], "--frame", "j2s6s200_end_effector",
                          "j2s6s200_link_finger_tip_1", "j2s6s200_link_finger_tip_2", folders=[tmp_path])
    assert "3 leaf links" in line
    assert not list(tmp_path.iterdir())


def test_a_file_robofmu_did_not_write_is_never_replaced_but_its_own_is(capfd, tmp_path):
    tail = f"{DIST}:xarm_description/urdf/xarm7.urdf"
    mine = tmp_path / "xarm.toml"
    mine.write_text("my own notes\n")
    assert_refused(capfd, ["new", "xarm", "--urdf", tail, "--out", tmp_path], str(mine), "--force",
                   untouched=[mine], folders=[tmp_path])
    assert main(["new", "xarm", "--urdf", tail, "--out", str(tmp_path), "--force"]) == 0
    first = mine.read_text()
    assert first.startswith("# Written by robofmu new") and tomllib.loads(first)["name"] == "xarm"
    assert main(["new", "xarm", "--urdf", tail, "--out", str(tmp_path)]) == 0      # its own: replaced
    assert mine.read_text() == first                                                 # deterministic
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


@pytest.mark.parametrize("argv, names", [
    (["--urdf", "no/such.urdf"], ["--urdf", "no/such.urdf"]),
    (["--urdf", "no-such-distribution:x.urdf"], ["--urdf", "no-such-distribution"]),
    (["--urdf", f"{DIST}:xarm_description/urdf/xarm7.urdf", "--frame", "nowhere"], ["--frame", "nowhere"]),
    (["--urdf", f"{DIST}:xarm_description/urdf/xarm7.urdf", "--frame", "joint3"], ["--frame", "joint3", "link3"]),
    (["--urdf", f"{DIST}:xarm_description/urdf/xarm7.urdf", "--frame", "link_base"], ["--frame", "link_base"]),
    (["--urdf", f"{DIST}:xarm_description/urdf/xarm7.urdf", "--frame", "link2"], ["--frame", "link2", "2 joint"]),
    (["--urdf", f"{DIST}:xarm_description/urdf/xarm7.urdf", "--xacro-arg", "a=1"], ["--xacro-arg"]),
])
def test_a_mistake_is_refused_in_one_line_naming_the_option(capfd, tmp_path, argv, names):
    assert_refused(capfd, ["new", "arm", *argv, "--out", tmp_path], *names, folders=[tmp_path])
    assert not list(tmp_path.iterdir())


def test_a_name_no_model_identifier_takes_is_refused(capfd, tmp_path):
    assert_refused(capfd, ["new", "my-arm", "--urdf", f"{DIST}:xarm_description/urdf/xarm7.urdf", "--out",
                           tmp_path], "NAME", "my-arm")


def test_a_xacro_arm_takes_its_arguments_into_the_toml(tmp_path):
    """A .xacro copy of xarm7 whose tool link is named by an argument: --xacro-arg names it, the
    TOML keeps xacro_args, and the robot it describes has that tool (read back by the package)."""
    from robofmu.components.robots import load_model
    from robofmu.components.robots.description import read

    text = urdf_file("xarm_description/urdf/xarm7.urdf").read_text()
    text = re.sub(r"<robot ([^>]*)>", r'<robot xmlns:xacro="http://www.ros.org/wiki/xacro" \1>'
                  '<xacro:arg name="tool" default="link_eef"/>', text.replace("link_eef", "$(arg tool)"), count=1)
    (tmp_path / "arm.urdf.xacro").write_text(text)
    assert main(["new", "arm", "--urdf", str(tmp_path / "arm.urdf.xacro"), "--xacro-arg", "tool=flange",
                 "--out", str(tmp_path)]) == 0
    written = tomllib.loads((tmp_path / "arm.toml").read_text())
    assert written["xacro_args"] == {"tool": "flange"}
    assert (tmp_path / written["urdf"]).resolve() == (tmp_path / "arm.urdf.xacro").resolve()
    assert written["task"]["frame"] == "flange"
    robot = load_model(read(tmp_path / "arm.toml"))
    assert robot.n == 7 and robot.model.existFrame("flange")


def test_a_relative_urdf_path_is_written_relative_to_the_toml(tmp_path, monkeypatch):
    (tmp_path / "src").mkdir()
    (tmp_path / "src" / "arm.urdf").write_text(urdf_file("xarm_description/urdf/xarm7.urdf").read_text())
    monkeypatch.chdir(tmp_path)
    assert main(["new", "arm", "--urdf", "src/arm.urdf", "--out", "robots"]) == 0
    assert tomllib.loads((tmp_path / "robots" / "arm.toml").read_text())["urdf"] == "../src/arm.urdf"
    assert tomllib.loads((tmp_path / "robots" / "arm-pose.toml").read_text())["robot"] == "arm.toml"


def test_an_srdf_state_naming_the_chain_is_home_when_it_passes_the_rule(tmp_path):
    """Panda with its SRDF and --frame panda_hand: home = "srdf:<state>", a state that names all
    seven arm joints; the model's home is that state's numbers (read here with ElementTree), the
    fingers off the chain locked."""
    from robofmu.components.robots import load_model
    from robofmu.components.robots.description import read

    srdf = urdf_file("panda_description/srdf/panda.srdf")
    assert main(["new", "panda_arm", "--urdf", f"{DIST}:panda_description/urdf/panda.urdf", "--srdf",
                 f"{DIST}:panda_description/srdf/panda.srdf", "--frame", "panda_hand", "--out", str(tmp_path)]) == 0
    written = tomllib.loads((tmp_path / "panda_arm.toml").read_text())
    state = written["configurations"]["home"]
    assert state.startswith("srdf:")
    values = {j.get("name"): float(j.get("value"))
              for s in ElementTree.parse(srdf).getroot().findall("group_state") if s.get("name") == state[5:]
              for j in s.findall("joint")}
    arm = [f"panda_joint{i}" for i in range(1, 8)]
    assert set(arm) <= set(values)
    robot = load_model(read(tmp_path / "panda_arm.toml"))
    assert robot.joint_names == arm
    np.testing.assert_allclose(robot.configuration("home"), [values[j] for j in arm], rtol=0, atol=0)
    assert written["joints"]["chain"] == ["panda_link0", "panda_hand"]

"""Issue 28, second acceptance point: arms of example-robot-data written by hand from
docs/robots.md, as a user would (no ``robofmu new``). Each mistake a user made on the way is
refused by ``robofmu build`` in one line that names the key, the joint (or link) and the fix
(the trial's log: a user's TOML per arm, its refusals verbatim); one hand-written arm builds and
runs, its tool checked against FK from an independent Pinocchio model of the URDF."""
from __future__ import annotations

import csv
import math
import re
from importlib import metadata
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from misuse import assert_refused
from robofmu.system.cli import main

DIST = "example-robot-data"
XARM7 = "xarm_description/urdf/xarm7.urdf"
SO100 = "so_arm_description/urdf/so100.urdf"
BAXTER = "baxter_description/urdf/baxter.urdf"
BAXTER_SRDF = "baxter_description/srdf/baxter_manipulation.srdf"
KINOVA = "kinova_description/robots/kinova.urdf"
KINOVA_SRDF = "kinova_description/srdf/kinova.srdf"


def _installed(tail: str) -> Path:
    """The file of example-robot-data whose path ends with ``tail`` (found independently of robofmu)."""
    files = [f for f in metadata.distribution(DIST).files if str(f).endswith(tail)]
    return Path(metadata.distribution(DIST).locate_file(files[0]))


def _model_joints(tail: str, keep=lambda name: True) -> list[str]:
    """Pinocchio's joint order of the URDF (home's order), the joints ``keep`` accepts."""
    model = pin.buildModelFromUrdf(str(_installed(tail)))
    return [name for name in model.names[1:] if keep(name)]


def _write(folder: Path, name: str, urdf: str, frame: str, home: str, extra: str = "", srdf: str | None = None,
           trajectory: str = 'profile = "line"\ndisplacement = [0.0, 0.02, 0.0]\nv_max = 0.05\na_max = 0.2\n') -> Path:
    """A user's robot TOML, position task, damped least squares, computed torque at 20 rad/s."""
    srdf_line = f'srdf = {{ distribution = "{DIST}", path = "{srdf}" }}\n' if srdf else ""
    path = folder / f"{name}.toml"
    path.write_text(f'''name = "{name}"
summary = "{name}, written by hand"
urdf = {{ distribution = "{DIST}", path = "{urdf}" }}
{srdf_line}blocks = ["trajectory", "ik", "controller", "plant", "fk"]
default_gains = "pd"
{extra}
[task]
frame = "{frame}"
coordinates = ["x", "y", "z"]

[configurations]
home = {home}

[gains.pd]
kp = 400.0
kd = 40.0

[ik]
solver = "damped_least_squares"

[trajectory]
{trajectory}''')
    return path


XARM7_HOME = "[0.0, -0.3, 0.0, 0.9, 0.0, 1.2, 0.0]"
BAXTER_HOME = "[0.0, -0.55, 0.0, 0.75, 0.0, 1.26, 0.0]"
BAXTER_CHAIN = '[joints]\nchain = ["right_arm_mount", "right_gripper"]\n'
XARM7_WAYPOINTS = ('profile = "waypoints"\nrelative = true\n'
                   'waypoints = [[0.10, 0.0, 0.0], [0.10, 0.10, -0.05], [0.0, 0.10, -0.05]]\n'
                   "durations = [{0}, {0}, {0}]\npause = 0.2\n")


def _case_locked_fixed(tmp):
    return (_write(tmp, "xarm7", XARM7, "link_eef", XARM7_HOME, '[joints]\nlocked = { joint_eef = 0.0 }\n'),
            ["joints.locked.joint_eef", "joint 'joint_eef' is fixed", "remove it",
             "its movable joints: " + ", ".join(_model_joints(XARM7, lambda n: n.startswith("joint") and n[5:].isdigit()))])


def _case_locked_missing(tmp):
    return (_write(tmp, "xarm7", XARM7, "link_eef", XARM7_HOME, '[joints]\nlocked = { joint8 = 0.0 }\n'),
            ["joints.locked.joint8", "no joint 'joint8' in xarm7.urdf", "its movable joints: joint1, joint2"])


def _case_home_after_chain(tmp):
    on = _model_joints(XARM7, lambda n: n in {f"joint{k}" for k in range(1, 6)})
    return (_write(tmp, "xarm7", XARM7, "link5", XARM7_HOME, '[joints]\nchain = ["link_base", "link5"]\n'),
            ["configurations.home", f"needs {len(on)} joint values", "in this order: " + ", ".join(on),
             "joint6, joint7 locked (joints.chain)", "got 7: give one value per joint"])


def _case_home_gripper_not_locked(tmp):
    order = _model_joints(SO100)
    return (_write(tmp, "so100", SO100, "gripper", "[0.0, 1.7, -1.2, -0.6, 0.3]"),
            ["configurations.home", "needs 6 joint values", "in this order: " + ", ".join(order),
             "got 5: give one value per joint, or lock a joint (joints.locked, joints.chain)"])


def _case_limits_off_chain(tmp):
    extra = '[joints]\nchain = ["link_base", "link5"]\n\n[joints.limits.joint7]\nvelocity = 2.0\n'
    return (_write(tmp, "xarm7", XARM7, "link5", "[0.0, -0.3, 0.0, 0.9, 0.0]", extra),
            ["joints.limits.joint7", "joint 'joint7' is off joints.chain", "remove the table or give a chain through it"])


def _case_chain_swapped(tmp):
    return (_write(tmp, "xarm7", XARM7, "link5", "[0.0, -0.3, 0.0]", '[joints]\nchain = ["link5", "link2"]\n'),
            ["joints.chain", "link 'link2': is not below link 'link5'", "swap them: the base link first, ['link2', 'link5']"])


def _case_chain_other_arm(tmp):
    return (_write(tmp, "baxter", BAXTER, "right_gripper", BAXTER_HOME,
                   '[joints]\nchain = ["left_arm_mount", "right_gripper"]\n'),
            ["joints.chain", "link 'right_gripper': is not below link 'left_arm_mount'",
             "give a base link above it (the links above it, from the root: base, torso, right_arm_mount,"])


def _case_srdf_state_beyond_a_limit(tmp):
    turned = -1.5707 + 2.0 * math.pi             # arm_up's joint 3, a turn away: inside [0.3316, 5.952]
    return (_write(tmp, "kinova", KINOVA, "j2s6s200_end_effector", '"srdf:arm_up"', srdf=KINOVA_SRDF),
            ["configurations.home", "the SRDF state 'arm_up' puts joint 3 (j2s6s200_joint_3) at -1.5707 rad",
             "beyond its lower limit 0.331613 rad (URDF)", f"write home as numbers with {turned:.6g} rad there"])


def _case_srdf_of_another_urdf(tmp):
    right = _model_joints(BAXTER, lambda n: re.fullmatch(r"right_[se]\d|right_w\d", n) is not None)
    return (_write(tmp, "baxter", BAXTER, "right_gripper", '"srdf:neutral"', BAXTER_CHAIN, srdf=BAXTER_SRDF),
            ["configurations.home", "names joint 'baxter/head_pan'", "the SRDF's names carry the prefix 'baxter/'",
             "write home as numbers, one per joint: " + ", ".join(right)])


def _case_too_fast(tmp):
    return (_write(tmp, "xarm7", XARM7, "link_eef", XARM7_HOME, trajectory=XARM7_WAYPOINTS.format(0.1)),
            ["trajectory", "joint 2 (joint2) beyond its velocity limit 3.14 rad/s (URDF)",
             "give trajectory.durations = ["])


def _case_start_away_from_home(tmp):
    """Absolute waypoints typed with a first row 50 mm off the tool at home (FK by an independent
    Pinocchio model): the loop would jump at t = 0."""
    model = pin.buildModelFromUrdf(str(_installed(XARM7)))
    data = model.createData()
    pin.framesForwardKinematics(model, data, np.array(eval(XARM7_HOME)))
    at_home = data.oMf[model.getFrameId("link_eef")].translation
    first = at_home + [0.05, 0.0, 0.0]
    rows = [[float(v) for v in first], [float(v) for v in at_home + [0.1, 0.0, 0.0]]]
    trajectory = f'profile = "waypoints"\nwaypoints = {rows}\ndurations = [1.0]\n'
    return (_write(tmp, "xarm7", XARM7, "link_eef", XARM7_HOME, trajectory=trajectory),
            ["trajectory: the reference does not start at home", "the task point 50 mm from its place at home",
             "give trajectory.relative = true", "first row of trajectory.waypoints (robofmu inspect xarm7.toml"])


@pytest.mark.parametrize("case", [_case_locked_fixed, _case_locked_missing, _case_home_after_chain,
                                  _case_home_gripper_not_locked, _case_limits_off_chain, _case_chain_swapped,
                                  _case_chain_other_arm, _case_srdf_state_beyond_a_limit, _case_srdf_of_another_urdf,
                                  _case_too_fast, _case_start_away_from_home], ids=lambda case: case.__name__[6:])
def test_a_hand_written_mistake_is_refused_naming_key_joint_and_fix(tmp_path, capfd, case):
    path, names = case(tmp_path)
    line = assert_refused(capfd, ["build", path, "--out", tmp_path / "fmus"], f"robofmu build: {path}: ", *names)
    assert "fmus" not in {p.name for p in tmp_path.iterdir()} or not any((tmp_path / "fmus").rglob("*.fmu")), line


def test_the_duration_a_too_fast_path_is_told_passes(tmp_path, capfd):
    """The durations the velocity refusal proposes for the xArm7's relative waypoints pass the
    build's check, and are the old ones times the worst ratio it names (rounded up)."""
    from robofmu.components.preflight import check_reference
    from robofmu.components.robots.description import read

    path = _write(tmp_path, "xarm7", XARM7, "link_eef", XARM7_HOME, trajectory=XARM7_WAYPOINTS.format(0.1))
    line = assert_refused(capfd, ["build", path, "--out", tmp_path / "fmus"], "trajectory.durations")
    ratio = float(re.search(r"at worst ([\d.]+) × the limit", line).group(1))
    proposed = [float(v) for v in re.search(r"durations = \[([^\]]+)\]", line).group(1).split(",")]
    assert all(0.1 * ratio <= d <= 0.1 * ratio + 0.01 for d in proposed), line
    path.write_text(path.read_text().replace("durations = [0.1, 0.1, 0.1]", f"durations = {proposed}"))
    found = check_reference(read(path))
    assert 0.9 < found.speed_ratio <= 1.0


def _results(path: Path) -> dict[str, np.ndarray]:
    with path.open() as f:
        rows = list(csv.reader(f))
    values = np.array([[float(v == "True") if v in ("True", "False") else float(v) for v in row] for row in rows[1:]])
    return {name: values[:, k] for k, name in enumerate(rows[0])}


@pytest.mark.slow
def test_baxters_right_arm_written_by_hand_builds_and_runs(tmp_path, monkeypatch):
    """Baxter's right arm as one chain of the dual-arm robot, a position task through relative
    waypoints (10 cm along -y, then 10 cm up), home typed in: built and run by the command line;
    ik.status 0 throughout, and the tool, by FK of the plant's joints in an independent Pinocchio
    model of the whole robot (the other joints at 0), within 0.01 mm of FK(home) plus the
    waypoints' offsets at each rest and after the move, the joints inside the URDF's limits."""
    waypoints = 'profile = "waypoints"\nrelative = true\nwaypoints = [[0.0, -0.1, 0.0], [0.0, -0.1, 0.1]]\n' \
                "durations = [1.5, 1.5]\npause = 0.5\n"
    robot = _write(tmp_path, "baxter", BAXTER, "right_gripper", BAXTER_HOME, BAXTER_CHAIN, trajectory=waypoints)
    (tmp_path / "baxter-wp.toml").write_text('robot = "baxter.toml"\nloop = "computed-torque"\nstop_time = 4.5\n'
                                             "step = 0.001\n")
    monkeypatch.chdir(tmp_path)
    assert main(["build", str(robot), "--out", "fmus"]) == 0
    assert main(["run", "baxter-wp.toml", "--fmus", "fmus", "--out", "out"]) == 0
    r = _results(tmp_path / "out" / "results.csv")
    assert np.all(r["ik.status"] == 0)

    model = pin.buildModelFromUrdf(str(_installed(BAXTER)))
    data = model.createData()
    arm = [name for name in model.names[1:] if re.fullmatch(r"right_[sew]\d", name)]
    tool = model.getFrameId("right_gripper", pin.FrameType.BODY)

    def tool_at(q_arm):
        q = pin.neutral(model)
        for name, value in zip(arm, q_arm):
            q[model.joints[model.getJointId(name)].idx_q] = value
        pin.framesForwardKinematics(model, data, q)
        return data.oMf[tool].translation.copy()

    q = np.column_stack([r[f"plant.q[{k + 1}]"] for k in range(len(arm))])
    start = tool_at([0.0, -0.55, 0.0, 0.75, 0.0, 1.26, 0.0])
    t = r["time"]
    for t0, t1, offset in ((1.55, 1.95, [0.0, -0.1, 0.0]), (3.6, 4.5, [0.0, -0.1, 0.1])):
        for k in np.flatnonzero((t >= t0) & (t <= t1))[::50]:
            assert np.linalg.norm(tool_at(q[k]) - (start + offset)) < 1e-5, (t[k], tool_at(q[k]) - start)
    for k in range(0, len(t), 100):          # the reference the IK got is FK's path, to the tracking error
        x_ref = np.array([r[f"trajectory.x_ref[{i}]"][k] for i in (1, 2, 3)])
        assert np.linalg.norm(tool_at(q[k]) - x_ref) < 1e-5, t[k]
    lower = [model.lowerPositionLimit[model.joints[model.getJointId(n)].idx_q] for n in arm]
    upper = [model.upperPositionLimit[model.joints[model.getJointId(n)].idx_q] for n in arm]
    assert np.all((q >= lower) & (q <= upper))

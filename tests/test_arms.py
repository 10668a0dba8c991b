"""The industrial arms (issue 22): ur5-pose, panda-pose and panda-waypoints through the master at
1 ms, checked against an independent model: Pinocchio's FK of the recorded joints, on a model the
test builds from the same URDF file (the Panda's fingers locked by hand), and the reference against
scipy's Slerp. The acceptance bars: tool position within 0.1 mm and orientation within 0.5 mrad
over the run, 0.01 mm and 0.05 mrad at the end, every joint inside its limits (the Panda's at
least 0.1 rad)."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial.transform import Rotation, Slerp

from robofmu.components.robots import load_description
from robofmu.components.time_law import lspb
from robofmu.system import experiment
from robofmu.system.analysis import tracking_metrics
from robofmu.system.master import Master
from robofmu.system.roles import Roles

from robot_files import independent_model

CASES = {"ur5-pose": "ur5", "panda-pose": "panda", "panda-waypoints": "panda"}
#: The experiments on the robot's default profile (a pose_line); panda-waypoints runs its
#: [trajectories.waypoints] profile (pose_waypoints from a CSV table).
LINES = ("ur5-pose", "panda-pose")


@pytest.fixture(scope="module", params=sorted(CASES))
def run(request, fmu_root):
    name = request.param
    system = experiment.load(name, fmu_dir=fmu_root)
    return name, system, Master(system).run()


def test_the_tool_follows_the_pose_within_the_bars(run):
    name, system, result = run
    robot = CASES[name]
    model, frame = independent_model(robot)
    data = model.createData()
    q = result.vector("plant.q")
    reference = result.vector("trajectory.x_ref")
    quaternions = result.vector("trajectory.quat_ref")
    position, angle = [], []
    for k in range(len(q)):
        pin.framesForwardKinematics(model, data, q[k])
        placement = data.oMf[frame]
        position.append(np.linalg.norm(placement.translation - reference[k]))
        angle.append((Rotation.from_quat(quaternions[k]).inv() * Rotation.from_matrix(placement.rotation)).magnitude())
    position, angle = np.array(position), np.array(angle)
    assert position.max() <= 1e-4 and angle.max() <= 5e-4, (position.max(), angle.max())
    assert position[-1] <= 1e-5 and angle[-1] <= 5e-5, (position[-1], angle[-1])
    assert position.max() > 1e-7                           # the loop does track (not a copy of the reference)
    # the run's own analysis says the same
    metrics = tracking_metrics(result, Roles.of(system))
    np.testing.assert_allclose(metrics.tcp_error, position, rtol=0, atol=1e-12)
    np.testing.assert_allclose(metrics.orientation_error, angle, rtol=0, atol=1e-9)


def test_every_joint_stays_inside_its_limits_and_the_blocks_say_so(run):
    name, _, result = run
    model, _ = independent_model(CASES[name])
    q = result.vector("plant.q")
    margin = np.minimum(q - model.lowerPositionLimit, model.upperPositionLimit - q)
    assert margin.min() > (0.1 if CASES[name] == "panda" else 0.0), margin.min()
    assert np.all(result["plant.within_limits"] == 1)
    assert np.all(result["ik.status"] == 0) and np.all(result["ik.reachable"] == 1)
    np.testing.assert_allclose(result["ik.joint_limit_margin"],
                               np.min(np.minimum(result.vector("ik.q_ref") - model.lowerPositionLimit,
                                                 model.upperPositionLimit - result.vector("ik.q_ref")), axis=1),
                               rtol=0, atol=1e-12)
    assert np.median(result["ik.iterations"][1:]) <= 2


def test_the_reference_is_a_line_and_a_slerp_on_one_lspb_time_law(run):
    name, _, result = run
    if name not in LINES:
        pytest.skip("a pose_waypoints profile: test_the_waypoints_reference_passes_through_the_tables_poses")
    robot = CASES[name]
    description = load_description(robot)
    model, frame = independent_model(robot)
    data = model.createData()
    pin.framesForwardKinematics(model, data, np.array(description.configuration("home")))
    start = data.oMf[frame]
    parameters = description.trajectory.parameters
    R0 = Rotation.from_matrix(start.rotation)
    R1 = R0 * Rotation.from_rotvec(parameters["rotation"])             # about the tool's own axes
    slerp = Slerp([0.0, 1.0], Rotation.concatenate([R0, R1]))
    for t in (0.0, 0.3, 0.7, 1.0, 1.5, 2.0, 2.5):
        k = int(round(t / 1e-3))
        s = float(lspb([0.0], [1.0], parameters["duration"], t)[0][0])
        np.testing.assert_allclose(result.vector("trajectory.x_ref")[k],
                                   start.translation + s * np.array(parameters["displacement"]), atol=1e-12)
        recorded = Rotation.from_quat(result.vector("trajectory.quat_ref")[k])
        assert (recorded.inv() * slerp(s)).magnitude() < 1e-12, t


def test_the_waypoints_reference_passes_through_the_tables_poses(run):
    """panda-waypoints: the table read here with numpy (not the package's reader); each leg a
    straight line and scipy's Slerp between its rows on its own LSPB law, pauses at rest."""
    name, _, result = run
    if name in LINES:
        pytest.skip("a pose_line profile: test_the_reference_is_a_line_and_a_slerp_on_one_lspb_time_law")
    description = load_description(CASES[name])
    parameters = description.profiles["waypoints"].parameters
    rows = np.loadtxt(description.path.parent / parameters["waypoints"], delimiter=",", skiprows=4)
    durations, pause = parameters["durations"], parameters["pause"]
    assert rows.shape == (len(durations) + 1, 7)
    x_ref, quat_ref = result.vector("trajectory.x_ref"), result.vector("trajectory.quat_ref")
    start = 0.0
    for i, T in enumerate(durations):
        slerp = Slerp([0.0, 1.0], Rotation.from_quat(rows[i:i + 2, 3:]))
        for k in np.linspace(round(start / 1e-3), round((start + T) / 1e-3), 9).round().astype(int):
            u = result.time[k] - start
            s = float(lspb([0.0], [1.0], T, u)[0][0])
            np.testing.assert_allclose(x_ref[k], rows[i, :3] + s * (rows[i + 1, :3] - rows[i, :3]), atol=1e-12)
            assert (Rotation.from_quat(quat_ref[k]).inv() * slerp(s)).magnitude() < 1e-12, (i, u)
        start += T + pause
    assert np.all(np.einsum("ij,ij->i", quat_ref[1:], quat_ref[:-1]) > 0.0)     # no sign flip between legs
    np.testing.assert_allclose(result.vector("trajectory.xd_ref")[-1], 0.0, atol=0)


def test_the_fk_block_outputs_the_frames_position_and_orientation(run):
    name, _, result = run
    model, frame = independent_model(CASES[name])
    data = model.createData()
    q = result.vector("plant.q")
    for k in (0, len(q) // 2, len(q) - 1):
        pin.framesForwardKinematics(model, data, q[k])
        np.testing.assert_allclose(result.vector("fk.x")[k], data.oMf[frame].translation, atol=1e-14)
        quaternion = result.vector("fk.quat")[k]
        assert quaternion[3] >= 0.0 and abs(np.linalg.norm(quaternion) - 1.0) < 1e-14
        assert (Rotation.from_quat(quaternion).inv() * Rotation.from_matrix(data.oMf[frame].rotation)).magnitude() < 1e-12


JOINT_CASES = {"ur5-joint": "ur5", "panda-joint": "panda"}


@pytest.mark.parametrize("name", sorted(JOINT_CASES))
def test_the_same_arm_in_joint_space_follows_its_second_profile(name, fmu_root):
    """The robot's [trajectories.joint] profile, its own FMU (trajectory_joint.fmu): the recorded
    reference is the synchronized bang-bang evaluated here, the joints track it within 1 mrad and
    end at rest on q_end; the FMU says which profile it is."""
    from robofmu.components.trajectory import SynchronizedBangBang
    from robofmu.system.fmu import block_identity

    robot = JOINT_CASES[name]
    system = experiment.load(name, fmu_dir=fmu_root)
    identity = block_identity(fmu_root / robot / "trajectory_joint.fmu")
    assert (identity["kind"], identity["variant"], identity["profile"]) == ("trajectory", "joint_bangbang", "joint")
    assert block_identity(fmu_root / robot / "trajectory.fmu")["profile"] == ""
    result = Master(system).run()
    parameters = load_description(robot).profiles["joint"].parameters
    profile = SynchronizedBangBang(parameters["q_start"], parameters["q_end"], parameters["a_max"])
    expected = np.array([profile.evaluate(t)[0] for t in result.time])
    np.testing.assert_allclose(result.vector("trajectory.q_ref"), expected, rtol=0, atol=1e-14)
    error = np.abs(result.vector("trajectory.q_ref") - result.vector("plant.q"))
    assert 1e-7 < error.max() < 1e-3, error.max()
    np.testing.assert_allclose(result.vector("plant.q")[-1], parameters["q_end"], rtol=0, atol=1e-8)
    assert np.abs(result.vector("plant.qd")[-1]).max() < 1e-6
    assert np.all(result["plant.within_limits"] == 1)

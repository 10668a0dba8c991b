"""The pose trajectory blocks, FMI-free (issue 22, point 3): ``pose_waypoints`` from a CSV table of
poses (panda's ``[trajectories.waypoints]``) and ``pose_line`` at minimum time under limits, each
against its profile built here from the description's numbers, with their refusals."""
from __future__ import annotations

import math

import numpy as np
import pytest

from robofmu.components.blocks import make_block
from robofmu.components.pose_trajectory import PoseLine, PoseWaypoints
from robofmu.components.preflight import check_reference
from robofmu.components.robots import DescriptionError, load_description
from robofmu.components.robots.description import read

from robot_files import del_key, set_key

POSE_OUTPUTS = ("x_ref", "xd_ref", "xdd_ref", "quat_ref", "omega_ref", "omegad_ref")


def outputs(block, t: float) -> list[np.ndarray]:
    block.output(t)
    names = {v.name: v for v in block.variables}
    return [np.array([block.get(f"{base}[{i}]") for i in range(1, 5 if base == "quat_ref" else 4)])
            for base in POSE_OUTPUTS if f"{base}[1]" in names]


def test_panda_waypoints_block_follows_its_table_of_poses():
    description = load_description("panda")
    kind, profile, described = description.block_of("trajectory_waypoints")
    assert (kind, profile) == ("trajectory", "waypoints")
    block = make_block(described, "trajectory")
    block.configure()
    parameters = described.trajectory.parameters
    rows = np.loadtxt(description.path.parent / parameters["waypoints"], delimiter=",", skiprows=4)
    expected = PoseWaypoints(rows, parameters["durations"], pause=parameters["pause"])
    assert block.profile.duration == expected.duration == pytest.approx(6.0)
    for t in np.linspace(-0.5, 6.5, 141):
        for got, want in zip(outputs(block, t), expected.evaluate(t)):
            np.testing.assert_array_equal(got, want)
    names = {v.name: v for v in block.variables}
    assert names["waypoints"].causality == "parameter" and names["quat_ref[4]"].unit == "1"
    assert names["omega_ref[3]"].unit == "rad/s" and "duration" not in names


def test_a_table_of_positions_is_refused_for_pose_waypoints(copy_robot):
    path = copy_robot("panda")
    (path.parent / "panda_poses.csv").write_text("x,y,z\n0.3,0.0,0.6\n0.4,0.1,0.5\n")
    _, _, described = read(path).block_of("trajectory_waypoints")
    with pytest.raises(DescriptionError, match=r"trajectory.waypoints: .*panda_poses.csv, line 1: expected 7 numbers "
                                               r"\(x, y, z, qx, qy, qz, qw\) or, first, the header x,y,z,qx,qy,qz,qw"):
        make_block(described, "trajectory")


def test_a_non_unit_quaternion_row_is_refused_naming_the_row(copy_robot):
    path = copy_robot("panda")
    table = path.parent / "panda_poses.csv"
    table.write_text(table.read_text().replace("0.923880,-0.382683", "0.823880,-0.382683"))
    _, _, described = read(path).block_of("trajectory_waypoints")
    block = make_block(described, "trajectory")
    with pytest.raises(ValueError, match=r"waypoints: row 2: the orientation quaternion .* has norm 0\.9\d+, not 1"):
        block.configure()


def test_pose_waypoints_needs_a_pose_task(copy_robot):
    def position_only(data):
        del_key(data, "task.orientation_axes")
        del data["trajectory"]
        data["trajectory"] = data["trajectories"].pop("waypoints")
        del data["trajectories"]
    path = copy_robot("panda", position_only)
    with pytest.raises(DescriptionError, match="trajectory.profile: pose_waypoints needs a pose task"):
        make_block(read(path), "trajectory")


LIMITS = {"v_max": 0.15, "a_max": 0.5, "omega_max": 1.0, "alpha_max": 2.0}


def _at_limits(data):
    del_key(data, "trajectory.duration")
    for key, value in LIMITS.items():
        set_key(data, f"trajectory.{key}", value)


def test_pose_line_at_minimum_time_declares_the_limits_and_follows_the_trapezoid(copy_robot):
    described = read(copy_robot("ur5", _at_limits))
    block = make_block(described, "trajectory")
    block.configure()
    names = {v.name: v for v in block.variables}
    assert "duration" not in names and "cruise_factor" not in names
    assert {k: names[k].unit for k in LIMITS} == {"v_max": "m/s", "a_max": "m/s2", "omega_max": "rad/s",
                                                  "alpha_max": "rad/s2"}
    start = [block.get(f"start[{i}]") for i in (1, 2, 3)]
    quaternion = [block.get(f"start_quaternion[{i}]") for i in (1, 2, 3, 4)]
    parameters = described.trajectory.parameters
    expected = PoseLine(start, parameters["displacement"], quaternion, parameters["rotation"], **LIMITS)
    # the ur5 move: 0.269 m and pi/2 rad; the rotation binds the rate, the line the acceleration
    distance = math.sqrt(0.15 ** 2 + 0.2 ** 2 + 0.1 ** 2)
    rate, acceleration = min(0.15 / distance, 1.0 / (math.pi / 2)), min(0.5 / distance, 2.0 / (math.pi / 2))
    assert block.profile.duration == pytest.approx(1.0 / rate + rate / acceleration, rel=1e-14)
    for t in np.linspace(-0.1, expected.duration + 0.1, 97):
        for got, want in zip(outputs(block, t), expected.evaluate(t)):
            np.testing.assert_array_equal(got, want)
    found = check_reference(described)                   # the build's check: solved along the path
    assert found.duration == pytest.approx(expected.duration) and found.ik_residual < 1e-9


def test_pose_line_with_both_duration_and_limits_is_refused(copy_robot):
    path = copy_robot("ur5", lambda d: set_key(d, "trajectory.v_max", 0.1))
    with pytest.raises(DescriptionError, match=r"trajectory.duration: give either duration \(an LSPB time law\) "
                                               r"or the limits v_max, a_max, omega_max, alpha_max"):
        make_block(read(path), "trajectory")


def test_pose_line_with_some_limits_missing_is_refused(copy_robot):
    def partial(data):
        del_key(data, "trajectory.duration")
        set_key(data, "trajectory.v_max", 0.1)
    with pytest.raises(DescriptionError, match=r"trajectory.a_max: parameter 'a_max' missing"):
        make_block(read(copy_robot("ur5", partial)), "trajectory")

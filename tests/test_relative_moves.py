"""Position tasks like pose tasks (issue 28, point 5): ``line`` and ``waypoints`` start at the task
point at home (or at ``start_configuration``) by default and take relative moves: ``line`` by
``displacement``, ``waypoints`` with ``relative = true`` (offsets from the start) or after a
``start``; the old forms still accepted. Checked against FK from an independent Pinocchio model
(or the planar arm's closed form) and the closed form of the line."""
from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from robofmu.components.blocks import make_block
from robofmu.components.preflight import check_reference
from robofmu.components.robots import DescriptionError, load_description
from robofmu.components.robots.description import read
from robofmu.components.time_law import lspb
from robofmu.components.trajectory import StraightLine, WaypointTrajectory

from robot_files import del_key, independent_model, set_key

DISPLACEMENT = [-0.10, 0.15, -0.05]
LIMITS = {"v_max": 0.2, "a_max": 0.8}


def fk_independent(robot: str, q) -> np.ndarray:
    """The task frame's position (m, world) at ``q`` by Pinocchio on the robot's URDF."""
    model, frame = independent_model(robot)
    data = model.createData()
    pin.framesForwardKinematics(model, data, np.asarray(q, dtype=float))
    return data.oMf[frame].translation.copy()


def trapezoid(t: float, length: float, v_max: float, a_max: float) -> float:
    """Arc length s(t) (m) of the minimum-time line: ramps at a_max to v_max and down (or a triangle)."""
    t1 = v_max / a_max if length >= v_max ** 2 / a_max else math.sqrt(length / a_max)
    peak = a_max * t1
    T = length / peak + t1
    t = min(max(t, 0.0), T)
    if t < t1:
        return 0.5 * a_max * t * t
    if t <= T - t1:
        return 0.5 * a_max * t1 * t1 + peak * (t - t1)
    return length - 0.5 * a_max * (T - t) ** 2


def ur5_position_line(data: dict) -> None:
    """UR5 with a position task (tool0's origin; the orientation free: a redundant task) moved by
    DISPLACEMENT from home on the minimum-time line."""
    del_key(data, "task.orientation_axes")
    data["trajectory"] = {"profile": "line", "displacement": DISPLACEMENT, **LIMITS}
    del data["trajectories"]


def configured(path):
    block = make_block(read(path), "trajectory")
    block.configure()
    return block


def test_a_line_by_displacement_starts_at_the_tool_at_home_and_runs_the_closed_form(copy_robot):
    path = copy_robot("ur5", ur5_position_line)
    block = configured(path)
    start = fk_independent("ur5", load_description("ur5").configuration("home"))
    np.testing.assert_allclose(block.get("start"), start, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(block.get("displacement"), DISPLACEMENT)
    d = np.array(DISPLACEMENT)
    length = float(np.linalg.norm(d))
    for t in np.linspace(-0.1, block.profile.duration + 0.1, 61):
        x = block.profile.evaluate(t)[0]
        np.testing.assert_allclose(x, start + trapezoid(t, length, **LIMITS) * d / length, rtol=0, atol=1e-12)
    np.testing.assert_allclose(block.profile.evaluate(block.profile.duration)[0], start + d, rtol=0, atol=1e-12)
    found = check_reference(read(path))                      # the build's check: the IK follows it
    assert found.ik_residual < 1e-9 and found.speed_ratio < 1.0


def test_a_line_by_displacement_declares_start_and_displacement_not_direction_and_length(copy_robot):
    block = make_block(read(copy_robot("ur5", ur5_position_line)), "trajectory")
    parameters = {v.name: v for v in block.variables if v.causality == "parameter"}
    assert list(parameters) == ["start[1]", "start[2]", "start[3]", "displacement[1]", "displacement[2]",
                                "displacement[3]", "v_max", "a_max"]
    assert [parameters[k].unit for k in parameters] == ["m"] * 6 + ["m/s", "m/s2"]
    assert all(v.description for v in parameters.values())
    assert "configuration 'home'" in parameters["start[1]"].description


def test_a_line_starts_at_start_configuration(copy_robot):
    """A second configuration named as the start: FK there, not at home."""
    ready = [0.3, -1.4, 1.6, -1.7, -1.5707963267948966, 0.2]

    def edit(data):
        ur5_position_line(data)
        data["configurations"]["ready"] = ready
        data["trajectory"]["start_configuration"] = "ready"
    block = configured(copy_robot("ur5", edit))
    np.testing.assert_allclose(block.get("start"), fk_independent("ur5", ready), rtol=0, atol=1e-12)


def test_the_old_line_form_takes_its_start_from_home_when_none_is_given(copy_robot):
    """rrp's line without its start: FK(home) of the URDF, the point its TOML gave by hand; the
    path the same as the TOML's to rounding."""
    given = load_description("rrp").trajectory.parameters
    block = configured(copy_robot("rrp", lambda d: del_key(d, "trajectory.start")))
    home = load_description("rrp").configuration("home")
    np.testing.assert_allclose(block.get("start"), fk_independent("rrp", home), rtol=0, atol=1e-12)
    np.testing.assert_allclose(block.get("start"), given["start"], rtol=0, atol=1e-12)
    old = StraightLine(given["start"], given["direction"], given["length"], given["v_max"], given["a_max"])
    for t in np.linspace(0.0, old.duration, 17):
        np.testing.assert_allclose(block.profile.evaluate(t)[0], old.evaluate(t)[0], rtol=0, atol=1e-12)


# -- waypoints -----------------------------------------------------------------------------------
def planar_home() -> np.ndarray:
    """planar2r's tool at home (q = 0, 1 rad): (1 + 0.5 cos 1, 0.5 sin 1) m, links 1 and 0.5 m."""
    return np.array([1.0 + 0.5 * math.cos(1.0), 0.5 * math.sin(1.0)])


#: planar2r's seed points (1.2, 0.6) and (0.6, 1.2) m as offsets from its tool at home
OFFSETS = (np.array([[1.2, 0.6], [0.6, 1.2]]) - planar_home()).tolist()


def relative_waypoints(data: dict) -> None:
    data["trajectory"]["waypoints"] = OFFSETS
    data["trajectory"]["relative"] = True


def test_relative_waypoints_are_offsets_from_the_tool_at_home(copy_robot):
    """planar2r's waypoints as offsets (one row per move): the path starts at the closed-form tool
    position at home and each move is the LSPB move from the point before to start + offset."""
    path = copy_robot("planar2r", relative_waypoints)
    block = configured(path)
    start = planar_home()
    np.testing.assert_allclose(start, fk_independent("planar2r", [0.0, 1.0])[:2], rtol=0, atol=1e-15)
    np.testing.assert_allclose(block.get("start"), start, rtol=0, atol=1e-15)
    points = [start] + [start + np.array(o) for o in OFFSETS]
    given = load_description("planar2r").trajectory.parameters
    t0 = 0.0
    for k, duration in enumerate(given["durations"]):
        for tau in np.linspace(0.0, duration, 9):
            x, xd, xdd = lspb(points[k], points[k + 1], duration, tau)
            got = block.profile.evaluate(t0 + tau)
            np.testing.assert_allclose(got[0], x, rtol=0, atol=1e-12)
            np.testing.assert_allclose(got[1], xd, rtol=0, atol=1e-12)
        t0 += duration + given["pause"]
    np.testing.assert_allclose(block.profile.evaluate(t0)[0], points[-1], rtol=0, atol=1e-12)
    assert check_reference(read(path)).speed_ratio < 1.0


def test_the_relative_form_is_the_seeds_path(copy_robot):
    """planar2r's TOML path (its first row FK(home) typed by hand, then (1.2, 0.6), (0.6, 1.2)) is
    the same path as offsets from home: OFFSETS are those points minus the tool at home."""
    block = configured(copy_robot("planar2r", relative_waypoints))
    seed = make_block(load_description("planar2r"), "trajectory")
    seed.configure()
    for t in np.linspace(-0.5, seed.profile.duration + 0.5, 73):
        for got, want in zip(block.profile.evaluate(t), seed.profile.evaluate(t)):
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


def test_waypoints_after_a_start_configuration_are_absolute_points(copy_robot):
    def edit(data):
        data["trajectory"]["waypoints"] = [[1.2, 0.6], [0.6, 1.2]]
        data["trajectory"]["start_configuration"] = "home"
    block = configured(copy_robot("planar2r", edit))
    np.testing.assert_allclose(block.get("start"), planar_home(), rtol=0, atol=1e-15)
    names = {v.name: v for v in block.variables}
    assert "one row per point after start" in names["waypoints"].description
    np.testing.assert_allclose(block.profile.evaluate(1.0)[0], [1.2, 0.6], rtol=0, atol=1e-15)
    np.testing.assert_allclose(block.profile.evaluate(0.0)[0], planar_home(), rtol=0, atol=1e-15)


def test_relative_waypoints_from_a_given_start():
    profile = WaypointTrajectory([[1.0, 0.0], [1.0, 2.0]], [1.0, 1.0], start=[0.5, -0.5], relative=True)
    np.testing.assert_array_equal(profile.waypoints, [[0.5, -0.5], [1.5, -0.5], [1.5, 1.5]])


# -- refusals --------------------------------------------------------------------------------------
@pytest.mark.parametrize("robot, edit, key, problem", [
    ("rrp", lambda d: set_key(d, "trajectory.displacement", [0.01, 0.0, 0.0]), "trajectory.displacement",
     "give either displacement or direction and length, not both"),
    ("rrp", lambda d: set_key(d, "trajectory.start_configuration", "ready"), "trajectory.start_configuration",
     "no configuration 'ready' (described: home)"),
    ("rrp", lambda d: set_key(d, "trajectory.start", [0.1, 0.0]), "trajectory.start", "needs 3 values"),
    ("planar2r", lambda d: set_key(d, "trajectory.relative", "yes"), "trajectory.relative",
     "must be true or false, got 'yes'"),
])
def test_a_wrong_relative_move_is_refused_naming_its_key(copy_robot, robot, edit, key, problem):
    path = copy_robot(robot, edit)
    with pytest.raises(DescriptionError) as info:
        make_block(read(path), "trajectory")
    assert str(info.value).startswith(f"{path}: {key}: {problem}"), str(info.value)


def test_a_zero_displacement_is_refused_naming_it(copy_robot):
    def edit(data):
        ur5_position_line(data)
        data["trajectory"]["displacement"] = [0.0, 0.0, 0.0]
    block = make_block(read(copy_robot("ur5", edit)), "trajectory")
    with pytest.raises(ValueError, match=r"parameter displacement = \(0, \.\.\., 0\) is invalid: must not be the "
                                         r"zero vector"):
        block.configure()
    with pytest.raises(ValueError, match="displacement: its length is beyond the largest float"):
        StraightLine.by_displacement([0.0, 0.0], [1.5e308, 1.5e308], 1.0, 1.0)


# -- as FMUs ---------------------------------------------------------------------------------------
@pytest.mark.slow
def test_the_relative_moves_build_into_valid_fmus_that_start_at_home(copy_robot, tmp_path):
    """The line by displacement and the relative waypoints as FMUs: both checkers find no
    problem, the start parameters' start values are FK at home, and fmpy's run ends at
    start + displacement (start + the last offset)."""
    from fmpy import read_model_description, simulate_fmu

    from robofmu.system.packaging.build import build
    from robofmu.system.packaging.validate import problems_of

    line = build(copy_robot("ur5", ur5_position_line), tmp_path / "fmus", blocks=["trajectory"], log=lambda *_: None)
    waypoints = build(copy_robot("planar2r", relative_waypoints), tmp_path / "fmus", blocks=["trajectory"],
                      log=lambda *_: None)
    home = fk_independent("ur5", load_description("ur5").configuration("home"))
    for fmu, start, end in ((line[0], home, home + DISPLACEMENT), (waypoints[0], planar_home(),
                                                                 planar_home() + OFFSETS[-1])):
        assert problems_of(fmu) == []
        starts = {v.name: v.start for v in read_model_description(str(fmu)).modelVariables}
        np.testing.assert_allclose([float(starts[f"start[{i}]"]) for i in range(1, len(start) + 1)], start,
                                   rtol=0, atol=1e-12)
        result = simulate_fmu(str(fmu), stop_time=4.0, step_size=1e-2)
        np.testing.assert_allclose([result[f"x_ref[{i}]"][-1] for i in range(1, len(end) + 1)], end,
                                   rtol=0, atol=1e-12)

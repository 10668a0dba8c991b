"""A robot's task rows, described once (:class:`TaskIndex`), against Pinocchio's full frame
quantities and finite differences."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from robofmu.components.robots import load_model
from robofmu.components.robots.description import read
from robofmu.components.robots.model import TaskIndex, consecutive
from robot_files import set_key


def test_consecutive_axes_become_a_slice_and_others_stay_a_list():
    assert consecutive([1, 2]) == slice(1, 3)
    assert consecutive([0, 2]) == [0, 2]
    assert consecutive([2, 1]) == [2, 1]                  # the task's order, never sorted
    assert consecutive([]) == []


@pytest.mark.parametrize("position, orientation, linear, angular, six, full", [
    ((0, 1, 2), (0, 1, 2), slice(0, 3), slice(0, 3), slice(0, 6), True),
    ((0, 1, 2), (), slice(0, 3), [], slice(0, 3), False),
    ((0, 2), (2,), [0, 2], slice(2, 3), [0, 2, 5], False),
    ((1, 2), (0, 1), slice(1, 3), slice(0, 2), slice(1, 5), False),
])
def test_the_index_of_each_part(position, orientation, linear, angular, six, full):
    index = TaskIndex(position, orientation)
    assert (index.linear, index.angular, index.six, index.is_full_pose) == (linear, angular, six, full)
    rows = np.arange(6.0)
    assert rows[index.six].tolist() == [*map(float, position), *(3.0 + a for a in orientation)]


@pytest.mark.parametrize("position, orientation", [((0, 3), ()), ((0, 0), ()), ((0,), (1, 1))])
def test_an_axis_out_of_range_or_repeated_is_refused(position, orientation):
    with pytest.raises(ValueError, match="distinct values of 0, 1, 2"):
        TaskIndex(position, orientation)


@pytest.mark.parametrize("axes, orientation_axes", [([0, 2], [2]), ([1, 2], [0, 1]), ([0, 1, 2], [0, 1, 2])])
def test_a_partial_pose_task_has_the_full_frame_jacobians_rows(copy_robot, axes, orientation_axes):
    """The UR5 with a task of some position and some orientation axes: its Jacobian is the rows of
    Pinocchio's full frame Jacobian (world-aligned linear, local angular) the index names, and its
    Jdot qd agrees with a central difference of J(q(t)) qd(t) along a motion of constant qd."""
    def edit(data):
        set_key(data, "task.axes", axes)
        set_key(data, "task.coordinates", [["x", "y", "z"][a] for a in axes])
        set_key(data, "task.orientation_axes", orientation_axes)
    model = load_model(read(copy_robot("ur5", edit)))
    assert model.task_index == TaskIndex(tuple(axes), tuple(orientation_axes))
    assert model.task_rows == len(axes) + len(orientation_axes)
    q = np.array([0.3, -1.1, 1.4, -0.7, 0.9, 0.2])
    qd = np.array([0.4, -0.3, 0.5, 0.2, -0.6, 0.3])
    pm, pd = model.model, model.model.createData()
    world = pin.computeFrameJacobian(pm, pd, q, model.task_id, pin.LOCAL_WORLD_ALIGNED)
    local = pin.computeFrameJacobian(pm, pd, q, model.task_id, pin.LOCAL)
    expected = np.vstack([world[axes], local[3:][orientation_axes]])
    np.testing.assert_allclose(model.jacobian(q), expected, rtol=0, atol=1e-14)
    dt = 1e-6

    def velocity(t):
        return model.jacobian(q + t * qd).dot(qd)
    difference = (velocity(dt) - velocity(-dt)) / (2 * dt)
    np.testing.assert_allclose(model.jdot_qdot(q, qd), difference, rtol=0, atol=1e-7)
    np.testing.assert_allclose(model.jacobian_derivative(q, qd).dot(qd), difference, rtol=0, atol=1e-7)


def test_a_mechanism_in_its_own_coordinates_has_no_task_index():
    assert load_model("3rrp").task_index is None

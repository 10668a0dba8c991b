"""Jacobian block: the task Jacobian J(q) (xd = J qd), direct feedthrough.

Outputs ``J[i,j]`` = d x_i / d q_j, row-major with FMI structured naming (two 1-based indices),
each in task unit i over joint unit j (m/rad, 1, rad/m). A pose task's rows after the task
coordinates are the angular velocity about the task frame's own tracked axes (rad over the joint
unit). Any robot model: it asks the model's ``jacobian(q)``. The input q starts at the robot's
home configuration.
"""
from __future__ import annotations

import numpy as np

from .base import Block, quotient_unit, vector_names


class JacobianBlock(Block):
    kind = "jacobian"
    feedthrough = True
    summary = "task Jacobian J(q), xd = J qd, row-major J[i,j] (direct feedthrough)"

    def declare(self):
        robot = self.robot
        n, m = robot.n, robot.task_rows
        frame = self.description.task.frame
        coords = list(robot.task_coordinates) + [f"the rotation about {frame}'s {'xyz'[a]} axis"
                                                 for a in robot.orientation_axes]
        joints = robot.joint_units(0)
        tasks = robot.task_units(0) + ["rad"] * len(robot.orientation_axes)
        self.q = self.joint_positions("q", "Joint {i} position")
        self.J = self.real_matrix(
            "J", m, n, "output", lambda i, j: quotient_unit(tasks[i - 1], joints[j - 1]),
            lambda i, j: f"Jacobian entry d {coords[i - 1]} / d q{j} (task coordinate {i} over joint {j})",
            depends=vector_names("q", n))
        self.shape = (m, n)

    def output(self, t):
        self.values[self.J] = np.asarray(self.robot.jacobian(self.values[self.q]), dtype=float).reshape(-1)

"""Forward-kinematics block: task coordinates x(q), direct feedthrough."""
from __future__ import annotations

from .base import Block, vector_names


class FKBlock(Block):
    kind = "fk"
    feedthrough = True
    summary = "forward kinematics: task coordinates from joint positions (direct feedthrough)"

    def declare(self):
        robot = self.robot
        coords = robot.task_coordinates
        self.q = self.joint_positions("q", "Joint {i} position")
        self.x = self.reals("x", robot.m, "output", robot.task_units(0),
                            lambda i: f"Task coordinate {coords[i - 1]}", depends=vector_names("q", robot.n))

    def output(self, t):
        self.values[self.x] = self.robot.fk(self.values[self.q])

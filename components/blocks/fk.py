"""Forward-kinematics block: task coordinates x(q), direct feedthrough; for a pose task also the
task frame's orientation as a unit quaternion (x, y, z, w), frame to world."""
from __future__ import annotations

from ..orientation import COMPONENTS
from .base import Block, vector_names


class FKBlock(Block):
    kind = "fk"
    feedthrough = True
    summary = "forward kinematics: task coordinates from joint positions (direct feedthrough)"

    def declare(self):
        robot = self.robot
        coords = robot.task_coordinates
        self.q = self.joint_positions("q", "Joint {i} position")
        joints = vector_names("q", robot.n)
        self.x = self.reals("x", robot.m, "output", robot.task_units(0),
                            lambda i: f"Task coordinate {coords[i - 1]}", depends=joints)
        self.quaternion = None
        if robot.orientation_axes:
            frame = self.description.task.frame
            self.quaternion = self.reals("quat", 4, "output", "1",
                                         lambda i: f"Orientation of frame {frame}: unit quaternion component "
                                                   f"{COMPONENTS[i - 1]} (x, y, z, w; frame to world)",
                                         depends=joints)

    def output(self, t):
        q = self.values[self.q]
        if self.quaternion is None:
            self.values[self.x] = self.robot.fk(q)
            return
        x, quaternion = self.robot.fk_quaternion(q)
        self.values[self.x] = x
        self.values[self.quaternion] = quaternion

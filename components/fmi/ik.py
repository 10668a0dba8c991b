"""IK block: joint reference (q, qd, qdd) from the task-space reference, with direct feedthrough.

Outputs are computed from the inputs at the current communication point (whenever inputs
change), so a master can evaluate trajectory -> IK -> controller without a step of delay.
Outside the workspace ``reachable`` is false, a warning is logged, and the block holds its last
valid position with zero velocity and acceleration.
"""
from __future__ import annotations

import math

import numpy as np

from ..ik import Unreachable, make_ik
from ..robot import Robot
from .base import DERIVATIVE_UNITS, BlockSlave



class IKSlave(BlockSlave):
    block = "ik"
    feedthrough = True
    summary = ("closed-form inverse kinematics at position, velocity and acceleration level "
               "(direct feedthrough)")

    def declare(self):
        self.robot = Robot(self.spec)
        coords = self.spec.task_coordinates
        m, n = len(coords), self.robot.n
        start = self.spec.scenario["waypoints"][0] if self.spec.scenario else [0.0] * m
        units = [DERIVATIVE_UNITS[u] for u in self.spec.task_units]
        self.string("elbow", "IK branch: 'up' or 'down'", self.spec.raw.get("elbow", "up"))
        self.real("tool_pitch", "parameter", "rad", "Tool pitch q2 + q3 + q4 held by the IK",
                  self.spec.raw["tool_pitch"])
        self.x = self.reals("x_ref", m, "input", [u[0] for u in units],
                            lambda i: f"Target TCP coordinate {coords[i - 1]}", starts=start)
        self.xd = self.reals("xd_ref", m, "input", [u[1] for u in units],
                             lambda i: f"Target TCP velocity along {coords[i - 1]}")
        self.xdd = self.reals("xdd_ref", m, "input", [u[2] for u in units],
                              lambda i: f"Target TCP acceleration along {coords[i - 1]}")
        xs = [f"x_ref[{i}]" for i in range(1, m + 1)]
        xds = [f"xd_ref[{i}]" for i in range(1, m + 1)]
        xdds = [f"xdd_ref[{i}]" for i in range(1, m + 1)]
        self.q = self.reals("q_ref", n, "output", self.robot.joint_units(0),
                            "Joint {i} reference position", depends=xs)
        self.qd = self.reals("qd_ref", n, "output", self.robot.joint_units(1),
                             "Joint {i} reference velocity", depends=xs + xds)
        self.qdd = self.reals("qdd_ref", n, "output", self.robot.joint_units(2),
                              "Joint {i} reference acceleration", depends=xs + xds + xdds)
        self.boolean("reachable", "output",
                     "False while the target lies outside the workspace (last valid solution held)",
                     depends=xs)
        self.last = None          # last valid joint position
        self.outside = False      # in an excursion outside the workspace (warned once per excursion)
        self.n = n

    def initialize(self):
        self.solver = make_ik(self.robot, tool_pitch=self.param("tool_pitch"),
                              elbow=str(self.other["elbow"]))
        self.last = None
        self.outside = False
        self.evaluate()

    def evaluate(self):
        r = self.r
        try:
            q, qd, qdd = self.solver.solve(r[self.x], r[self.xd], r[self.xdd])
            if not math.isfinite(qd.sum() + qdd.sum()):
                raise Unreachable(f"singular configuration at {r[self.x].tolist()}")
        except (Unreachable, np.linalg.LinAlgError) as exc:
            if not self.outside:
                held = ("holding the last valid solution" if self.last is not None else
                        "no valid solution yet: outputs zero")
                self.warn(f"t = {self.time:.9g} s: {exc}; {held}")
                self.outside = True
            self.other["reachable"] = False
            q = np.zeros(self.n) if self.last is None else self.last
            qd = qdd = np.zeros(self.n)
        else:
            self.other["reachable"] = True
            self.outside = False
            self.last = q
        r[self.q], r[self.qd], r[self.qdd] = q, qd, qdd

    def step(self, t, h):
        return True

    def logic_state(self):
        return {"last": None if self.last is None else list(map(float, self.last)), "outside": self.outside}

    def set_logic_state(self, state):
        self.last = None if state["last"] is None else np.array(state["last"])
        self.outside = state["outside"]

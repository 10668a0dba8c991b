"""Plant block: M(q) qdd + C(q, qd) qd + g(q) = tau, integrated by RK4 with tau held over the step.

No direct feedthrough: the outputs are the state at the communication point.
"""
from __future__ import annotations

import numpy as np

from ..ik import Unreachable, make_ik
from ..plant import Plant, PlantDiverged
from ..robot import Robot
from .base import BlockSlave


def scenario_start(robot: Robot) -> np.ndarray:
    """Joint position at the scenario's first waypoint (zeros if there is none)."""
    waypoints = robot.spec.scenario.get("waypoints")
    if not waypoints:
        return np.zeros(robot.n)
    try:
        return make_ik(robot).position(np.array(waypoints[0], dtype=float))
    except (Unreachable, ValueError):
        return np.zeros(robot.n)


class PlantSlave(BlockSlave):
    block = "plant"
    summary = ("manipulator dynamics M(q)qdd + C(q,qd)qd + g(q) = tau (Pinocchio ABA), RK4 with "
               "tau held over the step; no direct feedthrough")

    def declare(self):
        self.robot = Robot(self.spec)
        n = self.robot.n
        u0, u1 = self.robot.joint_units(0), self.robot.joint_units(1)
        self.real("g", "parameter", "m/s2", "Gravity magnitude, along -z of the world frame",
                  self.spec.gravity)
        self.real("payload_mass", "parameter", "kg",
                  "Point mass carried at the TCP while grip is true", self.spec.payload_mass)
        self.real("max_substep", "parameter", "s", "Largest RK4 sub-step inside a communication step",
                  1e-3)
        self.q0 = self.reals("q0", n, "parameter", u0, "Joint {i} initial position",
                             starts=scenario_start(self.robot))
        self.qd0 = self.reals("qd0", n, "parameter", u1, "Joint {i} initial velocity")
        self.tau = self.reals("tau", n, "input", self.robot.effort_units(),
                              "Joint {i} actuator torque (force for a prismatic joint)")
        self.boolean("grip", "input", "Gripper closed: carry payload_mass at the TCP")
        self.q = self.reals("q", n, "output", u0, "Joint {i} position", depends=[],
                            initial_depends=lambda i: [f"q0[{i}]"])
        self.qd = self.reals("qd", n, "output", u1, "Joint {i} velocity", depends=[],
                             initial_depends=lambda i: [f"qd0[{i}]"])
        self.plant = None

    def initialize(self):
        self.robot.set_gravity(self.param("g", low=0.0, unit="m/s2"))
        q0, qd0 = self.r[self.q0], self.r[self.qd0]
        for name, values in (("q0", q0), ("qd0", qd0)):
            bad = np.flatnonzero(~np.isfinite(values))
            if bad.size:
                raise ValueError(f"parameter {name}[{bad[0] + 1}] = {values[bad[0]]} is invalid: must be finite")
        self.plant = Plant(self.robot, q0, qd0,
                           payload_mass=self.param("payload_mass", low=0.0, unit="kg"),
                           max_substep=self.param("max_substep", low=0.0, low_inclusive=False, unit="s"))
        self.plant.set_grip(bool(self.other["grip"]))
        self.r[self.q], self.r[self.qd] = self.plant.q, self.plant.qd

    def step(self, t, h):
        self.plant.set_grip(bool(self.other["grip"]))
        try:
            self.plant.step(self.r[self.tau], h, t)
        except PlantDiverged as exc:
            return self.fail(str(exc))
        self.r[self.q], self.r[self.qd] = self.plant.q, self.plant.qd
        return True

    def logic_state(self):
        if self.plant is None:
            return {}
        return {"x": self.plant.x.tolist(), "grip": self.plant.grip}

    def set_logic_state(self, state):
        if self.plant is not None and state:
            self.plant.x = np.array(state["x"])
            self.plant.set_grip(state["grip"])

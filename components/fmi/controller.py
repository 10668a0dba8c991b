"""Controller block: computed-torque PD/PID, tau = M(q)(qdd_ref + kd e' + kp e + ki z) + N(q, qd).

Direct feedthrough: tau is computed from the inputs at the current communication point; the
integral z = integral of e dt advances in doStep with the error held over the step. The model
carries the payload only if ``payload_mass`` > 0 and ``grip`` is true (by default it does not
know the pawn).
"""
from __future__ import annotations

from ..control import ComputedTorque
from ..robot import Robot
from .base import BlockSlave


class ControllerSlave(BlockSlave):
    block = "controller"
    feedthrough = True
    summary = "computed-torque PD/PID joint controller (direct feedthrough)"

    def declare(self):
        self.robot = Robot(self.spec)
        n = self.robot.n
        gains = self.spec.gains("pd")
        self.real("kp", "parameter", "1/s2", "Proportional gain (every joint)", gains["kp"])
        self.real("kd", "parameter", "1/s", "Derivative gain (every joint)", gains["kd"])
        self.real("ki", "parameter", "1/s3", "Integral gain (every joint); 0 for PD", gains["ki"])
        self.real("g", "parameter", "m/s2", "Gravity in the controller's model", self.spec.gravity)
        self.real("payload_mass", "parameter", "kg",
                  "Payload the model assumes at the TCP while grip is true (0: unknown to it)", 0.0)
        u0, u1, u2 = (self.robot.joint_units(k) for k in range(3))
        self.q_ref = self.reals("q_ref", n, "input", u0, "Joint {i} reference position")
        self.qd_ref = self.reals("qd_ref", n, "input", u1, "Joint {i} reference velocity")
        self.qdd_ref = self.reals("qdd_ref", n, "input", u2, "Joint {i} reference acceleration")
        self.q = self.reals("q", n, "input", u0, "Joint {i} measured position")
        self.qd = self.reals("qd", n, "input", u1, "Joint {i} measured velocity")
        self.boolean("grip", "input", "Gripper closed (the model adds payload_mass)")
        inputs = [f"{b}[{i}]" for b in ("q_ref", "qd_ref", "qdd_ref", "q", "qd")
                  for i in range(1, n + 1)] + ["grip"]
        self.tau = self.reals("tau", n, "output", self.robot.effort_units(),
                              "Joint {i} actuator torque (force for a prismatic joint)",
                              depends=inputs)
        self.law = None

    def initialize(self):
        self.robot.set_gravity(self.param("g", low=0.0, unit="m/s2"))
        self.payload_mass = self.param("payload_mass", low=0.0, unit="kg")
        self.law = ComputedTorque(self.robot, self.param("kp", low=0.0), self.param("kd", low=0.0),
                                  self.param("ki", low=0.0))
        self.evaluate()

    def evaluate(self):
        r = self.r
        self.robot.set_payload(self.payload_mass if self.other["grip"] else 0.0)
        r[self.tau] = self.law.torque(r[self.q_ref], r[self.qd_ref], r[self.qdd_ref],
                                      r[self.q], r[self.qd])

    def step(self, t, h):
        self.law.advance(self.r[self.q_ref], self.r[self.q], h)
        return True

    def logic_state(self):
        return {"z": None if self.law is None else self.law.z.tolist()}

    def set_logic_state(self, state):
        if self.law is not None and state["z"] is not None:
            self.law.z[:] = state["z"]

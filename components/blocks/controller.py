"""Controller block: computed torque, tau = M(q)(qdd_ref + kd e' + kp e + ki z) + N(q, qd) + tau_f(qd).

``gain_scale`` (> 0) multiplies the three gains (a loop-gain knob for sweeps; 1 leaves them as
given). The gains start at the robot description's ``default_gains`` set and follow the gains'
rule (:mod:`~robofmu.components.control`: kp > 0, kd > 0, ki >= 0).
Direct feedthrough: tau is computed from the inputs at the current communication point; the
integral z = integral of e dt advances with the error held over the step (z += e h). The
position inputs q_ref and q start at the robot's home configuration (the rest at 0), so a lone
controller holds home with tau = g(home). For a robot
with a payload the model carries ``payload_mass`` while ``grip`` is true (0 by default: the
controller does not know the payload).
The controller's model of the joints' losses is its own: parameters ``damping[j]``,
``friction[j]``, ``friction_velocity[j]`` and (where the model takes one) ``armature[j]``, declared
as the plant's are and starting at the robot's data (known to the controller), so that an
experiment can make its model differ from the plant's; ``loss_compensation`` scales the damping
and friction it adds, tau_f = c (b qd + tau_c tanh(qd / v_s)) at the measured qd: 1 (default)
compensates them, 0 leaves the losses unknown to it (the armature stays in its M).
Where the robot description asks for it (``[joints] saturate_effort = true``), tau is clipped to
the joints' effort limits and the output ``saturated`` is true while any joint is clipped (one
warning per excursion, naming the joint and the time).
Computation delay: ``delay_steps`` = d (Integer, default 0) outputs at sample k the effort computed
from the inputs of sample k - d (a sample: one doStep of the controller, its sample time); before
sample d it outputs the effort of sample 0. The last d + 1 efforts wait in a ring buffer of
preallocated rows, part of the FMU state. d = 0 is the undelayed law, unchanged.
"""
from __future__ import annotations

import numpy as np

from ..control import GAINS, ComputedTorque
from ..parameters import Parameter
from ..plant import JointLosses
from .base import ContinuousBlock, vector_names
from .plant import configured_losses, declare_losses


#: The computation delay in controller samples (a FMU Integer parameter of the controller).
DELAY_STEPS = Parameter("delay_steps", "Integer", "", "Computation delay: the effort computed from the inputs "
                        "of one sample is output d samples later (0: at once)", 0, low=0, high=1000)


class ControllerBlock(ContinuousBlock):
    kind = "controller"
    feedthrough = True
    summary = "computed-torque PD/PID joint controller (direct feedthrough)"

    def declare(self):
        robot, d = self.robot, self.description
        n = robot.n
        gains = d.gain_set(d.default_gains).as_dict()     # kp, kd, ki bounded by the one rule (control.GAINS)
        for rule in GAINS:
            self.real(rule.name, "parameter", rule.unit, rule.description, gains[rule.name], low=rule.low,
                      above=rule.above)
        self.real("gain_scale", "parameter", "1", "Multiplies kp, kd and ki (1: the gains as given)", 1.0, above=0.0)
        self.real("g", "parameter", "m/s2", "Gravity in the controller's model", d.gravity, low=0.0)
        self.has_payload = d.payload is not None
        if self.has_payload:
            self.real("payload_mass", "parameter", "kg", "Payload the model assumes while grip is true "
                      "(0: unknown to it)", 0.0, low=0.0)
        u1, u2 = robot.joint_units(1), robot.joint_units(2)
        self.q_ref = self.joint_positions("q_ref", "Joint {i} reference position")
        self.qd_ref = self.reals("qd_ref", n, "input", u1, "Joint {i} reference velocity")
        self.qdd_ref = self.reals("qdd_ref", n, "input", u2, "Joint {i} reference acceleration")
        self.q = self.joint_positions("q", "Joint {i} measured position")
        self.qd = self.reals("qd", n, "input", u1, "Joint {i} measured velocity")
        inputs = [name for b in ("q_ref", "qd_ref", "qdd_ref", "q", "qd") for name in vector_names(b, n)]
        if self.has_payload:
            self.grip = self.boolean("grip", "input", "Gripper closed (the model adds payload_mass)")
            inputs.append("grip")
        self.tau = self.reals("tau", n, "output", robot.effort_units(),
                              "Joint {i} actuator effort (torque, or force for a prismatic joint)",
                              depends=inputs)
        self.saturates = d.saturate_effort
        if self.saturates:
            self.saturated = self.boolean("saturated", "output", "True while an effort is clipped to its "
                                          "joint's effort limit", depends=inputs)
        self.has_armature = declare_losses(self)
        self.real("loss_compensation", "parameter", "1", "Scales the damping and friction the controller adds "
                  "(1: the losses known to it, 0: unknown)", 1.0, low=0.0)
        self.setting(DELAY_STEPS, 0)
        self.law = None
        self._delay = 0

    def configure(self):
        self.robot.set_gravity(self.parameter("g"))
        self.payload_mass = self.parameter("payload_mass") if self.has_payload else 0.0
        scale = self.parameter("gain_scale")
        losses = configured_losses(self, self.has_armature)
        known = self.parameter("loss_compensation")
        losses = JointLosses(known * losses.damping, known * losses.friction, losses.velocity_scale)
        self.law = ComputedTorque(self.robot, scale * self.parameter("kp"), scale * self.parameter("kd"),
                                  scale * self.parameter("ki"), losses)
        v = self.values                          # views, made once (the values array is never replaced)
        self._inputs = tuple(v[s] for s in (self.q_ref, self.qd_ref, self.qdd_ref, self.q, self.qd))
        self._tau_out = v[self.tau]
        self._effort = self.robot.effort_limits()
        self._clipping = False
        self._delay = self.parameter("delay_steps")
        # efforts of the last d + 1 samples; row `_head` is this sample's (rows: views made once)
        self._pending = np.zeros((self._delay + 1, self.robot.n))
        self._rows = list(self._pending)
        self._head = 0
        self._samples = 0
        super().configure()

    def output(self, t):
        if self.has_payload:
            self.robot.set_payload(self.payload_mass if self.values[self.grip] else 0.0)
        if self._delay:
            now = self._rows[self._head]
            self.law.torque_into(*self._inputs, now)
            if not self._samples:                  # before sample d: the effort of sample 0
                self._pending[:] = now
            self._tau_out[:] = self._rows[(self._head + 1) % (self._delay + 1)]
        else:
            self.law.torque_into(*self._inputs, self._tau_out)
        if self.saturates:
            self._saturate(t)

    def _saturate(self, t):
        tau, limit = self._tau_out, self._effort
        clipped = bool((abs(tau) > limit).any())
        if clipped and not self._clipping:
            j = int(np.argmax(abs(tau) / limit))
            unit = self.robot.effort_units()[j]
            self.warn(f"t = {t:.9g} s: joint {j + 1} ({self.robot.joint_names[j]}) effort {tau[j]:.6g} {unit} "
                      f"exceeds its limit {limit[j]:.6g} {unit}: clipped")
        np.clip(tau, -limit, limit, out=tau)
        self.values[self.saturated] = clipped
        self._clipping = clipped

    def advance(self, t, h):
        q_ref, _, _, q, _ = self._inputs
        self.law.advance(q_ref, q, h)
        if self._delay:
            self._head = (self._head + 1) % (self._delay + 1)
            self._samples += 1

    def internal_state(self):
        if self.law is None:
            return {"z": None}
        return {"z": [float(x) for x in self.law.z], "pending": self._pending.tolist(), "head": self._head,
                "samples": self._samples}

    def set_internal_state(self, state):
        if self.law is not None and state.get("z") is not None:
            self.law.z[:] = state["z"]
            self._pending[:] = state["pending"]
            self._head, self._samples = int(state["head"]), int(state["samples"])

    def continuous_state(self):
        return self.law.z.copy()

    def set_continuous_state(self, x):
        self.law.z[:] = x

    def derivative(self, t):
        return self.values[self.q_ref] - self.values[self.q]

"""Computed-torque control: tau = M(q) (qdd_ref + kd e_dot + kp e + ki z) + N(q, qd) + tau_f(qd).

e = q_ref - q, z = integral of e dt. With a perfect model every joint's error obeys
e_ddot + kd e_dot + kp e + ki z = 0 (z_dot = e). M includes the model's armature; tau_f is the
joints' damping and friction as the controller believes them
(:class:`~robofmu.components.plant.JointLosses`; none: no compensation). Losses the controller
does not know leave e_ddot + kd e_dot + kp e + ki z = (M^-1 tau_f)(q, qd), e.g. a steady error
tau_c / (M_jj kp) of a PD on a decoupled joint moving at constant speed.

The gains' rule
---------------
The gains are validated here and nowhere else (:data:`GAINS`, :func:`check_gains`): the robot
descriptions' gain sets, the controller block's parameters, :class:`ComputedTorque` and the step
responses of ``robofmu step`` all apply it. The rule is

    kp > 0,  kd > 0,  ki >= 0   (finite; kp in 1/s^2, kd in 1/s, ki in 1/s^3),

the necessary conditions for the error dynamics to be asymptotically stable: the PD's
s^2 + kd s + kp is Hurwitz exactly when kp > 0 and kd > 0 (kp = 0 leaves a joint with no
restoring force, kd = 0 an undamped oscillator that never settles), and the PID's
s^3 + kd s^2 + kp s + ki needs every coefficient positive (ki = 0 is the PD). No experiment uses
kp = 0: the unactuated load cases have no controller block at all (the plant's tau unwired at 0),
and ``gain_scale`` must be > 0, so the scaled gains keep the rule. The PID's remaining Hurwitz
bound, ki < kp kd, couples the three gains (each a separate FMU parameter, and ``gain_scale``
moves it) and is left to the design: every seed gain set satisfies it, and so do gains placed
at stable poles (``robofmu step --settling-time --overshoot``).
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .floats import FloatWriter
from .parameters import Parameter, ParameterError

if TYPE_CHECKING:
    from .plant import JointLosses
    from .robots.model import RobotModel

__all__ = ["GAINS", "check_gains", "ComputedTorque"]

#: The gains as declared parameters, their bounds the rule (see the module notes): kp > 0,
#: kd > 0, ki >= 0 (default 0: a PD). The controller block declares its ``kp``, ``kd``, ``ki``
#: from these, the robot descriptions read their gain sets by them.
GAINS = (
    Parameter("kp", "Real", "1/s2", "Proportional gain (every joint)", above=0.0),
    Parameter("kd", "Real", "1/s", "Derivative gain (every joint)", above=0.0),
    Parameter("ki", "Real", "1/s3", "Integral gain (every joint); 0 for PD", default=0.0, low=0.0),
)


def check_gains(kp: float, kd: float, ki: float = 0.0) -> tuple[float, float, float]:
    """The gains as floats, checked by the rule (:data:`GAINS`: kp > 0, kd > 0, ki >= 0, finite).

    Raises
    ------
    ParameterError
        Naming the first gain that breaks the rule: ``name`` is "kp", "kd" or "ki", ``problem``
        the parameter's message (``parameter kd = 0 1/s is invalid: must be > 0``).
    """
    checked = []
    for rule, value in zip(GAINS, (kp, kd, ki)):
        try:
            checked.append(rule.validate(value))
        except ValueError as exc:
            raise ParameterError(rule.name, str(exc)) from None
    return checked[0], checked[1], checked[2]


class ComputedTorque:
    """Computed-torque PD/PID law with its integral state.

    Parameters
    ----------
    robot : RobotModel
        The controller's model of the arm (its payload is what the controller believes).
    kp, kd, ki : float
        Gains (1/s^2, 1/s, 1/s^3), the same on every joint, by the rule of :func:`check_gains`
        (ParameterError naming the gain otherwise).
    losses : JointLosses, optional
        The joints' damping and friction the controller compensates (added to its effort at the
        measured qd); None or all zero: none.

    Notes
    -----
    The integral z is advanced by :meth:`advance` with the error held over the step
    (z += e h), matching the zero-order hold of a sampled controller. The torque is the model's
    inverse dynamics at the commanded acceleration u = qdd_ref + kd e_dot + kp e + ki z: one
    recursive Newton-Euler pass on a serial robot instead of M(q) (CRBA) and N(q, qd) apart.
    """

    def __init__(self, robot: RobotModel, kp: float, kd: float, ki: float = 0.0, losses: JointLosses | None = None):
        self.robot = robot
        self.losses = losses if losses is not None and losses.active else None
        self.kp, self.kd, self.ki = check_gains(kp, kd, ki)
        self.z = np.zeros(robot.n)
        self._command = np.zeros(robot.n)
        self._write_command, self._write_integral = FloatWriter(self._command), FloatWriter(self.z)

    def torque(self, q_ref, qd_ref, qdd_ref, q, qd) -> np.ndarray:
        """Joint torques/forces (N.m or N), shape (n,), at the current instant."""
        out = np.empty(self.robot.n)
        self.torque_into(np.asarray(q_ref, float), np.asarray(qd_ref, float), np.asarray(qdd_ref, float),
                         np.asarray(q, float), np.asarray(qd, float), out)
        return out

    def torque_into(self, q_ref, qd_ref, qdd_ref, q, qd, out: np.ndarray) -> None:
        """:meth:`torque` of arrays of shape (n,), written into ``out`` (no allocation of arrays).

        The command u = ((qdd_ref + kd e') + kp e) + ki z is computed in floats, element by element
        (n values: see :mod:`~robofmu.components.floats`)."""
        kp, kd, ki = self.kp, self.kd, self.ki
        u = [a + (b - c) * kd + (d - e) * kp for a, b, c, d, e in
             zip(qdd_ref.tolist(), qd_ref.tolist(), qd.tolist(), q_ref.tolist(), q.tolist())]
        if ki != 0.0:                                # PD: u + 0 z is u
            u = [v + z * ki for v, z in zip(u, self.z.tolist())]
        self._write_command(u)
        self.robot.inverse_dynamics_into(q, qd, self._command, out)    # M(q) u + N(q, qd) in one pass (RNEA)
        if self.losses is not None:
            out += self.losses.torque(qd)

    def advance(self, q_ref, q, h: float) -> None:
        """Integrate the error over a step of ``h`` seconds (error held at its current value):
        z + (q_ref - q) h, in floats."""
        self._write_integral([z + (a - b) * h for z, a, b in zip(self.z.tolist(), q_ref.tolist(), q.tolist())])

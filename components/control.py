"""Computed-torque control: tau = M(q) (qdd_ref + kd e_dot + kp e + ki z) + N(q, qd).

e = q_ref - q, z = integral of e dt. With a perfect model every joint's error obeys
e_ddot + kd e_dot + kp e + ki z = 0 (z_dot = e).
"""
from __future__ import annotations

import numpy as np

from .floats import FloatWriter
from .robots.model import RobotModel


class ComputedTorque:
    """Computed-torque PD/PID law with its integral state.

    Parameters
    ----------
    robot : RobotModel
        The controller's model of the arm (its payload is what the controller believes).
    kp, kd, ki : float
        Gains (1/s^2, 1/s, 1/s^3), >= 0, the same on every joint.

    Notes
    -----
    The integral z is advanced by :meth:`advance` with the error held over the step
    (z += e h), matching the zero-order hold of a sampled controller. The torque is the model's
    inverse dynamics at the commanded acceleration u = qdd_ref + kd e_dot + kp e + ki z: one
    recursive Newton-Euler pass on a serial robot instead of M(q) (CRBA) and N(q, qd) apart.
    """

    def __init__(self, robot: RobotModel, kp: float, kd: float, ki: float = 0.0):
        for name, value in (("kp", kp), ("kd", kd), ("ki", ki)):
            if not (np.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name}: gain must be finite and >= 0, got {value}")
        self.robot = robot
        self.kp, self.kd, self.ki = float(kp), float(kd), float(ki)
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

    def advance(self, q_ref, q, h: float) -> None:
        """Integrate the error over a step of ``h`` seconds (error held at its current value):
        z + (q_ref - q) h, in floats."""
        self._write_integral([z + (a - b) * h for z, a, b in zip(self.z.tolist(), q_ref.tolist(), q.tolist())])

"""The manipulator plant: M(q) qdd + C(q, qd) qd + g(q) = tau, integrated with tau held."""
from __future__ import annotations

import numpy as np

from .integrators import rk4
from .robots.model import RobotModel


class PlantDiverged(FloatingPointError):
    """The plant's state became non-finite."""


class Plant:
    """Forward dynamics of a robot, stepped with the input held over each step (zero-order hold).

    Parameters
    ----------
    robot : RobotModel
        The true arm (its own model; ``grip`` adds the payload to it).
    q0, qd0 : array_like, shape (n,)
        Initial joint positions (rad or m) and velocities (rad/s or m/s).
    payload_mass : float
        Point mass (kg) carried at the TCP while the gripper is closed, >= 0.
    max_substep : float
        Largest RK4 sub-step (s) inside a step, > 0.
    """

    def __init__(self, robot: RobotModel, q0, qd0, payload_mass: float = 0.0, max_substep: float = 1e-3):
        if not (np.isfinite(payload_mass) and payload_mass >= 0.0):
            raise ValueError(f"payload_mass: must be finite and >= 0 kg, got {payload_mass}")
        if not (np.isfinite(max_substep) and max_substep > 0.0):
            raise ValueError(f"max_substep: must be > 0 s, got {max_substep}")
        self.robot = robot
        self.n = robot.n
        self.payload_mass = float(payload_mass)
        self.max_substep = float(max_substep)
        self.x = np.concatenate([np.asarray(q0, float), np.asarray(qd0, float)])
        if self.x.shape != (2 * self.n,) or not np.all(np.isfinite(self.x)):
            raise ValueError(f"q0/qd0: need {self.n} finite values each")
        self.grip = False

    @property
    def q(self) -> np.ndarray:
        return self.x[: self.n]

    @property
    def qd(self) -> np.ndarray:
        return self.x[self.n:]

    def set_grip(self, closed: bool) -> None:
        """Close (carry the payload) or open the gripper."""
        self.grip = bool(closed)
        self.robot.set_payload(self.payload_mass if self.grip else 0.0)

    def energy(self) -> float:
        """Kinetic plus potential energy (J), payload included."""
        return self.robot.kinetic_energy(self.q, self.qd) + self.robot.potential_energy(self.q)

    def acceleration(self, x: np.ndarray, tau: np.ndarray, f_ext: np.ndarray | None = None) -> np.ndarray:
        """qdd at state ``x`` = (q, qd) under ``tau`` and, for a model that takes one (it has
        ``wrench_torque``), the end-effector wrench ``f_ext`` (None: no wrench argument)."""
        n = self.n
        if f_ext is None:
            return self.robot.forward_dynamics(x[:n], x[n:], tau)
        return self.robot.forward_dynamics(x[:n], x[n:], tau, f_ext)

    def step(self, tau: np.ndarray, h: float, t: float = 0.0, f_ext: np.ndarray | None = None) -> np.ndarray:
        """Advance the state by ``h`` seconds with ``tau`` (and the end-effector wrench ``f_ext``,
        where the model takes one) held; returns the new state (q, qd).

        Raises PlantDiverged naming the joint and the time if the state turns non-finite; the
        state is then left as it was before the step.
        """
        n = self.n

        def f(x):
            return np.concatenate([x[n:], self.acceleration(x, tau, f_ext)])

        with np.errstate(all="ignore"):
            x = rk4(f, self.x, h, self.max_substep)
        bad = np.flatnonzero(~np.isfinite(x))
        if bad.size:
            j = bad[0] % n + 1
            what = "q" if bad[0] < n else "qd"
            raise PlantDiverged(
                f"state {what}[{j}] became non-finite during the step from t = {t:.9g} s "
                f"to {t + h:.9g} s (joint {j}); last finite state q = {self.q.tolist()}, "
                f"qd = {self.qd.tolist()}")
        self.x = x
        return x

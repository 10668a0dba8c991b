"""The manipulator plant: M(q) qdd + C(q, qd) qd + g(q) = tau, integrated with tau held."""
from __future__ import annotations

import math

import numpy as np

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
        n, size = self.n, 2 * self.n
        # RK4's four stages, a row each: (q, qd, qdd) of the stage's state. k_i = (qd, qdd) is then
        # the row's last 2n values, a view: no copy of qd into k. Row 0's state is the work state.
        self._rows = np.zeros((4, 3 * n))
        self._states = [row[:size] for row in self._rows]
        self._slopes = self._rows[:, n:]                       # k1 .. k4, shape (4, 2n)
        self._parts = [(row[:n], row[n:size], row[size:]) for row in self._rows]     # q, qd, qdd
        self._weights = np.array([[1.0], [2.0], [2.0], [1.0]])  # k1 + 2 k2 + 2 k3 + k4
        self._weighted = np.zeros((4, size))
        self._total = np.zeros(size)
        self._ones = np.ones(size)

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

        Classical RK4 in ceil(h / max_substep) equal sub-steps, the arithmetic of
        :func:`~robofmu.components.integrators.rk4` element for element, in buffers of the plant's
        own (no allocation per step beyond the model's results).

        Raises PlantDiverged naming the joint and the time if the state turns non-finite; the
        state is then left as it was before the step.
        """
        substeps = max(1, math.ceil(h / self.max_substep - 1e-9))
        dt = h / substeps
        half, sixth = 0.5 * dt, dt / 6.0
        x, s2, s3, s4 = self._states
        (xq, xv, a1), (q2, v2, a2), (q3, v3, a3), (q4, v4, a4) = self._parts
        k1, k2, k3, _ = self._slopes
        weights, weighted, total = self._weights, self._weighted, self._total
        multiply, add = np.multiply, np.add
        if f_ext is None:
            dynamics = self.robot.forward_dynamics_into
        else:
            wrench = self.robot.forward_dynamics

            def dynamics(q, qd, tau, out):
                out[:] = wrench(q, qd, tau, f_ext)
        x[:] = self.x
        for _ in range(substeps):
            dynamics(xq, xv, tau, a1)                # k1 = (qd, qdd) at x
            multiply(k1, half, s2)
            add(x, s2, s2)                           # x + (dt/2) k1
            dynamics(q2, v2, tau, a2)
            multiply(k2, half, s3)
            add(x, s3, s3)
            dynamics(q3, v3, tau, a3)
            multiply(k3, dt, s4)
            add(x, s4, s4)
            dynamics(q4, v4, tau, a4)
            # (dt/6) (k1 + 2 k2 + 2 k3 + k4), summed left to right (a reduction over the rows
            # adds them in row order), then x += it: integrators.rk4's arithmetic
            multiply(self._slopes, weights, weighted)
            add.reduce(weighted, axis=0, out=total)
            multiply(total, sixth, total)
            add(x, total, x)
        if not math.isfinite(x.dot(self._ones)):      # nan and inf propagate through the sum
            bad = np.flatnonzero(~np.isfinite(x))
            if bad.size:
                n = self.n
                j = bad[0] % n + 1
                what = "q" if bad[0] < n else "qd"
                raise PlantDiverged(
                    f"state {what}[{j}] became non-finite during the step from t = {t:.9g} s "
                    f"to {t + h:.9g} s (joint {j}); last finite state q = {self.q.tolist()}, "
                    f"qd = {self.qd.tolist()}")
        self.x[:] = x
        return self.x

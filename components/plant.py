"""The manipulator plant: M(q) qdd + C(q, qd) qd + g(q) = tau, integrated with tau held."""
from __future__ import annotations

import math
from itertools import repeat
from operator import add, mul

import numpy as np

from .floats import FloatWriter
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
        # One stage state of RK4 at a time: (q, qd) in one array, its halves the model's inputs
        self._stage = np.zeros(2 * self.n)
        self._stage_q, self._stage_qd = self._stage[: self.n], self._stage[self.n:]
        self._write_stage = FloatWriter(self._stage)

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
        :func:`~robofmu.components.integrators.rk4` element for element, in floats (2n values:
        see :mod:`~robofmu.components.floats`); the model takes each stage's state from one
        buffer of the plant's.

        Raises PlantDiverged naming the input that drove it (:meth:`cause`), the joint and the
        time if the state turns non-finite; the state is then left as it was before the step.
        """
        substeps = max(1, math.ceil(h / self.max_substep - 1e-9))
        dt = h / substeps
        half, sixth, two = repeat(0.5 * dt), repeat(dt / 6.0), repeat(2.0)
        full = repeat(dt)
        n = self.n
        q, qd, write = self._stage_q, self._stage_qd, self._write_stage
        if f_ext is None:
            dynamics = self.robot.forward_dynamics_floats
        else:
            wrench = self.robot.forward_dynamics

            def dynamics(q, qd, tau):
                return wrench(q, qd, tau, f_ext).tolist()
        x = self.x.tolist()
        try:
            for _ in range(substeps):
                write(x)
                k1 = x[n:] + dynamics(q, qd, tau)                      # (qd, qdd) at x
                s = list(map(add, x, map(mul, k1, half)))              # x + (dt/2) k1
                write(s)
                k2 = s[n:] + dynamics(q, qd, tau)
                s = list(map(add, x, map(mul, k2, half)))
                write(s)
                k3 = s[n:] + dynamics(q, qd, tau)
                s = list(map(add, x, map(mul, k3, full)))
                write(s)
                k4 = s[n:] + dynamics(q, qd, tau)
                # x + (dt/6) (((k1 + 2 k2) + 2 k3) + k4), summed left to right: integrators.rk4's arithmetic
                total = map(add, map(add, map(add, k1, map(mul, k2, two)), map(mul, k3, two)), k4)
                x = list(map(add, x, map(mul, total, sixth)))
        except ValueError:          # a model that refuses a non-finite stage state (a parallel robot's q)
            if np.isfinite(self._stage).all():
                raise
            x = self._stage.tolist()
        if not math.isfinite(sum(x)):                  # nan and inf propagate through the sum
            bad = [k for k, value in enumerate(x) if not math.isfinite(value)]
            if bad:
                j = bad[0] % n + 1
                what = "q" if bad[0] < n else "qd"
                state = (f"state {what}[{j}] became non-finite during the step from t = {t:.9g} s "
                         f"to {t + h:.9g} s (joint {j} first); last finite state q = {self.q.tolist()}, "
                         f"qd = {self.qd.tolist()}")
                cause = self.cause(tau, f_ext)
                raise PlantDiverged(f"{cause}: the {state}" if cause else state)
        self.x[:] = x
        return self.x

    def cause(self, tau: np.ndarray, f_ext: np.ndarray | None = None) -> str:
        """The input (``tau[i]``, ``f_ext[k]``) that drives the joints hardest at the current
        state, if it outweighs the arm's own dynamics, in words (``input tau[2] = 1e+200 N.m is
        too large ...``), else "": what made a step's state non-finite.

        Each input's share of the joint accelerations is its column of M(q)^-1 (through J^T
        for a wrench component) times its value; the dynamics' own is M(q)^-1 (C qd + g). The
        shares are compared by their largest element's log10 (a share may overflow)."""
        robot, q, qd = self.robot, self.q, self.qd
        with np.errstate(all="ignore"):
            inverse = np.linalg.inv(robot.mass_matrix(q))
            drift = _log_size(inverse.dot(robot.nonlinear_effects(q, qd)))
            shares = [(_log_size(inverse[:, i]) + _log_size(tau[i]), f"tau[{i + 1}]", float(tau[i]), unit)
                      for i, unit in enumerate(robot.effort_units())]
            if f_ext is not None:
                for k, value in enumerate(np.asarray(f_ext, dtype=float)):
                    unit_wrench = np.zeros(len(f_ext))
                    unit_wrench[k] = 1.0
                    column = inverse.dot(robot.wrench_torque(q, unit_wrench))
                    shares.append((_log_size(column) + _log_size(value), f"f_ext[{k + 1}]", float(value), ""))
        size, name, value, unit = max(shares)
        if not size > drift:
            return ""
        return (f"input {name} = {value:.6g}{' ' + unit if unit else ''} is too large (it drives joint "
                f"accelerations of about 1e{size:.0f})")


def _log_size(values) -> float:
    """log10 of the largest |element| of ``values`` (a number or an array); -inf for zeros."""
    largest = float(np.max(np.abs(values)))
    return math.log10(largest) if largest > 0.0 else -math.inf

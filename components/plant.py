"""The manipulator plant: M(q) qdd + C(q, qd) qd + g(q) = tau - tau_f(qd), integrated with tau held.

The joints' losses (:class:`JointLosses`) are viscous damping b and Coulomb friction tau_c per
joint, the Coulomb part smoothed by a tanh of a stated velocity scale v_s:

    tau_f(qd) = b qd + tau_c tanh(qd / v_s)

tanh keeps the right-hand side smooth (no switch at qd = 0 that a fixed-step RK4 would step
across with the wrong sign, no event to locate): |tau_f - tau_c sign(qd)| < 1e-8 tau_c once
|qd| > 10 v_s, and at rest the friction is a stiff viscous term of slope tau_c / v_s. That slope
bounds RK4's stable sub-step, so :meth:`Plant.step` shortens its sub-steps where it must (see
there). The rotor inertia (armature) is the robot model's own (Pinocchio's ``model.armature``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import repeat
from operator import add, mul

import numpy as np

from .floats import FloatWriter
from .robots.model import RobotModel


class PlantDiverged(FloatingPointError):
    """The plant's state became non-finite."""


#: Default velocity scale v_s of the smooth Coulomb friction (rad/s or m/s): tanh(qd / v_s) is
#: within 1e-8 of sign(qd) beyond 0.1 rad/s, slow against a joint's motion, yet its slope at
#: rest (tau_c / v_s) costs few extra RK4 sub-steps on an arm's joints.
FRICTION_VELOCITY = 0.01

#: RK4 is stable for h lambda down to -2.78 on the real axis; the plant keeps h times the
#: losses' decay rate below this (a margin for M(q) changing within a step).
STABLE_RK4 = 2.0


@dataclass(frozen=True)
class JointLosses:
    """Viscous damping and smooth Coulomb friction at the joints.

    Attributes
    ----------
    damping : ndarray, shape (n,)
        b (N.m.s/rad or N.s/m), >= 0.
    friction : ndarray, shape (n,)
        tau_c (N.m or N), >= 0.
    velocity_scale : ndarray, shape (n,)
        v_s (rad/s or m/s), > 0.
    """

    damping: np.ndarray
    friction: np.ndarray
    velocity_scale: np.ndarray

    @classmethod
    def of(cls, damping, friction, velocity_scale=FRICTION_VELOCITY, n: int | None = None) -> "JointLosses":
        """Losses from per-joint values (a number: every joint); ValueError naming the coefficient
        by its block parameter (``parameter friction_velocity[2] = 0 is invalid: ...``)."""
        size = n if n is not None else len(np.atleast_1d(damping))
        values = {}
        for name, parameter, value, rule in (("damping", "damping", damping, ">= 0"),
                                             ("friction", "friction", friction, ">= 0"),
                                             ("velocity_scale", "friction_velocity", velocity_scale, "> 0")):
            array = np.broadcast_to(np.asarray(value, dtype=float), (size,)).copy()
            good = np.isfinite(array) & ((array > 0.0) if rule == "> 0" else (array >= 0.0))
            if not good.all():
                k = int(np.flatnonzero(~good)[0])
                raise ValueError(f"parameter {parameter}[{k + 1}] = {array[k]:g} is invalid: must be finite and {rule}")
            values[name] = array
        return cls(**values)

    @property
    def active(self) -> bool:
        """Whether any joint has damping or friction (else tau_f = 0 and nothing is computed)."""
        return bool(self.damping.any() or self.friction.any())

    def torque(self, qd) -> np.ndarray:
        """tau_f = b qd + tau_c tanh(qd / v_s) (N.m or N), shape (n,), at joint velocities ``qd``."""
        qd = np.asarray(qd, dtype=float)
        return self.damping * qd + self.friction * np.tanh(qd / self.velocity_scale)

    def slope(self) -> np.ndarray:
        """d tau_f / d qd at rest, its largest value: b + tau_c / v_s, shape (n,)."""
        return self.damping + self.friction / self.velocity_scale


def robot_losses(robot: RobotModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Damping, friction and armature per joint as the robot's data gives them (each (n,));
    zeros for a model that gives none (it has no ``joint_losses``)."""
    given = getattr(robot, "joint_losses", None)
    if given is None:
        return np.zeros(robot.n), np.zeros(robot.n), np.zeros(robot.n)
    return given()


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
    losses : JointLosses, optional
        The joints' damping and friction (default: none).
    """

    def __init__(self, robot: RobotModel, q0, qd0, payload_mass: float = 0.0, max_substep: float = 1e-3,
                 losses: JointLosses | None = None):
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
        self.losses = losses if losses is not None and losses.active else None
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
        """qdd at state ``x`` = (q, qd) under ``tau`` less the losses' tau_f(qd) and, for a model
        that takes one (it has ``wrench_torque``), the end-effector wrench ``f_ext`` (None: no
        wrench argument)."""
        n = self.n
        if self.losses is not None:
            tau = tau - self.losses.torque(x[n:])
        if f_ext is None:
            return self.robot.forward_dynamics(x[:n], x[n:], tau)
        return self.robot.forward_dynamics(x[:n], x[n:], tau, f_ext)

    def substeps(self, h: float) -> int:
        """RK4 sub-steps of a step of ``h`` s: ceil(h / max_substep), or more where the losses
        need them (:meth:`stiff_substeps`)."""
        return max(1, math.ceil(h / self.max_substep - 1e-9), self.stiff_substeps(h))

    def step(self, tau: np.ndarray, h: float, t: float = 0.0, f_ext: np.ndarray | None = None,
             substeps: int | None = None) -> np.ndarray:
        """Advance the state by ``h`` seconds with ``tau`` (and the end-effector wrench ``f_ext``,
        where the model takes one) held; returns the new state (q, qd).

        Classical RK4 in ceil(h / max_substep) equal sub-steps (more where the losses are stiff:
        :meth:`stiff_substeps`), the arithmetic of
        :func:`~robofmu.components.integrators.rk4` element for element, in floats (2n values:
        see :mod:`~robofmu.components.floats`); the model takes each stage's state from one
        buffer of the plant's.

        Raises PlantDiverged naming the input that drove it (:meth:`cause`), the joint and the
        time if the state turns non-finite; the state is then left as it was before the step.
        ``substeps``: :meth:`substeps` of ``h`` if the caller has it already.
        """
        if substeps is None:
            substeps = self.substeps(h)
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
        if self.losses is not None:
            rigid, torque = dynamics, self.losses.torque

            def dynamics(q, qd, tau):
                return rigid(q, qd, tau - torque(qd))
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

    def stiff_substeps(self, h: float) -> int:
        """Sub-steps a step of ``h`` s needs for the losses alone: the joints' losses decay at
        rates up to lambda_j = (b_j + tau_c,j / v_s,j) (M(q)^-1)_jj (1/s) at the current q, and RK4
        stays stable while h lambda <= :data:`STABLE_RK4`; 1 without losses."""
        if self.losses is None:
            return 1
        with np.errstate(all="ignore"):
            rate = float(np.max(self.losses.slope() * np.diag(np.linalg.inv(self.robot.mass_matrix(self.q)))))
        return max(1, math.ceil(h * rate / STABLE_RK4 - 1e-9)) if math.isfinite(rate) else 1

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
            drift = robot.nonlinear_effects(q, qd)
            drift = _log_size(inverse.dot(drift if self.losses is None else drift + self.losses.torque(qd)))
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

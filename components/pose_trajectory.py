"""Pose profiles: a frame's position and orientation on one time law.

:class:`PoseLine`: the origin on a straight line and the orientation by slerp along the shortest
rotation, on an LSPB time law of a given duration or at minimum time under speed and
acceleration limits (a trapezoid). :class:`PoseWaypoints`: through several poses, one
:class:`PoseLine` per leg, with pauses between.

Both have ``duration``, ``breakpoints`` and ``evaluate(t, snap=True)`` returning six arrays:
position (3,), velocity (3,), acceleration (3,), quaternion (4,) in the order (x, y, z, w)
(:mod:`.orientation`), angular velocity (3,) and angular acceleration (3,), both in the world
frame. They rest at their start before 0 and at their end from ``duration`` on.
"""
from __future__ import annotations

from bisect import bisect_right
import math

import numpy as np
import pinocchio as pin

from .orientation import UNIT_TOLERANCE, rotation_of
from .profile import Profile, finite, finite_vector, positive, shown, snap_to
from .time_law import LSPBLaw, TrapezoidLaw, schedule

__all__ = ["POSE_COLUMNS", "PoseLine", "PoseWaypoints"]

#: A pose waypoint's columns: the frame's origin (m, world) and its orientation (x, y, z, w).
POSE_COLUMNS = ("x", "y", "z", "qx", "qy", "qz", "qw")
#: The limits of a minimum-time pose move, with their units.
LIMITS = {"v_max": "m/s", "a_max": "m/s2", "omega_max": "rad/s", "alpha_max": "rad/s2"}


class _PoseProfile(Profile):
    dim = 3

    def evaluate(self, t: float, snap: bool = True):
        """Position (m), velocity (m/s), acceleration (m/s^2), quaternion (x, y, z, w), angular
        velocity (rad/s) and angular acceleration (rad/s^2, both world frame) at time ``t`` (s):
        new arrays of shapes (3,), (3,), (3,), (4,), (3,), (3,).

        Before its start the pose rests at its start, after its end at its end. With ``snap``,
        times within 1e-9 s of a breakpoint are evaluated at the breakpoint (sampled use);
        without, the exact branch at ``t``.
        """
        x, xd, xdd, omega, omegad = (np.empty(3) for _ in range(5))
        quaternion = np.empty(4)
        self.evaluate_into(t, x, xd, xdd, quaternion, omega, omegad, snap)
        return x, xd, xdd, quaternion, omega, omegad


class PoseLine(_PoseProfile):
    """A task-space pose move: the frame origin on a straight line, the orientation by slerp
    along the shortest rotation, both driven by one time law.

    One scalar s(t) runs from 0 to 1, at rest at both ends: by LSPB in ``duration`` (cruise speed
    ``cruise_factor`` x the mean speed), or, given the four limits instead, at minimum time on a
    trapezoid (:class:`~.time_law.TrapezoidLaw`) whose rate and acceleration bounds are the
    tightest the limits allow: sd <= min(v_max / |d|, omega_max / |r|), |sdd| <= min(a_max / |d|,
    alpha_max / |r|). With d = ``displacement``, r = ``rotation`` (in the start frame) and R0 the
    start orientation:

        p(t) = start + s d,          pd = sd d,           pdd = sdd d,
        R(t) = R0 Exp(s r),          omega = sd R0 r,     omegad = sdd R0 r,

    so R runs from R0 to R1 = R0 Exp(r) about a fixed axis: slerp from R0 to R1. omega and
    omegad are in the world frame (dR/dt = [omega]x R). The quaternion (x, y, z, w) is
    q(t) = q0 (x) (u sin(s |r| / 2), cos(s |r| / 2)), u = r / |r|: it starts at ``start_quaternion``
    (normalised) and never changes sign. Before 0 the pose rests at its start, from
    ``duration`` on at its end.

    Parameters
    ----------
    start : array_like, shape (3,)
        Start position of the frame origin (m), world frame.
    displacement : array_like, shape (3,)
        Straight-line displacement of the origin (m), world frame; may be zero.
    start_quaternion : array_like, shape (4,)
        Start orientation (frame relative to world) as a unit quaternion (x, y, z, w), scalar
        last (scipy's ``Rotation.as_quat``, Pinocchio's ``Quaternion.coeffs()``); its norm must
        be within 1e-6 of 1 (it is normalised here).
    rotation : array_like, shape (3,)
        Rotation vector (axis times angle, rad) in the start frame (the tool's own axes): the end
        orientation is R0 Exp(rotation). Its angle must be <= pi (the shortest rotation); may be
        zero.
    duration : float, optional
        > 0 (s): the LSPB time law. Give either it or the four limits.
    cruise_factor : float
        In (1, 2] (LSPB only).
    v_max, a_max : float, optional
        Speed (m/s) and acceleration (m/s^2) limits of the origin along the line, > 0.
    omega_max, alpha_max : float, optional
        Angular speed (rad/s) and acceleration (rad/s^2) limits, > 0.

    Raises
    ------
    ValueError
        Naming the offending argument.
    """

    def __init__(self, start, displacement, start_quaternion, rotation, duration: float | None = None,
                 cruise_factor: float = 1.5, *, v_max: float | None = None, a_max: float | None = None,
                 omega_max: float | None = None, alpha_max: float | None = None):
        self.start = finite_vector(start, "start", 3)
        self.displacement = finite_vector(displacement, "displacement", 3)
        q0 = finite_vector(start_quaternion, "start_quaternion", 4)
        norm = float(np.linalg.norm(q0))
        if not abs(norm - 1.0) <= UNIT_TOLERANCE:
            raise ValueError(f"start_quaternion: must be a unit quaternion (x, y, z, w) (norm within "
                             f"{shown(UNIT_TOLERANCE)} of 1), got {q0.tolist()} of norm {shown(norm)}")
        self.start_quaternion = q0 / norm
        self.rotation = finite_vector(rotation, "rotation", 3)
        self.angle = float(np.linalg.norm(self.rotation))
        if self.angle > math.pi + 1e-12:          # pi itself, within rounding of the vector's norm
            shorter = self.rotation * (1.0 - 2.0 * math.pi / self.angle) if self.angle < 2.0 * math.pi else None
            hint = f" (here {[round(v, 6) for v in shorter.tolist()]})" if shorter is not None else ""
            raise ValueError(f"rotation: its angle |rotation| = {shown(self.angle)} rad exceeds pi; give the shortest "
                             f"rotation to the same end orientation, angle <= pi{hint}")
        limits = {"v_max": v_max, "a_max": a_max, "omega_max": omega_max, "alpha_max": alpha_max}
        self.cruise_factor = float(cruise_factor)
        if duration is not None:
            given = [k for k, v in limits.items() if v is not None]
            if given:
                raise ValueError(f"give either duration (an LSPB time law) or the limits {', '.join(LIMITS)} "
                                 f"(minimum time), not both: got duration and {', '.join(given)}")
            self.time_law = LSPBLaw(duration, cruise_factor)
        else:
            self.time_law = self._minimum_time(limits)
        self.duration = self.time_law.duration
        self.breakpoints = self.time_law.breakpoints
        self._break_list = self.breakpoints.tolist()

        # orientation constants: q0 (x) (u sin h, cos h) = (A sin h + v0 cos h, w0 cos h + B sin h)
        v0, w0 = self.start_quaternion[:3], float(self.start_quaternion[3])
        u = self.rotation / self.angle if self.angle > 0.0 else np.zeros(3)
        self._v0, self._w0 = tuple(v0.tolist()), w0
        self._a = tuple((w0 * u + np.cross(v0, u)).tolist())
        self._b = -float(v0 @ u)
        r = self.rotation                         # R0 r = r + 2 w0 (v0 x r) + 2 v0 x (v0 x r)
        c = np.cross(v0, r)
        self.world_rotation = r + 2.0 * w0 * c + 2.0 * np.cross(v0, c)
        with np.errstate(all="ignore"):
            self.end = self.start + self.displacement
        self.end_quaternion = np.empty(4)
        self._quaternion_into(1.0, self.end_quaternion)
        self._check_finite()

    def _minimum_time(self, limits: dict) -> TrapezoidLaw:
        """The trapezoid time law of s under the four limits (ValueError naming them)."""
        missing = [k for k, v in limits.items() if v is None]
        if missing:
            raise ValueError(f"give duration (an LSPB time law) or all four limits {', '.join(LIMITS)} "
                             f"(minimum time); missing: {', '.join(missing)}")
        bounds = {k: positive(v, k, LIMITS[k]) for k, v in limits.items()}
        distance = float(np.linalg.norm(self.displacement))
        if distance == 0.0 and self.angle == 0.0:
            raise ValueError("displacement and rotation are both zero: a move at minimum time needs something "
                             "to move (give duration to hold a pose for a time)")
        with np.errstate(all="ignore"):
            rate = min(bounds["v_max"] / distance if distance else math.inf,
                       bounds["omega_max"] / self.angle if self.angle else math.inf)
            acceleration = min(bounds["a_max"] / distance if distance else math.inf,
                               bounds["alpha_max"] / self.angle if self.angle else math.inf)
        law = TrapezoidLaw(1.0, rate, acceleration)
        given = ", ".join(f"{k} = {shown(v)} {LIMITS[k]}" for k, v in bounds.items())
        if not law.finite or not law.duration > 0.0:
            raise ValueError(f"{given}: a move of {shown(distance)} m and {shown(self.angle)} rad would take "
                             f"{shown(law.duration)} s, not a positive finite time; give limits nearer the move's size")
        return law

    def _check_finite(self) -> None:
        """Refuse parameters whose reference overflows (ValueError naming them): the end point
        (start, displacement), the peak speeds and accelerations (displacement, rotation with the
        time law)."""
        if not finite(self.end):
            k = int(np.flatnonzero(~np.isfinite(self.end))[0])
            raise ValueError(f"start[{k + 1}] = {shown(self.start[k])} and displacement[{k + 1}] = "
                             f"{shown(self.displacement[k])} m: the end point's coordinate {k + 1} would be "
                             f"{shown(self.end[k])} (beyond the largest float)")
        sd, sdd = self.time_law.peak_rate, self.time_law.peak_acceleration
        with np.errstate(all="ignore"):
            peaks = {"displacement": (self.displacement, "m/s", "m/s2"),
                     "rotation": (self.world_rotation, "rad/s", "rad/s2")}
            for name, (vector, v_unit, a_unit) in peaks.items():
                length = float(np.linalg.norm(vector))
                if not finite(length * sd, length * sdd):
                    raise ValueError(f"{name} and duration = {shown(self.duration)} s: the peak speed would be "
                                     f"{shown(length * sd)} {v_unit} and acceleration {shown(length * sdd)} {a_unit} "
                                     f"(not finite); give a smaller {name} or a longer duration")

    def path(self, t: float) -> tuple[float, float, float]:
        """s, sd (1/s), sdd (1/s^2) at ``t``: the time law from 0 to 1, at rest outside."""
        return self.time_law.path(t)

    def _quaternion_into(self, s: float, quaternion: np.ndarray) -> None:
        """q0 (x) (u sin(s |r| / 2), cos(s |r| / 2)) written into ``quaternion`` (x, y, z, w)."""
        h = 0.5 * s * self.angle
        sin_h, cos_h = math.sin(h), math.cos(h)
        (ax, ay, az), (vx, vy, vz) = self._a, self._v0
        quaternion[0] = ax * sin_h + vx * cos_h
        quaternion[1] = ay * sin_h + vy * cos_h
        quaternion[2] = az * sin_h + vz * cos_h
        quaternion[3] = self._w0 * cos_h + self._b * sin_h

    def evaluate_into(self, t: float, x: np.ndarray, xd: np.ndarray, xdd: np.ndarray,
                      quaternion: np.ndarray, omega: np.ndarray, omegad: np.ndarray,
                      snap: bool = True) -> None:
        """:meth:`evaluate` written into ``x``, ``xd``, ``xdd`` (shape (3,)), ``quaternion``
        (shape (4,)), ``omega``, ``omegad`` (shape (3,)); no allocation."""
        if snap:
            t = snap_to(self._break_list, t)
        if t < 0.0 or t >= self.duration:
            x[:] = self.start if t < 0.0 else self.end
            quaternion[:] = self.start_quaternion if t < 0.0 else self.end_quaternion
            xd[:], xdd[:], omega[:], omegad[:] = 0.0, 0.0, 0.0, 0.0
            return
        s, sd, sdd = self.time_law.path(t)
        d, w = self.displacement, self.world_rotation
        np.multiply(d, s, out=x)
        np.add(self.start, x, out=x)                 # start + s d
        np.multiply(d, sd, out=xd)
        np.multiply(d, sdd, out=xdd)
        self._quaternion_into(s, quaternion)
        np.multiply(w, sd, out=omega)
        np.multiply(w, sdd, out=omegad)


class PoseWaypoints(_PoseProfile):
    """Through several poses, one :class:`PoseLine` per leg (LSPB, at rest at each pose), with a
    pause after every move but the last.

    Leg i runs from pose i to pose i + 1: the origin on the straight line between them, the
    orientation by slerp along the shortest rotation log(R_i^T R_i+1) (angle <= pi). Each leg
    starts from the quaternion the leg before ended at, so the quaternion on the ports never
    changes sign, whichever signs the rows give.

    Parameters
    ----------
    waypoints : array_like, shape (k + 1, 7)
        One pose per row: the origin x, y, z (m, world) and a unit quaternion qx, qy, qz, qw
        (frame to world, :data:`POSE_COLUMNS`); each quaternion's norm must be within 1e-6 of 1.
    durations : array_like, shape (k,)
        Each move's duration (s), > 0.
    pause : float
        Rest between two moves (s), >= 0.
    cruise_factor : float
        Cruise speed over each move's mean speed, in (1, 2].

    Raises
    ------
    ValueError
        Naming the argument, and the rows or move at fault.
    """

    def __init__(self, waypoints, durations, pause: float = 0.0, cruise_factor: float = 1.5):
        w = np.asarray(waypoints, dtype=float)
        columns = len(POSE_COLUMNS)
        if w.ndim != 2 or w.shape[0] < 2 or w.shape[1] != columns:
            raise ValueError(f"waypoints: need at least two poses of {columns} values ({', '.join(POSE_COLUMNS)}), "
                             f"got shape {w.shape}")
        if not np.all(np.isfinite(w)):
            raise ValueError("waypoints: every value must be finite")
        rotations = []
        for i, row in enumerate(w, start=1):
            try:
                rotations.append(rotation_of(row[3:]))
            except ValueError as exc:
                raise ValueError(f"waypoints: row {i}: {exc}") from None
        moves = w.shape[0] - 1
        timeline, self.duration = schedule(durations, pause, moves)
        if not (1.0 < cruise_factor <= 2.0):
            raise ValueError(f"cruise_factor: must lie in (1, 2], got {cruise_factor}")
        self.waypoints, self.durations = w, np.asarray(durations, dtype=float)
        self.pause, self.cruise_factor = float(pause), float(cruise_factor)
        self.legs = []
        quaternion = w[0, 3:] / np.linalg.norm(w[0, 3:])
        for i in range(moves):
            rotation = pin.log3(rotations[i].T @ rotations[i + 1])      # the shortest, in the leg's start frame
            with np.errstate(all="ignore"):
                displacement = w[i + 1, :3] - w[i, :3]
            try:
                leg = PoseLine(w[i, :3], displacement, quaternion, rotation, float(self.durations[i]),
                               self.cruise_factor)
            except ValueError as exc:
                raise ValueError(f"waypoints rows {i + 1} to {i + 2}, durations[{i + 1}] = "
                                 f"{shown(self.durations[i])} s (move {i + 1}): {exc}") from None
            self.legs.append(leg)
            quaternion = leg.end_quaternion
        # each segment evaluates a leg at (t - offset): a pause, its move's leg past that leg's end
        self._segments = []
        for start, _, move in timeline:
            leg = self.legs[move - 1] if move else self._segments[-1][0]
            self._segments.append((leg, start if move else self._segments[-1][1]))
        self._start_list = [start for start, _, _ in timeline]
        leg_breaks = [self.legs[move - 1].breakpoints + start for start, _, move in timeline if move]
        self.breakpoints = np.unique(np.concatenate([self._start_list, [self.duration], *leg_breaks]))
        self._break_list = self.breakpoints.tolist()
        self.start, self.start_quaternion = self.legs[0].start, self.legs[0].start_quaternion
        self.end, self.end_quaternion = self.legs[-1].end, self.legs[-1].end_quaternion

    def evaluate_into(self, t: float, x: np.ndarray, xd: np.ndarray, xdd: np.ndarray,
                      quaternion: np.ndarray, omega: np.ndarray, omegad: np.ndarray,
                      snap: bool = True) -> None:
        """:meth:`evaluate` written into ``x``, ``xd``, ``xdd`` (shape (3,)), ``quaternion``
        (shape (4,)), ``omega``, ``omegad`` (shape (3,)); no allocation."""
        if snap:
            t = snap_to(self._break_list, t)
        if t >= self.duration:
            self.legs[-1].evaluate_into(math.inf, x, xd, xdd, quaternion, omega, omegad, False)
            return
        leg, offset = self._segments[max(bisect_right(self._start_list, t) - 1, 0)]
        leg.evaluate_into(t - offset, x, xd, xdd, quaternion, omega, omegad, False)

"""Trajectory profiles: LSPB through waypoints, a straight line with a trapezoidal speed profile,
a synchronized minimum-time bang-bang in joint space and a task-space circle run once with an
LSPB phase, on the time laws of :mod:`.time_law`; how a profile's time-law parameters scale
when it runs slower (:func:`slowed`). Pose profiles (orientation too) are in
:mod:`.pose_trajectory`, waypoint tables in :mod:`.waypoint_table`.

Every profile has ``dim``, ``duration``, ``breakpoints`` (the instants where its acceleration
jumps) and ``evaluate(t, snap=True) -> (x, xd, xdd)``; it rests at its start before 0 and at its
end from ``duration`` on. At a breakpoint the value is the one that holds after it (the start
instant already accelerates; the end instant is at rest), as a sampled block holds it.
"""
from __future__ import annotations

from bisect import bisect_right
from dataclasses import dataclass
import math

import numpy as np

from .profile import Profile, finite, finite_vector, positive, shown, snap_to
from .time_law import LSPBPiece, TrapezoidLaw, schedule


#: The profiles' time-law parameters and how each changes when the same path runs r times slower
#: (t -> r t divides every rate by r and every acceleration by r^2): the power of r it takes.
TIME_SCALING = {"duration": 1, "durations": 1, "v_max": -1, "omega_max": -1, "a_max": -2, "alpha_max": -2}


def slowed(parameters: dict, ratio: float, digits: int = 2) -> dict:
    """The time-law parameters of a profile (the keys of :data:`TIME_SCALING` it has) for the same
    path ``ratio`` times slower, each rounded to ``digits`` significant digits towards slower
    (durations up, limits down), lists element by element.

    Parameters
    ----------
    parameters : dict
        A profile's parameters as its ``[trajectory]`` table gives them.
    ratio : float
        > 0: the factor the path's time law is stretched by.

    Returns
    -------
    dict
        Only the scaled keys, with their new values.
    """
    def scaled(value, power):
        value = float(value) * ratio ** power
        unit = 10.0 ** (math.floor(math.log10(value)) - digits + 1)
        steps = math.ceil(value / unit - 1e-9) if power > 0 else math.floor(value / unit + 1e-9)
        return float(f"{steps * unit:.{digits}g}")

    return {key: [scaled(v, TIME_SCALING[key]) for v in value] if isinstance(value, list)
            else scaled(value, TIME_SCALING[key])
            for key, value in parameters.items() if key in TIME_SCALING}


@dataclass(frozen=True)
class Segment:
    start: float   # s
    end: float     # s
    x0: np.ndarray
    x1: np.ndarray
    move: int      # 1-based move number; 0 for a pause


class WaypointTrajectory(Profile):
    """Moves through waypoints, one LSPB move per leg, with a pause after every move but the last.

    Parameters
    ----------
    waypoints : array_like, shape (k + 1, m)
        Points to pass through, at rest at each.
    durations : array_like, shape (k,)
        Duration of each move (s), each > 0.
    pause : float
        Rest between two moves (s), >= 0.
    cruise_factor : float
        Cruise speed over each move's mean speed, in (1, 2].
    grip_close_after_move, grip_open_after_move : int
        The gripper closes at the end of this move (1-based) and opens at the end of that one;
        0 means never.
    start : array_like, shape (m,), optional
        The first point, before the rows: the path runs from ``start`` through every row of
        ``waypoints`` (shape (k, m), one row per move). None: the first row is the start.
    relative : bool
        With ``start``: the rows are offsets from ``start`` (the points start + row).

    Raises
    ------
    ValueError
        Naming the offending argument.
    """

    def __init__(self, waypoints, durations, pause: float = 0.0, cruise_factor: float = 1.5,
                 grip_close_after_move: int = 0, grip_open_after_move: int = 0, start=None,
                 relative: bool = False):
        w = np.asarray(waypoints, dtype=float)
        self.has_start = start is not None
        least = 1 if self.has_start else 2
        if w.ndim != 2 or w.shape[0] < least:
            raise ValueError(f"waypoints: need at least {least} point{'s' * (least > 1)} of equal dimension"
                             f"{' after the start' if self.has_start else ''}, got shape {w.shape}")
        if not np.all(np.isfinite(w)):
            raise ValueError("waypoints: every coordinate must be finite")
        if relative and not self.has_start:
            raise ValueError("relative: offsets need a start point (start)")
        if self.has_start:
            first = finite_vector(start, "start", w.shape[1])
            with np.errstate(all="ignore"):
                w = np.vstack([first, first + w if relative else w])
            if not np.all(np.isfinite(w)):
                row, axis = (int(v) for v in np.argwhere(~np.isfinite(w))[0])
                raise ValueError(f"start[{axis + 1}] = {shown(first[axis])} and waypoints row {row}: the point start + "
                                 f"offset is {shown(w[row, axis])} in coordinate {axis + 1} (beyond the largest float)")
        k = w.shape[0] - 1
        timeline, t = schedule(durations, pause, k)
        if not (1.0 < cruise_factor <= 2.0):
            raise ValueError(f"cruise_factor: must lie in (1, 2], got {cruise_factor}")
        for name, move in (("grip_close_after_move", grip_close_after_move),
                           ("grip_open_after_move", grip_open_after_move)):
            if not (0 <= move <= k):
                raise ValueError(f"{name}: must be 0 (never) or a move number 1..{k}, got {move}")
        if grip_open_after_move and not grip_close_after_move:
            raise ValueError(f"grip_open_after_move = {grip_open_after_move}: the gripper never closes "
                             "(grip_close_after_move = 0)")
        if grip_close_after_move and grip_open_after_move and grip_open_after_move <= grip_close_after_move:
            raise ValueError(f"grip_open_after_move = {grip_open_after_move} must come after "
                             f"grip_close_after_move = {grip_close_after_move}")
        self.waypoints = w
        self.durations = np.asarray(durations, dtype=float)
        self.pause = float(pause)
        self.cruise_factor = float(cruise_factor)
        self.dim = w.shape[1]
        segments = []
        for start, end, move in timeline:
            row = move or segments[-1].move          # a pause rests where the move before it ended
            segments.append(Segment(start, end, w[row - 1] if move else w[row], w[row], move))
        self.segments = segments
        self.duration = t
        self.move_ends = np.array([s.end for s in segments if s.move])
        self._starts = np.array([s.start for s in segments])
        self.grip_close_time = self.move_ends[grip_close_after_move - 1] if grip_close_after_move else np.inf
        self.grip_open_time = self.move_ends[grip_open_after_move - 1] if grip_open_after_move else np.inf
        moves = [s for s in segments if s.move]
        blends = [(s.end - s.start) * (1.0 - 1.0 / self.cruise_factor) for s in moves]
        self.breakpoints = np.unique(np.concatenate(
            [self._starts, [self.duration], [s.start + b for s, b in zip(moves, blends)],
             [s.end - b for s, b in zip(moves, blends)]]))
        self._break_list = self.breakpoints.tolist()      # searched by bisect at every evaluation
        self._start_list = self._starts.tolist()
        self._pieces = [LSPBPiece(s.x0, s.x1, s.end - s.start, self.cruise_factor) if s.move else None
                        for s in segments]
        for s, piece in zip(segments, self._pieces):
            problem = piece.overflow() if piece is not None else None
            if problem is not None:
                raise ValueError(self._overflow_message(s, piece, *problem))

    def _overflow_message(self, s: Segment, piece: LSPBPiece, what: str, axis: int, value: float) -> str:
        """Why move ``s`` overflows, naming the parameters (waypoints rows, durations)."""
        i = s.move
        row = i - 1 if self.has_start else i          # the row the move starts from (0: the start)
        pair, span = ((f"rows {row} and {row + 1}", f"waypoints rows {row} to {row + 1}") if row else
                      ("the start and row 1", "the start to waypoints row 1"))
        if what == "distance":
            return (f"waypoints: {pair} are too far apart: coordinate {axis + 1} goes from "
                    f"{shown(s.x0[axis])} to {shown(s.x1[axis])}, a change of {shown(value)} (beyond the largest float); "
                    "bring the waypoints closer")
        return (f"durations: move {i} takes {shown(s.end - s.start)} s, too short for {span} "
                f"(coordinate {axis + 1} changes by {shown(piece.dx[axis])}): its {what} would be {shown(value)} "
                f"(not finite); give move {i} more time (durations) or bring the waypoints closer")

    def snap(self, t: float) -> float:
        """``t`` moved onto a breakpoint within 1e-9 s (see :func:`snap_to`)."""
        return snap_to(self._break_list, t)

    def evaluate_into(self, t: float, x: np.ndarray, xd: np.ndarray, xdd: np.ndarray,
                      snap: bool = True) -> None:
        """:meth:`evaluate` written into ``x``, ``xd``, ``xdd`` (each shape (m,); no allocation)."""
        if snap:
            t = snap_to(self._break_list, t)
        if t >= self.duration:
            x[:], xd[:], xdd[:] = self.waypoints[-1], 0.0, 0.0
            return
        i = max(bisect_right(self._start_list, t) - 1, 0)
        piece = self._pieces[i]
        if piece is None:
            x[:], xd[:], xdd[:] = self.segments[i].x0, 0.0, 0.0
            return
        piece.evaluate_into(t - self._start_list[i], x, xd, xdd)

    def grip(self, t: float, snap: bool = True) -> bool:
        """Gripper closed at time ``t``? Closing and opening take effect at their instants
        (within 1e-9 s, so that communication points that land on them by rounding count;
        ``snap=False``: ``t`` is snapped already)."""
        if snap:
            t = snap_to(self._break_list, t)
        closed = t >= self.grip_close_time
        opened = t >= self.grip_open_time and self.grip_open_time > self.grip_close_time
        return bool(closed and not opened)


class StraightLine(Profile):
    """A straight line at minimum time under speed and acceleration limits (trapezoidal speed).

    The arc length s(t) runs from 0 to ``length`` along ``direction`` by :class:`TrapezoidLaw`:
    ramps at a_max up to v_max and down, or a triangle at a_max for a line too short to reach
    v_max.

    Parameters
    ----------
    start : array_like, shape (m,)
        Start point (m).
    direction : array_like, shape (m,)
        Direction of travel; normalized here (must not be zero).
    length : float
        Path length (m), > 0.
    v_max, a_max : float
        Speed (m/s) and acceleration (m/s^2) limits along the path, > 0.
    """

    @classmethod
    def by_displacement(cls, start, displacement, v_max: float, a_max: float) -> "StraightLine":
        """The line from ``start`` by ``displacement`` (shape (m,), the start's unit): direction
        displacement / |displacement|, length |displacement|; ValueError naming ``displacement``
        if it is zero, not finite or longer than the largest float."""
        start = finite_vector(start, "start")
        d = finite_vector(displacement, "displacement", len(start))
        if not d.any():
            raise ValueError("displacement: must not be the zero vector")
        biggest = float(np.max(np.abs(d)))
        with np.errstate(all="ignore"):
            length = biggest * float(np.linalg.norm(d / biggest))     # no overflow of the squares
        if not math.isfinite(length):
            raise ValueError(f"displacement: its length is beyond the largest float ({d.tolist()})")
        return cls(start, d, length, v_max, a_max)

    def __init__(self, start, direction, length: float, v_max: float, a_max: float):
        self.start = finite_vector(start, "start")
        d = finite_vector(direction, "direction", len(self.start))
        if not d.any():
            raise ValueError("direction: must not be the zero vector")
        with np.errstate(all="ignore"):
            norm = float(np.linalg.norm(d))
            if not (math.isfinite(norm) and norm > 1e-150):     # its square overflowed or underflowed
                d = d / np.max(np.abs(d))
                norm = float(np.linalg.norm(d))
        self.direction = d / norm
        self.length = positive(length, "length", "m")
        self.v_max = positive(v_max, "v_max", "m/s")
        self.a_max = positive(a_max, "a_max", "m/s2")
        self.dim = len(self.start)
        self.law = TrapezoidLaw(self.length, self.v_max, self.a_max)
        self.t1, self.duration, self.v_peak = self.law.t1, self.law.duration, self.law.peak_rate
        limits = f"length = {shown(self.length)} m, v_max = {shown(self.v_max)} m/s, a_max = {shown(self.a_max)} m/s2"
        if not self.law.finite:
            raise ValueError(f"{limits}: the line would take {shown(self.duration)} s (ramps of {shown(self.t1)} s, "
                             f"peak speed {shown(self.v_peak)} m/s), not finite; give a shorter length or larger "
                             "v_max and a_max")
        with np.errstate(all="ignore"):
            self.end = self.start + self.length * self.direction
        if not finite(self.end):
            k = int(np.flatnonzero(~np.isfinite(self.end))[0])
            raise ValueError(f"start[{k + 1}] = {shown(self.start[k])} and length = {shown(self.length)} m: the end "
                             f"point's coordinate {k + 1} would be {shown(self.end[k])} (beyond the largest float)")
        self.breakpoints = self.law.breakpoints
        self._break_list = self.breakpoints.tolist()

    def path(self, t: float) -> tuple[float, float, float]:
        """Arc length (m), speed (m/s) and acceleration (m/s^2) along the line at ``t``."""
        return self.law.path(t)

    def evaluate_into(self, t: float, x: np.ndarray, xd: np.ndarray, xdd: np.ndarray,
                      snap: bool = True) -> None:
        """Position (m), velocity (m/s), acceleration (m/s^2) at ``t`` written into ``x``, ``xd``,
        ``xdd`` (each shape (m,); no allocation)."""
        if snap:
            t = snap_to(self._break_list, t)
        s, v, a = self.path(t)
        d = self.direction
        np.multiply(d, s, out=x)
        np.add(self.start, x, out=x)                 # start + s d
        np.multiply(d, v, out=xd)
        np.multiply(d, a, out=xdd)


class SynchronizedBangBang(Profile):
    """Minimum-time bang-bang in joint space, every joint finishing at the same time.

    Joint j alone needs T_min,j = 2 sqrt(|dq_j| / a_max,j) (accelerate at a_max,j for half the
    time, decelerate for the other half). All joints move in T = max_j T_min,j, joint j with
    the rescaled acceleration a_j = 4 dq_j / T^2 (signed), switching at T / 2; the peak
    velocity is a_j T / 2.

    Parameters
    ----------
    q_start, q_end : array_like, shape (n,)
        Rest positions (rad or m).
    a_max : array_like, shape (n,)
        Acceleration limits (rad/s^2 or m/s^2), > 0.
    """

    def __init__(self, q_start, q_end, a_max):
        self.q_start = finite_vector(q_start, "q_start")
        self.dim = len(self.q_start)
        self.q_end = finite_vector(q_end, "q_end", self.dim)
        a = finite_vector(a_max, "a_max", self.dim)
        bad = np.flatnonzero(a <= 0.0)
        if bad.size:
            raise ValueError(f"a_max[{bad[0] + 1}]: must be > 0, got {a[bad[0]]}")
        self.a_max = a
        with np.errstate(all="ignore"):
            delta = self.q_end - self.q_start
            self.t_min = 2.0 * np.sqrt(np.abs(delta) / a)
        bad = np.flatnonzero(~np.isfinite(delta))
        if bad.size:
            j = int(bad[0]) + 1
            raise ValueError(f"q_start[{j}] = {shown(self.q_start[j - 1])} and q_end[{j}] = {shown(self.q_end[j - 1])} are "
                             f"too far apart: joint {j}'s move would be {shown(delta[j - 1])} (beyond the largest float)")
        self.duration = float(self.t_min.max())
        if not math.isfinite(self.duration):
            j = int(np.argmax(self.t_min)) + 1
            raise ValueError(f"a_max[{j}] = {shown(a[j - 1])} is too small for joint {j}'s move of {shown(delta[j - 1])} "
                             f"(q_start[{j}] to q_end[{j}]): it would take {shown(self.duration)} s (not finite)")
        with np.errstate(all="ignore"):
            if self.duration == 0.0:
                self.acceleration = np.zeros(self.dim)
            else:
                try:
                    self.acceleration = 4.0 * delta / self.duration ** 2
                except OverflowError:       # duration ** 2 beyond the largest float
                    self.acceleration = np.full(self.dim, np.nan)
                if not finite(self.acceleration) or not self.acceleration[delta != 0.0].all():
                    self.acceleration = delta / self.duration * (4.0 / self.duration)   # T^2 out of range
            self.switch_time = 0.5 * self.duration
            self.peak_velocity = self.acceleration * self.switch_time
        bad = np.flatnonzero(~np.isfinite(self.acceleration) | ~np.isfinite(self.peak_velocity))
        if bad.size:
            j = int(bad[0]) + 1
            raise ValueError(f"q_start[{j}], q_end[{j}] and a_max: joint {j} moves {shown(delta[j - 1])} in "
                             f"{shown(self.duration)} s: its acceleration would be {shown(self.acceleration[j - 1])} and "
                             f"peak velocity {shown(self.peak_velocity[j - 1])} (not finite)")
        self.breakpoints = np.unique([0.0, self.switch_time, self.duration])
        self._break_list = self.breakpoints.tolist()
        self._half_acceleration = 0.5 * self.acceleration

    def evaluate_into(self, t: float, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
                      snap: bool = True) -> None:
        """Position, velocity and acceleration (joint units) at ``t`` written into ``q``, ``qd``,
        ``qdd`` (each shape (n,); no allocation)."""
        if snap:
            t = snap_to(self._break_list, t)
        rest = (self.q_start if t < 0.0 or self.duration == 0.0 else
                self.q_end if t >= self.duration else None)
        if rest is not None:
            q[:], qd[:], qdd[:] = rest, 0.0, 0.0
            return
        a = self.acceleration
        if t < self.switch_time:
            np.multiply(self._half_acceleration, t, out=q)
            np.multiply(q, t, out=q)
            np.add(self.q_start, q, out=q)           # q_start + a t^2 / 2
            np.multiply(a, t, out=qd)
            qdd[:] = a
            return
        r = self.duration - t
        np.multiply(self._half_acceleration, r, out=q)
        np.multiply(q, r, out=q)
        np.subtract(self.q_end, q, out=q)            # q_end - a r^2 / 2
        np.multiply(a, r, out=qd)
        np.negative(a, out=qdd)


class Circle(Profile):
    """Once round a circle in the first two task coordinates, the phase phi(t) by LSPB.

    phi runs from 0 to 2 pi in ``duration`` by LSPB (cruise speed ``cruise_factor`` x the mean
    speed), at rest at both ends. The point is

        p(phi) = center + radius (cos psi, sin psi),  psi = start_angle + sense phi,

    (``sense`` +1 counter-clockwise, -1 clockwise), and every further task coordinate k is
    offset[k] + amplitude[k] sin phi. Velocity and acceleration are the exact derivatives:
    pd = radius sense phid (-sin psi, cos psi), pdd = radius sense phidd (-sin psi, cos psi)
    - radius phid^2 (cos psi, sin psi); the k-th extra one amplitude[k] (cos phi phid) and
    amplitude[k] (cos phi phidd - sin phi phid^2). Before 0 and from ``duration`` on it rests at
    the start point (phi = 0, the same as phi = 2 pi).

    Parameters
    ----------
    center : array_like, shape (2,)
        Centre in the first two task coordinates.
    radius : float
        > 0, in their unit.
    start_angle : float
        psi at phi = 0 (rad): the start point's direction from the centre.
    sense : {1, -1}
    duration : float
        > 0 (s).
    cruise_factor : float
        In (1, 2].
    offset, amplitude : array_like, shape (m - 2,)
        The extra task coordinates' offset and sin-phi amplitude (empty for m = 2).
    """

    def __init__(self, center, radius: float, start_angle: float, sense: int, duration: float,
                 cruise_factor: float = 1.5, offset=(), amplitude=()):
        self.center = finite_vector(center, "center", 2)
        self.radius = positive(radius, "radius", "m")
        self.start_angle = float(start_angle)
        if not np.isfinite(self.start_angle):
            raise ValueError(f"start_angle: must be finite, got {start_angle}")
        if sense not in (1, -1):
            raise ValueError(f"sense: must be 1 (counter-clockwise) or -1 (clockwise), got {sense}")
        self.sense = int(sense)
        self.duration = positive(duration, "duration", "s")
        if not (1.0 < cruise_factor <= 2.0):
            raise ValueError(f"cruise_factor: must lie in (1, 2], got {cruise_factor}")
        self.cruise_factor = float(cruise_factor)
        self.offset = finite_vector(np.asarray(offset, dtype=float).reshape(-1), "offset")
        self.amplitude = finite_vector(np.asarray(amplitude, dtype=float).reshape(-1), "amplitude",
                                        len(self.offset))
        self.dim = 2 + len(self.offset)
        tb = self.duration * (1.0 - 1.0 / self.cruise_factor)
        self.breakpoints = np.unique([0.0, tb, self.duration - tb, self.duration])
        self._phase = LSPBPiece(np.zeros(1), np.full(1, 2.0 * np.pi), self.duration, self.cruise_factor)
        self._check_finite()
        self._phase_values = (np.zeros(1), np.zeros(1), np.zeros(1))
        self._break_list = self.breakpoints.tolist()
        self._center = tuple(self.center.tolist())
        self._extras = list(zip(self.offset.tolist(), self.amplitude.tolist()))

    def _check_finite(self) -> None:
        """Refuse parameters whose reference overflows (ValueError naming them): the phase's
        rate and acceleration (duration), the circle's extent, speed and acceleration (center,
        radius with the phase), each extra coordinate's (offset, amplitude with the phase)."""
        problem = self._phase.overflow()
        if problem is not None:
            what, _, value = problem
            unit = {"cruise speed": "rad/s", "acceleration": "rad/s2"}.get(what, "rad")
            raise ValueError(f"duration = {shown(self.duration)} s is too short: once round the circle in it, the "
                             f"phase's {what} would be {shown(value)} {unit} (not finite); give a longer duration")
        w, alpha = abs(float(self._phase.V[0])), abs(float(self._phase.a[0]))    # peak phase rate, acceleration
        r = self.radius
        with np.errstate(all="ignore"):
            motion = {"speed": r * w, "acceleration": max(r * alpha, r * w * w)}     # as evaluate_into's terms
            extent = np.abs(self.center) + r
            extras = [(abs(o) + abs(m), abs(m) * w, max(abs(m) * alpha, abs(m) * w * w))
                      for o, m in zip(self.offset, self.amplitude)]
        for what, value in motion.items():
            if not math.isfinite(value):
                raise ValueError(f"radius = {shown(r)} m and duration = {shown(self.duration)} s: the reference's peak "
                                 f"{what} would be {shown(value)} (not finite); give a smaller radius or a longer duration")
        if not finite(extent):
            k = int(np.flatnonzero(~np.isfinite(extent))[0]) + 1
            raise ValueError(f"center[{k}] = {shown(self.center[k - 1])} and radius = {shown(r)} m: the circle reaches "
                             "beyond the largest float")
        for k, (reach, speed, acceleration) in enumerate(extras, start=1):
            if not finite(reach, speed, acceleration):
                raise ValueError(f"offset[{k}] = {shown(self.offset[k - 1])}, amplitude[{k}] = "
                                 f"{shown(self.amplitude[k - 1])} and duration = {shown(self.duration)} s: task coordinate "
                                 f"{k + 2} would reach {shown(reach)}, speed {shown(speed)}, acceleration "
                                 f"{shown(acceleration)} (not finite)")

    def phase(self, t: float) -> tuple[float, float, float]:
        """phi (rad), phid (rad/s), phidd (rad/s^2) at ``t``: LSPB from 0 to 2 pi, at rest outside."""
        if t < 0.0 or t >= self.duration:
            return (0.0 if t < 0.0 else 2.0 * np.pi), 0.0, 0.0
        p, v, a = self._phase_values
        self._phase.evaluate_into(t, p, v, a)
        return float(p[0]), float(v[0]), float(a[0])

    def evaluate_into(self, t: float, x: np.ndarray, xd: np.ndarray, xdd: np.ndarray,
                      snap: bool = True) -> None:
        """Position, velocity and acceleration (task units) at ``t`` written into ``x``, ``xd``,
        ``xdd`` (each shape (dim,)), in float arithmetic (a handful of numbers: NumPy's per-call
        overhead would cost more)."""
        if snap:
            t = snap_to(self._break_list, t)
        phi, w, alpha = self.phase(t)
        psi = self.start_angle + self.sense * phi
        c, s = math.cos(psi), math.sin(psi)
        r, k = self.radius, self.sense
        rkw, rka, rww = r * k * w, r * k * alpha, r * w * w
        cx, cy = self._center
        x[0], x[1] = cx + r * c, cy + r * s
        xd[0], xd[1] = rkw * -s, rkw * c
        xdd[0], xdd[1] = rka * -s - rww * c, rka * c - rww * s
        if self._extras:
            sin_phi, cos_phi = math.sin(phi), math.cos(phi)
            for i, (offset, amplitude) in enumerate(self._extras, start=2):
                x[i] = offset + amplitude * sin_phi
                xd[i] = amplitude * cos_phi * w
                xdd[i] = amplitude * (cos_phi * alpha - sin_phi * w * w)

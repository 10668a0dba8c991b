"""Trajectory profiles: LSPB through waypoints, a straight line with a trapezoidal speed profile,
a synchronized minimum-time bang-bang in joint space and a task-space circle run once with an
LSPB phase; the time laws they share (:class:`LSPBLaw`, :class:`TrapezoidLaw`, :func:`schedule`).
Pose profiles (orientation too) are in :mod:`.pose_trajectory`.

Every profile has ``dim``, ``duration``, ``breakpoints`` (the instants where its acceleration
jumps) and ``evaluate(t, snap=True) -> (x, xd, xdd)``; it rests at its start before 0 and at its
end from ``duration`` on. At a breakpoint the value is the one that holds after it (the start
instant already accelerates; the end instant is at rest), as a sampled block holds it.

LSPB: 
A move from x0 to x1 in time T with cruise speed V (per axis, |V| in (|dx|/T, 2|dx|/T]) blends
for tb = T - dx/V at constant acceleration a = V/tb, cruises, and blends to rest. With the
common default V = 1.5 dx/T: tb = T/3 and a = 4.5 dx/T^2.
"""
from __future__ import annotations

from bisect import bisect_left, bisect_right
from dataclasses import dataclass
import math

import numpy as np



def lspb(x0: np.ndarray, x1: np.ndarray, T: float, t: float, cruise_factor: float = 1.5):
    """Position, velocity and acceleration of an LSPB move at time ``t`` (0 <= t <= T).

    Parameters
    ----------
    x0, x1 : array_like, shape (m,)
        Start and end points; each axis moves independently, all in the same time.
    T : float
        Move duration (s), > 0.
    t : float
        Time since the start of the move (s); clipped to [0, T].
    cruise_factor : float
        Cruise speed over mean speed, in (1, 2]. 2 gives a bang-bang (triangular) profile.

    Returns
    -------
    x, xd, xdd : ndarray, shape (m,)
    """
    piece = _LSPBPiece(x0, x1, T, cruise_factor)
    x, xd, xdd = np.empty_like(piece.x0), np.empty_like(piece.x0), np.empty_like(piece.x0)
    piece.evaluate_into(t, x, xd, xdd)
    return x, xd, xdd


class _LSPBPiece:
    """One LSPB move with its constants computed once: :func:`lspb`'s arithmetic, written into
    given arrays."""

    def __init__(self, x0, x1, T: float, cruise_factor: float):
        self.x0 = np.asarray(x0, dtype=float)
        self.T = T
        self.tb = T - T / cruise_factor
        with np.errstate(all="ignore"):     # extreme parameters: refused by the profiles (overflow())
            dx = np.asarray(x1, dtype=float) - self.x0
            self.dx = dx
            self.V = cruise_factor * dx / T
            self.a = self.V / self.tb
            self.half_a = 0.5 * self.a
            self.minus_a = -self.a
            self.cruise_start = self.x0 + self.half_a * self.tb * self.tb
            self.end = self.x0 + dx

    def overflow(self) -> tuple[str, int, float] | None:
        """Why the move is not finite, or None: ``(what, axis, value)`` for the first non-finite
        of its distance, cruise speed, acceleration or cruise start (axis 0-based)."""
        for what, values in (("distance", self.dx), ("cruise speed", self.V), ("acceleration", self.a),
                             ("position", self.cruise_start)):
            bad = np.flatnonzero(~np.isfinite(values))
            if bad.size:
                return what, int(bad[0]), float(values[bad[0]])
        return None

    def evaluate_into(self, t: float, x: np.ndarray, xd: np.ndarray, xdd: np.ndarray) -> None:
        T, tb = self.T, self.tb
        t = min(max(t, 0.0), T)
        if t < tb:
            np.multiply(self.half_a, t, out=x)
            np.multiply(x, t, out=x)
            np.add(self.x0, x, out=x)
            np.multiply(self.a, t, out=xd)
            xdd[:] = self.a
        elif t <= T - tb:
            np.multiply(self.V, t - tb, out=x)
            np.add(self.cruise_start, x, out=x)
            xd[:] = self.V
            xdd[:] = 0.0
        else:
            r = T - t
            np.multiply(self.half_a, r, out=x)
            np.multiply(x, r, out=x)
            np.subtract(self.end, x, out=x)
            np.multiply(self.a, r, out=xd)
            xdd[:] = self.minus_a


class LSPBLaw:
    """A time law s(t) from 0 to 1 in ``duration`` by LSPB (cruise rate ``cruise_factor`` x the
    mean rate), at rest at both ends, in float arithmetic: :func:`lspb` of one coordinate.

    Attributes
    ----------
    duration : float
        s.
    breakpoints : ndarray
        The instants (s) where sdd jumps: 0, the blend ends, ``duration``.
    peak_rate, peak_acceleration : float
        The largest sd (1/s) and |sdd| (1/s^2).

    Raises
    ------
    ValueError
        Naming ``duration`` or ``cruise_factor``.
    """

    def __init__(self, duration: float, cruise_factor: float = 1.5):
        self.duration = _positive(duration, "duration", "s")
        if not (1.0 < cruise_factor <= 2.0):
            raise ValueError(f"cruise_factor: must lie in (1, 2], got {cruise_factor}")
        self.cruise_factor = float(cruise_factor)
        piece = _LSPBPiece(np.zeros(1), np.ones(1), self.duration, self.cruise_factor)
        problem = piece.overflow()
        if problem is not None:
            what, _, value = problem
            raise ValueError(f"duration = {_g(self.duration)} s is too short: the time law's {what} would be "
                             f"{_g(value)} (not finite); give a longer duration")
        self.tb = piece.tb
        self.peak_rate, self.peak_acceleration = float(piece.V[0]), float(piece.a[0])
        self._half_a, self._cruise_start = float(piece.half_a[0]), float(piece.cruise_start[0])
        self.breakpoints = np.unique([0.0, self.tb, self.duration - self.tb, self.duration])

    def path(self, t: float) -> tuple[float, float, float]:
        """s, sd (1/s), sdd (1/s^2) at ``t``; 0 before the start, 1 from ``duration`` on."""
        T, tb = self.duration, self.tb
        if t < 0.0 or t >= T:
            return (0.0 if t < 0.0 else 1.0), 0.0, 0.0
        a, v = self.peak_acceleration, self.peak_rate
        if t < tb:
            return self._half_a * t * t, a * t, a
        if t <= T - tb:
            return self._cruise_start + v * (t - tb), v, 0.0
        r = T - t
        return 1.0 - self._half_a * r * r, a * r, -a


class TrapezoidLaw:
    """A time law s(t) from 0 to ``length`` at minimum time under a rate and an acceleration
    limit: a trapezoidal rate profile.

    It accelerates at a_max to v_max (at t1 = v_max / a_max), cruises, and decelerates to rest at
    T = length / v_max + t1. If ``length`` is too short to reach v_max (length < v_max^2 / a_max)
    the profile is triangular: t1 = T / 2 = sqrt(length / a_max), peak rate a_max t1. v_max may be
    infinite (a triangle at a_max).

    Attributes
    ----------
    duration, t1 : float
        The time to the end and of each ramp (s).
    peak_rate, peak_acceleration : float
        The cruise rate a_max t1 and a_max (s's unit per s, per s^2).
    finite : bool
        Whether every number of the law is finite (the caller refuses one that is not, naming
        its own parameters).
    """

    def __init__(self, length: float, v_max: float, a_max: float):
        self.length, self.v_max, self.a_max = float(length), float(v_max), float(a_max)
        try:
            reach = self.v_max ** 2 / self.a_max        # the length the ramps up to v_max and down take
        except OverflowError:
            reach = math.inf
        with np.errstate(all="ignore"):
            if self.length >= reach:
                self.t1 = self.v_max / self.a_max
                self.duration = self.length / self.v_max + self.t1
            else:
                self.t1 = float(np.sqrt(self.length / self.a_max))
                self.duration = 2.0 * self.t1
            self.peak_rate = self.a_max * self.t1
            self.peak_acceleration = self.a_max
            self.finite = _finite(self.duration, self.t1, self.peak_rate, 0.5 * self.a_max * self.t1 * self.t1)
            self.breakpoints = np.unique([0.0, self.t1, self.duration - self.t1, self.duration])

    def path(self, t: float) -> tuple[float, float, float]:
        """s, sd, sdd at ``t``; 0 before the start, ``length`` from ``duration`` on."""
        T, t1, a = self.duration, self.t1, self.a_max
        if t < 0.0:
            return 0.0, 0.0, 0.0
        if t >= T:
            return self.length, 0.0, 0.0
        if t < t1:
            return 0.5 * a * t * t, a * t, a
        if t <= T - t1:
            return 0.5 * a * t1 * t1 + self.peak_rate * (t - t1), self.peak_rate, 0.0
        r = T - t
        return self.length - 0.5 * a * r * r, a * r, -a


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


#: Communication points within this many seconds of a breakpoint are evaluated at it.
SNAP_TOLERANCE = 1e-9


def snap_to(breakpoints, t: float, tol: float = SNAP_TOLERANCE) -> float:
    """``t`` moved onto a breakpoint within ``tol`` s, so that communication points that land on
    one by rounding (3.4995 + 5e-4) evaluate the same branch as the exact instant.
    ``breakpoints``: sorted (an array, or a list, which is faster to search)."""
    k = bisect_left(breakpoints, t)
    for j in (k - 1, k):
        if 0 <= j < len(breakpoints) and abs(breakpoints[j] - t) <= tol:
            return float(breakpoints[j])
    return t


def _finite_vector(value, name: str, length: int | None = None) -> np.ndarray:
    v = np.asarray(value, dtype=float)
    if v.ndim != 1 or (length is not None and v.shape[0] != length):
        raise ValueError(f"{name}: need {length or 'a vector of'} values, got shape {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name}: every value must be finite, got {v.tolist()}")
    return v


def _positive(value: float, name: str, unit: str) -> float:
    value = float(value)
    if not (np.isfinite(value) and value > 0.0):
        raise ValueError(f"{name}: must be > 0 {unit}, got {value}")
    return value


def _g(value: float) -> str:
    """A number in a message: 6 significant digits (inf, nan as such)."""
    return f"{float(value):.6g}"


def _finite(*values) -> bool:
    """Whether every number (or array) of ``values`` is finite."""
    return all(bool(np.all(np.isfinite(v))) for v in values)


class _Profile:
    """A reference profile: :meth:`evaluate_into` (each subclass's arithmetic, written into given
    arrays) and :meth:`evaluate` from it; ``dim`` values per order, ``breakpoints`` (s)."""

    dim: int

    def evaluate(self, t: float, snap: bool = True):
        """Position, velocity and acceleration at time ``t`` (s), each shape (dim,).

        Before its start the profile rests at its first point, after its end at its last. With
        ``snap``, times within 1e-9 s of a breakpoint are evaluated at the breakpoint (sampled
        use); without, the exact branch at ``t`` (an integrator working inside one piece).
        """
        x, xd, xdd = np.empty(self.dim), np.empty(self.dim), np.empty(self.dim)
        self.evaluate_into(t, x, xd, xdd, snap)
        return x, xd, xdd

    def evaluate_into(self, t: float, x: np.ndarray, xd: np.ndarray, xdd: np.ndarray,
                      snap: bool = True) -> None:
        raise NotImplementedError


def schedule(durations, pause: float, moves: int) -> tuple[list[tuple[float, float, int]], float]:
    """The timeline of ``moves`` moves with a ``pause`` after every move but the last.

    Parameters
    ----------
    durations : array_like, shape (moves,)
        Each move's duration (s), > 0.
    pause : float
        Rest between two moves (s), >= 0.
    moves : int
        The number of moves (legs between waypoints).

    Returns
    -------
    segments : list of (start, end, move)
        Each move or pause: its start and end (s) and its 1-based move number (0 for a pause).
    duration : float
        The end of the last move (s).

    Raises
    ------
    ValueError
        Naming ``durations`` or ``pause``: a count other than ``moves``, a duration that is not
        positive and finite, a move or pause lost in rounding, a total beyond the largest float.
    """
    d = np.asarray(durations, dtype=float)
    if d.ndim != 1 or d.shape[0] != moves:
        raise ValueError(f"durations: need one duration per move ({moves}), got {d.shape[0] if d.ndim == 1 else d.shape}")
    if not np.all(np.isfinite(d)) or np.any(d <= 0.0):
        raise ValueError(
            f"durations: every move must take a positive, finite time (waypoint times strictly increasing), got {d.tolist()}")
    if not (np.isfinite(pause) and pause >= 0.0):
        raise ValueError(f"pause: must be >= 0 s, got {pause}")
    segments, t = [], 0.0
    with np.errstate(all="ignore"):
        for i in range(moves):
            segments.append((t, t + d[i], i + 1))
            if segments[-1][1] == t and math.isfinite(t):
                raise ValueError(f"durations: move {i + 1} of {_g(d[i])} s starts at t = {_g(t)} s, where so short "
                                 "a time is lost in rounding (the earlier durations and pauses are too long "
                                 "beside it); give the earlier moves and pauses less time or this one more")
            t += d[i]
            if i < moves - 1 and pause > 0.0:
                segments.append((t, t + pause, 0))
                if segments[-1][1] == t and math.isfinite(t):
                    raise ValueError(f"pause = {_g(pause)} s is lost in rounding at t = {_g(t)} s (the durations "
                                     "are too long beside it); give a longer pause or shorter durations")
                t += pause
    if not math.isfinite(t):
        with np.errstate(all="ignore"):
            total = d.sum()
        raise ValueError(f"durations, pause: the moves ({_g(total)} s in all) and pauses ({_g(pause)} s each) "
                         f"add up to {_g(t)} s, beyond the largest float; give shorter durations or pauses")
    return [(float(a), float(b), m) for a, b, m in segments], float(t)


@dataclass(frozen=True)
class Segment:
    start: float   # s
    end: float     # s
    x0: np.ndarray
    x1: np.ndarray
    move: int      # 1-based move number; 0 for a pause


class WaypointTrajectory(_Profile):
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
            first = _finite_vector(start, "start", w.shape[1])
            with np.errstate(all="ignore"):
                w = np.vstack([first, first + w if relative else w])
            if not np.all(np.isfinite(w)):
                row, axis = (int(v) for v in np.argwhere(~np.isfinite(w))[0])
                raise ValueError(f"start[{axis + 1}] = {_g(first[axis])} and waypoints row {row}: the point start + "
                                 f"offset is {_g(w[row, axis])} in coordinate {axis + 1} (beyond the largest float)")
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
        self._pieces = [_LSPBPiece(s.x0, s.x1, s.end - s.start, self.cruise_factor) if s.move else None
                        for s in segments]
        for s, piece in zip(segments, self._pieces):
            problem = piece.overflow() if piece is not None else None
            if problem is not None:
                raise ValueError(self._overflow_message(s, piece, *problem))

    def _overflow_message(self, s: Segment, piece: _LSPBPiece, what: str, axis: int, value: float) -> str:
        """Why move ``s`` overflows, naming the parameters (waypoints rows, durations)."""
        i = s.move
        row = i - 1 if self.has_start else i          # the row the move starts from (0: the start)
        pair, span = ((f"rows {row} and {row + 1}", f"waypoints rows {row} to {row + 1}") if row else
                      ("the start and row 1", "the start to waypoints row 1"))
        if what == "distance":
            return (f"waypoints: {pair} are too far apart: coordinate {axis + 1} goes from "
                    f"{_g(s.x0[axis])} to {_g(s.x1[axis])}, a change of {_g(value)} (beyond the largest float); "
                    "bring the waypoints closer")
        return (f"durations: move {i} takes {_g(s.end - s.start)} s, too short for {span} "
                f"(coordinate {axis + 1} changes by {_g(piece.dx[axis])}): its {what} would be {_g(value)} "
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


class StraightLine(_Profile):
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
        start = _finite_vector(start, "start")
        d = _finite_vector(displacement, "displacement", len(start))
        if not d.any():
            raise ValueError("displacement: must not be the zero vector")
        biggest = float(np.max(np.abs(d)))
        with np.errstate(all="ignore"):
            length = biggest * float(np.linalg.norm(d / biggest))     # no overflow of the squares
        if not math.isfinite(length):
            raise ValueError(f"displacement: its length is beyond the largest float ({d.tolist()})")
        return cls(start, d, length, v_max, a_max)

    def __init__(self, start, direction, length: float, v_max: float, a_max: float):
        self.start = _finite_vector(start, "start")
        d = _finite_vector(direction, "direction", len(self.start))
        if not d.any():
            raise ValueError("direction: must not be the zero vector")
        with np.errstate(all="ignore"):
            norm = float(np.linalg.norm(d))
            if not (math.isfinite(norm) and norm > 1e-150):     # its square overflowed or underflowed
                d = d / np.max(np.abs(d))
                norm = float(np.linalg.norm(d))
        self.direction = d / norm
        self.length = _positive(length, "length", "m")
        self.v_max = _positive(v_max, "v_max", "m/s")
        self.a_max = _positive(a_max, "a_max", "m/s2")
        self.dim = len(self.start)
        self.law = TrapezoidLaw(self.length, self.v_max, self.a_max)
        self.t1, self.duration, self.v_peak = self.law.t1, self.law.duration, self.law.peak_rate
        limits = f"length = {_g(self.length)} m, v_max = {_g(self.v_max)} m/s, a_max = {_g(self.a_max)} m/s2"
        if not self.law.finite:
            raise ValueError(f"{limits}: the line would take {_g(self.duration)} s (ramps of {_g(self.t1)} s, "
                             f"peak speed {_g(self.v_peak)} m/s), not finite; give a shorter length or larger "
                             "v_max and a_max")
        with np.errstate(all="ignore"):
            self.end = self.start + self.length * self.direction
        if not _finite(self.end):
            k = int(np.flatnonzero(~np.isfinite(self.end))[0])
            raise ValueError(f"start[{k + 1}] = {_g(self.start[k])} and length = {_g(self.length)} m: the end "
                             f"point's coordinate {k + 1} would be {_g(self.end[k])} (beyond the largest float)")
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


class SynchronizedBangBang(_Profile):
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
        self.q_start = _finite_vector(q_start, "q_start")
        self.dim = len(self.q_start)
        self.q_end = _finite_vector(q_end, "q_end", self.dim)
        a = _finite_vector(a_max, "a_max", self.dim)
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
            raise ValueError(f"q_start[{j}] = {_g(self.q_start[j - 1])} and q_end[{j}] = {_g(self.q_end[j - 1])} are "
                             f"too far apart: joint {j}'s move would be {_g(delta[j - 1])} (beyond the largest float)")
        self.duration = float(self.t_min.max())
        if not math.isfinite(self.duration):
            j = int(np.argmax(self.t_min)) + 1
            raise ValueError(f"a_max[{j}] = {_g(a[j - 1])} is too small for joint {j}'s move of {_g(delta[j - 1])} "
                             f"(q_start[{j}] to q_end[{j}]): it would take {_g(self.duration)} s (not finite)")
        with np.errstate(all="ignore"):
            if self.duration == 0.0:
                self.acceleration = np.zeros(self.dim)
            else:
                try:
                    self.acceleration = 4.0 * delta / self.duration ** 2
                except OverflowError:       # duration ** 2 beyond the largest float
                    self.acceleration = np.full(self.dim, np.nan)
                if not _finite(self.acceleration) or not self.acceleration[delta != 0.0].all():
                    self.acceleration = delta / self.duration * (4.0 / self.duration)   # T^2 out of range
            self.switch_time = 0.5 * self.duration
            self.peak_velocity = self.acceleration * self.switch_time
        bad = np.flatnonzero(~np.isfinite(self.acceleration) | ~np.isfinite(self.peak_velocity))
        if bad.size:
            j = int(bad[0]) + 1
            raise ValueError(f"q_start[{j}], q_end[{j}] and a_max: joint {j} moves {_g(delta[j - 1])} in "
                             f"{_g(self.duration)} s: its acceleration would be {_g(self.acceleration[j - 1])} and "
                             f"peak velocity {_g(self.peak_velocity[j - 1])} (not finite)")
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


class Circle(_Profile):
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
        self.center = _finite_vector(center, "center", 2)
        self.radius = _positive(radius, "radius", "m")
        self.start_angle = float(start_angle)
        if not np.isfinite(self.start_angle):
            raise ValueError(f"start_angle: must be finite, got {start_angle}")
        if sense not in (1, -1):
            raise ValueError(f"sense: must be 1 (counter-clockwise) or -1 (clockwise), got {sense}")
        self.sense = int(sense)
        self.duration = _positive(duration, "duration", "s")
        if not (1.0 < cruise_factor <= 2.0):
            raise ValueError(f"cruise_factor: must lie in (1, 2], got {cruise_factor}")
        self.cruise_factor = float(cruise_factor)
        self.offset = _finite_vector(np.asarray(offset, dtype=float).reshape(-1), "offset")
        self.amplitude = _finite_vector(np.asarray(amplitude, dtype=float).reshape(-1), "amplitude",
                                        len(self.offset))
        self.dim = 2 + len(self.offset)
        tb = self.duration * (1.0 - 1.0 / self.cruise_factor)
        self.breakpoints = np.unique([0.0, tb, self.duration - tb, self.duration])
        self._phase = _LSPBPiece(np.zeros(1), np.full(1, 2.0 * np.pi), self.duration, self.cruise_factor)
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
            raise ValueError(f"duration = {_g(self.duration)} s is too short: once round the circle in it, the "
                             f"phase's {what} would be {_g(value)} {unit} (not finite); give a longer duration")
        w, alpha = abs(float(self._phase.V[0])), abs(float(self._phase.a[0]))    # peak phase rate, acceleration
        r = self.radius
        with np.errstate(all="ignore"):
            motion = {"speed": r * w, "acceleration": max(r * alpha, r * w * w)}     # as evaluate_into's terms
            extent = np.abs(self.center) + r
            extras = [(abs(o) + abs(m), abs(m) * w, max(abs(m) * alpha, abs(m) * w * w))
                      for o, m in zip(self.offset, self.amplitude)]
        for what, value in motion.items():
            if not math.isfinite(value):
                raise ValueError(f"radius = {_g(r)} m and duration = {_g(self.duration)} s: the reference's peak "
                                 f"{what} would be {_g(value)} (not finite); give a smaller radius or a longer duration")
        if not _finite(extent):
            k = int(np.flatnonzero(~np.isfinite(extent))[0]) + 1
            raise ValueError(f"center[{k}] = {_g(self.center[k - 1])} and radius = {_g(r)} m: the circle reaches "
                             "beyond the largest float")
        for k, (reach, speed, acceleration) in enumerate(extras, start=1):
            if not _finite(reach, speed, acceleration):
                raise ValueError(f"offset[{k}] = {_g(self.offset[k - 1])}, amplitude[{k}] = "
                                 f"{_g(self.amplitude[k - 1])} and duration = {_g(self.duration)} s: task coordinate "
                                 f"{k + 2} would reach {_g(reach)}, speed {_g(speed)}, acceleration "
                                 f"{_g(acceleration)} (not finite)")

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


def read_table(path, columns) -> list[list[float]]:
    """Rows of numbers from a CSV file: one row per waypoint, one column per task coordinate.

    An optional first row names the columns; it must name ``columns`` in order. Blank lines and
    lines starting with ``#`` are skipped.

    Raises
    ------
    ValueError
        Naming the file, and the line of a row that is not ``len(columns)`` finite numbers.
    """
    import csv
    from pathlib import Path

    path = Path(path)
    try:
        lines = path.read_text().splitlines()
    except OSError as exc:
        raise ValueError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    rows = []
    for number, row in enumerate(csv.reader(lines), start=1):
        cells = [c.strip() for c in row]
        if not any(cells) or cells[0].startswith("#"):
            continue
        try:
            values = [float(c) for c in cells]
        except ValueError:
            if rows or [c for c in cells] != list(columns):
                raise ValueError(f"{path}, line {number}: expected {len(columns)} numbers ("
                                 f"{', '.join(columns)}) or, first, the header {','.join(columns)}; "
                                 f"got {','.join(cells)!r}") from None
            continue
        if len(values) != len(columns) or not all(math.isfinite(v) for v in values):
            raise ValueError(f"{path}, line {number}: expected {len(columns)} finite numbers ("
                             f"{', '.join(columns)}), got {','.join(cells)!r}")
        rows.append(values)
    if len(rows) < 2:
        raise ValueError(f"{path}: needs at least two waypoints, got {len(rows)}")
    return rows

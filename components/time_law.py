"""The time laws the profiles share: LSPB (:func:`lspb`, :class:`LSPBLaw`), a trapezoidal
speed along a path (:class:`TrapezoidLaw`) and the timeline of moves and pauses
(:func:`schedule`).

LSPB:
A move from x0 to x1 in time T with cruise speed V (per axis, |V| in (|dx|/T, 2|dx|/T]) blends
for tb = T - dx/V at constant acceleration a = V/tb, cruises, and blends to rest. With the
common default V = 1.5 dx/T: tb = T/3 and a = 4.5 dx/T^2.
"""
from __future__ import annotations

import math

import numpy as np

from .profile import finite, positive, shown


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
    piece = LSPBPiece(x0, x1, T, cruise_factor)
    x, xd, xdd = np.empty_like(piece.x0), np.empty_like(piece.x0), np.empty_like(piece.x0)
    piece.evaluate_into(t, x, xd, xdd)
    return x, xd, xdd


class LSPBPiece:
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
        self.duration = positive(duration, "duration", "s")
        if not (1.0 < cruise_factor <= 2.0):
            raise ValueError(f"cruise_factor: must lie in (1, 2], got {cruise_factor}")
        self.cruise_factor = float(cruise_factor)
        piece = LSPBPiece(np.zeros(1), np.ones(1), self.duration, self.cruise_factor)
        problem = piece.overflow()
        if problem is not None:
            what, _, value = problem
            raise ValueError(f"duration = {shown(self.duration)} s is too short: the time law's {what} would be "
                             f"{shown(value)} (not finite); give a longer duration")
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
            self.finite = finite(self.duration, self.t1, self.peak_rate, 0.5 * self.a_max * self.t1 * self.t1)
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
                raise ValueError(f"durations: move {i + 1} of {shown(d[i])} s starts at t = {shown(t)} s, where so short "
                                 "a time is lost in rounding (the earlier durations and pauses are too long "
                                 "beside it); give the earlier moves and pauses less time or this one more")
            t += d[i]
            if i < moves - 1 and pause > 0.0:
                segments.append((t, t + pause, 0))
                if segments[-1][1] == t and math.isfinite(t):
                    raise ValueError(f"pause = {shown(pause)} s is lost in rounding at t = {shown(t)} s (the durations "
                                     "are too long beside it); give a longer pause or shorter durations")
                t += pause
    if not math.isfinite(t):
        with np.errstate(all="ignore"):
            total = d.sum()
        raise ValueError(f"durations, pause: the moves ({shown(total)} s in all) and pauses ({shown(pause)} s each) "
                         f"add up to {shown(t)} s, beyond the largest float; give shorter durations or pauses")
    return [(float(a), float(b), m) for a, b, m in segments], float(t)

"""Trajectory profiles: linear segments with parabolic blends (LSPB) through waypoints.

A move from x0 to x1 in time T with cruise speed V (per axis, |V| in (|dx|/T, 2|dx|/T]) blends
for tb = T - dx/V at constant acceleration a = V/tb, cruises, and blends to rest. With the
common default V = 1.5 dx/T: tb = T/3 and a = 4.5 dx/T^2.
"""
from __future__ import annotations

from dataclasses import dataclass

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
    x0 = np.asarray(x0, dtype=float)
    dx = np.asarray(x1, dtype=float) - x0
    t = min(max(t, 0.0), T)
    V = cruise_factor * dx / T
    tb = T - T / cruise_factor
    a = V / tb
    if t < tb:
        return x0 + 0.5 * a * t * t, a * t, a.copy()
    if t <= T - tb:
        return x0 + 0.5 * a * tb * tb + V * (t - tb), V.copy(), np.zeros_like(dx)
    r = T - t
    return x0 + dx - 0.5 * a * r * r, a * r, -a


@dataclass(frozen=True)
class Segment:
    start: float   # s
    end: float     # s
    x0: np.ndarray
    x1: np.ndarray
    move: int      # 1-based move number; 0 for a pause


class WaypointTrajectory:
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

    Raises
    ------
    ValueError
        Naming the offending argument.
    """

    def __init__(self, waypoints, durations, pause: float = 0.0, cruise_factor: float = 1.5,
                 grip_close_after_move: int = 0, grip_open_after_move: int = 0):
        w = np.asarray(waypoints, dtype=float)
        d = np.asarray(durations, dtype=float)
        if w.ndim != 2 or w.shape[0] < 2:
            raise ValueError(f"waypoints: need at least two points of equal dimension, got shape {w.shape}")
        if not np.all(np.isfinite(w)):
            raise ValueError("waypoints: every coordinate must be finite")
        if d.ndim != 1 or d.shape[0] != w.shape[0] - 1:
            raise ValueError(
                f"durations: need one duration per move ({w.shape[0] - 1}), got {d.shape[0] if d.ndim == 1 else d.shape}")
        if not np.all(np.isfinite(d)) or np.any(d <= 0.0):
            raise ValueError(
                f"durations: every move must take a positive, finite time (waypoint times strictly increasing), got {d.tolist()}")
        if not (np.isfinite(pause) and pause >= 0.0):
            raise ValueError(f"pause: must be >= 0 s, got {pause}")
        if not (1.0 < cruise_factor <= 2.0):
            raise ValueError(f"cruise_factor: must lie in (1, 2], got {cruise_factor}")
        k = d.shape[0]
        for name, move in (("grip_close_after_move", grip_close_after_move),
                           ("grip_open_after_move", grip_open_after_move)):
            if not (0 <= move <= k):
                raise ValueError(f"{name}: must be 0 (never) or a move number 1..{k}, got {move}")
        self.waypoints = w
        self.durations = d
        self.pause = float(pause)
        self.cruise_factor = float(cruise_factor)
        self.dim = w.shape[1]
        segments, t = [], 0.0
        for i in range(k):
            segments.append(Segment(t, t + d[i], w[i], w[i + 1], i + 1))
            t += d[i]
            if i < k - 1 and pause > 0.0:
                segments.append(Segment(t, t + pause, w[i + 1], w[i + 1], 0))
                t += pause
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

    @classmethod
    def from_scenario(cls, scenario: dict) -> "WaypointTrajectory":
        """The trajectory of a robot description's ``[scenario]`` table."""
        return cls(scenario["waypoints"], scenario["durations"], scenario.get("pause", 0.0),
                   scenario.get("cruise_factor", 1.5), scenario.get("grip_close_after_move", 0),
                   scenario.get("grip_open_after_move", 0))

    def _snap(self, t: float, tol: float = 1e-9) -> float:
        """``t`` moved onto a breakpoint (segment boundary or blend switch) within ``tol`` s, so
        that communication points that land on one by rounding (3.4995 + 5e-4) evaluate the same
        branch as the exact instant."""
        k = int(np.searchsorted(self.breakpoints, t))
        for j in (k - 1, k):
            if 0 <= j < len(self.breakpoints) and abs(self.breakpoints[j] - t) <= tol:
                return float(self.breakpoints[j])
        return t

    def evaluate(self, t: float, snap: bool = True):
        """Reference position, velocity and acceleration at time ``t`` (s), each shape (m,).

        Before 0 the trajectory rests at the first waypoint, after its end at the last. With
        ``snap``, times within 1e-9 s of a breakpoint are evaluated at the breakpoint (sampled
        use); without, the exact branch at ``t`` (an integrator working inside one piece).
        """
        if snap:
            t = self._snap(t)
        if t >= self.duration:
            return self.waypoints[-1].copy(), np.zeros(self.dim), np.zeros(self.dim)
        i = max(int(np.searchsorted(self._starts, t, side="right")) - 1, 0)
        s = self.segments[i]
        if s.move == 0:
            return s.x0.copy(), np.zeros(self.dim), np.zeros(self.dim)
        return lspb(s.x0, s.x1, s.end - s.start, t - s.start, self.cruise_factor)

    def grip(self, t: float) -> bool:
        """Gripper closed at time ``t``? Closing and opening take effect at their instants
        (within 1e-9 s, so that communication points that land on them by rounding count)."""
        t = self._snap(t)
        closed = t >= self.grip_close_time
        opened = t >= self.grip_open_time and self.grip_open_time > self.grip_close_time
        return bool(closed and not opened)


def parse_matrix(text: str, name: str, columns: int | None = None) -> np.ndarray:
    """Parse ``"x y z; x y z; ..."`` (commas also separate numbers) into a 2-D array.

    Raises ValueError naming ``name`` if the text is malformed.
    """
    rows = [r for r in text.replace("\n", ";").split(";") if r.strip()]
    try:
        values = [[float(v) for v in r.replace(",", " ").split()] for r in rows]
    except ValueError as exc:
        raise ValueError(f"{name}: malformed number ({exc}) in {text!r}") from None
    if not values or len({len(v) for v in values}) != 1:
        raise ValueError(f"{name}: rows must all have the same number of values, got {text!r}")
    if columns is not None and len(values[0]) != columns:
        raise ValueError(f"{name}: each row needs {columns} values, got {len(values[0])} in {text!r}")
    return np.array(values)


def parse_vector(text: str, name: str) -> np.ndarray:
    """Parse ``"1 3 1"`` (or comma-separated) into a 1-D array; ValueError naming ``name``."""
    try:
        values = [float(v) for v in text.replace(",", " ").split()]
    except ValueError as exc:
        raise ValueError(f"{name}: malformed number ({exc}) in {text!r}") from None
    if not values:
        raise ValueError(f"{name}: empty")
    return np.array(values)


def format_matrix(rows) -> str:
    """Inverse of :func:`parse_matrix`, exact for floats (repr)."""
    return "; ".join(" ".join(repr(float(v)) for v in row) for row in np.atleast_2d(rows))


def format_vector(values) -> str:
    """Inverse of :func:`parse_vector`."""
    return " ".join(repr(float(v)) for v in values)

"""The chess-pd reference both peers compute the same way, in plain NumPy (no robofmu, no
framework): the LSPB waypoint trajectory with its gripper and the pitch-elbow position IK, as
robofmu's components/trajectory.py and components/ik/closed_form.py define them, from the
numbers of ``benchmarks/loop_spec.py``. The joint rates stay with each peer (its own Jacobians).
"""
from __future__ import annotations

import bisect
import math

import numpy as np

#: Closer than this (m) to the base axis q1 is undefined (robofmu's AXIS_TOLERANCE).
AXIS_TOLERANCE = 1e-9


class Unreachable(ValueError):
    """The target is off the IK branch's workspace."""


class Waypoints:
    """LSPB moves through waypoints with pauses, and the gripper (closed on [close, open))."""

    def __init__(self, t: dict):
        w = np.asarray(t["waypoints"], dtype=float)
        d = np.asarray(t["durations"], dtype=float)
        self.pause, self.cf = float(t["pause"]), float(t["cruise_factor"])
        self.breaks = [float(b) for b in t["breakpoints"]]
        self.tol = float(t["snap_tolerance"])
        self.close, self.open = float(t["grip_close"]), float(t["grip_open"])
        self.final = w[-1].copy()
        self.dim = w.shape[1]
        segments, s, k = [], 0.0, len(d)
        for i in range(k):
            segments.append((s, s + d[i], w[i], w[i + 1], True))
            s += d[i]
            if i < k - 1 and self.pause > 0.0:
                segments.append((s, s + self.pause, w[i + 1], w[i + 1], False))
                s += self.pause
        self.segments, self.duration = segments, s
        self.starts = [seg[0] for seg in segments]

    def snap(self, t: float) -> float:
        """t moved onto a breakpoint within the snap tolerance."""
        b = self.breaks
        k = bisect.bisect_left(b, t)
        for j in (k - 1, k):
            if 0 <= j < len(b) and abs(b[j] - t) <= self.tol:
                return b[j]
        return t

    def lspb(self, x0, x1, T, t):
        dx = x1 - x0
        t = min(max(t, 0.0), T)
        V = self.cf * dx / T
        tb = T - T / self.cf
        a = V / tb
        if t < tb:
            return x0 + 0.5 * a * t * t, a * t, a.copy()
        if t <= T - tb:
            return x0 + 0.5 * a * tb * tb + V * (t - tb), V.copy(), np.zeros_like(dx)
        r = T - t
        return x0 + dx - 0.5 * a * r * r, a * r, -a

    def evaluate(self, t: float):
        """(x, xd, xdd) at t (fresh arrays) and the gripper (bool), at a breakpoint within the snap
        tolerance, as robofmu's sampled block evaluates it."""
        t = self.snap(float(t))
        grip = t >= self.close and not (t >= self.open and self.open > self.close)
        if t >= self.duration:
            return self.final.copy(), np.zeros(self.dim), np.zeros(self.dim), grip
        i = max(bisect.bisect_right(self.starts, t) - 1, 0)
        start, end, x0, x1, move = self.segments[i]
        if not move:
            return x0.copy(), np.zeros(self.dim), np.zeros(self.dim), grip
        x, xd, xdd = self.lspb(x0, x1, end - start, t - start)
        return x, xd, xdd, grip


def pitch_elbow_position(ik: dict, x) -> np.ndarray:
    """q (rad) placing the tcp at ``x`` (m) with the tool pitch held; ``ik``: the spec's ``ik``
    numbers (a1..a4, tool_pitch, elbow_sign). Raises Unreachable."""
    a1, a2, a3, a4 = (float(ik[k]) for k in ("a1", "a2", "a3", "a4"))
    phi, sign = float(ik["tool_pitch"]), float(ik["elbow_sign"])
    px, py, pz = float(x[0]), float(x[1]), float(x[2])
    p = math.hypot(px, py)
    if p < AXIS_TOLERANCE:
        raise Unreachable(f"target {x} lies on the base axis")
    pw = p - a4 * math.cos(phi)
    r = pz - a4 * math.sin(phi) - a1
    d = math.hypot(pw, r)
    c = (a2 ** 2 + d * d - a3 ** 2) / (2.0 * a2 * d) if d > 0 else 2.0
    if not abs(c) < 1.0 - 1e-12:
        raise Unreachable(f"target {x} is out of reach")
    q2 = math.atan2(r, pw) + sign * math.acos(c)
    q23 = math.atan2(r - a2 * math.sin(q2), pw - a2 * math.cos(q2))
    return np.array([math.atan2(py, px), q2, q23 - q2, phi - q23])

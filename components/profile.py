"""What every reference profile is: :class:`Profile` (``dim``, ``breakpoints``,
``evaluate``), how a sampled profile lands on its breakpoints (:func:`snap_to`), and the checks
its parameters share, whose messages name the parameter."""
from __future__ import annotations

from bisect import bisect_left

import numpy as np


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


def finite_vector(value, name: str, length: int | None = None) -> np.ndarray:
    """``value`` as a float vector of ``length`` values (any length: None), every one finite."""
    v = np.asarray(value, dtype=float)
    if v.ndim != 1 or (length is not None and v.shape[0] != length):
        raise ValueError(f"{name}: need {length or 'a vector of'} values, got shape {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name}: every value must be finite, got {v.tolist()}")
    return v


def positive(value: float, name: str, unit: str) -> float:
    """``value`` as a float, finite and > 0 (``unit`` for the message)."""
    value = float(value)
    if not (np.isfinite(value) and value > 0.0):
        raise ValueError(f"{name}: must be > 0 {unit}, got {value}")
    return value


def shown(value: float) -> str:
    """A number in a message: 6 significant digits (inf, nan as such)."""
    return f"{float(value):.6g}"


def finite(*values) -> bool:
    """Whether every number (or array) of ``values`` is finite."""
    return all(bool(np.all(np.isfinite(v))) for v in values)


class Profile:
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

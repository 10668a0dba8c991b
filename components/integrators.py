"""Fixed-step integration of x' = f(x) for a communication step split into sub-steps."""
from __future__ import annotations

import math
from typing import Callable

import numpy as np


def rk4(f: Callable[[np.ndarray], np.ndarray], x: np.ndarray, h: float, max_substep: float) -> np.ndarray:
    """Advance ``x`` by ``h`` with classical Runge-Kutta 4 in ceil(h / max_substep) equal sub-steps.

    Global error O(substep^4): halving ``max_substep`` shrinks it about 16-fold.
    """
    n = max(1, math.ceil(h / max_substep - 1e-9))
    dt = h / n
    for _ in range(n):
        k1 = f(x)
        k2 = f(x + 0.5 * dt * k1)
        k3 = f(x + 0.5 * dt * k2)
        k4 = f(x + dt * k3)
        x = x + (dt / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return x

"""Newton-Raphson position IK for any robot model (its FK and Jacobian only).

The unknowns q (n,) solve F(q) = [fk(q) - x; C q - c] = 0, where C q = c are the joint
combinations a robot holds fixed (none for a square task; chess's tool pitch, say). One
iteration is

    q_{k+1} = q_k - alpha_k A(q_k)^-1 F(q_k),        A = dF/dq = [J(q); C]

with alpha_k = 1 (the plain method, ``step_control = "none"``) or, by default (``"damped"``),
a step that lowers phi = |F|^2 / 2 by Armijo's fraction 1e-4 of its slope: the Newton step
(at most 1 rad or 1 m long), halved up to three times, else Levenberg-Marquardt steps
(A^T A + lambda I) d = A^T F with lambda growing tenfold, which turn towards steepest descent.
Far from a root a full step may overshoot, or A be singular; near one the full step is taken and
convergence is quadratic. Damped iterates stay inside the URDF's joint limits (each step is
clipped to them); the plain method refuses a solution outside them. The iteration stops when |F| (2-norm; m for task rows, rad or m for held
combinations) is at most ``tolerance``.

A solve that cannot reach the tolerance raises :class:`Unreachable` naming why: no convergence
within ``max_iterations``, divergence of the plain method (the residual grows beyond 1e3 times
its start or leaves the floating-point range), a singular Jacobian (no solution, or a step
beyond 1e6 rad or m, where a Newton step means nothing), or a target out of reach (no step along the Newton
direction lowers the residual: a stationary point of |F| that is not a root, A^T F = 0 with
F != 0, the nearest the TCP gets).
A solution at which A is singular (condition number beyond ``max_condition``) is refused too:
the rates there are unbounded. It never returns a non-converged q.

The solver starts from ``q_guess`` (default: the robot's ``home`` configuration), or from the
start its user gives (:meth:`NewtonRaphsonIK.start_from`, warm start from the last solution).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.linalg.lapack import dgesdd as gesdd, dgetrf as getrf, dgetrs as getrs

from ..parameters import Parameter
from .base import Diagnostic, IKSolver, Unreachable

# LAPACK called directly, as numpy.linalg calls it (getrf + getrs: solve; gesdd without
# vectors: the singular values of cond): numpy.linalg's wrappers cost several times a 3 x 3.

#: A Newton step longer than this (rad, m) comes from a numerically singular Jacobian.
STEP_BOUND = 1e6
#: The plain method counts as diverging once the residual exceeds its start by this factor.
DIVERGENCE_FACTOR = 1e3
#: Longest line-search step (rad or m): a far-off start takes several bounded steps.
MAX_STEP = 1.0
#: A residual below this (m) that no step lowers is round-off, not a missed target.
ROUND_OFF = 1e-9
#: Halvings of the Newton step before damping takes over (alpha down to 1/8).
NEWTON_HALVINGS = 3
#: Levenberg-Marquardt: first lambda relative to the mean of diag(A^T A), tries (x10 each).
DAMPING_START = 1e-6
DAMPING_TRIES = 16
#: |A^T F| below this fraction of |A| |F|: a stationary point of |F| that is not a root.
STATIONARY = 1e-6
#: ... below this fraction when the iterations run out: most likely out of reach.
NEAR_STATIONARY = 1e-2
#: Armijo's sufficient-decrease fraction.
ARMIJO = 1e-4


class NewtonRaphsonIK(IKSolver):
    """Newton-Raphson on the position equations, with damped steps and joint limits.

    Parameters (declared)
    ---------------------
    q_guess : joint units, one per joint
        Start of the first solve (default: the ``home`` configuration).
    tolerance : m
        Largest residual |F| accepted as converged.
    max_iterations : int
        Newton iterations per solve (0: accept only a start that already meets the tolerance).
    step_control : {"damped", "none"}
        Damped steps (default) or the plain method.
    max_condition : 1
        A converged solution with cond(A) beyond this is at a singularity: not reachable.

    Constraint rows (joint combinations held, C q = c) are given to the constructor as
    ``constraint_rows`` (c, n) and ``constraint_values`` (c,), not as FMU parameters.
    """

    kind = "newton_raphson"
    parameters = (
        Parameter("q_guess", "Real", "", "Start of the first Newton-Raphson solve (joint units)",
                  "home", size="joints"),
        Parameter("tolerance", "Real", "m", "Largest residual |F| accepted as converged", 1e-12,
                  above=0.0),
        Parameter("max_iterations", "Integer", "", "Newton iterations allowed per solve", 20, low=0,
                  high=10000),
        Parameter("step_control", "String", "", "'damped' (Newton step halved, else "
                  "Levenberg-Marquardt) or 'none' (the plain method)", "damped", choices=("damped", "none")),
        Parameter("max_condition", "Real", "1", "Condition number of the Jacobian beyond which a "
                  "solution counts as singular", 1e6, above=1.0),
    )
    diagnostics = (
        Diagnostic("iterations", "1", "Newton iterations of the last solve"),
        Diagnostic("residual", "m", "Residual |F| (2-norm) at the end of the last solve"),
    )

    def __init__(self, robot, constraint_rows=None, constraint_values=None, **values):
        self._rows = np.zeros((0, robot.n)) if constraint_rows is None else np.atleast_2d(
            np.asarray(constraint_rows, dtype=float))
        self._targets = np.zeros(len(self._rows)) if constraint_values is None else np.asarray(
            constraint_values, dtype=float).reshape(-1)
        super().__init__(robot, **values)

    def setup(self):
        robot, values = self.robot, self.values
        if self._rows.shape[1:] != (robot.n,) or len(self._targets) != len(self._rows):
            raise ValueError(f"IK solver {self.kind!r}: constraint rows must be (c, {robot.n}) with "
                             "one value each")
        self.constraint_rows = self._rows
        self.constraint_values = self._targets
        guess = values["q_guess"]
        guess = robot.configuration(guess) if isinstance(guess, str) else np.asarray(guess, dtype=float)
        if guess.shape != (robot.n,):
            raise ValueError(f"IK solver {self.kind!r}: q_guess needs {robot.n} values, got {guess.size}")
        self.q_guess = guess
        self.tolerance = float(values["tolerance"])
        self.max_iterations = int(values["max_iterations"])
        self.damped = values["step_control"] == "damped"
        self.max_condition = float(values["max_condition"])
        self.lower, self.upper = robot.position_limits()
        self._limits = list(zip(*self.position_limits))
        if np.any(self.q_guess < self.lower) or np.any(self.q_guess > self.upper):
            raise ValueError(f"IK solver {self.kind!r}: q_guess = {self.q_guess.tolist()} lies outside "
                             "the joint limits")
        self.start = self.q_guess.copy()
        self.history: list[float] = []          # |F| per iteration of the last solve (0: the start)
        self.iterates: list[np.ndarray] = []    # q per iteration of the last solve (0: the start)

    def start_from(self, q, qd=None, qdd=None, elapsed=0.0):
        self.start = self.q_guess.copy() if q is None else np.array(q, dtype=float)

    def residual(self, q: np.ndarray, x: np.ndarray) -> np.ndarray:
        """F(q) = [fk(q) - x; C q - c], shape (n,)."""
        return np.concatenate([self.robot.fk(q) - x, self.constraint_rows @ q - self.constraint_values])

    def position(self, x):
        x = np.asarray(x, dtype=float)
        q = self.start.clip(self.lower, self.upper) if self.damped else np.array(self.start, dtype=float)
        F = self.residual(q, x)
        r = r0 = _length(F)
        self.history = [r]
        self.iterates = [q]
        iterations = 0
        try:
            while not r <= self.tolerance:
                if not math.isfinite(r) or r > DIVERGENCE_FACTOR * max(r0, self.tolerance) or not self._within(q):
                    raise Unreachable(f"Newton-Raphson diverges from q = {_show(self.start)}: after "
                                      f"{iterations} iterations q = {_show(q)}, residual {r:.3g} m "
                                      f"(from {r0:.3g} m)")
                if iterations >= self.max_iterations:
                    raise Unreachable(f"Newton-Raphson did not converge within max_iterations = "
                                      f"{self.max_iterations}: residual {r:.3g} m > tolerance "
                                      f"{self.tolerance:.3g} m{self._diagnosis(q, F, r)}")
                A = self.augmented_jacobian(q)
                step = _newton_step(A, F)
                if self.damped:
                    q, F, r = self._search(q, A, F, step, r, x)
                else:
                    if step is None:
                        raise Unreachable(f"singular Jacobian (zero slope) at q = {_show(q)} after "
                                          f"{iterations} iterations, residual {r:.3g} m")
                    q = q - step
                    F = self.residual(q, x)
                    r = _length(F)
                iterations += 1
                self.history.append(r)
                self.iterates.append(q)
            if not self._within(q):
                raise Unreachable(f"the solution q = {_show(q)} lies outside the joint limits")
            condition = _condition(self.augmented_jacobian(q))
            if not condition <= self.max_condition:
                raise Unreachable(f"the target is at a singularity: the Jacobian at the solution "
                                  f"q = {_show(q)} has condition number {condition:.3g} > max_condition "
                                  f"{self.max_condition:g}")
        finally:
            self.report["iterations"] = float(iterations)
            self.report["residual"] = r if math.isfinite(r) else float(np.finfo(float).max)
        return q

    def _diagnosis(self, q, F, r) -> str:
        """Why iterations ran out, where the numbers say: at a near-stationary point of |F| far from
        a root (|A^T F| < 1 % of |A| |F|), the target is most likely out of reach."""
        if r < ROUND_OFF or self.max_iterations == 0:
            return ""
        A = self.augmented_jacobian(q)
        if np.linalg.norm(A.T @ F) < NEAR_STATIONARY * np.linalg.norm(A, 2) * r:
            return (f"; the residual is nearly stationary there (q = {_show(q)}): the target is most "
                    "likely out of reach")
        return ""

    def _within(self, q) -> bool:
        return all(low <= v <= high for v, (low, high) in zip(q.tolist(), self._limits))   # nan: False

    def _search(self, q, A, F, step, r, x):
        """One damped step: the Newton step (length-capped), halved up to three times, else
        Levenberg-Marquardt steps (A^T A + lambda I) d = A^T F with lambda growing tenfold; the
        first that lowers phi = |F|^2 / 2 by Armijo's fraction of its slope is taken."""
        phi = 0.5 * r * r
        g = A.T @ F                                   # gradient of phi
        if step is not None:
            step = _capped(step)
            alpha = 1.0
            for _ in range(NEWTON_HALVINGS + 1):
                taken = self._try(q, alpha * step, phi, g, x)
                if taken is not None:
                    return taken
                alpha *= 0.5
        if np.linalg.norm(g) <= STATIONARY * np.linalg.norm(A, 2) * r:
            raise self._out_of_reach(x, q, r)         # F is orthogonal to every direction A can move
        H = A.T @ A
        damping = DAMPING_START * max(np.trace(H) / len(q), 1e-300)
        for _ in range(DAMPING_TRIES):
            d = _capped(np.linalg.solve(H + damping * np.eye(len(q)), g))
            taken = self._try(q, d, phi, g, x)
            if taken is not None:
                return taken
            damping *= 10.0
        raise self._out_of_reach(x, q, r)

    def _try(self, q, d, phi, g, x):
        """(q, F, r) after the step q - d if it lowers phi enough, else None."""
        q_new = (q - d).clip(self.lower, self.upper)
        F_new = self.residual(q_new, x)
        r_new = _length(F_new)
        if 0.5 * r_new * r_new <= phi - ARMIJO * float(g @ (q - q_new)):
            return q_new, F_new, r_new
        return None

    def _out_of_reach(self, x, q, r) -> Unreachable:
        if r < ROUND_OFF:
            return Unreachable(f"the residual stalls at {r:.3g} m, above the tolerance "
                               f"{self.tolerance:.3g} m (round-off): raise the tolerance")
        return Unreachable(f"target {_show(x)} is out of reach: no step lowers the residual below "
                           f"{r:.6g} m (the nearest the task point gets, at q = {_show(q)})")


def _capped(step):
    longest = float(np.abs(step).max())
    return step * (MAX_STEP / longest) if longest > MAX_STEP else step


def _newton_step(A, F):
    """A^-1 F, or None where A is (numerically) singular."""
    lu, pivots, singular = getrf(A)
    if singular:                      # an exactly zero pivot: numpy.linalg.solve's LinAlgError
        return None
    step = getrs(lu, pivots, F)[0]
    if not math.isfinite(step.sum()) or not np.abs(step).max() < STEP_BOUND:
        return None
    return step


def _length(v) -> float:
    """|v| (2-norm) of a vector, as numpy.linalg.norm computes it (sqrt of v . v)."""
    return math.sqrt(v.dot(v))


def _condition(A) -> float:
    """cond(A) in the 2-norm, as numpy.linalg.cond computes it (largest over smallest singular value)."""
    s = gesdd(A, compute_uv=0)[1]
    smallest = float(s[-1])
    return float(s[0]) / smallest if smallest > 0.0 else math.inf     # singular (or nan): inf


def _show(v) -> list[float]:
    return np.round(np.asarray(v, dtype=float), 6).tolist()

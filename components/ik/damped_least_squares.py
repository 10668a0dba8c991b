"""Damped least squares IK for any task/joint ratio: pose tasks, redundant arms, joint limits.

Task error. With the task frame's position p(q), orientation R(q) (frame to world) and the target
(p*, R*), the error of the tracked rows is

    e(q) = [S_p (p(q) - p*);  S_o log3(R*^T R(q))]

(S_p: the task's world axes; S_o: the tracked axes of the frame's own orientation; log3 the SO(3)
logarithm, a rotation vector in the target frame, Pinocchio's ``log3``), with Jacobian
J_e = [S_p J_v;  S_o Jlog3(R*^T R) J_w,local] (``Jlog3``; J_v world linear rows, J_w,local the
angular rows about the frame's own axes).

Position level. The solve starts from the last solution carried forward by its rates,
q_0 = q_prev + dt qd_prev + dt^2/2 qdd_prev (the first solve from ``q_guess``), and corrects it by
damped least-squares steps dq = -J_e^T (J_e J_e^T + lambda^2 I)^-1 e, clipped to the joint
limits, until |e_p| <= ``position_tolerance`` and |e_o| <= ``orientation_tolerance``. The
corrections are minimum-norm: a redundant arm moves in the Jacobian's null space only as its
rates say, never by a jump; the start is deterministic (no restarts) and a solution never
flips branch between steps.

Rate level. With the task Jacobian J (task_rows, n) of :meth:`RobotModel.jacobian` and its
singular value decomposition J = U diag(sigma) V^T,

    qd  = J# nu + N qd_0,          nu = [S_p v*;  S_o R^T omega*]
    qdd = J# (a - Jdot qd) + N (Jdot^T J#^T (J# nu - qd_0) + d qd_0/dt),   a = [S_p a*;  S_o R^T omegad*]

J# = V diag(sigma / (sigma^2 + lambda^2)) U^T, with lambda = 0 while the smallest singular value
is at least ``singular_value`` and lambda^2 = ``damping``^2 (1 - (sigma_min / singular_value)^2)
below (bounded rates near a singularity, at the price of a task error the status reports).
N = I - V_r V_r^T (V_r: the first task_rows columns of V) projects on the null space exactly, so
the secondary motion changes no task coordinate: J N = 0. The secondary motion
qd_0 = -posture_gain (q - rest) + limit_gain (push away from a limit closer than
``limit_clearance``) and qdd_0 = d qd_0/dq qd draw a redundant arm towards its rest posture and
away from its limits (nothing for a square task: N = 0). qdd is the time derivative of qd: its
null-space part carries the turning of the null space itself (the pseudo-inverse's derivative,
dJ#/dt = -J# Jdot J# + N Jdot^T J#^T J#, for J of full row rank).

Honesty. Every solve reports, on the joints it returns: the position and orientation residuals
(2-norms of the tracked rows), the smallest margin of a joint to its limits, the smallest singular
value of J and a status: 0 converged, 1 not converged (the target is out of reach or the
iterations ran out), 2 near-singular (rates damped), 3 held at a joint limit (a joint of the
solution lies on its limit, where a correction was clipped). The solver raises
:class:`Unreachable` when the status is not 0 (the IK block then
holds its last valid solution), so an unreachable, limit-bound or near-singular target is never
passed on.
"""
from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
from scipy.linalg.lapack import dgesdd as gesdd, dgesv as gesv

from ..orientation import rotation_of
from ..parameters import Parameter
from .base import JOINT_UNIT, Diagnostic, IKSolver, Unreachable

#: Status codes (the ``status`` output).
CONVERGED, NOT_CONVERGED, NEAR_SINGULAR, AT_LIMIT = 0, 1, 2, 3
#: Damping of the position-level corrections (relative to the Jacobian's scale, 1): small, so
#: that the corrections converge quadratically away from singularities (it changes a step by
#: (1e-6 / sigma)^2 relative), large enough to keep J J^T + lambda^2 I invertible at one.
CORRECTION_DAMPING = 1e-6
#: The largest joint margin reported where no joint has a finite limit (rad or m).
NO_LIMIT_MARGIN = 1e6


class DampedLeastSquaresIK(IKSolver):
    """Damped least squares on position and pose tasks, with a null-space posture and joint limits.

    Parameters (declared)
    ---------------------
    q_guess : joint units, one per joint
        Start of the first solve (default: the ``home`` configuration).
    rest : joint units, one per joint
        The posture a redundant arm's null-space motion draws towards (default ``home``).
    position_tolerance : m
    orientation_tolerance : rad
    max_iterations : int
        Corrections per solve.
    singular_value : 1
        Smallest singular value of the task Jacobian below which the rates are damped (status 2).
    damping : 1
        The damping lambda at an exact singularity.
    posture_gain, limit_gain : 1/s
        Gains of the null-space motion towards ``rest`` and away from a joint limit.
    limit_clearance : joint units, one per joint (or one number for all)
        Distance from a joint limit inside which the null space pushes away from it.
    """

    kind = "damped_least_squares"
    square = False
    parameters = (
        Parameter("q_guess", "Real", "", "Start of the first solve (joint units)", "home", size="joints"),
        Parameter("rest", "Real", "", "Posture the null-space motion draws a redundant arm towards "
                  "(joint units)", "home", size="joints"),
        Parameter("position_tolerance", "Real", "m", "Largest position residual accepted as converged",
                  1e-12, above=0.0),
        Parameter("orientation_tolerance", "Real", "rad", "Largest orientation residual accepted as "
                  "converged", 1e-12, above=0.0),
        Parameter("max_iterations", "Integer", "", "Damped least-squares corrections allowed per solve", 20,
                  low=0, high=10000),
        Parameter("singular_value", "Real", "1", "Smallest singular value of the task Jacobian below which "
                  "the rates are damped (status 2: near a singularity)", 0.02, above=0.0),
        Parameter("damping", "Real", "1", "Damping of the rates at an exact singularity", 0.05, above=0.0),
        Parameter("posture_gain", "Real", "1/s", "Null-space motion towards the rest posture (redundant "
                  "arms)", 1.0, low=0.0),
        Parameter("limit_gain", "Real", "1/s", "Null-space motion away from a joint limit closer than "
                  "limit_clearance", 10.0, low=0.0),
        Parameter("limit_clearance", "Real", "", "Distance from the joint's limits inside which the "
                  "null-space motion pushes away from them", 0.15, low=0.0, size="joints"),
    )
    diagnostics = (
        Diagnostic("iterations", "1", "Damped least-squares corrections of the last solve"),
        Diagnostic("position_residual", "m", "Position error |S_p (p - p_ref)| of the returned joints"),
        Diagnostic("orientation_residual", "rad", "Orientation error |S_o log3(R_ref^T R)| of the "
                   "returned joints"),
        Diagnostic("joint_limit_margin", JOINT_UNIT, "Smallest distance of a returned joint to its limits"),
        Diagnostic("smallest_singular_value", "1", "Smallest singular value of the task Jacobian at the "
                   "returned joints"),
        Diagnostic("status", "1", "0 converged, 1 not converged (out of reach?), 2 near a singularity, "
                   "3 at a joint limit"),
    )

    def setup(self):
        robot, values = self.robot, self.values
        n = robot.n
        self.q_guess = self._configuration("q_guess")
        self.rest = self._configuration("rest")
        self.position_tolerance = float(values["position_tolerance"])
        self.orientation_tolerance = float(values["orientation_tolerance"])
        self.max_iterations = int(values["max_iterations"])
        self.singular_value = float(values["singular_value"])
        self.damping = float(values["damping"])
        self.posture_gain = float(values["posture_gain"])
        self.limit_gain = float(values["limit_gain"])
        self.clearance = self._configuration("limit_clearance")
        self.lower, self.upper = robot.position_limits()
        if np.any(self.q_guess < self.lower) or np.any(self.q_guess > self.upper):
            raise ValueError(f"IK solver {self.kind!r}: q_guess = {self.q_guess.tolist()} lies outside "
                             "the joint limits")
        self._limited = np.isfinite(self.lower) | np.isfinite(self.upper)
        self.m = robot.m
        self.rows = robot.task_rows
        self._position_rows = list(robot.description.task.axes)
        self._orientation_rows = list(robot.orientation_axes)
        self._pose = bool(self._orientation_rows)
        if self.rows > n:
            raise ValueError(f"IK solver {self.kind!r}: {self.rows} task rows for {n} joints: more task "
                             "coordinates than joints cannot all be tracked")
        task_rows = self._position_rows + [3 + axis for axis in self._orientation_rows]
        self._task_rows = slice(0, 6) if task_rows == list(range(6)) else task_rows     # a view where it can
        self._all_orientation = slice(0, 3) if self._orientation_rows == [0, 1, 2] else self._orientation_rows
        self._posture_slope = np.full(n, -self.posture_gain)
        self._target_rotation = np.eye(3)
        self._error = np.empty(self.rows)                # buffers of error(), consumed before its next call
        self._error_jacobian = np.empty((self.rows, n))
        self._angular = np.empty((3, n))
        self.start = self.q_guess.copy()

    def _configuration(self, name: str) -> np.ndarray:
        value = self.values[name]
        value = self.robot.configuration(value) if isinstance(value, str) else np.asarray(value, dtype=float)
        if value.size == 1:                              # one number: the same for every joint
            value = np.full(self.robot.n, float(value.reshape(-1)[0]))
        if value.shape != (self.robot.n,):
            raise ValueError(f"IK solver {self.kind!r}: {name} needs {self.robot.n} values, got {value.size}")
        return value

    def start_from(self, q, qd=None, qdd=None, elapsed=0.0):
        if q is None:
            self.start = self.q_guess.copy()
            return
        start = np.array(q, dtype=float)
        if qd is not None and elapsed > 0.0:
            start += elapsed * np.asarray(qd) + (0.5 * elapsed * elapsed) * np.asarray(qdd)
        self.start = start

    # -- position level ----------------------------------------------------------------------
    def error(self, q: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The tracked rows' error e(q) (task_rows,) and its Jacobian J_e (task_rows, n), for
        position target ``x`` and the orientation target of the solve: buffers, valid until the
        next call. Keeps the task Jacobian (:meth:`RobotModel.jacobian`) and the frame's
        orientation at ``q`` for the rates."""
        robot, m, e = self.robot, self.m, self._error
        if not self._pose:
            np.subtract(robot.fk(q), x, out=e)
            self._jacobian = robot.jacobian(q)
            return e, self._jacobian
        position, rotation, full = robot.kinematics(q)
        self._jacobian = full[self._task_rows]
        self._rotation = rotation
        np.subtract(position[self._position_rows], x, out=e[:m])
        relative = self._target_rotation.T @ rotation
        rows = self._all_orientation
        e[m:] = pin.log3(relative)[rows]
        J = self._error_jacobian
        J[:m] = self._jacobian[:m]
        np.dot(pin.Jlog3(relative), full[3:], out=self._angular)
        J[m:] = self._angular[rows]
        return e, J

    def _residuals(self, e: np.ndarray) -> tuple[float, float]:
        values = e.tolist()
        m = self.m
        return (math.sqrt(sum(v * v for v in values[:m])), math.sqrt(sum(v * v for v in values[m:])))

    def position(self, x, quaternion=None):
        """Joint positions (n,) for position target ``x`` and, for a pose task, orientation target
        ``quaternion`` (x, y, z, w; default: the last one given), with ``self.at_limit`` and
        ``self.report`` filled in. It raises nothing: the report says how good the result is."""
        if quaternion is not None and self._pose:
            self._target_rotation = rotation_of(quaternion)
        lower, upper = self.lower, self.upper
        q = np.minimum(np.maximum(self.start, lower), upper)
        e, J = self.error(q, x)
        position, orientation = self._residuals(e)
        iterations = 0
        while not (position <= self.position_tolerance and orientation <= self.orientation_tolerance) \
                and iterations < self.max_iterations:
            scale = max(1.0, float(np.abs(J).max()))
            normal = J @ J.T
            normal.flat[::self.rows + 1] += (CORRECTION_DAMPING * scale) ** 2
            step = J.T @ gesv(normal, e)[2]
            if not math.isfinite(float(step.sum())):
                break                                   # no finite correction: not converged
            q -= step
            np.maximum(q, lower, out=q)
            np.minimum(q, upper, out=q)
            iterations += 1
            e, J = self.error(q, x)
            position, orientation = self._residuals(e)
        self.at_limit = bool((q == lower).any() or (q == upper).any())
        self.report["iterations"] = float(iterations)
        self.report["position_residual"] = position
        self.report["orientation_residual"] = orientation
        self._converged_now = position <= self.position_tolerance and orientation <= self.orientation_tolerance
        return q

    # -- rate level ----------------------------------------------------------------------------
    def secondary(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The null-space motion qd_0 (n,) and its derivative d qd_0 / dq, a diagonal (n,)."""
        qd0 = self.posture_gain * (self.rest - q)
        if self.limit_gain == 0.0:
            return qd0, self._posture_slope
        low = q - self.lower - self.clearance            # < 0: inside the lower zone
        high = self.upper - q - self.clearance           # < 0: inside the upper zone
        qd0 += self.limit_gain * (np.minimum(high, 0.0) - np.minimum(low, 0.0))
        return qd0, self._posture_slope - self.limit_gain * ((low < 0.0) | (high < 0.0))

    def solve(self, x, xd, xdd, quaternion=None, omega=None, omegad=None):
        robot, m, rows = self.robot, self.m, self.rows
        for name in ("joint_limit_margin", "smallest_singular_value"):
            self.report[name] = 0.0
        self.report["status"] = float(NOT_CONVERGED)
        q = self.position(np.asarray(x, dtype=float), quaternion)
        U, sigma, Vt, _ = gesdd(self._jacobian, compute_uv=1, full_matrices=1)     # at q (position())
        smallest = float(sigma[-1])
        damping2 = 0.0
        if smallest < self.singular_value:
            damping2 = self.damping ** 2 * (1.0 - (smallest / self.singular_value) ** 2)
        range_ = Vt[:rows]
        inverse = (range_.T * (sigma / (sigma * sigma + damping2))) @ U.T          # J#
        nu = np.empty(rows)
        a = np.empty(rows)
        nu[:m] = xd
        a[:m] = xdd
        if self._pose:
            local = self._rotation.T[self._all_orientation]                            # S_o R^T
            nu[m:] = local @ omega
            a[m:] = local @ omegad
        qd = inverse @ nu
        if rows == robot.n:
            qdd = inverse @ (a - robot.jdot_qdot(q, qd))
        else:                                            # N = I - V_r V_r^T: the null space of J
            qd0, slope = self.secondary(q)
            qd += qd0 - range_.T @ (range_ @ qd0)
            derivative = robot.jacobian_derivative(q, qd)
            qdd = inverse @ (a - derivative @ qd)
            # the null-space part of d/dt (J# nu + N qd_0): N (dJ^T J#^T (J# nu - qd_0) + d qd_0/dt)
            z = derivative.T @ (inverse.T @ (inverse @ nu - qd0)) + slope * qd
            qdd += z - range_.T @ (range_ @ z)
        margins = np.minimum(q - self.lower, self.upper - q)[self._limited]
        self.report["joint_limit_margin"] = float(margins.min()) if margins.size else NO_LIMIT_MARGIN
        self.report["smallest_singular_value"] = smallest
        status = (NOT_CONVERGED if not self._converged_now else AT_LIMIT if self.at_limit
                  else NEAR_SINGULAR if damping2 > 0.0 else CONVERGED)
        self.report["status"] = float(status)
        if not math.isfinite(float(qd.sum() + qdd.sum())):
            self.report["status"] = float(NOT_CONVERGED)
            raise Unreachable(f"the rates are not finite at q = {np.round(q, 6).tolist()}")
        if status != CONVERGED:
            raise Unreachable(self._why(status, q))
        return q, qd, qdd

    def _why(self, status: int, q: np.ndarray) -> str:
        r = self.report
        where = f"at q = {np.round(q, 6).tolist()}"
        held = ""
        if self.at_limit:
            j = int(np.flatnonzero((q == self.lower) | (q == self.upper))[0])
            side = "lower" if q[j] == self.lower[j] else "upper"
            held = (f"joint {j + 1} ({self.robot.joint_names[j]}) is held at its {side} limit "
                    f"{q[j]:.6g} {self.robot.joint_units(0)[j]}")
        if status == NOT_CONVERGED:
            return (f"not converged within max_iterations = {self.max_iterations}: position residual "
                    f"{r['position_residual']:.3g} m, orientation residual {r['orientation_residual']:.3g} rad "
                    f"{where} " + (f"({held}: the target lies beyond the joint limits or out of reach)" if held
                                   else "(the target is most likely out of reach)"))
        if status == AT_LIMIT:
            return f"{held} {where}: the target is reached only on the limit"
        return (f"near a singularity: smallest singular value of the Jacobian "
                f"{r['smallest_singular_value']:.3g} < singular_value {self.singular_value:g} {where}")

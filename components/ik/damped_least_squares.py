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
the secondary motion changes no task coordinate: J N = 0. Clear of the threshold (sigma_min at
least ``CLEAR`` singular_value, sigma_min^2 the smallest eigenvalue of J J^T), the same J# and N
come without the singular vectors: J# = J^T (J J^T)^-1 (by Cholesky; J^-1 by LU for a square task)
and V_r V_r^T = J# J; only near a singularity is J decomposed in full. The secondary motion
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
from operator import mul

import numpy as np
import pinocchio as pin
from scipy.linalg.lapack import dgesdd as gesdd, dgesv as gesv, dposv as posv, dsyev as syev

from ..floats import FloatWriter
from ..orientation import rotation_of
from ..parameters import Parameter
from .base import JOINT_UNIT, Diagnostic, IKSolver, RatesOverflow, Unreachable

#: Status codes (the ``status`` output).
CONVERGED, NOT_CONVERGED, NEAR_SINGULAR, AT_LIMIT = 0, 1, 2, 3
#: Damping of the position-level corrections (relative to the Jacobian's scale, 1): small, so
#: that the corrections converge quadratically away from singularities (it changes a step by
#: (1e-6 / sigma)^2 relative), large enough to keep J J^T + lambda^2 I invertible at one.
CORRECTION_DAMPING = 1e-6
#: The largest joint margin reported where no joint has a finite limit (rad or m).
NO_LIMIT_MARGIN = 1e6
#: Where the smallest singular value, from the eigenvalues of J J^T, is at least CLEAR times
#: ``singular_value``, the rates need no singular vectors; its relative error there is
#: ~eps (sigma_max / sigma_min)^2: at most ~3e-13 for the arms (sigma_max ~2, sigma_min >= 0.04),
#: ~1e-14 along their paths. Closer to a singularity the full SVD gives sigma_min (to
#: ~eps sigma_max / sigma_min) and the damped rates.
CLEAR = 2.0
#: A joint farther than this (rad or m) inside limit_clearance of both its limits is outside both
#: zones of the null-space push whatever the rounding of q - lower - clearance (a few 1e-16).
FREE_MARGIN = 1e-9


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
        limited = np.flatnonzero(np.isfinite(self.lower) | np.isfinite(self.upper)).tolist()
        # (lower, upper) of each joint with a limit, as floats: the margins are taken in floats
        self._limited = [(float(self.lower[j]), float(self.upper[j]), j) for j in limited]
        self.m = robot.m
        self.task_rows = robot.task_rows
        self._index = robot.task_index
        if self._index is None:
            raise ValueError(f"IK solver {self.kind!r}: robot {robot.description.name!r} has no task frame "
                             "(its task coordinates are its mechanism's own); give it a closed-form IK")
        self._pose = bool(self._index.orientation)
        if self.task_rows > n:
            raise ValueError(f"IK solver {self.kind!r}: {self.task_rows} task rows for {n} joints: more task "
                             "coordinates than joints cannot all be tracked")
        self._posture_slope = np.full(n, -self.posture_gain)
        self._bounds = list(zip(self.lower.tolist(), self.upper.tolist()))          # per joint, as floats
        # the null-space motion's bounds per joint, as floats: (rest, lower, upper, clearance), and
        # where a joint lies certainly outside both zones (by far more than rounding: 1e-9)
        self._rest = self.rest.tolist()
        self._zones = list(zip(self._rest, self.lower.tolist(), self.upper.tolist(), self.clearance.tolist()))
        self._free = [(lower + clearance + FREE_MARGIN, upper - clearance - FREE_MARGIN)
                      for _, lower, upper, clearance in self._zones]
        self._target_rotation = np.eye(3)
        self._target_quaternion = [0.0, 0.0, 0.0, 1.0]
        # Buffers, each consumed within the call that fills it (the arrays returned are new)
        self._identity = np.eye(n)
        self._null = np.empty((n, n))
        self._je = np.empty((self.task_rows, n))
        self._angular = np.empty((3, n))
        self._normal = np.empty((self.task_rows, self.task_rows))
        self._normal_diagonal = self._normal.reshape(-1)[::self.task_rows + 1]            # a view
        self._gains = np.empty(self.task_rows)
        self._scaled = np.empty((n, self.task_rows))
        self._inverse = np.empty((n, self.task_rows))
        self._nu = np.empty(self.task_rows)                    # [xd; S_o R^T omega]
        self._a = np.empty(self.task_rows)                     # [xdd; S_o R^T omegad], then minus Jdot qd
        self._task_parts = (self._nu[:self.m], self._a[:self.m], self._nu[self.m:], self._a[self.m:])
        self._qd0 = np.empty(n)
        self._slope = np.empty(n)
        self._write_qd0, self._write_slope = FloatWriter(self._qd0), FloatWriter(self._slope)
        self.start = self.q_guess.tolist()

    def _configuration(self, name: str) -> np.ndarray:
        value = self.values[name]
        value = self.robot.configuration(value) if isinstance(value, str) else np.asarray(value, dtype=float)
        if value.size == 1:                              # one number: the same for every joint
            value = np.full(self.robot.n, float(value.reshape(-1)[0]))
        if value.shape != (self.robot.n,):
            raise ValueError(f"IK solver {self.kind!r}: {name} needs {self.robot.n} values, got {value.size}")
        return value

    def start_from(self, q, qd=None, qdd=None, elapsed=0.0):
        """The start of the next solve (``self.start``, floats): ``q_guess`` if ``q`` is None, else
        q + (elapsed qd + elapsed^2/2 qdd) (``q`` where no rates are given), clipped to the limits."""
        if q is None:
            self.start = self.q_guess.tolist()
            return
        q = np.asarray(q, dtype=float).tolist()
        if qd is None or not elapsed > 0.0:
            self.start = [min(max(p, low), high) for p, (low, high) in zip(q, self._bounds)]
            return
        half = 0.5 * elapsed * elapsed
        self.start = [min(max(p + (elapsed * v + half * a), low), high) for p, v, a, (low, high) in
                      zip(q, np.asarray(qd, dtype=float).tolist(), np.asarray(qdd, dtype=float).tolist(),
                          self._bounds)]

    # -- position level ----------------------------------------------------------------------
    def _evaluate(self, q: np.ndarray, x: list[float]) -> tuple[float, float]:
        """The residuals (position, orientation) of the tracked rows' error e(q) for position
        target ``x`` and the orientation target of the solve. Keeps e (floats), the task Jacobian
        (:meth:`RobotModel.jacobian`) and the frame's orientation at ``q`` for the corrections
        (:meth:`_error_jacobian`) and the rates."""
        robot, m = self.robot, self.m
        if not self._pose:
            e = [p - target for p, target in zip(robot.fk(q).tolist(), x)]
            self._jacobian = robot.jacobian(q)
        else:
            position, rotation, full = robot.kinematics(q)
            self._full = full
            self._jacobian = full[self._index.six]
            self._rotation = rotation
            self._relative = self._target_rotation.T.dot(rotation)
            p, log = position.tolist(), pin.log3(self._relative).tolist()
            e = [p[i] - target for i, target in zip(self._index.position, x)]
            e += [log[i] for i in self._index.orientation]
        self._e = e
        position, orientation = e[:m], e[m:]
        return math.sqrt(sum(map(mul, position, position))), math.sqrt(sum(map(mul, orientation, orientation)))

    def _error_jacobian(self) -> np.ndarray:
        """J_e (task_rows, n) at the joints of the last :meth:`_evaluate`: a buffer for a pose task."""
        if not self._pose:
            return self._jacobian
        J, m, angular = self._je, self.m, self._index.angular
        J[:m] = self._jacobian[:m]
        if angular == slice(0, 3):
            np.dot(pin.Jlog3(self._relative), self._full[3:], out=J[m:])
        else:
            np.dot(pin.Jlog3(self._relative), self._full[3:], out=self._angular)
            J[m:] = self._angular[angular]
        return J

    def position(self, x, quaternion=None):
        """Joint positions (n,) for position target ``x`` and, for a pose task, orientation target
        ``quaternion`` (x, y, z, w; default: the last one given), with ``self.at_limit`` and
        ``self.report`` filled in. It raises nothing: the report says how good the result is."""
        if quaternion is not None and self._pose:
            target = np.asarray(quaternion, dtype=float).tolist()
            if target != self._target_quaternion:        # the rotation of an unchanged target is kept
                self._target_rotation = rotation_of(target)
                self._target_quaternion = target
        x = np.asarray(x, dtype=float).tolist()
        bounds, values = self._bounds, self.start       # the joints in floats, within their limits
        q = np.array(values)
        position, orientation = self._evaluate(q, x)
        iterations = 0
        normal, diagonal = self._normal, self._normal_diagonal      # diagonal: a view of normal's
        while not (position <= self.position_tolerance and orientation <= self.orientation_tolerance) \
                and iterations < self.max_iterations:
            J = self._error_jacobian()
            scale = max(1.0, max(map(abs, J.ravel().tolist())))       # the largest |J_ij|, at least 1
            np.dot(J, J.T, out=normal)
            np.add(diagonal, (CORRECTION_DAMPING * scale) ** 2, out=diagonal)
            step = J.T.dot(gesv(normal, self._e)[2]).tolist()
            if not math.isfinite(sum(step)):
                break                                   # no finite correction: not converged
            values = [min(max(v - dv, low), high) for v, dv, (low, high) in zip(values, step, bounds)]
            q = np.array(values)
            iterations += 1
            position, orientation = self._evaluate(q, x)
        margins = [min(values[j] - low, high - values[j]) for low, high, j in self._limited]
        self._margin = min(margins) if margins else NO_LIMIT_MARGIN
        self.at_limit = 0.0 in margins          # q lies within its limits: a margin is 0 exactly on one
        self.report["iterations"] = float(iterations)
        self.report["position_residual"] = position
        self.report["orientation_residual"] = orientation
        self._converged_now = position <= self.position_tolerance and orientation <= self.orientation_tolerance
        return q

    # -- rate level ----------------------------------------------------------------------------
    def secondary(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The null-space motion qd_0 (n,) and its derivative d qd_0 / dq, a diagonal (n,):
        buffers, valid until the next call."""
        posture, push = self.posture_gain, self.limit_gain
        values = q.tolist()
        if push == 0.0 or all(low < v < high for v, (low, high) in zip(values, self._free)):
            self._write_qd0([posture * (rest - v) for v, rest in zip(values, self._rest)])
            return self._qd0, self._posture_slope
        qd0, inside = [], []
        for v, (rest, lower, upper, clearance) in zip(values, self._zones):
            low = v - lower - clearance                 # < 0: inside the lower zone
            high = upper - v - clearance                # < 0: inside the upper zone
            zone = push != 0.0 and (low < 0.0 or high < 0.0)
            qd0.append(posture * (rest - v) + push * (min(high, 0.0) - min(low, 0.0)) if zone
                       else posture * (rest - v))
            inside.append(zone)
        self._write_qd0(qd0)
        if not any(inside):
            return self._qd0, self._posture_slope
        self._write_slope([-posture - push if zone else -posture for zone in inside])
        return self._qd0, self._slope

    def solve(self, x, xd, xdd, quaternion=None, omega=None, omegad=None):
        robot, task_rows, report = self.robot, self.task_rows, self.report
        report["joint_limit_margin"] = report["smallest_singular_value"] = 0.0
        report["status"] = float(NOT_CONVERGED)
        q = self.position(x, quaternion)
        J = self._jacobian                               # at q (position())
        gram = J.dot(J.T)                                # J J^T: its eigenvalues are sigma^2
        eigenvalues, _, info = syev(gram, compute_v=0)
        smallest = math.sqrt(max(float(eigenvalues[0]), 0.0)) if info == 0 else 0.0
        damping2 = 0.0
        if smallest >= CLEAR * self.singular_value:      # full row rank, undamped: J# = J^T (J J^T)^-1
            inverse = gesv(J, self._identity)[2] if task_rows == robot.n else posv(gram, J)[1].T
            row_space = inverse, J                       # V_r V_r^T = J# J
        else:                                            # near (or at) a singularity: the full SVD
            U, sigma, Vt, _ = gesdd(J, compute_uv=1, full_matrices=1)
            smallest = float(sigma[-1])
            if smallest < self.singular_value:
                damping2 = self.damping ** 2 * (1.0 - (smallest / self.singular_value) ** 2)
            range_ = Vt[:task_rows]
            gains = np.multiply(sigma, sigma, out=self._gains)                    # sigma / (sigma^2 + lambda^2)
            gains += damping2
            np.divide(sigma, gains, out=gains)
            inverse = np.dot(np.multiply(range_.T, gains, out=self._scaled), U.T, out=self._inverse)   # J#
            row_space = range_.T, range_
        nu, a = self._nu, self._a
        nu_task, a_task, nu_angular, a_angular = self._task_parts
        nu_task[:] = xd
        a_task[:] = xdd
        if self._pose:
            local = self._rotation.T[self._index.angular]                            # S_o R^T
            np.dot(local, omega, out=nu_angular)
            np.dot(local, omegad, out=a_angular)
        qd = inverse.dot(nu)
        if task_rows == robot.n:
            qdd = inverse.dot(np.subtract(a, robot.jdot_qdot(q, qd), out=a))
        else:
            left, right = row_space                      # N = I - V_r V_r^T: the null space of J
            null = np.subtract(self._identity, left.dot(right), out=self._null)
            qd_task = qd
            qd0, slope = self.secondary(q)
            qd = qd_task + null.dot(qd0)
            derivative = robot.jacobian_derivative(q, qd)
            qdd = inverse.dot(np.subtract(a, derivative.dot(qd), out=a))
            # the null-space part of d/dt (J# nu + N qd_0): N (dJ^T J#^T (J# nu - qd_0) + d qd_0/dt)
            z = derivative.T.dot(inverse.T.dot(qd_task - qd0))
            z += slope * qd
            qdd += null.dot(z)
        report["joint_limit_margin"] = self._margin
        report["smallest_singular_value"] = smallest
        status = (NOT_CONVERGED if not self._converged_now else AT_LIMIT if self.at_limit
                  else NEAR_SINGULAR if damping2 > 0.0 else CONVERGED)
        report["status"] = float(status)
        if not math.isfinite(sum(qd.tolist()) + sum(qdd.tolist())):
            report["status"] = float(NOT_CONVERGED)
            raise RatesOverflow(f"the rates are not finite at q = {np.round(q, 6).tolist()}", q)
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


"""IK block: joint reference (q, qd, qdd) from the task-space reference, direct feedthrough.

The solver is the one the robot's description names; its declared parameters become the
block's. A target whose joint rates exceed ``qd_limit`` (default: the URDF's velocity limits)
counts as not reachable: the warning says "velocity limit" and names the task-rate input that
drives the fastest joint (``xd_ref[1]``) where the Jacobian is well-conditioned (condition number
at most :data:`SINGULAR_CONDITION`), "too close to a singularity" where it is not. Outside the
workspace (or at a singularity) ``reachable`` is false, one warning is logged per excursion, and
the block holds its last valid position with zero velocity and acceleration (zeros before it has
one).

An iterative solver (Newton-Raphson, damped least squares) starts each communication step from
the solution of the last completed step (warm start, carried forward by its rates where the solver
predicts; the first from its ``q_guess``), so that the outputs at a communication point depend on
the inputs and the state at the step's start only, however often they are evaluated. Its
diagnostics (``iterations``, ``residual``, ...) are outputs too.

A pose task (the robot's ``[task] orientation_axes``) adds the inputs ``quat_ref[1..4]``, the
target orientation of the task frame as a unit quaternion in the order (x, y, z, w) (scalar last,
frame to world; normalised; one whose norm is not 1 within 1e-6 is refused naming ``quat_ref``
and its norm, as a non-finite input is: outputs held, the next step fails), ``omega_ref[1..3]`` and
``omegad_ref[1..3]``, its angular velocity (rad/s) and acceleration (rad/s^2) in the world frame.
"""
from __future__ import annotations

import numpy as np

from ..orientation import UNIT_TOLERANCE, NotUnitQuaternion, quaternion_of
from ..ik import JOINT_UNIT, RatesOverflow, Unreachable, solver_class
from .base import Block, vector_names


#: qd_limit's start for a joint without a velocity limit (rad/s, m/s): a parameter is finite.
NO_RATE_LIMIT = 1e12
#: Rates beyond qd_limit where the Jacobian's condition number (largest over smallest singular
#: value of the matrix the rates are solved with: A = [J; C] of a square solver, J otherwise)
#: exceeds this are blamed on a singularity; below, on a task motion too fast for the joints.
#: (The arms' condition numbers at home are 3 to 11; the damped least-squares solver's default
#: singular_value, 0.02, is a condition number of about 90 on the arms.)
SINGULAR_CONDITION = 100.0


class IKBlock(Block):
    kind = "ik"
    feedthrough = True
    summary = ("inverse kinematics at position, velocity and acceleration level (qd = A^-1 xd, "
               "qdd = A^-1 (xdd - Jdot qd)); direct feedthrough")

    def declare(self):
        choice = self.description.ik
        if choice is None:
            self.table_error("ik", "solver", "the robot has no [ik] table")
        try:
            self.solver_type = solver_class(choice.kind)
        except ValueError as exc:
            self.table_error("ik", "solver", str(exc))
        values = self.table_values("ik", self.solver_type.parameters, choice.parameters)
        robot = self.robot
        for p in self.solver_type.parameters:
            if p.size is None:
                self.declare_parameter(p, values[p.name])
                continue
            start = values[p.name]
            if isinstance(start, str):
                if start not in self.description.configurations:
                    self.table_error("ik", p.name, f"no configuration {start!r} (described: "
                                     f"{', '.join(self.description.configurations)})")
                start = robot.configuration(start)
            if len(start) == 1:                  # one number: the same for every joint
                start = [start[0]] * robot.n
            if len(start) != robot.n:
                self.table_error("ik", p.name, f"needs {robot.n} values (one per joint), got {len(start)}")
            self.reals(p.name, robot.n, "parameter", robot.joint_units(0),
                       lambda i, p=p: f"{p.description}, joint {i}", starts=start)
        self.reals("qd_limit", robot.n, "parameter", robot.joint_units(1),
                   "Joint {i}: the largest rate the IK passes on (default: the URDF's velocity limit); "
                   "a target needing more counts as not reachable (a velocity limit, or a singularity)",
                   starts=np.minimum(robot.velocity_limits(), NO_RATE_LIMIT))
        coords, m, n = robot.task_coordinates, robot.m, robot.n
        start = robot.fk(robot.configuration("home"))
        xs, xds, xdds = (vector_names(b, m) for b in ("x_ref", "xd_ref", "xdd_ref"))
        self.x = self.reals("x_ref", m, "input", robot.task_units(0),
                            lambda i: f"Target task coordinate {coords[i - 1]}", starts=start)
        self.xd = self.reals("xd_ref", m, "input", robot.task_units(1),
                             lambda i: f"Target task velocity along {coords[i - 1]}")
        self.xdd = self.reals("xdd_ref", m, "input", robot.task_units(2),
                              lambda i: f"Target task acceleration along {coords[i - 1]}")
        if robot.orientation_axes:
            frame = self.description.task.frame
            self.quaternion = self.reals("quat_ref", 4, "input", "1",
                                         lambda i: f"Target orientation of frame {frame}: unit quaternion "
                                                   f"component {'xyzw'[i - 1]} (x, y, z, w; frame to world)",
                                         starts=quaternion_of(robot.rotation(robot.configuration("home"))))
            self.omega = self.reals("omega_ref", 3, "input", "rad/s",
                                    lambda i: f"Target angular velocity of frame {frame} about world axis "
                                              f"{'xyz'[i - 1]}")
            self.omegad = self.reals("omegad_ref", 3, "input", "rad/s2",
                                     lambda i: f"Target angular acceleration of frame {frame} about world axis "
                                               f"{'xyz'[i - 1]}")
            xs = xs + vector_names("quat_ref", 4)
            xds = xds + vector_names("omega_ref", 3)
            xdds = xdds + vector_names("omegad_ref", 3)
        self.q = self.reals("q_ref", n, "output", robot.joint_units(0), "Joint {i} reference position",
                            depends=xs)
        self.qd = self.reals("qd_ref", n, "output", robot.joint_units(1), "Joint {i} reference velocity",
                             depends=xs + xds)
        self.qdd = self.reals("qdd_ref", n, "output", robot.joint_units(2),
                              "Joint {i} reference acceleration", depends=xs + xds + xdds)
        self.reachable = self.boolean("reachable", "output", "False while the target lies outside the "
                                      "workspace or at a singularity (last valid solution held)", depends=xs)
        joints = set(robot.joint_units(0))
        joint_unit = joints.pop() if len(joints) == 1 else "1"      # a diagnostic in joint units
        self.diagnostics = [(d.name, self.real(d.name, "output", joint_unit if d.unit == JOINT_UNIT else d.unit,
                                               d.description, depends=xs))
                            for d in self.solver_type.diagnostics]
        self.last = None          # last valid joint position, velocity and acceleration
        self.committed = None     # the last valid solution at the end of the last completed step
        self.elapsed = 0.0        # the last completed step's size (s): how far to carry it forward
        self.outside = False      # in an excursion (warned once per excursion)
        self.reason = ""          # why the last target was not reachable

    def configure(self):
        values = {p.name: self.parameter(p.name) if p.size is None else tuple(self.finite_vector(p.name))
                  for p in self.solver_type.parameters}
        self.solver = self.solver_type(self.robot, **values)
        self.qd_limit = self.finite_vector("qd_limit", above=0.0)
        self.last = None
        self.committed = None
        self.elapsed = 0.0
        self.outside = False
        v = self.values                          # views, made once (the values array is never replaced)
        self._targets = (v[self.x], v[self.xd], v[self.xdd])
        if self.robot.orientation_axes:
            self._targets += (v[self.quaternion], v[self.omega], v[self.omegad])
        self._outputs = (v[self.q], v[self.qd], v[self.qdd])
        self._limits = self.qd_limit.tolist()
        super().configure()

    def output(self, t):
        v = self.values
        if self.committed is None:
            self.solver.start_from(None)
        else:
            self.solver.start_from(*self.committed, self.elapsed)
        try:
            try:
                q, qd, qdd = self.solver.solve(*self._targets)
            finally:
                for name, k in self.diagnostics:
                    v[k] = self.solver.report[name]
            for rate, limit in zip(qd.tolist(), self._limits):
                if abs(rate) > limit:
                    raise Unreachable(self._too_fast(q, qd))
        except NotUnitQuaternion as exc:
            shown = ", ".join(f"{c:.9g}" for c in exc.quaternion)
            raise ValueError(f"input quat_ref = ({shown}) has norm {exc.norm:.9g}, not 1: the target "
                             f"orientation must be a unit quaternion (x, y, z, w), its norm within "
                             f"{UNIT_TOLERANCE:g} of 1") from None
        except Unreachable as exc:
            if isinstance(exc, RatesOverflow):
                exc = self._overflow(exc)
            self.reason = str(exc)
            if not self.outside:
                held = ("holding the last valid solution" if self.last is not None else
                        "no valid solution yet: outputs zero")
                self.warn(f"t = {t:.9g} s: {exc}; {held}")
                self.outside = True
            v[self.reachable] = 0.0
            v[self.q] = 0.0 if self.last is None else self.last[0]
            v[self.qd] = 0.0
            v[self.qdd] = 0.0
            return
        v[self.reachable] = 1.0
        self.outside = False
        self.last = (q, qd, qdd)
        q_out, qd_out, qdd_out = self._outputs
        q_out[:], qd_out[:], qdd_out[:] = q, qd, qdd

    def _conditioning(self, q: np.ndarray) -> tuple[float, float, np.ndarray]:
        """The condition number and smallest singular value of the matrix the rates are solved
        with at ``q`` (A = [J; C] of a square solver, J otherwise), and its pseudo-inverse
        (n, rows): the rates' map."""
        matrix = self.solver.augmented_jacobian(q) if self.solver.square else self.robot.jacobian(q)
        sigma = np.linalg.svd(matrix, compute_uv=False)
        condition = float(sigma[0] / sigma[-1]) if sigma[-1] > 0.0 else np.inf
        return condition, float(sigma[-1]), np.linalg.pinv(matrix)

    def _task_inputs(self, q: np.ndarray, inverse: np.ndarray, level: str) -> tuple[list, list, list]:
        """The task inputs of one ``level`` ("rate": xd_ref, omega_ref; "acceleration": xdd_ref,
        omegad_ref): names, values and each one's column of the map ``inverse`` (n, rows) onto
        the joints (qd, or qdd, per unit of the input)."""
        robot, m = self.robot, self.robot.m
        linear = self.xd if level == "rate" else self.xdd
        names = [v.name for v in self.variables[linear]]
        values = self.values[linear].tolist()
        columns = [inverse[:, i] for i in range(m)]
        if robot.orientation_axes:                      # their rows: S_o R^T omega (frame axes)
            local = robot.rotation(q).T[list(robot.orientation_axes)]
            angular = self.omega if level == "rate" else self.omegad
            names += [v.name for v in self.variables[angular]]
            values += self.values[angular].tolist()
            columns += [inverse[:, m:robot.task_rows].dot(local[:, i]) for i in range(3)]
        return names, values, columns

    def _input_text(self, name: str, value: float) -> str:
        return f"input {name} = {value:.6g} {self.variables[self.index[name]].unit}"

    def _too_fast(self, q: np.ndarray, qd: np.ndarray) -> str:
        """Why the rates ``qd`` (n,), some beyond qd_limit at ``q``, are refused: near a
        singularity (condition number beyond :data:`SINGULAR_CONDITION`), or a velocity limit,
        naming the task-rate input whose share of the fastest joint's rate is largest."""
        ratios = np.abs(qd) / self.qd_limit
        j = int(np.argmax(ratios))
        beyond = [f"qd_ref[{k + 1}]" for k in np.flatnonzero(ratios > 1.0)]
        rate = (f"joint rate qd_ref[{j + 1}] = {qd[j]:.6g} exceeds qd_limit[{j + 1}] = {self.qd_limit[j]:g} "
                + (f"({len(beyond)} joints beyond their limits: {', '.join(beyond)}) " if len(beyond) > 1 else ""))
        where = f"at q = {np.round(q, 6).tolist()}"
        condition, smallest, inverse = self._conditioning(q)
        if not condition <= SINGULAR_CONDITION:
            return (f"too close to a singularity: {rate}{where} (condition number of the Jacobian "
                    f"{condition:.3g} > {SINGULAR_CONDITION:g}, smallest singular value {smallest:.3g})")
        names, values, columns = self._task_inputs(q, inverse, "rate")
        shares = [column[j] * value for column, value in zip(columns, values)]
        k = int(np.argmax(np.abs(shares)))
        driven = (f": {self._input_text(names[k], values[k])} drives {shares[k]:.6g} "
                  f"{self.robot.joint_units(1)[j]} of it, too fast for the joints" if shares[k] != 0.0 else "")
        return (f"velocity limit: {rate}{where}{driven} (the Jacobian is well-conditioned here: condition "
                f"number {condition:.3g})")

    def _overflow(self, exc) -> str:
        """Why the joint rates at ``exc.q`` (a :class:`~robofmu.components.ik.RatesOverflow`) are
        not finite: a singularity, or the task input (rate or acceleration) that is too large."""
        q = exc.q
        condition, smallest, inverse = self._conditioning(q)
        if not condition <= SINGULAR_CONDITION:
            return (f"too close to a singularity: {exc} (condition number of the Jacobian {condition:.3g} > "
                    f"{SINGULAR_CONDITION:g}, smallest singular value {smallest:.3g})")
        candidates = []
        for level in ("rate", "acceleration"):
            names, values, columns = self._task_inputs(q, inverse, level)
            candidates += [(abs(v), float(np.max(np.abs(c))), name, v) for name, v, c in zip(names, values, columns)]
        largest = max(size for size, _, _, _ in candidates) or 1.0
        _, _, name, value = max(candidates, key=lambda c: (c[0] / largest) * c[1])     # no overflow here
        return (f"{exc}: {self._input_text(name, value)} is too large (the Jacobian is well-conditioned here: "
                f"condition number {condition:.3g})")

    def advance(self, t, h):
        self.committed = self.last
        self.elapsed = h

    def internal_state(self):
        return {"last": _listed(self.last), "committed": _listed(self.committed), "elapsed": self.elapsed,
                "outside": self.outside}

    def set_internal_state(self, state):
        self.last = _solution(state["last"])
        self.committed = _solution(state["committed"])
        self.elapsed = float(state["elapsed"])
        self.outside = bool(state["outside"])


def _listed(solution):
    """A solution (q, qd, qdd) as plain lists (FMU state), or None."""
    return None if solution is None else [[float(x) for x in v] for v in solution]


def _solution(listed):
    return None if listed is None else tuple(np.array(v) for v in listed)

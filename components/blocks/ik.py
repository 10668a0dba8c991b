"""IK block: joint reference (q, qd, qdd) from the task-space reference, direct feedthrough.

The solver is the one the robot's description names; its declared parameters become the
block's. A target whose joint rates exceed ``qd_limit`` (default: the URDF's velocity limits) is
too close to a singularity and counts as not reachable. Outside the workspace (or at a singularity) ``reachable`` is false, one warning is
logged per excursion, and the block holds its last valid position with zero velocity and
acceleration (zeros before it has one).

An iterative solver (Newton-Raphson, damped least squares) starts each communication step from
the solution of the last completed step (warm start, carried forward by its rates where the solver
predicts; the first from its ``q_guess``), so that the outputs at a communication point depend on
the inputs and the state at the step's start only, however often they are evaluated. Its
diagnostics (``iterations``, ``residual``, ...) are outputs too.

A pose task (the robot's ``[task] orientation_axes``) adds the inputs ``quat_ref[1..4]``, the
target orientation of the task frame as a unit quaternion in the order (x, y, z, w) (scalar last,
frame to world; normalised, refused if its norm is not 1 within 1e-6), ``omega_ref[1..3]`` and
``omegad_ref[1..3]``, its angular velocity (rad/s) and acceleration (rad/s^2) in the world frame.
"""
from __future__ import annotations

import numpy as np

from ..orientation import quaternion_of
from ..ik import JOINT_UNIT, Unreachable, solver_class
from .base import Block, vector_names


#: qd_limit's start for a joint without a velocity limit (rad/s, m/s): a parameter is finite.
NO_RATE_LIMIT = 1e12


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
                   "a target needing more is too close to a singularity and counts as not reachable",
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
                    fastest = int(np.argmax(np.abs(qd) / self.qd_limit))
                    raise Unreachable(f"too close to a singularity: joint rate qd_ref[{fastest + 1}] = "
                                      f"{qd[fastest]:.6g} exceeds qd_limit[{fastest + 1}] = "
                                      f"{self.qd_limit[fastest]:g} at q = {np.round(q, 6).tolist()}")
        except Unreachable as exc:
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

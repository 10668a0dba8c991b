"""Plant block: M(q) qdd + C(q, qd) qd + g(q) = tau, integrated by RK4 with tau held over the step.

No direct feedthrough: the outputs are the state at the communication point. The initial
state defaults to the description's ``home`` configuration at rest.

A robot model with an end-effector wrench (it has ``wrench_torque``, e.g. a closed-chain
mechanism in actuated coordinates) gets an extra input ``f_ext[i]``, one component per task
coordinate (a force in N along a length coordinate, a moment in N.m about an angle one), held
over the step like tau and passed to the model's ``forward_dynamics(q, qd, tau, f_ext)``, and
extra outputs ``x[i]``: the task coordinates (pose) of the state, FK(q).

``within_limits`` is false while a joint's position or velocity lies beyond its limit (the
robot's: the URDF's or its description's); each excursion logs one warning naming the joint, the
limit and the time.
"""
from __future__ import annotations

import math

import numpy as np

from ..plant import Plant, PlantDiverged
from .base import ContinuousBlock, StepRefused, vector_names

#: The effort unit of a wrench component along / about a task coordinate of this unit.
_WRENCH_UNITS = {"m": "N", "rad": "N.m"}

#: More RK4 sub-steps than this in one communication step is a mistake (an hour-long step).
MAX_SUBSTEPS = 1_000_000


class PlantBlock(ContinuousBlock):
    kind = "plant"
    summary = ("manipulator dynamics M(q)qdd + C(q,qd)qd + g(q) = tau (+ J^T f_ext where the model "
               "takes an end-effector wrench), RK4 with the inputs held over the step; no direct feedthrough")

    def declare(self):
        robot, d = self.robot, self.description
        n = robot.n
        u0, u1 = robot.joint_units(0), robot.joint_units(1)
        self.real("g", "parameter", "m/s2", "Gravity magnitude along the robot's gravity direction",
                  d.gravity, low=0.0)
        self.has_payload = d.payload is not None
        if self.has_payload:
            self.real("payload_mass", "parameter", "kg", "Point mass carried at the payload frame while "
                      "grip is true", d.payload.mass, low=0.0)
        self.real("max_substep", "parameter", "s", "Largest RK4 sub-step inside a communication step",
                  1e-3, above=0.0)
        self.reals("q0", n, "parameter", u0, "Joint {i} initial position (default: home)",
                   starts=robot.configuration("home"))
        self.reals("qd0", n, "parameter", u1, "Joint {i} initial velocity")
        self.tau = self.reals("tau", n, "input", robot.effort_units(),
                              "Joint {i} actuator effort (torque, or force for a prismatic joint)")
        if self.has_payload:
            self.grip = self.boolean("grip", "input", "Gripper closed: carry payload_mass")
        self.has_wrench = callable(getattr(robot, "wrench_torque", None))
        if self.has_wrench:
            coords, units = robot.task_coordinates, robot.task_units(0)
            efforts = [_WRENCH_UNITS[u] for u in units]
            self.f_ext = self.reals(
                "f_ext", robot.m, "input", efforts,
                lambda i: (f"End-effector wrench: {'force along' if efforts[i - 1] == 'N' else 'moment about'} "
                           f"task coordinate {coords[i - 1]} (world axes)"))
        self.q = self.reals("q", n, "output", u0, "Joint {i} position", depends=[],
                            initial_depends=lambda i: [f"q0[{i}]"])
        self.qd = self.reals("qd", n, "output", u1, "Joint {i} velocity", depends=[],
                             initial_depends=lambda i: [f"qd0[{i}]"])
        self.within = self.boolean("within_limits", "output", "False while a joint's position or velocity "
                                   "lies beyond its limit (a warning names joint, limit and time)", start=True,
                                   depends=[])
        if self.has_wrench:
            coords = robot.task_coordinates
            self.x = self.reals("x", robot.m, "output", robot.task_units(0),
                                lambda i: f"Task coordinate {coords[i - 1]} of the state (FK of q)", depends=[],
                                initial_depends=vector_names("q0", n))
        self.plant = None

    def configure(self):
        self.robot.set_gravity(self.parameter("g"))
        max_substep = self.parameter("max_substep")
        self.plant = Plant(self.robot, self.finite_vector("q0"), self.finite_vector("qd0"),
                           payload_mass=self.parameter("payload_mass") if self.has_payload else 0.0,
                           max_substep=max_substep)
        self._grip()
        v = self.values                          # views, made once (the values array is never replaced)
        self._tau_in = v[self.tau]
        self._wrench_in = v[self.f_ext] if self.has_wrench else None
        contiguous = self.q.stop == self.qd.start
        self._state_out = v[self.q.start:self.qd.stop] if contiguous else None
        lower, upper = self.robot.position_limits()
        speed = self.robot.velocity_limits()
        self._limits = (np.concatenate([lower, -speed]), np.concatenate([upper, speed]))
        self._beyond = False
        super().configure()

    def _grip(self):
        if self.has_payload:
            closed = bool(self.values[self.grip])
            if closed != self.plant.grip:
                self.plant.set_grip(closed)

    def _wrench(self):
        return self.values[self.f_ext] if self.has_wrench else None

    def output(self, t):
        if self._state_out is not None:
            self._state_out[:] = self.plant.x
        else:
            self.values[self.q], self.values[self.qd] = self.plant.q, self.plant.qd
        if self.has_wrench:
            self.values[self.x] = self.robot.fk(self.plant.q)
        lower, upper = self._limits
        x = self.plant.x
        beyond = bool((x < lower).any() or (x > upper).any())
        self.values[self.within] = not beyond
        if beyond and not self._beyond:
            self.warn(f"t = {t:.9g} s: {self._violation(x)}")
        self._beyond = beyond

    def _violation(self, x) -> str:
        """Which joint is beyond which limit, in words (the first found)."""
        robot, n = self.robot, self.robot.n
        lower, upper = self._limits
        k = int(np.flatnonzero((x < lower) | (x > upper))[0])
        j = k % n
        what, units = ("position", robot.joint_units(0)) if k < n else ("velocity", robot.joint_units(1))
        if k >= n:
            return (f"joint {j + 1} ({robot.joint_names[j]}) velocity {x[k]:.6g} {units[j]} exceeds its limit "
                    f"{upper[k]:.6g} {units[j]}")
        side, limit = ("below its lower", lower[k]) if x[k] < lower[k] else ("above its upper", upper[k])
        return (f"joint {j + 1} ({robot.joint_names[j]}) position {x[k]:.9g} {units[j]} is {abs(x[k] - limit):.3g} "
                f"{units[j]} {side} limit {limit:.6g} {units[j]}")

    def advance(self, t, h):
        substeps = math.ceil(h / self.plant.max_substep - 1e-9)
        if substeps > MAX_SUBSTEPS:
            raise StepRefused(f"a step of {h:g} s needs {substeps} RK4 sub-steps of max_substep = "
                              f"{self.plant.max_substep:g} s (at most {MAX_SUBSTEPS}); step refused")
        self._grip()
        try:
            self.plant.step(self._tau_in, h, t, self._wrench_in)
        except PlantDiverged as exc:
            raise StepRefused(str(exc)) from None

    def internal_state(self):
        if self.plant is None:
            return {}
        return {"x": [float(v) for v in self.plant.x], "grip": self.plant.grip, "beyond": self._beyond}

    def set_internal_state(self, state):
        if self.plant is not None and state:
            self.plant.x = np.array(state["x"])
            self.plant.set_grip(state["grip"])
            self._beyond = bool(state.get("beyond", False))

    def continuous_state(self):
        return self.plant.x.copy()

    def set_continuous_state(self, x):
        self.plant.x = np.array(x, dtype=float)

    def derivative(self, t):
        self._grip()
        x = self.plant.x
        return np.concatenate([x[self.robot.n:], self.plant.acceleration(x, self.values[self.tau], self._wrench())])

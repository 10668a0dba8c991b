"""Plant block: M(q) qdd + C(q, qd) qd + g(q) = tau - tau_f(qd), integrated by RK4 with tau held over the step.

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

Joint losses (:class:`~robofmu.components.plant.JointLosses`): parameters ``damping[j]`` (b),
``friction[j]`` (tau_c) and ``friction_velocity[j]`` (v_s), tau_f = b qd + tau_c tanh(qd / v_s),
defaults the robot's data (URDF ``<dynamics>``, TOML ``[joints.dynamics]`` over it; 0 where none);
and, where the robot model has one (Pinocchio's), ``armature[j]``, the rotor inertia added to
M(q)'s diagonal. All zero: the rigid plant, bit for bit.

Encoder (the measured outputs ``q_measured[j]``, ``qd_measured[j]``; ``q``, ``qd`` stay the true
state, so the default loop, which wires ``q`` and ``qd`` to the controller, is unchanged; wire
``plant.q_measured -> controller.q`` and ``plant.qd_measured -> controller.qd`` to close the loop
through the encoder): ``encoder_counts[j]`` counts per revolution (revolute: resolution 2 pi /
counts rad) or per metre (prismatic: 1 / counts m), 0: not quantized; ``encoder_noise[j]`` a
Gaussian noise's standard deviation (rad, m) added before quantization, drawn once per
communication point from a NumPy Generator seeded by ``seed`` (re-seeded by initialization and
fmi2Reset; its state is part of the FMU state). A joint with an encoder (counts or noise > 0)
measures q_m = res round((q + noise) / res) and, as a drive does, its velocity as the backward
difference of q_m over the last communication step (at the start: qd0); a joint without one
measures the true q and qd.
"""
from __future__ import annotations

import math

import numpy as np

from ..parameters import INTEGER_RANGE, Parameter
from ..plant import FRICTION_VELOCITY, JointLosses, Plant, PlantDiverged, robot_losses
from .base import Block, ContinuousBlock, StepRefused, vector_names

#: The effort unit of a wrench component along / about a task coordinate of this unit.
_WRENCH_UNITS = {"m": "N", "rad": "N.m"}

#: More RK4 sub-steps than this in one communication step is a mistake (an hour-long step).
MAX_SUBSTEPS = 1_000_000

#: The encoder noise's seed (a FMU Integer parameter of the plant).
SEED = Parameter("seed", "Integer", "", "Seed of the encoder noise's generator (NumPy's default_rng)", 0,
                 low=0, high=INTEGER_RANGE[1])


def declare_losses(block: Block) -> bool:
    """Declare ``damping[j]``, ``friction[j]``, ``friction_velocity[j]`` and, where the block's
    robot model takes one (it has ``set_armature``), ``armature[j]``, starting at the robot's
    data (:func:`~robofmu.components.plant.robot_losses`); returns whether armature is declared.
    The plant and the controller declare the same (each its own model of the arm)."""
    robot = block.robot
    n = robot.n
    damping, friction, armature = robot_losses(robot)
    units = robot.joint_units(1)
    block.reals("damping", n, "parameter", [f"{e}.s/{u}" for e, u in zip(robot.effort_units(), robot.joint_units(0))],
                "Joint {i} viscous damping b (tau_f = b qd + friction tanh(qd / friction_velocity))", damping)
    block.reals("friction", n, "parameter", robot.effort_units(), "Joint {i} Coulomb friction (smoothed by tanh)",
                friction)
    block.reals("friction_velocity", n, "parameter", units, "Joint {i} velocity scale v_s of the Coulomb "
                "friction's tanh", [FRICTION_VELOCITY] * n)
    has_armature = callable(getattr(robot, "set_armature", None))
    if has_armature:
        block.reals("armature", n, "parameter", ["kg" if p else "kg.m2" for p in robot.prismatic],
                    "Joint {i} rotor inertia (armature), added to M(q)'s diagonal", armature)
    return has_armature


def configured_losses(block: Block, has_armature: bool) -> JointLosses:
    """The losses of ``block``'s parameters (ValueError naming a bad one), its model's armature set."""
    if has_armature:
        armature = block.finite_vector("armature")
        bad = np.flatnonzero(armature < 0.0)
        if bad.size:
            k = int(bad[0])
            raise ValueError(f"parameter armature[{k + 1}] = {armature[k]:g} is invalid: must be finite and >= 0")
        block.robot.set_armature(armature)
    return JointLosses.of(*(block.get(name) for name in ("damping", "friction", "friction_velocity")))


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
        self.has_armature = declare_losses(self)
        self.reals("encoder_counts", n, "parameter", ["1/m" if p else "1" for p in robot.prismatic],
                   "Joint {i} encoder counts per revolution (revolute) or per metre (prismatic); 0: not quantized")
        self.reals("encoder_noise", n, "parameter", u0, "Joint {i} encoder noise, standard deviation (Gaussian, "
                   "added before quantization); 0: none")
        self.setting(SEED, SEED.default)
        self.q_measured = self.reals(
            "q_measured", n, "output", u0, "Joint {i} position as its encoder measures it (q without one)",
            depends=[], initial_depends=lambda i: [f"q0[{i}]", f"encoder_counts[{i}]", f"encoder_noise[{i}]", "seed"])
        self.qd_measured = self.reals(
            "qd_measured", n, "output", u1, "Joint {i} velocity as the drive measures it: the encoder's position "
            "differenced over the step (qd without an encoder)", depends=[],
            initial_depends=lambda i: [f"qd0[{i}]"])
        self.plant = None

    def configure(self):
        self.robot.set_gravity(self.parameter("g"))
        max_substep = self.parameter("max_substep")
        losses = configured_losses(self, self.has_armature)
        self.plant = Plant(self.robot, self.finite_vector("q0"), self.finite_vector("qd0"),
                           payload_mass=self.parameter("payload_mass") if self.has_payload else 0.0,
                           max_substep=max_substep, losses=losses)
        self._configure_encoder()
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

    def _configure_encoder(self):
        """The encoder's resolution (0: none), noise, generator and first measurement (at q0, qd0)."""
        robot = self.robot
        counts = self.finite_vector("encoder_counts")
        noise = self.finite_vector("encoder_noise")
        for name, values in (("encoder_counts", counts), ("encoder_noise", noise)):
            bad = np.flatnonzero(values < 0.0)
            if bad.size:
                k = int(bad[0])
                raise ValueError(f"parameter {name}[{k + 1}] = {values[k]:g} is invalid: must be finite and >= 0")
        turn = np.where(robot.prismatic, 1.0, 2.0 * math.pi)          # a revolution (rad) or a metre
        with np.errstate(divide="ignore"):
            self._resolution = np.where(counts > 0.0, turn / np.where(counts > 0.0, counts, 1.0), 0.0)
        self._noise_std = noise
        self._encoded = (counts > 0.0) | (noise > 0.0)
        self._quantized = counts > 0.0
        self._rng = np.random.default_rng(self.parameter("seed"))
        if self._encoded.any():
            self._measured = self._measure()
            self._measured_rate = np.where(self._encoded, self.plant.qd, 0.0)

    def _measure(self) -> np.ndarray:
        """The encoders' reading of the current q (one noise draw): res round((q + noise) / res)
        where quantized; the true q on a joint without an encoder."""
        q = self.plant.q
        reading = q + self._rng.standard_normal(self.robot.n) * self._noise_std if self._noise_std.any() else q.copy()
        res = self._resolution
        quantized = np.round(reading / np.where(self._quantized, res, 1.0)) * res
        return np.where(self._quantized, quantized, np.where(self._encoded, reading, q))

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
        if self._encoded.any():
            encoded = self._encoded
            self.values[self.q_measured] = np.where(encoded, self._measured, self.plant.q)
            self.values[self.qd_measured] = np.where(encoded, self._measured_rate, self.plant.qd)
        else:
            self.values[self.q_measured], self.values[self.qd_measured] = self.plant.q, self.plant.qd
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
        substeps = self.plant.substeps(h)
        if substeps > MAX_SUBSTEPS:
            raise StepRefused(f"a step of {h:g} s needs {substeps} RK4 sub-steps of max_substep = "
                              f"{self.plant.max_substep:g} s (at most {MAX_SUBSTEPS}; the joints' losses "
                              "may shorten them); step refused")
        self._grip()
        try:
            self.plant.step(self._tau_in, h, t, self._wrench_in, substeps)
        except PlantDiverged as exc:
            raise StepRefused(str(exc)) from None
        if self._encoded.any():
            before = self._measured
            self._measured = self._measure()
            self._measured_rate = np.where(self._encoded, (self._measured - before) / h, 0.0)

    def internal_state(self):
        if self.plant is None:
            return {}
        state = {"x": [float(v) for v in self.plant.x], "grip": self.plant.grip, "beyond": self._beyond,
                 "rng": self._rng.bit_generator.state}
        if self._encoded.any():
            state["measured"] = [float(v) for v in self._measured]
            state["measured_rate"] = [float(v) for v in self._measured_rate]
        return state

    def set_internal_state(self, state):
        if self.plant is not None and state:
            self.plant.x = np.array(state["x"])
            self.plant.set_grip(state["grip"])
            self._beyond = bool(state.get("beyond", False))
            if "rng" in state:
                self._rng.bit_generator.state = state["rng"]
            if "measured" in state and self._encoded.any():
                self._measured = np.array(state["measured"])
                self._measured_rate = np.array(state["measured_rate"])

    def continuous_state(self):
        return self.plant.x.copy()

    def set_continuous_state(self, x):
        self.plant.x = np.array(x, dtype=float)

    def derivative(self, t):
        self._grip()
        x = self.plant.x
        return np.concatenate([x[self.robot.n:], self.plant.acceleration(x, self.values[self.tau], self._wrench())])

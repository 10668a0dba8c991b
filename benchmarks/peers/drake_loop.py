"""The chess-pd loop in Drake: the pydrake peer of ``make bench-peers``.

Runs in its own environment (Drake is not a robofmu dependency) and reads only the loop's numbers
that ``benchmarks/loop_spec.py`` writes; it imports neither robofmu nor pinocchio.

    python3 -m venv benchmarks/peers/.venv-drake
    benchmarks/peers/.venv-drake/bin/pip install -r benchmarks/peers/drake-requirements.txt
    .venv/bin/python benchmarks/loop_spec.py SPEC.json
    benchmarks/peers/.venv-drake/bin/python benchmarks/peers/drake_loop.py SPEC.json OUT.npz [--variant NAME]

The diagram: a MultibodyPlant from the URDF (gravity from the spec; a point-mass payload body
welded at the payload lever), a ``Reference`` LeafSystem (the waypoint LSPB trajectory, the
gripper and the closed-form pitch-elbow IK with its rates qd = A^-1 [xd; 0],
qdd = A^-1 [xdd - Jdot qd; 0], A = [J; 0 1 1 1], J and Jdot qd from Drake's kinematics) and a
``Controller`` LeafSystem (computed torque u = qdd_ref + kd (qd_ref - qd) + kp (q_ref - q) + ki z,
tau = ID(q, qd, u) = M u + C qd + g on its own MultibodyPlant, which carries its payload belief
while the gripper is closed; z += e h). Sampled like robofmu's master: at t_k = k h the reference
and the torque are computed from the plant's state at t_k and held over [t_k, t_k + h]:

* continuous-plant variants: the controller's periodic discrete update at h computes tau into its
  discrete state (zero-order hold), and the Simulator integrates the plant with a fixed-step
  integrator (step min(h, max_substep));
* ``discrete``: MultibodyPlant(time_step = h) (Drake's semi-implicit Euler step, without sampled
  output ports so that its step is a discrete update simultaneous with the controller's); tau is
  then a direct-feedthrough output of the state at t_k (a discrete state would reach the plant's
  simultaneous update one step late), z still advancing in the controller's update.

The plant's payload mass is a parameter, which no event may change: the stepping runs as
AdvanceTo segments ending at the steps where the gripper closes and opens, and sets
``RigidBody.SetMass`` on the plant's context between them (the controller switches its model's
mass from its grip input). Every step's row (q, qd, tau, q_ref, qd_ref, qdd_ref, grip at t_k) is
recorded inside the controller's update; the last one (t_N) by ``AdvancePendingEvents``.

Prints one line ``RESULT {json}`` ({"peer", "version", "variant", "loop" (s wall, the stepping
only: the AdvanceTo segments), "n_steps", "per_step", "loop_cpu" (s of process time), "order", ...}) and writes ``np.savez(OUT, time=(N+1,), data=(N+1, m), columns=(m,))`` with
robofmu's column names.
"""
from __future__ import annotations

import argparse
import importlib.metadata
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from reference import Unreachable, Waypoints, pitch_elbow_position   # beside this file
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import JacobianWrtVariable, MultibodyForces, SpatialInertia, UnitInertia
from pydrake.systems.analysis import ResetIntegratorFromFlags, Simulator
from pydrake.systems.framework import BasicVector, DiagramBuilder, LeafSystem

#: Variant name -> (Drake integration scheme, None for the discrete plant; order; description).
#: robofmu's plant is RK4 at 1 ms: the 1st-order variants differ from it by ~3e-4 rad, the
#: others by <= 2e-6 rad (chess-pd).
VARIANTS = {
    "rk3": ("runge_kutta3", 3, "continuous plant, RungeKutta3 in fixed-step mode (3 stages)"),
    "rk2": ("runge_kutta2", 2, "continuous plant, RungeKutta2 (2 stages; fixed step only)"),
    "rk5": ("runge_kutta5", 5, "continuous plant, RungeKutta5 (Dormand-Prince) in fixed-step mode"),
    "bs3": ("bogacki_shampine3", 3, "continuous plant, Bogacki-Shampine3 in fixed-step mode"),
    "semi_explicit_euler": ("semi_explicit_euler", 1, "continuous plant, semi-explicit (symplectic) Euler"),
    "explicit_euler": ("explicit_euler", 1, "continuous plant, explicit Euler"),
    "discrete": (None, 1, "discrete plant, MultibodyPlant(time_step=h): Drake's semi-implicit Euler step"),
}
DEFAULT_VARIANT = "rk3"



# -- the arm ---------------------------------------------------------------------------------------
class Arm:
    """A MultibodyPlant of the spec's URDF with a point-mass payload body at the payload lever."""

    def __init__(self, spec: dict, time_step: float = 0.0, builder: DiagramBuilder | None = None):
        plant = MultibodyPlant(time_step)
        if builder is not None:
            plant = builder.AddSystem(plant)
        models = Parser(plant).AddModels(spec["urdf"])
        base = plant.GetBodyByName(_root_link(spec["urdf"]), models[0])
        plant.WeldFrames(plant.world_frame(), base.body_frame(), RigidTransform())
        movable = [plant.get_joint(j) for j in plant.GetJointIndices(models[0])
                   if plant.get_joint(j).type_name() != "weld"]
        payload = spec["payload"]
        carrier = movable[payload["joint"] - 1].child_body()  # the joint frame is its child's frame
        mass = max(float(spec["plant"]["payload_mass"]), float(spec["controller"]["payload_mass"]), 1.0)
        self.payload = plant.AddRigidBody("payload", models[0], SpatialInertia(mass, np.zeros(3), UnitInertia(0.0, 0.0, 0.0)))
        plant.WeldFrames(carrier.body_frame(), self.payload.body_frame(), RigidTransform(payload["lever"]))
        plant.mutable_gravity_field().set_gravity_vector(np.asarray(spec["gravity"], dtype=float))
        if time_step > 0.0:
            # Sampled output ports make the discrete plant step in an unrestricted update, which
            # the Simulator runs before the discrete updates at the same time: the controller's
            # update at t_k would then see the state of t_{k+1}. Without them the plant's step is
            # a discrete update, simultaneous with the controller's (both read the state at t_k).
            plant.SetUseSampledOutputPorts(False)
        plant.Finalize()
        n = len(movable)
        if plant.num_positions() != n or plant.num_velocities() != n or plant.num_actuators() != 0:
            raise ValueError(f"{spec['urdf']}: expected {n} one-dof joints and no actuators")
        for j, joint in enumerate(movable):
            if joint.position_start() != j or joint.velocity_start() != j:
                raise ValueError(f"{joint.name()}: not the {j + 1}-th coordinate (a serial chain expected)")
        self.plant, self.n = plant, n
        self.tcp = plant.GetFrameByName(spec["tcp_frame"], models[0])
        self.world = plant.world_frame()


def _root_link(urdf: str) -> str:
    """The URDF's root link (the one that is no joint's child)."""
    import xml.etree.ElementTree as ET
    robot = ET.parse(urdf).getroot()
    children = {j.find("child").get("link") for j in robot.findall("joint")}
    roots = [link.get("name") for link in robot.findall("link") if link.get("name") not in children]
    if len(roots) != 1:
        raise ValueError(f"{urdf}: expected one root link, got {roots}")
    return roots[0]


# -- the trajectory and IK: benchmarks/peers/reference.py, shared with the bdsim peer ---------------
class Reference(LeafSystem):
    """Trajectory + pitch-elbow IK: output ``reference`` = [q_ref, qd_ref, qdd_ref, grip] at the
    context's time (no state; robofmu's hold of the last valid solution outside the workspace is
    kept in Python, as its IK block does)."""

    def __init__(self, spec: dict, arm: Arm):
        super().__init__()
        self.traj = Waypoints(spec["trajectory"])
        ik = self.ik = spec["ik"]
        self.qd_limit = np.asarray(ik["qd_limit"], dtype=float)
        self.arm, self.n = arm, arm.n
        self.kin = arm.plant.CreateDefaultContext()           # kinematics only: J, Jdot qd
        self.C = np.array([[0.0, 1.0, 1.0, 1.0]])
        self.A = np.zeros((self.n, self.n))
        self.A[3] = self.C
        self.origin = np.zeros(3)                             # the tcp frame's origin
        self.last = None                                      # the last valid q_ref
        self.warned = False
        self.DeclareVectorOutputPort("reference", BasicVector(3 * self.n + 1), self._calc,
                                     prerequisites_of_calc={self.time_ticket()})

    def position(self, x):
        return pitch_elbow_position(self.ik, x)

    def rates(self, q, xd, xdd):
        """qd = A^-1 [xd; 0], qdd = A^-1 [xdd - Jdot qd; 0], A = [J; C] (J, Jdot qd from Drake)."""
        plant, ctx, tcp, world, o = self.arm.plant, self.kin, self.arm.tcp, self.arm.world, self.origin
        plant.SetPositions(ctx, q)
        A = self.A
        A[:3] = plant.CalcJacobianTranslationalVelocity(ctx, JacobianWrtVariable.kV, tcp, o, world, world)
        Ainv = np.linalg.inv(A)
        qd = Ainv[:, :3] @ xd
        plant.SetVelocities(ctx, qd)
        bias = plant.CalcBiasTranslationalAcceleration(ctx, JacobianWrtVariable.kV, tcp, o, world, world)
        qdd = Ainv[:, :3] @ (xdd - bias[:, 0])
        return qd, qdd

    def _calc(self, context, output):
        n = self.n
        t = context.get_time()
        x, xd, xdd, grip = self.traj.evaluate(t)
        out = output.get_mutable_value()
        try:
            q = self.position(x)
            qd, qdd = self.rates(q, xd, xdd)
            if not np.all(np.abs(qd) <= self.qd_limit) or not np.isfinite(qd.sum() + qdd.sum()):
                raise Unreachable(f"too close to a singularity at q = {q}")
        except (Unreachable, np.linalg.LinAlgError) as exc:
            if not self.warned:
                print(f"drake_loop: t = {t:.9g} s: {exc}; holding the last valid solution", file=sys.stderr)
                self.warned = True
            out[:n] = 0.0 if self.last is None else self.last
            out[n:3 * n] = 0.0
            out[3 * n] = float(grip)
            return
        self.warned = False
        self.last = q
        out[:n], out[n:2 * n], out[2 * n:3 * n], out[3 * n] = q, qd, qdd, float(grip)


# -- the controller --------------------------------------------------------------------------------
class Controller(LeafSystem):
    """Computed torque on its own MultibodyPlant (with its payload belief while grip is closed).

    ``hold=True``: tau is a discrete state set by the periodic update at h (zero-order hold, for a
    continuous plant). ``hold=False``: tau is a direct-feedthrough output (for a discrete plant,
    whose update at t_k reads it at t_k). Either way the update at t_k advances z += e h and
    records the row of t_k.
    """

    def __init__(self, spec: dict, model: Arm, hold: bool, n_steps: int):
        super().__init__()
        c, n, h = spec["controller"], model.n, float(spec["h"])
        self.kp, self.kd, self.ki = float(c["kp"]), float(c["kd"]), float(c["ki"])
        self.belief = float(c["payload_mass"])
        self.h, self.n, self.hold = h, n, hold
        self.model = model
        self.ctx = model.plant.CreateDefaultContext()
        model.payload.SetMass(self.ctx, 0.0)
        self.mass = 0.0
        self.forces = MultibodyForces(model.plant)
        self.state_in = self.DeclareVectorInputPort("state", 2 * n)
        self.ref_in = self.DeclareVectorInputPort("reference", 3 * n + 1)
        self.z_index = self.DeclareDiscreteState(n)
        if hold:
            self.tau_index = self.DeclareDiscreteState(n)
            self.tau_out = self.DeclareStateOutputPort("tau", self.tau_index)
        else:
            self.tau_out = self.DeclareVectorOutputPort(
                "tau", BasicVector(n), self._calc_tau,
                prerequisites_of_calc={self.input_port_ticket(self.state_in.get_index()),
                                       self.input_port_ticket(self.ref_in.get_index()),
                                       self.discrete_state_ticket(self.z_index)})
        self.DeclarePeriodicDiscreteUpdateEvent(h, 0.0, self._update)
        # rows: time, q, qd, tau, q_ref, qd_ref, qdd_ref, grip
        self.rows = np.full((n_steps + 1, 1 + 6 * n + 1), np.nan)
        self.columns = (["plant.q[%d]" % (j + 1) for j in range(n)] + ["plant.qd[%d]" % (j + 1) for j in range(n)]
                        + ["controller.tau[%d]" % (j + 1) for j in range(n)]
                        + [f"ik.{b}[{j + 1}]" for b in ("q_ref", "qd_ref", "qdd_ref") for j in range(n)]
                        + ["trajectory.grip"])

    def torque(self, x, ref, z):
        n = self.n
        q, qd = x[:n], x[n:]
        mass = self.belief if ref[3 * n] > 0.5 else 0.0
        plant, ctx = self.model.plant, self.ctx
        if mass != self.mass:
            self.model.payload.SetMass(ctx, mass)
            self.mass = mass
        u = ref[2 * n:3 * n] + self.kd * (ref[n:2 * n] - qd) + self.kp * (ref[:n] - q)
        if self.ki:
            u = u + self.ki * z
        plant.SetPositionsAndVelocities(ctx, x)
        forces = self.forces
        forces.SetZero()
        plant.CalcForceElementsContribution(ctx, forces)   # gravity (as applied forces)
        return plant.CalcInverseDynamics(ctx, u, forces)   # M u + C qd - tau_gravity

    def _calc_tau(self, context, output):
        output.SetFromVector(self.torque(self.state_in.Eval(context), self.ref_in.Eval(context),
                                         context.get_discrete_state(self.z_index).get_value()))

    def _update(self, context, discrete_state):
        n = self.n
        t = context.get_time()
        x = self.state_in.Eval(context)
        ref = self.ref_in.Eval(context)
        z = context.get_discrete_state(self.z_index).get_value()
        if self.hold:
            tau = self.torque(x, ref, z)
            discrete_state.get_mutable_vector(self.tau_index).SetFromVector(tau)
        else:
            tau = self.tau_out.Eval(context)
        if self.ki:
            discrete_state.get_mutable_vector(self.z_index).SetFromVector(z + (ref[:n] - x[:n]) * self.h)
        k = int(round(t / self.h))
        if 0 <= k < len(self.rows):
            row = self.rows[k]
            row[0] = t
            row[1:1 + 2 * n] = x
            row[1 + 2 * n:1 + 3 * n] = tau
            row[1 + 3 * n:] = ref


# -- the loop --------------------------------------------------------------------------------------
def build(spec: dict, variant: str):
    scheme = VARIANTS[variant][0]
    h, n_steps = float(spec["h"]), int(spec["n_steps"])
    builder = DiagramBuilder()
    arm = Arm(spec, time_step=0.0 if scheme else h, builder=builder)
    plant = arm.plant
    reference = builder.AddSystem(Reference(spec, Arm(spec)))
    controller = builder.AddSystem(Controller(spec, Arm(spec), hold=scheme is not None, n_steps=n_steps))
    builder.Connect(plant.get_state_output_port(), controller.state_in)
    builder.Connect(reference.get_output_port(0), controller.ref_in)
    builder.Connect(controller.tau_out, plant.get_applied_generalized_force_input_port())
    diagram = builder.Build()

    simulator = Simulator(diagram)
    simulator.set_target_realtime_rate(0.0)
    if scheme:
        step = min(h, float(spec["plant"]["max_substep"]))
        integrator = ResetIntegratorFromFlags(simulator, scheme, step)
        integrator.set_fixed_step_mode(True)       # no error control: steps of exactly `step`
    context = simulator.get_mutable_context()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    plant.SetPositions(plant_context, np.asarray(spec["plant"]["q0"], dtype=float))
    plant.SetVelocities(plant_context, np.asarray(spec["plant"]["qd0"], dtype=float))
    arm.payload.SetMass(plant_context, 0.0)
    return diagram, simulator, arm, plant_context, reference, controller


def segments(spec: dict, traj: Waypoints):
    """[(k, payload mass from step k on)]: the steps at which the gripper changes, as the master
    samples it (at t_k = k h)."""
    h, n_steps, m = float(spec["h"]), int(spec["n_steps"]), float(spec["plant"]["payload_mass"])
    out, closed, k = [], False, 0
    for event in sorted(e for e in (traj.close, traj.open) if math.isfinite(e)):
        k = max(k, int(math.floor(event / h)) - 2)
        while k <= n_steps and traj.evaluate(k * h)[3] == closed:
            k += 1
        if k > n_steps:
            break
        closed = not closed
        out.append((k, m if closed else 0.0))
    return out


def run(spec: dict, variant: str):
    h, n_steps = float(spec["h"]), int(spec["n_steps"])
    diagram, simulator, arm, plant_context, reference, controller = build(spec, variant)
    switches = segments(spec, reference.traj)
    simulator.Initialize()
    cpu, start = time.process_time(), time.perf_counter()
    for k, mass in switches:
        simulator.AdvanceTo(k * h)
        arm.payload.SetMass(plant_context, mass)
    simulator.AdvanceTo(n_steps * h)
    simulator.AdvancePendingEvents()            # the row of t_N (tau at t_N, as the master outputs it)
    loop, loop_cpu = time.perf_counter() - start, time.process_time() - cpu
    rows = controller.rows
    if np.isnan(rows).any():
        missing = np.flatnonzero(np.isnan(rows).any(axis=1))
        raise RuntimeError(f"{len(missing)} steps not recorded (first k = {missing[0]})")
    return loop, loop_cpu, rows, controller.columns, switches


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("spec", nargs="?", help="the loop's JSON (benchmarks/loop_spec.py)")
    parser.add_argument("out", nargs="?", help="the trajectory (.npz) to write")
    parser.add_argument("--variant", default=DEFAULT_VARIANT, choices=sorted(VARIANTS))
    parser.add_argument("--list-variants", action="store_true",
                        help="print the variants' names, one a line, and exit (descriptions: VARIANTS)")
    args = parser.parse_args(argv)
    if args.list_variants:
        print("\n".join(VARIANTS))
        return 0
    if not args.spec or not args.out:
        parser.error("SPEC.json and OUT.npz are required")
    spec = json.loads(Path(args.spec).read_text())
    loop, loop_cpu, rows, columns, switches = run(spec, args.variant)
    np.savez(args.out, time=rows[:, 0], data=rows[:, 1:], columns=np.array(columns))
    n_steps = int(spec["n_steps"])
    result = {"peer": "pydrake", "version": importlib.metadata.version("drake"), "variant": args.variant,
              "loop": loop, "n_steps": n_steps, "per_step": loop / n_steps,
              "loop_cpu": loop_cpu,
              "integrator": VARIANTS[args.variant][0] or "discrete plant", "order": VARIANTS[args.variant][1],
              "grip_steps": [k for k, _ in switches]}
    print("RESULT " + json.dumps(result), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

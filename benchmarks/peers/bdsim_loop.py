"""The chess-pd loop as a bdsim block diagram on the Robotics Toolbox for Python (a peer of
``make bench-peers``), run in its own venv (benchmarks/peers/bdsim-requirements.txt).

    benchmarks/peers/.venv-bdsim/bin/python benchmarks/peers/bdsim_loop.py SPEC.json OUT.npz [--variant NAME]
    benchmarks/peers/.venv-bdsim/bin/python benchmarks/peers/bdsim_loop.py --list-variants

SPEC.json is written by ``.venv/bin/python benchmarks/loop_spec.py SPEC.json`` (the only input:
nothing here imports robofmu or Pinocchio). Prints one line ``RESULT {json}`` and writes
``np.savez(OUT, time, data, columns)`` with robofmu's column names (``plant.q[j]``,
``plant.qd[j]``, ``controller.tau[j]``) at the communication points t_k = k h.

The diagram (what robofmu's blocks do, block for block)::

    TIME -> traj (FUNCTION: LSPB waypoints, snapped to breakpoints; x, xd, xdd, grip)
         -> ik   (FUNCTION: closed-form pitch/elbow IK; qd = A^-1 [xd; 0],
                  qdd = A^-1 [xdd - Jdot qd; 0], A = [J; 0 1 1 1], J and Jdot from RTB)
         -> ctc  (sampled block on a clock of period h: tau = rne(q, qd, u) on the controller's
                  model, its payload belief while grip, u = qdd_ref + kd e' + kp e + ki z,
                  z += e h; output held over the step)
    traj.grip -> ZOH (clock h) -> plant (RTB FDYN with a grip input: the payload at the TCP
                                         while the held grip is closed; robot.accel)

bdsim integrates the plant between clock ticks with scipy's solve_ivp (one call per 1 ms
interval), so tau and grip are held over each step as in robofmu. A clock's first tick is at
t = h, so the held values over [0, h] are the hold's initial states, computed here from the same
functions at t = 0 (the value the first sample would give).

Variants (``--variant``; ``--list-variants`` prints them):

- ``mdh-rk4`` (default): the diagram above; the dynamics (M, rne, accel) on an RTB ``DHRobot``
  in modified DH form derived from the URDF robot (its chain split joint by joint at the common
  normals, inertias carried into the DH frames, checked against the URDF ``Robot`` at random
  states to 1e-9) so that RTB's C RNE (``frne``) does the work; kinematics (J, Jdot) on the
  URDF ``Robot``; solve_ivp with a fixed-step classical RK4 method class (max_step = the plant's
  max_substep = h: one RK4 step per interval, robofmu's plant integrator);
- ``mdh-rk4-fused``: trajectory, IK and computed torque in one sampled block (a digital
  controller), so the solver's right-hand side evaluates only the plant;
- ``mdh-rk4-continuous``: no clock and no hold: trajectory, IK and computed torque in one
  continuous-time block (``ContinuousBlock`` with direct feedthrough; its state is the integral
  z of the joint error, z' = q_ref - q) evaluated at every right-hand-side call (the computed
  torque at each; the reference, a function of t alone, once per distinct time: an RK4 step's
  middle stages share one, its last stage the next step's first, reused exactly), its grip
  straight into the plant, so that bdsim integrates the whole horizon in ONE solve_ivp run
  (fixed-step RK4 of step h; the grip instants 6.0 s and 11.5 s fall on step boundaries, where
  the step ending there sees the new grip at its last stage). A different system from robofmu's:
  a continuous-time controller, not a sampled one, so its trajectory differs from robofmu's by
  the hold's effect. tau is the block's output at t_k (watched on the solver's own points). Not
  faster than ``mdh-rk4-fused`` for all its single solve_ivp run: the reference (trajectory + IK
  on the URDF robot, ~160 us a call) is needed at three distinct times a step (t_k + h/2, t_k + h
  and bdsim's replay of the point t_k after the run) and the computed torque at five, against
  once each for the sampled controller, which outweighs the ~50-100 us a solve_ivp restart costs;
- ``mdh-rk45``: as ``mdh-rk4`` with scipy's RK45 (first step and max_step = h);
- ``urdf-rk4``: as ``mdh-rk4`` with the dynamics on the URDF ``Robot`` (``Robot.URDF``) itself:
  RTB's pure-Python spatial-vector RNE, some 100x slower a call.

The ``loop`` time is ``sim.run`` alone (not the imports, loading the URDF or compiling the
diagram). Output rows are the solver's own points at the interval ends (no interpolation); the
sampled controller's tau is read from the clock's state log, the continuous one's from bdsim's watch
of its output at those points. ``order`` in the RESULT is the integrator's order (4 for RK4, 5 for
RK45); ``solve_ivp_runs`` counts bdsim's solve_ivp calls (one per clock interval, or one).
"""
from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np

import reference          # benchmarks/peers/reference.py, beside this file

VARIANTS = {
    "mdh-rk4": ("mdh", "RK4", "blocks",
                "trajectory, IK (FUNCTION blocks), sampled computed torque, grip ZOH, FDYN plant; "
                "dynamics on the URDF robot as an RTB modified-DH DHRobot (C RNE); solve_ivp with a "
                "fixed-step RK4 method, max_step = h"),
    "mdh-rk4-fused": ("mdh", "RK4", "fused",
                      "trajectory, IK and computed torque in one sampled block, FDYN plant; "
                      "modified-DH DHRobot dynamics (C RNE); fixed-step RK4, max_step = h"),
    "mdh-rk4-continuous": ("mdh", "RK4", "continuous",
                           "trajectory, IK and computed torque as one continuous-time (non-sampled) "
                           "block evaluated at every right-hand-side call, no clock: one solve_ivp run "
                           "over the whole horizon; modified-DH DHRobot dynamics (C RNE); fixed-step "
                           "RK4, step h (not robofmu's zero-order-hold controller)"),
    "mdh-rk45": ("mdh", "RK45", "blocks",
                 "as mdh-rk4 with solve_ivp's RK45 (first step and max_step = h)"),
    "urdf-rk4": ("urdf", "RK4", "blocks",
                 "as mdh-rk4 with the dynamics on RTB's URDF Robot itself (pure-Python RNE, "
                 "about 40 ms a step)"),
}
DEFAULT_VARIANT = "mdh-rk4"

#: The derived DH robot must reproduce the URDF robot's FK, M(q) and rne to this.
DH_TOLERANCE = 1e-9


# -- the reference: LSPB through waypoints (robofmu components/trajectory.py) -------------------------
class Waypoints(reference.Waypoints):
    """benchmarks/peers/reference.py's trajectory (shared with the pydrake peer), its gripper as
    0/1 for a bdsim signal."""

    def __call__(self, t: float):
        x, xd, xdd, grip = self.evaluate(t)
        return x, xd, xdd, 1.0 if grip else 0.0


# -- the IK: base rotation + three pitch joints, tool pitch held (components/ik/closed_form.py) ---------
class PitchElbowIK:
    def __init__(self, spec: dict, robot, tcp: str):
        self.spec = spec
        self.qd_limit = np.asarray(spec["qd_limit"], float)
        self.robot = robot
        self.tcp = next(l for l in robot.links if l.name == tcp)
        self.C = np.array([[0.0, 1.0, 1.0, 1.0]])

    def position(self, x):
        return reference.pitch_elbow_position(self.spec, x)

    def __call__(self, x, xd, xdd):
        """q, qd, qdd of the reference. robofmu holds its last solution outside the workspace;
        this loop never leaves it, so that case is an error here."""
        q = self.position(x)
        J = self.robot.jacob0(q, end=self.tcp)
        A = np.vstack([J[:3], self.C])
        qd = np.linalg.solve(A, np.concatenate([xd, [0.0]]))
        jdot_qd = self.robot.jacob0_dot(q, qd, J0=J)[:3] @ qd
        qdd = np.linalg.solve(A, np.concatenate([np.asarray(xdd) - jdot_qd, [0.0]]))
        if np.any(np.abs(qd) > self.qd_limit):
            raise ValueError(f"IK: joint rates {qd} exceed qd_limit at q = {q}")
        return q, qd, qdd


# -- RTB robots ------------------------------------------------------------------------------------
def load_urdf(path: str, gravity):
    import roboticstoolbox as rtb

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")          # Robot.URDF() is deprecated in favour of URDF_read
        robot = rtb.Robot.URDF(path)
    robot.gravity = np.asarray(gravity, float)
    return robot


def _rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def _rx(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def _tz(d):
    T = np.eye(4)
    T[2, 3] = d
    return T


def _tx(a):
    T = np.eye(4)
    T[0, 3] = a
    return T


def _line_to_line(F):
    """F = Rz(gamma) Tz(c) Rx(alpha) Tx(a) Rz(theta) Tz(d): the fixed transform from one joint's
    z axis to the next, split at their common normal (gamma, c ride on the previous axis)."""
    R, p = F[:3, :3], F[:3, 3]
    z0, z1 = np.array([0.0, 0.0, 1.0]), R[:, 2]
    n = np.cross(z0, z1)
    if np.linalg.norm(n) > 1e-12:                       # skew or intersecting axes
        x = n / np.linalg.norm(n)
        # feet of the common normal: c z0 and p + s z1 with (p + s z1 - c z0) . z0 = . z1 = 0
        M = np.array([[1.0, -z0 @ z1], [z0 @ z1, -1.0]])
        c, s = np.linalg.solve(M, [p @ z0, p @ z1])
        foot = p + s * z1
    else:                                              # parallel axes: the normal through c = 0
        c = 0.0
        foot = p - (p @ z1) * z1
        x = foot / np.linalg.norm(foot) if np.linalg.norm(foot) > 1e-12 else np.array([1.0, 0.0, 0.0])
    a = float((foot - c * z0) @ x)
    alpha = math.atan2(np.cross(z0, z1) @ x, z0 @ z1)
    gamma = math.atan2(x[1], x[0])
    d = float((p - foot) @ z1)
    theta = math.atan2(np.cross(x, R[:, 0]) @ z1, x @ R[:, 0])
    gamma, c, alpha, a, theta, d = (0.0 if abs(v) < 1e-15 else float(v) for v in (gamma, c, alpha, a, theta, d))
    G = _rz(gamma) @ _tz(c) @ _rx(alpha) @ _tx(a) @ _rz(theta) @ _tz(d)
    if np.max(np.abs(G - F)) > 1e-12:
        raise ValueError("fixed transform does not split at a common normal")
    return gamma, c, alpha, a, theta, d


def _chain(robot, tcp: str):
    """The joint links base to tip, each with the fixed transform from the previous joint's
    frame (the base's for the first), and the tool transform to ``tcp``."""
    links = {l.name: l for l in robot.links}
    if tcp not in links:
        raise ValueError(f"no link {tcp!r}")
    path, link = [], links[tcp]
    while link is not None:
        path.append(link)
        link = link.parent
    path.reverse()
    joints, F = [], robot.base.A.copy()
    for link in path:
        if link.isjoint:
            v = link.v
            if v.kind != "Rz" or v.isflip:
                raise ValueError(f"joint of {link.name}: {v.kind}{' flipped' if v.isflip else ''}; "
                                 "only revolute joints about +z are converted")
            joints.append((link, F @ link.ets[:-1].fkine([]).A))
            F = np.eye(4)
        else:
            if link.m != 0.0 and joints:
                raise ValueError(f"static link {link.name} carries mass")
            F = F @ link.ets.fkine([]).A
    if len(joints) != robot.n:
        raise ValueError("not a serial chain to the tcp")
    return joints, F


def mdh_robot(robot, tcp: str, gravity):
    """The URDF robot as an RTB modified-DH ``DHRobot`` (its C RNE) and, per joint, the
    transform P_j from the URDF link frame to the DH frame (for payload levers)."""
    from roboticstoolbox import DHRobot, RevoluteMDH
    from spatialmath import SE3

    joints, tool = _chain(robot, tcp)
    parts = [_line_to_line(F) for _, F in joints]
    P = [np.eye(4) for _ in joints]                    # URDF link frame j -> DH frame j
    for j in range(len(joints) - 1):
        gamma, c = parts[j + 1][:2]
        P[j] = _rz(gamma) @ _tz(c)
    base = _rz(parts[0][0]) @ _tz(parts[0][1])
    links = []
    for j, ((link, _), (_, _, alpha, a, theta, d)) in enumerate(zip(joints, parts)):
        Rp, tp = P[j][:3, :3], P[j][:3, 3]
        offset = theta + (parts[j + 1][0] if j + 1 < len(parts) else 0.0)
        dj = d + (parts[j + 1][1] if j + 1 < len(parts) else 0.0)
        links.append(RevoluteMDH(d=dj, a=a, alpha=alpha, offset=offset, m=link.m,
                                 r=Rp.T @ (np.asarray(link.r) - tp), I=Rp.T @ np.asarray(link.I) @ Rp,
                                 Jm=link.Jm, G=link.G, B=link.B, Tc=np.asarray(link.Tc)))
    dh = DHRobot(links, base=SE3(base, check=False), tool=SE3(tool, check=False), name=robot.name + "-mdh",
                 gravity=np.asarray(gravity, float))
    rng = np.random.default_rng(1)
    worst = 0.0
    for _ in range(5):
        q, qd, qdd = rng.normal(size=(3, robot.n))
        worst = max(worst,
                    np.max(np.abs(dh.fkine(q).A - robot.fkine(q, end=tcp).A)),
                    np.max(np.abs(dh.inertia(q) - robot.inertia(q))),
                    np.max(np.abs(dh.rne(q, qd, qdd) - robot.rne(q, qd, qdd))))
    if worst > DH_TOLERANCE:
        raise ValueError(f"the modified-DH robot differs from the URDF robot by {worst:.3g}")
    return dh, P


class Payload:
    """A point mass switched on and off at a link of an RTB robot (the link's own parameters kept)."""

    def __init__(self, link, mass: float, lever):
        self.link, self.mass = link, float(mass)
        self.lever = np.asarray(lever, float)
        self.own = (float(link.m), np.array(link.r, float), np.array(link.I, float))
        self.on = False

    def set(self, on: bool) -> None:
        if on == self.on:
            return
        self.on = on
        m0, r0, I0 = self.own
        if not on or self.mass == 0.0:
            self.link.m, self.link.r, self.link.I = m0, r0.copy(), I0.copy()
            return
        m, p = self.mass, self.lever
        mc = m0 + m
        rc = (m0 * r0 + m * p) / mc
        E = np.eye(3)
        d0, dp = r0 - rc, p - rc
        self.link.m = mc
        self.link.r = rc
        self.link.I = I0 + m0 * (d0 @ d0 * E - np.outer(d0, d0)) + m * (dp @ dp * E - np.outer(dp, dp))


def dynamics_model(spec: dict, backend: str, payload_mass: float):
    """(robot for rne / accel, its Payload) of the given backend, a fresh instance."""
    robot = load_urdf(spec["urdf"], spec["gravity"])
    j = int(spec["payload"]["joint"]) - 1
    lever = np.asarray(spec["payload"]["lever"], float)
    if backend == "urdf":
        link = next(l for l in robot.links if l.isjoint and l.jindex == j)
        return robot, Payload(link, payload_mass, lever)
    dh, P = mdh_robot(robot, spec["tcp_frame"], spec["gravity"])
    Rp, tp = P[j][:3, :3], P[j][:3, 3]
    return dh, Payload(dh.links[j], payload_mass, Rp.T @ (lever - tp))


# -- the fixed-step RK4 method for solve_ivp ---------------------------------------------------------
def rk4_method():
    from scipy.integrate import OdeSolver
    from scipy.integrate._ivp.base import DenseOutput

    class Linear(DenseOutput):
        def __init__(self, t_old, t, y_old, y):
            super().__init__(t_old, t)
            self.y_old, self.dy = y_old, (y - y_old) / (t - t_old)

        def _call_impl(self, t):
            return self.y_old[:, None] + self.dy[:, None] * (np.atleast_1d(t) - self.t_old)

    class RK4(OdeSolver):
        """Classical RK4 in equal steps of at most max_step, landing on t_bound (robofmu's
        ``integrators.rk4``: ceil(interval / max_step) sub-steps)."""

        def __init__(self, fun, t0, y0, t_bound, vectorized=False, max_step=np.inf, **extraneous):
            super().__init__(fun, t0, y0, t_bound, vectorized)
            n = max(1, math.ceil((t_bound - t0) / max_step - 1e-9)) if np.isfinite(max_step) else 1
            self.dt = (t_bound - t0) / n
            self.t_start, self.n_steps, self.i = t0, n, 0
            self.y_old = None

        def _step_impl(self):
            t, y, dt = self.t, self.y, self.dt
            self.i += 1
            last = self.i >= self.n_steps
            # the step's end t0 + i dt (exact at one-step intervals; no drift over many steps)
            t_end = self.t_bound if last else self.t_start + self.i * self.dt
            dt = t_end - t
            k1 = self.fun(t, y)
            k2 = self.fun(t + 0.5 * dt, y + 0.5 * dt * k1)
            k3 = self.fun(t + 0.5 * dt, y + 0.5 * dt * k2)
            k4 = self.fun(t_end, y + dt * k3)
            self.y_old = y
            self.y = y + (dt / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
            self.t = t_end
            return True, None

        def _dense_output_impl(self):
            return Linear(self.t_old, self.t, self.y_old, self.y)

    return RK4


# -- the diagram -------------------------------------------------------------------------------------
def build(spec: dict, variant: str):
    import bdsim
    from bdsim.block import ContinuousBlock, SampledBlock
    from bdsim.blocks.functions import Function
    from bdsim.blocks.sampled import ZOH
    from bdsim.blocks.sources import Time
    from roboticstoolbox.blocks.arm import FDyn

    backend, method, structure = VARIANTS[variant][:3]
    h = float(spec["h"])
    n = 4
    kin = load_urdf(spec["urdf"], spec["gravity"])            # kinematics: the URDF robot
    ctrl_robot, ctrl_payload = dynamics_model(spec, backend, spec["controller"]["payload_mass"])
    plant_robot, plant_payload = dynamics_model(spec, backend, spec["plant"]["payload_mass"])
    traj = Waypoints(spec["trajectory"])
    ik = PitchElbowIK(spec["ik"], kin, spec["tcp_frame"])
    kp, kd, ki = (float(spec["controller"][k]) for k in ("kp", "kd", "ki"))
    q0 = np.asarray(spec["plant"]["q0"], float)
    qd0 = np.asarray(spec["plant"]["qd0"], float)

    def control(q_ref, qd_ref, qdd_ref, q, qd, grip, z):
        ctrl_payload.set(grip > 0.5)
        u = qdd_ref + kd * (qd_ref - qd) + kp * (q_ref - q) + ki * z
        return ctrl_robot.rne(q, qd, u)

    class ComputedTorque(SampledBlock):
        """Computed torque sampled on a clock: state [tau, z]; the output is tau, held."""

        def __init__(self, clock, x0, **blockargs):
            super().__init__(clock=clock, x0=x0, nin=6, nout=1, **blockargs)

        def output(self, t, inputs, x):
            return [x[:n]]

        def next(self, t, inputs, x):
            q_ref, qd_ref, qdd_ref, q, qd, grip = inputs
            z = x[n:]
            tau = control(q_ref, qd_ref, qdd_ref, q, qd, float(grip), z)
            return np.r_[tau, z + (q_ref - q) * h]

    class SampledController(SampledBlock):
        """Trajectory, IK and computed torque in one sampled block (a digital controller):
        inputs q, qd; state [tau, z, grip]; outputs tau and grip, held over the step."""

        def __init__(self, clock, x0, **blockargs):
            super().__init__(clock=clock, x0=x0, nin=2, nout=2, **blockargs)

        def output(self, t, inputs, x):
            return [x[:n], x[2 * n]]

        def next(self, t, inputs, x):
            q, qd = inputs
            x_ref, xd_ref, xdd_ref, grip = traj(t)
            q_ref, qd_ref, qdd_ref = ik(x_ref, xd_ref, xdd_ref)
            z = x[n:2 * n]
            tau = control(q_ref, qd_ref, qdd_ref, q, qd, grip, z)
            return np.r_[tau, z + (q_ref - q) * h, grip]

    class ContinuousController(ContinuousBlock):
        """Trajectory, IK and computed torque in continuous time (no clock, no hold), evaluated
        at every right-hand-side call: inputs q, qd; state z (the integral of the joint error,
        z' = q_ref - q); outputs tau and grip, both functions of (t, q, qd, z) now, with direct
        feedthrough from q, qd."""

        def __init__(self, **blockargs):
            super().__init__(nstates=n, x0=np.zeros(n), feedthrough=True, nin=2, nout=2, **blockargs)
            self._refs = {}                  # t -> (q_ref, qd_ref, qdd_ref, grip), the latest few

        def reference(self, t):
            """Trajectory + IK at t: a function of t alone, so the value at a time already asked
            for (an RK4 step's two middle stages share a time, and its last stage the next step's
            first) is reused, exactly, from the latest few times."""
            ref = self._refs.get(t)
            if ref is None:
                x_ref, xd_ref, xdd_ref, grip = traj(t)
                ref = (*ik(x_ref, xd_ref, xdd_ref), grip)
                if len(self._refs) >= 4:
                    del self._refs[next(iter(self._refs))]
                self._refs[t] = ref
            return ref

        def output(self, t, inputs, x):
            q, qd = inputs
            q_ref, qd_ref, qdd_ref, grip = self.reference(t)
            return [control(q_ref, qd_ref, qdd_ref, q, qd, grip, x), grip]

        def deriv(self, t, inputs, x):
            return self.reference(t)[0] - inputs[0]

    class Plant(FDyn):
        """RTB's FDYN with a second input: the (held) grip, carrying the payload while closed."""

        nin = 2
        inlabels = ("tau", "grip")

        def __init__(self, robot, q0, qd0, **blockargs):
            super().__init__(robot, q0=q0, **blockargs)
            self._x0 = np.r_[q0, qd0]
            self.inport_names(("tau", "grip"))

        def deriv(self, t, inputs, x):
            plant_payload.set(float(inputs[1]) > 0.5)
            return super().deriv(t, inputs[:1], x)

    # the held values over [0, h]: the first sample, at t = 0
    x_ref, xd_ref, xdd_ref, grip0 = traj(0.0)
    r0 = ik(x_ref, xd_ref, xdd_ref)
    tau0 = control(*r0, q0, qd0, grip0, np.zeros(n))

    # toolboxes=False: bdsim 1.4.0's block-library scan trips over a docstring of RTB 1.5.0's
    # Bicycle block (KeyError 'type'); RTB's FDyn is imported directly instead.
    sim = bdsim.BDSim(sysargs=False, banner=False, graphics=False, animation=False, progress=False,
                      quiet=True, toolboxes=False)
    bd = sim.blockdiagram(name="chess-pd")
    # no clock in the continuous variant: a clock's ticks would split the run into intervals
    clock = None if structure == "continuous" else bd.clock(h, "s", name="control")
    plant = Plant(plant_robot, q0, qd0, bd=bd, name="plant")
    if structure == "continuous":
        ctc = ContinuousController(bd=bd, name="controller")
        bd.connect(plant[0], ctc[0])
        bd.connect(plant[1], ctc[1])
        bd.connect(ctc[0], plant[0])
        bd.connect(ctc[1], plant[1])
    elif structure == "blocks":
        t_src = Time(bd=bd, name="time")
        ref = Function(lambda t: list(traj(t)), nin=1, nout=4, bd=bd, name="trajectory")
        ikb = Function(lambda x, xd, xdd: list(ik(x, xd, xdd)), nin=3, nout=3, bd=bd, name="ik")
        ctc = ComputedTorque(clock, x0=np.r_[tau0, np.zeros(n)], bd=bd, name="controller")
        hold = ZOH(clock, x0=[grip0], bd=bd, name="grip_hold")
        bd.connect(t_src[0], ref[0])
        for i in range(3):
            bd.connect(ref[i], ikb[i])
            bd.connect(ikb[i], ctc[i])
        bd.connect(plant[0], ctc[3])
        bd.connect(plant[1], ctc[4])
        bd.connect(ref[3], ctc[5], hold[0])
        bd.connect(ctc[0], plant[0])
        bd.connect(hold[0], plant[1])
    else:
        ctc = SampledController(clock, x0=np.r_[tau0, np.zeros(n), grip0], bd=bd, name="controller")
        bd.connect(plant[0], ctc[0])
        bd.connect(plant[1], ctc[1])
        bd.connect(ctc[0], plant[0])
        bd.connect(ctc[1], plant[1])
    with contextlib.redirect_stdout(sys.stderr):      # its notes (FDYN's qdd output unused) off stdout
        bd.compile(report=False, verbose=False)
    return sim, bd, clock, plant, ctc, {"method": rk4_method() if method == "RK4" else rk45_interval_method()}


def rk45_interval_method():
    """scipy's RK45 whose first step is the whole interval (one clock period): solve_ivp's
    ``first_step = h`` is refused when the interval rounds to a hair under h."""
    from scipy.integrate import RK45

    class RK45Interval(RK45):
        def __init__(self, fun, t0, y0, t_bound, **options):
            options["first_step"] = min(t_bound - t0, options.get("max_step", np.inf))
            super().__init__(fun, t0, y0, t_bound, **options)

    return RK45Interval


def run(spec: dict, variant: str, out: Path) -> dict:
    import roboticstoolbox as rtb

    h, stop, N = float(spec["h"]), float(spec["stop"]), int(spec["n_steps"])
    n = 4
    sim, bd, clock, plant, ctc, solver_args = build(spec, variant)
    continuous = clock is None
    # the continuous controller's tau, logged by bdsim at the solver's points (its output there)
    watch = [ctc[0]] if continuous else None
    t0 = time.perf_counter()
    # max_step: the plant's max_substep (robofmu's RK4 sub-step; h in chess-pd), a hair over it
    # since an interval k h - (k - 1) h may round to just above h, which would add a 1e-16 s step
    # (over one run of the whole horizon: ceil(stop / max_step) = N equal steps of stop / N = h)
    max_step = min(h, float(spec["plant"]["max_substep"])) * (1.0 + 1e-9)
    res = sim.run(bd, T=stop, max_step=max_step, solver_args=solver_args, watch=watch)
    loop = time.perf_counter() - t0

    grid = h * np.arange(N + 1)
    # continuous state [q, qd] at the interval ends (the solver's own points, no interpolation)
    t_out, x_out = np.asarray(res.t, float), np.asarray(res.x, float)
    x0 = np.asarray(bd.getstate0(), float)
    if t_out.size == 0 or abs(t_out[0]) > 1e-12:
        t_out, x_out = np.r_[0.0, t_out], np.vstack([x0, x_out])
    k = np.searchsorted(t_out, grid - 1e-9)
    k = np.minimum(k, len(t_out) - 1)
    if np.max(np.abs(t_out[k] - grid)) > 1e-9:
        raise RuntimeError("the solver's points miss some communication points")
    X = x_out[k]
    offset = 0                           # the plant's [q, qd] in the continuous state vector
    for b in bd.blocklist:
        if b is plant:
            break
        if b.blockclass == "continuous":
            offset += b.nstates
    X = X[:, offset:offset + 2 * n]
    if continuous:
        tau = np.asarray(res["y"], float)[:, :n]
        if tau.shape[0] != len(t_out):
            raise RuntimeError("the watched tau does not match the solver's points")
        data = np.hstack([X[:, :n], X[:, n:2 * n], tau[k]])
    else:
        data = np.hstack([X[:, :n], X[:, n:2 * n], _clock_tau(res, clock, ctc, grid, n)])
    columns = ([f"plant.q[{j}]" for j in range(1, n + 1)] + [f"plant.qd[{j}]" for j in range(1, n + 1)]
               + [f"controller.tau[{j}]" for j in range(1, n + 1)])
    np.savez(out, time=grid, data=data, columns=np.array(columns))
    stats = res[".stats"] if ".stats" in res else None
    method = VARIANTS[variant][1]
    info = {"peer": "bdsim + RTB",
            "version": f"bdsim {_version('bdsim')}, roboticstoolbox {getattr(rtb, '__version__', '?')}",
            "variant": variant, "order": {"RK4": 4, "RK45": 5}[method], "loop": loop, "n_steps": N,
            "per_step": loop / N, "interpolated": False}
    if stats is not None:
        info["rhs_calls"] = int(stats["ydot_calls"])
        info["solve_ivp_runs"] = int(stats["run_interval_calls"])
    return info


def _clock_tau(res, clock, ctc, grid, n: int):
    """The sampled controller's tau at t_k: its state logged at each tick (t = h .. stop), its
    x0 at t = 0."""
    log = next(res[key] for key in ("clock0", clock.name.replace(".", "")) if key in res)
    t_log = np.asarray(log["t"], float)
    x_log = np.asarray(log["X"] if "X" in log else log["x"], float)
    offset = 0
    for b in clock.blocklist:
        if b is ctc:
            break
        offset += b.ndstates
    tau = np.vstack([ctc.getstate0()[:n][None, :], x_log[:, offset:offset + n]])
    t_tau = np.r_[0.0, t_log]
    kt = np.searchsorted(t_tau, grid - 1e-9)
    kt = np.minimum(kt, len(t_tau) - 1)
    if np.max(np.abs(t_tau[kt] - grid)) > 1e-9:
        raise RuntimeError("the clock log misses some ticks")
    return tau[kt]


def _version(dist: str) -> str:
    from importlib.metadata import version

    return version(dist)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("spec", nargs="?", help="loop spec JSON (benchmarks/loop_spec.py)")
    parser.add_argument("out", nargs="?", help="trajectory .npz to write")
    parser.add_argument("--variant", default=DEFAULT_VARIANT, choices=list(VARIANTS))
    parser.add_argument("--list-variants", action="store_true", help="print the variants, fastest first")
    args = parser.parse_args(argv)
    if args.list_variants:
        for name, (*_, what) in VARIANTS.items():
            print(f"{name}\t{what}")
        return 0
    if not args.spec or not args.out:
        parser.error("SPEC.json and OUT.npz are required")
    spec = json.loads(Path(args.spec).read_text())
    info = run(spec, args.variant, Path(args.out))
    print("RESULT " + json.dumps(info), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

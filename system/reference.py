"""The monolithic reference: the co-simulated loop as one ODE with a continuous controller.

The co-simulation (``trajectory -> ik -> controller -> plant``, q and qd fed back) samples the
controller at communication points, holds its torque over each step and advances the integral
by forward Euler. The reference removes every one of those approximations: with state
``x = (q, qd, z)`` (dimension 3n, 12 for the chess arm)

    q_ref, qd_ref, qdd_ref = IK(trajectory(t))
    tau  = M_model(q) (qdd_ref + kd (qd_ref - qd) + kp (q_ref - q) + ki z) + N_model(q, qd)
    qdd  = FD_true(q, qd, tau)               (plant: the true arm, payload while grip)
    z'   = q_ref - q

and integrates it with DOP853 at tight tolerances (rtol 1e-10, atol 1e-12) piecewise between
every instant where the right-hand side is discontinuous: the start and end of every
trajectory segment (moves and pauses), the blend switches ``start + tb`` and ``end - tb`` of
every LSPB move (``tb = T - T / cruise_factor``, T/3 for the default 1.5), the gripper's
closing and opening times, and the trajectory's end. Within one piece the right-hand side is
smooth, so the integrator's error estimate holds and the reference is accurate to about 1e-9.

Everything the loop needs (gains, gravity, payloads, initial state, scenario, IK options) is
read from a :class:`~robofmu.system.diagram.System` (:meth:`LoopSetup.from_system`): the block
parameters set by the experiment over the start values in each FMU's model description.

Conventions at a discontinuity instant match the blocks': the trajectory's grip and
:meth:`WaypointTrajectory.evaluate` are read at the instant itself for the recorded outputs
(torque, references); the state is continuous there.

Examples
--------
>>> from robofmu.system.experiment import load
>>> from robofmu.system.reference import reference_run
>>> system = load("chess-pd", fmu_dir="fmus")
>>> ref = reference_run(system, np.linspace(0.0, 13.0, 1301))
>>> ref.vector("plant.q").shape
(1301, 4)
"""
from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass, replace

import numpy as np
from scipy.integrate import solve_ivp

from robofmu.components.control import ComputedTorque
from robofmu.components.ik import make_ik
from robofmu.components.robot import Robot, load_spec
from robofmu.components.trajectory import (WaypointTrajectory, format_matrix, format_vector,
                                           parse_matrix, parse_vector)

from .diagram import System
from .master import Result, step_count

__all__ = ["LoopSetup", "MonolithicLoop", "reference_run", "discontinuities"]

#: Offset (s) by which the trajectory is evaluated inside a piece when the integrator asks for
#: the piece's very ends, so that the branch of the piece is used there (a piece's right-hand
#: side is the smooth continuation of its interior). Moves the reference by < 1e-12 m.
_INSIDE = 1e-11


# ------------------------------------------------------------------------------------------------
# parameters
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class LoopSetup:
    """Everything the closed loop depends on.

    Parameters
    ----------
    robot : str
        Robot description name (``components/robots/<robot>``).
    kp, kd, ki : float
        Controller gains (1/s^2, 1/s, 1/s^3), the same on every joint.
    model_gravity : float
        Gravity (m/s^2) in the controller's model.
    model_payload : float
        Payload (kg) the controller's model assumes at the TCP while the gripper is closed
        (0: the controller does not know the pawn).
    gravity : float
        Gravity (m/s^2) acting on the true arm (the plant).
    payload : float
        Point mass (kg) the true arm carries at the TCP while the gripper is closed.
    q0, qd0 : ndarray, shape (n,)
        Initial joint positions (rad or m) and velocities (rad/s or m/s).
    max_substep : float
        The plant block's largest RK4 sub-step (s). Not used by the monolithic reference (which
        is integrated adaptively); kept for in-process replicas of the sampled loop.
    waypoints : ndarray, shape (k + 1, 3)
        Trajectory waypoints (m).
    durations : ndarray, shape (k,)
        Move durations (s).
    pause : float
        Rest between moves (s).
    cruise_factor : float
        LSPB cruise speed over mean speed, in (1, 2].
    grip_close_after_move, grip_open_after_move : int
        Gripper events (1-based move numbers; 0 = never).
    tool_pitch : float or None
        IK tool pitch (rad); None: the robot description's.
    elbow : str or None
        IK branch ("up" / "down"); None: the robot description's.
    """

    robot: str
    kp: float
    kd: float
    ki: float
    model_gravity: float
    model_payload: float
    gravity: float
    payload: float
    q0: np.ndarray
    qd0: np.ndarray
    waypoints: np.ndarray
    durations: np.ndarray
    pause: float
    cruise_factor: float
    grip_close_after_move: int = 0
    grip_open_after_move: int = 0
    tool_pitch: float | None = None
    elbow: str | None = None
    max_substep: float = 1e-3

    # -- constructors --------------------------------------------------------------------------
    @classmethod
    def from_robot(cls, robot: str = "chess", gains: str = "pd", model_knows_payload: bool = True,
                   **overrides) -> "LoopSetup":
        """The loop of ``robot``'s scenario with its seed ``gains`` ("pd" or "pid").

        Mirrors the blocks' defaults: gravity and payload from the description, the plant
        starting at rest at the IK of the first waypoint. ``overrides`` replace any field.
        """
        spec = load_spec(robot)
        g = spec.gains(gains)
        s = spec.scenario
        r = Robot(spec)
        q0 = make_ik(r).position(np.asarray(s["waypoints"][0], dtype=float))
        setup = cls(robot=spec.name, kp=g["kp"], kd=g["kd"], ki=g["ki"],
                    model_gravity=spec.gravity,
                    model_payload=spec.payload_mass if model_knows_payload else 0.0,
                    gravity=spec.gravity, payload=spec.payload_mass,
                    q0=q0, qd0=np.zeros(r.n),
                    waypoints=np.asarray(s["waypoints"], dtype=float),
                    durations=np.asarray(s["durations"], dtype=float),
                    pause=float(s.get("pause", 0.0)), cruise_factor=float(s.get("cruise_factor", 1.5)),
                    grip_close_after_move=int(s.get("grip_close_after_move", 0)),
                    grip_open_after_move=int(s.get("grip_open_after_move", 0)))
        return replace(setup, **overrides) if overrides else setup

    @classmethod
    def from_system(cls, system: System, trajectory: str = "trajectory", ik: str = "ik",
                    controller: str = "controller", plant: str = "plant") -> "LoopSetup":
        """Read the loop from a diagram: each block's parameters as the experiment sets them,
        over the start values of its FMU's model description (or, if the FMU file is absent,
        over the block's documented defaults for the robot).

        Parameters
        ----------
        system : System
            E.g. ``robofmu.system.experiment.load("chess-pid")``.
        trajectory, ik, controller, plant : str
            Instance names of the four blocks.

        Raises
        ------
        KeyError
            If a block is missing from the diagram.
        """
        robot = str(system.extra.get("robot", "chess"))
        defaults = cls.from_robot(robot, "pd", model_knows_payload=False)
        n = len(defaults.q0)

        tp = _parameters(system, trajectory, {
            "waypoints": format_matrix(defaults.waypoints),
            "durations": format_vector(defaults.durations),
            "pause": defaults.pause, "cruise_factor": defaults.cruise_factor,
            "grip_close_after_move": defaults.grip_close_after_move,
            "grip_open_after_move": defaults.grip_open_after_move})
        spec = load_spec(robot)
        ip = _parameters(system, ik, {"tool_pitch": float(spec.raw["tool_pitch"]),
                                      "elbow": spec.raw.get("elbow", "up")})
        cp = _parameters(system, controller, {"kp": defaults.kp, "kd": defaults.kd, "ki": defaults.ki,
                                              "g": defaults.model_gravity, "payload_mass": 0.0})
        pdefaults = {"g": defaults.gravity, "payload_mass": defaults.payload, "max_substep": 1e-3}
        pdefaults.update({f"q0[{i + 1}]": float(v) for i, v in enumerate(defaults.q0)})
        pdefaults.update({f"qd0[{i + 1}]": 0.0 for i in range(n)})
        pp = _parameters(system, plant, pdefaults)
        return cls(robot=robot,
                   kp=float(cp["kp"]), kd=float(cp["kd"]), ki=float(cp["ki"]),
                   model_gravity=float(cp["g"]), model_payload=float(cp["payload_mass"]),
                   gravity=float(pp["g"]), payload=float(pp["payload_mass"]),
                   q0=np.array([float(pp[f"q0[{i + 1}]"]) for i in range(n)]),
                   qd0=np.array([float(pp[f"qd0[{i + 1}]"]) for i in range(n)]),
                   waypoints=parse_matrix(str(tp["waypoints"]), "waypoints"),
                   durations=parse_vector(str(tp["durations"]), "durations"),
                   pause=float(tp["pause"]), cruise_factor=float(tp["cruise_factor"]),
                   grip_close_after_move=int(tp.get("grip_close_after_move", 0)),
                   grip_open_after_move=int(tp.get("grip_open_after_move", 0)),
                   tool_pitch=float(ip["tool_pitch"]), elbow=str(ip["elbow"]),
                   max_substep=float(pp.get("max_substep", 1e-3)))

    # -- derived objects -------------------------------------------------------------------------
    def trajectory(self) -> WaypointTrajectory:
        """The task-space reference (the trajectory block's logic)."""
        return WaypointTrajectory(self.waypoints, self.durations, pause=self.pause,
                                  cruise_factor=self.cruise_factor,
                                  grip_close_after_move=self.grip_close_after_move,
                                  grip_open_after_move=self.grip_open_after_move)


def _parameters(system: System, name: str, fallback: dict) -> dict:
    """A block's parameter values by scalar name: FMU start values (or ``fallback``), then the
    experiment's settings (a vector base set to a list fills ``base[1]`` .. ``base[n]``)."""
    block = system.block(name)
    path = system.fmu_path(block)
    values = dict(fallback)
    if path.is_file():
        from fmpy import read_model_description

        md = read_model_description(str(path), validate=False)
        for v in md.modelVariables:
            if v.causality == "parameter" and v.start is not None:
                values[v.name] = _parse_start(v.type, v.start)
    for key, value in block.parameters.items():
        if isinstance(value, (list, tuple, np.ndarray)):
            for i, item in enumerate(value, start=1):
                values[f"{key}[{i}]"] = item
        else:
            values[key] = value
    return values


def _parse_start(kind: str, text):
    if not isinstance(text, str):
        return text
    if kind == "Real":
        return float(text)
    if kind in ("Integer", "Enumeration"):
        return int(text)
    if kind == "Boolean":
        return text.strip().lower() in ("true", "1")
    return text


def discontinuities(trajectory: WaypointTrajectory, t_end: float) -> np.ndarray:
    """Instants in (0, t_end) where the loop's right-hand side jumps, sorted, unique.

    Segment starts and ends, each LSPB move's blend switches (``start + tb``, ``end - tb``
    with ``tb = T - T / cruise_factor``), the gripper's closing and opening and the
    trajectory's end.

    Parameters
    ----------
    trajectory : WaypointTrajectory
    t_end : float
        End of the interval of interest (s).

    Returns
    -------
    ndarray, shape (m,)
        Times (s).
    """
    times = trajectory.breakpoints          # segment bounds (gripper events among them), blend switches
    times = times[(times > 0.0) & (times < t_end)]
    # merge instants closer than rounding (e.g. a blend switch equal to a segment end)
    if times.size:
        keep = np.concatenate([[True], np.diff(times) > 1e-9])
        times = times[keep]
    return times


# ------------------------------------------------------------------------------------------------
# the loop
# ------------------------------------------------------------------------------------------------
class MonolithicLoop:
    """The closed loop as one ODE in (q, qd, z), with a continuous computed-torque controller.

    Parameters
    ----------
    setup : LoopSetup
    rtol, atol : float
        DOP853 tolerances (relative; absolute in rad, rad/s, rad.s).

    Notes
    -----
    :meth:`solve` integrates once up to a time; :meth:`evaluate` then samples the dense output
    at any times within it (cheap), so one solve serves every communication grid.
    """

    def __init__(self, setup: LoopSetup, rtol: float = 1e-10, atol: float = 1e-12):
        self.setup = setup
        self.rtol, self.atol = float(rtol), float(atol)
        spec = load_spec(setup.robot)
        self.plant = Robot(spec, gravity=setup.gravity)            # the true arm
        self.model = Robot(spec, gravity=setup.model_gravity)      # the controller's model
        self.law = ComputedTorque(self.model, setup.kp, setup.kd, setup.ki)
        self.ik = make_ik(Robot(spec), tool_pitch=setup.tool_pitch, elbow=setup.elbow)
        self.trajectory = setup.trajectory()
        self.n = self.plant.n
        self.pieces: list = []        # (t0, t1, grip, OdeSolution)
        self.t_end = 0.0
        self.stats = {"nfev": 0, "pieces": 0, "wall_time": 0.0}

    # -- pieces of the right-hand side ----------------------------------------------------------
    def references(self, t: float, snap: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Joint reference (q_ref, qd_ref, qdd_ref) at ``t`` (s), each shape (n,); ``snap`` as in
        :meth:`WaypointTrajectory.evaluate`."""
        x, xd, xdd = self.trajectory.evaluate(t, snap)
        return self.ik.solve(x, xd, xdd)

    def _payloads(self, grip: bool) -> None:
        self.plant.set_payload(self.setup.payload if grip else 0.0)
        self.model.set_payload(self.setup.model_payload if grip else 0.0)

    def rhs(self, t: float, x: np.ndarray, lo: float, hi: float, grip: bool) -> np.ndarray:
        """x' on the piece [lo, hi] where the gripper state is ``grip``; shape (3n,)."""
        n = self.n
        q, qd, z = x[:n], x[n:2 * n], x[2 * n:]
        t_ref = min(max(t, lo + _INSIDE), hi - _INSIDE)
        self._payloads(grip)
        q_ref, qd_ref, qdd_ref = self.references(t_ref, snap=False)
        self.law.z[:] = z
        tau = self.law.torque(q_ref, qd_ref, qdd_ref, q, qd)
        qdd = self.plant.forward_dynamics(q, qd, tau)
        return np.concatenate([qd, qdd, q_ref - q])

    # -- integration ------------------------------------------------------------------------------
    def solve(self, t_end: float) -> "MonolithicLoop":
        """Integrate from 0 to ``t_end`` (s), piecewise between the discontinuities; returns self.

        Raises
        ------
        RuntimeError
            If the integrator fails on a piece (naming it).
        """
        if not (t_end > 0 and math.isfinite(t_end)):
            raise ValueError(f"t_end: must be > 0 s, got {t_end}")
        wall = _time.perf_counter()
        s = self.setup
        x = np.concatenate([np.asarray(s.q0, float), np.asarray(s.qd0, float), np.zeros(self.n)])
        bounds = np.concatenate([[0.0], discontinuities(self.trajectory, t_end), [t_end]])
        self.pieces, nfev = [], 0
        for lo, hi in zip(bounds[:-1], bounds[1:]):
            grip = self.trajectory.grip(0.5 * (lo + hi))
            sol = solve_ivp(self.rhs, (lo, hi), x, method="DOP853", rtol=self.rtol, atol=self.atol,
                            dense_output=True, args=(lo, hi, grip))
            if not sol.success:
                raise RuntimeError(f"reference: integration failed on [{lo:.9g}, {hi:.9g}] s: {sol.message}")
            nfev += sol.nfev
            self.pieces.append((float(lo), float(hi), grip, sol.sol))
            x = sol.y[:, -1]
        self.t_end = float(t_end)
        self._bounds = bounds
        self.stats = {"nfev": nfev, "pieces": len(self.pieces),
                      "wall_time": _time.perf_counter() - wall}
        return self

    def state(self, times: np.ndarray) -> np.ndarray:
        """The state (q, qd, z) at ``times`` (s, within [0, t_end]); shape (len(times), 3n)."""
        times = np.atleast_1d(np.asarray(times, dtype=float))
        if not self.pieces:
            raise RuntimeError("reference: call solve(t_end) first")
        tol = 1e-9 * max(1.0, self.t_end)
        if times.size and (times.min() < -tol or times.max() > self.t_end + tol):
            raise ValueError(f"times must lie in [0, {self.t_end}] s (solved so far), got "
                             f"[{times.min()}, {times.max()}]")
        idx = np.clip(np.searchsorted(self._bounds, times, side="right") - 1, 0, len(self.pieces) - 1)
        out = np.empty((times.size, 3 * self.n))
        for i in np.unique(idx):
            sel = idx == i
            lo, hi, _, sol = self.pieces[i]
            out[sel] = sol(np.clip(times[sel], lo, hi)).T
        return out

    def evaluate(self, times: np.ndarray, outputs: bool = True) -> dict[str, np.ndarray]:
        """Sample the solved loop.

        Parameters
        ----------
        times : array_like, shape (m,)
            Times (s) within [0, t_end].
        outputs : bool
            Also compute the torque, the references and the TCP (one IK and one model evaluation
            per time; about 0.1 ms each).

        Returns
        -------
        dict
            ``q`` (m, n) rad, ``qd`` (m, n) rad/s, ``z`` (m, n) rad.s; with ``outputs``: ``tau``
            (m, n) N.m, ``q_ref``, ``qd_ref``, ``qdd_ref`` (m, n), ``x_ref`` (m, 3) m, ``tcp``
            (m, 3) m (TCP of q), ``grip`` (m,) bool.
        """
        times = np.atleast_1d(np.asarray(times, dtype=float))
        n = self.n
        x = self.state(times)
        out = {"time": times, "q": x[:, :n], "qd": x[:, n:2 * n], "z": x[:, 2 * n:]}
        if not outputs:
            return out
        m = times.size
        tau, q_ref, qd_ref, qdd_ref = (np.empty((m, n)) for _ in range(4))
        x_ref, tcp = np.empty((m, 3)), np.empty((m, 3))
        grip = np.empty(m, dtype=bool)
        for k, t in enumerate(times):
            xr, xdr, xddr = self.trajectory.evaluate(t)
            g = self.trajectory.grip(t)
            self._payloads(g)
            q_ref[k], qd_ref[k], qdd_ref[k] = self.ik.solve(xr, xdr, xddr)
            self.law.z[:] = out["z"][k]
            tau[k] = self.law.torque(q_ref[k], qd_ref[k], qdd_ref[k], out["q"][k], out["qd"][k])
            x_ref[k], grip[k] = xr, g
            tcp[k] = self.plant.fk(out["q"][k])
        out.update(tau=tau, q_ref=q_ref, qd_ref=qd_ref, qdd_ref=qdd_ref, x_ref=x_ref, tcp=tcp, grip=grip)
        return out

    def to_result(self, times: np.ndarray) -> Result:
        """:meth:`evaluate` as a :class:`~robofmu.system.master.Result` whose columns are named
        like the co-simulation's (``plant.q[i]``, ``plant.qd[i]``, ``controller.tau[i]``,
        ``ik.q_ref[i]``, ``ik.qd_ref[i]``, ``ik.qdd_ref[i]``, ``trajectory.x_ref[i]``,
        ``trajectory.grip``) plus ``controller.z[i]`` and ``tcp.x[i]`` (TCP of plant.q, m)."""
        e = self.evaluate(times)
        blocks = [("trajectory.x_ref", e["x_ref"]), ("ik.q_ref", e["q_ref"]), ("ik.qd_ref", e["qd_ref"]),
                  ("ik.qdd_ref", e["qdd_ref"]), ("plant.q", e["q"]), ("plant.qd", e["qd"]),
                  ("controller.tau", e["tau"]), ("controller.z", e["z"]), ("tcp.x", e["tcp"])]
        columns, data = [], []
        for base, values in blocks:
            columns += [f"{base}[{i + 1}]" for i in range(values.shape[1])]
            data.append(values)
        columns.append("trajectory.grip")
        data.append(e["grip"].astype(float)[:, None])
        info = {"algorithm": "monolithic", "method": "DOP853", "rtol": self.rtol, "atol": self.atol,
                **self.stats}
        return Result(np.asarray(times, float).copy(), columns, np.hstack(data), info)


# ------------------------------------------------------------------------------------------------
# one-call API
# ------------------------------------------------------------------------------------------------
def reference_run(system: System | LoopSetup, times=None, rtol: float = 1e-10,
                  atol: float = 1e-12) -> Result:
    """The monolithic reference of an experiment, recorded like a co-simulation run.

    Parameters
    ----------
    system : System or LoopSetup
        The experiment (gains, payloads, gravity, initial state and scenario are read from its
        blocks' parameters).
    times : array_like, shape (m,), optional
        Output times (s). Default: the experiment's grid, 0 to ``stop_time`` by ``step``.
    rtol, atol : float
        DOP853 tolerances.

    Returns
    -------
    Result
        ``result.vector("plant.q")`` (m, n) etc.; see :meth:`MonolithicLoop.to_result`.
        ``result.info`` holds the integrator's statistics (``nfev``, ``pieces``, ``wall_time``).
    """
    setup = system if isinstance(system, LoopSetup) else LoopSetup.from_system(system)
    if times is None:
        if not isinstance(system, System):
            raise ValueError("times: required when a LoopSetup is given")
        k = step_count(0.0, system.stop_time, system.step)
        times = system.step * np.arange(k + 1)
    times = np.atleast_1d(np.asarray(times, dtype=float))
    loop = MonolithicLoop(setup, rtol, atol).solve(float(times.max()))
    return loop.to_result(times)

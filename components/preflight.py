"""Checks at build time of what a run would otherwise discover: a robot's reference against its
joints' limits.

:func:`check_reference` samples the robot's reference trajectory (its ``[trajectory]``, the
trajectory block's defaults) and, for a task-space reference, solves its IK along it as the IK
block does at run time (warm starts, one sample per communication step), its rates unclipped: it
measures them against the velocity limits itself, over the whole path. It refuses, in one line
naming the key to change:

- a reference beyond a velocity limit: the joint, the limit and where it is set (URDF or the
  TOML's ``[joints.limits.<joint>]``), the worst ratio |qd| / limit with its time, and the time
  law scaled by that ratio (a path run r times slower has every rate divided by r): the
  ``duration`` (``durations``) or the limits (``v_max`` / r, ``a_max`` / r^2, ...) that fit,
  checked to pass before they are proposed;
- a reference beyond a position limit: the deepest excursion and its time (for a task-space
  reference, where the IK stops on a limit, the path solved again without position limits
  tells how deep it would go);
- a singularity (the IK's smallest singular value below its ``singular_value``), named as such;
- a target the IK cannot reach;
- a reference that does not start at home (where the plant starts, at rest), with the profile's
  way to start there.

The ``home`` configuration must lie within the position limits too.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pinocchio as pin

from .blocks import make_block
from .blocks.ik import NO_RATE_LIMIT
from .robots import RobotDescription, load_model
from .trajectory import slowed

__all__ = ["ReferenceCheck", "ReferenceRefused", "check_reference", "check_references"]

#: The worst ratio is raised by this factor before the time law is scaled by it, so that the
#: parameters proposed pass (a redundant arm's null-space motion is not scaled by the time law).
MARGIN = 1.005
#: Proposals tried at most, each checked along the whole path, before the last is given.
ATTEMPTS = 4
#: How far (rad or m) the reference's first joint positions may lie from home, where the plant
#: starts at rest, before the loop would jump at t = 0.
START_TOLERANCE = 1e-3
#: Rotation (rad) about a frame axis the task leaves free below which a reference is taken not to turn about it.
UNTRACKED_ROTATION = 1e-6


@dataclass(frozen=True)
class ReferenceCheck:
    """What :func:`check_reference` found along an acceptable reference.

    Attributes
    ----------
    samples : int
    duration : float
        s.
    position_margin : float
        Smallest distance of a joint to its position limits along the reference (rad or m; inf
        without limits).
    speed_ratio : float
        Largest |qd| over the velocity limit along the reference (1: at the limit).
    ik_residual : float or None
        Largest IK residual reported along the reference (m, or the solver's unit), where the
        solver reports one.
    fastest_joint : str
        The joint at ``speed_ratio`` ("" where no joint moves).
    fastest_time : float
        When (s).
    untracked : tuple of (float, int, float) or None
        For a pose task that leaves some of the frame's axes free (``orientation_axes``): the
        largest rotation (rad) the reference asks about one of them, from its start, the axis
        (0, 1, 2: the frame's x, y, z) and when (s); the IK does not track it. None otherwise.
    """

    samples: int
    duration: float
    position_margin: float
    speed_ratio: float
    ik_residual: float | None
    fastest_joint: str = ""
    fastest_time: float = 0.0
    untracked: tuple[float, int, float] | None = None


class ReferenceRefused(ValueError):
    """The reference leaves the workspace or the joints' limits; the message names joint, limit, time."""


@dataclass(frozen=True)
class _Sampled:
    """A reference sampled (through the IK for a task-space one) up to its end or a failure."""

    duration: float                  # s: the profile's end
    times: np.ndarray                # (k,) s: the samples solved
    q: np.ndarray                    # (k, n)
    qd: np.ndarray                   # (k, n)
    residual: float | None
    failure: tuple[float, str, bool] | None   # (t, the IK block's reason, at a singularity)
    untracked: tuple[float, int, float] | None = None   # (rad, free axis, t): see ReferenceCheck


def check_references(description: RobotDescription, step_size: float = 1e-3) -> dict[str, ReferenceCheck]:
    """:func:`check_reference` of the robot's reference and of each named profile, by profile
    name ("" the default); empty for a robot without a trajectory block."""
    found = {}
    for fmu in description.fmu_blocks:
        kind, profile, described = description.block_of(fmu)
        if kind == "trajectory":
            found[profile] = check_reference(described, step_size,
                                             f"trajectories.{profile}" if profile else "trajectory")
    if not found:
        check_reference(description, step_size)        # home within the limits
    return found


def check_reference(description: RobotDescription, step_size: float = 1e-3,
                    table: str = "trajectory") -> ReferenceCheck | None:
    """Sample the robot's reference at ``step_size`` (s) and check it against the joint limits.

    ``table`` is the reference's key in the robot's TOML (``trajectories.<name>`` for a named
    profile), named by a refusal. Returns None for a robot without a trajectory block.

    Raises
    ------
    ReferenceRefused
        One line, beginning with the TOML's path and ``table``: the worst velocity excess with
        the time law that fits, the deepest position excursion, a singularity or a target the
        IK cannot reach, each with joint, limit and time.
    """
    robot = load_model(description)
    lower, upper = robot.position_limits()
    speed = robot.velocity_limits()
    home = np.asarray(robot.configuration("home"), dtype=float)
    outside = np.flatnonzero((home < lower) | (home > upper))
    if outside.size:
        j = int(outside[0])
        unit = robot.joint_units(0)[j]
        side, limit = ("lower", lower[j]) if home[j] < lower[j] else ("upper", upper[j])
        state = description.srdf_configurations.get("home")
        raise ReferenceRefused(f"{description.path}: configurations.home: "
                               + (f"the SRDF state {state!r} " if state else "") + f"puts joint {j + 1} "
                               f"({robot.joint_names[j]}) at {home[j]:.6g} {unit}, beyond its {side} limit "
                               f"{limit:.6g} {unit} ({_source(description, robot.joint_names[j], side)}); "
                               + _home_fix(home[j], lower[j], upper[j], unit, bool(state)))
    if "trajectory" not in description.blocks:
        return None
    sampled = _sample(description, step_size)
    if sampled is None:
        return None
    where = f"{description.path}: {table}: "
    if sampled.failure is not None:
        raise ReferenceRefused(where + _failure(description, robot, sampled, step_size))
    if len(sampled.times) and np.max(np.abs(sampled.q[0] - home)) > START_TOLERANCE:
        raise ReferenceRefused(where + _away(robot, description, table, sampled.q[0], home))
    beyond = _deepest(robot, description, sampled, lower, upper)
    if beyond:
        raise ReferenceRefused(where + beyond)
    ratio, k, j = _fastest(sampled.qd, speed)
    if ratio > 1.0:
        unit = robot.joint_units(1)[j]
        first = sampled.times[np.flatnonzero(np.abs(sampled.qd[:, j]) > speed[j])[0]]
        joint = robot.joint_names[j]
        raise ReferenceRefused(
            f"{where}the reference drives joint {j + 1} ({joint}) beyond its velocity limit {speed[j]:.6g} {unit} "
            f"({_source(description, joint, 'velocity')}) from t = {first:.6g} s, at worst {ratio:.3g} × the limit "
            f"({abs(sampled.qd[k, j]):.6g} {unit}) at t = {sampled.times[k]:.6g} s"
            + _slower(description, table, sampled.duration, ratio, speed, step_size))
    margin = float(np.min(np.minimum(sampled.q - lower, upper - sampled.q))) if len(sampled.times) else np.inf
    return ReferenceCheck(len(sampled.times), sampled.duration, margin, ratio, sampled.residual,
                          robot.joint_names[j] if ratio > 0.0 else "", float(sampled.times[k]), sampled.untracked)


def _sample(description: RobotDescription, step_size: float) -> _Sampled | None:
    """The reference at every ``step_size`` from 0 to its end: joint positions and rates, through
    the IK block for a task-space reference (its rate limit ``qd_limit`` lifted: the rates are
    measured, not refused), up to the first sample the IK cannot solve. None for a task-space
    reference without an IK block."""
    trajectory = make_block(description, "trajectory")
    trajectory.configure()
    duration = float(trajectory.breakpoints()[-1])
    n = trajectory.robot.n
    joint_space = "q_ref[1]" in trajectory.index
    if not joint_space:
        if "ik" not in description.blocks:
            return None
        ik = make_block(description, "ik")
        ik.set("qd_limit", np.full(n, NO_RATE_LIMIT))
        ik.configure()
        shared = sorted({v.name.split("[")[0] for v in trajectory.variables if v.causality == "output"}
                        & {v.name.split("[")[0] for v in ik.variables if v.causality == "input"})
        residuals = [d.name for d in ik.solver_type.diagnostics if d.name in ("residual", "position_residual")]
    times = np.arange(0.0, duration + step_size / 2, step_size)
    q, qd = np.empty((len(times), n)), np.empty((len(times), n))
    residual, failure, solved = None, None, len(times)
    free = [] if joint_space or "omega_ref[1]" not in trajectory.index else \
        [a for a in range(3) if a not in trajectory.robot.orientation_axes]
    turned, untracked = np.zeros(3), None        # rad about the frame's own axes, from the start
    for k, t in enumerate(times):
        trajectory.output(t)
        if joint_space:
            q[k], qd[k] = trajectory.get("q_ref"), trajectory.get("qd_ref")
            continue
        if free:
            x, y, z, w = trajectory.get("quat_ref")
            body = pin.Quaternion(w, x, y, z).matrix().T @ np.asarray(trajectory.get("omega_ref"))
            turned += body * (step_size if k else 0.0)
            axis = max(free, key=lambda a: abs(turned[a]))
            if abs(turned[axis]) > UNTRACKED_ROTATION and (untracked is None or abs(turned[axis]) > untracked[0]):
                untracked = (float(abs(turned[axis])), axis, float(t))
        for name in shared:
            ik.set(name, trajectory.get(name))
        ik.output(t)
        if not ik.get("reachable"):
            failure, solved = (float(t), ik.reason, _at_singularity(ik)), k
            break
        ik.advance(t, step_size)
        q[k], qd[k] = ik.get("q_ref"), ik.get("qd_ref")
        for name in residuals:
            residual = max(residual or 0.0, float(ik.get(name)))
    return _Sampled(duration, times[:solved], q[:solved], qd[:solved], residual, failure, untracked)


def _at_singularity(ik) -> bool:
    """Whether the IK block's last failure is a singularity: its solver's smallest singular value
    below its ``singular_value`` where it reports them, else its reason says so."""
    if "smallest_singular_value" in ik.index and "singular_value" in ik.index:
        return ik.get("smallest_singular_value") < ik.parameter("singular_value")
    return "singular" in ik.reason


def _fastest(qd: np.ndarray, speed: np.ndarray) -> tuple[float, int, int]:
    """The largest |qd| / limit over samples and joints, with its sample and joint (0, 0, 0 for
    no sample or no limit)."""
    if not len(qd):
        return 0.0, 0, 0
    ratios = np.abs(qd) / speed
    k, j = np.unravel_index(int(np.argmax(ratios)), ratios.shape)
    return float(ratios[k, j]), int(k), int(j)


def _deepest(robot, description, sampled: _Sampled, lower, upper) -> str:
    """The deepest excursion of the samples beyond a position limit, told (or "")."""
    below, above = lower - sampled.q, sampled.q - upper
    depth = np.maximum(below, above)
    if not len(depth) or not (depth > 0.0).any():
        return ""
    k, j = np.unravel_index(int(np.argmax(depth)), depth.shape)
    side, limit = ("lower", lower[j]) if below[k, j] > above[k, j] else ("upper", upper[j])
    first = sampled.times[np.flatnonzero(depth[:, j] > 0.0)[0]]
    unit = robot.joint_units(0)[j]
    joint = robot.joint_names[j]
    return (f"the reference drives joint {j + 1} ({joint}) beyond its {side} limit {limit:.6g} {unit} "
            f"({_source(description, joint, side)}) from t = {first:.6g} s, at worst to {sampled.q[k, j]:.6g} {unit} "
            f"({depth[k, j]:.3g} {unit} beyond) at t = {sampled.times[k]:.6g} s; keep the path (or home) inside "
            "the limits")


def _failure(description, robot, sampled: _Sampled, step_size: float) -> str:
    """Why the IK stopped along the reference: a singularity, a position limit the path goes
    through (the path solved again without position limits: its deepest excursion), or a target
    out of reach."""
    t, reason, singular = sampled.failure
    if singular:
        return (f"the reference meets a singularity at t = {t:.6g} s (no duration avoids it): {reason}; move the "
                "path (or home) away from it")
    lower, upper = robot.position_limits()
    limited = np.flatnonzero(np.isfinite(lower) | np.isfinite(upper)).tolist()
    if description.urdf is not None and limited:
        unlimited = dict(description.joint_limits)
        for j in limited:
            name = robot.joint_names[j]
            unlimited[name] = {**unlimited.get(name, {}), "lower": -np.inf, "upper": np.inf}
        try:
            free = _sample(replace(description, joint_limits=unlimited), step_size)
        except ValueError:
            free = None
        beyond = _deepest(robot, description, free, lower, upper) if free is not None else ""
        if beyond and free.times[np.flatnonzero(((free.q < lower) | (free.q > upper)).any(axis=1))[0]] <= t:
            return f"{beyond} (the IK stops on the limit at t = {t:.6g} s)"
    return f"the IK finds no solution for the reference at t = {t:.6g} s: {reason}"


def _slower(description, table: str, duration: float, ratio: float, speed, step_size: float) -> str:
    """The profile's time-law parameters scaled by ``ratio`` (and rounded towards slower), checked
    along the path and scaled again while they do not fit: "; ... give <key> = <value>" (or "" for
    a profile without a time-law parameter)."""
    given = description.trajectory.parameters
    proposal = slowed(given, ratio * MARGIN)
    if not proposal:
        return ""
    then = None                          # the path's duration with the proposal, once checked
    for _ in range(ATTEMPTS):
        trial = replace(description, trajectory=replace(description.trajectory, parameters={**given, **proposal}))
        try:
            sampled = _sample(trial, step_size)
        except ValueError:
            break
        then = sampled.duration
        again = _fastest(sampled.qd, speed)[0]
        if sampled.failure is not None or again <= 1.0:
            break
        proposal = slowed({**given, **proposal}, again * MARGIN)
    give = ", ".join(f"{table}.{key} = {_toml(value)}" for key, value in proposal.items())
    if "duration" in proposal:
        return (f"; the shortest duration that fits is {duration * ratio:.3g} s (the time law scaled by {ratio:.3g}): "
                f"give {give}")
    taking = f" (the path then takes {then:.3g} s)" if then is not None else ""
    return f"; the path fits run {ratio:.3g} × slower: give {give}{taking}"


def _toml(value) -> str:
    """A proposed value as the TOML takes it."""
    return f"[{', '.join(f'{v:g}' for v in value)}]" if isinstance(value, list) else f"{value:g}"


def _away(robot, description: RobotDescription, table: str, start: np.ndarray, home: np.ndarray) -> str:
    """A reference that does not start where the plant does (home, at rest), told with the fix."""
    j = int(np.argmax(np.abs(start - home)))
    unit = robot.joint_units(0)[j]
    task = ""
    if all(u == "m" for u in robot.task_units(0)):
        task = f" (the task point {1e3 * np.linalg.norm(robot.fk(start) - robot.fk(home)):.4g} mm from its place at home)"
    kind = description.trajectory.kind if description.trajectory is not None else ""
    inspect = f"robofmu inspect {description.path.name} prints it"
    fix = {"joint_bangbang": f"give {table}.q_start = home",
           "line": f"leave {table}.start out (it defaults to the task point at home)",
           "pose_line": f"leave {table}.start and start_quaternion out (they default to the tool's pose at home)",
           "waypoints": f"give {table}.relative = true with the rows as offsets from home's task point, or home's "
                        f"task point as the first row of {table}.waypoints ({inspect})",
           "pose_waypoints": f"give the tool's pose at home as the first row of {table}.waypoints ({inspect}: "
                             "position, quaternion)"}.get(kind, "start the path where home puts the robot")
    return (f"the reference does not start at home, where the plant starts at rest: at t = 0 it puts joint {j + 1} "
            f"({robot.joint_names[j]}) at {start[j]:.6g} {unit}, {abs(start[j] - home[j]):.3g} {unit} from home's "
            f"{home[j]:.6g}{task}, a jump; {fix}")


def _home_fix(value: float, lower: float, upper: float, unit: str, state: bool) -> str:
    """The fix for a home joint value beyond its limits: the same angle a turn away where that
    lies inside, else a value inside; home as numbers when it was an SRDF state."""
    turned = [value + turn for turn in (2.0 * np.pi, -2.0 * np.pi) if lower <= value + turn <= upper]
    write = "write home as numbers with" if state else "give"
    if unit == "rad" and turned:
        return f"{write} {turned[0]:.6g} rad there, the same angle a turn away, inside [{lower:.6g}, {upper:.6g}]"
    return f"{write} a value inside [{lower:.6g}, {upper:.6g}] {unit} there"


def _source(description: RobotDescription, joint: str, key: str) -> str:
    """Where a joint's limit ``key`` (lower, upper, velocity) is set: the TOML's key, or the URDF."""
    if description.mechanism is not None:
        return "[mechanism]"
    if key in description.joint_limits.get(joint, {}):
        return f"joints.limits.{joint}.{key}"
    return "URDF"

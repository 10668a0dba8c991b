"""Checks at build time of what a run would otherwise discover: a robot's reference against its
joints' limits.

:func:`check_reference` samples the robot's reference trajectory (its ``[trajectory]``, the
trajectory block's defaults) and, for a task-space reference, solves its IK along it as the IK
block does at run time (warm starts, one sample per communication step). It refuses, naming the
joint, the limit and the time, a reference that leaves the workspace or the joints' position or
velocity limits; the ``home`` configuration must lie within the position limits too.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .blocks import make_block
from .robots import RobotDescription, load_model

__all__ = ["ReferenceCheck", "ReferenceRefused", "check_reference", "check_references"]


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
    """

    samples: int
    duration: float
    position_margin: float
    speed_ratio: float
    ik_residual: float | None


class ReferenceRefused(ValueError):
    """The reference leaves the workspace or the joints' limits; the message names joint, limit, time."""


def check_references(description: RobotDescription, step_size: float = 1e-3) -> dict[str, ReferenceCheck]:
    """:func:`check_reference` of the robot's reference and of each named profile, by profile
    name ("" the default); empty for a robot without a trajectory block."""
    found = {}
    for fmu in description.fmu_blocks:
        kind, profile, described = description.block_of(fmu)
        if kind == "trajectory":
            try:
                found[profile] = check_reference(described, step_size)
            except ReferenceRefused as exc:
                raise ReferenceRefused(f"profile {profile!r}: {exc}" if profile else str(exc)) from None
    if not found:
        check_reference(description, step_size)        # home within the limits
    return found


def check_reference(description: RobotDescription, step_size: float = 1e-3) -> ReferenceCheck | None:
    """Sample the robot's reference at ``step_size`` (s) and check it against the joint limits.

    Returns None for a robot without a trajectory block.

    Raises
    ------
    ReferenceRefused
        Naming the joint, the limit and the time of the first violation, or the time the IK
        found no solution.
    """
    robot = load_model(description)
    lower, upper = robot.position_limits()
    speed = robot.velocity_limits()
    home = robot.configuration("home")
    _within(robot, home, lower, upper, "configuration home")
    if "trajectory" not in description.blocks:
        return None
    trajectory = make_block(description, "trajectory")
    trajectory.configure()
    duration = float(trajectory.breakpoints()[-1])
    names = {v.name for v in trajectory.variables}
    joint_space = "q_ref[1]" in names
    ik = None
    if not joint_space:
        if "ik" not in description.blocks:
            return None
        ik = make_block(description, "ik")
        ik.configure()
        shared = [v.name for v in trajectory.variables if v.causality == "output"
                  and any(w.name == v.name and w.causality == "input" for w in ik.variables)]
    times = np.arange(0.0, duration + step_size / 2, step_size)
    margin, ratio, residual = np.inf, 0.0, None
    residuals = [d.name for d in getattr(getattr(ik, "solver_type", None), "diagnostics", ())
                 if d.name in ("residual", "position_residual")]
    for k, t in enumerate(times):
        trajectory.output(t)
        if joint_space:
            q = np.array([trajectory.get(f"q_ref[{j + 1}]") for j in range(robot.n)])
            qd = np.array([trajectory.get(f"qd_ref[{j + 1}]") for j in range(robot.n)])
        else:
            for name in shared:
                ik.set(name, trajectory.get(name))
            ik.output(t)
            if not ik.get("reachable"):
                raise ReferenceRefused(f"the IK finds no solution for the reference at t = {t:.6g} s: {ik.reason}")
            ik.advance(t, step_size)
            q = np.array([ik.get(f"q_ref[{j + 1}]") for j in range(robot.n)])
            qd = np.array([ik.get(f"qd_ref[{j + 1}]") for j in range(robot.n)])
            for name in residuals:
                residual = max(residual or 0.0, float(ik.get(name)))
        _within(robot, q, lower, upper, f"the reference at t = {t:.6g} s")
        fastest = int(np.argmax(np.abs(qd) / speed))
        if abs(qd[fastest]) > speed[fastest]:
            unit = robot.joint_units(1)[fastest]
            raise ReferenceRefused(f"the reference at t = {t:.6g} s drives joint {fastest + 1} "
                                 f"({robot.joint_names[fastest]}) at {qd[fastest]:.6g} {unit}, beyond its velocity "
                                 f"limit {speed[fastest]:.6g} {unit}")
        margin = min(margin, float(np.min(np.minimum(q - lower, upper - q))))
        ratio = max(ratio, float(np.max(np.abs(qd) / speed)))
    return ReferenceCheck(len(times), duration, margin, ratio, residual)


def _within(robot, q, lower, upper, where: str) -> None:
    outside = np.flatnonzero((q < lower) | (q > upper))
    if outside.size:
        j = int(outside[0])
        unit = robot.joint_units(0)[j]
        side, limit = ("lower", lower[j]) if q[j] < lower[j] else ("upper", upper[j])
        raise ReferenceRefused(f"{where} puts joint {j + 1} ({robot.joint_names[j]}) at {q[j]:.6g} {unit}, "
                             f"beyond its {side} limit {limit:.6g} {unit}")

"""Tracking metrics of a run, for any robot: joint errors, task-point error, efforts.

Signals are read by role (:class:`~robofmu.system.roles.Roles`), units from the result.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robofmu.system.result import Result
from robofmu.system.roles import Roles
from robofmu.system.units import printed, small


@dataclass
class Tracking:
    """Metrics of one run (SI; arrays have one entry per joint).

    Attributes
    ----------
    max_error, rms_error : ndarray, shape (n,)
        max |q_ref - q| and RMS of q_ref - q (joint units: rad or m).
    joint_units, effort_units : list of str
    tcp_error : ndarray, shape (k,) or None
        The task point's distance |FK(q) - x_ref| (m, over the task coordinates in m) at every
        recorded point, where the run has a task reference.
    orientation_error : ndarray, shape (k,) or None
        The largest |FK(q)_i - x_ref_i| (rad) over the task coordinates in rad (a pose's angle),
        where the task has such coordinates.
    events : dict
        name -> (time in s, task-point error or NaN), e.g. when the gripper closes.
    peak_effort : ndarray, shape (n,) or None
        max |tau| (N.m or N); None without a ``tau`` role (an unactuated run).
    final_error : ndarray, shape (n,)
        q_ref - q at the last point.
    final_speed : ndarray, shape (n,) or None
        |qd| at the last point.
    """

    max_error: np.ndarray
    rms_error: np.ndarray
    joint_units: list
    effort_units: list
    tcp_error: np.ndarray | None
    orientation_error: np.ndarray | None
    events: dict
    peak_effort: np.ndarray | None
    final_error: np.ndarray
    final_speed: np.ndarray | None


def tracking_metrics(result: Result, roles: Roles) -> Tracking:
    """Metrics of a run recording the roles ``q`` and ``q_ref`` (``tau``, ``x_ref``, ``grip`` if any)."""
    roles.require("q", "q_ref")
    q, q_ref = roles.vector(result, "q"), roles.vector(result, "q_ref")
    tau = roles.vector(result, "tau") if roles.tau else None
    e = q_ref - q
    model = roles.model()
    n = q.shape[1]
    joint_units = [result.units.get(f"{roles.q}[{j + 1}]") or u for j, u in enumerate(model.joint_units(0))]
    effort_units = [(result.units.get(f"{roles.tau}[{j + 1}]") if roles.tau else None) or u
                    for j, u in enumerate(model.effort_units())]
    tcp, orientation = roles.task_errors(result, model) or (None, None)
    ev = {}
    for name, t in roles.events(result).items():
        k = int(np.argmin(np.abs(result.time - t)))
        ev[name] = (float(result.time[k]), float(tcp[k]) if tcp is not None else float("nan"))
    speed = np.abs(result.vector(roles.qd)[-1]) if roles.qd and f"{roles.qd}[1]" in result.columns else None
    return Tracking(np.max(np.abs(e), axis=0), np.sqrt(np.mean(e ** 2, axis=0)), joint_units[:n],
                    effort_units[:n], tcp, orientation, ev, None if tau is None else np.max(np.abs(tau), axis=0), e[-1], speed)


def limit_excursions(result: Result, roles: Roles, model=None) -> list[tuple[str, str]]:
    """The recorded points at which a joint lies beyond its limits (the robot's: the URDF's or
    its description's): position from the ``q`` role, velocity from ``qd`` where recorded.

    Returns
    -------
    list of (str, str)
        One entry per joint and limit kind crossed: (a line for a report, a few words for a
        summary), ``("joint 3 (elbow_joint) beyond its velocity limit 3.15 rad/s at t = 0.187 s,
        1 step", "joint 3 (elbow_joint) beyond its velocity limit for 1 step")``; [] when every
        joint stayed within its limits.
    """
    model = model or roles.model()
    lower, upper = model.position_limits()
    speed = model.velocity_limits()
    checks = [("position", roles.q, lower, upper, model.joint_units(0))]
    if roles.qd and f"{roles.qd}[1]" in result.columns:
        checks.append(("velocity", roles.qd, -speed, speed, model.joint_units(1)))
    found = []
    for kind, base, low, high, units in checks:
        values = result.vector(base)
        for j in range(values.shape[1]):
            rows = np.flatnonzero((values[:, j] < low[j]) | (values[:, j] > high[j]))
            if not rows.size:
                continue
            joint = f"joint {j + 1} ({model.joint_names[j]}) beyond its {kind} limit"
            first, last = float(result.time[rows[0]]), float(result.time[rows[-1]])
            span = f"at t = {first:g} s" if first == last else f"from t = {first:g} s to {last:g} s"
            limits = f"{high[j]:.6g} {units[j]}" if kind == "velocity" else \
                f"[{low[j]:.6g}, {high[j]:.6g}] {units[j]}"
            steps = f"{rows.size} step{'' if rows.size == 1 else 's'}"
            found.append((f"{joint} {limits} {span}, {steps}", f"{joint} for {steps}"))
    return found


def markdown_table(rows: list[list], header: list[str]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def joint_table(m: Tracking) -> str:
    """One row per joint: max and RMS error (mrad or mm), peak effort (N·m or N; "—" without efforts)."""
    rows = []
    for j in range(len(m.max_error)):
        factor, unit = small(m.joint_units[j])
        rows.append([f"q{j + 1}", f"{m.max_error[j] * factor:.4f} {unit}", f"{m.rms_error[j] * factor:.4f} {unit}",
                     f"{m.final_error[j] * factor:.4f} {unit}",
                     "—" if m.peak_effort is None else f"{m.peak_effort[j]:.4f} {printed(m.effort_units[j])}"])
    return markdown_table(rows, ["joint", "max error", "RMS error", "error at the end", "peak effort"])


def tracking_report(name: str, description: str, m: Tracking, result: Result) -> str:
    """Markdown section for one experiment."""
    text = [f"### {name}", "", description, "",
            f"Communication step {result.info.get('step', float('nan')) * 1e3:g} ms, "
            f"{result.info.get('algorithm', '')}, {len(result.time)} points, "
            f"wall time {result.info.get('wall_time', float('nan')):.2f} s.", "", joint_table(m)]
    if m.tcp_error is not None:
        line = f"Task-point error |FK(q) - x_ref|: max {np.max(m.tcp_error) * 1e3:.4f} mm over the run"
        if m.events:
            line += "; " + "; ".join(f"{k} at t = {t:g} s: {e * 1e3:.4f} mm" for k, (t, e) in m.events.items())
        if m.orientation_error is not None:
            line += f"; orientation error max {np.max(m.orientation_error) * 1e3:.4f} mrad"
        text += ["", line + "."]
    if m.final_speed is not None:
        text += ["", "At the end (t = {:g} s): joint speeds {}.".format(
            result.time[-1], ", ".join(f"{v:.2e}" for v in m.final_speed))]
    return "\n".join(text)


def settling_time(time: np.ndarray, q_ref: np.ndarray, q: np.ndarray, band: float = 0.02) -> float:
    """Time from the instant the reference comes to rest until every joint has settled (s).

    The reference comes to rest at its last change (a change larger than 1e-9 of a joint's
    travel). A joint has settled from the first point after which its error |q_ref - q| stays
    within ``band`` times its travel (max - min of its reference over the run); joints that do
    not move are not counted.

    Parameters
    ----------
    time : ndarray, shape (k,)
        Recorded points (s).
    q_ref, q : ndarray, shape (k, n)
        Joint reference and measured joint positions (joint units).
    band : float
        The settling band as a fraction of each joint's travel (0.02: 2 %).

    Returns
    -------
    float
        The settling time (0 if every error is inside the band from the rest instant on); NaN
        where it does not apply or is not reached: the reference still moves at the end, no
        joint moves, or an error is outside the band at the last point.
    """
    travel = np.ptp(q_ref, axis=0)
    moving = travel > 0.0
    if not np.any(moving):
        return float("nan")
    changed = np.any(np.abs(q_ref[:, moving] - q_ref[-1, moving]) > 1e-9 * travel[moving], axis=1)
    rest = int(np.flatnonzero(changed)[-1]) + 1 if np.any(changed) else 0
    if rest >= len(time) - 1:
        return float("nan")
    error = np.abs(q_ref[rest:, moving] - q[rest:, moving])
    outside = np.any(error > band * travel[moving], axis=1)
    if not np.any(outside):
        return 0.0
    last = int(np.flatnonzero(outside)[-1])
    if last == len(error) - 1:
        return float("nan")
    return float(time[rest + last + 1] - time[rest])

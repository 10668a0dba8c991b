"""Tracking metrics of a chess run: joint errors, TCP error at the pick and place instants, torques."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robofmu.components.robot import Robot

from .master import Result


@dataclass
class Tracking:
    """Metrics of one run (SI units; arrays have one entry per joint).

    Attributes
    ----------
    max_error, rms_error : ndarray, shape (n,)
        max |q_ref - q| and RMS of q_ref - q over the run (rad).
    tcp_error : ndarray, shape (k,)
        |FK(q) - x_ref| at every recorded point (m).
    events : dict
        name -> (time in s, TCP error in m), e.g. the pick and place instants.
    peak_torque : ndarray, shape (n,)
        max |tau| (N.m).
    """

    max_error: np.ndarray
    rms_error: np.ndarray
    tcp_error: np.ndarray
    events: dict
    peak_torque: np.ndarray


def tracking(result: Result, robot: Robot, events: dict[str, float] | None = None) -> Tracking:
    """Metrics of a run recorded with ``ik.q_ref``, ``plant.q``, ``trajectory.x_ref``, ``controller.tau``."""
    q, q_ref = result.vector("plant.q"), result.vector("ik.q_ref")
    e = q_ref - q
    x_ref = result.vector("trajectory.x_ref")
    tcp = np.array([robot.fk(qi) for qi in q])
    tcp_error = np.linalg.norm(tcp - x_ref, axis=1)
    ev = {}
    for name, t in (events or {}).items():
        k = int(np.argmin(np.abs(result.time - t)))
        ev[name] = (float(result.time[k]), float(tcp_error[k]))
    return Tracking(np.max(np.abs(e), axis=0), np.sqrt(np.mean(e**2, axis=0)), tcp_error, ev,
                    np.max(np.abs(result.vector("controller.tau")), axis=0))


def grip_events(trajectory) -> dict[str, float]:
    """Pick and place instants: when the gripper closes and opens (s); only those that happen."""
    events = {"pick": trajectory.grip_close_time, "place": trajectory.grip_open_time}
    return {k: float(t) for k, t in events.items() if np.isfinite(t)}


def markdown_table(rows: list[list], header: list[str]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def tracking_report(name: str, description: str, m: Tracking, result: Result) -> str:
    """Markdown section for one experiment."""
    n = len(m.max_error)
    rows = [[f"q{j + 1}", f"{m.max_error[j] * 1e3:.4f}", f"{m.rms_error[j] * 1e3:.4f}", f"{m.peak_torque[j]:.4f}"]
            for j in range(n)]
    text = [f"### {name}", "", description, "",
            f"Communication step {result.info.get('step', float('nan')) * 1e3:g} ms, "
            f"{result.info.get('algorithm', '')}, {len(result.time)} points, "
            f"wall time {result.info.get('wall_time', float('nan')):.2f} s.", "",
            markdown_table(rows, ["joint", "max error (mrad)", "RMS error (mrad)", "peak torque (N.m)"]), "",
            f"TCP error: max {np.max(m.tcp_error) * 1e3:.4f} mm over the task; "
            + "; ".join(f"{k} at t = {t:g} s: {e * 1e3:.4f} mm" for k, (t, e) in m.events.items()) + "."]
    return "\n".join(text)

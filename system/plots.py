"""Figures of a run (after seed 002's Figures 2-11) and the block diagram of a System."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch  # noqa: E402

from .diagram import System  # noqa: E402
from .master import Result  # noqa: E402

COLORS = ["tab:red", "tab:green", "tab:blue", "k"]


def _save(fig, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _grip_spans(ax, result: Result):
    if "trajectory.grip" in result.columns:
        g = result["trajectory.grip"] > 0.5
        if g.any():
            t = result.time[g]
            ax.axvspan(t[0], t[-1], color="0.9", zorder=0, label="pawn carried")


def _profile(result: Result, path: Path, bases: list[str], units: list[str], labels: list[str],
             title: str) -> Path:
    """Position, velocity and acceleration of a vector signal, one panel each."""
    fig, axes = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
    for ax, base, unit, kind in zip(axes, bases, units, ("position", "velocity", "acceleration")):
        v = result.vector(base)
        for i, label in enumerate(labels):
            ax.plot(result.time, v[:, i], color=COLORS[i % 4], label=label)
        ax.set_ylabel(f"{kind} ({unit})")
        ax.grid(alpha=0.3)
    axes[0].legend(ncol=len(labels), loc="upper right")
    axes[0].set_title(title)
    axes[-1].set_xlabel("time (s)")
    return _save(fig, path)


def cartesian_reference(result: Result, path: Path) -> Path:
    """Seed Fig. 2: TCP reference position, velocity and acceleration."""
    return _profile(result, path, ["trajectory.x_ref", "trajectory.xd_ref", "trajectory.xdd_ref"],
                    ["m", "m/s", "m/s²"], list("xyz"),
                    "TCP reference: LSPB moves through the waypoints (queen's gambit)")


def joint_reference(result: Result, path: Path) -> Path:
    """Seed Fig. 3: joint references from the IK block."""
    n = result.vector("ik.q_ref").shape[1]
    return _profile(result, path, ["ik.q_ref", "ik.qd_ref", "ik.qdd_ref"], ["rad", "rad/s", "rad/s²"],
                    [f"θ{j + 1}" for j in range(n)], "Joint-space reference (closed-form IK, analytic rates)")


def tracking(result: Result, path: Path, title: str) -> Path:
    """Seed Figs. 7 and 9: each joint angle against its reference, and the error."""
    q, q_ref = result.vector("plant.q"), result.vector("ik.q_ref")
    n = q.shape[1]
    fig, axes = plt.subplots(n, 2, figsize=(11, 2.2 * n), sharex=True)
    for j in range(n):
        ax = axes[j, 0]
        ax.plot(result.time, q_ref[:, j], color="0.5", lw=3, label="reference")
        ax.plot(result.time, q[:, j], color=COLORS[j % 4], lw=1, label="joint")
        ax.set_ylabel(f"θ{j + 1} (rad)")
        ax.grid(alpha=0.3)
        ax = axes[j, 1]
        _grip_spans(ax, result)
        ax.plot(result.time, (q_ref[:, j] - q[:, j]) * 1e3, color=COLORS[j % 4])
        ax.set_ylabel(f"e{j + 1} (mrad)")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(loc="upper right")
    axes[0, 0].set_title(f"{title}: joint angle and reference")
    axes[0, 1].set_title("tracking error (grey: pawn carried)")
    axes[-1, 0].set_xlabel("time (s)")
    axes[-1, 1].set_xlabel("time (s)")
    return _save(fig, path)


def torques(result: Result, path: Path, title: str) -> Path:
    """Seed Figs. 8 and 10: joint torques."""
    tau = result.vector("controller.tau")
    fig, ax = plt.subplots(figsize=(8, 4))
    _grip_spans(ax, result)
    for j in range(tau.shape[1]):
        ax.plot(result.time, tau[:, j], color=COLORS[j % 4], label=f"τ{j + 1}")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("torque (N·m)")
    ax.set_title(f"{title}: joint torques")
    ax.legend(ncol=5, loc="upper right")
    ax.grid(alpha=0.3)
    return _save(fig, path)


def error_comparison(results: dict[str, Result], path: Path, joint: int | None = None) -> Path:
    """Seed Fig. 11: tracking error of several runs (PD vs PID, pawn known or not)."""
    first = next(iter(results.values()))
    n = first.vector("plant.q").shape[1]
    joints = range(n) if joint is None else [joint]
    fig, axes = plt.subplots(len(joints), 1, figsize=(9, 2.3 * len(joints)), sharex=True, squeeze=False)
    for row, j in enumerate(joints):
        ax = axes[row, 0]
        _grip_spans(ax, first)
        for name, r in results.items():
            e = r.vector("ik.q_ref")[:, j] - r.vector("plant.q")[:, j]
            ax.plot(r.time, e * 1e3, "--" if "unknown" in name else "-",
                    color="tab:red" if "pid" in name else "tab:blue", lw=1, label=name)
        ax.set_ylabel(f"e{j + 1} (mrad)")
        ax.grid(alpha=0.3)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    axes[-1, 0].legend(handles, labels, ncol=3, fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.35))
    axes[0, 0].set_title("Tracking error: PD (blue) vs PID (red); dashed: pawn unknown to the model")
    axes[-1, 0].set_xlabel("time (s)")
    return _save(fig, path)


def tcp_error(results: dict[str, tuple[np.ndarray, np.ndarray]], path: Path) -> Path:
    """TCP position error |FK(q) - x_ref| over time for several runs (log scale)."""
    fig, ax = plt.subplots(figsize=(9, 3.6))
    for name, (t, err) in results.items():
        ax.semilogy(t, np.maximum(err, 1e-12) * 1e3, lw=1, label=name)
    ax.axhline(1.0, color="0.3", ls=":", label="1 mm")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("TCP error (mm)")
    ax.set_title("Tool-point error against the Cartesian reference")
    ax.legend(fontsize=8, ncol=3)
    ax.grid(alpha=0.3, which="both")
    return _save(fig, path)


def block_diagram(system: System, path: Path, order: list[str] | None = None) -> Path:
    """Seed Figs. 5 and 6, drawn from the system description: blocks left to right as declared,
    one arrow per wired block pair labelled with the variables it carries; wires that skip blocks
    arc above, wires that run backwards (feedback) arc below. ``order`` (the master's evaluation
    order) is printed underneath."""
    names = [b.name for b in system.blocks]
    pos = {n: i * 3.4 for i, n in enumerate(names)}
    fig, ax = plt.subplots(figsize=(2.8 * len(names) + 1.5, 4.8))
    w, h = 2.2, 1.7
    for b in system.blocks:
        x = pos[b.name]
        ax.add_patch(FancyBboxPatch((x - w / 2, -h / 2), w, h, boxstyle="round,pad=0.05",
                                    fc="#e8f0fb", ec="#2b5797", lw=1.5))
        ax.text(x, 0.5, b.name, ha="center", va="center", fontsize=12, weight="bold")
        ax.text(x, 0.2, Path(str(b.fmu)).name, ha="center", va="center", fontsize=7, color="0.3")
        params = ", ".join(f"{k} = {v:g}" if isinstance(v, (int, float)) else k for k, v in b.parameters.items())
        if params:
            ax.text(x, -0.05, params.replace(", payload", ",\npayload"), ha="center", va="top",
                    fontsize=6.5, color="0.3", wrap=True)
    pairs: dict[tuple[str, str], list[str]] = {}
    for wire in system.wires:
        pairs.setdefault((wire.src, wire.dst), []).append(wire.src_var)
    above = below = 0
    for (src, dst), vars_ in pairs.items():
        x0, x1 = pos[src], pos[dst]
        label = ", ".join(dict.fromkeys(vars_))
        span = abs(x1 - x0)
        if x1 > x0 and span < 4:          # neighbours: a straight arrow
            ax.add_patch(FancyArrowPatch((x0 + w / 2, 0.05), (x1 - w / 2, 0.05), arrowstyle="-|>",
                                         mutation_scale=14, lw=1.2, color="#2b5797"))
            ax.text((x0 + x1) / 2, 0.15, label.replace(", ", "\n"), ha="center", va="bottom", fontsize=7)
            continue
        if x1 > x0:                       # skips blocks: arc above
            above += 1
            height, color, y = 0.7 + 0.45 * above, "#2b5797", h / 2 + 0.05
            rad = -2 * height / span
        else:                             # feedback: arc below
            below += 1
            height, color, y = 0.9 + 0.45 * below, "#b03a2e", -h / 2 - 0.05
            rad = -2 * height / span
        ax.add_patch(FancyArrowPatch((x0, y), (x1, y), arrowstyle="-|>", mutation_scale=14, lw=1.2,
                                     connectionstyle=f"arc3,rad={rad}", color=color))
        ty = y + height + 0.05 if x1 > x0 else y - height - 0.05   # a quadratic arc peaks at rad*span/2
        ax.text((x0 + x1) / 2, ty, label + (" (feedback)" if x1 < x0 else ""), ha="center",
                va="bottom" if x1 > x0 else "top", fontsize=8, color=color,
                bbox=dict(fc="white", ec="none", pad=0.5))
    if order:
        ax.text(pos[names[0]] - w / 2, -3.2, "evaluation order at each communication point: "
                + " → ".join(order), fontsize=8, color="0.3")
    ax.set_xlim(pos[names[0]] - w / 2 - 0.3, pos[names[-1]] + w / 2 + 0.3)
    ax.set_ylim(-3.4, 3.0)
    ax.set_aspect("equal")
    ax.axis("off")
    ax.set_title(f"{system.name}: {system.description}", fontsize=10)
    return _save(fig, path)

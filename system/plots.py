"""Figures of a run of any robot (after seed 002's Figures 2-11) and the block diagram of a System.

Signals come by role, axis units from the recorded FMUs' model descriptions."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch  # noqa: E402

from robofmu.system.diagram import System  # noqa: E402
from robofmu.system.result import Result  # noqa: E402
from robofmu.system.roles import Roles  # noqa: E402
from robofmu.system.units import printed, small  # noqa: E402
from robofmu.system.usage import atomic_file  # noqa: E402

COLORS = ["tab:red", "tab:green", "tab:blue", "k", "tab:orange", "tab:purple"]
#: The iterative IK solvers' diagnostics a run may record as outputs ``<instance>.<name>``, and the
#: name each is drawn as (a pose solver's position residual is its residual here).
DIAGNOSTICS = {"iterations": "iterations", "residual": "residual", "position_residual": "residual"}


def save_figure(fig, path: Path, tight: bool = True, dpi: int = 110) -> Path:
    """Write ``fig`` as PNG (laid out tight unless ``tight`` is false) and close it: every figure
    robofmu writes goes through here, to a temporary sibling renamed into place
    (:func:`~robofmu.system.usage.atomic_file`), so an interrupted run leaves no half-written PNG."""
    path = Path(path)
    if tight:
        fig.tight_layout()
    try:
        with atomic_file(path) as partial:
            fig.savefig(partial, dpi=dpi, format="png")
    finally:
        plt.close(fig)
    return path


def _grip_spans(ax, result: Result, roles: Roles):
    """Shade the interval while the gripper is closed (where the run has a ``grip`` role)."""
    if roles.grip and roles.grip in result.columns:
        g = result[roles.grip] > 0.5
        if g.any():
            t = result.time[g]
            ax.axvspan(t[0], t[-1], color="0.9", zorder=0, label="payload carried")


def _profile(result: Result, path: Path, bases: list[str], labels: list[str], title: str) -> Path:
    """Position, velocity and acceleration of a vector signal, one panel each; units from the run."""
    fig, axes = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
    for ax, base, kind in zip(axes, bases, ("position", "velocity", "acceleration")):
        v = result.vector(base)
        units = {printed(result.units.get(f"{base}[{i + 1}]")) for i in range(v.shape[1])}
        for i, label in enumerate(labels):
            ax.plot(result.time, v[:, i], color=COLORS[i % len(COLORS)], label=label)
        ax.set_ylabel(f"{kind} ({', '.join(sorted(u for u in units if u))})")
        ax.grid(alpha=0.3)
    axes[0].legend(ncol=len(labels), loc="upper right")
    axes[0].set_title(title)
    axes[-1].set_xlabel("time (s)")
    return save_figure(fig, path)


def task_reference(result: Result, roles: Roles, path: Path) -> Path:
    """Seed 002 Fig. 2: the task-space reference position, velocity and acceleration."""
    roles.require("x_ref")
    base = roles.x_ref
    instance = base.split(".")[0]
    names = [f"{instance}.{b}" for b in ("x_ref", "xd_ref", "xdd_ref")]
    coordinates = roles.model().task_coordinates
    return _profile(result, path, names, list(coordinates), "Task-space reference")


def joint_reference(result: Result, roles: Roles, path: Path) -> Path:
    """Seed 002 Fig. 3: the joint reference (position, velocity, acceleration)."""
    roles.require("q_ref")
    instance = roles.q_ref.split(".")[0]
    names = [f"{instance}.{b}" for b in ("q_ref", "qd_ref", "qdd_ref")]
    n = result.vector(roles.q_ref).shape[1]
    return _profile(result, path, names, [f"q{j + 1}" for j in range(n)], "Joint-space reference")


def tracking(result: Result, roles: Roles, path: Path, title: str) -> Path:
    """Seed 002 Figs. 7 and 9: each joint against its reference, and the error."""
    q, q_ref = roles.vector(result, "q"), roles.vector(result, "q_ref")
    n = q.shape[1]
    fig, axes = plt.subplots(n, 2, figsize=(11, 2.2 * n), sharex=True, squeeze=False)
    for j in range(n):
        unit = result.units.get(f"{roles.q}[{j + 1}]")
        factor, small_unit = small(unit)
        ax = axes[j, 0]
        ax.plot(result.time, q_ref[:, j], color="0.5", lw=3, label="reference")
        ax.plot(result.time, q[:, j], color=COLORS[j % len(COLORS)], lw=1, label="joint")
        ax.set_ylabel(f"q{j + 1} ({printed(unit)})")
        ax.grid(alpha=0.3)
        ax = axes[j, 1]
        _grip_spans(ax, result, roles)
        ax.plot(result.time, (q_ref[:, j] - q[:, j]) * factor, color=COLORS[j % len(COLORS)])
        ax.set_ylabel(f"e{j + 1} ({small_unit})")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(loc="upper right")
    axes[0, 0].set_title(f"{title}: joint position and reference")
    axes[0, 1].set_title("tracking error" + (" (grey: payload carried)" if roles.grip else ""))
    axes[-1, 0].set_xlabel("time (s)")
    axes[-1, 1].set_xlabel("time (s)")
    return save_figure(fig, path)


def efforts(result: Result, roles: Roles, path: Path, title: str) -> Path:
    """Seed 002 Figs. 8 and 10: joint efforts, one panel per unit (torques N·m, forces N)."""
    tau = roles.vector(result, "tau")
    units = [printed(result.units.get(f"{roles.tau}[{j + 1}]")) for j in range(tau.shape[1])]
    groups = list(dict.fromkeys(units))
    fig, axes = plt.subplots(len(groups), 1, figsize=(8, 3.2 * len(groups)), sharex=True, squeeze=False)
    for ax, unit in zip(axes[:, 0], groups):
        _grip_spans(ax, result, roles)
        for j in (j for j, u in enumerate(units) if u == unit):
            ax.plot(result.time, tau[:, j], color=COLORS[j % len(COLORS)], label=f"τ{j + 1}")
        ax.set_ylabel(f"{'torque' if unit == 'N·m' else 'force' if unit == 'N' else 'effort'} ({unit})")
        ax.legend(ncol=5, loc="upper right")
        ax.grid(alpha=0.3)
    axes[0, 0].set_title(f"{title}: joint efforts")
    axes[-1, 0].set_xlabel("time (s)")
    return save_figure(fig, path)


def pose(result: Result, roles: Roles, path: Path, title: str) -> Path:
    """The measured task coordinates (role ``x``) over time, one row per coordinate: beside the
    task reference and with the error x_ref - x where the run has an ``x_ref`` role, else with the
    departure x - x(0) from the start."""
    roles.require("x")
    x = roles.vector(result, "x")
    x_ref = roles.vector(result, "x_ref") if roles.x_ref else None
    coordinates = roles.model().task_coordinates
    m = x.shape[1]
    fig, axes = plt.subplots(m, 2, figsize=(11, 2.2 * m), sharex=True, squeeze=False)
    for i in range(m):
        unit = result.units.get(f"{roles.x}[{i + 1}]")
        factor, small_unit = small(unit)
        name = coordinates[i] if i < len(coordinates) else f"x{i + 1}"
        ax = axes[i, 0]
        if x_ref is not None:
            ax.plot(result.time, x_ref[:, i], color="0.5", lw=3, label="reference")
        ax.plot(result.time, x[:, i], color=COLORS[i % len(COLORS)], lw=1, label="measured")
        ax.set_ylabel(f"{name} ({printed(unit)})")
        ax.grid(alpha=0.3)
        ax = axes[i, 1]
        shown = (x_ref[:, i] - x[:, i]) if x_ref is not None else (x[:, i] - x[0, i])
        ax.plot(result.time, shown * factor, color=COLORS[i % len(COLORS)])
        ax.set_ylabel(f"{'error' if x_ref is not None else 'change'} in {name} ({small_unit})")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(loc="upper right")
    axes[0, 0].set_title(f"{title}: task coordinates")
    axes[0, 1].set_title("x_ref - x" if x_ref is not None else "x - x(0): change from the start")
    axes[-1, 0].set_xlabel("time (s)")
    axes[-1, 1].set_xlabel("time (s)")
    return save_figure(fig, path)

#: How :func:`mechanism` draws each kind of polyline a model's ``sketch(q)`` returns.
SKETCH_STYLES = {"links": dict(lw=2.5, solid_capstyle="round"), "passive": dict(lw=1.0, ls="--"),
                 "end_effector": dict(lw=2.0, marker="o", ms=5, markevery=[0])}


def tool_pose(result: Result, roles: Roles, path: Path, title: str) -> Path:
    """A pose task's run: the task frame's path in space, FK(q) of the recorded joints beside the
    reference, with the frame's axes drawn at a few instants (left), and over time the position
    error |FK(q) - x_ref| (mm) and the orientation error |log3(R_ref^T R(q))| (mrad) (right)."""
    from robofmu.components.orientation import rotation_of

    roles.require("q", "x_ref", "quat_ref")
    model = roles.model()
    q = roles.vector(result, "q")
    poses = roles.poses(result, model)
    reference = roles.vector(result, "x_ref")
    quaternions = roles.vector(result, "quat_ref")
    position, orientation = roles.task_errors(result, model, poses)
    fig = plt.figure(figsize=(12, 5.2))
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    ax.plot(*reference.T, color="0.5", lw=4, label="reference")
    ax.plot(*poses.T, color="tab:red", lw=1, label="FK(q)")
    span = float(np.ptp(reference, axis=0).max()) or 0.1
    for k in np.linspace(0, len(q) - 1, 5).astype(int):
        R, origin = rotation_of(quaternions[k]), reference[k]
        for axis, color in zip(range(3), ("tab:red", "tab:green", "tab:blue")):
            ax.plot(*np.array([origin, origin + 0.15 * span * R[:, axis]]).T, color=color, lw=1.5)
    center = (reference.max(axis=0) + reference.min(axis=0)) / 2
    half = 0.6 * span                                   # one scale on the three axes
    ax.set_xlim(center[0] - half, center[0] + half)
    ax.set_ylim(center[1] - half, center[1] + half)
    ax.set_zlim(center[2] - half, center[2] + half)
    ax.set_box_aspect((1, 1, 1))
    travel = reference[-1] - reference[0]                # seen from the side of the travel
    ax.view_init(elev=20.0, azim=float(np.degrees(np.arctan2(travel[1], travel[0]))) - 70.0)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(f"{title}: path of {model.description.task.frame} (axes: reference x, y, z)", fontsize=10)
    top = fig.add_subplot(2, 2, 2)
    top.plot(result.time, position * 1e3, color="tab:red")
    top.set_ylabel("position error (mm)")
    top.set_title(f"max {position.max() * 1e3:.4f} mm, at the end {position[-1] * 1e3:.2e} mm", fontsize=9)
    bottom = fig.add_subplot(2, 2, 4, sharex=top)
    bottom.plot(result.time, orientation * 1e3, color="tab:blue")
    bottom.set_ylabel("orientation error (mrad)")
    bottom.set_title(f"max {orientation.max() * 1e3:.4f} mrad, at the end {orientation[-1] * 1e3:.2e} mrad",
                     fontsize=9)
    bottom.set_xlabel("time (s)")
    for a in (top, bottom):
        a.grid(alpha=0.3)
    return save_figure(fig, path)


def mechanism(result: Result, roles: Roles, path: Path, title: str, instants: int = 6) -> Path | None:
    """The mechanism drawn at ``instants`` recorded instants evenly spaced along the path of its
    first two task coordinates (in time where it does not move) by a model's ``sketch(q)`` (plane
    polylines by kind), with that path; None for a model that draws none."""
    model = roles.model()
    if not callable(getattr(model, "sketch", None)):
        return None
    q = roles.vector(result, "q")
    path_xy = np.array([model.fk(v)[:2] for v in q])
    travelled = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path_xy, axis=0), axis=1))])
    if travelled[-1] > 0.0:        # evenly spaced along the path (distinct poses), its first and last points
        picks = np.searchsorted(travelled, np.linspace(0.0, travelled[-1], instants), side="left")
        picks[-1] = len(q) - 1
    else:
        picks = np.linspace(0, len(q) - 1, instants).round().astype(int)
    picks = np.unique(np.minimum(picks, len(q) - 1))
    fig, ax = plt.subplots(figsize=(6.4, 6.0))
    ax.plot(path_xy[:, 0], path_xy[:, 1], color="0.6", lw=1, label="path of the task point")
    cmap = plt.get_cmap("viridis")
    for n, k in enumerate(picks):
        color = cmap(n / max(1, len(picks) - 1))
        drawn = model.sketch(q[k])
        for kind, lines in drawn.items():
            for m, line in enumerate(lines):
                ax.plot(line[:, 0], line[:, 1], color=color, **SKETCH_STYLES.get(kind, {}),
                        label=f"t = {result.time[k]:g} s" if kind == next(iter(drawn)) and m == 0 else None)
    ax.plot([0.0], [0.0], "ko", ms=4)
    ax.set_aspect("equal")
    unit = printed(model.task_units(0)[0])
    ax.set_xlabel(f"{model.task_coordinates[0]} ({unit})")
    ax.set_ylabel(f"{model.task_coordinates[1]} ({unit})")
    ax.set_title(f"{title}: the mechanism at {len(picks)} instants")
    ax.legend(fontsize=8, loc="best")
    ax.grid(alpha=0.3)
    return save_figure(fig, path)

def error_comparison(results: dict[str, Result], roles: Roles, path: Path, title: str) -> Path:
    """Seed 002 Fig. 11: the tracking error of several runs of one diagram, per joint."""
    first = next(iter(results.values()))
    n = roles.vector(first, "q").shape[1]
    fig, axes = plt.subplots(n, 1, figsize=(9, 2.3 * n), sharex=True, squeeze=False)
    styles = ["-", "--", "-.", ":"]
    for j in range(n):
        ax = axes[j, 0]
        factor, unit = small(first.units.get(f"{roles.q}[{j + 1}]"))
        _grip_spans(ax, first, roles)
        for k, (name, r) in enumerate(results.items()):
            e = roles.vector(r, "q_ref")[:, j] - roles.vector(r, "q")[:, j]
            ax.plot(r.time, e * factor, styles[k // len(COLORS) % len(styles)],
                    color=COLORS[k % len(COLORS)], lw=1, label=name)
        ax.set_ylabel(f"e{j + 1} ({unit})")
        ax.grid(alpha=0.3)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    axes[-1, 0].legend(handles, labels, ncol=3, fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.35))
    axes[0, 0].set_title(title)
    axes[-1, 0].set_xlabel("time (s)")
    return save_figure(fig, path)


def tcp_error(results: dict[str, tuple[np.ndarray, np.ndarray]], path: Path) -> Path:
    """TCP position error |FK(q) - x_ref| over time for several runs (log scale)."""
    fig, ax = plt.subplots(figsize=(9, 3.6))
    for name, (t, err) in results.items():
        ax.semilogy(t, np.maximum(err, 1e-12) * 1e3, lw=1, label=name)
    ax.axhline(1.0, color="0.3", ls=":", label="1 mm")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("task-point error (mm)")
    ax.set_title("Task-point error |FK(q) - x_ref| against the reference")
    ax.legend(fontsize=8, ncol=3)
    ax.grid(alpha=0.3, which="both")
    return save_figure(fig, path)


def solver_diagnostics(result: Result) -> dict[str, dict[str, np.ndarray]]:
    """The recorded diagnostics of iterative solvers: instance -> {name: signal} for every scalar
    output ``<instance>.iterations`` / ``<instance>.residual`` (:data:`DIAGNOSTICS`) of the run."""
    found: dict[str, dict[str, np.ndarray]] = {}
    for column in result.columns:
        instance, _, name = column.partition(".")
        if name in DIAGNOSTICS:
            found.setdefault(instance, {})[DIAGNOSTICS[name]] = result[column]
    return found


def iterations(results: dict[str, Result], path: Path, title: str,
               tolerances: dict[str, float] | None = None) -> Path | None:
    """Iterations of an iterative solver per communication point along each run (top) and the
    residual it ended with (bottom, log scale; a residual of exactly 0 is drawn at the panel's
    floor), one column per run; ``tolerances`` (run -> tolerance) draws the solver's tolerance.
    Runs without recorded diagnostics are left out; None if no run has any."""
    runs = {name: (r, solver_diagnostics(r)) for name, r in results.items()}
    runs = {name: (r, d) for name, (r, d) in runs.items() if d}
    if not runs:
        return None
    fig, axes = plt.subplots(2, len(runs), figsize=(4.8 * len(runs) + 1.0, 5.6), sharey="row", squeeze=False)
    residuals = [s["residual"] for _, d in runs.values() for s in d.values() if "residual" in s]
    positive = [float(r[r > 0].min()) for r in residuals if np.any(r > 0)]
    tiny = 10.0 ** np.floor(np.log10(min(positive, default=1e-16))) / 10.0
    units = {printed(r.units.get(f"{i}.residual")) for r, d in runs.values() for i in d if "residual" in d[i]}
    counts = [float(s["iterations"].max()) for _, d in runs.values() for s in d.values() if "iterations" in s]
    top_limit = max(counts, default=1.0)
    for col, (name, (result, diagnostics)) in enumerate(runs.items()):
        top, bottom = axes[0, col], axes[1, col]
        for k, (instance, signals) in enumerate(diagnostics.items()):
            color = COLORS[(k + 2) % len(COLORS)]
            prefix = f"{instance}: " if len(diagnostics) > 1 else ""
            if "iterations" in signals:
                it = signals["iterations"]
                after = it[1:] if len(it) > 1 else it
                top.step(result.time, it, where="post", color=color, lw=1,
                         label=f"{prefix}first point {it[0]:.0f}, then at most {after.max():.0f} "
                               f"(mean {after.mean():.2f})")
            if "residual" in signals:
                res = signals["residual"]
                bottom.semilogy(result.time[res > 0], res[res > 0], ".", color=color, ms=2,
                                label=f"{prefix}max {res.max():.2g}")
                if np.any(res == 0):
                    bottom.semilogy(result.time[res == 0], np.full(int(np.sum(res == 0)), tiny), "|",
                                    color=color, ms=4, label=f"{prefix}exactly 0 (drawn at {tiny:.0e})")
        tolerance = (tolerances or {}).get(name)
        if tolerance is not None:
            bottom.axhline(tolerance, color="0.3", ls=":", label=f"tolerance {tolerance:g}")
        top.set_ylim(-0.25, top_limit + 1.0)
        top.legend(fontsize=8, loc="upper right")
        bottom.legend(fontsize=7, loc="lower center", ncol=3)
        top.set_title(name, fontsize=10)
        top.grid(alpha=0.3)
        bottom.grid(alpha=0.3, which="both")
        bottom.set_xlabel("time (s)")
    axes[0, 0].set_ylabel("iterations per step")
    axes[0, 0].yaxis.get_major_locator().set_params(integer=True)
    unit = ", ".join(sorted(u for u in units if u))
    axes[1, 0].set_ylabel(f"residual |F|{f' ({unit})' if unit else ''}")
    axes[1, 0].set_ylim(tiny / 100.0, axes[1, 0].get_ylim()[1])
    fig.suptitle(title, fontsize=11)
    return save_figure(fig, path)


def residual_history(histories: dict[str, list[float]], path: Path, title: str,
                     tolerance: float | None = None) -> Path:
    """Residual |F_k| against the iteration k of iterative solves (log scale), one line per solve;
    where the convergence is quadratic the exponent roughly doubles from one iteration to the next."""
    fig, ax = plt.subplots(figsize=(8, 4))
    for k, (name, residuals) in enumerate(histories.items()):
        r = np.asarray(residuals, dtype=float)
        ax.semilogy(np.arange(len(r)), np.where(r > 0, r, np.nan), "o-", color=COLORS[k % len(COLORS)],
                    lw=1, ms=4, label=name)
    if tolerance is not None:
        ax.axhline(tolerance, color="0.3", ls=":", label=f"tolerance {tolerance:g}")
    ax.xaxis.get_major_locator().set_params(integer=True)
    ax.set_xlabel("iteration k")
    ax.set_ylabel("residual |F_k|")
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=8, loc="lower left")
    ax.grid(alpha=0.3, which="both")
    return save_figure(fig, path)


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
        params = [f"{k} = {v:g}" if isinstance(v, (int, float)) else k for k, v in b.parameters.items()]
        if params:
            lines = [", ".join(params[i:i + 2]) for i in range(0, len(params), 2)]
            ax.text(x, -0.05, "\n".join(lines), ha="center", va="top", fontsize=6.5, color="0.3")
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
    return save_figure(fig, path)


def constraint_residual(checks: dict, path: Path, title: str) -> Path:
    """A second, independent formulation of the dynamics along each run (``checks``: run ->
    :class:`~robofmu.system.studies.crosscheck.CrossCheck`): its constraint residual |Phi(t)| (top) and
    the largest difference of its joint coordinates from the co-simulated plant's (bottom), both
    on log scales; points where a value is exactly 0 are left out."""
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(9, 6.4), sharex=True)
    styles = ["-", "--", "-.", ":"]
    for k, (name, c) in enumerate(checks.items()):
        color, style = COLORS[k % len(COLORS)], styles[k // len(COLORS) % len(styles)]
        top.semilogy(c.time, np.where(c.residual > 0, c.residual, np.nan), style, color=color, lw=1,
                     label=f"{name}: max {c.residual.max():.2g}")
        bottom.semilogy(c.time, np.where(c.joint_difference > 0, c.joint_difference, np.nan), style,
                        color=color, lw=1, label=f"{name}: max {c.joint_difference.max():.2g}")
    first = next(iter(checks.values()))
    top.set_ylabel(f"constraint residual |Φ| ({printed(first.residual_units[0])})")
    bottom.set_ylabel(f"max over joints |q_indep − q_cosim| ({first.joint_unit})")
    for ax in (top, bottom):
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7, ncol=2, loc="lower right")
    top.set_title(title, fontsize=10)
    bottom.set_xlabel("time (s)")
    return save_figure(fig, path)

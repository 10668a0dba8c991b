"""A workspace study's figures (:func:`figures`) and report (:func:`report_lines`, :func:`write`)."""
from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from robofmu.system.analysis import markdown_table
from robofmu.system.studies.workspace.measures import BISECTION_TOLERANCE, ZOOM_LEVELS, ZOOM_POINTS

if TYPE_CHECKING:
    from robofmu.system.studies.workspace.run import Workspace


def _save(fig, path: Path, tight: bool = True) -> Path:
    from robofmu.system import plots

    return plots.save_figure(fig, path, tight)


def figures(ws: Workspace, out: Path) -> dict[str, Path]:
    """The maps and the GII refinement as PNG files in ``out``."""
    import matplotlib.pyplot as plt

    from matplotlib.colors import ListedColormap

    out = Path(out)
    m, r, c = ws.maps, ws.radii, ws.centre
    extent = [m.x[0] * 1e3, m.x[-1] * 1e3, m.y[0] * 1e3, m.y[-1] * 1e3]
    ring = np.append(r.beta, r.beta[0])
    made = {}

    def rays(ax, values, style, label):
        v = np.append(values, values[0])
        ax.plot((c[0] + v * np.cos(ring)) * 1e3, (c[1] + v * np.sin(ring)) * 1e3, style, lw=1.2, label=label)

    fig, ax = plt.subplots(figsize=(6.4, 5.6))
    kind = np.where(m.dexterous, 2, np.where(m.reachable, 1, 0))
    ax.imshow(kind, origin="lower", extent=extent, cmap=ListedColormap(["white", "#9ecae1", "#3182bd"]),
              vmin=-0.5, vmax=2.5, interpolation="nearest")
    rays(ax, r.reachable, "k-", f"reachable boundary (rays), min radius {r.reachable_radius * 1e3:.3f} mm")
    rays(ax, r.dexterous, "r--", f"dexterous boundary (rays), min radius {r.dexterous_radius * 1e3:.3f} mm")
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title("Workspace: reachable (light, some θ) and dexterous (dark, every θ)")
    ax.legend(loc="lower left", fontsize=8)
    made["workspace"] = _save(fig, out / "workspace.png")

    fig, ax = plt.subplots(figsize=(6.4, 5.6))
    rng = np.where(m.reachable, np.degrees(m.orientation_range), np.nan)
    im = ax.imshow(rng, origin="lower", extent=extent, cmap="viridis", vmin=0, vmax=360)
    fig.colorbar(im, ax=ax, label="orientation range (deg)")
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title(f"Orientation range per position ({m.orientations} orientations)")
    made["orientation_range"] = _save(fig, out / "orientation_range.png")

    iso_extent = [m.isotropy_x[0] * 1e3, m.isotropy_x[-1] * 1e3, m.isotropy_y[0] * 1e3, m.isotropy_y[-1] * 1e3]
    fig, axes = plt.subplots(1, 2, figsize=(12, 5), constrained_layout=True)
    for ax, data, title in ((axes[0], m.isotropy_at, f"at θ = {math.degrees(m.theta):g}°"),
                            (axes[1], m.isotropy_best, "at the best θ")):
        im = ax.imshow(data, origin="lower", extent=iso_extent, cmap="magma", vmin=0, vmax=1)
        ax.set_aspect("equal")
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("y (mm)")
        ax.set_title(f"Local isotropy 1/cond(J) {title}")
    fig.colorbar(im, ax=axes, label=f"1/cond(J), θ row × L = {ws.length:g} m", shrink=0.85)
    made["isotropy"] = _save(fig, out / "isotropy.png", tight=False)

    if ws.joint:
        fig, ax = plt.subplots(figsize=(6.4, 4.6))
        n = np.array([round(g.samples ** (1 / 3)) for g in ws.joint])
        ax.loglog(n, [g.gii for g in ws.joint], "ko-", label="GII, full joint grid")
        ax.loglog(n, [g.sigma_min / ws.length for g in ws.joint], "b^--", label="min σ_min / L")
        ax.loglog(n, [g.sigma_max / ws.length for g in ws.joint], "rv--", label="max σ_max / L")
        for region in ws.regions:
            ax.axhline(region.gii, color="0.6", lw=0.8)
        if ws.regions:
            ax.axhline(ws.regions[0].gii, color="0.6", lw=0.8, label="GII of the regions")
        ax.set_xlabel("joint grid points per joint N")
        ax.set_title("Full joint grid: GII → 0 as the grid is refined")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
        made["gii"] = _save(fig, out / "gii.png")
    return made


def _relative(value: float, expected: float) -> str:
    return f"{(value / expected - 1.0) * 100:+.2e} %"


def report_lines(ws: Workspace, made: dict[str, Path], level: int = 2, prefix: str = "") -> list[str]:
    """The report (headings from ``level``); figures linked as ``prefix + name``."""
    h = "#" * level
    s, r, m = ws.study, ws.radii, ws.maps
    L = ws.length
    lines = [f"{h} {s.title}", "", s.text, "",
             f"Characteristic length L = {L:g} m: {s.length_text}", "",
             f"{h}# Reachable and dexterous radius", ""]
    rows = []
    for key, values, grid in (("reachable", r.reachable, m.reachable), ("dexterous", r.dexterous, m.dexterous)):
        cell = (m.x[1] - m.x[0]) * (m.y[1] - m.y[0])
        area = math.sqrt(grid.sum() * cell / math.pi)
        expected = s.expected.get(key)
        row = [key, f"{values.min() * 1e3:.6f}", f"{values.max() * 1e3:.6f}", f"{area * 1e3:.2f}"]
        if expected is not None:
            e = float(expected) * L
            row += [f"{s.expected.get(key + '_text', '')} = {e * 1e3:.6f}", _relative(values.min(), e)]
        else:
            row += ["—", "—"]
        rows.append(row)
    lines += [markdown_table(rows, ["workspace", "radius: min over rays (mm)", "max over rays (mm)",
                                    "√(area/π) of the pose-grid map (mm)", "expected (mm)",
                                    "min over rays vs expected"]),
              "",
              f"{len(r.beta)} rays from ({ws.centre[0]:g}, {ws.centre[1]:g}) m, {s.grids['ray_orientations']} "
              f"orientations each, bisection to {BISECTION_TOLERANCE:g} of {r.outer * 1e3:.1f} mm, then "
              f"{ZOOM_LEVELS} zoom levels of {ZOOM_POINTS} orientations about each ray's extreme "
              f"({r.seconds:.1f} s). The map: {len(m.x)}² positions × {m.orientations} orientations "
              f"({m.seconds:.1f} s with the isotropy maps).",
              "", f"![workspace]({prefix}{made['workspace'].name})", "",
              f"{h}# Orientation range per position", "",
              f"The measure of the orientations θ ∈ [-π, π) with an IK solution, on the grid of "
              f"{m.orientations} orientations (360° at the dexterous positions).",
              "", f"![orientation range]({prefix}{made['orientation_range'].name})", "",
              f"{h}# Isotropy", "",
              f"Local isotropy 1/cond(J) with the θ row of J multiplied by L = {L:g} m, on "
              f"{len(m.isotropy_x)}² positions: at θ = {math.degrees(m.theta):g}° and the best of "
              f"{s.grids['isotropy_orientations']} orientations (white: unreachable). Largest at θ = "
              f"{math.degrees(m.theta):g}°: {np.nanmax(m.isotropy_at):.4f}; at the best θ: "
              f"{np.nanmax(m.isotropy_best):.4f}.", "",
              f"![isotropy]({prefix}{made['isotropy'].name})", "",
              f"{h}# Global Isotropy Index", "",
              f"GII = min σ_min(J) / max σ_max(J) over a set of configurations, θ row × L = {L:g} m. "
              f"Regions: discs about the centre (radius as a fraction of L) and an orientation window, "
              f"sampled on a polar grid of {' × '.join(map(str, s.grids['region']))} (radii incl. the rim, "
              "bearings, orientations) through the IK.", ""]
    rows = [[g.name, f"{g.samples}", f"{g.unreachable}", f"{g.sigma_min / L:.6g}", f"{g.sigma_max / L:.6g}",
             f"{g.gii:.6g}"] for g in ws.regions]
    lines += [markdown_table(rows, ["region", "samples", "unreachable", "min σ_min / L", "max σ_max / L", "GII"]), ""]
    if ws.joint:
        rows = [[f"{round(g.samples ** (1 / 3))}³ = {g.samples}", f"{g.unreachable}", f"{g.sigma_min / L:.3e}",
                 f"{g.sigma_max / L:.3e}", f"{g.gii:.3e}", f"{g.reach * 1e3:.4f}", f"{g.exact}",
                 f"{g.seconds:.2f}"] for g in ws.joint]
        lines += [f"{h}## The full joint grid", "",
                  "q_j = -π + 2πk/N, k = 0 … N−1, every combination; configurations without a pose (direct "
                  "singularities) excluded. The exact singular values are computed only where the bounds "
                  "from ‖J‖_F and |det J| leave a configuration in the running for an extreme.", "",
                  markdown_table(rows, ["grid", "no pose", "min σ_min / L", "max σ_max / L", "GII",
                                        "farthest FK position (mm)", "exact SVDs", "time (s)"]), ""]
        if "gii" in made:
            lines += [f"![GII refinement]({prefix}{made['gii'].name})", ""]
    if s.notes.get("full_grid"):
        lines += [s.notes["full_grid"], ""]
    lines += [f"Whole analysis: {ws.seconds:.1f} s.", ""]
    return lines


def write(ws: Workspace, out: Path, level: int = 1) -> Path:
    """Figures and ``out/report.md``; returns the report's path."""
    made = figures(ws, out)
    path = Path(out) / "report.md"
    path.write_text("\n".join(report_lines(ws, made, level)) + "\n")
    return path

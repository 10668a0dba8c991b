"""Figures of a sweep: a metric against its varied parameters, drawn from the rows of ``sweep.csv``.

Which figure a sweep gets depends on its design (:func:`sweep_figures`):

- one grid axis: ``metric_vs_parameter.png``, the metric (and the other headline metrics, one
  panel each) against the parameter;
- two or more grid axes: ``heatmap.png``, the metric over the first two axes (the worst over
  the others), with the contour where it crosses the threshold;
- random sampling: ``histograms.png`` (each headline metric) and ``scatter.png`` (the metric
  against each varied quantity).

:func:`comparison_heatmaps` puts the heat maps of several sweeps of one design side by side,
with a panel overlaying their threshold contours. Failed runs are drawn (red crosses, hatched
grey cells), never left out silently. A metric in m is shown in mm; a varied parameter in the
unit of its FMU variable.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib import patheffects  # noqa: E402
from matplotlib.colors import LogNorm, Normalize  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch, Rectangle  # noqa: E402
from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter, NullLocator  # noqa: E402

from robofmu.system.plots import save_figure  # noqa: E402
from robofmu.system.units import printed, small  # noqa: E402
from robofmu.system.sweep.result import SweepRun  # noqa: E402

__all__ = ["HEADLINE", "column", "comparison_heatmaps", "heatmap", "histograms", "metric_vs_parameter",
           "scatter", "shown", "sweep_figures", "threshold_text"]

#: The metrics a figure shows beside the chosen one, where the sweep has them.
HEADLINE = ("max_tcp_error", "max_joint_error", "peak_effort")
COLORS = ["tab:red", "tab:blue", "tab:green", "k", "tab:orange", "tab:purple"]
CMAP = "viridis"
FAILED = dict(facecolor="0.82", edgecolor="0.45", hatch="//", lw=0.0)
#: Grids up to this many cells get their values written in the cells.
ANNOTATED_CELLS = 80


# ---------------------------------------------------------------------------------------------
# Reading the rows

def _number(text: str) -> float:
    """A cell of ``sweep.csv`` as a float: empty -> NaN, ``true`` / ``false`` -> 1 / 0."""
    if text in ("true", "false"):
        return float(text == "true")
    return float(text) if text else math.nan


def _as_float(value) -> float:
    """A design value (number or bool) as a float, as :func:`_number` reads it back."""
    return float(bool(value)) if isinstance(value, bool) else float(value)


def column(run: SweepRun, name: str, rows: list | None = None) -> np.ndarray:
    """One column of the rows as floats.

    Parameters
    ----------
    run : SweepRun
    name : str
        A varied name or a metric column.
    rows : list of dict, optional
        The rows to read (default: all of ``run.rows``).

    Returns
    -------
    ndarray, shape (len(rows),)
        The values in SI units; NaN where the cell is empty.
    """
    return np.array([_number(r[name]) for r in (run.rows if rows is None else rows)], dtype=float)


def _ok(run: SweepRun) -> np.ndarray:
    """Mask of the ok rows, shape (len(run.rows),)."""
    return np.array([r["status"] == "ok" for r in run.rows], dtype=bool)


def shown(run: SweepRun, metric: str) -> tuple[float, str]:
    """Factor and printed unit a metric is displayed in (m -> mm; ``""`` without a unit)."""
    unit = run.units.get(metric)
    return small(unit) if unit else (1.0, "")


def threshold_text(run: SweepRun, metric: str, threshold: float) -> str:
    """The threshold as displayed, ``1 mm``."""
    factor, unit = shown(run, metric)
    return f"{threshold * factor:g} {unit}".strip()


def _metric_label(run: SweepRun, metric: str) -> str:
    unit = shown(run, metric)[1]
    return f"{metric} ({unit})" if unit else metric


def _axis_label(run: SweepRun, name: str) -> str:
    unit = run.units.get(name)
    return f"{name} ({printed(unit)})" if unit else name


def _title(run: SweepRun) -> str:
    """The name a figure's title gives the sweep: its system's, else its experiment's."""
    return run.name or run.design.experiment


def _panels(run: SweepRun, metric: str) -> list[str]:
    """The chosen metric, then the other headline metrics the sweep has."""
    return [metric] + [m for m in HEADLINE if m != metric and m in run.metrics]


def _check_metric(run: SweepRun, metric: str) -> None:
    if metric not in run.metrics:
        raise ValueError(f"{metric!r} is not a metric of this sweep (metrics: {', '.join(run.metrics[:4])}, ...)")


# ---------------------------------------------------------------------------------------------
# Scales and axes

def _spans_decade(values: np.ndarray) -> bool:
    """Whether finite ``values`` are all positive and span more than a factor of ten."""
    v = values[np.isfinite(values)]
    return v.size > 1 and bool(np.all(v > 0)) and v.max() > 10.0 * v.min()


def _log_axis(values: np.ndarray) -> bool:
    """Whether grid values are best drawn on a log axis: positive, and spanning more than a
    decade or evenly spaced in their logarithm (200, 400, 800, 1600) rather than linearly."""
    v = np.unique(values[np.isfinite(values)])
    if v.size < 2 or np.any(v <= 0):
        return False
    if v.max() > 10.0 * v.min():
        return True
    if v.size < 3:
        return False
    linear, logarithmic = np.diff(v), np.diff(np.log(v))
    return bool(np.std(logarithmic) / np.mean(logarithmic) < 0.5 * np.std(linear) / np.mean(linear))


def _bar_ticks(bar, norm: Normalize) -> None:
    """Plain numbers on a colour bar (1, 2, 5 per decade on a log scale)."""
    plain = FuncFormatter(lambda v, _: f"{v:g}")
    if isinstance(norm, LogNorm):
        bar.ax.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
        bar.ax.yaxis.set_minor_formatter(NullFormatter())
    bar.ax.yaxis.set_major_formatter(plain)


def _norm(values: np.ndarray) -> Normalize:
    """Colour scale of ``values``: logarithmic where they are positive and span more than a decade."""
    v = values[np.isfinite(values)]
    if v.size == 0:
        return Normalize(0.0, 1.0)
    low, high = float(v.min()), float(v.max())
    if _spans_decade(v):
        return LogNorm(low, high)
    if low == high:
        pad = abs(low) * 0.1 or 1.0
        low, high = low - pad, high + pad
    return Normalize(low, high)


def _is_bool(run: SweepRun, name: str) -> bool:
    texts = {r[name] for r in run.rows}
    return bool(texts) and texts <= {"true", "false"}


def _value_ticks(ax, which: str, values: np.ndarray, boolean: bool) -> None:
    """Ticks at a few grid values (``false`` / ``true`` for a boolean)."""
    axis = ax.xaxis if which == "x" else ax.yaxis
    if boolean:
        axis.set_ticks([0.0, 1.0], ["false", "true"])
    elif len(values) <= 12:
        axis.set_ticks(values, [f"{v:g}" for v in values])
        axis.set_minor_locator(NullLocator())


def _edges(centres: np.ndarray, log: bool) -> np.ndarray:
    """Cell edges around sorted cell centres, shape (n + 1,): midpoints (geometric on a log axis),
    the outer cells as wide as their neighbours."""
    c = np.log10(centres) if log else np.asarray(centres, dtype=float)
    if len(c) == 1:
        half = 0.5 if log or c[0] == 0 else abs(c[0]) * 0.25
        e = np.array([c[0] - half, c[0] + half])
    else:
        mid = (c[1:] + c[:-1]) / 2
        e = np.concatenate([[c[0] - (mid[0] - c[0])], mid, [c[-1] + (c[-1] - mid[-1])]])
    return 10.0 ** e if log else e


def _failed_marks(ax, x: np.ndarray, label: str | None = "failed run") -> None:
    """Red crosses at the bottom of the panel at the ``x`` of failed runs."""
    if len(x):
        ax.plot(x, np.zeros(len(x)), "x", color="tab:red", ms=8, mew=2, clip_on=False, zorder=5,
                transform=ax.get_xaxis_transform(), label=label)


# ---------------------------------------------------------------------------------------------
# One grid axis

def metric_vs_parameter(run: SweepRun, metric: str, threshold: float | None = None) -> Path:
    """``metric_vs_parameter.png``: the metric and the other headline metrics against the one
    grid axis, one panel each; failed runs as red crosses at the bottom, the threshold dashed.

    Parameters
    ----------
    run : SweepRun
        A sweep of exactly one grid axis.
    metric : str
        The metric of the first panel.
    threshold : float, optional
        A level of ``metric`` (SI) drawn as a horizontal dashed line.
    """
    _check_metric(run, metric)
    axis = run.design.grid_axes[0]
    x, ok = column(run, axis.name), _ok(run)
    order = np.argsort(x, kind="stable")
    panels = _panels(run, metric)
    fig, axes = plt.subplots(len(panels), 1, figsize=(8, 2.4 * len(panels) + 0.8), sharex=True, squeeze=False)
    log_x = _log_axis(x)
    for k, (ax, name) in enumerate(zip(axes[:, 0], panels)):
        factor, _ = shown(run, name)
        y = column(run, name) * factor
        keep = order[ok[order]]
        ax.plot(x[keep], y[keep], "o-", color=COLORS[1], ms=5, lw=1.2, label="ok run")
        if _spans_decade(y[keep]):
            ax.set_yscale("log")
        if name == metric and threshold is not None:
            ax.axhline(threshold * factor, color="0.3", ls="--", lw=1.2,
                       label=f"threshold {threshold_text(run, metric, threshold)}")
        _failed_marks(ax, x[~ok], "failed run" if k == 0 else None)
        ax.set_ylabel(_metric_label(run, name))
        ax.grid(alpha=0.3, which="both")
    if log_x:
        axes[0, 0].set_xscale("log")
    _value_ticks(axes[-1, 0], "x", np.unique(x), _is_bool(run, axis.name))
    axes[-1, 0].set_xlabel(_axis_label(run, axis.name))
    failed = int(np.sum(~ok))
    axes[0, 0].set_title(f"{_title(run)}: {metric} against {axis.name} ({len(run.rows)} runs"
                         + (f", {failed} failed: red crosses" if failed else "") + ")", fontsize=10)
    axes[0, 0].legend(fontsize=8, loc="best")
    return save_figure(fig, run.folder / "metric_vs_parameter.png")


# ---------------------------------------------------------------------------------------------
# Two or more grid axes

@dataclass
class Grid:
    """The metric over the first two grid axes of a sweep.

    Attributes
    ----------
    x, y : ndarray, shape (nx,), (ny,)
        The sorted values of the first and second grid axes (SI).
    z : ndarray, shape (ny, nx)
        The metric as displayed (e.g. mm): the worst (max) over the other axes; NaN where a run
        failed, was not run, or has no value.
    failed : ndarray of bool, shape (ny, nx)
        Cells where a run failed.
    empty : ndarray of bool, shape (ny, nx)
        Cells without a failed run and without a value (not run, or an empty metric).
    names : tuple of str
        The names of the x and y axes.
    others : list of str
        The grid axes the worst is taken over.
    """

    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    failed: np.ndarray
    empty: np.ndarray
    names: tuple
    others: list

    @property
    def log_x(self) -> bool:
        return _log_axis(self.x)

    @property
    def log_y(self) -> bool:
        return _log_axis(self.y)


def grid_of(run: SweepRun, metric: str) -> Grid:
    """The :class:`Grid` of ``metric`` over the first two grid axes of ``run``."""
    _check_metric(run, metric)
    gx, gy, *others = run.design.grid_axes
    x = np.unique([_as_float(v) for v in gx.values])
    y = np.unique([_as_float(v) for v in gy.values])
    ix, iy = {v: i for i, v in enumerate(x)}, {v: j for j, v in enumerate(y)}
    factor, _ = shown(run, metric)
    z = np.full((len(y), len(x)), np.nan)
    failed = np.zeros(z.shape, dtype=bool)
    for row in run.rows:
        i, j = ix[_number(row[gx.name])], iy[_number(row[gy.name])]
        if row["status"] != "ok":
            failed[j, i] = True
            continue
        value = _number(row[metric]) * factor
        if np.isfinite(value):
            z[j, i] = value if np.isnan(z[j, i]) else max(z[j, i], value)
    z[failed] = np.nan
    return Grid(x, y, z, failed, ~failed & np.isnan(z), (gx.name, gy.name), [a.name for a in others])


def _side(grid: Grid, level: float) -> str:
    """Where the values of ``grid`` lie against ``level``: ``"crossing"`` (a contour can be drawn),
    ``"within"`` (every value at most ``level``), ``"above"`` (every value above), ``"no value"``,
    or ``"one line"`` (fewer than 2 x 2 cells: the values cross, no contour can be drawn)."""
    z = grid.z[np.isfinite(grid.z)]
    if z.size == 0:
        return "no value"
    if z.max() <= level:
        return "within"
    if z.min() > level:
        return "above"
    return "crossing" if min(grid.z.shape) >= 2 and z.min() < level else "one line"


def _contour(ax, grid: Grid, level: float | None, color: str, label: str, stroke: bool = True):
    """The contour where ``grid.z`` crosses ``level`` (a labelled line); None where it does not
    cross it (:func:`_side`)."""
    if level is None or _side(grid, level) != "crossing":
        return None
    effects = [patheffects.withStroke(linewidth=4.0, foreground="k")] if stroke else None
    cs = ax.contour(grid.x, grid.y, np.ma.masked_invalid(grid.z), levels=[level], colors=[color],
                    linewidths=2.0)
    if effects:
        cs.set_path_effects(effects)
    texts = ax.clabel(cs, fmt={level: label}, fontsize=9, inline=True)
    for t in texts:
        t.set_color(color)
        if effects:
            t.set_path_effects(effects)
    return cs


def _cell_texts(ax, grid: Grid, norm: Normalize) -> None:
    """Each cell's value, in black or white as its colour needs."""
    cmap = plt.get_cmap(CMAP)
    for j, yv in enumerate(grid.y):
        for i, xv in enumerate(grid.x):
            v = grid.z[j, i]
            if np.isfinite(v):
                r, g, b, _ = cmap(norm(v))
                dark = 0.299 * r + 0.587 * g + 0.114 * b < 0.5
                ax.text(xv, yv, f"{v:.3g}", ha="center", va="center", fontsize=8,
                        color="w" if dark else "k")


def _draw_grid(ax, run: SweepRun, grid: Grid, norm: Normalize, texts: bool = True):
    """A heat map of ``grid`` on ``ax`` (failed cells hatched grey); returns the QuadMesh."""
    log_x, log_y = grid.log_x, grid.log_y
    xe, ye = _edges(grid.x, log_x), _edges(grid.y, log_y)
    mesh = ax.pcolormesh(xe, ye, np.ma.masked_invalid(grid.z), norm=norm, cmap=CMAP, shading="flat")
    for j, i in zip(*np.nonzero(grid.failed)):
        ax.add_patch(Rectangle((xe[i], ye[j]), xe[i + 1] - xe[i], ye[j + 1] - ye[j], **FAILED))
    _frame(ax, run, grid)
    if texts and grid.z.size <= ANNOTATED_CELLS:
        _cell_texts(ax, grid, norm)
    return mesh


def _frame(ax, run: SweepRun, grid: Grid) -> None:
    """Scales, limits, ticks at the grid values and axis labels of a heat map panel."""
    xe, ye = _edges(grid.x, grid.log_x), _edges(grid.y, grid.log_y)
    if grid.log_x:
        ax.set_xscale("log")
    if grid.log_y:
        ax.set_yscale("log")
    ax.set_xlim(xe[0], xe[-1])
    ax.set_ylim(ye[0], ye[-1])
    _value_ticks(ax, "x", grid.x, _is_bool(run, grid.names[0]))
    _value_ticks(ax, "y", grid.y, _is_bool(run, grid.names[1]))
    ax.set_xlabel(_axis_label(run, grid.names[0]))
    ax.set_ylabel(_axis_label(run, grid.names[1]))


def _legend_handles(grid: Grid, contour: bool, label: str) -> list:
    handles = []
    if contour:
        handles.append(Line2D([], [], color="w", lw=2.0, label=label,
                              path_effects=[patheffects.withStroke(linewidth=4.0, foreground="k")]))
    if grid.failed.any():
        handles.append(Patch(**FAILED, label=f"failed run ({int(grid.failed.sum())})"))
    if grid.empty.any():
        handles.append(Patch(facecolor="w", edgecolor="0.45", label="no value"))
    return handles


def _no_contour(grid: Grid, level: float, text: str) -> str:
    """Why a heat map has no threshold contour, in words."""
    side = _side(grid, level)
    return {"within": f"every value within {text}", "above": f"every value above {text}",
            "no value": "no value", "one line": f"{text} crossed on a single line of cells"}[side]


def heatmap(run: SweepRun, metric: str, threshold: float | None = None) -> Path:
    """``heatmap.png``: ``metric`` over the first two grid axes (x: the first, y: the second),
    the worst (max) over any further grid axes; failed cells hatched grey; the contour where the
    metric crosses ``threshold`` (SI) where it lies within the data range.

    The colour scale is logarithmic where the metric is positive and spans more than a decade.
    """
    grid = grid_of(run, metric)
    factor, _ = shown(run, metric)
    norm = _norm(grid.z)
    fig, ax = plt.subplots(figsize=(7.4, 5.8))
    mesh = _draw_grid(ax, run, grid, norm)
    level = None if threshold is None else threshold * factor
    label = f"{metric} = {threshold_text(run, metric, threshold)}" if threshold is not None else ""
    contour = _contour(ax, grid, level, "w", threshold_text(run, metric, threshold) if level is not None else "")
    bar = fig.colorbar(mesh, ax=ax)
    bar.set_label(_metric_label(run, metric))
    _bar_ticks(bar, norm)
    if contour is not None:
        bar.ax.axhline(level, color="w", lw=2.0)
    title = f"{_title(run)}: {metric}"
    if grid.others:
        title += f", the worst over {', '.join(grid.others)}"
    notes = [f"{len(run.rows)} runs"]
    if grid.failed.any():
        count = int(grid.failed.sum())
        notes.append(f"{count} cell{'s' * (count != 1)} with a failed run (hatched)")
    if threshold is not None and contour is None:
        notes.append(_no_contour(grid, level, threshold_text(run, metric, threshold)))
    ax.set_title(f"{title}\n{'; '.join(notes)}", fontsize=10)
    handles = _legend_handles(grid, contour is not None, label)
    if handles:
        ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=len(handles),
                  fontsize=8, frameon=False)
    return save_figure(fig, run.folder / "heatmap.png")


# ---------------------------------------------------------------------------------------------
# Random sampling

def _grid_shape(count: int) -> tuple[int, int]:
    cols = min(3, count)
    return math.ceil(count / cols), cols


def histograms(run: SweepRun, metric: str, threshold: float | None = None) -> Path:
    """``histograms.png``: a histogram of ``metric`` and of each other headline metric over the
    ok runs (log bins where the values span more than a decade), the threshold dashed."""
    _check_metric(run, metric)
    ok = _ok(run)
    panels = _panels(run, metric)
    rows, cols = _grid_shape(len(panels))
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols + 0.6, 3.4 * rows), squeeze=False)
    for ax, name in zip(axes.flat, panels):
        factor, _ = shown(run, name)
        v = column(run, name)[ok] * factor
        v = v[np.isfinite(v)]
        if v.size:
            log = _spans_decade(v)
            bins = np.geomspace(v.min(), v.max(), 21) if log else min(20, max(5, v.size // 3))
            ax.hist(v, bins=bins, color=COLORS[1], alpha=0.8, edgecolor="w")
            if log:
                ax.set_xscale("log")
            ax.set_title(f"{name}: median {np.median(v):.3g}, max {v.max():.3g}", fontsize=9)
        if name == metric and threshold is not None:
            within = int(np.sum(v <= threshold * factor))
            ax.axvline(threshold * factor, color="0.3", ls="--", lw=1.2,
                       label=f"{threshold_text(run, metric, threshold)}: {within} of {v.size} within")
            ax.legend(fontsize=8)
        ax.set_xlabel(_metric_label(run, name))
        ax.set_ylabel("runs")
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(panels):]:
        ax.axis("off")
    failed = int(np.sum(~ok))
    fig.suptitle(f"{_title(run)}: {int(ok.sum())} ok runs" + (f" ({failed} failed, not counted)" if failed else ""),
                 fontsize=10)
    return save_figure(fig, run.folder / "histograms.png")


def scatter(run: SweepRun, metric: str, threshold: float | None = None) -> Path:
    """``scatter.png``: ``metric`` against each varied quantity, one panel each; failed runs as
    red crosses at the bottom, the threshold dashed."""
    _check_metric(run, metric)
    ok = _ok(run)
    factor, _ = shown(run, metric)
    y = column(run, metric) * factor
    names = run.design.names
    rows, cols = _grid_shape(len(names))
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols + 0.6, 3.4 * rows), sharey=True, squeeze=False)
    log_y = _spans_decade(y[ok])
    for k, (ax, name) in enumerate(zip(axes.flat, names)):
        x = column(run, name)
        ax.plot(x[ok], y[ok], "o", color=COLORS[1], ms=4, alpha=0.7, label="ok run")
        if log_y:
            ax.set_yscale("log")
        if threshold is not None:
            ax.axhline(threshold * factor, color="0.3", ls="--", lw=1.2,
                       label=f"threshold {threshold_text(run, metric, threshold)}")
        _failed_marks(ax, x[~ok], "failed run")
        axis = run.design.axes[k]
        if not axis.random or _is_bool(run, name):
            _value_ticks(ax, "x", np.unique(x), _is_bool(run, name))
        ax.set_xlabel(_axis_label(run, name))
        ax.grid(alpha=0.3, which="both")
        if k % cols == 0:
            ax.set_ylabel(_metric_label(run, metric))
    for ax in list(axes.flat)[len(names):]:
        ax.axis("off")
    axes[0, 0].legend(fontsize=8, loc="best")
    failed = int(np.sum(~ok))
    fig.suptitle(f"{_title(run)}: {metric} against each varied quantity ({len(run.rows)} runs"
                 + (f", {failed} failed: red crosses" if failed else "") + ")", fontsize=10)
    return save_figure(fig, run.folder / "scatter.png")


# ---------------------------------------------------------------------------------------------
# Choosing, comparing

def sweep_figures(run: SweepRun, metric: str, threshold: float | None = None) -> list[Path]:
    """The figures that apply to the design of ``run``, written in ``run.folder``.

    Parameters
    ----------
    run : SweepRun
    metric : str
        The metric mapped (a column of ``run.metrics``).
    threshold : float, optional
        A level of ``metric`` (SI units, e.g. m) drawn as a line or contour.

    Returns
    -------
    list of Path
        ``histograms.png`` and ``scatter.png`` for random sampling, ``metric_vs_parameter.png``
        for one grid axis, ``heatmap.png`` for two or more; none without an ok row.
    """
    _check_metric(run, metric)
    if not _ok(run).any():
        return []
    if run.design.random:
        return [histograms(run, metric, threshold), scatter(run, metric, threshold)]
    if len(run.design.grid_axes) == 1:
        return [metric_vs_parameter(run, metric, threshold)]
    return [heatmap(run, metric, threshold)]


def comparison_heatmaps(runs: list[tuple[str, SweepRun]], metric: str, threshold: float | None,
                        path: str | Path) -> Path:
    """Heat maps of several sweeps of the same two (or more) grid axes side by side, on one colour
    scale, each with its threshold contour; then a panel overlaying the contours of all of them
    (shaded on the side within the threshold).

    Parameters
    ----------
    runs : list of (str, SweepRun)
        A label (e.g. the controller) and its sweep; every sweep varies the same grid axes.
    metric : str
    threshold : float or None
        The level of ``metric`` (SI); None: no contours and no overlay panel.
    path : str or Path
        The PNG written.
    """
    if not runs:
        raise ValueError("comparison_heatmaps: no sweep given")
    names = [tuple(a.name for a in run.design.grid_axes[:2]) for _, run in runs]
    if len(names[0]) < 2 or any(n != names[0] for n in names):
        raise ValueError(f"comparison_heatmaps: the sweeps must vary the same two grid axes ({names})")
    first = runs[0][1]
    grids = [grid_of(run, metric) for _, run in runs]
    norm = _norm(np.concatenate([g.z.ravel() for g in grids]))
    factor, _ = shown(first, metric)
    level = None if threshold is None else threshold * factor
    text = threshold_text(first, metric, threshold) if threshold is not None else ""
    panels = len(runs) + (level is not None)
    fig, axes = plt.subplots(1, panels, figsize=(4.6 * panels + 1.4, 4.9), squeeze=False, layout="constrained")
    axes = axes[0]
    mesh = None
    for ax, (label, run), grid in zip(axes, runs, grids):
        mesh = _draw_grid(ax, run, grid, norm)
        _contour(ax, grid, level, "w", text)
        failed = int(grid.failed.sum())
        ax.set_title(label + (f" ({failed} failed, hatched)" if failed else ""), fontsize=10)
    bar = fig.colorbar(mesh, ax=list(axes[:len(runs)]), fraction=0.05, pad=0.02)
    bar.set_label(_metric_label(first, metric))
    _bar_ticks(bar, norm)
    if level is not None:
        _overlay(axes[-1], runs, grids, level, text, metric)
    worst = f", the worst over {', '.join(grids[0].others)}" if grids[0].others else ""
    fig.suptitle(f"{metric} of {', '.join(label for label, _ in runs)}{worst}", fontsize=11)
    return save_figure(fig, Path(path), tight=False)


def _overlay(ax, runs: list, grids: list[Grid], level: float, text: str, metric: str) -> None:
    """The threshold contour of every sweep on one panel, shaded where the metric is within it."""
    handles = []
    for k, ((label, run), grid) in enumerate(zip(runs, grids)):
        color = COLORS[k % len(COLORS)]
        _frame(ax, run, grid)
        if _side(grid, level) == "crossing":
            masked = np.ma.masked_invalid(grid.z)
            ax.contourf(grid.x, grid.y, masked, levels=[float(masked.min()), level], colors=[color], alpha=0.15)
            ax.contour(grid.x, grid.y, masked, levels=[level], colors=[color], linewidths=2.0)
            handles.append(Line2D([], [], color=color, lw=2.0, label=label))
        else:
            handles.append(Line2D([], [], color=color, lw=2.0, ls=":",
                                  label=f"{label}: {_no_contour(grid, level, text)}"))
    ax.grid(alpha=0.3)
    ax.legend(handles=handles, fontsize=8, loc="best")
    ax.set_title(f"{metric} = {text} (shaded: within)", fontsize=10)

"""``report.md`` of a sweep: what was varied, how many runs ran and failed, the worst runs, the
region within a threshold, the failed runs' messages, how to rerun one row alone, the figures.

Metrics in m are shown in mm (as in the figures); every table value is printed with four
significant digits, while the rerun commands give each varied value exactly as recorded.
"""
from __future__ import annotations

import math
import shlex
from pathlib import Path

import numpy as np

from robofmu.system.analysis import markdown_table
from robofmu.system.units import printed
from robofmu.system.sweep.design import STEP_SIZE_AXIS
from robofmu.system.sweep.figures import HEADLINE, column, shown, sweep_figures, threshold_text
from robofmu.system.sweep.journal import cell, key_of
from robofmu.system.usage import atomic_file
from robofmu.system.sweep.result import SweepRun

__all__ = ["default_metric", "default_threshold", "reproduce_command", "write_report"]

#: Rows of the worst-runs table, and failed runs listed before "and K more".
WORST_ROWS = 5
FAILED_ROWS = 20


def default_metric(run: SweepRun) -> str:
    """``max_tcp_error`` where the sweep has it, else ``max_joint_error``."""
    return "max_tcp_error" if "max_tcp_error" in run.metrics else "max_joint_error"


def default_threshold(metric: str) -> float | None:
    """1 mm (0.001 m) for ``max_tcp_error``; None for any other metric."""
    return 1e-3 if metric == "max_tcp_error" else None


# ---------------------------------------------------------------------------------------------
# Values as text

def _number(text: str) -> float:
    return float(text) if text and text not in ("true", "false") else math.nan


def _exact(text: str) -> str:
    """A recorded value as a command line takes it: whole numbers without ``.0``, other floats
    exactly (repr), booleans ``true`` / ``false``."""
    if text in ("true", "false") or not text:
        return text
    value = float(text)
    return str(int(value)) if value.is_integer() and abs(value) < 1e15 else repr(value)


def _short(text: str) -> str:
    """A varied value for a table: four significant digits (booleans as written)."""
    return text if text in ("true", "false") or not text else f"{float(text):.4g}"


def _metric_cell(run: SweepRun, row: dict, name: str) -> str:
    value = _number(row[name])
    return "—" if math.isnan(value) else f"{value * shown(run, name)[0]:.4g}"


def _header(run: SweepRun, name: str, metric: bool = False) -> str:
    unit = shown(run, name)[1] if metric else printed(run.units.get(name))
    return f"{name} ({unit})" if unit else name


def _message(text: str) -> str:
    """A failure message on one table line (``|`` escaped)."""
    return " ".join(text.split()).replace("|", "\\|") or "—"


# ---------------------------------------------------------------------------------------------
# Pieces of the report

def reproduce_command(run: SweepRun, row: dict) -> str:
    """The ``robofmu run`` command that runs one row of the sweep alone.

    Each varied ``BLOCK.PARAM`` becomes ``--set BLOCK.PARAM=VALUE`` (the value as recorded; a
    vector parameter, one ``--set BLOCK.PARAM[j]=VALUE`` per element); a varied step size, or the
    design's fixed step, ``--step-size``; the design's stop time ``--stop-time``.
    """
    design = run.design
    words = ["robofmu", "run", shlex.quote(design.experiment)]
    step = None if design.step is None else cell(design.step)
    for name in design.names:
        if name == STEP_SIZE_AXIS:
            step = row[name]
            continue
        elements = [f"{name}[{j}]" for j in range(1, run.widths[name] + 1)] if name in run.widths else [name]
        for element in elements:
            words += ["--set", shlex.quote(f"{element}={_exact(row[name])}")]
    if step:
        words += ["--step-size", _exact(step)]
    if design.stop_time is not None:
        words += ["--stop-time", _exact(cell(design.stop_time))]
    return " ".join(words)


def _numbering(run: SweepRun) -> dict:
    """Run number (its index in the design, as in ``runs/run-NNNNN``) by row key."""
    return {key_of(values, run.design.names): i for i, values in enumerate(run.design.runs())}


def _row_number(run: SweepRun, numbers: dict, row: dict) -> str:
    key = tuple(row[n] for n in run.design.names)
    return str(numbers.get(key, "?"))


def _design_section(run: SweepRun) -> list[str]:
    design = run.design
    lines = ["## What was varied", "", f"Experiment `{design.experiment}`, {len(design.runs())} runs:", ""]
    for axis in design.axes:
        unit = printed(run.units.get(axis.name))
        lines.append(f"- `{axis.describe()}`" + (f" ({unit})" if unit else ""))
    lines.append("")
    grid = design.grid_axes
    if design.random:
        points = math.prod(len(a.values) for a in grid) if grid else 1
        lines.append(f"{design.samples} random samples drawn with seed {design.seed}"
                     + (f", for each of the {points} combinations of the grid values." if grid else "."))
    elif len(grid) == 1:
        lines.append("One run per value.")
    else:
        lines.append("Every combination of the grid values (the last varying fastest).")
    timing = []
    if design.step is not None:
        timing.append(f"communication step {design.step:g} s")
    if design.stop_time is not None:
        timing.append(f"stop time {design.stop_time:g} s")
    if timing:
        lines[-1] += " " + "; ".join(timing).capitalize() + "."
    return lines


def _runs_section(run: SweepRun, interrupted: bool) -> list[str]:
    total = len(run.design.runs())
    ok = len(run.rows) - len(run.failed)
    lines = ["## Runs", ""]
    if interrupted:
        lines += [f"**interrupted: {len(run.rows)} of {total} runs finished; run the same command again "
                  "to finish.**", ""]
    lines.append(f"- runs: {len(run.rows)} of {total}: {ok} ok, {len(run.failed)} failed")
    lines.append(f"- reused from an earlier invocation: {run.reused}")
    where = "an existing Dask cluster" if run.workers is None else \
        f"{run.workers} local worker process" + "es" * (run.workers != 1)
    if run.ran > 0:
        rate = f", {run.ran / run.seconds * 60:.3g} runs per minute" if run.seconds > 0 else ""
        lines.append(f"- executed now: {run.ran} runs in {run.seconds:.1f} s wall time{rate}, on {where}")
    else:
        lines.append("- executed now: none")
    each = column(run, "wall_time", [r for r in run.rows if r["status"] == "ok"])
    each = each[np.isfinite(each)]
    if each.size:
        lines.append(f"- one run: {np.median(each):.3g} s wall time (median over the ok runs)")
    return lines


def _ranges(run: SweepRun, rows: list[dict]) -> list[str]:
    """The range of each varied quantity among ``rows``."""
    lines = []
    for axis in run.design.axes:
        texts = [r[axis.name] for r in rows]
        unit = printed(run.units.get(axis.name))
        if set(texts) <= {"true", "false"}:
            shown_values = ", ".join(sorted(set(texts)))
        else:
            values = np.array([_number(t) for t in texts])
            low, high = f"{values.min():.4g}", f"{values.max():.4g}"
            shown_values = (low if low == high else f"{low} to {high}") + (f" {unit}" if unit else "")
            if axis.follows:
                shown_values += f" (as {axis.follows})"
            elif not axis.random:
                shown_values += f" ({len(set(texts))} of {len(axis.values)} values)"
        lines.append(f"- `{axis.name}`: {shown_values}")
    return lines


def _threshold_section(run: SweepRun, ok: list[dict], metric: str, threshold: float) -> list[str]:
    values = column(run, metric, ok)
    within = [r for r, v in zip(ok, values) if v <= threshold]
    text = threshold_text(run, metric, threshold)
    lines = ["## Within the threshold", "",
             f"{len(within)} of {len(ok)} ok runs keep {metric} within {text}."]
    if within:
        lines += ["", "Among those:", "", *_ranges(run, within)]
    return lines


def _worst_section(run: SweepRun, ok: list[dict], metric: str, numbers: dict) -> list[str]:
    values = column(run, metric, ok)
    ranked = [ok[k] for k in np.argsort(-values, kind="stable") if np.isfinite(values[k])]
    lines = [f"## The worst runs by {metric}", ""]
    missing = len(ok) - len(ranked)
    if not ranked:
        return lines + [f"No ok run has a value of {metric}."]
    metrics = [metric] + [m for m in HEADLINE if m != metric and m in run.metrics]
    header = ["run", *(_header(run, n) for n in run.design.names), *(_header(run, m, True) for m in metrics)]
    table = [[_row_number(run, numbers, r), *(_short(r[n]) for n in run.design.names),
              *(_metric_cell(run, r, m) for m in metrics)] for r in ranked[:WORST_ROWS]]
    lines.append(markdown_table(table, header))
    if missing:
        lines += ["", f"{missing} ok run{'s' * (missing != 1)} without a value of {metric} "
                      f"{'are' if missing != 1 else 'is'} not ranked."]
    lines += ["", "Rerun the worst alone:", "", f"    {reproduce_command(run, ranked[0])}"]
    return lines


def _failed_section(run: SweepRun, numbers: dict) -> list[str]:
    failed = run.failed
    header = ["run", *(_header(run, n) for n in run.design.names), "message"]
    table = [[_row_number(run, numbers, r), *(_short(r[n]) for n in run.design.names), _message(r["message"])]
             for r in failed[:FAILED_ROWS]]
    lines = ["## Failed runs", "", markdown_table(table, header)]
    if len(failed) > FAILED_ROWS:
        lines += ["", f"and {len(failed) - FAILED_ROWS} more (see sweep.csv)."]
    lines += ["", "Rerun the first alone:", "", f"    {reproduce_command(run, failed[0])}"]
    return lines


# ---------------------------------------------------------------------------------------------

def write_report(run: SweepRun, figures: bool = True, metric: str | None = None, threshold: float | None = None,
                 interrupted: bool = False) -> Path:
    """Write ``run.folder / "report.md"`` (and the figures); sets ``run.figures``.

    Parameters
    ----------
    run : SweepRun
    figures : bool
        Write the figures (:func:`~robofmu.system.sweep.figures.sweep_figures`) where there is an
        ok row, and link them.
    metric : str, optional
        The metric ranked and mapped (default :func:`default_metric`).
    threshold : float, optional
        A level of ``metric`` in SI units (default :func:`default_threshold`: 1 mm for
        ``max_tcp_error``).
    interrupted : bool
        The sweep was stopped before every run finished (the report says how to continue).

    Returns
    -------
    Path
        The report written.
    """
    metric = metric or default_metric(run)
    if metric not in run.metrics:
        raise ValueError(f"{metric!r} is not a metric of this sweep (metrics: {', '.join(run.metrics[:4])}, ...)")
    if threshold is None:
        threshold = default_threshold(metric)
    ok = [r for r in run.rows if r["status"] == "ok"]
    run.figures = sweep_figures(run, metric, threshold) if figures and ok else []
    numbers = _numbering(run)
    text = [f"# Sweep of {run.name or run.design.experiment}", ""]
    if run.description:
        text += [run.description, ""]
    text += [*_design_section(run), "", *_runs_section(run, interrupted)]
    if threshold is not None and ok:
        text += ["", *_threshold_section(run, ok, metric, threshold)]
    if ok:
        text += ["", *_worst_section(run, ok, metric, numbers)]
    if run.failed:
        text += ["", *_failed_section(run, numbers)]
    if not run.rows:
        text += ["", "No run has finished. Run the first alone:", "",
                 f"    {reproduce_command(run, {k: cell(v) for k, v in run.design.runs()[0].items()})}"]
    if run.figures:
        text += ["", "## Figures", ""]
        text += [f"![{p.stem}]({p.name})" for p in run.figures]
    path = Path(run.folder) / "report.md"
    with atomic_file(path) as partial:
        partial.write_text("\n".join(text) + "\n")
    return path

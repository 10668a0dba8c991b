"""The loop as it runs on the robot: one experiment at several controller sample rates and
computation delays, its joints' losses known to the controller's model or not.

What runs is data (``[sampled_loop]`` of ``system/studies/demo.toml``, read by :mod:`.plan`): an
experiment file that states the plant's losses (and the controller's model of them), the sample
times and the delays. It runs as one sweep (:func:`~robofmu.system.sweep.run.run_sweep`, a local
Dask cluster) over ``<controller>.sample_time`` x ``<controller>.delay_steps`` x
``<controller>.loss_compensation`` (1: the losses known to the controller, 0: unknown); each
case's path and end-pose errors are the sweep's metrics (:mod:`~robofmu.system.sweep.metrics`,
the analysis of a single run with the same settings). This module knows no robot.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from robofmu.system.analysis import markdown_table  # noqa: E402
from robofmu.system.diagram import expand, parameter_address  # noqa: E402
from robofmu.system.experiment import SAMPLE_TIME, load  # noqa: E402
from robofmu.system.plan import described, start_values, variable_unit  # noqa: E402
from robofmu.system.plots import save_figure  # noqa: E402
from robofmu.system.roles import Roles  # noqa: E402
from robofmu.system.studies.plan import SampledLoopStudy  # noqa: E402
from robofmu.system.sweep.design import Design, parse_axis  # noqa: E402
from robofmu.system.sweep.result import SweepRun  # noqa: E402
from robofmu.system.units import printed  # noqa: E402

__all__ = ["Case", "cases", "cases_table", "design", "figure", "losses_table", "run_study", "section"]

#: The controller's parameter that switches its compensation of the losses (1 known, 0 unknown).
COMPENSATION = "loss_compensation"
DELAY = "delay_steps"


@dataclass(frozen=True)
class Case:
    """One run of the study.

    Attributes
    ----------
    sample_time : float
        The controller's sample time (s).
    delay_steps : int
        Its computation delay (samples).
    known : bool
        Whether the controller compensates the losses (``loss_compensation`` 1) or not (0).
    max_position, end_position : float
        |FK(q) - x_ref| of the task point (m): the largest over the run, and at its end.
    max_orientation, end_orientation : float or None
        The orientation error (rad), where the task has one: the largest, and at the end.
    status : str
        ``ok``, or the sweep row's failure.
    """

    sample_time: float
    delay_steps: int
    known: bool
    max_position: float
    end_position: float
    max_orientation: float | None
    end_orientation: float | None
    status: str = "ok"

    @property
    def rate(self) -> float:
        """The controller's rate (Hz)."""
        return 1.0 / self.sample_time


def design(study: SampledLoopStudy) -> Design:
    """The study's sweep: sample times x delays x the losses known (1) or not (0), the last fastest."""
    c = study.controller
    return Design(str(study.experiment), [
        parse_axis(f"{c}.{SAMPLE_TIME}=" + ",".join(f"{t!r}" for t in study.sample_times)),
        parse_axis(f"{c}.{DELAY}=" + ",".join(f"{int(d)}" for d in study.delay_steps)),
        parse_axis(f"{c}.{COMPENSATION}=1,0")])


def _float(text: str) -> float | None:
    return float(text) if text not in ("", None) else None


def cases(study: SampledLoopStudy, run: SweepRun) -> list[Case]:
    """The sweep's rows as cases, in the design's order."""
    c = study.controller
    found = []
    for row in run.rows:
        ok = row["status"] == "ok"
        found.append(Case(float(row[f"{c}.{SAMPLE_TIME}"]), int(float(row[f"{c}.{DELAY}"])),
                          float(row[f"{c}.{COMPENSATION}"]) == 1.0,
                          _float(row.get("max_tcp_error", "")) if ok else None,
                          _float(row.get("final_tcp_error", "")) if ok else None,
                          _float(row.get("max_orientation_error", "")) if ok else None,
                          _float(row.get("final_orientation_error", "")) if ok else None,
                          "ok" if ok else row["message"]))
    return found


def run_study(study: SampledLoopStudy, out: Path, fmu_dir, workers: int | None = None,
              progress: bool = True) -> tuple[SweepRun, list[Case]]:
    """Run the study's sweep into ``out`` (a new folder); its SweepRun (report and figures in
    ``out``) and cases."""
    from robofmu.system.sweep.run import run_sweep

    run = run_sweep(design(study), out, fmu_dir=fmu_dir, workers=workers, progress=progress,
                    metric="max_tcp_error")
    return run, cases(study, run)


def losses_table(study: SampledLoopStudy, fmu_dir) -> str:
    """The ``stated`` parameters per joint, as the study's experiment sets them (else the FMU's
    start values), with their units: one row per joint."""
    system = load(study.experiment, fmu_dir=fmu_dir)
    joints = Roles.of(system).model().joint_names
    columns, header = [], ["joint"]
    for name in study.stated:
        block, parameter = parameter_address(name)
        spec = system.block(block)
        md = described(system.fmu_path(spec))[1]
        variables = {v.name: v for v in md.modelVariables}
        members = expand(variables, parameter)
        given = spec.parameters.get(parameter)
        values = list(given) if isinstance(given, (list, tuple)) else \
            [start_values(md)[m] for m in members] if given is None else [given] * len(members)
        columns.append(values)
        unit = printed(variable_unit(variables[members[0]])) if members else ""
        header.append(f"{name} ({unit})" if unit else name)
    rows = [[joint, *(f"{col[j]:g}" for col in columns)] for j, joint in enumerate(joints)]
    return markdown_table(rows, header)


def _milli(value: float | None) -> str:
    return "—" if value is None else f"{value * 1e3:.3g}"


def cases_table(found: list[Case]) -> str:
    """Path and end-pose errors per case: position in mm, orientation in mrad."""
    orientation = any(c.max_orientation is not None for c in found)
    rows = []
    for c in found:
        row = [f"{c.rate:g}", f"{c.delay_steps}", "known" if c.known else "unknown",
               _milli(c.max_position), _milli(c.end_position)]
        row += [_milli(c.max_orientation), _milli(c.end_orientation)] if orientation else []
        rows.append(row if c.status == "ok" else row[:3] + [f"failed: {c.status}"] + ["—"] * (len(row) - 4))
    header = ["controller rate (Hz)", "delay (samples)", "losses to the controller", "max position error (mm)",
              "end position error (mm)"]
    header += ["max orientation error (mrad)", "end orientation error (mrad)"] if orientation else []
    return markdown_table(rows, header)


def figure(found: list[Case], path: Path, title: str) -> Path:
    """Grouped bars: per (rate, delay) the largest error over the path with the losses known and
    unknown (log scale), the end-pose error as a black tick on each bar; a panel for the position
    (mm) and one for the orientation (mrad) where the task has it."""
    groups = list(dict.fromkeys((c.sample_time, c.delay_steps) for c in found))
    panels = [("position", "max_position", "end_position", "task-point position error (mm)")]
    if any(c.max_orientation is not None for c in found):
        panels.append(("orientation", "max_orientation", "end_orientation", "orientation error (mrad)"))
    fig, axes = plt.subplots(len(panels), 1, figsize=(9, 3.4 * len(panels)), squeeze=False, sharex=True)
    width, x = 0.38, np.arange(len(groups))
    for ax, (_, peak, end, label) in zip(axes[:, 0], panels):
        for k, (known, color) in enumerate(((True, "tab:blue"), (False, "tab:red"))):
            by_group = {(c.sample_time, c.delay_steps): c for c in found if c.known == known}
            heights = [_value(by_group.get(g), peak) for g in groups]
            ends = [_value(by_group.get(g), end) for g in groups]
            where = x + (k - 0.5) * width
            ax.bar(where, heights, width, color=color, alpha=0.8,
                   label=f"losses {'known' if known else 'unknown'} to the controller")
            ax.scatter(where, ends, marker="_", s=250, color="k", zorder=3,
                       label="at the end" if k == 1 else None)
        ax.set_yscale("log")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3, axis="y", which="both")
    axes[-1, 0].set_xticks(x, [f"{1 / t:g} Hz\nd = {d}" for t, d in groups])
    axes[0, 0].set_title(title)
    axes[-1, 0].legend(fontsize=8, ncol=3, loc="upper center", bbox_to_anchor=(0.5, -0.3))
    return save_figure(fig, path)


def _value(case: Case | None, name: str) -> float:
    value = None if case is None else getattr(case, name)
    return np.nan if value is None else value * 1e3


def section(study: SampledLoopStudy, out: Path, fmu_dir, say=None) -> list[str]:
    """The demo's section: the stated losses, the sweep, its table and figure (in ``out``)."""
    if say:
        say(f"sampled loop: {study.experiment.name} over {'; '.join(a.describe() for a in design(study).axes)}")
    start = time.perf_counter()
    run, found = run_study(study, out / "sampled-loop", fmu_dir)
    made = figure(found, out / "sampled-loop.png", "The largest error over the path (bars) and at the end (ticks)")
    return [f"## {study.title}", "", study.text, "",
            f"The joint losses of the study (`{study.experiment.name}`; the controller's model states the same "
            "numbers and compensates them or not):", "", losses_table(study, fmu_dir), "",
            cases_table(found), "",
            f"{len(found)} runs as one sweep in {time.perf_counter() - start:.0f} s ({run.workers} workers): "
            "[report](sampled-loop/report.md), [sweep.csv](sampled-loop/sweep.csv).", "",
            f"![sampled loop]({made.name})", ""]

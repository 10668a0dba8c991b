"""Run a named experiment end to end: co-simulation, results.csv, figures and a short report."""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from pathlib import Path

from . import analysis, experiment, plots
from .master import Master, Result
from .roles import Roles


def progress_printer(label: str, stream=sys.stderr):
    """A ``progress(fraction, t)`` callback printing one updating line."""
    start = time.perf_counter()

    tty = stream.isatty()

    def show(fraction: float, t: float) -> None:
        if not tty and fraction < 1.0 and round(fraction * 20) % 5:
            return                     # in a log: a line every 25 %
        elapsed = time.perf_counter() - start
        end = "\r" if tty and fraction < 1.0 else "\n"
        stream.write(f"  {label}: {fraction * 100:5.1f}%  t = {t:7.3f} s  ({elapsed:5.1f} s){end}")
        stream.flush()

    return show


@dataclass
class Run:
    name: str
    result: Result
    roles: Roles
    metrics: analysis.Tracking
    section: str
    figures: list[Path]


def figures_of(system, result: Result, roles: Roles, out: Path, order: list[str]) -> list[Path]:
    """The figures of one run: block diagram, references, tracking, efforts."""
    made = [plots.block_diagram(system, out / "block_diagram.png", order)]
    if roles.x_ref:
        made.append(plots.task_reference(result, roles, out / "task_reference.png"))
    made += [plots.joint_reference(result, roles, out / "joint_reference.png"),
             plots.tracking(result, roles, out / "tracking.png", system.name),
             plots.efforts(result, roles, out / "efforts.png", system.name)]
    return made


def run_experiment(name: str, out_dir: str | Path, fmu_dir: str | Path = "fmus", step: float | None = None,
                   stop_time: float | None = None, algorithm: str | None = None, progress: bool = True,
                   figures: bool = True) -> Run:
    """Run experiment ``name`` and write ``out_dir/results.csv``, its figures and ``report.md``.

    On a failure the results recorded so far are in ``results.csv`` and SimulationError is raised.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    system = experiment.load(name, fmu_dir=fmu_dir)
    roles = Roles.of(system)
    master = Master(system, progress=progress_printer(system.name) if progress else None)
    for w in master.check():
        print(f"warning: {w}", file=sys.stderr)
    result = master.run(stop_time=stop_time, step=step, algorithm=algorithm, csv_path=out / "results.csv")
    metrics = analysis.tracking(result, roles)
    section = analysis.tracking_report(system.name, system.description, metrics, result)
    made = figures_of(system, result, roles, out, master.order) if figures else []
    (out / "report.md").write_text(f"# {system.name}\n\n" + section + "\n\n"
                                   + "\n".join(f"![{p.stem}]({p.name})" for p in made) + "\n")
    return Run(system.name, result, roles, metrics, section, made)

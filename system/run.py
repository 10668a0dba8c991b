"""Run a named experiment end to end: co-simulation, results.csv, figures and a short report.

``robofmu run`` checks everything it can before the first FMU is instantiated, and refuses a
mistake with a :class:`UsageError` (a ValueError) in one line naming the option, file or key:

- the experiment (:func:`robofmu.system.experiment.load`: the file and the key);
- the FMU folder (``--fmus``): missing, an FMU missing, or built from other robofmu sources
  than this process runs (each says ``robofmu build``);
- the diagram (:func:`robofmu.system.check.plan`) and the roles the analysis needs;
- ``--step-size`` / ``--stop-time``: finite and > 0, the stop time a whole number of steps, and
  the recording ((n + 1) rows x (signals + 1) x 8 bytes) within half the available memory;
- ``--out``: a folder that can be created, or replaced
  (:class:`~robofmu.system.usage.OutputFolder`).

The output folder is replaced whole (:mod:`robofmu.system.usage`). A run that fails or is
interrupted (Ctrl-C) is swapped in too: ``results.csv`` with the points recorded so far and a
``report.md`` saying where it stopped.
"""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from pathlib import Path

from robofmu.system import analysis, experiment
from robofmu.system.diagram import System
from robofmu.system.master import DiagramError, Interrupted, Master, Result, SimulationError
from robofmu.system.roles import Roles, check_roles
from robofmu.system.usage import OutputFolder, UsageError, check_fmu_folder, check_times, times_given, timing

__all__ = ["Run", "figures_of", "progress_printer", "run_experiment"]


def progress_printer(label: str, stream=sys.stderr):
    """A ``progress(fraction, t)`` callback printing one updating line."""
    start = time.perf_counter()

    tty = stream.isatty()

    def show(fraction: float, t: float) -> None:
        if not tty and fraction < 1.0 and round(fraction * 20) % 5 and round(fraction * 20) != 1:
            return                     # in a log: a line at 5 % (it runs), then every 25 %
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
    """The figures of one run: block diagram, references, tracking, efforts (where the run has a
    ``tau`` role), the task coordinates (where it has an ``x`` role), a pose task's path and
    errors (where it has ``x_ref`` and ``quat_ref`` roles), the mechanism at several
    instants (where the robot's model draws itself) and the iterations of an iterative solver
    where the run recorded some."""
    from robofmu.system import plots

    made = [plots.block_diagram(system, out / "block_diagram.png", order)]
    if roles.x_ref:
        made.append(plots.task_reference(result, roles, out / "task_reference.png"))
    made += [plots.joint_reference(result, roles, out / "joint_reference.png"),
             plots.tracking(result, roles, out / "tracking.png", system.name)]
    if roles.tau:
        made.append(plots.efforts(result, roles, out / "efforts.png", system.name))
    if roles.x:
        made.append(plots.pose(result, roles, out / "pose.png", system.name))
    if roles.quat_ref and roles.x_ref:
        made.append(plots.tool_pose(result, roles, out / "tool_pose.png", system.name))
    drawing = plots.mechanism(result, roles, out / "mechanism.png", system.name)
    if drawing is not None:                        # a model that draws itself (sketch)
        made.append(drawing)
    solver = plots.iterations({system.name: result}, out / "iterations.png", system.name)
    if solver is not None:                         # an iterative solver's recorded diagnostics
        made.append(solver)
    return made


def _check_memory(system: System, master: Master, n: int, step: float | None, stop_time: float | None) -> None:
    """Refuse (UsageError) a run whose recording would not fit in memory (:meth:`Master.memory_problem`)."""
    problem = master.memory_problem(n)
    if problem:
        raise UsageError(f"{times_given(system, step, stop_time)}: {problem}; use a larger --step-size or a "
                         "shorter --stop-time")


def _short_report(name: str, text: str) -> str:
    return f"# {name}\n\n{text}\n"


def run_experiment(name: str, out_dir: str | Path, fmu_dir: str | Path = "fmus", step: float | None = None,
                   stop_time: float | None = None, algorithm: str | None = None, progress: bool = True,
                   figures: bool = True, parameters: dict | None = None, results_format: str = "csv") -> Run:
    """Run experiment ``name`` and write ``out_dir/results.csv``, its figures and ``report.md``.

    Everything is checked before the first FMU is instantiated (see the module notes); the
    outputs are written in a temporary sibling folder and replace ``out_dir`` whole at the end.

    Parameters
    ----------
    name : str
        A packaged experiment or an experiment file.
    out_dir : str or Path
        The output folder (created, or replaced whole; see :class:`OutputFolder`).
    fmu_dir : str or Path
        The FMU folder.
    step, stop_time : float, optional
        Communication step and stop time (s); default the experiment's.
    algorithm : {"gauss-seidel", "jacobi"}, optional
    progress : bool
        Print progress lines to stderr.
    figures : bool
        Write the figures.
    parameters : dict, optional
        Block parameters to set over the experiment's, ``{"controller.kp": 400.0}``
        (``robofmu run --set``).
    results_format : {"csv", "parquet"}
        ``results.csv`` (default) or ``results.parquet`` (binary, exact, with units; for large
        runs: about 30x faster to write).

    Returns
    -------
    Run

    Raises
    ------
    ValueError
        A mistake, before anything runs: :class:`UsageError`, ExperimentError or DiagramError,
        each one line naming the option, file or key.
    Interrupted
        Ctrl-C (SIGINT, or a KeyboardInterrupt: in a block's code, a callback) during the
        co-simulation: ``out_dir`` holds ``results.csv`` with the points recorded so far and a
        short report; the exception's ``result`` holds them too.
    SimulationError
        The run failed: ``out_dir`` holds ``results.csv`` with the points recorded so far and a
        short report naming the failure.
    """
    check_times(step, stop_time)
    if results_format not in ("csv", "parquet"):
        raise UsageError(f"--format {results_format}: choose csv or parquet")
    results = f"results.{results_format}"
    folder = OutputFolder(out_dir)
    system = experiment.load(name, fmu_dir=fmu_dir)
    if parameters:
        try:
            system = experiment.with_parameters(system, parameters)
        except ValueError as exc:
            raise UsageError(f"--set {exc}") from None
    h, stop, n = timing(system, step, stop_time)
    check_fmu_folder(system)
    master = Master(system, progress=progress_printer(system.name) if progress else None)
    try:
        warnings = master.check()
    except DiagramError as exc:
        raise DiagramError(str(system.source or system.name), exc.problems) from None
    roles = check_roles(system, master)
    _check_memory(system, master, n, step, stop_time)
    for w in warnings:
        print(f"warning: {w}", file=sys.stderr)
    out = folder.open()
    final = folder.path if folder.given.is_absolute() else folder.given
    try:
        try:
            result = master.run(stop_time=stop, step=h, algorithm=algorithm)
        except SimulationError as exc:
            kept = exc.result
            if kept is None or not len(kept.time):      # nothing recorded: the folder stays as it was
                folder.discard()
                raise type(exc)(f"{exc.reason} (nothing recorded; {final} untouched)", exc.block, exc.time, kept,
                                exc.reason) from None
            kept.write(out / results)
            points = f"{results} holds the {len(kept.time)} points up to t = {kept.time[-1]:.9g} s"
            if isinstance(exc, Interrupted):
                how = "" if "KeyboardInterrupt" in exc.reason else " (SIGINT)"
                text = f"Interrupted{how} {exc.reason.removeprefix('interrupted ')}; {points}; no figures."
            else:
                text = f"The run failed: {' '.join(exc.reason.split())}\n\n{points}; no figures."
            (out / "report.md").write_text(_short_report(system.name, text))
            folder.commit()
            where = (f"; results up to t = {kept.time[-1]:.9g} s in {final / results} "
                     f"(report: {final / 'report.md'})")
            raise type(exc)(exc.reason + where, exc.block, exc.time, kept, exc.reason) from None
        try:
            result.write(out / results)
        except KeyboardInterrupt:      # the file may be cut short: not swapped in; the result is on the exception
            folder.discard()
            reason = "interrupted while writing the complete results"
            raise Interrupted(f"{reason}; {final} untouched (the exception's result holds them)", None,
                              float(result.time[-1]), result, reason) from None
        try:
            metrics = analysis.tracking_metrics(result, roles)
            section = analysis.tracking_report(system.name, system.description, metrics, result)
            made = figures_of(system, result, roles, out, master.order) if figures else []
        except KeyboardInterrupt:
            (out / "report.md").write_text(_short_report(
                system.name, f"The run is complete ({results}, {len(result.time)} points); interrupted "
                             "(SIGINT) while writing the report and figures."))
            folder.commit()
            raise Interrupted(f"interrupted while writing the report and figures; the complete results are "
                              f"in {final / results}", None, float(result.time[-1]), result,
                              "interrupted while writing the report and figures") from None
        (out / "report.md").write_text(f"# {system.name}\n\n" + section + "\n\n"
                                       + "\n".join(f"![{p.stem}]({p.name})" for p in made) + "\n")
        folder.commit()
    except BaseException:
        folder.discard()               # nothing written yet, or already committed
        raise
    made = [final / p.name for p in made]
    return Run(system.name, result, roles, metrics, section, made)

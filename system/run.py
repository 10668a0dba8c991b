"""Run a named experiment end to end: co-simulation, results.csv, figures and a short report.

``robofmu run`` checks everything it can before the first FMU is instantiated, and refuses a
mistake with a :class:`UsageError` (a ValueError) in one line naming the option, file or key:

- the experiment (:func:`robofmu.system.experiment.load`: the file and the key);
- the FMU folder (``--fmus``): missing, an FMU missing, or built from other robofmu sources
  than this process runs (each says ``robofmu build``);
- ``--step-size`` / ``--stop-time``: finite and > 0, the stop time a whole number of steps
  (:func:`robofmu.system.usage.timing`);
- the run's plan, in one pass (:func:`robofmu.system.plan.plan` through :meth:`Master.check`):
  the diagram, each block's sample time a whole multiple of the base step, and the recording
  ((n + 1) rows x (signals + 1) x 8 bytes) within half the available memory; then the roles the
  analysis needs;
- ``--out``: a folder that can be created, or replaced
  (:class:`~robofmu.system.usage.OutputFolder`).

The output folder is replaced whole (:mod:`robofmu.system.usage`). A run that fails or is
interrupted (Ctrl-C) is swapped in too: ``results.csv`` with the points recorded so far and a
``report.md`` saying where it stopped.

**What the FMUs said.** Every warning and error the FMUs log is kept with the communication
point it arrived at (:attr:`Master.heard`) and grouped with the excursions the record shows
(:func:`robofmu.system.result.group_messages`: an IK's ``status`` other than 0, a ``reachable``
or ``within_limits`` that is false). ``report.md`` begins with them (:func:`said_section`, with
the joints the record shows beyond their limits: :func:`robofmu.system.analysis.limit_excursions`),
``run.log`` holds every message, one per line, and :attr:`Run.troubles` says in a few words what
was not respected (the summary line, ``robofmu run --strict``). A ``--set`` of a trajectory or IK
parameter repeats the build's reference check first (:func:`reference_check`).
"""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from pathlib import Path

from robofmu.system import analysis, defaults, experiment
from robofmu.system.diagram import System, parameter_address
from robofmu.system.master import DiagramError, Interrupted, Master, Result, SimulationError
from robofmu.system.roles import Roles, check_roles
from robofmu.system.usage import OutputFolder, UsageError, check_fmu_folder, times_given, timing

__all__ = ["Run", "figures_of", "progress_printer", "reference_check", "run_experiment", "said_section",
           "summary_line"]


def progress_printer(label: str, stream=None):
    """A ``progress(fraction, t)`` callback printing one updating line (on ``stream``, default the
    ``sys.stderr`` of the moment it is made, not of the moment this module was imported)."""
    start = time.perf_counter()
    stream = sys.stderr if stream is None else stream

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
    """A finished run of :func:`run_experiment`.

    Attributes
    ----------
    name : str
    result : Result
        Its ``messages`` are what the FMUs said, grouped.
    roles : Roles
    metrics : Tracking
    section : str
        The report's tracking section (markdown).
    figures : list of Path
    said : list of str
        The lines of the report's "What the FMUs said" ([] where nothing was said): the
        message groups, then the joints the record shows beyond their limits.
    troubles : list of str
        What the run did not respect, a few words each (the FMUs' messages, an IK's status,
        a joint beyond its limits, a refused reference check); [] for a clean run.
    """

    name: str
    result: Result
    roles: Roles
    metrics: analysis.Tracking
    section: str
    figures: list[Path]
    said: list[str]
    troubles: list[str]


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


def _short_report(name: str, text: str, said: list[str] | None = None) -> str:
    return f"# {name}\n\n" + (said_section(said) if said else "") + f"{text}\n"


def said_section(said: list[str]) -> str:
    """The report's first section (markdown): "What the FMUs said", one item per line of ``said``
    (:attr:`Run.said`), or that they said nothing."""
    items = "\n".join(f"- {line}" for line in said) if said else \
        "Nothing: no warning or error, every health output recorded stayed fine, every joint within its limits."
    return f"## What the FMUs said\n\n{items}\n\nEvery message, one per line: [run.log](run.log).\n\n"


def summary_line(name: str, result: Result, troubles: list[str]) -> str:
    """``ur5-pose: done, 3000 steps to t = 3 s in 2.9 s`` and, where the run did not respect
    something, `` — WARNING: `` and :attr:`Run.troubles`."""
    steps = len(result.time) - 1
    line = (f"{name}: done, {steps} step{'' if steps == 1 else 's'} to t = {result.time[-1]:g} s "
            f"in {result.info.get('wall_time', float('nan')):.1f} s")
    return line + (" — WARNING: " + "; ".join(troubles) if troubles else "")


def _run_log(result: Result | None) -> str:
    return "".join(f"{message}\n" for message in (result.log if result is not None else []))


def reference_check(system: System, master: Master, parameters: dict, step: float) -> str | None:
    """The build's reference check (:func:`robofmu.components.preflight.check_reference`)
    repeated where ``parameters`` (``--set``) change a trajectory or IK block of the experiment's
    robot: the robot's description with those blocks' parameters as the run sets them
    (the experiment's, then ``parameters``), sampled at ``step`` (s).

    Returns
    -------
    str or None
        The check's refusal (the joint, the limit, the time); None where it passes or nothing
        was changed that it checks (or it cannot check: a robot it cannot read, a value it
        cannot place).
    """
    from dataclasses import replace

    from robofmu.components.blocks import make_block
    from robofmu.components.preflight import ReferenceRefused, check_reference
    from robofmu.components.robots import load_description
    from robofmu.components.robots.description import PROFILE_PREFIX, Choice
    from robofmu.system.fmu import block_identity

    robot = system.extra.get("robot")
    touched = {parameter_address(name)[0] for name in parameters}
    kinds = {}
    for name in master.order:
        try:
            identity = block_identity(master.nodes[name].path)
        except ValueError:
            continue
        if identity["kind"] in ("trajectory", "ik") and identity["robot"]:
            kinds[name] = identity
    if not robot or not touched & set(kinds):
        return None
    try:
        description = load_description(robot)
        for name, identity in kinds.items():
            table = identity["kind"]
            profile = identity.get("profile", "")
            _, _, described = description.block_of(f"{PROFILE_PREFIX}{profile}" if profile else table)
            choice = getattr(described, table)
            if choice is None:
                continue
            block = make_block(described, table)
            declared = {v.name for v in block.variables if v.causality == "parameter"}
            given = dict(choice.parameters)
            for key, value in master.nodes[name].spec.parameters.items():
                if isinstance(value, str):
                    continue
                base, bracket, rest = key.partition("[")
                size = sum(1 for v in declared if v.startswith(base + "["))
                if bracket:
                    current = given.get(base)
                    if not isinstance(current, (list, tuple)) or len(current) != size:
                        current = [block.get(f"{base}[{k + 1}]") for k in range(size)]
                    current = list(current)
                    current[int(rest[:-1]) - 1] = value
                    given[base] = current
                elif size:
                    given[base] = [value] * size
                elif key in declared:
                    given[key] = value
            description = replace(description, **{table: Choice(choice.kind, given)})
        check_reference(description, step)
    except ReferenceRefused as exc:
        return str(exc)
    except (ValueError, KeyError, IndexError):
        return None
    return None


def _settings_at_fault(parameters: dict, problems: list[str]) -> str:
    """The ``--set`` entries the plan's problems are all about (``plant.q00=1``), or "" where a
    problem is the experiment file's own: a mistake is told where the user made it."""
    def about(problem: str, name: str) -> bool:
        block, parameter = parameter_address(name)
        return problem.startswith(f"block {block!r}: ") and (repr(parameter) in problem
                                                              or problem.startswith(f"block {block!r}: {parameter} ="))

    if not parameters or not all(any(about(p, name) for name in parameters) for p in problems):
        return ""
    return ", ".join(f"{name}={value:g}" if isinstance(value, float) else f"{name}={value}"
                     for name, value in parameters.items() if any(about(p, name) for p in problems))


def run_experiment(name: str, out_dir: str | Path, fmu_dir: str | Path = defaults.FMU_FOLDER, step: float | None = None,
                   stop_time: float | None = None, algorithm: str | None = None, progress: bool = True,
                   figures: bool = True, parameters: dict | None = None, results_format: str = "csv",
                   debug: bool = False) -> Run:
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
    debug : bool
        Keep the FMUs' debug messages (a failure's traceback, ...) in ``run.log`` too
        (:class:`Master`'s ``debug``); by default their warnings and errors only.

    Returns
    -------
    Run
        With what the FMUs said (:attr:`Run.said`, also first in ``report.md`` and whole in
        ``run.log``) and what the run did not respect (:attr:`Run.troubles`).

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
    run_times = timing(system, step, stop_time)
    check_fmu_folder(system)
    master = Master(system, progress=progress_printer(system.name) if progress else None, debug=debug)
    try:
        warnings = master.check(run_times)
    except DiagramError as exc:
        given = _settings_at_fault(parameters or {}, exc.problems)
        raise DiagramError(f"--set {given}" if given else str(system.source or system.name), exc.problems) from None
    roles = check_roles(system, master)
    if master.plan.memory:
        raise UsageError(f"{times_given(system, step, stop_time)}: {master.plan.memory}; use a larger --step-size "
                         "or a shorter --stop-time")
    for w in warnings:
        print(f"warning: {w}", file=sys.stderr)
    refused = reference_check(system, master, parameters, run_times.step) if parameters else None
    if refused:
        settings = ", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in parameters.items())
        print(f"warning: --set {settings}: the build's reference check refuses the reference: {refused}",
              file=sys.stderr)
    out = folder.open()
    final = folder.path if folder.given.is_absolute() else folder.given
    try:
        try:
            result = master.run(algorithm=algorithm)
        except SimulationError as exc:
            kept = exc.result
            if kept is None or not len(kept.time):      # nothing recorded: the folder stays as it was
                folder.discard()
                raise type(exc)(f"{exc.reason} (nothing recorded; {final} untouched)", exc.block, exc.time, kept,
                                exc.reason) from None
            kept.write(out / results)
            if kept.log:
                (out / "run.log").write_text(_run_log(kept))
            points = f"{results} holds the {len(kept.time)} points up to t = {kept.time[-1]:.9g} s"
            if isinstance(exc, Interrupted):
                how = "" if "KeyboardInterrupt" in exc.reason else " (SIGINT)"
                text = f"Interrupted{how} {exc.reason.removeprefix('interrupted ')}; {points}; no figures."
            else:
                text = f"The run failed: {' '.join(exc.reason.split())}\n\n{points}; no figures."
            (out / "report.md").write_text(_short_report(system.name, text, [str(g) for g in kept.messages]))
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
        (out / "run.log").write_text(_run_log(result))
        excursions = analysis.limit_excursions(result, roles)
        said = [str(g) for g in result.messages] + [line for line, _ in excursions]
        troubles = ([g.short() for g in result.messages] + [words for _, words in excursions]
                    + (["the build's reference check refuses the --set reference"] if refused else []))
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
        (out / "report.md").write_text(f"# {system.name}\n\n" + said_section(said) + section + "\n\n"
                                       + "\n".join(f"![{p.stem}]({p.name})" for p in made) + "\n")
        folder.commit()
    except BaseException:
        folder.discard()               # nothing written yet, or already committed
        raise
    made = [final / p.name for p in made]
    return Run(system.name, result, roles, metrics, section, made, said, troubles)

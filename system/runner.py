"""Run a named experiment end to end: co-simulation, results.csv, figures and a short report.

``robofmu run`` checks everything it can before the first FMU is instantiated, and refuses a
mistake with a :class:`UsageError` (a ValueError) in one line naming the option, file or key:

- the experiment (:func:`robofmu.system.experiment.load`: the file and the key);
- the FMU folder (``--fmus``): missing, an FMU missing, or built from other robofmu sources
  than this process runs (each says ``robofmu build``);
- the diagram (:func:`robofmu.system.check.plan`) and the roles the analysis needs;
- ``--step`` / ``--stop``: finite and > 0, the stop time a whole number of steps, and the
  recording ((n + 1) rows x (signals + 1) x 8 bytes) within half the available memory;
- ``--out``: a folder that can be created, or replaced (:class:`OutputFolder`).

**Output folders are replaced whole.** The run writes into a temporary sibling folder
(``.<name>.robofmu-XXXX`` beside ``--out``) and swaps it in for ``--out`` at the end, so the
folder then holds this run's outputs only, never an earlier run's figures beside new results;
until the swap an earlier run's results stay intact. A run that fails or is interrupted (Ctrl-C)
is swapped in too: ``results.csv`` with the points recorded so far and a ``report.md`` saying
where it stopped. So that no one's files are deleted, an existing folder is replaced only if it
holds nothing but what a run writes (``results.csv``, ``report.md``, ``*.png``), and never the
current folder or one containing it.
"""
from __future__ import annotations

import math
import os
import shutil
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from . import analysis, experiment
from .diagram import System, expand
from .master import DiagramError, Interrupted, Master, Result, SimulationError, step_count
from .roles import Roles

__all__ = ["OutputFolder", "Run", "UsageError", "check_fmu_folder", "check_roles", "check_times", "check_writable",
           "figures_of", "progress_printer", "run_experiment", "timing"]

#: The roles the analysis of a run reads (``tau`` too where the diagram has efforts: an
#: unactuated run, whose plant's efforts are unwired at their start values, declares none).
NEEDED_ROLES = ("q", "q_ref")


class UsageError(ValueError):
    """A mistake in what ``robofmu`` was asked to do; the message is one line naming the option,
    file or key."""


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
    ``tau`` role), the task coordinates (where it has an ``x`` role), the mechanism at several
    instants (where the robot's model draws itself) and the iterations of an iterative solver
    where the run recorded some."""
    from . import plots

    made = [plots.block_diagram(system, out / "block_diagram.png", order)]
    if roles.x_ref:
        made.append(plots.task_reference(result, roles, out / "task_reference.png"))
    made += [plots.joint_reference(result, roles, out / "joint_reference.png"),
             plots.tracking(result, roles, out / "tracking.png", system.name)]
    if roles.tau:
        made.append(plots.efforts(result, roles, out / "efforts.png", system.name))
    if roles.x:
        made.append(plots.pose(result, roles, out / "pose.png", system.name))
    drawing = plots.mechanism(result, roles, out / "mechanism.png", system.name)
    if drawing is not None:                        # a model that draws itself (sketch)
        made.append(drawing)
    solver = plots.iterations({system.name: result}, out / "iterations.png", system.name)
    if solver is not None:                         # an iterative solver's recorded diagnostics
        made.append(solver)
    return made


# -- the output folder -----------------------------------------------------------------------------
def is_run_output(entry: Path) -> bool:
    """Whether ``entry`` (in an output folder) is something ``robofmu run`` writes."""
    return entry.is_file() and (entry.name in ("results.csv", "results.parquet", "report.md")
                                or entry.suffix == ".png")


class OutputFolder:
    """An output folder that is replaced whole: written in a temporary sibling, swapped in at the end.

    The constructor checks the folder (:class:`UsageError` naming ``option``): not a file, not
    the current folder nor one containing it, creatable (a missing parent is fine) or, if it
    exists, holding only entries ``owned`` accepts (and ``mark`` where given), with write
    permission where the swap needs it.

    Parameters
    ----------
    path : str or Path
        The folder (``--out``); a symbolic link is followed.
    option : str
        The option or argument named in messages.
    owned : callable
        ``owned(entry) -> bool``: whether an existing entry was written by the command (default
        :func:`is_run_output`).
    mark : tuple of (str, str), optional
        ``(file, text)``: an existing non-empty folder must hold ``file`` containing ``text``.
    """

    def __init__(self, path: str | Path, option: str = "--out", owned: Callable[[Path], bool] = is_run_output,
                 mark: tuple[str, str] | None = None):
        self.given = Path(path)
        self.option = option
        self.path = Path(os.path.realpath(self.given))
        self.staging: Path | None = None
        self._check(owned, mark)

    def _problem(self, text: str) -> UsageError:
        return UsageError(f"{self.option} {self.given}: {text}")

    def _check(self, owned, mark) -> None:
        path = self.path
        cwd = Path.cwd().resolve()
        if path == cwd or path in cwd.parents:
            raise self._problem("is the current folder or contains it; give a folder for the results")
        if path.exists():
            if not path.is_dir():
                raise self._problem("exists and is a file, not a folder")
            try:
                entries = sorted(path.iterdir())
            except OSError as exc:
                raise self._problem(f"cannot read it: {exc.strerror}") from None
            foreign = [e.name for e in entries if not owned(e)]
            if entries and mark is not None:
                marked = path / mark[0]
                try:
                    found = marked.is_file() and mark[1] in marked.read_text(errors="replace")
                except OSError:
                    found = False
                if not found:
                    foreign = foreign or [e.name for e in entries[:3]]
            if foreign:
                shown = ", ".join(foreign[:3]) + (f" and {len(foreign) - 3} more" if len(foreign) > 3 else "")
                raise self._problem(f"holds {shown}, not written by robofmu; the folder would be replaced "
                                    "whole: give an empty folder, a new one, or an earlier results folder")
            for folder in (path, path.parent):
                if not os.access(folder, os.W_OK | os.X_OK):
                    raise self._problem(f"cannot replace it: no write permission in {folder}")
            return
        check_writable(self.given, self.option)

    def open(self) -> Path:
        """Create the parents and the temporary sibling folder; returns it (UsageError if that fails)."""
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.staging = Path(tempfile.mkdtemp(prefix=f".{self.path.name}.robofmu-", dir=self.path.parent))
        except OSError as exc:
            raise self._problem(f"cannot write there: {exc.strerror or exc}") from None
        return self.staging

    def commit(self) -> Path:
        """Swap the written folder in for :attr:`path` (the earlier folder is deleted); returns the path."""
        staging, path = self.staging, self.path
        if staging is None:
            raise RuntimeError("OutputFolder.commit before open")
        if path.is_dir():
            mode = path.stat().st_mode & 0o7777
        else:
            umask = os.umask(0)
            os.umask(umask)
            mode = 0o777 & ~umask
        os.chmod(staging, mode)                 # mkdtemp makes it 0o700
        old = None
        if path.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{path.name}.old-", dir=path.parent))
            os.rmdir(old)
            os.rename(path, old)
        try:
            os.rename(staging, path)
        except OSError:
            if old is not None:
                os.rename(old, path)
            raise
        self.staging = None
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
        return path

    def discard(self) -> None:
        """Delete the temporary folder; :attr:`path` stays as it was."""
        if self.staging is not None:
            shutil.rmtree(self.staging, ignore_errors=True)
            self.staging = None


# -- checks before a run ---------------------------------------------------------------------------
def check_writable(path: str | Path, option: str, file: bool = False) -> None:
    """Refuse (:class:`UsageError` naming ``option``) a folder (or with ``file``, a file) that
    cannot be written: a file where a folder is needed (or a folder where a file is), a parent
    that is a file, no write permission. Missing parents are fine (they will be created)."""
    given = Path(path)
    path = Path(os.path.realpath(given))
    if path.exists():
        if file and path.is_dir():
            raise UsageError(f"{option} {given}: is a folder; give a file name")
        if not file and not path.is_dir():
            raise UsageError(f"{option} {given}: exists and is a file, not a folder")
        if not os.access(path, os.W_OK | (0 if file else os.X_OK)):
            raise UsageError(f"{option} {given}: no write permission")
        return
    ancestor = path.parent
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise UsageError(f"{option} {given}: {ancestor} is a file, not a folder")
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise UsageError(f"{option} {given}: cannot create it: no write permission in {ancestor}")


def check_times(step: float | None, stop_time: float | None) -> None:
    """Refuse (:class:`UsageError`) a ``--step`` or ``--stop`` that is not a finite time > 0 s."""
    for option, value in (("--step", step), ("--stop", stop_time)):
        if value is not None and not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise UsageError(f"{option} {value:g}: must be a finite time > 0 s")


def check_fmu_folder(system: System, option: str = "--fmus") -> None:
    """Refuse (:class:`UsageError`) a missing FMU folder, missing FMUs, or robofmu FMUs built from
    other sources than this process runs; each message says how to build them."""
    from robofmu.components import SOURCE_HASH

    folder = system.fmu_dir
    robot = system.extra.get("robot")
    build = f"robofmu build{' ' + robot if isinstance(robot, str) else ''} --out {folder}"
    relative = [spec for spec in system.blocks if not Path(spec.fmu).is_absolute()]
    if relative and not folder.is_dir():
        if folder.exists():
            raise UsageError(f"{option} {folder}: is a file, not the folder of the FMUs")
        raise UsageError(f"{option} {folder}: no such folder; build the FMUs: robofmu build --out {folder}")
    missing = [spec for spec in system.blocks if not system.fmu_path(spec).is_file()]
    if missing:
        names = ", ".join(str(spec.fmu) for spec in missing)
        where = f"{option} {folder}" if all(spec in relative for spec in missing) else "FMU"
        raise UsageError(f"{where}: no {names} (for {system.source or system.name}); build them: {build}")
    from .replica import block_identity

    stale = []
    for spec in system.blocks:
        try:
            identity = block_identity(system.fmu_path(spec))
        except Exception:              # not a robofmu block, or not a valid FMU: the plan names it
            continue
        if identity.get("source") != SOURCE_HASH:
            stale.append(str(spec.fmu))
    if stale:
        raise UsageError(f"{option} {folder}: {', '.join(stale)} built from other robofmu sources than this "
                         f"one runs; rebuild: {build}")


def check_roles(system: System, master: Master) -> Roles:
    """The roles, checked against the planned outputs (UsageError naming the file and key)."""
    source = system.source or system.name
    if not system.extra.get("robot"):
        raise UsageError(f"{source}: robot: missing key: `robofmu run` needs the experiment's robot "
                         "(its analysis uses the robot's model)")
    roles = Roles.of(system)
    missing = [r for r in NEEDED_ROLES if getattr(roles, r) is None]
    if missing:
        raise UsageError(f"{source}: roles: `robofmu run` needs the roles {', '.join(NEEDED_ROLES)}; "
                         f"missing: {', '.join(missing)}")
    for role in experiment.ROLES:
        signal = getattr(roles, role)
        if signal is None:
            continue
        block, _, base = signal.partition(".")
        node = master.nodes.get(block)
        if node is None:
            raise UsageError(f"{source}: roles.{role}: {signal!r} names no block "
                             f"(blocks: {', '.join(master.nodes)})")
        outputs = [name for name, v in node.variables.items() if v.causality == "output"]
        if not expand(outputs, base):
            bases = sorted({name.split("[")[0] for name in outputs})
            raise UsageError(f"{source}: roles.{role}: {signal!r} names no output of {block} "
                             f"(outputs: {', '.join(bases)})")
    return roles


def timing(system: System, step: float | None, stop_time: float | None) -> tuple[float, float, int]:
    """The step, stop time and number of steps of the run, checked (UsageError naming --step /
    --stop or the file)."""
    check_times(step, stop_time)
    source = system.source or system.name
    h = system.step if step is None else float(step)
    stop = system.stop_time if stop_time is None else float(stop_time)
    stop_text = f"--stop {stop:g} s" if stop_time is not None else f"the stop time {stop:g} s (stop_time in {source})"
    step_text = f"--step {h:g} s" if step is not None else f"{h:g} s (the step in {source}; or give --step)"
    given = ", ".join(f"{option} {value:g}" for option, value in (("--step", step), ("--stop", stop_time))
                      if value is not None) or str(source)
    ratio = stop / h
    if not ratio <= 1e15:
        raise UsageError(f"{given}: {ratio:.3g} steps, far more than memory can record; use a larger --step "
                         "or a shorter --stop")
    if round(ratio) < 1:
        raise UsageError(f"{stop_text} is shorter than one step of {step_text}")
    try:
        n = step_count(0.0, stop, h)
    except ValueError:
        hint = " (give --stop too)" if step is not None and stop_time is None else ""
        raise UsageError(f"{stop_text} is not a whole number of steps of {step_text}{hint}") from None
    return h, stop, n


def _check_memory(system: System, master: Master, n: int, step: float | None, stop_time: float | None) -> None:
    """Refuse (UsageError) a run whose recording would not fit in memory (:meth:`Master.memory_problem`)."""
    problem = master.memory_problem(n)
    if problem:
        given = ", ".join(f"{option} {value:g}" for option, value in (("--step", step), ("--stop", stop_time))
                          if value is not None) or str(system.source or system.name)
        raise UsageError(f"{given}: {problem}; use a larger --step or a shorter --stop")


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
            metrics = analysis.tracking(result, roles)
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

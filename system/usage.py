"""What every ``robofmu`` command checks before it runs, and the rules of its output folder.

A mistake is refused with a :class:`UsageError` (a ValueError) in one line naming the option,
file or key, before the first FMU is instantiated:

- the FMU folder (``--fmus``): missing, an FMU missing, or built from other robofmu sources
  than this process runs (each says ``robofmu build``);
- ``--step-size`` / ``--stop-time``: finite and > 0, the stop time a whole number of steps;
- ``--out``: a folder (or file) that can be created, or replaced (:class:`OutputFolder`), tried
  by creating a file there (root may write where permissions say no, and nobody in /proc);
- a count the user gives (samples, grid points, steps): its memory, before it is allocated
  (:func:`check_memory`: at most half the memory available, the rule ``robofmu run`` applies).

**Files are written atomically** (:func:`atomic_file`): into a temporary sibling
``.<name>.<random>.partial``, renamed over the file at the end, so an interrupted or failed write
leaves the earlier file or none. An existing file is replaced only if it is an output of the
same kind (:func:`check_replaceable`): ``robofmu ssp --out notes.txt`` never overwrites the notes.

**Output folders are replaced whole.** A command writes into a temporary sibling folder
(``.<name>.robofmu-XXXX`` beside ``--out``) and swaps it in for ``--out`` at the end, so the
folder then holds this command's outputs only, never an earlier run's figures beside new
results; until the swap the earlier outputs stay intact. So that no one's files are deleted, an
existing folder is replaced only if it holds nothing but what the command writes
(:data:`OUTPUTS`), and never the current folder or one containing it.
"""
from __future__ import annotations

import fnmatch
import math
import os
import shutil
import tempfile
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

from robofmu.system.plan import Times, times
from robofmu.system.diagram import System

__all__ = ["OUTPUTS", "PARTIAL", "OutputFolder", "Outputs", "UsageError", "atomic_file", "check_fmu_folder",
           "check_memory", "check_replaceable", "check_times", "check_writable", "default_out", "export_experiment",
           "one_line", "owned_by", "say", "stopped", "times_given", "timing"]

#: How the temporary sibling of a file being written ends (:func:`atomic_file`).
PARTIAL = ".partial"


@dataclass(frozen=True)
class Outputs:
    """What a command writes into its output folder.

    Attributes
    ----------
    files : tuple of str
        File name patterns (``fnmatch``: ``"*.png"``).
    folders : tuple of str
        Folder name patterns.
    """
    files: tuple[str, ...]
    folders: tuple[str, ...] = ()

    def owns(self, entry: Path) -> bool:
        """Whether ``entry`` (in an output folder) is something the command writes."""
        patterns = self.folders if entry.is_dir() else self.files if entry.is_file() else ()
        return any(fnmatch.fnmatchcase(entry.name, pattern) for pattern in patterns)


#: The outputs of each command that writes a folder: the one statement of which existing folders
#: it may replace (``run``, ``workspace``, ``convergence``, ``osp``, ``demo``) or continue (``sweep``).
OUTPUTS = {
    "run": Outputs(("results.csv", "results.parquet", "report.md", "run.log", "*.png")),
    "sweep": Outputs(("sweep.json", "sweep.csv", "sweep.csv.tmp", "sweep.parquet", "sweep.parquet.tmp",
                      "report.md", "*.png", f".*{PARTIAL}"), folders=("runs",)),
    "workspace": Outputs(("*.md", "*.png")),
    "convergence": Outputs(("convergence.md", "convergence.png", "convergence.json")),
    "osp": Outputs(("OspSystemStructure.xml", "*.fmu")),
    "demo": Outputs(("*.md", "*.png", "*.csv"), folders=("*",)),
}


def owned_by(command: str, entry: Path) -> bool:
    """Whether ``entry`` of an existing output folder is something ``robofmu <command>`` writes."""
    return OUTPUTS[command].owns(entry)


class UsageError(ValueError):
    """A mistake in what ``robofmu`` was asked to do; the message is one line naming the option,
    file or key."""


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
    owned : str or callable
        The command whose :data:`OUTPUTS` an existing entry must be (default ``"run"``), or
        ``owned(entry) -> bool``.
    mark : tuple of (str, str), optional
        ``(file, text)``: an existing non-empty folder must hold ``file`` containing ``text``.
    """

    def __init__(self, path: str | Path, option: str = "--out", owned: Callable[[Path], bool] | str = "run",
                 mark: tuple[str, str] | None = None):
        self.given = Path(path)
        self.option = option
        self.path = Path(os.path.realpath(self.given))
        self.staging: Path | None = None
        self._check(owned if callable(owned) else OUTPUTS[owned].owns, mark)

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
        os.chmod(staging, _kept_mode(path, 0o777))      # mkdtemp makes it 0o700
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


def check_writable(path: str | Path, option: str, file: bool = False) -> None:
    """Refuse (:class:`UsageError` naming ``option``) a folder (or with ``file``, a file) that
    cannot be written: a file where a folder is needed (or a folder where a file is), a parent
    that is a file, a name too long, no write permission, or a place where no file can be created
    (tried: :func:`_probe`). Missing parents are fine (they will be created)."""
    given = Path(path)
    path = Path(os.path.realpath(given))
    if path.exists():
        if file and path.is_dir():
            raise UsageError(f"{option} {given}: is a folder; give a file name")
        if not file and not path.is_dir():
            raise UsageError(f"{option} {given}: exists and is a file, not a folder")
        if not os.access(path, os.W_OK | (0 if file else os.X_OK)):
            raise UsageError(f"{option} {given}: no write permission")
        problem = _probe(path.parent if file else path)
        if problem:
            raise UsageError(f"{option} {given}: cannot write there: {problem}")
        return
    ancestor = path.parent
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise UsageError(f"{option} {given}: {ancestor} is a file, not a folder")
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise UsageError(f"{option} {given}: cannot create it: no write permission in {ancestor}")
    try:
        longest = os.pathconf(ancestor, "PC_NAME_MAX")
    except (OSError, ValueError):
        longest = 255
    if any(len(os.fsencode(part)) > longest for part in path.relative_to(ancestor).parts):
        raise UsageError(f"{option} {given}: a name in it is longer than {longest} bytes")
    problem = _probe(ancestor)
    if problem:
        raise UsageError(f"{option} {given}: cannot create it in {ancestor}: {problem}")


def _probe(folder: Path) -> str | None:
    """Why no file can be created in ``folder`` (an existing folder), or None: creates and deletes
    one (``os.access`` answers yes to root on a read-only file system or in /proc)."""
    try:
        fd, name = tempfile.mkstemp(dir=folder, prefix=".robofmu-probe.", suffix=PARTIAL)
    except OSError as exc:
        return exc.strerror or str(exc)
    os.close(fd)
    os.unlink(name)
    return None



def _kept_mode(path: Path, full: int) -> int:
    """The permission bits a replacement of ``path`` gets: those of what is there, else ``full``
    less the umask (what a plain open or mkdir would give)."""
    if path.exists():
        return path.stat().st_mode & 0o7777
    umask = os.umask(0)
    os.umask(umask)
    return full & ~umask

@contextmanager
def atomic_file(path: str | Path) -> Iterator[Path]:
    """Write a file atomically: yields a temporary sibling ``.<name>.<random>.partial`` (created
    empty, in the same folder: parents are created) to write to, renamed over ``path`` when the
    block ends; on any exception (Ctrl-C too) it is deleted, so ``path`` stays as it was or absent.

    A symbolic link at ``path`` is followed: its target is replaced. The file gets the mode of
    the file it replaces, else the one a new file gets (0666 less the umask).
    """
    path = Path(os.path.realpath(path))
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=PARTIAL)
    os.close(fd)
    partial = Path(name)
    try:
        yield partial
        os.chmod(partial, _kept_mode(path, 0o666))      # mkstemp makes it 0o600
        os.replace(partial, path)
    finally:
        partial.unlink(missing_ok=True)


def check_replaceable(path: str | Path, option: str, owned: Callable[[Path], bool], what: str) -> None:
    """Refuse (:class:`UsageError` naming ``option`` and the file) to replace an existing file
    that is not an output of the same kind: ``owned(path)`` says whether it is (``what`` names
    the kind in the message: ``"an SSP package robofmu wrote"``)."""
    given = Path(path)
    path = Path(os.path.realpath(given))
    if not path.is_file():
        return
    try:
        mine = owned(path)
    except Exception:                  # not a zip, unreadable: not ours
        mine = False
    if not mine:
        raise UsageError(f"{option} {given}: exists and is not {what}; it is not replaced: give a new file name "
                         "or remove it first")


def check_memory(need: int, where: str, fix: str) -> None:
    """Refuse (:class:`UsageError`) an allocation of ``need`` bytes that would take more than half
    the memory available (:func:`robofmu.system.plan.memory_shortfall`), the rule ``robofmu run``
    applies to its recording; the message names ``where`` (the option or file and key) and says
    what to do (``fix``)."""
    from robofmu.system.plan import memory_shortfall

    shortfall = memory_shortfall(need)
    if shortfall is not None:
        raise UsageError(f"{where}: needs {shortfall}; {fix}")


def check_times(step: float | None, stop_time: float | None) -> None:
    """Refuse (:class:`UsageError`) a ``--step-size`` or ``--stop-time`` that is not a finite time > 0 s."""
    for option, value in (("--step-size", step), ("--stop-time", stop_time)):
        if value is not None and not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise UsageError(f"{option} {value:g}: must be a finite time > 0 s")


def check_fmu_folder(system: System, option: str = "--fmus") -> None:
    """Refuse (:class:`UsageError`) a missing FMU folder, missing FMUs, or robofmu FMUs that are
    stale for this run (:func:`robofmu.system.fmu.stale_reasons`): built from other code than
    this process runs, or carrying other data of the experiment's robot than its description
    now holds (a FMU built before a robofmu version change, its code the same, runs as built).
    Each message says how to build them."""
    from robofmu.components.robots import is_robot_file, load_description

    folder = system.fmu_dir
    robot = system.extra.get("robot")
    build = f"robofmu build{' ' + robot if isinstance(robot, str) else ''} --out {folder}"
    relative = [spec for spec in system.blocks if not Path(spec.fmu).is_absolute()]
    if relative and not folder.is_dir():
        if folder.exists():
            raise UsageError(f"{option} {folder}: is a file, not the folder of the FMUs")
        # every package robot's FMUs, or those of a robot TOML of one's own (not among them)
        everything = build if isinstance(robot, str) and is_robot_file(robot) else f"robofmu build --out {folder}"
        raise UsageError(f"{option} {folder}: no such folder; build the FMUs: {everything}")
    missing = [spec for spec in system.blocks if not system.fmu_path(spec).is_file()]
    if missing:
        names = ", ".join(str(spec.fmu) for spec in missing)
        where = f"{option} {folder}" if all(spec in relative for spec in missing) else "FMU"
        raise UsageError(f"{where}: no {names} (for {system.source or system.name}); build them: {build}")
    from robofmu.system.fmu import block_identity, stale_reasons

    try:
        description = load_description(robot) if isinstance(robot, str) else None
    except ValueError:
        description = None
    code, data = [], []
    for spec in system.blocks:
        path = system.fmu_path(spec)
        try:
            identity = block_identity(path)
        except Exception:              # not a robofmu block, or not a valid FMU: the plan names it
            continue
        mine = description if description is not None and identity.get("robot") == description.name else None
        reasons = stale_reasons(path, mine)
        if "code changed" in reasons:
            code.append(str(spec.fmu))
        elif "robot data changed" in reasons:
            data.append(str(spec.fmu))
    if code:
        raise UsageError(f"{option} {folder}: {', '.join(code)} built from other robofmu sources than this "
                         f"one runs; rebuild: {build}")
    if data:
        raise UsageError(f"{option} {folder}: {', '.join(data)} built from other data of robot "
                         f"{description.name!r} than {description.path} holds now; rebuild: {build}")


def times_given(system: System, step: float | None, stop_time: float | None) -> str:
    """What a message about the run's length names: the options given (``--step-size 0.001,
    --stop-time 40``), else the experiment file."""
    return ", ".join(f"{option} {value:g}" for option, value in (("--step-size", step), ("--stop-time", stop_time))
                     if value is not None) or str(system.source or system.name)


def timing(system: System, step: float | None, stop_time: float | None) -> Times:
    """The run's times (:func:`robofmu.system.plan.times`, the one check), each value named as
    the option that gave it or as the experiment file's key (UsageError, one line)."""
    check_times(step, stop_time)
    source = system.source or system.name

    def named(key: str, value: float, given: bool) -> str:
        if key == "stop_time":
            return f"--stop-time {value:g} s" if given else f"the stop time {value:g} s (stop_time in {source})"
        if key == "step":
            return f"--step-size {value:g} s" if given else f"{value:g} s (the step in {source}; or give --step-size)"
        return f"the start time {value:g} s"

    try:
        return times(system, 0.0, stop_time, step, named)
    except ValueError as exc:
        text = str(exc)
        if "far more than memory" in text:
            text += "; use a larger --step-size or a shorter --stop-time"
        elif "whole number of steps" in text and step is not None and stop_time is None:
            text += " (give --stop-time too)"
        raise UsageError(text) from None


# -- one-line answers ------------------------------------------------------------------------------
def one_line(exc: BaseException) -> str:
    """An exception's message on one line (a DiagramError's problems joined by '; ')."""
    problems = getattr(exc, "problems", None)
    if problems:
        head = str(exc).split("\n", 1)[0]
        return " ".join(f"{head} {'; '.join(problems)}".split())
    return " ".join(str(exc).split())


def say(command: str, exc_or_text) -> None:
    """Print ``robofmu <command>: <message>`` on stderr, on one line."""
    import sys

    text = exc_or_text if isinstance(exc_or_text, str) else one_line(exc_or_text)
    print(f"robofmu {command}: {text}", file=sys.stderr)


def stopped(command: str, exc: BaseException, after: str = "") -> int:
    """Say on one line why ``command`` stopped (``after`` appended) and return its exit status:
    130 interrupted (Ctrl-C: a run's Interrupted, a sweep's SweepInterrupted), 1 a run that failed
    (SimulationError), 2 a user's mistake (ValueError: usage, experiment, diagram, design; a
    scheduler that cannot be reached)."""
    from robofmu.system.master import Interrupted, SimulationError

    say(command, f"{one_line(exc)}{after}")
    if isinstance(exc, (Interrupted, KeyboardInterrupt)):
        return 130
    return 1 if isinstance(exc, SimulationError) else 2


def default_out(experiment: str, suffix: str = "") -> Path:
    """``results/<experiment name><suffix>``: where a command writes without ``--out``."""
    from robofmu.system import defaults

    name = Path(experiment).stem if experiment.endswith(".toml") else experiment
    return Path(defaults.RESULTS_FOLDER) / f"{name}{suffix}"


def export_experiment(command: str, experiment: str, out: str | None, fmu_dir, suffix: str, write,
                      owned: Callable[[Path], bool], what: str) -> int:
    """Load ``experiment``, check the output file and the FMU folder, then ``write(system, path)``;
    print the path written and return the exit status. The one shape of ``robofmu ssp`` and
    ``robofmu container``.

    An existing output file is replaced only where ``owned(path)`` says it is an output of this
    kind (``what``: :func:`check_replaceable`). A file that cannot be written is a mistake in
    what was asked (exit status 2), as every refusal before anything is written.
    """
    from robofmu.system.experiment import load

    given = out
    option = "--out" if given else "the default output"
    try:
        system = load(experiment, fmu_dir=fmu_dir)
        out = Path(given or f"{system.name}{suffix}")
        check_writable(out, option, file=True)
        check_replaceable(out, option, owned, what)
        check_fmu_folder(system)
        written = write(system, out)
    except ValueError as exc:          # UsageError, ExperimentError, DiagramError, a tool's refusal
        return stopped(command, exc)
    except OSError as exc:
        say(command, f"{option} {out}: cannot write it: {exc.strerror or exc}")
        return 2
    print(written)
    return 0

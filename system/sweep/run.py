"""``robofmu sweep``: many runs of one experiment on Dask, written as they finish, with figures.

Everything that can be checked is checked before a worker starts, and refused in one line
(:class:`~robofmu.system.usage.UsageError` or the error of the file at fault): the design
(:mod:`~robofmu.system.sweep.design`), the experiment, the FMU folder, each varied block and
parameter (planned with the first run's values; every value typed against the FMU's variable),
each varied step size (the stop time a whole number of its steps), the output folder.

The output folder is kept, not replaced: it holds what ``OUTPUTS["sweep"]`` of
:mod:`robofmu.system.usage` lists, ``sweep.json`` (the design), ``sweep.csv`` (one row per
finished run, appended as runs finish), and at the end ``sweep.parquet``, the figures and
``report.md``. A rerun of the same design into the same folder skips the runs
already recorded (``retry_failed`` runs the failed ones again); a folder holding another sweep,
or files robofmu did not write, is refused. Ctrl-C stops the sweep: every finished row stays,
the Parquet file and a report of the finished rows are written, and :class:`SweepInterrupted`
says how to continue.
"""
from __future__ import annotations

import os
import time
from contextlib import ExitStack
from dataclasses import replace
from pathlib import Path

from robofmu.system import defaults, experiment
from robofmu.system.plan import plan, variable_unit
from robofmu.components.unknown_names import nearest
from robofmu.system.diagram import bases, coerce, expand
from robofmu.system.master import DiagramError, Master
from robofmu.system.roles import check_roles
from robofmu.system.sweep.design import STEP_SIZE_AXIS, Design
from robofmu.system.options import finite
from robofmu.system.sweep.engine import BYTES_PER_WORKER, SweepProgress, cluster_client, default_workers, execute, \
    probe_scheduler
from robofmu.system.sweep.journal import Journal, key_of
from robofmu.system.sweep.metrics import METRIC_UNITS, metric_names
from robofmu.system.sweep.report import write_report
from robofmu.system.sweep.result import SweepRun
from robofmu.system.sweep.worker import block_settings
from robofmu.system.usage import UsageError, check_fmu_folder, check_memory, check_times, check_writable, owned_by, timing

__all__ = ["SweepInterrupted", "SweepRun", "check", "run_sweep"]


class SweepInterrupted(KeyboardInterrupt):
    """Ctrl-C during a sweep: the message says how many rows were kept and how to continue."""


def _folder(out: Path, design: Design) -> bool:
    """Check the output folder; True if it holds this design's earlier rows."""
    entries = list(out.iterdir()) if out.is_dir() else []
    if not entries:
        check_writable(out, "--out")
        return False
    marker = out / "sweep.json"
    foreign = [e.name for e in entries if not owned_by("sweep", e)]
    if foreign or not marker.is_file():
        shown = ", ".join(sorted(foreign or [e.name for e in entries])[:3])
        raise UsageError(f"--out {out}: holds {shown}, not a robofmu sweep; give an empty folder, a new one, "
                         "or the folder of this same sweep to continue it")
    try:
        earlier = Design.from_json(marker.read_text())
    except (ValueError, KeyError, TypeError):
        raise UsageError(f"--out {out}: sweep.json cannot be read; give another folder") from None
    if not earlier.same_as(design):
        raise UsageError(f"--out {out}: holds another sweep ({earlier.experiment}: "
                         f"{'; '.join(a.describe() for a in earlier.axes)}); give another folder, or the same "
                         "experiment and --vary / --samples / --seed / --step-size / --stop-time to continue it")
    check_writable(out, "--out")
    return True


def _check_sample_times(system, base, axis, steps, stop_time) -> None:
    """Refuse (UsageError naming ``--vary``) a varied sample time that is no number > 0, or no
    whole multiple of a step the sweep runs at (the plan's one rule: :meth:`Plan.timed` of the
    experiment's plan ``base`` with that sample time)."""
    if axis.random:
        raise UsageError(f"--vary {axis.name}: a sample time is varied over a grid only (a comma list or a range)")
    for value in axis.values:
        try:
            configured = experiment.with_parameters(system, {axis.name: value})
        except ValueError as exc:
            raise UsageError(f"--vary {exc}") from None
        for h in steps:
            try:
                replace(base, system=configured).timed(timing(system, h, stop_time))
            except DiagramError as exc:
                raise UsageError(f"--vary {axis.name}={value:g}: {'; '.join(exc.problems)}") from None


def check(design: Design, fmu_dir):
    """The experiment's System (FMU paths absolute), checked against the design; its Roles,
    metric columns, units and the design's runs with typed values."""
    check_times(design.step, design.stop_time)
    system = experiment.load(design.experiment, fmu_dir=fmu_dir)
    system.fmu_dir = Path(os.path.abspath(system.fmu_dir))
    steps = next((a.values for a in design.axes if a.name == STEP_SIZE_AXIS), ())
    if any(a.name == STEP_SIZE_AXIS and a.random for a in design.axes):
        raise UsageError(f"--vary {STEP_SIZE_AXIS}: the step is varied over a grid only (a comma list or a range)")
    for h in steps or [design.step]:
        try:
            timing(system, h, design.stop_time)
        except UsageError as exc:
            raise UsageError(f"--vary {STEP_SIZE_AXIS}={h:g}: {exc}" if steps else str(exc)) from None
    check_fmu_folder(system)
    names = [b.name for b in system.blocks]
    for axis in design.axes:
        if axis.name != STEP_SIZE_AXIS and axis.block not in names:
            raise UsageError(f"--vary {axis.name}: no block {axis.block!r} in {system.name} "
                             f"(blocks: {', '.join(names)})")
    runs = design.runs()
    try:
        base = plan(system)
    except DiagramError as exc:
        raise DiagramError(str(system.source or system.name), exc.problems) from None
    units, kinds = {STEP_SIZE_AXIS: "s"}, {}
    for axis in design.axes:
        if axis.name == STEP_SIZE_AXIS:
            continue
        if axis.parameter == experiment.SAMPLE_TIME:
            leader = next((a for a in design.axes if a.name == axis.follows), axis)
            _check_sample_times(system, base, replace(leader, name=axis.name), steps or [design.step], design.stop_time)
            kinds[axis.name], units[axis.name] = "Real", "s"
            continue
        node = base.nodes[axis.block]
        variables = [node.variables[v] for v in expand(node.variables, axis.parameter)]
        if not variables:
            parameters = bases(n for n, v in node.variables.items() if v.causality == "parameter")
            raise UsageError(f"--vary {axis.name}: unknown parameter {axis.parameter!r} of block {axis.block!r} "
                             f"({node.path.name}){nearest(axis.parameter, parameters)}")
        if any(v.causality != "parameter" for v in variables):
            raise UsageError(f"--vary {axis.name}: {axis.parameter!r} of {axis.block} is not a parameter")
        kinds[axis.name] = variables[0].type
        if variable_unit(variables[0]):
            units[axis.name] = variable_unit(variables[0])
    master = Master(experiment.with_parameters(system, block_settings(system, runs[0])))
    try:
        master.check(timing(system, (steps or [design.step])[0], design.stop_time))
    except DiagramError as exc:
        raise DiagramError(f"{system.source or system.name} with --vary", exc.problems) from None
    roles = check_roles(system, master)
    try:
        typed = [{k: (v if k == STEP_SIZE_AXIS else coerce(kinds[k], v, f"--vary {k}")) for k, v in run.items()}
                 for run in runs]
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    metrics = metric_names(roles, roles.model())
    units.update({name: unit for name, unit in METRIC_UNITS.items() if name in metrics})
    return system, roles, metrics, units, typed


def run_sweep(design: Design, out: str | Path, fmu_dir: str | Path = defaults.FMU_FOLDER, workers: int | None = None,
              scheduler: str | None = None, keep_results: bool = False, retry_failed: bool = False,
              progress: bool = True, figures: bool = True, metric: str | None = None,
              threshold: float | None = None) -> SweepRun:
    """Run every run of ``design`` not yet in ``out`` and write sweep.csv, Parquet, figures, report.

    Parameters
    ----------
    design : Design
    out : str or Path
        The sweep folder (created; continued if it holds this design's earlier rows).
    fmu_dir : str or Path
        The FMU folder.
    workers : int, optional
        Local worker processes (default: the cores of this machine, at most one per run).
    scheduler : str, optional
        Address of an existing Dask scheduler (``tcp://host:8786``): run there instead.
    keep_results : bool
        Keep each run's ``results.csv`` under ``out/runs/run-NNNNN/``.
    retry_failed : bool
        Run the failed rows of an earlier invocation again (refused where ``out`` holds no earlier
        run of this design: there is nothing to retry).
    progress : bool
        Print a progress line to stderr.
    figures : bool
        Write the figures and the report's figure links.
    metric : str, optional
        The metric the figures map (default ``max_tcp_error`` where there is one, else
        ``max_joint_error``).
    threshold : float, optional
        The level of ``metric`` drawn as a contour (default 1 mm for ``max_tcp_error``).

    Raises
    ------
    ValueError
        A mistake, before anything runs (UsageError, DesignError, ExperimentError, DiagramError).
    ConnectionError
        ``scheduler`` cannot be reached: at once where the connection is refused
        (:func:`~robofmu.system.sweep.engine.probe_scheduler`), else after Dask's timeout.
    SweepInterrupted
        Ctrl-C: the finished rows are kept (sweep.csv, sweep.parquet, report.md).
    """
    if workers is not None and workers < 1:
        raise UsageError(f"--workers {workers}: must be at least 1")
    if workers is not None:
        check_memory(workers * BYTES_PER_WORKER, f"--workers {workers}", "give fewer workers (each is a process)")
    finite("--threshold", threshold)
    if scheduler:
        probe_scheduler(scheduler)           # a refused connection at once, not after Dask's timeout
    out = Path(out)
    continuing = _folder(out, design)
    if retry_failed and not continuing:
        raise UsageError(f"--retry-failed: --out {out} holds no earlier run of this sweep, so nothing failed to "
                         "retry; run it without --retry-failed")
    system, roles, metrics, units, runs = check(design, fmu_dir)
    if metric is not None and metric not in metrics:
        raise UsageError(f"--metric {metric}: not a metric of this sweep (metrics: {', '.join(metrics[:4])}, ...)")
    with ExitStack() as stack:
        client = stack.enter_context(cluster_client(None, scheduler)) if scheduler else None
        out.mkdir(parents=True, exist_ok=True)
        (out / "sweep.json").write_text(design.to_json())
        try:
            journal = Journal(out, design.names, metrics)
        except ValueError as exc:
            raise UsageError(f"--out {out}: {exc}") from None
        if retry_failed:
            journal.forget_failed()
        keys = [key_of(run, design.names) for run in runs]
        reused = sum(k in journal.rows for k in keys) if continuing else 0
        pending = [(i, run) for i, (run, k) in enumerate(zip(runs, keys)) if k not in journal.rows]
        keep = None
        if keep_results:
            keep = (out / "runs").resolve()
            keep.mkdir(exist_ok=True)
        count = None if scheduler else min(workers or default_workers(), max(1, len(pending)))
        reused_failed = sum(journal.rows[k]["status"] != "ok" for k in keys if k in journal.rows)
        meter = SweepProgress(system.name, len(runs), reused, reused_failed) if progress else None
        start = time.perf_counter()

        def arrived(index, record):
            row = journal.append(record)
            if meter:
                meter.update(row["status"])

        interrupted = False
        try:
            if pending:
                if client is None:
                    client = stack.enter_context(cluster_client(count))
                if meter:
                    where = f"the cluster at {scheduler}" if scheduler else \
                        f"{count} local worker process" + "es" * (count != 1)
                    meter.stream.write(f"  {system.name}: {len(pending)} runs on {where}\n")
                execute(client, system, pending, design.stop_time, design.step, keep, arrived,
                        tag=f"{os.getpid()}-{int(time.time() * 1e3)}")
        except KeyboardInterrupt:
            interrupted = True
    seconds = time.perf_counter() - start
    rows = journal.finish(keys)
    widths = {name: len(value) for name, value in block_settings(system, runs[0]).items() if isinstance(value, list)}
    result = SweepRun(design, out, rows, metrics, len(rows) - reused, reused, seconds, count, [], units,
                      system.name, system.description, widths)
    write_report(result, figures=figures and not interrupted, metric=metric, threshold=threshold,
                 interrupted=interrupted)
    if interrupted:
        raise SweepInterrupted(f"interrupted: {len(rows)} of {len(runs)} runs are in {out / 'sweep.csv'}; "
                               "run the same command again to finish the rest")
    return result

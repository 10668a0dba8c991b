"""Running the runs of a sweep on Dask: a local cluster by default, or an existing one by address.

The embedded default is a :class:`distributed.LocalCluster` of ``workers`` single-threaded
worker processes on this machine, started for the sweep and stopped after it. With
``scheduler`` the same runs go to an existing Dask cluster (its workers need robofmu installed
and the FMUs at the same path). Each worker process runs many co-simulations one after the
other (:func:`robofmu.system.sweep.worker.run_one`); only the small records come back.

A worker process that dies (a crash, a kill) loses the run it was executing: the scheduler
runs it again elsewhere, once (``distributed.scheduler.allowed-failures`` is 1 on the local
cluster); a run whose worker dies twice becomes a failed row. Records are handed to
``on_record`` as they arrive, in completion order.
"""
from __future__ import annotations

import logging
import os
import sys
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Callable

from robofmu.system.interrupt import sigint_flag

__all__ = ["BYTES_PER_WORKER", "PRELOAD", "SweepProgress", "cluster_client", "default_workers", "execute", "probe_scheduler"]

#: The module a worker preloads (it ignores SIGINT: Ctrl-C is the client's to handle).
PRELOAD = "robofmu.system.sweep.worker"
#: Memory a local worker process holds, in bytes (bounded above): the interpreter, NumPy,
#: Pinocchio, Dask and a run's FMUs (a run's child process peaks at about 150 MB, measured).
BYTES_PER_WORKER = 256 << 20


def default_workers() -> int:
    """The cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def probe_scheduler(scheduler: str, timeout: float = 1.0) -> None:
    """Refuse at once a scheduler address nothing listens at: a TCP connection to it that is
    refused (as at a closed local port) fails in microseconds, whereas Dask waits for its whole
    connect timeout. A host that does not answer within ``timeout`` s is left to Dask's timeout.

    Raises
    ------
    ConnectionError
        The connection is refused, or the host cannot be resolved (the message names the
        address); ValueError (naming ``--scheduler``): an address with no port.
    """
    import socket

    from distributed.comm.addressing import parse_address, parse_host_port

    protocol, location = parse_address(scheduler)
    if protocol not in ("tcp", "tls"):
        return
    try:
        host, port = parse_host_port(location)
    except ValueError as exc:
        raise ValueError(f"--scheduler {scheduler}: {exc}; e.g. tcp://host:8786") from None
    try:
        socket.create_connection((host, port), timeout=timeout).close()
    except (ConnectionRefusedError, socket.gaierror) as exc:
        raise ConnectionError(f"--scheduler {scheduler}: cannot connect: {exc.strerror or exc}; is a Dask "
                              "scheduler running there?") from None
    except OSError:                    # silent (a timeout) or unreachable: Dask's timeout decides
        return


@contextmanager
def cluster_client(workers: int | None = None, scheduler: str | None = None, timeout: float = 10.0):
    """A Dask client: of a new local cluster (``workers`` processes) or connected to ``scheduler``.

    Raises
    ------
    ConnectionError
        ``scheduler`` cannot be reached within ``timeout`` s (the message names the address).
    """
    import dask
    from distributed import Client, LocalCluster

    if scheduler is not None:
        try:
            client = Client(scheduler, timeout=timeout)
        except (OSError, TimeoutError) as exc:
            raise ConnectionError(f"--scheduler {scheduler}: cannot connect: {' '.join(str(exc).split())}") from None
        try:
            yield client
        finally:
            client.close()
        return
    local = {"distributed.scheduler.allowed-failures": 1,          # a run whose worker dies: retried once
             "distributed.worker.preload": [PRELOAD],
             "distributed.worker.daemon": False,
             # the workers' event loops wake less often: their thread takes the GIL from the run's
             "distributed.worker.profile.enabled": False,
             "distributed.admin.tick.interval": "500ms", "distributed.admin.tick.limit": "30s",
             "distributed.admin.system-monitor.interval": "2s",
             "distributed.admin.system-monitor.gil.enabled": False,
             "distributed.worker.memory.monitor-interval": "1s",
             "distributed.scheduler.work-stealing": False}          # equal runs: the queue balances them
    with _without_fmu_bundles():          # the workers (and any restarted one) inherit sys.path
        with dask.config.set(local):
            cluster = LocalCluster(n_workers=workers or default_workers(), threads_per_worker=1, processes=True,
                                   dashboard_address=None, silence_logs=logging.ERROR)
        client = Client(cluster)
        try:
            yield client
        finally:
            client.close()
            cluster.close()


@contextmanager
def _without_fmu_bundles():
    """``sys.path`` without the folders of FMUs instantiated in this process, while it lasts.

    pythonfmu puts a FMU's resources folder on ``sys.path``; that folder holds a copy of
    ``robofmu/components`` without the package's robots. A process that multiprocessing starts
    gets its parent's ``sys.path`` and imports ``robofmu`` anew, from the first folder that has it:
    a worker started after a FMU ran in this process would read robots from the FMU's copy and
    know none ("unknown robot"). This process has imported its own robofmu already."""
    import robofmu.components

    own = Path(robofmu.components.__file__).resolve().parent
    saved = list(sys.path)
    sys.path[:] = [p for p in saved if not ((Path(p or ".") / "robofmu" / "components").is_dir()
                                             and (Path(p or ".") / "robofmu" / "components").resolve() != own)]
    try:
        yield
    finally:
        sys.path[:] = saved


class SweepProgress:
    """One updating line: runs done and failed of the total, and the estimated time left."""

    def __init__(self, label: str, total: int, skipped: int = 0, skipped_failed: int = 0, stream=sys.stderr):
        self.label, self.total, self.skipped, self.stream = label, total, skipped, stream
        self.done, self.failed = skipped, skipped_failed       # rows an earlier invocation finished
        self.start = time.perf_counter()
        self.tty = stream.isatty()
        self.shown = -1.0

    def line(self) -> str:
        elapsed = time.perf_counter() - self.start
        now = self.done - self.skipped                    # finished in this invocation
        left = elapsed / now * (self.total - self.done) if now else float("nan")
        eta = "" if self.done == self.total else \
            f", {_duration(left)} left" if now else ", estimating the time left"
        reused = f" ({self.skipped} reused)" if self.skipped else ""
        return (f"  {self.label}: {self.done}/{self.total} runs{reused}, {self.failed} failed, "
                f"{_duration(elapsed)}{eta}")

    def update(self, status: str | None = None) -> None:
        if status is not None:
            self.done += 1
            self.failed += status != "ok"
        fraction = self.done / self.total if self.total else 1.0
        last = self.done == self.total
        if not self.tty and not last and fraction - self.shown < 0.1 and self.shown >= 0:
            return                                  # in a log: a line every tenth of the runs
        self.shown = fraction
        self.stream.write(self.line() + ("\r" if self.tty and not last else "\n"))
        self.stream.flush()


def _duration(seconds: float) -> str:
    if seconds != seconds:
        return "?"
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.1f} h"


def execute(client, system, runs: list[tuple[int, dict]], stop_time, step, keep_folder,
            on_record: Callable[[int, dict], None], tag: str) -> None:
    """Submit every ``(index, values)`` run and hand each record to ``on_record`` as it arrives.

    A run whose task fails without a record (its worker died twice: KilledWorker) becomes a
    failed record naming that. KeyboardInterrupt cancels the runs not finished and propagates;
    a Ctrl-C whose KeyboardInterrupt some library code swallowed still stops the sweep at the
    next record (the SIGINT handler also sets a flag, checked after every record).
    """
    with sigint_flag(raise_interrupt=True) as interrupted:
        _execute(client, system, runs, stop_time, step, keep_folder, on_record, tag, interrupted)


def _execute(client, system, runs, stop_time, step, keep_folder, on_record, tag, interrupted) -> None:
    from distributed import as_completed

    from robofmu.system.sweep.worker import run_one

    futures = {}
    for index, values in runs:
        keep = None if keep_folder is None else str(keep_folder / f"run-{index:05d}")
        future = client.submit(run_one, system, values, stop_time, step, keep, key=f"robofmu-{tag}-{index}",
                               pure=False)
        futures[future] = (index, values)
    try:
        for future in as_completed(list(futures)):
            index, values = futures.pop(future)
            if future.status == "finished":
                record = future.result()
            else:
                exc = future.exception()
                died = type(exc).__name__ == "KilledWorker"
                reason = ("its worker process died twice while running it (crash or kill); it was retried once"
                          if died else " ".join(f"{type(exc).__name__}: {exc}".split()))
                record = dict(values, status="failed", message=reason)
            future.release()
            on_record(index, record)
            if interrupted[0]:
                raise KeyboardInterrupt
    except BaseException:
        client.cancel(list(futures), force=True)
        raise

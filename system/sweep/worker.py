"""One run of a sweep, as a Dask worker executes it: co-simulate, analyse, return a small record.

:func:`run_one` never raises for a run that fails: the record says ``status = "failed"`` and
the message names the block, the variable and the time (the master's
:class:`~robofmu.system.master.SimulationError`). A run that completes says ``status = "ok"``;
its message is what the FMUs said, grouped (:attr:`~robofmu.system.result.Result.messages`,
joined by `` | ``), empty when they said nothing. Runs in one process are serialised by a lock:
all pythonfmu FMUs of a process share its one interpreter, so a worker started with several
threads still runs one co-simulation at a time (start workers with ``--nthreads 1``).
"""
from __future__ import annotations

import logging
import threading
import time
from pathlib import Path

from robofmu.system import analysis
from robofmu.system.diagram import parameter_address
from robofmu.system.experiment import SAMPLE_TIME, spread_over_elements, with_parameters
from robofmu.system.master import Master, SimulationError
from robofmu.system.roles import Roles
from robofmu.system.sweep.design import STEP_SIZE_AXIS
from robofmu.system.sweep.metrics import metrics_of

__all__ = ["block_settings", "run_one", "simulate"]

_ONE_RUN_AT_A_TIME = threading.Lock()


def block_settings(system, values: dict) -> dict:
    """A run's ``values`` as the experiment's override takes them
    (:func:`~robofmu.system.experiment.with_parameters`): the step size left out, and one number
    for a vector parameter (``plant.friction``: every joint's) spread over its elements
    (:func:`~robofmu.system.experiment.spread_over_elements`, as ``with_parameters`` does).

    Parameters
    ----------
    system : System
        The experiment (its FMUs are read for the vectors' lengths).
    values : dict
        ``BLOCK.PARAM`` (and :data:`~robofmu.system.sweep.design.STEP_SIZE_AXIS`) -> value.
    """
    settings = {}
    for name, value in values.items():
        if name == STEP_SIZE_AXIS:
            continue
        block, parameter = parameter_address(name)
        settings[name] = value if parameter == SAMPLE_TIME else spread_over_elements(system, block, parameter, value)
    return settings


def simulate(system, values: dict, stop_time: float | None, step: float | None, everything: bool = False):
    """Run ``system`` with the varied ``values`` set (:func:`block_settings`); returns (Result, Roles, Tracking).

    ``values`` maps ``BLOCK.PARAM`` (and :data:`~robofmu.system.sweep.design.STEP_SIZE_AXIS`) to a value.
    Only the signals the metrics read (the experiment's roles) are recorded, unless
    ``everything``; the values are the same either way (reading an output changes nothing).
    Raises what :meth:`Master.run` raises (SimulationError with the points recorded so far).
    """
    step = values.get(STEP_SIZE_AXIS, step)
    configured = with_parameters(system, block_settings(system, values))
    roles = Roles.of(configured)
    master = Master(configured, record=None if everything else roles.signals())
    result = master.run(stop_time=stop_time, step=step)        # planned against this run's step
    return result, roles, analysis.tracking_metrics(result, roles)


def run_one(system, values: dict, stop_time: float | None, step: float | None,
            keep: str | None = None) -> dict:
    """The record of one run: ``values``, the metrics, ``wall_time`` (s), ``status``, ``message``
    (a failure, or what the FMUs of a completed run said).

    Parameters
    ----------
    system : System
        The experiment's diagram (FMU paths absolute, reachable from this worker).
    values : dict
        The varied quantities of this run.
    stop_time, step : float or None
        Timing (s); None: the experiment's (a varied step size takes precedence).
    keep : str, optional
        A folder to write this run's ``results.csv`` in (also the points before a failure).
    """
    start = time.perf_counter()
    record = dict(values)
    with _ONE_RUN_AT_A_TIME:
        try:
            result, roles, tracking = simulate(system, values, stop_time, step, everything=bool(keep))
        except SimulationError as exc:
            if keep and exc.result is not None and len(exc.result.time):
                exc.result.to_csv(Path(keep) / "results.csv")
            record.update(status="failed", message=" ".join(str(exc).split()))
        except Exception as exc:         # a diagram this value breaks, a file gone: the row says which
            record.update(status="failed", message=" ".join(f"{type(exc).__name__}: {exc}".split()))
        else:
            record.update(metrics_of(tracking, result, roles), status="ok",
                          message=" | ".join(" ".join(str(group).split()) for group in result.messages))
            if keep:
                result.to_csv(Path(keep) / "results.csv")
    record["wall_time"] = time.perf_counter() - start
    return record


class _ShutdownHeartbeat(logging.Filter):
    """Drops distributed's "Failed to communicate with scheduler during heartbeat." (logged with
    its traceback): after a Ctrl-C the sweep closes the local cluster, and a worker whose
    heartbeat was under way when the scheduler closed logs it, though its nanny is about to close
    it (a race in distributed's shutdown, seen in about one sweep in five)."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not record.getMessage().startswith("Failed to communicate with scheduler during heartbeat")


def dask_setup(worker) -> None:
    """Dask worker preload of the sweep's local cluster (``robofmu.system.sweep.worker``):
    ignore SIGINT, and drop the heartbeat message of a cluster shutting down.

    Ctrl-C in a terminal reaches every process of the foreground group, the local workers too;
    the sweep's client handles it (keeps the finished rows, stops the cluster), so a worker
    must not die of it half-way through a run.
    """
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    logging.getLogger("distributed.worker").addFilter(_ShutdownHeartbeat())

"""The co-simulation master: runs a planned diagram, initializing its FMUs and stepping them.

:meth:`Master.check` plans the diagram (:func:`robofmu.system.check.plan`: every problem at
once, the evaluation order); :meth:`Master.run` instantiates the blocks in that order and steps
them, returning a :class:`~robofmu.system.result.Result`.

At every communication point t the master evaluates the diagram in dependency order
(Gauss-Seidel: a direct-feedthrough block reads inputs its upstream blocks produced at t, so
trajectory -> ik -> controller -> plant has no step of delay); inputs that come from blocks
evaluated later (the plant's torque: the plant has no feedthrough, so it is evaluated before the
controller) are set once the pass is over. It records every output, then calls doStep(t, h) on
each block, so the plant integrates [t, t + h] with the torque computed at t. The Jacobi option
reads all outputs first and then sets all inputs, so each feedthrough block lags one step (for
comparison).

Values move between FMUs through preallocated signal vectors: one batched fmi2GetReal per block
into them, one batched fmi2SetReal per block from them, nothing allocated per step. Those calls
and doStep go through the master's FMI gateway, :mod:`robofmu.system.exchange` (fmpy does the
rest of each FMU's life: :class:`~robofmu.system.fmu.FMUInstance`).

Ctrl-C (SIGINT) during :meth:`Master.run` stops the run at the next communication point: a
handler installed for the run only notes the signal (a KeyboardInterrupt raised inside an FMU's
Python code would take pythonfmu's fragile exception path), the loop checks it after recording
each point, the FMUs are terminated and freed, and :class:`Interrupted` carries the points
recorded so far. A KeyboardInterrupt all the same (raised by a ``progress`` or ``log``
callback, or where no handler could be installed) is an interruption too, and so is a
KeyboardInterrupt raised in a block's own Python code during an FMI call: the block abandons
the call with fmi2Error and a message holding :data:`INTERRUPTION`, which the master recognizes.

``Result``, ``DiagramError`` and ``step_count`` are re-exported from
:mod:`robofmu.system.result` and :mod:`robofmu.system.check`.
"""
from __future__ import annotations

import math
import os
import time as _time
from pathlib import Path
from typing import Callable

import numpy as np

from robofmu.system.check import DiagramError, Link, Node, Plan, plan, step_count, variable_unit
from robofmu.components.fmi.reporting import INTERRUPTION
from robofmu.system.defaults import ALGORITHMS
from robofmu.system.diagram import System, select, unmatched
from robofmu.system.exchange import (Failure, Fmi2Functions, Inputs, Ports, getters, output_port, setters,
                                     stepper)
from robofmu.system.fmu import FMUInstance, FMUError, LogMessage
from robofmu.system.interrupt import sigint_flag
from robofmu.system.result import HEALTH, Message, Result, group_messages, status_meanings

__all__ = ["DiagramError", "Interrupted", "Master", "Result", "SimulationError", "available_memory", "step_count"]



class SimulationError(RuntimeError):
    """A run failed.

    Attributes
    ----------
    block : str or None
        The instance that failed.
    time : float or None
        The communication point (s) of the failure (None: at instantiation).
    result : Result or None
        Everything recorded up to the failure (None if it failed before the first point).
    reason : str
        The message without the note on the results kept.
    """

    def __init__(self, message: str, block: str | None, time: float | None, result: Result | None,
                 reason: str | None = None):
        super().__init__(message)
        self.block = block
        self.time = time
        self.result = result
        self.reason = message if reason is None else reason


class Interrupted(SimulationError):
    """The run was interrupted (SIGINT: Ctrl-C, or a KeyboardInterrupt) and stopped at a
    communication point.

    The master stops at the first communication point after the signal, once that point is
    recorded; the FMUs are terminated and freed as after any run. A KeyboardInterrupt raised in
    the master's loop (a callback) or in a block's Python code during an FMI call stops it at
    once, keeping the points recorded before. ``time`` is the last recorded point (None:
    interrupted before the first one), ``result`` every point up to it (None: none), ``block``
    the block whose code was interrupted, else None.
    """


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation (``MemAvailable``), or None if unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        return None


def _compact(names: list[str]) -> list[str]:
    """Signal names with each vector written once: ``plant.q[1..4]``, ``trajectory.grip``."""
    bases: dict[str, list[int]] = {}
    for name in names:
        head, bracket, rest = name.partition("[")
        if bracket and rest[:-1].isdigit():
            bases.setdefault(head, []).append(int(rest[:-1]))
        else:
            bases.setdefault(name, [])
    return [f"{base}[{min(i)}..{max(i)}]" if len(i) > 1 else f"{base}[{i[0]}]" if i else base
            for base, i in bases.items()]


def _gigabytes(n: int) -> str:
    """A byte count for messages: 38.5 GB, 288 TB."""
    for size, unit in ((1e12, "TB"), (1e9, "GB"), (1e6, "MB")):
        if n >= size or unit == "MB":
            return f"{n / size:.3g} {unit}"


class Master:
    """Runs a :class:`~robofmu.system.diagram.System`.

    Parameters
    ----------
    system : System
    record : list of str, optional
        The outputs to record, each entry an exact ``instance.variable`` (``plant.q[2]``), a
        vector base (``plant.q``) or an fnmatch pattern (``plant.*``); default all outputs. An
        entry that names no output is refused by :meth:`check` (DiagramError). Outputs neither
        recorded nor wired are not read at all.
    progress : callable, optional
        ``progress(fraction, t)`` about 20 times in a run (t in s).
    log : callable, optional
        Receives every FMU log message as it arrives.
    debug : bool
        Keep the FMUs' debug messages (status OK: a failure's traceback, ...) in the result's
        :attr:`~robofmu.system.result.Result.log` too; by default it keeps their warnings and
        errors only.

    Attributes
    ----------
    plan : Plan or None
        The checked diagram (None until :meth:`check`); :attr:`nodes`, :attr:`links`,
        :attr:`order` and :attr:`warnings` read it.
    blocks : dict of str to FMUInstance
        The instantiated blocks during a run.
    heard : list of Message
        What the FMUs logged during the last run (as :attr:`debug` keeps it), each message with
        the communication point it arrived at; every result of the run, a partial one on a
        :class:`SimulationError` too, carries it (``log``) and its groups (``messages``).
    """

    def __init__(self, system: System, record: list[str] | None = None,
                 progress: Callable[[float, float], None] | None = None,
                 log: Callable[[LogMessage], None] | None = None, debug: bool = False):
        self.system = system
        self.record = record
        self.progress = progress
        self.log = log
        self.debug = debug
        self.plan: Plan | None = None
        self.blocks: dict[str, FMUInstance] = {}
        self.heard: list[Message] = []
        self._clock = [0.0]            # the communication point the messages arrive at (s)

    # -- the plan ----------------------------------------------------------------------------------
    def check(self) -> list[str]:
        """Refuse a diagram that cannot run (DiagramError); return the warnings.

        Besides :func:`~robofmu.system.check.plan`'s checks, every ``record`` entry must name
        at least one output (the refusal names the entry and some of the outputs).
        """
        planned = plan(self.system)
        outputs = [f"{name}.{v.name}" for name in planned.order
                   for v in planned.nodes[name].model_description.modelVariables
                   if v.causality == "output" and v.type in ("Real", "Boolean")]
        missing = unmatched(outputs, self.record)
        if missing:
            problems = []
            for entry in missing:
                block = entry.split(".", 1)[0]
                near = [o for o in outputs if o.split(".", 1)[0] == block]
                shown = _compact(near or outputs)
                problems.append(f"record: {entry!r} names no output ({'outputs of ' + block if near else 'outputs'}: "
                                f"{', '.join(shown[:12])}{', ...' if len(shown) > 12 else ''})")
            raise DiagramError(self.system.name, problems)
        self.plan = planned
        return self.plan.warnings

    def recorded_columns(self) -> int:
        """How many signals a run records (plans the diagram first if :meth:`check` has not run)."""
        if self.plan is None:
            self.check()
        self._layout()
        return len(self.keep)

    def memory_problem(self, n_steps: int) -> str | None:
        """Why a run of ``n_steps`` steps would not fit in memory, or None if it fits.

        The recording takes (n + 1) rows x (recorded signals + time) x 8 bytes; it must fit in
        half the memory available (:func:`available_memory`; the analysis of a run makes copies).
        """
        columns = self.recorded_columns()
        need, free = (n_steps + 1) * (columns + 1) * 8, available_memory()
        if free is None or need <= free / 2:
            return None
        return (f"{n_steps} steps x {columns} recorded signals need {_gigabytes(need)} of memory, more "
                f"than half of the {_gigabytes(free)} available")

    @property
    def nodes(self) -> dict[str, Node]:
        """The planned blocks by instance name ({} before :meth:`check`)."""
        return self.plan.nodes if self.plan is not None else {}

    @property
    def links(self) -> list[Link]:
        """The scalar connections ([] before :meth:`check`)."""
        return self.plan.links if self.plan is not None else []

    @property
    def order(self) -> list[str]:
        """The evaluation (and instantiation) order ([] before :meth:`check`)."""
        return self.plan.order if self.plan is not None else []

    @property
    def warnings(self) -> list[str]:
        """The diagram's warnings ([] before :meth:`check`)."""
        return self.plan.warnings if self.plan is not None else []

    # -- run ----------------------------------------------------------------------------------------
    def run(self, stop_time: float | None = None, step: float | None = None,
            algorithm: str | None = None, start_time: float = 0.0,
            csv_path: str | Path | None = None) -> Result:
        """Initialize every block and step the diagram from ``start_time`` to ``stop_time``.

        Parameters
        ----------
        stop_time, step : float, optional
            Run end and communication step (s); default the system's.
        algorithm : str, optional
            One of :data:`robofmu.system.defaults.ALGORITHMS`; default the system's.
        start_time : float
            (s).
        csv_path : str or Path, optional
            Where to write the result (also on a failure, with the points recorded so far).

        Returns
        -------
        Result
            Every recorded output at ``start_time + k step``, k = 0 .. n, shape (n + 1, m),
            with the outputs' units and what the FMUs said (``log``, ``messages``: :attr:`heard`).

        Raises
        ------
        ValueError
            A bad start time, stop time or step (not finite, a step not > 0, a stop time not
            after the start or not a whole number of steps; each named as the argument, or as
            the system's value it defaults to), an unknown algorithm, or a recording that would
            not fit in memory (:meth:`memory_problem`); nothing is instantiated.
        DiagramError
            The diagram or the ``record`` selection cannot run (:meth:`check`).
        SimulationError
            Naming the block, the time and the FMU's message; its ``result`` holds every point
            recorded so far.
        Interrupted
            SIGINT (Ctrl-C) during the run: the run stops at the next communication point; its
            ``result`` holds every point up to it (also written to ``csv_path``). The handler
            that notes the signal is installed for the run only (main thread), the previous one
            restored afterwards. A KeyboardInterrupt raised all the same (by ``progress`` or
            ``log``, or in a block's Python code during an FMI call: ``block`` names it) stops
            the run at once, with every point recorded before it, written to ``csv_path`` too.
        """
        system = self.system
        given = {"start_time": start_time, "stop_time": stop_time, "step": step}
        start_time = float(start_time)
        stop_time = float(system.stop_time if stop_time is None else stop_time)
        h = float(system.step if step is None else step)
        algorithm = system.algorithm if algorithm is None else algorithm
        if algorithm not in ALGORITHMS:
            raise ValueError(f"algorithm {algorithm!r}: choose one of {', '.join(ALGORITHMS)}")
        n_steps = _checked_steps(start_time, stop_time, h, given, system.name)
        if self.plan is None:
            self.check()
        problem = self.memory_problem(n_steps)
        if problem:
            raise ValueError(problem)
        with sigint_flag() as interrupted:     # the loop stops at the next point (no exception in a FMU)
            try:
                try:
                    self._instantiate(start_time, stop_time)
                except KeyboardInterrupt:
                    raise Interrupted("interrupted before the first communication point (KeyboardInterrupt)",
                                      None, None, None) from None
                if interrupted[0]:
                    raise Interrupted("interrupted before the first communication point", None, None, None)
                return self._loop(start_time, h, n_steps, algorithm, csv_path, interrupted)
            finally:
                self.close()

    def _hear(self, message: LogMessage) -> None:
        """Keep ``message`` (a warning or worse; any with :attr:`debug`) with the current point,
        then pass it to :attr:`log`."""
        if self.debug or message.status != "OK":
            prefix = f"{message.instance}: "
            text = message.message[len(prefix):] if message.message.startswith(prefix) else message.message
            self.heard.append(Message(message.instance, message.status, message.category, text, self._clock[0]))
        if self.log is not None:
            self.log(message)

    def _result(self, times: np.ndarray, recorded: np.ndarray, info: dict) -> Result:
        """The :class:`Result` of the points recorded, with what the FMUs said."""
        columns = list(self.columns)
        meanings = {}
        for column in columns:
            block, _, name = column.partition(".")
            if name == "status" and HEALTH.get(name) == 0.0:      # a status whose codes its description names
                meanings[column] = status_meanings(self.nodes[block].variables[name].description)
        heard = list(self.heard)
        return Result(times, columns, recorded, info, dict(self.units), heard,
                      group_messages(heard, times, columns, recorded, meanings))

    def _instantiate(self, start_time: float, stop_time: float) -> None:
        self.blocks = {}
        self.heard = []
        self._clock[0] = start_time
        for name in self.order:
            node = self.nodes[name]
            try:
                block = FMUInstance(node.path, name, echo=self._hear, model_description=node.model_description)
            except FMUError as exc:
                raise SimulationError(str(exc), name, None, None) from None
            self.blocks[name] = block
            try:
                block.initialize(start_time, node.spec.parameters, stop_time=stop_time)
            except FMUError as exc:
                if any(INTERRUPTION in text for text in exc.logged):
                    reason = f"interrupted before the first communication point (KeyboardInterrupt in {exc.call} of {name})"
                    raise Interrupted(f"{reason}: {exc}", name, None, None, reason) from None
                raise SimulationError(f"{exc}", name, start_time, None) from None

    def _layout(self) -> None:
        """Signal vectors, ports, recorded columns and their units.

        Only the outputs that are wired to an input or recorded are read (all of them with the
        default ``record``); an output nothing uses costs no FMI call.
        """
        outputs = [(name, variable) for name in self.order
                   for variable in self.nodes[name].model_description.modelVariables
                   if variable.causality == "output" and variable.type in ("Real", "Boolean")]
        recorded = set(select([f"{name}.{v.name}" for name, v in outputs], self.record))
        wired = {(link.source, link.output) for link in self.links}
        read = [(name, v) for k, (name, v) in enumerate(outputs) if k in recorded or (name, v.name) in wired]
        real_outputs = [(name, v) for name, v in read if v.type == "Real"]           # evaluation order
        boolean_outputs = [(name, v) for name, v in read if v.type == "Boolean"]
        self.real_signals = np.zeros(len(real_outputs))
        self.boolean_signals = np.zeros(len(boolean_outputs), dtype=np.int32)
        real_index = {(block, v.name): k for k, (block, v) in enumerate(real_outputs)}
        boolean_index = {(block, v.name): k for k, (block, v) in enumerate(boolean_outputs)}
        rank = {name: k for k, name in enumerate(self.order)}
        self.ports = {}
        for name in self.order:
            variables = self.nodes[name].variables
            # each block's outputs are contiguous in the signal vectors (outputs in evaluation order)
            real_rows = [k for k, (block, _) in enumerate(real_outputs) if block == name]
            boolean_rows = [k for k, (block, _) in enumerate(boolean_outputs) if block == name]
            get_real = output_port([real_outputs[k][1].valueReference for k in real_rows],
                                   self.real_signals, real_rows)
            get_boolean = output_port([boolean_outputs[k][1].valueReference for k in boolean_rows],
                                      self.boolean_signals, boolean_rows)
            # Inputs from blocks evaluated earlier are set before this block's outputs are read;
            # inputs from blocks evaluated later cannot affect those outputs (the order is
            # topological in the feedthrough graph) and are set after the pass, before doStep.
            links = [link for link in self.links if link.target == name]
            early = Inputs([link for link in links if rank[link.source] < rank[name]], variables,
                           real_index, boolean_index, self.real_signals)
            late = Inputs([link for link in links if rank[link.source] >= rank[name]], variables,
                          real_index, boolean_index, self.real_signals)
            self.ports[name] = Ports(get_real, get_boolean, early, late)
        self.real_names = [f"{block}.{v.name}" for block, v in real_outputs]
        self.boolean_names = [f"{block}.{v.name}" for block, v in boolean_outputs]
        units = {f"{block}.{v.name}": variable_unit(v) for block, v in real_outputs + boolean_outputs}
        columns = self.real_names + self.boolean_names
        keep = select(columns, self.record)
        self.columns = [columns[k] for k in keep]
        self.units = {column: units[column] for column in self.columns if units[column]}
        self.keep = np.array(keep, dtype=np.intp)

    def _operations(self, algorithm: str):
        """One exchange and one step as flat lists of closures over preallocated buffers.

        Gauss-Seidel: for each block in evaluation order, set its inputs from blocks evaluated
        before it, then read its outputs; after the pass, set the inputs that come from blocks
        evaluated later. Jacobi: read every output, then set every input.

        Returns
        -------
        first, exchange : list of callable
            The exchange at the first point (always Gauss-Seidel: a consistent start) and at
            every later point; each op takes no argument.
        steps : list of callable
            ``op(t, h)``: one doStep per block, in evaluation order.
        """
        real_signals, boolean_signals = self.real_signals, self.boolean_signals
        early, reads, late, steps = [], [], [], []
        for name in self.order:
            functions, ports = Fmi2Functions(self.blocks[name].slave), self.ports[name]
            reads.append(getters(functions, ports, name))
            early.append(setters(functions, ports.early, real_signals, boolean_signals, name))
            late.append(setters(functions, ports.late, real_signals, boolean_signals, name))
            steps.append(stepper(functions, name))
        gauss_seidel = ([op for sets, gets in zip(early, reads) for op in sets + gets]
                        + [op for sets in late for op in sets])
        if algorithm == "gauss-seidel":
            return gauss_seidel, gauss_seidel, steps
        jacobi = ([op for gets in reads for op in gets]
                  + [op for sets_early, sets_late in zip(early, late) for op in sets_early + sets_late])
        return gauss_seidel, jacobi, steps     # Jacobi, too, starts from a consistent first exchange

    def _loop(self, t0: float, h: float, n_steps: int, algorithm: str, csv_path,
              interrupted: list | None = None) -> Result:
        interrupted = [False] if interrupted is None else interrupted
        real_signals, boolean_signals = self.real_signals, self.boolean_signals
        n_real = len(real_signals)
        ones = np.ones(n_real)              # signals . ones: nan and inf propagate, a sum at BLAS speed
        row = np.zeros(n_real + len(boolean_signals))
        record_all = np.array_equal(self.keep, np.arange(len(row)))
        recorded = np.empty((n_steps + 1, len(self.keep)))
        times = t0 + h * np.arange(n_steps + 1)
        first, exchange, steps = self._operations(algorithm)
        clock = self._clock
        every = max(1, n_steps // 20)
        t, n_recorded = t0, 0
        wall = _time.perf_counter()
        try:
            for k in range(n_steps + 1):
                t = clock[0] = times[k]
                for op in (first if k == 0 else exchange):    # Jacobi, too, starts consistent
                    op()
                if not math.isfinite(real_signals.dot(ones)) and not np.isfinite(real_signals).all():
                    index = int(np.flatnonzero(~np.isfinite(real_signals))[0])
                    bad = self.real_names[index]
                    raise Failure(bad.split(".")[0], f"output {bad} is not finite "
                                   f"({real_signals[index]}) at t = {t:.9g} s")
                if record_all:
                    recorded[k, :n_real] = real_signals
                    recorded[k, n_real:] = boolean_signals
                else:
                    row[:n_real] = real_signals
                    row[n_real:] = boolean_signals
                    recorded[k] = row[self.keep]
                n_recorded = k + 1
                if interrupted[0]:                 # SIGINT: stop at this recorded point
                    raise Failure("", "interrupted", "SIGINT")
                if k == n_steps:
                    break
                for op in steps:
                    op(t, h)
                if self.progress is not None and (k + 1) % every == 0:
                    self.progress((k + 1) / n_steps, t + h)
        except KeyboardInterrupt:       # a callback's, or a signal no handler could note
            kept = (times, recorded, n_recorded, algorithm, h, csv_path)
            raise self._interruption(" (KeyboardInterrupt)", None, *kept) from None
        except Failure as exc:
            kept = (times, recorded, n_recorded, algorithm, h, csv_path)
            if exc.call == "SIGINT":
                raise self._interruption("", None, *kept) from None
            if exc.call:
                logged = self.blocks[exc.block].errors()
                if logged and INTERRUPTION in logged[-1]:      # the block's code was interrupted
                    raise self._interruption(f" (KeyboardInterrupt in {exc.block}'s {exc.call})", exc.block,
                                             *kept) from None
                message = (f"{exc.block}: {exc.call} failed at t = {t:.9g} s"
                           + (": " + logged[-1] if logged else f" (status {exc.message})"))
            else:
                message = f"{exc.block}: {exc.message}"
            result = self._result(times[:n_recorded].copy(), recorded[:n_recorded].copy(),
                                  {"failed": message, "algorithm": algorithm, "step": h})
            if csv_path is not None:
                result.to_csv(csv_path)
            raise SimulationError(message + (f"\nresults up to t = {times[n_recorded - 1]:.9g} s kept"
                                             + (f" in {csv_path}" if csv_path else "") if n_recorded else ""),
                                  exc.block, float(t), result, message) from None
        result = self._result(times, recorded, {"algorithm": algorithm, "step": h,
                                                "wall_time": _time.perf_counter() - wall, "order": list(self.order)})
        if csv_path is not None:
            result.to_csv(csv_path)
        return result

    def _interruption(self, how: str, block: str | None, times: np.ndarray, recorded: np.ndarray, n_recorded: int,
                      algorithm: str, h: float, csv_path) -> Interrupted:
        """The :class:`Interrupted` of a run stopped after ``n_recorded`` points (``how``: what
        interrupted it, appended to the reason), with the result so far, written to ``csv_path``."""
        if not n_recorded:
            reason = f"interrupted before the first communication point{how}"
            return Interrupted(reason, block, None, None, reason)
        t = float(times[n_recorded - 1])
        reason = f"interrupted at t = {t:.9g} s{how}"
        result = self._result(times[:n_recorded].copy(), recorded[:n_recorded].copy(),
                              {"interrupted": t, "algorithm": algorithm, "step": h})
        if csv_path is not None:
            result.to_csv(csv_path)
        return Interrupted(reason + f"; results up to t = {t:.9g} s kept" + (f" in {csv_path}" if csv_path else ""),
                           block, t, result, reason)

    def close(self) -> None:
        """Terminate and free every instantiated block. Safe to call twice."""
        for block in self.blocks.values():
            block.close()
        self.blocks = {}


def _checked_steps(start_time: float, stop_time: float, h: float, given: dict, name: str) -> int:
    """:func:`step_count` of a run, each bad argument refused first (ValueError naming it: the
    argument of :meth:`Master.run`, or the system's value it defaults to)."""
    values = {"start_time": start_time, "stop_time": stop_time, "step": h}

    def named(key: str) -> str:
        return f"{key} = {values[key]!r} s" if given[key] is not None or key == "start_time" else \
            f"{key} = {values[key]!r} s (system {name!r})"

    for key, value in values.items():
        if not math.isfinite(value):
            raise ValueError(f"Master.run: {named(key)} is invalid: must be a finite time")
    if not h > 0.0:
        raise ValueError(f"Master.run: {named('step')} is invalid: must be > 0")
    if not stop_time > start_time:
        raise ValueError(f"Master.run: {named('stop_time')} is invalid: must be after {named('start_time')}")
    ratio = (stop_time - start_time) / h
    if not ratio <= 1e15:
        raise ValueError(f"Master.run: {named('stop_time')}, {named('start_time')} and {named('step')} make "
                         f"{ratio:.3g} steps, far more than memory can record")
    try:
        return step_count(start_time, stop_time, h)
    except ValueError as exc:
        raise ValueError(f"Master.run: {exc}") from None


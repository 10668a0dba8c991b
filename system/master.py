"""The co-simulation master: runs a planned diagram, initializing its FMUs and stepping them.

:meth:`Master.check` plans the run (:func:`robofmu.system.plan.plan`, one pass: every problem
at once, the evaluation order, the times, each block's sample rate, the memory check);
:meth:`Master.run` instantiates the blocks in that order and steps them, returning a
:class:`~robofmu.system.result.Result`.

At every communication point t the master evaluates the diagram in dependency order
(Gauss-Seidel: a direct-feedthrough block reads inputs its upstream blocks produced at t, so
trajectory -> ik -> controller -> plant has no step of delay); inputs that come from blocks
evaluated later (the plant's torque: the plant has no feedthrough, so it is evaluated before the
controller) are set once the pass is over. It records every output, then calls doStep(t, h) on
each block, so the plant integrates [t, t + h] with the torque computed at t. The Jacobi option
reads all outputs first and then sets all inputs, so each feedthrough block lags one step (for
comparison).

**Sample rates.** A block whose ``sample_time`` is r base steps h is *due* at the base steps
k = 0, r, 2r, ...: there its inputs are set and its outputs read (in the same evaluation order),
and it steps doStep(t_k, r h). At the other base steps it is left alone: its outputs stay in
the signal vector as last read (zero-order hold), and nothing is set on it. So a controller at
4 ms beside a plant at 1 ms reads the plant's outputs at t_k (k = 0, 4, 8, ...) and its effort
is held over the plant's next four steps. A due block whose step would end after the stop time
is not stepped (nothing would read its result). With every block at the base step this is the
loop above, call for call.

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

``Result``, ``DiagramError``, ``step_count`` and ``available_memory`` are re-exported from
:mod:`robofmu.system.result` and :mod:`robofmu.system.plan`.
"""
from __future__ import annotations

import math
import time as _time
from pathlib import Path
from typing import Callable

import numpy as np
from fmpy.fmi2 import fmi2Real

from robofmu.components.fmi.reporting import INTERRUPTION
from robofmu.system.call_list import batch, runner
from robofmu.system.defaults import ALGORITHMS
from robofmu.system.diagram import System
from robofmu.system.exchange import (Failure, Fmi2Functions, Inputs, Ports, failed, getters, output_port,
                                     setters, stepper)
from robofmu.system.fmu import FMUInstance, FMUError, LogMessage
from robofmu.system.interrupt import sigint_flag
from robofmu.system.plan import (DiagramError, Link, Node, Plan, Times, available_memory, plan, step_count, times,
                                 variable_unit)
from robofmu.system.result import HEALTH, Message, Result, group_messages, stated_time, status_meanings

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
    def check(self, run_times: Times | None = None) -> list[str]:
        """Plan the run (:func:`~robofmu.system.plan.plan`: DiagramError listing every problem,
        a ``record`` entry naming no output among them); return the warnings.

        Parameters
        ----------
        run_times : Times, optional
            The run's (:func:`~robofmu.system.plan.times`): the plan then holds them, the
            blocks' ratios against its base step and the memory check, and :meth:`run` without
            times runs them. None: times are planned by :meth:`run`.
        """
        self.plan = plan(self.system, self.record, run_times)
        return self.plan.warnings

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
            algorithm: str | None = None, start_time: float | None = None,
            csv_path: str | Path | None = None) -> Result:
        """Initialize every block and step the diagram from ``start_time`` to ``stop_time``.

        Parameters
        ----------
        stop_time, step : float, optional
            Run end and base communication step (s); default the times :meth:`check` planned
            (when none of the three is given), else the system's.
        algorithm : str, optional
            One of :data:`robofmu.system.defaults.ALGORITHMS`; default the system's.
        start_time : float, optional
            (s); default 0 (or the planned one).
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
            not fit in memory (:attr:`Plan.memory <robofmu.system.plan.Plan.memory>`); nothing is
            instantiated.
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
        algorithm = system.algorithm if algorithm is None else algorithm
        if algorithm not in ALGORITHMS:
            raise ValueError(f"algorithm {algorithm!r}: choose one of {', '.join(ALGORITHMS)}")
        planned = self.plan
        if planned is None or planned.times is None or (start_time, stop_time, step) != (None, None, None):
            try:
                run_times = times(system, 0.0 if start_time is None else start_time, stop_time, step)
            except ValueError as exc:
                raise ValueError(f"Master.run: {exc}") from None
            if planned is None:
                self.check(run_times)
            elif planned.times != run_times:
                self.plan = planned.timed(run_times)
        run_times = self.plan.times
        if self.plan.memory:
            raise ValueError(self.plan.memory)
        start_time, stop_time, h, n_steps = run_times.start, run_times.stop, run_times.step, run_times.n_steps
        self._layout()
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
            self.heard.append(Message(message.instance, message.status, message.category, text,
                                      stated_time(text, self._clock[0])))
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
                      group_messages(heard, times, columns, recorded, meanings, list(self.order)))

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
        recorded = set(self.plan.recorded)
        wired = {(link.source, link.output) for link in self.links}
        read = [(name, v) for name, v in outputs if f"{name}.{v.name}" in recorded or (name, v.name) in wired]
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
        keep = [k for k, column in enumerate(columns) if column in recorded]
        self.columns = [columns[k] for k in keep]
        self.units = {column: units[column] for column in self.columns if units[column]}
        self.keep = np.array(keep, dtype=np.intp)

    def _operations(self, algorithm: str, h: float, time, run=None):
        """The exchanges and steps as flat lists of :data:`~robofmu.system.exchange.Call` tuples
        over preallocated buffers.

        Gauss-Seidel: for each due block in evaluation order, set its inputs from blocks
        evaluated before it, then read its outputs; after the pass, set the due blocks' inputs
        that come from blocks evaluated later. Jacobi: read every due output, then set every due
        input. A block not due is left alone (its outputs held in the signal vectors).

        Parameters
        ----------
        time : fmi2Real
            The communication point (s) every doStep passes, set by the loop.
        run : ctypes function, optional
            The C call list's (:func:`~robofmu.system.call_list.runner`): each exchange and
            each round of steps is then one call of it; None: the single calls.

        Returns
        -------
        first : list of Call
            The exchange at the first point (Gauss-Seidel, every block due: a consistent start).
        schedule : callable
            ``schedule(due, stepped)`` -> (exchange, steps), lists of Call: the exchange of the
            blocks ``due`` and the doSteps (of one sample time each) of the blocks ``stepped``
            (tuples of names in evaluation order).
        """
        real_signals, boolean_signals = self.real_signals, self.boolean_signals
        early, reads, late, steps = {}, {}, {}, {}
        for name in self.order:
            functions, ports = Fmi2Functions(self.blocks[name].slave), self.ports[name]
            reads[name] = getters(functions, ports, name)
            early[name] = setters(functions, ports.early, real_signals, boolean_signals, name)
            late[name] = setters(functions, ports.late, real_signals, boolean_signals, name)
            steps[name] = stepper(functions, name, time, self.plan.ratios[name] * h)

        def exchange(due, method):
            if method == "gauss-seidel":
                calls = ([call for name in due for call in early[name] + reads[name]]
                         + [call for name in due for call in late[name]])
            else:
                calls = ([call for name in due for call in reads[name]]
                         + [call for name in due for call in early[name] + late[name]])
            return batch(run, calls)

        def schedule(due, stepped):
            return exchange(due, algorithm), batch(run, [steps[name] for name in stepped])

        return exchange(tuple(self.order), "gauss-seidel"), schedule

    def _loop(self, t0: float, h: float, n_steps: int, algorithm: str, csv_path,
              interrupted: list | None = None) -> Result:
        interrupted = [False] if interrupted is None else interrupted
        real_signals, boolean_signals = self.real_signals, self.boolean_signals
        n_real, n_boolean = len(real_signals), len(boolean_signals)
        ones = np.ones(n_real)              # signals . ones: nan and inf propagate, a sum at BLAS speed
        row = np.zeros(n_real + n_boolean)
        record_all = np.array_equal(self.keep, np.arange(len(row)))
        recorded = np.empty((n_steps + 1, len(self.keep)))
        times_ = t0 + h * np.arange(n_steps + 1)
        if record_all:
            # Recording every signal, the loop copies the Reals into their row of `recorded`
            # (memoryviews: a copy without NumPy's indexing) and the Booleans into rows of their
            # own, cast into `recorded` (exactly: 0 or 1) for the points kept when the run ends.
            reals, booleans = memoryview(real_signals), memoryview(boolean_signals)
            real_rows = memoryview(recorded.reshape(-1))
            boolean_record = np.zeros((n_steps + 1, n_boolean), dtype=np.int32)
            boolean_rows = memoryview(boolean_record.reshape(-1))
            width = len(row)
        time = fmi2Real()                   # the communication point of every doStep (s)
        run, calls_how = runner()
        first, schedule = self._operations(algorithm, h, time, run)
        everyone = tuple(self.order)
        exchange, steps = schedule(everyone, everyone)
        # Multi-rate: which blocks are due at base step k (their inputs set, outputs read) and
        # stepped there (their step ends by the stop time) repeats with the ratios' least common
        # multiple, until the longest sample time reaches the stop time.
        ratios = [(name, self.plan.ratios[name]) for name in self.order]
        multirate = self.plan.multirate
        if multirate:
            cycle = math.lcm(*(r for _, r in ratios))
            regular = n_steps - max(r for _, r in ratios)    # every due block stepped up to here

            def plan_at(k):
                return schedule(tuple(name for name, r in ratios if k % r == 0),
                                tuple(name for name, r in ratios if k % r == 0 and k + r <= n_steps))
            phases = [plan_at(k) for k in range(min(cycle, n_steps + 1))]
            last = {k: plan_at(k) for k in range(max(regular + 1, 0), n_steps + 1)}    # made before the loop
        clock = self._clock
        every = max(1, n_steps // 20)
        progress = self.progress
        isfinite, dot = math.isfinite, real_signals.dot
        t, n_recorded = t0, 0

        def record_booleans():        # into the points kept, before the result is made of them
            if record_all and n_boolean:
                recorded[:n_recorded, n_real:] = boolean_record[:n_recorded]

        wall = _time.perf_counter()
        try:
            for k in range(n_steps + 1):
                t = clock[0] = t0 + h * k      # = times_[k] bit for bit: the same two IEEE operations
                if multirate:
                    exchange, steps = phases[k % cycle] if k <= regular else last[k]
                for function, arguments, block, call, _ in (first if k == 0 else exchange):
                    status = function(*arguments)      # Jacobi, too, starts consistent
                    if status > 1:
                        raise failed(block, status, call)
                if not isfinite(dot(ones)) and not np.isfinite(real_signals).all():
                    index = int(np.flatnonzero(~np.isfinite(real_signals))[0])
                    bad = self.real_names[index]
                    raise Failure(bad.split(".")[0], f"output {bad} is not finite "
                                   f"({real_signals[index]}) at t = {t:.9g} s")
                if record_all:
                    start = k * width
                    real_rows[start:start + n_real] = reals
                    start = k * n_boolean
                    boolean_rows[start:start + n_boolean] = booleans
                else:
                    row[:n_real] = real_signals
                    row[n_real:] = boolean_signals
                    recorded[k] = row[self.keep]
                n_recorded = k + 1
                if interrupted[0]:                 # SIGINT: stop at this recorded point
                    raise Failure("", "interrupted", "SIGINT")
                if k == n_steps:
                    break
                time.value = t
                for function, arguments, block, call, _ in steps:
                    status = function(*arguments)
                    if status > 1:
                        raise failed(block, status, call)
                if progress is not None and (k + 1) % every == 0:
                    progress((k + 1) / n_steps, t + h)
        except KeyboardInterrupt:       # a callback's, or a signal no handler could note
            record_booleans()
            kept = (times_, recorded, n_recorded, algorithm, h, csv_path)
            raise self._interruption(" (KeyboardInterrupt)", None, *kept) from None
        except Failure as exc:
            record_booleans()
            kept = (times_, recorded, n_recorded, algorithm, h, csv_path)
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
            result = self._result(times_[:n_recorded].copy(), recorded[:n_recorded].copy(),
                                  {"failed": message, "algorithm": algorithm, "step": h})
            if csv_path is not None:
                result.to_csv(csv_path)
            raise SimulationError(message + (f"\nresults up to t = {times_[n_recorded - 1]:.9g} s kept"
                                             + (f" in {csv_path}" if csv_path else "") if n_recorded else ""),
                                  exc.block, float(t), result, message) from None
        info = {"algorithm": algorithm, "step": h, "wall_time": _time.perf_counter() - wall, "order": list(self.order),
                "calls": calls_how}
        record_booleans()
        if multirate:
            info["sample_times"] = {name: r * h for name, r in ratios}
        result = self._result(times_, recorded, info)
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

"""The FMI life cycle of a block: experiment set-up, initialization, steps, termination.

- fmi2SetupExperiment sets the start time (refused, naming the argument, if it is invalid);
- fmi2ExitInitializationMode -> ``Block.configure()`` (invalid parameters fail naming the
  parameter) and the first outputs;
- fmi2DoStep(t, h) -> ``Block.advance(t, h)``; outputs then belong to t + h. A step that does
  not continue from the instance's time, a non-finite input or held outputs
  (:mod:`.outputs`), and a block's :class:`~robofmu.components.blocks.StepRefused` refuse the
  step with the reason;
- fmi2Terminate ends it: no step afterwards.

fmi2Reset is pythonfmu's: it constructs the slave anew.
"""
from __future__ import annotations

import math

from ..blocks import StepRefused
from .quiet import quietly
from .reporting import one_line

__all__ = ["LifeCycle"]


class LifeCycle:
    """The life-cycle calls (a mixin of :class:`~.base.BlockSlave`).

    Uses the slave's ``logic``, ``values``, ``time``, the flags of
    :class:`~.fast_path.FastPath`, the outputs of :class:`~.outputs.Outputs` and the messages
    of :class:`~.reporting.Reporting`.
    """

    def _refuse_when_not_new(self, call: str, hint: str = "") -> None:
        """Fail ``call`` if the instance is already initialized or terminated."""
        if self._initialized or self._terminated:
            self._raise_to_importer(f"{call}: the instance is already "
                                    + ("terminated" if self._terminated else "initialized") + hint)

    def setup_experiment(self, start_time: float, stop_time=None, tolerance=None):
        """fmi2SetupExperiment (``stop_time``, ``tolerance``: None when not defined). Refused,
        nothing set, each reason naming its argument: an initialized or terminated instance, a
        startTime that is not finite, a defined stopTime that is not finite or before startTime,
        a defined tolerance that is not finite or negative."""
        self._refuse_when_not_new("fmi2SetupExperiment")
        problems = []
        if not math.isfinite(start_time):
            problems.append(f"startTime = {start_time!r} s is invalid: must be finite")
        if stop_time is not None:
            if not math.isfinite(stop_time):
                problems.append(f"stopTime = {stop_time!r} s is invalid: must be finite (or not defined: "
                                "stopTimeDefined = fmi2False)")
            elif math.isfinite(start_time) and stop_time < start_time:
                problems.append(f"stopTime = {stop_time!r} s is before startTime = {start_time!r} s")
        if tolerance is not None and not (math.isfinite(tolerance) and tolerance >= 0.0):
            problems.append(f"tolerance = {tolerance!r} is invalid: must be finite and >= 0 (or not defined: "
                            "toleranceDefined = fmi2False)")
        if problems:
            self._raise_to_importer("fmi2SetupExperiment: " + "; ".join(problems) + "; nothing set")
        self.time = float(start_time)

    def enter_initialization_mode(self):
        self._refuse_when_not_new("fmi2EnterInitializationMode", "; instantiate a new one")

    def exit_initialization_mode(self):
        self._refuse_when_not_new("fmi2ExitInitializationMode")
        try:
            self.logic.configure()
            self.logic.output(self.time)
        except Exception as exc:
            self._raise_to_importer(f"initialization failed: {one_line(exc)}", exc)
        bad = self._nonfinite_output()
        if bad is not None:
            self._raise_to_importer(f"initialization failed: {bad}")
        self._initialized = True
        self._dirty = False

    def terminate(self):
        self._terminated = True

    def _at_own_time(self, t: float) -> bool:
        """Whether a step from ``t`` continues from the instance's time (to 1e-9 s, relative
        beyond 1 s; False for a non-finite ``t``)."""
        scale = abs(self.time)          # max(1.0, |time|) without builtin max's call (hot path)
        return abs(t - self.time) <= 1e-9 * (scale if scale > 1.0 else 1.0)

    def _step_problem(self, current_time: float, step_size: float) -> str | None:
        """Why ``fmi2DoStep(current_time, step_size)`` cannot run now, or None."""
        if self._shared.active and 0.0 < step_size < math.inf and self._at_own_time(current_time):
            return None                                              # the usual case, in one test
        if self._terminated:
            return "fmi2DoStep: the instance is terminated"
        if not self._initialized:
            return "fmi2DoStep: called before fmi2ExitInitializationMode"
        if not (math.isfinite(step_size) and step_size > 0.0):
            return f"fmi2DoStep: communication step h = {step_size} s is invalid: must be finite and > 0"
        if not self._at_own_time(current_time):
            return (f"fmi2DoStep: communication point t = {current_time!r} s does not continue from the "
                    f"instance's time {self.time!r} s (restore a saved FMU state to go back)")
        return None

    def do_step(self, current_time: float, step_size: float) -> bool:
        problem = self._step_problem(current_time, step_size)
        if problem is not None:
            return self.fail(problem)
        shared = self._shared
        try:
            if not shared.inputs_checked:                   # once per setting of the inputs
                bad = self.nonfinite_input()
                if bad is not None:
                    return self.fail(f"input {bad} at t = {current_time:.9g} s is not finite; step refused")
                shared.inputs_checked = 1
            if self._feedthrough and shared.dirty:   # the state a feedthrough block keeps (IK's last solution)
                self._output_safely(announce=False)     # a failure is this step's one message
            if self._bad_output is not None:
                return self.fail(f"t = {current_time:.9g} s: {self._bad_output}; step refused")
            quietly(self.logic.advance, current_time, step_size)
        except Exception as exc:
            return self._step_failed(exc, current_time)
        self.time = current_time + step_size
        self._held_warned = False
        shared.dirty = 1        # _dirty: internal state moved on, outputs at t + h are due
        return True

    def _step_failed(self, exc: Exception, current_time: float) -> bool:
        """The block's advance raised ``exc``: the step refused with its reason in one line (a
        :class:`~robofmu.components.blocks.StepRefused` in its own words), False; an unexpected
        exception's traceback only as a debug message (:meth:`~.reporting.Reporting._trace`)."""
        if isinstance(exc, StepRefused):
            self.fail(one_line(exc))
        else:
            self.fail(f"step from t = {current_time:.9g} s failed: {one_line(exc)}")
        self._trace(exc)
        return False

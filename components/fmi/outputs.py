"""The block's outputs: computed when read, and never a non-finite one.

Outputs are computed lazily (``Block.output(t)``) whenever inputs or time changed since they
were last computed and the importer reads one. A non-finite input, an output that would not be
finite, or an output evaluation that raises holds the previous outputs and makes the next step
fail with the reason (the master then reports it); NumPy's floating-point warnings stay inside
(:func:`.quiet.quietly`): an overflow is the FMU's message, not a warning printed by the host.
"""
from __future__ import annotations

import math

import numpy as np
from pythonfmu.enums import Fmi2Status

from .quiet import quietly
from .reporting import REFUSALS, one_line

__all__ = ["Outputs"]


class Outputs:
    """Outputs kept current and finite (a mixin of :class:`~.base.BlockSlave`).

    Uses the slave's ``logic``, ``values``, ``time``, the slot masks of
    :class:`~.variables.Variables`, the shared flags (``_shared``, ``_initialized``,
    ``_dirty``: :class:`~.fast_path.FastPath`) and the messages of
    :class:`~.reporting.Reporting`.
    """

    def _refresh(self) -> None:
        """Bring outputs up to date: from the inputs and state at the current time or, during
        initialization mode, from the parameters and inputs set so far (FMI 2.0 lets an
        importer read calculated outputs before fmi2ExitInitializationMode)."""
        if self._initialized:
            self._output_safely()
            return
        try:
            self.logic.configure()
            self.logic.output(self.time)
        except Exception:
            pass        # invalid parameters are reported by fmi2ExitInitializationMode
        self._dirty = False

    def nonfinite_input(self) -> str | None:
        """'name = value' of the first non-finite Real input, or None."""
        if math.isfinite(quietly(self.values.dot, self._input_mask)):    # nan, inf propagate (inf 0: nan)
            return None
        values = self.values[self._input_vrs]
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size == 0:
            return None
        vr = self._input_vrs[bad[0]]
        return f"{self._names[vr]} = {self.values[vr]}"

    def _nonfinite_output(self) -> str | None:
        """Why the outputs just computed are not finite (naming the largest input), or None."""
        if math.isfinite(quietly(self.values.dot, self._output_mask)):    # nan, inf propagate (inf 0: nan)
            return None
        outputs = self.values[self._output_slots]
        if np.isfinite(outputs).all():                           # a non-finite value elsewhere
            return None
        k = int(self._output_slots[np.flatnonzero(~np.isfinite(outputs))[0]])
        cause = ""
        if self._input_vrs.size:
            inputs = np.abs(self.values[self._input_vrs])
            j = int(self._input_vrs[int(np.argmax(inputs))])
            cause = f" for input {self._names[j]} = {self.values[j]:g}"
        if self._parameter_slots.size:
            j = int(self._parameter_slots[int(np.argmax(np.abs(self.values[self._parameter_slots])))])
            cause += f" (largest parameter {self._names[j]} = {self.values[j]:g})"
        return f"output {self._names[k]} would be {self.values[k]}{cause}"

    def _output_safely(self, announce: bool = True) -> None:
        """Outputs at the current time from the current inputs; never a non-finite one: a
        non-finite input or output, or a block's refusal of its inputs, holds the previous
        outputs and makes the next step fail. ``announce`` False: a failure is left to the
        step's message (fmi2DoStep's own evaluation), nothing logged here."""
        shared = self._shared
        if not shared.inputs_checked:                   # inputs set since the last check
            bad = self.nonfinite_input()
            if bad is not None:
                if not self._held_warned:
                    self.warn(f"input {bad} at t = {self.time:.9g} s is not finite: outputs held at their "
                              "last values; the next step will fail")
                    self._held_warned = True
                return
            shared.inputs_checked = 1
        held = self.values.take(self._output_slots, out=self._held)
        try:
            quietly(self.logic.output, self.time)    # an overflow is reported below, not as a host warning
        except Exception as exc:
            self._output_failed(exc, held, announce)
            return
        if self._hold_nonfinite(held, announce):
            return
        self._bad_output = None
        shared.dirty = 0                # _dirty

    def _output_failed(self, exc: Exception, held: np.ndarray, announce: bool = True) -> None:
        """Evaluating the outputs raised ``exc``: the ``held`` ones back and the reason, in one
        line, for the next step's refusal. A block's refusal of its inputs (:data:`.REFUSALS`: a
        non-unit quaternion on ``quat_ref``) is announced as a non-finite input is, one warning
        until a step succeeds; an unexpected exception as an error, once per reason, its
        traceback a debug message."""
        self.values[self._output_slots] = held
        refusal = isinstance(exc, REFUSALS)
        reason = one_line(exc) if refusal else f"evaluating outputs failed: {one_line(exc)}"
        new, self._bad_output = reason != self._bad_output, reason
        if announce and refusal and not self._held_warned:
            self.warn(f"t = {self.time:.9g} s: {reason}: outputs held at their last values; the next step will fail")
            self._held_warned = True
        elif announce and new and not refusal:
            self.log(f"{self.instance_name}: t = {self.time:.9g} s: {reason}", Fmi2Status.error)
        if new:
            self._trace(exc)

    def _hold_nonfinite(self, held: np.ndarray, announce: bool = True) -> bool:
        """If an output just computed is not finite: the ``held`` ones back, the reason
        reported (unless not ``announce``: left to the step's refusal), True."""
        if math.isfinite(quietly(self.values.dot, self._output_mask)):    # else every output is finite
            return False
        bad = self._nonfinite_output()
        if bad is None:
            return False
        self.values[self._output_slots] = held
        self._bad_output = f"{bad}: outputs held at their last values"
        if announce:
            self.log(f"{self.instance_name}: t = {self.time:.9g} s: {self._bad_output}", Fmi2Status.error)
        return True

"""The fast path: robofmu's export library serving the hot FMI calls of a slave itself.

Behind robofmu's export library the slave, once constructed, registers with it
(:data:`.contract.REGISTER`, with a :class:`.contract.FastShared` it owns: its ``values`` array,
which masks of slots are Real / Boolean / Real inputs / Real outputs, the flags
``_initialized``/``_terminated``, ``_dirty`` and ``_inputs_checked`` as shared fields, an
array for the values saved before a refresh, and :meth:`FastPath._fast_refresh`,
:meth:`FastPath._fast_step`, :meth:`FastPath._fast_nonfinite`, with a context in which
NumPy ignores floating-point errors, :func:`.quiet.quiet_context`). While initialized, that library then serves fmi2SetReal of
inputs, fmi2GetReal / fmi2GetBoolean and fmi2DoStep itself, calling only those methods (the
header comment of ``robofmu_fmi2.c``, point 4); all other calls still come to the slave
through pythonfmu. So ``values`` is never rebound.
"""
from __future__ import annotations

import _ctypes
import ctypes
import functools
import math
import operator
import os
from pathlib import Path

import numpy as np

from .contract import (FAST_CALLS, FAST_CHECK, FAST_GET_REAL, FAST_MESSAGES, FAST_OK, FAST_VERSION, PLATFORM,
                       REGISTER, REGISTER_PARAMETERS, STOCK_LIBRARY, FastShared)
from .quiet import quiet_context, quietly

__all__ = ["FastPath"]


class FastPath:
    """The slave's side of the fast path (a mixin of :class:`~.base.BlockSlave`): the flags it
    shares with the library, its registration and the three callables the library calls.

    Uses the slave's ``logic``, ``values``, ``time``, ``resources``, ``log_queue``, the slot
    masks of :class:`~.variables.Variables`, the outputs of :class:`~.outputs.Outputs`, the
    steps of :class:`~.lifecycle.LifeCycle` and the messages of :class:`~.reporting.Reporting`.
    """

    def _share_flags(self) -> None:
        """The struct the flags live in (before anything sets them) and the flags' start."""
        self._shared = FastShared(version=FAST_VERSION, size=ctypes.sizeof(FastShared))
        self._initialized_flag = self._terminated_flag = False
        self.fast_path = False          # whether robofmu's export library serves the hot calls

    # Read in the hot path: getters without a Python frame (1 / 0 for the shared int32 fields).
    def _set_dirty(self, value) -> None:
        self._shared.dirty = 1 if value else 0

    def _set_inputs_checked(self, value) -> None:
        self._shared.inputs_checked = 1 if value else 0

    def _set_initialized(self, value) -> None:
        self._initialized_flag = bool(value)
        self._shared.active = int(self._initialized_flag and not self._terminated_flag)

    def _set_terminated(self, value) -> None:
        self._terminated_flag = bool(value)
        self._shared.active = int(self._initialized_flag and not self._terminated_flag)

    _dirty = property(operator.attrgetter("_shared.dirty"), _set_dirty,
                      doc="The outputs are stale: inputs or time changed since they were computed.")
    _inputs_checked = property(operator.attrgetter("_shared.inputs_checked"), _set_inputs_checked,
                               doc="The current inputs were found finite (reset by any set).")
    _initialized = property(operator.attrgetter("_initialized_flag"), _set_initialized)
    _terminated = property(operator.attrgetter("_terminated_flag"), _set_terminated)

    def _prepare_fast_path(self) -> None:
        """What the library reads besides the values (the masks, an array to save the values
        into before a refresh), and the block's calls NumPy-quiet until the library makes
        them so (:meth:`_register_fast_path`)."""
        self._fast_masks = [np.ascontiguousarray(mask, dtype=np.uint8) for mask in
                            (self._real, self._boolean, self._input_real, self._output_mask != 0.0)]
        self._saved = np.zeros(len(self.values))     # the values before a refresh (the library writes it)
        self._output_now = functools.partial(quietly, self.logic.output)
        self._advance_now = functools.partial(quietly, self.logic.advance)

    def _register_fast_path(self) -> bool:
        """Register with robofmu's export library of this instance's FMU, the one the importer
        loaded from its ``binaries/linux64`` (already loaded: found with RTLD_NOLOAD, the handle
        closed again after). It accepts only inside its fmi2Instantiate (or fmi2Reset) of this
        instance; True if it did."""
        values = self.values
        if values.dtype != np.float64 or not values.flags.c_contiguous or not values.flags.writeable:
            return False
        shared = self._shared
        shared.values = values.ctypes.data
        shared.n = values.size
        shared.get_real, shared.get_boolean, shared.set_real, shared.output = (m.ctypes.data for m in self._fast_masks)
        shared.saved = self._saved.ctypes.data
        self._quiet = quiet_context()     # alive as long as the slave: the library holds its address
        folder = Path(self.resources).parent / "binaries" / PLATFORM
        for path in sorted(folder.glob("*.so")):
            if path.name == STOCK_LIBRARY:
                continue
            try:
                library = ctypes.PyDLL(str(path), mode=os.RTLD_NOLOAD)
            except OSError:
                continue            # not loaded in this process: not the importer's library
            try:
                register = getattr(library, REGISTER, None)
                if register is None:
                    continue
                register.restype = ctypes.c_int
                register.argtypes = [ctype for _, ctype, _ in REGISTER_PARAMETERS]
                # the quiet context as its address (None: NULL)
                if register(ctypes.addressof(shared), self._fast_refresh, self._fast_step, self._fast_nonfinite,
                            None if self._quiet is None else id(self._quiet)) == 1:
                    if self._quiet is not None:     # the library enters it around each call
                        self._output_now, self._advance_now = self.logic.output, self.logic.advance
                    return True
            finally:
                _ctypes.dlclose(library._handle)
        return False

    # The three callables the library calls (the slave initialized and not terminated). It has
    # saved the values into _saved before a refresh and entered the quiet context (NumPy's
    # error state as quietly() sets it) around each call. The usual case takes the shortest way; any other goes the way
    # of the FMI method (get_real's refresh, do_step), which decides and reports.
    def _fast_refresh(self) -> int:
        """refresh(): the outputs brought up to date as fmi2GetReal / fmi2GetBoolean
        (``_shared.call``) do here. Never raises: FAST_OK if it succeeded, +FAST_MESSAGES if
        messages wait in the log queue, +FAST_CHECK if it computed the outputs and leaves
        their check to the library (finite: the outputs are current; else it calls
        :meth:`_fast_nonfinite`)."""
        shared = self._shared
        try:
            if not shared.dirty:
                done = FAST_OK
            elif shared.inputs_checked:            # the usual case: _output_safely, the check in C
                try:
                    self._output_now(self.time)
                except Exception as exc:
                    self._output_failed(exc, self._saved[self._output_slots])
                    done = FAST_OK
                else:
                    if self._bad_output is not None:      # a read costs less than a write here
                        self._bad_output = None
                    done = FAST_OK | FAST_CHECK
            else:
                self._refresh()
                done = FAST_OK
        except BaseException as exc:    # nothing may reach the C caller
            self._report_failure(exc, FAST_CALLS.get(shared.call, FAST_CALLS[FAST_GET_REAL]))
            done = 0
        return (done | FAST_MESSAGES) if self.log_queue else done

    def _fast_nonfinite(self) -> int:
        """nonfinite(): the library found a non-finite output after :meth:`_fast_refresh`: the
        saved outputs held and the reason reported, as :meth:`_output_safely` does."""
        try:
            self._hold_nonfinite(self._saved[self._output_slots])
            done = FAST_OK
        except BaseException as exc:
            self._report_failure(exc, FAST_CALLS.get(self._shared.call, FAST_CALLS[FAST_GET_REAL]))
            done = 0
        return (done | FAST_MESSAGES) if self.log_queue else done

    def _fast_step(self, current_time: float, step_size: float) -> int:
        """step(t, h): :meth:`do_step`; returns as :meth:`_fast_refresh`. A block without
        feedthrough (its outputs depend on its state and time only) computes its outputs at
        t + h in the same call (:meth:`_fast_outputs`): the read that follows need not enter
        Python again."""
        shared = self._shared
        try:
            if (shared.inputs_checked and self._bad_output is None          # the usual case of do_step
                    and not (shared.dirty and self._feedthrough) and 0.0 < step_size < math.inf
                    and self._at_own_time(current_time)):
                try:
                    self._advance_now(current_time, step_size)
                except Exception as exc:
                    done = FAST_OK if self._step_failed(exc, current_time) else 0
                else:
                    self.time = current_time + step_size
                    if self._held_warned:
                        self._held_warned = False
                    shared.dirty = 1
                    done = FAST_OK if self._feedthrough else self._fast_outputs()
            else:
                done = FAST_OK if self._do_step(current_time, step_size) else 0
        except BaseException as exc:    # do_step catches every Exception; this the rest
            self._report_failure(exc, "fmi2DoStep")
            done = 0
        return (done | FAST_MESSAGES) if self.log_queue else done

    def _fast_outputs(self) -> int:
        """After a step of a block without feedthrough: its outputs at the new time, FAST_OK |
        FAST_CHECK (the library checks them; finite: they are current). If the block raises,
        the outputs the library saved before the step are back and they stay stale: the read
        that follows computes them again and reports as :meth:`_fast_refresh` does."""
        try:
            self._output_now(self.time)
        except Exception:
            slots = self._output_slots
            self.values[slots] = self._saved[slots]
            return FAST_OK
        return FAST_OK | FAST_CHECK

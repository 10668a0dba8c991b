"""The one pythonfmu slave of every robofmu block: a thin FMI wrapper over an FMI-free block.

The generated script of each FMU names the robot and the block kind; the slave builds that
block (:mod:`robofmu.components.blocks`) for the robot, registers its declared variables with
pythonfmu in declaration order (so a value reference is the block's slot in
:attr:`Block.values`, and a batched fmi2GetReal/fmi2SetReal is one NumPy indexing operation),
and maps the FMI life cycle onto the block's hooks:

- fmi2ExitInitializationMode -> ``configure()`` (invalid parameters fail naming the parameter);
- reading outputs -> ``output(t)``, lazily, whenever inputs or time changed;
- fmi2DoStep(t, h) -> ``advance(t, h)``; outputs then belong to t + h.

It turns exceptions into logged errors, works around pythonfmu 0.7.0 (docs/design.md), saves the
full internal state for fmi2GetFMUstate/fmi2SetFMUstate, and has the model description pythonfmu
writes completed by :mod:`.model_description`.

FMI statuses: in a robofmu FMU, robofmu's export library (``robofmu.system.fmi_export``) stands
in front of pythonfmu's and returns the status of every message logged with the category
:data:`STATUS_CATEGORY` from the FMI call it is logged in. So a refused step or invalid input
is fmi2Error (:meth:`BlockSlave.fail`, :meth:`BlockSlave._raise_to_importer`), and the instance
stays usable. Behind pythonfmu's library alone (its win64 one, or a slave used without a FMU)
only raising fails a call (fmi2Fatal), and a refused step is fmi2Discard.

The fast path: behind robofmu's export library the slave, once constructed, registers with it
(:class:`_FastShared`: its ``values`` array, which masks of slots are Real / Boolean / Real
inputs / Real outputs, the flags ``_initialized``/``_terminated``, ``_dirty`` and
``_inputs_checked`` as shared fields, an array for the values saved before a refresh, and
:meth:`BlockSlave._fast_refresh`, :meth:`BlockSlave._fast_step`,
:meth:`BlockSlave._fast_nonfinite`, with NumPy's error state, :data:`.quiet.ERROR_STATE`).
While initialized, that library then serves fmi2SetReal of inputs, fmi2GetReal /
fmi2GetBoolean and fmi2DoStep itself, calling only those methods (the header comment of
``robofmu_fmi2.c``, point 4); all other calls still come here through pythonfmu. So
``values`` is never rebound.
"""
from __future__ import annotations

import _ctypes
import ctypes
import functools
import json
import math
import operator
import os
import sys
import traceback
from pathlib import Path
from xml.etree.ElementTree import Element

import numpy as np
from pythonfmu import Boolean, Fmi2Slave, Integer, Real, String
from pythonfmu.default_experiment import DefaultExperiment
from pythonfmu.enums import Fmi2Causality, Fmi2Initial, Fmi2Status, Fmi2Variability

from .. import SOURCE_HASH, check_bundle
from ..blocks import StepRefused, block_type
from ..robots import load_description, load_model
from ..robots.description import read
from .model_description import PYTHON, VENDOR_TOOL, complete  # noqa: F401  (VENDOR_TOOL: public here)
from .quiet import ERROR_STATE, quietly

_CAUSALITY = {c.name: c for c in Fmi2Causality}
_VARIABILITY = {v.name: v for v in Fmi2Variability}
_INITIAL = {i.name: i for i in Fmi2Initial}
_PYTHONFMU_TYPES = {"Real": Real, "Boolean": Boolean, "Integer": Integer, "String": String}

#: A message logged with this category makes robofmu's export library return the message's
#: status from the FMI call (``robofmu.system.fmi_export.STATUS_CATEGORY``; the importer sees
#: pythonfmu's usual category, ``logStatusError``...).
STATUS_CATEGORY = "robofmu:status"
#: How a KeyboardInterrupt (Ctrl-C) raised in the block's Python code during an FMI call is
#: logged (with fmi2Error, the call abandoned): ``"<call> " + INTERRUPTION + " at t = ..."``.
#: The master reports a failed call whose message holds it as an interruption
#: (``robofmu.system.master``: the same text).
INTERRUPTION = "interrupted: KeyboardInterrupt (Ctrl-C) in the block's Python code"
#: A fmi2SetString value that is not valid UTF-8 reaches the slave as this prefix and the hex of
#: its bytes: what robofmu's export library is to forward instead of the raw bytes, which
#: pythonfmu 0.7.0 cannot convert (PyUnicode_FromString fails: fmi2Fatal, the instance damaged).
NOT_UTF8 = "\x1brobofmu:not-utf8:"
_PYTHONFMU_LIBRARY = "libpythonfmu-export.so"   # beside robofmu's in binaries/linux64


def _behind_robofmu_export(resources) -> bool:
    """Whether robofmu's export library stands in front of this instance: its FMU keeps
    pythonfmu's own library beside robofmu's in ``binaries/linux64`` (``robofmu.system.fmi_export``)."""
    return (bool(resources) and sys.platform.startswith("linux")
            and (Path(resources).parent / "binaries" / "linux64" / _PYTHONFMU_LIBRARY).is_file())


class _FastShared(ctypes.Structure):
    """What robofmu's export library reads and writes of a slave on its fast path
    (``robofmu_fmi2.c``: ``FastShared``, the same layout). The slave owns it and the arrays it
    points to, as long as it lives; the library uses it between fmi2Instantiate and
    fmi2FreeInstance only."""
    _fields_ = [("version", ctypes.c_uint32), ("size", ctypes.c_uint32),
                ("values", ctypes.c_void_p), ("n", ctypes.c_size_t),
                ("get_real", ctypes.c_void_p), ("get_boolean", ctypes.c_void_p), ("set_real", ctypes.c_void_p),
                ("output", ctypes.c_void_p), ("saved", ctypes.c_void_p),
                ("active", ctypes.c_int32), ("dirty", ctypes.c_int32), ("inputs_checked", ctypes.c_int32),
                ("call", ctypes.c_int32)]


_FAST_VERSION = 2                   # robofmu_fmi2.c: FAST_VERSION
_FAST_OK, _FAST_MESSAGES, _FAST_CHECK = 1, 2, 4     # what the _fast_* methods return, as bits
_FAST_CALLS = {1: "fmi2GetReal", 2: "fmi2GetBoolean"}       # FastShared.call


class _CallFailed(RuntimeError):
    """The current FMI call fails; its message has been logged."""


def _balance_pythonfmu_refcount(cls) -> None:
    """Work around pythonfmu 0.7.0's loader, which releases a reference it does not own to the
    script module's globals at every instantiation (``Py_DECREF`` of ``PyModule_GetDict``):
    without this the second instance of a FMU in one process finds its module emptied.
    The generated script keeps one extra reference (``_keepalive = globals()``); this adds back
    the one the loader takes. If a later pythonfmu fixes the loader, this leaks one reference
    per instance, which is harmless."""
    module = sys.modules.get(cls.__module__)
    if module is not None and "_keepalive" in vars(module):
        ctypes.pythonapi.Py_IncRef(ctypes.py_object(module.__dict__))


class BlockSlave(Fmi2Slave):
    """The FMU of one block of one robot; the generated script sets ``robot_name`` and ``block_kind``."""

    robot_name: str = ""
    block_kind: str = ""

    def __init__(self, **kwargs):
        self._shared = _FastShared(version=_FAST_VERSION, size=ctypes.sizeof(_FastShared))   # the flags live here
        self._initialized_flag = self._terminated_flag = False
        self.fast_path = False          # whether robofmu's export library serves the hot calls
        super().__init__(**kwargs)
        self._statuses = _behind_robofmu_export(self.resources)     # see _fmi_entry
        _balance_pythonfmu_refcount(type(self))
        if self.resources:
            check_bundle(self.resources)
        if not self.robot_name or not self.block_kind:
            raise TypeError(f"{type(self).__name__}: robot_name and block_kind must be set")
        description = self._own_description()
        self.logic = block_type(description, self.block_kind)(load_model(description))
        self.logic.logger = self._log_from_block
        self.author = "robofmu"
        self.version = f"0.1.0+{SOURCE_HASH[:12]}"
        self.description = (f"robofmu {self.block_kind} block of robot '{self.robot_name}': {self.logic.summary}. "
                            f"Runs in Python {PYTHON} with the packages of resources/requirements.txt")
        self.default_experiment = DefaultExperiment(start_time=0.0, stop_time=self.logic.nominal_stop_time(),
                                                    step_size=1e-3)
        self.time = 0.0
        self._dirty = True
        self._inputs_checked = False
        self._initialized = False
        self._terminated = False
        self._held_warned = False
        self._bad_output: str | None = None     # why the outputs are held (the next step fails)
        for var in self.logic.variables:
            self._register(var)
        self.values = self.logic.values
        kinds = np.array([v.kind for v in self.logic.variables])
        causalities = np.array([v.causality for v in self.logic.variables])
        self._real = kinds == "Real"
        self._input_real = self._real & (causalities == "input")      # settable once initialized
        self._settable_real = self._input_real | (self._real & (causalities == "parameter"))
        self._input_vrs = np.flatnonzero(self._input_real)
        self._input_mask = self._input_real.astype(float)
        self._output_slots = np.flatnonzero(self._real & (causalities == "output"))
        self._held = np.empty(len(self._output_slots))      # outputs kept while new ones are computed
        self._output_mask = np.zeros(len(kinds))
        self._output_mask[self._output_slots] = 1.0
        self._parameter_slots = np.flatnonzero(self._real & (causalities == "parameter"))
        self._indices: dict[tuple, np.ndarray] = {}
        self._names = [v.name for v in self.logic.variables]
        self._feedthrough = self.logic.feedthrough   # outputs that depend on inputs (else on state only)
        self._fast_masks = [np.ascontiguousarray(mask, dtype=np.uint8) for mask in
                            (self._real, kinds == "Boolean", self._input_real, self._output_mask != 0.0)]
        self._saved = np.zeros(len(kinds))     # the fast path: values before a refresh (the library writes it)
        self._output_now = functools.partial(quietly, self.logic.output)      # see _register_fast_path
        self._advance_now = functools.partial(quietly, self.logic.advance)
        if self._statuses:
            self.fast_path = self._register_fast_path()       # last: the instance is complete

    # -- the flags robofmu's export library shares (the module docstring: the fast path) --------
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
        quiet_var, quiet_value = ERROR_STATE if ERROR_STATE is not None else (None, None)
        folder = Path(self.resources).parent / "binaries" / "linux64"
        for path in sorted(folder.glob("*.so")):
            if path.name == _PYTHONFMU_LIBRARY:
                continue
            try:
                library = ctypes.PyDLL(str(path), mode=os.RTLD_NOLOAD)
            except OSError:
                continue            # not loaded in this process: not the importer's library
            try:
                register = getattr(library, "robofmu_fast_register", None)
                if register is None:
                    continue
                register.restype = ctypes.c_int
                register.argtypes = [ctypes.c_void_p] + [ctypes.py_object] * 3 + [ctypes.c_void_p] * 2
                # NumPy's error state as the objects' addresses (None: NULL); alive as module globals
                if register(ctypes.addressof(shared), self._fast_refresh, self._fast_step, self._fast_nonfinite,
                            None if quiet_var is None else id(quiet_var),
                            None if quiet_value is None else id(quiet_value)) == 1:
                    if quiet_var is not None:       # the library sets NumPy's error state around each call
                        self._output_now, self._advance_now = self.logic.output, self.logic.advance
                    return True
            finally:
                _ctypes.dlclose(library._handle)
        return False

    # The three callables the library calls (the slave initialized and not terminated). It has
    # saved the values into _saved before a refresh and set NumPy's error state, as quietly()
    # does, around each call. The usual case takes the shortest way; any other goes the way
    # of the FMI method (get_real's refresh, do_step), which decides and reports.
    def _fast_refresh(self) -> int:
        """refresh(): the outputs brought up to date as fmi2GetReal / fmi2GetBoolean
        (``_shared.call``) do here. Never raises: _FAST_OK if it succeeded, +_FAST_MESSAGES if
        messages wait in the log queue, +_FAST_CHECK if it computed the outputs and leaves
        their check to the library (finite: the outputs are current; else it calls
        :meth:`_fast_nonfinite`)."""
        shared = self._shared
        try:
            if not shared.dirty:
                done = _FAST_OK
            elif shared.inputs_checked:            # the usual case: _output_safely, the check in C
                try:
                    self._output_now(self.time)
                except Exception as exc:
                    self._output_failed(exc, self._saved[self._output_slots])
                    done = _FAST_OK
                else:
                    self._bad_output = None
                    done = _FAST_OK | _FAST_CHECK
            else:
                self._refresh()
                done = _FAST_OK
        except BaseException as exc:    # nothing may reach the C caller
            self._report_failure(exc, _FAST_CALLS.get(shared.call, "fmi2GetReal"))
            done = 0
        return (done | _FAST_MESSAGES) if self.log_queue else done

    def _fast_nonfinite(self) -> int:
        """nonfinite(): the library found a non-finite output after :meth:`_fast_refresh`: the
        saved outputs held and the reason reported, as :meth:`_output_safely` does."""
        try:
            self._hold_nonfinite(self._saved[self._output_slots])
            done = _FAST_OK
        except BaseException as exc:
            self._report_failure(exc, _FAST_CALLS.get(self._shared.call, "fmi2GetReal"))
            done = 0
        return (done | _FAST_MESSAGES) if self.log_queue else done

    def _fast_step(self, current_time: float, step_size: float) -> int:
        """step(t, h): :meth:`do_step`; returns as :meth:`_fast_refresh`."""
        shared = self._shared
        try:
            if (shared.inputs_checked and self._bad_output is None          # the usual case of do_step
                    and not (shared.dirty and self._feedthrough) and 0.0 < step_size < math.inf
                    and self._at_own_time(current_time)):
                try:
                    self._advance_now(current_time, step_size)
                except Exception as exc:
                    done = _FAST_OK if self._step_failed(exc, current_time) else 0
                else:
                    self.time = current_time + step_size
                    self._held_warned = False
                    shared.dirty = 1
                    done = _FAST_OK
            else:
                done = _FAST_OK if self._do_step(current_time, step_size) else 0
        except BaseException as exc:    # do_step catches every Exception; this the rest
            self._report_failure(exc, "fmi2DoStep")
            done = 0
        return (done | _FAST_MESSAGES) if self.log_queue else done

    def _report_failure(self, exc: BaseException, call: str) -> None:
        """Log the exception that failed ``call`` (a _CallFailed is logged already); a
        KeyboardInterrupt as an interruption (:data:`INTERRUPTION`), which the master recognizes."""
        if isinstance(exc, KeyboardInterrupt):
            self._report(f"{call} {INTERRUPTION} at t = {self.time:.9g} s; the call is abandoned")
        elif not isinstance(exc, _CallFailed):
            self._report(f"{call} failed: {type(exc).__name__}: {exc}\n{traceback.format_exc()}")

    def _own_description(self):
        """The robot's description from this FMU's own resources folder.

        All pythonfmu FMUs of a process share one interpreter, so the robofmu package is the one
        imported first, perhaps from another FMU's extraction folder that its importer has since
        deleted. Robot data (TOML, URDF) is therefore read from this instance's own folder, which
        lives as long as the instance."""
        if not self.resources:
            return load_description(self.robot_name)
        return read(Path(self.resources) / "robofmu" / "components" / "robots" / self.robot_name
                    / f"{self.robot_name}.toml")

    # -- variables --------------------------------------------------------------------------------
    def _register(self, v) -> None:
        """Register one declared variable with pythonfmu; its value reference is its slot."""
        slot = len(self.vars)
        if self.logic.variables[slot] is not v:
            raise TypeError(f"{v.name}: value reference {slot} is not its slot")
        values, settings = self.logic.values, self.logic.settings
        setter = None
        if v.kind == "Real":
            getter = lambda k=slot: float(values[k])
        elif v.kind == "Boolean":
            getter = lambda k=slot: bool(values[k])
        else:
            getter = lambda name=v.name: settings[name]
        if v.causality in ("input", "parameter") and v.kind != "Real":   # Reals go through set_real
            def setter(value, k=slot, name=v.name, kind=v.kind, causality=v.causality):
                if causality == "parameter" and self._initialized:
                    self._raise_to_importer(f"cannot set parameter {name}: parameters are fixed "
                                            "once initialized")
                if kind == "Boolean":
                    values[k] = float(bool(value))
                else:
                    settings[name] = value
                self._dirty = True
                self._inputs_checked = False
        variability = "fixed" if v.causality == "parameter" else (
            "continuous" if v.kind == "Real" else "discrete")
        initial = {"parameter": "exact", "output": "calculated"}.get(v.causality)
        var = _PYTHONFMU_TYPES[v.kind](
            v.name, causality=_CAUSALITY[v.causality], description=v.description,
            variability=_VARIABILITY[variability], initial=_INITIAL[initial] if initial else None,
            getter=getter, setter=setter)
        if v.causality in ("input", "parameter"):
            var.start = v.start
        self.register_variable(var)

    def _log_from_block(self, level: str, text: str) -> None:
        status = Fmi2Status.warning if level == "warning" else Fmi2Status.error
        self.log(f"{self.instance_name}: {text}", status)

    # -- FMI value access -----------------------------------------------------------------------
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

    def _index(self, vrs, allowed: np.ndarray, call: str) -> np.ndarray:
        """Value references as an index array, checked once per distinct list (importers batch
        the same references at every step)."""
        key = (id(allowed), *vrs)
        index = self._indices.get(key)
        if index is None:
            index = np.asarray(vrs, dtype=np.intp)
            size = len(self.values)
            if index.size and (index.min() < 0 or index.max() >= size or not allowed[index].all()):
                bad = [self._names[v] if 0 <= v < size else v for v in vrs
                       if not (0 <= v < size) or not allowed[v]]
                if allowed is self._real:
                    wanted = "Real variables"
                elif self._initialized:
                    wanted = "Real inputs (parameters are fixed once initialized)"
                else:
                    wanted = "Real inputs or parameters"
                self._raise_to_importer(f"{call}: value references of {bad} do not name {wanted}")
            self._indices[key] = index
        return index

    def get_real(self, vrs):
        if self._dirty:
            self._refresh()
        return self.values[self._index(vrs, self._real, "fmi2GetReal")].tolist()

    def set_real(self, vrs, values):
        allowed = self._input_real if self._initialized else self._settable_real
        self.values[self._index(vrs, allowed, "fmi2SetReal")] = values
        shared = self._shared           # _dirty, _inputs_checked
        shared.dirty = 1
        shared.inputs_checked = 0

    def _check_kind(self, vrs, kind: str, call: str, setting: bool = False) -> None:
        """Refuse value references that are not ``kind`` variables (or, when ``setting``, not
        settable now), naming the variables."""
        bad = []
        for vr in vrs:
            if not 0 <= vr < len(self.values):
                bad.append(vr)
                continue
            var = self.logic.variables[vr]
            if setting and var.kind == kind and var.causality == "parameter" and self._initialized:
                self._raise_to_importer(f"cannot set parameter {var.name}: parameters are fixed once initialized")
            if var.kind != kind or (setting and var.causality == "output"):
                bad.append(var.name)
        if bad:
            wanted = f"settable {kind} variables" if setting else f"{kind} variables"
            self._raise_to_importer(f"{call}: value references of {bad} do not name {wanted}")

    def get_boolean(self, vrs):
        self._check_kind(vrs, "Boolean", "fmi2GetBoolean")
        if self._dirty:
            self._refresh()
        return super().get_boolean(vrs)

    def set_boolean(self, vrs, values):
        self._check_kind(vrs, "Boolean", "fmi2SetBoolean", setting=True)
        super().set_boolean(vrs, values)

    def get_integer(self, vrs):
        self._check_kind(vrs, "Integer", "fmi2GetInteger")
        return super().get_integer(vrs)

    def set_integer(self, vrs, values):
        self._check_kind(vrs, "Integer", "fmi2SetInteger", setting=True)
        super().set_integer(vrs, values)

    def get_string(self, vrs):
        self._check_kind(vrs, "String", "fmi2GetString")
        return super().get_string(vrs)

    def set_string(self, vrs, values):
        self._check_kind(vrs, "String", "fmi2SetString", setting=True)
        values = list(values)
        for k, (vr, value) in enumerate(zip(vrs, values)):      # all checked before any is set
            value, problem = _string_value(value)
            if problem is not None:
                var = self.logic.variables[vr]
                self._raise_to_importer(f"fmi2SetString: {var.causality} {var.name}: {problem}; nothing set")
            values[k] = value
        super().set_string(vrs, values)

    # -- helpers --------------------------------------------------------------------------------
    def fail(self, message: str, status: Fmi2Status = Fmi2Status.error) -> bool:
        """Refuse the step: log ``message``, return False. Behind robofmu's export library
        fmi2DoStep returns ``status`` (fmi2Error; fmi2Discard only where a smaller step could
        succeed and the importer retries), behind pythonfmu's alone fmi2Discard."""
        self._report(message, status)
        return False

    def _report(self, message: str, status: Fmi2Status = Fmi2Status.error) -> None:
        """Log ``message``; behind robofmu's export library the current FMI call returns ``status``."""
        self.log(f"{self.instance_name}: {message}", status, STATUS_CATEGORY if self._statuses else None)

    def warn(self, message: str) -> None:
        self.log(f"{self.instance_name}: {message}", Fmi2Status.warning)

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

    # -- FMI life cycle -----------------------------------------------------------------------------
    def setup_experiment(self, start_time: float, stop_time=None, tolerance=None):
        """fmi2SetupExperiment (``stop_time``, ``tolerance``: None when not defined). Refused,
        nothing set, each reason naming its argument: an initialized or terminated instance, a
        startTime that is not finite, a defined stopTime that is not finite or before startTime,
        a defined tolerance that is not finite or negative."""
        if self._initialized or self._terminated:
            self._raise_to_importer("fmi2SetupExperiment: the instance is already "
                                    + ("terminated" if self._terminated else "initialized"))
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
        if self._initialized or self._terminated:
            self._raise_to_importer("fmi2EnterInitializationMode: the instance is already "
                                    + ("terminated" if self._terminated else "initialized")
                                    + "; instantiate a new one")

    def exit_initialization_mode(self):
        if self._initialized or self._terminated:
            self._raise_to_importer("fmi2ExitInitializationMode: the instance is already "
                                    + ("terminated" if self._terminated else "initialized"))
        try:
            self.logic.configure()
            self.logic.output(self.time)
        except Exception as exc:
            self._raise_to_importer(f"initialization failed: {exc}")
        bad = self._nonfinite_output()
        if bad is not None:
            self._raise_to_importer(f"initialization failed: {bad}")
        self._initialized = True
        self._dirty = False

    def terminate(self):
        self._terminated = True

    def _raise_to_importer(self, message: str):
        """Log ``message`` as an error and abandon the current FMI call, which fails with
        fmi2Error behind robofmu's export library (the entry point returns normally, see
        :func:`_fmi_entry`) and with fmi2Fatal behind pythonfmu's alone."""
        self._report(message)
        raise _CallFailed(f"{self.instance_name}: {message}")

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

    def _output_safely(self) -> None:
        """Outputs at the current time from the current inputs; never a non-finite one: a
        non-finite input or output holds the previous outputs and makes the next step fail."""
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
            self._output_failed(exc, held)
            return
        if self._hold_nonfinite(held):
            return
        self._bad_output = None
        shared.dirty = 0                # _dirty

    def _output_failed(self, exc: Exception, held: np.ndarray) -> None:
        """Evaluating the outputs raised ``exc``: the ``held`` ones back, the reason reported."""
        self.values[self._output_slots] = held
        self._bad_output = f"evaluating outputs failed: {type(exc).__name__}: {exc}"
        self.log(f"{self.instance_name}: t = {self.time:.9g} s: {self._bad_output}\n"
                 f"{traceback.format_exc()}", Fmi2Status.error)

    def _hold_nonfinite(self, held: np.ndarray) -> bool:
        """If an output just computed is not finite: the ``held`` ones back, the reason
        reported, True."""
        if math.isfinite(quietly(self.values.dot, self._output_mask)):    # else every output is finite
            return False
        bad = self._nonfinite_output()
        if bad is None:
            return False
        self.values[self._output_slots] = held
        self._bad_output = f"{bad}: outputs held at their last values"
        self.log(f"{self.instance_name}: t = {self.time:.9g} s: {self._bad_output}", Fmi2Status.error)
        return True

    def _at_own_time(self, t: float) -> bool:
        """Whether a step from ``t`` continues from the instance's time (to 1e-9 s, relative
        beyond 1 s; False for a non-finite ``t``)."""
        return abs(t - self.time) <= 1e-9 * max(1.0, abs(self.time))

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
            if self._feedthrough and shared.dirty:
                self._output_safely()          # the state a feedthrough block keeps (IK's last solution)
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
        """The block's advance raised ``exc``: the step refused with its reason (False)."""
        if isinstance(exc, StepRefused):
            return self.fail(str(exc))
        return self.fail(f"step from t = {current_time:.9g} s failed: {type(exc).__name__}: {exc}\n"
                         f"{traceback.format_exc()}")

    # -- FMU state ------------------------------------------------------------------------------------
    def _identity(self) -> dict:
        return {"robot": self.robot_name, "block": self.block_kind, "variant": self.logic.variant,
                "source": SOURCE_HASH}

    def _parameters(self) -> dict:
        values = {self._names[k]: float(self.values[k]) for k in self._parameter_slots}
        values.update({v.name: self.logic.settings[v.name] for v in self.logic.variables
                       if v.causality == "parameter" and v.kind != "Real"})
        return values

    def _get_fmu_state(self):
        return {"identity": self._identity(), "parameters": self._parameters(), "time": self.time,
                "values": self.values.tolist(), "settings": dict(self.logic.settings),
                "dirty": bool(self._dirty), "initialized": self._initialized, "terminated": self._terminated,
                "bad_output": self._bad_output, "logic": self.logic.internal_state()}

    def _state_problem(self, state) -> str | None:
        """Why ``state`` cannot be restored into this instance, or None."""
        keys = {"identity", "parameters", "time", "values", "settings", "dirty", "initialized",
                "terminated", "bad_output", "logic"}
        if isinstance(state, dict) and set(state) == {"corrupt"}:
            return str(state["corrupt"])
        if not isinstance(state, dict) or set(state) != keys:
            return "the state is not a robofmu block state (corrupt or from another FMU)"
        theirs, mine = state["identity"], self._identity()
        if theirs != mine:
            what = [f"{k} {theirs.get(k)!r} (this instance: {mine[k]!r})" for k in mine if theirs.get(k) != mine[k]]
            return "the state belongs to another block: " + ", ".join(what)
        values = state["values"]
        if (not isinstance(values, list) or len(values) != len(self.values)
                or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)):
            return "the state's values are corrupt"
        if not math.isfinite(sum(float(v) for v in values)) or not isinstance(state["time"], (int, float)) \
                or not math.isfinite(state["time"]):
            return "the state holds non-finite values"
        if self._initialized and state["initialized"] and state["parameters"] != self._parameters():
            mine_p = self._parameters()
            differ = [f"{k} = {v!r} (this instance: {mine_p.get(k)!r})" for k, v in state["parameters"].items()
                      if mine_p.get(k) != v]
            return "the state was saved with other parameters: " + ", ".join(differ[:4])
        return None

    def _set_fmu_state(self, state):
        problem = self._state_problem(state)
        if problem is not None:
            self._raise_to_importer(f"fmi2SetFMUstate: {problem}; nothing restored")
        saved = self._get_fmu_state()
        try:
            self._apply_state(state)
        except Exception as exc:
            self._apply_state(saved)
            self._raise_to_importer(f"fmi2SetFMUstate: {type(exc).__name__}: {exc}; nothing restored")

    def _apply_state(self, state) -> None:
        self.time = float(state["time"])
        self.values[:] = state["values"]
        self.logic.settings.update(state["settings"])
        self._dirty = bool(state["dirty"])
        self._inputs_checked = False
        self._initialized = bool(state["initialized"])
        self._terminated = bool(state["terminated"])
        self._bad_output = state["bad_output"]
        self.logic.set_internal_state(state["logic"])

    @staticmethod
    def _fmu_state_from_bytes(data: bytes):
        """A serialized state back. pythonfmu calls this on the class, so it cannot log: a
        corrupt state comes back as a marker that fmi2SetFMUstate refuses, naming the cause."""
        try:
            return json.loads(bytes(data).decode("utf-8"))
        except (ValueError, UnicodeDecodeError) as exc:
            return {"corrupt": f"the serialized state is corrupt ({exc})"}

    # -- model description ----------------------------------------------------------------------------
    def to_xml(self, model_options=dict()) -> Element:
        """pythonfmu's model description, completed (see :mod:`.model_description`)."""
        return complete(super().to_xml(model_options), self.logic, self.robot_name, self.block_kind)


def _string_value(value) -> tuple:
    """``(value, problem)`` for a fmi2SetString value: the value to set (a string robofmu's
    export library forwarded as :data:`NOT_UTF8` and hex, decoded where it is valid UTF-8 after
    all), and why it cannot be set, or None."""
    if value is None:
        return value, "no value (a NULL string)"
    if isinstance(value, str) and value.startswith(NOT_UTF8):
        try:
            raw = bytes.fromhex(value[len(NOT_UTF8):])
        except ValueError:
            return value, "the value is not valid UTF-8"
        try:
            return raw.decode("utf-8"), None
        except UnicodeDecodeError as exc:
            bad = raw[exc.start:exc.end].hex(" ")
            shown = repr(raw[:40]) + ("..." if len(raw) > 40 else "")
            return value, (f"the value {shown} ({len(raw)} bytes) is not valid UTF-8: {exc.reason} at byte "
                           f"{exc.start} ({bad})")
    if isinstance(value, str):
        try:
            value.encode("utf-8")
        except UnicodeEncodeError as exc:
            return value, f"the value {value[:40]!r} is not valid UTF-8: {exc.reason} at character {exc.start}"
    return value, None


def _keep_for_pythonfmu_handler(slave) -> None:
    """pythonfmu 0.7.0's exception handler releases the instance, its class and its log queue
    once more than it took them (and again when the instance is freed): take those references
    before an exception reaches it, so that freeing the instance later does not crash."""
    for obj in (slave, slave.log_queue, type(slave)):
        ctypes.pythonapi.Py_IncRef(ctypes.py_object(obj))


def _fmi_entry(method, fallback, call: str):
    """``method``, as pythonfmu's library calls it for the FMI function ``call``.

    Behind robofmu's export library a failure (:meth:`BlockSlave._raise_to_importer`, or any
    exception, then logged with its traceback) returns ``fallback(*args)``: the logged
    :data:`STATUS_CATEGORY` message makes the call return fmi2Error, and the instance stays
    usable. Behind pythonfmu's library alone the exception propagates (fmi2Fatal), after the
    references its handler drops are taken."""
    @functools.wraps(method)
    def entry(self, *args):
        try:
            return method(self, *args)
        except BaseException as exc:    # a KeyboardInterrupt too: an interruption (_report_failure)
            self._report_failure(exc, call)
            if not self._statuses:
                _keep_for_pythonfmu_handler(self)
                raise
        return fallback(*args)
    return entry


_NOTHING = lambda *args: None  # noqa: E731
for _name, _call, _fallback in [
        ("setup_experiment", "fmi2SetupExperiment", _NOTHING),
        ("enter_initialization_mode", "fmi2EnterInitializationMode", _NOTHING),
        ("exit_initialization_mode", "fmi2ExitInitializationMode", _NOTHING),
        ("terminate", "fmi2Terminate", _NOTHING),
        ("do_step", "fmi2DoStep", lambda *args: False),
        ("get_real", "fmi2GetReal", lambda vrs: [0.0] * len(vrs)),      # with fmi2Error; no NaN leaves
        ("get_integer", "fmi2GetInteger", lambda vrs: [0] * len(vrs)),
        ("get_boolean", "fmi2GetBoolean", lambda vrs: [False] * len(vrs)),
        ("get_string", "fmi2GetString", lambda vrs: [""] * len(vrs)),
        ("set_real", "fmi2SetReal", _NOTHING),
        ("set_integer", "fmi2SetInteger", _NOTHING),
        ("set_boolean", "fmi2SetBoolean", _NOTHING),
        ("set_string", "fmi2SetString", _NOTHING),
        ("_get_fmu_state", "fmi2GetFMUstate", _NOTHING),
        ("_set_fmu_state", "fmi2SetFMUstate", _NOTHING)]:
    setattr(BlockSlave, _name, _fmi_entry(getattr(BlockSlave, _name), _fallback, _call))
# The fast path's step calls do_step unwrapped: _fast_step itself catches, logs and fails.
BlockSlave._do_step = BlockSlave.do_step.__wrapped__

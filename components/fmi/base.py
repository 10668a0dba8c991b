"""The common pythonfmu slave of every robofmu block.

A block declares its variables (name, causality, SI unit, description, the inputs an output
depends on) and implements three hooks:

- ``initialize()``: read and validate parameters (raise ValueError naming the parameter), build
  the FMI-free logic, compute the outputs at the start time;
- ``evaluate()``: direct-feedthrough blocks only: outputs from the current inputs;
- ``step(t, h)``: advance internal state from t to t + h and set the outputs at t + h.

All Real values live in one float array indexed by value reference, so that a batched
fmi2GetReal/fmi2SetReal is one NumPy indexing operation. The base completes the model
description pythonfmu writes (units, InitialUnknowns, output dependencies), turns exceptions
into logged errors, and saves the full internal state for fmi2GetFMUstate/fmi2SetFMUstate.
"""
from __future__ import annotations

import ctypes
import math
import sys
import traceback
from dataclasses import dataclass
from xml.etree.ElementTree import Element, SubElement

import numpy as np
from pythonfmu import Boolean, Fmi2Slave, Integer, Real, String
from pythonfmu.default_experiment import DefaultExperiment
from pythonfmu.enums import Fmi2Causality, Fmi2Initial, Fmi2Status, Fmi2Variability

from .. import SOURCE_HASH, check_bundle
from ..robot import load_spec
from ..trajectory import WaypointTrajectory

#: SI base-unit exponents of every unit a block may use (FMI 2.0 UnitDefinitions).
UNITS = {
    "1": {},
    "s": {"s": 1},
    "m": {"m": 1},
    "m/s": {"m": 1, "s": -1},
    "m/s2": {"m": 1, "s": -2},
    "rad": {"rad": 1},
    "rad/s": {"rad": 1, "s": -1},
    "rad/s2": {"rad": 1, "s": -2},
    "kg": {"kg": 1},
    "N": {"kg": 1, "m": 1, "s": -2},
    "N.m": {"kg": 1, "m": 2, "s": -2},
    "1/s2": {"s": -2},
    "1/s": {"s": -1},
    "1/s3": {"s": -3},
}

#: A coordinate's unit -> the units of it and its first two time derivatives.
DERIVATIVE_UNITS = {"m": ("m", "m/s", "m/s2"), "rad": ("rad", "rad/s", "rad/s2")}

_CAUSALITY = {c.name: c for c in Fmi2Causality}
_VARIABILITY = {v.name: v for v in Fmi2Variability}
_INITIAL = {i.name: i for i in Fmi2Initial}


@dataclass
class Var:
    """What the model description says of one variable, beyond pythonfmu's attributes."""

    name: str
    vr: int
    kind: str                      # Real, Boolean, Integer, String
    causality: str
    unit: str | None = None
    depends: list[str] | None = None   # outputs: the inputs they depend on (None: not declared)
    initial_depends: list[str] | None = None  # outputs: knowns they depend on at initialization
    description: str = ""


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
    """Base of every robofmu block FMU; subclasses set ``block`` and the script sets ``robot_name``."""

    robot_name: str = ""
    block: str = ""
    feedthrough: bool = False
    summary: str = ""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        _balance_pythonfmu_refcount(type(self))
        if self.resources:
            check_bundle(self.resources)
        if not self.robot_name:
            raise TypeError(f"{type(self).__name__}: robot_name is not set")
        self.spec = load_spec(self.robot_name)
        self.author = "robofmu"
        self.version = f"0.1.0+{SOURCE_HASH[:12]}"
        self.description = f"robofmu {self.block} block of robot '{self.robot_name}': {self.summary}"
        scenario_end = WaypointTrajectory.from_scenario(self.spec.scenario).duration if self.spec.scenario else None
        self.default_experiment = DefaultExperiment(start_time=0.0, stop_time=scenario_end, step_size=1e-3)
        self.meta: dict[str, Var] = {}
        self._starts: list[float] = []
        self._kinds: list[str] = []
        self._causalities: list[str] = []
        self.other: dict[str, object] = {}   # non-Real values by name
        self.time = 0.0
        self._dirty = True
        self._initialized = False
        self._held_warned = False
        self.declare()
        n = len(self._starts)
        self.r = np.array(self._starts, dtype=float)
        kinds = np.array(self._kinds)
        caus = np.array(self._causalities)
        self._real = kinds == "Real"
        self._input_real = self._real & (caus == "input")          # settable once initialized
        self._settable_real = self._input_real | (self._real & (caus == "parameter"))
        self._input_vrs = np.flatnonzero(self._input_real)
        self._input_mask = self._input_real.astype(float)
        self._indices: dict[tuple, np.ndarray] = {}
        self._names = [None] * n
        for v in self.meta.values():
            self._names[v.vr] = v.name

    # -- declaration helpers -------------------------------------------------------------------
    def declare(self) -> None:  # pragma: no cover - every block overrides it
        raise NotImplementedError

    def _register(self, var, kind: str, causality: str, start, unit, description, depends,
                  initial_depends=None):
        self.register_variable(var)
        vr = var.value_reference
        self.meta[var.name] = Var(var.name, vr, kind, causality, unit, depends, initial_depends,
                                  description)
        self._starts.append(float(start) if kind == "Real" else 0.0)
        self._kinds.append(kind)
        self._causalities.append(causality)
        return vr

    def real(self, name: str, causality: str, unit: str, description: str, start: float = 0.0,
             depends: list[str] | None = None, initial_depends: list[str] | None = None) -> int:
        """Declare a Real; returns its value reference."""
        if unit not in UNITS:
            raise KeyError(f"unit {unit!r} missing from UNITS")
        vr_next = len(self.vars)
        getter = lambda vr=vr_next: float(self.r[vr])
        setter = None
        if causality in ("input", "parameter"):
            def setter(value, vr=vr_next):
                self.r[vr] = value
                self._dirty = True
        variability = "fixed" if causality == "parameter" else "continuous"
        initial = None
        if causality == "parameter":
            initial = "exact"
        elif causality == "output":
            initial = "calculated"
        var = Real(name, causality=_CAUSALITY[causality], description=description,
                   variability=_VARIABILITY[variability],
                   initial=_INITIAL[initial] if initial else None, getter=getter, setter=setter)
        if causality in ("input", "parameter"):
            var.start = float(start)
        return self._register(var, "Real", causality, start, unit, description, depends, initial_depends)

    def reals(self, base: str, n: int, causality: str, units, description: str, starts=None,
              depends=None, initial_depends=None) -> slice:
        """Declare ``base[1]`` .. ``base[n]`` (contiguous value references); returns their slice.

        ``units`` is one unit or one per element; ``description`` may use ``{i}`` (1-based) or
        be a callable of i;
        ``depends``/``initial_depends`` are lists of names, or callables of i giving them.
        """
        units = [units] * n if isinstance(units, str) else list(units)
        starts = [0.0] * n if starts is None else list(starts)
        first = len(self.vars)
        for i in range(1, n + 1):
            dep = depends(i) if callable(depends) else depends
            idep = initial_depends(i) if callable(initial_depends) else initial_depends
            text = description(i) if callable(description) else description.format(i=i)
            self.real(f"{base}[{i}]", causality, units[i - 1], text, starts[i - 1], dep, idep)
        return slice(first, first + n)

    def _other(self, cls, kind, name, causality, description, start, variability, depends=None,
               initial_depends=None):
        self.other[name] = start
        getter = lambda: self.other[name]
        setter = None
        if causality in ("input", "parameter"):
            def setter(value):
                if causality == "parameter" and self._initialized:
                    self._raise_to_importer(f"cannot set parameter {name}: parameters are fixed "
                                            "once initialized")
                self.other[name] = value
                self._dirty = True
        initial = {"parameter": "exact", "output": "calculated"}.get(causality)
        var = cls(name, causality=_CAUSALITY[causality], description=description,
                  variability=_VARIABILITY[variability],
                  initial=_INITIAL[initial] if initial else None, getter=getter, setter=setter)
        if causality in ("input", "parameter"):
            var.start = start
        return self._register(var, kind, causality, 0.0, None, description, depends, initial_depends)

    def boolean(self, name, causality, description, start=False, depends=None, initial_depends=None):
        return self._other(Boolean, "Boolean", name, causality, description, bool(start),
                           "discrete" if causality != "parameter" else "fixed", depends, initial_depends)

    def integer(self, name, description, start=0):
        return self._other(Integer, "Integer", name, "parameter", description, int(start), "fixed")

    def string(self, name, description, start=""):
        return self._other(String, "String", name, "parameter", description, str(start), "fixed")

    # -- FMI value access -----------------------------------------------------------------------
    def _refresh(self) -> None:
        """Bring outputs up to date: from the inputs (feedthrough blocks) or, during
        initialization mode, from the parameters and inputs set so far (FMI 2.0 lets an
        importer read calculated outputs before fmi2ExitInitializationMode)."""
        if self._initialized:
            if self.feedthrough:
                self._evaluate_safely()
            return
        try:
            self.initialize()
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
            if index.size and (index.min() < 0 or index.max() >= len(self.r) or not allowed[index].all()):
                bad = [self._names[v] if 0 <= v < len(self.r) else v for v in vrs
                       if not (0 <= v < len(self.r)) or not allowed[v]]
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
        return self.r[self._index(vrs, self._real, "fmi2GetReal")].tolist()

    def set_real(self, vrs, values):
        allowed = self._input_real if self._initialized else self._settable_real
        self.r[self._index(vrs, allowed, "fmi2SetReal")] = values
        self._dirty = True

    def get_boolean(self, vrs):
        if self._dirty:
            self._refresh()
        return super().get_boolean(vrs)

    # -- helpers for subclasses -----------------------------------------------------------------
    def fail(self, message: str) -> bool:
        """Log ``message`` as an error through the FMI logger; returns False (step refused)."""
        self.log(f"{self.instance_name}: {message}", Fmi2Status.error)
        return False

    def warn(self, message: str) -> None:
        self.log(f"{self.instance_name}: {message}", Fmi2Status.warning)

    def nonfinite_input(self) -> str | None:
        """'name = value' of the first non-finite Real input, or None."""
        if math.isfinite(self.r.dot(self._input_mask)):    # fast path: nan and inf propagate
            return None
        values = self.r[self._input_vrs]
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size == 0:
            return None
        vr = self._input_vrs[bad[0]]
        return f"{self._names[vr]} = {self.r[vr]}"

    def param(self, name: str, low: float | None = None, high: float | None = None,
              low_inclusive: bool = True, unit: str = "") -> float:
        """A Real parameter's value, validated: ValueError naming it if out of range."""
        value = float(self.r[self.meta[name].vr])
        ok = math.isfinite(value)
        if ok and low is not None:
            ok = value >= low if low_inclusive else value > low
        if ok and high is not None:
            ok = value <= high
        if not ok:
            lo = "" if low is None else (">= " if low_inclusive else "> ") + f"{low:g}"
            hi = "" if high is None else f"<= {high:g}"
            rng = " and ".join(s for s in (lo, hi) if s) or "finite"
            raise ValueError(f"parameter {name} = {value:g}{' ' + unit if unit else ''} is invalid: must be {rng}")
        return value

    # -- hooks ------------------------------------------------------------------------------------
    def initialize(self) -> None:
        raise NotImplementedError

    def evaluate(self) -> None:
        """Direct-feedthrough blocks: compute outputs from the current inputs."""

    def step(self, t: float, h: float) -> bool:
        raise NotImplementedError

    def logic_state(self) -> dict:
        """Internal state beyond the variables (JSON-compatible)."""
        return {}

    def set_logic_state(self, state: dict) -> None:
        pass

    # -- FMI life cycle -----------------------------------------------------------------------------
    def setup_experiment(self, start_time: float, stop_time=None, tolerance=None):
        self.time = float(start_time)

    def exit_initialization_mode(self):
        try:
            self.initialize()
        except Exception as exc:
            self._raise_to_importer(f"initialization failed: {exc}")
        self._initialized = True
        self._dirty = True

    def _raise_to_importer(self, message: str):
        """Log ``message`` as an error, then make the current FMI call fail.

        pythonfmu 0.7.0 ignores return values outside doStep, so raising is the only way to
        return a non-OK status (it becomes fmi2Fatal). Its exception handler delivers the
        logged message, but drops the exception text ("unknown error") and releases the
        instance, its class and its log queue once more than it took them (they are released
        again when the instance is freed): take those references first, so that freeing the
        instance later does not crash the process.
        """
        self.log(f"{self.instance_name}: {message}", Fmi2Status.error)
        for obj in (self, self.log_queue, type(self)):
            ctypes.pythonapi.Py_IncRef(ctypes.py_object(obj))
        raise RuntimeError(f"{self.instance_name}: {message}")

    def _evaluate_safely(self) -> None:
        bad = self.nonfinite_input()
        if bad is not None:
            if not self._held_warned:
                self.warn(f"input {bad} at t = {self.time:.9g} s is not finite: outputs held at their "
                          "last values; the next step will fail")
                self._held_warned = True
            return
        try:
            self.evaluate()
            self._dirty = False
        except Exception as exc:
            self.log(f"{self.instance_name}: evaluating outputs at t = {self.time:.9g} s failed: "
                     f"{type(exc).__name__}: {exc}\n{traceback.format_exc()}", Fmi2Status.error)

    def do_step(self, current_time: float, step_size: float) -> bool:
        try:
            # a feedthrough block whose outputs are up to date has checked these inputs already
            if self._dirty or not self.feedthrough:
                bad = self.nonfinite_input()
                if bad is not None:
                    return self.fail(f"input {bad} at t = {current_time:.9g} s is not finite; step refused")
            if self.feedthrough and self._dirty:
                self.evaluate()
            ok = self.step(current_time, step_size)
        except Exception as exc:
            return self.fail(f"step from t = {current_time:.9g} s failed: {type(exc).__name__}: {exc}\n"
                             f"{traceback.format_exc()}")
        if ok:
            self.time = current_time + step_size
            self._held_warned = False
            self._dirty = True      # internal state moved on: outputs at t + h are due
        return ok

    # -- FMU state ------------------------------------------------------------------------------------
    def _get_fmu_state(self):
        return {"time": self.time, "r": self.r.tolist(), "other": dict(self.other),
                "dirty": self._dirty, "initialized": self._initialized,
                "logic": self.logic_state()}

    def _set_fmu_state(self, state):
        self.time = state["time"]
        self.r[:] = state["r"]
        self.other.update(state["other"])
        self._dirty = state["dirty"]
        self._initialized = state["initialized"]
        self.set_logic_state(state["logic"])

    # -- model description ----------------------------------------------------------------------------
    def to_xml(self, model_options=dict()) -> Element:
        """pythonfmu's model description, completed with units, InitialUnknowns and dependencies."""
        root = super().to_xml(model_options)
        used = sorted({v.unit for v in self.meta.values() if v.unit})
        units = Element("UnitDefinitions")
        for name in used:
            unit = SubElement(units, "Unit", name=name)
            SubElement(unit, "BaseUnit", {k: str(e) for k, e in UNITS[name].items()})
        children = list(root)
        position = [c.tag for c in children].index("CoSimulation") + 1
        root.insert(position, units)

        index = {}
        for i, sv in enumerate(root.find("ModelVariables"), start=1):
            var = self.meta[sv.get("name")]
            index[var.name] = i
            if var.unit:
                sv[0].set("unit", var.unit)
            if var.kind == "Real" and sv[0].get("start") is not None:
                sv[0].set("start", repr(float(self.r[var.vr])))   # pythonfmu's %.16g does not round-trip

        structure = root.find("ModelStructure")
        for child in list(structure):
            structure.remove(child)
        outputs = [v for v in self.meta.values() if v.causality == "output"]
        if outputs:
            node = SubElement(structure, "Outputs")
            for v in outputs:
                attrib = {"index": str(index[v.name])}
                if v.depends is not None:
                    attrib["dependencies"] = " ".join(str(i) for i in sorted(index[d] for d in v.depends))
                SubElement(node, "Unknown", attrib)
            node = SubElement(structure, "InitialUnknowns")
            for v in sorted(outputs, key=lambda v: index[v.name]):
                # at initialization outputs also depend on parameters: without an explicit list
                # the attribute is left out, which declares a dependency on every known
                attrib = {"index": str(index[v.name])}
                if v.initial_depends is not None:
                    attrib["dependencies"] = " ".join(str(i) for i in sorted(index[d] for d in v.initial_depends))
                SubElement(node, "Unknown", attrib)
        return root

"""The block's variables as FMI variables: registered with pythonfmu, read and written.

The slave registers the block's declared variables with pythonfmu in declaration order, so a
value reference is the variable's slot in the block's ``values`` array, and a batched
fmi2GetReal / fmi2SetReal is one NumPy indexing operation. Booleans live in the same array
(1.0 / 0.0), Integer and String parameters in the block's ``settings``. A value reference that
does not name a variable of the call's type, or one not settable now, fails the call naming
the variables.

An Integer arrives as an fmi2Integer, 32 bits: a larger value is cast by the host before the call
(fmpy's ctypes arrays pass 2**32 + 3 as 3) and cannot be told here from the value it became.
robofmu's own conversions refuse it naming the parameter first (``robofmu.system.diagram.coerce``
for ``--set``, experiments and ``FMUInstance.set``; ``Parameter.validate`` for a robot's TOML).
"""
from __future__ import annotations

import numpy as np
from pythonfmu import Boolean, Integer, Real, String
from pythonfmu.enums import Fmi2Causality, Fmi2Initial, Fmi2Variability

from .pythonfmu_workarounds import string_value

__all__ = ["Variables"]

_CAUSALITY = {c.name: c for c in Fmi2Causality}
_VARIABILITY = {v.name: v for v in Fmi2Variability}
_INITIAL = {i.name: i for i in Fmi2Initial}
_PYTHONFMU_TYPES = {"Real": Real, "Boolean": Boolean, "Integer": Integer, "String": String}


class Variables:
    """Registration and value access (a mixin of :class:`~.base.BlockSlave`).

    Uses the slave's ``logic`` (the block), ``_initialized``, ``_dirty``, ``_inputs_checked``,
    ``_refresh`` (:class:`~.outputs.Outputs`) and ``_raise_to_importer``
    (:class:`~.reporting.Reporting`).
    """

    def _register_variables(self) -> None:
        """Register every declared variable, and sort the slots by what they are (the masks
        and index arrays the value access, the output checks and the fast path use)."""
        for var in self.logic.variables:
            self._register(var)
        self.values = self.logic.values
        kinds = np.array([v.kind for v in self.logic.variables])
        causalities = np.array([v.causality for v in self.logic.variables])
        self._real = kinds == "Real"
        self._boolean = kinds == "Boolean"
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
            value, problem = string_value(value)
            if problem is not None:
                var = self.logic.variables[vr]
                self._raise_to_importer(f"fmi2SetString: {var.causality} {var.name}: {problem}; nothing set")
            values[k] = value
        super().set_string(vrs, values)

"""FMU states: the slave's full state saved and restored (fmi2GetFMUstate, fmi2SetFMUstate,
their serialized forms), bit for bit.

A state is a JSON-compatible dict: the block's identity (robot, block, variant, source hash),
its parameters, time, values, settings, the slave's flags and the block's
``internal_state()``. pythonfmu serializes it (JSON, UTF-8). A state is refused, nothing
restored, if it is corrupt, belongs to another block, holds non-finite values, or was saved
with other parameters than an initialized instance has; restoring that fails half-way puts the
instance back as it was.
"""
from __future__ import annotations

import json
import math

from .. import SOURCE_HASH

__all__ = ["FmuState", "STATE_KEYS"]

#: The keys of a saved state.
STATE_KEYS = frozenset({"identity", "parameters", "time", "values", "settings", "dirty", "initialized",
                        "terminated", "bad_output", "logic"})


class FmuState:
    """Saving and restoring the slave's state (a mixin of :class:`~.base.BlockSlave`).

    Uses the slave's ``robot_name``, ``block_kind``, ``logic``, ``values``, ``time``, the flags
    of :class:`~.fast_path.FastPath`, ``_bad_output`` (:class:`~.outputs.Outputs`) and
    ``_raise_to_importer`` (:class:`~.reporting.Reporting`).
    """

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
        if isinstance(state, dict) and set(state) == {"corrupt"}:
            return str(state["corrupt"])
        if not isinstance(state, dict) or set(state) != STATE_KEYS:
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

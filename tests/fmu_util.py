"""Helpers for tests that drive the FMUs through fmpy (via robofmu.system.fmu.FMUInstance).

- :func:`open_block`: one instantiated, initialized FMU;
- :func:`robot_blocks`: ``(robot, block)`` test parameters over the whole collection;
- :class:`Loop`: an experiment's diagram stepped by hand, for tests that need the blocks between
  two steps (FMU state). Its topology is the experiment's (``robofmu.system.plan.plan``: the
  wires and the evaluation order), nothing is wired here; a test that only needs a loop run
  drives :class:`robofmu.system.master.Master` instead;
- :class:`RawInstance`: one instance through fmpy's ``FMU2Slave`` with the raw FMI functions
  (statuses as returned) and a logger of the test's own, for tests of statuses and messages;
- :func:`refuse_plant_steps`: a robot's plant that refuses every step from a given time.
"""
from __future__ import annotations

import ctypes
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from fmpy import calloc, extract, free, read_model_description
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, fmi2True)

from robofmu.components.robots import available, load_description
from robofmu.system import experiment
from robofmu.system.plan import plan
from robofmu.system.fmu import FMUInstance


def open_block(fmu_dir, block, name=None, parameters=None, start_time=0.0):
    """Instantiate and initialize ``fmu_dir/<block>.fmu``."""
    b = FMUInstance(Path(fmu_dir) / f"{block}.fmu", name or block)
    b.initialize(start_time, parameters)
    return b


def refuse_plant_steps(monkeypatch, robot: str, time: float) -> None:
    """Make ``robot``'s plant refuse (``StepRefused("refused for the test")``) its steps from
    ``time`` (s) on, in this process (the FMUs' slaves run the same classes)."""
    from robofmu.components.blocks import StepRefused, block_type

    cls = block_type(load_description(robot), "plant")
    original = cls.advance

    def advance(self, t, h):
        if t >= time - 1e-12:
            raise StepRefused("refused for the test")
        return original(self, t, h)

    monkeypatch.setattr(cls, "advance", advance)


def robot_blocks(kinds=None, robots=None) -> list:
    """``pytest.param(robot, block, id="robot-block")`` for every block of every described robot
    (optionally only blocks of ``kinds`` / robots in ``robots``), in description order."""
    params = []
    for robot in available() if robots is None else robots:
        for block in load_description(robot).blocks:
            if kinds is None or block in kinds:
                params.append(pytest.param(robot, block, id=f"{robot}-{block}"))
    return params


#: The Boolean outputs of robofmu's blocks (by variable name): ik ``reachable``, trajectory and
#: plant ``grip``, plant ``within_limits``, controller ``saturated``. A tool that records Reals
#: only (libcosim, ecos) has every other column.
BOOLEAN_OUTPUTS = ("grip", "reachable", "within_limits", "saturated")


def real_columns(columns) -> list:
    """The columns of Real signals: every column but the Boolean outputs'."""
    return [c for c in columns if c.split(".", 1)[-1] not in BOOLEAN_OUTPUTS]


def assert_same_run(other, master, what: str, atol: float = 0.0, skip=()) -> None:
    """Another tool's run equals the master's: every column of ``other``, exactly (``atol`` 0) or
    to ``atol`` times its range. An experiment whose IK carries its solution forward by its rates
    (damped least squares: its start, and a redundant arm's null-space path, depend on the order in
    which a host evaluates and steps it; a host that sets the next point's inputs before doStep
    starts it elsewhere) is compared at the task: the trajectory as every column, the frame's pose from the
    plant's joints (``fk``) to 1e-6 m and 1e-6 (quaternion; the loop's tracking error, up to 0.01 mm,
    differs by about 2e-7 m along another null-space path), every other column to 1e-9 of its range for a square
    task (the solver's tolerance) and not at all for a redundant one."""
    if "ik.status" in master.columns:                       # the damped least-squares IK
        redundant = len([c for c in master.columns if c.startswith("ik.q_ref[")]) > sum(
            1 for c in master.columns if c.startswith(("trajectory.xd_ref[", "trajectory.omega_ref[")))
        for column in other.columns:
            block = column.split(".", 1)[0]
            scale = max(1.0, float(np.max(np.abs(master[column]))))
            if block == "trajectory":
                np.testing.assert_allclose(other[column], master[column], rtol=0, atol=atol * scale,
                                           err_msg=f"{what}: {column}")
            elif block == "fk":
                np.testing.assert_allclose(other[column], master[column], rtol=0, atol=1e-6, err_msg=f"{what}: {column}")
            elif not redundant and column not in skip and not column.endswith((".iterations", ".status")):
                np.testing.assert_allclose(other[column], master[column], rtol=0, atol=max(atol, 1e-9) * scale,
                                           err_msg=f"{what}: {column}")
        return
    for column in other.columns:
        if column in skip:
            continue
        if atol == 0.0:
            np.testing.assert_array_equal(other[column], master[column], err_msg=f"{what}: {column}")
        else:
            scale = max(1.0, float(np.max(np.abs(master[column]))))
            np.testing.assert_allclose(other[column], master[column], rtol=0, atol=atol * scale,
                                       err_msg=f"{what}: {column}")


#: One computed-torque PD experiment per robot (its flagship loop): for the tests that run every
#: robot's whole diagram in another FMI tool (a PD loop has no state in its feedthrough blocks).
PD_EXPERIMENTS = {"chess": "chess-pd", "rrp": "rrp-line", "rpp": "rpp-bangbang", "planar2r": "planar2r-nr",
                  "rrp_offset": "rrp_offset-nr", "3rrp": "3rrp-circle", "ur5": "ur5-pose", "panda": "panda-pose"}


def robot_experiments() -> list:
    """``pytest.param(experiment, id=robot)``: :data:`PD_EXPERIMENTS`, which must name an
    experiment of every described robot."""
    missing = sorted(set(available()) - set(PD_EXPERIMENTS))
    assert not missing, f"PD_EXPERIMENTS names no experiment of {missing}"
    return [pytest.param(PD_EXPERIMENTS[robot], id=robot) for robot in available()]


class Loop:
    """The diagram of an experiment, exchanged and stepped by hand like the master does.

    At each communication point the blocks are evaluated in the plan's order (Gauss-Seidel): a
    block gets the inputs produced by blocks evaluated before it, then its outputs are read;
    inputs from blocks evaluated later are set after the pass. Then every block steps.

    Parameters
    ----------
    name : str
        Experiment name (``system/experiments/<name>.toml``).
    fmu_root : Path
        Root of the FMU collection.
    parameters : dict, optional
        ``{instance: {parameter: value}}`` over the experiment's own.
    """

    def __init__(self, name: str, fmu_root, parameters: dict | None = None):
        system = experiment.load(name, fmu_dir=fmu_root)
        for instance, values in (parameters or {}).items():
            system.block(instance).parameters.update(values)
        self.plan = plan(system)
        self.order = list(self.plan.order)
        self.blocks: dict[str, FMUInstance] = {}
        try:
            for instance in self.order:
                node = self.plan.nodes[instance]
                b = FMUInstance(node.path, instance)
                self.blocks[instance] = b
                b.initialize(0.0, node.spec.parameters)
        except Exception:
            self.close()
            raise
        rank = {instance: k for k, instance in enumerate(self.order)}
        self._outputs = {}
        for instance in self.order:
            variables = self.plan.nodes[instance].variables
            reals = [v.name for v in variables.values() if v.causality == "output" and v.type == "Real"]
            booleans = [v.name for v in variables.values() if v.causality == "output" and v.type == "Boolean"]
            self._outputs[instance] = (reals, [variables[n].valueReference for n in reals],
                                       booleans, [variables[n].valueReference for n in booleans])
        links = self.plan.links
        self._early = {i: [l for l in links if l.target == i and rank[l.source] < rank[i]] for i in self.order}
        self._late = {i: [l for l in links if l.target == i and rank[l.source] >= rank[i]] for i in self.order}
        self.t = 0.0

    def __getitem__(self, instance: str) -> FMUInstance:
        return self.blocks[instance]

    def _set(self, instance: str, links, signals: dict) -> None:
        block = self.blocks[instance]
        variables = self.plan.nodes[instance].variables
        reals = [l for l in links if variables[l.input].type == "Real"]
        if reals:
            block.set_real([variables[l.input].valueReference for l in reals],
                           [signals[f"{l.source}.{l.output}"] for l in reals])
        for l in links:
            if variables[l.input].type != "Real":
                block.set(l.input, signals[f"{l.source}.{l.output}"])

    def exchange(self) -> dict:
        """Evaluate the diagram at the current point; every output by ``instance.variable``."""
        signals = {}
        for instance in self.order:
            self._set(instance, self._early[instance], signals)
            reals, real_vrs, booleans, boolean_vrs = self._outputs[instance]
            block = self.blocks[instance]
            if reals:
                signals.update(zip((f"{instance}.{n}" for n in reals), block.get_real(real_vrs)))
            if booleans:
                values = block.slave.getBoolean(boolean_vrs)
                signals.update(zip((f"{instance}.{n}" for n in booleans), (bool(v) for v in values)))
        for instance in self.order:
            self._set(instance, self._late[instance], signals)
        return signals

    def step(self, h: float) -> dict:
        """Exchange at t, then doStep(t, h) on every block; returns the outputs at t."""
        out = self.exchange()
        for instance in self.order:
            self.blocks[instance].do_step(self.t, h)
        self.t += h
        return out

    def get_states(self) -> dict:
        return {instance: b.get_state() for instance, b in self.blocks.items()}

    def set_states(self, states: dict, t: float) -> None:
        for instance, state in states.items():
            self.blocks[instance].set_state(state)
        self.t = t

    def close(self) -> None:
        for b in self.blocks.values():
            b.close()


# -- raw FMI instances ----------------------------------------------------------------------------
OK, WARNING, DISCARD, ERROR, FATAL = range(5)          # fmi2Status
LABEL = ["OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING"]
H = 1e-3

_KEEP: list = []


def keep_alive(callbacks) -> None:
    """Keep a logger (or callback struct) alive for the whole session: a FMU may log through one
    after its test ended."""
    _KEEP.append(callbacks)


class RawInstance:
    """One co-simulation instance through fmpy's FMU2Slave: the raw FMI functions (statuses as
    returned), every message recorded as ``(status label, category, text)``. ``fast=False``
    instantiates it with robofmu's FMI fast path off (``ROBOFMU_FMI_FAST_PATH=0``), None leaves
    the environment as it is. ``component`` is None if fmi2Instantiate failed."""

    def __init__(self, path: Path, name: str, fast: bool | None = None, logging_on: bool = False):
        self.messages: list[tuple[str, str | None, str]] = []
        md = read_model_description(str(path), validate=False)
        self.variables = {v.name: v for v in md.modelVariables}
        self.dir = extract(str(path))
        self.slave = FMU2Slave(guid=md.guid, unzipDirectory=self.dir,
                               modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        keep_alive(self.callbacks)
        before = os.environ.get("ROBOFMU_FMI_FAST_PATH")
        if fast is not None:
            os.environ["ROBOFMU_FMI_FAST_PATH"] = "1" if fast else "0"
        try:
            self.component = self.slave.fmi2Instantiate(name.encode(), 1, md.guid.encode(),
                                                        (Path(self.dir) / "resources").as_uri().encode(),
                                                        ctypes.byref(self.callbacks), 0, int(logging_on))
        finally:
            if before is None:
                os.environ.pop("ROBOFMU_FMI_FAST_PATH", None)
            else:
                os.environ["ROBOFMU_FMI_FAST_PATH"] = before

    def _log(self, env, instance, status, category, message):
        self.messages.append((LABEL[status], category.decode() if category else None,
                              message.decode(errors="replace") if message else ""))

    def _library_function(self, name: str, restype):
        function = getattr(self.slave.dll, name)
        function.argtypes, function.restype = [ctypes.c_void_p], restype
        return function

    @property
    def fast_path(self) -> bool:
        """Whether robofmu's FMI library serves this instance's hot calls itself."""
        return bool(self._library_function("robofmu_fast_path", ctypes.c_int)(self.component))

    @property
    def fast_calls(self) -> int:
        """How many calls of this instance the fast path served."""
        return self._library_function("robofmu_fast_calls", ctypes.c_ulonglong)(self.component)

    def names(self, kind: str, *causalities: str) -> list[str]:
        return [n for n, v in self.variables.items() if v.type == kind and (not causalities or v.causality in causalities)]

    def refs(self, names):
        return (ctypes.c_uint * max(1, len(names)))(*[self.variables[n].valueReference for n in names])

    def call(self, function: str, *args) -> int:
        return self.slave._functions[function](self.component, *args)

    def set_real(self, names, values) -> int:
        return self.call("fmi2SetReal", self.refs(names), len(names), (ctypes.c_double * max(1, len(names)))(*values))

    def get_real(self, names) -> tuple[int, np.ndarray]:
        out = (ctypes.c_double * max(1, len(names)))()
        status = self.call("fmi2GetReal", self.refs(names), len(names), out)
        return status, np.array(out[:len(names)])

    def get_boolean(self, names) -> tuple[int, list[int]]:
        out = (ctypes.c_int * max(1, len(names)))()
        status = self.call("fmi2GetBoolean", self.refs(names), len(names), out)
        return status, list(out[:len(names)])

    def set_boolean(self, names, values) -> int:
        return self.call("fmi2SetBoolean", self.refs(names), len(names), (ctypes.c_int * max(1, len(names)))(*values))

    def step(self, t: float, h: float = H) -> int:
        return self.call("fmi2DoStep", t, h, fmi2True)

    def initialize(self, parameters: dict | None = None) -> int:
        """Set up, enter initialization, set the Real ``parameters``, exit: the exit's status."""
        assert self.call("fmi2SetupExperiment", 0, 0.0, 0.0, 0, 0.0) == OK
        assert self.call("fmi2EnterInitializationMode") == OK
        for name, value in (parameters or {}).items():
            assert self.set_real([name], [value]) == OK
        return self.call("fmi2ExitInitializationMode")

    def real_status(self, kind: int) -> tuple[int, float]:
        value = ctypes.c_double()
        return self.call("fmi2GetRealStatus", kind, ctypes.byref(value)), value.value

    def boolean_status(self, kind: int) -> tuple[int, int]:
        value = ctypes.c_int()
        return self.call("fmi2GetBooleanStatus", kind, ctypes.byref(value)), value.value

    def texts(self, *statuses: str) -> list[str]:
        return [m for s, _, m in self.messages if not statuses or s in statuses]

    def close(self) -> None:
        if self.component:
            self.slave.fmi2FreeInstance(self.component)
            self.component = None
        self.slave.freeLibrary()
        shutil.rmtree(self.dir, ignore_errors=True)


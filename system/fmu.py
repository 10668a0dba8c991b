"""One FMU instance, as the master sees it: fmpy's FMU2Slave plus names, batching and a log.

Everything FMI goes through fmpy. An :class:`FMUInstance` resolves variable names (``q[2]``) and
vector bases (``q`` -> ``q[1]``..``q[n]``) to value references once, keeps every message the FMU
logs (:attr:`FMUInstance.messages`), and raises :class:`FMUError` naming the instance, the call and the
FMU's last error messages when a call fails.
"""
from __future__ import annotations

import ctypes
import shutil
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable
from xml.etree import ElementTree

from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi1 import printLogMessage
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)
from fmpy import calloc, free

from robofmu.components.fmi.model_description import VENDOR_TOOL
from robofmu.system.diagram import coerce, expand, spread

STATUS = ["OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING"]

#: The statuses of the messages that tell why a call failed (:meth:`FMUInstance.errors`).
FAILURES = ("ERROR", "FATAL", "DISCARD")


def status_name(status: int) -> str:
    """The name of an fmi2Status (``"ERROR"``), or the number as text if it names none."""
    return STATUS[status] if 0 <= status < len(STATUS) else str(status)


@dataclass(frozen=True)
class LogMessage:
    instance: str
    status: str
    category: str
    message: str

    def __str__(self) -> str:
        return f"[{self.status}] {self.instance}: {self.message}"


class FMUError(RuntimeError):
    """A FMU call failed; the message names the instance, the call and what the FMU logged."""

    def __init__(self, block: "FMUInstance", call: str, detail: str = "", since: int = 0):
        logged = block.errors(since)
        text = f"{block.name}: {call} failed"
        if detail:
            text += f" ({detail})"
        if logged:
            text += ": " + " | ".join(logged)
        super().__init__(text)
        self.block = block.name
        self.call = call
        self.logged = logged


# fmpy's native logger proxy (it formats the variadic message) remembers one Python logger for
# the whole process, whichever instance registered last. So every FMUInstance registers the same
# logger, and each instance's callbacks carry its own componentEnvironment, which the FMU hands
# back with every message: the route to the FMUInstance the message belongs to. A message of no
# FMUInstance's (fmpy's own default callbacks, e.g. ``simulate_fmu`` without a logger, lead here too
# once a FMUInstance exists) is printed as fmpy's default logger would.
_ROUTES: dict[int, "FMUInstance"] = {}
_NEXT_ROUTE = [1]


def _route_message(env, instance, status, category, message):
    block = _ROUTES.get(env or 0)
    if block is not None:
        block._log(env, instance, status, category, message)
    else:
        printLogMessage(env, instance, status, category, message)


_LOGGER = fmi2CallbackLoggerTYPE(_route_message)


def _callbacks_for(block: "FMUInstance") -> fmi2CallbackFunctions:
    key = _NEXT_ROUTE[0]
    _NEXT_ROUTE[0] += 1
    _ROUTES[key] = block
    block._route = key
    callbacks = fmi2CallbackFunctions()
    callbacks.logger = _LOGGER
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    callbacks.componentEnvironment = key
    try:
        from fmpy.logging import addLoggerProxy
        addLoggerProxy(ctypes.byref(callbacks))
    except Exception:  # pragma: no cover - fmpy without its logging proxy
        pass
    return callbacks


class FMUInstance:
    """An instantiated co-simulation FMU.

    Parameters
    ----------
    path : str or Path
        The ``.fmu`` file.
    name : str
        Instance name (also used in messages and recorded column names).
    echo : callable, optional
        Called with every :class:`LogMessage` as it arrives (default: none; all are kept in
        :attr:`messages`).
    model_description : fmpy ModelDescription, optional
        The FMU's, already read (the master passes its plan's); default: read from ``path``.
    """

    def __init__(self, path: str | Path, name: str, echo: Callable[[LogMessage], None] | None = None,
                 model_description=None):
        self.path = Path(path)
        self.name = name
        if not self.path.is_file():
            raise FileNotFoundError(f"{name}: FMU {self.path} does not exist (run `robofmu build`)")
        self.md = model_description or read_model_description(str(self.path), validate=False)
        if self.md.coSimulation is None:
            raise ValueError(f"{name}: {self.path} is not a co-simulation FMU")
        self.variables = {v.name: v for v in self.md.modelVariables}
        self.messages: list[LogMessage] = []
        self._echo = echo
        self._alive = False
        self._unzipdir = extract(str(self.path))
        self._callbacks = _callbacks_for(self)
        try:
            self.slave = FMU2Slave(guid=self.md.guid, unzipDirectory=self._unzipdir,
                                   modelIdentifier=self.md.coSimulation.modelIdentifier,
                                   instanceName=name)
            self.slave.instantiate(callbacks=self._callbacks, loggingOn=True)
        except Exception as exc:
            if hasattr(self, "slave"):
                self.slave.freeLibrary()
            shutil.rmtree(self._unzipdir, ignore_errors=True)
            _ROUTES.pop(self._route, None)
            raise FMUError(self, "fmi2Instantiate", "" if self.messages else str(exc)) from None
        self._alive = True

    def _log(self, env, instance, status, category, message):
        msg = LogMessage(instance.decode(errors="replace") if instance else self.name,
                         status_name(status),
                         category.decode(errors="replace") if category else "",
                         message.decode(errors="replace") if message else "")
        self.messages.append(msg)
        if self._echo is not None:
            self._echo(msg)

    def errors(self, since: int = 0) -> list[str]:
        """The texts of the messages logged with a failure's status (:data:`FAILURES`), from
        message ``since`` on."""
        return [m.message for m in self.messages[since:] if m.status in FAILURES]

    # -- names -------------------------------------------------------------------------------------
    def variable(self, name: str):
        try:
            return self.variables[name]
        except KeyError:
            raise KeyError(f"{self.name}: no variable {name!r} in {self.path.name}") from None

    def names(self, base: str) -> list[str]:
        """``base`` itself if it is a variable, else ``base[1]``, ``base[2]``, ... in order."""
        found = expand(self.variables, base)
        if not found:
            raise KeyError(f"{self.name}: no variable {base!r} (nor {base}[i]) in {self.path.name}")
        return found

    def vrs(self, *bases: str) -> list[int]:
        """Value references of the variables named by ``bases`` (each a name or a vector base)."""
        return [self.variables[n].valueReference for b in bases for n in self.names(b)]

    # -- life cycle --------------------------------------------------------------------------------
    def _call(self, call: str, fn, *args):
        since = len(self.messages)
        try:
            return fn(*args)
        except FMICallException as exc:
            raise FMUError(self, call, str(exc), since) from None

    def initialize(self, start_time: float = 0.0, parameters: dict | None = None,
                   stop_time: float | None = None) -> None:
        """setupExperiment, enterInitializationMode, set ``parameters`` (by name), exit."""
        s = self.slave
        self._call("fmi2SetupExperiment", s.setupExperiment, None, start_time, stop_time)
        self._call("fmi2EnterInitializationMode", s.enterInitializationMode)
        for name, value in (parameters or {}).items():
            self.set(name, value)
        self._call("fmi2ExitInitializationMode", s.exitInitializationMode)

    def set(self, name: str, value) -> None:
        """Set one variable (any type) or a whole vector (``q0`` = [..]) by name."""
        names = self.names(name)
        for n, v in zip(names, spread(names, value, f"{self.name}.{name}")):
            var = self.variable(n)
            vr, v = [var.valueReference], coerce(var.type, v, f"{self.name}.{n}")
            if var.type == "Real":
                self._call(f"fmi2SetReal({n})", self.slave.setReal, vr, [v])
            elif var.type == "Boolean":
                self._call(f"fmi2SetBoolean({n})", self.slave.setBoolean, vr, [v])
            elif var.type in ("Integer", "Enumeration"):
                self._call(f"fmi2SetInteger({n})", self.slave.setInteger, vr, [v])
            else:
                self._call(f"fmi2SetString({n})", self.slave.setString, vr, [v])

    def get(self, name: str):
        """Value of one variable, or list of values of a vector base."""
        out = []
        for n in self.names(name):
            var = self.variable(n)
            vr = [var.valueReference]
            if var.type == "Real":
                out += self._call(f"fmi2GetReal({n})", self.slave.getReal, vr)
            elif var.type == "Boolean":
                out += [bool(b) for b in self._call(f"fmi2GetBoolean({n})", self.slave.getBoolean, vr)]
            elif var.type in ("Integer", "Enumeration"):
                out += self._call(f"fmi2GetInteger({n})", self.slave.getInteger, vr)
            else:
                out += [v.decode() if isinstance(v, bytes) else v
                        for v in self._call(f"fmi2GetString({n})", self.slave.getString, vr)]
        return out[0] if name in self.variables else out

    def get_real(self, vrs: list[int]) -> list[float]:
        return self._call("fmi2GetReal", self.slave.getReal, vrs)

    def get_boolean(self, vrs: list[int]) -> list[bool]:
        return self._call("fmi2GetBoolean", self.slave.getBoolean, vrs)

    def set_real(self, vrs: list[int], values) -> None:
        self._call("fmi2SetReal", self.slave.setReal, vrs, values)

    def do_step(self, t: float, h: float) -> None:
        self._call(f"fmi2DoStep(t = {t:.9g} s, h = {h:.9g} s)", self.slave.doStep, t, h)

    def get_state(self):
        return self._call("fmi2GetFMUstate", self.slave.getFMUstate)

    def set_state(self, state) -> None:
        self._call("fmi2SetFMUstate", self.slave.setFMUstate, state)

    def free_state(self, state) -> None:
        self._call("fmi2FreeFMUstate", self.slave.freeFMUstate, state)

    def close(self) -> None:
        """Terminate and free the instance; remove its extracted files. Safe to call twice."""
        if not self._alive:
            return
        self._alive = False
        try:
            self.slave.terminate()
        except Exception:
            pass
        try:
            self.slave.freeInstance()
        except Exception:
            pass
        shutil.rmtree(self._unzipdir, ignore_errors=True)
        _ROUTES.pop(self._route, None)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def block_identity(path: str | Path) -> dict[str, str]:
    """Robot, kind, variant, code hash (``source``) and robot data hash (``robot_data``) a
    robofmu FMU declares in its vendor annotation.

    Raises
    ------
    ValueError
        If the FMU carries no robofmu annotation (not a robofmu block).
    """
    return _identity(_model_description(path), path)


def _model_description(path: str | Path) -> ElementTree.Element:
    with zipfile.ZipFile(path) as archive:
        return ElementTree.fromstring(archive.read("modelDescription.xml"))


def _identity(root: ElementTree.Element, path: str | Path) -> dict[str, str]:
    node = root.find(f"VendorAnnotations/Tool[@name='{VENDOR_TOOL}']/Block")
    if node is None:
        raise ValueError(f"{path}: not a robofmu block (no {VENDOR_TOOL} vendor annotation)")
    return dict(node.attrib)


def stale_reasons(path: str | Path, robot=None) -> list[str]:
    """Why the robofmu FMU at ``path`` is stale for this installation, in words (none: fresh).

    - ``"robofmu version changed"``: its model description's version (``<version>+...``) is not
      the installed robofmu's (package metadata);
    - ``"code changed"``: it bundles other code (its annotation's ``source`` is not
      :data:`robofmu.components.SOURCE_HASH`; the code only, no robot's data);
    - ``"robot data changed"``: the robot's TOML or URDF it carries are not those of ``robot``
      now (its annotation's ``robot_data`` against :func:`robofmu.components.robot_data_hash`;
      a FMU built before robot data was hashed apart has none, and its code changed).

    Parameters
    ----------
    path : str or Path
        A robofmu block FMU.
    robot : RobotDescription, optional
        The robot the FMU is for as described now; default: the package's robot of the FMU's
        name, if there is one (else the robot's data is not compared).

    Raises
    ------
    ValueError
        If the FMU is not a robofmu block (:func:`block_identity`).
    """
    from importlib import metadata

    from robofmu.components import SOURCE_HASH, description_hash
    from robofmu.components.robots import available, load_description

    root = _model_description(path)
    identity, version = _identity(root, path), root.get("version", "")
    try:
        installed = metadata.version("robofmu")
    except metadata.PackageNotFoundError:
        installed = None
    reasons = []
    if installed is not None and version.split("+", 1)[0] != installed:
        reasons.append("robofmu version changed")
    if identity.get("source") != SOURCE_HASH:
        reasons.append("code changed")
    if robot is None and identity.get("robot") in available():
        robot = load_description(identity["robot"])
    if robot is not None:
        if robot.name != identity.get("robot"):
            reasons.append(f"built for robot {identity.get('robot')!r}, not {robot.name!r}")
        elif "robot_data" in identity and identity["robot_data"] != description_hash(robot):
            reasons.append("robot data changed")
    return reasons

"""Run robofmu FMUs through libcosim (the OSP co-simulation library) via libcosimpy.

A thin layer over libcosimpy 0.0.6 that speaks variable *names* (``q[2]``) and vector bases
(``q`` -> ``q[1]``..``q[n]``) instead of value references, and raises instead of returning
False. libcosimpy is an optional (dev) dependency: it is imported only when a
:class:`CosimRun` is created.

In-process use: libcosimpy calls libcosimc through ``ctypes.CDLL``, which releases the GIL
for the duration of every call. libcosim then drives the FMUs from its own worker threads, and
the pythonfmu FMUs (which import nothing of libpython themselves but resolve its symbols from
the host process) find the running interpreter (``Py_IsInitialized``) and take the GIL with
``PyGILState_Ensure``. So the FMUs run on *this* interpreter, and no subprocess nor
``LD_PRELOAD`` of libpython is needed when the host is a dynamically linked CPython. (A host
that is not Python, e.g. the ``cosim`` command-line tool, would need libpython preloaded.)

Beware: a FMU that fails fmi2ExitInitializationMode (e.g. an invalid parameter) makes libcosim
throw from a worker thread, and the process dies of std::terminate (SIGABRT) instead of
:meth:`CosimRun.step` raising; run such cases in a child process. A refused fmi2DoStep and a
failed fmi2Instantiate are reported as :class:`CosimError`. libcosim's log (FMU messages
included) is written to the C++ stdout.

Several executions in one process, one after the other or side by side, are independent: each
:class:`CosimRun` (each ``add``, each ``from_ssp``) extracts its FMUs to a folder of its own, so
every execution has its own copies of the FMU binaries and of pythonfmu's export library, and
each block instance its own state (the Python modules the FMUs import are shared). Destroying an
execution (:meth:`CosimRun.close`) frees its instances and unloads its copies of the binaries
(all but the process's first copy of pythonfmu's library, see below).

Process exit (pythonfmu 0.7.0). pythonfmu's export library keeps its Python state in a static
``std::shared_ptr`` released by two hooks: its C++ destructor (run by ``exit()`` among the
atexit handlers, or by ``dlclose``) and ``onLibraryUnload`` (a destructor function, run by
``_dl_fini`` at exit or by ``dlclose``). ``dlclose`` runs the hook first, which empties the
pointer: unloading mid-run is safe. At ``exit()`` the C++ destructor runs first and frees the
state's control block without emptying the pointer; the hook then decrements a counter inside
the freed block (valgrind: "Invalid read of size 4 ... finalizePythonInterpreter ... 8 bytes
inside a block of size 128 free'd"). The first copy of the library loaded in a process is never
unloaded (it defines C++ ``STB_GNU_UNIQUE`` symbols, which makes it ``NODELETE``), so every
process that ever instantiated a pythonfmu FMU, with fmpy or libcosim, writes into freed heap
memory while it exits. Mostly harmless, sometimes fatal: "corrupted double-linked list"
(SIGABRT) or a segfault after the script's last line, more often the more the process did
(two ``simulate_ssp`` or libcosim runs). The cure is to call the hook's body, the exported
``finalizePythonInterpreter``, before the C++ destructor: it empties the pointer, and both hooks
then do nothing. robofmu's FMUs do it themselves, in any host: as robofmu's export library
(system/packaging/fmi_export/robofmu_fmi2.c, point 3) loads pythonfmu's, it registers that library's
``finalizePythonInterpreter`` as an exit handler owned by it (``__cxa_atexit`` with its
``__dso_handle``), which ``exit()`` runs before the library's destructors, and its unloading
after its hook, so a script using fmpy or libcosimpy without robofmu exits cleanly too. In a
Python host that handler runs after ``Py_Finalize``, harmlessly: the state is only a thread that
ended as it was made (``Py_Initialize`` had been called already), and its release calls nothing
of Python. In a host that is not Python it finalizes the interpreter pythonfmu started, at the
point of ``exit()`` where pythonfmu's destructor would have. For other pythonfmu 0.7.0 FMUs
(without robofmu's export library, or robofmu's built before it had this), there is
:func:`guard_pythonfmu_exit` (called by every :class:`CosimRun` and by
:func:`robofmu.system.interop.fmpy_ssp.run_ssp_fmpy`, harmless beside the FMUs' own handler): it registers
:func:`release_pythonfmu_states` to run at interpreter exit, which calls the
``finalizePythonInterpreter`` of every pythonfmu library still loaded.

An SSP package (:func:`run_ssp_libcosim`, ``CosimExecution.from_ssp_file`` ->
``cosim_ssp_fixed_step_execution_create``):
    - Loads a ``.ssp`` archive (or a folder/``.ssd``), FMUs by relative ``source``; reads
      connector types (a connector without a type element is rejected), connections (with
      ``ssc:LinearTransformation``), DefaultExperiment ``startTime`` and the OSP fixed-step
      annotation; applies the **first** parameter set bound to each component (inline or
      ``.ssv``) as initial values; a parameter it cannot apply is only logged as a warning.
      It ignores ``stopTime``, system-level bindings and ParameterMapping.
    - Components are stored in a hash map: slave indices do not follow the SSD order, so the
      runner looks them up by instance name.
    - Master algorithm: the fixed-step (Jacobi) algorithm. Initialization passes connected
      values along in initialization mode (outputs read there), so the loop starts consistent
      at t0 (tests/test_libcosim.py). Then at every step all slaves step from t with the inputs
      transferred at t, outputs are read after the step and transferred: a feedthrough block's
      output at t + h is computed from its inputs at t. The reference reaches the plant two
      steps late (ik, controller each hold one), the measured q one step late; controller ->
      plant adds no delay of its own (the plant has no feedthrough: it steps from t with the
      torque read at t, as in Gauss-Seidel).
    - Time is integer nanoseconds: no drift. Only Real variables can be recorded as time
      series; Boolean outputs are not in the Result. A FMU failing initialization aborts the
      process (see system/interop/libcosim.py).
"""
from __future__ import annotations

import atexit
import ctypes
import os
import sys
import time as _time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robofmu.system import defaults
from robofmu.system.diagram import coerce, expand, select, spread
from robofmu.system.plan import step_count
from robofmu.system.result import Result

NANO = 1_000_000_000
_FMI_TYPES = {"REAL": "Real", "INTEGER": "Integer", "BOOLEAN": "Boolean", "STRING": "String"}   # libcosim -> FMI


def to_ns(t: float) -> int:
    """Seconds to libcosim's integer nanoseconds (rounded, not truncated: 1e-3 s -> 1000000)."""
    return int(round(float(t) * NANO))


def _set_log_level(level: str | None) -> None:
    """libcosim's console log level, process-wide (None: leave it)."""
    if level is not None:
        from libcosimpy.CosimLogging import CosimLogLevel, log_output_level

        log_output_level(CosimLogLevel[level.upper()])


class CosimError(RuntimeError):
    """A libcosim call failed; the message carries libcosim's last error message."""


# -- pythonfmu 0.7.0 at process exit (see the module notes) ---------------------------------------
#: ``pythonfmu::createInstance(fmu_data)``: with ``finalizePythonInterpreter``, marks pythonfmu's
#: export library (the FMU's own binary in plain pythonfmu FMUs, ``libpythonfmu-export.so``
#: beside robofmu's export library in robofmu's)
PYTHONFMU_MARK = b"_ZN9pythonfmu14createInstanceENS_8fmu_dataE"
PYTHONFMU_FINALIZE = b"finalizePythonInterpreter"
_exit_guard_registered = False


class _PhdrInfo(ctypes.Structure):
    """The first fields of ``struct dl_phdr_info`` (all that is read)."""
    _fields_ = [("dlpi_addr", ctypes.c_void_p), ("dlpi_name", ctypes.c_char_p)]


_PHDR_CALLBACK = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.POINTER(_PhdrInfo), ctypes.c_size_t, ctypes.c_void_p)


def _dl():
    """dl_iterate_phdr, dlopen, dlsym, dlclose of the C library, with their prototypes."""
    libc = ctypes.CDLL(None)
    libc.dl_iterate_phdr.argtypes = [_PHDR_CALLBACK, ctypes.c_void_p]
    libc.dl_iterate_phdr.restype = ctypes.c_int
    libc.dlopen.argtypes = [ctypes.c_char_p, ctypes.c_int]
    libc.dlopen.restype = ctypes.c_void_p
    libc.dlsym.argtypes = [ctypes.c_void_p, ctypes.c_char_p]
    libc.dlsym.restype = ctypes.c_void_p
    libc.dlclose.argtypes = [ctypes.c_void_p]
    libc.dlclose.restype = ctypes.c_int
    return libc


def pythonfmu_libraries() -> list[tuple[str, int]]:
    """(path, address of ``finalizePythonInterpreter``) of every pythonfmu export library loaded
    in this process (Linux; [] elsewhere). A library whose FMU folder was deleted keeps its path."""
    if not sys.platform.startswith("linux"):
        return []
    libc = _dl()
    names: list[bytes] = []

    def visit(info, size, data):
        name = info.contents.dlpi_name
        if name:
            names.append(name)
        return 0

    libc.dl_iterate_phdr(_PHDR_CALLBACK(visit), None)     # collect first: no dlopen under its lock
    found = []
    for name in names:
        handle = libc.dlopen(name, os.RTLD_NOLOAD | os.RTLD_LAZY)   # loaded already, matched by name
        if not handle:
            continue
        try:
            finalize = libc.dlsym(handle, PYTHONFMU_FINALIZE)
            if finalize and libc.dlsym(handle, PYTHONFMU_MARK):
                found.append((os.fsdecode(name), finalize))
        finally:
            libc.dlclose(handle)                          # the reference NOLOAD took; nothing unloads
    return found


def _python_host() -> bool:
    """Whether this interpreter was started as a program (``python ...``), not by pythonfmu's
    own ``Py_Initialize`` in a host that is not Python (``sys.orig_argv`` is empty there): only
    then is pythonfmu's state a finished thread that can be released at any time."""
    return bool(getattr(sys, "orig_argv", None))


def release_pythonfmu_states() -> int:
    """Empty the Python state of every loaded pythonfmu export library now; returns how many.

    Calls each library's ``finalizePythonInterpreter`` (what its unload hook calls): the state
    is released while it is intact, and pythonfmu's two exit hooks then find nothing to release
    (see the module notes). Harmless at any time in a Python host: instances do not use the
    state, and a later instantiation creates a new one (release again before exit). Does
    nothing in an interpreter pythonfmu started itself, or outside Linux.
    """
    if not _python_host():
        return 0
    released = 0
    for _, finalize in pythonfmu_libraries():
        ctypes.CFUNCTYPE(None)(finalize)()
        released += 1
    return released


def _release_at_exit() -> None:
    try:
        release_pythonfmu_states()
    except Exception:   # pragma: no cover - never fail an exiting interpreter
        pass


def guard_pythonfmu_exit() -> None:
    """Register :func:`release_pythonfmu_states` to run at interpreter exit (once per process).

    Python runs atexit handlers before the C library's exit handlers, so the release comes
    before pythonfmu's destructors. Called by every :class:`CosimRun` and by
    :func:`robofmu.system.interop.fmpy_ssp.run_ssp_fmpy`. robofmu's FMUs need it nowhere (their export
    library releases the state itself, see the module notes); call it yourself when you run
    other pythonfmu 0.7.0 FMUs with fmpy or libcosimpy directly.
    """
    global _exit_guard_registered
    if not _exit_guard_registered:
        atexit.register(_release_at_exit)
        _exit_guard_registered = True


@dataclass(frozen=True)
class CosimVariable:
    name: str
    reference: int
    type: str          # "REAL", "INTEGER", "STRING", "BOOLEAN"
    causality: str     # "INPUT", "PARAMETER", "OUTPUT", ...


@dataclass
class _Slave:
    index: int
    path: Path
    variables: dict[str, CosimVariable]
    local_slave: object   # the CosimLocalSlave, kept alive with the run


class CosimRun:
    """One libcosim execution with a fixed step, a last-value observer and an override manipulator.

    Parameters
    ----------
    step_size : float
        Communication step (s) of libcosim's fixed-step algorithm.
    log_level : str, optional
        libcosim console log level ("TRACE", "DEBUG", "INFO", "WARNING", "ERROR", "FATAL");
        process-wide (libcosim's own default, DEBUG, prints every FMI Library call). None: leave
        it as it is.
    """

    def __init__(self, step_size: float = defaults.STEP_SIZE, log_level: str | None = "WARNING", *,
                 execution=None, last_value: bool = True):
        from libcosimpy.CosimExecution import CosimExecution
        from libcosimpy.CosimManipulator import CosimManipulator
        from libcosimpy.CosimObserver import CosimObserver

        _set_log_level(log_level)
        if not step_size > 0:
            raise ValueError(f"step_size must be > 0 s, got {step_size}")
        guard_pythonfmu_exit()
        self.step_size = float(step_size)
        self.execution = CosimExecution.from_step_size(to_ns(step_size)) if execution is None else execution
        self.observer = self.manipulator = None
        if last_value:
            self.observer = CosimObserver.create_last_value()
            self._check(self.execution.add_observer(self.observer), "add last-value observer")
            self.manipulator = CosimManipulator.create_override()
            self._check(self.execution.add_manipulator(self.manipulator), "add override manipulator")
        self.slaves: dict[str, _Slave] = {}
        self.time_series = None

    @classmethod
    def from_ssp(cls, path: str | Path, step_size: float, log_level: str | None = "WARNING",
                 last_value: bool = True) -> "CosimRun":
        """An execution loaded by libcosim from an SSP package (its slaves, connections and
        parameter sets). ``last_value=False`` leaves out the last-value observer (it reads every
        variable of every slave after every step) and the override manipulator: ``get`` and
        ``override`` are then unavailable."""
        from libcosimpy.CosimExecution import CosimExecution

        _set_log_level(log_level)
        path = Path(path)
        try:
            execution = CosimExecution.from_ssp_file(str(path), step_size=to_ns(step_size))
        except AssertionError:
            raise CosimError(f"libcosim: loading {path} failed: {cls.last_error()}") from None
        run = cls(step_size, None, execution=execution, last_value=last_value)
        for info in execution.slave_infos():
            index = int(info.index)
            run.slaves[info.name.decode()] = _Slave(index, path, run._variables(index), None)
        return run

    @classmethod
    def from_osp(cls, path: str | Path, step_size: float, log_level: str | None = "WARNING",
                 last_value: bool = True) -> "CosimRun":
        """An execution loaded by libcosim from an OSP system structure (``OspSystemStructure.xml``
        or its folder): its simulators with their step sizes, connections, initial values, base
        step and start time (:mod:`robofmu.system.interop.osp`). ``step_size`` is the file's base
        step (s; libcosim takes it from the file, this only records it); ``last_value`` as in
        :meth:`from_ssp`."""
        from libcosimpy.CosimExecution import CosimExecution

        _set_log_level(log_level)
        path = Path(path)
        try:
            execution = CosimExecution.from_osp_config_file(str(path))
        except AssertionError:
            raise CosimError(f"libcosim: loading {path} failed: {cls.last_error()}") from None
        run = cls(step_size, None, execution=execution, last_value=last_value)
        for info in execution.slave_infos():
            index = int(info.index)
            run.slaves[info.name.decode()] = _Slave(index, path, run._variables(index), None)
        return run

    def _variables(self, index: int) -> dict[str, CosimVariable]:
        variables = {}
        for v in self.execution.slave_variables(index):
            var = CosimVariable(v.name.decode(), int(v.reference), _enum_name("CosimVariableType", v.type),
                                _enum_name("CosimVariableCausality", v.causality))
            variables[var.name] = var
        return variables

    # -- errors ---------------------------------------------------------------------------------
    @staticmethod
    def last_error() -> str:
        from libcosimpy._internal import get_last_error_message

        try:
            return get_last_error_message()
        except Exception:  # pragma: no cover - message not decodable
            return "(no message)"

    def _check(self, ok: bool, what: str) -> None:
        if not ok:
            raise CosimError(f"libcosim: {what} failed: {self.last_error()}")

    # -- slaves and names -----------------------------------------------------------------------
    def add(self, path: str | Path, name: str) -> int:
        """Add FMU ``path`` as local slave ``name``; returns its slave index."""
        from libcosimpy.CosimSlave import CosimLocalSlave

        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"{name}: FMU {path} does not exist")
        if name in self.slaves:
            raise ValueError(f"instance name {name!r} already used")
        local = CosimLocalSlave(fmu_path=str(path.resolve()), instance_name=name)
        if not local.ptr():
            raise CosimError(f"libcosim: loading {path} failed: {self.last_error()}")
        index = self.execution.add_local_slave(local)
        if index < 0:
            raise CosimError(f"libcosim: adding {name} ({path}) failed: {self.last_error()}")
        self.slaves[name] = _Slave(index, path, self._variables(index), local)
        return index

    def index(self, instance: str) -> int:
        return self._slave(instance).index

    def _slave(self, instance: str) -> _Slave:
        try:
            return self.slaves[instance]
        except KeyError:
            raise KeyError(f"no instance {instance!r}; have {sorted(self.slaves)}") from None

    def names(self, instance: str, base: str) -> list[str]:
        """``base`` itself if it is a variable of ``instance``, else ``base[1]``, ``base[2]``, ..."""
        found = expand(self._slave(instance).variables, base)
        if not found:
            raise KeyError(f"{instance}: no variable {base!r} (nor {base}[i])")
        return found

    def variables(self, instance: str, base: str) -> list[CosimVariable]:
        slave = self._slave(instance)
        return [slave.variables[n] for n in self.names(instance, base)]

    def vrs(self, instance: str, base: str) -> list[int]:
        return [v.reference for v in self.variables(instance, base)]

    # -- values ---------------------------------------------------------------------------------
    def set_initial(self, instance: str, name: str, value) -> None:
        """Initial (start) value of a parameter or input, or of every element of a vector base.

        Applied by libcosim in initialization mode, before fmi2ExitInitializationMode, so it
        must be called before the first step."""
        index = self.index(instance)
        variables = self.variables(instance, name)
        ex = self.execution
        setters = {"REAL": ex.real_initial_value, "INTEGER": ex.integer_initial_value,
                   "BOOLEAN": ex.boolean_initial_value, "STRING": ex.string_initial_value}
        for var, v in zip(variables, spread(variables, value, f"{instance}.{name}")):
            typed = coerce(_FMI_TYPES[var.type], v, f"{instance}.{var.name}")
            self._check(setters[var.type](index, var.reference, typed),
                        f"initial value {instance}.{var.name} = {v!r}")

    def override(self, instance: str, name: str, value) -> None:
        """Override a Real variable (or vector) from now on, through the override manipulator:
        libcosim sets it on the FMU before every following step. Not applied during
        initialization: an override made before the first step shows from t = one step on (use
        :meth:`set_initial` for t = 0)."""
        variables = self.variables(instance, name)
        bad = [v.name for v in variables if v.type != "REAL"]
        if bad:
            raise TypeError(f"{instance}: override supports Real variables only, not {bad}")
        values = [coerce("Real", v, f"{instance}.{var.name}")
                  for var, v in zip(variables, spread(variables, value, f"{instance}.{name}"))]
        self._check(self.manipulator.slave_real_values(self.index(instance), [v.reference for v in variables],
                                                       values),
                    f"override {instance}.{name}")

    def connect(self, source: str, output: str, target: str, input_: str) -> None:
        """Connect ``source.output`` to ``target.input_`` (vector bases element by element)."""
        outs, ins = self.variables(source, output), self.variables(target, input_)
        if len(outs) != len(ins):
            raise ValueError(f"{source}.{output} has {len(outs)} elements, {target}.{input_} {len(ins)}")
        ex = self.execution
        connectors = {"REAL": ex.connect_real_variables, "INTEGER": ex.connect_integer_variables,
                      "BOOLEAN": ex.connect_boolean_variables, "STRING": ex.connect_string_variables}
        for o, i in zip(outs, ins):
            if o.type != i.type:
                raise TypeError(f"{source}.{o.name} ({o.type}) -> {target}.{i.name} ({i.type})")
            status = connectors[o.type](self.index(source), o.reference, self.index(target), i.reference)
            # libcosimpy returns libcosimc's raw status here (0: success, -1: failure), not a bool
            self._check(status == 0, f"connect {source}.{o.name} -> {target}.{i.name}")

    def get(self, instance: str, name: str):
        """Last observed value of a variable (or list for a vector base), from the last-value
        observer (values after the latest step)."""
        index = self.index(instance)
        variables = self.variables(instance, name)
        getters = {"REAL": self.observer.last_real_values, "INTEGER": self.observer.last_integer_values,
                   "BOOLEAN": self.observer.last_boolean_values, "STRING": self.observer.last_string_values}
        out = []
        for var in variables:
            (value,) = getters[var.type](index, [var.reference])
            out.append(value.decode() if isinstance(value, bytes) else value)
        return out[0] if name in self._slave(instance).variables else out

    def observe_real_outputs(self, record: list[str] | None, steps: int) -> list[tuple[str, str]]:
        """Observe, ``steps + 1`` samples each, the Real outputs matching ``record`` (fnmatch
        patterns on ``instance.variable``; default all), in the order of the slaves and of their
        value references; returns them as (instance, variable)."""
        candidates = [(inst, v.name) for inst, slave in self.slaves.items() for v in slave.variables.values()
                      if v.causality == "OUTPUT" and v.type == "REAL"]
        candidates.sort(key=lambda c: (self.slaves[c[0]].index, self.slaves[c[0]].variables[c[1]].reference))
        keep = [candidates[k] for k in select([f"{i}.{v}" for i, v in candidates], record)]
        for inst, name in keep:
            self.observe_series(inst, name, buffer_size=steps + 1)
        return keep

    def observe_series(self, instance: str, name: str, buffer_size: int = 100_000) -> None:
        """Record every step's value of Real variable(s) with a (buffered) time-series observer."""
        from libcosimpy.CosimEnums import CosimVariableType
        from libcosimpy.CosimObserver import CosimObserver

        if self.time_series is None:
            self.time_series = CosimObserver.create_time_series(buffer_size)
            self._check(self.execution.add_observer(self.time_series), "add time-series observer")
        for var in self.variables(instance, name):
            if var.type != "REAL":
                raise TypeError(f"{instance}.{var.name}: only Real variables are recorded")
            self._check(self.time_series.start_time_series(self.index(instance), var.reference,
                                                           CosimVariableType.REAL),
                        f"observe {instance}.{var.name}")

    def series(self, instance: str, name: str, from_step: int = 0, count: int = 100_000):
        """(times in s, step numbers, values) recorded for one Real variable since ``from_step``.

        Calls libcosimc directly: libcosimpy 0.0.6's ``time_series_real_samples`` trims its
        result by counting the step numbers equal to 0, so when the samples start at step 0
        (the values right after initialization) it drops the last sample."""
        from ctypes import POINTER, c_double, c_int, c_int64, c_size_t, c_uint32

        from libcosimpy.CosimObserver import CosimObserver
        from libcosimpy._internal import libcosimc, wrap_function

        if self.time_series is None:
            raise RuntimeError("no variable is observed; call observe_series() first")
        (var,) = self.variables(instance, name)
        values, steps, times = (c_double * count)(), (c_int64 * count)(), (c_int64 * count)()
        get = wrap_function(lib=libcosimc(), funcname="cosim_observer_slave_get_real_samples",
                            argtypes=[POINTER(CosimObserver), c_int, c_uint32, c_int64, c_size_t,
                                      c_double * count, c_int64 * count, c_int64 * count],
                            restype=c_int64)
        n = get(self.time_series.ptr(), self.index(instance), var.reference, from_step, count,
                values, steps, times)
        self._check(n >= 0, f"time series of {instance}.{var.name}")
        return [t / NANO for t in times[:n]], list(steps[:n]), list(values[:n])

    # -- time -----------------------------------------------------------------------------------
    def step(self, count: int = 1) -> None:
        """Advance ``count`` communication steps (the first call also initializes the FMUs)."""
        t = self.time
        self._check(self.execution.step(count), f"{count} step(s) from t = {t:.9g} s")

    @property
    def time(self) -> float:
        return self.execution.status().current_time / NANO

    def status(self):
        return self.execution.status()

    # -- life cycle -----------------------------------------------------------------------------
    def close(self) -> None:
        """Destroy the execution (which frees every FMU instance) now, rather than whenever the
        garbage collector gets to it (possibly at interpreter shutdown). Safe to call twice."""
        for attr in ("execution", "observer", "manipulator", "time_series"):
            if hasattr(self, attr):
                setattr(self, attr, None)
        self.slaves.clear()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _enum_name(enum: str, value: int) -> str:
    from libcosimpy import CosimEnums

    return getattr(CosimEnums, enum)(value).name


def run_ssp_libcosim(path: str | Path, stop_time: float, step: float, start_time: float = 0.0,
                     record: list[str] | None = None, log_level: str | None = "WARNING") -> Result:
    """Simulate an SSP with libcosim's fixed-step algorithm (see the module notes).

    ``start_time`` must be the SSD's DefaultExperiment start time (libcosim starts there).
    Returns a :class:`~robofmu.system.result.Result` with the Real outputs matching ``record``
    (fnmatch patterns on ``instance.variable``; default all Real outputs) at t0, t0 + h, ..,
    t0 + n h, recorded by a time-series observer (Boolean outputs cannot be recorded).
    """
    path = Path(path)
    n = step_count(start_time, stop_time, step)
    run = CosimRun.from_ssp(path, step, log_level, last_value=False)
    try:
        t0 = run.execution.status().current_time / NANO
        if abs(t0 - start_time) > 1e-9:
            raise ValueError(f"{path.name} starts at t = {t0} s, not {start_time} s")
        keep = run.observe_real_outputs(record, n)
        wall = _time.perf_counter()
        run.step(n)
        wall = _time.perf_counter() - wall
        data = np.empty((n + 1, len(keep)))
        times = None
        for j, (inst, name) in enumerate(keep):
            t, steps, values = run.series(inst, name, count=n + 1)
            if len(values) != n + 1:
                raise RuntimeError(f"libcosim recorded {len(values)} samples of {inst}.{name}, expected {n + 1}")
            data[:, j] = values
            times = np.asarray(t)
        if times is None:
            times = start_time + step * np.arange(n + 1)
        return Result(times, [f"{i}.{v}" for i, v in keep], data,
                      {"tool": "libcosim", "algorithm": "jacobi (libcosim fixed-step)", "step": step,
                       "wall_time": wall})
    finally:
        run.close()

"""The master's call list: the FMI calls of one exchange, or of one round of steps, made by one
ctypes call into a small C loop (``call_list.c``) instead of one ctypes call each.

A ctypes call costs about 2k instructions in libffi and ctypes before the FMU sees it; chess-pd
makes 14 FMI calls a step. :func:`batch` turns a list of :data:`~robofmu.system.exchange.Call`
tuples into one: the same calls, in the same order, on the same buffers, so a run is bit for
bit the same either way (a test). Each single call carries its :class:`Record`, the fields
the C loop needs (function pointer, component, value references, buffers); a Call without one
(none today) leaves the list to Python.

The library is compiled with ``$CC``, the machine's C compiler or Zig's the first time a process needs it
(cached beside robofmu's FMI export library, keyed by the source and the compiler) and loaded
with ``ctypes.PyDLL``: the calling thread keeps the GIL through the list, as through the
single calls (:class:`~robofmu.system.exchange.Fmi2Functions`). Where no compiler is found,
or with ``ROBOFMU_CALL_LIST=0`` in the environment, the master makes the single calls
(:func:`runner` says why, in the result's ``info["calls"]``).
"""
from __future__ import annotations

import ctypes
import hashlib
import importlib.util
import os
import shlex
import subprocess
import sys
from functools import lru_cache
from pathlib import Path
from typing import NamedTuple

import numpy as np

from robofmu.system.compiled import cache_folder, machine_compiler

__all__ = ["Batch", "Record", "batch", "runner"]

SOURCE = Path(__file__).resolve().with_name("call_list.c")
#: The kinds of call (``call_list.c``'s enum).
GET_REAL, SET_REAL, GET_BOOLEAN, SET_BOOLEAN, DO_STEP = range(5)
KINDS = {"fmi2GetReal": GET_REAL, "fmi2SetReal": SET_REAL, "fmi2GetBoolean": GET_BOOLEAN,
         "fmi2SetBoolean": SET_BOOLEAN, "fmi2DoStep": DO_STEP}
#: Environment switch: ``0`` makes the master make the single calls.
SWITCH = "ROBOFMU_CALL_LIST"


class _Call(ctypes.Structure):
    _fields_ = [("kind", ctypes.c_long), ("function", ctypes.c_void_p), ("component", ctypes.c_void_p),
                ("references", ctypes.c_void_p), ("count", ctypes.c_size_t), ("values", ctypes.c_void_p),
                ("signals", ctypes.c_void_p), ("sources", ctypes.c_void_p), ("last", ctypes.c_void_p),
                ("have_last", ctypes.c_void_p), ("time", ctypes.c_void_p), ("step", ctypes.c_double)]


class Record(NamedTuple):
    """What the C loop needs of one call; the arrays it points into are kept here, alive.

    Attributes
    ----------
    function : ctypes function
        The FMU's fmi2GetReal ... fmi2DoStep (:class:`~robofmu.system.exchange.Fmi2Functions`).
    component : int
        The instance's fmi2Component.
    references : ctypes array or None
        The value references (None for fmi2DoStep).
    count : int
    values : ndarray or ctypes array or None
        The buffer the call reads or writes.
    signals, sources : ndarray or None
        For a set gathered from a signal vector: the vector and the indices in it.
    last, have_last : ndarray or None
        fmi2SetBoolean: the values last set (int32, count) and whether there are any (int32, 1).
    time : ctypes.c_double or None
        fmi2DoStep: the communication point the loop sets.
    step : float
        fmi2DoStep: the step size (s).
    """

    function: object
    component: int
    references: object = None
    count: int = 0
    values: object = None
    signals: np.ndarray | None = None
    sources: np.ndarray | None = None
    last: np.ndarray | None = None
    have_last: np.ndarray | None = None
    time: object = None
    step: float = 0.0


def _address(value) -> int | None:
    if value is None:
        return None
    if isinstance(value, np.ndarray):
        return value.ctypes.data
    return ctypes.addressof(value)


class Batch:
    """One call list: the C records, the names of the calls for the failure, the last failed index.

    Parameters
    ----------
    run : ctypes function
        ``robofmu_run_calls`` (:func:`runner`).
    calls : list of Call
        Single calls, each with its :class:`Record` (5th element).

    Attributes
    ----------
    call : Call
        ``(run, arguments, self, None, None)``: the loop makes ``status = run(*arguments)`` as
        for a single call and hands ``self`` to :func:`~robofmu.system.exchange.failed`.
    """

    def __init__(self, run, calls: list):
        self.names = [(block, call) for _, _, block, call, _ in calls]
        self.records = [record for *_, record in calls]       # keeps the buffers alive
        self.array = (_Call * max(len(calls), 1))()
        for c, (_, _, _, name, record) in zip(self.array, calls):
            c.kind = KINDS[name]
            c.function = ctypes.cast(record.function, ctypes.c_void_p).value
            c.component = record.component
            c.references = _address(record.references)
            c.count = record.count
            c.values = _address(record.values)
            c.signals = _address(record.signals)
            c.sources = _address(record.sources)
            c.last = _address(record.last)
            c.have_last = _address(record.have_last)
            c.time = _address(record.time)
            c.step = record.step
        self.failed_index = ctypes.c_size_t(0)
        self.call = (run, (ctypes.byref(self.array), ctypes.c_size_t.from_param(len(calls)),
                           ctypes.byref(self.failed_index)), self, None, None)

    def failed(self) -> tuple[str, str]:
        """The block and the FMI function of the call that failed last."""
        return self.names[self.failed_index.value]


def batch(run, calls: list) -> list:
    """``calls`` as one call of ``run`` (a list of one Call), or as they are if ``run`` is None,
    if there are fewer than two, or if one has no :class:`Record`."""
    if run is None or len(calls) < 2 or any(call[4] is None for call in calls):
        return calls
    return [Batch(run, calls).call]


def _compiler() -> list[str] | None:
    """$CC, else the machine's compiler, else Zig's (``ziglang``, the dev extra), else None."""
    if os.environ.get("CC"):
        return shlex.split(os.environ["CC"])
    found = machine_compiler()
    if found is None and importlib.util.find_spec("ziglang") is not None:
        found = [sys.executable, "-m", "ziglang", "cc"]
    return found


@lru_cache(maxsize=1)
def runner() -> tuple[object, str]:
    """``robofmu_run_calls`` of the compiled call list, or None, and how the master makes its calls.

    Returns
    -------
    run : ctypes function or None
    how : str
        ``"call list (<library>)"``, or ``"single ctypes calls: <why>"``.
    """
    if os.environ.get(SWITCH, "1") == "0":
        return None, f"single ctypes calls: {SWITCH}=0"
    cc = _compiler()
    if cc is None:
        return None, "single ctypes calls: no C compiler ($CC, cc, gcc, clang) for the call list"
    try:
        version = subprocess.run(cc + ["--version"], capture_output=True, text=True, timeout=60).stdout
        folder = cache_folder()
    except (OSError, subprocess.SubprocessError) as exc:
        return None, f"single ctypes calls: {exc}"
    flags = ["-shared", "-fPIC", "-O2", "-Wall", "-fvisibility=hidden"]
    key = hashlib.sha256(b"\0".join([SOURCE.read_bytes(), shlex.join(cc + flags).encode(), version.encode()]))
    target = folder / key.hexdigest()[:16] / "call_list.so"
    if not target.is_file():
        target.parent.mkdir(parents=True, exist_ok=True)
        partial = target.with_name(f".{target.name}.{os.getpid()}")
        try:
            done = subprocess.run(cc + flags + ["-o", str(partial), str(SOURCE)], capture_output=True,
                                  text=True, timeout=300)
        except (OSError, subprocess.SubprocessError) as exc:
            return None, f"single ctypes calls: compiling {SOURCE.name} failed: {exc}"
        if done.returncode != 0 or not partial.is_file():
            partial.unlink(missing_ok=True)
            said = (done.stderr.strip() or done.stdout.strip()).splitlines()
            return None, (f"single ctypes calls: compiling {SOURCE.name} failed (exit status {done.returncode})"
                          + (f": {said[0]}" if said else ""))
        os.replace(partial, target)
    library = ctypes.PyDLL(str(target))
    size = library.robofmu_call_size
    size.restype = ctypes.c_size_t
    offsets = (ctypes.c_size_t * len(_Call._fields_))()
    library.robofmu_call_offsets(offsets)
    expected = [getattr(_Call, name).offset for name, _ in _Call._fields_]
    if size() != ctypes.sizeof(_Call) or list(offsets) != expected:
        return None, f"single ctypes calls: {target} lays its record out unlike {__name__}._Call"
    run = library.robofmu_run_calls
    run.restype = ctypes.c_int
    return run, f"call list ({target})"

"""Workarounds for pythonfmu 0.7.0's export library (docs/design.md, the pythonfmu workarounds).

- Its loader releases a reference it does not own to the script module's globals at every
  instantiation: :func:`balance_pythonfmu_refcount`.
- Its exception handler releases the instance, its class and its log queue once too often:
  :func:`keep_for_pythonfmu_handler`, and no exception reaches it behind robofmu's export
  library (:func:`fmi_entry`, applied to every FMI method by :func:`guard_entry_points`).
- Its fmi2SetString cannot convert a value that is not UTF-8: robofmu's export library forwards
  such a value as :data:`.contract.NOT_UTF8` and hex, which :func:`string_value` decodes.
"""
from __future__ import annotations

import ctypes
import functools
import sys

from .contract import NOT_UTF8

__all__ = ["balance_pythonfmu_refcount", "fmi_entry", "guard_entry_points", "keep_for_pythonfmu_handler",
           "string_value"]


def balance_pythonfmu_refcount(cls) -> None:
    """Work around pythonfmu 0.7.0's loader, which releases a reference it does not own to the
    script module's globals at every instantiation (``Py_DECREF`` of ``PyModule_GetDict``):
    without this the second instance of a FMU in one process finds its module emptied.
    The generated script keeps one extra reference (``_keepalive = globals()``); this adds back
    the one the loader takes. If a later pythonfmu fixes the loader, this leaks one reference
    per instance, which is harmless."""
    module = sys.modules.get(cls.__module__)
    if module is not None and "_keepalive" in vars(module):
        ctypes.pythonapi.Py_IncRef(ctypes.py_object(module.__dict__))


def keep_for_pythonfmu_handler(slave) -> None:
    """pythonfmu 0.7.0's exception handler releases the instance, its class and its log queue
    once more than it took them (and again when the instance is freed): take those references
    before an exception reaches it, so that freeing the instance later does not crash."""
    for obj in (slave, slave.log_queue, type(slave)):
        ctypes.pythonapi.Py_IncRef(ctypes.py_object(obj))


def string_value(value) -> tuple:
    """``(value, problem)`` for a fmi2SetString value: the value to set (a string robofmu's
    export library forwarded as :data:`.contract.NOT_UTF8` and hex, decoded where it is valid
    UTF-8 after all), and why it cannot be set, or None."""
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


def fmi_entry(method, fallback, call: str):
    """``method``, as pythonfmu's library calls it for the FMI function ``call``.

    Behind robofmu's export library a failure (``_raise_to_importer``, or any exception, then
    logged with its traceback) returns ``fallback(*args)``: the logged
    :data:`.contract.STATUS_CATEGORY` message makes the call return fmi2Error, and the instance
    stays usable. Behind pythonfmu's library alone the exception propagates (fmi2Fatal), after
    the references its handler drops are taken."""
    @functools.wraps(method)
    def entry(self, *args):
        try:
            return method(self, *args)
        except BaseException as exc:    # a KeyboardInterrupt too: an interruption (_report_failure)
            self._report_failure(exc, call)
            if not self._statuses:
                keep_for_pythonfmu_handler(self)
                raise
        return fallback(*args)
    return entry


_NOTHING = lambda *args: None  # noqa: E731

#: The methods pythonfmu's library calls: (method, FMI function, what it returns after a failure).
ENTRY_POINTS = [
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
    ("_set_fmu_state", "fmi2SetFMUstate", _NOTHING)]


def guard_entry_points(cls) -> type:
    """Wrap every method of :data:`ENTRY_POINTS` of ``cls`` with :func:`fmi_entry` (in place),
    and keep ``do_step`` unwrapped as ``_do_step``: the fast path's step calls it, catching,
    logging and failing itself. Returns ``cls``."""
    for name, call, fallback in ENTRY_POINTS:
        setattr(cls, name, fmi_entry(getattr(cls, name), fallback, call))
    cls._do_step = cls.do_step.__wrapped__
    return cls

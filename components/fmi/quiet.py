"""Calls with NumPy's floating-point warnings off, at the cost of two context-variable writes.

A FMU runs inside its importer's process: an overflow in a block must come back as the FMU's own
error message (the wrapper checks every output), not as a RuntimeWarning printed by the host.
``numpy.errstate`` does that but builds its state anew at every entry (about 2 µs, twice per
block-step); :func:`quietly` sets the same state, built once, on NumPy's error-state context
variable (NumPy >= 2: ``numpy._core._ufunc_config``) and falls back to ``numpy.errstate`` where
that is not found. :func:`quiet_context` makes a context in which that state holds, for C code
that enters it around its calls into Python (robofmu's FMI export library, on its fast path):
entering a context allocates nothing, setting the variable makes a new mapping and a token.
"""
from __future__ import annotations

import contextvars

import numpy as np

try:
    from numpy._core._ufunc_config import _extobj_contextvar, _make_extobj
    _IGNORE = _make_extobj(all="ignore")
except (ImportError, AttributeError, TypeError):        # another NumPy: the public way
    _extobj_contextvar = _IGNORE = None


def quiet_context() -> contextvars.Context | None:
    """A copy of the current context with NumPy's floating-point errors ignored (what
    :func:`quietly` sets), for code that runs calls in it; None where this NumPy has no
    error-state context variable."""
    if _extobj_contextvar is None:
        return None
    context = contextvars.copy_context()
    context.run(_extobj_contextvar.set, _IGNORE)
    return context


def quietly(function, *args):
    """``function(*args)`` with NumPy's floating-point errors ignored (as in
    ``numpy.errstate(all="ignore")``); the previous state is back afterwards, whatever happens."""
    if _extobj_contextvar is None:
        with np.errstate(all="ignore"):
            return function(*args)
    token = _extobj_contextvar.set(_IGNORE)
    try:
        return function(*args)
    finally:
        _extobj_contextvar.reset(token)

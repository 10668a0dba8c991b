"""Python floats into NumPy arrays, for block logic that does its arithmetic in floats.

A block's vectors hold a few values (n joints, m task coordinates). On so few, Python's own
arithmetic (over ``array.tolist()``) costs less than a NumPy ufunc call per operation; the result
then goes back into an array. ``array[:] = values`` converts the list through NumPy's generic
sequence path; :class:`FloatWriter` packs the floats into the array's memory directly
(``struct.pack_into``), the same bits in about half the time.
"""
from __future__ import annotations

import struct

import numpy as np


class FloatWriter:
    """Writes ``array.size`` floats into ``array`` (float64, C-contiguous), every call.

    Parameters
    ----------
    array : ndarray
        The destination (a view is fine: it is written in place, and kept alive by the writer).

    Examples
    --------
    >>> a = np.zeros(3)
    >>> FloatWriter(a)([1.0, 2.0, 3.0]); a.tolist()
    [1.0, 2.0, 3.0]
    """

    def __init__(self, array: np.ndarray):
        if array.dtype != np.float64 or not array.flags.c_contiguous or not array.flags.writeable:
            raise ValueError("FloatWriter: needs a writeable, C-contiguous float64 array")
        self.size = array.size
        self._memory = memoryview(array).cast("B")
        self._pack = struct.Struct(f"={array.size}d").pack_into

    def __call__(self, values) -> None:
        """``array[:] = values`` for a sequence of exactly ``size`` floats."""
        self._pack(self._memory, 0, *values)

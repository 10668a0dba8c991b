"""Text values of String parameters: matrices as ``"x y z; x y z"``, vectors as ``"1 3 1"``."""
from __future__ import annotations

import numpy as np


def parse_matrix(text: str, name: str, columns: int | None = None) -> np.ndarray:
    """Parse ``"x y z; x y z; ..."`` (commas also separate numbers) into a 2-D array.

    Raises ValueError naming ``name`` if the text is malformed.
    """
    rows = [r for r in text.replace("\n", ";").split(";") if r.strip()]
    try:
        values = [[float(v) for v in r.replace(",", " ").split()] for r in rows]
    except ValueError as exc:
        raise ValueError(f"{name}: malformed number ({exc}) in {text!r}") from None
    if not values or len({len(v) for v in values}) != 1:
        raise ValueError(f"{name}: rows must all have the same number of values, got {text!r}")
    if columns is not None and len(values[0]) != columns:
        raise ValueError(f"{name}: each row needs {columns} values, got {len(values[0])} in {text!r}")
    return np.array(values)


def parse_vector(text: str, name: str) -> np.ndarray:
    """Parse ``"1 3 1"`` (or comma-separated) into a 1-D array; ValueError naming ``name``."""
    try:
        values = [float(v) for v in text.replace(",", " ").split()]
    except ValueError as exc:
        raise ValueError(f"{name}: malformed number ({exc}) in {text!r}") from None
    if not values:
        raise ValueError(f"{name}: empty")
    return np.array(values)


def format_matrix(rows) -> str:
    """Inverse of :func:`parse_matrix`, exact for floats (repr)."""
    return "; ".join(" ".join(repr(float(v)) for v in row) for row in np.atleast_2d(rows))


def format_vector(values) -> str:
    """Inverse of :func:`parse_vector`."""
    return " ".join(repr(float(v)) for v in values)

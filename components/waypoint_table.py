"""Waypoint tables: a profile's waypoints read from a CSV file beside the robot's TOML."""
from __future__ import annotations

import csv
import math
from pathlib import Path


def read_table(path, columns) -> list[list[float]]:
    """Rows of numbers from a CSV file: one row per waypoint, one column per task coordinate.

    An optional first row names the columns; it must name ``columns`` in order. Blank lines and
    lines starting with ``#`` are skipped.

    Raises
    ------
    ValueError
        Naming the file, and the line of a row that is not ``len(columns)`` finite numbers.
    """
    path = Path(path)
    try:
        lines = path.read_text().splitlines()
    except OSError as exc:
        raise ValueError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    rows = []
    for number, row in enumerate(csv.reader(lines), start=1):
        cells = [c.strip() for c in row]
        if not any(cells) or cells[0].startswith("#"):
            continue
        try:
            values = [float(c) for c in cells]
        except ValueError:
            if rows or [c for c in cells] != list(columns):
                raise ValueError(f"{path}, line {number}: expected {len(columns)} numbers ("
                                 f"{', '.join(columns)}) or, first, the header {','.join(columns)}; "
                                 f"got {','.join(cells)!r}") from None
            continue
        if len(values) != len(columns) or not all(math.isfinite(v) for v in values):
            raise ValueError(f"{path}, line {number}: expected {len(columns)} finite numbers ("
                             f"{', '.join(columns)}), got {','.join(cells)!r}")
        rows.append(values)
    if len(rows) < 2:
        raise ValueError(f"{path}: needs at least two waypoints, got {len(rows)}")
    return rows

"""Recorded signals of a run: times, one column per ``instance.variable``, and their units.

Every runner (the master, the SSP runners, the monolithic reference) returns a :class:`Result`.
On disk it is a CSV file: a header ``time,instance.variable,...`` and one row per recorded
point, every number written with ``repr`` (exact round trip). Units are not written; they come
from the FMUs' model descriptions and live in :attr:`Result.units` only.
"""
from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


@dataclass
class Result:
    """Recorded signals.

    Parameters
    ----------
    time : ndarray, shape (n,)
        Recorded points (s).
    columns : list of str, length m
        One name per signal, ``instance.variable`` (e.g. ``plant.q[2]``).
    data : ndarray, shape (n, m)
        ``data[k, j]`` is signal ``columns[j]`` at ``time[k]`` (Booleans as 0.0 / 1.0), in the
        unit ``units.get(columns[j])``.
    info : dict
        What produced the run (``algorithm``, ``step`` in s, ``wall_time`` in s, ``failed``, ...).
    units : dict of str to str
        Unit of each column that has one (the FMU variable's ``unit``, else its declared
        type's), e.g. ``{"plant.q[2]": "rad"}``; columns without a unit are absent. May be
        empty (a result read from CSV, or from a runner that knows no units).
    """

    time: np.ndarray
    columns: list[str]
    data: np.ndarray
    info: dict = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)

    def __getitem__(self, name: str) -> np.ndarray:
        """One recorded signal, shape (n,)."""
        try:
            return self.data[:, self.columns.index(name)]
        except ValueError:
            raise KeyError(f"no recorded signal {name!r}") from None

    def vector(self, name: str) -> np.ndarray:
        """All recorded indices of a vector base, in column order: ``plant.q`` -> shape (n, 4)."""
        indices = [k for k, column in enumerate(self.columns) if column.startswith(name + "[")]
        if not indices:
            raise KeyError(f"no recorded vector {name!r}")
        return self.data[:, indices]

    def to_csv(self, path: str | Path) -> Path:
        """Write ``time`` then one column per signal (``instance.variable``), full precision.

        Parent folders are created; returns the path. Units are not written.
        """
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(["time", *self.columns])
            for t, values in zip(self.time, self.data):
                writer.writerow([repr(float(t)), *(repr(float(v)) for v in values)])
        return path

    @classmethod
    def from_csv(cls, path: str | Path) -> "Result":
        """Read a file written by :meth:`to_csv` (``info`` and ``units`` come back empty)."""
        with Path(path).open() as f:
            rows = list(csv.reader(f))
        header = rows[0]
        table = np.array([[float(v) for v in row] for row in rows[1:]]).reshape(-1, len(header))
        return cls(table[:, 0], header[1:], table[:, 1:])

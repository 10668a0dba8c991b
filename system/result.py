"""Recorded signals of a run: times, one column per ``instance.variable``, and their units.

Every runner (the master, the SSP runners, the monolithic reference) returns a :class:`Result`.
On disk it is a CSV file: a header ``time,instance.variable,...`` and one row per recorded
point, every number written with ``repr`` (exact round trip). Units are not written; they come
from the FMUs' model descriptions and live in :attr:`Result.units` only. For large runs the
same table is written as Parquet (:meth:`Result.to_parquet`: float64 columns, exact, about 30x
faster to write than the CSV), with each column's unit in its field metadata and ``info`` in
the file's.
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

    def to_parquet(self, path: str | Path) -> Path:
        """Write ``time`` then one float64 column per signal as Parquet (pyarrow), exactly.

        Each column's unit is its field's ``unit`` metadata; :attr:`info` (numbers and strings)
        is the file's ``robofmu.info`` metadata (JSON). Parent folders are created; returns the
        path.
        """
        import json

        import pyarrow as pa
        import pyarrow.parquet as pq

        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        fields = [pa.field("time", pa.float64(), metadata={"unit": "s"})]
        fields += [pa.field(c, pa.float64(), metadata={"unit": self.units[c]} if c in self.units else None)
                   for c in self.columns]
        info = {k: v for k, v in self.info.items() if isinstance(v, (bool, int, float, str))}
        schema = pa.schema(fields, metadata={"robofmu.info": json.dumps(info)})
        arrays = [pa.array(np.asarray(self.time, dtype=float))]
        arrays += [pa.array(np.ascontiguousarray(self.data[:, k], dtype=float)) for k in range(len(self.columns))]
        pq.write_table(pa.Table.from_arrays(arrays, schema=schema), path)
        return path

    @classmethod
    def from_parquet(cls, path: str | Path) -> "Result":
        """Read a file written by :meth:`to_parquet` (with its units and info)."""
        import json

        import pyarrow.parquet as pq

        table = pq.read_table(path)
        names = table.column_names
        if not names or names[0] != "time":
            raise ValueError(f"{path}: not a robofmu result (its first column is not `time`)")
        data = np.column_stack([table.column(k).to_numpy() for k in range(1, len(names))]) \
            if len(names) > 1 else np.empty((table.num_rows, 0))
        units = {}
        for column in list(table.schema)[1:]:
            if column.metadata and b"unit" in column.metadata:
                units[column.name] = column.metadata[b"unit"].decode()
        metadata = table.schema.metadata or {}
        info = json.loads(metadata.get(b"robofmu.info", b"{}"))
        return cls(table.column(0).to_numpy(), names[1:], data, info, units)

    def write(self, path: str | Path) -> Path:
        """Write as CSV or Parquet, by the suffix of ``path`` (``.csv`` / ``.parquet``)."""
        path = Path(path)
        if path.suffix == ".parquet":
            return self.to_parquet(path)
        if path.suffix == ".csv":
            return self.to_csv(path)
        raise ValueError(f"{path}: a result file is .csv or .parquet")

    @classmethod
    def read(cls, path: str | Path) -> "Result":
        """Read a ``.csv`` or ``.parquet`` result file."""
        path = Path(path)
        return cls.from_parquet(path) if path.suffix == ".parquet" else cls.from_csv(path)

    @classmethod
    def from_csv(cls, path: str | Path) -> "Result":
        """Read a file written by :meth:`to_csv` (``info`` and ``units`` come back empty)."""
        with Path(path).open() as f:
            rows = list(csv.reader(f))
        header = rows[0]
        table = np.array([[float(v) for v in row] for row in rows[1:]]).reshape(-1, len(header))
        return cls(table[:, 0], header[1:], table[:, 1:])

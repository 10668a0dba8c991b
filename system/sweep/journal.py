"""``sweep.csv``: the rows of a sweep, appended as runs finish, and its Parquet copy.

A row is written (and flushed to disk) as soon as its run's record arrives, so an interrupted
sweep keeps every finished run, and a rerun into the same folder reads them back and skips
them. ``sweep.parquet`` beside it is rewritten (atomically) at most every
:data:`PARQUET_EVERY` seconds while rows arrive, so it is never far behind. A row is identified
by its varied values, written exactly (``repr`` of the float); a line cut short by a crash is
dropped when the file is read back. :meth:`Journal.finish` rewrites both files in the order of
the runs.
"""
from __future__ import annotations

import csv
import math
import os
import time
from pathlib import Path

from robofmu.system.sweep.design import RENAMED_AXES
from robofmu.system.usage import atomic_file

__all__ = ["Journal", "cell", "key_of"]

#: The columns after the metrics.
TRAILER = ["wall_time", "status", "message"]

#: Seconds between rewrites of ``sweep.parquet`` while rows arrive.
PARQUET_EVERY = 5.0


def cell(value) -> str:
    """A value as ``sweep.csv`` writes it: floats exactly (repr), booleans true/false, NaN and
    missing values empty."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        value = float(value)
        return "" if math.isnan(value) else repr(value)
    return str(value)


def key_of(values: dict, names: list[str]) -> tuple[str, ...]:
    """The identity of a run: its varied values as written."""
    return tuple(cell(values[name]) for name in names)


class Journal:
    """``folder/sweep.csv`` with the given columns (the varied names, the metrics, then
    ``wall_time``, ``status``, ``message``).

    An existing file with the same header is continued (an axis named by its earlier name,
    :data:`~robofmu.system.sweep.design.RENAMED_AXES`, is read and rewritten under its current
    one); one with another header raises ValueError (another sweep was written there).
    """

    def __init__(self, folder: Path, names: list[str], metrics: list[str]):
        self.path = Path(folder) / "sweep.csv"
        self.names = names
        self.columns = [*names, *metrics, *TRAILER]
        self.rows: dict[tuple, dict[str, str]] = {}
        self._parquet_at = time.monotonic()
        if self.path.is_file():
            self._read()
        self._file = None

    def _read(self) -> None:
        with self.path.open(newline="") as f:
            lines = list(csv.reader(f))
        if not lines:
            return
        if [RENAMED_AXES.get(c, c) for c in lines[0]] != self.columns:       # an earlier sweep's names too
            raise ValueError(f"{self.path}: its columns are not this sweep's ({', '.join(lines[0][:4])}, ...)")
        for line in lines[1:]:
            if len(line) == len(self.columns) and line[-2] in ("ok", "failed"):
                row = dict(zip(self.columns, line))
                self.rows[tuple(row[n] for n in self.names)] = row
        self._rewrite(list(self.rows.values()))          # drop a line cut short

    def _rewrite(self, rows: list[dict[str, str]]) -> None:
        with atomic_file(self.path) as temporary, temporary.open("w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(self.columns)
            writer.writerows([row[c] for c in self.columns] for row in rows)

    def forget_failed(self) -> int:
        """Drop the failed rows (to run them again); returns how many."""
        failed = [k for k, row in self.rows.items() if row["status"] != "ok"]
        for k in failed:
            del self.rows[k]
        if failed:
            self._rewrite(list(self.rows.values()))
        return len(failed)

    def append(self, record: dict) -> dict[str, str]:
        """Write one run's record (missing metrics empty) and flush it to disk.

        The row is kept in memory before it is written: a Ctrl-C that lands while the write or
        the fsync is under way (the line may already be visible to readers) cannot leave a row
        on disk that :meth:`finish`, which rewrites the file from memory, would drop.
        """
        row = {c: cell(record.get(c)) for c in self.columns}
        self.rows[tuple(row[n] for n in self.names)] = row
        if self._file is None:
            new = not self.path.is_file() or self.path.stat().st_size == 0
            self._file = self.path.open("a", newline="")
            self._writer = csv.writer(self._file)
            if new:
                self._writer.writerow(self.columns)
        self._writer.writerow([row[c] for c in self.columns])
        self._file.flush()
        os.fsync(self._file.fileno())
        if time.monotonic() - self._parquet_at >= PARQUET_EVERY:
            self.write_parquet(list(self.rows.values()))
        return row

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None

    def finish(self, order: list[tuple]) -> list[dict[str, str]]:
        """Rewrite ``sweep.csv`` in run order, write ``sweep.parquet``; returns the rows."""
        self.close()
        rows = [self.rows[k] for k in order if k in self.rows]
        self._rewrite(rows)
        self.write_parquet(rows)
        return rows

    def write_parquet(self, rows: list[dict[str, str]]) -> Path:
        """``sweep.parquet``: the same table, numbers as float64 (NaN where empty), text as strings."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        table = {}
        for c in self.columns:
            texts = [row[c] for row in rows]
            if c in ("status", "message"):
                table[c] = pa.array(texts, pa.string())
            elif texts and all(t in ("true", "false") for t in texts):
                table[c] = pa.array([t == "true" for t in texts], pa.bool_())
            else:
                table[c] = pa.array([float(t) if t else float("nan") for t in texts], pa.float64())
        path = self.path.with_suffix(".parquet")
        with atomic_file(path) as temporary:
            pq.write_table(pa.table(table), temporary)
        self._parquet_at = time.monotonic()
        return path

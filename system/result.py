"""Recorded signals of a run: times, one column per ``instance.variable``, and their units.

Every runner (the master, the SSP runners, the monolithic reference) returns a :class:`Result`.
On disk it is a CSV file: a header ``time,instance.variable,...`` and one row per recorded
point, every number written with ``repr`` (exact round trip). Units are not written; they come
from the FMUs' model descriptions and live in :attr:`Result.units` only. For large runs the
same table is written as Parquet (:meth:`Result.to_parquet`: float64 columns, exact, about 30x
faster to write than the CSV), with each column's unit in its field metadata and ``info`` in
the file's.

A run by the master also carries what its FMUs logged: :attr:`Result.log`, every message with
the communication point it arrived at (:class:`Message`), and :attr:`Result.messages`, the same
grouped (:func:`group_messages`), with the excursions the record shows in the blocks' health
outputs (:data:`HEALTH`: a ``status`` other than 0, a ``reachable`` or ``within_limits`` that is
false).
"""
from __future__ import annotations

import csv
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

#: The outputs that tell whether a block did what it was asked, by variable name, and the value
#: that means it did: a recorded ``<instance>.status`` other than 0 or a ``reachable`` /
#: ``within_limits`` that is false is an excursion (:func:`group_messages`). A ``status``'s codes
#: are named by its description, ``"0 converged, 1 not converged (out of reach?), ..."``.
HEALTH = {"status": 0.0, "reachable": 1.0, "within_limits": 1.0}

#: A number in a message (not a digit inside a name such as ``panda_joint1``): what
#: :func:`message_pattern` replaces by ``#``.
_NUMBER = re.compile(r"(?<![\w.])[-+]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|nan|inf)(?!\w)")
#: The time a block puts before its message (``"t = 0.33 s: "``): the message's time says it.
_TIME_PREFIX = re.compile(r"^t = [^ ]+ s: ")
_STATED_TIME = re.compile(r"^t = ([^ ]+) s: ")


def stated_time(text: str, clock: float) -> float:
    """The time (s) a block's message states in its ``"t = <time> s: "`` prefix, else ``clock``.

    A block without feedthrough evaluates its outputs for t + h inside the step from t, so its
    own word on when is kept over the master's communication point.
    """
    match = _STATED_TIME.match(text)
    if match is None:
        return clock
    try:
        stated = float(match.group(1))
    except ValueError:
        return clock
    return stated if math.isfinite(stated) else clock


@dataclass(frozen=True)
class Message:
    """One message an FMU logged during a run.

    Attributes
    ----------
    block : str
        The instance that logged it.
    status : str
        ``"WARNING"``, ``"ERROR"``, ``"DISCARD"``, ``"FATAL"``, or ``"OK"`` (debug).
    category : str
        The FMI log category (``"logStatusWarning"``, ...).
    text : str
        The FMU's words, without the ``"<block>: "`` the slave puts before them.
    time : float
        The time (s) the block states in its ``"t = <time> s: "`` prefix (a block without
        feedthrough says t + h for outputs it evaluates in the step from t); else the
        communication point at which it arrived: the start time during initialization, t during
        the exchange at t and the step from t.
    """

    block: str
    status: str
    category: str
    text: str
    time: float

    def __str__(self) -> str:
        return f"t = {self.time:.9g} s [{self.status}] {self.block}: {self.text}"


@dataclass(frozen=True)
class MessageGroup:
    """Messages of one block alike but for their numbers, or one excursion of a health output.

    Attributes
    ----------
    block : str
    status : str
        The messages' status (``"WARNING"``, ...); ``""`` for a group read from the record only
        (no message told it).
    text : str
        The first message's words (its time prefix removed), or what the health output says
        (``"not converged (status 1, 2670 steps)"``).
    count : int
        Messages in the group (0: read from the record only).
    first, last : float
        The first message's time and the last instant of the group (s): its last message or the
        end of the excursion the record shows, whichever is later (a group read from the record:
        its first and last points).
    last_message : float or None
        The last message's time (s); None for a group read from the record.
    steps : int or None
        Recorded points at which the block's health outputs (:data:`HEALTH`) were off in the
        excursions the messages started; None where nothing recorded tells.
    signals : tuple of str
        Those outputs (``"ik.reachable"``).
    """

    block: str
    status: str
    text: str
    count: int
    first: float
    last: float
    last_message: float | None = None
    steps: int | None = None
    signals: tuple[str, ...] = ()

    def __str__(self) -> str:
        """One line: ``ik: not converged (status 1, 2670 steps) from t = 0.33 s to 3 s, 2670
        steps``, ``plant: WARNING once at t = 0.187 s: joint 3 ... (plant.within_limits off at
        t = 0.187 s, 1 step)``."""
        if not self.count:
            return f"{self.block}: {self.text} {_span(self.first, self.last)}, {_steps(self.steps)}"
        said = self.text.split("\n", 1)[0]
        times = "once" if self.count == 1 else f"{self.count} times"
        line = f"{self.block}: {self.status} {times} {_span(self.first, self.last_message)}: {said}"
        if self.steps is not None:
            line += (f" ({' and '.join(self.signals)} off {_span(self.first, self.last)}, "
                     f"{_steps(self.steps)})")
        return line

    def short(self) -> str:
        """A few words for a summary line: ``ik not converged for 2670 steps``, ``plant: 1 warning``."""
        if not self.count:
            return f"{self.block} {self.text}"
        return f"{self.block}: {self.count} {self.status.lower()}{'s' if self.count > 1 else ''}"


def _span(first: float, last: float) -> str:
    return f"at t = {first:g} s" if last == first else f"from t = {first:g} s to {last:g} s"


def _steps(n: int | None) -> str:
    return f"{n} step{'' if n == 1 else 's'}"


def message_pattern(text: str) -> str:
    """A message with its time prefix removed and every number replaced by ``#``: what messages
    alike share (``"joint # (elbow_joint) velocity # rad/s exceeds its limit # rad/s"``)."""
    return _NUMBER.sub("#", _TIME_PREFIX.sub("", text))


def status_meanings(description: str) -> dict[int, str]:
    """The codes a ``status`` output's description names, ``"0 converged, 1 not converged (out
    of reach?), 2 near a singularity"`` -> ``{0: "converged", 1: "not converged", ...}`` (words
    in parentheses left out); {} where it names none."""
    found = {}
    for code, words in re.findall(r"(?:^|,)\s*(\d+)\s+([^,]+)", description or ""):
        found[int(code)] = re.sub(r"\s*\([^)]*\)", "", words).strip() or words.strip()
    return found


def group_messages(log: list[Message], time: np.ndarray, columns: list[str], data: np.ndarray,
                   meanings: dict[str, dict[int, str]] | None = None,
                   order: list[str] | None = None) -> list[MessageGroup]:
    """What the FMUs of a run said, grouped, with the excursions their health outputs recorded.

    Messages of one block with one status and one :func:`message_pattern` make one group
    (warnings and worse: a debug message, status OK, stays in the log only). A
    message logged at a point where a recorded health output of its block (:data:`HEALTH`) is
    off starts an excursion lasting until that output is back (a block warns once per
    excursion): the group counts those points (``steps``) and ends with them. Recorded points
    where a health output is off that no message started make a group of their own (``count``
    0), e.g. an IK's ``status`` other than 0.

    Parameters
    ----------
    log : list of Message
        In the order logged.
    time : ndarray, shape (k,)
        The recorded points (s).
    columns : list of str, length m
    data : ndarray, shape (k, m)
    meanings : dict, optional
        ``"<instance>.status"`` -> its codes' words (:func:`status_meanings`).
    order : list of str, optional
        The blocks in the diagram's evaluation order: groups whose first messages fall on one
        recorded point follow it (a block without feedthrough speaks for t + h in the step
        from t, before the exchange at t + h); else, and among one block's, the order logged.

    Returns
    -------
    list of MessageGroup
        Message groups in the order of their first message's point, then the record's groups.
    """
    meanings = meanings or {}
    time = np.asarray(time, dtype=float)
    health = {}                                   # column -> (block, off: bool array)
    for j, column in enumerate(columns):
        block, _, name = column.partition(".")
        if name in HEALTH and len(time):
            health[column] = (block, data[:, j] != HEALTH[name])
    covered = {column: np.zeros(len(time), dtype=bool) for column in health}
    groups: dict[tuple[str, str, str], dict] = {}
    for message in log:
        if message.status == "OK":
            continue
        key = (message.block, message.status, message_pattern(message.text))
        k = int(np.searchsorted(time, message.time - 1e-9 * max(1.0, abs(message.time))))
        group = groups.setdefault(key, {"first": message, "count": 0, "last": message.time, "point": k,
                                        "rows": np.zeros(len(time), dtype=bool), "signals": []})
        group["count"] += 1
        group["last"] = max(group["last"], message.time)
        for column, (block, off) in health.items():
            if block != message.block or k >= len(time) or not off[k]:
                continue
            back = np.flatnonzero(~off[k:])
            end = k + int(back[0]) if back.size else len(time)
            group["rows"][k:end] = True
            covered[column][k:end] = True
            if column not in group["signals"]:
                group["signals"].append(column)
    rank = {block: j for j, block in enumerate(order or ())}
    found = []
    ranked = sorted(groups.items(), key=lambda item: (item[1]["point"], rank.get(item[0][0], len(rank))))
    for (block, status, _), group in ranked:
        first, rows = group["first"], group["rows"]
        last = max(group["last"], float(time[np.flatnonzero(rows)[-1]])) if rows.any() else group["last"]
        found.append(MessageGroup(block, status, _TIME_PREFIX.sub("", first.text), group["count"], first.time,
                                  last, group["last"], int(rows.sum()) if group["signals"] else None,
                                  tuple(group["signals"])))
    for column, (block, off) in health.items():
        alone = off & ~covered[column]
        if not alone.any():
            continue
        rows = np.flatnonzero(alone)
        name = column.partition(".")[2]
        if name == "status":
            j = columns.index(column)
            codes, counts = np.unique(data[rows, j], return_counts=True)
            words = meanings.get(column, {})
            text = ", ".join(f"{words.get(int(c), 'status') if float(c).is_integer() else 'status'} "
                             f"(status {c:g}, {_steps(int(n))})"
                             for c, n in sorted(zip(codes, counts), key=lambda cn: -cn[1]))
        else:
            text = f"{name} false"
        found.append(MessageGroup(block, "", text, 0, float(time[rows[0]]), float(time[rows[-1]]), None,
                                  len(rows), (column,)))
    return found


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
    log : list of Message
        Every message the FMUs logged during the run (warnings and errors; debug messages too
        where the master was asked for them), in order; empty from other runners and files.
    messages : list of MessageGroup
        :attr:`log` grouped with the record's excursions (:func:`group_messages`): what the
        FMUs said, e.g. ``ik: not converged (status 1, 2670 steps) from t = 0.33 s to 3 s, ...``.
    """

    time: np.ndarray
    columns: list[str]
    data: np.ndarray
    info: dict = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)
    log: list[Message] = field(default_factory=list)
    messages: list[MessageGroup] = field(default_factory=list)

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

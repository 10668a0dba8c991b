"""What a sweep gives back: :class:`SweepRun`, the design, the folder and the rows of a finished
(or interrupted) sweep, which :mod:`.run` builds and :mod:`.report` and :mod:`.figures` read."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from robofmu.system.sweep.design import Design

__all__ = ["SweepRun"]


@dataclass
class SweepRun:
    """A finished (or interrupted) sweep.

    Attributes
    ----------
    design : Design
    folder : Path
    rows : list of dict
        ``sweep.csv``'s rows in run order (text cells, as written).
    metrics : list of str
        The metric columns.
    ran, reused : int
        Runs executed now, and rows found from an earlier invocation.
    seconds : float
        Wall time of the runs executed now (s).
    workers : int or None
        Local worker processes (None: an existing cluster).
    figures : list of Path
    units : dict
        Unit of each varied parameter and metric column that has one.
    name, description : str
        The experiment's name and description.
    widths : dict
        The element count of each varied vector parameter (``plant.friction``: 6), which one value
        sets alike.
    """

    design: Design
    folder: Path
    rows: list
    metrics: list
    ran: int
    reused: int
    seconds: float
    workers: int | None
    figures: list = field(default_factory=list)
    units: dict = field(default_factory=dict)
    name: str = ""
    description: str = ""
    widths: dict = field(default_factory=dict)

    @property
    def failed(self) -> list:
        """The rows whose run failed."""
        return [r for r in self.rows if r["status"] != "ok"]

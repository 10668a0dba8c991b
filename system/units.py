"""Units for people: the scale and label a report or a figure shows an SI quantity in."""
from __future__ import annotations

#: SI unit -> (factor, displayed unit) for small quantities such as tracking errors.
_SMALL = {"rad": (1e3, "mrad"), "m": (1e3, "mm"), "rad/s": (1e3, "mrad/s"), "m/s": (1e3, "mm/s")}
#: SI unit as written in a model description -> as printed.
_PRINTED = {"N.m": "N·m", "m/s2": "m/s²", "rad/s2": "rad/s²", "1/s2": "1/s²", "1/s3": "1/s³"}


def printed(unit: str | None) -> str:
    """``N.m`` -> ``N·m``, ``m/s2`` -> ``m/s²``; None -> ``""``."""
    return _PRINTED.get(unit, unit) if unit else ""


def small(unit: str | None) -> tuple[float, str]:
    """Factor and printed unit to show a small error in (rad -> mrad, m -> mm)."""
    factor, shown = _SMALL.get(unit or "", (1.0, unit or ""))
    return factor, printed(shown)


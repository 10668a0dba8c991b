"""Declared parameters: what a solver or profile needs, with unit, default and validation.

A block turns each :class:`Parameter` into a FMU parameter; :func:`validate` checks a value and
raises ValueError naming the parameter.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Parameter:
    """One parameter.

    Attributes
    ----------
    name : str
    kind : {"Real", "Integer", "String"}
    unit : str
        SI unit of a Real ("1" if dimensionless; "" for other kinds).
    description : str
    default : Any
        Used when the robot description does not set it (None: the description must).
    low, high : float, optional
        Inclusive bounds of a Real or Integer.
    choices : tuple of str, optional
        Allowed values of a String.
    """

    name: str
    kind: str
    unit: str
    description: str
    default: Any = None
    low: float | None = None
    high: float | None = None
    choices: tuple[str, ...] | None = None

    def validate(self, value) -> Any:
        """``value`` checked (and converted to the parameter's Python type); ValueError naming it."""
        shown = f"{value!r}{' ' + self.unit if self.unit not in ('', '1') else ''}"
        if self.kind == "String":
            if not isinstance(value, str) or (self.choices and value not in self.choices):
                allowed = f"one of {', '.join(map(repr, self.choices))}" if self.choices else "a string"
                raise ValueError(f"parameter {self.name} = {value!r} is invalid: must be {allowed}")
            return value
        try:
            number = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"parameter {self.name} = {value!r} is invalid: must be a number") from None
        rules = []
        if self.low is not None:
            rules.append(f">= {self.low:g}")
        if self.high is not None:
            rules.append(f"<= {self.high:g}")
        ok = math.isfinite(number) and (self.low is None or number >= self.low) and (
            self.high is None or number <= self.high)
        if self.kind == "Integer" and ok and not number.is_integer():
            ok, rules = False, rules + ["a whole number"]
        if not ok:
            raise ValueError(f"parameter {self.name} = {shown} is invalid: must be "
                             f"{' and '.join(rules) or 'finite'}")
        return int(number) if self.kind == "Integer" else number


def resolve(declared: tuple[Parameter, ...], given: dict[str, Any], where: str) -> dict[str, Any]:
    """Values of ``declared`` from ``given`` (a description table) over their defaults.

    Raises ValueError naming ``where`` for an unknown key or a missing or invalid value.
    """
    names = {p.name for p in declared}
    unknown = sorted(set(given) - names)
    if unknown:
        raise ValueError(f"{where}: unknown parameter {unknown[0]!r} (known: {', '.join(sorted(names)) or 'none'})")
    values = {}
    for p in declared:
        value = given.get(p.name, p.default)
        if value is None:
            raise ValueError(f"{where}: parameter {p.name!r} missing")
        try:
            values[p.name] = p.validate(value)
        except ValueError as exc:
            raise ValueError(f"{where}: {exc}") from None
    return values

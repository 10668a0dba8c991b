"""Declared parameters: what a solver or profile needs, with unit, default and validation.

A block turns each :class:`Parameter` into a FMU parameter; :func:`validate` checks a value and
raises ValueError naming the parameter.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from .unknown_names import nearest

#: The values an Integer parameter may take: a FMU's Integer is an fmi2Integer, 32-bit signed.
INTEGER_RANGE = (-2**31, 2**31 - 1)


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
    above : float, optional
        Exclusive lower bound (the value must be greater).
    choices : tuple of str, optional
        Allowed values of a String.
    size : {"joints"}, optional
        A vector Real with one element per joint (FMU parameters ``name[1]`` ..); its value is a
        list of numbers, one number (the same for every joint) or the name of one of the robot's
        configurations (``"home"``), which the block resolves. The bounds apply to every
        element; the unit is the joints' (rad, m).
    """

    name: str
    kind: str
    unit: str
    description: str
    default: Any = None
    low: float | None = None
    high: float | None = None
    choices: tuple[str, ...] | None = None
    above: float | None = None
    size: str | None = None

    def validate(self, value) -> Any:
        """``value`` checked (and converted to the parameter's Python type); ValueError naming it.
        A vector's value is a tuple of floats (each element checked) or a configuration name."""
        if self.size is not None:
            if isinstance(value, str):
                return value
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                value = [value]                 # one number: the same for every joint
            if not isinstance(value, (list, tuple)) and not hasattr(value, "__len__"):
                raise ValueError(f"parameter {self.name} = {value!r} is invalid: must be a list of "
                                 "numbers (one per joint) or a configuration name")
            element = Parameter(self.name, self.kind, self.unit, self.description, low=self.low,
                                high=self.high, above=self.above)
            checked = []
            for k, item in enumerate(value, start=1):
                try:
                    checked.append(element.validate(item))
                except ValueError as exc:
                    raise ValueError(str(exc).replace(f"parameter {self.name} ",
                                                      f"parameter {self.name}[{k}] ", 1)) from None
            return tuple(checked)
        unit = f" {self.unit}" if self.unit not in ("", "1") else ""
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
        if self.above is not None:
            rules.append(f"> {self.above:g}")
        if self.low is not None:
            rules.append(f">= {self.low:g}")
        if self.high is not None:
            rules.append(f"<= {self.high:g}")
        ok = (math.isfinite(number) and (self.above is None or number > self.above)
              and (self.low is None or number >= self.low) and (self.high is None or number <= self.high))
        shown = f"{number:g}"
        if self.kind == "Integer" and ok:
            if not number.is_integer():
                ok, rules = False, rules + ["a whole number"]
            elif not INTEGER_RANGE[0] <= number <= INTEGER_RANGE[1]:
                ok, rules = False, [f"within {INTEGER_RANGE[0]}..{INTEGER_RANGE[1]} (a 32-bit FMI Integer)"]
                shown = str(value) if isinstance(value, int) else shown
        if not ok:
            raise ValueError(f"parameter {self.name} = {shown}{unit} is invalid: must be "
                             f"{' and '.join(rules) or 'finite'}")
        return int(number) if self.kind == "Integer" else number


class ParameterError(ValueError):
    """A parameter table is wrong; ``name`` is the offending key, ``problem`` what is wrong."""

    def __init__(self, name: str, problem: str):
        super().__init__(f"{name}: {problem}")
        self.name = name
        self.problem = problem


def resolve(declared: tuple[Parameter, ...], given: dict[str, Any], where: str = "") -> dict[str, Any]:
    """Values of ``declared`` from ``given`` (a description table) over their defaults.

    Raises
    ------
    ParameterError
        For an unknown key or a missing or invalid value, naming the key.
    """
    names = {p.name for p in declared}
    unknown = sorted(set(given) - names)
    if unknown:
        raise ParameterError(unknown[0], f"unknown parameter {unknown[0]!r} (known: {', '.join(sorted(names)) or 'none'})"
                                         + nearest(unknown[0], names))
    values = {}
    for p in declared:
        value = given.get(p.name, p.default)
        if value is None:
            raise ParameterError(p.name, f"parameter {p.name!r} missing")
        try:
            values[p.name] = p.validate(value)
        except ValueError as exc:
            raise ParameterError(p.name, str(exc)) from None
    return values

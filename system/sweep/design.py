"""What a sweep runs: the varied parameters, their values, and the list of runs.

``--vary BLOCK.PARAM=VALUES`` (or ``step=VALUES`` for the communication step) names an
:class:`Axis`. VALUES is

- a comma list, ``200,400,800`` (numbers, or ``true`` / ``false``);
- a range ``START:STOP:COUNT``: COUNT evenly spaced values from START to STOP, both included;
- a distribution for random sampling, ``uniform(LOW,HIGH)`` or ``normal(MEAN,STD)``, drawn
  ``--samples`` times from a generator seeded with ``--seed``.

The runs are the Cartesian product of the grid axes (in the order given, the last varying
fastest), each crossed with every random sample when there are distributions. The samples are
drawn before anything runs, in one fixed order, so the same design always gives the same runs.
A :class:`Design` is plain data (JSON), written beside the results so that a rerun into the same
folder can tell whether it continues the same sweep.
"""
from __future__ import annotations

import itertools
import json
import math
import re
from dataclasses import dataclass, field

import numpy as np

__all__ = ["STEP", "Axis", "Design", "DesignError", "parse_axis"]

#: The axis name that varies the communication step (s) rather than a block parameter.
STEP = "step"

_NUMBER = r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*"
_DISTRIBUTION = re.compile(rf"^\s*(uniform|normal)\s*\({_NUMBER},{_NUMBER}\)\s*$")
DISTRIBUTIONS = {"uniform": "uniform(LOW,HIGH): LOW < HIGH", "normal": "normal(MEAN,STD): STD > 0"}


class DesignError(ValueError):
    """A ``--vary`` (or ``--samples`` / ``--seed``) that cannot be used; one line naming it."""


@dataclass(frozen=True)
class Axis:
    """One varied quantity.

    Attributes
    ----------
    name : str
        ``BLOCK.PARAM``, or :data:`STEP`.
    values : tuple
        The grid values (empty for a distribution).
    distribution : tuple or None
        ``("uniform", low, high)`` or ``("normal", mean, std)`` for random sampling.
    """

    name: str
    values: tuple = ()
    distribution: tuple | None = None

    @property
    def block(self) -> str | None:
        """The instance name (None for the step)."""
        return None if self.name == STEP else self.name.split(".", 1)[0]

    @property
    def parameter(self) -> str | None:
        """The parameter name (None for the step)."""
        return None if self.name == STEP else self.name.split(".", 1)[1]

    @property
    def random(self) -> bool:
        return self.distribution is not None

    def describe(self) -> str:
        """``controller.kp: 200, 400, 800`` or ``plant.payload_mass: uniform(0, 0.3)``."""
        if self.random:
            kind, a, b = self.distribution
            return f"{self.name}: {kind}({a:g}, {b:g})"
        return f"{self.name}: {', '.join(_text(v) for v in self.values)}"


def _text(value) -> str:
    return str(value).lower() if isinstance(value, bool) else f"{value:g}" if isinstance(value, float) else str(value)


def _number(text: str, option: str):
    word = text.strip().lower()
    if word in ("true", "false"):
        return word == "true"
    try:
        value = float(word)
    except ValueError:
        raise DesignError(f"{option}: {text.strip()!r} is no number (VALUES: a comma list 200,400,800, "
                          f"a range START:STOP:COUNT, uniform(LOW,HIGH) or normal(MEAN,STD))") from None
    if not math.isfinite(value):
        raise DesignError(f"{option}: {text.strip()!r} is not a finite number")
    return value


def parse_axis(text: str) -> Axis:
    """The :class:`Axis` of one ``--vary`` value ``BLOCK.PARAM=VALUES`` (DesignError otherwise)."""
    option = f"--vary {text}"
    name, equals, values = text.partition("=")
    name = name.strip()
    if not equals or not values.strip():
        raise DesignError(f"{option}: expected BLOCK.PARAM=VALUES (e.g. controller.kp=200,400,800) or step=VALUES")
    if name != STEP:
        block, dot, parameter = name.partition(".")
        if not dot or not block or not parameter or not re.fullmatch(r"[A-Za-z_][\w\[\]]*", parameter):
            raise DesignError(f"{option}: {name!r} is not BLOCK.PARAM (e.g. controller.kp) nor {STEP!r}")
    match = _DISTRIBUTION.match(values)
    if match:
        kind, a, b = match.group(1), float(match.group(2)), float(match.group(3))
        if (kind == "uniform" and not a < b) or (kind == "normal" and not b > 0):
            raise DesignError(f"{option}: {DISTRIBUTIONS[kind]}")
        return Axis(name, (), (kind, a, b))
    if "(" in values:
        raise DesignError(f"{option}: unknown distribution; use {' or '.join(DISTRIBUTIONS.values())}")
    if ":" in values:
        parts = values.split(":")
        if len(parts) != 3:
            raise DesignError(f"{option}: a range is START:STOP:COUNT (e.g. 0:0.3:7)")
        start, stop = _number(parts[0], option), _number(parts[1], option)
        try:
            count = int(parts[2])
        except ValueError:
            count = 0
        if count < 2 or isinstance(start, bool) or isinstance(stop, bool):
            raise DesignError(f"{option}: a range is START:STOP:COUNT with numbers and a whole COUNT >= 2")
        grid = tuple(float(v) for v in np.linspace(start, stop, count))
        return Axis(name, grid)
    grid = tuple(_number(v, option) for v in values.split(","))
    if len(set(grid)) != len(grid):
        raise DesignError(f"{option}: a value is given twice")
    return Axis(name, grid)


@dataclass
class Design:
    """A whole sweep: experiment, axes, sampling, timing.

    Parameters
    ----------
    experiment : str
        The experiment's name or file, as given.
    axes : list of Axis
    samples : int or None
        Random samples (required with a distribution, refused without one).
    seed : int
        Seed of the random samples.
    stop_time : float or None
        ``--stop`` (s); None: the experiment's.
    step : float or None
        ``--step`` (s) when the step is not an axis; None: the experiment's.
    """

    experiment: str
    axes: list[Axis]
    samples: int | None = None
    seed: int = 0
    stop_time: float | None = None
    step: float | None = None
    runs_cache: list = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self):
        names = [a.name for a in self.axes]
        if not names:
            raise DesignError("--vary: give at least one BLOCK.PARAM=VALUES")
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise DesignError(f"--vary {twice[0]}: varied twice")
        random = [a for a in self.axes if a.random]
        if random and self.samples is None:
            raise DesignError(f"--vary {random[0].name}: a distribution needs --samples N")
        if self.samples is not None:
            if not random:
                raise DesignError(f"--samples {self.samples}: no --vary is a distribution "
                                  "(uniform(LOW,HIGH) or normal(MEAN,STD))")
            if self.samples < 1:
                raise DesignError(f"--samples {self.samples}: must be at least 1")
        if self.step is not None and STEP in names:
            raise DesignError("--step: the step is varied (--vary step=...); give one or the other")

    @property
    def names(self) -> list[str]:
        """Column names of the varied quantities, in the order given."""
        return [a.name for a in self.axes]

    @property
    def grid_axes(self) -> list[Axis]:
        return [a for a in self.axes if not a.random]

    @property
    def random(self) -> bool:
        return any(a.random for a in self.axes)

    def runs(self) -> list[dict]:
        """Every run's values by axis name, in the order the runs are listed (and numbered)."""
        if self.runs_cache is None:
            rng = np.random.default_rng(self.seed)
            random = [a for a in self.axes if a.random]
            draws = {}
            for a in random:                    # one axis after the other: fixed order, reproducible
                kind, p1, p2 = a.distribution
                draw = rng.uniform(p1, p2, self.samples) if kind == "uniform" else rng.normal(p1, p2, self.samples)
                draws[a.name] = [float(v) for v in draw]
            grid = self.grid_axes
            runs = []
            for point in itertools.product(*(a.values for a in grid)):
                fixed = dict(zip((a.name for a in grid), point))
                for k in range(self.samples or 1):
                    run = dict(fixed, **{name: values[k] for name, values in draws.items()})
                    runs.append({name: run[name] for name in self.names})
            self.runs_cache = runs
        return self.runs_cache

    def to_json(self) -> str:
        data = {"experiment": self.experiment, "samples": self.samples, "seed": self.seed,
                "stop_time": self.stop_time, "step": self.step,
                "axes": [{"name": a.name, "values": list(a.values),
                          "distribution": list(a.distribution) if a.distribution else None} for a in self.axes]}
        return json.dumps(data, indent=2) + "\n"

    @classmethod
    def from_json(cls, text: str) -> "Design":
        data = json.loads(text)
        axes = [Axis(a["name"], tuple(a["values"]), tuple(a["distribution"]) if a["distribution"] else None)
                for a in data["axes"]]
        return cls(data["experiment"], axes, data["samples"], data["seed"], data["stop_time"], data["step"])

    def same_as(self, other: "Design") -> bool:
        """Whether ``other`` lists the same runs of the same experiment with the same timing."""
        return (self.experiment, self.stop_time, self.step, self.names, self.runs()) == \
            (other.experiment, other.stop_time, other.step, other.names, other.runs())


def parse_setting(text: str, option: str = "--set") -> tuple[str, object]:
    """``BLOCK.PARAM=VALUE`` (one number, or true / false) as ``(name, value)``; DesignError otherwise."""
    name, equals, value = text.partition("=")
    name = name.strip()
    block, dot, parameter = name.partition(".")
    if not equals or not dot or not block or not parameter or not value.strip():
        raise DesignError(f"{option} {text}: expected BLOCK.PARAM=VALUE (e.g. controller.kp=400)")
    return name, _number(value, f"{option} {text}")

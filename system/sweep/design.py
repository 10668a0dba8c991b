"""What a sweep runs: the varied parameters, their values, and the list of runs.

``--vary BLOCK.PARAM=VALUES`` (or ``step_size=VALUES`` for the communication step) names an
:class:`Axis`. VALUES is

- a comma list, ``200,400,800`` (numbers, or ``true`` / ``false``);
- a range ``START:STOP:COUNT``: COUNT evenly spaced values from START to STOP, both included;
- a distribution for random sampling, ``uniform(LOW,HIGH)`` or ``normal(MEAN,STD)``, drawn
  ``--samples`` times from a generator seeded with ``--seed``.

``--vary BLOCK.PARAM=OTHER.PARAM`` links an axis to another one: it takes that axis's value in
every run and adds no dimension (``controller.friction=plant.friction``: the friction the
controller compensates follows the plant's, friction known to it, over the same map as
``controller.loss_compensation=0`` gives unknown).

``BLOCK.sample_time`` varies a block's sample time (s; a grid only, each value a whole multiple of
every step the sweep runs at), ``controller.delay_steps`` its computation delay; a vector
parameter given one value (``plant.friction``) sets every element to it
(:func:`~robofmu.system.sweep.worker.block_settings`), ``plant.friction[2]`` one element.

The runs are the Cartesian product of the grid axes (in the order given, the last varying
fastest), each crossed with every random sample when there are distributions. The samples are
drawn before anything runs, in one fixed order, so the same design always gives the same runs.
A :class:`Design` is plain data (JSON), written beside the results so that a rerun into the same
folder can tell whether it continues the same sweep.

The axis of the communication step was named ``step`` before: ``--vary step=VALUES`` still works
(with a one-line deprecation warning), and an earlier sweep's ``sweep.json`` and ``sweep.csv``
naming it so are read as ``step_size`` (:data:`RENAMED_AXES`).
"""
from __future__ import annotations

import itertools
import json
import math
import re
from dataclasses import dataclass, field

import numpy as np

from robofmu.system.diagram import parameter_address
from robofmu.system.options import number, whole
from robofmu.system.usage import check_memory, say

__all__ = ["RENAMED_AXES", "STEP_SIZE_AXIS", "Axis", "Design", "DesignError", "parse_axis"]

#: The axis name that varies the communication step (s) rather than a block parameter.
STEP_SIZE_AXIS = "step_size"

#: Earlier names of axes: still accepted by ``--vary`` (deprecated), and read from an earlier
#: sweep's ``sweep.json`` and ``sweep.csv`` under the current name.
RENAMED_AXES = {"step": STEP_SIZE_AXIS}

_NUMBER = r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*"
_DISTRIBUTION = re.compile(rf"^\s*(uniform|normal)\s*\({_NUMBER},{_NUMBER}\)\s*$")
DISTRIBUTIONS = {"uniform": "uniform(LOW,HIGH): LOW < HIGH", "normal": "normal(MEAN,STD): STD > 0"}
#: Memory a sweep holds per run, in bytes (bounded above): its values, their typed copy, key and
#: journal row, and its Dask task (about 0.7 kB before the rows and tasks, measured).
BYTES_PER_RUN = 4096


def check_runs(count: int, where: str) -> None:
    """Refuse (UsageError naming ``where``) a sweep of ``count`` runs whose bookkeeping alone would
    not fit in memory (:func:`~robofmu.system.usage.check_memory`), before anything is allocated."""
    check_memory(count * BYTES_PER_RUN, f"{where}: {count} runs", "give fewer runs (a smaller --samples, "
                 "fewer grid values), or split the sweep")


class DesignError(ValueError):
    """A ``--vary`` (or ``--samples`` / ``--seed``) that cannot be used; one line naming it."""


@dataclass(frozen=True)
class Axis:
    """One varied quantity.

    Attributes
    ----------
    name : str
        ``BLOCK.PARAM``, or :data:`STEP_SIZE_AXIS`.
    values : tuple
        The grid values (empty for a distribution).
    distribution : tuple or None
        ``("uniform", low, high)`` or ``("normal", mean, std)`` for random sampling.
    follows : str or None
        The name of the axis whose value this one takes in every run (a linked axis: no values,
        no distribution, no dimension of the grid).
    """

    name: str
    values: tuple = ()
    distribution: tuple | None = None
    follows: str | None = None

    @property
    def block(self) -> str | None:
        """The instance name (None for the step size)."""
        return None if self.name == STEP_SIZE_AXIS else parameter_address(self.name)[0]

    @property
    def parameter(self) -> str | None:
        """The parameter name (None for the step size)."""
        return None if self.name == STEP_SIZE_AXIS else parameter_address(self.name)[1]

    @property
    def random(self) -> bool:
        return self.distribution is not None

    def describe(self) -> str:
        """``controller.kp: 200, 400, 800``, ``plant.payload_mass: uniform(0, 0.3)`` or
        ``controller.friction: as plant.friction``."""
        if self.follows:
            return f"{self.name}: as {self.follows}"
        if self.random:
            kind, a, b = self.distribution
            return f"{self.name}: {kind}({a:g}, {b:g})"
        return f"{self.name}: {', '.join(_text(v) for v in self.values)}"


def _text(value) -> str:
    return str(value).lower() if isinstance(value, bool) else f"{value:g}" if isinstance(value, float) else str(value)


def parse_axis(text: str) -> Axis:
    """The :class:`Axis` of one ``--vary`` value ``BLOCK.PARAM=VALUES`` (DesignError otherwise).

    The old name ``step`` of the step size axis gives a :data:`STEP_SIZE_AXIS` axis, with a
    deprecation warning on stderr.
    """
    try:
        return _axis(text, f"--vary {text}")
    except ValueError as exc:           # the grammar of a number or of BLOCK.PARAM, shared with --set
        raise DesignError(str(exc)) from None


def _axis(text: str, option: str) -> Axis:
    name, equals, values = text.partition("=")
    name = name.strip()
    if not equals or not values.strip():
        raise DesignError(f"{option}: expected BLOCK.PARAM=VALUES (e.g. controller.kp=200,400,800) "
                          f"or {STEP_SIZE_AXIS}=VALUES")
    if name in RENAMED_AXES:
        say("sweep", f"--vary {name}=... is deprecated; use {RENAMED_AXES[name]}=...")
        name = RENAMED_AXES[name]
    if name != STEP_SIZE_AXIS:
        try:
            parameter_address(name)
        except ValueError as exc:
            raise DesignError(f"{option}: {exc} nor {STEP_SIZE_AXIS!r}") from None
    if re.fullmatch(r"\s*[A-Za-z_]\w*\.[A-Za-z_][\w\[\]]*\s*", values):
        try:
            parameter_address(values.strip())
        except ValueError as exc:
            raise DesignError(f"{option}: {exc}") from None
        return Axis(name, follows=values.strip())
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
        start, stop = number(parts[0], option), number(parts[1], option)
        try:
            count = int(parts[2])
        except ValueError:
            count = 0
        if count < 2 or isinstance(start, bool) or isinstance(stop, bool):
            raise DesignError(f"{option}: a range is START:STOP:COUNT with numbers and a whole COUNT >= 2")
        check_runs(count, option)               # each value is a run at least: before linspace allocates
        grid = tuple(float(v) for v in np.linspace(start, stop, count))
        return Axis(name, grid)
    grid = tuple(number(v, option) for v in values.split(","))
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
        ``--stop-time`` (s); None: the experiment's.
    step : float or None
        The communication step, ``--step-size`` (s), when it is not an axis; None: the experiment's.
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
        whole("--seed", self.seed, 0)
        for a in self.axes:
            if not a.follows:
                continue
            leader = next((b for b in self.axes if b.name == a.follows), None)
            if leader is None or leader.follows or a.follows == a.name:
                raise DesignError(f"--vary {a.name}={a.follows}: a linked axis follows another --vary that is varied "
                                  f"itself ({', '.join(b.name for b in self.axes if not b.follows) or 'none'})")
        grid = self.grid_axes
        count = math.prod(len(a.values) for a in grid) * (self.samples or 1)
        check_runs(count, " x ".join([f"--vary {a.name} ({len(a.values)} values)" for a in grid]
                                     + ([f"--samples {self.samples}"] if self.samples else [])))
        if self.step is not None and STEP_SIZE_AXIS in names:
            raise DesignError(f"--step-size: the step is varied (--vary {STEP_SIZE_AXIS}=...); "
                              "give one or the other")

    @property
    def names(self) -> list[str]:
        """Column names of the varied quantities, in the order given."""
        return [a.name for a in self.axes]

    @property
    def grid_axes(self) -> list[Axis]:
        """The axes whose values make the grid: neither random nor linked."""
        return [a for a in self.axes if not a.random and not a.follows]

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
                    run.update({a.name: run[a.follows] for a in self.axes if a.follows})
                    runs.append({name: run[name] for name in self.names})
            self.runs_cache = runs
        return self.runs_cache

    def to_json(self) -> str:
        data = {"experiment": self.experiment, "samples": self.samples, "seed": self.seed,
                "stop_time": self.stop_time, "step": self.step,
                "axes": [{"name": a.name, "values": list(a.values),
                          "distribution": list(a.distribution) if a.distribution else None}
                         | ({"follows": a.follows} if a.follows else {}) for a in self.axes]}
        return json.dumps(data, indent=2) + "\n"

    @classmethod
    def from_json(cls, text: str) -> "Design":
        data = json.loads(text)
        axes = [Axis(RENAMED_AXES.get(a["name"], a["name"]), tuple(a["values"]),
                     tuple(a["distribution"]) if a["distribution"] else None, a.get("follows")) for a in data["axes"]]
        return cls(data["experiment"], axes, data["samples"], data["seed"], data["stop_time"], data["step"])

    def same_as(self, other: "Design") -> bool:
        """Whether ``other`` lists the same runs of the same experiment with the same timing."""
        return (self.experiment, self.stop_time, self.step, self.names, self.runs()) == \
            (other.experiment, other.stop_time, other.step, other.names, other.runs())


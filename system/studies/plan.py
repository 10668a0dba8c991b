"""The plan of ``robofmu demo``: ``system/studies/demo.toml`` read into typed, validated sections.

Nothing else reads the raw TOML. Each table is a dataclass below (:class:`DemoPlan` the whole
file); its fields are the keys, with their types and defaults. A missing, mistyped or unknown
key, an experiment or robot that does not exist, or a file the plan names that is not beside it
is refused before anything runs, with a :class:`~robofmu.system.usage.UsageError` in one line
naming the file and the key (``…/demo.toml: sections[2].seed_table: no such file
seed000_a3.csv``), as the robot descriptions and the experiment files are.
"""
from __future__ import annotations

import math
import tomllib
import types
import typing
from dataclasses import MISSING, dataclass, field, fields, is_dataclass
from pathlib import Path

from robofmu.components.unknown_names import unknown_key
from robofmu.system.usage import UsageError

__all__ = ["PLAN", "DemoPlan", "ExperimentSection", "WorkspaceEntry", "RobustnessStudy", "SampledLoopStudy",
           "InteropSection", "AccuracyStudy", "GainDesignCase", "StepResponses", "read_plan"]

#: The demo's plan, beside this module.
PLAN = Path(__file__).resolve().parent / "demo.toml"

#: Field metadata: the names a field holds must be runnable experiments, or described robots.
EXPERIMENTS = {"names": "experiment"}
ROBOTS = {"names": "robot"}


@dataclass(frozen=True)
class ExperimentSection:
    """``[[sections]]``: experiments of one source document run, plotted and tabled together.

    ``seed_table``, ``seed_dynamics`` and ``tutorial`` are files beside the plan; the titles and
    texts are the report's.
    """

    title: str
    experiments: tuple[str, ...] = field(metadata=EXPERIMENTS)
    text: str = ""
    comparison: str = "Tracking error"
    diagnostics: str = "Iterations of the IK solver per communication step along the run"
    seed_table: Path | None = None
    seed_table_title: str = "Against the seed"
    seed_table_notes: tuple[str, ...] = ()
    bangbang: bool = False
    seed_dynamics: Path | None = None
    tutorial: Path | None = None
    tutorial_title: str = "Worked examples"
    tutorial_figure: str = "Residual per Newton-Raphson iteration"
    cross_check: bool = False
    cross_check_title: str = "The runs against a second, independent formulation of the dynamics"
    cross_check_text: str = ""


@dataclass(frozen=True)
class WorkspaceEntry:
    """``[[workspace]]``: a workspace study file beside the plan."""

    study: Path


@dataclass(frozen=True)
class RobustnessStudy:
    """``[robustness]``: the same sweep over each labelled experiment (``label = "experiment"``);
    ``vary`` / ``quick_vary`` are ``robofmu sweep --vary`` axes, ``metric`` and ``threshold``
    the map's."""

    title: str
    experiments: dict[str, str] = field(metadata=EXPERIMENTS)
    vary: tuple[str, ...]
    quick_vary: tuple[str, ...]
    metric: str
    threshold: float
    text: str = ""


@dataclass(frozen=True)
class SampledLoopStudy:
    """``[sampled_loop]``: the loop as it runs on the robot (:mod:`~robofmu.system.studies.sampled_loop`).

    ``experiment`` (a file beside the plan) runs at each of ``controller``'s ``sample_times`` (s)
    and ``delay_steps`` (samples), its losses known to the controller or not
    (``loss_compensation`` 1 or 0), as one sweep; ``stated`` lists the ``BLOCK.PARAM`` the report
    states per joint (the losses the file gives)."""

    title: str
    experiment: Path
    sample_times: tuple[float, ...]
    delay_steps: tuple[float, ...]
    stated: tuple[str, ...]
    controller: str = "controller"
    text: str = ""


@dataclass(frozen=True)
class InteropSection:
    """``[interop]``: the experiments run by other FMI tools for ``stop_time`` (s)."""

    title: str
    experiments: tuple[str, ...] = field(metadata=EXPERIMENTS)
    stop_time: float
    text: str = ""


@dataclass(frozen=True)
class AccuracyStudy:
    """``[accuracy]``: the convergence study of each experiment over the communication steps (s);
    ``quick_step_sizes`` with ``robofmu demo --quick``."""

    experiments: tuple[str, ...] = field(metadata=EXPERIMENTS)
    step_sizes: tuple[float, ...]
    quick_step_sizes: tuple[float, ...]


@dataclass(frozen=True)
class GainDesignCase:
    """``[step_response] design``: gains for a 2 % settling time (s) and an overshoot (%), co-simulated
    on ``robots``."""

    settling_time: float
    overshoot: float
    robots: tuple[str, ...] = field(metadata=ROBOTS)


@dataclass(frozen=True)
class StepResponses:
    """``[step_response]``: each robot's gain sets stepped, and optionally a designed case."""

    robots: tuple[str, ...] = field(metadata=ROBOTS)
    design: GainDesignCase | None = None


@dataclass(frozen=True)
class DemoPlan:
    """The whole plan, section by section in the report's order (``path``: the file read)."""

    path: Path
    title: str
    accuracy: AccuracyStudy
    step_response: StepResponses
    intro: str = ""
    sections: tuple[ExperimentSection, ...] = ()
    workspace: tuple[WorkspaceEntry, ...] = ()
    robustness: RobustnessStudy | None = None
    sampled_loop: SampledLoopStudy | None = None
    interop: InteropSection | None = None


def read_plan(path: str | Path = PLAN) -> DemoPlan:
    """Read and check the demo's plan (default :data:`PLAN`).

    Raises
    ------
    UsageError
        Naming the file and the key: a missing, mistyped or unknown key, an unknown experiment or
        robot, a file that is not beside the plan; or the file unreadable, not TOML.
    """
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:           # missing, unreadable, not UTF-8, not TOML
        raise UsageError(f"{path}: cannot read it as TOML: {getattr(exc, 'strerror', None) or exc}") from None
    return _table(DemoPlan, data, _Where(path, ""), path=path)


# -- reading by the dataclasses' fields ------------------------------------------------------------
@dataclass(frozen=True)
class _Where:
    """The file and the dotted key being read."""

    file: Path
    key: str

    def at(self, name: str | int) -> "_Where":
        if isinstance(name, int):
            return _Where(self.file, f"{self.key}[{name}]")
        return _Where(self.file, f"{self.key}.{name}" if self.key else name)


def _fail(file: Path, key: str, problem: str):
    raise UsageError(f"{file}: {key}: {problem}")


def _table(cls, data, where: _Where, **given):
    """An instance of dataclass ``cls`` from TOML table ``data`` (fields in ``given`` are not keys)."""
    if not isinstance(data, dict):
        _fail(where.file, where.key, f"must be a table, got {data!r}")
    hints = typing.get_type_hints(cls)
    keys = [f for f in fields(cls) if f.name not in given]
    unknown = sorted(set(data) - {f.name for f in keys})
    if unknown:
        _fail(where.file, where.at(unknown[0]).key, unknown_key(unknown[0], (f.name for f in keys)))
    values = dict(given)
    for f in keys:
        if f.name in data:
            values[f.name] = _value(hints[f.name], data[f.name], where.at(f.name), f.metadata.get("names"))
        elif f.default is MISSING and f.default_factory is MISSING:
            _fail(where.file, where.at(f.name).key, "missing")
    return cls(**values)


def _value(kind, value, where: _Where, names: str | None):
    """``value`` as type ``kind`` (str, bool, float, Path, a dataclass, an optional one, a tuple
    or a dict of them); ``names``: each string must be a runnable experiment or described robot."""
    origin, args = typing.get_origin(kind), typing.get_args(kind)
    if origin in (typing.Union, types.UnionType):
        return _value(next(a for a in args if a is not type(None)), value, where, names)
    if origin is tuple:
        if not isinstance(value, list):
            _fail(where.file, where.key, f"must be a list, got {value!r}")
        return tuple(_value(args[0], item, where.at(k), names) for k, item in enumerate(value, 1))
    if origin is dict:
        if not isinstance(value, dict) or not value:
            _fail(where.file, where.key, f"must be a non-empty table, got {value!r}")
        return {key: _value(args[1], item, where.at(key), names) for key, item in value.items()}
    if is_dataclass(kind):
        return _table(kind, value, where)
    if kind is bool:
        if not isinstance(value, bool):
            _fail(where.file, where.key, f"must be true or false, got {value!r}")
        return value
    if kind is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            _fail(where.file, where.key, f"must be a finite number, got {value!r}")
        return float(value)
    if not isinstance(value, str):
        _fail(where.file, where.key, f"must be a string, got {value!r}")
    if kind is Path:
        file = where.file.parent / value
        if not file.is_file():
            _fail(where.file, where.key, f"no such file {value} beside the plan")
        return file
    if names is not None:
        _check_name(names, value, where)
    return value


def _check_name(names: str, value: str, where: _Where) -> None:
    if names == "experiment":
        from robofmu.system.experiment import available
    else:
        from robofmu.components.robots import available
    known = available()
    if value not in known:
        _fail(where.file, where.key, f"unknown {names} {value!r}; available: {', '.join(known)}")

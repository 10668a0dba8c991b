"""A robot's description: its ``<name>.toml`` beside its URDF, read into typed, validated values.

The TOML holds what the URDF cannot: the task coordinates, named configurations, gravity, the
payload, the seed's gains, the blocks the robot gets, the IK solver and the reference trajectory
(the trajectory block's defaults). Nothing outside this module reads the raw TOML; a missing or
malformed key raises :class:`DescriptionError` naming the file and the key.

Schema (every table but those marked optional is required)::

    name = "rrp"                         # the folder's name
    summary = "Spherical RRP arm (seed 000)"
    urdf = "rrp.urdf"                    # relative to the TOML
    blocks = ["trajectory", "ik", "controller", "plant", "fk"]

    [task]
    frame = "tcp"                        # URDF frame whose position is the task point
    coordinates = ["x", "y", "z"]        # names of the task coordinates
    axes = [0, 1, 2]                     # optional: which world axes of that position (default all)

    [configurations]
    home = [0.0, 0.0, 0.125]             # joint positions (rad, m); `home` is required

    [gravity]                            # optional
    magnitude = 9.81                     # m/s^2
    direction = [0.0, 0.0, -1.0]         # unit vector in the world frame

    [payload]                            # optional: a point mass carried while gripping
    mass = 0.03                          # kg
    frame = "tcp"

    [gains.pd]                           # at least one set; kp, kd, ki in 1/s^2, 1/s, 1/s^3
    kp = 400.0
    kd = 40.0
    ki = 0.0

    [trajectory]                         # the reference scenario (trajectory block defaults)
    profile = "line"                     # a registered profile; its own parameters follow
    ...

    [ik]                                 # optional (a robot whose trajectory is in joint space has none)
    solver = "spherical"                 # a registered solver; its own parameters follow
    ...
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["DescriptionError", "Gains", "TaskSpace", "Payload", "Choice", "RobotDescription", "read"]

#: Blocks a description may list (each built as ``fmus/<robot>/<block>.fmu``).
KNOWN_BLOCKS = ("trajectory", "ik", "controller", "plant", "fk", "jacobian")


class DescriptionError(ValueError):
    """A robot description is malformed; the message names the file and the key."""

    def __init__(self, path: Path, key: str, problem: str):
        super().__init__(f"{path}: {key}: {problem}")
        self.path = path
        self.key = key


@dataclass(frozen=True)
class Gains:
    """Computed-torque gains, the same on every joint: kp (1/s^2), kd (1/s), ki (1/s^3)."""

    kp: float
    kd: float
    ki: float = 0.0

    def as_dict(self) -> dict[str, float]:
        return {"kp": self.kp, "kd": self.kd, "ki": self.ki}


@dataclass(frozen=True)
class TaskSpace:
    """The task coordinates: components ``axes`` of the position of URDF frame ``frame``."""

    frame: str
    coordinates: tuple[str, ...]
    axes: tuple[int, ...]


@dataclass(frozen=True)
class Payload:
    """A point mass (kg) carried at URDF frame ``frame`` while the gripper is closed."""

    mass: float
    frame: str


@dataclass(frozen=True)
class Choice:
    """A registered implementation (``kind``) with its own parameters, as the TOML gives them."""

    kind: str
    parameters: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class RobotDescription:
    """Everything known about one robot beyond its URDF.

    Attributes
    ----------
    name, summary : str
    path : Path
        The TOML file.
    urdf : Path
    blocks : tuple of str
        The blocks this robot gets, in diagram order.
    task : TaskSpace
    configurations : dict of str to tuple of float
        Named joint configurations (rad, m); always holds ``home``.
    gravity : float
        Magnitude (m/s^2), >= 0.
    gravity_direction : tuple of 3 floats
        Unit vector in the world frame.
    payload : Payload or None
    gains : dict of str to Gains
        The seed's gain sets by name ("pd", "pid").
    trajectory : Choice
        Reference profile and its parameters (the trajectory block's defaults).
    ik : Choice or None
        IK solver and its parameters; None for robots without an IK block.
    """

    name: str
    summary: str
    path: Path
    urdf: Path
    blocks: tuple[str, ...]
    task: TaskSpace
    configurations: dict[str, tuple[float, ...]]
    gravity: float
    gravity_direction: tuple[float, float, float]
    payload: Payload | None
    gains: dict[str, Gains]
    trajectory: Choice
    ik: Choice | None

    def configuration(self, name: str) -> tuple[float, ...]:
        """Joint positions of a named configuration; ValueError naming the known ones."""
        try:
            return self.configurations[name]
        except KeyError:
            raise ValueError(f"robot {self.name!r} has no configuration {name!r}; known: "
                             f"{', '.join(self.configurations)}") from None

    def gain_set(self, name: str) -> Gains:
        """A gain set by name; ValueError naming the known ones."""
        try:
            return self.gains[name]
        except KeyError:
            raise ValueError(f"robot {self.name!r} has no gains {name!r}; known: "
                             f"{', '.join(self.gains)}") from None


# -- reading ---------------------------------------------------------------------------------------
class _Table:
    """A TOML table with typed accessors whose errors name the file and the dotted key."""

    def __init__(self, path: Path, data: dict, prefix: str = ""):
        self.path, self.data, self.prefix = path, data, prefix

    def key(self, name: str) -> str:
        return f"{self.prefix}{name}"

    def fail(self, name: str, problem: str):
        raise DescriptionError(self.path, self.key(name), problem)

    def _get(self, name: str, default):
        if name in self.data:
            return self.data[name]
        if default is _REQUIRED:
            self.fail(name, "missing")
        return default

    def string(self, name: str, default=None) -> str:
        value = self._get(name, default)
        if not isinstance(value, str) or not value:
            self.fail(name, f"must be a non-empty string, got {value!r}")
        return value

    def number(self, name: str, default=None, low: float | None = None) -> float:
        value = self._get(name, default)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            self.fail(name, f"must be a finite number, got {value!r}")
        if low is not None and value < low:
            self.fail(name, f"must be >= {low:g}, got {value!r}")
        return float(value)

    def numbers(self, name: str, default=None, length: int | None = None) -> tuple[float, ...]:
        value = self._get(name, default)
        if not isinstance(value, list) or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value):
            self.fail(name, f"must be a list of finite numbers, got {value!r}")
        if length is not None and len(value) != length:
            self.fail(name, f"must have {length} values, got {len(value)}")
        return tuple(float(v) for v in value)

    def strings(self, name: str, default=None) -> tuple[str, ...]:
        value = self._get(name, default)
        if not isinstance(value, list) or not value or not all(isinstance(v, str) and v for v in value):
            self.fail(name, f"must be a non-empty list of strings, got {value!r}")
        return tuple(value)

    def table(self, name: str, default=None) -> "_Table | None":
        value = self._get(name, default)
        if value is None:
            return None
        if not isinstance(value, dict):
            self.fail(name, f"must be a table, got {value!r}")
        return _Table(self.path, value, f"{self.prefix}{name}.")

    def unknown(self, known: set[str]) -> None:
        extra = sorted(set(self.data) - known)
        if extra:
            self.fail(extra[0], f"unknown key (known: {', '.join(sorted(known))})")


_REQUIRED = object()


def _choice(table: _Table, selector: str) -> Choice:
    kind = table.string(selector, _REQUIRED)
    return Choice(kind, {k: v for k, v in table.data.items() if k != selector})


def read(path: str | Path) -> RobotDescription:
    """Read and validate one description file.

    Raises
    ------
    DescriptionError
        Naming the file and the key for a missing, malformed or unknown entry.
    """
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise DescriptionError(path, "(file)", "does not exist") from None
    except tomllib.TOMLDecodeError as exc:
        raise DescriptionError(path, "(syntax)", str(exc)) from None
    top = _Table(path, data)
    top.unknown({"name", "summary", "urdf", "blocks", "task", "configurations", "gravity", "payload",
                 "gains", "trajectory", "ik"})
    name = top.string("name", _REQUIRED)
    if name != path.stem:
        top.fail("name", f"must be the file's name {path.stem!r}, got {name!r}")
    urdf = path.parent / top.string("urdf", _REQUIRED)
    if not urdf.is_file():
        top.fail("urdf", f"no such file {urdf}")
    blocks = top.strings("blocks", _REQUIRED)
    for b in blocks:
        if b not in KNOWN_BLOCKS:
            top.fail("blocks", f"unknown block {b!r} (known: {', '.join(KNOWN_BLOCKS)})")

    task = top.table("task", _REQUIRED)
    task.unknown({"frame", "coordinates", "axes"})
    coordinates = task.strings("coordinates", _REQUIRED)
    axes = task.numbers("axes", list(range(len(coordinates))), length=len(coordinates))
    if any(a not in (0.0, 1.0, 2.0) for a in axes) or len(set(axes)) != len(axes):
        task.fail("axes", f"must be distinct world axes among 0, 1, 2, got {list(axes)}")
    task_space = TaskSpace(task.string("frame", _REQUIRED), coordinates, tuple(int(a) for a in axes))

    conf = top.table("configurations", _REQUIRED)
    configurations = {k: conf.numbers(k, _REQUIRED) for k in conf.data}
    if "home" not in configurations:
        conf.fail("home", "missing")
    lengths = {len(v) for v in configurations.values()}
    if len(lengths) != 1:
        conf.fail("home", f"every configuration needs the same number of joints, got {sorted(lengths)}")

    grav = top.table("gravity", {})
    grav.unknown({"magnitude", "direction"})
    magnitude = grav.number("magnitude", 9.81, low=0.0)
    direction = grav.numbers("direction", [0.0, 0.0, -1.0], length=3)
    norm = math.sqrt(sum(d * d for d in direction))
    if abs(norm - 1.0) > 1e-12:
        grav.fail("direction", f"must be a unit vector, got length {norm:.6g}")

    payload = None
    pay = top.table("payload", None)
    if pay is not None:
        pay.unknown({"mass", "frame"})
        payload = Payload(pay.number("mass", _REQUIRED, low=0.0), pay.string("frame", task_space.frame))

    gains_table = top.table("gains", _REQUIRED)
    gains = {}
    for set_name in gains_table.data:
        g = gains_table.table(set_name, _REQUIRED)
        g.unknown({"kp", "kd", "ki"})
        gains[set_name] = Gains(g.number("kp", _REQUIRED, low=0.0), g.number("kd", _REQUIRED, low=0.0),
                                g.number("ki", 0.0, low=0.0))
    if not gains:
        top.fail("gains", "needs at least one gain set, e.g. [gains.pd]")

    trajectory = _choice(top.table("trajectory", _REQUIRED), "profile")
    ik_table = top.table("ik", None)
    ik = _choice(ik_table, "solver") if ik_table is not None else None
    if ("ik" in blocks) != (ik is not None):
        top.fail("ik", "an [ik] table is needed exactly when `blocks` lists 'ik'")

    return RobotDescription(
        name=name, summary=top.string("summary", _REQUIRED), path=path, urdf=urdf, blocks=blocks,
        task=task_space, configurations=configurations, gravity=magnitude,
        gravity_direction=direction, payload=payload, gains=gains, trajectory=trajectory, ik=ik)

"""Robots as data: one folder per robot, holding a small TOML description and, for a serial robot,
a URDF (a closed-chain mechanism describes itself in its TOML's ``[mechanism]`` table). The
package's robots live in folders here (``robots/<name>/``); a robot of one's own is a TOML file
anywhere, given by its path (its URDF relative to it, or in an installed distribution).

>>> from robofmu.components.robots import load_description, load_model
>>> load_model("chess").n
4
"""
from __future__ import annotations

import os
from functools import lru_cache
from importlib import import_module
from pathlib import Path

from .description import DescriptionError, Gains, RobotDescription, read
from .model import RobotModel

__all__ = ["ROBOTS_DIR", "MODEL_CLASSES", "available", "description_path", "is_robot_file", "load_description",
           "load_model", "model_class", "DescriptionError", "Gains", "RobotDescription", "RobotModel"]

ROBOTS_DIR = Path(__file__).resolve().parent


def available() -> list[str]:
    """Names of the robots described in this package, sorted."""
    return sorted(p.name for p in ROBOTS_DIR.iterdir() if (p / f"{p.name}.toml").is_file())


def is_robot_file(robot: str | Path) -> bool:
    """Whether ``robot`` names a robot TOML file rather than a robot of this package: a Path, or a
    string ending in ``.toml`` or holding a path separator (``./myarm/myarm.toml``)."""
    if isinstance(robot, Path):
        return True
    text = str(robot)
    return text.endswith(".toml") or any(sep in text for sep in ("/", os.sep, os.altsep) if sep)


def description_path(robot: str | Path) -> Path:
    """Path of a robot's TOML: ``robot`` is a robot of this package (by name: its folder,
    :func:`available`) or a robot TOML file anywhere (:func:`is_robot_file`). ValueError in one
    line naming the known robots, or the file that does not exist."""
    if is_robot_file(robot):
        path = Path(robot)
        if path.is_dir():
            inside = os.path.join(str(robot), f"{path.name}.toml")
            hint = f" ({inside})" if (path / f"{path.name}.toml").is_file() else ""
            raise ValueError(f"{robot}: is a folder; give its robot TOML{hint}")
        if not path.is_file():
            raise ValueError(f"no such robot file {robot}")
        return path
    path = ROBOTS_DIR / robot / f"{robot}.toml"
    if not path.is_file():
        raise ValueError(f"unknown robot {robot!r}; known robots: {', '.join(available())} "
                         "(or give the path of a robot TOML)")
    return path


def load_description(robot: str | Path) -> RobotDescription:
    """A robot's validated description: by name (a robot of this package) or from a robot TOML
    anywhere (:func:`description_path`). Cached per file and its modification time
    (descriptions are immutable)."""
    path = description_path(robot)
    stat = path.stat()
    return _read(str(path.resolve()), (stat.st_mtime_ns, stat.st_size))


@lru_cache(maxsize=None)
def _read(path: str, version: tuple[int, int]) -> RobotDescription:
    """The description in ``path``, read once per ``version`` of the file (its modification
    time and size: the cache key)."""
    del version
    return read(path)


#: The robot-model class of each kind of description (:attr:`RobotDescription.model_kind`), as
#: ``"module:Class"`` of this package, imported when first used: ``serial`` for a robot with a
#: URDF (Pinocchio), a mechanism's ``[mechanism] kind`` for a closed chain.
MODEL_CLASSES = {
    "serial": "serial:SerialRobot",
    "planar_3rrp": "parallel:Planar3RRP",
}


def model_class(kind: str) -> type[RobotModel]:
    """The robot-model class registered for ``kind``; ValueError naming the known kinds."""
    try:
        module, name = MODEL_CLASSES[kind].split(":")
    except KeyError:
        raise ValueError(f"no robot model for kind {kind!r}; known: {', '.join(sorted(MODEL_CLASSES))}") from None
    return getattr(import_module(f".{module}", __name__), name)


def load_model(robot: str | Path | RobotDescription, gravity: float | None = None) -> RobotModel:
    """A new model instance of a robot (by name, robot TOML path or description); each owns its
    payload state.

    The class is the one :data:`MODEL_CLASSES` registers for the description's ``model_kind``."""
    description = robot if isinstance(robot, RobotDescription) else load_description(robot)
    return model_class(description.model_kind)(description, gravity)

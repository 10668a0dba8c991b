"""Robots as data: one folder per robot, holding a small TOML description and, for a serial robot,
a URDF (a closed-chain mechanism describes itself in its TOML's ``[mechanism]`` table).

>>> from robofmu.components.robots import load_description, load_model
>>> load_model("chess").n
4
"""
from __future__ import annotations

from functools import lru_cache
from importlib import import_module
from pathlib import Path

from .description import DescriptionError, Gains, RobotDescription, read
from .model import RobotModel

__all__ = ["ROBOTS_DIR", "MODEL_CLASSES", "available", "description_path", "load_description", "load_model",
           "model_class", "DescriptionError", "Gains", "RobotDescription", "RobotModel"]

ROBOTS_DIR = Path(__file__).resolve().parent


def available() -> list[str]:
    """Names of the robots described in this package, sorted."""
    return sorted(p.name for p in ROBOTS_DIR.iterdir() if (p / f"{p.name}.toml").is_file())


def description_path(name: str) -> Path:
    """Path of robot ``name``'s TOML; ValueError naming the known robots otherwise."""
    path = ROBOTS_DIR / name / f"{name}.toml"
    if not path.is_file():
        raise ValueError(f"unknown robot {name!r}; known robots: {', '.join(available())}")
    return path


@lru_cache(maxsize=None)
def load_description(name: str) -> RobotDescription:
    """Robot ``name``'s validated description (cached; descriptions are immutable)."""
    return read(description_path(name))


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


def load_model(robot: str | RobotDescription, gravity: float | None = None) -> RobotModel:
    """A new model instance of a robot (by name or description); each owns its payload state.

    The class is the one :data:`MODEL_CLASSES` registers for the description's ``model_kind``."""
    description = load_description(robot) if isinstance(robot, str) else robot
    return model_class(description.model_kind)(description, gravity)

"""Robots as data: one folder per robot, holding a URDF and a small TOML description.

>>> from robofmu.components.robots import load_description, load_model
>>> load_model("chess").n
4
"""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path

from .description import DescriptionError, Gains, RobotDescription, read
from .model import RobotModel

__all__ = ["ROBOTS_DIR", "available", "description_path", "load_description", "load_model",
           "DescriptionError", "Gains", "RobotDescription", "RobotModel"]

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


def load_model(robot: str | RobotDescription, gravity: float | None = None) -> RobotModel:
    """A new model instance of a robot (by name or description); each owns its payload state."""
    from .serial import SerialRobot

    description = load_description(robot) if isinstance(robot, str) else robot
    return SerialRobot(description, gravity)

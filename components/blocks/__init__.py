"""The blocks a robot gets, FMI-free: each declares its ports and implements output / advance.

>>> from robofmu.components.blocks import make_block
>>> plant = make_block("rpp", "plant")
"""
from __future__ import annotations

from ..robots import DescriptionError, RobotDescription, load_description, load_model
from .base import Block, ContinuousBlock, StepRefused, Variable, block_class, registered
from . import controller, fk, ik, jacobian, plant, trajectory  # noqa: F401  (register the blocks)

__all__ = ["Block", "ContinuousBlock", "StepRefused", "Variable", "block_class", "block_type", "make_block", "registered"]


def block_type(description: RobotDescription, kind: str) -> type[Block]:
    """The block class of ``kind`` for a robot: the trajectory's by the description's profile."""
    if kind not in description.blocks:
        raise ValueError(f"robot {description.name!r} has no {kind!r} block (it has: "
                         f"{', '.join(description.blocks)})")
    if kind != "trajectory":
        return block_class(kind)
    try:
        return block_class(kind, description.trajectory.kind)
    except ValueError:
        known = ", ".join(v for k, v in registered() if k == kind)
        raise DescriptionError(description.path, "trajectory.profile",
                               f"unknown profile {description.trajectory.kind!r}; known: {known}") from None


def make_block(robot: str | RobotDescription, kind: str) -> Block:
    """A new block of ``kind`` for ``robot`` with its own robot-model instance."""
    description = load_description(robot) if isinstance(robot, str) else robot
    return block_type(description, kind)(load_model(description))

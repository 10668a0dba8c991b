"""Orientation on the ports: unit quaternions in the order (x, y, z, w), scalar last.

The order is scipy's (``Rotation.as_quat``), Pinocchio's ``Quaternion.coeffs()`` and ROS's. A
quaternion on a port is the orientation of a frame relative to the world (it rotates frame
coordinates into world coordinates); angular velocities and accelerations on ports are in the
world frame.
"""
from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

__all__ = ["COMPONENTS", "UNIT_TOLERANCE", "NotUnitQuaternion", "canonical", "quaternion_of", "rotation_of"]

#: The components' order on the ports (``quat_ref[1]`` is x, ..., ``quat_ref[4]`` is w).
COMPONENTS = "xyzw"
#: A quaternion whose norm is this close to 1 is normalised; one further off is refused.
UNIT_TOLERANCE = 1e-6


class NotUnitQuaternion(ValueError):
    """A quaternion (x, y, z, w) whose ``norm`` differs from 1 by more than :data:`UNIT_TOLERANCE`
    (or is not finite); ``quaternion`` holds its four components."""

    def __init__(self, quaternion: tuple[float, float, float, float], norm: float):
        self.quaternion, self.norm = quaternion, norm
        shown = ", ".join(f"{c:.9g}" for c in quaternion)
        super().__init__(f"the orientation quaternion (x, y, z, w) = ({shown}) has norm {norm:.9g}, not 1 "
                         "(a unit quaternion is needed)")


def canonical(quaternion: list[float]) -> list[float]:
    """The quaternion (x, y, z, w) with w >= 0 (q and -q are the same rotation)."""
    x, y, z, w = quaternion
    return [-x, -y, -z, -w] if w < 0.0 else [x, y, z, w]


def quaternion_of(rotation) -> list[float]:
    """The unit quaternion (x, y, z, w) of a rotation matrix (3, 3), with w >= 0."""
    return canonical(pin.Quaternion(np.asarray(rotation, dtype=float)).coeffs().tolist())


def rotation_of(quaternion) -> np.ndarray:
    """The rotation matrix (3, 3) of a quaternion (x, y, z, w), normalised.

    Raises
    ------
    NotUnitQuaternion
        If its norm differs from 1 by more than :data:`UNIT_TOLERANCE` (or is not finite).
    """
    x, y, z, w = (quaternion.astype(float, copy=False).tolist() if isinstance(quaternion, np.ndarray)
                  else [float(c) for c in quaternion])
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if not abs(norm - 1.0) <= UNIT_TOLERANCE:
        raise NotUnitQuaternion((x, y, z, w), norm)
    # Pinocchio's (x, y, z, qx, qy, qz, qw) placement: the rotation of Quaternion(w, x, y, z), without
    # the cost of that constructor's overload resolution
    pose = pin.XYZQUATToSE3(np.array([0.0, 0.0, 0.0, x / norm, y / norm, z / norm, w / norm]))
    return np.ascontiguousarray(pose.rotation)

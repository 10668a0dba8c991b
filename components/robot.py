"""A serial robot from its URDF, with kinematics and dynamics from Pinocchio.

Joint coordinates q are the URDF's revolute (rad) and prismatic (m) joints, in URDF order.
Task coordinates are the TCP frame's position in the world frame (m).
"""
from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from .robots import description_path


@dataclass(frozen=True)
class RobotSpec:
    """A robot's metadata (its TOML), with the path of its URDF."""

    name: str
    urdf: Path
    tcp_frame: str
    task_coordinates: tuple[str, ...]
    task_units: tuple[str, ...]
    ik: str
    gravity: float
    payload_mass: float
    raw: dict[str, Any] = field(repr=False, compare=False)

    @property
    def scenario(self) -> dict[str, Any]:
        return self.raw.get("scenario", {})

    def gains(self, kind: str) -> dict[str, float]:
        """Seed gains ``{"kp", "kd", "ki"}`` of ``kind`` ("pd" or "pid")."""
        try:
            return dict(self.raw["gains"][kind])
        except KeyError:
            raise ValueError(f"robot {self.name!r} has no gains {kind!r}") from None


@lru_cache(maxsize=None)
def load_spec(name: str) -> RobotSpec:
    """Read robot ``name``'s description (``components/robots/<name>/<name>.toml``)."""
    path = description_path(name)
    raw = tomllib.loads(path.read_text())
    return RobotSpec(
        name=raw["name"],
        urdf=path.parent / raw["urdf"],
        tcp_frame=raw["tcp_frame"],
        task_coordinates=tuple(raw["task_coordinates"]),
        task_units=tuple(raw["task_units"]),
        ik=raw["ik"],
        gravity=float(raw.get("gravity", 9.81)),
        payload_mass=float(raw.get("payload_mass", 0.0)),
        raw=raw,
    )


class Robot:
    """Kinematics and rigid-body dynamics of one robot, on its own Pinocchio model and data.

    Each instance owns its model, so a payload set on one (``set_payload``) leaves the others
    alone: the plant and the controller each hold their own.

    Parameters
    ----------
    spec : RobotSpec or str
        The robot's description, or its name.
    gravity : float, optional
        Magnitude of gravity (m/s^2), acting along -z of the world frame. Default: the spec's.
    """

    def __init__(self, spec: RobotSpec | str, gravity: float | None = None):
        self.spec = load_spec(spec) if isinstance(spec, str) else spec
        self.model = pin.buildModelFromUrdf(str(self.spec.urdf))
        self.data = self.model.createData()
        if self.model.nq != self.model.nv:
            raise ValueError(f"{self.spec.name}: only revolute and prismatic joints are supported")
        self.n = self.model.nv
        self.tcp_id = self.model.getFrameId(self.spec.tcp_frame)
        if self.tcp_id >= len(self.model.frames):
            raise ValueError(f"{self.spec.name}: no frame {self.spec.tcp_frame!r} in the URDF")
        self.set_gravity(self.spec.gravity if gravity is None else gravity)
        self._tcp_joint = self.model.frames[self.tcp_id].parentJoint
        self._tcp_lever = self.model.frames[self.tcp_id].placement.translation.copy()
        self._bare_inertia = self.model.inertias[self._tcp_joint].copy()
        self.payload = 0.0
        self._zero = np.zeros(self.n)
        self.joint_names = [self.model.names[j] for j in range(1, self.model.njoints)]
        self.prismatic = [
            self.model.joints[j].shortname().startswith("JointModelP")
            for j in range(1, self.model.njoints)
        ]

    # -- parameters -------------------------------------------------------------------------
    def set_gravity(self, g: float) -> None:
        """Set the magnitude of gravity (m/s^2), acting along -z of the world frame."""
        self.gravity = float(g)
        self.model.gravity.linear = np.array([0.0, 0.0, -self.gravity])

    def set_payload(self, mass: float) -> None:
        """Carry a point mass (kg) at the TCP; 0 removes it."""
        mass = float(mass)
        if mass == self.payload:
            return
        inertia = self._bare_inertia.copy()
        if mass > 0.0:
            inertia += pin.Inertia(mass, self._tcp_lever, np.zeros((3, 3)))
        self.model.inertias[self._tcp_joint] = inertia
        self.payload = mass

    def joint_units(self, order: int = 0) -> list[str]:
        """SI unit of each joint coordinate's ``order``-th time derivative (0, 1 or 2)."""
        suffix = ["", "/s", "/s2"][order]
        return [("m" if p else "rad") + suffix for p in self.prismatic]

    def effort_units(self) -> list[str]:
        """N for a prismatic joint, N.m for a revolute one."""
        return ["N" if p else "N.m" for p in self.prismatic]

    # -- kinematics -------------------------------------------------------------------------
    def fk(self, q: np.ndarray) -> np.ndarray:
        """TCP position (m) in the world frame, shape (3,)."""
        pin.forwardKinematics(self.model, self.data, q)
        return pin.updateFramePlacement(self.model, self.data, self.tcp_id).translation.copy()

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """Linear TCP Jacobian in world axes, shape (3, n): xdot = J(q) qdot."""
        return pin.computeFrameJacobian(
            self.model, self.data, q, self.tcp_id, pin.LOCAL_WORLD_ALIGNED
        )[:3].copy()

    def jdot_qdot(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """Jdot(q, qd) qd (m/s^2), shape (3,): the TCP acceleration when qdd = 0."""
        pin.forwardKinematics(self.model, self.data, q, qd, self._zero)
        return pin.getFrameClassicalAcceleration(
            self.model, self.data, self.tcp_id, pin.LOCAL_WORLD_ALIGNED
        ).linear.copy()

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """Joint-space inertia matrix M(q), shape (n, n), symmetric."""
        upper = pin.crba(self.model, self.data, q)
        return np.triu(upper) + np.triu(upper, 1).T

    def nonlinear_effects(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """N(q, qd) = C(q, qd) qd + g(q), shape (n,)."""
        return pin.nonLinearEffects(self.model, self.data, q, qd).copy()

    def coriolis_matrix(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """C(q, qd) (Christoffel form, Mdot - 2C skew), shape (n, n)."""
        return pin.computeCoriolisMatrix(self.model, self.data, q, qd).copy()

    def gravity_torque(self, q: np.ndarray) -> np.ndarray:
        """g(q), shape (n,)."""
        return pin.computeGeneralizedGravity(self.model, self.data, q).copy()

    def forward_dynamics(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """qdd = M(q)^-1 (tau - N(q, qd)) by the articulated-body algorithm, shape (n,)."""
        return pin.aba(self.model, self.data, q, qd, tau).copy()

    def inverse_dynamics(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        """tau = M(q) qdd + N(q, qd) by the recursive Newton-Euler algorithm, shape (n,)."""
        return pin.rnea(self.model, self.data, q, qd, qdd).copy()

    def kinetic_energy(self, q: np.ndarray, qd: np.ndarray) -> float:
        """Kinetic energy (J)."""
        return float(pin.computeKineticEnergy(self.model, self.data, q, qd))

    def potential_energy(self, q: np.ndarray) -> float:
        """Gravitational potential energy (J), zero at world z = 0."""
        return float(pin.computePotentialEnergy(self.model, self.data, q))

"""A serial robot from its URDF, with kinematics and dynamics from Pinocchio.

Joint coordinates q are the URDF's revolute (rad) and prismatic (m) joints, in URDF order.
Task coordinates are the chosen world axes of the task frame's position (m).
"""
from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from .description import RobotDescription
from .model import RobotModel, derivative_unit


_CONTINUOUS = "continuous (Pinocchio's q = (cos, sin))"
#: What a joint that robofmu does not take is, by a word of Pinocchio's joint model name
#: (``JointModelRUBZ``, ``JointModelRevoluteUnboundedUnaligned``, ``JointModelSpherical``, ...).
_JOINT_KINDS = {"RUB": _CONTINUOUS, "Unbounded": _CONTINUOUS, "Spherical": "spherical", "FreeFlyer": "floating",
                "Planar": "planar", "Translation": "a translation", "Composite": "composite",
                "Mimic": "a mimic joint"}


class SerialRobot(RobotModel):
    """Kinematics and rigid-body dynamics of a serial robot, on its own Pinocchio model and data.

    Each instance owns its model, so a payload set on one (``set_payload``) leaves the others
    alone: the plant and the controller each hold their own.

    Parameters
    ----------
    description : RobotDescription
    gravity : float, optional
        Magnitude of gravity (m/s^2) along the description's direction. Default: the
        description's.
    """

    def __init__(self, description: RobotDescription, gravity: float | None = None):
        self.description = description
        self.model = pin.buildModelFromUrdf(str(description.urdf))
        self.data = self.model.createData()
        self._check_joints_and_links()
        self.n = self.model.nv
        if len(description.configuration("home")) != self.n:
            raise ValueError(f"{description.path}: configurations.home: needs {self.n} joint values "
                             f"(the URDF has {self.n} joints), got {len(description.configuration('home'))}")
        self.task_id = self._frame(description.task.frame, "task.frame")
        self._axes = np.array(description.task.axes)
        self.m = len(self._axes)
        first = int(self._axes[0])               # the Jacobian's task rows: a slice where consecutive
        consecutive = list(self._axes) == list(range(first, first + self.m))
        self._rows = slice(first, first + self.m) if consecutive else self._axes
        self._direction = np.array(description.gravity_direction)
        self.set_gravity(description.gravity if gravity is None else gravity)
        self.payload = 0.0
        if description.payload is not None:
            frame = self.model.frames[self._frame(description.payload.frame, "payload.frame")]
            self._payload_joint = frame.parentJoint
            self._payload_lever = frame.placement.translation.copy()
            self._bare_inertia = self.model.inertias[self._payload_joint].copy()
        self._zero = np.zeros(self.n)
        self.joint_names = [self.model.names[j] for j in range(1, self.model.njoints)]
        self.prismatic = [self.model.joints[j].shortname().startswith("JointModelP")
                          for j in range(1, self.model.njoints)]

    def _check_joints_and_links(self) -> None:
        """Refuse, naming the joint or link, what the run would otherwise discover at t = 0: a joint
        that is not revolute or prismatic (a continuous joint is q = (cos, sin) in Pinocchio), and a
        moving link without a valid inertia (no mass, or a rotational inertia that no body has:
        not symmetric positive semi-definite, or breaking the triangle inequality), which makes
        M(q) singular."""
        model, urdf = self.model, self.description.urdf.name
        for j in range(1, model.njoints):
            joint, kind = model.names[j], model.joints[j].shortname()
            if not kind.startswith(("JointModelR", "JointModelP")) or model.joints[j].nq != 1:
                what = next((text for word, text in _JOINT_KINDS.items() if word in kind), kind)
                raise ValueError(f"{urdf}: joint {joint!r} is {what}; robofmu "
                                 "supports revolute and prismatic joints")
            link = next(f.name for f in model.frames if f.type == pin.FrameType.BODY and f.parentJoint == j)
            inertia = model.inertias[j]
            rotational = np.asarray(inertia.inertia)
            eigenvalues = np.linalg.eigvalsh(rotational) if np.all(np.isfinite(rotational)) else np.full(3, np.nan)
            tolerance = 1e-12 * max(1.0, float(np.max(np.abs(rotational))))
            if not (math.isfinite(inertia.mass) and inertia.mass > 0.0):
                raise ValueError(f"{urdf}: link {link!r} (moved by joint {joint!r}) has no mass "
                                 f"({inertia.mass:g} kg): give it an <inertial> with mass > 0")
            if not (np.allclose(rotational, rotational.T, atol=tolerance) and eigenvalues.min() >= -tolerance
                    and 2.0 * eigenvalues.max() <= eigenvalues.sum() + tolerance):
                raise ValueError(f"{urdf}: link {link!r} (moved by joint {joint!r}) has an inertia no body has "
                                 f"(principal moments {', '.join(f'{v:g}' for v in eigenvalues)} kg m^2: each "
                                 "must be >= 0 and at most the sum of the other two)")

    def _frame(self, frame: str, key: str) -> int:
        fid = self.model.getFrameId(frame)
        if fid >= len(self.model.frames):
            raise ValueError(f"{self.description.path}: {key}: no frame {frame!r} in {self.description.urdf.name}")
        return fid

    def task_units(self, order: int = 0) -> list[str]:
        return [derivative_unit("m", order)] * self.m

    def position_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """The URDF's joint limits (Pinocchio's lower/upperPositionLimit)."""
        return self.model.lowerPositionLimit.copy(), self.model.upperPositionLimit.copy()

    def velocity_limits(self) -> np.ndarray:
        """The URDF's joint velocity limits (Pinocchio's velocityLimit)."""
        return self.model.velocityLimit.copy()

    # -- parameters -------------------------------------------------------------------------
    def set_gravity(self, magnitude: float) -> None:
        self.gravity = float(magnitude)
        self.model.gravity.linear = self.gravity * self._direction

    def set_payload(self, mass: float) -> None:
        mass = float(mass)
        if mass == self.payload:
            return
        if self.description.payload is None:
            raise ValueError(f"robot {self.description.name!r} describes no payload frame")
        inertia = self._bare_inertia.copy()
        if mass > 0.0:
            inertia += pin.Inertia(mass, self._payload_lever, np.zeros((3, 3)))
        self.model.inertias[self._payload_joint] = inertia
        self.payload = mass

    # -- kinematics -------------------------------------------------------------------------
    def fk(self, q: np.ndarray) -> np.ndarray:
        pin.forwardKinematics(self.model, self.data, q)
        return pin.updateFramePlacement(self.model, self.data, self.task_id).translation[self._rows]

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        return pin.computeFrameJacobian(self.model, self.data, q, self.task_id,
                                        pin.LOCAL_WORLD_ALIGNED)[self._rows]

    def jdot_qdot(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        pin.forwardKinematics(self.model, self.data, q, qd, self._zero)
        return pin.getFrameClassicalAcceleration(self.model, self.data, self.task_id,
                                                 pin.LOCAL_WORLD_ALIGNED).linear[self._rows]

    # -- dynamics ---------------------------------------------------------------------------
    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        upper = pin.crba(self.model, self.data, q)
        return np.triu(upper) + np.triu(upper, 1).T

    def nonlinear_effects(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        return pin.nonLinearEffects(self.model, self.data, q, qd).copy()

    def coriolis_matrix(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        return pin.computeCoriolisMatrix(self.model, self.data, q, qd).copy()

    def gravity_torque(self, q: np.ndarray) -> np.ndarray:
        return pin.computeGeneralizedGravity(self.model, self.data, q).copy()

    def forward_dynamics(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> np.ndarray:
        return pin.aba(self.model, self.data, q, qd, tau).copy()

    def inverse_dynamics(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        return pin.rnea(self.model, self.data, q, qd, qdd).copy()

    def forward_dynamics_floats(self, q, qd, tau) -> list[float]:
        return pin.aba(self.model, self.data, q, qd, tau).tolist()

    def inverse_dynamics_into(self, q, qd, qdd, out) -> None:
        out[:] = pin.rnea(self.model, self.data, q, qd, qdd)

    def kinetic_energy(self, q: np.ndarray, qd: np.ndarray) -> float:
        return float(pin.computeKineticEnergy(self.model, self.data, q, qd))

    def potential_energy(self, q: np.ndarray) -> float:
        """Gravitational potential energy (J), zero at the world origin's height."""
        return float(pin.computePotentialEnergy(self.model, self.data, q))

"""The robot-model interface every block talks to, whatever the mechanism.

Joint coordinates q (n,) are the actuated joints: rad for revolute, m for prismatic. Task
coordinates x (m,) are what the trajectory and the IK speak: a point's position (m) for the
arms, possibly with an orientation angle (rad) for a planar mechanism. A serial arm implements
this on Pinocchio (:class:`~robofmu.components.robots.serial.SerialRobot`); a closed-chain
mechanism can implement the same methods in its actuated coordinates.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..orientation import quaternion_of
from .description import RobotDescription

_DERIVATIVE_SUFFIX = ("", "/s", "/s2")


def derivative_unit(unit: str, order: int) -> str:
    """SI unit of the ``order``-th time derivative (0, 1, 2) of a coordinate in ``unit``."""
    return unit + _DERIVATIVE_SUFFIX[order]


def consecutive(indices) -> slice | list[int]:
    """``indices`` as a slice where they are consecutive and ascending (indexing by it gives a
    view), else as a list."""
    indices = list(indices)
    if indices and indices == list(range(indices[0], indices[0] + len(indices))):
        return slice(indices[0], indices[0] + len(indices))
    return indices


@dataclass(frozen=True)
class TaskIndex:
    """Which rows of a frame's six-row quantities a task tracks, in the task's order.

    Pinocchio's frame Jacobians, velocities and accelerations stack [linear; angular], three
    rows each. A task's rows are first the tracked axes of the linear part (the task point,
    world-aligned), then the tracked axes of the angular part (about the task frame's own axes).

    Parameters
    ----------
    position : tuple of int
        Tracked linear axes (0, 1, 2: x, y, z), one per task coordinate.
    orientation : tuple of int
        Tracked angular axes (0, 1, 2); none: a position task.
    """

    position: tuple[int, ...]
    orientation: tuple[int, ...] = ()

    def __post_init__(self):
        for name in ("position", "orientation"):
            axes = tuple(getattr(self, name))
            if any(a not in (0, 1, 2) for a in axes) or len(set(axes)) != len(axes):
                raise ValueError(f"task {name} axes must be distinct values of 0, 1, 2, got {axes}")
            object.__setattr__(self, name, axes)

    @cached_property
    def linear(self) -> slice | list[int]:
        """The position rows within the linear part (rows 0-2)."""
        return consecutive(self.position)

    @cached_property
    def angular(self) -> slice | list[int]:
        """The orientation rows within the angular part (rows 3-5 counted from 0)."""
        return consecutive(self.orientation)

    @cached_property
    def six(self) -> slice | list[int]:
        """The task's rows within all six."""
        return consecutive(self.position + tuple(3 + axis for axis in self.orientation))

    @property
    def is_full_pose(self) -> bool:
        """Whether the task tracks all six rows, in Pinocchio's order."""
        return self.position == (0, 1, 2) and self.orientation == (0, 1, 2)


class RobotModel(ABC):
    """Kinematics and rigid-body dynamics in joint coordinates, with task coordinates.

    Attributes
    ----------
    description : RobotDescription
    n : int
        Number of joint coordinates.
    m : int
        Number of task coordinates.
    prismatic : list of bool, shape (n,)
    joint_names : list of str
    """

    description: RobotDescription
    n: int
    m: int
    prismatic: list[bool]
    joint_names: list[str]
    #: A pose task's rotations, about these axes of the task frame (0, 1, 2); none: a position task.
    orientation_axes: tuple[int, ...] = ()
    #: A task on a frame: which rows of its six-row quantities the task's are (None: a mechanism
    #: in its own task coordinates).
    task_index: TaskIndex | None = None

    @property
    def task_rows(self) -> int:
        """Rows of the task velocity (and of :meth:`jacobian`): the m task coordinates' rates, then
        one angular rate per orientation axis."""
        return self.m + len(self.orientation_axes)

    # -- units and names ---------------------------------------------------------------------
    def joint_units(self, order: int = 0) -> list[str]:
        """SI unit of each joint coordinate's ``order``-th time derivative (0, 1 or 2)."""
        return [derivative_unit("m" if p else "rad", order) for p in self.prismatic]

    def effort_units(self) -> list[str]:
        """N for a prismatic joint, N.m for a revolute one."""
        return ["N" if p else "N.m" for p in self.prismatic]

    def joint_symbols(self) -> list[str]:
        """Short plot labels: q1, q2, ... (the unit tells revolute from prismatic)."""
        return [f"q{j + 1}" for j in range(self.n)]

    @property
    def task_coordinates(self) -> tuple[str, ...]:
        return self.description.task.coordinates

    @abstractmethod
    def task_units(self, order: int = 0) -> list[str]:
        """SI unit of each task coordinate's ``order``-th time derivative."""

    def configuration(self, name: str) -> np.ndarray:
        """A named joint configuration of the description (``home``, ...), shape (n,)."""
        return np.array(self.description.configuration(name), dtype=float)

    @abstractmethod
    def position_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper joint position limits (rad, m), each shape (n,) (+/- inf where none)."""

    @abstractmethod
    def velocity_limits(self) -> np.ndarray:
        """Joint velocity limits (rad/s, m/s), shape (n,) (inf where none)."""

    def effort_limits(self) -> np.ndarray:
        """Joint effort limits (N.m, N), shape (n,) (inf where none: the default)."""
        return np.full(self.n, np.inf)

    # -- parameters ---------------------------------------------------------------------------
    @abstractmethod
    def set_gravity(self, magnitude: float) -> None:
        """Magnitude of gravity (m/s^2) along the description's direction."""

    @abstractmethod
    def set_payload(self, mass: float) -> None:
        """Carry a point mass (kg) at the payload frame; 0 removes it."""

    # -- kinematics ---------------------------------------------------------------------------
    @abstractmethod
    def fk(self, q: np.ndarray) -> np.ndarray:
        """Task coordinates x(q), shape (m,)."""

    def rotation(self, q: np.ndarray) -> np.ndarray:
        """Orientation of the task frame (frame to world), shape (3, 3): a pose task's robot has it."""
        raise NotImplementedError(f"robot {self.description.name!r} has no task orientation")

    def fk_quaternion(self, q: np.ndarray) -> tuple[list[float], list[float]]:
        """A pose task's robot: :meth:`fk` and the orientation of :meth:`rotation` as a unit
        quaternion (x, y, z, w), w >= 0 (:func:`~robofmu.components.orientation.quaternion_of`),
        at ``q``, as floats (a model may take both from one pass)."""
        return self.fk(q).tolist(), quaternion_of(self.rotation(q))

    def kinematics(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A pose task's robot: the task frame's position (3,), orientation (3, 3) and full Jacobian
        (6, n) (world linear rows, then angular rows about the frame's own axes), in one pass."""
        raise NotImplementedError(f"robot {self.description.name!r} has no task orientation")

    @abstractmethod
    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """Task Jacobian, shape (task_rows, n): the task velocity is J(q) qd (for a pose task, the
        angular rows are about the task frame's own axes)."""

    @abstractmethod
    def jdot_qdot(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """Jdot(q, qd) qd, shape (task_rows,): the task acceleration when qdd = 0."""

    def jacobian_derivative(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """dJ/dt (task_rows, n) along the motion (q, qd): what a solver for redundant tasks needs."""
        raise NotImplementedError(f"robot {self.description.name!r} gives no Jacobian derivative")

    # -- dynamics -----------------------------------------------------------------------------
    @abstractmethod
    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """M(q), shape (n, n), symmetric positive definite."""

    @abstractmethod
    def coriolis_matrix(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """C(q, qd), shape (n, n), with Mdot - 2C skew-symmetric."""

    @abstractmethod
    def gravity_torque(self, q: np.ndarray) -> np.ndarray:
        """g(q), shape (n,)."""

    def gravity_jacobian(self, q: np.ndarray) -> np.ndarray:
        """dg/dq at ``q``, shape (n, n) (N.m/rad, N/m, ...): the stiffness gravity adds about ``q``.

        Central differences of :meth:`gravity_torque` (step 1e-6 in each coordinate, error about
        1e-10 of g''); a model with the derivative in closed form overrides this."""
        q = np.asarray(q, dtype=float)
        step = 1e-6
        columns = [(self.gravity_torque(q + step * e) - self.gravity_torque(q - step * e)) / (2.0 * step)
                   for e in np.eye(q.size)]
        return np.column_stack(columns)

    @abstractmethod
    def nonlinear_effects(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """N(q, qd) = C(q, qd) qd + g(q), shape (n,)."""

    @abstractmethod
    def forward_dynamics(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """qdd = M^-1 (tau - N), shape (n,)."""

    def forward_dynamics_floats(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> list[float]:
        """:meth:`forward_dynamics` as a list of n floats (a model may spare the array of its result)."""
        return self.forward_dynamics(q, qd, tau).tolist()

    @abstractmethod
    def inverse_dynamics(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        """tau = M qdd + N, shape (n,)."""

    def inverse_dynamics_into(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, out: np.ndarray) -> None:
        """:meth:`inverse_dynamics` written into ``out`` (n,) (a model may spare the copy of its result)."""
        out[:] = self.inverse_dynamics(q, qd, qdd)

    @abstractmethod
    def kinetic_energy(self, q: np.ndarray, qd: np.ndarray) -> float:
        """Kinetic energy (J)."""

    @abstractmethod
    def potential_energy(self, q: np.ndarray) -> float:
        """Gravitational potential energy (J)."""

"""The IK solver interface and the joint rates shared by every solver.

With task Jacobian J(q) (m, n) and, where a solver fixes extra joint combinations (a tool pitch
held constant), constant constraint rows C (c, n) with m + c = n, the augmented matrix
A = [J; C] gives

    qd  = A^-1 [xd; 0]
    qdd = A^-1 [xdd - Jdot(q, qd) qd; 0]

(the constraint rows are constant, so their time derivative adds nothing).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import math

import numpy as np
from scipy.linalg.lapack import dgesv as gesv, dgetrs as getrs

from ..parameters import Parameter, ParameterError, resolve
from ..robots.model import RobotModel

_SOLVERS: dict[str, type["IKSolver"]] = {}


class Unreachable(ValueError):
    """The target lies outside the workspace of the solver's branch, or on a singularity."""


class RatesOverflow(Unreachable):
    """The joint rates at ``q`` (n,) are not finite although the rate equations are regular there:
    the task rates or accelerations are too large (the IK block names the input)."""

    def __init__(self, message: str, q: np.ndarray):
        super().__init__(message)
        self.q = np.array(q, dtype=float)


#: A diagnostic's unit that is the joints' own (rad, m; "1" for a robot with both kinds).
JOINT_UNIT = "joint"


@dataclass(frozen=True)
class Diagnostic:
    """A number a solver reports about its last solve (the IK block makes it an output); its
    ``unit`` an SI unit or :data:`JOINT_UNIT`."""

    name: str
    unit: str
    description: str


class IKSolver:
    """Base of every IK solver.

    Subclasses set ``kind`` (the registry name), ``parameters`` (declared
    :class:`~robofmu.components.parameters.Parameter` s) and implement :meth:`position`; a
    solver that holds extra joint combinations fixed sets ``constraint_rows`` and
    ``constraint_values`` (C q = c) in :meth:`setup`. An iterative solver declares
    ``diagnostics`` (filled in :attr:`report` by every :meth:`position` call, failed or not) and
    takes its start from :meth:`start_from`.

    Parameters
    ----------
    robot : RobotModel
    **values
        Parameter values (validated against the declaration; defaults from it).
    """

    kind: ClassVar[str] = ""
    parameters: ClassVar[tuple[Parameter, ...]] = ()
    diagnostics: ClassVar[tuple[Diagnostic, ...]] = ()
    #: A square solver needs as many task coordinates and constraints as joints, and a position
    #: task; a solver for any task/joint ratio and pose tasks sets False and overrides :meth:`solve`.
    square: ClassVar[bool] = True

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if not cls.kind:
            raise TypeError(f"{cls.__name__}: an IK solver needs a registry name `kind`")
        if cls.position is IKSolver.position:
            raise TypeError(f"{cls.__name__}: an IK solver must implement position(x)")
        if cls.kind in _SOLVERS:
            raise TypeError(f"{cls.__name__}: IK solver kind {cls.kind!r} is taken by "
                            f"{_SOLVERS[cls.kind].__name__}")
        _SOLVERS[cls.kind] = cls

    def __init__(self, robot: RobotModel, **values):
        self.robot = robot
        #: The robot's joint position limits (lower, upper) as lists of floats, read once.
        self.position_limits = tuple(v.tolist() for v in robot.position_limits())
        try:
            self.values = resolve(self.parameters, values)
        except ParameterError as exc:
            raise ValueError(f"IK solver {self.kind!r}: {exc.problem}") from None
        self.constraint_rows = np.zeros((0, robot.n))
        self.constraint_values = np.zeros(0)
        self.report: dict[str, float] = {d.name: 0.0 for d in self.diagnostics}
        self.setup()
        if not self.square:
            return
        if robot.orientation_axes:
            raise ValueError(f"IK solver {self.kind!r} solves position tasks; robot {robot.description.name!r} "
                             "tracks an orientation too (use a solver for pose tasks: damped_least_squares)")
        rows = robot.m + len(self.constraint_rows)
        if rows != robot.n or len(self.constraint_values) != len(self.constraint_rows):
            raise ValueError(f"IK solver {self.kind!r}: {robot.m} task coordinates and "
                             f"{len(self.constraint_rows)} constraints for {robot.n} joints (a square "
                             "solver; for other ratios use damped_least_squares)")
        n, m = robot.n, robot.m
        self._A = np.zeros((n, n))                 # A = [J; C]: the constraint rows set once
        self._A[m:] = self.constraint_rows
        self._rhs = np.zeros(n)                    # [xd; 0], then [xdd - Jdot qd; 0]
        self._rhs_task = self._rhs[:m]             # its first m rows, a view

    def setup(self) -> None:
        """Read the parameters (``self.values``) and robot geometry; set ``constraint_rows``."""

    def position(self, x: np.ndarray, quaternion: np.ndarray | None = None) -> np.ndarray:
        """Joint positions (rad, m), shape (n,), placing the task point at ``x`` (and, a solver of
        pose tasks, the task frame's orientation at ``quaternion``, x, y, z, w); raises Unreachable."""
        raise NotImplementedError

    def start_from(self, q: np.ndarray | None, qd: np.ndarray | None = None, qdd: np.ndarray | None = None,
                   elapsed: float = 0.0) -> None:
        """Where an iterative solver starts its next solve: ``q`` (a previous solution), or its
        initial guess if None; ``qd``, ``qdd`` and ``elapsed`` (s) are that solution's rates and the
        time since it, for a solver that predicts its start. Closed-form solvers ignore it."""

    def augmented_jacobian(self, q: np.ndarray) -> np.ndarray:
        """A(q) = [J(q); C], shape (n, n): a new array."""
        A = np.empty((self.robot.n, self.robot.n))
        m = self.robot.m
        A[:m] = self.robot.jacobian(q)
        A[m:] = self.constraint_rows
        return A

    def rates(self, q: np.ndarray, xd: np.ndarray, xdd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Joint velocity and acceleration for task velocity ``xd`` and acceleration ``xdd`` at ``q``.

        Raises
        ------
        Unreachable
            If A(q) is singular (an exact zero pivot); :class:`RatesOverflow` if the rates are
            not finite (the task rates or accelerations too large).
        """
        A, rhs, m = self._A, self._rhs, self.robot.m
        A[:m] = self.robot.jacobian(q)
        # One LU factorization for both right-hand sides, LAPACK called directly (numpy.linalg.solve
        # costs several times the arithmetic of a 4 x 4): gesv factors A and solves for qd (getrf
        # then getrs, as numpy.linalg.solve does), getrs reuses the factors for qdd.
        self._rhs_task[:] = xd
        lu, pivots, qd, singular = gesv(A, rhs)
        if singular:
            raise Unreachable(f"singular configuration q = {np.asarray(q).tolist()}")
        np.subtract(xdd, self.robot.jdot_qdot(q, qd), out=self._rhs_task)
        qdd = getrs(lu, pivots, rhs)[0]
        if not math.isfinite(sum(qd.tolist()) + sum(qdd.tolist())):    # nan and inf propagate
            raise RatesOverflow(f"the joint rates are not finite at q = {np.asarray(q).tolist()}", q)
        return qd, qdd

    def solve(self, x, xd, xdd, quaternion=None, omega=None, omegad=None):
        """Joint position, velocity and acceleration for a task-space motion.

        Parameters
        ----------
        x, xd, xdd : array_like, shape (m,)
            Task position, velocity and acceleration (task units).
        quaternion, omega, omegad : array_like, shapes (4,), (3,), (3,), optional
            A pose task's orientation (unit quaternion x, y, z, w, frame to world), angular
            velocity (rad/s) and acceleration (rad/s^2), both in the world frame.

        Returns
        -------
        q, qd, qdd : ndarray, shape (n,)
            Joint units.

        Raises
        ------
        Unreachable
        """
        q = self.position(np.asarray(x, dtype=float))
        qd, qdd = self.rates(q, xd, xdd)
        return q, qd, qdd


def solvers() -> list[str]:
    """Registered solver names."""
    return sorted(_SOLVERS)


def solver_class(kind: str) -> type[IKSolver]:
    try:
        return _SOLVERS[kind]
    except KeyError:
        raise ValueError(f"unknown IK solver {kind!r}; known: {', '.join(solvers())}") from None


def make_solver(robot: RobotModel, **overrides) -> IKSolver:
    """The solver the robot's description names, with its ``[ik]`` values and ``overrides``."""
    choice = robot.description.ik
    if choice is None:
        raise ValueError(f"robot {robot.description.name!r} has no IK ([ik] table)")
    return solver_class(choice.kind)(robot, **{**choice.parameters, **overrides})

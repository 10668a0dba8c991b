"""Inverse kinematics as a family of solvers behind one interface.

Each solver (:class:`IKSolver` subclass) declares its parameters and implements the position
level; velocity and acceleration follow for every solver from the robot model's J and Jdot qd
(:meth:`IKSolver.solve`). Solvers register by ``kind``; a robot description names its solver
in ``[ik] solver = ...``.
"""
from __future__ import annotations

from .base import JOINT_UNIT, Diagnostic, IKSolver, RatesOverflow, Unreachable, make_solver, solver_class, solvers
from . import closed_form  # noqa: F401  (registers the closed-form solvers)
from . import newton  # noqa: F401  (registers the Newton-Raphson solver)
from . import damped_least_squares  # noqa: F401  (registers the damped least-squares solver)

__all__ = ["JOINT_UNIT", "Diagnostic", "IKSolver", "RatesOverflow", "Unreachable", "make_solver", "solver_class", "solvers"]

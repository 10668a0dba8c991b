"""Inverse kinematics: closed form for the chess arm, at position, velocity and acceleration level.

Position (robots.md section 1, elbow up, tool pitch phi = q2 + q3 + q4 held at -pi/2):
with p = sqrt(x^2 + y^2), the wrist sits at radius p_w = p - a4 cos(phi), height
z_w = z - a4 sin(phi); with r = z_w - a1, d = sqrt(p_w^2 + r^2), w = atan2(r, p_w):

    q1 = atan2(y, x)
    q2 = w +/- acos((a2^2 + d^2 - a3^2) / (2 a2 d))     (+ elbow up, - elbow down)
    q3 = atan2(r - a2 sin q2, p_w - a2 cos q2) - q2
    q4 = phi - q2 - q3

The atan2 form of q3 equals robots.md's ``-q2 - acos((p - a2 cos q2)/a3)`` wherever the forearm
points down (the whole reference task) and stays right where it does not. (The seed writes
``-w + acos(...)`` for q2; that sign misses the target by up to 0.19 m.)

Velocity and acceleration use the augmented Jacobian A = [J(q); (0, 1, 1, 1)] (TCP position plus
the tool-pitch constraint): qd = A^-1 [xd; 0], qdd = A^-1 [xdd - Jdot(q, qd) qd; 0], with J and
Jdot qd from the robot model (analytic, not finite differences).
"""
from __future__ import annotations

import math

import numpy as np

from .robot import Robot


class Unreachable(ValueError):
    """The target lies outside the workspace (or on a singularity) of the IK branch."""


class ChessIK:
    """Closed-form IK of the chess arm.

    Parameters
    ----------
    robot : Robot
        The chess robot; its link lengths are read from the model, not repeated here.
    tool_pitch : float, optional
        Tool pitch phi = q2 + q3 + q4 (rad). Default: the robot description's (-pi/2).
    elbow : {"up", "down"}, optional
        IK branch. Default: the robot description's ("up").
    """

    def __init__(self, robot: Robot, tool_pitch: float | None = None, elbow: str | None = None):
        raw = robot.spec.raw
        self.robot = robot
        self.tool_pitch = float(raw["tool_pitch"] if tool_pitch is None else tool_pitch)
        elbow = raw.get("elbow", "up") if elbow is None else elbow
        if elbow not in ("up", "down"):
            raise ValueError(f"elbow: unknown option {elbow!r}; choose 'up' or 'down'")
        self.elbow = elbow
        placements = robot.model.jointPlacements
        self.a1 = float(placements[2].translation[2])
        self.a2 = float(placements[3].translation[0])
        self.a3 = float(placements[4].translation[0])
        self.a4 = float(robot._tcp_lever[0])
        self._sign = 1.0 if elbow == "up" else -1.0
        self._pitch_row = np.array([0.0, 1.0, 1.0, 1.0])

    def position(self, x: np.ndarray) -> np.ndarray:
        """Joint angles (rad), shape (4,), placing the TCP at ``x`` (m); raises Unreachable."""
        px, py, pz = float(x[0]), float(x[1]), float(x[2])
        p = math.hypot(px, py)
        if p < 1e-9:
            raise Unreachable(f"target ({px:.6g}, {py:.6g}, {pz:.6g}) m lies on the base axis: q1 undefined")
        phi = self.tool_pitch
        pw = p - self.a4 * math.cos(phi)
        r = pz - self.a4 * math.sin(phi) - self.a1
        d = math.hypot(pw, r)
        c = (self.a2 ** 2 + d * d - self.a3 ** 2) / (2.0 * self.a2 * d) if d > 0 else 2.0
        if not abs(c) < 1.0 - 1e-12:
            raise Unreachable(
                f"target ({px:.6g}, {py:.6g}, {pz:.6g}) m is out of reach: wrist at {d:.6g} m from "
                f"the shoulder, reachable {abs(self.a2 - self.a3):.6g} to {self.a2 + self.a3:.6g} m")
        q2 = math.atan2(r, pw) + self._sign * math.acos(c)
        q23 = math.atan2(r - self.a2 * math.sin(q2), pw - self.a2 * math.cos(q2))
        return np.array([math.atan2(py, px), q2, q23 - q2, phi - q23])

    def augmented_jacobian(self, q: np.ndarray) -> np.ndarray:
        """A(q) = [J(q); (0, 1, 1, 1)], shape (4, 4)."""
        return np.vstack([self.robot.jacobian(q), self._pitch_row])

    def solve(self, x: np.ndarray, xd: np.ndarray, xdd: np.ndarray):
        """Joint position, velocity and acceleration for a TCP motion.

        Parameters
        ----------
        x, xd, xdd : array_like, shape (3,)
            TCP position (m), velocity (m/s) and acceleration (m/s^2).

        Returns
        -------
        q, qd, qdd : ndarray, shape (4,)
            rad, rad/s, rad/s^2.

        Raises
        ------
        Unreachable
        """
        q = self.position(x)
        A = self.augmented_jacobian(q)
        qd = np.linalg.solve(A, np.append(xd, 0.0))
        qdd = np.linalg.solve(A, np.append(np.asarray(xdd) - self.robot.jdot_qdot(q, qd), 0.0))
        return q, qd, qdd


def make_ik(robot: Robot, **options):
    """The IK solver named by the robot description's ``ik`` entry."""
    kinds = {"chess_closed_form": ChessIK}
    try:
        return kinds[robot.spec.ik](robot, **options)
    except KeyError:
        raise ValueError(f"robot {robot.spec.name!r}: unknown ik {robot.spec.ik!r}") from None

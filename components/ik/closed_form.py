"""Closed-form position IK for the geometries that have one.

``pitch_elbow`` (a base rotation, then three pitch joints with a tool pitch held constant):
with phi = q2 + q3 + q4 the tool pitch, p = sqrt(x^2 + y^2), the wrist sits at radius
p_w = p - a4 cos(phi), height z_w = z - a4 sin(phi); with r = z_w - a1, d = sqrt(p_w^2 + r^2),
w = atan2(r, p_w):

    q1 = atan2(y, x)
    q2 = w +/- acos((a2^2 + d^2 - a3^2) / (2 a2 d))     (+ elbow up, - elbow down)
    q3 = atan2(r - a2 sin q2, p_w - a2 cos q2) - q2
    q4 = phi - q2 - q3

The atan2 form of q3 equals ``-q2 - acos((p - a2 cos q2)/a3)`` wherever the forearm points down
and stays right where it does not. The constraint row (0, 1, 1, 1) holds phi.

``spherical`` (RRP: base rotation q1, elevation q2, radial extension s3 from a shoulder at
height d1): q1 = atan2(y, x), q2 = atan2(z - d1, sqrt(x^2 + y^2)), s3 = |x - (0, 0, d1)|, the
branch with s3 >= 0 and |q2| < pi/2. det J = s3^2 cos q2: singular at s3 = 0 and q2 = +/- pi/2.

Link lengths are read from the robot model's joint placements, never repeated here.
"""
from __future__ import annotations

import math

import numpy as np

from ..parameters import Parameter
from .base import IKSolver, Unreachable

#: Closer than this (m) to an axis where a joint angle is undefined counts as singular.
AXIS_TOLERANCE = 1e-9


def _placements(robot):
    model = getattr(robot, "model", None)
    if model is None or not hasattr(model, "jointPlacements"):
        raise ValueError(f"robot {robot.description.name!r}: closed-form IK needs a serial URDF model")
    return [p.translation for p in model.jointPlacements]


class PitchElbowIK(IKSolver):
    """Base rotation plus three pitch joints, tool pitch held (elbow up or down)."""

    kind = "pitch_elbow"
    parameters = (
        Parameter("tool_pitch", "Real", "rad", "Tool pitch q2 + q3 + q4 held by the IK", -math.pi / 2),
        Parameter("elbow", "String", "", "IK branch: 'up' or 'down'", "up", choices=("up", "down")),
    )

    def setup(self):
        robot = self.robot
        if robot.n != 4 or robot.m != 3:
            raise ValueError(f"IK solver {self.kind!r} needs 4 joints and 3 task coordinates")
        t = _placements(robot)
        self.a1, self.a2, self.a3 = float(t[2][2]), float(t[3][0]), float(t[4][0])
        self.a4 = float(robot.model.frames[robot.task_id].placement.translation[0])
        self.tool_pitch = self.values["tool_pitch"]
        self._sign = 1.0 if self.values["elbow"] == "up" else -1.0
        self.constraint_rows = np.array([[0.0, 1.0, 1.0, 1.0]])

    def position(self, x):
        px, py, pz = float(x[0]), float(x[1]), float(x[2])
        p = math.hypot(px, py)
        if p < AXIS_TOLERANCE:
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


class SphericalIK(IKSolver):
    """Spherical RRP arm: azimuth, elevation, radial extension."""

    kind = "spherical"

    def setup(self):
        robot = self.robot
        if robot.n != 3 or robot.m != 3 or robot.prismatic != [False, False, True]:
            raise ValueError(f"IK solver {self.kind!r} needs joints revolute, revolute, prismatic "
                             "and 3 task coordinates")
        self.d1 = float(robot.fk(np.zeros(3))[2])           # the shoulder: the TCP at s3 = 0
        lower, upper = robot.position_limits()
        self.extension = (max(0.0, float(lower[2])), float(upper[2]))

    def position(self, x):
        px, py, pz = float(x[0]), float(x[1]), float(x[2]) - self.d1
        p = math.hypot(px, py)
        s3 = math.sqrt(p * p + pz * pz)
        if p < AXIS_TOLERANCE:
            raise Unreachable(f"target ({px:.6g}, {py:.6g}, {pz + self.d1:.6g}) m lies on the base "
                              "axis: q1 undefined (det J = s3^2 cos q2 = 0)")
        lo, hi = self.extension
        if not (lo <= s3 <= hi + 1e-12):
            raise Unreachable(f"target ({px:.6g}, {py:.6g}, {pz + self.d1:.6g}) m needs an extension "
                              f"of {s3:.6g} m; the slide reaches {lo:.6g} to {hi:.6g} m")
        return np.array([math.atan2(py, px), math.atan2(pz, p), s3])

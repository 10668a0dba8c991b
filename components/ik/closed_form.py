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
        self.constraint_values = np.array([self.tool_pitch])

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
        _check_geometry(self, self._fk, ((0.3, -0.7, 0.4), (-2.0, 1.3, 1.7), (1.1, 2.9, 0.9)))

    def _fk(self, q):
        """The spherical arm's FK: the TCP at s3 along the elevation q2 and the azimuth q1."""
        q1, q2, s3 = (float(v) for v in q)
        return np.array([s3 * math.cos(q2) * math.cos(q1), s3 * math.cos(q2) * math.sin(q1),
                         self.d1 + s3 * math.sin(q2)])

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


# -- seed 003: the planar 2R arm and the RRP arm with a shoulder offset ------------------------------
#: FK(q) of a solver's geometry must equal the robot model's to this (m) at the check configurations.
GEOMETRY_TOLERANCE = 1e-9
#: Joint angles returned by the seed-003 solvers are wrapped into [-pi, pi].
_TWO_PI = 2.0 * math.pi


def _point(x) -> str:
    return "(" + ", ".join(f"{float(v):.6g}" for v in x) + ")"


def _check_geometry(solver, fk, configurations) -> None:
    """Refuse a robot whose URDF is not the solver's mechanism: its FK must be ``fk`` (the closed
    form on the lengths read from the model) at every configuration given."""
    robot = solver.robot
    for q in configurations:
        q = np.asarray(q, dtype=float)
        error = float(np.max(np.abs(robot.fk(q) - fk(q))))
        if not error <= GEOMETRY_TOLERANCE:
            raise ValueError(f"IK solver {solver.kind!r}: robot {robot.description.name!r} is not this "
                             f"mechanism (its FK differs from the solver's by {error:.3g} m at q = "
                             f"{q.tolist()})")


def _check_limits(solver, q, x) -> None:
    """Unreachable if a joint of ``q`` lies outside the URDF's position limits."""
    robot = solver.robot
    lower, upper = solver.position_limits
    for j, value in enumerate(q.tolist()):
        if not (lower[j] - 1e-12 <= value <= upper[j] + 1e-12):
            units = robot.joint_units(0)
            raise Unreachable(f"target {_point(x)} m needs {robot.joint_names[j]} = {q[j]:.6g} {units[j]}, "
                              f"outside its limits {lower[j]:.6g} to {upper[j]:.6g} {units[j]}")


class PlanarElbowIK(IKSolver):
    """Planar 2R arm: two revolute joints about z, task (x, y); returns the URDF's relative q2.

    With b the joint-1 axis in the plane, l1 the distance from it to the joint-2 axis and l2 from
    that to the TCP (read from the model at q = 0, with the links' angles there, zero for links
    along x), d = x - b, r = |d|:

        cos phi = (r^2 - l1^2 - l2^2) / (2 l1 l2)
        phi = +acos(cos phi)   elbow "down": q2 in [0, pi]
        phi = -acos(cos phi)   elbow "up":   q2 in [-pi, 0]
        q1 = atan2(d_y, d_x) - atan2(l2 sin phi, l1 + l2 cos phi),  q2 = phi  (relative)

    For a target with x > 0 in a vertical plane with gravity along -y, "up" puts the elbow above
    the line from joint 1 to the TCP and "down" below it (at home, q2 = 1 rad, the arm is elbow
    down). The seed's absolute angle of link 2 is q1 + q2. Angles are wrapped into [-pi, pi].
    Reachable: |l1 - l2| <= r <= l1 + l2; det J = l1 l2 sin q2, singular at both edges.
    """

    kind = "planar_elbow"
    parameters = (
        Parameter("elbow", "String", "", "IK branch: 'down' (q2 >= 0) or 'up' (q2 <= 0)", "down",
                  choices=("down", "up")),
    )

    def setup(self):
        robot = self.robot
        if robot.n != 2 or robot.m != 2 or robot.prismatic != [False, False]:
            raise ValueError(f"IK solver {self.kind!r} needs 2 revolute joints and 2 task coordinates")
        model = robot.model
        axes = list(robot.description.task.axes)
        base = np.asarray(model.jointPlacements[1].translation)[axes]
        elbow = np.asarray(model.jointPlacements[1].act(model.jointPlacements[2].translation))[axes]
        tip = robot.fk(np.zeros(2))
        self.base = base
        self.l1, self.l2 = float(np.hypot(*(elbow - base))), float(np.hypot(*(tip - elbow)))
        self.theta1 = math.atan2(*(elbow - base)[::-1])
        self.theta2 = math.atan2(*(tip - elbow)[::-1])
        self._sign = 1.0 if self.values["elbow"] == "down" else -1.0
        _check_geometry(self, self._fk, ((0.3, -0.7), (-2.0, 1.3), (1.1, 2.9)))

    def _fk(self, q):
        a1, a2 = q[0] + self.theta1, q[0] + q[1] + self.theta2
        return self.base + np.array([self.l1 * math.cos(a1) + self.l2 * math.cos(a2),
                                     self.l1 * math.sin(a1) + self.l2 * math.sin(a2)])

    def position(self, x):
        dx, dy = float(x[0]) - self.base[0], float(x[1]) - self.base[1]
        r = math.hypot(dx, dy)
        l1, l2 = self.l1, self.l2
        inner, outer = abs(l1 - l2), l1 + l2
        c = (r * r - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)
        if not abs(c) <= 1.0 + 1e-12:
            raise Unreachable(f"target {_point(x)} m is out of reach: {r:.6g} m from joint 1's axis, "
                              f"reachable {inner:.6g} to {outer:.6g} m (l1 = {l1:.6g} m, l2 = {l2:.6g} m)")
        if r < AXIS_TOLERANCE:                             # only where l1 = l2: folded onto the axis
            raise Unreachable(f"target {_point(x)} m lies on joint 1's axis: q1 undefined")
        phi = self._sign * math.acos(min(1.0, max(-1.0, c)))
        q1 = math.atan2(dy, dx) - math.atan2(l2 * math.sin(phi), l1 + l2 * math.cos(phi)) - self.theta1
        q2 = phi + self.theta1 - self.theta2
        q = np.array([math.remainder(q1, _TWO_PI), math.remainder(q2, _TWO_PI)])
        _check_limits(self, q, x)
        return q


class OffsetRRPIK(IKSolver):
    """RRP arm with a shoulder offset: q1 about z, an arm of length l2 (along y of link 1) at
    height l1, q2 about that arm, a slide of extension q3 = l3 > 0:

        x = -l2 sin q1 - l3 sin q2 cos q1,  y = l2 cos q1 - l3 sin q2 sin q1,  z = l1 + l3 cos q2

    (l1, l2 and the arm's angle at q1 = 0 read from the model: the TCP with the slide retracted).
    With s = l3 sin q2 = +/- sqrt(x^2 + y^2 - l2^2), h = z - l1:

        q2 = atan2(s, h),  q3 = l3 = sqrt(s^2 + h^2),  q1 = atan2(y, x) - atan2(l2, -s)

    Branch "positive": s = l3 sin q2 >= 0, i.e. q2 in [0, pi] (the home configuration's);
    "negative": s <= 0, q2 in [-pi, 0]. det J = -q3^2 sin q2: the branches meet on the singular
    cylinder x^2 + y^2 = l2^2; inside it there is no solution. Angles are wrapped into [-pi, pi];
    an extension outside the slide's URDF limits is unreachable.
    """

    kind = "offset_rrp"
    parameters = (
        Parameter("branch", "String", "", "IK branch: sign of l3 sin q2, 'positive' (q2 >= 0) or "
                  "'negative' (q2 <= 0)", "positive", choices=("positive", "negative")),
    )

    def setup(self):
        robot = self.robot
        if robot.n != 3 or robot.m != 3 or robot.prismatic != [False, False, True]:
            raise ValueError(f"IK solver {self.kind!r} needs joints revolute, revolute, prismatic "
                             "and 3 task coordinates")
        shoulder = robot.fk(np.zeros(3))                   # the TCP with the slide retracted
        self.l1 = float(shoulder[2])
        self.l2 = float(math.hypot(shoulder[0], shoulder[1]))
        self.theta = math.atan2(shoulder[1], shoulder[0]) - math.pi / 2
        self._sign = 1.0 if self.values["branch"] == "positive" else -1.0
        lower, upper = robot.position_limits()
        self.extension = (float(lower[2]), float(upper[2]))
        _check_geometry(self, self._fk, ((0.3, -0.7, 0.4), (-2.0, 1.3, 1.7), (1.1, 2.9, 0.9)))

    def _fk(self, q):
        q1, q2, l3 = q[0] + self.theta, q[1], q[2]
        s1, c1, s = math.sin(q1), math.cos(q1), l3 * math.sin(q2)
        return np.array([-self.l2 * s1 - s * c1, self.l2 * c1 - s * s1, self.l1 + l3 * math.cos(q2)])

    def position(self, x):
        px, py, pz = float(x[0]), float(x[1]), float(x[2])
        rho2 = px * px + py * py
        s2 = rho2 - self.l2 ** 2
        if s2 < -1e-12:
            raise Unreachable(f"target {_point(x)} m is out of reach: {math.sqrt(rho2):.6g} m from "
                              f"joint 1's axis, inside the offset l2 = {self.l2:.6g} m")
        s = self._sign * math.sqrt(max(s2, 0.0))
        h = pz - self.l1
        l3 = math.hypot(s, h)
        lo, hi = self.extension
        if not (lo - 1e-12 <= l3 <= hi + 1e-12):
            raise Unreachable(f"target {_point(x)} m needs an extension l3 = q3 = {l3:.6g} m; the slide "
                              f"reaches {lo:.6g} to {hi:.6g} m")
        q1 = math.atan2(py, px) - math.atan2(self.l2, -s) - self.theta
        q = np.array([math.remainder(q1, _TWO_PI), math.atan2(s, h), l3])
        _check_limits(self, q, x)
        return q


# -- seed 004: the planar 3-RRP parallel mechanism -------------------------------------------------
class Planar3RRPIK(IKSolver):
    """Planar 3-RRP mechanism: closed form, leg by leg (the robot model's
    :meth:`~robofmu.components.robots.parallel.Planar3RRP.ik`).

    Line i of the end effector lies at p_i = n_i . Z from O; its tip is Q_i = p_i n_i + w_i u_i
    with w_i = +/- sqrt(r^2 - p_i^2), so q_i = phi_i + atan2(p_i, w_i). ``branch`` gives the sign
    per leg: '+' the tip farther along the line (the larger slider extension; inside the disc
    |Z| < r the only positive one), "+++" the default (the specification's branch with positive
    slider extensions), the other seven combinations as options. Angles are wrapped to within pi
    of the ``home`` configuration. Unreachable when a line passes farther than r from O (every
    pose beyond 2r/sqrt(3), some orientations beyond r) or a joint leaves its limits.
    """

    kind = "planar_3rrp"
    parameters = (
        Parameter("branch", "String", "", "IK branch: one sign per leg, '+' the tip farther along "
                  "its line (the larger slider extension), '-' the other", "+++",
                  choices=tuple("".join(s) for s in ((a, b, c) for a in "+-" for b in "+-" for c in "+-"))),
    )

    def setup(self):
        robot = self.robot
        if getattr(robot, "kind", None) != "planar_3rrp" or not hasattr(robot, "ik_many"):
            raise ValueError(f"IK solver {self.kind!r}: robot {robot.description.name!r} is not a planar "
                             "3-RRP mechanism")
        self.branch = self.values["branch"]

    def position(self, x):
        try:
            q = self.robot.ik(x, self.branch)
        except ValueError as exc:
            raise Unreachable(str(exc)) from None
        _check_limits(self, q, x)
        return q

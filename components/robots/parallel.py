"""The planar 3-RRP parallel mechanism as a robot model in its actuated coordinates.

Mechanism (robots.md section 5; parameters in the robot's ``[mechanism]`` table). Leg i
(i = 1, 2, 3) has an actuated revolute joint at the origin O (angle q_i), a link of length r to
its tip Q_i = r (cos q_i, sin q_i), a passive revolute joint at Q_i and a massless slider by which
Q_i runs on a line of the end effector. The three lines pass through the end-effector point
Z = (x, y) at angles phi_i = theta + alpha_i, alpha = (pi/3, pi, -pi/3): three directions 120
degrees apart. Joint coordinates q = (q1, q2, q3) (rad), task coordinates x = (x, y, theta)
(m, m, rad). Notation, per leg::

    u_i = (cos phi_i, sin phi_i)      the line's direction
    n_i = (-sin phi_i, cos phi_i)     its normal (u_i turned by +90 degrees)
    c_i = cos(q_i - phi_i),  b_i = r sin(q_i - phi_i) = n_i . Q_i
    s_i = u_i . (Q_i - Z)             the slider extension (m): Q_i = Z + s_i u_i
    psi_i = phi_i - q_i               the passive revolute joint's angle (line relative to link)

The lines' unit vectors sum to zero, so do their normals, and sum_i n_i n_i^T = 3/2 I.

Forward kinematics (closed form, the Fermat-Torricelli construction: where every s_i > 0 the
three tips seen from Z lie along rays 120 degrees apart, Z is the Fermat-Torricelli point of the
triangle Q_1 Q_2 Q_3). The loop closures are n_i . Z = n_i . Q_i (three equations,
linear in Z). Their sum eliminates Z (sum_i n_i = 0) and leaves one equation in theta,
sum_i sin(q_i - alpha_i - theta) = 0, so that

    theta = atan2(sum_i sin(q_i - alpha_i), sum_i cos(q_i - alpha_i)),

the direction of V = sum_i exp(j (q_i - alpha_i)); then the consistent linear system gives

    Z = 2/3 sum_i b_i n_i.

theta is fixed by the loop closures only modulo pi (theta and theta + pi give the same three
lines); the atan2 picks the orientation with sum_i c_i = |V| > 0, i.e. a positive total slider
extension sum_i s_i = r |V| (the seed's convention, eq. 3: its K and L are 2r times the sine and
cosine sums above). The seed's eqs. 1-9 give the same pose but divide by its L = 2r sum_i
cos(q_i - alpha_i), which vanishes wherever theta = +/- pi/2 although nothing is singular there;
the form above divides by nothing but the constant 3/2. Where |V| <= :data:`DIRECT_SINGULARITY`
the pose is not determined by q at all (a direct singularity: every theta closes the loops, the
end effector moves with the actuators locked); :meth:`Planar3RRP.fk` raises ValueError there and
the vectorized :meth:`Planar3RRP.fk_many` returns NaN.

Inverse kinematics (closed form). Line i lies at signed distance p_i = n_i . Z from O; it meets
the circle of radius r iff |p_i| <= r, at the two tips Q_i = p_i n_i + w_i u_i,
w_i = +/- sqrt(r^2 - p_i^2) (w_i = u_i . Q_i = r c_i), so

    q_i = phi_i + atan2(p_i, w_i),    s_i = w_i - u_i . Z.

Branch '+' takes w_i >= 0: the tip farther along u_i, the larger slider extension. Inside the
disc |Z| < r it is the only positive one (the two extensions have the product |Z|^2 - r^2 < 0);
outside it the '+' tip is the continuation of that branch (its extension may be negative there:
with sliders restricted to s_i > 0 no pose outside the disc of radius r would be reachable, while
the specification's reachable disc, radius 2r/sqrt(3), needs the lines' full length). A branch is
a string of three signs, one per leg; "+++" is the default, the other seven are options. On
"+++" every c_i >= 0, so FK(IK(x)) = x (sum_i c_i > 0) and the branch has no direct singularity.
The seed's eqs. 10-21 return the tips -Q_i (q_i + pi), a configuration whose FK is
(-x, -y, theta + pi). IK angles are wrapped into [q_ref - pi, q_ref + pi), q_ref the ``home``
configuration by default, so that the IK of the home pose is home itself.

Reach: a position is reachable (at some theta) iff |Z| <= 2r/sqrt(3); every theta only within r.

Velocities. Differentiating n_i . (Q_i - Z) = 0 gives A xd = B qd with rows A_i = (n_i^T, s_i)
and B = diag(r c_i), so J = A^-1 B. A is solved in closed form: for A (v, w) = h,

    w = sum_i h_i / sum_i s_i,    v = 2/3 sum_i (h_i - s_i w) n_i,

hence the theta row of J is c_j / sum_i c_i and det J = r^2 prod_i c_i / (sin(alpha_2 - alpha_1)
sum_i c_i): an inverse (serial) singularity where a link is perpendicular to its line (c_i = 0,
the line tangent to the circle: q_i moves nothing to first order), a direct one where
sum_i c_i = 0. Differentiating once more (exact, analytic; no finite differences):
A xdd = B qdd + h with h_i = -b_i qd_i^2 + 2 b_i thetad qd_i + 2 thetad u_i . Zd, so
Jdot qd = A^-1 h, and Jdot = A^-1 (Bdot - Adot J) with Bdot = diag(-b_i (qd_i - thetad)) and
Adot rows (-thetad u_i^T, sd_i), sd_i = -b_i qd_i - u_i . Zd.

Dynamics (the projected, minimal-coordinate form; Kane-like). Links rotate about O (centre of
mass at link_com r, moment of inertia I_O = I_c + m (link_com r)^2 about O), the end-effector body
at Z (mass m_E, moment of inertia I_E), the sliders massless. The kinetic energy

    KE = 1/2 sum_i I_O qd_i^2 + 1/2 xd^T M_E xd,   M_E = diag(m_E, m_E, I_E),  xd = J qd,

gives M(q) = I_O 1 + J^T M_E J and, projecting the end effector's Newton-Euler equations with J^T
(planar: M_E constant, no gyroscopic term), N(q, qd) = J^T M_E Jdot qd, C(q, qd) = J^T M_E Jdot
(Mdot - 2C = Jdot^T M_E J - J^T M_E Jdot is skew) and g = 0: the mechanism moves in a horizontal
plane and gravity (along z) does no work. An external wrench f_ext = (Fx, Fy, Mz) on the end
effector (at Z, world axes) acts as tau_ext = J^T f_ext (:meth:`Planar3RRP.wrench_torque`, and the
optional ``f_ext`` argument of the dynamics methods):

    M(q) qdd + N(q, qd) = tau + J(q)^T f_ext.

The vectorized ``*_many`` methods take arrays of shape (..., 3) (many configurations, e.g. a
joint grid; chunk a 200^3 grid to bound memory) and return NaN where undefined; the scalar
interface methods are thin wrappers on the same code.
"""
from __future__ import annotations

import itertools
import math
import operator

import numpy as np
from scipy.linalg.lapack import dgesv as gesv

from .description import DescriptionError, RobotDescription
from .model import RobotModel, derivative_unit

__all__ = ["Planar3RRP", "BRANCHES", "DIRECT_SINGULARITY"]

#: |sum_i exp(j (q_i - alpha_i))| (at most 3) at or below this: a direct singularity, no pose.
DIRECT_SINGULARITY = 1e-12
#: A line may pass this much (relative to r) beyond the circle and still touch it (round-off).
REACH_TOLERANCE = 1e-12
#: IK branches: one sign per leg, '+' the tip farther along the line (larger slider extension).
BRANCHES = tuple("".join(signs) for signs in itertools.product("+-", repeat=3))
#: The name of the mechanism's task body (``[task] frame``, ``[payload] frame``).
TASK_FRAME = "end_effector"

_TWO_PI = 2.0 * math.pi


class Planar3RRP(RobotModel):
    """The planar 3-RRP mechanism (``[mechanism] kind = "planar_3rrp"``) in actuated coordinates.

    Parameters
    ----------
    description : RobotDescription
        With a :class:`~robofmu.components.robots.description.Planar3RRPMechanism`.
    gravity : float, optional
        Magnitude (m/s^2); stored for the interface, it has no effect (gravity acts along z,
        perpendicular to the plane of motion; a description whose gravity direction has a
        component in the plane is refused).

    Attributes (beyond :class:`RobotModel`)
    ----------
    r : float
        Link length (m).
    alpha : ndarray, shape (3,)
        Line angle offsets (rad).
    link_inertia_O : float
        Each link's moment of inertia about O (kg m^2).
    payload : float
        Point mass (kg) carried at Z (:meth:`set_payload`).
    """

    kind = "planar_3rrp"

    def __init__(self, description: RobotDescription, gravity: float | None = None):
        mech = description.mechanism
        path = description.path
        if mech is None or mech.kind != self.kind:
            raise ValueError(f"{path}: mechanism: robot {description.name!r} is not a {self.kind!r} mechanism")
        self.description = description
        self.mechanism = mech
        self.n = self.m = 3
        self.prismatic = [False, False, False]
        self.joint_names = ["leg1", "leg2", "leg3"]
        self.r = float(mech.r)
        self.alpha = np.array(mech.line_offsets, dtype=float)
        self._sin_offsets = math.sin(self.alpha[1] - self.alpha[0])      # +/- sqrt(3)/2
        self._cos_alpha, self._sin_alpha = np.cos(self.alpha), np.sin(self.alpha)
        self._offsets = tuple(tuple(v.tolist()) for v in (self.alpha, self._cos_alpha, self._sin_alpha))
        self.link_inertia_O = float(mech.link_inertia_about_origin)
        self._ee_mass, self._ee_inertia = float(mech.ee_mass), float(mech.ee_inertia)
        self._lower = np.array(mech.position_lower, dtype=float)
        self._upper = np.array(mech.position_upper, dtype=float)
        self._velocity = np.array(mech.velocity_limits, dtype=float)
        home = description.configuration("home")
        if len(home) != self.n:
            raise DescriptionError(path, "configurations.home", f"needs {self.n} joint values (the mechanism "
                                   f"has {self.n} actuated joints), got {len(home)}")
        if len(description.task.coordinates) != self.m:
            raise DescriptionError(path, "task.coordinates", f"needs {self.m} names (the pose x, y, theta), "
                                   f"got {list(description.task.coordinates)}")
        if description.task.frame != TASK_FRAME:
            raise DescriptionError(path, "task.frame", f"the mechanism's task body is {TASK_FRAME!r}, "
                                   f"got {description.task.frame!r}")
        direction = description.gravity_direction
        if abs(direction[0]) > 1e-12 or abs(direction[1]) > 1e-12:
            raise DescriptionError(path, "gravity.direction", "the mechanism moves in the horizontal x-y "
                                   f"plane: gravity must act along z, got {list(direction)}")
        if description.payload is not None and description.payload.frame != TASK_FRAME:
            raise DescriptionError(path, "payload.frame", f"a payload rides on {TASK_FRAME!r}, got "
                                   f"{description.payload.frame!r}")
        if not np.all((self._lower <= home) & (np.asarray(home) <= self._upper)):
            raise DescriptionError(path, "configurations.home", f"q = {list(home)} lies outside the position "
                                   f"limits {self._lower.tolist()} to {self._upper.tolist()}")
        if not self._direct_measure(np.asarray(home)) > DIRECT_SINGULARITY:
            raise DescriptionError(path, "configurations.home", f"q = {list(home)} is a direct singularity "
                                   "(no pose)")
        self._home = list(home)
        self._last = (None, None)          # the last configuration _checked and its legs
        self.payload = 0.0
        self._inertia = tuple(self.end_effector_inertia.tolist())    # diag(M_E), kept with the payload
        self.set_gravity(description.gravity if gravity is None else gravity)

    # -- units, limits, parameters ----------------------------------------------------------------
    def task_units(self, order: int = 0) -> list[str]:
        return [derivative_unit("m", order), derivative_unit("m", order), derivative_unit("rad", order)]

    def position_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """The ``[mechanism]`` position limits (rad), -inf / +inf where there are none."""
        return self._lower.copy(), self._upper.copy()

    def velocity_limits(self) -> np.ndarray:
        """The ``[mechanism]`` velocity limits (rad/s)."""
        return self._velocity.copy()

    def set_gravity(self, magnitude: float) -> None:
        """Store the magnitude (m/s^2); no effect: gravity is perpendicular to the plane of motion."""
        self.gravity = float(magnitude)

    def set_payload(self, mass: float) -> None:
        """Carry a point mass (kg) at Z (it adds to the end effector's mass, not to its inertia);
        0 removes it. Only where the description has a ``[payload]``."""
        mass = float(mass)
        if mass == self.payload:
            return
        if self.description.payload is None:
            raise ValueError(f"robot {self.description.name!r} describes no payload frame")
        if not (math.isfinite(mass) and mass >= 0.0):
            raise ValueError(f"payload mass must be finite and >= 0 kg, got {mass}")
        self.payload = mass
        self._inertia = tuple(self.end_effector_inertia.tolist())

    def independent_dynamics(self, **baumgarte):
        """A second, independent formulation of this mechanism's dynamics, for cross-checks:
        Lagrange's equations on the spanning tree in maximal coordinates (q, x, y, theta) with
        loop-closure multipliers and Baumgarte stabilization
        (:class:`~robofmu.components.robots.parallel_lagrange.LagrangeRRP3`), built from the same
        description's ``[mechanism]`` numbers and the current payload; it shares no code with this
        model. ``baumgarte`` may give ``alpha`` and ``beta`` (1/s)."""
        from .parallel_lagrange import LagrangeRRP3

        return LagrangeRRP3.from_mechanism(self.mechanism, payload=self.payload, **baumgarte)

    @property
    def end_effector_inertia(self) -> np.ndarray:
        """diag(M_E) = (m_E, m_E, I_E) with the payload, shape (3,)."""
        m = self._ee_mass + self.payload
        return np.array([m, m, self._ee_inertia])

    # -- geometry, leg by leg ----------------------------------------------------------------------
    # The kinematics is written once, leg by leg: a per-leg quantity is a sequence of three values,
    # each a float (one configuration: plain float arithmetic, math's functions) or an array over
    # the configurations (the *_many methods: each leg's values one contiguous array, NumPy's
    # functions). Sums over the legs are written out in leg order (what .sum over a leg axis does).
    def _direct_measure(self, q: np.ndarray) -> np.ndarray:
        """|V| = |sum_i exp(j (q_i - alpha_i))| = sum_i c_i for q (..., 3): 0 at a direct
        singularity, at most 3."""
        d = np.moveaxis(np.asarray(q, dtype=float), -1, 0) - self._legwise(self.alpha, np.ndim(q) - 1)
        return np.hypot(np.sin(d).sum(0), np.cos(d).sum(0))

    def _pose(self, q):
        """(sd, cd, V, S, C, theta, x, y) at the legs' angles q (three values): sd, cd = sin,
        cos(q_i - alpha_i) (the only trigonometric evaluations), S, C their sums, V = hypot(S, C);
        NaN where V is at or below :data:`DIRECT_SINGULARITY`.

        With cos, sin theta = C/V, S/V the sums of Z = 2/3 sum_i b_i n_i are quadratic forms in
        (C, S) over V^2, with the coefficients A1, A2 = sum_i sd_i (cos, sin) alpha_i and
        B1, B2 = sum_i cd_i (cos, sin) alpha_i."""
        f = _functions(q[0])
        (a1, a2, a3), (ca1, ca2, ca3), (sa1, sa2, sa3) = self._offsets
        d1, d2, d3 = q[0] - a1, q[1] - a2, q[2] - a3
        sd = (f.sin(d1), f.sin(d2), f.sin(d3))
        cd = (f.cos(d1), f.cos(d2), f.cos(d3))
        S, C = sd[0] + sd[1] + sd[2], cd[0] + cd[1] + cd[2]
        A1, A2 = sd[0] * ca1 + sd[1] * ca2 + sd[2] * ca3, sd[0] * sa1 + sd[1] * sa2 + sd[2] * sa3
        B1, B2 = cd[0] * ca1 + cd[1] * ca2 + cd[2] * ca3, cd[0] * sa1 + cd[1] * sa2 + cd[2] * sa3
        V2 = S * S + C * C
        V2 = f.singular_to_nan(V2)
        CS, CC, SS = C * S, C * C, S * S
        k = (2.0 * self.r / 3.0) / V2
        x = -k * (CS * (A1 - B2) + CC * A2 - SS * B1)
        y = k * (CC * A1 - CS * (A2 + B1) + SS * B2)
        theta = f.atan2(S, C) + 0.0 * V2                 # NaN where singular
        return sd, cd, f.sqrt(V2), S, C, theta, x, y

    def _directions(self, V, S, C):
        """(cp, sp): cos, sin phi_i = cos, sin(theta + alpha_i), three values each."""
        _, (ca1, ca2, ca3), (sa1, sa2, sa3) = self._offsets
        ct, st = C / V, S / V
        return ((ct * ca1 - st * sa1, ct * ca2 - st * sa2, ct * ca3 - st * sa3),
                (st * ca1 + ct * sa1, st * ca2 + ct * sa2, st * ca3 + ct * sa3))

    def _legs(self, q) -> "_Legs":
        """Everything the kinematics needs at the legs' angles q (see the module docstring's notation)."""
        sd, cd, V, S, C, theta, x, y = self._pose(q)
        cp, sp = self._directions(V, S, C)               # u = (cp, sp), n = (-sp, cp)
        ct, st = C / V, S / V
        r = self.r
        # written out leg by leg (a comprehension costs more than the arithmetic of one configuration)
        c = (cd[0] * ct + sd[0] * st, cd[1] * ct + sd[1] * st, cd[2] * ct + sd[2] * st)   # cos(q_i - phi_i)
        b = (r * (sd[0] * ct - cd[0] * st), r * (sd[1] * ct - cd[1] * st),
             r * (sd[2] * ct - cd[2] * st))                                           # r sin(q_i - phi_i)
        s = (r * c[0] - (cp[0] * x + sp[0] * y), r * c[1] - (cp[1] * x + sp[1] * y),
             r * c[2] - (cp[2] * x + sp[2] * y))
        return _Legs(theta, V, x, y, cp, sp, c, b, s)

    def _jacobian_from(self, V, x, y, cp, sp, c) -> list:
        """J = A^-1 B written out, rows (x, y, theta) of three columns each: theta row
        gamma_j = c_j / sum_i c_i (sum_i c_i = V), Z rows 2/3 (r c_j n_j - gamma_j sum_i s_i n_i),
        where sum_i s_i n_i = r sum_i c_i n_i - 3/2 (-y, x) (sum_i n_i u_i^T = 3/2 [[0, -1], [1, 0]])."""
        r = self.r
        g1, g2, g3 = c[0] / V, c[1] / V, c[2] / V
        k = 2.0 * r / 3.0
        rc1, rc2, rc3 = k * c[0], k * c[1], k * c[2]
        snx = (2.0 / 3.0) * (-r * (c[0] * sp[0] + c[1] * sp[1] + c[2] * sp[2]) + 1.5 * y)
        sny = (2.0 / 3.0) * (r * (c[0] * cp[0] + c[1] * cp[1] + c[2] * cp[2]) - 1.5 * x)
        return [[-rc1 * sp[0] - g1 * snx, -rc2 * sp[1] - g2 * snx, -rc3 * sp[2] - g3 * snx],
                [rc1 * cp[0] - g1 * sny, rc2 * cp[1] - g2 * sny, rc3 * cp[2] - g3 * sny],
                [g1, g2, g3]]

    def _jacobian(self, k: "_Legs") -> list:
        return self._jacobian_from(k.V, k.x, k.y, k.cp, k.sp, k.c)

    @staticmethod
    def _solve_a(k: "_Legs", h) -> list:
        """A^-1 h for one right-hand side h (three values, one per leg), A rows (n_i^T, s_i);
        returns (x, y, theta).

        Summing the rows (sum_i n_i = 0) gives w = sum_i h_i / sum_i s_i; then n_i . v = h_i - s_i w
        is consistent and v = 2/3 sum_i (h_i - s_i w) n_i (sum_i n_i n_i^T = 3/2 I)."""
        s, cp, sp = k.s, k.cp, k.sp
        w = (h[0] + h[1] + h[2]) / (s[0] + s[1] + s[2])
        hp1, hp2, hp3 = h[0] - s[0] * w, h[1] - s[1] * w, h[2] - s[2] * w
        return [-(2.0 / 3.0) * (hp1 * sp[0] + hp2 * sp[1] + hp3 * sp[2]),
                (2.0 / 3.0) * (hp1 * cp[0] + hp2 * cp[1] + hp3 * cp[2]), w]

    @staticmethod
    def _times(J, v) -> list:
        """J v for J as rows of three values and v three values."""
        (a, b, c), (d, e, f), (g, h, i) = J
        return [a * v[0] + b * v[1] + c * v[2], d * v[0] + e * v[1] + f * v[2], g * v[0] + h * v[1] + i * v[2]]

    def _jdot_qdot(self, k: "_Legs", J, qd) -> list:
        """Jdot qd = A^-1 h, h_i = -b_i qd_i^2 + 2 b_i thetad qd_i + 2 thetad u_i . Zd."""
        zx, zy, thd = self._times(J, qd)
        b, cp, sp = k.b, k.cp, k.sp
        h = (-b[0] * qd[0] * qd[0] + 2.0 * b[0] * thd * qd[0] + 2.0 * thd * (cp[0] * zx + sp[0] * zy),
             -b[1] * qd[1] * qd[1] + 2.0 * b[1] * thd * qd[1] + 2.0 * thd * (cp[1] * zx + sp[1] * zy),
             -b[2] * qd[2] * qd[2] + 2.0 * b[2] * thd * qd[2] + 2.0 * thd * (cp[2] * zx + sp[2] * zy))
        return self._solve_a(k, h)

    def _jacobian_dot(self, k: "_Legs", J, qd) -> list:
        """Jdot = A^-1 (Bdot - Adot J), Bdot = diag(-b_i (qd_i - thetad)), Adot rows
        (-thetad u_i^T, sd_i), sd_i = -b_i qd_i - u_i . Zd; rows (x, y, theta) of three columns."""
        zx, zy, thd = self._times(J, qd)
        b, cp, sp = k.b, k.cp, k.sp
        bdot = [-b[i] * (qd[i] - thd) for i in range(3)]
        sdot = [-b[i] * qd[i] - (cp[i] * zx + sp[i] * zy) for i in range(3)]
        columns = []
        for j in range(3):
            adot_j = [-thd * (cp[i] * J[0][j] + sp[i] * J[1][j]) + sdot[i] * J[2][j] for i in range(3)]
            columns.append(self._solve_a(k, [(1.0 if i == j else 0.0) * bdot[i] - adot_j[i] for i in range(3)]))
        return [[columns[j][row] for j in range(3)] for row in range(3)]

    def _legwise(self, v: np.ndarray, nd: int) -> np.ndarray:
        """A per-leg constant (3,) shaped (3, 1, ...) for ``nd`` configuration axes."""
        return v.reshape((3,) + (1,) * nd)

    # -- vectorized kinematics: shapes (..., 3) in, (..., 3) or (..., 3, 3) out ---------------------
    @staticmethod
    def _legs_first(a) -> np.ndarray:
        a = np.asarray(a, dtype=float)
        if a.shape[-1:] != (3,):
            raise ValueError(f"needs arrays of shape (..., 3), got {a.shape}")
        return np.ascontiguousarray(np.moveaxis(a, -1, 0))   # each leg's values contiguous

    @staticmethod
    def _vector_last(a: np.ndarray) -> np.ndarray:
        return np.moveaxis(a, 0, -1)

    @staticmethod
    def _matrix_last(a: np.ndarray) -> np.ndarray:
        return np.moveaxis(a, (0, 1), (-2, -1))

    def fk_many(self, q) -> np.ndarray:
        """Poses (x, y, theta) of configurations q, shape (..., 3) -> (..., 3); NaN at a direct
        singularity. theta in (-pi, pi]."""
        with np.errstate(invalid="ignore", divide="ignore"):
            _, _, _, _, _, theta, x, y = self._pose(self._legs_first(q))
        return np.stack(np.broadcast_arrays(x, y, theta), axis=-1)

    def jacobian_many(self, q) -> np.ndarray:
        """J(q), shape (..., 3) -> (..., 3, 3); NaN at a direct singularity."""
        with np.errstate(invalid="ignore", divide="ignore"):
            sd, cd, V, S, C, _, x, y = self._pose(self._legs_first(q))
            cp, sp = self._directions(V, S, C)
            return self._matrix_last(_array(self._jacobian_from(V, x, y, cp, sp, _link_cosines(sd, cd, V, S, C))))

    def jdot_qdot_many(self, q, qd) -> np.ndarray:
        """Jdot(q, qd) qd, shapes (..., 3) -> (..., 3)."""
        qdT = self._legs_first(qd)
        with np.errstate(invalid="ignore", divide="ignore"):
            k = self._legs(self._legs_first(q))
            return self._vector_last(_array(self._jdot_qdot(k, self._jacobian(k), qdT)))

    def jacobian_dot_many(self, q, qd) -> np.ndarray:
        """Jdot(q, qd) = dJ/dt along qd, shapes (..., 3) -> (..., 3, 3)."""
        qdT = self._legs_first(qd)
        with np.errstate(invalid="ignore", divide="ignore"):
            k = self._legs(self._legs_first(q))
            return self._matrix_last(_array(self._jacobian_dot(k, self._jacobian(k), qdT)))

    def jacobian_determinant_many(self, q) -> np.ndarray:
        """det J = r^2 prod_i c_i / (sin(alpha_2 - alpha_1) sum_i c_i), shape (..., 3) -> (...):
        0 at an inverse singularity (c_i = 0), NaN at a direct one."""
        with np.errstate(invalid="ignore", divide="ignore"):
            sd, cd, V, S, C, _, _, _ = self._pose(self._legs_first(q))
            c = _array(_link_cosines(sd, cd, V, S, C))
            return self.r ** 2 * c.prod(0) / (self._sin_offsets * V)

    def singular_values_many(self, q, theta_scale: float = 1.0, exact: bool = False) -> np.ndarray:
        """Singular values of J (descending), shape (..., 3) -> (..., 3), with the theta row
        multiplied by ``theta_scale`` (m: a characteristic length makes every row m/rad); NaN at a
        direct singularity.

        ``exact``: LAPACK's SVD per configuration (slow over millions). Default: closed form, the
        largest eigenvalue of J^T J (trigonometric solution of the 3 x 3 symmetric eigenproblem)
        for sigma_max, the same of J^-T J^-1 with J^-1 = B^-1 A (closed form) for sigma_min, and
        sigma_mid = |det J| / (sigma_max sigma_min); it agrees with LAPACK to about 1e-11
        relative over random configurations (characteristic-polynomial roots can lose accuracy
        where two singular values nearly coincide; the tests bound the difference by 1e-7);
        sigma_min = 0 where a link is perpendicular to its line.
        """
        L = float(theta_scale)
        qT = self._legs_first(q)
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            k = self._legs(qT)
            J = _array(self._jacobian(k))
            J[2] *= L
            if exact:
                Jm = self._matrix_last(J)
                out = np.full(Jm.shape[:-1], np.nan)
                finite = np.isfinite(Jm).all(axis=(-2, -1))
                out[finite] = np.linalg.svd(Jm[finite], compute_uv=False)
                return out
            top = np.sqrt(_largest_eigenvalue(_gram(J)))
            # J^-1 = B^-1 A: row i (n_i^T, s_i / L) / (r c_i)
            c, cp, sp, s = (_array(v) for v in (k.c, k.cp, k.sp, k.s))
            rc = self.r * c
            inverse = np.stack([-sp / rc, cp / rc, s / (L * rc)], axis=1)          # (leg i, column, ...)
            inv_top = np.sqrt(_largest_eigenvalue(_gram(inverse)))
            low = np.where(np.isfinite(inv_top) & (c != 0.0).all(0), 1.0 / inv_top, 0.0) + 0.0 * top
            det = np.abs(L * self.r ** 2 * c.prod(0) / (self._sin_offsets * k.V))
            trace = (J * J).sum((0, 1))
            mid = np.where(low > 0.0, det / (top * low), np.sqrt(np.clip(trace - top * top, 0.0, None)))
            return np.stack([top, mid, low], axis=-1)

    def condition_number_many(self, q, theta_scale: float = 1.0, exact: bool = False) -> np.ndarray:
        """cond(J) = sigma_max / sigma_min, shape (..., 3) -> (...); inf at an inverse singularity,
        NaN at a direct one (see :meth:`singular_values_many`)."""
        sv = self.singular_values_many(q, theta_scale, exact)
        with np.errstate(invalid="ignore", divide="ignore"):
            return sv[..., 0] / sv[..., 2]

    def line_distances_many(self, pose) -> np.ndarray:
        """Signed distances p_i = n_i . Z (m) of the three lines from O, shape (..., 3) -> (..., 3):
        the pose is reachable iff every |p_i| <= r."""
        x, y, th = self._legs_first(pose)
        phi = th + self._legwise(self.alpha, np.ndim(th))
        return self._vector_last(-x * np.sin(phi) + y * np.cos(phi))

    def ik_many(self, pose, branch: str = "+++", near=None) -> np.ndarray:
        """Joint angles for poses, shape (..., 3) -> (..., 3); NaN rows where unreachable.

        ``branch``: one sign per leg (:data:`BRANCHES`); angles wrapped into
        [near - pi, near + pi), ``near`` (3,) or (..., 3), by default the home configuration.
        """
        ref = self._legs_first(self.configuration("home") if near is None else near)
        return self._vector_last(_array(self._ik(self._legs_first(pose), _branch_signs(branch), ref)))

    def _ik(self, pose, signs, near) -> list:
        """The legs' angles (three values, NaN where unreachable) for pose (x, y, theta) on the
        branch of ``signs`` (three of +1 / -1), wrapped into [near_i - pi, near_i + pi)."""
        f = _functions(pose[2])
        x, y, th = pose
        reach, q = True, []
        for alpha, sign, ref in zip(self._offsets[0], signs, near):
            phi = th + alpha
            cp, sp = f.cos(phi), f.sin(phi)
            ratio = (-x * sp + y * cp) / self.r                           # p_i / r
            reach = reach & (abs(ratio) <= 1.0 + REACH_TOLERANCE)
            w = sign * f.sqrt(f.clip(1.0 - ratio * ratio, 0.0, None))
            angle = phi + f.atan2(f.clip(ratio, -1.0, 1.0), w)
            q.append(ref + f.mod(angle - ref + math.pi, _TWO_PI) - math.pi)
        return [f.where(reach, angle, math.nan) for angle in q]

    def slider_extensions_many(self, q) -> np.ndarray:
        """s_i = u_i . (Q_i - Z) (m), shape (..., 3) -> (..., 3)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return self._vector_last(_array(self._legs(self._legs_first(q)).s))

    def passive_joints(self, q, qd=None) -> dict[str, np.ndarray]:
        """The passive joints (vectorized, shapes (..., 3)): slider extensions ``s`` (m) and the
        passive revolute angles ``psi`` = phi_i - q_i (rad, the line relative to the link, in
        [-pi, pi)), and with ``qd`` their rates ``sd`` = u_i . (Qd_i - Zd) (m/s) and
        ``psid`` = thetad - qd_i (rad/s)."""
        qT = self._legs_first(q)
        with np.errstate(invalid="ignore", divide="ignore"):
            k = self._legs(qT)
            b, c, cp, sp = (_array(v) for v in (k.b, k.c, k.cp, k.sp))
            out = {"s": _array(k.s), "psi": -np.arctan2(b, self.r * c)}
            if qd is not None:
                qdT = self._legs_first(qd)
                zx, zy, thd = self._times(self._jacobian(k), qdT)
                out["sd"] = -b * qdT - (cp * zx + sp * zy)
                out["psid"] = thd - qdT
        return {name: self._vector_last(value) for name, value in out.items()}

    # -- the interface: kinematics ------------------------------------------------------------------
    def _checked(self, q) -> "_Legs":
        """The legs at one configuration q (3,), in float arithmetic; ValueError if q is not
        finite or a direct singularity."""
        q = np.asarray(q, dtype=float)
        if q.shape != (3,):
            raise ValueError(f"q: needs 3 joint angles, got shape {q.shape}")
        angles = q.tolist()
        if angles == self._last[0]:          # the same configuration again (IK: J, then Jdot qd)
            return self._last[1]
        if not math.isfinite(angles[0] + angles[1] + angles[2]) and not all(map(math.isfinite, angles)):
            raise ValueError(f"q = {angles} rad is not finite")
        k = self._legs(angles)
        if not math.isfinite(k.theta):
            raise ValueError(f"q = {q.tolist()} rad is a direct singularity of the {self.kind} mechanism "
                             f"(|sum_i exp(j (q_i - alpha_i))| = {float(self._direct_measure(q)):.3g}): "
                             "the pose is not determined by q")
        self._last = (angles, k)
        return k

    def fk(self, q: np.ndarray) -> np.ndarray:
        """Pose (x, y, theta), theta in (-pi, pi]; ValueError at a direct singularity."""
        k = self._checked(q)
        return np.array([k.x, k.y, k.theta])

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        return np.array(self._jacobian(self._checked(q)))

    def jdot_qdot(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        k = self._checked(q)
        return np.array(self._jdot_qdot(k, self._jacobian(k), _rates(qd)))

    def jacobian_dot(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """dJ/dt along qd, shape (3, 3)."""
        k = self._checked(q)
        return np.array(self._jacobian_dot(k, self._jacobian(k), _rates(qd)))

    def jacobian_determinant(self, q: np.ndarray) -> float:
        """det J(q): 0 at an inverse singularity, unbounded near a direct one."""
        self._checked(q)
        return float(self.jacobian_determinant_many(q))

    def condition_number(self, q: np.ndarray, theta_scale: float = 1.0) -> float:
        """cond(J(q)) (2-norm, LAPACK's SVD), theta row scaled by ``theta_scale``: the singularity
        measure, inf at an inverse singularity."""
        self._checked(q)
        return float(self.condition_number_many(q, theta_scale, exact=True))

    def ik(self, pose, branch: str = "+++", near=None) -> np.ndarray:
        """Joint angles placing the end effector at ``pose`` on ``branch`` (see :meth:`ik_many`);
        ValueError naming the leg whose line misses the circle."""
        pose = np.asarray(pose, dtype=float)
        values = pose.tolist()
        if pose.shape != (3,) or not all(map(math.isfinite, values)):
            raise ValueError(f"pose: needs 3 finite values (x, y, theta), got {values}")
        ref = self._home if near is None else _three(near, "near", "joint angles")
        q = np.array(self._ik(values, _branch_signs(branch), ref))
        if not math.isfinite(q.dot(q)):
            p = self.line_distances_many(pose)
            i = int(np.argmax(np.abs(p)))
            x, y, th = pose.tolist()
            raise ValueError(
                f"pose ({x:.6g} m, {y:.6g} m, {th:.6g} rad) is out of reach: line {i + 1} passes "
                f"{abs(p[i]):.6g} m from O, beyond r = {self.r:g} m (positions within 2r/sqrt(3) = "
                f"{2.0 * self.r / math.sqrt(3.0):.6g} m of O are reachable at some orientations, "
                f"within r at every orientation; this one is {math.hypot(x, y):.6g} m away)")
        return q

    # -- the interface: dynamics --------------------------------------------------------------------
    # At one configuration in float arithmetic as the kinematics above: J's columns j are the
    # joints, its rows i the task coordinates, M_E = diag(w_1, w_2, w_3).
    def _terms(self, q, qd):
        """J (rows of three floats) and N = J^T M_E Jdot qd (three floats) at one configuration."""
        k = self._checked(q)
        J = self._jacobian(k)
        a1, a2, a3 = self._jdot_qdot(k, J, _rates(qd))
        w1, w2, w3 = self._inertia
        return J, _transposed_times(J, (w1 * a1, w2 * a2, w3 * a3))

    def _mass(self, J) -> np.ndarray:
        """M = I_O 1 + J^T M_E J (3, 3), exactly symmetric, from J as rows of three floats:
        M_jk = I_O delta_jk + sum_i w_i J_ij J_ik."""
        w1, w2, w3 = self._inertia
        i_o = self.link_inertia_O
        (a, b, c), (d, e, f), (g, h, i) = J
        m12 = w1 * a * b + w2 * d * e + w3 * g * h
        m13 = w1 * a * c + w2 * d * f + w3 * g * i
        m23 = w1 * b * c + w2 * e * f + w3 * h * i
        return np.array([[i_o + (w1 * a * a + w2 * d * d + w3 * g * g), m12, m13],
                         [m12, i_o + (w1 * b * b + w2 * e * e + w3 * h * h), m23],
                         [m13, m23, i_o + (w1 * c * c + w2 * f * f + w3 * i * i)]])

    def wrench_torque(self, q: np.ndarray, f_ext) -> np.ndarray:
        """Joint torques (N m) equivalent to the wrench f_ext = (Fx, Fy, Mz) (N, N, N m) on the end
        effector at Z, world axes: J(q)^T f_ext."""
        return np.array(_transposed_times(self._jacobian(self._checked(q)), _wrench(f_ext)))

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """M(q) = I_O 1 + J^T M_E J."""
        return self._mass(self._jacobian(self._checked(q)))

    def coriolis_matrix(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """C(q, qd) = J^T M_E Jdot (C qd = N; Mdot - 2C skew)."""
        J = self.jacobian(q)
        return J.T @ (self.end_effector_inertia[:, None] * self.jacobian_dot(q, qd))

    def gravity_torque(self, q: np.ndarray) -> np.ndarray:
        """Zero: gravity is perpendicular to the plane of motion."""
        return np.zeros(3)

    def nonlinear_effects(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """N(q, qd) = J^T M_E Jdot qd (g = 0)."""
        return np.array(self._terms(q, qd)[1])

    def forward_dynamics(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray,
                         f_ext: np.ndarray | None = None) -> np.ndarray:
        """qdd = M^-1 (tau + J^T f_ext - N); ``f_ext`` = (Fx, Fy, Mz) on the end effector (default 0)."""
        J, n = self._terms(q, qd)
        rhs = np.asarray(tau, dtype=float) - n
        if f_ext is not None:
            rhs += _transposed_times(J, _wrench(f_ext))
        # LAPACK gesv, as numpy.linalg.solve calls it (the same result) without its overhead;
        # M is positive definite (I_O > 0), never singular
        return gesv(self._mass(J), rhs)[2]

    def inverse_dynamics(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
                         f_ext: np.ndarray | None = None) -> np.ndarray:
        """tau = M qdd + N - J^T f_ext."""
        J, n = self._terms(q, qd)
        tau = self._mass(J) @ np.asarray(qdd, dtype=float) + n
        if f_ext is not None:
            tau -= _transposed_times(J, _wrench(f_ext))
        return tau

    def kinetic_energy(self, q: np.ndarray, qd: np.ndarray) -> float:
        """1/2 sum_i I_O qd_i^2 + 1/2 xd^T M_E xd (J)."""
        qd = np.asarray(qd, dtype=float)
        xd = self.jacobian(q) @ qd
        return float(0.5 * self.link_inertia_O * qd @ qd + 0.5 * xd @ (self.end_effector_inertia * xd))

    def potential_energy(self, q: np.ndarray) -> float:
        """Zero: gravity does no work in the horizontal plane."""
        return 0.0


    # -- drawing --------------------------------------------------------------------------------
    def sketch(self, q: np.ndarray) -> dict[str, list[np.ndarray]]:
        """The mechanism at ``q`` as plane polylines (m), for figures: ``links`` (O -> Q_i, the
        actuated links), ``passive`` (Q_i -> Z, each leg's slider line between its tip and the end
        effector) and ``end_effector`` (Z and a tick of length r / 4 along theta). Each polyline
        has shape (k, 2)."""
        x, y, theta = self.fk(q)
        z = np.array([x, y])
        tips = self.r * np.stack([np.cos(q), np.sin(q)], axis=1)
        return {"links": [np.array([[0.0, 0.0], tip]) for tip in tips],
                "passive": [np.array([tip, z]) for tip in tips],
                "end_effector": [np.array([z, z + 0.25 * self.r * np.array([np.cos(theta), np.sin(theta)])])]}

class _Legs:
    """The per-leg quantities at one or many configurations (see the module docstring)."""

    __slots__ = ("theta", "V", "x", "y", "cp", "sp", "c", "b", "s")

    def __init__(self, theta, V, x, y, cp, sp, c, b, s):
        self.theta, self.V, self.x, self.y = theta, V, x, y
        self.cp, self.sp, self.c, self.b, self.s = cp, sp, c, b, s


class _FloatFunctions:
    """The functions :meth:`Planar3RRP._pose` needs, for one configuration (floats)."""

    sin, cos, atan2, sqrt = math.sin, math.cos, math.atan2, math.sqrt
    mod = operator.mod                                   # Python's float % is numpy.mod's

    @staticmethod
    def singular_to_nan(v2: float) -> float:
        return v2 if v2 > DIRECT_SINGULARITY ** 2 else math.nan

    @staticmethod
    def clip(v: float, low: float, high: float | None) -> float:
        v = v if not v < low else low
        return v if high is None or not v > high else high

    @staticmethod
    def where(condition: bool, a: float, b: float) -> float:
        return a if condition else b


class _ArrayFunctions:
    """The same for arrays over many configurations (NumPy)."""

    sin, cos, atan2, sqrt, mod, clip, where = np.sin, np.cos, np.arctan2, np.sqrt, np.mod, np.clip, np.where

    @staticmethod
    def singular_to_nan(v2: np.ndarray) -> np.ndarray:
        return np.where(v2 > DIRECT_SINGULARITY ** 2, v2, np.nan)


def _functions(value):
    """:class:`_FloatFunctions` for a float (NumPy's float64 is one), else :class:`_ArrayFunctions`."""
    return _FloatFunctions if isinstance(value, float) else _ArrayFunctions


def _array(values) -> np.ndarray:
    """Per-leg (or nested row) values as one array, the legs (rows) on axis 0."""
    return np.array(values, dtype=float) if not isinstance(values, np.ndarray) else values


def _link_cosines(sd, cd, V, S, C) -> list:
    """c_i = cos(q_i - phi_i) = (cd_i C + sd_i S) / V (:meth:`Planar3RRP._pose`) of many
    configurations (arrays, one division per leg); one configuration's, in floats, are
    :meth:`Planar3RRP._legs`'."""
    return [(cd[i] * C + sd[i] * S) / V for i in range(3)]


def _transposed_times(J, v) -> tuple:
    """J^T v for J as rows of three values and v three values."""
    (a, b, c), (d, e, f), (g, h, i) = J
    return (a * v[0] + d * v[1] + g * v[2], b * v[0] + e * v[1] + h * v[2], c * v[0] + f * v[1] + i * v[2])


def _three(values, name: str, what: str) -> list:
    """``values`` (shape (3,)) as three floats; ValueError naming ``name`` (``what``: the three)."""
    v = np.asarray(values, dtype=float)
    if v.shape != (3,):
        raise ValueError(f"{name}: needs 3 {what}, got shape {v.shape}")
    return v.tolist()


def _rates(qd) -> list:
    """Joint rates (3,) as floats."""
    return _three(qd, "qd", "joint rates")


def _wrench(f_ext) -> list:
    """An end-effector wrench (Fx, Fy, Mz) as three floats."""
    return _three(f_ext, "f_ext", "values (Fx, Fy, Mz)")


_BRANCH_SIGNS = {branch: tuple(1.0 if ch == "+" else -1.0 for ch in branch) for branch in BRANCHES}


def _branch_signs(branch: str) -> tuple:
    """The branch's signs (three of +1.0 / -1.0); ValueError if it is not one of :data:`BRANCHES`."""
    try:
        return _BRANCH_SIGNS[branch]
    except (KeyError, TypeError):
        raise ValueError(f"branch {branch!r} is invalid: must be one of {', '.join(BRANCHES)}") from None


def _gram(K: np.ndarray) -> np.ndarray:
    """K^T K for leg-first K (3 rows, 3 columns, ...): shape (3, 3, ...)."""
    return (K[:, :, None] * K[:, None, :]).sum(0)


def _largest_eigenvalue(G: np.ndarray) -> np.ndarray:
    """Largest eigenvalue of symmetric 3 x 3 matrices G (3, 3, ...), in closed form (the
    trigonometric solution of the characteristic cubic); NaN where G is not finite."""
    q = (G[0, 0] + G[1, 1] + G[2, 2]) / 3.0
    off = G[0, 1] ** 2 + G[0, 2] ** 2 + G[1, 2] ** 2
    p = np.sqrt(((G[0, 0] - q) ** 2 + (G[1, 1] - q) ** 2 + (G[2, 2] - q) ** 2 + 2.0 * off) / 6.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        a, b, c = (G[0, 0] - q) / p, (G[1, 1] - q) / p, (G[2, 2] - q) / p
        d, e, f = G[0, 1] / p, G[0, 2] / p, G[1, 2] / p
        half_det = 0.5 * (a * (b * c - f * f) - d * (d * c - f * e) + e * (d * f - b * e))
        phi = np.arccos(np.clip(half_det, -1.0, 1.0)) / 3.0
    return np.where(p > 0.0, q + 2.0 * p * np.cos(phi), q)

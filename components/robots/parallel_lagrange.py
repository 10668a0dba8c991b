"""The planar 3-RRP mechanism by Lagrange's equations on its spanning tree, with multipliers.

A second, independent formulation of the dynamics of robot ``3rrp`` (robots.md section 5), kept
apart from the robot model so that the two can check each other: nothing here imports the
model's module; it shares only the robot's numbers.

Mechanism. Leg i (i = 1, 2, 3) has an actuated revolute joint at the origin O (angle q_i), a link
of length r to its tip Q_i = r (cos q_i, sin q_i), a passive revolute joint at Q_i and a massless
slider along which Q_i runs on a line of the end effector through Z = (x, y), at angle
phi_i = theta + c_i to the x axis (c = pi/3, pi, -pi/3). The mechanism moves in a horizontal
plane: no gravity.

Spanning tree. Cutting each slider leaves four free bodies: the three links, each rotating
about O, and the end effector, free in the plane. Coordinates

    p = (q1, q2, q3, x, y, theta),

kinetic energy, written body by body in p (link centre of mass at distance c_l r from O, link
inertia I_l and end-effector inertia I_e about each body's own centre of mass, end-effector mass
m_e at Z)::

    T = sum_i 1/2 (I_l + m_l (c_l r)^2) qd_i^2 + 1/2 m_e (xd^2 + yd^2) + 1/2 I_e thetad^2,

so the tree's mass matrix M_p = diag(I_O, I_O, I_O, m_e, m_e, I_e), I_O = I_l + m_l (c_l r)^2, is
constant and Lagrange's equations of the tree have no velocity terms: M_p pdd = Q.

Loop closures. Q_i lies on its line: the cross product of (Q_i - Z) with the line's unit vector
u_i = (cos phi_i, sin phi_i) vanishes::

    Phi_i(p) = (Q_i - Z) x u_i = r sin(phi_i - q_i) - x sin phi_i + y cos phi_i      (m).

Its Jacobian (row i; the q-columns are diagonal)::

    dPhi_i/dq_i   = -r cos(phi_i - q_i)
    dPhi_i/dx     = -sin phi_i,   dPhi_i/dy = cos phi_i
    dPhi_i/dtheta =  r cos(phi_i - q_i) - x cos phi_i - y sin phi_i  =  s_i,

s_i = (Q_i - Z) . u_i being the slider extension, and the convective term
(d/dt Phi_p) pd = pd^T (d^2 Phi_i / dp^2) pd::

    -r sin(phi_i - q_i) (thetad - qd_i)^2 - 2 thetad (xd cos phi_i + yd sin phi_i)
    + thetad^2 (x sin phi_i - y cos phi_i).

The multiplier lambda_i (N) is the slider's normal force: the end effector feels -lambda_i n_i
at its line i, n_i = (-sin phi_i, cos phi_i), the link lambda_i n_i at its tip (a moment
r cos(phi_i - q_i) lambda_i about O). The joint is ideal (frictionless slider, the passive
revolute transmitting no moment), so the force does no work on motions that keep the loops closed.

Equations of motion. With generalized forces Q = (tau_1, tau_2, tau_3, Fx, Fy, Mz) (the external
wrench f_ext acts at Z in world axes; virtual work Fx dx + Fy dy + Mz dtheta) and Baumgarte's
stabilization of the acceleration-level constraint, Phidd + 2 alpha Phid + beta^2 Phi = 0::

    [ M_p    Phi_p^T ] [ pdd    ]   [ Q                                            ]
    [ Phi_p  0       ] [ lambda ] = [ -(d/dt Phi_p) pd - 2 alpha Phid - beta^2 Phi ]

The KKT matrix is regular wherever Phi_p has full row rank, which holds wherever no link is
perpendicular to its line (cos(phi_i - q_i) != 0), including the mechanism's direct
(parallel) singularities, where the minimal-coordinate form's Jacobian blows up. Defaults
alpha = beta = 20 1/s: critically damped constraint error, time constant 50 ms; both are
parameters (0 switches the stabilization off). On a consistent state the correction terms
vanish, so they change nothing but the integrator's drift. With RK4 at 1 ms, beta h = 0.02 keeps
the stabilized error dynamics far from RK4's stability limit; on a fast free motion passing near
direct singularities (condition number 1e5) the largest |Phi| over 5 s was 6e-9 m without
stabilization, 8e-11 m with alpha = beta = 20 1/s, and 1e-9 m with 100 1/s (too stiff for the
step).

State for integration: (p, pd), 12 values; :meth:`LagrangeRRP3.simulate` integrates it with
fixed-step classical RK4 (the default) or with scipy's ``solve_ivp`` (e.g. DOP853).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

__all__ = ["LagrangeRRP3", "Trajectory", "LINE_OFFSETS"]

#: Angles of the three lines relative to the end effector's orientation theta (rad).
LINE_OFFSETS = (math.pi / 3.0, math.pi, -math.pi / 3.0)

Input = np.ndarray | Sequence[float] | Callable[[float], np.ndarray] | None


@dataclass(frozen=True)
class Trajectory:
    """A simulated motion: times t (k,), coordinates p (k, 6), rates pd (k, 6)."""

    t: np.ndarray
    p: np.ndarray
    pd: np.ndarray

    @property
    def q(self) -> np.ndarray:
        return self.p[:, :3]

    @property
    def qd(self) -> np.ndarray:
        return self.pd[:, :3]

    @property
    def pose(self) -> np.ndarray:
        return self.p[:, 3:]


class LagrangeRRP3:
    """Lagrange's equations of the 3-RRP spanning tree with loop-closure multipliers.

    Parameters
    ----------
    r : float
        Link length (m).
    link_mass : float
        Mass of each link (kg).
    link_com : float
        Distance of each link's centre of mass from O as a fraction of r.
    link_inertia : float
        Each link's inertia about its own centre of mass, about z (kg m^2).
    ee_mass : float
        End-effector mass (kg), centre of mass at Z.
    ee_inertia : float
        End-effector inertia about Z, about z (kg m^2).
    alpha, beta : float
        Baumgarte gains (1/s): Phidd + 2 alpha Phid + beta^2 Phi = 0.
    line_offsets : 3 floats
        Angles of the lines relative to theta (rad).
    """

    def __init__(self, r: float, link_mass: float, link_com: float, link_inertia: float,
                 ee_mass: float, ee_inertia: float, alpha: float = 20.0, beta: float = 20.0,
                 line_offsets: Sequence[float] = LINE_OFFSETS):
        values = dict(r=r, link_mass=link_mass, link_com=link_com, link_inertia=link_inertia,
                      ee_mass=ee_mass, ee_inertia=ee_inertia, alpha=alpha, beta=beta)
        for name, value in values.items():
            if not math.isfinite(value) or value < 0.0:
                raise ValueError(f"{name} = {value!r} must be finite and >= 0")
        for name in ("r", "ee_mass", "ee_inertia"):
            if values[name] <= 0.0:
                raise ValueError(f"{name} = {values[name]!r} must be > 0")
        self.r = float(r)
        self.link_mass = float(link_mass)
        self.link_com = float(link_com)
        self.link_inertia = float(link_inertia)
        self.ee_mass = float(ee_mass)
        self.ee_inertia = float(ee_inertia)
        self.alpha = float(alpha)
        self.beta = float(beta)
        self.line_offsets = np.array(line_offsets, dtype=float)
        if self.line_offsets.shape != (3,):
            raise ValueError("line_offsets must hold 3 angles")
        #: Each link's inertia about O (kg m^2), by the parallel-axis theorem.
        self.link_inertia_O = self.link_inertia + self.link_mass * (self.link_com * self.r) ** 2
        if self.link_inertia_O <= 0.0:
            raise ValueError("each link needs a positive inertia about O")
        self._mass_diag = np.array([self.link_inertia_O] * 3 + [self.ee_mass, self.ee_mass, self.ee_inertia])

    #: Units of the constraint residual |Phi| and of its rate |Phid| (:meth:`residuals`).
    residual_units = ("m", "m/s")

    @classmethod
    def from_description(cls, robot: str = "3rrp", **baumgarte) -> "LagrangeRRP3":
        """The robot's numbers from its description's ``[mechanism]`` table (via the loader).

        ``baumgarte`` may give ``alpha`` and ``beta``.
        """
        from . import load_description

        description = load_description(robot)
        mech = description.mechanism
        if mech is None:
            raise ValueError(f"robot {robot!r}: its description has no [mechanism] table")
        return cls.from_mechanism(mech, **baumgarte)

    @classmethod
    def from_mechanism(cls, mech, payload: float = 0.0, **baumgarte) -> "LagrangeRRP3":
        """From a description's ``[mechanism]`` table (r, link_*, ee_*, line_offsets); a point
        ``payload`` (kg) at Z adds to the end effector's mass (not to its inertia)."""
        return cls(r=mech.r, link_mass=mech.link_mass, link_com=mech.link_com,
                   link_inertia=mech.link_inertia, ee_mass=mech.ee_mass + float(payload),
                   ee_inertia=mech.ee_inertia, line_offsets=mech.line_offsets, **baumgarte)

    # -- geometry -------------------------------------------------------------------------------
    def line_angles(self, theta: float) -> np.ndarray:
        """phi_i = theta + c_i (rad), shape (3,)."""
        return theta + self.line_offsets

    def tips(self, q: np.ndarray) -> np.ndarray:
        """Link tips Q_i (m), shape (3, 2)."""
        q = np.asarray(q, dtype=float)
        return self.r * np.column_stack([np.cos(q), np.sin(q)])

    def slider_extensions(self, p: np.ndarray) -> np.ndarray:
        """s_i = (Q_i - Z) . u_i (m), shape (3,): where each tip sits on its line."""
        p = np.asarray(p, dtype=float)
        q, x, y, th = p[:3], p[3], p[4], p[5]
        phi = self.line_angles(th)
        return self.r * np.cos(phi - q) - x * np.cos(phi) - y * np.sin(phi)

    # -- constraints ----------------------------------------------------------------------------
    def constraints(self, p: np.ndarray) -> np.ndarray:
        """Phi(p) (m), shape (3,): signed distance of each tip from its line."""
        p = np.asarray(p, dtype=float)
        q, x, y, th = p[:3], p[3], p[4], p[5]
        phi = self.line_angles(th)
        return self.r * np.sin(phi - q) - x * np.sin(phi) + y * np.cos(phi)

    def constraint_jacobian(self, p: np.ndarray) -> np.ndarray:
        """Phi_p = dPhi/dp, shape (3, 6)."""
        p = np.asarray(p, dtype=float)
        q, x, y, th = p[:3], p[3], p[4], p[5]
        phi = self.line_angles(th)
        c = self.r * np.cos(phi - q)
        J = np.zeros((3, 6))
        J[[0, 1, 2], [0, 1, 2]] = -c
        J[:, 3] = -np.sin(phi)
        J[:, 4] = np.cos(phi)
        J[:, 5] = c - x * np.cos(phi) - y * np.sin(phi)
        return J

    def constraint_rates(self, p: np.ndarray, pd: np.ndarray) -> np.ndarray:
        """Phid = Phi_p pd (m/s), shape (3,)."""
        return self.constraint_jacobian(p) @ np.asarray(pd, dtype=float)

    def constraint_convective(self, p: np.ndarray, pd: np.ndarray) -> np.ndarray:
        """(d/dt Phi_p) pd (m/s^2), shape (3,): Phidd when pdd = 0."""
        p = np.asarray(p, dtype=float)
        pd = np.asarray(pd, dtype=float)
        q, x, y, th = p[:3], p[3], p[4], p[5]
        qd, xd, yd, thd = pd[:3], pd[3], pd[4], pd[5]
        phi = self.line_angles(th)
        cphi, sphi = np.cos(phi), np.sin(phi)
        return (-self.r * np.sin(phi - q) * (thd - qd) ** 2
                - 2.0 * thd * (xd * cphi + yd * sphi)
                + thd ** 2 * (x * sphi - y * cphi))

    def residual(self, p: np.ndarray, pd: np.ndarray) -> tuple[float, float]:
        """(|Phi| in m, |Phid| in m/s), Euclidean norms over the three loops."""
        return float(np.linalg.norm(self.constraints(p))), float(np.linalg.norm(self.constraint_rates(p, pd)))

    def residuals(self, trajectory: "Trajectory") -> tuple[np.ndarray, np.ndarray]:
        """(|Phi(t)| in m, |Phid(t)| in m/s), shape (k,) each: :meth:`residual` along a trajectory."""
        P, Pd = trajectory.p, trajectory.pd
        q, x, y, th = P[:, :3], P[:, 3:4], P[:, 4:5], P[:, 5:6]
        phi = th + self.line_offsets
        sphi, cphi = np.sin(phi), np.cos(phi)
        Phi = self.r * np.sin(phi - q) - x * sphi + y * cphi
        c = self.r * np.cos(phi - q)
        Phid = (-c * Pd[:, :3] - sphi * Pd[:, 3:4] + cphi * Pd[:, 4:5]
                + (c - x * cphi - y * sphi) * Pd[:, 5:6])
        return np.linalg.norm(Phi, axis=1), np.linalg.norm(Phid, axis=1)

    # -- consistent states (for starting a simulation; independent of the robot model) ----------
    def pose_from_joints(self, q: np.ndarray, guess: np.ndarray, tol: float = 1e-15,
                         max_iterations: int = 50) -> np.ndarray:
        """The pose (x, y, theta) closing the loops at q, by Newton's method from ``guess``.

        Raises ValueError when it does not converge (no pose near the guess, or a singularity).
        """
        q = np.asarray(q, dtype=float)
        z = np.array(guess, dtype=float)
        for _ in range(max_iterations):
            p = np.concatenate([q, z])
            F = self.constraints(p)
            if np.max(np.abs(F)) <= tol * max(1.0, self.r):
                return z
            step = np.linalg.solve(self.constraint_jacobian(p)[:, 3:], -F)
            z = z + step
            if np.max(np.abs(step)) < 1e-17:
                break
        p = np.concatenate([q, z])
        if np.max(np.abs(self.constraints(p))) <= 1e-13 * max(1.0, self.r):
            return z
        raise ValueError(f"no pose closing the loops near {guess!r} at q = {q!r}")

    def joints_from_pose(self, pose: np.ndarray, positive_sliders: bool = True) -> np.ndarray:
        """The joint angles q closing the loops at a pose, leg by leg (each a 2-way choice).

        r sin(phi_i - q_i) = x sin phi_i - y cos phi_i = d_i, so q_i = phi_i - asin(d_i / r) (the
        slider extension r cos(phi_i - q_i) - ... has the sign of cos(asin)) or its mirror
        q_i = phi_i - pi + asin(d_i / r). ``positive_sliders`` picks the branch whose tip lies
        ahead of Z along u_i (s_i > 0) where both do not; ValueError when |d_i| > r.
        """
        x, y, th = (float(v) for v in pose)
        phi = self.line_angles(th)
        d = x * np.sin(phi) - y * np.cos(phi)
        if np.any(np.abs(d) > self.r):
            raise ValueError(f"pose {pose!r} is out of reach: a line passes farther than r from O")
        a = np.arcsin(d / self.r)
        candidates = (phi - a, phi - math.pi + a)
        q = np.empty(3)
        for i in range(3):
            best = None
            for cand in (candidates[0][i], candidates[1][i]):
                s = self.r * math.cos(phi[i] - cand) - x * math.cos(phi[i]) - y * math.sin(phi[i])
                score = s if positive_sliders else -s
                if best is None or score > best[0]:
                    best = (score, cand)
            q[i] = math.remainder(best[1], 2.0 * math.pi)
        return q

    def pose_rates(self, p: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """(xd, yd, thetad) keeping Phid = 0 for joint rates qd: Phi_z zd = -Phi_q qd."""
        J = self.constraint_jacobian(p)
        return np.linalg.solve(J[:, 3:], -J[:, :3] @ np.asarray(qd, dtype=float))

    def joint_rates(self, p: np.ndarray, zd: np.ndarray) -> np.ndarray:
        """qd keeping Phid = 0 for pose rates zd (Phi_q is diagonal): qd = -Phi_q^-1 Phi_z zd."""
        J = self.constraint_jacobian(p)
        return -(J[:, 3:] @ np.asarray(zd, dtype=float)) / np.diag(J[:, :3])

    def consistent_rates(self, p: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """pd = (qd, zd) with Phi_p pd = 0."""
        qd = np.asarray(qd, dtype=float)
        return np.concatenate([qd, self.pose_rates(p, qd)])

    # -- dynamics -------------------------------------------------------------------------------
    def mass_matrix(self) -> np.ndarray:
        """M_p of the spanning tree, shape (6, 6) (constant)."""
        return np.diag(self._mass_diag)

    @staticmethod
    def generalized_forces(tau: np.ndarray, f_ext: np.ndarray | None = None) -> np.ndarray:
        """Q = (tau (N m), Fx, Fy (N), Mz (N m)), shape (6,)."""
        Q = np.zeros(6)
        Q[:3] = np.asarray(tau, dtype=float)
        if f_ext is not None:
            Q[3:] = np.asarray(f_ext, dtype=float)
        return Q

    def kinetic_energy(self, p: np.ndarray, pd: np.ndarray) -> float:
        """T (J), body by body: links about O (centre of mass speed c_l r qd_i), end effector at Z."""
        pd = np.asarray(pd, dtype=float)
        qd = pd[:3]
        v_link = self.link_com * self.r * qd                       # speed of each link's centre of mass
        t_links = 0.5 * self.link_mass * np.sum(v_link ** 2) + 0.5 * self.link_inertia * np.sum(qd ** 2)
        t_ee = 0.5 * self.ee_mass * (pd[3] ** 2 + pd[4] ** 2) + 0.5 * self.ee_inertia * pd[5] ** 2
        return float(t_links + t_ee)

    def power(self, pd: np.ndarray, tau: np.ndarray, f_ext: np.ndarray | None = None) -> float:
        """Power of the actuators and the external wrench (W): Q . pd."""
        return float(self.generalized_forces(tau, f_ext) @ np.asarray(pd, dtype=float))

    def solve(self, p: np.ndarray, pd: np.ndarray, tau: np.ndarray,
              f_ext: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(pdd (6,), lambda (3,)) from the KKT system with Baumgarte's terms."""
        p = np.asarray(p, dtype=float)
        pd = np.asarray(pd, dtype=float)
        A = self.constraint_jacobian(p)
        rhs_c = (-self.constraint_convective(p, pd) - 2.0 * self.alpha * (A @ pd)
                 - self.beta ** 2 * self.constraints(p))
        K = np.zeros((9, 9))
        K[:6, :6] = np.diag(self._mass_diag)
        K[:6, 6:] = A.T
        K[6:, :6] = A
        rhs = np.concatenate([self.generalized_forces(tau, f_ext), rhs_c])
        sol = np.linalg.solve(K, rhs)
        return sol[:6], sol[6:]

    def accelerations(self, p: np.ndarray, pd: np.ndarray, tau: np.ndarray,
                      f_ext: np.ndarray | None = None) -> np.ndarray:
        """pdd (6,): (qdd in rad/s^2, xdd, ydd in m/s^2, thetadd in rad/s^2)."""
        return self.solve(p, pd, tau, f_ext)[0]

    def multipliers(self, p: np.ndarray, pd: np.ndarray, tau: np.ndarray,
                    f_ext: np.ndarray | None = None) -> np.ndarray:
        """lambda (N), shape (3,): the sliders' normal forces (M_p pdd = Q - Phi_p^T lambda)."""
        return self.solve(p, pd, tau, f_ext)[1]

    def state_derivative(self, t: float, state: np.ndarray, tau: Input = None, f_ext: Input = None) -> np.ndarray:
        """d/dt (p, pd), shape (12,); tau and f_ext constant or functions of t."""
        state = np.asarray(state, dtype=float)
        p, pd = state[:6], state[6:]
        pdd = self.accelerations(p, pd, _value(tau, t, 3), _value(f_ext, t, 3))
        return np.concatenate([pd, pdd])

    def simulate(self, p0: np.ndarray, pd0: np.ndarray, t_end: float, h: float = 1e-3,
                 tau: Input = None, f_ext: Input = None, method: str = "rk4",
                 rtol: float = 1e-12, atol: float = 1e-14) -> Trajectory:
        """Integrate from (p0, pd0) at t = 0 to t_end, output every h seconds.

        ``method`` ``"rk4"``: classical fixed-step Runge-Kutta 4 with step h (t_end a whole number
        of steps); any other name is passed to ``scipy.integrate.solve_ivp`` (e.g. ``"DOP853"``,
        tolerances ``rtol``, ``atol``), sampled at the same instants. Inputs are constants or
        functions of t.
        """
        n = round(t_end / h)
        if n < 1 or abs(n * h - t_end) > 1e-9 * max(1.0, t_end):
            raise ValueError(f"t_end = {t_end} must be a whole number of steps h = {h}")
        t = np.arange(n + 1) * h
        x0 = np.concatenate([np.asarray(p0, dtype=float), np.asarray(pd0, dtype=float)])
        f = lambda tt, xx: self.state_derivative(tt, xx, tau, f_ext)  # noqa: E731
        if method == "rk4":
            X = np.empty((n + 1, 12))
            X[0] = x = x0
            for k in range(n):
                tk = t[k]
                k1 = f(tk, x)
                k2 = f(tk + 0.5 * h, x + 0.5 * h * k1)
                k3 = f(tk + 0.5 * h, x + 0.5 * h * k2)
                k4 = f(tk + h, x + h * k3)
                x = x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
                X[k + 1] = x
        else:
            from scipy.integrate import solve_ivp

            sol = solve_ivp(f, (0.0, t[-1]), x0, method=method, t_eval=t, rtol=rtol, atol=atol)
            if not sol.success:
                raise RuntimeError(f"solve_ivp ({method}) failed: {sol.message}")
            X = sol.y.T
        return Trajectory(t, X[:, :6].copy(), X[:, 6:].copy())


    def simulate_joints(self, q0: np.ndarray, qd0: np.ndarray, t_end: float, h: float = 1e-3,
                        tau: Input = None, f_ext: Input = None, method: str = "rk4",
                        pose_guess: np.ndarray | None = None, **tolerances) -> Trajectory:
        """:meth:`simulate` from a state in actuated coordinates: the start pose closes the loops
        at q0 (:meth:`pose_from_joints`, Newton from ``pose_guess``, e.g. another model's FK of
        q0: only a start for the iteration), the start rates keep them closed
        (:meth:`consistent_rates`)."""
        q0 = np.asarray(q0, dtype=float)
        guess = np.zeros(3) if pose_guess is None else np.asarray(pose_guess, dtype=float)
        p0 = np.concatenate([q0, self.pose_from_joints(q0, guess)])
        pd0 = self.consistent_rates(p0, np.asarray(qd0, dtype=float))
        return self.simulate(p0, pd0, t_end, h=h, tau=tau, f_ext=f_ext, method=method, **tolerances)


def _value(u: Input, t: float, size: int) -> np.ndarray:
    if u is None:
        return np.zeros(size)
    if callable(u):
        return np.asarray(u(t), dtype=float)
    return np.asarray(u, dtype=float)

"""The sampled, delayed computed-torque loop: python-control's prediction and its stability limit.

:func:`~.linear.discrete_prediction` models a controller that samples at the communication step
h. Here the controller runs at its own ``sample_time`` Ts = N h (N a positive integer) and its
effort may arrive ``delay_steps`` = d controller samples late. Per joint, with y = q - q0 and a
reference step r from t = 0 (see :mod:`.linear`):

Plant, integrated at h
    y'' = u - beta y', beta = ``damping`` (1/s): viscous friction b per unit inertia that the
    controller does not compensate (beta = 0: the perfect model). u is held over each
    controller period [t_k, t_k + Ts), t_k = k Ts, so the plant sees a zero-order hold at Ts
    whatever its own step h < Ts (up to M(q) and g(q) varying within the held period, as in
    :mod:`.linear`, now over Ts instead of h):

        x_{k+1} = Phi x_k + Gamma u_k,  x = (y, y'),  (Phi, Gamma) = ``control.c2d(plant, Ts, 'zoh')``

    (beta = 0: Phi = [[1, Ts], [0, 1]], Gamma = [Ts^2 / 2, Ts]). Between two controller samples
    the plant's state at t_k + j h is exactly (Phi(j h), Gamma(j h)) applied to (x_k, u_k): the
    co-simulation's records at the base step are predicted exactly, not interpolated.
Controller, sampled at Ts
    v_k = kp (r - y_k) - kd y'_k + ki z_k,   z_{k+1} = z_k + Ts (r - y_k).
Delay
    u_k = v_{k-d} (v computed from the samples at t_k is output at t_{k+d}), a shift register
    of d states (z^-d); before t_d the plant receives the effort computed before the step,
    u = 0 (tau = the computed torque of the resting arm).

With Ts = h and d = 0 this is :func:`~.linear.discrete_prediction`. For PD and beta = 0 the
closed loop's characteristic polynomial is, with T = Ts,

    z^d (z - 1)^2 + kd T (z - 1) + kp T^2 (z + 1) / 2 = 0

(PID: z^d (z - 1)^3 + kd T (z - 1)^2 + (T^2 / 2)(z + 1)(kp (z - 1) + ki T) = 0). Its Jury
conditions give the stability limit in closed form for d = 0, kp < 2 kd / T (with kd T < 2), and
for d = 1, kp < (2 q - 3 + sqrt(9 - 8 q)) / T^2 with q = kd T, about a third of it (2 kd / (3 T)
for small q). :func:`largest_stable_kp` finds the limit for any d, ki and beta from
python-control's discrete poles.

Joints coupled through the held effort
    The computed torque cancels the arm's gravity and the damping it knows only at its samples:
    over the hold and the delay they act on the plant while the effort carries their values at
    t_{k-d}, across joints (a slide's weight on the joint that lifts it).
    :func:`predict_coupled` is the loop above for n joints at once with those terms linearized
    (stiffness K = M^-1 dg/dq, damping B = M^-1 D, compensation B_c = M^-1 D_c); with K = B_c = 0
    and B diagonal it is n copies of this one.
Friction the controller does not know
    Viscous b: the ``damping`` above, beta = b / m. Coulomb tau_c: at rest a PD balances it with
    its proportional term, m kp e = tau_c, so the joint stops short of the reference by
    e = tau_c / (m kp) (:func:`friction_steady_state_error`); a PID's integral removes it. m is
    the joint's inertia at the operating point: 1 / (M^-1)_jj, which is M_jj for a decoupled
    joint (in general the errors at rest are kp e = M^-1 tau_f, a vector). The plant's smooth
    Coulomb model tau_c tanh(qd / v_s) has no stiction: at rest it is a viscous term of slope
    tau_c / v_s, so inside the stick band the error creeps to zero with the time constant of
    :func:`friction_creep_time` instead of staying. None of this is in the linear prediction,
    which settles at r: its miss is e.

The gains follow :func:`robofmu.components.control.check_gains`; other arguments are refused
with a ValueError naming the argument.
"""
from __future__ import annotations

import math
import operator

import control
import numpy as np
from scipy.optimize import brentq

from robofmu.components.control import check_gains

__all__ = ["sampled_prediction", "predict_sampled", "predict_coupled", "spectral_radius", "largest_stable_kp",
           "friction_steady_state_error", "friction_creep_time"]


def _positive(name: str, value: float, unit: str, zero: bool = False) -> float:
    value = float(value)
    if not (math.isfinite(value) and (value >= 0.0 if zero else value > 0.0)):
        raise ValueError(f"{name} must be {'>= 0' if zero else '> 0'} {unit}, got {value:g}")
    return value


def _delay(delay_steps) -> int:
    try:
        d = operator.index(delay_steps)
    except TypeError:
        raise ValueError(f"delay_steps must be an integer >= 0, got {delay_steps!r}") from None
    if isinstance(delay_steps, bool) or d < 0:
        raise ValueError(f"delay_steps must be an integer >= 0, got {delay_steps!r}")
    return d


def _signals(base: str, n: int) -> list[str]:
    """Signal names of a vector of n: ``base`` itself for one joint, else ``base[0]`` ... ``base[n-1]``."""
    return [base] if n == 1 else [f"{base}[{i}]" for i in range(n)]


def _plant(damping, stiffness=None) -> control.StateSpace:
    """y'' = u - stiffness y - damping y' (n joints; scalars for one) with outputs (y, y')."""
    damping = np.atleast_2d(np.asarray(damping, dtype=float))
    n = damping.shape[0]
    stiffness = np.zeros((n, n)) if stiffness is None else np.atleast_2d(np.asarray(stiffness, dtype=float))
    zero, one = np.zeros((n, n)), np.eye(n)
    return control.ss(np.block([[zero, one], [-stiffness, -damping]]), np.vstack([zero, one]), np.eye(2 * n),
                      np.zeros((2 * n, n)), inputs=_signals("u", n), outputs=_signals("y", n) + _signals("yd", n),
                      name="plant")


def _closed_loop(plant: control.StateSpace, kp: float, kd: float, ki: float, d: int,
                 stiffness=None, compensation=None) -> control.StateSpace:
    """The loop of the discretized ``plant`` (dt = Ts, n joints), inputs r, outputs (y, y', u applied).

    The controller's effort per unit inertia is w = kp (r - y) - kd y' + ki z + stiffness y +
    compensation y' (the last two: the model terms it computes from its samples, zero for one
    decoupled joint). States: (y, y'), then z if ki > 0, then the delay line (newest effort first)."""
    ts, n = plant.dt, plant.ninputs
    stiffness = np.zeros((n, n)) if stiffness is None else np.atleast_2d(np.asarray(stiffness, dtype=float))
    compensation = np.zeros((n, n)) if compensation is None else np.atleast_2d(np.asarray(compensation, dtype=float))
    one, zero = np.eye(n), np.zeros((n, n))
    inputs = _signals("r", n) + _signals("y", n) + _signals("yd", n)
    ctrl_out = _signals("v" if d else "u", n)
    feedthrough = np.hstack([kp * one, stiffness - kp * one, compensation - kd * one])
    if ki == 0.0:
        ctrl = control.ss(np.zeros((0, 0)), np.zeros((0, 3 * n)), np.zeros((n, 0)), feedthrough, dt=ts,
                          inputs=inputs, outputs=ctrl_out, name="ctrl")
    else:
        ctrl = control.ss(one, np.hstack([ts * one, -ts * one, zero]), ki * one, feedthrough, dt=ts,
                          inputs=inputs, outputs=ctrl_out, name="ctrl")
    parts = [plant, ctrl]
    if d:
        parts.append(control.ss(np.kron(np.eye(d, k=-1), one), np.kron(np.eye(d, 1), one),
                                np.kron(np.eye(1, d, k=d - 1), one), zero, dt=ts,
                                inputs=_signals("v", n), outputs=_signals("u", n), name="delay"))
    outputs = _signals("y", n) + _signals("yd", n) + _signals("u", n)
    return control.interconnect(parts, inplist=_signals("r", n), outlist=outputs, inputs=_signals("r", n),
                                outputs=outputs)


def _coupling(n: int, **matrices) -> dict[str, np.ndarray]:
    """Each of ``matrices`` (stiffness, damping, compensation) as a finite (n, n) array, zeros for None."""
    checked = {}
    for name, value in matrices.items():
        value = np.zeros((n, n)) if value is None else np.asarray(value, dtype=float)
        if value.shape != (n, n) or not np.all(np.isfinite(value)):
            raise ValueError(f"{name} must be a finite ({n}, {n}) matrix, one row per joint, got shape {value.shape}")
        checked[name] = value
    return checked


def _coupled_plant(sample_time, stiffness, damping, compensation) -> tuple[control.StateSpace, dict]:
    """The n-joint plant of :func:`predict_coupled` discretized at ``sample_time``, and its checked matrices."""
    ts = _positive("sample_time", sample_time, "s")
    n = np.atleast_2d(np.asarray(stiffness)).shape[0]
    matrices = _coupling(n, stiffness=stiffness, damping=damping, compensation=compensation)
    return control.c2d(_plant(matrices["damping"], matrices["stiffness"]), ts, method="zoh"), matrices


def _discrete_plant(sample_time, damping) -> tuple[control.StateSpace, control.StateSpace, float, float]:
    ts = _positive("sample_time", sample_time, "s")
    beta = _positive("damping", damping, "1/s", zero=True)
    continuous = _plant(beta)
    return continuous, control.c2d(continuous, ts, method="zoh"), ts, beta


def sampled_prediction(kp: float, kd: float, ki: float, sample_time: float, delay_steps: int = 0,
                       damping: float = 0.0) -> control.StateSpace:
    """The loop sampled at ``sample_time`` with ``delay_steps`` of delay, at its samples.

    Parameters
    ----------
    kp, kd, ki : float
        Gains (1/s^2, 1/s, 1/s^3); ``ki = 0`` for PD (no integral state).
    sample_time : float
        The controller's sample time Ts (s), > 0; the effort is held over it.
    delay_steps : int
        d >= 0: the effort computed from the samples at t_k is applied from t_{k+d}.
    damping : float
        beta = b / m (1/s), >= 0: viscous friction per unit inertia, unknown to the controller.

    Returns
    -------
    control.StateSpace
        Discrete (``dt = sample_time``), input r (reference relative to the start, joint unit),
        output y at t_k (same unit); states (y, y'[, z], delayed efforts). With Ts = h, d = 0
        and beta = 0 it is :func:`~.linear.discrete_prediction` (same states, same matrices).
    """
    kp, kd, ki = check_gains(kp, kd, ki)
    d = _delay(delay_steps)
    _, plant, ts, _ = _discrete_plant(sample_time, damping)
    loop = _closed_loop(plant, kp, kd, ki, d)
    return control.ss(loop.A, loop.B, loop.C[:1], loop.D[:1], dt=ts)


def predict_sampled(kp: float, kd: float, ki: float, t: np.ndarray, amplitude: float = 1.0,
                    sample_time: float | None = None, delay_steps: int = 0, damping: float = 0.0,
                    h: float | None = None, startup: str = "rest") -> np.ndarray:
    """Predicted y(t) = q(t) - q0 after a reference step, on the base-step grid of the co-simulation.

    The loop of :func:`sampled_prediction` gives the state at the controller's samples; between
    them the ZOH'd plant (``control.c2d`` at j h) gives the exact values at t_k + j h,
    j = 0 .. N - 1, computed as one lifted system (N outputs, dt = Ts) and interleaved.

    Parameters
    ----------
    kp, kd, ki : float
        Gains (1/s^2, 1/s, 1/s^3).
    t : array_like, shape (n,)
        Times (s) from the step: ``t[k] = t[0] + k h``.
    amplitude : float
        Step size A (joint unit: rad or m).
    sample_time : float, optional
        Controller sample time Ts (s), an integer multiple N of ``h``; default ``h``.
    delay_steps : int
        d, in controller samples.
    damping : float
        beta (1/s), as in :func:`sampled_prediction`.
    h : float, optional
        Base (communication) step (s); default ``t[1] - t[0]``.
    startup : {"rest", "first"}
        What the plant receives before t_d (d > 0): "rest", u = 0, the effort computed before
        the step (the notes above); "first", u = v_0, the effort of the first sample, which is
        what the controller block outputs before its sample d (it has no earlier sample;
        ``components/blocks/controller.py``). Equal for d = 0.

    Returns
    -------
    numpy.ndarray, shape (n,)
        y in the unit of ``amplitude``.
    """
    response = predict_coupled(kp, kd, ki, t, [amplitude], sample_time=sample_time, delay_steps=delay_steps,
                               damping=[[_positive("damping", damping, "1/s", zero=True)]], h=h, startup=startup)
    return response[:, 0]


def predict_coupled(kp: float, kd: float, ki: float, t: np.ndarray, amplitudes, *, sample_time: float | None = None,
                    delay_steps: int = 0, stiffness=None, damping=None, compensation=None, h: float | None = None,
                    startup: str = "rest") -> np.ndarray:
    """Predicted y(t) = q(t) - q0 of every joint after a step of the reference vector, the joints
    coupled by the model terms the controller computes from its (held, delayed) samples.

    The law tau = M(q_k) v_k + g(q_k) + D_c q'_k cancels the plant's M, g and damping only at the
    sample t_k; in between, and over the delay, the plant feels g(q(t)) while the effort holds
    g(q_k). Linearized about q* (M, g and D evaluated there, y = q - q0 small):

        y'' = u - K y - B y',   u_k = v_{k-d} + K y_{k-d} + B_c y'_{k-d}

    with K = M^-1 dg/dq (``stiffness``), B = M^-1 D (``damping``, the plant's viscous friction) and
    B_c = M^-1 D_c (``compensation``, the part the controller adds), each (n, n) in 1/s^2 or 1/s.
    With zero delay and continuous sampling K and B_c cancel; sampled and delayed they couple the
    joints in proportion to the effort's mean lag (d + 1/2) Ts. With K = B_c = 0 and B diagonal
    each column is :func:`predict_sampled` of that joint. What stays out is second order in the
    amplitude: M(q) and dg/dq varying over the step, and the Coriolis terms.

    Parameters
    ----------
    kp, kd, ki : float
        Gains (1/s^2, 1/s, 1/s^3).
    t : array_like, shape (m,)
        Times (s) from the step: ``t[k] = t[0] + k h``.
    amplitudes : array_like, shape (n,)
        The step of each joint's reference (joint units: rad or m); 0 for a joint held.
    sample_time : float, optional
        Controller sample time Ts (s), an integer multiple N of ``h``; default ``h``.
    delay_steps : int
        d, in controller samples.
    stiffness, damping, compensation : array_like, shape (n, n), optional
        K (1/s^2), B and B_c (1/s) above; default zeros.
    h : float, optional
        Base (communication) step (s); default ``t[1] - t[0]``.
    startup : {"rest", "first"}
        As in :func:`predict_sampled`: before t_d the plant receives u = 0 ("rest") or the first
        sample's effort u = kp r ("first", what the controller block does).

    Returns
    -------
    numpy.ndarray, shape (m, n)
        y of each joint, in the joints' units.
    """
    kp, kd, ki = check_gains(kp, kd, ki)
    d = _delay(delay_steps)
    if startup not in ("rest", "first"):
        raise ValueError(f"startup must be 'rest' or 'first', got {startup!r}")
    amplitudes = np.atleast_1d(np.asarray(amplitudes, dtype=float))
    n = amplitudes.size
    matrices = _coupling(n, stiffness=stiffness, damping=damping, compensation=compensation)
    t = np.asarray(t, dtype=float)
    h = _positive("h", t[1] - t[0] if h is None else h, "s")
    ts = _positive("sample_time", h if sample_time is None else sample_time, "s")
    ratio = round(ts / h)
    if ratio < 1 or abs(ratio * h - ts) > 1e-9 * ts:
        raise ValueError(f"sample_time must be an integer multiple of the base step {h:g} s, got {ts:g} s")
    continuous = _plant(matrices["damping"], matrices["stiffness"])
    loop = _closed_loop(control.c2d(continuous, ts, method="zoh"), kp, kd, ki, d, matrices["stiffness"],
                        matrices["compensation"])
    cx, cu, du = np.asarray(loop.C[:2 * n]), np.asarray(loop.C[2 * n:]), np.asarray(loop.D[2 * n:])
    rows_c, rows_d = [], []
    for j in range(ratio):
        if j == 0:
            phi, gamma = np.eye(2 * n), np.zeros((2 * n, n))
        else:
            part = control.c2d(continuous, j * h, method="zoh")
            phi, gamma = np.asarray(part.A), np.asarray(part.B)
        rows_c.append((phi @ cx + gamma @ cu)[:n])
        rows_d.append((gamma @ du)[:n])
    lifted = control.ss(loop.A, loop.B, np.vstack(rows_c), np.vstack(rows_d), dt=ts)
    samples = -(-len(t) // ratio)
    x0 = np.zeros(loop.nstates)
    if startup == "first" and d:
        x0[-d * n:] = np.tile(kp * amplitudes, d)   # the delay line full of v_0 = kp r
    y = control.forced_response(lifted, T=ts * np.arange(samples), U=np.tile(amplitudes[:, None], samples),
                                X0=x0, squeeze=False).outputs          # (ratio n, samples): row j n + i
    return np.asarray(y, dtype=float).reshape(ratio, n, samples).transpose(2, 0, 1).reshape(-1, n)[:len(t)]


def spectral_radius(kp: float, kd: float, ki: float, sample_time: float, delay_steps: int = 0,
                    damping=0.0, *, stiffness=None, compensation=None) -> float:
    """Largest |pole| of :func:`sampled_prediction` (``control.poles``): stable iff < 1.

    Each sample multiplies the slowest error by about this radius, so -Ts / ln(radius) is the
    slowest time constant (s) of a stable loop. With ``stiffness`` (n, n) it is the coupled loop
    of :func:`predict_coupled` (``damping`` and ``compensation`` then (n, n) matrices or None).
    """
    if stiffness is None and compensation is None:
        loop = sampled_prediction(kp, kd, ki, sample_time, delay_steps, damping)
    else:
        kp, kd, ki = check_gains(kp, kd, ki)
        plant, m = _coupled_plant(sample_time, stiffness, None if np.isscalar(damping) and damping == 0.0 else damping,
                                  compensation)
        loop = _closed_loop(plant, kp, kd, ki, _delay(delay_steps), m["stiffness"], m["compensation"])
    return float(np.max(np.abs(control.poles(loop))))


def largest_stable_kp(kd: float | None, sample_time: float, delay_steps: int = 0, ki: float = 0.0, *,
                      zeta: float | None = None, damping=0.0, stiffness=None, compensation=None) -> float:
    """The largest kp (1/s^2) at which every pole of :func:`sampled_prediction` is inside the unit circle.

    Two forms, one of ``kd`` and ``zeta`` given:

    - ``kd`` held (1/s), what a user tuning kp alone changes; PD, d = 0, beta = 0: 2 kd / Ts.
    - ``zeta`` held, kd = 2 zeta sqrt(kp) (the continuous loop's damping ratio, as gains designed
      from an overshoot keep it when made faster); PD, d = 0, beta = 0: min(16 zeta^2, 1 / zeta^2) / Ts^2.

    The limit is the upper end of the interval of stable kp: kp is scanned upwards by factors
    of 2 from 2^-40 / Ts^2 to the first unstable value after a stable one, then the crossing of
    max |pole| - 1 is found by ``scipy.optimize.brentq`` to 1e-11 relative. (A PID has a lower
    limit as well, about ki / kd; it is not returned.)

    Parameters
    ----------
    kd : float or None
        Derivative gain (1/s), None when ``zeta`` is given.
    sample_time : float
        Controller sample time Ts (s).
    delay_steps : int
        d, in controller samples.
    ki : float
        Integral gain (1/s^3), held; 0 for PD.
    zeta : float, optional
        Damping ratio held instead of ``kd``, > 0.
    damping : float or array_like (n, n)
        beta (1/s), as in :func:`sampled_prediction`; with ``stiffness``, B of :func:`predict_coupled`.
    stiffness, compensation : array_like (n, n), optional
        K and B_c of :func:`predict_coupled`: the limit of the n joints' coupled loop (the arm
        linearized), which gravity's stiffness felt through the held, delayed effort lowers.

    Returns
    -------
    float
        kp (1/s^2). ValueError (naming the arguments) if no kp gives a stable loop.
    """
    if (kd is None) == (zeta is None):
        raise ValueError("largest_stable_kp: give exactly one of kd and zeta")
    if zeta is not None:
        zeta = _positive("zeta", zeta, "")
    _, kd_held, ki = check_gains(1.0, 1.0 if kd is None else kd, ki)
    d = _delay(delay_steps)
    if stiffness is None and compensation is None:
        _, plant, ts, _ = _discrete_plant(sample_time, damping)
        model_terms = {}
    else:
        plant, m = _coupled_plant(sample_time, stiffness, None if np.isscalar(damping) and damping == 0.0 else damping,
                                  compensation)
        ts, model_terms = plant.dt, dict(stiffness=m["stiffness"], compensation=m["compensation"])

    def margin(kp: float) -> float:
        kd_now = kd_held if zeta is None else 2.0 * zeta * math.sqrt(kp)
        return float(np.max(np.abs(control.poles(_closed_loop(plant, kp, kd_now, ki, d, **model_terms))))) - 1.0

    stable_at = None
    for kp in 2.0 ** np.arange(-40, 11) / ts**2:
        if margin(kp) < 0.0:
            stable_at = kp
        elif stable_at is not None:
            return brentq(margin, stable_at, kp, xtol=1e-15 * kp, rtol=1e-11)
    held = f"kd = {kd_held:g} 1/s" if zeta is None else f"zeta = {zeta:g}"
    what = "is stable at no kp" if stable_at is None else f"is still stable at kp = {stable_at:g} 1/s^2"
    raise ValueError(f"the loop with {held}, ki = {ki:g} 1/s^3, sample_time = {ts:g} s, delay_steps = {d}, "
                     f"damping = {np.max(np.abs(damping)):g} 1/s{' (coupled)' * bool(model_terms)} {what}")


def friction_steady_state_error(kp: float, coulomb: float, inertia: float, ki: float = 0.0) -> float:
    """How far short of the reference Coulomb friction unknown to the controller stops a joint.

    At rest the law's effort m kp e (+ m ki z) balances the friction; a PD can only do it with
    e = tau_c / (m kp), a PID's integral takes over and e = 0. This is the edge of the stick band
    |e| <= tau_c / (m kp) of ideal (sticking) Coulomb friction, where a joint ends that reaches
    it without overshooting (the error keeps the sign of the step). The smooth model of the
    plant creeps from there (:func:`friction_creep_time`).

    Parameters
    ----------
    kp : float
        Proportional gain (1/s^2), > 0.
    coulomb : float
        tau_c (N.m for a revolute joint, N for a prismatic one), >= 0.
    inertia : float
        m (kg.m^2 or kg), > 0: the joint's inertia at the operating point, 1 / (M^-1)_jj.
    ki : float
        Integral gain (1/s^3), >= 0.

    Returns
    -------
    float
        e = r - y at rest (rad or m), >= 0 for a step up.
    """
    kp, _, ki = check_gains(kp, 1.0, ki)
    coulomb = _positive("coulomb", coulomb, "N.m (N)", zero=True)
    inertia = _positive("inertia", inertia, "kg.m^2 (kg)")
    return 0.0 if ki > 0.0 else coulomb / (inertia * kp)


def friction_creep_time(kp: float, kd: float, ki: float, sample_time: float, coulomb: float, inertia: float,
                        velocity_scale: float, delay_steps: int = 0, damping: float = 0.0) -> float:
    """Time constant (s) with which the smooth Coulomb model lets the error creep out of the stick band.

    tau_c tanh(qd / v_s) is, for |qd| << v_s, a viscous term of slope tau_c / v_s: near rest the
    loop is :func:`sampled_prediction` with damping beta + tau_c / (m v_s), and the error decays
    with its slowest pole, -Ts / ln(:func:`spectral_radius`). A run much shorter than this ends on
    :func:`friction_steady_state_error`; a longer one ends closer to the reference.

    Parameters
    ----------
    kp, kd, ki : float
        Gains (1/s^2, 1/s, 1/s^3).
    sample_time : float
        Ts (s).
    coulomb, inertia : float
        tau_c (N.m or N) and m (kg.m^2 or kg), as in :func:`friction_steady_state_error`.
    velocity_scale : float
        v_s (rad/s or m/s), > 0.
    delay_steps : int
        d, in controller samples.
    damping : float
        beta = b / m (1/s) of the viscous friction.

    Returns
    -------
    float
        Seconds; inf if the linearized loop is not stable.
    """
    coulomb = _positive("coulomb", coulomb, "N.m (N)", zero=True)
    inertia = _positive("inertia", inertia, "kg.m^2 (kg)")
    velocity_scale = _positive("velocity_scale", velocity_scale, "rad/s (m/s)")
    beta = _positive("damping", damping, "1/s", zero=True) + coulomb / (inertia * velocity_scale)
    radius = spectral_radius(kp, kd, ki, sample_time, delay_steps, beta)
    return -float(sample_time) / math.log(radius) if radius < 1.0 else math.inf

"""Step responses of the computed-torque loop: co-simulation against linear predictions.

With a perfect model the computed-torque law

    tau = M(q) (qdd_ref + kd (qd_ref - qd) + kp (q_ref - q) + ki z) + N(q, qd),   z' = q_ref - q

turns every joint into a double integrator q'' = u driven by the outer PD/PID law u. A *step
experiment* holds ``q_ref = q0 + A`` (on one joint or all of them) from t = 0, with
``qd_ref = qdd_ref = 0``, starting from rest at ``q0``. Per joint, with y = q - q0 and r = A:

Continuous loop (:func:`error_dynamics`)
    y'' = kp (r - y) - kd y' + ki z, z' = r - y, hence

        Y/R = (kp s + ki) / (s^3 + kd s^2 + kp s + ki)        (PD: kp / (s^2 + kd s + kp)).

    The derivative acts on the measurement only, because qd_ref = 0 during a step. The
    textbook form (kd s^2 + kp s + ki) / (s^3 + kd s^2 + kp s + ki) is the same loop when
    qd_ref is the derivative of the reference step (an impulse: a "derivative kick"), which a
    constant input cannot deliver; it is available as ``velocity_reference=True`` for
    comparison but predicts half the rise time and nearly twice the overshoot (PD 400/20:
    29.8 % instead of 16.3 %) of what the FMUs show.

ZOH discretization of the continuous loop, option (b) (:func:`zoh_prediction`)
    ``control.c2d(T, h, 'zoh')``. It holds the *reference* between samples; for a step
    reference that is no approximation at all, so its step response is exactly the
    continuous response sampled at t_k. It still models a controller acting continuously.

Sampled-data loop (:func:`discrete_prediction`), what the FMUs implement
    The controller block computes tau at t_k from q_k, qd_k, holds it over [t_k, t_k + h)
    (zero-order hold) and advances z_{k+1} = z_k + h e_k (forward Euler). With tau held, the
    plant sees u_k held (up to the variation of M(q) and N(q, qd) within the step, see below),
    so per joint the double integrator 1/s^2 discretized with a ZOH,

        x_{k+1} = Phi x_k + Gamma u_k,  x = (y, y'),  Phi = [[1, h], [0, 1]],
        Gamma = [h^2 / 2, h]   (``control.c2d(ss(1/s^2), h, 'zoh')``),

    is closed by the *sampled* law

        u_k = kp (r - y_k) - kd y'_k + ki z_k,   z_{k+1} = z_k + h (r - y_k).

    The hold inside the loop acts like a delay of about h / 2 on the feedback: the sampled
    loop is less damped than the continuous one (more overshoot, by O(kd h) and O(wn h)), and
    c2d of the continuous loop misses exactly that. For the chess arm (0.02 rad on every
    joint) the sampled-data model matches the co-simulated FMUs to 0.18 % of the step height at
    every sample for h = 1 ms and to 0.9 % for h = 5 ms (PD and PID); the c2d model is off by
    0.6-0.7 % at 1 ms and 3-4 % at 5 ms. What remains is the variation of the gravity torque
    g(q) (and of M(q)) within a step while tau is held: the plant feels
    -M^-1 dg/dq (q - q_k), a perturbation of relative size about (h / 2) ||M^-1 dg/dq|| / kd.
    It is O(h), does not shrink with the step height, is largest on the light wrist joint and
    absent on the vertical first joint; Coriolis terms add errors quadratic in the height.

The step experiment does not start at y = 0 nor necessarily at t = 0, so :func:`step_metrics`
measures rise time, settling time, overshoot and peak relative to an initial value and time
(python-control's ``step_info`` assumes both are 0). :func:`design_gains` goes the other way:
gains from a requested 2 % settling time and overshoot, as MATLAB's
``updateErrorDynamicsFromStep`` does for its second-order error dynamics, but with the exact
second-order settling time instead of the 4 / (zeta wn) rule of thumb.

Co-simulation (:func:`cosimulate_step`): the diagram runs on the project's
:class:`~robofmu.system.master.Master`, Gauss-Seidel by default (``driver="jacobi"`` for its
Jacobi scheme).
"""
from __future__ import annotations

import argparse
import csv
import math
import sys
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import control
import numpy as np
from scipy.optimize import brentq

from .diagram import BlockSpec, System
from .master import Master, Result

__all__ = [
    "DEFAULT_Q0", "StepMetrics", "Comparison", "GainDesign",
    "error_dynamics", "discrete_prediction", "zoh_prediction", "predict",
    "step_metrics", "second_order_settling_time", "damping_from_overshoot",
    "step_system", "cosimulate_step", "compare", "design_gains", "plot_comparison",
    "write_csv", "add_step_command",
]

#: Default start pose of the chess arm for step experiments (rad).
DEFAULT_Q0 = (0.3, 0.8, -1.5, -0.87)

#: Names of the predictions, in the order they are reported.
MODELS = ("sampled", "zoh", "continuous")
_MODEL_TEXT = {
    "sampled": "sampled-data loop (ZOH plant, sampled PD/PID)",
    "zoh": "c2d(T_cont, h, 'zoh')",
    "continuous": "continuous T_cont(s)",
}


# -- linear models ------------------------------------------------------------------------------
def _check_gains(kp: float, kd: float, ki: float) -> tuple[float, float, float]:
    out = []
    for name, value in (("kp", kp), ("kd", kd), ("ki", ki)):
        value = float(value)
        if not (math.isfinite(value) and value >= 0.0):
            raise ValueError(f"{name}: gain must be finite and >= 0, got {value}")
        out.append(value)
    if out[0] <= 0.0:
        raise ValueError(f"kp: must be > 0 for a step to settle, got {out[0]}")
    return out[0], out[1], out[2]


def error_dynamics(kp: float, kd: float, ki: float = 0.0,
                   velocity_reference: bool = False) -> control.TransferFunction:
    """Continuous closed loop of one joint, from its reference position to its position.

    Parameters
    ----------
    kp, kd, ki : float
        Gains (1/s^2, 1/s, 1/s^3); ``ki = 0`` for PD.
    velocity_reference : bool
        False (default, the step experiment): qd_ref = qdd_ref = 0, so
        ``(kp s + ki) / (s^3 + kd s^2 + kp s + ki)``, PD ``kp / (s^2 + kd s + kp)``.
        True: qd_ref is the derivative of q_ref (unity-feedback PID on the error),
        ``(kd s^2 + kp s + ki) / (s^3 + kd s^2 + kp s + ki)``, PD ``(kd s + kp) / (s^2 + kd s + kp)``.

    Returns
    -------
    control.TransferFunction
        Continuous, SISO, unit DC gain (rad/rad).
    """
    kp, kd, ki = _check_gains(kp, kd, ki)
    if ki == 0.0:
        num = [kd, kp] if velocity_reference else [kp]
        return control.tf(num, [1.0, kd, kp])
    num = [kd, kp, ki] if velocity_reference else [kp, ki]
    return control.tf(num, [1.0, kd, kp, ki])


def zoh_prediction(kp: float, kd: float, ki: float, h: float,
                   velocity_reference: bool = False) -> control.TransferFunction:
    """``control.c2d(error_dynamics(...), h, 'zoh')``: the continuous loop with its reference held.

    Its step response equals the continuous step response at t_k = k h exactly (a step is
    constant between samples); it does not model the controller's own sampling and hold (see
    the module notes), so it is *not* the model of the co-simulated loop.

    Parameters
    ----------
    kp, kd, ki : float
        Gains (1/s^2, 1/s, 1/s^3).
    h : float
        Communication step (s), > 0.

    Returns
    -------
    control.TransferFunction
        Discrete, ``dt = h``.
    """
    h = _check_step(h)
    return control.c2d(error_dynamics(kp, kd, ki, velocity_reference), h, method="zoh")


def _check_step(h: float) -> float:
    h = float(h)
    if not (math.isfinite(h) and h > 0.0):
        raise ValueError(f"communication step h must be > 0 s, got {h}")
    return h


def discrete_prediction(kp: float, kd: float, ki: float, h: float) -> control.StateSpace:
    """The sampled-data loop the FMUs implement: ZOH double integrator, sampled PD/PID.

    The plant y'' = u (the arm seen through the computed-torque law) is discretized with
    ``control.c2d(..., method='zoh')``; the loop is closed with the law evaluated at the
    communication points, u_k = kp (r - y_k) - kd y'_k + ki z_k, z_{k+1} = z_k + h (r - y_k)
    (qd_ref = qdd_ref = 0). With Phi, Gamma the ZOH matrices of 1/s^2:

        [y, y']_{k+1} = (Phi - Gamma [kp, kd]) [y, y']_k + Gamma ki z_k + Gamma kp r
        z_{k+1}       = z_k - h y_k + h r

    Parameters
    ----------
    kp, kd, ki : float
        Gains (1/s^2, 1/s, 1/s^3); with ``ki = 0`` the integral state is dropped.
    h : float
        Communication step (s), > 0.

    Returns
    -------
    control.StateSpace
        Discrete (``dt = h``), input r (reference relative to the start, rad), output y
        (position relative to the start, rad); states (y, y'[, z]). Stable iff every
        eigenvalue of ``A`` is inside the unit circle.
    """
    kp, kd, ki = _check_gains(kp, kd, ki)
    h = _check_step(h)
    plant = control.c2d(control.ss([[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], [[1.0, 0.0]], [[0.0]]),
                        h, method="zoh")
    phi, gamma = np.asarray(plant.A), np.asarray(plant.B)
    k = np.array([[kp, kd]])
    if ki == 0.0:
        a = phi - gamma @ k
        b = gamma * kp
        c = np.array([[1.0, 0.0]])
    else:
        a = np.block([[phi - gamma @ k, gamma * ki],
                      [np.array([[-h, 0.0]]), np.ones((1, 1))]])
        b = np.vstack([gamma * kp, [[h]]])
        c = np.array([[1.0, 0.0, 0.0]])
    return control.ss(a, b, c, np.zeros((1, 1)), dt=h)


def predict(kp: float, kd: float, ki: float, t: np.ndarray, height: float = 1.0,
            model: str = "sampled", h: float | None = None) -> np.ndarray:
    """Predicted position change y(t) = q(t) - q0 of a joint after a reference step.

    Parameters
    ----------
    kp, kd, ki : float
        Gains (1/s^2, 1/s, 1/s^3).
    t : array_like, shape (n,)
        Times (s) from the step; for the discrete models multiples of ``h`` (``t[k] = k h``).
    height : float
        Step height A (rad).
    model : {"sampled", "zoh", "continuous"}
        :func:`discrete_prediction`, :func:`zoh_prediction` or :func:`error_dynamics`.
    h : float, optional
        Communication step (s); default ``t[1] - t[0]``.

    Returns
    -------
    numpy.ndarray, shape (n,)
        y(t) in rad (``height`` times the unit step response).
    """
    t = np.asarray(t, dtype=float)
    if model == "continuous":
        sys_ = error_dynamics(kp, kd, ki)
        # step_response wants a grid from 0: times are measured from the step
        tt = t - t[0]
        y = control.step_response(sys_, T=tt).outputs
        return height * np.asarray(y, dtype=float).reshape(-1)
    if h is None:
        h = float(t[1] - t[0])
    if model == "sampled":
        sys_ = discrete_prediction(kp, kd, ki, h)
    elif model == "zoh":
        sys_ = zoh_prediction(kp, kd, ki, h)
    else:
        raise ValueError(f"model {model!r}: choose one of {', '.join(MODELS)}")
    n = len(t)
    y = control.step_response(sys_, T=h * np.arange(n)).outputs
    return height * np.asarray(y, dtype=float).reshape(-1)


# -- metrics ------------------------------------------------------------------------------------
@dataclass
class StepMetrics:
    """Step-response characteristics, in the signal's own coordinates.

    Attributes
    ----------
    rise_time : float
        Time (s) from ``rise[0]`` to ``rise[1]`` of the change y0 -> yf.
    settling_time : float
        Time (s) after ``t0`` from which y stays within ``settling`` |yf - y0| of yf
        (nan if it never does within the record).
    overshoot, undershoot : float
        Percent of |yf - y0| beyond yf, and before y0 in the wrong direction (>= 0).
    peak : float
        Value of y where |y - y0| is largest (signal units).
    peak_change : float
        max |y - y0| (python-control's ``Peak`` of the offset-free signal).
    peak_time : float
        Time (s) after ``t0`` of that peak.
    settling_min, settling_max : float
        Extremes of y after the rise (yf included), signal units.
    steady_state : float
        yf.
    y0, t0 : float
        The initial value and time the metrics are relative to.
    """

    rise_time: float
    settling_time: float
    overshoot: float
    undershoot: float
    peak: float
    peak_change: float
    peak_time: float
    settling_min: float
    settling_max: float
    steady_state: float
    y0: float
    t0: float

    def step_info(self) -> dict:
        """The same metrics as python-control's ``step_info`` would give for y - y0, t - t0."""
        return {"RiseTime": self.rise_time, "SettlingTime": self.settling_time,
                "SettlingMin": self.settling_min - self.y0, "SettlingMax": self.settling_max - self.y0,
                "Overshoot": self.overshoot, "Undershoot": self.undershoot, "Peak": self.peak_change,
                "PeakTime": self.peak_time, "SteadyStateValue": self.steady_state - self.y0}


def _crossing(t: np.ndarray, x: np.ndarray, i: int, level: float) -> float:
    """Time where x crosses ``level`` between samples i - 1 and i (linear interpolation)."""
    if i <= 0 or x[i] == x[i - 1]:
        return float(t[i])
    return float(t[i - 1] + (level - x[i - 1]) * (t[i] - t[i - 1]) / (x[i] - x[i - 1]))


def step_metrics(t, y, y0: float | None = None, yf: float | None = None, t0: float | None = None,
                 settling: float = 0.02, rise: tuple[float, float] = (0.1, 0.9),
                 interpolate: bool = False) -> StepMetrics:
    """Rise time, settling time, overshoot and peak of a step response that need not start at 0.

    Parameters
    ----------
    t : array_like, shape (n,)
        Sample times (s), increasing.
    y : array_like, shape (n,)
        The response (any unit, e.g. rad).
    y0 : float, optional
        Value before the step; default y at ``t0``.
    yf : float, optional
        Final value; default ``y[-1]`` (as ``step_info``). Pass the known steady state if the
        record is too short to reach it.
    t0 : float, optional
        Time of the step (s); default ``t[0]``. Samples before it are ignored; every time
        reported is measured from it.
    settling : float
        Settling band as a fraction of |yf - y0| (0.02: 2 %).
    rise : (float, float)
        Rise-time limits as fractions of yf - y0.
    interpolate : bool
        False: sample-based like ``step_info`` (times are sample times; for y0 = 0, t0 = 0 the
        results equal ``step_info``'s). True: crossing times interpolated linearly between
        samples, peak refined by a parabola through three samples (for coarse grids).

    Returns
    -------
    StepMetrics
        All nan if yf == y0.
    """
    t = np.asarray(t, dtype=float).reshape(-1)
    y = np.asarray(y, dtype=float).reshape(-1)
    if t.shape != y.shape or t.size < 2:
        raise ValueError(f"t and y must have the same length >= 2, got {t.shape} and {y.shape}")
    if t0 is None:
        t0 = float(t[0])
    keep = t >= t0 - 1e-12 * max(1.0, abs(t0))
    t, y = t[keep], y[keep]
    if t.size < 2:
        raise ValueError(f"fewer than 2 samples at or after t0 = {t0}")
    y0 = float(y[0]) if y0 is None else float(y0)
    yf = float(y[-1]) if yf is None else float(yf)
    amp = yf - y0
    nan = float("nan")
    if amp == 0.0 or not math.isfinite(amp):
        return StepMetrics(nan, nan, nan, nan, nan, nan, nan, nan, nan, yf, y0, float(t0))
    x = (y - y0) / amp                      # 0 -> 1 whatever the sign of the step
    lo, hi = rise
    above_lo, above_hi = np.flatnonzero(x >= lo), np.flatnonzero(x >= hi)
    if above_lo.size and above_hi.size:
        i_lo, i_hi = int(above_lo[0]), int(above_hi[0])
        if interpolate:
            rise_time = _crossing(t, x, i_hi, hi) - _crossing(t, x, i_lo, lo)
        else:
            rise_time = float(t[i_hi] - t[i_lo])
    else:
        i_hi, rise_time = None, nan
    outside = np.flatnonzero(np.abs(x - 1.0) >= settling)
    if outside.size == 0:
        settling_time = 0.0
    elif outside[-1] + 1 >= t.size:
        settling_time = nan
    else:
        j = int(outside[-1]) + 1
        if interpolate:
            d = np.abs(x - 1.0)
            settling_time = _crossing(t, d, j, settling) - t0
        else:
            settling_time = float(t[j] - t0)
    overshoot = max(float(x.max()) - 1.0, 0.0) * 100.0
    undershoot = max(-float(x.min()), 0.0) * 100.0
    ip = int(np.argmax(np.abs(x)))
    peak_x, peak_t = float(x[ip]), float(t[ip])
    if interpolate and 0 < ip < t.size - 1:
        # vertex of the parabola through the three samples around the peak (uniform or not)
        ta, tb, tc = t[ip - 1:ip + 2]
        xa, xb, xc = x[ip - 1:ip + 2]
        denom = (ta - tb) * (ta - tc) * (tb - tc)
        a = (tc * (xb - xa) + tb * (xa - xc) + ta * (xc - xb)) / denom
        b = (tc**2 * (xa - xb) + tb**2 * (xc - xa) + ta**2 * (xb - xc)) / denom
        if a != 0.0:
            tv = -b / (2 * a)
            if ta < tv < tc:
                c = xb - a * tb**2 - b * tb
                peak_x, peak_t = float(a * tv**2 + b * tv + c), float(tv)
        if peak_x > 1.0:
            overshoot = max(overshoot, (peak_x - 1.0) * 100.0)
    if i_hi is not None:
        tail = y[i_hi:]
        settling_min, settling_max = min(float(tail.min()), yf), max(float(tail.max()), yf)
    else:
        settling_min = settling_max = nan
    return StepMetrics(rise_time=float(rise_time), settling_time=float(settling_time),
                       overshoot=overshoot, undershoot=undershoot, peak=y0 + peak_x * amp,
                       peak_change=abs(peak_x * amp), peak_time=peak_t - t0,
                       settling_min=settling_min, settling_max=settling_max, steady_state=yf,
                       y0=y0, t0=float(t0))


# -- second-order design --------------------------------------------------------------------------
def damping_from_overshoot(overshoot_percent: float) -> float:
    """Damping ratio zeta of kp / (s^2 + kd s + kp) whose step overshoots by ``overshoot_percent``.

    zeta = -ln(OS) / sqrt(pi^2 + ln(OS)^2), OS = overshoot_percent / 100; 1 for 0 %.
    """
    os_ = float(overshoot_percent) / 100.0
    if not (0.0 <= os_ < 1.0):
        raise ValueError(f"overshoot must be in [0, 100) %, got {overshoot_percent}")
    if os_ == 0.0:
        return 1.0
    ln = math.log(os_)
    return -ln / math.sqrt(math.pi**2 + ln**2)


def second_order_settling_time(zeta: float, wn: float = 1.0, settling: float = 0.02) -> float:
    """Exact settling time (s) of the step response of wn^2 / (s^2 + 2 zeta wn s + wn^2).

    The last time |1 - y(t)| equals ``settling``; solved with brentq on the bracket where it
    happens (underdamped: between the last extremum of the error above the band, at
    t = k pi / wd, and the next zero of the error). Discontinuous in zeta where an extremum
    touches the band. The rule of thumb 4 / (zeta wn) is its envelope approximation.
    """
    zeta, wn, band = float(zeta), float(wn), float(settling)
    if not (zeta > 0.0 and wn > 0.0 and 0.0 < band < 1.0):
        raise ValueError(f"need zeta > 0, wn > 0, 0 < settling < 1; got {zeta}, {wn}, {settling}")
    if zeta < 1.0:
        s = zeta                                  # wn = 1, scaled at the end
        wd = math.sqrt(1.0 - zeta**2)

        def err(tt):
            return math.exp(-s * tt) * (math.cos(wd * tt) + s / wd * math.sin(wd * tt))

        decay = s * math.pi / wd                  # |error| at t_k = k pi / wd is exp(-k decay)
        k = max(0, math.ceil(math.log(1.0 / band) / decay) - 1)
        while math.exp(-(k + 1) * decay) > band:  # guard against rounding in the ceil
            k += 1
        while k > 0 and math.exp(-k * decay) <= band:
            k -= 1
        ta = k * math.pi / wd
        tz = (math.atan2(s, wd) + math.pi / 2 + k * math.pi) / wd
        ts = brentq(lambda tt: abs(err(tt)) - band, ta, tz, xtol=1e-14, rtol=1e-14)
    elif zeta == 1.0:
        ts = brentq(lambda tt: math.exp(-tt) * (1.0 + tt) - band, 0.0, 50.0 - math.log(band),
                    xtol=1e-14, rtol=1e-14)
    else:
        r = math.sqrt(zeta**2 - 1.0)
        p1, p2 = zeta - r, zeta + r

        def err(tt):
            return (p2 * math.exp(-p1 * tt) - p1 * math.exp(-p2 * tt)) / (p2 - p1)

        upper = (math.log(p2 / ((p2 - p1) * band)) + 1.0) / p1
        ts = brentq(lambda tt: err(tt) - band, 0.0, upper, xtol=1e-14, rtol=1e-14)
    return ts / wn


@dataclass
class GainDesign:
    """Gains designed from a requested step response (see :func:`design_gains`).

    Attributes
    ----------
    kp, kd, ki : float
        Gains (1/s^2, 1/s, 1/s^3).
    zeta, wn : float
        Damping ratio and natural frequency (rad/s) of the dominant pole pair.
    settling_time, overshoot : float
        Requested 2 % settling time (s) and overshoot (%).
    ki_ratio : float or None
        Integral pole position p = ki_ratio zeta wn (None: PD).
    h : float or None
        Communication step (s) the design was refined for (None: continuous loop).
    predicted : StepMetrics
        Metrics of the designed loop's model (continuous, or sampled-data if ``h``).
    rule_of_thumb_wn : float
        4 / (zeta Ts) (rad/s), MATLAB/Ogata's envelope estimate, for comparison.
    iterations : int
        Refinement iterations of the returned design (0: closed form or first guess).
    converged : bool
        Whether the model's metrics are within ``tol`` of the request.
    """

    kp: float
    kd: float
    ki: float
    zeta: float
    wn: float
    settling_time: float
    overshoot: float
    ki_ratio: float | None
    h: float | None
    predicted: StepMetrics
    rule_of_thumb_wn: float
    iterations: int = 0
    converged: bool = True

    @property
    def gains(self) -> dict:
        return {"kp": self.kp, "kd": self.kd, "ki": self.ki}


def _gains_from_poles(zeta: float, wn: float, ki_ratio: float | None) -> tuple[float, float, float]:
    if ki_ratio is None:
        return wn**2, 2.0 * zeta * wn, 0.0
    p = ki_ratio * zeta * wn        # (s^2 + 2 zeta wn s + wn^2)(s + p)
    return wn**2 + 2.0 * zeta * wn * p, 2.0 * zeta * wn + p, wn**2 * p


def _model_metrics(kp, kd, ki, t_end, h, settling):
    if h is None:
        t = np.linspace(0.0, t_end, 8001)
        y = predict(kp, kd, ki, t, model="continuous")
    else:
        t = h * np.arange(int(round(t_end / h)) + 1)
        y = predict(kp, kd, ki, t, model="sampled", h=h)
    return step_metrics(t, y, y0=0.0, yf=1.0, settling=settling, interpolate=True)


def design_gains(settling_time: float, overshoot_percent: float, ki_ratio: float | None = None,
                 h: float | None = None, settling: float = 0.02, tol: float = 1e-4,
                 max_iter: int = 40) -> GainDesign:
    """Gains whose step response settles (2 %) in ``settling_time`` with ``overshoot_percent``.

    PD (``ki_ratio`` None, ``h`` None), as MATLAB's ``updateErrorDynamicsFromStep``: the loop
    is kp / (s^2 + kd s + kp), so zeta = :func:`damping_from_overshoot`, wn from the *exact*
    settling time wn = Ts_n(zeta) / Ts (:func:`second_order_settling_time` with wn = 1), and
    kp = wn^2, kd = 2 zeta wn. Exact, no iteration.

    PID (``ki_ratio`` > 0): the characteristic polynomial is placed at
    (s^2 + 2 zeta wn s + wn^2)(s + p) with p = ki_ratio zeta wn, i.e. kd = 2 zeta wn + p,
    kp = wn^2 + 2 zeta wn p, ki = wn^2 p; the zero of (kp s + ki) and the extra pole then move
    the response, so (zeta, wn) are refined until the loop's own metrics hit the request:
    zeta += zeta(OS_req) - zeta(OS_achieved), wn *= Ts_achieved / Ts_req. Small ratios
    (about 0.005 .. 0.02; the seed PID 600/25/75 is 0.0101) keep the slow integral pole nearly
    cancelled by the zero: its residue, about 2 zeta^2 ki_ratio, stays inside the 2 % band.
    Around 0.05 .. 0.5 that slow tail dominates the settling time and the design runs to very
    large gains or does not converge; large ratios (>= 2, a fast integral pole) converge to
    overdamped "dominant pairs" whose zeta and wn no longer describe the response. A design
    that does not reach ``tol`` is returned as the best iterate with ``converged`` False (and a
    RuntimeWarning).

    With ``h`` the same refinement is done on the sampled-data loop (:func:`discrete_prediction`)
    instead of the continuous one, so that the co-simulation at step ``h`` hits the request.

    Parameters
    ----------
    settling_time : float
        Requested settling time (s), > 0.
    overshoot_percent : float
        Requested overshoot (%), in [0, 100).
    ki_ratio : float, optional
        > 0 for PID (see above); None for PD.
    h : float, optional
        Communication step (s) to design the sampled loop for.
    settling : float
        Settling band (0.02: 2 %).
    tol : float
        Relative tolerance on both metrics for the refinement (overshoot: relative to the
        requested value, absolute 1e-3 % for a 0 % request).

    Returns
    -------
    GainDesign
    """
    ts_req = float(settling_time)
    if not (math.isfinite(ts_req) and ts_req > 0.0):
        raise ValueError(f"settling time must be > 0 s, got {settling_time}")
    zeta0 = damping_from_overshoot(overshoot_percent)
    if ki_ratio is not None and not (math.isfinite(ki_ratio) and ki_ratio > 0.0):
        raise ValueError(f"ki_ratio must be > 0 (or None for PD), got {ki_ratio}")
    if h is not None:
        h = _check_step(h)
    wn0 = second_order_settling_time(zeta0, 1.0, settling) / ts_req
    rule = 4.0 / (zeta0 * ts_req)
    t_end = 4.0 * ts_req
    os_req = float(overshoot_percent)
    zeta, wn = zeta0, wn0
    kp, kd, ki = _gains_from_poles(zeta, wn, ki_ratio)
    metrics = _model_metrics(kp, kd, ki, t_end, h, settling)
    if ki_ratio is None and h is None:
        return GainDesign(kp, kd, ki, zeta, wn, ts_req, os_req, None, None, metrics, rule, 0)

    def error(m: StepMetrics) -> float:
        e_ts = abs(m.settling_time / ts_req - 1.0) if math.isfinite(m.settling_time) else math.inf
        e_os = abs(m.overshoot - os_req) / os_req if os_req > 0 else abs(m.overshoot) / 1e-3 * tol
        return max(e_ts, e_os)

    best = (error(metrics), kp, kd, ki, zeta, wn, metrics, 0)
    for it in range(1, max_iter + 1):
        if best[0] <= tol:
            break
        os_now = min(max(metrics.overshoot, 1e-9), 99.0)
        zeta = min(max(zeta + zeta0 - damping_from_overshoot(os_now if os_req > 0 else 0.0), 0.05), 3.0)
        if math.isfinite(metrics.settling_time) and metrics.settling_time > 0:
            wn *= metrics.settling_time / ts_req
        else:
            wn *= 1.5
        kp, kd, ki = _gains_from_poles(zeta, wn, ki_ratio)
        metrics = _model_metrics(kp, kd, ki, t_end, h, settling)
        e = error(metrics)
        if e < best[0]:
            best = (e, kp, kd, ki, zeta, wn, metrics, it)
    err, kp, kd, ki, zeta, wn, metrics, it = best
    converged = err <= tol
    if not converged:
        warnings.warn(f"design_gains: Ts {ts_req:g} s, overshoot {os_req:g} %, ki_ratio {ki_ratio}: not "
                      f"reached within {tol:g} (best: Ts {metrics.settling_time:.4g} s, overshoot "
                      f"{metrics.overshoot:.4g} %)", RuntimeWarning, stacklevel=2)
    return GainDesign(kp, kd, ki, zeta, wn, ts_req, os_req, ki_ratio, h, metrics, rule, it, converged)


# -- co-simulation ------------------------------------------------------------------------------------
def _joints(joint: int | Sequence[int] | None, n: int) -> list[int]:
    if joint is None:
        return list(range(1, n + 1))
    js = [joint] if isinstance(joint, (int, np.integer)) else list(joint)
    for j in js:
        if not 1 <= int(j) <= n:
            raise ValueError(f"joint {j}: joints are numbered 1 .. {n}")
    return [int(j) for j in js]


def step_system(fmu_root: str | Path, kp: float, kd: float, ki: float = 0.0, step: float = 0.02,
                h: float = 1e-3, t_end: float = 1.0, joint: int | Sequence[int] | None = None,
                q0: Sequence[float] = DEFAULT_Q0, robot: str = "chess") -> System:
    """The step-experiment diagram: controller + plant, q and qd fed back, tau forward.

    The controller's q_ref input (unconnected) starts at q0 + step on the stepped joints;
    qd_ref, qdd_ref and grip keep their start values 0 / false (the master warns that they are
    unconnected). The controller's model is the plant's (same g, no payload: grip is open).

    Parameters
    ----------
    fmu_root : str or Path
        Folder holding ``<robot>/controller.fmu`` and ``<robot>/plant.fmu``.
    kp, kd, ki : float
        Gains (1/s^2, 1/s, 1/s^3).
    step : float
        Step height A (rad).
    h, t_end : float
        Communication step and stop time (s).
    joint : int, sequence of int or None
        Stepped joint(s), numbered from 1 like the FMU variables; None: all.
    q0 : sequence of float, shape (n,)
        Start pose (rad), at rest.
    """
    kp, kd, ki = _check_gains(kp, kd, ki)
    q0 = np.asarray(q0, dtype=float).reshape(-1)
    js = _joints(joint, q0.size)
    q_ref = q0.copy()
    q_ref[np.array(js) - 1] += float(step)
    return System(
        blocks=[BlockSpec("controller", f"{robot}/controller.fmu",
                          {"kp": kp, "kd": kd, "ki": ki, "payload_mass": 0.0, "q_ref": q_ref.tolist()}),
                BlockSpec("plant", f"{robot}/plant.fmu", {"q0": q0.tolist()})],
        wires=["plant.q -> controller.q", "plant.qd -> controller.qd", "controller.tau -> plant.tau"],
        fmu_dir=Path(fmu_root), name=f"{robot}-step", stop_time=float(t_end), step=float(h),
        description=f"reference step of {step} rad on joint(s) {js}")


def cosimulate_step(fmu_root: str | Path, kp: float, kd: float, ki: float = 0.0, step: float = 0.02,
                    h: float = 1e-3, t_end: float = 1.0, joint: int | Sequence[int] | None = None,
                    q0: Sequence[float] = DEFAULT_Q0, robot: str = "chess",
                    driver: str = "master") -> Result:
    """Co-simulate a reference step of the computed-torque loop (controller + plant FMUs).

    Parameters
    ----------
    fmu_root : str or Path
        Folder holding ``<robot>/{controller,plant}.fmu`` (e.g. ``fmus``).
    kp, kd, ki : float
        Gains (1/s^2, 1/s, 1/s^3).
    step : float
        Step height A (rad), e.g. 0.01 .. 0.05.
    h : float
        Communication step (s).
    t_end : float
        Stop time (s), a whole number of steps.
    joint : int, sequence of int or None
        Stepped joint(s), from 1; None: every joint.
    q0 : sequence of float, shape (n,)
        Start pose (rad).
    driver : {"master", "jacobi"}
        :class:`~robofmu.system.master.Master` with Gauss-Seidel ("master") or Jacobi.

    Returns
    -------
    Result
        Recorded ``plant.q[i]``, ``plant.qd[i]`` (rad, rad/s), ``controller.tau[i]`` (N.m) at
        t_k = k h, shape (n_steps + 1,) each; ``info`` adds ``kp, kd, ki, h, height, joints,
        q0 (list), q_ref (list), driver, warnings``.
    """
    h = _check_step(h)
    system = step_system(fmu_root, kp, kd, ki, step, h, t_end, joint, q0, robot)
    q0a = np.asarray(q0, dtype=float).reshape(-1)
    if driver not in ("master", "jacobi"):
        raise ValueError(f"driver {driver!r}: choose master or jacobi")
    master = Master(system, record=["plant.q*", "controller.tau*"])
    diagram_warnings = master.check()
    result = master.run(float(t_end), h, "jacobi" if driver == "jacobi" else "gauss-seidel")
    result.info.update(kp=float(kp), kd=float(kd), ki=float(ki), h=h, height=float(step),
                       joints=_joints(joint, q0a.size), q0=q0a.tolist(),
                       q_ref=system.block("controller").parameters["q_ref"], driver=driver,
                       robot=robot, warnings=diagram_warnings)
    return result


# -- comparison --------------------------------------------------------------------------------------
@dataclass
class Comparison:
    """A co-simulated step against the linear predictions (see :func:`compare`).

    Attributes
    ----------
    time : ndarray, shape (n,)
        Communication points (s).
    height : float
        Step height (rad).
    joints : list of int
        Stepped joints (from 1).
    response : ndarray, shape (n, len(joints))
        Co-simulated q - q0 of the stepped joints (rad).
    crosstalk : ndarray, shape (n, n_joints - len(joints))
        Co-simulated q - q0 of the other joints (rad; 0 with perfect decoupling).
    predictions : dict of str -> ndarray, shape (n,)
        q - q0 predicted by each model in :data:`MODELS` (rad).
    deviation : dict of str -> ndarray, shape (len(joints),)
        max over samples of |co-simulated - predicted| in % of |height|, per stepped joint.
    crosstalk_percent : float
        max |q - q0| of the unstepped joints in % of |height| (0 if all are stepped).
    metrics : dict of str -> StepMetrics
        ``"joint <j>"`` for each co-simulated joint (absolute positions, rad) and one per model
        (absolute: q0 of the first stepped joint added).
    result : Result
        The co-simulation.
    gains : dict
        kp, kd, ki.
    h : float
        Communication step (s).
    """

    time: np.ndarray
    height: float
    joints: list
    response: np.ndarray
    crosstalk: np.ndarray
    predictions: dict
    deviation: dict
    crosstalk_percent: float
    metrics: dict
    result: Result
    gains: dict
    h: float
    driver: str = "master"
    q0: list = field(default_factory=list)

    def best(self) -> str:
        """The model with the smallest max deviation."""
        return min(self.deviation, key=lambda m: float(np.max(self.deviation[m])))

    def max_deviation(self, model: str = "sampled") -> float:
        """max over joints and samples of |co-simulated - predicted|, % of the height."""
        return float(np.max(self.deviation[model]))

    def table(self) -> str:
        """Metrics of every joint and model, then the deviations, as aligned text."""
        g = self.gains
        lines = [f"step {self.height:g} rad on joint(s) {', '.join(map(str, self.joints))}; "
                 f"kp {g['kp']:g}, kd {g['kd']:g}, ki {g['ki']:g}; h {self.h * 1e3:g} ms; "
                 f"driver {self.driver}",
                 f"{'response':<24}{'rise (s)':>10}{'settle (s)':>12}{'overshoot %':>13}"
                 f"{'peak time (s)':>15}{'peak (rad)':>12}{'final (rad)':>13}"]
        for name, m in self.metrics.items():
            lines.append(f"{name:<24}{m.rise_time:>10.4f}{m.settling_time:>12.4f}{m.overshoot:>13.3f}"
                         f"{m.peak_time:>15.4f}{m.peak:>12.5f}{m.steady_state:>13.5f}")
        lines.append("max |co-simulated - predicted| over all samples, % of the step height:")
        for model in self.deviation:
            dev = ", ".join(f"j{j} {d:.3f}" for j, d in zip(self.joints, self.deviation[model]))
            lines.append(f"  {model:<11} {self.max_deviation(model):8.3f} %   ({dev})  "
                         f"{_MODEL_TEXT[model]}")
        if self.crosstalk.size:
            lines.append(f"  unstepped joints moved by at most {self.crosstalk_percent:.3f} % of the height")
        lines.append(f"best match: {self.best()}")
        return "\n".join(lines)


def compare(result: Result, models: Sequence[str] = MODELS, settling: float = 0.02,
            interpolate: bool = True) -> Comparison:
    """Compare a co-simulated step (from :func:`cosimulate_step`) with the linear predictions.

    Parameters
    ----------
    result : Result
        From :func:`cosimulate_step` (its ``info`` carries gains, h, height, joints, q0).
    models : sequence of str
        Predictions to compute, from :data:`MODELS`.
    settling : float
        Settling band for the metrics (0.02: 2 %).
    interpolate : bool
        Passed to :func:`step_metrics`.

    Returns
    -------
    Comparison
        Deviations (max over samples of |co-simulated - predicted|, % of the height) and the
        metrics of both (steady state taken as the reference q0 + height, which a perfect
        model reaches; the record may end before the PID's slow integral mode has).
    """
    info = result.info
    kp, kd, ki, h, height = info["kp"], info["kd"], info["ki"], info["h"], info["height"]
    joints, q0 = list(info["joints"]), np.asarray(info["q0"], dtype=float)
    q = result.vector("plant.q")
    t = result.time
    y = q - q0
    idx = np.array(joints) - 1
    others = np.array([i for i in range(q0.size) if i not in set(idx)], dtype=int)
    response = y[:, idx]
    crosstalk = y[:, others] if others.size else np.zeros((len(t), 0))
    predictions, deviation = {}, {}
    for model in models:
        p = predict(kp, kd, ki, t - t[0], height, model, h)
        predictions[model] = p
        deviation[model] = np.max(np.abs(response - p[:, None]), axis=0) / abs(height) * 100.0
    metrics = {}
    for j, col in zip(joints, response.T):
        metrics[f"joint {j}"] = step_metrics(t, col + q0[j - 1], y0=q0[j - 1], yf=q0[j - 1] + height,
                                             settling=settling, interpolate=interpolate)
    base = q0[joints[0] - 1]
    for model, p in predictions.items():
        metrics[model] = step_metrics(t, p + base, y0=base, yf=base + height, settling=settling,
                                      interpolate=interpolate)
    ct = float(np.max(np.abs(crosstalk)) / abs(height) * 100.0) if crosstalk.size else 0.0
    return Comparison(time=t, height=height, joints=joints, response=response, crosstalk=crosstalk,
                      predictions=predictions, deviation=deviation, crosstalk_percent=ct,
                      metrics=metrics, result=result, gains={"kp": kp, "kd": kd, "ki": ki}, h=h,
                      driver=info.get("driver", "master"), q0=q0.tolist())


# -- output -------------------------------------------------------------------------------------------
def write_csv(comparison: Comparison, path: str | Path) -> Path:
    """``time``, co-simulated q - q0 of each stepped joint, then each prediction (rad)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    c = comparison
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["time"] + [f"cosim_q{j}" for j in c.joints] + [f"pred_{m}" for m in c.predictions])
        for k, tk in enumerate(c.time):
            w.writerow([repr(float(tk))] + [repr(float(v)) for v in c.response[k]]
                       + [repr(float(c.predictions[m][k])) for m in c.predictions])
    return path


def plot_comparison(comparison: Comparison, out_dir: str | Path, name: str | None = None) -> Path:
    """Figure of the co-simulated step against the continuous, c2d and sampled-data predictions.

    Top: q - q0 (rad) of each stepped joint and the predictions; bottom: co-simulated minus
    predicted, in % of the step height, with the 1 % band.

    Parameters
    ----------
    comparison : Comparison
    out_dir : str or Path
        Folder for the PNG (created).
    name : str, optional
        File stem; default from gains and step.

    Returns
    -------
    Path
        The PNG written.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    c = comparison
    g = c.gains
    if name is None:
        name = (f"step_kp{g['kp']:g}_kd{g['kd']:g}_ki{g['ki']:g}_h{c.h * 1e3:g}ms_"
                f"j{'-'.join(map(str, c.joints))}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(8, 7), sharex=True,
                                  gridspec_kw={"height_ratios": [3, 2]})
    styles = {"continuous": dict(color="k", lw=1.2, ls="-"),
              "zoh": dict(color="tab:orange", lw=0, marker=".", ms=3),
              "sampled": dict(color="tab:blue", lw=1.2, ls="--")}
    for j, col in zip(c.joints, c.response.T):
        ax.plot(c.time, col, lw=2.5, alpha=0.45, label=f"co-simulated, joint {j}")
    for model, p in c.predictions.items():
        ax.plot(c.time, p, label=_MODEL_TEXT[model], **styles.get(model, {}))
        for k, (j, col) in enumerate(zip(c.joints, c.response.T)):
            ax2.plot(c.time, (col - p) / abs(c.height) * 100.0, color=styles[model]["color"],
                     lw=0.9 if model != "continuous" else 0.7, ls=":" if model == "continuous" else "-",
                     alpha=0.85, label=(f"vs {model} (max {c.max_deviation(model):.2f} %)" if k == 0 else None))
    for s in (-1.0, 1.0):
        ax2.axhline(s, color="grey", ls=":", lw=0.8)
    ax2.plot([], [], color="grey", ls=":", label="1 % of the step")
    ax.axhline(c.height, color="grey", lw=0.6)
    ax.set_ylabel("q - q0 (rad)")
    ax.set_title(f"Step {c.height:g} rad: kp {g['kp']:g}, kd {g['kd']:g}, ki {g['ki']:g}, "
                 f"h = {c.h * 1e3:g} ms ({c.driver})")
    ax.legend(fontsize=8)
    ax2.set_xlabel("t (s)")
    ax2.set_ylabel("co-sim - prediction (% of step)")
    ax2.legend(fontsize=7, ncol=2)
    for a in (ax, ax2):
        a.grid(alpha=0.3)
    fig.tight_layout()
    path = out / f"{name}.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


# -- command line ---------------------------------------------------------------------------------------
def _step_command(args) -> int:
    from robofmu.components.robot import load_spec

    design = None
    if args.settling_time is not None or args.overshoot is not None:
        if args.settling_time is None or args.overshoot is None:
            print("robofmu step: --settling-time and --overshoot go together", file=sys.stderr)
            return 2
        try:
            design = design_gains(args.settling_time, args.overshoot, ki_ratio=args.ki_ratio,
                                  h=args.step_size if args.design_for_step else None)
        except ValueError as exc:
            print(f"robofmu step: {exc}", file=sys.stderr)
            return 2
        kp, kd, ki = design.kp, design.kd, design.ki
    else:
        try:
            seed = load_spec(args.robot).gains(args.gains)
        except ValueError as exc:
            print(f"robofmu step: {exc}", file=sys.stderr)
            return 2
        kp = seed["kp"] if args.kp is None else args.kp
        kd = seed["kd"] if args.kd is None else args.kd
        ki = seed["ki"] if args.ki is None else args.ki
    t_end = args.t_end
    if t_end is None:
        t_end = max(1.0, 3.0 * args.settling_time) if design else 1.0
    t_end = round(t_end / args.step_size) * args.step_size
    try:
        result = cosimulate_step(Path(args.fmus), kp, kd, ki, step=args.height, h=args.step_size,
                                 t_end=t_end, joint=args.joint, q0=args.q0 or DEFAULT_Q0,
                                 robot=args.robot, driver=args.driver)
    except Exception as exc:        # DiagramError, SimulationError, ValueError: one line each
        print(f"robofmu step: {exc}", file=sys.stderr)
        return 1
    comparison = compare(result)
    if design is not None:
        print(f"design: settling time {design.settling_time:g} s, overshoot {design.overshoot:g} % -> "
              f"zeta {design.zeta:.4f}, wn {design.wn:.4f} rad/s (rule of thumb 4/(zeta Ts): "
              f"{design.rule_of_thumb_wn:.4f}); kp {kp:.6g}, kd {kd:.6g}, ki {ki:.6g}"
              + (f"; refined for h = {design.h:g} s" if design.h else ""))
    print(comparison.table())
    if design is not None:
        for j in comparison.joints:
            m = comparison.metrics[f"joint {j}"]
            os_dev = (f"{(m.overshoot / design.overshoot - 1) * 100:+.2f} %" if design.overshoot
                      else "requested 0")
            print(f"achieved, joint {j}: settling {m.settling_time:.4f} s "
                  f"({(m.settling_time / design.settling_time - 1) * 100:+.2f} %), overshoot "
                  f"{m.overshoot:.3f} % ({os_dev})")
    if args.out:
        out = Path(args.out)
        stem = f"step_h{args.step_size * 1e3:g}ms"
        result.to_csv(out / f"{stem}_cosim.csv")
        write_csv(comparison, out / f"{stem}_compare.csv")
        fig = plot_comparison(comparison, out, stem)
        print(f"wrote {out / (stem + '_cosim.csv')}, {out / (stem + '_compare.csv')}, {fig}")
    return 0


def add_step_command(subparsers) -> argparse.ArgumentParser:
    """Register ``robofmu step`` on an argparse ``subparsers`` object; returns its parser."""
    p = subparsers.add_parser(
        "step", help="co-simulate a joint reference step and compare it with linear predictions",
        description="Co-simulate a reference step of the computed-torque loop (controller + plant "
                    "FMUs), print rise/settling time, overshoot and peak of the co-simulated "
                    "response and of three linear predictions (continuous error dynamics, its "
                    "c2d ZOH discretization, the sampled-data loop), and their max deviation in "
                    "%% of the step height. Gains: the robot's seed gains (--gains), explicit "
                    "values (--kp/--kd/--ki), or designed from --settling-time and --overshoot.")
    p.add_argument("--gains", choices=("pd", "pid"), default="pd", help="seed gains (default: pd)")
    p.add_argument("--kp", type=float, help="proportional gain (1/s^2), overrides --gains")
    p.add_argument("--kd", type=float, help="derivative gain (1/s)")
    p.add_argument("--ki", type=float, help="integral gain (1/s^3)")
    p.add_argument("--settling-time", type=float, metavar="T", help="design gains: 2%% settling time (s)")
    p.add_argument("--overshoot", type=float, metavar="P", help="design gains: overshoot (%%)")
    p.add_argument("--ki-ratio", type=float, metavar="R",
                   help="design a PID: integral pole at R zeta wn (e.g. 0.05); default PD")
    p.add_argument("--design-for-step", action="store_true",
                   help="refine the design on the sampled-data loop at --step-size")
    p.add_argument("--step-size", type=float, default=1e-3, metavar="H",
                   help="communication step (s, default 0.001)")
    p.add_argument("--height", type=float, default=0.02, metavar="A", help="step height (rad, default 0.02)")
    p.add_argument("--joint", type=int, metavar="J", help="step joint J only (from 1; default: all)")
    p.add_argument("--q0", type=float, nargs="+", metavar="Q", help=f"start pose (rad, default {DEFAULT_Q0})")
    p.add_argument("--t-end", type=float, metavar="T", help="stop time (s; default 1, or 3 x settling time)")
    p.add_argument("--driver", choices=("master", "jacobi"), default="master",
                   help="co-simulation driver (default master: the project's Gauss-Seidel master)")
    p.add_argument("--robot", default="chess", help="robot (default chess)")
    p.add_argument("--fmus", default="fmus", metavar="DIR", help="FMU root holding ROBOT/*.fmu (default fmus)")
    p.add_argument("--out", metavar="DIR", help="write CSVs and the figure here")
    p.set_defaults(func=_step_command)
    return p


def main(argv: list[str] | None = None) -> int:
    """``python -m robofmu.system.stepresponse ...``: the ``step`` command on its own."""
    parser = argparse.ArgumentParser(prog="robofmu")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    add_step_command(sub)
    args = parser.parse_args(["step", *(argv if argv is not None else sys.argv[1:])])
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())

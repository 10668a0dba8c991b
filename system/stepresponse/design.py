"""Gain design: kp, kd (and ki) from a requested 2 % settling time and overshoot.

As MATLAB's ``updateErrorDynamicsFromStep`` does for its second-order error dynamics, but with
the exact second-order settling time (:func:`~.metrics.second_order_settling_time`) instead of
the 4 / (zeta wn) rule of thumb, an iterative refinement for PID, and optionally for the
sampled-data loop of a given communication step (:func:`~.linear.discrete_prediction`). The
gains are per unit of joint coordinate, so one design serves revolute and prismatic joints.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from robofmu.system.stepresponse.linear import check_step, predict
from robofmu.system.stepresponse.metrics import StepMetrics, damping_from_overshoot, second_order_settling_time, step_metrics

__all__ = ["GainDesign", "design_gains"]


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
        """``{"kp": ..., "kd": ..., "ki": ...}`` (1/s^2, 1/s, 1/s^3)."""
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
    is kp / (s^2 + kd s + kp), so zeta = :func:`~.metrics.damping_from_overshoot`, wn from the *exact*
    settling time wn = Ts_n(zeta) / Ts (:func:`~.metrics.second_order_settling_time` with wn = 1), and
    kp = wn^2, kd = 2 zeta wn. Exact, no iteration.

    PID (``ki_ratio`` > 0): the characteristic polynomial is placed at
    (s^2 + 2 zeta wn s + wn^2)(s + p) with p = ki_ratio zeta wn, i.e. kd = 2 zeta wn + p,
    kp = wn^2 + 2 zeta wn p, ki = wn^2 p; the zero of (kp s + ki) and the extra pole then move
    the response, so (zeta, wn) are refined until the loop's own metrics hit the request:
    zeta += zeta(OS_req) - zeta(OS_achieved), wn *= Ts_achieved / Ts_req. Small ratios
    (about 0.005 .. 0.02; kp, kd, ki = 600, 25, 75 is 0.0101) keep the slow integral pole nearly
    cancelled by the zero: its residue, about 2 zeta^2 ki_ratio, stays inside the 2 % band.
    Around 0.05 .. 0.5 that slow tail dominates the settling time and the design runs to very
    large gains or does not converge; large ratios (>= 2, a fast integral pole) converge to
    overdamped "dominant pairs" whose zeta and wn no longer describe the response. A design
    that does not reach ``tol`` is returned as the best iterate with ``converged`` False (and a
    RuntimeWarning).

    With ``h`` the same refinement is done on the sampled-data loop (:func:`~.linear.discrete_prediction`)
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
    max_iter : int
        Most refinement iterations (PID, or with ``h``).

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
        h = check_step(h)
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

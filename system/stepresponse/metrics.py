"""Step-response metrics relative to an initial value and time, and second-order formulas.

A step experiment neither starts at y = 0 nor necessarily at t = 0, so :func:`step_metrics`
measures rise time, settling time, overshoot and peak relative to an initial value and time
(python-control's ``step_info`` assumes both are 0). :func:`damping_from_overshoot` and
:func:`second_order_settling_time` are the closed forms of the standard second-order loop
wn^2 / (s^2 + 2 zeta wn s + wn^2) that gain design inverts; the settling time is the exact one,
not the 4 / (zeta wn) rule of thumb.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

__all__ = ["StepMetrics", "step_metrics", "damping_from_overshoot", "second_order_settling_time"]


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
        The response (any unit, e.g. rad or m).
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


def damping_from_overshoot(overshoot_percent: float) -> float:
    """Damping ratio zeta of kp / (s^2 + kd s + kp) whose step overshoots by ``overshoot_percent``.

    zeta = -ln(OS) / sqrt(pi^2 + ln(OS)^2), OS = overshoot_percent / 100; 1 for 0 %.

    Parameters
    ----------
    overshoot_percent : float
        Overshoot (%), in [0, 100).

    Returns
    -------
    float
        zeta, in (0, 1].
    """
    overshoot = float(overshoot_percent) / 100.0
    if not (0.0 <= overshoot < 1.0):
        raise ValueError(f"overshoot must be in [0, 100) %, got {overshoot_percent}")
    if overshoot == 0.0:
        return 1.0
    log_overshoot = math.log(overshoot)
    return -log_overshoot / math.sqrt(math.pi**2 + log_overshoot**2)


def second_order_settling_time(zeta: float, wn: float = 1.0, settling: float = 0.02) -> float:
    """Exact settling time (s) of the step response of wn^2 / (s^2 + 2 zeta wn s + wn^2).

    The last time |1 - y(t)| equals ``settling``; solved with brentq on the bracket where it
    happens (underdamped: between the last extremum of the error above the band, at
    t = k pi / wd, and the next zero of the error). Discontinuous in zeta where an extremum
    touches the band. The rule of thumb 4 / (zeta wn) is its envelope approximation.

    Parameters
    ----------
    zeta : float
        Damping ratio, > 0.
    wn : float
        Natural frequency (rad/s), > 0.
    settling : float
        Settling band as a fraction of the step, in (0, 1) (0.02: 2 %).

    Returns
    -------
    float
        Settling time (s).
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

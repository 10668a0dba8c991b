"""Linear models of one joint's step response under the computed-torque law.

With a perfect model the computed-torque law

    tau = M(q) (qdd_ref + kd (qd_ref - qd) + kp (q_ref - q) + ki z) + N(q, qd),   z' = q_ref - q

turns every joint into a double integrator q'' = u driven by the outer PD/PID law u, whatever
the joint's kind: q is an angle (rad) for a revolute joint, a length (m) for a prismatic one,
and every model below is the same in both (it maps reference to position, unit to the same
unit). A *step experiment* holds ``q_ref = q0 + A`` from t = 0, with ``qd_ref = qdd_ref = 0``,
starting from rest at ``q0``. Per joint, with y = q - q0 and r = A:

Continuous loop (:func:`error_dynamics`)
    y'' = kp (r - y) - kd y' + ki z, z' = r - y, hence

        Y/R = (kp s + ki) / (s^3 + kd s^2 + kp s + ki)        (PD: kp / (s^2 + kd s + kp)).

    The derivative acts on the measurement only, because qd_ref = 0 during a step. The
    textbook form (kd s^2 + kp s + ki) / (s^3 + kd s^2 + kp s + ki) is the same loop when
    qd_ref is the derivative of the reference step (an impulse: a "derivative kick"), which a
    constant input cannot deliver; it is available as ``velocity_reference=True`` for
    comparison but predicts half the rise time and nearly twice the overshoot (PD 400/20:
    29.8 % instead of 16.3 %) of what the FMUs show.

ZOH discretization of the continuous loop (:func:`zoh_prediction`)
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
    c2d of the continuous loop misses exactly that. What the sampled-data model leaves out is
    the variation of the gravity effort g(q) (and of M(q)) within a step while tau is held:
    the plant feels -M^-1 dg/dq (q - q_k), a perturbation of relative size about
    (h / 2) ||M^-1 dg/dq|| / kd. It is O(h), does not shrink with the amplitude, is largest
    on joints whose inertia is small against the slope of their gravity load and absent where
    gravity does not depend on q (a joint about the vertical, a vertical slide); Coriolis
    terms add errors quadratic in the amplitude. ``tests/test_stepresponse.py`` holds every
    described robot to 1 % of the amplitude at every sample for h = 1 ms.

    A controller sampling at its own Ts = N h, its effort held over Ts and output d samples
    late, and joint friction unknown to it, are :mod:`.sampled`'s (``sampled_prediction``,
    ``predict_sampled``, ``largest_stable_kp``); with Ts = h and d = 0 it is this model.

The gains follow the project's one rule (:func:`robofmu.components.control.check_gains`:
kp > 0, kd > 0, ki >= 0); every model below refuses others with a ParameterError naming the gain.
"""
from __future__ import annotations

import math

import control
import numpy as np

from robofmu.components.control import check_gains

__all__ = ["MODELS", "MODEL_TEXT", "check_step", "error_dynamics", "zoh_prediction", "discrete_prediction",
           "predict"]

#: Names of the predictions, in the order they are reported.
MODELS = ("sampled", "zoh", "continuous")

#: One line describing each prediction, for tables and legends.
MODEL_TEXT = {
    "sampled": "sampled-data loop (ZOH plant, sampled PD/PID)",
    "zoh": "c2d(T_cont, h, 'zoh')",
    "continuous": "continuous T_cont(s)",
}


def check_step(h: float) -> float:
    """The communication step ``h`` (s) as a float; ValueError unless it is finite and > 0."""
    h = float(h)
    if not (math.isfinite(h) and h > 0.0):
        raise ValueError(f"communication step h must be > 0 s, got {h}")
    return h


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
        Continuous, SISO, unit DC gain (joint unit per joint unit: rad/rad or m/m).
    """
    kp, kd, ki = check_gains(kp, kd, ki)
    if ki == 0.0:
        numerator = [kd, kp] if velocity_reference else [kp]
        return control.tf(numerator, [1.0, kd, kp])
    numerator = [kd, kp, ki] if velocity_reference else [kp, ki]
    return control.tf(numerator, [1.0, kd, kp, ki])


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
    velocity_reference : bool
        As for :func:`error_dynamics`.

    Returns
    -------
    control.TransferFunction
        Discrete, ``dt = h``.
    """
    h = check_step(h)
    return control.c2d(error_dynamics(kp, kd, ki, velocity_reference), h, method="zoh")


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
        Discrete (``dt = h``), input r (reference relative to the start, joint unit), output y
        (position relative to the start, same unit); states (y, y'[, z]). Stable iff every
        eigenvalue of ``A`` is inside the unit circle.
    """
    kp, kd, ki = check_gains(kp, kd, ki)
    h = check_step(h)
    double_integrator = control.ss([[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], [[1.0, 0.0]], [[0.0]])
    plant = control.c2d(double_integrator, h, method="zoh")
    phi, gamma = np.asarray(plant.A), np.asarray(plant.B)
    feedback = np.array([[kp, kd]])
    if ki == 0.0:
        a = phi - gamma @ feedback
        b = gamma * kp
        c = np.array([[1.0, 0.0]])
    else:
        a = np.block([[phi - gamma @ feedback, gamma * ki],
                      [np.array([[-h, 0.0]]), np.ones((1, 1))]])
        b = np.vstack([gamma * kp, [[h]]])
        c = np.array([[1.0, 0.0, 0.0]])
    return control.ss(a, b, c, np.zeros((1, 1)), dt=h)


def predict(kp: float, kd: float, ki: float, t: np.ndarray, amplitude: float = 1.0,
            model: str = "sampled", h: float | None = None) -> np.ndarray:
    """Predicted position change y(t) = q(t) - q0 of a joint after a reference step.

    Parameters
    ----------
    kp, kd, ki : float
        Gains (1/s^2, 1/s, 1/s^3).
    t : array_like, shape (n,)
        Times (s) from the step; for the discrete models multiples of ``h`` (``t[k] = k h``).
    amplitude : float
        Size A of the reference step (the joint's unit: rad or m).
    model : {"sampled", "zoh", "continuous"}
        :func:`discrete_prediction`, :func:`zoh_prediction` or :func:`error_dynamics`.
    h : float, optional
        Communication step (s); default ``t[1] - t[0]``.

    Returns
    -------
    numpy.ndarray, shape (n,)
        y(t) in the unit of ``amplitude`` (``amplitude`` times the unit step response).
    """
    t = np.asarray(t, dtype=float)
    if model == "continuous":
        # step_response wants a grid from 0: times are measured from the step
        y = control.step_response(error_dynamics(kp, kd, ki), T=t - t[0]).outputs
        return amplitude * np.asarray(y, dtype=float).reshape(-1)
    if h is None:
        h = float(t[1] - t[0])
    if model == "sampled":
        loop = discrete_prediction(kp, kd, ki, h)
    elif model == "zoh":
        loop = zoh_prediction(kp, kd, ki, h)
    else:
        raise ValueError(f"model {model!r}: choose one of {', '.join(MODELS)}")
    y = control.step_response(loop, T=h * np.arange(len(t))).outputs
    return amplitude * np.asarray(y, dtype=float).reshape(-1)

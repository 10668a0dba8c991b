"""Step responses of the computed-torque loop of any robot: co-simulation against linear predictions.

A *step experiment* holds a joint reference ``q_ref = q0 + A`` (A, the amplitude, in each joint's
unit) from t = 0 and lets the robot's
controller and plant FMUs respond from rest at ``q0`` (by default its ``home`` configuration).
With a perfect model every joint is a double integrator closed by the PD/PID law, so the
response of each joint, revolute (rad) or prismatic (m), is predicted by linear models:

:mod:`.linear`
    The continuous error dynamics, its ZOH discretization and the sampled-data loop the FMUs
    implement (:func:`error_dynamics`, :func:`zoh_prediction`, :func:`discrete_prediction`,
    :func:`predict`).
:mod:`.sampled`
    The loop with the controller at its own sample time and a computation delay, python-control's
    prediction of it (:func:`sampled_prediction`, :func:`predict_sampled`; :func:`predict_coupled` with
    the joints coupled by gravity and damping through the held effort), its kp stability limit
    (:func:`largest_stable_kp`, :func:`spectral_radius`) and what Coulomb friction unknown to the
    controller costs (:func:`friction_steady_state_error`, :func:`friction_creep_time`).
:mod:`.metrics`
    Rise time, settling time, overshoot and peak relative to an initial value and time
    (:func:`step_metrics`), and the second-order closed forms (:func:`damping_from_overshoot`,
    :func:`second_order_settling_time`).
:mod:`.design`
    Gains from a requested settling time and overshoot (:func:`design_gains`).
:mod:`.experiment`
    The two-block step diagram of any robot on the project's
    :class:`~robofmu.system.master.Master` (:func:`step_system`, :func:`cosimulate_step`).
:mod:`.comparison`
    Its :class:`Comparison` with the predictions (:func:`compare`; :class:`FrictionMiss`) and CSV
    (:func:`write_csv`).
:mod:`.figures`
    Its figure (:func:`plot_comparison`); :func:`demo_cases` for the report.

The ``robofmu step`` command is :mod:`robofmu.system.commands.step`.
"""
from __future__ import annotations

from robofmu.system.stepresponse.design import GainDesign, design_gains
from robofmu.system.stepresponse.comparison import Comparison, FrictionMiss, compare, write_csv
from robofmu.system.stepresponse.experiment import (CONTROLLER, DEFAULT_AMPLITUDE, PLANT, StepSetup, cosimulate_step,
                                                    default_amplitudes, step_setup, step_system, steppable_robots)
from robofmu.system.stepresponse.figures import demo_cases, plot_comparison
from robofmu.system.stepresponse.linear import (MODEL_TEXT, MODELS, discrete_prediction, error_dynamics, predict,
                                                zoh_prediction)
from robofmu.system.stepresponse.sampled import (friction_creep_time, friction_steady_state_error,
                                                 largest_stable_kp, predict_coupled, predict_sampled,
                                                 sampled_prediction, spectral_radius)
from robofmu.system.stepresponse.metrics import (StepMetrics, damping_from_overshoot, second_order_settling_time,
                                                 step_metrics)

__all__ = [
    "MODELS", "MODEL_TEXT", "error_dynamics", "zoh_prediction", "discrete_prediction", "predict",
    "StepMetrics", "step_metrics", "damping_from_overshoot", "second_order_settling_time",
    "sampled_prediction", "predict_sampled", "predict_coupled", "spectral_radius", "largest_stable_kp",
    "friction_steady_state_error", "friction_creep_time",
    "GainDesign", "design_gains",
    "CONTROLLER", "PLANT", "DEFAULT_AMPLITUDE", "StepSetup", "Comparison", "FrictionMiss", "steppable_robots",
    "default_amplitudes", "step_setup", "step_system", "cosimulate_step", "compare", "write_csv",
    "plot_comparison", "demo_cases",
]

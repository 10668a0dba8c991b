"""A co-simulated run against a second, independent formulation of its robot's dynamics.

A robot model may offer ``independent_dynamics()``: another derivation of the same equations of
motion (e.g. in maximal coordinates with loop-closure constraints where the model works in
actuated coordinates). This integrates it with the run's inputs and start state (the plant
block's parameters and input start values in the experiment, else its FMU's start values) over
the run's duration, at the run's communication step, and compares it with the run: its own
constraint residual |Phi(t)| and the largest difference of its actuated coordinates from the
plant's q(t). Nothing here knows a robot; a model without the method has no cross-check.

The formulation object needs ``simulate_joints(q0, qd0, t_end, h, tau=, f_ext=, method=,
pose_guess=)`` returning a trajectory with ``t`` and ``q``, ``residuals(trajectory)`` -> (|Phi|,
|Phid|) and ``residual_units``.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from robofmu.system.result import Result
from robofmu.system.roles import Roles
from robofmu.system.units import printed


@dataclass
class CrossCheck:
    """The independent formulation along one run.

    Attributes
    ----------
    time : ndarray, shape (k,)
        The run's communication points (s).
    residual, residual_rate : ndarray, shape (k,)
        Its constraint residual |Phi(t)| and |Phid(t)| (units ``residual_units``).
    joint_difference : ndarray, shape (k,)
        max over joints |q_independent(t) - q_cosim(t)| (joint units).
    residual_units : tuple of str
    joint_units : list of str
    method : str
        The integrator (``"rk4"`` fixed step, or a ``solve_ivp`` method).
    step : float
        Its output (and, for RK4, integration) step (s).
    seconds : float
        Wall time of the integration.
    """

    time: np.ndarray
    residual: np.ndarray
    residual_rate: np.ndarray
    joint_difference: np.ndarray
    residual_units: tuple[str, str]
    joint_units: list[str]
    method: str
    step: float
    seconds: float

    @property
    def joint_unit(self) -> str:
        """The printed joint unit(s) of :attr:`joint_difference`."""
        return ", ".join(dict.fromkeys(printed(u) for u in self.joint_units))


def has_independent_dynamics(model) -> bool:
    """Whether a robot model offers a second formulation (``independent_dynamics()``)."""
    return callable(getattr(model, "independent_dynamics", None))


def block_parameter(system, instance: str, name: str, vectors: bool = True):
    """A block's parameter or input start value: its value in the experiment, else its FMU's
    start value (a vector base gathered into a list with ``vectors``); None if it has none."""
    spec = next((b for b in system.blocks if b.name == instance), None)
    if spec is None:
        return None
    if name in spec.parameters:
        return spec.parameters[name]
    from fmpy import read_model_description

    from robofmu.system.plan import start_values

    return start_values(read_model_description(str(system.fmu_path(spec)), validate=False),
                        vectors=vectors).get(name)


def cross_check(system, result: Result, roles: Roles, method: str = "rk4") -> CrossCheck | None:
    """Integrate the robot model's independent formulation with the run's inputs and start state;
    None when the model has none. The plant (the instance of the ``q`` role) must have its inputs
    unwired (constant at their values in the experiment), else ValueError."""
    model = roles.model()
    if not has_independent_dynamics(model):
        return None
    roles.require("q")
    instance = roles.q.split(".")[0]
    driven = sorted({w.dst_var for w in system.wires if w.dst == instance})
    if driven:
        raise ValueError(f"cross-check of {system.name}: {instance}'s inputs {driven} are wired; it "
                         "needs the plant's inputs constant (unwired)")
    q_cosim = roles.vector(result, "q")
    n = q_cosim.shape[1]
    value = lambda name: block_parameter(system, instance, name)  # noqa: E731
    q0 = np.asarray(value("q0"), dtype=float)
    qd0 = value("qd0")
    qd0 = np.zeros(n) if qd0 is None else np.asarray(qd0, dtype=float)
    tau = value("tau")
    f_ext = value("f_ext")
    dynamics = model.independent_dynamics()
    h = float(system.step)
    t_end = float(result.time[-1] - result.time[0])
    start = time.perf_counter()
    trajectory = dynamics.simulate_joints(q0, qd0, t_end, h=h, tau=tau, f_ext=f_ext, method=method,
                                          pose_guess=model.fk(q0))
    seconds = time.perf_counter() - start
    aligned = len(trajectory.t) == len(result.time) and \
        np.abs(trajectory.t + result.time[0] - result.time).max() <= 1e-9 * max(1.0, t_end)
    if not aligned:
        raise ValueError(f"cross-check of {system.name}: the run's {len(result.time)} points are not "
                         f"evenly spaced by its step {h:g} s")
    residual, rate = dynamics.residuals(trajectory)
    difference = np.abs(np.asarray(trajectory.q) - q_cosim).max(axis=1)
    units = [result.units.get(f"{roles.q}[{j + 1}]", "") for j in range(n)]
    return CrossCheck(np.asarray(result.time), residual, rate, difference, tuple(dynamics.residual_units),
                      units, method, h, seconds)

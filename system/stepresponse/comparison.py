"""A co-simulated step against the linear predictions: :func:`compare` gives a
:class:`Comparison` (metrics, predictions, the kp stability limit where the controller samples
on its own, :class:`FrictionMiss` for Coulomb friction the controller does not know, an
instability named), :func:`write_csv` writes it. The run is :mod:`.experiment`'s."""
from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from robofmu.system import defaults
from robofmu.system.master import Result
from robofmu.system.stepresponse.experiment import CONTROLLER, PLANT, step_text
from robofmu.system.stepresponse.linear import MODEL_TEXT, MODELS, predict
from robofmu.system.stepresponse.metrics import StepMetrics, step_metrics
from robofmu.system.stepresponse.sampled import (friction_creep_time, friction_steady_state_error,
                                                 largest_stable_kp, predict_coupled, spectral_radius)

__all__ = ["Comparison", "FrictionMiss", "compare", "write_csv"]


@dataclass(frozen=True)
class FrictionMiss:
    """Coulomb friction the controller does not know, on one stepped joint: what it costs.

    Attributes
    ----------
    joint : int
        The joint (from 1).
    coulomb : float
        tau_c unknown to the controller (N.m or N).
    inertia : float
        m = 1 / (M^-1)_jj at the held reference (kg.m^2 or kg).
    predicted : float
        The stop short e = tau_c / (m kp) (0 for a PID) of
        :func:`~.sampled.friction_steady_state_error`, joint unit.
    creep_time : float
        (s) :func:`~.sampled.friction_creep_time`: the smooth model's way out of the stick band;
        a run much shorter than it ends near ``predicted``.
    measured : float
        How far short of the reference the co-simulation ended, sign(A) (A - y(t_end)), joint unit.
    miss : float
        How far the linear prediction (the ``sampled`` model, which settles on the reference) is
        off at the end, sign(A) (y_predicted(t_end) - y(t_end)), joint unit.
    """

    joint: int
    coulomb: float
    inertia: float
    predicted: float
    creep_time: float
    measured: float
    miss: float


@dataclass
class Comparison:
    """A co-simulated step against the linear predictions (see :func:`compare`).

    With n samples, n_joints joints of which k are stepped:

    Attributes
    ----------
    time : ndarray, shape (n,)
        Communication points (s).
    joints : list of int, length k
        Stepped joints (from 1).
    amplitudes : ndarray, shape (k,)
        Amplitude of each stepped joint (its unit).
    response : ndarray, shape (n, k)
        Co-simulated q - q0 of the stepped joints (their units).
    crosstalk_joints : list of int, length n_joints - k
        The other joints (from 1).
    crosstalk : ndarray, shape (n, n_joints - k)
        Co-simulated q - q0 of the other joints (their units; 0 with perfect decoupling).
    predictions : dict of str -> ndarray, shape (n, k)
        q - q0 predicted by each model in :data:`~.linear.MODELS`, per stepped joint (its unit).
    deviation : dict of str -> ndarray, shape (k,)
        max over samples of |co-simulated - predicted| in % of |amplitude|, per stepped joint.
    crosstalk_percent : float
        max over the other joints of max |q - q0| in % of that joint's own amplitude
        (``Result.info["amplitudes"]``); 0 if every joint is stepped.
    metrics : dict of str -> StepMetrics
        ``"joint <j>"`` for each stepped joint (absolute positions, its unit, from q0 to
        q0 + amplitude) and one per model, of the unit step response (from 0 to 1: peak and final
        values are fractions of the amplitude; times and percentages are the same as for any
        amplitude, the models being linear).
    result : Result
        The co-simulation.
    gains : dict
        kp, kd, ki (1/s^2, 1/s, 1/s^3).
    h : float
        Communication step (s).
    algorithm : str
        The master's algorithm (one of :data:`~robofmu.system.defaults.ALGORITHMS`).
    robot : str
        The robot's name.
    q0 : list of float, length n_joints
        Start configuration (joint units).
    joint_units, effort_units, symbols : list of str, length n_joints
        From the robot model ("rad" / "m", "N.m" / "N", "q1", ...).
    sample_time : float or None
        The controller's sample time Ts (s) of a step run as on a robot (:func:`cosimulate_step`
        with ``sample_time``, ``delay_steps`` or ``parameters``); None: every step, the
        ``sampled`` model being :func:`~.linear.discrete_prediction`.
    delay_steps : int
        The controller's delay d (samples).
    kp_limit : float or None
        The largest stable kp (1/s^2) at Ts and d with kd and ki held, the model exact
        (:func:`~.sampled.largest_stable_kp`); None without ``sample_time``, or if no kp is stable.
    kp_limit_arm : float or None
        The same for the joints' coupled loop linearized at the step's middle
        (:func:`~.sampled.predict_coupled`'s, ``largest_stable_kp`` with its matrices): gravity's
        stiffness felt through the held, delayed effort lowers it a little.
    spectral_radius : float or None
        Largest |pole| of the predicted (coupled) loop at the run's gains (< 1: stable).
    friction : list of FrictionMiss
        One per stepped joint with Coulomb friction unknown to the controller.
    divergence : str
        "" unless the co-simulated error grew: then one line naming the block, the joint and the time.
    """

    time: np.ndarray
    joints: list
    amplitudes: np.ndarray
    response: np.ndarray
    crosstalk_joints: list
    crosstalk: np.ndarray
    predictions: dict
    deviation: dict
    crosstalk_percent: float
    metrics: dict
    result: Result
    gains: dict
    h: float
    algorithm: str = defaults.ALGORITHM
    robot: str = ""
    q0: list = field(default_factory=list)
    joint_units: list = field(default_factory=list)
    effort_units: list = field(default_factory=list)
    symbols: list = field(default_factory=list)
    sample_time: float | None = None
    delay_steps: int = 0
    kp_limit: float | None = None
    kp_limit_arm: float | None = None
    spectral_radius: float | None = None
    friction: list = field(default_factory=list)
    divergence: str = ""

    def model_text(self, model: str) -> str:
        """One line describing ``model`` (:data:`~.linear.MODEL_TEXT`; ``sampled`` at Ts with d)."""
        if model == "sampled" and self.sample_time is not None:
            return (f"sampled-data loop, controller every {self.sample_time * 1e3:g} ms, "
                    f"{self.delay_steps} sample{'s' * (self.delay_steps != 1)} late (predict_coupled)")
        return MODEL_TEXT[model]

    def unit(self, joint: int) -> str:
        """Unit of joint ``joint``'s position (from 1): "rad" or "m"."""
        return self.joint_units[joint - 1]

    def symbol(self, joint: int) -> str:
        """Label of joint ``joint`` (from 1), e.g. "q2"."""
        return self.symbols[joint - 1]

    def effort(self) -> np.ndarray:
        """Co-simulated actuator efforts ``controller.tau``, shape (n, n_joints) (N.m or N)."""
        return self.result.vector(f"{CONTROLLER}.tau")

    def best(self) -> str:
        """The model with the smallest max deviation."""
        return min(self.deviation, key=lambda model: float(np.max(self.deviation[model])))

    def max_deviation(self, model: str = "sampled") -> float:
        """max over stepped joints and samples of |co-simulated - predicted|, % of the amplitude."""
        return float(np.max(self.deviation[model]))

    def step_text(self) -> str:
        """``q1 +0.02 rad, q3 +0.02 m``: the stepped joints with their amplitudes and units."""
        return step_text(self.joints, self.amplitudes, self.symbols, self.joint_units)

    def table(self) -> str:
        """Metrics of every stepped joint and model, then the deviations, as aligned text."""
        g = self.gains
        start = ", ".join(f"{q:g} {u}" for q, u in zip(self.q0, self.joint_units))
        rate = ("" if self.sample_time is None else
                f"; controller every {self.sample_time * 1e3:g} ms, {self.delay_steps} sample"
                f"{'s' * (self.delay_steps != 1)} late")
        lines = [f"{self.robot}: step {self.step_text()} from q0 = ({start}); kp {g['kp']:g}, "
                 f"kd {g['kd']:g}, ki {g['ki']:g}; h {self.h * 1e3:g} ms{rate}; algorithm {self.algorithm}",
                 f"{'response':<24}{'rise (s)':>10}{'settle (s)':>12}{'overshoot %':>13}"
                 f"{'peak time (s)':>15}{'peak':>12}{'final':>12}  unit"]
        for name, m in self.metrics.items():
            unit = self.unit(int(name.split()[1])) if name.startswith("joint ") else "amplitude"
            lines.append(f"{name:<24}{m.rise_time:>10.4f}{m.settling_time:>12.4f}{m.overshoot:>13.3f}"
                         f"{m.peak_time:>15.4f}{m.peak:>12.5f}{m.steady_state:>12.5f}  {unit}")
        lines.append("max |co-simulated - predicted| over all samples, % of the amplitude:")
        for model in self.deviation:
            per_joint = ", ".join(f"{self.symbol(j)} {d:.3f}"
                                  for j, d in zip(self.joints, self.deviation[model]))
            lines.append(f"  {model:<11} {self.max_deviation(model):8.3f} %   ({per_joint})  "
                         f"{self.model_text(model)}")
        if self.crosstalk.size:
            lines.append(f"  unstepped joints moved by at most {self.crosstalk_percent:.3f} % of their "
                         "amplitude")
        lines.append(f"best match: {self.best()}")
        lines.extend(self._sampled_lines())
        if self.divergence:
            lines.append(self.divergence)
        return "\n".join(lines)

    def _sampled_lines(self) -> list[str]:
        """The stability limit and the unknown friction's cost, for a run with ``sample_time``."""
        if self.sample_time is None:
            return []
        g, ts, d = self.gains, self.sample_time, self.delay_steps
        where = f"Ts {ts * 1e3:g} ms, d {d}, kd {g['kd']:g}" + (f", ki {g['ki']:g}" if g["ki"] else "")
        if self.kp_limit is None:
            lines = [f"stability limit: no kp is stable at {where}"]
        else:
            lines = [f"stability limit: largest stable kp {self.kp_limit:.6g} 1/s^2 at {where} held (python-control's "
                     f"discrete poles); kp {g['kp']:g} is {g['kp'] / self.kp_limit * 100:.1f} % of it, spectral "
                     f"radius {self.spectral_radius:.5f}"]
            if self.kp_limit_arm is not None and abs(self.kp_limit_arm / self.kp_limit - 1.0) > 1e-6:
                lines.append(f"  the arm linearized at the step's middle (gravity and damping felt through the held "
                             f"effort): largest stable kp {self.kp_limit_arm:.6g} 1/s^2, kp {g['kp']:g} is "
                             f"{g['kp'] / self.kp_limit_arm * 100:.1f} % of it")
        for f in self.friction:
            k = self.joints.index(f.joint)
            unit, amplitude = self.unit(f.joint), abs(float(self.amplitudes[k]))
            effort = self.effort_units[f.joint - 1]
            off = f" ({(f.measured / f.predicted - 1) * 100:+.1f} %)" if f.predicted else ""
            lines.append(f"friction unknown to the controller, {self.symbol(f.joint)}: Coulomb {f.coulomb:g} {effort}, "
                         f"m {f.inertia:.5g}: stops short by {f.predicted:.5g} {unit} predicted (tau_c / (m kp); "
                         f"creep time {f.creep_time:.3g} s), measured {f.measured:.5g} {unit}{off} at "
                         f"t = {self.time[-1]:g} s; the linear prediction misses it by {f.miss:.5g} {unit} "
                         f"({abs(f.miss) / amplitude * 100:.2f} % of the amplitude)")
        return lines


def _units_of(result: Result, n: int) -> tuple[list, list, list]:
    """Joint units, effort units and symbols of a step result: its ``info``, else its columns'."""
    info = result.info
    joint_units = info.get("joint_units") or [result.units.get(f"{PLANT}.q[{j}]", "")
                                              for j in range(1, n + 1)]
    effort_units = info.get("effort_units") or [result.units.get(f"{CONTROLLER}.tau[{j}]", "")
                                                for j in range(1, n + 1)]
    symbols = info.get("symbols") or [f"q{j}" for j in range(1, n + 1)]
    return list(joint_units), list(effort_units), list(symbols)


def compare(result: Result, models: Sequence[str] = MODELS, settling: float = 0.02,
            interpolate: bool = True) -> Comparison:
    """Compare a co-simulated step (from :func:`cosimulate_step`) with the linear predictions.

    Parameters
    ----------
    result : Result
        From :func:`cosimulate_step` (its ``info`` carries gains, h, amplitudes, joints, q0, units).
    models : sequence of str
        Predictions to compute, from :data:`~.linear.MODELS`.
    settling : float
        Settling band for the metrics (0.02: 2 %).
    interpolate : bool
        Passed to :func:`~.metrics.step_metrics`.

    Returns
    -------
    Comparison
        Deviations (max over samples of |co-simulated - predicted|, % of each joint's amplitude)
        and the metrics of both (steady state taken as the reference q0 + amplitude, which a
        perfect model reaches; the record may end before the PID's slow integral mode has).
        For a run with ``sample_time`` in its ``info`` (see :func:`cosimulate_step`) the
        ``sampled`` model is :func:`~.sampled.predict_coupled` at Ts with d, the run's
        ``linearization`` and the controller's start-up (``startup="first"``; the model's metrics
        are those of the first stepped joint's), with the stability limit and the friction rows.
    """
    info = result.info
    kp, kd, ki, h = info["kp"], info["kd"], info["ki"], info["h"]
    joints, q0 = list(info["joints"]), np.asarray(info["q0"], dtype=float)
    all_amplitudes = np.asarray(info["amplitudes"], dtype=float)
    t = result.time
    y = result.vector(f"{PLANT}.q") - q0
    stepped = np.array(joints) - 1
    others = [j for j in range(1, q0.size + 1) if j not in joints]
    amplitudes = all_amplitudes[stepped]
    response = y[:, stepped]
    crosstalk = y[:, np.array(others, dtype=int) - 1] if others else np.zeros((len(t), 0))
    ts, d = info.get("sample_time"), int(info.get("delay_steps", 0))
    beta = (np.asarray(info["unknown_damping"])[stepped] / np.asarray(info["inertia"])[stepped]
            if ts is not None else np.zeros(len(joints)))
    unit_responses, predictions, deviation = {}, {}, {}
    for model in models:
        if model == "sampled" and ts is not None:
            step = np.zeros(q0.size)
            step[stepped] = amplitudes
            linearization = info["linearization"]
            every = predict_coupled(kp, kd, ki, t - t[0], step, sample_time=ts, delay_steps=d, h=h, startup="first",
                                    **{key: linearization[key] for key in ("stiffness", "damping", "compensation")})
            predictions[model] = every[:, stepped]
            unit_responses[model] = predictions[model][:, 0] / amplitudes[0]
        else:
            unit_responses[model] = predict(kp, kd, ki, t - t[0], 1.0, model, h)
            predictions[model] = unit_responses[model][:, None] * amplitudes[None, :]
        deviation[model] = np.max(np.abs(response - predictions[model]), axis=0) / np.abs(amplitudes) * 100.0
    metrics: dict[str, StepMetrics] = {}
    for j, amplitude, column in zip(joints, amplitudes, response.T):
        start = q0[j - 1]
        metrics[f"joint {j}"] = step_metrics(t, column + start, y0=start, yf=start + amplitude,
                                             settling=settling, interpolate=interpolate)
    for model, unit_response in unit_responses.items():
        metrics[model] = step_metrics(t, unit_response, y0=0.0, yf=1.0, settling=settling,
                                      interpolate=interpolate)
    crosstalk_percent = 0.0
    if others:
        scale = np.abs(all_amplitudes[np.array(others) - 1])
        crosstalk_percent = float(np.max(np.max(np.abs(crosstalk), axis=0) / scale) * 100.0)
    joint_units, effort_units, symbols = _units_of(result, q0.size)
    sampled = {}
    if ts is not None:
        arm = {key: info["linearization"][key] for key in ("stiffness", "damping", "compensation")}
        limits = []
        for terms in ({}, arm):
            try:
                limits.append(largest_stable_kp(kd, ts, d, ki, **terms))
            except ValueError:               # no kp is stable at this kd, ki, Ts and d
                limits.append(None)
        sampled = dict(sample_time=ts, delay_steps=d, kp_limit=limits[0], kp_limit_arm=limits[1],
                       spectral_radius=spectral_radius(kp, kd, ki, ts, d, **arm),
                       friction=_friction_misses(info, joints, amplitudes, response, predictions.get("sampled"), beta))
    rate = "" if ts is None else f", controller every {ts * 1e3:g} ms, {d} sample{'s' * (d != 1)} late"
    return Comparison(time=t, joints=joints, amplitudes=amplitudes, response=response,
                      crosstalk_joints=others, crosstalk=crosstalk, predictions=predictions,
                      deviation=deviation, crosstalk_percent=crosstalk_percent, metrics=metrics,
                      result=result, gains={"kp": kp, "kd": kd, "ki": ki}, h=h,
                      algorithm=info.get("algorithm", defaults.ALGORITHM), robot=info.get("robot", ""),
                      q0=q0.tolist(), joint_units=joint_units, effort_units=effort_units,
                      symbols=symbols, divergence=_divergence(t, response, amplitudes, joints, symbols, kp, rate),
                      **sampled)


def _friction_misses(info: dict, joints: list, amplitudes: np.ndarray, response: np.ndarray,
                     predicted: np.ndarray | None, beta: np.ndarray) -> list[FrictionMiss]:
    """A :class:`FrictionMiss` per stepped joint whose plant has Coulomb friction the controller
    does not add (``info``'s unknown losses, from :func:`cosimulate_step`)."""
    misses = []
    for k, j in enumerate(joints):
        coulomb = float(info["unknown_friction"][j - 1])
        if coulomb <= 0.0:
            continue
        inertia, sign = float(info["inertia"][j - 1]), float(np.sign(amplitudes[k]))
        creep = friction_creep_time(info["kp"], info["kd"], info["ki"], info["sample_time"], coulomb, inertia,
                                    float(info["friction_velocity"][j - 1]), info["delay_steps"], float(beta[k]))
        end = float(response[-1, k])
        misses.append(FrictionMiss(
            joint=j, coulomb=coulomb, inertia=inertia,
            predicted=friction_steady_state_error(info["kp"], coulomb, inertia, info["ki"]), creep_time=creep,
            measured=sign * (float(amplitudes[k]) - end),
            miss=sign * ((float(predicted[-1, k]) if predicted is not None else float(amplitudes[k])) - end)))
    return misses


def _divergence(t: np.ndarray, response: np.ndarray, amplitudes: np.ndarray, joints: list, symbols: list,
                kp: float, rate: str) -> str:
    """"" for a step whose error |y - A| shrinks; else one line: unstable, the controller's loop,
    the joint whose error grew most from the run's first fifth to its last, and when.

    The error of a stable loop decays (its largest value after the step's first fifth is below
    the first fifth's); that of a loop beyond its stability limit grows geometrically."""
    fifth = max(len(t) // 5, 1)
    if len(t) < 10:
        return ""
    error = np.abs(response - amplitudes[None, :]) / np.abs(amplitudes)[None, :]
    first, last = np.max(error[:fifth], axis=0), np.max(error[-fifth:], axis=0)
    growth = last / first
    k = int(np.argmax(growth))
    if not growth[k] > 1.0:
        return ""
    at = len(t) - fifth + int(np.argmax(error[-fifth:, k]))
    return (f"UNSTABLE: the loop of block {CONTROLLER!r} (kp {kp:g}{rate}) diverged: joint {joints[k]} "
            f"({symbols[joints[k] - 1]}) |q - q_ref| grew from {first[k]:.3g} to {last[k]:.3g} times the amplitude "
            f"(at t = {t[at]:g} s)")


# -- output -------------------------------------------------------------------------------------
def write_csv(comparison: Comparison, path: str | Path) -> Path:
    """Write the comparison as CSV, units in the header.

    Columns: ``time [s]``; ``cosim_<q> [<unit>]`` (co-simulated q - q0) of each stepped joint;
    ``pred_<model>_<q> [<unit>]`` (predicted q - q0) for each model and stepped joint;
    ``tau<j> [<unit>]`` (co-simulated effort, N.m or N) of every joint. Full precision
    (``repr``). Parent folders are created.

    Parameters
    ----------
    comparison : Comparison
    path : str or Path

    Returns
    -------
    Path
        The file written.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    c = comparison
    effort = c.effort()
    header = (["time [s]"] + [f"cosim_{c.symbol(j)} [{c.unit(j)}]" for j in c.joints]
              + [f"pred_{model}_{c.symbol(j)} [{c.unit(j)}]" for model in c.predictions for j in c.joints]
              + [f"tau{j} [{unit}]" for j, unit in enumerate(c.effort_units, start=1)])
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        for k, tk in enumerate(c.time):
            predicted = (v for model in c.predictions for v in c.predictions[model][k])
            row = [float(tk), *c.response[k], *predicted, *effort[k]]
            writer.writerow([repr(float(v)) for v in row])
    return path

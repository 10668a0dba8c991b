"""Convergence of the co-simulation to the monolithic reference as the communication step shrinks.

For each algorithm (Gauss-Seidel, Jacobi) and each communication step h the experiment is
co-simulated with :class:`~robofmu.system.master.Master` and compared, at its communication
points t_k, with the continuous closed loop
(:meth:`~robofmu.system.studies.replica.InProcessDiagram.monolithic`, solved once, sampled on
every grid):

- ``q_error``: max over k and joints of |q_cosim(t_k) - q_mono(t_k)| (joint units: rad or m);
- ``tcp_error``: max over k of ||fk(q_cosim(t_k)) - fk(q_mono(t_k))|| (m), over the task
  coordinates measured in m (a pose's angle is not added to a distance);
- ``tracking``: max over k of ||fk(q_cosim(t_k)) - x_ref(t_k)|| (m), the co-simulated TCP's
  distance to the task-space trajectory (for context: includes the loop's own tracking error,
  which is zero when the controller's model is exact).

The observed order p is the least-squares slope of log(error) against log(h). The reference is
scipy's :data:`~robofmu.system.defaults.REFERENCE_SOLVER` at
:data:`~robofmu.system.defaults.REFERENCE_RTOL`.

Why first order
---------------
A sampled controller holds tau(t_k) over [t_k, t_k + h] (zero-order hold) and advances its
integral by forward Euler, z += e(t_k) h; the plant itself is integrated almost exactly for the
torque it is given (RK4 sub-steps of at most 1 ms). Over a step the held torque differs from
the continuous one by tau'(t_k) (t - t_k) + O(h^2); its mean, -tau' h / 2, is a persistent O(h)
forcing (a ZOH acts like a delay of h / 2) on the stable error dynamics, so the global error is
O(h): order p = 1. Forward Euler on z is O(h) too, and a discontinuity of the reference
acceleration (LSPB blend switches at T/3 are not communication points) is missed by less than
one step, again O(h): the missed part of the step is the distance from the discontinuity to the
next communication point, at most h but not proportional to it (a switch 0.4 ms before a point
that is on the 1 ms and the 2 ms grids is missed by 0.4 ms on both), so where such misses
dominate the error is bounded by C h while the local order between two steps scatters around 1.
Any further delay of d whole steps adds d h to the effective delay: still
O(h), with a larger constant.

What the algorithms do (:class:`~robofmu.system.studies.replica.InProcessDiagram` replays the
Gauss-Seidel loop in-process and matches the FMU runs to the last bit):

- ``gauss-seidel``: at t_k the outputs are evaluated in dependency order (reference, IK, plant,
  controller); inputs from blocks evaluated later (the plant's effort) are set after that pass,
  so the plant integrates [t_k, t_k + h] with tau(t_k): effective delay h / 2.
- ``jacobi``: every block reads the outputs of the previous exchange: the torque applied over
  [t_k, t_k + h] comes from the plant state at t_(k-1) and the joint reference of t_(k-2) (the
  IK lags the trajectory one step, the controller lags the IK one more). Effective delays
  1.5 h on the state, 2.5 h on the reference: first order, with a larger constant.
- ``in-process`` (no FMI calls): the Gauss-Seidel loop with the blocks' logic called directly.

Run ``robofmu convergence EXPERIMENT`` for the study (:mod:`robofmu.system.commands.convergence`);
:func:`study` returns it typed (:class:`ConvergenceStudy`).
"""
from __future__ import annotations

import json
import math
import time as _time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from robofmu.system import defaults
from robofmu.system.diagram import System
from robofmu.system.experiment import load
from robofmu.system.master import Master, Result
from robofmu.system.roles import Roles, task_axes
from robofmu.system.studies.replica import InProcessDiagram

__all__ = ["DEFAULT_STEP_SIZES", "IN_PROCESS", "ALGORITHMS", "Errors", "ConvergenceRun", "Order",
           "ConvergenceStudy", "check_plan", "errors", "observed_order", "run_cosim", "study",
           "error_table", "plot", "write"]

#: Communication steps of the study (s).
DEFAULT_STEP_SIZES = (0.01, 0.005, 0.002, 0.001, 0.0005)

#: The Gauss-Seidel loop replayed in-process on the blocks' logic (no FMI calls).
IN_PROCESS = "in-process"

#: What the study can compare: the master's algorithms and the in-process replica.
ALGORITHMS = (*defaults.ALGORITHMS, IN_PROCESS)


@dataclass(frozen=True)
class Errors:
    """One run against the monolithic reference at its communication points.

    Attributes
    ----------
    q_error : float
        max over k and joints of |q_cosim(t_k) - q_mono(t_k)| (joint units: rad or m).
    q_error_at : float
        Where it occurs (s).
    tcp_error : float
        max over k of the task-point distance ||fk(q_cosim) - fk(q_mono)|| (m).
    tracking : float
        max over k of ||fk(q_cosim(t_k)) - x_ref(t_k)|| (m); NaN without an ``x_ref`` role.
    qd_error : float
        max |qd_cosim - qd_mono| (rad/s or m/s); NaN without a ``qd`` role.
    """

    q_error: float
    q_error_at: float
    tcp_error: float
    tracking: float
    qd_error: float


@dataclass(frozen=True)
class ConvergenceRun(Errors):
    """One co-simulation of the study: its :class:`Errors`, algorithm, communication step and
    wall time (s)."""

    algorithm: str
    step_size: float
    wall_time: float


@dataclass(frozen=True)
class Order:
    """How one algorithm's error falls with the communication step.

    Attributes
    ----------
    q, tcp : float
        Observed orders (:func:`observed_order`) of the joint and task-point errors.
    error_constant : float
        C = mean of q_error / h (joint units per s): q error ~ C h.
    ratio_to_gauss_seidel : float or None
        Mean over the steps of this algorithm's q error over Gauss-Seidel's (None for
        Gauss-Seidel itself, or when it did not run).
    """

    q: float
    tcp: float
    error_constant: float
    ratio_to_gauss_seidel: float | None = None


@dataclass
class ConvergenceStudy:
    """The co-simulation error against the monolithic reference versus the communication step.

    Attributes
    ----------
    experiment : str
    stop_time : float
        End of every run (s).
    step_sizes : tuple of float
        Communication steps (s), largest first.
    algorithms : tuple of str
        In the order they ran (of :data:`ALGORITHMS`).
    runs : tuple of ConvergenceRun
        One per algorithm and step, algorithm by algorithm, largest step first.
    orders : dict of str to Order
        Per algorithm.
    reference : dict
        The monolithic reference's integrator statistics: ``pieces``, ``nfev``, ``wall_time`` (s).
    runtime : float
        Wall time of the whole study (s).
    files : dict of str to Path
        What was written: ``table`` (convergence.md), ``figure`` (convergence.png), ``data``
        (convergence.json); empty without an output folder.
    """

    experiment: str
    stop_time: float
    step_sizes: tuple[float, ...]
    algorithms: tuple[str, ...]
    runs: tuple[ConvergenceRun, ...]
    orders: dict[str, Order]
    reference: dict
    runtime: float
    files: dict[str, Path] = field(default_factory=dict)

    def runs_of(self, algorithm: str) -> list[ConvergenceRun]:
        """The runs of ``algorithm``, largest step first."""
        return [r for r in self.runs if r.algorithm == algorithm]

    @property
    def table(self) -> str:
        """The runs as a markdown table, then the observed orders (:func:`error_table`)."""
        return error_table(self.runs, self.orders)

    def to_json(self) -> dict:
        """Every number of the study, as ``convergence.json`` holds it (file names relative to it)."""
        data = asdict(self)
        data["files"] = {key: path.name for key, path in self.files.items()}
        return data


def observed_order(steps: Sequence[float], errs: Sequence[float]) -> float:
    """Least-squares slope of log(error) against log(h): the observed order p in error ~ C h^p.

    Parameters
    ----------
    steps : sequence of float, length >= 2
        Communication steps (s), positive.
    errs : sequence of float
        Errors at those steps (any unit), positive.

    Returns
    -------
    float
        p (dimensionless).
    """
    h = np.log(np.asarray(steps, dtype=float))
    e = np.log(np.asarray(errs, dtype=float))
    if h.size < 2:
        raise ValueError("observed_order: need at least two steps")
    return float(np.polyfit(h, e, 1)[0])


def run_cosim(system: System, h: float, algorithm: str, stop_time: float) -> Result:
    """Co-simulate ``system`` recording only the signals the study compares (its roles).

    Parameters
    ----------
    system : System
    h : float
        Communication step (s); ``stop_time`` must be a whole number of steps.
    algorithm : one of :data:`~robofmu.system.defaults.ALGORITHMS`
    stop_time : float
        End time (s).

    Returns
    -------
    Result
        The vectors of the roles ``q``, ``qd``, ``x_ref`` and ``tau`` the experiment declares.
    """
    roles = Roles.of(system)
    bases = [b for b in (roles.q, roles.qd, roles.x_ref, roles.tau) if b]
    master = Master(system, record=[f"{b}[[]*" for b in bases])
    return master.run(stop_time=stop_time, step=h, algorithm=algorithm)


def errors(result: Result, reference: Result, roles: Roles, model=None) -> Errors:
    """Errors of a co-simulation run against the monolithic reference at the same times.

    Parameters
    ----------
    result : Result
        A co-simulation run recording the ``q`` role (and ``qd``, ``x_ref`` where declared).
    reference : Result
        The monolithic reference evaluated at ``result.time``.
    roles : Roles
    model : RobotModel, optional
        For forward kinematics (default: a new model of the experiment's robot).

    Returns
    -------
    Errors
    """
    model = roles.model() if model is None else model
    q, q_mono = result.vector(roles.q), reference.vector(roles.q)
    dq = np.abs(q - q_mono)
    k = int(np.argmax(dq.max(axis=1)))
    position = task_axes(model)[0]
    poses, poses_mono = roles.poses(result, model), roles.poses(reference, model)
    tcp_error = float(np.linalg.norm(poses[:, position] - poses_mono[:, position], axis=1).max())
    qd_error = math.nan
    if roles.qd is not None:
        qd_error = float(np.abs(result.vector(roles.qd) - reference.vector(roles.qd)).max())
    tracking = roles.tcp_error(result, model, poses)
    return Errors(q_error=float(dq.max()), q_error_at=float(result.time[k]), tcp_error=tcp_error,
                  tracking=math.nan if tracking is None else float(tracking.max()), qd_error=qd_error)


def error_table(runs: Sequence[ConvergenceRun], orders: dict[str, Order]) -> str:
    """The study's runs as a markdown table, then the observed orders."""
    lines = ["| algorithm | h (ms) | max abs q error (rad or m) | max TCP error (mm) | local order (q) "
             "| TCP tracking error vs x_ref (mm) | wall time (s) |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    prev = {}
    for r in runs:
        a = r.algorithm
        local = ""
        if a in prev:
            h0, e0 = prev[a]
            local = f"{math.log(e0 / r.q_error) / math.log(h0 / r.step_size):.2f}"
        prev[a] = (r.step_size, r.q_error)
        lines.append(f"| {a} | {r.step_size * 1e3:g} | {r.q_error:.3e} | {r.tcp_error * 1e3:.4f} "
                     f"| {local} | {r.tracking * 1e3:.4f} | {r.wall_time:.1f} |")
    lines.append("")
    for a, o in orders.items():
        lines.append(f"- {a}: observed order {o.q:.2f} (q), {o.tcp:.2f} (TCP); "
                     f"error constant C = {o.error_constant:.3g} per s (q error ~ C h, joint units)")
    for a, o in orders.items():
        if o.ratio_to_gauss_seidel is not None:
            lines.append(f"- {a} / gauss-seidel q error ratio (mean over steps): {o.ratio_to_gauss_seidel:.2f}")
    return "\n".join(lines) + "\n"


def plot(runs: Sequence[ConvergenceRun], path: str | Path, title: str = "") -> Path:
    """Log-log figure of the q and TCP errors against h, per algorithm, with an O(h) guide."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2), constrained_layout=True)
    for ax, key, scale, label in ((axes[0], "q_error", 1.0, "max |q - q_mono| (rad or m)"),
                                  (axes[1], "tcp_error", 1e3, "max TCP error (mm)")):
        names = list(dict.fromkeys(r.algorithm for r in runs))
        for a, marker in zip(names, ("o", "s", "^", "v", "D")):
            rs = [r for r in runs if r.algorithm == a]
            if not rs:
                continue
            h = np.array([r.step_size for r in rs]) * 1e3
            e = np.array([getattr(r, key) for r in rs]) * scale
            ax.loglog(h, e, marker=marker, label=a)
        rs = [r for r in runs if r.algorithm == runs[0].algorithm]
        h = np.array(sorted(r.step_size for r in rs)) * 1e3
        e0 = min(getattr(r, key) for r in rs) * scale
        ax.loglog(h, e0 * h / h[0], "k--", lw=0.8, label="slope 1")
        ax.set_xlabel("communication step h (ms)")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    if title:
        fig.suptitle(title)
    from robofmu.system.plots import save_figure

    return save_figure(fig, path, tight=False, dpi=120)


def check_plan(step_sizes: Sequence[float], algorithms: Sequence[str],
               stop_time: float) -> tuple[tuple[float, ...], tuple[str, ...]]:
    """The study's communication steps (largest first) and algorithms, checked.

    Raises
    ------
    ValueError
        Starting with the argument at fault, ``"step_sizes: "`` (a step that is not a finite time
        > 0 s or does not divide ``stop_time`` into whole steps, one given twice, fewer than two)
        or ``"algorithms: "`` (one not in :data:`ALGORITHMS`, one given twice, none at all).
    """
    algorithms = tuple(algorithms)
    unknown = [a for a in algorithms if a not in ALGORITHMS]
    if unknown or not algorithms:
        what = f"unknown {', '.join(map(repr, unknown))}" if unknown else "none given"
        raise ValueError(f"algorithms: {what}; choose from {', '.join(ALGORITHMS)}")
    steps = tuple(sorted((float(h) for h in step_sizes), reverse=True))
    for argument, given in (("algorithms", algorithms), ("step_sizes", steps)):
        twice = next((v for k, v in enumerate(given) if v in given[:k]), None)
        if twice is not None:
            raise ValueError(f"{argument}: {twice if isinstance(twice, str) else f'{twice:g}'} is given twice")
    for h in steps:
        if not (math.isfinite(h) and h > 0.0):
            raise ValueError(f"step_sizes: {h:g} is not a finite time > 0 s")
        n = round(stop_time / h)
        if n < 1 or abs(n * h - stop_time) > 1e-9 * max(1.0, stop_time):
            raise ValueError(f"step_sizes: {h:g} s does not divide the stop time {stop_time:g} s into whole steps")
    if len(steps) < 2:
        raise ValueError(f"step_sizes: need at least two communication steps, got "
                         f"{', '.join(f'{h:g}' for h in steps) or 'none'}")
    return steps, algorithms


def study(experiment: str | System, step_sizes: Sequence[float] = DEFAULT_STEP_SIZES,
          out_dir: str | Path | None = None, algorithms: Sequence[str] = defaults.ALGORITHMS,
          stop_time: float | None = None, fmu_dir: str | Path | None = defaults.FMU_FOLDER,
          progress: Callable[[str], None] | None = print) -> ConvergenceStudy:
    """Co-simulation error against the monolithic reference versus the communication step.

    Parameters
    ----------
    experiment : str or System
        Experiment name (loaded with ``fmu_dir``) or a loaded System.
    step_sizes : sequence of float
        Communication steps h (s); ``stop_time`` must be a whole number of each.
    out_dir : str or Path, optional
        Folder for ``convergence.md`` (the table), ``convergence.png`` (log-log figure) and
        ``convergence.json`` (every number: :meth:`ConvergenceStudy.to_json`). Nothing is written
        if None.
    algorithms : sequence of str
        What to compare, of :data:`ALGORITHMS`: the master's "gauss-seidel" and "jacobi", and
        "in-process", the Gauss-Seidel loop run in-process on the blocks' logic (no FMI calls).
    stop_time : float, optional
        End of every run (s); default the experiment's.
    fmu_dir : str or Path
        FMU root when ``experiment`` is a name.
    progress : callable, optional
        Receives one line per run (default: print).

    Returns
    -------
    ConvergenceStudy

    Raises
    ------
    ValueError
        From :func:`check_plan`, before anything runs.
    """
    wall = _time.perf_counter()
    say = progress or (lambda *_: None)
    system = experiment if isinstance(experiment, System) else load(experiment, fmu_dir=fmu_dir)
    stop_time = system.stop_time if stop_time is None else float(stop_time)
    steps, algorithms = check_plan(step_sizes, algorithms, stop_time)

    roles = Roles.of(system)
    roles.require("q")
    diagram = InProcessDiagram(system)
    loop = diagram.monolithic(stop_time)
    say(f"reference: {system.name}, 0..{stop_time:g} s, {defaults.REFERENCE_SOLVER} rtol "
        f"{defaults.REFERENCE_RTOL:g} on {loop.stats['pieces']} pieces, {loop.stats['nfev']} evaluations, "
        f"{loop.stats['wall_time']:.1f} s")
    model = roles.model()
    runs, total = [], len(steps) * len(algorithms)
    for a in algorithms:
        for h in steps:
            t0 = _time.perf_counter()
            result = diagram.sampled(h, stop_time) if a == IN_PROCESS else run_cosim(system, h, a, stop_time)
            found = errors(result, loop.evaluate(result.time), roles, model)
            run = ConvergenceRun(**asdict(found), algorithm=a, step_size=h, wall_time=_time.perf_counter() - t0)
            runs.append(run)
            say(f"[{len(runs)}/{total}] {a:12s} h = {h * 1e3:6.3g} ms: max |dq| {run.q_error:.3e} "
                f"(t = {run.q_error_at:.3f} s), TCP {run.tcp_error * 1e3:.4f} mm, "
                f"tracking {run.tracking * 1e3:.4f} mm  [{run.wall_time:.1f} s]")
            for group in result.messages:          # what the FMUs of this run said
                say(f"    {group}")

    gauss_seidel = {r.step_size: r.q_error for r in runs if r.algorithm == "gauss-seidel"}
    orders: dict[str, Order] = {}
    for a in algorithms:
        rs = [r for r in runs if r.algorithm == a]
        hs = [r.step_size for r in rs]
        ratio = None
        if gauss_seidel and a != "gauss-seidel":
            ratio = float(np.mean([r.q_error / gauss_seidel[r.step_size] for r in rs]))
        orders[a] = Order(q=observed_order(hs, [r.q_error for r in rs]),
                          tcp=observed_order(hs, [r.tcp_error for r in rs]),
                          error_constant=float(np.mean([r.q_error / r.step_size for r in rs])),
                          ratio_to_gauss_seidel=ratio)
    found = ConvergenceStudy(experiment=system.name, stop_time=stop_time, step_sizes=steps,
                             algorithms=algorithms, runs=tuple(runs), orders=orders,
                             reference=dict(loop.stats), runtime=_time.perf_counter() - wall)
    if out_dir is not None:
        write(found, out_dir)
    say(f"study done in {found.runtime:.1f} s")
    return found


def write(found: ConvergenceStudy, out_dir: str | Path) -> dict[str, Path]:
    """Write ``convergence.md``, ``convergence.png`` and ``convergence.json`` into ``out_dir``
    (created); records them in ``found.files`` and returns them."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    head = (f"# Co-simulation convergence: {found.experiment}, 0 to {found.stop_time:g} s\n\n"
            f"Errors at the communication points against the monolithic reference (continuous controller, "
            f"{defaults.REFERENCE_SOLVER} rtol {defaults.REFERENCE_RTOL:g}, piecewise between "
            "discontinuities).\n\n")
    found.files["table"] = out_dir / "convergence.md"
    found.files["table"].write_text(head + found.table)
    found.files["figure"] = plot(found.runs, out_dir / "convergence.png",
                                 f"{found.experiment}: co-simulation error vs communication step")
    found.files["data"] = out_dir / "convergence.json"
    found.files["data"].write_text(json.dumps(found.to_json(), indent=2))
    return found.files

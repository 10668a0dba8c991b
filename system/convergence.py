"""Convergence of the co-simulation to the monolithic reference as the communication step shrinks.

For each algorithm (Gauss-Seidel, Jacobi) and each communication step h the experiment is
co-simulated with :class:`~robofmu.system.master.Master` and compared, at its communication
points t_k, with the continuous closed loop of :mod:`robofmu.system.reference` (solved once,
sampled on every grid):

- ``q_error``: max over k and joints of |q_cosim(t_k) - q_mono(t_k)| (joint units: rad or m);
- ``tcp_error``: max over k of ||fk(q_cosim(t_k)) - fk(q_mono(t_k))|| (m), over the task
  coordinates measured in m (a pose's angle is not added to a distance);
- ``tracking``: max over k of ||fk(q_cosim(t_k)) - x_ref(t_k)|| (m), the co-simulated TCP's
  distance to the task-space trajectory (for context: includes the loop's own tracking error,
  which is zero when the controller's model is exact).

The observed order p is the least-squares slope of log(error) against log(h).

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

What the algorithms do (:class:`~robofmu.system.replica.InProcessDiagram` replays the
Gauss-Seidel loop in-process and matches the FMU runs to the last bit):

- ``gauss-seidel``: at t_k the outputs are evaluated in dependency order (reference, IK, plant,
  controller); inputs from blocks evaluated later (the plant's effort) are set after that pass,
  so the plant integrates [t_k, t_k + h] with tau(t_k): effective delay h / 2.
- ``jacobi``: every block reads the outputs of the previous exchange: the torque applied over
  [t_k, t_k + h] comes from the plant state at t_(k-1) and the joint reference of t_(k-2) (the
  IK lags the trajectory one step, the controller lags the IK one more). Effective delays
  1.5 h on the state, 2.5 h on the reference: first order, with a larger constant.
- ``in-process`` (no FMI calls): the Gauss-Seidel loop with the blocks' logic called directly.

Run ``python -m robofmu.system.convergence --out results/convergence`` for the study.
"""
from __future__ import annotations

import argparse
import json
import math
import time as _time
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from .diagram import System
from .experiment import load
from .master import ALGORITHMS, Master, Result
from .replica import InProcessDiagram
from .roles import Roles, task_axes

__all__ = ["DEFAULT_STEPS", "ALGORITHMS", "errors", "observed_order", "run_cosim",
           "study", "markdown_table", "plot"]

#: Communication steps of the study (s).
DEFAULT_STEPS = (0.01, 0.005, 0.002, 0.001, 0.0005)


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


def run_cosim(system: System, step: float, algorithm: str, stop_time: float) -> Result:
    """Co-simulate ``system`` recording only the signals the study compares (its roles).

    Parameters
    ----------
    system : System
    step : float
        Communication step h (s); ``stop_time`` must be a whole number of steps.
    algorithm : {"gauss-seidel", "jacobi"}
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
    return master.run(stop_time=stop_time, step=step, algorithm=algorithm)


def errors(result: Result, reference: Result, roles: Roles, model=None) -> dict[str, float]:
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
    dict
        ``q_error`` (joint units), ``qd_error``, ``tcp_error`` (m), ``tracking``
        (distance of the co-simulated task point to ``x_ref``; NaN without that role),
        ``q_error_at`` (s, where q_error occurs).
    """
    model = roles.model() if model is None else model
    q, q_mono = result.vector(roles.q), reference.vector(roles.q)
    dq = np.abs(q - q_mono)
    k = int(np.argmax(dq.max(axis=1)))
    position = task_axes(model)[0]
    poses, poses_mono = roles.poses(result, model), roles.poses(reference, model)
    out = {"q_error": float(dq.max()), "q_error_at": float(result.time[k]),
           "tcp_error": float(np.linalg.norm(poses[:, position] - poses_mono[:, position], axis=1).max()),
           "tracking": math.nan, "qd_error": math.nan}
    if roles.qd is not None:
        out["qd_error"] = float(np.abs(result.vector(roles.qd) - reference.vector(roles.qd)).max())
    tracking = roles.tcp_error(result, model, poses)
    if tracking is not None:
        out["tracking"] = float(tracking.max())
    return out


def markdown_table(rows: list[dict], orders: dict) -> str:
    """The study's rows as a markdown table, then the observed orders."""
    lines = ["| algorithm | h (ms) | max abs q error (rad or m) | max TCP error (mm) | local order (q) "
             "| TCP tracking error vs x_ref (mm) | wall time (s) |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    prev = {}
    for r in rows:
        a = r["algorithm"]
        local = ""
        if a in prev:
            h0, e0 = prev[a]
            local = f"{math.log(e0 / r['q_error']) / math.log(h0 / r['step']):.2f}"
        prev[a] = (r["step"], r["q_error"])
        lines.append(f"| {a} | {r['step'] * 1e3:g} | {r['q_error']:.3e} | {r['tcp_error'] * 1e3:.4f} "
                     f"| {local} | {r['tracking'] * 1e3:.4f} | {r['wall_time']:.1f} |")
    lines.append("")
    for a, o in orders.items():
        lines.append(f"- {a}: observed order {o['q']:.2f} (q), {o['tcp']:.2f} (TCP); "
                     f"error constant C = {o['C_q']:.3g} per s (q error ~ C h, joint units)")
    for a, o in orders.items():
        if "ratio_to_gs" in o:
            lines.append(f"- {a} / gauss-seidel q error ratio (mean over steps): {o['ratio_to_gs']:.2f}")
    return "\n".join(lines) + "\n"


def plot(rows: list[dict], path: str | Path, title: str = "") -> Path:
    """Log-log figure of the q and TCP errors against h, per algorithm, with an O(h) guide."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2), constrained_layout=True)
    for ax, key, scale, label in ((axes[0], "q_error", 1.0, "max |q - q_mono| (rad or m)"),
                                  (axes[1], "tcp_error", 1e3, "max TCP error (mm)")):
        names = list(dict.fromkeys(r["algorithm"] for r in rows))
        for a, marker in zip(names, ("o", "s", "^", "v", "D")):
            rs = [r for r in rows if r["algorithm"] == a]
            if not rs:
                continue
            h = np.array([r["step"] for r in rs]) * 1e3
            e = np.array([r[key] for r in rs]) * scale
            ax.loglog(h, e, marker=marker, label=a)
        rs = [r for r in rows if r["algorithm"] == rows[0]["algorithm"]]
        h = np.array(sorted(r["step"] for r in rs)) * 1e3
        e0 = min(r[key] for r in rs) * scale
        ax.loglog(h, e0 * h / h[0], "k--", lw=0.8, label="slope 1")
        ax.set_xlabel("communication step h (ms)")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    if title:
        fig.suptitle(title)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def study(experiment: str | System, steps: Sequence[float] = DEFAULT_STEPS,
          out_dir: str | Path | None = None, algorithms: Sequence[str] = ALGORITHMS,
          stop_time: float | None = None, fmu_dir: str | Path | None = "fmus",
          progress: Callable[[str], None] | None = print) -> dict:
    """Co-simulation error against the monolithic reference versus the communication step.

    Parameters
    ----------
    experiment : str or System
        Experiment name (loaded with ``fmu_dir``) or a loaded System.
    steps : sequence of float
        Communication steps h (s); ``stop_time`` must be a whole number of each.
    out_dir : str or Path, optional
        Folder for ``convergence.md`` (the table), ``convergence.png`` (log-log figure) and
        ``convergence.json`` (every number). Nothing is written if None.
    algorithms : sequence of str
        Master algorithms to compare ("gauss-seidel", "jacobi"); "in-process" adds the
        Gauss-Seidel loop run in-process on the blocks' logic (no FMI calls).
    stop_time : float, optional
        End of every run (s); default the experiment's.
    fmu_dir : str or Path
        FMU root when ``experiment`` is a name.
    progress : callable, optional
        Receives one line per run (default: print).

    Returns
    -------
    dict
        ``experiment``, ``stop_time`` (s), ``steps`` (s), ``rows`` (one dict per run:
        ``algorithm``, ``step``, ``q_error`` rad, ``qd_error`` rad/s, ``tcp_error`` m,
        ``tracking`` m, ``q_error_at`` s, ``wall_time`` s), ``orders`` (per algorithm: ``q``,
        ``tcp`` observed orders, ``C_q`` = mean of q_error / h (rad/s), and, when Gauss-Seidel
        ran, ``ratio_to_gs`` = mean q error over Gauss-Seidel's), ``reference`` (integrator statistics), ``table`` (markdown),
        ``runtime`` (s), and ``files`` (paths written).
    """
    wall = _time.perf_counter()
    say = progress or (lambda *_: None)
    system = experiment if isinstance(experiment, System) else load(experiment, fmu_dir=fmu_dir)
    stop_time = system.stop_time if stop_time is None else float(stop_time)
    steps = sorted((float(h) for h in steps), reverse=True)
    algorithms = list(algorithms)
    unknown = [a for a in algorithms if a not in ALGORITHMS + ("in-process",)]
    if unknown:
        raise ValueError(f"algorithms: unknown {unknown}; choose from {', '.join(ALGORITHMS)}, in-process")
    if len(steps) < 2:
        raise ValueError("steps: need at least two communication steps")
    for h in steps:
        n = round(stop_time / h)
        if abs(n * h - stop_time) > 1e-9 * max(1.0, stop_time):
            raise ValueError(f"steps: stop time {stop_time} s is not a whole number of {h} s steps")

    roles = Roles.of(system)
    roles.require("q")
    diagram = InProcessDiagram(system)
    loop = diagram.monolithic(stop_time)
    say(f"reference: {system.name}, 0..{stop_time:g} s, DOP853 rtol 1e-10 on "
        f"{loop.stats['pieces']} pieces, {loop.stats['nfev']} evaluations, "
        f"{loop.stats['wall_time']:.1f} s")
    model = roles.model()
    rows, total = [], len(steps) * len(algorithms)
    for a in algorithms:
        for h in steps:
            t0 = _time.perf_counter()
            if a == "in-process":
                result = diagram.sampled(h, stop_time)
            else:
                result = run_cosim(system, h, a, stop_time)
            row = {"algorithm": a, "step": h, **errors(result, loop.evaluate(result.time), roles, model)}
            row["wall_time"] = _time.perf_counter() - t0
            rows.append(row)
            say(f"[{len(rows)}/{total}] {a:12s} h = {h * 1e3:6.3g} ms: max |dq| {row['q_error']:.3e} "
                f"(t = {row['q_error_at']:.3f} s), TCP {row['tcp_error'] * 1e3:.4f} mm, "
                f"tracking {row['tracking'] * 1e3:.4f} mm  [{row['wall_time']:.1f} s]")

    orders: dict[str, dict] = {}
    for a in algorithms:
        rs = [r for r in rows if r["algorithm"] == a]
        hs = [r["step"] for r in rs]
        orders[a] = {"q": observed_order(hs, [r["q_error"] for r in rs]),
                     "tcp": observed_order(hs, [r["tcp_error"] for r in rs]),
                     "C_q": float(np.mean([r["q_error"] / r["step"] for r in rs]))}
    if "gauss-seidel" in orders:
        gs = {r["step"]: r["q_error"] for r in rows if r["algorithm"] == "gauss-seidel"}
        for a in orders:
            if a != "gauss-seidel":
                orders[a]["ratio_to_gs"] = float(np.mean(
                    [r["q_error"] / gs[r["step"]] for r in rows if r["algorithm"] == a]))
    table = markdown_table(rows, orders)
    out = {"experiment": system.name, "stop_time": stop_time, "steps": steps, "rows": rows,
           "orders": orders, "reference": dict(loop.stats), "table": table,
           "runtime": _time.perf_counter() - wall, "files": {}}
    if out_dir is not None:
        out_dir = Path(out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
        head = (f"# Co-simulation convergence: {system.name}, 0 to {stop_time:g} s\n\n"
                "Errors at the communication points against the monolithic reference "
                "(continuous controller, DOP853 rtol 1e-10, piecewise between discontinuities).\n\n")
        out["files"]["table"] = str(out_dir / "convergence.md")
        (out_dir / "convergence.md").write_text(head + table)
        out["files"]["figure"] = str(plot(rows, out_dir / "convergence.png",
                                          f"{system.name}: co-simulation error vs communication step"))
        out["files"]["data"] = str(out_dir / "convergence.json")
        out["runtime"] = _time.perf_counter() - wall
        (out_dir / "convergence.json").write_text(json.dumps(
            {k: v for k, v in out.items() if k != "table"}, indent=2))
    say(f"study done in {out['runtime']:.1f} s")
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m robofmu.system.convergence",
                                description="co-simulation error vs communication step")
    p.add_argument("--experiment", required=True)
    p.add_argument("--steps", default=",".join(f"{h:g}" for h in DEFAULT_STEPS),
                   help="communication steps in s, comma-separated")
    p.add_argument("--stop-time", type=float, default=None)
    p.add_argument("--fmu-dir", default="fmus")
    p.add_argument("--out", default="results/convergence")
    p.add_argument("--algorithms", default="gauss-seidel,jacobi,in-process",
                   help="comma-separated: gauss-seidel, jacobi, in-process (no FMI calls)")
    a = p.parse_args(argv)
    res = study(a.experiment, [float(s) for s in a.steps.split(",")], a.out,
                algorithms=a.algorithms.split(","), stop_time=a.stop_time, fmu_dir=a.fmu_dir)
    print(res["table"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

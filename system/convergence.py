"""Convergence of the co-simulation to the monolithic reference as the communication step shrinks.

For each algorithm (Gauss-Seidel, Jacobi) and each communication step h the experiment is
co-simulated with :class:`~robofmu.system.master.Master` and compared, at its communication
points t_k, with the continuous closed loop of :mod:`robofmu.system.reference` (solved once,
sampled on every grid):

- ``q_error``: max over k and joints of |q_cosim(t_k) - q_mono(t_k)| (rad);
- ``tcp_error``: max over k of ||fk(q_cosim(t_k)) - fk(q_mono(t_k))|| (m);
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
one step, again O(h). Any further delay of d whole steps adds d h to the effective delay: still
O(h), with a larger constant.

What the algorithms do (:func:`sampled_loop` replays the Gauss-Seidel loop in-process and
matches the FMU runs to round-off):

- ``gauss-seidel``: at t_k the outputs are evaluated in dependency order (trajectory, ik, plant,
  controller); inputs from blocks evaluated later (the plant's torque) are set after that pass,
  so the plant integrates [t_k, t_k + h] with tau(t_k): effective delay h / 2.
- ``jacobi``: every block reads the outputs of the previous exchange: the torque applied over
  [t_k, t_k + h] comes from the plant state at t_(k-1) and the joint reference of t_(k-2) (the
  IK lags the trajectory one step, the controller lags the IK one more). Effective delays
  1.5 h on the state, 2.5 h on the reference: first order, with a larger constant.
- ``replica`` (no FMUs): the Gauss-Seidel loop with the blocks' logic called directly.

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

from robofmu.components.robot import Robot

from .diagram import System
from .experiment import load
from .master import ALGORITHMS, Master, Result, step_count
from .reference import LoopSetup, MonolithicLoop

__all__ = ["DEFAULT_STEPS", "ALGORITHMS", "errors", "observed_order", "run_cosim", "sampled_loop",
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
    """Co-simulate ``system`` and record the plant's q and the trajectory (nothing else).

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
        Columns ``plant.q[i]``, ``plant.qd[i]``, ``trajectory.x_ref[i]``, ``controller.tau[i]``.
    """
    master = Master(system, record=["plant.q[[]*", "plant.qd[[]*", "trajectory.x_ref[[]*",
                                    "controller.tau[[]*"])
    return master.run(stop_time=stop_time, step=step, algorithm=algorithm)


def sampled_loop(setup: LoopSetup, step: float, stop_time: float) -> Result:
    """The Gauss-Seidel loop in one Python process: the blocks' logic without FMI.

    At each t_k = k h the trajectory's outputs at t_k (computed at the end of the previous step,
    as the FMU does), the IK, the plant's state and the controller's torque (model payload while
    grip) are recorded; then the integral advances (z += e(t_k) h) and the plant (payload while
    grip) is integrated over [t_k, t_k + h] by RK4 (sub-steps <= ``setup.max_substep``) with
    tau(t_k) held. This is what the master does with the FMUs, call for call, so the two agree
    to the last bit (``benchmarks/loop.py`` checks it and times both).

    Parameters
    ----------
    setup : LoopSetup
    step : float
        Communication step h (s).
    stop_time : float
        End time (s), a whole number of steps.

    Returns
    -------
    Result
        The master's columns, in its order: ``trajectory.x_ref[i]``, ``xd_ref``, ``xdd_ref`` (m,
        m/s, m/s^2), ``ik.q_ref[j]``, ``qd_ref``, ``qdd_ref``, ``plant.q[j]``, ``plant.qd[j]``,
        ``controller.tau[j]``, then ``trajectory.grip`` and ``ik.reachable`` (0/1);
        ``info["wall_time"]`` is the stepping loop's wall time (s).
    """
    from robofmu.components.control import ComputedTorque
    from robofmu.components.ik import make_ik
    from robofmu.components.plant import Plant

    h = float(step)
    n_steps = step_count(0.0, stop_time, h)
    trajectory = setup.trajectory()
    plant = Plant(Robot(setup.robot, gravity=setup.gravity), setup.q0, setup.qd0,
                  payload_mass=setup.payload, max_substep=setup.max_substep)
    model = Robot(setup.robot, gravity=setup.model_gravity)
    law = ComputedTorque(model, setup.kp, setup.kd, setup.ki)
    ik = make_ik(Robot(setup.robot), tool_pitch=setup.tool_pitch, elbow=setup.elbow)
    n, m = plant.n, trajectory.dim
    columns = ([f"trajectory.{b}[{i}]" for b in ("x_ref", "xd_ref", "xdd_ref") for i in range(1, m + 1)]
               + [f"ik.{b}[{j}]" for b in ("q_ref", "qd_ref", "qdd_ref") for j in range(1, n + 1)]
               + [f"plant.{b}[{j}]" for b in ("q", "qd") for j in range(1, n + 1)]
               + [f"controller.tau[{j}]" for j in range(1, n + 1)] + ["trajectory.grip", "ik.reachable"])
    cuts = np.cumsum([0, m, m, m, n, n, n, n, n, n])
    sx, sxd, sxdd, sq_ref, sqd_ref, sqdd_ref, sq, sqd, stau = (slice(a, b) for a, b in zip(cuts, cuts[1:]))
    times = h * np.arange(n_steps + 1)
    data = np.empty((n_steps + 1, len(columns)))
    data[:, -1] = 1.0                                   # reachable: the solve below raises otherwise
    x, xd, xdd = trajectory.evaluate(times[0])
    wall = _time.perf_counter()
    for k, t in enumerate(times):
        row = data[k]
        grip = trajectory.grip(t)
        q_ref, qd_ref, qdd_ref = ik.solve(x, xd, xdd)
        model.set_payload(setup.model_payload if grip else 0.0)
        tau = law.torque(q_ref, qd_ref, qdd_ref, plant.q, plant.qd)
        row[sx], row[sxd], row[sxdd] = x, xd, xdd
        row[sq_ref], row[sqd_ref], row[sqdd_ref] = q_ref, qd_ref, qdd_ref
        row[sq], row[sqd], row[stau] = plant.q, plant.qd, tau
        row[-2] = grip
        if k == n_steps:
            break
        law.advance(q_ref, plant.q, h)
        plant.set_grip(grip)
        plant.step(tau, h, t)
        x, xd, xdd = trajectory.evaluate(t + h)          # the trajectory FMU's outputs at t + h
    return Result(times, columns, data, {"algorithm": "replica", "step": h,
                                         "wall_time": _time.perf_counter() - wall})


def errors(result: Result, loop: MonolithicLoop, robot: Robot | None = None) -> dict[str, float]:
    """Errors of a co-simulation run against the solved monolithic loop, at its time points.

    Parameters
    ----------
    result : Result
        A co-simulation run recording ``plant.q`` (and ``trajectory.x_ref`` for ``tracking``).
    loop : MonolithicLoop
        Solved up to at least the run's last time.
    robot : Robot, optional
        For forward kinematics (default: the loop's robot, no payload).

    Returns
    -------
    dict
        ``q_error`` (rad), ``qd_error`` (rad/s), ``tcp_error`` (m), ``tracking`` (m, NaN if
        ``trajectory.x_ref`` was not recorded), ``q_error_at`` (s, where q_error occurs).
    """
    robot = Robot(loop.setup.robot) if robot is None else robot
    ref = loop.evaluate(result.time, outputs=False)
    q = result.vector("plant.q")
    dq = np.abs(q - ref["q"])
    k = int(np.argmax(dq.max(axis=1)))
    tcp = np.array([robot.fk(v) for v in q])
    tcp_ref = np.array([robot.fk(v) for v in ref["q"]])
    out = {"q_error": float(dq.max()), "q_error_at": float(result.time[k]),
           "tcp_error": float(np.linalg.norm(tcp - tcp_ref, axis=1).max()),
           "tracking": math.nan, "qd_error": math.nan}
    try:
        out["qd_error"] = float(np.abs(result.vector("plant.qd") - ref["qd"]).max())
    except KeyError:
        pass
    try:
        out["tracking"] = float(np.linalg.norm(tcp - result.vector("trajectory.x_ref"), axis=1).max())
    except KeyError:
        pass
    return out


def markdown_table(rows: list[dict], orders: dict) -> str:
    """The study's rows as a markdown table, then the observed orders."""
    lines = ["| algorithm | h (ms) | max abs q error (rad) | max TCP error (mm) | local order (q) "
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
                     f"error constant C = {o['C_q']:.3g} rad/s (q error ~ C h)")
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
    for ax, key, scale, label in ((axes[0], "q_error", 1.0, "max |q - q_ref| (rad)"),
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


def study(experiment: str | System = "chess-pd", steps: Sequence[float] = DEFAULT_STEPS,
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
        Master algorithms to compare ("gauss-seidel", "jacobi"); "replica" adds the sampled
        loop run in-process with the intended Gauss-Seidel semantics (:func:`sampled_loop`).
    stop_time : float, optional
        End of every run (s); default the experiment's (13 s for the chess task).
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
    unknown = [a for a in algorithms if a not in ALGORITHMS + ("replica",)]
    if unknown:
        raise ValueError(f"algorithms: unknown {unknown}; choose from {', '.join(ALGORITHMS)}, replica")
    if len(steps) < 2:
        raise ValueError("steps: need at least two communication steps")
    for h in steps:
        n = round(stop_time / h)
        if abs(n * h - stop_time) > 1e-9 * max(1.0, stop_time):
            raise ValueError(f"steps: stop time {stop_time} s is not a whole number of {h} s steps")

    loop = MonolithicLoop(LoopSetup.from_system(system)).solve(stop_time)
    say(f"reference: {system.name}, 0..{stop_time:g} s, DOP853 rtol {loop.rtol:g} on "
        f"{loop.stats['pieces']} pieces, {loop.stats['nfev']} evaluations, "
        f"{loop.stats['wall_time']:.1f} s")
    robot = Robot(loop.setup.robot)
    rows, total = [], len(steps) * len(algorithms)
    for a in algorithms:
        for h in steps:
            t0 = _time.perf_counter()
            if a == "replica":
                result = sampled_loop(loop.setup, h, stop_time)
            else:
                result = run_cosim(system, h, a, stop_time)
            row = {"algorithm": a, "step": h, **errors(result, loop, robot)}
            row["wall_time"] = _time.perf_counter() - t0
            rows.append(row)
            say(f"[{len(rows)}/{total}] {a:12s} h = {h * 1e3:6.3g} ms: max |dq| {row['q_error']:.3e} rad "
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
    p.add_argument("--experiment", default="chess-pd")
    p.add_argument("--steps", default=",".join(f"{h:g}" for h in DEFAULT_STEPS),
                   help="communication steps in s, comma-separated")
    p.add_argument("--stop-time", type=float, default=None)
    p.add_argument("--fmu-dir", default="fmus")
    p.add_argument("--out", default="results/convergence")
    p.add_argument("--algorithms", default="gauss-seidel,jacobi,replica",
                   help="comma-separated: gauss-seidel, jacobi, replica (in-process, no FMUs)")
    a = p.parse_args(argv)
    res = study(a.experiment, [float(s) for s in a.steps.split(",")], a.out,
                algorithms=a.algorithms.split(","), stop_time=a.stop_time, fmu_dir=a.fmu_dir)
    print(res["table"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

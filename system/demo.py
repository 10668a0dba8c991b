"""`robofmu demo`: the flagship study of seed 002, reproduced and extended."""
from __future__ import annotations

import sys
import time
from pathlib import Path

from . import plots
from .analysis import markdown_table
from .runner import run_experiment

EXPERIMENTS = ["chess-pd", "chess-pid", "chess-pd-unknown-pawn", "chess-pid-unknown-pawn"]


def accuracy_section(out: Path, fmu_dir, quick: bool) -> list[str]:
    """Co-simulation error against the monolithic reference versus the communication step."""
    from .convergence import study

    steps = (0.01, 0.005, 0.002) if quick else (0.01, 0.005, 0.002, 0.001, 0.0005)
    print("accuracy study: chess-pd against the monolithic reference", file=sys.stderr)
    res = study("chess-pd", steps=steps, out_dir=out / "convergence", fmu_dir=fmu_dir,
                progress=lambda line: print("  " + line, file=sys.stderr))
    return ["## Accuracy: co-simulation against a monolithic reference", "",
            "The same closed loop as one ODE (continuous controller, DOP853 at rtol 1e-10, integrated "
            "piecewise between the trajectory's discontinuities) against the co-simulation at its "
            "communication points. The torque is held over each step (zero-order hold, an effective "
            "delay of h/2), so the error is first order in h; Jacobi adds a step of delay through the "
            "IK and the controller and a larger constant.", "",
            res["table"], "", "![convergence](convergence/convergence.png)", ""]


def step_section(out: Path, fmu_dir) -> list[str]:
    """Joint-reference steps through the controller and plant FMUs against python-control."""
    from robofmu.components.robot import load_spec

    from . import stepresponse as sr

    print("step responses: PD and PID seed gains, and gains designed for 0.3 s / 5 %", file=sys.stderr)
    spec = load_spec("chess")
    lines = ["## Step responses", "",
             "A 0.02 rad step on every joint's reference through the controller and plant FMUs "
             "(1 ms), against python-control: the continuous error dynamics, its ZOH discretization "
             "and the sampled-data loop (a ZOH-discretized double integrator closed by the sampled "
             "controller), which is what the FMUs implement. Metrics are taken relative to the "
             "initial value and time of the step.", ""]
    cases = [("PD (seed)", spec.gains("pd")), ("PID (seed)", spec.gains("pid"))]
    design = sr.design_gains(0.3, 5.0)
    cases.append(("PD designed for 0.3 s, 5 %", {"kp": design.kp, "kd": design.kd, "ki": design.ki}))
    rows = []
    for k, (label, g) in enumerate(cases):
        cmp = sr.compare(sr.cosimulate_step(fmu_dir, g["kp"], g["kd"], g["ki"], step=0.02, h=1e-3))
        fig = sr.plot_comparison(cmp, out / "step", name=f"step_{k + 1}")
        m = cmp.metrics["joint 2"]
        rows.append([label, f"{g['kp']:.4g}, {g['kd']:.4g}, {g['ki']:.4g}", f"{m.rise_time:.4f}",
                     f"{m.settling_time:.4f}", f"{m.overshoot:.2f}", f"{cmp.max_deviation('sampled'):.3f}",
                     f"{cmp.max_deviation('zoh'):.3f}"])
        lines.append(f"![{label}](step/{fig.name})")
    lines[-len(cases):-len(cases)] = [markdown_table(rows, [
        "gains", "kp, kd, ki", "rise (s)", "settling (s)", "overshoot (%)",
        "max dev. from sampled-data model (% of step)", "max dev. from c2d ZOH (% of step)"]), ""]
    return lines + [""]


def demo(out: Path, fmu_dir: str | Path = "fmus", quick: bool = False) -> int:
    """Run every chess experiment and write ``out/report.md`` with the figures beside it."""
    start = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    runs = {}
    for name in EXPERIMENTS:
        runs[name] = run_experiment(name, out / name, fmu_dir=fmu_dir)
    results = {n: r.result for n, r in runs.items()}
    figs = [plots.error_comparison(results, out / "tracking_error_pd_vs_pid.png"),
            plots.tcp_error({n: (r.result.time, r.metrics.tcp_error) for n, r in runs.items()},
                            out / "tcp_error.png")]
    rows = []
    for n, r in runs.items():
        m = r.metrics
        ev = list(m.events.values())
        rows.append([n, f"{max(m.max_error) * 1e3:.3f}", f"{max(m.rms_error) * 1e3:.3f}",
                     f"{max(m.tcp_error) * 1e3:.3f}", f"{ev[0][1] * 1e3:.3f}", f"{ev[1][1] * 1e3:.3f}",
                     f"{max(m.peak_torque):.3f}"])
    summary = markdown_table(rows, ["experiment", "max joint error (mrad)", "max RMS (mrad)",
                                    "max TCP error (mm)", "TCP error at pick (mm)",
                                    "TCP error at place (mm)", "peak torque (N.m)"])
    sections = ["# robofmu demo: computed-torque control of the chess arm", "",
                "Seed 002's Simulink study (queen's gambit, d2 -> d4) as a co-simulation of four FMUs "
                "(trajectory -> ik -> controller -> plant), Gauss-Seidel at 1 ms.", "",
                "## Summary", "", summary, "",
                "![tracking error](tracking_error_pd_vs_pid.png)", "", "![TCP error](tcp_error.png)", ""]
    for n, r in runs.items():
        sections += [r.section.replace("### ", "## "), "",
                     *[f"![{p.stem}]({n}/{p.name})" for p in r.figures], ""]
    sections += accuracy_section(out, fmu_dir, quick)
    sections += step_section(out, fmu_dir)
    sections.append(f"_Generated by `robofmu demo` in {time.perf_counter() - start:.1f} s._")
    (out / "report.md").write_text("\n".join(sections) + "\n")
    print(summary)
    print(f"\nwrote {out / 'report.md'} and {len(figs) + sum(len(r.figures) for r in runs.values())} figures "
          f"in {out} ({time.perf_counter() - start:.1f} s)", file=sys.stderr)
    return 0

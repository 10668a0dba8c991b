"""Benchmark: the cost per communication step of the industrial arms' pose experiments, as a ratio
to chess-pd in the same process, and their IK iterations per step.

Each experiment runs whole through the master (``robofmu run`` without figures); the time is the
master's loop (``wall_time``: the FMUs instantiated, stepping only) divided by its communication
steps, best of ``--repeats``. The aims (issue 22): at most 2x chess-pd per step, and a median of
at most 2 IK iterations per step.

    make bench            # or: .venv/bin/python benchmarks/arms.py [--fmus DIR] [--repeats N]
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

import robofmu.components  # noqa: F401  (the installed copy before any bundled one)
from robofmu.system.run import run_experiment

BASELINE = "chess-pd"
ARMS = ("ur5-pose", "panda-pose")
#: The aims: cost per step over chess-pd's, median IK iterations per step.
AIM_RATIO, AIM_ITERATIONS = 2.0, 2.0


def per_step(name: str, fmus: str, repeats: int, stop_time: float | None = None) -> tuple[float, np.ndarray | None]:
    """Best loop time per communication step (s) and the IK's recorded iterations (or None), over
    the experiment's whole run (or its first ``stop_time`` s)."""
    best, iterations = float("inf"), None
    for _ in range(repeats):
        with tempfile.TemporaryDirectory() as out:
            run = run_experiment(name, Path(out) / name, fmus, stop_time=stop_time, progress=False, figures=False)
        steps = len(run.result.time) - 1
        best = min(best, run.result.info["wall_time"] / steps)
        if "ik.iterations" in run.result.columns:
            iterations = run.result["ik.iterations"][1:]
    return best, iterations


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fmus", default="fmus")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--stop-time", type=float, help="run each experiment's first T s only (default: whole)")
    parser.add_argument("--quick", action="store_true", help="a smoke test: 0.1 s of each experiment, one repeat")
    args = parser.parse_args(argv)
    if args.quick:
        args.stop_time, args.repeats = 0.1, 1
    base, _ = per_step(BASELINE, args.fmus, args.repeats, args.stop_time)
    print(f"\nCost per communication step, ratio to {BASELINE} ({base * 1e6:.0f} µs) in this process "
          f"(aims: <= {AIM_RATIO:g}x, median IK iterations <= {AIM_ITERATIONS:g})\n")
    print("| experiment | µs per step | ratio to chess-pd | IK iterations per step: median | mean | max |")
    print("|---|---|---|---|---|---|")
    print(f"| {BASELINE} | {base * 1e6:.0f} | 1.00 | — | — | — |")
    for name in ARMS:
        cost, iterations = per_step(name, args.fmus, args.repeats, args.stop_time)
        it = ("—", "—", "—") if iterations is None else (
            f"{np.median(iterations):g}", f"{iterations.mean():.2f}", f"{iterations.max():g}")
        print(f"| {name} | {cost * 1e6:.0f} | {cost / base:.2f} | {it[0]} | {it[1]} | {it[2]} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

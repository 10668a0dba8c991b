"""Benchmark: what a multi-rate run costs per plant step against the same run single-rate.

For each experiment (default chess-pd and ur5-pose), two runs through the master at the base
step h (default 1 ms), taking turns in this process, best of ``--repeats`` each:

- ``single-rate``: every block at h, as the experiment is;
- ``multi-rate``: the plant (the block of the ``q`` role) at h, every other block at
  ``--ratio`` x h (default 4: 4 ms), stepped only where due, its outputs held in between.

The time is the master's stepping loop (``wall_time``) over the base steps, which are the
plant's steps in both runs. The aim (issue 30): the multi-rate run is cheaper per plant step.
The last column is how far the plant's joints move from the single-rate run's (the slower
controller changes the loop; rad or m).

    make bench            # or: .venv/bin/python benchmarks/multirate.py [--fmus DIR] [--experiments ...]
"""
from __future__ import annotations

import argparse
import sys

import numpy as np

import robofmu.components  # noqa: F401  (the installed copy before any bundled one)
from robofmu.system import experiment
from robofmu.system.master import Master


def systems(name: str, fmus: str, h: float, ratio: int):
    """The experiment single-rate and with every block but the plant at ``ratio`` h, and its q role."""
    single = experiment.load(name, fmu_dir=fmus)
    q = single.extra.get("roles", {}).get("q")
    if not q:
        raise SystemExit(f"{name}: no q role names the plant's joints; cannot tell which block is the plant")
    plant = q.split(".")[0]
    multi = experiment.load(name, fmu_dir=fmus)
    for block in multi.blocks:
        if block.name != plant:
            block.sample_time = ratio * h
    return single, multi, q


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--experiments", nargs="+", default=["chess-pd", "ur5-pose"])
    parser.add_argument("--fmus", default="fmus")
    parser.add_argument("--step-size", type=float, default=1e-3, help="base step h (s), the plant's")
    parser.add_argument("--ratio", type=int, default=4, help="every other block's sample time in base steps")
    parser.add_argument("--stop-time", type=float, default=3.0, help="each run's stop time (s)")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--quick", action="store_true", help="a smoke test: 0.1 s, one repeat")
    args = parser.parse_args(argv)
    if args.quick:
        args.stop_time, args.repeats = 0.1, 1
    h, rows = args.step_size, []
    for name in args.experiments:
        single, multi, q = systems(name, args.fmus, h, args.ratio)
        best = {"single": float("inf"), "multi": float("inf")}
        results = {}
        for _ in range(args.repeats):        # taking turns: the machine's load hits both alike
            for kind, system in (("single", single), ("multi", multi)):
                result = Master(system).run(args.stop_time, h)
                best[kind] = min(best[kind], result.info["wall_time"] / (len(result.time) - 1))
                results[kind] = result
        columns = [c for c in results["single"].columns if c.startswith(f"{q}[")]
        moved = max(float(np.max(np.abs(results["multi"][c] - results["single"][c]))) for c in columns)
        rows.append((name, best["single"] * 1e6, best["multi"] * 1e6, moved))
    print(f"\n## Multi-rate: the plant at {h * 1e3:g} ms, every other block at {args.ratio * h * 1e3:g} ms "
          f"({args.stop_time:g} s runs, best of {args.repeats} each, taking turns; µs per plant step)\n")
    print("| experiment | single-rate | multi-rate | multi-rate / single-rate | max abs(q − q single-rate) |")
    print("|---|---|---|---|---|")
    for name, one, many, moved in rows:
        print(f"| {name} | {one:.1f} | {many:.1f} | {many / one:.2f} | {moved:.2g} |")
    verdicts = ", ".join(f"{'met' if many < one else 'NOT met'} on {name} ({many / one:.2f}x)"
                         for name, one, many, _ in rows)
    print(f"\nmulti-rate cheaper per plant step than single-rate: {verdicts}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

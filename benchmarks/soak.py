"""Soak test: 10^6 communication steps of one experiment through the robofmu master in one process,
resident memory measured at ten points; it fails if memory grows after the first tenth.

    make soak            # or: .venv/bin/python benchmarks/soak.py [--experiment chess-pd] [--fmus fmus]
                         #         [--steps 1000000] [--step-size 0.001] [--stop-time 13] [--limit 5]

The long-running user this stands for runs the experiment again and again in one process (a
parameter study, an optimizer, a service): full runs of the experiment's own length (chess-pd:
13 s at 1 ms, 13 001 points), one after the other, until the steps add up to ``--steps``
(chess-pd: 77 runs, 1 001 000 steps). Every run instantiates, initializes, steps, terminates and
frees its four FMUs, so both kinds of leak show: per step (the master's loop, the FMUs' Python)
and per run (FMU extraction, loading and unloading of the binaries, instance creation). Each run
records only ``plant.q`` (the master preallocates what it records: every output of chess-pd for
13 s is 3.7 MB, freed after the run) and is reduced to its final joint angles, which must be
the first run's, bit for bit.

One run of 10^6 steps would instead grow by its own recording (points x signals x 8 bytes),
which is not a leak; ``--stop-time`` lengthens the runs for a user with long runs (``--stop-time 1000``:
one run, most of it at rest after the motion).

Resident memory is ``VmRSS`` of /proc/self/status after the run that completes each tenth of
the steps. The soak passes (exit 0) when the largest value from the first tenth on exceeds the
value at the first tenth by less than ``--limit`` MB (default 5); the first tenth is the
warm-up (imports, the first extraction, caches, the allocator's arenas). The table also shows
``sys.path``: pythonfmu 0.7.0 inserts each instance's resources folder into it at every
instantiation and never removes it (four entries per run, each a deleted folder).
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

import robofmu.components  # noqa: F401  (the installed copy first, before any FMU's bundle)
from robofmu.system import options
from robofmu.system.plan import step_count
from robofmu.system.experiment import load
from robofmu.system.master import Master


def rss_mb() -> float:
    """Resident set size of this process now (MB): VmRSS of /proc/self/status."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0          # kB
    raise RuntimeError("no VmRSS in /proc/self/status")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--experiment", default="chess-pd")
    parser.add_argument("--fmus", default="fmus", help="FMU root folder (default fmus)")
    parser.add_argument("--steps", type=int, default=1_000_000, help="communication steps in all (default 10^6)")
    options.add_step_size(parser)
    options.add_stop_time(parser)
    parser.add_argument("--record", nargs="*", default=["plant.q"], help="what each run records (default plant.q)")
    parser.add_argument("--limit", type=float, default=5.0, help="allowed growth after the first tenth (MB)")
    args = parser.parse_args(argv)
    if args.steps < 10:
        parser.error("--steps must be at least 10")

    system = load(args.experiment, fmu_dir=args.fmus)
    h = system.step if args.step_size is None else args.step_size
    stop = system.stop_time if args.stop_time is None else args.stop_time
    per_run = step_count(0.0, stop, h)
    runs = math.ceil(args.steps / per_run)
    marks = [math.ceil(args.steps * k / 10) for k in range(1, 11)]       # steps completing each tenth
    master = Master(system, record=args.record)
    print(f"soak: {args.experiment}, {runs} runs of {stop:g} s at h = {h:g} s ({per_run} steps each, "
          f"{runs * per_run} in all), recording {', '.join(args.record)}; pid {os.getpid()}", flush=True)
    print(f"  VmRSS after the imports: {rss_mb():.1f} MB", flush=True)

    header = f"{'point':>5}  {'runs':>5}  {'steps':>9}  {'VmRSS (MB)':>10}  {'vs 10 % (MB)':>12}  {'sys.path':>8}  {'wall (s)':>8}"
    print(header)
    print("-" * len(header))
    rows, first, done, t0 = [], None, 0, time.perf_counter()
    for run in range(1, runs + 1):
        result = master.run(stop, h)
        final = result.data[-1].copy()
        del result
        if first is None:
            first = final
        elif not np.array_equal(final, first):
            print(f"run {run}: the final state differs from the first run's by "
                  f"{np.max(np.abs(final - first)):.3g}: runs in one process must be repeatable", flush=True)
            return 1
        done += per_run
        while marks and done >= marks[0]:
            marks.pop(0)
            rss = rss_mb()
            base = rows[0][3] if rows else rss
            rows.append((len(rows) + 1, run, done, rss, rss - base, len(sys.path), time.perf_counter() - t0))
            print(f"{rows[-1][0]:>5}  {run:>5}  {done:>9}  {rss:>10.1f}  {rss - base:>+12.2f}  {len(sys.path):>8}  "
                  f"{rows[-1][6]:>8.1f}", flush=True)

    growth = max(r[3] for r in rows) - rows[0][3]
    ok = growth < args.limit
    print(f"growth after the first 10 %: {growth:+.2f} MB (limit {args.limit:g} MB): {'PASS' if ok else 'FAIL'}; "
          f"{done} steps in {time.perf_counter() - t0:.0f} s, every run's final state equal to the first's")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())

"""Benchmark: sweep throughput on local Dask workers, and the cost a sweep adds to each run.

One experiment (default ``rrp-line``), N runs varying the controller's ``gain_scale`` (every
run does the same work). Measured, in this order:

- ``robofmu run``: the command as a user types it (a new interpreter, the FMUs, results.csv,
  figures and report), best of two;
- the master in-process: plan, instantiate, run and analyse one run, best of three (what each
  sweep run does inside its worker);
- the sweep with 1 and with 2 local worker processes (interleaved rounds, the best of each): runs per minute from the first run
  submitted to the last row written (the cluster's start is given beside it: a fixed cost per
  sweep, not per run), and the overhead per run against the in-process run.

    make bench            # or: .venv/bin/python benchmarks/sweep.py [--runs N] [--fmus DIR] [EXPERIMENT]
"""
from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def single_run(experiment: str, fmus: str, work: Path, stop_time: float | None = None) -> float:
    best = float("inf")
    stop = [] if stop_time is None else ["--stop-time", str(stop_time)]
    for k in range(2):
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "robofmu.system.cli", "run", experiment, "--fmus", fmus,
                        "--out", str(work / f"single-{k}"), *stop], check=True, capture_output=True)
        best = min(best, time.perf_counter() - start)
    return best


def in_process(experiment: str, fmus: str, stop_time: float | None = None) -> float:
    from robofmu.system.sweep.design import Design, parse_axis
    from robofmu.system.sweep.run import check
    from robofmu.system.sweep.worker import run_one

    design = Design(experiment, [parse_axis("controller.gain_scale=1,1.001")], stop_time=stop_time)
    system, *_ , runs = check(design, fmus)
    times = []
    for _ in range(3):
        start = time.perf_counter()
        record = run_one(system, runs[0], stop_time, None)
        assert record["status"] == "ok", record["message"]
        times.append(time.perf_counter() - start)
    return min(times)


def one_sweep(experiment: str, fmus: str, workers: int, runs: int, work: Path,
              stop_time: float | None = None) -> tuple[float, float, float]:
    from robofmu.system.sweep import engine
    from robofmu.system.sweep.design import Design, parse_axis
    from robofmu.system.sweep.run import check

    values = ",".join(f"{1 + 1e-3 * k:.3f}" for k in range(runs))
    design = Design(experiment, [parse_axis(f"controller.gain_scale={values}")], stop_time=stop_time)
    system, *_, listed = check(design, fmus)
    start = time.perf_counter()
    with engine.cluster_client(workers) as client:
        client.wait_for_workers(workers)
        ready = time.perf_counter()
        records = []
        engine.execute(client, system, list(enumerate(listed)), stop_time, None, None,
                       lambda index, record: records.append(record), tag=f"bench-{workers}")
        done = time.perf_counter()
    assert all(r["status"] == "ok" for r in records), [r["message"] for r in records]
    return runs / (done - ready) * 60.0, ready - start, statistics.median(r["wall_time"] for r in records)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("experiment", nargs="?", default="rrp-line")
    parser.add_argument("--runs", type=int, default=12, help="runs per sweep (default 12)")
    parser.add_argument("--rounds", type=int, default=3, help="1- and 2-worker sweeps interleaved, best of each "
                                                               "(default 3: the machine is shared)")
    parser.add_argument("--fmus", default="fmus")
    parser.add_argument("--stop-time", type=float, help="each run's first T s only (default: the experiment's)")
    parser.add_argument("--quick", action="store_true", help="a smoke test: 4 runs of 0.1 s, one round")
    args = parser.parse_args(argv)
    if args.quick:
        args.runs, args.rounds, args.stop_time = 4, 1, 0.1
    stop = args.stop_time
    with tempfile.TemporaryDirectory() as folder:
        work = Path(folder)
        cli = single_run(args.experiment, args.fmus, work, stop)
        inside = in_process(args.experiment, args.fmus, stop)
        rounds = [(one_sweep(args.experiment, args.fmus, 1, args.runs, work, stop),
                   one_sweep(args.experiment, args.fmus, 2, args.runs, work, stop)) for _ in range(args.rounds)]
        one, two = max(r[0] for r in rounds), max(r[1] for r in rounds)
    print(f"\n## Sweep throughput: {args.experiment}, {args.runs} runs per sweep\n")
    print("| | runs per minute | per run (s) | cluster start (s) | vs. 1 worker |")
    print("|---|---|---|---|---|")
    print(f"| `robofmu run` (new process, figures) | {60 / cli:.1f} | {cli:.3f} | — | — |")
    print(f"| one run in-process (plan, run, metrics) | {60 / inside:.1f} | {inside:.3f} | — | — |")
    for label, (rate, startup, median) in (("sweep, 1 worker", one), ("sweep, 2 workers", two)):
        print(f"| {label} | {rate:.1f} | {60 / rate:.3f} (median in a worker {median:.3f}) | {startup:.2f} | "
              f"{rate / one[0]:.2f}x |")
    overhead = 60 / one[0] - inside
    print(f"\nOverhead per run on 1 worker: {overhead:+.3f} s against the in-process run "
          f"({overhead / inside * 100:+.0f} %); a `robofmu run` costs {cli / (60 / one[0]):.2f}x a sweep run.")
    ratios = ", ".join(f"{b[0] / a[0]:.2f}x" for a, b in rounds)
    print(f"Two workers give {two[0] / one[0]:.2f}x the throughput of one (best of each; round by round {ratios}; "
          "acceptance: at least 1.7x).")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Benchmark: the master's own overhead in instructions, which the machine's load does not move.

    .venv/bin/python benchmarks/instructions.py [--experiment chess-pd] [--fmus fmus] [--step-size 0.001]

``benchmarks/loop.py`` times the master against the in-process loop (the same block logic in one
Python loop, no FMI); on a shared machine that ratio moves by 10-30 % from run to run. This
script counts instead: each runner in a fresh process under valgrind's callgrind, once for
``--short`` and once for ``--long`` steps; the difference over ``long - short`` is the
instructions of one step, start-up and the FMUs' instantiation cancelled. ``PYTHONHASHSEED=0``
and ``OPENBLAS_NUM_THREADS=1`` (idle BLAS threads spin under callgrind) make the count
repeatable to a few hundred instructions a step. Instructions are not time: the master's FMI
boundary misses the caches more often than the block arithmetic, so the timed ratio sits above
this one (docs/design.md, "Speed").

Without valgrind the script says so and counts nothing; ``--quick`` runs the two children
natively on a few steps (the smoke test of ``make bench``).
"""
from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from loop import AIM_IN_PROCESS  # the master's own overhead aim (issue 30): one place, loop.py

ROOT = Path(__file__).resolve().parents[1]
RUNNERS = ("robofmu", "in-process")


def child(experiment: str, runner: str, h: float, steps: int, fmu_root: str) -> None:
    import robofmu.components  # noqa: F401  (the installed copy first, before any FMU's bundle)
    from robofmu.system.experiment import load

    system = load(experiment, fmu_dir=fmu_root)
    if runner == "robofmu":
        from robofmu.system.master import Master

        result = Master(system).run(steps * h, h)
    else:
        from robofmu.system.studies.replica import InProcessDiagram

        result = InProcessDiagram(system).sampled(h, steps * h)
    print(f"STEPS {len(result.time) - 1} {result.info.get('calls', '')}")


def counted(argv: list[str], folder: Path, valgrind: str | None) -> tuple[int | None, str]:
    """Instructions of the child ``argv`` (None without valgrind) and its stdout."""
    environment = {**os.environ, "PYTHONHASHSEED": "0", "OPENBLAS_NUM_THREADS": "1"}
    command = [sys.executable, str(Path(__file__).resolve()), *argv]
    if valgrind:
        out = folder / "callgrind.out"
        command = [valgrind, "--tool=callgrind", f"--callgrind-out-file={out}", *command]
    done = subprocess.run(command, capture_output=True, text=True, cwd=ROOT, env=environment)
    if done.returncode != 0 or "STEPS" not in done.stdout:
        raise RuntimeError(f"{' '.join(argv)}: child failed ({done.returncode})\n{done.stdout[-2000:]}\n"
                           f"{done.stderr[-3000:]}")
    if not valgrind:
        return None, done.stdout
    found = re.search(r"Collected\s*:\s*(\d+)", done.stderr)
    if not found:
        raise RuntimeError(f"callgrind printed no count:\n{done.stderr[-2000:]}")
    return int(found.group(1)), done.stdout


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--experiment", default="chess-pd", help="experiment to run (default chess-pd)")
    parser.add_argument("--fmus", default="fmus", help="FMU root folder (default fmus)")
    parser.add_argument("--step-size", type=float, default=1e-3, help="communication step (s; default 0.001)")
    parser.add_argument("--short", type=int, default=100, help="steps of the short run (default 100)")
    parser.add_argument("--long", type=int, default=2100, help="steps of the long run (default 2100)")
    parser.add_argument("--quick", action="store_true", help="a smoke test: natively, 5 and 15 steps")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--steps", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        child(args.experiment, args.child, args.step_size, args.steps, args.fmus)
        return 0
    if args.long <= args.short or args.short < 1:
        parser.error("--long must exceed --short, and --short be at least 1")
    valgrind = None if args.quick else shutil.which("valgrind")
    short, long = (5, 15) if args.quick else (args.short, args.long)
    how = ("quick: the children run natively, nothing counted" if args.quick
           else f"callgrind, (I({long} steps) - I({short} steps)) / {long - short}")
    print(f"{args.experiment} at h = {args.step_size * 1e3:g} ms: instructions a step ({how})\n")
    if not args.quick and valgrind is None:
        print("valgrind not found: nothing counted (Debian: apt-get install valgrind)")
        return 0
    per = {}
    calls = ""
    with tempfile.TemporaryDirectory() as folder:
        for runner in RUNNERS:
            counts = []
            for steps in (short, long):
                count, out = counted(["--experiment", args.experiment, "--child", runner, "--steps", str(steps),
                                      "--step-size", repr(args.step_size), "--fmus", args.fmus], Path(folder), valgrind)
                counts.append(count)
                if runner == "robofmu":
                    calls = out.split("STEPS", 1)[1].split(maxsplit=1)[1].strip()
            per[runner] = None if None in counts else (counts[1] - counts[0]) / (long - short)
    print(f"{'runner':<12}{'instructions a step':>22}{'x in-process':>14}")
    print("-" * 48)
    for runner in RUNNERS:
        if per[runner] is None:
            print(f"{runner:<12}{'(quick: not counted)':>22}{'—':>14}")
        else:
            print(f"{runner:<12}{per[runner] / 1e3:>21.1f}k{per[runner] / per['in-process']:>14.3f}")
    print(f"\nthe master's FMI calls: {calls}")
    if per["robofmu"] is not None:
        ratio = per["robofmu"] / per["in-process"]
        print(f"robofmu master <= {AIM_IN_PROCESS:.2f}x in-process in instructions: "
              f"{'met' if ratio <= AIM_IN_PROCESS else 'NOT met'} ({ratio:.3f}x)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Benchmark: the FMI cost of one communication step per block, beside the same logic called directly.

For every block of every robot, one communication step is what the master does at every point:
set the inputs (one batched call per type), get the outputs, doStep. The direct column runs the
block's own FMI-free logic (robofmu.components.blocks) on the same values: set the inputs,
compute the outputs, advance. Inputs are the FMU's start values (the robot at home). Times are
the best of several repeats. The FMI column calls through fmpy's ``FMU2Slave`` methods, as a
script using fmpy does (Python lists converted at every call: several µs a call of fmpy's own);
the master binds the FMI functions itself (``benchmarks/split.py`` times that way).

    make bench            # or: .venv/bin/python benchmarks/run.py [--fmus DIR] [--steps N] [ROBOT ...]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

import robofmu.components  # noqa: F401  (the installed copy before any bundled one)
from robofmu.components.blocks import make_block
from robofmu.components.robots import available, load_description
from robofmu.system.fmu import FMUInstance

H = 1e-3


def best_of(fn, steps: int, repeats: int) -> float:
    """Best wall time per step (s) of ``fn(k)`` over ``steps`` calls, best of ``repeats``."""
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        for k in range(steps):
            fn(k)
        best = min(best, (time.perf_counter() - t0) / steps)
    return best


def one_block(path: Path, robot: str, kind: str):
    """(FMI step, direct step) callables for one block, fed with its start values."""
    fmu = FMUInstance(path, kind)
    fmu.initialize()
    reals_in = [v for v in fmu.md.modelVariables if v.causality == "input" and v.type == "Real"]
    reals_out = [v for v in fmu.md.modelVariables if v.causality == "output" and v.type == "Real"]
    bools_out = [v for v in fmu.md.modelVariables if v.causality == "output" and v.type == "Boolean"]
    vin = [v.valueReference for v in reals_in]
    values = [float(v.start) for v in reals_in]
    vout = [v.valueReference for v in reals_out]
    vbool = [v.valueReference for v in bools_out]
    slave = fmu.slave
    clock = [0, 0]              # steps taken by the FMU and by the logic: time goes on across repeats

    def fmi(k):
        if vin:
            slave.setReal(vin, values)
        slave.getReal(vout)
        if vbool:
            slave.getBoolean(vbool)
        slave.doStep(clock[0] * H, H)          # the FMU refuses a point that does not continue its time
        clock[0] += 1

    logic = make_block(robot, kind)
    logic.configure()
    slots = np.array([logic.index[v.name] for v in reals_in], dtype=np.intp)
    start = np.array(values)

    def direct(k):
        t = clock[1] * H
        logic.values[slots] = start
        logic.output(t)
        logic.advance(t, H)
        clock[1] += 1

    return fmu, fmi, direct


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("robots", nargs="*", help="robots (default: all described)")
    parser.add_argument("--fmus", default="fmus", help="FMU root folder (default fmus)")
    parser.add_argument("--steps", type=int, default=2000, help="steps per repeat")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--quick", action="store_true", help="a smoke test: 20 steps, one repeat")
    args = parser.parse_args(argv)
    if args.quick:
        args.steps, args.repeats = 20, 1
    root = Path(args.fmus)
    robots = args.robots or available()
    rows = []
    for robot in robots:
        for kind in load_description(robot).blocks:
            path = root / robot / f"{kind}.fmu"
            if not path.is_file():
                print(f"no {path}: run `robofmu build --out {root}` first", file=sys.stderr)
                return 2
            fmu, fmi, direct = one_block(path, robot, kind)
            try:
                t_fmi = best_of(fmi, args.steps, args.repeats)
                t_direct = best_of(direct, args.steps, args.repeats)
            finally:
                fmu.close()
            rows.append((robot, kind, t_direct * 1e6, t_fmi * 1e6, t_fmi / t_direct))
    width = max([len("robot")] + [len(r[0]) for r in rows]) + 2
    header = f"{'robot':<{width}}{'block':<12}{'direct (us)':>13}{'through FMI (us)':>18}{'ratio':>8}"
    print(header)
    print("-" * len(header))
    for robot, kind, direct_us, fmi_us, ratio in rows:
        print(f"{robot:<{width}}{kind:<12}{direct_us:>13.1f}{fmi_us:>18.1f}{ratio:>8.2f}")
    print(f"\none communication step (set inputs, get outputs, doStep) at h = {H * 1e3:g} ms; "
          f"best of {args.repeats} x {args.steps} steps")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Benchmark: a whole experiment (default chess-pd, 13 s) through the robofmu master, the same
block logic in one Python loop without FMI, libcosim and ecos on the SSP export of the same
diagram, and the diagram as one FMU container.

    .venv/bin/python benchmarks/loop.py [--experiment chess-pd] [--fmus fmus] [--step-sizes 0.001 0.005] [--stop-time 13]

Runners (each in a fresh child process, one after the other):

- ``robofmu``: ``Master(system).run(stop, h)`` (Gauss-Seidel), every output recorded;
- ``in-process``: :meth:`robofmu.system.studies.replica.InProcessDiagram.sampled`, the FMUs' own
  FMI-free block logic called in the master's order, the same outputs recorded into a
  preallocated array: it reproduces the master exactly (the correctness lines print the difference);
- ``libcosim``: :func:`robofmu.system.interop.libcosim.run_ssp_libcosim` on ``export_ssp(system)``
  (libcosim's fixed-step, Jacobi-like algorithm; Real outputs recorded by a time-series
  observer, Booleans cannot be);
- ``ecos``: :func:`robofmu.system.interop.ecos.run_ssp_ecos` on the same SSP export (ecos's fixed-step
  algorithm, the components stepped in parallel threads; Real outputs read through ecospy
  after every step);
- ``container``: :func:`robofmu.system.interop.container.export_container` of the same diagram (one FMU,
  fmu-manipulation-toolbox's C runtime stepping the block FMUs in the master's Gauss-Seidel
  order), run by :func:`robofmu.system.interop.container.run_container` (fmpy's ``FMU2Slave``: ``doStep``,
  one ``getReal`` and one ``getBoolean`` of the recorded variables per step); it reproduces the
  master bit for bit;
- ``C++ floor``: the same loop on Pinocchio's C++ API (``benchmarks/floor.py``: compiled here
  where a compiler and the headers are found, else skipped with a note), the physical limit
  the Python runners are measured against.

Columns: ``wall`` is the whole call (loading and initializing the FMUs included; for libcosim
also unpacking the SSP), ``per step`` the stepping loop alone divided by the number of steps
(``ratio`` compares these; the container's wall includes building it), ``peak memory`` the child's peak resident set size
(``VmHWM`` of ``/proc/self/status`` after the run, see :func:`_peak_mb`: interpreter, NumPy,
Pinocchio and, for FMU runners, the FMU libraries and their instances included); ``imports`` is
the same high-water mark taken before the run starts. Times are the best of ``--repeat`` fresh
processes (default 3), the runners taking turns round after round.
"""
from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from robofmu.system import options

ROOT = Path(__file__).resolve().parents[1]
RUNNERS = ("robofmu", "in-process", "libcosim", "ecos", "container")
#: The master's own overhead (issue 30): its time per step at most this times the in-process loop's.
AIM_IN_PROCESS = 1.20


def _peak_mb() -> float:
    """Peak resident set size of this process (MB): VmHWM of /proc/self/status.

    Not ``getrusage(RUSAGE_SELF).ru_maxrss``: on Linux that high-water mark survives execve, so a
    child started by fork + exec reports at least its parent's RSS at the fork (here ~100 MB
    of NumPy, Pinocchio and the SSP export), not its own peak. ru_maxrss is the fallback where
    /proc is missing."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0          # kB
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0     # Linux: KiB


# -- one runner in this (child) process ------------------------------------------------------------------
def child(experiment: str, runner: str, h: float, stop: float, fmu_root: Path, ssp: Path | None,
          out: Path) -> dict:
    import robofmu.components  # noqa: F401  (the installed copy first, before any FMU's bundle)
    from robofmu.system.experiment import load
    from robofmu.system.master import Master

    system = load(experiment, fmu_dir=fmu_root)
    n_steps = int(round(stop / h))
    if runner == "libcosim":
        import libcosimpy.CosimExecution  # noqa: F401  (loaded before the "imports" mark, as for the others)
    elif runner == "ecos":
        from robofmu.system.interop.ecos import load_ecospy

        load_ecospy()
    imports_mb = _peak_mb()
    t0 = time.perf_counter()
    if runner == "robofmu":
        result = Master(system).run(stop, h)
    elif runner == "in-process":
        from robofmu.system.studies.replica import InProcessDiagram

        result = InProcessDiagram(system).sampled(h, stop)
    elif runner == "libcosim":
        from robofmu.system.interop.libcosim import run_ssp_libcosim

        result = run_ssp_libcosim(ssp, stop, h)
    elif runner == "ecos":
        from robofmu.system.interop.ecos import run_ssp_ecos

        result = run_ssp_ecos(ssp, stop, h)
    elif runner == "container":
        from robofmu.system.interop.container import export_container, run_container

        system.step = h
        result = run_container(export_container(system, out.with_suffix(".fmu")), stop, h)
    else:
        raise ValueError(runner)
    loop = result.info["wall_time"]                  # each runner's stepping loop alone
    wall = time.perf_counter() - t0
    peak = _peak_mb()
    np.savez(out, time=result.time, data=result.data, columns=np.array(result.columns))
    return {"runner": runner, "h": h, "n_steps": n_steps, "wall": wall, "loop": loop,
            "peak_mb": peak, "imports_mb": imports_mb}


def _cell(value: float, width: int, spec: str) -> str:
    return f"{'—':>{width}}" if value != value else f"{value:>{width}{spec}}"


def run_child(experiment: str, runner: str, h: float, stop: float, fmu_root: Path, ssp: Path, out: Path) -> dict:
    cmd = [sys.executable, str(Path(__file__).resolve()), "--experiment", experiment, "--child", runner, "--step-size", repr(h),
           "--stop-time", repr(stop), "--fmus", str(fmu_root), "--ssp", str(ssp), "--out", str(out)]
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    if proc.returncode != 0 or not lines:
        raise RuntimeError(f"{runner} at h = {h}: child failed ({proc.returncode})\n{proc.stdout[-3000:]}\n"
                           f"{proc.stderr[-3000:]}")
    return json.loads(lines[-1][len("RESULT "):])


def max_diff(a: Path, b: Path, pattern: str | None = None) -> tuple[float, str]:
    """Largest |a - b| over the columns both recorded (optionally only those containing pattern),
    and the column where it occurs ("all equal" if none differs)."""
    A, B = np.load(a), np.load(b)
    ca, cb = list(A["columns"]), list(B["columns"])
    worst, where = 0.0, ""
    for j, c in enumerate(ca):
        if c not in cb or (pattern and pattern not in c):
            continue
        d = float(np.max(np.abs(A["data"][:, j] - B["data"][:, cb.index(c)])))
        if d > worst:
            worst, where = d, c
    return worst, where or "all equal"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--experiment", default="chess-pd", help="experiment to run (default chess-pd)")
    parser.add_argument("--fmus", default="fmus", help="FMU root folder (default fmus)")
    parser.add_argument("--step-sizes", type=float, nargs="+", default=[1e-3, 5e-3], help="communication steps (s)")
    options.add_stop_time(parser)
    parser.add_argument("--repeat", type=int, default=3, help="fresh processes per runner; best time kept")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--step-size", type=float, help=argparse.SUPPRESS)
    parser.add_argument("--ssp", help=argparse.SUPPRESS)
    parser.add_argument("--out", help=argparse.SUPPRESS)
    parser.add_argument("--quick", action="store_true", help="a smoke test: 0.1 s at h = 5 ms, one process each")
    args = parser.parse_args(argv)
    if args.quick:
        args.stop_time, args.repeat, args.step_sizes = 0.1, 1, [5e-3]
    fmu_root = Path(args.fmus).resolve()

    if args.child:
        info = child(args.experiment, args.child, args.step_size, args.stop_time, fmu_root, Path(args.ssp) if args.ssp else None, Path(args.out))
        print("RESULT " + json.dumps(info), flush=True)
        return 0

    import robofmu.components  # noqa: F401
    from robofmu.system.experiment import load
    from robofmu.system.interop.ssp import export_ssp

    system = load(args.experiment, fmu_dir=fmu_root)
    missing = [str(system.fmu_path(b)) for b in system.blocks if not system.fmu_path(b).is_file()]
    if missing:
        print(f"missing FMUs {', '.join(missing)}: run `robofmu build --out {args.fmus}` first", file=sys.stderr)
        return 2
    experiment = args.experiment
    stop = system.stop_time if args.stop_time is None else args.stop_time
    rows, checks = [], []
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    try:
        import floor
        from loop_spec import spec as loop_spec

        spec = loop_spec(experiment, fmu_root)
        floor_note = None
    except ValueError as exc:             # an experiment the C++ floor does not implement
        floor_note = f"C++ floor skipped: {exc}"
    with tempfile.TemporaryDirectory(prefix="robofmu-bench-") as tmp:
        tmp = Path(tmp)
        ssp = export_ssp(system, tmp / f"{experiment}.ssp")
        for h in args.step_sizes:
            numbers = {**spec, "h": h, "n_steps": int(round(stop / h)), "stop": stop} if floor_note is None else None
            tries = {runner: [] for runner in RUNNERS}
            floor_tries = []
            for _ in range(args.repeat):    # the runners take turns: the machine's load hits all alike
                for runner in RUNNERS:
                    tries[runner].append(run_child(experiment, runner, h, stop, fmu_root, ssp,
                                                   tmp / f"{runner}-{h}.npz"))
                if floor_note is None:
                    result = floor.run_floor(numbers, tmp / f"floor-{h}.npz")
                    if isinstance(result, str):         # no compiler or no headers here
                        floor_note = result
                    else:
                        floor_tries.append(result)
            got = {}
            for runner in RUNNERS:
                best = min(tries[runner], key=lambda r: r["loop"])
                best["wall"] = min(r["wall"] for r in tries[runner])
                best["peak_mb"] = max(r["peak_mb"] for r in tries[runner])
                got[runner] = {**best, "npz": tmp / f"{runner}-{h}.npz"}      # every try: the same outputs
            floor_per = None
            if floor_tries:
                best = min(floor_tries, key=lambda r: r["loop"])
                floor_per = best["loop"] / best["n_steps"]
                d, c = max_diff(tmp / f"floor-{h}.npz", got["robofmu"]["npz"], "plant.q[")
                checks.append(f"h = {h * 1e3:g} ms: C++ floor vs robofmu master: max |q diff| = {d:.3g} "
                              f"(rad or m; {c})")
            base = got["in-process"]["loop"] / got["in-process"]["n_steps"]
            for runner in RUNNERS:
                r = got[runner]
                per = r["loop"] / r["n_steps"]
                rows.append((runner, h, r["wall"], per * 1e6, per / base,
                             per / floor_per if floor_per else float("nan"), r["peak_mb"], r["imports_mb"]))
            if floor_per:
                rows.append(("C++ floor", h, float("nan"), floor_per * 1e6, floor_per / base, 1.0,
                             float("nan"), float("nan")))
            d, c = max_diff(got["in-process"]["npz"], got["robofmu"]["npz"])
            checks.append(f"h = {h * 1e3:g} ms: in-process vs robofmu master, max |diff| over all "
                          f"{len(np.load(got['robofmu']['npz'])['columns'])} outputs = {d:.3g} ({c})")
            q = system.extra.get("roles", {}).get("q", "")
            d, c = max_diff(got["libcosim"]["npz"], got["robofmu"]["npz"], f"{q}[")
            checks.append(f"h = {h * 1e3:g} ms: libcosim (Jacobi) vs robofmu master (Gauss-Seidel): "
                          f"max |q diff| = {d:.3g} (rad or m; {c})")
            d, c = max_diff(got["ecos"]["npz"], got["libcosim"]["npz"], f"{q}[")
            checks.append(f"h = {h * 1e3:g} ms: ecos vs libcosim (both Jacobi): max |q diff| = {d:.3g} (rad or m; {c})")
            d, c = max_diff(got["container"]["npz"], got["robofmu"]["npz"])
            checks.append(f"h = {h * 1e3:g} ms: container vs robofmu master (both Gauss-Seidel), max |diff| over "
                          f"every output = {d:.3g} ({c})")

    print(f"{experiment}, {stop:g} s task; each runner in a fresh process\n")
    header = (f"{'runner':<12}{'h (ms)':>8}{'wall (s)':>10}{'per step (us)':>15}{'x in-process':>14}"
              f"{'x C++ floor':>13}{'peak memory (MB)':>18}{'imports (MB)':>14}")
    print(header)
    print("-" * len(header))
    for runner, h, wall, per, ratio, to_floor, peak, imp in rows:
        print(f"{runner:<12}{h * 1e3:>8g}{_cell(wall, 10, '.2f')}{per:>15.1f}{ratio:>14.2f}"
              f"{_cell(to_floor, 13, '.1f')}{_cell(peak, 18, '.1f')}{_cell(imp, 14, '.1f')}")
    if floor_note:
        print(f"\n{floor_note}")
    print(f"\nbest of {args.repeat} fresh processes, taking turns. wall: whole call incl. loading/initializing the FMUs "
          "(libcosim, ecos: also unpacking the SSP; container: also building it);\nper step: stepping loop only; peak memory: VmHWM of the "
          "child process after the run (imports: the same before the run).\n")
    for line in checks:
        print(line)
    print()
    for h in args.step_sizes:
        per = {r: p for r, hh, _, p, *_ in rows if hh == h}
        walls = {r: w for r, hh, w, *_ in rows if hh == h}
        print(f"h = {h * 1e3:g} ms: robofmu no slower than libcosim: "
              f"{'met' if per['robofmu'] <= per['libcosim'] else 'NOT met'} per step "
              f"({per['robofmu']:.0f} vs {per['libcosim']:.0f} us), "
              f"{'met' if walls['robofmu'] <= walls['libcosim'] else 'NOT met'} in wall time "
              f"({walls['robofmu']:.2f} vs {walls['libcosim']:.2f} s)")
        overhead = per["robofmu"] / per["in-process"]
        print(f"h = {h * 1e3:g} ms: robofmu master <= {AIM_IN_PROCESS:.2f}x in-process: "
              f"{'met' if overhead <= AIM_IN_PROCESS else 'NOT met'} ({overhead:.2f}x)")
        speedup = per["libcosim"] / per["robofmu"]
        print(f"h = {h * 1e3:g} ms: robofmu >= 4x faster than libcosim per step: "
              f"{'met' if speedup >= 4 else 'NOT met'} ({speedup:.2f}x)")
        if "C++ floor" in per:
            master, inproc = per["robofmu"] / per["C++ floor"], per["in-process"] / per["C++ floor"]
            print(f"h = {h * 1e3:g} ms: robofmu master <= 20x the C++ floor: {'met' if master <= 20 else 'NOT met'} "
                  f"({master:.1f}x); in-process <= 12x: {'met' if inproc <= 12 else 'NOT met'} ({inproc:.1f}x)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

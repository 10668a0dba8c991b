"""``make bench``: the machine time from a URDF to the first validated run of a new arm.

    .venv/bin/python benchmarks/new_arm.py [--urdf DIST:PATH] [--frame LINK]

Runs, each in its own process as a user would, ``robofmu new`` (default: example-robot-data's
xarm7, a 7-DOF arm not in the package), ``robofmu build`` of the robot TOML it wrote (the
reference check, five FMUs, their validation) and ``robofmu run`` of its experiment, in a
temporary folder, and prints each step's wall-clock and CPU time (user + system of the child
processes) beside the aim of issue 28: 60 s or less on a 2-core machine. Not a timed test: a
table.
"""
from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

AIM = 60.0
ARM = "example-robot-data:xarm_description/urdf/xarm7.urdf"


def _cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def timed(argv: list[str], folder: Path) -> tuple[float, float, str]:
    """Run ``robofmu argv`` in ``folder``; its wall-clock and CPU time (s) and its last output line."""
    wall, cpu = time.perf_counter(), _cpu()
    done = subprocess.run([sys.executable, "-m", "robofmu.system.cli", *argv], cwd=folder, capture_output=True,
                          text=True)
    wall, cpu = time.perf_counter() - wall, _cpu() - cpu
    if done.returncode != 0:
        raise SystemExit(f"robofmu {' '.join(argv)} failed ({done.returncode}):\n{done.stdout}{done.stderr}")
    lines = [line for line in done.stdout.splitlines() if line.strip()]
    return wall, cpu, lines[-1] if lines else ""


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--urdf", default=ARM, help=f"the arm's URDF (default: {ARM})")
    parser.add_argument("--frame", help="its tool link (default: the one leaf link joints move)")
    args = parser.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory(prefix="robofmu-bench-new-") as folder:
        folder = Path(folder)
        steps = [("new", ["new", "arm", "--urdf", args.urdf] + (["--frame", args.frame] if args.frame else [])),
                 ("build", ["build", "arm.toml", "--out", "fmus"])]
        for step, command in steps:
            rows.append((step, *timed(command, folder)))
        experiment = next(folder.glob("arm-*.toml")).name
        rows.append(("run", *timed(["run", experiment, "--fmus", "fmus", "--out", "out"], folder)))
    wall, cpu = sum(r[1] for r in rows), sum(r[2] for r in rows)
    print(f"\nURDF to the first validated run ({args.urdf}): robofmu new + build + run, each its own process\n")
    print("| step | wall-clock (s) | CPU (s) |")
    print("|---|---|---|")
    for step, w, c, _ in rows:
        print(f"| robofmu {step} | {w:.1f} | {c:.1f} |")
    print(f"| **total** | **{wall:.1f}** | {cpu:.1f} |")
    print(f"\naim: <= {AIM:g} s of wall-clock time: {'met' if wall <= AIM else 'NOT met'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

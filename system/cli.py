"""The ``robofmu`` command line."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path


def _build(args) -> int:
    from robofmu.components.robots import available
    from robofmu.system.build import build
    from robofmu.system.validate import problems_of

    robots = args.robots or available()
    status = 0
    for robot in robots:
        try:
            paths = build(robot, args.out)
        except ValueError as exc:
            print(f"robofmu build: {exc}", file=sys.stderr)
            return 2
        for path in paths:
            problems = problems_of(path)
            for p in problems:
                print(f"  {path}: {p}", file=sys.stderr)
            status |= bool(problems)
    return status


def _run(args) -> int:
    from robofmu.system.master import DiagramError, SimulationError
    from robofmu.system.runner import run_experiment

    out = Path(args.out or Path("results") / args.experiment)
    try:
        run = run_experiment(args.experiment, out, fmu_dir=args.fmus, step=args.step,
                             stop_time=args.stop, algorithm=args.algorithm)
    except (ValueError, DiagramError) as exc:
        print(f"robofmu run: {exc}", file=sys.stderr)
        return 2
    except SimulationError as exc:
        print(f"robofmu run: {exc}", file=sys.stderr)
        return 1
    print(run.section)
    print(f"\nwrote {out / 'results.csv'}, {out / 'report.md'} and {len(run.figures)} figures in {out}")
    return 0


def _ssp(args) -> int:
    from robofmu.system.experiment import load
    from robofmu.system.master import DiagramError
    from robofmu.system.ssp import export_ssp

    try:
        system = load(args.experiment, fmu_dir=args.fmus)
        out = Path(args.out or f"{system.name}.ssp")
        print(export_ssp(system, out, inline=args.inline))
    except (ValueError, DiagramError) as exc:
        print(f"robofmu ssp: {exc}", file=sys.stderr)
        return 2
    return 0


def _demo(args) -> int:
    from robofmu.system.demo import demo

    return demo(Path(args.out), fmu_dir=args.fmus, quick=args.quick)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="robofmu",
        description="Robot-arm control blocks as FMI 2.0 co-simulation FMUs, and their co-simulation.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    p = sub.add_parser("build", help="build the block FMUs of robots into DIR/<robot>/<block>.fmu",
                       description="Build FMI 2.0 co-simulation FMUs (pythonfmu) for each robot "
                                   "and validate them with fmpy.")
    p.add_argument("robots", nargs="*", metavar="ROBOT", help="robots to build (default: all described)")
    p.add_argument("--out", default="fmus", metavar="DIR", help="output folder (default: fmus)")
    p.set_defaults(func=_build)

    from robofmu.system.experiment import available as experiments
    p = sub.add_parser("run", help="run a named co-simulation experiment",
                       description="Run a co-simulation experiment and write DIR/results.csv (time, then "
                                   "one column per signal 'instance.variable'), figures and report.md. "
                                   f"Experiments: {', '.join(experiments())}.")
    p.add_argument("experiment", metavar="EXPERIMENT", help="experiment name or TOML file")
    p.add_argument("--out", metavar="DIR", help="output folder (default: results/EXPERIMENT)")
    p.add_argument("--step", type=float, metavar="H", help="communication step in s (default: the experiment's)")
    p.add_argument("--stop", type=float, metavar="T", help="stop time in s (default: the experiment's)")
    p.add_argument("--algorithm", choices=["gauss-seidel", "jacobi"], help="master algorithm")
    p.add_argument("--fmus", default="fmus", metavar="DIR", help="FMU folder (default: fmus)")
    p.set_defaults(func=_run)

    p = sub.add_parser("ssp", help="export an experiment as an SSP 1.0 package (.ssp)",
                       description="Write the experiment's diagram, FMUs and parameter sets as an SSP "
                                   "1.0 package that libcosim and fmpy.ssp can run.")
    p.add_argument("experiment", metavar="EXPERIMENT", help="experiment name or TOML file")
    p.add_argument("--out", metavar="FILE", help="output file (default: EXPERIMENT.ssp)")
    p.add_argument("--fmus", default="fmus", metavar="DIR", help="FMU folder (default: fmus)")
    p.add_argument("--inline", action="store_true", help="parameter sets inline in the SSD, not .ssv files")
    p.set_defaults(func=_ssp)

    from robofmu.system.stepresponse import add_step_command
    add_step_command(sub)

    p = sub.add_parser("demo", help="the flagship studies of every robot: experiments, figures and a report",
                       description="Run the studies of system/studies/demo.toml (one section per source "
                                   "document), the accuracy study against a monolithic reference and the "
                                   "step responses; write figures and DIR/report.md (DIR is replaced).")
    p.add_argument("--out", default="results", metavar="DIR", help="output folder (default: results)")
    p.add_argument("--fmus", default="fmus", metavar="DIR", help="FMU folder (default: fmus)")
    p.add_argument("--quick", action="store_true", help="shorter accuracy study")
    p.set_defaults(func=_demo)

    args = parser.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())

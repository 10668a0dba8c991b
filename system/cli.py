"""The ``robofmu`` command line."""
from __future__ import annotations

import argparse
import sys


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

    args = parser.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())

"""``robofmu build``: the block FMUs of robots, validated."""
from __future__ import annotations

import sys

from robofmu.system import defaults, options
from robofmu.system.usage import UsageError, check_writable, one_line, say

HELP = "build the block FMUs of robots into DIR/<robot>/<block>.fmu"


def add_parser(subparsers):
    p = subparsers.add_parser("build", help=HELP,
                              description="Build FMI 2.0 co-simulation FMUs (pythonfmu) for each robot "
                                          "and validate them with fmpy and fmu-manipulation-toolbox's checker.")
    p.add_argument("robots", nargs="*", metavar="ROBOT", help="robots to build (default: all described)")
    options.add_out(p, f"output folder (default: {defaults.FMU_FOLDER})", default=defaults.FMU_FOLDER)
    p.set_defaults(func=main)
    return p


def main(args) -> int:
    from robofmu.components.robots import available

    known = available()
    unknown = [robot for robot in args.robots if robot not in known]
    if unknown:
        say("build", f"unknown robot {unknown[0]!r}; described robots: {', '.join(known)}")
        return 2
    try:
        check_writable(args.out, "--out")
    except UsageError as exc:
        say("build", exc)
        return 2
    from robofmu.system.packaging.build import build
    from robofmu.system.packaging.validate import problems_of

    status = 0
    for robot in args.robots or known:
        try:
            paths = build(robot, args.out)
        except (ValueError, OSError) as exc:
            say("build", f"{robot}: {one_line(exc)}")
            return 1
        for path in paths:
            problems = problems_of(path)
            for p in problems:
                print(f"  {path}: {p}", file=sys.stderr)
            status |= bool(problems)
    return status

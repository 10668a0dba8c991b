"""``robofmu build``: the block FMUs of robots, validated.

Before building, it says which of the requested FMUs already in the output folder are stale and
why (:func:`robofmu.system.fmu.stale_reasons`: robofmu version, code, robot data), one line
each, and which are up to date; it then builds every requested FMU all the same (what the
hashes do not cover, robofmu's FMI library, changes too). ``--check`` only says so, missing
FMUs included, and builds nothing (exit status 1 if any is stale or missing).
"""
from __future__ import annotations

import sys
from pathlib import Path

from robofmu.system import defaults, options
from robofmu.system.usage import UsageError, check_writable, one_line, say

HELP = "build the block FMUs of robots into DIR/<robot>/<block>.fmu"


def add_parser(subparsers):
    p = subparsers.add_parser("build", help=HELP,
                              description="Build FMI 2.0 co-simulation FMUs (pythonfmu) for each robot "
                                          "and validate them with fmpy and fmu-manipulation-toolbox's checker. "
                                          "A robot is a robot of the package (by name) or a robot TOML "
                                          "anywhere (by path: PATH/robot.toml); its FMUs go to "
                                          "DIR/<robot name>/<block>.fmu. FMUs already there are first "
                                          "reported stale (and why) or up to date.")
    p.add_argument("robots", nargs="*", metavar="ROBOT",
                   help="robots to build: names or robot TOML paths (default: every robot of the package)")
    options.add_out(p, f"output folder (default: {defaults.FMU_FOLDER})", default=defaults.FMU_FOLDER)
    p.add_argument("--check", action="store_true",
                   help="only say which FMUs are stale (and why), missing or up to date; build nothing "
                        "(exit status 1 if any is stale or missing)")
    p.set_defaults(func=main)
    return p


def report_staleness(description, out: Path, missing: bool = False) -> tuple[list[str], bool]:
    """One line per FMU of ``description``'s robot in ``out`` that is stale, with why
    (``fmus/rrp/ik.fmu: stale: code changed``; ``missing``: also one per FMU not there), and one
    line for those up to date; and whether all are."""
    from robofmu.system.fmu import stale_reasons

    lines, fresh = [], []
    for block in description.fmu_blocks:
        path = out / description.name / f"{block}.fmu"
        if not path.is_file():
            if missing:
                lines.append(f"{path}: missing")
            continue
        try:
            reasons = stale_reasons(path, description)
        except Exception as exc:         # not a robofmu block, not a zip: it is replaced
            reasons = [f"not a robofmu FMU ({one_line(exc)})"]
        if reasons:
            lines.append(f"{path}: stale: {', '.join(reasons)}")
        else:
            fresh.append(block)
    everything = len(fresh) == len(description.fmu_blocks)
    if fresh:
        lines.append(f"{out / description.name}: up to date: {', '.join(f'{b}.fmu' for b in fresh)}")
    return lines, everything


def located(description, exc: BaseException) -> str:
    """A refusal of ``description``'s robot on one line, naming a file: the message itself where it
    starts with one of the robot's files (the TOML, URDF, SRDF: the user's paths), else prefixed
    with the TOML and what was checked (a reference beyond a limit: ``trajectory``)."""
    from robofmu.components.preflight import ReferenceRefused

    text = one_line(exc)
    files = [str(f) for f in (description.path, description.urdf, getattr(description, "srdf", None)) if f]
    if any(text.startswith(f"{f}: ") for f in files):
        return text
    key = "robot"
    if isinstance(exc, ReferenceRefused):
        key = "configurations.home" if text.startswith("configuration home") else "trajectory"
    return f"{description.path}: {key}: {text}"


def main(args) -> int:
    from robofmu.components.robots import available, is_robot_file, load_description
    from robofmu.system.packaging.build import build, check_name, checked
    from robofmu.system.packaging.validate import problems_of

    known = available()
    descriptions = []
    for robot in args.robots or known:
        if not is_robot_file(robot) and robot not in known:
            say("build", f"unknown robot {robot!r}; described robots: {', '.join(known)} "
                         "(or give the path of a robot TOML)")
            return 2
        try:
            descriptions.append(check_name(load_description(robot)))
        except ValueError as exc:        # a missing or malformed robot TOML, a name no identifier takes
            say("build", exc)
            return 2
    if args.check:
        status = 0
        for description in descriptions:
            lines, fresh = report_staleness(description, Path(args.out), missing=True)
            print("\n".join(lines))
            status |= not fresh
        return int(status)
    try:
        check_writable(args.out, "--out")
    except UsageError as exc:
        say("build", exc)
        return 2
    findings = {}                        # what each check found, printed when its robot is built
    for description in descriptions:
        try:
            checked(description, log=findings.setdefault(description.name, []).append)
        except ValueError as exc:        # the user's files: TOML, URDF, SRDF, CSV, the reference
            say("build", located(description, exc))
            return 2

    status = 0
    for description in descriptions:
        for line in report_staleness(description, Path(args.out))[0]:
            print(line)
    for robot, description in zip(args.robots or known, descriptions):
        try:
            for line in findings[description.name]:
                print(line)
            paths = build(robot, args.out, check=False)      # checked above, once
        except (ValueError, OSError) as exc:
            say("build", f"{description.name}: {one_line(exc)}")
            return 1
        for path in paths:
            problems = problems_of(path)
            for p in problems:
                print(f"  {path}: {p}", file=sys.stderr)
            status |= bool(problems)
    return status

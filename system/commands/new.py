"""``robofmu new``: a robot TOML and its demonstration experiment from a URDF, ready to build and run.

The choices (chain, home, task, move) follow the rules of :mod:`robofmu.system.packaging.scaffold`
(docs/robots.md, "Your arm in one minute"); this module parses, prints what was chosen and why,
and writes the two files atomically.
"""
from __future__ import annotations

from pathlib import Path

HELP = "write a robot TOML and a demonstration experiment for an arm from its URDF"


def add_parser(subparsers):
    p = subparsers.add_parser(
        "new", help=HELP,
        description="From a URDF, write DIR/NAME.toml (the robot: its chain, home, pose or position task, "
                    "damped least-squares IK, computed-torque gains and a demonstration move checked as "
                    "robofmu build checks it) and DIR/NAME-pose.toml (NAME-line.toml for a position task: the "
                    "standard loop), so that robofmu build DIR/NAME.toml and robofmu run DIR/NAME-pose.toml "
                    "work with no edit. A file robofmu new did not write is never replaced (unless --force).")
    p.add_argument("name", metavar="NAME", help="the robot's name (letters, digits, underscores)")
    p.add_argument("--urdf", required=True, metavar="PATH",
                   help="the URDF (or .xacro) file, or DIST:PATH, the file of an installed distribution whose "
                        "path ends with PATH (e.g. example-robot-data:ur_description/urdf/ur5_robot.urdf)")
    p.add_argument("--srdf", metavar="PATH", help="an SRDF whose group_state gives home (PATH or DIST:PATH)")
    p.add_argument("--frame", metavar="LINK", help="the tool link (default: the one leaf link joints move)")
    p.add_argument("--xacro-arg", action="append", default=[], metavar="NAME=VALUE",
                   help="an argument of a .xacro URDF (repeatable)")
    p.add_argument("--out", default=".", metavar="DIR", help="the folder the two files go to (default: .)")
    p.add_argument("--force", action="store_true", help="replace files of those names robofmu new did not write")
    p.set_defaults(func=main)
    return p


def _xacro_args(values: list[str]) -> dict[str, str]:
    from robofmu.system.packaging.scaffold import ScaffoldError

    found = {}
    for value in values:
        key, sep, text = value.partition("=")
        if not sep or not key.strip():
            raise ScaffoldError(f"--xacro-arg {value}: give NAME=VALUE")
        found[key.strip()] = text
    return found


def main(args) -> int:
    from robofmu.components.robots.urdf import UrdfError
    from robofmu.system.packaging import scaffold
    from robofmu.system.usage import UsageError, check_writable, say

    out = Path(args.out)
    try:
        check_writable(out, "--out")
        xacro_args = _xacro_args(args.xacro_arg)
        if xacro_args and not args.urdf.endswith(".xacro"):
            raise scaffold.ScaffoldError(f"--xacro-arg: the URDF {args.urdf} is no .xacro file")
        urdf = scaffold.resolve_file(args.urdf, "--urdf")
        srdf = scaffold.resolve_file(args.srdf, "--srdf") if args.srdf else None
        scaffold.check_targets([out / f"{args.name}.toml"], args.force)
        plan = scaffold.plan(args.name, *urdf, out, args.frame, srdf, xacro_args)
        robot, experiment = out / f"{plan.name}.toml", out / f"{plan.experiment_name}.toml"
        scaffold.write_files({robot: plan.robot_text, experiment: plan.experiment_text}, args.force)
    except (scaffold.ScaffoldError, UsageError, UrdfError) as exc:
        say("new", exc)
        return 2
    except scaffold.NoDemonstration as exc:
        say("new", exc)
        return 1
    chain, home, check = plan.chain, plan.home, plan.check
    locked = f"; locked off the chain: {', '.join(chain.locked)}" if chain.locked else ""
    followers = f"; mimic followers moving with it: {', '.join(chain.followers)}" if chain.followers else ""
    print(f"chain: {chain.base} -> {chain.tool}, {len(chain.joints)} joints ({', '.join(chain.joints)}){locked}"
          f"{followers}")
    print(f"home: {'the SRDF state ' + home.source[5:] if home.source.startswith('srdf:') else 'the posture rule'}"
          f": smallest singular value {home.sigma_min:.3g} (the IK's singular_value: {scaffold.singular_value():g}), joints at least "
          f"{home.margin * 100:.0f} % of their range inside their limits, tool {home.height:.3g} m above the "
          f"first joint (reach {plan.reach:.3g} m)")
    print(f"task: {'pose' if plan.pose else 'position'} of {chain.tool} ({len(chain.joints)} joints"
          f"{', redundant: the null space holds home' if len(chain.joints) > (6 if plan.pose else 3) else ''}); "
          f"damped least-squares IK; computed torque kp {scaffold.OMEGA_N ** 2:g}, kd {2 * scaffold.OMEGA_N:g} "
          f"(wn = {scaffold.OMEGA_N:g} rad/s)")
    print(f"move: {scaffold.describe_move(plan.trajectory, plan.duration)}; reference checked over "
          f"{check.duration:g} s: joints at least {check.position_margin:.3g} from their limits, at most "
          f"{check.speed_ratio * 100:.0f} % of their velocity limits")
    for note in plan.notes:
        print(f"note: {note}")
    print(f"wrote {robot} and {experiment}; next: robofmu build {robot} && robofmu run {experiment}")
    return 0

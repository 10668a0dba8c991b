"""``robofmu inspect``: a URDF's or robot TOML's joints, chains, frames, mass and tool at home, as tables.

The tables are :func:`robofmu.system.packaging.inspection.render`'s; this module parses and prints.
"""
from __future__ import annotations

HELP = "the joints, chains, frames, mass and tool pose at home of a URDF or robot TOML"


def add_parser(subparsers):
    p = subparsers.add_parser(
        "inspect", help=HELP,
        description="Print, on one screen of tables, what writing a task by hand needs: the joints (type, "
                    "position, velocity and effort limits, mimic, continuous), the leaf links joints move "
                    "and their chains, the frames and what each is (link, fixed joint, joint) with name "
                    "clashes marked, the total mass; and at home (a TOML's home; for a URDF the posture rule's "
                    "of robofmu new, or zeros clipped into the limits: it says which) the tool's position and "
                    "quaternion (x y z w), the task Jacobian's smallest singular value and the distance to "
                    "the limits.")
    p.add_argument("file", metavar="URDF|TOML", help="a URDF (or DIST:PATH, a file of an installed distribution) "
                                                     "or a robot TOML")
    p.add_argument("--frame", metavar="LINK", help="a URDF's tool link (default: the one leaf link joints move)")
    p.set_defaults(func=main)
    return p


def main(args) -> int:
    from robofmu.components.robots.urdf import UrdfError
    from robofmu.system.packaging import inspection, scaffold
    from robofmu.system.usage import say

    try:
        target = args.file if args.file.endswith(".toml") else scaffold.resolve_file(args.file, "URDF")[0]
        found = inspection.inspect(target, args.frame)
    except (scaffold.ScaffoldError, UrdfError, ValueError) as exc:
        say("inspect", exc)
        return 2
    print(inspection.render(found))
    return 0

"""``robofmu workspace``: workspace, orientation range and isotropy maps of a parallel robot."""
from __future__ import annotations

import sys
from pathlib import Path

from robofmu.system import defaults, options
from robofmu.system.usage import OutputFolder, UsageError, stopped

HELP = "workspace, orientation range and isotropy maps of a parallel robot"


def add_parser(subparsers):
    p = subparsers.add_parser(
        "workspace", help=HELP,
        description="For a robot model with vectorized kinematics (a parallel mechanism; a serial robot is "
                    "refused) and its workspace study (system/studies/*.toml with kind = \"workspace\"): the "
                    "reachable and dexterous workspace with their radii (bisection along rays), the orientation "
                    "range per position, the local isotropy 1/cond(J), and the Global Isotropy Index over the "
                    "study's regions and over full joint grids. Writes PNG figures and DIR/report.md; DIR is "
                    "replaced whole.")
    p.add_argument("robot", metavar="ROBOT", help="robot name, or a workspace study file (.toml)")
    options.add_out(p, "output folder, replaced whole (default: results/ROBOT-workspace)")
    p.add_argument("--grid", type=int, metavar="N", help="finest full joint grid, N points per joint "
                                                         "(default: the study's)")
    p.set_defaults(func=main)
    return p


def main(args) -> int:
    from robofmu.system.studies import workspace

    try:
        study = workspace.study_for(args.robot)
        grids = None
        if args.grid is not None:
            if not 2 <= args.grid <= workspace.MAX_JOINT_GRID:
                raise UsageError(f"--grid {args.grid}: must be a whole number of points per joint from 2 to "
                                 f"{workspace.MAX_JOINT_GRID} (the full joint grid has N³ configurations)")
            grids = [n for n in study.grids["joint"] if n < args.grid] + [args.grid]
        out = Path(args.out) if args.out else Path(defaults.RESULTS_FOLDER) / f"{study.robot}-workspace"
        folder = OutputFolder(out, owned="workspace")
        staging = folder.open()
    except ValueError as exc:            # UsageError
        return stopped("workspace", exc)
    try:
        result = workspace.run(study, grids, progress=lambda line: print(f"  {line}", file=sys.stderr))
        workspace.write(result, staging)
        folder.commit()
    except BaseException:
        folder.discard()
        raise
    r = result.radii
    print(f"reachable radius {r.reachable_radius * 1e3:.6f} mm, dexterous radius {r.dexterous_radius * 1e3:.6f} mm")
    for g in result.regions + result.joint:
        print(f"GII {g.gii:.6g}  {g.name}")
    print(f"\nwrote {out / 'report.md'} and its figures in {out} ({result.seconds:.1f} s)")
    return 0

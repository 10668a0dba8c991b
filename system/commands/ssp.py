"""``robofmu ssp``: an experiment as an SSP 1.0 package."""
from __future__ import annotations

from robofmu.system import options
from robofmu.system.usage import export_experiment

HELP = "export an experiment as an SSP 1.0 package (.ssp)"


def add_parser(subparsers):
    p = subparsers.add_parser(
        "ssp", help=HELP,
        description="Write the experiment's diagram, FMUs and parameter sets as an SSP 1.0 package that "
                    "libcosim, ecos and fmpy.ssp can run. Its system and components are named by identifiers "
                    "every tool takes (letters, digits and underscores, a letter first: my-arm-pd gives "
                    "my_arm_pd, 2-link-pd gives x2_link_pd); the experiment's name is the SSD's description.")
    p.add_argument("experiment", metavar="EXPERIMENT", help="experiment name or TOML file")
    options.add_out(p, "output file (default: EXPERIMENT.ssp)", metavar="FILE")
    options.add_fmus(p)
    p.add_argument("--inline", action="store_true", help="parameter sets inline in the SSD, not .ssv files")
    p.set_defaults(func=main)
    return p


def main(args) -> int:
    from robofmu.system.interop.ssp import export_ssp, is_robofmu_ssp

    return export_experiment("ssp", args.experiment, args.out, args.fmus, ".ssp",
                             lambda system, out: export_ssp(system, out, inline=args.inline),
                             owned=is_robofmu_ssp, what="an SSP package robofmu wrote")

"""``robofmu demo``: the flagship studies of every robot, their figures and report."""
from __future__ import annotations

from pathlib import Path

from robofmu.system import defaults, options
from robofmu.system.usage import stopped

HELP = "the flagship studies of every robot: experiments, figures and a report"


def add_parser(subparsers):
    p = subparsers.add_parser(
        "demo", help=HELP,
        description="Run the studies of system/studies/demo.toml (one section per source document), the "
                    "accuracy study against a monolithic reference and the step responses; write figures and "
                    "DIR/report.md. DIR is replaced whole once the studies are done (written in a temporary "
                    "sibling folder); a folder that is not an earlier demo's is refused.")
    options.add_out(p, f"output folder (default: {defaults.RESULTS_FOLDER})", default=defaults.RESULTS_FOLDER)
    options.add_fmus(p)
    p.add_argument("--quick", action="store_true", help="shorter accuracy study")
    p.set_defaults(func=main)
    return p


def main(args) -> int:
    from robofmu.system.master import Interrupted, SimulationError
    from robofmu.system.studies.demo import demo

    try:
        return demo(Path(args.out), fmu_dir=args.fmus, quick=args.quick)
    except (SimulationError, ValueError) as exc:      # ValueError: UsageError, ExperimentError, DiagramError
        return stopped("demo", exc, f"; {args.out} left as it was" if isinstance(exc, Interrupted) else "")

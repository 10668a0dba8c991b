"""``robofmu run``: one experiment, its results, figures and report.

After the run, what the FMUs said (their warnings and errors, grouped with counts and first and
last times, and the excursions the record shows: an IK's status other than 0, a joint beyond its
limits) is printed on stderr, one line each; ``report.md`` begins with it and ``run.log`` holds
every message. The last line is the run's summary; a run whose IK or limits were not respected
says so there (``— WARNING: ...``), and with ``--strict`` it exits with status 1.
"""
from __future__ import annotations

import sys
from pathlib import Path

from robofmu.system import options
from robofmu.system.usage import default_out, stopped

HELP = "run a named co-simulation experiment"


def add_parser(subparsers):
    from robofmu.system.experiment import available

    p = subparsers.add_parser(
        "run", help=HELP,
        description="Run a co-simulation experiment and write DIR/results.csv (time, then one column per "
                    "signal 'instance.variable'), figures and report.md. DIR is replaced whole at the end of "
                    "the run (written in a temporary sibling folder, then swapped in), so no earlier output "
                    "stays beside new results; a folder holding other files than a run's outputs is refused. "
                    "Ctrl-C stops at the next communication point and writes the results so far (exit status "
                    "130). What the FMUs said (warnings and errors, grouped) is printed on stderr after the run, "
                    "first in report.md and whole in DIR/run.log; the summary line ends with '— WARNING: ...' "
                    "where the IK or the joints' limits were not respected (exit status 1 with --strict). "
                    "An experiment file may name a packaged experiment as its base. "
                    f"Experiments: {', '.join(available())}.")
    p.add_argument("experiment", metavar="EXPERIMENT", help="experiment name or TOML file")
    options.add_out(p, "output folder, replaced whole (default: results/EXPERIMENT)")
    options.add_step_size(p)
    options.add_stop_time(p)
    options.add_algorithm(p)
    options.add_fmus(p)
    p.add_argument("--set", action="append", metavar=options.PARAMETER_SETTING,
                   help="set a block parameter over the experiment's (repeatable), e.g. controller.kp=400; one "
                        "number for a vector parameter sets every element (plant.friction=0.5)")
    p.add_argument("--format", choices=["csv", "parquet"], default="csv",
                   help="results.csv (default) or results.parquet: binary, exact, with units; for large runs")
    p.add_argument("--debug", action="store_true",
                   help="keep the FMUs' debug messages (a failure's traceback) in DIR/run.log too")
    p.add_argument("--strict", action="store_true",
                   help="exit with status 1 when the run did not respect its IK or limits: an FMU warning or "
                        "error, an IK status other than 0, a joint beyond its limits, or a --set reference the "
                        "build's check refuses (the results are written all the same)")
    p.set_defaults(func=main)
    return p


def main(args) -> int:
    from robofmu.system.master import SimulationError
    from robofmu.system.run import run_experiment, summary_line

    out = Path(args.out) if args.out else default_out(args.experiment)
    try:
        parameters = dict(options.parse_setting(text) for text in args.set or [])
        run = run_experiment(args.experiment, out, fmu_dir=args.fmus, step=args.step_size,
                             stop_time=args.stop_time, algorithm=args.algorithm, parameters=parameters,
                             results_format=args.format, debug=args.debug)
    except (SimulationError, ValueError) as exc:      # ValueError: UsageError, ExperimentError, DiagramError
        return stopped("run", exc)
    if run.said:
        print(f"What the FMUs said ({run.name}; every message in {out / 'run.log'}):", file=sys.stderr)
        for line in run.said:
            print(f"  {line}", file=sys.stderr)
    print(run.section)
    print(f"\nwrote {out / ('results.' + args.format)}, {out / 'report.md'}, {out / 'run.log'} and "
          f"{len(run.figures)} figures in {out}")
    print(summary_line(run.name, run.result, run.troubles))
    return 1 if args.strict and run.troubles else 0

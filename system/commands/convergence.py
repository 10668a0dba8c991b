"""``robofmu convergence``: co-simulation error against the communication step, beside a monolithic reference."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from robofmu.system import defaults, options
from robofmu.system.usage import OutputFolder, UsageError, check_fmu_folder, check_times, default_out, \
    stopped

HELP = "co-simulation error against the communication step, beside a monolithic reference"

#: The study's arguments (``check_plan``'s messages start with them) as options.
_OPTIONS = {"step_sizes": "--step-sizes", "algorithms": "--algorithms"}


def add_parser(subparsers):
    from robofmu.system.experiment import available

    p = subparsers.add_parser(
        "convergence", help=HELP,
        description="Co-simulate an experiment at each communication step with each algorithm and compare "
                    f"it, at its communication points, with the same diagram as one ODE ({defaults.REFERENCE_SOLVER} "
                    f"at rtol {defaults.REFERENCE_RTOL:g}, continuous controller): the max joint and task-point "
                    "errors, their observed order in the step, the error constant. Writes DIR/convergence.md "
                    "(the table), convergence.png and convergence.json (every number); DIR is replaced whole at "
                    f"the end. Experiments: {', '.join(available())}.")
    p.add_argument("experiment", metavar="EXPERIMENT", help="experiment name or TOML file")
    p.add_argument("--step-sizes", type=_step_sizes, metavar="H,H,...",
                   help="communication steps in s, comma-separated, at least two, each dividing the stop time "
                        "(default: the study's DEFAULT_STEP_SIZES, 10 ms down to 0.5 ms)")
    p.add_argument("--steps", dest="step_sizes", type=_step_sizes, action=options.deprecated_alias("--step-sizes"),
                   help=argparse.SUPPRESS)
    options.add_stop_time(p, old=())
    p.add_argument("--algorithms", type=_names, metavar="A,A,...",
                   help=f"comma-separated: {', '.join(defaults.ALGORITHMS)} (the master's), in-process (the "
                        "Gauss-Seidel loop on the blocks' logic, no FMI calls) (default: all three)")
    options.add_fmus(p)
    p.add_argument("--fmu-dir", dest="fmus", action=options.deprecated_alias("--fmus"), help=argparse.SUPPRESS)
    options.add_out(p, "output folder, replaced whole (default: results/EXPERIMENT-convergence)")
    p.set_defaults(func=main)
    return p


def _step_sizes(text: str) -> tuple[float, ...]:
    """``--step-sizes``: comma-separated times in s, as argparse reads them."""
    try:
        return tuple(float(item) for item in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected communication steps in s, comma-separated "
                                         "(e.g. 0.01,0.005,0.002)") from None


def _names(text: str) -> tuple[str, ...]:
    """``--algorithms``: comma-separated names (checked by the study)."""
    return tuple(name.strip() for name in text.split(","))


def main(args) -> int:
    from robofmu.system.experiment import load
    from robofmu.system.master import Interrupted, SimulationError
    from robofmu.system.studies import convergence

    out = Path(args.out) if args.out else default_out(args.experiment, "-convergence")
    step_sizes = convergence.DEFAULT_STEP_SIZES if args.step_sizes is None else args.step_sizes
    algorithms = convergence.ALGORITHMS if args.algorithms is None else args.algorithms
    try:
        check_times(None, args.stop_time)
        system = load(args.experiment, fmu_dir=args.fmus)
        stop_time = system.stop_time if args.stop_time is None else args.stop_time
        try:
            convergence.check_plan(step_sizes, algorithms, stop_time)
        except ValueError as exc:
            argument, _, problem = str(exc).partition(": ")
            raise UsageError(f"{_OPTIONS[argument]}: {problem}") from None
        check_fmu_folder(system)
        folder = OutputFolder(out, owned="convergence")
        staging = folder.open()
    except ValueError as exc:          # UsageError, ExperimentError, DiagramError
        return stopped("convergence", exc)
    try:
        found = convergence.study(system, step_sizes, staging, algorithms=algorithms, stop_time=stop_time,
                                  progress=lambda line: print(f"  {line}", file=sys.stderr))
        folder.commit()
    except (SimulationError, ValueError) as exc:
        folder.discard()
        return stopped("convergence", exc, f"; {out} left as it was" if isinstance(exc, Interrupted) else "")
    except BaseException:
        folder.discard()
        raise
    found.files = {key: out / path.name for key, path in found.files.items()}     # swapped in for the staging
    print(found.table)
    print(f"wrote {', '.join(map(str, found.files.values()))}")
    return 0

"""``robofmu container``: an experiment's whole diagram as one FMU."""
from __future__ import annotations

from robofmu.system import options
from robofmu.system.usage import export_experiment

HELP = "an experiment's whole diagram as one FMU (an FMU container)"


def add_parser(subparsers):
    p = subparsers.add_parser(
        "container", help=HELP,
        description="Package the experiment's block FMUs, wires and parameters as one FMI 2.0 co-simulation "
                    "FMU (fmu-manipulation-toolbox's FMU container) that any FMI tool runs as a single block. "
                    "It steps the blocks at the experiment's step and reproduces the master's run: Gauss-Seidel "
                    "(sequential mode, blocks without feedthrough first) or Jacobi (parallel mode), bit for bit "
                    "for a PD loop (a PID's integral differs at first order in the step). The diagram's unwired "
                    "inputs are its inputs (the experiment's values as start values), its unwired outputs its "
                    "outputs, the wired signals its locals (its outputs instead with --expose-signals), all "
                    "named BLOCK.VARIABLE.")
    p.add_argument("experiment", metavar="EXPERIMENT", help="experiment name or TOML file")
    options.add_out(p, "output file (default: EXPERIMENT.fmu)", metavar="FILE")
    options.add_fmus(p)
    options.add_algorithm(p, what="the experiment's: the master algorithm to reproduce")
    p.add_argument("--expose-signals", action="store_true",
                   help="declare the wired signals (plant.q[1], controller.tau[1], ...) as the container's "
                        "outputs instead of its locals, for tools that record outputs only (fmusim's CSV); "
                        "same names and values")
    p.set_defaults(func=main)
    return p


def main(args) -> int:
    from robofmu.system.interop.container import export_container, is_robofmu_container

    return export_experiment("container", args.experiment, args.out, args.fmus, ".fmu",
                             lambda system, out: export_container(system, out, algorithm=args.algorithm,
                                                                  expose_signals=args.expose_signals),
                             owned=is_robofmu_container, what="a FMU container robofmu wrote")

"""The ``robofmu`` command line.

Exit status and messages, for every command:

- **2**: a mistake in what was asked (an unknown experiment or robot, an experiment file that
  cannot be used, a bad option value, an FMU folder that is missing or stale, an output path
  that cannot be written), found before anything runs; one line ``robofmu <command>: ...``
  naming the file, key or option, never a traceback. argparse's own errors (an unknown
  option, a value that is no number) also exit 2, after a usage line.
- **1**: the work itself failed (a co-simulation step, an FMU that fails to initialize; for
  ``doctor``: a problem found), one line per failure.
- **130**: interrupted (Ctrl-C). ``robofmu run`` stops at the next communication point, frees
  the FMUs and writes what was recorded so far; ``robofmu sweep`` keeps every finished row.

``robofmu sweep`` exits 0 when every run has a row, failed runs included: a run that fails is a
finding of the sweep (a row with its status and message), not a failure of the command.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

#: ``robofmu step``'s one-line help; its parser (and python-control, which it imports) is only
#: loaded when the command is ``step``.
STEP_HELP = "co-simulate a joint reference step and compare it with linear predictions"


def _one_line(exc: BaseException) -> str:
    """An exception's message on one line (a DiagramError's problems joined by '; ')."""
    problems = getattr(exc, "problems", None)
    if problems:
        head = str(exc).split("\n", 1)[0]
        return " ".join(f"{head} {'; '.join(problems)}".split())
    return " ".join(str(exc).split())


def _say(command: str, exc_or_text) -> None:
    text = exc_or_text if isinstance(exc_or_text, str) else _one_line(exc_or_text)
    print(f"robofmu {command}: {text}", file=sys.stderr)


def _stopped(command: str, exc: BaseException, after: str = "") -> int:
    """Say on one line why ``command`` stopped (``after`` appended) and return its exit status:
    130 interrupted (Ctrl-C: a run's Interrupted, a sweep's SweepInterrupted), 1 a run that failed
    (SimulationError), 2 a user's mistake (ValueError: usage, experiment, diagram, design; a
    scheduler that cannot be reached)."""
    from robofmu.system.master import Interrupted, SimulationError

    _say(command, f"{_one_line(exc)}{after}")
    if isinstance(exc, (Interrupted, KeyboardInterrupt)):
        return 130
    return 1 if isinstance(exc, SimulationError) else 2


def _build(args) -> int:
    from robofmu.components.robots import available
    from robofmu.system.runner import UsageError, check_writable

    known = available()
    unknown = [robot for robot in args.robots if robot not in known]
    if unknown:
        _say("build", f"unknown robot {unknown[0]!r}; described robots: {', '.join(known)}")
        return 2
    try:
        check_writable(args.out, "--out")
    except UsageError as exc:
        _say("build", exc)
        return 2
    from robofmu.system.build import build
    from robofmu.system.validate import problems_of

    status = 0
    for robot in args.robots or known:
        try:
            paths = build(robot, args.out)
        except (ValueError, OSError) as exc:
            _say("build", f"{robot}: {_one_line(exc)}")
            return 1
        for path in paths:
            problems = problems_of(path)
            for p in problems:
                print(f"  {path}: {p}", file=sys.stderr)
            status |= bool(problems)
    return status


def _default_out(experiment: str) -> Path:
    name = Path(experiment).stem if experiment.endswith(".toml") else experiment
    return Path("results") / name


def _run(args) -> int:
    from robofmu.system.master import SimulationError
    from robofmu.system.runner import run_experiment
    from robofmu.system.sweep.design import parse_setting

    out = Path(args.out) if args.out else _default_out(args.experiment)
    try:
        parameters = dict(parse_setting(text) for text in args.set or [])
        run = run_experiment(args.experiment, out, fmu_dir=args.fmus, step=args.step,
                             stop_time=args.stop, algorithm=args.algorithm, parameters=parameters,
                             results_format=args.format)
    except (SimulationError, ValueError) as exc:      # ValueError: UsageError, ExperimentError, DiagramError
        return _stopped("run", exc)
    print(run.section)
    print(f"\nwrote {out / ('results.' + args.format)}, {out / 'report.md'} and {len(run.figures)} figures in {out}")
    return 0


def _sweep(args) -> int:
    from robofmu.system.sweep.design import Design, parse_axis
    from robofmu.system.sweep.run import SweepInterrupted, run_sweep

    out = Path(args.out) if args.out else Path(str(_default_out(args.experiment)) + "-sweep")
    try:
        design = Design(args.experiment, [parse_axis(text) for text in args.vary], args.samples, args.seed,
                        args.stop, args.step)
        run = run_sweep(design, out, fmu_dir=args.fmus, workers=args.workers, scheduler=args.scheduler,
                        keep_results=args.keep_results, retry_failed=args.retry_failed, metric=args.metric,
                        threshold=args.threshold)
    except (SweepInterrupted, ValueError, ConnectionError) as exc:    # ValueError: UsageError, DesignError,
        return _stopped("sweep", exc)                                 # ExperimentError, DiagramError
    failed = len(run.failed)
    print(f"{len(run.rows)} runs ({run.ran} now, {run.reused} reused), {failed} failed; wrote "
          f"{out / 'sweep.csv'}, {out / 'sweep.parquet'}, {out / 'report.md'} and {len(run.figures)} figures")
    return 0                          # failed runs are rows of the map, not a failure of the sweep


def _export(command: str, args, suffix: str, write) -> int:
    """Load ``args.experiment``, check the output file and the FMU folder, then ``write(system,
    out)``; print the path written. The one shape of ``robofmu ssp`` and ``robofmu container``."""
    from robofmu.system.experiment import load
    from robofmu.system.runner import check_fmu_folder, check_writable

    out = args.out
    try:
        system = load(args.experiment, fmu_dir=args.fmus)
        out = Path(args.out or f"{system.name}{suffix}")
        check_writable(out, "--out" if args.out else "the default output", file=True)
        check_fmu_folder(system)
        written = write(system, out)
    except ValueError as exc:          # UsageError, ExperimentError, DiagramError, a tool's refusal
        return _stopped(command, exc)
    except OSError as exc:
        _say(command, f"cannot write {out}: {exc.strerror or exc}")
        return 1
    print(written)
    return 0


def _ssp(args) -> int:
    from robofmu.system.ssp import export_ssp

    return _export("ssp", args, ".ssp", lambda system, out: export_ssp(system, out, inline=args.inline))


def _container(args) -> int:
    from robofmu.system.container import export_container

    return _export("container", args, ".fmu",
                   lambda system, out: export_container(system, out, algorithm=args.algorithm,
                                                        expose_signals=args.expose_signals))


def _demo(args) -> int:
    from robofmu.system.demo import demo
    from robofmu.system.master import Interrupted, SimulationError

    try:
        return demo(Path(args.out), fmu_dir=args.fmus, quick=args.quick)
    except (SimulationError, ValueError) as exc:      # ValueError: UsageError, ExperimentError, DiagramError
        return _stopped("demo", exc, f"; {args.out} left as it was" if isinstance(exc, Interrupted) else "")


def _workspace(args) -> int:
    from robofmu.system import workspace
    from robofmu.system.runner import OutputFolder, UsageError

    try:
        study = workspace.study_for(args.robot)
        grids = None
        if args.grid is not None:
            if not 2 <= args.grid <= workspace.MAX_JOINT_GRID:
                raise UsageError(f"--grid {args.grid}: must be a whole number of points per joint from 2 to "
                                 f"{workspace.MAX_JOINT_GRID} (the full joint grid has N³ configurations)")
            grids = [n for n in study.grids["joint"] if n < args.grid] + [args.grid]
        out = Path(args.out) if args.out else Path("results") / f"{study.robot}-workspace"
        folder = OutputFolder(out, owned=lambda e: e.is_file() and e.suffix in (".md", ".png"))
        staging = folder.open()
    except ValueError as exc:            # UsageError
        return _stopped("workspace", exc)
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


def _doctor(args) -> int:
    from robofmu.system.doctor import doctor

    return doctor(Path(args.fmus))


def _command(argv: list[str]) -> str | None:
    """The sub-command in ``argv``: its first argument that is not an option."""
    return next((a for a in argv if not a.startswith("-")), None)


def parser_for(argv: list[str]) -> argparse.ArgumentParser:
    """The argument parser (``robofmu step``'s own only when ``argv`` asks for it)."""
    parser = argparse.ArgumentParser(
        prog="robofmu",
        description="Robot-arm control blocks as FMI 2.0 co-simulation FMUs, and their co-simulation. "
                    "A mistake is answered in one line naming the file, key or option (exit status 2), "
                    "a failed run with status 1, Ctrl-C with 130.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    p = sub.add_parser("build", help="build the block FMUs of robots into DIR/<robot>/<block>.fmu",
                       description="Build FMI 2.0 co-simulation FMUs (pythonfmu) for each robot "
                                   "and validate them with fmpy and fmu-manipulation-toolbox's checker.")
    p.add_argument("robots", nargs="*", metavar="ROBOT", help="robots to build (default: all described)")
    p.add_argument("--out", default="fmus", metavar="DIR", help="output folder (default: fmus)")
    p.set_defaults(func=_build)

    from robofmu.system.experiment import available as experiments
    p = sub.add_parser("run", help="run a named co-simulation experiment",
                       description="Run a co-simulation experiment and write DIR/results.csv (time, then "
                                   "one column per signal 'instance.variable'), figures and report.md. "
                                   "DIR is replaced whole at the end of the run (written in a temporary "
                                   "sibling folder, then swapped in), so no earlier output stays beside "
                                   "new results; a folder holding other files than a run's outputs is "
                                   "refused. Ctrl-C stops at the next communication point and writes the "
                                   "results so far (exit status 130). An experiment file may name a "
                                   "packaged experiment as its base. "
                                   f"Experiments: {', '.join(experiments())}.")
    p.add_argument("experiment", metavar="EXPERIMENT", help="experiment name or TOML file")
    p.add_argument("--out", metavar="DIR", help="output folder, replaced whole (default: results/EXPERIMENT)")
    p.add_argument("--step", type=float, metavar="H", help="communication step in s (default: the experiment's)")
    p.add_argument("--stop", type=float, metavar="T", help="stop time in s, a whole number of steps "
                                                           "(default: the experiment's)")
    p.add_argument("--algorithm", choices=["gauss-seidel", "jacobi"], help="master algorithm")
    p.add_argument("--fmus", default="fmus", metavar="DIR", help="FMU folder (default: fmus)")
    p.add_argument("--set", action="append", metavar="BLOCK.PARAM=VALUE",
                   help="set a block parameter over the experiment's (repeatable), e.g. controller.kp=400")
    p.add_argument("--format", choices=["csv", "parquet"], default="csv",
                   help="results.csv (default) or results.parquet: binary, exact, with units; for large runs")
    p.set_defaults(func=_run)

    p = sub.add_parser("sweep", help="many runs of one experiment over parameter grids or random samples, on Dask",
                       description="Run an experiment many times with block parameters varied over a grid or "
                                   "drawn at random, in parallel on Dask: a local cluster of worker processes by "
                                   "default, or an existing cluster (--scheduler). Writes DIR/sweep.csv (one row "
                                   "per run as it finishes: a column per varied BLOCK.PARAM, the metrics, "
                                   "status and message), sweep.parquet, figures and report.md. A rerun of the same "
                                   "sweep into the same DIR skips the runs already done; Ctrl-C keeps every "
                                   "finished row (exit status 130). VALUES: a comma list 200,400,800, a range "
                                   "START:STOP:COUNT (both ends included), or a distribution uniform(LOW,HIGH) / "
                                   "normal(MEAN,STD) drawn --samples times with --seed. 'step=VALUES' varies the "
                                   "communication step.")
    p.add_argument("experiment", metavar="EXPERIMENT", help="experiment name or TOML file")
    p.add_argument("--vary", action="append", metavar="BLOCK.PARAM=VALUES", required=True,
                   help="a varied block parameter (repeatable; the grid is their product)")
    p.add_argument("--samples", type=int, metavar="N", help="random samples (with a distribution)")
    p.add_argument("--seed", type=int, default=0, metavar="S", help="seed of the random samples (default: 0)")
    p.add_argument("--workers", type=int, metavar="N", help="local worker processes (default: the core count)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="run on an existing Dask cluster, e.g. tcp://host:8786")
    p.add_argument("--out", metavar="DIR", help="sweep folder, continued if it holds this sweep "
                                                "(default: results/EXPERIMENT-sweep)")
    p.add_argument("--step", type=float, metavar="H", help="communication step in s (default: the experiment's)")
    p.add_argument("--stop", type=float, metavar="T", help="stop time in s (default: the experiment's)")
    p.add_argument("--fmus", default="fmus", metavar="DIR", help="FMU folder (default: fmus)")
    p.add_argument("--keep-results", action="store_true", help="keep each run's results.csv under DIR/runs/")
    p.add_argument("--retry-failed", action="store_true", help="run the failed rows of an earlier sweep again")
    p.add_argument("--metric", metavar="NAME", help="the metric the figures map (default: max_tcp_error where "
                                                   "there is one, else max_joint_error)")
    p.add_argument("--threshold", type=float, metavar="VALUE", help="the metric's level drawn as a contour "
                                                                    "(default: 0.001 m for max_tcp_error)")
    p.set_defaults(func=_sweep)

    p = sub.add_parser("ssp", help="export an experiment as an SSP 1.0 package (.ssp)",
                       description="Write the experiment's diagram, FMUs and parameter sets as an SSP "
                                   "1.0 package that libcosim, ecos and fmpy.ssp can run. Its system and "
                                   "components are named by identifiers every tool takes (letters, digits and "
                                   "underscores, a letter first: my-arm-pd gives my_arm_pd, 2-link-pd gives "
                                   "x2_link_pd); the experiment's name is the SSD's description.")
    p.add_argument("experiment", metavar="EXPERIMENT", help="experiment name or TOML file")
    p.add_argument("--out", metavar="FILE", help="output file (default: EXPERIMENT.ssp)")
    p.add_argument("--fmus", default="fmus", metavar="DIR", help="FMU folder (default: fmus)")
    p.add_argument("--inline", action="store_true", help="parameter sets inline in the SSD, not .ssv files")
    p.set_defaults(func=_ssp)

    p = sub.add_parser("container", help="an experiment's whole diagram as one FMU (an FMU container)",
                       description="Package the experiment's block FMUs, wires and parameters as one FMI 2.0 "
                                   "co-simulation FMU (fmu-manipulation-toolbox's FMU container) that any FMI "
                                   "tool runs as a single block. It steps the blocks at the experiment's step "
                                   "and reproduces the master's run: Gauss-Seidel (sequential mode, blocks "
                                   "without feedthrough first) or Jacobi (parallel mode), bit for bit for a PD "
                                   "loop (a PID's integral differs at first order in the step). The "
                                   "diagram's unwired inputs are its inputs (the experiment's values as start "
                                   "values), its unwired outputs its outputs, the wired signals its locals "
                                   "(its outputs instead with --expose-signals), all named BLOCK.VARIABLE.")
    p.add_argument("experiment", metavar="EXPERIMENT", help="experiment name or TOML file")
    p.add_argument("--out", metavar="FILE", help="output file (default: EXPERIMENT.fmu)")
    p.add_argument("--fmus", default="fmus", metavar="DIR", help="FMU folder (default: fmus)")
    p.add_argument("--algorithm", choices=["gauss-seidel", "jacobi"],
                   help="the master algorithm to reproduce (default: the experiment's)")
    p.add_argument("--expose-signals", action="store_true",
                   help="declare the wired signals (plant.q[1], controller.tau[1], ...) as the container's "
                        "outputs instead of its locals, for tools that record outputs only (fmusim's CSV); "
                        "same names and values")
    p.set_defaults(func=_container)

    if _command(argv) == "step":
        from robofmu.system.stepresponse import add_step_command
        add_step_command(sub)
    else:
        sub.add_parser("step", help=STEP_HELP)

    p = sub.add_parser("demo", help="the flagship studies of every robot: experiments, figures and a report",
                       description="Run the studies of system/studies/demo.toml (one section per source "
                                   "document), the accuracy study against a monolithic reference and the "
                                   "step responses; write figures and DIR/report.md. DIR is replaced whole "
                                   "once the studies are done (written in a temporary sibling folder); a "
                                   "folder that is not an earlier demo's is refused.")
    p.add_argument("--out", default="results", metavar="DIR", help="output folder (default: results)")
    p.add_argument("--fmus", default="fmus", metavar="DIR", help="FMU folder (default: fmus)")
    p.add_argument("--quick", action="store_true", help="shorter accuracy study")
    p.set_defaults(func=_demo)

    p = sub.add_parser("workspace", help="workspace, orientation range and isotropy maps of a parallel robot",
                       description="For a robot model with vectorized kinematics (a parallel mechanism; a "
                                   "serial robot is refused) and its workspace study (system/studies/*.toml "
                                   "with kind = \"workspace\"): the reachable and dexterous workspace with "
                                   "their radii (bisection along rays), the orientation range per position, "
                                   "the local isotropy 1/cond(J), and the Global Isotropy Index over the "
                                   "study's regions and over full joint grids. Writes PNG figures and "
                                   "DIR/report.md; DIR is replaced whole.")
    p.add_argument("robot", metavar="ROBOT", help="robot name, or a workspace study file (.toml)")
    p.add_argument("--out", metavar="DIR", help="output folder, replaced whole (default: results/ROBOT-workspace)")
    p.add_argument("--grid", type=int, metavar="N", help="finest full joint grid, N points per joint "
                                                         "(default: the study's)")
    p.set_defaults(func=_workspace)

    p = sub.add_parser("doctor", help="what a process needs to run the FMUs, and whether it works here",
                       description="Tell what an importing process needs to run the FMUs: the Python "
                                   "interpreter they were built for (path, version), the libpython a "
                                   "non-Python host (e.g. libcosim's cosim) must preload, the venv's bin "
                                   "to put on PATH, and the packages the FMUs import (from robofmu's "
                                   "requirements); print the exact `export` lines. Then check: each package "
                                   "importable (with its version), every described robot's FMUs present under "
                                   "--fmus and built from these robofmu sources (their vendor annotation's "
                                   "source hash), one FMU instantiated and stepped through fmpy in a fresh "
                                   "process. Exit status 0 when everything checks, 1 otherwise (one line "
                                   "per problem).")
    p.add_argument("--fmus", default="fmus", metavar="DIR", help="FMU folder to check (default: fmus)")
    p.set_defaults(func=_doctor)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``robofmu`` with ``argv`` (default ``sys.argv[1:]``); returns the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        args = parser_for(argv).parse_args(argv)
        return args.func(args)
    except KeyboardInterrupt:
        print(f"robofmu{' ' + _command(argv) if _command(argv) else ''}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())

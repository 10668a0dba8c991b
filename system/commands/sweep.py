"""``robofmu sweep``: many runs of one experiment over parameter grids or random samples, on Dask."""
from __future__ import annotations

from pathlib import Path

from robofmu.system import options
from robofmu.system.usage import default_out, stopped

HELP = "many runs of one experiment over parameter grids or random samples, on Dask"


def add_parser(subparsers):
    p = subparsers.add_parser(
        "sweep", help=HELP,
        description="Run an experiment many times with block parameters varied over a grid or drawn at "
                    "random, in parallel on Dask: a local cluster of worker processes by default, or an "
                    "existing cluster (--scheduler). Writes DIR/sweep.csv (one row per run as it finishes: a "
                    "column per varied BLOCK.PARAM, the metrics, status and message), sweep.parquet, figures "
                    "and report.md. A rerun of the same sweep into the same DIR skips the runs already done; "
                    "Ctrl-C keeps every finished row (exit status 130). VALUES: a comma list 200,400,800, a "
                    "range START:STOP:COUNT (both ends included), or a distribution uniform(LOW,HIGH) / "
                    "normal(MEAN,STD) drawn --samples times with --seed, or another varied BLOCK.PARAM whose "
                    "value it takes in every run (a linked axis, e.g. controller.friction=plant.friction). "
                    "'step_size=VALUES' varies the communication step.")
    p.add_argument("experiment", metavar="EXPERIMENT", help="experiment name or TOML file")
    p.add_argument("--vary", action="append", metavar="BLOCK.PARAM=VALUES", required=True,
                   help="a varied block parameter (repeatable; the grid is their product)")
    p.add_argument("--samples", type=int, metavar="N", help="random samples (with a distribution)")
    p.add_argument("--seed", type=int, default=0, metavar="S", help="seed of the random samples (default: 0)")
    p.add_argument("--workers", type=int, metavar="N", help="local worker processes (default: the core count)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="run on an existing Dask cluster, e.g. tcp://host:8786")
    options.add_out(p, "sweep folder, continued if it holds this sweep (default: results/EXPERIMENT-sweep)")
    options.add_step_size(p)
    options.add_stop_time(p)
    options.add_fmus(p)
    p.add_argument("--keep-results", action="store_true", help="keep each run's results.csv under DIR/runs/")
    p.add_argument("--retry-failed", action="store_true", help="run the failed rows of an earlier sweep again "
                                                               "(refused where DIR holds no earlier run of it)")
    p.add_argument("--metric", metavar="NAME", help="the metric the figures map (default: max_tcp_error where "
                                                   "there is one, else max_joint_error)")
    p.add_argument("--threshold", type=float, metavar="VALUE", help="the metric's level drawn as a contour "
                                                                    "(default: 0.001 m for max_tcp_error)")
    p.set_defaults(func=main)
    return p


def main(args) -> int:
    from robofmu.system.sweep.design import Design, parse_axis
    from robofmu.system.sweep.run import SweepInterrupted, run_sweep

    out = Path(args.out) if args.out else default_out(args.experiment, "-sweep")
    try:
        design = Design(args.experiment, [parse_axis(text) for text in args.vary], args.samples, args.seed,
                        args.stop_time, args.step_size)
        run = run_sweep(design, out, fmu_dir=args.fmus, workers=args.workers, scheduler=args.scheduler,
                        keep_results=args.keep_results, retry_failed=args.retry_failed, metric=args.metric,
                        threshold=args.threshold)
    except (SweepInterrupted, ValueError, ConnectionError) as exc:    # ValueError: UsageError, DesignError,
        return stopped("sweep", exc)                                  # ExperimentError, DiagramError
    failed = len(run.failed)
    print(f"{len(run.rows)} runs ({run.ran} now, {run.reused} reused), {failed} failed; wrote "
          f"{out / 'sweep.csv'}, {out / 'sweep.parquet'}, {out / 'report.md'} and {len(run.figures)} figures")
    return 0                          # failed runs are rows of the map, not a failure of the sweep

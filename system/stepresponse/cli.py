"""``robofmu step``: co-simulate a joint reference step of a robot and compare it with the predictions.

A mistake on the command line is answered in one line naming the option, with exit status 2
(argparse's own messages included); a co-simulation that fails, in one line with status 1.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from robofmu.components.robots import available, load_description

from ..master import Interrupted
from .design import design_gains
from .experiment import CONTROLLER, DEFAULT_STEP_HEIGHT, DRIVERS, PLANT, compare, cosimulate_step, \
    plot_comparison, step_setup, write_csv

__all__ = ["add_step_command", "default_robot", "main"]

PROG = "robofmu step"


class UsageError(ValueError):
    """A command-line mistake; ``option`` is the option to name."""

    def __init__(self, option: str, message: str):
        super().__init__(f"{option}: {message}")
        self.option = option


def steppable_robots() -> list[str]:
    """Described robots that have both a controller and a plant block, sorted."""
    return [name for name in available()
            if {CONTROLLER, PLANT} <= set(load_description(name).blocks)]


def default_robot() -> str | None:
    """The robot ``robofmu step`` uses without ``--robot``: the first of :func:`steppable_robots`."""
    robots = steppable_robots()
    return robots[0] if robots else None


def _gain_sets_text() -> str:
    return "; ".join(f"{name}: {', '.join(load_description(name).gains)}" for name in steppable_robots())


def _positive(option: str, value: float | None, allow_zero: bool = False) -> None:
    if value is None:
        return
    if not math.isfinite(value) or value < 0.0 or (value == 0.0 and not allow_zero):
        raise UsageError(option, f"must be {'>= 0' if allow_zero else '> 0'}, got {value:g}")


def _gains(args) -> tuple[float, float, float, object]:
    """kp, kd, ki and the design (or None) the options ask for."""
    explicit = [option for option, value in (("--kp", args.kp), ("--kd", args.kd), ("--ki", args.ki),
                                             ("--gains", args.gains)) if value is not None]
    designing = args.settling_time is not None or args.overshoot is not None
    if designing:
        if args.settling_time is None or args.overshoot is None:
            missing = "--overshoot" if args.settling_time is not None else "--settling-time"
            raise UsageError(missing, "missing: --settling-time and --overshoot go together")
        if explicit:
            raise UsageError(explicit[0], "the gains are designed from --settling-time and --overshoot; "
                                          "give one or the other")
        _positive("--settling-time", args.settling_time)
        if not (math.isfinite(args.overshoot) and 0.0 <= args.overshoot < 100.0):
            raise UsageError("--overshoot", f"must be in [0, 100) %, got {args.overshoot:g}")
        _positive("--ki-ratio", args.ki_ratio)
        try:
            design = design_gains(args.settling_time, args.overshoot, ki_ratio=args.ki_ratio,
                                  h=args.step_size if args.design_for_step else None)
        except ValueError as exc:
            raise UsageError("--settling-time", str(exc)) from None
        return design.kp, design.kd, design.ki, design
    for option, value in (("--ki-ratio", args.ki_ratio), ("--design-for-step", args.design_for_step or None)):
        if value is not None:
            raise UsageError(option, "needs --settling-time and --overshoot")
    description = load_description(args.robot)
    if args.gains is None:
        seed = description.gains.get("pd") or next(iter(description.gains.values()))
    else:
        try:
            seed = description.gain_set(args.gains)
        except ValueError as exc:
            raise UsageError("--gains", str(exc)) from None
    kp = seed.kp if args.kp is None else args.kp
    kd = seed.kd if args.kd is None else args.kd
    ki = seed.ki if args.ki is None else args.ki
    for option, value in (("--kd", kd), ("--ki", ki)):
        _positive(option, value, allow_zero=True)
    _positive("--kp", kp)
    return kp, kd, ki, None


def _check_options(args):
    """Validate everything but the gains; returns the resolved step setup and stop time (s)."""
    if args.robot is None:
        raise UsageError("--robot", "no described robot has a controller and a plant block")
    if args.robot not in available():
        raise UsageError("--robot", f"unknown robot {args.robot!r}; known robots: {', '.join(available())}")
    if args.robot not in steppable_robots():
        raise UsageError("--robot", f"robot {args.robot!r} has no controller and plant blocks; robots that "
                                    f"have: {', '.join(steppable_robots())}")
    _positive("--step-size", args.step_size)
    _positive("--t-end", args.t_end)
    try:
        setup = step_setup(args.robot, args.step_height, args.joint, args.q0)
    except ValueError as exc:
        argument, _, message = str(exc).partition(": ")
        option = {"step": "--step-height", "joint": "--joint", "q0": "--q0"}.get(argument, "--robot")
        raise UsageError(option, message if argument in ("step", "joint", "q0") else str(exc)) from None
    fmus = Path(args.fmus)
    for block in (CONTROLLER, PLANT):
        path = fmus / args.robot / f"{block}.fmu"
        if not path.is_file():
            raise UsageError("--fmus", f"no {path} (build it: robofmu build {args.robot} --out {fmus})")
    if args.out is not None and Path(args.out).exists() and not Path(args.out).is_dir():
        raise UsageError("--out", f"{args.out} exists and is not a folder")
    return setup


def _step_command(args) -> int:
    try:
        setup = _check_options(args)
        kp, kd, ki, design = _gains(args)
    except UsageError as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return 2
    t_end = args.t_end
    if t_end is None:
        t_end = max(1.0, 3.0 * args.settling_time) if design else 1.0
    t_end = max(1, round(t_end / args.step_size)) * args.step_size
    try:
        result = cosimulate_step(Path(args.fmus), kp, kd, ki, robot=args.robot, step=setup.heights,
                                 h=args.step_size, t_end=t_end, joint=setup.joints, q0=setup.q0,
                                 driver=args.driver)
    except Interrupted as exc:      # Ctrl-C: stopped at a communication point
        print(f"{PROG}: interrupted at t = {exc.time:g} s", file=sys.stderr)
        return 130
    except Exception as exc:        # DiagramError, SimulationError: one line each
        print(f"{PROG}: {' '.join(str(exc).split())}", file=sys.stderr)
        return 1
    comparison = compare(result)
    if design is not None:
        print(f"design: settling time {design.settling_time:g} s, overshoot {design.overshoot:g} % -> "
              f"zeta {design.zeta:.4f}, wn {design.wn:.4f} rad/s (rule of thumb 4/(zeta Ts): "
              f"{design.rule_of_thumb_wn:.4f}); kp {kp:.6g}, kd {kd:.6g}, ki {ki:.6g}"
              + (f"; refined for h = {design.h:g} s" if design.h else ""))
    print(comparison.table())
    if design is not None:
        for j in comparison.joints:
            m = comparison.metrics[f"joint {j}"]
            overshoot_error = (f"{(m.overshoot / design.overshoot - 1) * 100:+.2f} %" if design.overshoot
                               else "requested 0")
            print(f"achieved, joint {j}: settling {m.settling_time:.4f} s "
                  f"({(m.settling_time / design.settling_time - 1) * 100:+.2f} %), overshoot "
                  f"{m.overshoot:.3f} % ({overshoot_error})")
    if args.out:
        out = Path(args.out)
        stem = f"step_h{args.step_size * 1e3:g}ms"
        result.to_csv(out / f"{stem}_cosim.csv")
        write_csv(comparison, out / f"{stem}_compare.csv")
        figure = plot_comparison(comparison, out, stem)
        print(f"wrote {out / (stem + '_cosim.csv')}, {out / (stem + '_compare.csv')}, {figure}")
    return 0


def _answer_in_one_line(parser: argparse.ArgumentParser) -> None:
    """Make ``parser`` report mistakes (bad values, unknown options) in one line, exit status 2."""
    def error(message: str):
        parser.exit(2, f"{parser.prog}: {message}\n")

    parse_known_args = parser.parse_known_args

    def parse_known_args_strictly(args=None, namespace=None):
        namespace, extras = parse_known_args(args, namespace)
        if extras:
            error(f"unrecognized arguments: {' '.join(extras)}")
        return namespace, extras

    parser.error = error
    parser.parse_known_args = parse_known_args_strictly


def add_step_command(subparsers) -> argparse.ArgumentParser:
    """Register ``robofmu step`` on an argparse ``subparsers`` object; returns its parser."""
    robot = default_robot()
    units = ", ".join(f"{height:g} {unit}" for unit, height in DEFAULT_STEP_HEIGHT.items())
    p = subparsers.add_parser(
        "step", help="co-simulate a joint reference step and compare it with linear predictions",
        description="Co-simulate a reference step of a robot's computed-torque loop (its controller "
                    "and plant FMUs), starting at rest at its home configuration; print rise/settling "
                    "time, overshoot and peak of the co-simulated response and of three linear "
                    "predictions (continuous error dynamics, its c2d ZOH discretization, the "
                    "sampled-data loop), and their max deviation in % of the step height. Gains: a "
                    "gain set of the robot's description (--gains), explicit values (--kp/--kd/--ki), "
                    "or designed from --settling-time and --overshoot.")
    p.add_argument("--robot", default=robot, metavar="NAME",
                   help=f"robot with controller and plant FMUs: {', '.join(steppable_robots())} "
                        f"(default: {robot}, the first)")
    p.add_argument("--gains", metavar="SET",
                   help=f"gain set of the robot's description ({_gain_sets_text()}; default pd, else "
                        "the first)")
    p.add_argument("--kp", type=float, help="proportional gain (1/s^2), overrides the set's")
    p.add_argument("--kd", type=float, help="derivative gain (1/s), overrides the set's")
    p.add_argument("--ki", type=float, help="integral gain (1/s^3), overrides the set's")
    p.add_argument("--settling-time", type=float, metavar="T", help="design gains: 2%% settling time (s)")
    p.add_argument("--overshoot", type=float, metavar="P", help="design gains: overshoot (%%)")
    p.add_argument("--ki-ratio", type=float, metavar="R",
                   help="design a PID: integral pole at R zeta wn (e.g. 0.01); default PD")
    p.add_argument("--design-for-step", action="store_true",
                   help="refine the design on the sampled-data loop at --step-size")
    p.add_argument("--step-size", type=float, default=1e-3, metavar="H",
                   help="communication step (s, default 0.001)")
    p.add_argument("--step-height", "--height", dest="step_height", type=float, nargs="+", metavar="A",
                   help="step height in joint units: one for every stepped joint, or one per joint, or "
                        f"one per stepped joint (default {units} per joint)")
    p.add_argument("--joint", type=int, nargs="+", metavar="J", help="step these joints only (from 1; "
                                                                     "default: all)")
    p.add_argument("--q0", type=float, nargs="+", metavar="Q",
                   help="start configuration, joint units (default: the robot's home configuration)")
    p.add_argument("--t-end", type=float, metavar="T", help="stop time (s; default 1, or 3 x settling time)")
    p.add_argument("--driver", choices=tuple(DRIVERS), default="master",
                   help="co-simulation driver (default master: the project's Gauss-Seidel master)")
    p.add_argument("--fmus", default="fmus", metavar="DIR", help="FMU root holding ROBOT/*.fmu (default fmus)")
    p.add_argument("--out", metavar="DIR", help="write CSVs and the figure here")
    p.set_defaults(func=_step_command)
    _answer_in_one_line(p)
    return p


def main(argv: list[str] | None = None) -> int:
    """``python -m robofmu.system.stepresponse ...``: the ``step`` command on its own."""
    parser = argparse.ArgumentParser(prog="robofmu")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    add_step_command(sub)
    args = parser.parse_args(["step", *(argv if argv is not None else sys.argv[1:])])
    return args.func(args)

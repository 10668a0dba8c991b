"""``robofmu step``: co-simulate a joint reference step of a robot and compare it with the predictions.

A mistake on the command line is answered in one line naming the option, with exit status 2
(argparse's own messages included); a co-simulation that fails, in one line with status 1;
Ctrl-C with 130 (:func:`~robofmu.system.usage.stopped`).

"Step" alone is the communication step (``--step-size``); the size of the reference step is its
amplitude (``--amplitude``). Older spellings still work and warn in one line: ``--t-end``
(``--stop-time``), ``--driver master|jacobi`` (``--algorithm gauss-seidel|jacobi``),
``--step-height`` / ``--height`` (``--amplitude``).

The amplitude must be finite and not 0, and the held reference ``q0 + amplitude`` of each
stepped joint within its position limits (a joint without limits: a step of at most one turn,
2 pi rad, or 1 m): the predictions are of a step the loop can follow. ``--step-size`` must not
exceed ``--stop-time`` (a given stop time is a whole number of steps), and the recording must fit
in memory (:func:`~robofmu.system.usage.check_memory`).

``--robot`` is a robot of the package by name or the path of a robot TOML anywhere (as for
``robofmu build``); either way its FMUs are ``<--fmus>/<its name>/{controller,plant}.fmu``.

The loop as it runs on a robot: ``--sample-time TS`` (a whole multiple of ``--step-size``) makes
the controller sample every TS, ``--delay-steps D`` outputs its effort D samples late, ``--set
BLOCK.PARAM=VALUE`` changes a block parameter (``plant.friction[2]=0.5``: joint losses the
controller does not know) and ``--friction-unknown`` sets ``controller.loss_compensation`` to 0.
With any of them the ``sampled`` model is the loop at TS with D, the joints coupled by gravity and
damping through the held effort (:func:`~robofmu.system.stepresponse.sampled.predict_coupled`,
linearized at the step's middle), and the report adds the largest
stable kp at TS and D (kd held) and, per stepped joint with Coulomb friction unknown to the
controller, the stop short predicted, measured and missed. Without them the command is as before.
A response whose error grows is reported ``UNSTABLE`` naming the block, the joint and the time
(exit status 0: the run itself worked).
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

from robofmu.system import defaults, options
from robofmu.system.usage import UsageError, atomic_file, check_fmu_folder, check_memory, check_times, check_writable, \
    one_line, say, stopped

HELP = "co-simulate a joint reference step and compare it with linear predictions"

#: ``--driver`` (deprecated) values as ``--algorithm`` values.
_DRIVER_ALGORITHMS = {"master": "gauss-seidel", "jacobi": "jacobi"}


class _Driver(options.deprecated_alias("--algorithm")):
    """``--driver master|jacobi``: the old spelling of ``--algorithm`` (master is gauss-seidel)."""

    def __call__(self, parser, namespace, values, option_string=None):
        super().__call__(parser, namespace, _DRIVER_ALGORITHMS[values], option_string)


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register ``robofmu step``; returns its parser (python-control is imported by :func:`main`)."""
    p = subparsers.add_parser(
        "step", help=HELP,
        description="Co-simulate a reference step of a robot's computed-torque loop (its controller "
                    "and plant FMUs), starting at rest at its home configuration; print rise/settling "
                    "time, overshoot and peak of the co-simulated response and of three linear "
                    "predictions (continuous error dynamics, its c2d ZOH discretization, the "
                    "sampled-data loop), and their max deviation in % of the amplitude. Gains: a "
                    "gain set of the robot's description (--gains), explicit values (--kp/--kd/--ki: "
                    "kp > 0, kd > 0, ki >= 0), or designed from --settling-time and --overshoot.")
    p.add_argument("--robot", metavar="NAME|PATH",
                   help="a robot with a controller and a plant block: a robot of the package by name, or the "
                        "path of a robot TOML (e.g. ./myarm/myarm.toml; its FMUs in --fmus/<its name>/, as "
                        "robofmu build writes them) (default: the first package robot that has both, by name)")
    p.add_argument("--gains", metavar="SET",
                   help="a gain set of the robot's description, [gains.SET] (default: its default_gains)")
    p.add_argument("--kp", type=float, help="proportional gain (1/s^2, > 0), overrides the set's")
    p.add_argument("--kd", type=float, help="derivative gain (1/s, > 0), overrides the set's")
    p.add_argument("--ki", type=float, help="integral gain (1/s^3, >= 0), overrides the set's")
    p.add_argument("--settling-time", type=float, metavar="T", help="design gains: 2%% settling time (s)")
    p.add_argument("--overshoot", type=float, metavar="P", help="design gains: overshoot (%%)")
    p.add_argument("--ki-ratio", type=float, metavar="R",
                   help="design a PID: integral pole at R zeta wn (e.g. 0.01); default PD")
    p.add_argument("--design-for-step", action="store_true",
                   help="refine the design on the sampled-data loop at --step-size")
    options.add_step_size(p, default=defaults.STEP_SIZE)
    p.add_argument("--amplitude", type=float, nargs="+", metavar="A",
                   help="size of the reference step in joint units (rad or m): one for every stepped joint, "
                        "one per joint, or one per stepped joint; finite, not 0, the reference within the joint's "
                        "position limits (without limits: at most one turn, 2 pi rad, or 1 m) (default: the step "
                        "experiment's DEFAULT_AMPLITUDE per joint unit, downward where it would pass the joint's "
                        "upper limit)")
    for old in ("--step-height", "--height"):
        p.add_argument(old, dest="amplitude", type=float, nargs="+", metavar="A",
                       action=options.deprecated_alias("--amplitude"), help=argparse.SUPPRESS)
    p.add_argument("--joint", type=int, nargs="+", metavar="J", help="step these joints only (from 1; "
                                                                     "default: all)")
    p.add_argument("--q0", type=float, nargs="+", metavar="Q",
                   help="start configuration, joint units (default: the robot's home configuration)")
    options.add_stop_time(p, what=f"{defaults.STOP_TIME:g}, or 3 x --settling-time", old=("--t-end",))
    options.add_algorithm(p, default=defaults.ALGORITHM)
    p.add_argument("--sample-time", type=float, metavar="TS",
                   help="the controller's sample time in s, a whole multiple of --step-size (the plant still steps "
                        "at --step-size); the sampled model and the stability limit follow it (default: --step-size)")
    p.add_argument("--delay-steps", type=int, metavar="D",
                   help="computation delay: the controller outputs the effort of a sample D samples later "
                        "(default: 0)")
    p.add_argument("--set", action="append", metavar=options.PARAMETER_SETTING,
                   help="set a plant or controller parameter (repeatable), e.g. plant.friction[2]=0.5 (joint "
                        "losses the controller does not know); not the gains, the start or the reference, which "
                        "have their options")
    p.add_argument("--friction-unknown", action="store_true",
                   help="the controller does not compensate the joints' damping and friction "
                        "(controller.loss_compensation = 0); the report gives the stop short they cause")
    p.add_argument("--driver", dest="algorithm", choices=tuple(_DRIVER_ALGORITHMS), action=_Driver,
                   help=argparse.SUPPRESS)
    options.add_fmus(p)
    options.add_out(p, "write the CSVs and the figure into this folder (created; other files in it stay)")
    p.set_defaults(func=main)
    options.one_line_errors(p)
    return p


def _positive(option: str, value: float | None) -> None:
    if value is not None and not (math.isfinite(value) and value > 0.0):
        raise UsageError(f"{option}: must be > 0, got {value:g}")


def _design(args):
    """The gain design ``--settling-time`` and ``--overshoot`` ask for, or None; UsageError naming
    the option."""
    from robofmu.system.stepresponse import design_gains

    explicit = [option for option, value in (("--kp", args.kp), ("--kd", args.kd), ("--ki", args.ki),
                                             ("--gains", args.gains)) if value is not None]
    if args.settling_time is None and args.overshoot is None:
        for option, value in (("--ki-ratio", args.ki_ratio), ("--design-for-step", args.design_for_step or None)):
            if value is not None:
                raise UsageError(f"{option}: needs --settling-time and --overshoot")
        return None
    if args.settling_time is None or args.overshoot is None:
        missing = "--overshoot" if args.settling_time is not None else "--settling-time"
        raise UsageError(f"{missing}: missing: --settling-time and --overshoot go together")
    if explicit:
        raise UsageError(f"{explicit[0]}: the gains are designed from --settling-time and --overshoot; "
                         "give one or the other")
    _positive("--settling-time", args.settling_time)
    if not (math.isfinite(args.overshoot) and 0.0 <= args.overshoot < 100.0):
        raise UsageError(f"--overshoot: must be in [0, 100) %, got {args.overshoot:g}")
    _positive("--ki-ratio", args.ki_ratio)
    try:
        return design_gains(args.settling_time, args.overshoot, ki_ratio=args.ki_ratio,
                            h=args.step_size if args.design_for_step else None)
    except ValueError as exc:
        raise UsageError(f"--settling-time: {exc}") from None


def _gains(args, description, design) -> tuple[float, float, float]:
    """kp, kd, ki: designed, else the gain set of the robot's ``description`` (``--gains``, default
    its ``default_gains``) with ``--kp`` / ``--kd`` / ``--ki`` over it, by the gains' rule
    (UsageError naming the option)."""
    from robofmu.components.control import check_gains
    from robofmu.components.parameters import ParameterError

    if design is not None:
        return design.kp, design.kd, design.ki
    try:
        seed = description.gain_set(description.default_gains if args.gains is None else args.gains)
    except ValueError as exc:
        raise UsageError(f"--gains: {exc}") from None
    gains = {name: getattr(seed, name) if given is None else given
             for name, given in (("kp", args.kp), ("kd", args.kd), ("ki", args.ki))}
    try:
        return check_gains(**gains)
    except ParameterError as exc:      # naming the gain
        raise UsageError(f"--{exc.name}: {exc.problem}") from None


def _robot(args):
    """The description of ``--robot`` (a package robot's name or a robot TOML's path), default the
    first package robot a step experiment can run on; UsageError naming the option: an unknown
    name, a path that does not exist, a TOML that is not a valid description (its DescriptionError,
    naming file and key), a robot without a controller and a plant block."""
    from robofmu.components.robots import is_robot_file, load_description
    from robofmu.system.stepresponse import CONTROLLER, PLANT, steppable_robots

    if args.robot is None:
        robots = steppable_robots()
        if not robots:
            raise UsageError("--robot: no described robot has a controller and a plant block")
        return load_description(robots[0])
    try:
        description = load_description(args.robot)
    except ValueError as exc:         # unknown name, missing file, a folder, DescriptionError
        raise UsageError(f"--robot: {one_line(exc)}") from None
    if not {CONTROLLER, PLANT} <= set(description.blocks):
        if is_robot_file(args.robot):
            raise UsageError(f"--robot: {args.robot}: robot {description.name!r} has no controller and plant "
                             f"blocks (its blocks: {', '.join(description.blocks)})")
        raise UsageError(f"--robot: robot {args.robot!r} has no controller and plant blocks; robots that "
                         f"have: {', '.join(steppable_robots())}")
    return description


#: Largest reference step on a joint without position limits, by joint unit: one turn, 1 m.
UNBOUNDED_AMPLITUDE = {"rad": 2.0 * math.pi, "m": 1.0}

#: Bytes of memory per communication step and joint: five float64 series (the recorded q and tau,
#: the three linear predictions), about four times over for the comparison's copies.
BYTES_PER_STEP_AND_JOINT = 4 * 8 * 5


def _stem(args) -> str:
    """The file names' stem: ``step_h1ms`` (``step_h1ms_ts4ms_d1`` with ``--sample-time`` or ``--delay-steps``)."""
    stem = f"step_h{args.step_size * 1e3:g}ms"
    if args.sample_time is not None or args.delay_steps is not None:
        stem += f"_ts{(args.sample_time or args.step_size) * 1e3:g}ms_d{args.delay_steps or 0}"
    return stem


#: Parameters the step experiment sets itself, by ``--set`` name: the option that gives them.
_OWN_SETTINGS = {"controller.kp": "--kp", "controller.kd": "--kd", "controller.ki": "--ki",
                 "controller.gain_scale": "--kp/--kd/--ki", "controller.q_ref": "--amplitude",
                 "controller.delay_steps": "--delay-steps", "controller.sample_time": "--sample-time",
                 "plant.q0": "--q0", "plant.qd0": "a step from rest"}


def _sampled(args) -> dict:
    """The loop as on a robot: ``sample_time``, ``delay_steps`` and ``parameters`` for
    :func:`~robofmu.system.stepresponse.cosimulate_step`, {} without the options (the command as
    before); UsageError naming the option: a sample time that is not a whole multiple of
    ``--step-size``, a negative or too large delay, a ``--set`` that is not BLOCK.PARAM=VALUE,
    names another block, or sets what the step experiment sets itself."""
    from robofmu.components.blocks.controller import DELAY_STEPS
    from robofmu.system.stepresponse import CONTROLLER, PLANT

    if args.sample_time is None and args.delay_steps is None and not args.set and not args.friction_unknown:
        return {}
    if args.sample_time is not None:
        ratio = args.sample_time / args.step_size if math.isfinite(args.sample_time) else 0.0
        if not (args.sample_time > 0.0 and round(ratio) >= 1 and abs(round(ratio) - ratio) <= 1e-9 * ratio):
            raise UsageError(f"--sample-time {args.sample_time:g}: must be a whole multiple of --step-size "
                             f"{args.step_size:g} s (1, 2, 3, ... times it)")
    if args.delay_steps is not None and not DELAY_STEPS.low <= args.delay_steps <= DELAY_STEPS.high:
        raise UsageError(f"--delay-steps {args.delay_steps}: must be a whole number from {DELAY_STEPS.low:g} "
                         f"to {DELAY_STEPS.high:g}")
    parameters = {}
    for text in args.set or []:
        try:
            name, value = options.parse_setting(text)
        except ValueError as exc:
            raise UsageError(str(exc)) from None
        block, _, parameter = name.partition(".")
        base = f"{block}.{parameter.split('[', 1)[0]}"
        if block not in (CONTROLLER, PLANT):
            raise UsageError(f"--set {text}: no block {block!r} in the step diagram (its blocks: {CONTROLLER}, {PLANT})")
        if base in _OWN_SETTINGS:
            raise UsageError(f"--set {text}: the step experiment sets {base} itself; give {_OWN_SETTINGS[base]}")
        parameters[name] = value
    if args.friction_unknown:
        parameters[f"{CONTROLLER}.loss_compensation"] = 0.0
    return dict(sample_time=args.sample_time, delay_steps=args.delay_steps, parameters=parameters)


def _check_reference(args, robot, setup) -> None:
    """Refuse (UsageError naming ``--amplitude`` or ``--q0``) a step whose start or held reference
    ``q0 + amplitude`` leaves a stepped joint's position limits, or a step larger than
    :data:`UNBOUNDED_AMPLITUDE` on a joint without limits: the linear predictions are of a step
    the loop can follow."""
    from robofmu.components.robots import load_model

    lower, upper = load_model(robot).position_limits()
    for j in setup.joints:
        k, unit = j - 1, setup.joint_units[j - 1]
        if args.q0 is not None and not lower[k] <= setup.q0[k] <= upper[k]:
            raise UsageError(f"--q0: joint {j} at {setup.q0[k]:g} {unit} is outside its limits "
                             f"[{lower[k]:g}, {upper[k]:g}] {unit}")
        amplitude, target = setup.amplitudes[k], setup.q_ref[k]
        if math.isfinite(lower[k]) or math.isfinite(upper[k]):
            if not lower[k] <= target <= upper[k]:
                bound = upper[k] if target > upper[k] else lower[k]
                raise UsageError(f"--amplitude: joint {j}: {amplitude:g} {unit} from {setup.q0[k]:g} {unit} passes "
                                 f"its {'upper' if bound == upper[k] else 'lower'} limit {bound:g} {unit}; give an "
                                 f"amplitude from {lower[k] - setup.q0[k]:g} to {upper[k] - setup.q0[k]:g} {unit}")
        elif abs(amplitude) > UNBOUNDED_AMPLITUDE.get(unit, 1.0):
            raise UsageError(f"--amplitude: joint {j}: {amplitude:g} {unit} is more than "
                             f"{UNBOUNDED_AMPLITUDE.get(unit, 1.0):g} {unit}, the largest step on a joint without "
                             "position limits")


def _stop_time(args, design, joints: int) -> float:
    """The stop time (s): ``--stop-time`` or the default (3 x the designed settling time), a whole
    number of steps; UsageError naming ``--step-size`` and ``--stop-time`` for a step longer than
    the run, and for a run whose recording would not fit in memory."""
    from robofmu.system.plan import step_count

    stop_time = args.stop_time
    if stop_time is None:
        stop_time = max(defaults.STOP_TIME, 3.0 * args.settling_time) if design else defaults.STOP_TIME
    given = f"--step-size {args.step_size:g} s, --stop-time {stop_time:g} s" + \
        ("" if args.stop_time is not None else " (the default)")
    if args.step_size > stop_time:
        raise UsageError(f"{given}: the step is longer than the run; give a --step-size at most the --stop-time")
    ratio = stop_time / args.step_size
    if not ratio <= 1e15:
        raise UsageError(f"{given}: {ratio:.3g} steps, far more than memory can record")
    steps = round(ratio)
    if args.stop_time is not None:
        try:
            step_count(0.0, stop_time, args.step_size)
        except ValueError:
            raise UsageError(f"{given}: the stop time is not a whole number of steps") from None
    check_memory((steps + 1) * joints * BYTES_PER_STEP_AND_JOINT, f"{given}: {steps} steps",
                 "give a larger --step-size or a shorter --stop-time")
    return steps * args.step_size


def main(args) -> int:
    from robofmu.system.master import SimulationError
    from robofmu.system.stepresponse import compare, cosimulate_step, plot_comparison, step_setup, step_system, \
        write_csv

    try:
        robot = _robot(args)                 # its description: resolved once
        check_times(args.step_size, args.stop_time)
        try:
            setup = step_setup(robot, args.amplitude, args.joint, args.q0)
        except ValueError as exc:
            argument, _, message = str(exc).partition(": ")
            option = {"amplitude": "--amplitude", "joint": "--joint", "q0": "--q0",
                      "robot": "--robot"}.get(argument)
            raise UsageError(f"{option}: {message}" if option else f"--robot: {exc}") from None
        _check_reference(args, robot, setup)
        design = _design(args)
        kp, kd, ki = _gains(args, robot, design)
        stop_time = _stop_time(args, design, len(setup.q0))
        sampled = _sampled(args)
        if (args.sample_time or 0.0) > stop_time:
            raise UsageError(f"--sample-time {args.sample_time:g}: longer than the run (--stop-time {stop_time:g} s): "
                             "the controller would sample once")
        check_fmu_folder(step_system(args.fmus, kp, kd, ki, robot=robot, amplitude=setup.amplitudes,
                                     h=args.step_size, stop_time=stop_time, joint=setup.joints, q0=setup.q0,
                                     **sampled))
        if args.out is not None:
            check_writable(args.out, "--out")
            check_writable(Path(args.out) / f"{_stem(args)}_cosim.csv", "--out", file=True)
        result = cosimulate_step(Path(args.fmus), kp, kd, ki, robot=robot, amplitude=setup.amplitudes,
                                 h=args.step_size, stop_time=stop_time, joint=setup.joints, q0=setup.q0,
                                 algorithm=args.algorithm, **sampled)
    except (SimulationError, ValueError) as exc:     # ValueError: UsageError, DiagramError
        return stopped("step", exc)
    comparison = compare(result)
    for group in result.messages:           # what the FMUs said: a limit crossed, ...
        say("step", f"warning: {group}")
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
        stem = _stem(args)
        try:
            with atomic_file(out / f"{stem}_cosim.csv") as partial:
                result.to_csv(partial)
            with atomic_file(out / f"{stem}_compare.csv") as partial:
                write_csv(comparison, partial)
            figure = plot_comparison(comparison, out, stem)
        except OSError as exc:           # checked before the run: the folder changed since
            say("step", f"--out {out}: cannot write it: {exc.strerror or exc}")
            return 2
        print(f"wrote {out / (stem + '_cosim.csv')}, {out / (stem + '_compare.csv')}, {figure}")
    return 0

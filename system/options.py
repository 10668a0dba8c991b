"""The command-line options several ``robofmu`` commands share, declared once.

The spellings are those of FMI tools (``fmpy simulate``): ``--stop-time``, ``--step-size``,
``--algorithm gauss-seidel|jacobi``, ``--fmus``, ``--out``. An older spelling still works for
now and prints a one-line deprecation warning (:func:`deprecated_alias`). A test walks every
subcommand's parser and fails when two commands name one concept differently.

Option values are checked by the validators here, called by each command before it runs:
:func:`finite` (no NaN or infinity), :func:`whole` (an integer with a least value: a count >= 1,
a seed >= 0); each refusal is a :class:`~robofmu.system.usage.UsageError` naming the option and
its value, so the command answers in one line with exit status 2. :func:`one_line_errors`
makes a command's parser answer argparse's own mistakes in one line too. The times
(``--step-size``, ``--stop-time``) are checked where the experiment's defaults are known
(:func:`robofmu.system.usage.timing`).
"""
from __future__ import annotations

import argparse
import math
import sys

from robofmu.system import defaults
from robofmu.system.diagram import parameter_address

__all__ = ["PARAMETER_SETTING", "add_algorithm", "add_fmus", "add_out", "add_step_size", "add_stop_time",
           "deprecated_alias", "finite", "number", "one_line_errors", "parse_setting", "whole"]

#: What ``--set`` and a sweep's ``--vary`` take before ``=``.
PARAMETER_SETTING = "BLOCK.PARAM=VALUE"


def deprecated_alias(new: str):
    """An argparse action for an old spelling of option ``new``: stores the value under ``new``'s
    destination and warns on stderr in one line (``robofmu: --step is deprecated; use --step-size``)."""

    class Deprecated(argparse.Action):
        def __call__(self, parser, namespace, values, option_string=None):
            print(f"{parser.prog}: {option_string} is deprecated; use {new}", file=sys.stderr)
            setattr(namespace, self.dest, values)

    return Deprecated


def _add(parser, new: str, old: list[str], **kwargs) -> None:
    parser.add_argument(new, **kwargs)
    dest = new.lstrip("-").replace("-", "_")
    for spelling in old:
        parser.add_argument(spelling, dest=dest, action=deprecated_alias(new), help=argparse.SUPPRESS,
                            **{k: v for k, v in kwargs.items() if k in ("type", "choices", "metavar")})


def add_step_size(parser, default: float | None = None, what: str = "the experiment's") -> None:
    """``--step-size H`` (old: ``--step``): the communication step in s."""
    shown = f"{default:g}" if default is not None else what
    _add(parser, "--step-size", ["--step"], type=float, default=default, metavar="H",
         help=f"communication step in s (default: {shown})")


def add_stop_time(parser, default: float | None = None, what: str = "the experiment's",
                  old: tuple[str, ...] = ("--stop",)) -> None:
    """``--stop-time T`` (old: ``--stop``): the stop time in s."""
    shown = f"{default:g}" if default is not None else what
    _add(parser, "--stop-time", list(old), type=float, default=default, metavar="T",
         help=f"stop time in s, a whole number of steps (default: {shown})")


def add_algorithm(parser, default: str | None = None, what: str = "the experiment's") -> None:
    """``--algorithm gauss-seidel|jacobi``: the master algorithm."""
    parser.add_argument("--algorithm", choices=defaults.ALGORITHMS, default=default,
                        help=f"master algorithm (default: {default or what})")


def add_fmus(parser) -> None:
    """``--fmus DIR``: the folder of the built FMUs."""
    _add(parser, "--fmus", [], default=defaults.FMU_FOLDER, metavar="DIR",
         help=f"FMU folder (default: {defaults.FMU_FOLDER})")


def add_out(parser, help: str, metavar: str = "DIR", default: str | None = None) -> None:
    """``--out DIR`` (or ``FILE``): where the command writes."""
    parser.add_argument("--out", default=default, metavar=metavar, help=help)


def parse_setting(text: str, option: str = "--set") -> tuple[str, float | bool]:
    """``BLOCK.PARAM=VALUE`` (one number, or true / false) as ``(name, value)``.

    Raises
    ------
    ValueError
        Naming ``option`` and ``text``, with an example.
    """
    name, equals, value = text.partition("=")
    name = name.strip()
    try:
        parameter_address(name)
    except ValueError:
        equals = ""
    if not equals or not value.strip():
        raise ValueError(f"{option} {text}: expected {PARAMETER_SETTING} (e.g. controller.kp=400)")
    return name, number(value, f"{option} {text}")


def number(text: str, where: str) -> float | bool:
    """A finite number, or true / false, from ``text`` (ValueError naming ``where``)."""
    word = text.strip().lower()
    if word in ("true", "false"):
        return word == "true"
    try:
        value = float(word)
    except ValueError:
        raise ValueError(f"{where}: {text.strip()!r} is no number (VALUES: a comma list 200,400,800, "
                         f"a range START:STOP:COUNT, uniform(LOW,HIGH) or normal(MEAN,STD))") from None
    if not math.isfinite(value):
        raise ValueError(f"{where}: {text.strip()!r} is not a finite number")
    return value


def finite(option: str, value: float | None) -> float | None:
    """``value`` of ``option`` if it is a finite number (None: not given); UsageError naming the
    option otherwise (NaN, infinity)."""
    from robofmu.system.usage import UsageError

    if value is not None and not math.isfinite(value):
        raise UsageError(f"{option} {value:g}: must be a finite number")
    return value


def whole(option: str, value: int | None, least: int) -> int | None:
    """``value`` of ``option`` if it is a whole number >= ``least`` (None: not given); UsageError
    naming the option otherwise (a count below 1, a negative seed)."""
    from robofmu.system.usage import UsageError

    if value is not None and not value >= least:
        raise UsageError(f"{option} {value}: must be a whole number >= {least}")
    return value

def one_line_errors(parser: argparse.ArgumentParser) -> None:
    """Make ``parser`` (a command's) report argparse's own mistakes (a bad value, an unknown
    option) in one line ``robofmu <command>: argument --option: ...``, exit status 2."""
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

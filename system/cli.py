"""The ``robofmu`` command line.

Exit status and messages, for every command:

- **2**: a mistake in what was asked (an unknown experiment or robot, an experiment file that
  cannot be used, a bad option value, a count or grid that would not fit in memory, an FMU folder
  that is missing or stale, an output path that cannot be written or holds a file robofmu did
  not write, a scheduler that refuses the connection), found before anything runs; one line
  ``robofmu <command>: ...`` naming the file, key or option, never a traceback. Each FMU,
  SSP package, container, CSV and report is written whole or not at all (a temporary sibling
  renamed into place), so Ctrl-C leaves the earlier file or none. argparse's own errors (an unknown
  option, a value that is no number) also exit 2, after a usage line.
- **1**: the work itself failed (a co-simulation step, an FMU that fails to initialize; for
  ``doctor``: a problem found), one line per failure.
- **130**: interrupted (Ctrl-C). ``robofmu run`` stops at the next communication point, frees
  the FMUs and writes what was recorded so far; ``robofmu sweep`` keeps every finished row.

``robofmu sweep`` exits 0 when every run has a row, failed runs included: a run that fails is a
finding of the sweep (a row with its status and message), not a failure of the command.

A run that completes but did not respect its IK or limits (an FMU warning or error, an IK
status other than 0, a joint beyond its limits) exits 0 with ``— WARNING: ...`` in its summary
line, what the FMUs said printed on stderr; ``robofmu run --strict`` makes it exit 1.
"""
from __future__ import annotations

import argparse
import importlib
import sys

from robofmu.system.commands import build, container, demo, doctor, inspect, new, osp, run, ssp, sweep, workspace

#: The subcommands in the order ``robofmu --help`` lists them. ``step`` and ``convergence``
#: import python-control or scipy's integrators: their modules are loaded only when asked for
#: (name, module, one-line help).
COMMANDS = [new, inspect, build, run, sweep, ssp, osp, container, ("step", "robofmu.system.commands.step",
                                                 "co-simulate a joint reference step and compare it with "
                                                 "linear predictions"),
            ("convergence", "robofmu.system.commands.convergence",
             "co-simulation error against the communication step, beside a monolithic reference"),
            demo, workspace, doctor]


def _command(argv: list[str]) -> str | None:
    """The sub-command in ``argv``: its first argument that is not an option."""
    return next((a for a in argv if not a.startswith("-")), None)


def parser_for(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The argument parser; a lazily loaded command's own parser only when ``argv`` asks for it
    (``None``: every command's parser)."""
    parser = argparse.ArgumentParser(
        prog="robofmu",
        description="Robot-arm control blocks as FMI 2.0 co-simulation FMUs, and their co-simulation. "
                    "A mistake is answered in one line naming the file, key or option (exit status 2), "
                    "a failed run with status 1, Ctrl-C with 130.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    wanted = None if argv is None else _command(argv)
    for command in COMMANDS:
        if isinstance(command, tuple):
            name, module, help_text = command
            if argv is None or wanted == name:
                importlib.import_module(module).add_parser(sub)
            else:
                sub.add_parser(name, help=help_text)
        else:
            command.add_parser(sub)
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

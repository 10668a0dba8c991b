"""One spelling per concept across every ``robofmu`` subcommand (python-control's kwargs_test).

The parser of every subcommand is walked; an option that names one of the shared concepts must
use the one spelling FMI tools use (``fmpy simulate``), and an older spelling may only survive
hidden, as a deprecated alias that warns in one line.
"""
from __future__ import annotations

import argparse
import subprocess
import sys

import pytest

from robofmu.system import defaults
from robofmu.system.cli import parser_for

#: Each shared concept: its one spelling, and spellings that mean the same (never visible).
CONCEPTS = {
    "stop time": ("--stop-time", {"--stop", "--t-end", "--tend", "--t-stop", "--stop_time", "--end-time", "--duration"}),
    "communication step": ("--step-size", {"--step", "--h", "--dt", "--step_size", "--communication-step"}),
    "master algorithm": ("--algorithm", {"--driver", "--master", "--method", "--scheme"}),
    "FMU folder": ("--fmus", {"--fmu-dir", "--fmu_dir", "--fmu-root", "--fmu-folder", "--fmudir"}),
    "output": ("--out", {"--output", "--out-dir", "--outdir", "--output-dir", "-o"}),
}


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def _options(parser: argparse.ArgumentParser) -> list[tuple[str, argparse.Action]]:
    return [(s, a) for a in parser._actions for s in a.option_strings]


@pytest.fixture(scope="module")
def commands() -> dict[str, argparse.ArgumentParser]:
    return _subparsers(parser_for(None))


def test_the_walk_sees_every_subcommand_with_its_own_parser(commands):
    assert {"build", "run", "sweep", "ssp", "container", "step", "convergence", "demo", "workspace",
            "doctor"} <= set(commands)
    for name, parser in commands.items():
        assert parser.get_default("func") is not None, f"robofmu {name}: a placeholder parser, not its own"


def test_a_concept_has_one_visible_spelling_in_every_command(commands):
    found = []
    for name, parser in commands.items():
        for option, action in _options(parser):
            visible = action.help is not argparse.SUPPRESS
            for concept, (spelling, synonyms) in CONCEPTS.items():
                if option in synonyms and visible:
                    found.append(f"robofmu {name} {option}: the {concept} is spelled {spelling}")
    assert not found, "\n".join(found)


def test_one_option_means_one_thing_across_commands(commands):
    """The same visible option string stores to the same destination with the same type."""
    seen: dict[str, tuple[str, object, str]] = {}
    clashes = []
    for name, parser in commands.items():
        for option, action in _options(parser):
            if action.help is argparse.SUPPRESS or option in ("-h", "--help"):
                continue
            kind = (action.dest, action.type)
            if option in seen and seen[option][:2] != kind:
                clashes.append(f"{option}: {seen[option][2]} stores {seen[option][:2]}, {name} stores {kind}")
            seen.setdefault(option, (*kind, name))
    assert not clashes, "\n".join(clashes)


def test_the_algorithm_choices_are_the_masters(commands):
    for name, parser in commands.items():
        for option, action in _options(parser):
            if option == "--algorithm":
                assert tuple(action.choices) == defaults.ALGORITHMS, name


def test_the_walk_would_catch_a_second_spelling():
    """The negative control: a command that spells the stop time its own way fails the check."""
    parser = argparse.ArgumentParser(prog="robofmu")
    sub = parser.add_subparsers()
    p = sub.add_parser("mine")
    p.add_argument("--t-end", type=float)
    p.set_defaults(func=print)
    with pytest.raises(AssertionError, match="--t-end: the stop time is spelled --stop-time"):
        test_a_concept_has_one_visible_spelling_in_every_command({"mine": p})


@pytest.mark.parametrize("command, old, new, value", [
    ("run", "--step", "--step-size", "0.001"),
    ("run", "--stop", "--stop-time", "0.01"),
])
def test_an_old_spelling_still_works_and_warns_in_one_line(commands, command, old, new, value):
    args = commands[command].parse_args(["chess-pd", old, value])
    assert getattr(args, new.lstrip("-").replace("-", "_")) == float(value)
    done = subprocess.run([sys.executable, "-c", "import sys; from robofmu.system.cli import parser_for; "
                           "parser_for(sys.argv[1:]).parse_args(sys.argv[1:])", command, "chess-pd", old, value],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stderr.strip().splitlines() == [f"robofmu {command}: {old} is deprecated; use {new}"]

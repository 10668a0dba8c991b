"""system/ is generic: no robot name, no number or default of a robot's description in its code.

Robot data lives in components/robots/<name>/ and in experiment and study files; the code in
system/ must run any robot. This reads the code (not docstrings or comments) of every module.
"""
from __future__ import annotations

import io
import re
import tokenize
from pathlib import Path

import pytest

from robofmu.components.robots import ROBOTS_DIR, available

SYSTEM = Path(__file__).resolve().parents[1] / "system"
#: Numbers too common to tell a robot by (0, 1, 2, a half, ...).
COMMON = {0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 10.0, 20.0, 100.0, 0.5, 0.25, 0.1, 0.2, 1.5, 0.05, 1e-3, 0.001, 0.01,
          0.02, 0.005, 0.002, 1e-9, 1e-12, 9.81, 1000.0, 1e3, 0.3, 0.15, 40.0, 400.0, 0.6, 0.7, 1.2}


def code_tokens(path: Path):
    """(kind, text, line) of every NAME, STRING and NUMBER token that is code, not a docstring."""
    tokens = list(tokenize.generate_tokens(io.StringIO(path.read_text()).readline))
    previous = tokenize.NEWLINE
    for tok in tokens:
        if tok.type == tokenize.STRING and previous in (tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT,
                                                         tokenize.NL):
            previous = tok.type
            continue                                     # a docstring or a bare string statement
        if tok.type not in (tokenize.COMMENT, tokenize.NL):
            previous = tok.type
        if tok.type in (tokenize.NAME, tokenize.STRING, tokenize.NUMBER):
            yield tok.type, tok.string, tok.start[0]


def robot_numbers() -> set[float]:
    """The numbers of every robot description and URDF, but the common ones."""
    found = set()
    for robot in available():
        text = (ROBOTS_DIR / robot / f"{robot}.toml").read_text()
        urdf = ROBOTS_DIR / robot / f"{robot}.urdf"
        if urdf.is_file():                                # a closed chain is described in its TOML
            text += urdf.read_text()
        for match in re.findall(r"(?<![\w.])-?\d+\.\d+(?:[eE]-?\d+)?", text):
            value = abs(float(match))
            if value not in COMMON:
                found.add(value)
    return found


MODULES = sorted(SYSTEM.rglob("*.py"))


def test_robot_numbers_were_found():
    numbers = robot_numbers()
    assert 0.1905 in numbers and 0.3048 in numbers and 0.03 in numbers and 0.125 in numbers


def problems_in(path: Path) -> list[str]:
    """Every robot name and robot-description number in the code of ``path``."""
    names = set(available()) | {"pawn", "gambit", "queen"}
    numbers = robot_numbers()
    problems = []
    for kind, text, line in code_tokens(path):
        if kind == tokenize.NUMBER:
            try:
                value = abs(float(text))
            except ValueError:
                continue
            if value in numbers:
                problems.append(f"line {line}: number {text} of a robot description")
            continue
        words = set(re.findall(r"[a-z0-9_]+", text.lower())) | set(re.findall(r"[a-z0-9_-]+", text.lower()))
        for name in sorted(names):
            if name in words or any(w.startswith(name + "-") for w in words):
                problems.append(f"line {line}: robot name {name!r} in {text!r}")
    return problems


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(SYSTEM)))
def test_no_robot_name_or_number_in_system_code(path):
    problems = problems_in(path)
    assert not problems, "\n".join(problems)


def test_the_check_can_fail(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text('"""A docstring may say chess."""\nROBOT = "chess"  # a comment may say rrp\n'
                   'A2 = 0.3048\nNAME = "rpp-bangbang"\n')
    assert problems_in(bad) == ["line 2: robot name 'chess' in '\"chess\"'",
                                "line 3: number 0.3048 of a robot description",
                                "line 4: robot name 'rpp' in '\"rpp-bangbang\"'"]

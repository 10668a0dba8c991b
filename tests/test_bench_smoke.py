"""``make bench`` runs whole: every command of the Makefile's bench target, read from the Makefile
(a script added there is covered: its expected table must be listed here), runs on a few steps
(``--quick``, where a script takes it: every timing loop of the bench does) against freshly built
FMUs (``--fmus``, where it takes them), exits 0, and prints its table with the rows that matter: the
arms' cost ratio to chess-pd, the sweep's speed-up and the multi-rate run's cost per plant step
against single-rate, each consistent with the numbers printed beside it (a ratio is the quotient
of its row's columns, to the printed digits).
"""
from __future__ import annotations

import math
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def bench_commands() -> list[list[str]]:
    """The bench target's recipe lines, each as ``[script, arguments...]`` (``$(PY)`` dropped)."""
    lines = (ROOT / "Makefile").read_text().splitlines()
    start = next(k for k, line in enumerate(lines) if line.startswith("bench:"))
    commands = []
    for line in lines[start + 1:]:
        if not line.startswith("\t"):
            break
        words = shlex.split(line.strip())
        assert words[0] == "$(PY)" and words[1].startswith("benchmarks/"), line
        commands.append(words[1:])
    return commands


#: What each script's output must hold (regular expressions, multiline), by script name.
TABLES = {
    "run.py": [r"^robot\s+block\s+direct \(us\)\s+through FMI \(us\)\s+ratio$", r"^chess\s+plant\s"],
    "split.py": [r"^\| all \| [-\d.]+ \| [-\d.]+ \| [-\d.]+ \| [\d.]+ \| \d+ \|$"],
    "loop.py": [r"^robofmu\s+5\s", r"^in-process\s+5\s", r"in-process vs robofmu master",
                r"robofmu master <= 1\.20x in-process: (met|NOT met) \(\d+\.\d\dx\)"],
    "instructions.py": [r"^robofmu\s+\(quick: not counted\)", r"^in-process\s+\(quick: not counted\)",
                        r"^the master's FMI calls: (call list \(|single ctypes calls: )"],
    "multirate.py": [r"^\| chess-pd \| [\d.]+ \| [\d.]+ \| \d+\.\d\d \|", r"^\| ur5-pose \| [\d.]+ \| [\d.]+ \| \d+\.\d\d \|",
                     r"multi-rate cheaper per plant step than single-rate: (met|NOT met) on chess-pd"],
    "ik.py": [r"^chess\s+pitch_elbow\s+[\d.]+\s+0\.00\s+1\.00$", r"^panda\s+damped_least_squares\s"],
    "arms.py": [r"^\| chess-pd \| \d+ \| 1\.00 \|", r"^\| ur5-pose \| \d+ \| \d+\.\d\d \|",
                r"^\| panda-pose \| \d+ \| \d+\.\d\d \|"],
    "sweep.py": [r"^\| sweep, 1 worker \| [\d.]+ \|", r"^\| sweep, 2 workers \| [\d.]+ \|",
                 r"Two workers give \d+\.\d\dx the throughput of one"],
    "new_arm.py": [r"^\| robofmu new \| [\d.]+ \|", r"^\| robofmu run \| [\d.]+ \|", r"^\| \*\*total\*\* \|"],
}

COMMANDS = bench_commands()


def test_the_bench_target_lists_the_arms_and_the_sweep_and_every_script_has_a_table():
    scripts = [Path(command[0]).name for command in COMMANDS]
    assert {"arms.py", "sweep.py", "ik.py"} <= set(scripts)
    assert set(scripts) <= set(TABLES), "a bench script without its expected table here"
    assert all((ROOT / command[0]).is_file() for command in COMMANDS)


def check_arms(out: str) -> None:
    """Each arm's ratio is its µs per step over chess-pd's (both printed as whole µs)."""
    base = float(re.search(r"^\| chess-pd \| (\d+) \|", out, re.M).group(1))
    for name in ("ur5-pose", "panda-pose"):
        cost, ratio = map(float, re.search(rf"^\| {name} \| (\d+) \| (\d+\.\d\d) \|", out, re.M).groups())
        assert ratio > 0 and math.isfinite(ratio)
        low, high = (cost - 0.5) / (base + 0.5), (cost + 0.5) / (base - 0.5)
        assert low - 0.005 <= ratio <= high + 0.005, (name, cost, base, ratio)


def check_sweep(out: str) -> None:
    """The speed-up is the 2-worker rate over the 1-worker rate (printed to 0.1 run per minute)."""
    one = float(re.search(r"^\| sweep, 1 worker \| ([\d.]+) \|", out, re.M).group(1))
    two = float(re.search(r"^\| sweep, 2 workers \| ([\d.]+) \|", out, re.M).group(1))
    speedup = float(re.search(r"Two workers give (\d+\.\d\d)x", out).group(1))
    assert speedup > 0
    assert (two - 0.05) / (one + 0.05) - 0.005 <= speedup <= (two + 0.05) / (one - 0.05) + 0.005, (one, two, speedup)


def check_multirate(out: str) -> None:
    """Each ratio is the multi-rate µs per plant step over the single-rate (both printed to 0.1 µs),
    and the verdict follows it."""
    for name, one, many, ratio in re.findall(r"^\| ([\w-]+) \| ([\d.]+) \| ([\d.]+) \| (\d+\.\d\d) \|", out, re.M):
        one, many, ratio = float(one), float(many), float(ratio)
        assert ratio > 0 and math.isfinite(ratio)
        assert (many - 0.05) / (one + 0.05) - 0.005 <= ratio <= (many + 0.05) / (one - 0.05) + 0.005, (name, one, many)
        verdict = re.search(rf"(met|NOT met) on {name} \((\d+\.\d\d)x\)", out)
        assert verdict and float(verdict.group(2)) == ratio, name
        if abs(many - one) > 0.1:             # the verdict compares the unrounded times
            assert (verdict.group(1) == "met") == (many < one), (name, one, many)


CHECKS = {"arms.py": check_arms, "sweep.py": check_sweep, "multirate.py": check_multirate}


def offered(command: list[str]) -> list[str]:
    """``--quick`` and ``--fmus`` where the script takes them (its ``--help``): a script that
    builds its own FMUs, or is small already, may take neither."""
    shown = subprocess.run([sys.executable, command[0], "--help"], cwd=ROOT, capture_output=True, text=True,
                           timeout=300)
    assert shown.returncode == 0, shown.stderr
    return [option for option in ("--quick", "--fmus") if re.search(rf"{option}\b", shown.stdout)]


@pytest.mark.slow
@pytest.mark.parametrize("command", COMMANDS, ids=[" ".join(c) for c in COMMANDS])
def test_bench_script_runs_on_a_few_steps(fmu_root, command):
    script = Path(command[0]).name
    extra = offered(command)
    argv = [*command, *(["--quick"] if "--quick" in extra else []),
            *(["--fmus", str(fmu_root)] if "--fmus" in extra else [])]
    done = subprocess.run([sys.executable, *argv], cwd=ROOT, capture_output=True, text=True, timeout=900)
    shown = f"{' '.join(argv)}\n--- stdout\n{done.stdout}--- stderr\n{done.stderr}"
    assert done.returncode == 0, shown
    assert "Traceback" not in done.stdout + done.stderr, shown
    for pattern in TABLES[script]:
        assert re.search(pattern, done.stdout, re.M), f"no {pattern!r}:\n{shown}"
    if script in CHECKS:
        CHECKS[script](done.stdout)

"""No dead code: vulture (confidence >= 60) finds nothing but the hooks tools/vulture_whitelist.py
lists with their reasons."""
from __future__ import annotations

import pytest

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCANNED = ["components", "system", "tests", "benchmarks"]
#: Scripts run in the peers' own environments (bdsim, pydrake): their hooks are those libraries'.
EXCLUDED = "benchmarks/peers"


def scan(*paths: str) -> list[str]:
    done = subprocess.run([sys.executable, "-m", "vulture", *(paths or SCANNED), "tools/vulture_whitelist.py",
                           "--min-confidence", "60", "--exclude", EXCLUDED],
                          cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode in (0, 3), done.stderr              # 3: dead code found
    return done.stdout.splitlines()


@pytest.mark.slow
def test_vulture_finds_no_dead_code():
    assert scan() == []


def test_the_scan_finds_dead_code(tmp_path):
    """The negative control: an unused function is reported."""
    module = tmp_path / "dead.py"
    module.write_text("def never_called():\n    return 1\n")
    assert [line.split(": ", 1)[1] for line in scan(str(module))] == ["unused function 'never_called' (60% confidence)"]

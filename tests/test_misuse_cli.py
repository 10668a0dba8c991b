"""The misuse suite, command-line side (issue 29 classes 5 and 6): options that make no sense,
counts that would not fit in memory, a scheduler nothing listens at. Each case through the
common contract (:func:`misuse.assert_refused`): one line naming the option, file or key, exit
status 2, no traceback, nothing written.

The memory cases ask for far more than any machine has (10^12 runs, a grid of 10^12 points), so
that the code before the checks failed at once with NumPy's MemoryError instead of filling the
machine's memory; ``robofmu sweep --samples 1000000000`` is refused by the same check.
"""
from __future__ import annotations

import socket
import time

import pytest

from misuse import assert_refused

STUDY = "seed004_workspace.toml"


def closed_port() -> int:
    """A local TCP port nothing listens at (bound, then released)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


#: sweep: argv after the fixed part (experiment, --fmus, --out), and what the one line names.
SWEEP_OPTIONS = {
    "threshold-nan": (["--vary", "controller.kp=100,200", "--threshold", "nan"], ["--threshold", "nan"]),
    "threshold-inf": (["--vary", "controller.kp=100,200", "--threshold", "inf"], ["--threshold", "inf"]),
    "seed-negative": (["--vary", "controller.kp=uniform(100,200)", "--samples", "2", "--seed", "-1"],
                      ["--seed -1", ">= 0"]),
    "retry-failed-no-sweep": (["--vary", "controller.kp=100,200", "--retry-failed"],
                              ["--retry-failed", "no earlier run"]),
    "samples-memory": (["--vary", "controller.kp=uniform(100,200)", "--samples", str(10 ** 12)],
                       [f"--samples {10 ** 12}", "memory", "available"]),
    "range-memory": (["--vary", f"controller.kp=1:2:{10 ** 12}"],
                     [f"--vary controller.kp=1:2:{10 ** 12}", "memory", "available"]),
    "workers-memory": (["--vary", "controller.kp=100,200", "--workers", "100000"], ["--workers 100000", "memory"]),
    "grid-memory": (["--vary", "controller.kp=1:2:100000", "--vary", "controller.kd=1:2:100000"],
                    ["--vary controller.kp (100000 values) x --vary controller.kd (100000 values)", "10000000000 runs",
                     "memory"]),
}


@pytest.mark.parametrize("case", SWEEP_OPTIONS)
def test_sweep_refuses(capfd, tmp_path, fmu_root, case):
    extra, names = SWEEP_OPTIONS[case]
    out = tmp_path / "sweep"
    assert_refused(capfd, ["sweep", "rrp-line", "--fmus", fmu_root, "--out", out, "--stop-time", "0.1", *extra],
                   *names, folders=[tmp_path])
    assert not out.exists()


def test_sweep_refuses_a_closed_scheduler_port_at_once(capfd, tmp_path, fmu_root):
    """A refused TCP connection is known in microseconds: the sweep says so before Dask's 10 s
    connect timeout (the whole command, its imports and checks included, well under it)."""
    address = f"tcp://127.0.0.1:{closed_port()}"
    start = time.perf_counter()
    assert_refused(capfd, ["sweep", "rrp-line", "--vary", "controller.kp=100,200", "--stop-time", "0.1",
                           "--fmus", fmu_root, "--out", tmp_path / "sweep", "--scheduler", address],
                   f"--scheduler {address}", "refused", folders=[tmp_path])
    assert time.perf_counter() - start < 5.0
    assert not (tmp_path / "sweep").exists()


#: step: argv after --fmus, and what the one line names.
STEP_OPTIONS = {
    "step-above-stop": (["--robot", "rrp", "--step-size", "2", "--stop-time", "1"],
                        ["--step-size 2 s", "--stop-time 1 s", "longer than the run"]),
    "stop-not-whole": (["--robot", "rrp", "--step-size", "0.6", "--stop-time", "1"],
                       ["--step-size 0.6 s", "--stop-time 1 s", "whole number of steps"]),
    "amplitude-huge-limited": (["--robot", "rrp", "--amplitude", "1e300"],
                               ["--amplitude", "joint 1", "upper limit 3.14159"]),
    # rrp's joint 3 (a slider) starts at its upper limit 0.125 m: a step up passes it
    "amplitude-past-limit": (["--robot", "rrp", "--joint", "3", "--amplitude", "0.01"],
                             ["--amplitude", "joint 3", "upper limit 0.125 m", "from -0.125 to 0 m"]),
    "amplitude-huge-unlimited": (["--robot", "3rrp", "--amplitude", "1e300"],
                                 ["--amplitude", "joint 1", "6.28319 rad", "without position limits"]),
    "q0-outside-limits": (["--robot", "rrp", "--q0", "4", "0", "0.1"], ["--q0", "joint 1", "outside its limits"]),
    "memory": (["--robot", "rrp", "--step-size", "1e-9", "--stop-time", "1000"],
               ["--step-size 1e-09 s", "--stop-time 1000 s", "memory", "available"]),
}


@pytest.mark.parametrize("case", STEP_OPTIONS)
def test_step_refuses(capfd, tmp_path, fmu_root, case):
    extra, names = STEP_OPTIONS[case]
    assert_refused(capfd, ["step", "--fmus", fmu_root, "--out", tmp_path / "step", *extra], *names,
                   folders=[tmp_path])
    assert not (tmp_path / "step").exists()


@pytest.mark.parametrize("key, line, value", [
    ("joint", "joint = [25, 50, 100, 200]", "[25, 1000000]"),
    ("positions", "positions = 161", "1000000"),
    ("region", "region = [41, 72, 72]", "[10000, 10000, 10000]"),
])
def test_workspace_refuses_a_grid_beyond_memory(capfd, tmp_path, key, line, value):
    """A study whose grid would not fit is refused when it is read, naming the file and the key,
    before the first ray is cast."""
    from robofmu.system.studies.tables import STUDIES_DIR

    text = (STUDIES_DIR / STUDY).read_text()
    assert line in text
    study = tmp_path / "huge.toml"
    study.write_text(text.replace(line, f"{key} = {value}"))
    assert_refused(capfd, ["workspace", study, "--out", tmp_path / "ws"], str(study), f"grids.{key} = {value}",
                   "memory", untouched=[study], folders=[tmp_path])
    assert not (tmp_path / "ws").exists()

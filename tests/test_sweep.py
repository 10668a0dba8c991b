"""``robofmu sweep`` end to end: rows equal single runs bit for bit, failures recorded, resumed
sweeps, an existing Dask cluster, a worker killed mid-sweep, Ctrl-C, and mistakes in one line.

The sweeps run in subprocesses (``python -m robofmu.system.cli``), as a user runs them, on a
short run of the spherical arm's straight line (1 s). The Dask cluster of ``--scheduler`` is a
scheduler and two workers this module starts on 127.0.0.1 and stops.
"""
from __future__ import annotations

import csv
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from robofmu.system import analysis, experiment
from robofmu.system.result import Result
from robofmu.system.roles import Roles
from robofmu.system.sweep.journal import cell
from robofmu.system.sweep.metrics import metrics_of

CLI = [sys.executable, "-m", "robofmu.system.cli"]
EXPERIMENT, STOP = "rrp-line", "1"
GRID = ["--vary", "controller.kp=-1,100,400", "--vary", "controller.kd=20,40"]
#: controller.kp = -1 is refused by the controller (kp > 0: the gains' rule, components/control.py):
#: those two runs fail.
GRID_RUNS = [(kp, kd) for kp in (-1.0, 100.0, 400.0) for kd in (20.0, 40.0)]


def cli(*args, cwd, timeout=600) -> subprocess.CompletedProcess:
    return subprocess.run([*CLI, *map(str, args)], cwd=cwd, capture_output=True, text=True, timeout=timeout)


def start(*args, cwd) -> subprocess.Popen:
    """A sweep in its own process group (as a terminal runs it: Ctrl-C reaches every process)."""
    return subprocess.Popen([*CLI, *map(str, args)], cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)


def rows(folder: Path) -> list[dict]:
    with (folder / "sweep.csv").open(newline="") as f:
        return list(csv.DictReader(f))


def wait_for_rows(folder: Path, count: int, process: subprocess.Popen, timeout: float = 120) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if (folder / "sweep.csv").is_file() and len(rows(folder)) >= count:
            return
        assert process.poll() is None, process.communicate()
        time.sleep(0.05)
    raise AssertionError(f"no {count} rows in {folder} after {timeout} s")


@pytest.fixture(scope="module")
def grid(fmu_root, tmp_path_factory):
    """The 3 x 2 grid on a local cluster of 2 workers, each run's results kept."""
    work = tmp_path_factory.mktemp("sweep")
    out = work / "grid"
    done = cli("sweep", EXPERIMENT, *GRID, "--stop-time", STOP, "--workers", 2, "--fmus", fmu_root, "--out", out,
               "--keep-results", cwd=work)
    assert done.returncode == 0, done.stderr
    return work, out, done


def test_grid_rows_and_failures(grid):
    work, out, done = grid
    table = rows(out)
    assert [(float(r["controller.kp"]), float(r["controller.kd"])) for r in table] == GRID_RUNS
    header = list(table[0])
    assert header[:2] == ["controller.kp", "controller.kd"] and header[-2:] == ["status", "message"]
    assert {"max_tcp_error", "max_joint_error", "peak_effort"} <= set(header)
    failed = [r for r in table if r["status"] == "failed"]
    assert [float(r["controller.kp"]) for r in failed] == [-1.0, -1.0]
    for r in failed:                          # the block, the parameter and the rule, on one line
        assert "controller" in r["message"] and "kp = -1" in r["message"] and "must be > 0" in r["message"]
        assert r["max_tcp_error"] == ""
    ok = [r for r in table if r["status"] == "ok"]
    assert len(ok) == 4 and all(0.0 < float(r["max_tcp_error"]) < 1e-3 for r in ok)
    # more gain, less error, on the same kd
    by = {(float(r["controller.kp"]), float(r["controller.kd"])): float(r["max_tcp_error"]) for r in ok}
    assert by[400.0, 20.0] < by[100.0, 20.0] and by[400.0, 40.0] < by[100.0, 40.0]
    assert "6 runs (6 now, 0 reused), 2 failed" in done.stdout
    report = (out / "report.md").read_text()
    assert "kp = -1" in report and (out / "heatmap.png").stat().st_size > 10_000


def test_parquet_holds_the_same_table(grid):
    import pyarrow.parquet as pq

    _, out, _ = grid
    table = pq.read_table(out / "sweep.parquet").to_pydict()
    for k, row in enumerate(rows(out)):
        for column, text in row.items():
            value = table[column][k]
            if column in ("status", "message"):
                assert value == text
            elif text:
                assert value == float(text)          # exact: the CSV holds repr of the float
            else:
                assert np.isnan(value)


@pytest.mark.parametrize("kp, kd", [(100.0, 40.0), (400.0, 20.0)])
def test_rows_equal_single_runs_bit_for_bit(grid, fmu_root, kp, kd):
    """`robofmu run --set` with a row's values writes the same results.csv byte for byte, and its
    analysis gives the row's metrics exactly."""
    work, out, _ = grid
    index = GRID_RUNS.index((kp, kd))
    single = work / f"single-{index}"
    done = cli("run", EXPERIMENT, "--set", f"controller.kp={kp:g}", "--set", f"controller.kd={kd:g}",
               "--stop-time", STOP, "--fmus", fmu_root, "--out", single, cwd=work)
    assert done.returncode == 0, done.stderr
    kept = out / "runs" / f"run-{index:05d}" / "results.csv"
    assert kept.read_bytes() == (single / "results.csv").read_bytes()
    system = experiment.load(EXPERIMENT)
    roles = Roles.of(system)
    result = Result.from_csv(single / "results.csv")
    expected = metrics_of(analysis.tracking_metrics(result, roles), result, roles)
    row = rows(out)[index]
    assert {name: row[name] for name in expected} == {name: cell(value) for name, value in expected.items()}


def test_a_rerun_skips_finished_runs_and_redoes_missing_ones(grid, fmu_root):
    work, out, _ = grid
    resumed = work / "resumed"
    shutil.copytree(out, resumed, ignore=shutil.ignore_patterns("runs"))
    table = rows(resumed)
    with (resumed / "sweep.csv").open("w", newline="") as f:   # two ok runs lost, a line cut short
        writer = csv.DictWriter(f, fieldnames=list(table[0]))
        writer.writeheader()
        writer.writerows(table[:3] + table[4:5])
        f.write(",".join(list(table[5].values())[:5]))
    done = cli("sweep", EXPERIMENT, *GRID, "--stop-time", STOP, "--workers", 2, "--fmus", fmu_root, "--out", resumed,
               cwd=work)
    assert done.returncode == 0, done.stderr
    assert "6 runs (2 now, 4 reused), 2 failed" in done.stdout
    again = rows(resumed)
    original = rows(out)
    for a, b in zip(again, original):          # the runs done again give the same rows exactly
        assert {k: v for k, v in a.items() if k != "wall_time"} == {k: v for k, v in b.items() if k != "wall_time"}
    same = cli("sweep", EXPERIMENT, *GRID, "--stop-time", STOP, "--fmus", fmu_root, "--out", resumed, cwd=work)
    assert "6 runs (0 now, 6 reused)" in same.stdout
    other = cli("sweep", EXPERIMENT, "--vary", "controller.kp=100,200", "--stop-time", STOP, "--fmus", fmu_root,
                "--out", resumed, cwd=work)
    assert other.returncode == 2 and other.stderr.count("\n") == 1
    assert "holds another sweep" in other.stderr and "Traceback" not in other.stderr


@pytest.fixture
def dask_cluster(tmp_path):
    """A scheduler and two single-threaded workers on 127.0.0.1, stopped afterwards."""
    from distributed import Client

    scheduler_file = tmp_path / "scheduler.json"
    env = dict(os.environ, DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED="False")
    processes = [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                                   "--port", "0", "--no-dashboard", "--scheduler-file", str(scheduler_file)],
                                  cwd=tmp_path, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        deadline = time.monotonic() + 60
        while not scheduler_file.is_file() and time.monotonic() < deadline:
            time.sleep(0.1)
        for _ in range(2):
            processes.append(subprocess.Popen(
                [sys.executable, "-m", "distributed.cli.dask_worker", "--scheduler-file", str(scheduler_file),
                 "--nthreads", "1", "--nworkers", "1", "--no-dashboard", "--host", "127.0.0.1",
                 "--preload", "robofmu.system.sweep.worker"],
                cwd=tmp_path, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        with Client(scheduler_file=str(scheduler_file), timeout=60) as client:
            client.wait_for_workers(2, timeout=120)
            address = client.scheduler.address
            assert address.startswith("tcp://127.0.0.1:")
        yield address
    finally:
        for p in reversed(processes):
            p.terminate()
        for p in processes:
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()


def test_the_same_sweep_on_an_existing_cluster(grid, fmu_root, dask_cluster):
    work, out, _ = grid
    there = work / "on-cluster"
    done = cli("sweep", EXPERIMENT, "--vary", "controller.kp=100,400", "--vary", "controller.kd=40",
               "--stop-time", STOP, "--fmus", fmu_root, "--out", there, "--scheduler", dask_cluster, cwd=work)
    assert done.returncode == 0, done.stderr
    assert f"the cluster at {dask_cluster}" in done.stderr
    local = {(r["controller.kp"], r["controller.kd"]): r for r in rows(out)}
    remote = rows(there)
    assert len(remote) == 2
    for r in remote:
        twin = local[r["controller.kp"], r["controller.kd"]]
        assert {k: v for k, v in r.items() if k != "wall_time"} == {k: v for k, v in twin.items() if k != "wall_time"}
    assert "an existing Dask cluster" in (there / "report.md").read_text()


def _worker_processes(pid: int) -> list:
    import psutil

    return [p for p in psutil.Process(pid).children(recursive=True)
            if any("spawn_main" in part for part in p.cmdline())]


def test_a_killed_worker_loses_no_row(grid, fmu_root):
    work, out, _ = grid
    folder = work / "killed"
    sweep = start("sweep", EXPERIMENT, "--vary", "controller.kp=100,200,300,400", "--vary", "controller.kd=20,40",
                  "--stop-time", STOP, "--workers", 2, "--fmus", fmu_root, "--out", folder, cwd=work)
    try:
        wait_for_rows(folder, 1, sweep)
        workers = _worker_processes(sweep.pid)
        assert len(workers) == 2
        workers[0].kill()                     # SIGKILL, mid-run: both workers are busy
        stdout, stderr = sweep.communicate(timeout=300)
    finally:
        if sweep.poll() is None:
            os.killpg(sweep.pid, signal.SIGKILL)
    assert sweep.returncode == 0, stderr
    table = rows(folder)
    assert len(table) == 8 and all(r["status"] == "ok" for r in table), [r["message"] for r in table]
    local = {(r["controller.kp"], r["controller.kd"]): r for r in rows(out)}
    for r in table:
        twin = local.get((r["controller.kp"], r["controller.kd"]))
        if twin is not None:
            assert r["max_tcp_error"] == twin["max_tcp_error"]


def test_ctrl_c_keeps_every_finished_row(grid, fmu_root):
    work, _, _ = grid
    folder = work / "interrupted"
    runs = 24                 # enough that Ctrl-C after the first row lands mid-sweep, however fast a run
    args = ["sweep", EXPERIMENT, "--vary", "controller.kp=100:400:12", "--vary", "controller.kd=20,40",
            "--stop-time", STOP, "--workers", 2, "--fmus", fmu_root, "--out", folder]
    sweep = start(*args, cwd=work)
    try:
        wait_for_rows(folder, 1, sweep)
        os.killpg(sweep.pid, signal.SIGINT)   # as a terminal sends Ctrl-C: to every process of the group
        stdout, stderr = sweep.communicate(timeout=120)
    finally:
        if sweep.poll() is None:
            os.killpg(sweep.pid, signal.SIGKILL)
    assert sweep.returncode == 130, stderr
    assert "Traceback" not in stderr
    kept = rows(folder)
    assert 1 <= len(kept) < runs and all(r["status"] == "ok" for r in kept)
    assert f"interrupted: {len(kept)} of {runs} runs are in" in stderr.splitlines()[-1]
    assert (folder / "sweep.parquet").is_file() and "interrupted" in (folder / "report.md").read_text()
    done = cli(*args, cwd=work)
    assert done.returncode == 0, done.stderr
    assert f"{runs} runs ({runs - len(kept)} now, {len(kept)} reused), 0 failed" in done.stdout
    assert len(rows(folder)) == runs


@pytest.mark.parametrize("args, expected", [
    (["--vary", "controller.kq=1,2"], "unknown parameter 'kq'"),
    (["--vary", "regulator.kp=1,2"], "--vary regulator.kp: no block 'regulator'"),
    (["--vary", "controller.kp=1:2"], "a range is START:STOP:COUNT"),
    (["--vary", "controller.kp=1,x"], "'x' is no number"),
    (["--vary", "controller.kp=uniform(1,2)"], "a distribution needs --samples N"),
    (["--vary", "controller.kp=normal(1,-2)", "--samples", "3"], "normal(MEAN,STD): STD > 0"),
    (["--vary", "controller.kp=1,2", "--samples", "3"], "--samples 3: no --vary is a distribution"),
    (["--vary", "controller.kp=1,2", "--workers", "0"], "--workers 0: must be at least 1"),
    (["--vary", "step_size=0.0007"], "--vary step_size=0.0007"),
    (["--vary", "controller.kp=1,2", "--metric", "speed"], "--metric speed"),
    (["--vary", "controller.kp=1,2", "--scheduler", "tcp://127.0.0.1:9"], "--scheduler tcp://127.0.0.1:9: cannot connect"),
])
def test_mistakes_are_one_line(fmu_root, tmp_path, args, expected):
    done = cli("sweep", EXPERIMENT, *args, "--fmus", fmu_root, "--out", tmp_path / "out", cwd=tmp_path, timeout=120)
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert done.stderr.count("\n") == 1 and done.stderr.startswith("robofmu sweep: "), done.stderr
    assert expected in done.stderr
    assert not (tmp_path / "out").exists()


def test_a_folder_with_other_files_is_refused(fmu_root, tmp_path):
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "thesis.tex").write_text("mine")
    done = cli("sweep", EXPERIMENT, "--vary", "controller.kp=1,2", "--fmus", fmu_root, "--out", tmp_path / "out",
               cwd=tmp_path)
    assert done.returncode == 2 and "thesis.tex" in done.stderr and "not a robofmu sweep" in done.stderr
    assert (tmp_path / "out" / "thesis.tex").read_text() == "mine"


def test_run_set_refuses_a_bad_setting(fmu_root, tmp_path):
    done = cli("run", EXPERIMENT, "--set", "controller.kp", "--fmus", fmu_root, "--out", tmp_path / "o", cwd=tmp_path)
    assert done.returncode == 2 and "--set controller.kp: expected BLOCK.PARAM=VALUE" in done.stderr
    done = cli("run", EXPERIMENT, "--set", "nothing.kp=3", "--fmus", fmu_root, "--out", tmp_path / "o", cwd=tmp_path)
    assert done.returncode == 2 and "--set nothing.kp: no block 'nothing'" in done.stderr


def test_random_samples_crossed_with_steps(grid, fmu_root):
    """Random sampling (reproducible: the values are numpy's draws for the seed) crossed with a
    varied communication step; histograms and scatter plots for random designs."""
    work, _, _ = grid
    folder = work / "random"
    done = cli("sweep", EXPERIMENT, "--vary", "step_size=0.001,0.002", "--vary", "controller.kp=uniform(100,400)",
               "--samples", 2, "--seed", 3, "--stop-time", STOP, "--workers", 2, "--fmus", fmu_root, "--out", folder,
               cwd=work)
    assert done.returncode == 0, done.stderr
    table = rows(folder)
    draws = np.random.default_rng(3).uniform(100, 400, 2)
    assert [(float(r["step_size"]), float(r["controller.kp"])) for r in table] == \
        [(h, kp) for h in (0.001, 0.002) for kp in draws]
    assert all(r["status"] == "ok" for r in table)
    # the same gains at a coarser step: a larger tracking error
    assert float(table[2]["max_tcp_error"]) > float(table[0]["max_tcp_error"])
    assert (folder / "histograms.png").is_file() and (folder / "scatter.png").is_file()

"""Result files: Parquet beside CSV, both exact; ``robofmu run --format parquet``."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from robofmu.system.result import Result

CLI = [sys.executable, "-m", "robofmu.system.cli"]


def test_parquet_round_trip_is_exact_with_units_and_info(tmp_path, rng):
    data = rng.normal(size=(501, 7)) * np.logspace(-300, 300, 7)        # extreme magnitudes too
    result = Result(np.arange(501) * 1e-3, [f"plant.q[{k}]" for k in range(1, 8)], data,
                    {"step": 1e-3, "algorithm": "gauss-seidel", "failed": False}, {"plant.q[1]": "rad"})
    back = Result.read(result.write(tmp_path / "r.parquet"))
    assert back.columns == result.columns and back.units == result.units and back.info == result.info
    assert np.array_equal(back.time, result.time) and np.array_equal(back.data, result.data)
    csv = Result.read(result.write(tmp_path / "r.csv"))
    assert np.array_equal(csv.data, back.data)
    with pytest.raises(ValueError, match=r"\.csv or \.parquet"):
        result.write(tmp_path / "r.txt")


@pytest.mark.slow
def test_run_writes_parquet_equal_to_its_csv(fmu_root, tmp_path):
    runs = {}
    for kind in ("csv", "parquet"):
        done = subprocess.run([*CLI, "run", "rpp-bangbang", "--stop", "0.5", "--fmus", str(fmu_root), "--format", kind,
                               "--out", str(tmp_path / kind)], cwd=tmp_path, capture_output=True, text=True,
                              timeout=300)
        assert done.returncode == 0, done.stderr
        assert sorted(p.name for p in (tmp_path / kind).glob("results.*")) == [f"results.{kind}"]
        runs[kind] = Result.read(tmp_path / kind / f"results.{kind}")
    assert runs["csv"].columns == runs["parquet"].columns
    assert np.array_equal(runs["csv"].data, runs["parquet"].data)
    assert runs["parquet"].units["plant.q[1]"] == "rad" and runs["parquet"].units["plant.q[2]"] == "m"
    assert runs["parquet"].info["step"] == 0.001
    # the folder of a parquet run is a run's folder: a csv run may replace it
    again = subprocess.run([*CLI, "run", "rpp-bangbang", "--stop", "0.5", "--fmus", str(fmu_root),
                            "--out", str(tmp_path / "parquet")], cwd=tmp_path, capture_output=True, text=True,
                           timeout=300)
    assert again.returncode == 0, again.stderr
    assert not (tmp_path / "parquet" / "results.parquet").exists()

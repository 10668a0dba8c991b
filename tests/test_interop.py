"""The demo's table of other FMI tools (robofmu.system.interop.compare): what each row measures."""
from __future__ import annotations

import importlib.util
import math


from robofmu.system import experiment
from robofmu.system.interop.compare import compare_tools


def test_every_tool_against_the_master(fmu_root, tmp_path):
    runs = compare_tools(experiment.load("rpp-bangbang", fmu_dir=fmu_root), 0.2, tmp_path)
    assert [(r.tool, r.algorithm, r.compared) for r in runs] == [
        ("container (fmpy)", "gauss-seidel", "every output"), ("container (fmpy)", "jacobi", "every output"),
        ("libcosim", "jacobi", "plant.q"), ("ecos", "jacobi", "plant.q")]
    assert runs[0].difference == 0.0 and runs[1].difference == 0.0        # bit for bit
    assert 0.0 <= runs[2].difference < 1e-12 and 0.0 <= runs[3].difference < 1e-12
    assert all(r.seconds > 0 and not r.note for r in runs)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rpp-bangbang-gauss-seidel.fmu", "rpp-bangbang-jacobi.fmu",
                                                          "rpp-bangbang.ssp"]


def test_a_tool_not_installed_is_a_note_not_a_failure(fmu_root, tmp_path, monkeypatch):
    find_spec = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *args: None if name in ("libcosimpy", "ecospy") else find_spec(name, *args))
    runs = compare_tools(experiment.load("rpp-bangbang", fmu_dir=fmu_root), 0.05, tmp_path)
    assert [r.note for r in runs[2:]] == ["libcosimpy is not installed (dev extra)", "ecospy is not installed (dev extra)"]
    assert all(math.isnan(r.difference) for r in runs[2:]) and runs[0].difference == 0.0

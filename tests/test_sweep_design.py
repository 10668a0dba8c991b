"""What a sweep runs (no co-simulation): VALUES, grids, reproducible random samples, the
journal's rows, and the settling time against a closed form."""
from __future__ import annotations

import math

import numpy as np
import pytest

from robofmu.system.analysis import settling_time
from robofmu.system.options import parse_setting
from robofmu.system.sweep.design import STEP_SIZE_AXIS, Design, DesignError, parse_axis
from robofmu.system.sweep.journal import Journal, cell, key_of


def test_values_lists_ranges_and_distributions():
    assert parse_axis("controller.kp=200,400,800").values == (200.0, 400.0, 800.0)
    assert parse_axis("plant.payload_mass=0:0.3:4").values == tuple(np.linspace(0.0, 0.3, 4))
    assert parse_axis("step_size=0.001,0.002").name == STEP_SIZE_AXIS == "step_size"
    assert parse_axis("controller.kp=uniform(100, 400)").distribution == ("uniform", 100.0, 400.0)
    assert parse_axis("plant.payload_mass=normal(0.03,1e-2)").distribution == ("normal", 0.03, 0.01)
    assert parse_axis("ik.flag=true,false").values == (True, False)


@pytest.mark.parametrize("text, expected", [
    ("controller.kp", "expected BLOCK.PARAM=VALUES"),
    ("kp=1,2", "is not BLOCK.PARAM"),
    ("controller.kp=1,1", "a value is given twice"),
    ("controller.kp=1:2:1", "COUNT >= 2"),
    ("controller.kp=gamma(1,2)", "unknown distribution"),
    ("controller.kp=uniform(2,1)", "LOW < HIGH"),
    ("controller.kp=1,inf", "not a finite number"),
])
def test_bad_values_name_the_option(text, expected):
    with pytest.raises(DesignError, match=r"^--vary ") as error:
        parse_axis(text)
    assert expected in str(error.value)


def test_grid_is_the_product_in_order():
    design = Design("e", [parse_axis("a.x=1,2"), parse_axis("b.y=10,20,30")])
    assert [(r["a.x"], r["b.y"]) for r in design.runs()] == [(1, 10), (1, 20), (1, 30), (2, 10), (2, 20), (2, 30)]


def test_random_samples_are_reproducible_and_crossed_with_the_grid():
    axes = [parse_axis("a.x=1,2"), parse_axis("b.y=uniform(0,0.1)"), parse_axis("c.z=normal(5,2)")]
    runs = Design("e", axes, samples=3, seed=7).runs()
    rng = np.random.default_rng(7)
    y, z = rng.uniform(0, 0.1, 3), rng.normal(5, 2, 3)        # drawn axis after axis
    assert [r["a.x"] for r in runs] == [1, 1, 1, 2, 2, 2]
    assert [r["b.y"] for r in runs] == list(y) * 2 and [r["c.z"] for r in runs] == list(z) * 2
    assert Design("e", axes, samples=3, seed=7).runs() == runs
    assert Design("e", axes, samples=3, seed=8).runs() != runs


def test_a_design_survives_its_json():
    design = Design("e", [parse_axis("a.x=1,2"), parse_axis("b.y=uniform(0,0.1)")], samples=4, seed=3,
                    stop_time=2.0)
    again = Design.from_json(design.to_json())
    assert again.same_as(design) and again.runs() == design.runs()
    assert not Design("e", [parse_axis("a.x=1,3"), parse_axis("b.y=uniform(0,0.1)")], samples=4, seed=3,
                      stop_time=2.0).same_as(design)


def test_design_mistakes():
    with pytest.raises(DesignError, match="varied twice"):
        Design("e", [parse_axis("a.x=1"), parse_axis("a.x=2")])
    with pytest.raises(DesignError, match="--step-size: the step is varied"):
        Design("e", [parse_axis("step_size=0.001")], step=0.002)
    assert parse_setting("controller.kp=400") == ("controller.kp", 400.0)
    with pytest.raises(ValueError, match="--set controller.kp=x"):
        parse_setting("controller.kp=x")


def test_the_old_step_axis_name_still_works_with_a_warning(capsys):
    axis = parse_axis("step=0.001,0.002")
    assert axis == parse_axis("step_size=0.001,0.002") and axis.name == "step_size"
    warnings = capsys.readouterr().err.splitlines()
    assert warnings == ["robofmu sweep: --vary step=... is deprecated; use step_size=..."]


def test_an_earlier_sweep_with_the_old_step_axis_name_is_continued(tmp_path):
    """sweep.json and sweep.csv written when the axis was named ``step`` are read as step_size."""
    design = Design("e", [parse_axis("step_size=0.001,0.002"), parse_axis("a.x=1,2")], stop_time=1.0)
    earlier = design.to_json().replace('"name": "step_size"', '"name": "step"')
    assert '"name": "step"' in earlier
    again = Design.from_json(earlier)
    assert again.same_as(design) and again.names == ["step_size", "a.x"]
    (tmp_path / "sweep.csv").write_text("step,a.x,m,wall_time,status,message\n0.001,1.0,0.5,1.0,ok,\n")
    journal = Journal(tmp_path, design.names, ["m"])
    assert list(journal.rows) == [key_of({"step_size": 0.001, "a.x": 1.0}, design.names)]
    assert (tmp_path / "sweep.csv").read_text().splitlines()[0] == "step_size,a.x,m,wall_time,status,message"


def test_journal_appends_reads_back_and_drops_a_cut_line(tmp_path):
    journal = Journal(tmp_path, ["a.x"], ["m"])
    journal.append({"a.x": 0.1, "m": 1 / 3, "wall_time": 1.0, "status": "ok", "message": ""})
    journal.append({"a.x": 0.2, "wall_time": 1.0, "status": "failed", "message": "block b, at t = 1 s"})
    journal.close()
    with (tmp_path / "sweep.csv").open("a") as f:
        f.write("0.3,0.5")                              # a crash mid-line
    again = Journal(tmp_path, ["a.x"], ["m"])
    assert list(again.rows) == [key_of({"a.x": 0.1}, ["a.x"]), key_of({"a.x": 0.2}, ["a.x"])]
    assert float(again.rows[(cell(0.1),)]["m"]) == 1 / 3                       # exactly
    assert again.rows[(cell(0.2),)]["m"] == "" and "at t = 1 s" in again.rows[(cell(0.2),)]["message"]
    assert again.forget_failed() == 1 and len(again.rows) == 1
    with pytest.raises(ValueError, match="not this sweep's"):
        Journal(tmp_path, ["a.y"], ["m"])


def test_settling_time_of_an_exponential_error():
    """The reference steps to 1 at t = 1 s and rests; q approaches it as 1 - exp(-(t - 1) / T):
    the error enters the 2 % band at t - 1 = T ln 50."""
    t = np.arange(0.0, 10.0 + 1e-12, 1e-4)
    q_ref = np.where(t < 1.0, 0.0, 1.0)[:, None]
    q = np.where(t < 1.0, 0.0, 1.0 - np.exp(-(t - 1.0) / 0.5))[:, None]
    assert settling_time(t, q_ref, q) == pytest.approx(0.5 * math.log(50.0), abs=2e-4)
    assert settling_time(t, q_ref, q, band=0.05) == pytest.approx(0.5 * math.log(20.0), abs=2e-4)
    assert math.isnan(settling_time(t[:12000], q_ref[:12000], q[:12000]))      # not settled at the end
    assert math.isnan(settling_time(t, np.sin(t)[:, None], q))                  # the reference never rests
    assert math.isnan(settling_time(t, np.zeros_like(q), q))                    # nothing moves
    assert settling_time(t, q_ref, q_ref) == 0.0


def test_parquet_follows_the_rows_as_they_arrive(tmp_path, monkeypatch):
    import pyarrow.parquet as pq

    from robofmu.system.sweep import journal as module

    monkeypatch.setattr(module, "PARQUET_EVERY", 0.0)          # rewrite at every row
    journal = Journal(tmp_path, ["a.x"], ["m"])
    for k in range(3):
        journal.append({"a.x": k / 10, "m": k / 3, "wall_time": 1.0, "status": "ok", "message": ""})
        table = pq.read_table(tmp_path / "sweep.parquet").to_pydict()
        assert table["a.x"] == [j / 10 for j in range(k + 1)] and table["m"] == [j / 3 for j in range(k + 1)]
    assert not (tmp_path / "sweep.parquet.tmp").exists()


def test_ctrl_c_during_the_fsync_keeps_the_row_already_visible(tmp_path, monkeypatch):
    """The line is flushed (a reader sees it) before the fsync returns; a Ctrl-C raised there must
    not let :meth:`Journal.finish`, which rewrites the file from memory, drop it."""
    from robofmu.system.sweep import journal as module

    journal = Journal(tmp_path, ["a.x"], ["m"])
    journal.append({"a.x": 0.1, "m": 1.0, "wall_time": 1.0, "status": "ok", "message": ""})

    def interrupted(_descriptor):
        raise KeyboardInterrupt

    monkeypatch.setattr(module.os, "fsync", interrupted)
    with pytest.raises(KeyboardInterrupt):
        journal.append({"a.x": 0.2, "m": 2.0, "wall_time": 1.0, "status": "ok", "message": ""})
    monkeypatch.undo()
    rows = journal.finish([(cell(0.1),), (cell(0.2),)])
    assert [r["m"] for r in rows] == [cell(1.0), cell(2.0)]
    with (tmp_path / "sweep.csv").open() as f:
        assert f.read().splitlines()[1:] == ["0.1,1.0,1.0,ok,", "0.2,2.0,1.0,ok,"]

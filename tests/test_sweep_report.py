"""The report and figures of a sweep, from synthetic rows (no FMU runs): the counts, the worst
runs, the threshold region, the failed runs and the figure each design gets."""
from __future__ import annotations

import math
import pytest

from robofmu.system.sweep.design import STEP_SIZE_AXIS, Axis, Design
from robofmu.system.sweep.figures import comparison_heatmaps, grid_of, sweep_figures
from robofmu.system.sweep.journal import cell
from robofmu.system.sweep.report import reproduce_command, write_report
from robofmu.system.sweep.result import SweepRun

METRICS = ["max_tcp_error", "max_joint_error", "peak_effort", "settling_time"]
UNITS = {"controller.kp": "N.m/rad", "controller.kd": "N.m.s/rad", "max_tcp_error": "m", "settling_time": "s"}
KP = (200.0, 400.0, 800.0, 1600.0)
KD = (10.0, 20.0, 40.0)
FAILED_AT = {"controller.kp": 200.0, "controller.kd": 40.0}
MESSAGE = "SimulationError: plant.q[2] is not finite at t = 0.42 s"


def tcp(values: dict) -> float:
    """The synthetic max_tcp_error (m): falls with kp, rises with kd; crosses 1 mm inside the grid."""
    return 0.4 / values["controller.kp"] * (1.0 + values["controller.kd"] / 20.0) * values.get("plant.scale", 1.0)


def row_of(values: dict, names: list[str], metrics: dict | None, message: str = "") -> dict:
    record = {n: cell(values[n]) for n in names}
    record.update({m: cell((metrics or {}).get(m)) for m in METRICS})
    record.update(wall_time=cell(0.5), status="ok" if metrics is not None else "failed", message=message)
    return record


def make_run(folder, design: Design, error, fail=None, name="tracking test", **kwargs) -> SweepRun:
    """A SweepRun of ``design`` whose max_tcp_error is ``error(values)``; ``fail(values)`` -> failed."""
    rows = []
    for values in design.runs():
        if fail is not None and fail(values):
            rows.append(row_of(values, design.names, None, MESSAGE))
            continue
        e = error(values)
        rows.append(row_of(values, design.names, {"max_tcp_error": e, "max_joint_error": 3.0 * e,
                                                  "peak_effort": 50.0 + 1e4 * e, "settling_time": math.nan}))
    folder.mkdir(parents=True, exist_ok=True)
    options = dict(ran=len(rows), reused=0, seconds=12.0, workers=4, units=dict(UNITS), name=name,
                   description="A synthetic sweep.")
    options.update(kwargs)
    return SweepRun(design, folder, rows, list(METRICS), **options)


def is_png(path) -> bool:
    return path.is_file() and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.stat().st_size > 5000


def table_after(text: str, heading: str) -> list[list[str]]:
    """The data rows of the first markdown table after ``heading`` (cells stripped)."""
    lines = text.split(heading, 1)[1].splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("|"))
    rows = []
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        rows.append([c.strip() for c in line.strip().strip("|").split("|")])
    return rows


def grid_design(**kwargs) -> Design:
    return Design("tracking", [Axis("controller.kp", KP), Axis("controller.kd", KD)], **kwargs)


def failed(values: dict) -> bool:
    return all(values[k] == v for k, v in FAILED_AT.items())


def test_grid_report_counts_worst_threshold_failed_and_rerun(tmp_path):
    design = grid_design(stop_time=2.0)
    run = make_run(tmp_path / "grid", design, tcp, failed)
    path = write_report(run)
    text = path.read_text()
    assert path == tmp_path / "grid" / "report.md"
    assert run.figures == [tmp_path / "grid" / "heatmap.png"] and is_png(run.figures[0])
    assert "![heatmap](heatmap.png)" in text
    assert text.startswith("# Sweep of tracking test\n\nA synthetic sweep.")
    assert "- runs: 12 of 12: 11 ok, 1 failed" in text
    assert "- reused from an earlier invocation: 0" in text
    assert "60 runs per minute" in text and "4 local worker processes" in text
    assert "`controller.kp: 200, 400, 800, 1600` (N.m/rad)" in text

    ok = [v for v in design.runs() if not failed(v)]
    worst = max(ok, key=tcp)
    first = table_after(text, "## The worst runs by max_tcp_error")[0]
    assert first[1:3] == [f"{worst['controller.kp']:.4g}", f"{worst['controller.kd']:.4g}"]
    assert float(first[3]) == pytest.approx(tcp(worst) * 1e3, rel=1e-3)          # shown in mm
    assert len(table_after(text, "## The worst runs by max_tcp_error")) == 5
    assert f"robofmu run tracking --set controller.kp={worst['controller.kp']:.0f} " \
           f"--set controller.kd={worst['controller.kd']:.0f} --stop-time 2" in text

    within = [v for v in ok if tcp(v) <= 1e-3]
    assert 0 < len(within) < len(ok)
    assert f"{len(within)} of 11 ok runs keep max_tcp_error within 1 mm." in text
    kps = [v["controller.kp"] for v in within]
    assert f"- `controller.kp`: {min(kps):.4g} to {max(kps):.4g} N.m/rad ({len(set(kps))} of 4 values)" in text

    failed_rows = table_after(text, "## Failed runs")
    assert failed_rows == [["2", "200", "40", MESSAGE]]          # run 2: kp first, kd fastest
    assert "--set controller.kp=200 --set controller.kd=40 --stop-time 2" in text


def test_grid_of_takes_the_worst_over_a_third_axis_and_marks_failed_cells(tmp_path):
    design = Design("tracking", [Axis("controller.kp", KP), Axis("controller.kd", KD), Axis("plant.scale", (0.5, 2.0))])
    run = make_run(tmp_path / "three", design, tcp, lambda v: failed(v) and v["plant.scale"] == 2.0)
    grid = grid_of(run, "max_tcp_error")
    assert grid.z.shape == (3, 4) and grid.others == ["plant.scale"]
    assert grid.failed.sum() == 1 and grid.failed[2, 0]
    expected = tcp({"controller.kp": 400.0, "controller.kd": 20.0, "plant.scale": 2.0}) * 1e3
    assert grid.z[1, 1] == pytest.approx(expected)
    assert sweep_figures(run, "max_tcp_error", 1e-3) == [tmp_path / "three" / "heatmap.png"]
    assert is_png(tmp_path / "three" / "heatmap.png")


def test_one_axis_gets_metric_against_parameter_and_rerun_with_step(tmp_path):
    design = Design("tracking", [Axis(STEP_SIZE_AXIS, (1e-3, 2e-3, 5e-3, 1e-2))])
    run = make_run(tmp_path / "step", design, lambda v: 0.2 * v[STEP_SIZE_AXIS], lambda v: v[STEP_SIZE_AXIS] == 1e-2,
                   units={**UNITS, STEP_SIZE_AXIS: "s"})
    text = write_report(run, threshold=5e-4).read_text()
    assert run.figures == [tmp_path / "step" / "metric_vs_parameter.png"] and is_png(run.figures[0])
    assert "2 of 3 ok runs keep max_tcp_error within 0.5 mm." in text
    assert "robofmu run tracking --step-size 0.005" in text               # the worst ok run
    assert "robofmu run tracking --step-size 0.01" in text                # the failed one
    assert "--set" not in text


def test_random_design_gets_histograms_and_scatter(tmp_path):
    design = Design("tracking", [Axis("controller.kp", (), ("uniform", 200.0, 1600.0)),
                                 Axis("controller.kd", (10.0, 40.0))], samples=15, seed=3)
    run = make_run(tmp_path / "random", design, tcp, lambda v: v["controller.kp"] < 500.0, workers=None)
    text = write_report(run).read_text()
    assert [p.name for p in run.figures] == ["histograms.png", "scatter.png"]
    assert all(is_png(p) for p in run.figures)
    assert "15 random samples drawn with seed 3, for each of the 2 combinations" in text
    assert "an existing Dask cluster" in text
    ok = [v for v in design.runs() if v["controller.kp"] >= 500.0]
    assert f"- runs: 30 of 30: {len(ok)} ok, {30 - len(ok)} failed" in text
    within = sum(tcp(v) <= 1e-3 for v in ok)
    assert f"{within} of {len(ok)} ok runs keep max_tcp_error within 1 mm." in text
    worst = max(ok, key=tcp)
    assert f"--set controller.kp={worst['controller.kp']!r} --set controller.kd=" in text   # exact value


def test_comparison_writes_one_figure(tmp_path):
    design = grid_design()
    pd = make_run(tmp_path / "pd", design, tcp, failed, name="PD")
    pid = make_run(tmp_path / "pid", design, lambda v: 0.5 * tcp(v), name="PID")
    path = comparison_heatmaps([("PD", pd), ("PID", pid)], "max_tcp_error", 1e-3, tmp_path / "compare.png")
    assert path == tmp_path / "compare.png" and is_png(path)
    plain = comparison_heatmaps([("PD", pd), ("PID", pid)], "max_tcp_error", None, tmp_path / "plain.png")
    assert is_png(plain)
    with pytest.raises(ValueError):
        one = make_run(tmp_path / "one", Design("tracking", [Axis("controller.kp", KP)]), lambda v: 1e-3)
        comparison_heatmaps([("PD", pd), ("one", one)], "max_tcp_error", 1e-3, tmp_path / "bad.png")


def test_interrupted_report_without_ok_rows_writes_no_figure(tmp_path):
    design = grid_design()
    run = make_run(tmp_path / "cut", design, tcp, lambda v: True)
    run.rows = run.rows[:3]
    text = write_report(run, interrupted=True).read_text()
    assert run.figures == [] and not list((tmp_path / "cut").glob("*.png"))
    assert "interrupted: 3 of 12 runs finished; run the same command again to finish" in text
    assert "- runs: 3 of 12: 0 ok, 3 failed" in text
    assert "## Figures" not in text and "## The worst runs" not in text


def test_failed_table_stops_at_twenty(tmp_path):
    design = Design("tracking", [Axis("controller.kp", tuple(float(k) for k in range(100, 2600, 100)))])
    run = make_run(tmp_path / "many", design, lambda v: 1.0 / v["controller.kp"], lambda v: True)
    text = write_report(run, figures=False).read_text()
    assert len(table_after(text, "## Failed runs")) == 20
    assert "and 5 more" in text
    assert reproduce_command(run, run.rows[0]) == "robofmu run tracking --set controller.kp=100"


def test_metric_default_without_task_error(tmp_path):
    design = grid_design()
    run = make_run(tmp_path / "joint", design, tcp)
    run.metrics = [m for m in METRICS if m != "max_tcp_error"]
    text = write_report(run).read_text()
    assert "## The worst runs by max_joint_error" in text
    assert "## Within the threshold" not in text                   # no default threshold
    worst = max(range(12), key=lambda k: tcp(design.runs()[k]))
    values = design.runs()[worst]
    first = table_after(text, "## The worst runs by max_joint_error")[0]
    assert first[:4] == [str(worst), f"{values['controller.kp']:g}", f"{values['controller.kd']:g}",
                         f"{3.0 * tcp(values):.4g}"]


def test_heatmap_says_when_the_threshold_is_not_crossed(tmp_path):
    run = make_run(tmp_path / "low", grid_design(), lambda v: 1e-5 * tcp(v))
    assert sweep_figures(run, "max_tcp_error", 1e-3) == [tmp_path / "low" / "heatmap.png"]
    text = write_report(run).read_text()
    assert "12 of 12 ok runs keep max_tcp_error within 1 mm." in text
    with pytest.raises(ValueError):
        write_report(run, metric="no_such_metric")

"""Sweep axes of the loop as it runs on the robot (issue 30): a block's ``sample_time``, the
controller's ``delay_steps`` and the joints' friction are varied like any parameter. Each sweep
row equals a single run made by hand on the experiment's System (the block's sample time and the
FMU parameters set directly, not through the sweep's override); an off-grid sample time is
refused naming the axis, in one line."""
from __future__ import annotations

import numpy as np
import pytest

from misuse import assert_refused
from robofmu.components.robots import load_model
from robofmu.system import analysis, experiment
from robofmu.system.master import Master
from robofmu.system.roles import Roles
from robofmu.system.run import run_experiment
from robofmu.system.sweep.design import Design, DesignError, parse_axis
from robofmu.system.sweep.run import check, run_sweep
from robofmu.system.sweep.worker import run_one

EXPERIMENT, STOP = "rrp-line", 0.5
N = load_model("rrp").n
#: The metrics compared with the single runs (settling_time: not reached in 0.5 s, empty).
COMPARED = ["max_tcp_error", "final_tcp_error", "max_joint_error", "peak_effort",
            *[f"{m}[{j}]" for j in range(1, N + 1) for m in ("max_joint_error", "rms_joint_error",
                                                              "final_joint_error", "peak_effort")]]


def by_hand(fmu_root, sample_time=None, friction=None, delay=None, stop=STOP, known=None):
    """A single run of the experiment with its settings put on the System directly (``known``:
    the friction the controller compensates)."""
    system = experiment.load(EXPERIMENT, fmu_dir=fmu_root)
    if sample_time is not None:
        system.block("controller").sample_time = sample_time
    if friction is not None:
        system.block("plant").parameters["friction"] = [friction] * N
    if known is not None:
        system.block("controller").parameters["friction"] = [known] * N
    if delay is not None:
        system.block("controller").parameters["delay_steps"] = delay
    result = Master(system).run(stop_time=stop)
    return result, analysis.tracking_metrics(result, Roles.of(system))


def expected(tracking) -> dict[str, float]:
    found = {"max_tcp_error": tracking.tcp_error.max(), "final_tcp_error": tracking.tcp_error[-1],
             "max_joint_error": tracking.max_error.max(), "peak_effort": tracking.peak_effort.max()}
    for j in range(N):
        found.update({f"max_joint_error[{j + 1}]": tracking.max_error[j],
                      f"rms_joint_error[{j + 1}]": tracking.rms_error[j],
                      f"final_joint_error[{j + 1}]": tracking.final_error[j],
                      f"peak_effort[{j + 1}]": tracking.peak_effort[j]})
    return found


@pytest.mark.slow
def test_sample_time_by_friction_rows_equal_single_runs(fmu_root, tmp_path):
    """A 2 x 2 sweep (controller at 1 and 4 ms x every joint's Coulomb friction 0 and 0.05) on a
    local Dask worker: each row's settings applied, its metrics those of the hand-made run."""
    design = Design(EXPERIMENT, [parse_axis("controller.sample_time=0.001,0.004"),
                                 parse_axis("plant.friction=0,0.05")], stop_time=STOP)
    run = run_sweep(design, tmp_path / "sweep", fmu_dir=fmu_root, workers=1, progress=False)
    assert [r["status"] for r in run.rows] == ["ok"] * 4, [r["message"] for r in run.rows]
    assert run.units["controller.sample_time"] == "s" and run.widths == {"plant.friction": N}
    worst = []
    for row in run.rows:
        sample_time, friction = float(row["controller.sample_time"]), float(row["plant.friction"])
        result, tracking = by_hand(fmu_root, sample_time, friction)
        assert result.info.get("sample_times", {}).get("controller", 0.001) == sample_time
        for name, value in expected(tracking).items():
            assert float(row[name]) == pytest.approx(value, abs=1e-12, rel=0), (row, name)
        worst.append(float(row["max_tcp_error"]))
    assert len(set(worst)) == 4                            # each setting changed the run
    assert worst[1] > 10 * worst[0] and worst[0] < worst[2]  # friction unknown to the PD; a slower controller
    report = (tmp_path / "sweep" / "report.md").read_text()
    assert "--set controller.sample_time=0.004" in report
    assert all(f"--set 'plant.friction[{j}]=0.05'" in report for j in range(1, N + 1))
    assert (tmp_path / "sweep" / "heatmap.png").is_file()


def test_delay_steps_is_an_integer_axis_and_its_row_is_the_single_run(fmu_root):
    design = Design(EXPERIMENT, [parse_axis("controller.delay_steps=0,1"),
                                 parse_axis("controller.sample_time=0.002")], stop_time=0.2)
    system, _, _, units, runs = check(design, fmu_root)
    assert [r["controller.delay_steps"] for r in runs] == [0, 1]
    assert all(type(r["controller.delay_steps"]) is int for r in runs) and units["controller.sample_time"] == "s"
    rows = [run_one(system, r, 0.2, None) for r in runs]
    assert [r["status"] for r in rows] == ["ok", "ok"], rows
    for delay, row in zip((0, 1), rows):
        _, tracking = by_hand(fmu_root, 0.002, delay=delay, stop=0.2)
        for name, value in expected(tracking).items():
            assert row[name] == pytest.approx(value, abs=1e-12, rel=0), (delay, name)
    assert rows[1]["max_tcp_error"] > rows[0]["max_tcp_error"]


def test_a_linked_axis_takes_its_leaders_value_and_adds_no_dimension(fmu_root):
    """``controller.friction=plant.friction``: friction known to the controller over the same grid;
    each row is the hand-made run with both set, and knowing the friction removes most of its error."""
    axes = [parse_axis("controller.sample_time=0.001,0.004"), parse_axis("plant.friction=0,0.05"),
            parse_axis("controller.friction=plant.friction")]
    design = Design(EXPERIMENT, axes, stop_time=0.2)
    assert [a.name for a in design.grid_axes] == ["controller.sample_time", "plant.friction"]
    assert axes[2].describe() == "controller.friction: as plant.friction"
    system, _, _, _, runs = check(design, fmu_root)
    assert [(r["controller.sample_time"], r["plant.friction"], r["controller.friction"]) for r in runs] == \
        [(0.001, 0, 0), (0.001, 0.05, 0.05), (0.004, 0, 0), (0.004, 0.05, 0.05)]
    assert Design.from_json(design.to_json()).same_as(design)
    rows = [run_one(system, r, 0.2, None) for r in runs]
    assert [r["status"] for r in rows] == ["ok"] * 4, rows
    for run, row in zip(runs, rows):
        _, tracking = by_hand(fmu_root, run["controller.sample_time"], run["plant.friction"], stop=0.2,
                              known=run["controller.friction"])
        for name, value in expected(tracking).items():
            assert row[name] == pytest.approx(value, abs=1e-12, rel=0), (run, name)
    _, unknown = by_hand(fmu_root, 0.001, 0.05, stop=0.2)
    assert rows[1]["max_tcp_error"] < 0.1 * unknown.tcp_error.max()


@pytest.mark.parametrize("texts, named", [
    (["controller.friction=plant.friction"], "--vary controller.friction=plant.friction"),
    (["plant.friction=0,1", "controller.friction=plant.damping"], "--vary controller.friction=plant.damping"),
    (["plant.friction=0,1", "controller.friction=plant.friction", "controller.damping=controller.friction"],
     "--vary controller.damping=controller.friction"),
])
def test_a_linked_axis_follows_a_varied_axis(texts, named):
    with pytest.raises(DesignError, match="a linked axis follows another --vary") as caught:
        Design(EXPERIMENT, [parse_axis(t) for t in texts])
    assert str(caught.value).startswith(named)


def test_run_set_sample_time_is_the_same_override(fmu_root, tmp_path):
    """``robofmu run --set controller.sample_time=0.004`` runs what the System with that sample
    time runs, bit for bit."""
    run = run_experiment(EXPERIMENT, tmp_path / "out", fmu_dir=fmu_root, stop_time=0.2, progress=False,
                         figures=False, parameters={"controller.sample_time": 0.004})
    result, _ = by_hand(fmu_root, 0.004, stop=0.2)
    assert run.result.info["sample_times"]["controller"] == 0.004
    for column in ("controller.tau[1]", "plant.q[3]"):
        assert np.array_equal(run.result[column], result[column]), column
    single, _ = by_hand(fmu_root, stop=0.2)
    assert not np.array_equal(single["controller.tau[1]"], result["controller.tau[1]"])


def test_run_set_of_one_number_for_a_vector_parameter_sets_every_element(fmu_root, tmp_path, capsys):
    """``run --set plant.friction=0.05`` (and ``step --set``) is every joint's friction, as the
    sweep's ``--vary plant.friction=0.05`` is: the run equals the System with the vector set."""
    run = run_experiment(EXPERIMENT, tmp_path / "out", fmu_dir=fmu_root, stop_time=0.2, progress=False,
                         figures=False, parameters={"plant.friction": 0.05})
    result, _ = by_hand(fmu_root, friction=0.05, stop=0.2)
    for column in ("controller.tau[1]", "plant.q[3]"):
        assert np.array_equal(run.result[column], result[column]), column
    configured = experiment.with_parameters(experiment.load(EXPERIMENT, fmu_dir=fmu_root),
                                            {"plant.friction": 0.05, "plant.friction_velocity": [0.01] * N})
    assert configured.block("plant").parameters["friction"] == [0.05] * N
    assert configured.block("plant").parameters["friction_velocity"] == [0.01] * N
    from robofmu.system.stepresponse import experiment as step_experiment
    stepped = step_experiment.cosimulate_step(fmu_root, 400.0, 40.0, robot="rrp", stop_time=0.05,
                                              parameters={"plant.friction": 0.5})
    assert stepped.info["unknown_friction"] == [0.5] * N          # the plant's alone
    assert step_experiment.cosimulate_step(fmu_root, 400.0, 40.0, robot="rrp", stop_time=0.05,
                                           parameters={"plant.friction": 0.5, "controller.friction": 0.5}
                                           ).info["unknown_friction"] == [0.0] * N     # known: compensated


@pytest.mark.parametrize("args, names", [
    (["sweep", EXPERIMENT, "--vary", "controller.sample_time=0.001,0.0025"],
     ["--vary controller.sample_time=0.0025", "block 'controller': sample_time = 0.0025 s is not a whole multiple "
                                              "of the base step 0.001 s"]),
    (["sweep", EXPERIMENT, "--vary", "controller.sample_time=0.003", "--step-size", "0.002", "--stop-time", "1"],
     ["--vary controller.sample_time=0.003", "base step 0.002 s"]),
    (["sweep", EXPERIMENT, "--vary", "controller.sample_time=0.001,0", "--vary", "controller.kp=400"],
     ["--vary controller.sample_time: must be a time in s > 0, got 0.0"]),
    (["sweep", EXPERIMENT, "--vary", "controller.sample_time=uniform(0.001,0.004)", "--samples", "2"],
     ["--vary controller.sample_time: a sample time is varied over a grid only"]),
    (["sweep", EXPERIMENT, "--vary", "plant.frictoin=0,1"],
     ["--vary plant.frictoin: unknown parameter 'frictoin' of block 'plant'"]),
    (["run", EXPERIMENT, "--set", "controller.sample_time=0.0025"],
     ["block 'controller': sample_time = 0.0025 s is not a whole multiple of the base step 0.001 s"]),
    (["run", EXPERIMENT, "--set", "controller.sample_time=-0.004"],
     ["--set controller.sample_time: must be a time in s > 0"]),
])
def test_a_sample_time_off_the_grid_is_refused_naming_the_axis(fmu_root, tmp_path, capfd, args, names):
    out = tmp_path / "out"
    assert_refused(capfd, [*args, "--fmus", fmu_root, "--out", out], *names)
    assert not out.exists()


@pytest.mark.slow
def test_workers_started_after_a_fmu_bundle_went_on_sys_path_know_the_robots(fmu_root, tmp_path):
    """pythonfmu puts a FMU's resources (a copy of robofmu/components without the robots) on this
    process's sys.path, and multiprocessing hands sys.path to the workers it starts: they imported
    robofmu from the copy and knew no robot (every row 'unknown robot', seen in the full suite)."""
    import shutil
    import sys
    from pathlib import Path

    import robofmu.components
    from robofmu.components.robots import available

    bundle = tmp_path / "resources"
    shutil.copytree(Path(robofmu.components.__file__).parent, bundle / "robofmu" / "components",
                    ignore=shutil.ignore_patterns(*available(), "__pycache__"))
    (bundle / "robofmu" / "__init__.py").write_text("")
    sys.path.insert(0, str(bundle))
    try:
        design = Design(EXPERIMENT, [parse_axis("controller.sample_time=0.001,0.004")], stop_time=STOP)
        run = run_sweep(design, tmp_path / "sweep", fmu_dir=fmu_root, workers=1, progress=False)
    finally:
        sys.path.remove(str(bundle))
    assert [r["status"] for r in run.rows] == ["ok"] * 2, [r["message"] for r in run.rows]

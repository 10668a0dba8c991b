"""A sweep run of one experiment of every robot, in-process (the worker's function, without
Dask): the record holds exactly the metric columns the sweep declares, finite where they apply,
and equals the analysis of the same run done by hand."""
from __future__ import annotations

import math

import pytest

from robofmu.components.robots import available
from robofmu.system import analysis, experiment
from robofmu.system.master import Master
from robofmu.system.roles import Roles
from robofmu.system.sweep.design import Design, parse_axis
from robofmu.system.sweep.metrics import metric_names, metrics_of
from robofmu.system.sweep.run import check
from robofmu.system.sweep.worker import run_one


def first_experiment(robot: str) -> str:
    names = [n for n in experiment.available() if experiment.load(n).extra.get("robot") == robot]
    assert names, f"no experiment of {robot}: every robot needs one (the sweep contract runs it)"
    return names[0]


@pytest.mark.slow
@pytest.mark.parametrize("robot", available())
def test_a_sweep_run_of_every_robot(robot, fmu_root):
    name = first_experiment(robot)
    design = Design(name, [parse_axis("controller.gain_scale=0.5,2")], stop_time=0.05)
    system, roles, metrics, units, runs = check(design, fmu_root)
    record = run_one(system, runs[1], design.stop_time, None)
    assert record["status"] == "ok", record["message"]
    model = roles.model()
    assert [k for k in record if k in metrics] == metrics == metric_names(roles, model)
    assert all(math.isfinite(record[m]) for m in metrics if m != "settling_time")
    assert ("max_tcp_error" in metrics) == bool(roles.x_ref) and ("peak_effort" in metrics) == bool(roles.tau)
    angles = "rad" in model.task_units(0)           # a pose's angle: its error apart from the distance
    assert ("max_orientation_error" in metrics) == (bool(roles.x_ref) and angles)
    configured = experiment.with_parameters(system, {"controller.gain_scale": 2.0})
    master = Master(configured)
    master.check()
    result = master.run(stop_time=0.05)
    by_hand = metrics_of(analysis.tracking_metrics(result, Roles.of(configured)), result, roles)
    assert {m: record[m] for m in metrics if m != "settling_time"} == \
        {m: by_hand[m] for m in metrics if m != "settling_time"}


@pytest.mark.slow
def test_a_sweep_run_of_a_pose_task_records_its_orientation_error(fmu_root):
    """ur5-pose: the tool's orientation error (from quat_ref) is a metric column, equal to the
    single run's analysis."""
    design = Design("ur5-pose", [parse_axis("controller.gain_scale=0.5,2")], stop_time=0.3)
    system, roles, metrics, _, runs = check(design, fmu_root)
    assert metrics[:2] == ["max_tcp_error", "max_orientation_error"]
    record = run_one(system, runs[0], design.stop_time, None)
    assert record["status"] == "ok", record["message"]
    configured = experiment.with_parameters(system, {"controller.gain_scale": 0.5})
    result = Master(configured).run(stop_time=0.3)
    tracking = analysis.tracking_metrics(result, Roles.of(configured))
    assert record["max_orientation_error"] == float(tracking.orientation_error.max())
    assert 0.0 < record["max_orientation_error"] < 5e-4

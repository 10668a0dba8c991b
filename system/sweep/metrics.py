"""The small record a sweep keeps of one run: its metrics as named numbers.

Every number comes from :func:`robofmu.system.analysis.tracking_metrics` (the metrics ``robofmu run``
reports) and :func:`robofmu.system.analysis.settling_time`, so a sweep row equals the analysis
of a single run with the same parameters bit for bit.

Columns (joint j = 1 .. n; joint units rad or m, effort units N·m or N):

- ``max_tcp_error`` (m): max |FK(q) - x_ref| over the run, over the task coordinates measured in
  m (a pose's angle is not added to a distance), where the experiment has a task reference;
- ``max_orientation_error`` (rad): where the experiment has a task reference and an orientation
  (:meth:`~robofmu.system.roles.Roles.measures_orientation`): for a pose task the largest rotation
  angle from quat_ref to the frame, else max |FK(q)_i - x_ref_i| over the task coordinates
  measured in rad (3rrp);
- ``final_tcp_error`` (m), ``final_orientation_error`` (rad): the same two at the last point
  (the end pose), where the run has them;
- ``max_joint_error``: the largest ``max_joint_error[j]``;
- ``peak_effort``: the largest ``peak_effort[j]``, where the experiment has efforts;
- ``settling_time`` (s): see :func:`~robofmu.system.analysis.settling_time` (empty where it
  does not apply);
- per joint ``max_joint_error[j]``, ``rms_joint_error[j]``, ``final_joint_error[j]``
  (q_ref - q at the end) and ``peak_effort[j]``.
"""
from __future__ import annotations

from robofmu.components.robots import RobotModel

from robofmu.system.analysis import Tracking, settling_time
from robofmu.system.result import Result
from robofmu.system.roles import Roles

__all__ = ["METRIC_UNITS", "metric_names", "metrics_of"]

#: The metrics whose unit is the same for every robot (the joint ones are rad or m per joint).
METRIC_UNITS = {"max_tcp_error": "m", "max_orientation_error": "rad", "final_tcp_error": "m",
                "final_orientation_error": "rad", "settling_time": "s"}


def metric_names(roles: Roles, model: RobotModel) -> list[str]:
    """The metric columns of an experiment with these roles on this robot, in order."""
    names = ["max_tcp_error"] if roles.x_ref else []
    names += ["max_orientation_error"] if roles.measures_orientation(model) else []
    names += ["final_tcp_error"] if roles.x_ref else []
    names += ["final_orientation_error"] if roles.measures_orientation(model) else []
    names += ["max_joint_error"] + (["peak_effort"] if roles.tau else []) + ["settling_time"]
    for j in range(1, model.n + 1):
        names += [f"max_joint_error[{j}]", f"rms_joint_error[{j}]", f"final_joint_error[{j}]"]
        names += [f"peak_effort[{j}]"] if roles.tau else []
    return names


def metrics_of(tracking: Tracking, result: Result, roles: Roles) -> dict[str, float]:
    """The metrics of one run by column name (:func:`metric_names`), as Python floats."""
    record = {}
    if roles.x_ref:
        record["max_tcp_error"] = float(tracking.tcp_error.max())
        if tracking.orientation_error is not None:
            record["max_orientation_error"] = float(tracking.orientation_error.max())
        record["final_tcp_error"] = float(tracking.tcp_error[-1])
        if tracking.orientation_error is not None:
            record["final_orientation_error"] = float(tracking.orientation_error[-1])
    record["max_joint_error"] = float(tracking.max_error.max())
    if roles.tau:
        record["peak_effort"] = float(tracking.peak_effort.max())
    record["settling_time"] = settling_time(result.time, roles.vector(result, "q_ref"), roles.vector(result, "q"))
    for j in range(len(tracking.max_error)):
        record[f"max_joint_error[{j + 1}]"] = float(tracking.max_error[j])
        record[f"rms_joint_error[{j + 1}]"] = float(tracking.rms_error[j])
        record[f"final_joint_error[{j + 1}]"] = float(tracking.final_error[j])
        if roles.tau:
            record[f"peak_effort[{j + 1}]"] = float(tracking.peak_effort[j])
    return record

"""A run tells what its FMUs said: the FMUs' warnings and errors grouped with the excursions the
record shows, on stderr, first in report.md, whole in run.log, in the summary line and in the
Python API's result; ``--strict`` makes a run that did not respect its IK or limits exit 1.

The failing run is ur5-pose with ``--set trajectory.displacement[1]=5``: the tool is sent 5 m
away, the IK stops at its joints' velocity limit at t = 0.187 s and stops converging at 0.33 s.
Every count and time is checked against the recorded columns (``ik.status``, ``ik.reachable``,
``plant.within_limits``, ``plant.qd``) and the URDF's limits read by an independent Pinocchio
model, never against the grouping's own output.
"""
from __future__ import annotations

import re
import contextlib
import io
from dataclasses import replace

import numpy as np
import pytest

from robofmu.system import cli, experiment
from robofmu.system.master import Master, SimulationError
from robofmu.system.result import Message, Result, group_messages, message_pattern, stated_time, status_meanings

from fmu_util import refuse_plant_steps
from robot_files import independent_model

SET = "trajectory.displacement[1]=5"


@pytest.fixture(scope="module")
def ur5_fmus(tmp_path_factory):
    """The UR5's FMUs built from the current sources (only this robot: a few seconds)."""
    from robofmu.system.packaging.build import build

    root = tmp_path_factory.mktemp("fmus")
    build("ur5", root, log=lambda *_: None)
    return root


def run_cli(capsys, *args) -> tuple[int, str, str]:
    status = cli.main(["run", "ur5-pose", *map(str, args)])
    captured = capsys.readouterr()
    return status, captured.out, captured.err


@pytest.fixture(scope="module")
def failing(ur5_fmus, tmp_path_factory):
    """The CLI's run with the tool sent 5 m away (plain, then --strict): status, stdout, stderr,
    the output folder, and the strict run's status."""
    out = tmp_path_factory.mktemp("failing") / "out"
    answers = []
    for extra in ([], ["--strict"]):
        stdout, stderr = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
            status = cli.main(["run", "ur5-pose", "--set", SET, "--out", str(out), "--fmus", str(ur5_fmus), *extra])
        answers.append((status, stdout.getvalue(), stderr.getvalue()))
    (status, printed, said), (strict, strict_printed, _) = answers
    return {"status": status, "out": printed, "err": said, "folder": out, "strict": strict,
            "strict_out": strict_printed}


def excursion(result: Result, column: str, off) -> tuple[int, float, float]:
    """(points, first time, last time) at which ``column`` is off, from the record."""
    rows = np.flatnonzero(off(result[column]))
    return len(rows), float(result.time[rows[0]]), float(result.time[rows[-1]])


def falling_edges(flag: np.ndarray) -> int:
    """How many times a health flag goes from true to false (the first point counts if false)."""
    good = flag > 0.5
    return int((~good[0]) + np.sum(good[:-1] & ~good[1:]))


# -- grouping, without FMUs --------------------------------------------------------------------------
def test_message_pattern_strips_numbers_and_the_time_prefix_but_not_names():
    text = "t = 0.187 s: joint 3 (panda_joint3) velocity -3.17 rad/s exceeds its limit 3.15 rad/s at q = [0.1, 2e-05]."
    assert message_pattern(text) == "joint # (panda_joint3) velocity # rad/s exceeds its limit # rad/s at q = [#, #]."
    assert message_pattern("qd_ref[3] = nan") == "qd_ref[#] = #"


def test_status_meanings_read_the_codes_the_description_names():
    assert status_meanings("0 converged, 1 not converged (out of reach?), 2 near a singularity, 3 at a joint limit") \
        == {0: "converged", 1: "not converged", 2: "near a singularity", 3: "at a joint limit"}
    assert status_meanings("Damped least-squares corrections") == {}


def test_group_messages_counts_excursions_from_the_record():
    """Made-up record of 11 points (h = 0.1 s): ``b.reachable`` false on points 2..5 and 8..9,
    ``b.status`` 1 on 3..6 and 2 on 10; b warns at the start of each excursion (numbers differ),
    c warns twice with no health output. Expected numbers counted by hand."""
    time = np.round(np.arange(11) * 0.1, 12)
    reachable = np.ones(11)
    reachable[2:6] = 0.0
    reachable[8:10] = 0.0
    status = np.zeros(11)
    status[3:7] = 1.0
    status[10] = 2.0
    data = np.column_stack([reachable, status])
    log = [Message("b", "WARNING", "logStatusWarning", "t = 0.2 s: out of reach by 0.5 m", 0.2),
           Message("c", "ERROR", "logStatusError", "bad input x[2] = 7", 0.3),
           Message("b", "WARNING", "logStatusWarning", "t = 0.8 s: out of reach by 1.25 m", 0.8),
           Message("c", "ERROR", "logStatusError", "bad input x[2] = 9", 0.9)]
    groups = group_messages(log, time, ["b.reachable", "b.status"], data,
                            {"b.status": {0: "converged", 1: "not converged", 2: "near a singularity"}})
    assert len(groups) == 3
    b, c, record = groups
    # b: two warnings; reachable off on 2..5 and 8..9 (6 points); status is 0 at both warnings
    assert (b.block, b.status, b.count, b.first, b.last_message, b.last, b.steps, b.signals) == \
        ("b", "WARNING", 2, 0.2, 0.8, 0.9, 6, ("b.reachable",))
    assert b.text == "out of reach by 0.5 m"
    assert (c.count, c.first, c.last, c.steps) == (2, 0.3, 0.9, None)
    # the status column: 1 on 3..6 (4 points), 2 on 10 (1 point); no message started it
    assert (record.block, record.count, record.first, record.last, record.steps) == ("b", 0, 0.3, 1.0, 5)
    assert str(record) == ("b: not converged (status 1, 4 steps), near a singularity (status 2, 1 step) "
                           "from t = 0.3 s to 1 s, 5 steps")
    assert str(c) == "c: ERROR 2 times from t = 0.3 s to 0.9 s: bad input x[2] = 7"
    assert str(b).endswith("(b.reachable off from t = 0.2 s to 0.9 s, 6 steps)")


def test_a_message_at_a_point_where_the_status_is_off_takes_its_excursion():
    time = np.arange(6) * 1.0
    status = np.array([0.0, 1.0, 1.0, 0.0, 1.0, 0.0])
    log = [Message("ik", "WARNING", "", "t = 1 s: not converged", 1.0)]
    (group, rest) = group_messages(log, time, ["ik.status"], status[:, None])
    assert (group.steps, group.first, group.last, group.signals) == (2, 1.0, 2.0, ("ik.status",))
    assert (rest.count, rest.steps, rest.first, rest.last) == (0, 1, 4.0, 4.0)     # the point no message started



def test_a_message_s_time_is_the_one_its_block_states_else_the_point_it_arrived_at():
    assert stated_time("t = 0.187 s: joint 3 velocity exceeds its limit", 0.186) == 0.187
    assert stated_time("t = 1e-05 s: x", 0.0) == 1e-05
    for text in ("joint 3 velocity exceeds its limit", "t = nan s: x", "t = soon s: x", "at t = 2 s: x"):
        assert stated_time(text, 0.5) == 0.5


def test_groups_first_on_one_point_follow_the_diagram_order_and_later_points_come_after():
    """The plant speaks for t = 2 in its step from 1, before the IK's exchange at 2, and 'z'
    speaks first at 1: the groups go by point, then by the diagram's order."""
    time = np.arange(4) * 1.0
    log = [Message("plant", "WARNING", "", "t = 2 s: too fast", 2.0),
           Message("z", "WARNING", "", "odd", 1.0 + 1e-13),
           Message("ik", "WARNING", "", "t = 2 s: not reached", 2.0 + 1e-13)]
    groups = group_messages(log, time, [], np.zeros((4, 0)), order=["ik", "plant", "z"])
    assert [g.block for g in groups] == ["z", "ik", "plant"]
    assert [g.block for g in group_messages(log, time, [], np.zeros((4, 0)))] == ["z", "plant", "ik"]

# -- robofmu run ----------------------------------------------------------------------------------------
def test_run_prints_the_grouped_messages_with_the_record_s_counts(failing):
    """stderr: the IK's status group counts the recorded points with ik.status != 0, from the
    first to the last of them; the IK's warning and the plant's each once, with the excursion
    of ik.reachable and plant.within_limits as recorded."""
    assert failing["status"] == 0 and "Traceback" not in failing["err"]
    result = Result.from_csv(failing["folder"] / "results.csv")
    n, first, last = excursion(result, "ik.status", lambda v: v != 0)
    assert n > 2000 and 0.3 < first < 0.4 and last == 3.0
    lines = failing["err"].splitlines()
    assert any(line.startswith("What the FMUs said (ur5-pose;") for line in lines)
    (status_line,) = [line for line in lines if line.startswith("  ik: not converged (status 1")]
    assert status_line.endswith(f"from t = {first:g} s to {last:g} s, {n} steps")
    codes = {int(c): int(np.sum(result["ik.status"] == c)) for c in np.unique(result["ik.status"]) if c}
    for code, count in codes.items():
        assert f"(status {code}, {count} step{'' if count == 1 else 's'})" in status_line
    n_reach, first_reach, last_reach = excursion(result, "ik.reachable", lambda v: v < 0.5)
    (ik_line,) = [line for line in lines if line.startswith("  ik: WARNING once")]
    assert ik_line.startswith(f"  ik: WARNING once at t = {first_reach:g} s: ")
    assert ik_line.endswith(f"(ik.reachable off from t = {first_reach:g} s to {last_reach:g} s, {n_reach} steps)")
    n_plant, first_plant, _ = excursion(result, "plant.within_limits", lambda v: v < 0.5)
    (plant_line,) = [line for line in lines if line.startswith("  plant: WARNING")]
    assert f"at t = {first_plant:g} s" in plant_line and f", {n_plant} step" in plant_line


def test_run_names_the_joints_beyond_their_limits_as_the_urdf_gives_them(failing):
    """The record's velocity excursions against the URDF's limits (an independent Pinocchio model)."""
    result = Result.from_csv(failing["folder"] / "results.csv")
    model, _ = independent_model("ur5")
    qd = result.vector("plant.qd")
    beyond = np.abs(qd) > model.velocityLimit[None, :]
    assert beyond.any()
    lines = failing["err"].splitlines()
    for j in np.flatnonzero(beyond.any(axis=0)):
        rows = np.flatnonzero(beyond[:, j])
        (line,) = [x for x in lines if x.startswith(f"  joint {j + 1} (") and "velocity limit" in x]
        assert f"{model.velocityLimit[j]:.6g} rad/s" in line and line.endswith(
            f", {len(rows)} step{'' if len(rows) == 1 else 's'}")


def test_report_starts_with_what_the_fmus_said_and_run_log_has_every_message(failing):
    folder = failing["folder"]
    report = (folder / "report.md").read_text()
    assert report.startswith("# ur5-pose\n\n## What the FMUs said\n\n- ")
    said = [line.removeprefix("  ") for line in failing["err"].splitlines() if line.startswith("  ")
            and not line.startswith("  ur5-pose:")]
    head = report.split("\n### ")[0]
    assert [line.removeprefix("- ") for line in head.splitlines() if line.startswith("- ")] == said
    assert report.index("## What the FMUs said") < report.index("| joint |")
    # one warning per excursion of each block's health flag (they warn once per excursion)
    result = Result.from_csv(folder / "results.csv")
    expected = falling_edges(result["ik.reachable"]) + falling_edges(result["plant.within_limits"])
    log = (folder / "run.log").read_text().splitlines()
    assert len(log) == expected == 2
    assert all(re.match(r"t = \S+ s \[WARNING\] (ik|plant): t = \S+ s: ", line) for line in log)


def test_summary_says_what_was_not_respected_and_strict_exits_1(failing):
    summary = failing["out"].splitlines()[-1]
    result = Result.from_csv(failing["folder"] / "results.csv")
    assert summary.startswith(f"ur5-pose: done, {len(result.time) - 1} steps to t = 3 s in ")
    assert " — WARNING: " in summary and "ik not converged (status 1" in summary
    assert "the build's reference check refuses the --set reference" in summary
    assert failing["status"] == 0 and failing["strict"] == 1
    assert failing["strict_out"].splitlines()[-1].split(" in ")[0] == summary.split(" in ")[0]


def test_set_of_a_trajectory_parameter_repeats_the_build_s_reference_check(failing):
    """The warning before the run is check_reference's refusal of the description with
    displacement[1] = 5 (built here by hand), word for word."""
    from robofmu.components.preflight import ReferenceRefused, check_reference
    from robofmu.components.robots import load_description
    from robofmu.components.robots.description import Choice

    description = load_description("ur5")
    given = dict(description.trajectory.parameters)
    given["displacement"] = [5.0, *given["displacement"][1:]]
    with pytest.raises(ReferenceRefused) as refused:
        check_reference(replace(description, trajectory=Choice(description.trajectory.kind, given)), 1e-3)
    (line,) = [x for x in failing["err"].splitlines() if x.startswith("warning: --set")]
    assert line == (f"warning: --set {SET}: the build's reference check refuses the "
                    f"reference: {refused.value}")


def test_a_clean_run_says_nothing(ur5_fmus, tmp_path, capsys):
    out = tmp_path / "clean"
    status, printed, said = run_cli(capsys, "--out", out, "--fmus", ur5_fmus, "--strict")
    result = Result.from_csv(out / "results.csv")
    assert not np.any(result["ik.status"]) and np.all(result["ik.reachable"] == 1)
    assert status == 0 and "What the FMUs said" not in said and "warning" not in said.lower()
    assert "WARNING" not in printed and printed.splitlines()[-1].startswith("ur5-pose: done, 3000 steps")
    assert (out / "run.log").read_text() == ""
    assert (out / "report.md").read_text().startswith("# ur5-pose\n\n## What the FMUs said\n\nNothing: ")


def test_the_python_api_result_carries_the_same_groups(failing, ur5_fmus):
    system = experiment.with_parameters(experiment.load("ur5-pose", fmu_dir=ur5_fmus),
                                        {"trajectory.displacement[1]": 5.0})
    master = Master(system)
    master.check()
    result = master.run()
    printed = [line.removeprefix("  ") for line in failing["err"].splitlines() if line.startswith("  ")
               and not line.startswith(("  ur5-pose:", "  joint "))]
    assert [str(g) for g in result.messages] == printed
    (record,) = [g for g in result.messages if g.count == 0]
    n, first, last = excursion(result, "ik.status", lambda v: v != 0)
    assert (record.block, record.steps, record.first, record.last, record.signals) == ("ik", n, first, last,
                                                                                        ("ik.status",))
    # The log keeps the order logged: the plant, without feedthrough, evaluates its outputs for
    # t + h in its step from t and speaks before the IK's exchange at t + h; both say t + h.
    assert [m.block for m in result.log] == ["plant", "ik"] and all(m.status == "WARNING" for m in result.log)
    assert [m.time for m in result.log] == pytest.approx([0.187, 0.187], abs=1e-12)
    assert [g.block for g in result.messages if g.count] == ["ik", "plant"]      # one point: diagram order
    assert master.heard == result.log


def test_a_failed_run_s_partial_result_carries_the_messages(ur5_fmus, monkeypatch):
    """The plant refuses its step from t = 0.5 s: the SimulationError's result holds the IK's
    warning of t = 0.187 s and the plant's error, grouped."""
    refuse_plant_steps(monkeypatch, "ur5", 0.5)
    system = experiment.with_parameters(experiment.load("ur5-pose", fmu_dir=ur5_fmus),
                                        {"trajectory.displacement[1]": 5.0})
    with pytest.raises(SimulationError) as failed:
        Master(system).run(stop_time=1.0)
    kept = failed.value.result
    assert kept is not None and kept.time[-1] == pytest.approx(0.5)
    blocks = [(g.block, g.status) for g in kept.messages if g.count]
    assert ("ik", "WARNING") in blocks and ("plant", "ERROR") in blocks
    (error,) = [g for g in kept.messages if g.status == "ERROR"]
    assert error.first == pytest.approx(0.5) and "refused for the test" in error.text
    n, first, _ = excursion(kept, "ik.status", lambda v: v != 0)
    (record,) = [g for g in kept.messages if g.count == 0]
    assert (record.steps, record.first) == (n, first)


def test_a_sweep_row_of_a_completed_run_carries_what_the_fmus_said(ur5_fmus):
    """The sweep's worker, in process: a run with the tool sent 5 m away is ``ok`` and its message
    holds the IK's warning group of the same run by the master; the packaged run's is empty."""
    from robofmu.system.sweep.worker import run_one

    system = experiment.load("ur5-pose", fmu_dir=ur5_fmus)
    row = run_one(system, {"trajectory.displacement[1]": 5.0}, 0.5, None)
    master = Master(experiment.with_parameters(system, {"trajectory.displacement[1]": 5.0}),
                    record=experiment_roles(system))
    master.check()
    groups = master.run(stop_time=0.5).messages
    assert row["status"] == "ok" and [g.block for g in groups] == ["ik", "plant"]
    assert row["message"] == " | ".join(str(g) for g in groups)
    assert run_one(system, {"trajectory.displacement[1]": -0.15}, 0.5, None)["message"] == ""


def experiment_roles(system) -> list[str]:
    """What the sweep records: the experiment's roles."""
    from robofmu.system.roles import Roles

    return Roles.of(system).signals()


@pytest.mark.parametrize("debug", [False, True])
def test_debug_keeps_the_fmus_debug_messages_in_the_log_only(ur5_fmus, monkeypatch, debug):
    """An unexpected exception in the plant's step is logged as an error and its traceback as a
    debug message (status OK): the log keeps the traceback only with ``debug``; the groups never."""
    from robofmu.components.blocks import block_type
    from robofmu.components.robots import load_description

    cls = block_type(load_description("ur5"), "plant")
    original = cls.advance

    def advance(self, t, h):
        if t >= 0.01 - 1e-12:
            raise RuntimeError("unexpected, for the test")
        return original(self, t, h)

    monkeypatch.setattr(cls, "advance", advance)
    master = Master(experiment.load("ur5-pose", fmu_dir=ur5_fmus), debug=debug)
    with pytest.raises(SimulationError) as failed:
        master.run(stop_time=0.1)
    log = failed.value.result.log
    traces = [m for m in log if m.status == "OK"]
    assert [m.status for m in log if m.status != "OK"] == ["ERROR"]
    assert bool(traces) == debug and all("Traceback" in m.text for m in traces)
    assert [(g.block, g.status, g.count) for g in failed.value.result.messages] == [("plant", "ERROR", 1)]

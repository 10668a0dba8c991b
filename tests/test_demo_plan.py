"""The demo's plan (``system/studies/demo.toml``) read typed: every section a dataclass, every mistake
refused before the demo runs, in one line naming the file and the key."""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from robofmu.components.robots import available as robots
from robofmu.system.experiment import available as experiments
from robofmu.system.studies.plan import (PLAN, AccuracyStudy, DemoPlan, ExperimentSection, GainDesignCase,
                                         InteropSection, RobustnessStudy, SampledLoopStudy, StepResponses,
                                         WorkspaceEntry, read_plan)
from robofmu.system.usage import UsageError


def test_the_plan_reads_into_its_dataclasses():
    plan = read_plan()
    assert isinstance(plan, DemoPlan) and plan.path == PLAN and plan.title.startswith("robofmu demo")
    assert plan.sections and all(isinstance(s, ExperimentSection) for s in plan.sections)
    assert all(isinstance(w, WorkspaceEntry) and w.study.is_file() for w in plan.workspace)
    assert isinstance(plan.robustness, RobustnessStudy) and isinstance(plan.interop, InteropSection)
    assert isinstance(plan.accuracy, AccuracyStudy) and isinstance(plan.step_response, StepResponses)
    assert isinstance(plan.step_response.design, GainDesignCase)
    named = [name for s in plan.sections for name in s.experiments] + list(plan.accuracy.experiments) \
        + list(plan.interop.experiments) + list(plan.robustness.experiments.values())
    assert set(named) <= set(experiments())
    assert set(plan.step_response.robots) | set(plan.step_response.design.robots) <= set(robots())
    rrp = next(s for s in plan.sections if "rrp-line" in s.experiments)
    assert rrp.seed_table == PLAN.parent / "seed000_a2.csv" and rrp.seed_table_notes
    chess = plan.sections[0]
    assert (chess.seed_table, chess.bangbang, chess.cross_check, chess.tutorial) == (None, False, False, None)
    assert chess.diagnostics == ExperimentSection.__dataclass_fields__["diagnostics"].default
    assert all(isinstance(h, float) for h in plan.accuracy.step_sizes + plan.accuracy.quick_step_sizes)


def test_the_plan_knows_the_sampled_loop_study():
    """[sampled_loop]: the UR5's pose line with the study's own joint losses, at 1000, 500 and 250 Hz and
    0 or 1 sample of delay (its losses known or not: the study's third axis)."""
    from robofmu.system.experiment import load

    study = read_plan().sampled_loop
    assert isinstance(study, SampledLoopStudy) and study.experiment == PLAN.parent / "ur5_joint_losses.toml"
    assert study.sample_times == (0.001, 0.002, 0.004) and study.delay_steps == (0.0, 1.0)
    system = load(study.experiment)
    assert system.extra["robot"] == "ur5" and system.name == "ur5-pose-losses" and system.step == 0.001
    plant = system.block("plant").parameters
    assert all(len(plant[p]) == 6 and min(plant[p]) > 0 for p in ("damping", "friction", "friction_velocity"))
    assert all(name.startswith("plant.") for name in study.stated)


@pytest.fixture
def plan_copy(tmp_path):
    """``plan_copy(old, new)``: the plan and the files it names copied to tmp_path, ``old`` replaced by
    ``new`` once in its text; returns the copy's path."""
    def make(old: str = "", new: str = "") -> Path:
        for data in PLAN.parent.iterdir():
            if data.suffix in (".toml", ".csv"):
                shutil.copy(data, tmp_path / data.name)
        path = tmp_path / PLAN.name
        text = PLAN.read_text()
        if old:
            assert text.count(old) == 1, old
            text = text.replace(old, new)
        path.write_text(text)
        return path
    return make


def test_an_unedited_copy_reads_the_same(plan_copy):
    path = plan_copy()
    copy, real = read_plan(path), read_plan()
    assert copy.sections[1].seed_table == path.parent / "seed000_a2.csv"
    assert copy.accuracy == real.accuracy and copy.step_response == real.step_response
    assert copy.robustness == real.robustness and copy.title == real.title


@pytest.mark.parametrize("old, new, key, problem", [
    ("\nstep_sizes = [", "\nsteps = [", "accuracy.steps",
     "unknown key (known: experiments, quick_step_sizes, step_sizes)"),
    ("quick_step_sizes = [0.01, 0.005, 0.002]", "", "accuracy.quick_step_sizes", "missing"),
    ('title = "robofmu demo', 'titel = "robofmu demo', "titel", "unknown key"),
    ('experiments = ["chess-pd", "chess-pid", "chess-pd-unknown-pawn", "chess-pid-unknown-pawn"]',
     'experiments = ["chess-pd", "chess-pdd"]', "sections[1].experiments[2]", "unknown experiment 'chess-pdd'"),
    ('experiments = ["chess-pd", "chess-pid", "chess-pd-unknown-pawn", "chess-pid-unknown-pawn"]',
     'experiments = "chess-pd"', "sections[1].experiments", "must be a list, got 'chess-pd'"),
    ('seed_table = "seed000_a2.csv"', 'seed_table = "seed000_a3.csv"', "sections[2].seed_table",
     "no such file seed000_a3.csv beside the plan"),
    ("bangbang = true", 'bangbang = "yes"', "sections[3].bangbang", "must be true or false, got 'yes'"),
    ("threshold = 0.001", 'threshold = "1 mm"', "robustness.threshold", "must be a finite number, got '1 mm'"),
    ('experiment = "ur5_joint_losses.toml"', 'experiment = "ur5_losses.toml"', "sampled_loop.experiment",
     "no such file ur5_losses.toml beside the plan"),
    ("sample_times = [0.001, 0.002, 0.004]", "sample_times = 0.001", "sampled_loop.sample_times",
     "must be a list, got 0.001"),
    ('experiments = { PD = "chess-pd-unknown-pawn", PID = "chess-pid-unknown-pawn" }',
     'experiments = { PD = "chess-pd-unknown-pawn", PID = "chess-pid-unknown" }', "robustness.experiments.PID",
     "unknown experiment 'chess-pid-unknown'"),
    ('robots = ["chess", "rrp", "rpp", "planar2r", "rrp_offset"]', 'robots = ["chess", "scara"]',
     "step_response.robots[2]", "unknown robot 'scara'"),
    ('design = { settling_time = 0.3, overshoot = 5.0, robots = ["chess"] }',
     'design = { settling_time = 0.3, robots = ["chess"] }', "step_response.design.overshoot", "missing"),
    ('study = "seed004_workspace.toml"', "study = 4", "workspace[1].study", "must be a string, got 4"),
])
def test_a_mistake_is_refused_naming_file_and_key(plan_copy, old, new, key, problem):
    path = plan_copy(old, new)
    with pytest.raises(UsageError) as info:
        read_plan(path)
    text = str(info.value)
    assert text.startswith(f"{path}: {key}: {problem}"), text
    assert "\n" not in text


def test_a_missing_or_broken_file_is_named(tmp_path):
    with pytest.raises(UsageError, match="demo.toml: cannot read it as TOML: No such file or directory$"):
        read_plan(tmp_path / "demo.toml")
    (tmp_path / "demo.toml").write_text("title = \n")
    with pytest.raises(UsageError, match=r"demo.toml: cannot read it as TOML: Invalid value \(at line 1"):
        read_plan(tmp_path / "demo.toml")

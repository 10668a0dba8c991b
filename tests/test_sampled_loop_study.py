"""The demo's sampled-loop study (``[sampled_loop]`` of system/studies/demo.toml): the UR5's pose
line at 1000, 500 and 250 Hz, 0 and 1 sample of delay, its joint losses known to the controller
or not. Its table equals single runs made by hand for two of its cases; the losses it states are
its file's; the ordering its text claims holds."""
from __future__ import annotations

import tomllib

import pytest

from robofmu.system import analysis, experiment
from robofmu.system.master import Master
from robofmu.system.roles import Roles
from robofmu.system.studies import sampled_loop
from robofmu.system.studies.plan import read_plan

STUDY = read_plan().sampled_loop


def single_run(fmu_root, sample_time: float, delay: int, known: bool):
    """The study's experiment with the case's settings put on the System directly."""
    system = experiment.load(STUDY.experiment, fmu_dir=fmu_root)
    controller = system.block(STUDY.controller)
    controller.sample_time = sample_time
    controller.parameters.update(delay_steps=delay, loss_compensation=1.0 if known else 0.0)
    result = Master(system).run()
    return analysis.tracking_metrics(result, Roles.of(system))


def test_the_design_is_the_twelve_cases():
    runs = sampled_loop.design(STUDY).runs()
    assert len(runs) == 12
    assert runs[0] == {"controller.sample_time": 0.001, "controller.delay_steps": 0,
                       "controller.loss_compensation": 1}
    assert runs[-1] == {"controller.sample_time": 0.004, "controller.delay_steps": 1,
                        "controller.loss_compensation": 0}


@pytest.mark.slow
def test_the_study_table_equals_single_runs(fmu_root, tmp_path):
    run, cases = sampled_loop.run_study(STUDY, tmp_path / "study", fmu_root, workers=2, progress=False)
    assert [c.status for c in cases] == ["ok"] * 12
    assert [(c.rate, c.delay_steps, c.known) for c in cases[:4]] == \
        [(1000.0, 0, True), (1000.0, 0, False), (1000.0, 1, True), (1000.0, 1, False)]
    by_case = {(c.sample_time, c.delay_steps, c.known): c for c in cases}
    for key in ((0.001, 0, True), (0.004, 1, False)):
        tracking = single_run(fmu_root, *key)
        case = by_case[key]
        for got, want in ((case.max_position, tracking.tcp_error.max()), (case.end_position, tracking.tcp_error[-1]),
                          (case.max_orientation, tracking.orientation_error.max()),
                          (case.end_orientation, tracking.orientation_error[-1])):
            assert got == pytest.approx(want, abs=1e-12, rel=0), key
    # what the report's text says: the sampling's error grows with the sample time and with a delay
    # when the losses are known; unknown friction costs far more at every rate
    known = [by_case[(t, d, True)].max_position for t in STUDY.sample_times for d in (0, 1)]
    assert known[0] < known[2] < known[4] and all(known[k + 1] > 2 * known[k] for k in (0, 2, 4))
    for t in STUDY.sample_times:
        for d in (0, 1):
            assert by_case[(t, d, False)].max_position > 20 * by_case[(t, d, True)].max_position
    table = sampled_loop.cases_table(cases)
    assert table.count("\n") == 13 and f"| 250 | 1 | unknown | {cases[-1].max_position * 1e3:.3g} |" in table
    figure = sampled_loop.figure(cases, tmp_path / "sampled-loop.png", "errors")
    assert figure.stat().st_size > 10_000


def test_the_stated_losses_are_the_study_file(fmu_root):
    stated = tomllib.loads(STUDY.experiment.read_text())["parameters"]["plant"]
    table = sampled_loop.losses_table(STUDY, fmu_root).splitlines()
    assert len(table) == 2 + 6 and table[2].startswith("| shoulder_pan_joint |")
    for j, line in enumerate(table[2:]):
        cells = [c.strip() for c in line.strip("|").split("|")]
        assert [float(c) for c in cells[1:]] == [stated["damping"][j], stated["friction"][j],
                                                 stated["friction_velocity"][j]]

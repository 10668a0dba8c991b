"""``robofmu convergence``: the accuracy study as a command, its typed result and its one-line mistakes.

The runs are short (0.1 s of chess-pd at 2 and 1 ms); the study's numbers are tested in
tests/test_reference.py.
"""
from __future__ import annotations

import json
import math

import pytest

from robofmu.system import defaults
from robofmu.system.cli import main, parser_for
from robofmu.system.experiment import load
from robofmu.system.studies import convergence
from robofmu.system.studies.convergence import ConvergenceRun, ConvergenceStudy, Order, check_plan, study


def test_the_study_returns_typed_results_and_writes_them(fmu_root, tmp_path):
    system = load("chess-pd", fmu_dir=fmu_root)
    found = study(system, (0.001, 0.002), tmp_path, algorithms=("gauss-seidel", "in-process"), stop_time=0.1,
                  progress=None)
    assert isinstance(found, ConvergenceStudy)
    assert found.step_sizes == (0.002, 0.001) and found.algorithms == ("gauss-seidel", "in-process")
    assert all(isinstance(run, ConvergenceRun) for run in found.runs) and len(found.runs) == 4
    assert [r.step_size for r in found.runs_of("in-process")] == [0.002, 0.001]
    for gs, replica in zip(found.runs_of("gauss-seidel"), found.runs_of("in-process")):
        assert gs.q_error == replica.q_error and gs.tcp_error == replica.tcp_error     # bit for bit
    assert set(found.orders) == {"gauss-seidel", "in-process"}
    assert isinstance(found.orders["in-process"], Order)
    assert found.orders["gauss-seidel"].ratio_to_gauss_seidel is None
    assert found.orders["in-process"].ratio_to_gauss_seidel == 1.0
    assert found.orders["gauss-seidel"].error_constant == pytest.approx(
        sum(r.q_error / r.step_size for r in found.runs_of("gauss-seidel")) / 2)
    assert "| gauss-seidel | 2 |" in found.table
    assert {key: path.name for key, path in found.files.items()} == {
        "table": "convergence.md", "figure": "convergence.png", "data": "convergence.json"}
    saved = json.loads((tmp_path / "convergence.json").read_text())
    assert saved == json.loads(json.dumps(found.to_json()))
    assert saved["orders"]["gauss-seidel"]["q"] == found.orders["gauss-seidel"].q
    assert saved["runs"][0]["step_size"] == 0.002 and saved["files"]["table"] == "convergence.md"
    assert (tmp_path / "convergence.md").read_text().endswith(found.table)


def test_the_plan_is_checked_naming_the_argument():
    assert check_plan([0.001, 0.002], ["jacobi"], 0.1) == ((0.002, 0.001), ("jacobi",))
    for args, start in [(([0.003, 0.001], ["jacobi"], 0.1), "step_sizes: 0.003 s does not divide the stop time 0.1 s"),
                        (([0.001], ["jacobi"], 0.1), "step_sizes: need at least two communication steps, got 0.001"),
                        (([0.001, 0.001], ["jacobi"], 0.1), "step_sizes: 0.001 is given twice"),
                        (([0.001, 0.002], ["jacobi", "jacobi"], 0.1), "algorithms: jacobi is given twice"),
                        (([0.001, -0.002], ["jacobi"], 0.1), "step_sizes: -0.002 is not a finite time > 0 s"),
                        (([0.001, math.nan], ["jacobi"], 0.1), "step_sizes: nan is not"),
                        (([0.001, 0.002], ["gs"], 0.1), "algorithms: unknown 'gs'; choose from gauss-seidel, jacobi, "
                                                        "in-process"),
                        (([0.001, 0.002], [], 0.1), "algorithms: none given")]:
        with pytest.raises(ValueError) as info:
            check_plan(*args)
        assert str(info.value).startswith(start), info.value
    assert convergence.ALGORITHMS == (*defaults.ALGORITHMS, convergence.IN_PROCESS)


def test_the_command_writes_the_study_and_replaces_its_folder(fmu_root, tmp_path, capsys):
    out = tmp_path / "conv"
    argv = ["convergence", "chess-pd", "--step-sizes", "0.002,0.001", "--stop-time", "0.1",
            "--algorithms", "gauss-seidel,in-process", "--fmus", str(fmu_root), "--out", str(out)]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "| in-process | 1 |" in printed and f"wrote {out / 'convergence.md'}" in printed
    assert sorted(p.name for p in out.iterdir()) == ["convergence.json", "convergence.md", "convergence.png"]
    assert json.loads((out / "convergence.json").read_text())["algorithms"] == ["gauss-seidel", "in-process"]
    assert main([*argv[:-4], "--algorithms", "in-process", "--fmus", str(fmu_root), "--out", str(out)]) == 0
    assert json.loads((out / "convergence.json").read_text())["algorithms"] == ["in-process"]   # replaced whole
    (out / "notes.txt").write_text("mine")
    capsys.readouterr()
    assert main(argv) == 2
    assert capsys.readouterr().err.strip() == f"robofmu convergence: --out {out}: holds notes.txt, not written by " \
                                              "robofmu; the folder would be replaced whole: give an empty folder, " \
                                              "a new one, or an earlier results folder"


@pytest.mark.parametrize("argv, message", [
    (["--step-sizes", "0.003,0.001", "--stop-time", "0.1"],
     "--step-sizes: 0.003 s does not divide the stop time 0.1 s into whole steps"),
    (["--step-sizes", "0.001"], "--step-sizes: need at least two communication steps, got 0.001"),
    (["--algorithms", "gauss-seidel,euler"], "--algorithms: unknown 'euler'"),
    (["--stop-time", "-1"], "--stop-time -1: must be a finite time > 0 s"),
    (["--fmus", "no-such-folder"], "--fmus no-such-folder: no such folder"),
])
def test_mistakes_answer_in_one_line(fmu_root, tmp_path, capsys, monkeypatch, argv, message):
    monkeypatch.chdir(tmp_path)
    if "--fmus" not in argv:
        argv = [*argv, "--fmus", str(fmu_root)]
    assert main(["convergence", "chess-pd", *argv, "--out", str(tmp_path / "conv")]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and len(captured.err.strip().splitlines()) == 1, captured.err
    assert captured.err.startswith(f"robofmu convergence: {message}"), captured.err
    assert not (tmp_path / "conv").exists()


def test_an_unknown_experiment_and_a_value_that_is_no_number(capsys):
    assert main(["convergence", "no-such-experiment"]) == 2
    assert capsys.readouterr().err.startswith("robofmu convergence: unknown experiment 'no-such-experiment'")
    with pytest.raises(SystemExit) as info:
        main(["convergence", "chess-pd", "--step-sizes", "0.01,fast"])
    assert info.value.code == 2
    assert "argument --step-sizes: '0.01,fast': expected communication steps in s" in capsys.readouterr().err


def test_defaults_and_old_spellings(capsys):
    p = parser_for(["convergence"])
    args = p.parse_args(["convergence", "chess-pd"])
    assert (args.step_sizes, args.algorithms, args.stop_time, args.fmus, args.out) == (
        None, None, None, defaults.FMU_FOLDER, None)            # main: the study's DEFAULT_STEP_SIZES, ALGORITHMS
    args = p.parse_args(["convergence", "chess-pd", "--steps", "0.002,0.001", "--fmu-dir", "elsewhere"])
    assert (args.step_sizes, args.fmus) == ((0.002, 0.001), "elsewhere")
    assert capsys.readouterr().err.splitlines() == ["robofmu convergence: --steps is deprecated; use --step-sizes",
                                                    "robofmu convergence: --fmu-dir is deprecated; use --fmus"]

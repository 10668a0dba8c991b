"""The command line: every mistake in one line (exit status 2), output folders replaced whole,
Ctrl-C during a run (exit status 130), the master's record selection, ``robofmu doctor``.

The CLI runs in subprocesses (``python -m robofmu.system.cli``). The mistakes are independent,
so they are all started at once (a thread pool) in one fixture, and each test reads its answer.
"""
from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import zipfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

import robofmu.components as components
from robofmu.system import experiment
from robofmu.system.diagram import select
from robofmu.system.master import DiagramError, Interrupted, Master, Result

CLI = [sys.executable, "-m", "robofmu.system.cli"]


def cli(*args, cwd, timeout=300) -> subprocess.CompletedProcess:
    return subprocess.run([*CLI, *map(str, args)], cwd=cwd, capture_output=True, text=True, timeout=timeout)


def sources_unchanged():
    """Skip a check that needs the session's FMUs to match the sources a new process loads (a
    colleague editing components/ during the session makes them stale, rightly)."""
    if components.source_hash(Path(components.__file__).parent) != components.SOURCE_HASH:
        pytest.skip("robofmu.components changed during the session: the session's FMUs are stale")


def stale_copy(src: Path, dst: Path) -> None:
    """``src`` with the vendor annotation's source hash changed (built from other sources)."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                data = data.replace(f'source="{components.SOURCE_HASH}"'.encode(), b'source="' + b"0" * 64 + b'"')
            zout.writestr(item, data)


@pytest.fixture(scope="module")
def work(tmp_path_factory, fmu_root):
    """A working folder with the files the mistakes need, and a broken copy of the FMUs."""
    root = tmp_path_factory.mktemp("cli")
    files = {
        "syntax.toml": 'name = "x"\nstep = \n',
        "unterminated.toml": 'name = "x"\nconnections = [\n',
        "noblocks.toml": 'name = "x"\nrobot = "chess"\n',
        "nofmu.toml": 'name = "x"\n[[blocks]]\nname = "plant"\n',
        "noblockname.toml": 'name = "x"\n[[blocks]]\nfmu = "chess/plant.fmu"\n',
        "noname.toml": 'base = "chess-loop"\n',
        "steptype.toml": 'name = "x"\nstep = "fast"\n[[blocks]]\nname = "plant"\nfmu = "chess/plant.fmu"\n',
        "blockstype.toml": 'name = "x"\nblocks = 3\n',
        "unknownkey.toml": 'name = "x"\nstoptime = 3.0\nbase = "chess-loop"\n',
        "nobase.toml": 'name = "x"\nbase = "no-such-base"\n',
        "robot.toml": 'name = "x"\nrobot = "no-such-robot"\nbase = "chess-loop"\n',
        "role.toml": 'name = "x"\nbase = "chess-loop"\n[roles]\nspeed = "plant.qd"\n',
        "wire.toml": 'name = "x"\nbase = "chess-loop"\nconnections = ["plant.q controller.q"]\n',
        "badvariable.toml": 'name = "x"\nbase = "chess-loop"\nconnections = ["plant.qq -> controller.q"]\n',
        "roleoutput.toml": 'name = "x"\nbase = "chess-loop"\n[roles]\nq = "plant.qq"\nq_ref = "ik.q_ref"\n'
                           'tau = "controller.tau"\n',
        "afile": "not a folder\n",
    }
    for name, text in files.items():
        (root / name).write_text(text)
    (root / "mine").mkdir()
    (root / "mine" / "notes.txt").write_text("my notes\n")
    broken = root / "broken"
    shutil.copytree(fmu_root, broken)
    (broken / "rpp" / "fk.fmu").unlink()
    stale_copy(fmu_root / "chess" / "ik.fmu", broken / "chess" / "ik.fmu")
    return root


def readonly_target(root: Path) -> Path:
    """A folder that cannot be created (root ignores permission bits, not /sys)."""
    if os.geteuid() != 0:
        locked = root / "locked"
        locked.mkdir(exist_ok=True)
        locked.chmod(0o555)
        return locked / "out"
    return Path("/sys/robofmu-cli-test/out")


#: id -> (arguments, fragments the one line must contain). ``{fmus}``, ``{broken}`` and
#: ``{readonly}`` are filled in; every command runs in the ``work`` folder.
MISTAKES = {
    "unknown-experiment": (["run", "no-such-experiment"], ["unknown experiment 'no-such-experiment'",
                                                           "available: 3rrp-circle, 3rrp-disturbance, ", ", chess-pd, "]),
    "missing-file": (["run", "missing.toml"], ["missing.toml: no such experiment file"]),
    "syntax-error": (["run", "syntax.toml"], ["syntax.toml: invalid TOML", "line 2"]),
    "syntax-error-at-end": (["run", "unterminated.toml"], ["unterminated.toml: invalid TOML", "line 3"]),
    "no-blocks": (["run", "noblocks.toml"], ["noblocks.toml: blocks: missing key"]),
    "block-without-fmu": (["run", "nofmu.toml"], ["nofmu.toml: blocks[1].fmu: missing key", "'plant'"]),
    "block-without-name": (["run", "noblockname.toml"], ["noblockname.toml: blocks[1].name: missing key"]),
    "no-name": (["run", "noname.toml"], ["noname.toml: name: missing key"]),
    "wrong-type": (["run", "steptype.toml"], ["steptype.toml: step: must be", "'fast' (a string)"]),
    "blocks-not-tables": (["run", "blockstype.toml"], ["blockstype.toml: blocks: must be"]),
    "unknown-key": (["run", "unknownkey.toml"], ["unknownkey.toml: stoptime: unknown key", "'stop_time'"]),
    "base-missing": (["run", "nobase.toml"], ["nobase.toml: base: no experiment 'no-such-base'", "chess-loop"]),
    "unknown-robot": (["run", "robot.toml"], ["robot.toml: robot: unknown robot 'no-such-robot'"]),
    "unknown-role": (["run", "role.toml"], ["role.toml: roles: unknown role 'speed'"]),
    "malformed-connection": (["run", "wire.toml"], ["wire.toml: connections[1]", "plant.q controller.q"]),
    "step-zero": (["run", "chess-pd", "--step-size", "0"], ["--step-size 0: must be a finite time > 0 s"]),
    "step-negative": (["run", "chess-pd", "--step-size", "-0.001"], ["--step-size -0.001: must be"]),
    "step-nan": (["run", "chess-pd", "--step-size", "nan"], ["--step-size nan: must be"]),
    "stop-infinite": (["run", "chess-pd", "--stop-time", "inf"], ["--stop-time inf: must be"]),
    "stop-zero": (["run", "chess-pd", "--stop-time", "0"], ["--stop-time 0: must be"]),
    "stop-not-whole": (["run", "chess-pd", "--stop-time", "0.0105", "--fmus", "{fmus}"],
                       ["--stop-time 0.0105 s is not a whole number of steps", "chess-pd.toml"]),
    "step-not-dividing": (["run", "chess-pd", "--step-size", "0.003", "--fmus", "{fmus}"],
                          ["stop time 13 s", "--step-size 0.003 s", "give --stop-time"]),
    "stop-below-step": (["run", "chess-pd", "--stop-time", "0.0004", "--fmus", "{fmus}"], ["--stop-time 0.0004 s is shorter"]),
    "too-many-steps": (["run", "chess-pd", "--step-size", "1e-9", "--stop-time", "1000", "--fmus", "{fmus}"],
                       ["--step-size 1e-09, --stop-time 1000", "1000000000000 steps x {signals} recorded signals", "memory"]),
    "absurd-steps": (["run", "chess-pd", "--step-size", "1e-300", "--stop-time", "1e300"], ["--step-size 1e-300", "steps"]),
    "out-is-a-file": (["run", "chess-pd", "--out", "afile", "--fmus", "{fmus}"],
                      ["--out afile: exists and is a file, not a folder"]),
    "out-under-a-file": (["run", "chess-pd", "--out", "afile/results", "--fmus", "{fmus}"],
                         ["--out afile/results:", "afile is a file, not a folder"]),
    "out-not-writable": (["run", "chess-pd", "--stop-time", "0.01", "--out", "{readonly}", "--fmus", "{fmus}"],
                         ["--out {readonly}:"]),
    "out-holds-other-files": (["run", "chess-pd", "--out", "mine", "--fmus", "{fmus}"],
                              ["--out mine: holds notes.txt, not written by robofmu"]),
    "out-is-the-current-folder": (["run", "chess-pd", "--out", ".", "--fmus", "{fmus}"],
                                  ["--out .: is the current folder"]),
    "fmu-folder-missing": (["run", "chess-pd", "--fmus", "no-fmus"],
                           ["--fmus no-fmus: no such folder", "robofmu build --out no-fmus"]),
    "fmu-missing": (["run", "rpp-bangbang", "--fmus", "{broken}"], ["--fmus {broken}: no rpp/fk.fmu",
                                                                     "robofmu build rpp"]),
    "fmu-stale": (["run", "chess-pd", "--fmus", "{broken}"], ["chess/ik.fmu", "built from other robofmu sources",
                                                               "robofmu build chess"]),
    "diagram-refused": (["run", "badvariable.toml", "--fmus", "{fmus}"],
                        ["badvariable.toml: the diagram cannot run", "plant has no variable 'qq'"]),
    "role-names-no-output": (["run", "roleoutput.toml", "--fmus", "{fmus}"],
                             ["roleoutput.toml: roles.q: 'plant.qq' names no output of plant"]),
    "build-unknown-robot": (["build", "no-such-robot", "--out", "built"],
                            ["robofmu build: unknown robot 'no-such-robot'; described robots: 3rrp, chess"]),
    "build-out-is-a-file": (["build", "--out", "afile"], ["robofmu build: --out afile: exists and is a file"]),
    "ssp-unknown-experiment": (["ssp", "no-such-experiment"], ["robofmu ssp: unknown experiment"]),
    "ssp-out-is-a-folder": (["ssp", "chess-pd", "--fmus", "{fmus}", "--out", "mine"],
                            ["robofmu ssp: --out mine: is a folder"]),
    "ssp-fmu-folder-missing": (["ssp", "chess-pd", "--fmus", "no-fmus"], ["robofmu ssp: --fmus no-fmus: no such "
                                                                          "folder", "robofmu build"]),
    "step-unknown-robot": (["step", "--robot", "no-such-robot"], ["robofmu step: --robot: unknown robot"]),
    "demo-fmu-folder-missing": (["demo", "--fmus", "no-fmus", "--out", "demo"],
                                ["robofmu demo: --fmus no-fmus: no such folder", "robofmu build --out no-fmus"]),
    "demo-out-holds-other-files": (["demo", "--fmus", "{fmus}", "--out", "mine"],
                                   ["robofmu demo: --out mine: holds notes.txt"]),
}


def _fill(text: str, values: dict) -> str:
    for key, value in values.items():
        text = text.replace("{" + key + "}", str(value))
    return text


@pytest.fixture(scope="module")
def answers(work, fmu_root):
    """Every mistake's CompletedProcess (and the fragments to look for), run concurrently."""
    from robofmu.system import experiment
    from robofmu.system.plan import plan

    signals = len(plan(experiment.load("chess-pd", fmu_dir=fmu_root)).recorded)     # what chess-pd records
    values = {"fmus": fmu_root, "broken": work / "broken", "readonly": readonly_target(work), "signals": signals}
    cases = {name: ([_fill(a, values) for a in args], [_fill(f, values) for f in fragments])
             for name, (args, fragments) in MISTAKES.items()}
    with ThreadPoolExecutor(max_workers=4) as pool:
        futures = {name: pool.submit(cli, *args, cwd=work) for name, (args, _) in cases.items()}
        return {name: (futures[name].result(), cases[name][1]) for name in cases}


@pytest.mark.slow
@pytest.mark.parametrize("case", list(MISTAKES))
def test_a_mistake_is_one_line_naming_it_with_status_2(answers, case, work):
    if "{fmus}" in MISTAKES[case][0]:
        sources_unchanged()              # else the FMUs are (rightly) refused as stale first
    done, fragments = answers[case]
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr
    assert len(lines) == 1, done.stderr
    command = MISTAKES[case][0][0]
    assert lines[0].startswith(f"robofmu {command}: ")
    for fragment in fragments:
        assert fragment in lines[0]
    assert not list(work.glob(".*.robofmu-*"))          # nothing was started: no temporary folder


def test_argparse_mistakes_keep_the_usage_line(work):
    done = cli("run", "chess-pd", "--step-size", "fast", cwd=work)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert done.stderr.splitlines()[0].startswith("usage: robofmu run")
    assert done.stderr.splitlines()[-1] == "robofmu run: error: argument --step-size: invalid float value: 'fast'"


@pytest.mark.slow
def test_a_user_file_builds_on_a_packaged_base_and_replaces_the_folder(work, fmu_root):
    """A file outside the package names a packaged experiment (itself built on a packaged base) as
    its base; the run replaces an earlier run's folder whole (no stale figure stays)."""
    sources_unchanged()
    user = work / "elsewhere" / "softer.toml"
    user.parent.mkdir()
    user.write_text('name = "softer"\nbase = "chess-pd"\n[parameters.controller]\nkp = 300.0\n')
    out = work / "runs" / "softer"
    out.mkdir(parents=True)
    for stale in ("results.csv", "report.md", "task_reference.png", "old_figure.png"):
        (out / stale).write_text("from an earlier run\n")
    done = cli("run", user, "--stop-time", "0.01", "--out", out, "--fmus", fmu_root, cwd=work)
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    names = sorted(p.name for p in out.iterdir())
    assert "old_figure.png" not in names
    assert {"results.csv", "report.md", "tracking.png"} <= set(names)
    assert not list(out.parent.glob(".softer.*"))          # the temporary sibling was swapped in
    result = Result.from_csv(out / "results.csv")
    assert len(result.time) == 11 and result.time[-1] == pytest.approx(0.01)
    assert (out / "report.md").read_text().startswith("# softer")


@pytest.mark.slow
def test_ctrl_c_stops_at_a_communication_point_and_keeps_the_results(work, fmu_root):
    sources_unchanged()
    out = work / "interrupted"
    process = subprocess.Popen([*CLI, "run", "chess-pd", "--stop-time", "40", "--out", str(out), "--fmus",
                                str(fmu_root)], cwd=work, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    seen = []
    for line in process.stderr:                  # the progress line: the run is stepping
        seen.append(line)
        if "%" in line:
            break
    process.send_signal(signal.SIGINT)
    stdout, rest = process.communicate(timeout=120)
    stderr = "".join(seen) + rest
    assert process.returncode == 130, stderr
    for bad in ("Traceback", "Segmentation fault", "corrupted", "Fatal Python error"):
        assert bad not in stderr
    (line,) = [line for line in stderr.splitlines() if line.startswith("robofmu run:")]
    assert line.startswith("robofmu run: interrupted at t = ") and str(out / "results.csv") in line
    result = Result.from_csv(out / "results.csv")
    assert 1 < len(result.time) < 40001
    np.testing.assert_allclose(np.diff(result.time), 1e-3, rtol=1e-6)
    assert f"t = {result.time[-1]:.9g} s" in line
    report = (out / "report.md").read_text()
    assert "Interrupted" in report and f"{len(result.time)} points" in report
    assert sorted(p.name for p in out.iterdir()) == ["report.md", "results.csv"]


def test_master_stops_on_sigint_and_restores_the_handler(fmu_root):
    """In process: SIGINT during the run raises Interrupted with the points so far; the FMUs are
    freed and the previous handler is back."""
    system = experiment.load("rrp-line", fmu_dir=fmu_root)
    before = signal.getsignal(signal.SIGINT)
    calls = []

    def progress(fraction, t):
        calls.append(t)
        if len(calls) == 2:
            os.kill(os.getpid(), signal.SIGINT)

    master = Master(system, progress=progress)
    with pytest.raises(Interrupted) as info:
        master.run(stop_time=1.0)
    err = info.value
    assert signal.getsignal(signal.SIGINT) is before and master.blocks == {}
    assert err.block is None and err.result is not None
    assert err.time == pytest.approx(err.result.time[-1]) and calls[1] <= err.time < 1.0
    assert "interrupted at t = " in str(err)


def test_record_selection_exact_names_vector_bases_patterns(fmu_root):
    columns = ["plant.q[1]", "plant.q[2]", "plant.qd[1]", "controller.tau[1]", "trajectory.grip"]
    assert select(columns, ["plant.q[2]"]) == [1]              # not a character class
    assert select(columns, ["plant.q"]) == [0, 1]              # a vector base, not plant.qd
    assert select(columns, ["*.tau*", "trajectory.grip"]) == [3, 4]
    system = experiment.load("chess-pd", fmu_dir=fmu_root)
    result = Master(system, record=["plant.q[2]", "controller.tau", "trajectory.g*"]).run(stop_time=0.005)
    assert result.columns == ["plant.q[2]", "controller.tau[1]", "controller.tau[2]", "controller.tau[3]",
                              "controller.tau[4]", "trajectory.grip"]
    assert result.data.shape == (6, 6)
    with pytest.raises(DiagramError) as info:
        Master(system, record=["plant.q", "plant.q[9]", "plnt.*"]).check()
    text = str(info.value)
    assert ("record: 'plant.q[9]' names no output (outputs of plant: plant.q[1..4], plant.qd[1..4], plant.within_limits, "
            "plant.q_measured[1..4], plant.qd_measured[1..4])") in text
    assert "record: 'plnt.*' names no output (outputs: trajectory.x_ref[1..3]" in text
    assert "'plant.q'" not in text


@pytest.mark.slow
def test_doctor_on_good_fmus(fmu_root, tmp_path):
    sources_unchanged()
    done = cli("doctor", "--fmus", fmu_root, cwd=tmp_path)
    assert done.returncode == 0, done.stdout + done.stderr
    text = done.stdout
    assert "Traceback" not in done.stderr
    assert f"python      {sys.executable}" in text
    assert "LD_PRELOAD" not in text
    n = sum(1 for _ in fmu_root.glob("*/*.fmu"))
    assert (f"  ok       {n} FMUs recording Python {sys.version_info.major}.{sys.version_info.minor} "
            f"(program {sys.executable}, libpython ") in text
    assert "a host that is not Python loads them with no environment variable" in text
    for package in ("numpy", "pin", "scipy"):
        assert f"  ok       {package} " in text
    assert "imported as pinocchio: the FMUs import it" in text
    assert f"built from these sources ({components.SOURCE_HASH[:12]})" in text
    assert "instantiates and steps through fmpy" in text
    assert "problem" not in text and text.rstrip().endswith("everything checks")


@pytest.mark.slow
def test_doctor_names_a_stale_and_a_missing_fmu(work, tmp_path):
    broken = work / "broken"
    done = cli("doctor", "--fmus", broken, cwd=tmp_path)
    assert done.returncode == 1, done.stdout + done.stderr
    problems = [line for line in done.stdout.splitlines() if line.startswith("  problem: ")]
    assert any(f"{broken / 'rpp' / 'fk.fmu'}: missing; build it: robofmu build rpp" in p for p in problems)
    assert any(f"{broken / 'chess' / 'ik.fmu'}: stale" in p and "robofmu build chess" in p for p in problems)
    assert done.stdout.rstrip().endswith(f"{len(problems)} problems")
    missing_folder = cli("doctor", "--fmus", tmp_path / "none", cwd=tmp_path)
    assert missing_folder.returncode == 1 and "no such folder" in missing_folder.stdout


# -- interruptions through the Python API and the CLI keep what was recorded ------------------------
def test_run_experiment_refuses_an_infinite_stop_time_naming_it(fmu_root, tmp_path):
    from robofmu.system.run import UsageError, run_experiment

    with pytest.raises(UsageError) as info:
        run_experiment("rrp-line", tmp_path / "out", fmu_dir=fmu_root, stop_time=float("inf"), progress=False)
    assert str(info.value) == "--stop-time inf: must be a finite time > 0 s"
    assert not (tmp_path / "out").exists() and list(tmp_path.iterdir()) == []


def _interrupting_progress(after: int):
    """A progress_printer stand-in raising KeyboardInterrupt at its ``after``-th call."""
    def printer(label, stream=None):
        calls = []

        def show(fraction, t):
            calls.append(t)
            if len(calls) == after:
                raise KeyboardInterrupt
        return show
    return printer


def test_run_experiment_interrupted_keeps_the_rows_on_the_exception_and_on_disk(fmu_root, tmp_path, monkeypatch):
    """Python API: a KeyboardInterrupt in the progress callback (its 2nd call, after the step to
    0.01 s) raises Interrupted whose result holds the rows t = 0 .. 0.009 s of an uninterrupted
    run; out_dir holds them as results.csv and a report saying so."""
    import robofmu.system.run as runner

    sources_unchanged()
    reference = Master(experiment.load("rrp-line", fmu_dir=fmu_root)).run(stop_time=0.1)
    monkeypatch.setattr(runner, "progress_printer", _interrupting_progress(2))
    out = tmp_path / "out"
    with pytest.raises(Interrupted) as info:
        runner.run_experiment("rrp-line", out, fmu_dir=fmu_root, stop_time=0.1, progress=True)
    err = info.value
    assert str(err) == (f"interrupted at t = 0.009 s (KeyboardInterrupt); results up to t = 0.009 s in "
                        f"{out / 'results.csv'} (report: {out / 'report.md'})")
    assert len(err.result.time) == 10
    np.testing.assert_array_equal(err.result.data, reference.data[:10])
    np.testing.assert_array_equal(Result.from_csv(out / "results.csv").data, reference.data[:10])
    assert (out / "report.md").read_text() == ("# rrp-line\n\nInterrupted at t = 0.009 s (KeyboardInterrupt); "
                                               "results.csv holds the 10 points up to t = 0.009 s; no figures.\n")
    assert sorted(p.name for p in out.iterdir()) == ["report.md", "results.csv"]


def test_cli_run_interrupted_inside_a_block_exits_130_keeping_the_rows(fmu_root, tmp_path, monkeypatch, capsys):
    """`robofmu run` (in process), the plant's step from 0.02 s interrupted: one line, exit 130,
    the rows t = 0 .. 0.02 s kept."""
    from robofmu.components.blocks import block_type
    from robofmu.components.robots import load_description
    from robofmu.system import cli as command

    sources_unchanged()
    reference = Master(experiment.load("rrp-line", fmu_dir=fmu_root)).run(stop_time=0.1)
    cls = block_type(load_description("rrp"), "plant")
    original = cls.advance

    def advance(self, t, h):
        if t >= 0.02 - 1e-12:
            raise KeyboardInterrupt
        return original(self, t, h)

    monkeypatch.setattr(cls, "advance", advance)
    out = tmp_path / "out"
    status = command.main(["run", "rrp-line", "--stop-time", "0.1", "--out", str(out), "--fmus", str(fmu_root)])
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("robofmu")]
    assert status == 130 and "Traceback" not in err
    assert lines == [f"robofmu run: interrupted at t = 0.02 s (KeyboardInterrupt in plant's fmi2DoStep); results up "
                     f"to t = 0.02 s in {out / 'results.csv'} (report: {out / 'report.md'})"]
    np.testing.assert_array_equal(Result.from_csv(out / "results.csv").data, reference.data[:21])


def test_run_experiment_interrupted_writing_the_results_keeps_them_on_the_exception(fmu_root, tmp_path, monkeypatch):
    """Ctrl-C while the complete results are written: the folder is left as it was (a file cut
    short is not swapped in) and the exception carries all 101 points."""
    import robofmu.system.run as runner

    sources_unchanged()

    def write(self, path):
        raise KeyboardInterrupt

    monkeypatch.setattr(runner.Result, "write", write)
    out = tmp_path / "out"
    with pytest.raises(Interrupted) as info:
        runner.run_experiment("rrp-line", out, fmu_dir=fmu_root, stop_time=0.1, progress=False, figures=False)
    err = info.value
    assert str(err) == (f"interrupted while writing the complete results; {out} untouched (the exception's result "
                        "holds them)")
    assert len(err.result.time) == 101 and err.time == pytest.approx(0.1)
    assert not out.exists() and not list(tmp_path.glob(".out.robofmu-*"))

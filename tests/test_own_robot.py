"""A robot and an experiment of one's own, outside the package, and FMUs that bundle only their
own robot's data (issue 22, point 6).

- A robot is a package robot's name or the path of a robot TOML anywhere
  (``load_description``, ``robofmu build PATH/robot.toml``); an experiment's ``robot`` may be such a
  path, relative to the experiment file, and its ``robot:`` references resolve against it.
- A FMU bundles the code of ``robofmu.components`` (no robot's data folder) and its own robot's
  TOML and URDF in ``resources/robot/``; the code hash (``SOURCE_HASH``) covers the code only, so
  adding a robot leaves every other robot's FMUs valid, and a FMU runs with its robot's folder
  gone.
- ``robofmu build`` says which FMUs already built are stale and why; ``robofmu run`` refuses a
  FMU whose robot data changed.

The outside robot is planar2r under a new name (``myarm``, its URDF renamed too) with another
pd gain; its experiment is planar2r-nr's. Its run equals the package robot's run of
planar2r-nr with that gain set, to the last bit.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import numpy as np
import pytest

import robofmu.components as components
from robofmu.components import SOURCE_HASH, robot_data_hash, source_hash
from robofmu.components.robots import (ROBOTS_DIR, available, description_path, is_robot_file, load_description,
                                       load_model)
from robofmu.system import experiment
from robofmu.system.experiment import ExperimentError
from robofmu.system.fmu import block_identity, stale_reasons

CLI = [sys.executable, "-m", "robofmu.system.cli"]
KP = 300.0             # myarm's pd gain (planar2r's: 400), reached through "robot:gains.pd.kp"


def cli(*args, cwd, env=None, timeout=600) -> subprocess.CompletedProcess:
    return subprocess.run([*CLI, *map(str, args)], cwd=cwd, capture_output=True, text=True, timeout=timeout,
                          env=env)


def write_robot(folder: Path, name: str = "myarm", source: str = "planar2r", kp: float = KP) -> Path:
    """``folder/<name>.toml`` + ``folder/arm.urdf``: the package robot ``source`` renamed, with its
    pd gain set to ``kp``."""
    folder.mkdir(parents=True, exist_ok=True)
    original = load_description(source)
    shutil.copyfile(original.urdf, folder / "arm.urdf")
    text = original.path.read_text()
    assert f'name = "{source}"' in text and f'urdf = "{source}.urdf"' in text and "kp = 400.0" in text
    text = (text.replace(f'name = "{source}"', f'name = "{name}"', 1)
                .replace(f'urdf = "{source}.urdf"', 'urdf = "arm.urdf"', 1)
                .replace("kp = 400.0", f"kp = {kp!r}", 1))
    toml = folder / f"{name}.toml"
    toml.write_text(text)
    return toml


def write_experiment(path: Path, robot: str, name: str = "myexp", fmu_folder: str = "myarm") -> Path:
    """planar2r-nr's experiment, written out block by block (its explicit form, test data: the
    packaged one derives its wiring), with ``robot`` (as written in the file) and its FMUs under
    ``fmu_folder/``."""
    text = (Path(__file__).parent / "data" / "explicit_experiments" / "planar2r-nr.toml").read_text()
    for old, new in (('name = "planar2r-nr"', f'name = "{name}"'), ('robot = "planar2r"', f'robot = "{robot}"'),
                     ('fmu = "planar2r/', f'fmu = "{fmu_folder}/')):
        assert old in text
        text = text.replace(old, new)
    assert '"robot:gains.pd.kp"' in text
    path.write_text(text)
    return path


def sources_unchanged():
    """Skip a check that needs FMUs built earlier in the session to match the code a new process
    loads (a colleague editing components/ during the session makes them stale, rightly)."""
    if source_hash(Path(components.__file__).parent) != SOURCE_HASH:
        pytest.skip("robofmu.components changed during the session: the session's FMUs are stale")


def one_line_error(done: subprocess.CompletedProcess, command: str, *fragments: str) -> str:
    """The one line a command printed when it refused, exit status 2; checked."""
    assert done.returncode == 2, done.stdout + done.stderr
    assert "Traceback" not in done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"robofmu {command}: "), done.stderr
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    return lines[0]


# -- robots by path, in-process ---------------------------------------------------------------------
def test_a_robot_is_a_name_or_a_robot_toml_path(tmp_path, monkeypatch):
    toml = write_robot(tmp_path / "myarm")
    assert not is_robot_file("planar2r") and is_robot_file("myarm.toml") and is_robot_file("arms/myarm")
    assert is_robot_file(Path("myarm"))
    monkeypatch.chdir(tmp_path)
    for given in (toml, str(toml), "myarm/myarm.toml", "./myarm/myarm.toml"):
        description = load_description(given)
        assert description.name == "myarm" and description.urdf == (tmp_path / "myarm" / "arm.urdf").resolve()
        assert description.gains["pd"].kp == KP
        assert description_path(given).resolve() == toml.resolve()
    assert load_description("myarm/myarm.toml") is load_description(toml)       # cached per file
    assert "myarm" not in available() and "planar2r" in available()            # available(): the package's
    assert load_description("planar2r").path == ROBOTS_DIR / "planar2r" / "planar2r.toml"


def test_a_missing_robot_file_is_one_line_naming_it(tmp_path):
    (tmp_path / "myarm").mkdir()
    with pytest.raises(ValueError, match=r"^no such robot file .*nothere[/\\]arm\.toml$"):
        load_description(str(tmp_path / "nothere" / "arm.toml"))
    with pytest.raises(ValueError, match=r"^no such robot file arm\.toml$"):
        description_path("arm.toml")
    with pytest.raises(ValueError, match=r"myarm: is a folder; give its robot TOML"):
        load_description(tmp_path / "myarm")
    with pytest.raises(ValueError, match=r"^unknown robot 'nosuch'; known robots: .*planar2r"):
        load_description("nosuch")


def test_an_experiments_robot_path_is_relative_to_the_file(tmp_path, monkeypatch):
    """``robot = "myarm/myarm.toml"`` beside the experiment, loaded from another working folder;
    ``robot:`` references resolve against that robot; a file building on it as a base, elsewhere,
    keeps it."""
    toml = write_robot(tmp_path / "mine" / "myarm")
    path = write_experiment(tmp_path / "mine" / "myexp.toml", "myarm/myarm.toml")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    system = experiment.load(Path("..") / "mine" / "myexp.toml")
    assert Path(system.extra["robot"]) == toml and Path(system.extra["robot"]).is_absolute()
    assert system.block("controller").parameters["kp"] == KP
    (elsewhere / "variant.toml").write_text(f'name = "variant"\nbase = "{path}"\n[parameters.controller]\nkd = 30.0\n')
    variant = experiment.load("variant.toml")
    assert Path(variant.extra["robot"]) == toml and variant.block("controller").parameters["kd"] == 30.0
    (elsewhere / "bad.toml").write_text(f'name = "bad"\nbase = "{path}"\nrobot = "nothere/arm.toml"\n')
    with pytest.raises(ExperimentError) as refused:
        experiment.load("bad.toml")
    assert str(refused.value) == f"bad.toml: robot: no such robot file {elsewhere / 'nothere' / 'arm.toml'}"


# -- the code hash and robot data -----------------------------------------------------------------------
def package_copy(root: Path) -> Path:
    """A copy of the installed robofmu (components and system) under ``root/robofmu``; returns
    the copy's ``components`` folder."""
    package = Path(components.__file__).parent
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    shutil.copytree(package, root / "robofmu" / "components", ignore=ignore)
    shutil.copytree(Path(experiment.__file__).parent, root / "robofmu" / "system", ignore=ignore)
    return root / "robofmu" / "components"


def test_adding_or_changing_a_robot_leaves_the_code_hash(tmp_path):
    """The code hash covers the code only: a copy of the package with a robot added, and another
    robot's TOML changed, hashes as before; a change of code does not. (The hash of every .py,
    .toml and .urdf file under the package, as before, changed with any robot.)"""
    copy = package_copy(tmp_path)
    before = source_hash(copy)
    write_robot(copy / "robots" / "newarm", name="newarm")
    (copy / "robots" / "rrp" / "rrp.toml").write_text((copy / "robots" / "rrp" / "rrp.toml").read_text() + "\n# changed\n")
    assert source_hash(copy) == before
    assert not [p for p in components.code_files(copy) if p.suffix != ".py" or p.parts[:2] == ("robots", "rrp")]
    (copy / "control.py").write_text((copy / "control.py").read_text() + "\n# a change of code\n")
    assert source_hash(copy) != before


def test_robot_data_hash_is_the_content_not_the_names(tmp_path):
    """The robot's files where they are described and the copies a FMU carries under other
    names hash alike; either file's content changes it."""
    description = load_description("planar2r")
    toml, urdf = tmp_path / "x.toml", tmp_path / "y.urdf"
    shutil.copyfile(description.path, toml)
    shutil.copyfile(description.urdf, urdf)
    reference = robot_data_hash(description.path, description.urdf)
    assert robot_data_hash(toml, urdf) == reference != robot_data_hash(toml)
    urdf.write_text(urdf.read_text() + "\n")
    assert robot_data_hash(toml, urdf) != reference


# -- a robot folder outside the repository, through the command line -------------------------------------
@pytest.fixture(scope="module")
def own(tmp_path_factory):
    """A working folder outside the repository: ``myarm/myarm.toml`` + ``myarm/arm.urdf``,
    ``myexp.toml`` beside them, and ``robofmu build ./myarm/myarm.toml --out fmus`` run there."""
    root = tmp_path_factory.mktemp("own")
    write_robot(root / "myarm")
    write_experiment(root / "myexp.toml", "myarm/myarm.toml")
    done = cli("build", "./myarm/myarm.toml", "--out", "fmus", cwd=root)
    assert done.returncode == 0, done.stdout + done.stderr
    return root, done


@pytest.mark.slow
def test_build_makes_the_robots_fmus_under_its_name(own):
    root, done = own
    sources_unchanged()
    blocks = load_description(root / "myarm" / "myarm.toml").blocks
    assert sorted(p.name for p in (root / "fmus" / "myarm").iterdir()) == sorted(f"{b}.fmu" for b in blocks)
    for block in blocks:
        assert f"built fmus/myarm/{block}.fmu  (model identifier robofmu_myarm_{block})" in done.stdout
        identity = block_identity(root / "fmus" / "myarm" / f"{block}.fmu")
        assert identity["robot"] == "myarm" and identity["source"] == SOURCE_HASH
        assert stale_reasons(root / "fmus" / "myarm" / f"{block}.fmu", load_description(root / "myarm" / "myarm.toml")) == []
    assert "stale" not in done.stdout and "up to date" not in done.stdout       # nothing was there before


@pytest.mark.slow
def test_the_fmu_carries_its_robot_and_no_other(own):
    """resources/robot/ holds myarm.toml and myarm.urdf (the URDF the TOML names, arm.urdf),
    byte for byte; the bundled package holds code only, no robot's folder, no TOML or URDF."""
    root, _ = own
    for fmu in (root / "fmus" / "myarm").glob("*.fmu"):
        with zipfile.ZipFile(fmu) as archive:
            names = archive.namelist()
            assert sorted(n for n in names if n.startswith("resources/robot/")) == \
                ["resources/robot/myarm.toml", "resources/robot/myarm.urdf"]
            assert archive.read("resources/robot/myarm.urdf") == (root / "myarm" / "arm.urdf").read_bytes()
            assert archive.read("resources/robot/myarm.toml") == (root / "myarm" / "myarm.toml").read_bytes()
        data = [n for n in names if n.endswith((".toml", ".urdf")) and not n.startswith("resources/robot/")]
        assert data == [], data
        bundled = {n for n in names if n.startswith("resources/robofmu/components/robots/")}
        assert bundled and all(n.count("/") == 4 and n.endswith(".py") for n in bundled), sorted(bundled)
        for robot in available():
            assert not any(f"/{robot}/" in n or n.endswith(f"/{robot}.toml") for n in names), robot


@pytest.mark.slow
def test_the_fmu_runs_with_its_robot_folder_gone(own):
    """The FMU reads its robot from its own resources: moved away, the robot's folder is not
    needed (fmpy runs the forward kinematics of myarm = planar2r)."""
    from fmpy import simulate_fmu

    root, _ = own
    folder, away = root / "myarm", root / "myarm-away"
    folder.rename(away)
    try:
        rows = simulate_fmu(str(root / "fmus" / "myarm" / "fk.fmu"), stop_time=0.002, step_size=1e-3,
                            start_values={"q[1]": 0.3, "q[2]": -0.4}, output=["x[1]", "x[2]"])
    finally:
        away.rename(folder)
    np.testing.assert_allclose([rows[-1]["x[1]"], rows[-1]["x[2]"]], load_model("planar2r").fk(np.array([0.3, -0.4])),
                               rtol=0, atol=1e-15)


@pytest.mark.slow
def test_the_own_experiment_runs_as_the_package_robots(own, tmp_path):
    """``robofmu run ./myexp.toml --fmus fmus --out out`` in the outside folder equals the package's
    planar2r-nr with controller.kp = 300 (myarm's gain, which its experiment reads as
    robot:gains.pd.kp), every recorded signal to 1e-12 (in fact bit for bit), and tracks."""
    from robofmu.system.packaging.build import build

    root, _ = own
    sources_unchanged()
    mine = cli("run", "./myexp.toml", "--fmus", "fmus", "--out", "out", cwd=root)
    assert mine.returncode == 0, mine.stdout + mine.stderr
    build("planar2r", tmp_path / "fmus", log=lambda *_: None)
    theirs = cli("run", "planar2r-nr", "--fmus", tmp_path / "fmus", "--out", tmp_path / "out",
                 "--set", f"controller.kp={KP}", cwd=tmp_path)
    assert theirs.returncode == 0, theirs.stdout + theirs.stderr
    with open(root / "out" / "results.csv") as f:
        columns = f.readline().strip().split(",")
    with open(tmp_path / "out" / "results.csv") as f:
        assert f.readline().strip().split(",") == columns
    a = np.loadtxt(root / "out" / "results.csv", delimiter=",", skiprows=1)
    b = np.loadtxt(tmp_path / "out" / "results.csv", delimiter=",", skiprows=1)
    assert a.shape == b.shape == (4001, len(columns))
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)
    q = [columns.index(f"plant.q[{j}]") for j in (1, 2)]
    q_ref = [columns.index(f"ik.q_ref[{j}]") for j in (1, 2)]
    assert 1e-6 < np.abs(a[:, q] - a[:, q_ref]).max() < 1e-4          # it tracks (kp 300: about 0.04 mrad)
    assert np.ptp(a[:, q[0]]) > 0.3                                   # and it moved


def shim(folder: Path, version: str) -> Path:
    """A folder whose ``sitecustomize`` makes the installed robofmu's metadata say ``version``
    (as after a bump in pyproject.toml), for a child process's PYTHONPATH."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "sitecustomize.py").write_text(textwrap.dedent(f'''
        import importlib.metadata as metadata
        _version = metadata.version
        metadata.version = lambda name: {version!r} if name == "robofmu" else _version(name)
    '''))
    return folder


@pytest.mark.slow
def test_adding_a_robot_leaves_the_other_robots_fmus_valid(tmp_path):
    """robofmu from a copy of the package (first on the children's path): myarm's FMUs built by
    it stay up to date, code hash and all, once a robot is added to its package's robots folder;
    the children do see the new robot (its FMUs are missing)."""
    copy = package_copy(tmp_path / "copy")
    env = dict(os.environ, PYTHONPATH=str(tmp_path / "copy"))
    root = tmp_path / "work"
    write_robot(root / "myarm")
    built = cli("build", "./myarm/myarm.toml", "--out", "fmus", cwd=root, env=env)
    assert built.returncode == 0, built.stdout + built.stderr
    code = block_identity(root / "fmus" / "myarm" / "ik.fmu")["source"]
    write_robot(copy / "robots" / "newarm", name="newarm", kp=500.0)
    probe = subprocess.run([sys.executable, "-c", "import robofmu.components as c, robofmu.components.robots as r; "
                            "print(c.__file__, c.SOURCE_HASH, 'newarm' in r.available())"],
                           capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120)
    assert probe.stdout.split() == [str(copy / "__init__.py"), code, "True"], probe.stdout + probe.stderr
    blocks = load_description(root / "myarm" / "myarm.toml").blocks
    done = cli("build", "--check", "./myarm/myarm.toml", "newarm", "--out", "fmus", cwd=root, env=env)
    assert done.returncode == 1, done.stdout + done.stderr            # newarm's FMUs are missing
    assert done.stdout.splitlines() == [
        "fmus/myarm: up to date: " + ", ".join(f"{b}.fmu" for b in blocks),
        *(f"fmus/newarm/{b}.fmu: missing" for b in load_description(copy / "robots" / "newarm" / "newarm.toml").blocks)]
    fresh = cli("build", "--check", "./myarm/myarm.toml", "--out", "fmus", cwd=root, env=env)
    assert fresh.returncode == 0 and "stale" not in fresh.stdout, fresh.stdout + fresh.stderr


@pytest.mark.slow
def test_build_says_which_fmus_are_stale_and_why(own, tmp_path):
    """Each FMU in one line with every reason: after a change of the robot's TOML (``robofmu run``
    refuses them, naming the robot), of the code and of robofmu's version, ``--check`` names all
    three; ``robofmu build`` says so before building, and afterwards they are up to date."""
    sources_unchanged()
    root = tmp_path / "mine"
    shutil.copytree(own[0], root, ignore=shutil.ignore_patterns("out"))
    toml = root / "myarm" / "myarm.toml"
    blocks = load_description(toml).blocks
    names = ", ".join(f"{b}.fmu" for b in blocks)
    toml.write_text(toml.read_text().replace('summary = "', 'summary = "My arm: ', 1))
    refused = cli("run", "./myexp.toml", "--fmus", "fmus", "--out", "out", cwd=root)
    one_line_error(refused, "run", "--fmus fmus: myarm/trajectory.fmu, ", "built from other data of robot 'myarm'",
                   f"robofmu build {toml} --out fmus")
    copy = package_copy(tmp_path / "copy")
    (copy / "control.py").write_text((copy / "control.py").read_text() + "\n# a change of code\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(shim(tmp_path / "shim", "9.9.9")), str(tmp_path / "copy")]))
    everything = cli("build", "--check", "./myarm/myarm.toml", "--out", "fmus", cwd=root, env=env)
    assert everything.returncode == 1, everything.stdout + everything.stderr
    assert everything.stdout.splitlines() == \
        [f"fmus/myarm/{b}.fmu: stale: robofmu version changed, code changed, robot data changed" for b in blocks]
    done = cli("build", "./myarm/myarm.toml", "--out", "fmus", cwd=root)
    assert done.returncode == 0, done.stdout + done.stderr
    lines = done.stdout.splitlines()
    assert [line.split(": stale: ")[0] for line in lines[:len(blocks)]] == [f"fmus/myarm/{b}.fmu" for b in blocks]
    assert all(line.endswith("robot data changed") for line in lines[:len(blocks)]), lines
    assert lines[len(blocks)].startswith("myarm: reference checked over 3.5 s (3501 samples): "), lines
    assert all(line.startswith("built fmus/myarm/") for line in lines[len(blocks) + 1:]), lines
    after = cli("build", "--check", "./myarm/myarm.toml", "--out", "fmus", cwd=root)
    assert (after.returncode, after.stdout) == (0, f"fmus/myarm: up to date: {names}\n"), after.stderr


def test_one_line_answers_for_a_missing_robot(tmp_path):
    """A robot TOML path that does not exist, a folder, an unknown name (build), an experiment
    whose robot file does not exist (run): one line naming it, exit status 2."""
    (tmp_path / "myarm").mkdir()
    one_line_error(cli("build", "./nothere/arm.toml", "--out", "fmus", cwd=tmp_path), "build",
                   "no such robot file ./nothere/arm.toml")
    one_line_error(cli("build", "./myarm", cwd=tmp_path), "build", "./myarm: is a folder; give its robot TOML")
    one_line_error(cli("build", "myarn", cwd=tmp_path), "build", "unknown robot 'myarn'", "planar2r",
                   "or give the path of a robot TOML")
    write_experiment(tmp_path / "myexp.toml", "nothere/arm.toml")
    one_line_error(cli("run", "./myexp.toml", "--fmus", "fmus", cwd=tmp_path), "run",
                   f"myexp.toml: robot: no such robot file {tmp_path / 'nothere' / 'arm.toml'}")
    assert not (tmp_path / "fmus").exists() and not (tmp_path / "results").exists()


#: Run in a child: example-robot-data made unfindable (importlib.metadata), then the ur5 FMU.
_WITHOUT_DISTRIBUTION = textwrap.dedent('''
    import importlib.metadata as metadata, json, sys
    _distribution = metadata.distribution

    def distribution(name):
        if name == "example-robot-data":
            raise metadata.PackageNotFoundError(name)
        return _distribution(name)

    metadata.distribution = distribution
    from robofmu.components.robots import load_description
    try:
        load_description("ur5")
        refused = ""
    except ValueError as exc:
        refused = str(exc)
    import fmpy
    rows = fmpy.simulate_fmu(sys.argv[1], stop_time=0.002, step_size=1e-3)
    print("RESULT " + json.dumps({"refused": refused, "names": list(rows.dtype.names),
                                  "last": [float(v) for v in rows[-1]]}))
''')


@pytest.mark.slow
def test_a_urdf_of_an_installed_distribution_travels_in_the_fmu(tmp_path):
    """ur5's URDF is a file of example-robot-data: the FMU carries it as resources/robot/ur5.urdf,
    and runs where that distribution cannot be found (the same outputs as here)."""
    if "ur5" not in available():
        pytest.skip("no ur5 robot in this checkout")
    from fmpy import simulate_fmu

    from robofmu.system.packaging.build import build

    description = load_description("ur5")
    [fmu] = build("ur5", tmp_path, blocks=["fk"], log=lambda *_: None)
    with zipfile.ZipFile(fmu) as archive:
        assert sorted(n for n in archive.namelist() if n.startswith("resources/robot/")) == \
            ["resources/robot/ur5.toml", "resources/robot/ur5.urdf"]
        assert archive.read("resources/robot/ur5.urdf") == description.urdf.read_bytes()
    assert "example-robot-data" in description.urdf.as_posix() or "cmeel" in description.urdf.as_posix()
    done = subprocess.run([sys.executable, "-c", _WITHOUT_DISTRIBUTION, str(fmu)], capture_output=True, text=True,
                          cwd=tmp_path, timeout=300)
    line = next((line for line in done.stdout.splitlines() if line.startswith("RESULT ")), None)
    assert line is not None, done.stdout + done.stderr
    child = json.loads(line[7:])
    assert "'example-robot-data' is not installed" in child["refused"]
    rows = simulate_fmu(str(fmu), stop_time=0.002, step_size=1e-3)
    assert child["names"] == list(rows.dtype.names) and child["last"] == [float(v) for v in rows[-1]]


# -- robofmu step on a robot of one's own ----------------------------------------------------------------
def myarm(data: dict) -> None:
    """A copy_robot edit: planar2r renamed myarm (the TOML then is myarm.toml), its pd gain KP."""
    data["name"] = "myarm"
    data["gains"]["pd"]["kp"] = KP


def test_the_step_api_takes_a_robot_by_name_path_or_description(copy_robot, tmp_path):
    """step_setup, step_system and default_amplitudes take a robot TOML's path (str or Path) or its
    description as they take a package robot's name: the FMUs are ``<fmu_dir>/myarm/``, and the
    system names the robot again by its TOML's absolute path (a package robot by its name), so a
    missing FMU's message says how to build it."""
    from robofmu.system import stepresponse as sr
    from robofmu.system.usage import UsageError, check_fmu_folder

    toml = copy_robot("planar2r", myarm, stem="myarm")
    assert toml == tmp_path / "planar2r" / "myarm.toml"
    by_name = sr.step_setup("planar2r", joint=2)
    np.testing.assert_array_equal(by_name.q_ref, [0.0, 1.02])           # home (0, 1 rad) + 0.02 rad on q2
    for given in (toml, str(toml), load_description(toml)):
        setup = sr.step_setup(given, joint=2)
        assert setup.robot == "myarm" and setup.joints == [2] and setup.joint_units == ["rad", "rad"]
        np.testing.assert_array_equal(setup.q_ref, by_name.q_ref)
        np.testing.assert_array_equal(sr.default_amplitudes(given), [0.02, 0.02])
        system = sr.step_system(tmp_path / "fmus", KP, 40.0, robot=given, joint=2)
        assert system.name == "myarm-step" and system.extra["robot"] == str(toml.resolve())
        assert [(b.name, str(b.fmu)) for b in system.blocks] == [("controller", "myarm/controller.fmu"),
                                                                 ("plant", "myarm/plant.fmu")]
        assert system.block("controller").parameters["q_ref"] == [0.0, 1.02]
    assert sr.step_system("fmus", 400.0, 40.0, robot="planar2r").extra["robot"] == "planar2r"
    assert sr.step_system("fmus", 400.0, 40.0, robot=ROBOTS_DIR / "planar2r" / "planar2r.toml").extra["robot"] == \
        "planar2r"                                                           # the package's own file: its name
    (tmp_path / "fmus").mkdir()
    with pytest.raises(UsageError) as refused:
        check_fmu_folder(sr.step_system(tmp_path / "fmus", KP, 40.0, robot=toml))
    assert str(refused.value) == (f"--fmus {tmp_path / 'fmus'}: no myarm/controller.fmu, myarm/plant.fmu (for "
                                  f"myarm-step); build them: robofmu build {toml.resolve()} --out {tmp_path / 'fmus'}")

    def open_loop(data):
        myarm(data)
        data["blocks"] = ["trajectory", "ik", "fk"]

    copy_robot("planar2r", open_loop, stem="myarm")
    with pytest.raises(ValueError) as refused:
        sr.step_setup(toml)
    assert str(refused.value) == "robot: 'myarm' has no controller and no plant block (its blocks: trajectory, ik, fk)"


def step_cli(argv, capsys) -> tuple[int, str, str]:
    """(exit status, stdout, stderr) of ``robofmu step ARGV``, in this process (cli.main)."""
    from robofmu.system import cli as command

    status = command.main(["step", *map(str, argv)])
    out, err = capsys.readouterr()
    return status, out, err


def test_step_refuses_a_robot_toml_in_one_line_naming_robot(copy_robot, tmp_path, capsys):
    """``robofmu step --robot PATH``: a path that does not exist, a folder, a TOML with a syntax
    error, a TOML that is not a valid description (its DescriptionError, naming file and key) and a
    robot without controller and plant blocks are each one line naming --robot, status 2, nothing
    run or written."""
    from robot_files import refusal

    fmus, out = tmp_path / "fmus", tmp_path / "out"
    fmus.mkdir()

    def refused(robot) -> str:
        status, stdout, err = step_cli(["--robot", robot, "--fmus", fmus, "--out", out], capsys)
        assert status == 2 and stdout == "" and "Traceback" not in err, (status, stdout, err)
        lines = err.splitlines()
        assert len(lines) == 1 and lines[0].startswith("robofmu step: --robot: "), err
        return lines[0]

    missing = tmp_path / "nothere" / "arm.toml"
    assert refused(missing) == f"robofmu step: --robot: no such robot file {missing}"
    toml = copy_robot("planar2r", myarm, stem="myarm")
    assert refused(toml.parent) == f"robofmu step: --robot: {toml.parent}: is a folder; give its robot TOML"
    broken = tmp_path / "broken" / "broken.toml"
    broken.parent.mkdir()
    broken.write_text('name = "broken"\nsummary = \nblocks = ["controller", "plant"]\n')
    syntax = refusal(broken.resolve(), "(syntax)")
    assert refused(broken) == f"robofmu step: --robot: {syntax}"
    assert syntax == f"{broken.resolve()}: (syntax): Invalid value (at line 2, column 11)"

    def negative_kp(data):
        myarm(data)
        data["gains"]["pd"]["kp"] = -1.0

    copy_robot("planar2r", negative_kp, stem="myarm")
    invalid = refusal(toml.resolve(), "gains.pd.kp")
    assert refused(toml) == f"robofmu step: --robot: {invalid}"
    assert invalid == f"{toml.resolve()}: gains.pd.kp: parameter kp = -1 1/s2 is invalid: must be > 0"

    def open_loop(data):
        myarm(data)
        data["blocks"] = ["trajectory", "ik", "fk"]

    copy_robot("planar2r", open_loop, stem="myarm")
    assert refused(toml) == (f"robofmu step: --robot: {toml}: robot 'myarm' has no controller and plant blocks "
                             "(its blocks: trajectory, ik, fk)")
    assert refused("myarm").startswith("robofmu step: --robot: unknown robot 'myarm'; known robots: ")
    assert list(fmus.iterdir()) == [] and not out.exists()


def build_in_child(robot, out: Path, blocks: list[str], cwd: Path) -> list[Path]:
    """``build(robot, out, blocks=blocks)`` in a new process, returning its paths: the code the FMUs
    bundle is then the code a later ``robofmu`` process runs, even if a colleague edits
    robofmu.components during the session (this process's FMU check would refuse them)."""
    script = ("import sys\nfrom robofmu.system.packaging.build import build\n"
              "for path in build(sys.argv[1], sys.argv[2], blocks=sys.argv[3].split(','), log=lambda *_: None):\n"
              "    print(path)\n")
    done = subprocess.run([sys.executable, "-c", script, str(robot), str(out), ",".join(blocks)], cwd=cwd,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr
    return [Path(line) for line in done.stdout.splitlines()]


@pytest.mark.slow
def test_step_on_a_robot_toml_equals_the_robot_by_name(copy_robot, tmp_path):
    """``robofmu step --robot ./planar2r/myarm.toml --fmus mine`` (planar2r copied outside the
    package as myarm, pd kp 300; its controller and plant built into mine/myarm/) prints the
    table of the package's planar2r stepped with --kp 300 from its own FMUs, but for the robot's
    name, and writes the same CSVs, to the last digit; the step arrives and the sampled-data
    prediction holds to 1 % of the amplitude. With FMUs of another robot only, it says how to
    build its own."""
    toml = copy_robot("planar2r", myarm, stem="myarm")
    blocks = ["controller", "plant"]
    assert build_in_child(toml, tmp_path / "mine", blocks, tmp_path) == \
        [tmp_path / "mine" / "myarm" / f"{b}.fmu" for b in blocks]
    assert build_in_child("planar2r", "theirs", blocks, tmp_path) == [Path("theirs", "planar2r", f"{b}.fmu")
                                                                      for b in blocks]
    common = ["--step-size", "0.005", "--stop-time", "0.6"]
    mine = cli("step", "--robot", "./planar2r/myarm.toml", "--fmus", "mine", "--out", "out-mine", *common,
               cwd=tmp_path)
    theirs = cli("step", "--robot", "planar2r", "--kp", KP, "--fmus", "theirs", "--out", "out-theirs", *common,
                 cwd=tmp_path)
    assert mine.returncode == 0 and theirs.returncode == 0, mine.stderr + theirs.stderr
    *table, wrote = mine.stdout.splitlines()
    *their_table, their_wrote = theirs.stdout.splitlines()
    assert table[0] == ("myarm: step q1 +0.02 rad, q2 +0.02 rad from q0 = (0 rad, 1 rad); kp 300, kd 40, ki 0; "
                        "h 5 ms; algorithm gauss-seidel")
    assert their_table[0] == "planar2r" + table[0][len("myarm"):]
    assert table[1:] == their_table[1:] and table[-1] == "best match: sampled"
    names = ["step_h5ms_cosim.csv", "step_h5ms_compare.csv", "step_h5ms.png"]
    assert wrote == "wrote " + ", ".join(f"out-mine/{name}" for name in names)
    assert their_wrote == "wrote " + ", ".join(f"out-theirs/{name}" for name in names)
    for name in names[:2]:
        assert (tmp_path / "out-mine" / name).read_text() == (tmp_path / "out-theirs" / name).read_text(), name
    with open(tmp_path / "out-mine" / "step_h5ms_compare.csv") as f:
        columns = f.readline().strip().split(",")
    data = np.loadtxt(tmp_path / "out-mine" / "step_h5ms_compare.csv", delimiter=",", skiprows=1)
    assert data.shape == (121, len(columns))                                 # t = 0 .. 0.6 s by 5 ms
    cosim = data[:, [columns.index(f"cosim_q{j} [rad]") for j in (1, 2)]]
    sampled = data[:, [columns.index(f"pred_sampled_q{j} [rad]") for j in (1, 2)]]
    np.testing.assert_allclose(cosim[0], [0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(cosim[-1], [0.02, 0.02], rtol=0.01)           # poles -10, -30 1/s: arrived
    assert 1e-5 < np.abs(cosim - sampled).max() / 0.02 < 0.01                # within 1 % of the amplitude
    one_line_error(cli("step", "--robot", "./planar2r/myarm.toml", "--fmus", "theirs", cwd=tmp_path), "step",
                   "--fmus theirs: no myarm/controller.fmu, myarm/plant.fmu",
                   f"robofmu build {toml.resolve()} --out theirs")

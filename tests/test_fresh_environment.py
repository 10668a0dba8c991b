"""The FMUs in a host that has only what they declare: a fresh virtual environment (``python -m
venv``) with ``pip install -r`` one FMU's ``resources/requirements.txt`` and fmpy (the host's own
tool, not a FMU requirement); robofmu is not installed in it.

In one child process it runs FMUs of three robot families one after another with
``fmpy.simulate_fmu`` (which extracts each FMU to a folder of its own and deletes it after the
run), in both orders, and every FMU of the collection in a shuffled order. The first FMU's bundled
``robofmu.components`` serves every FMU of the process; the generated FMU script imports all its
modules at once (robofmu.components.fmi.bundle), so no module is looked up later in that deleted
folder. Without it (the negative control here: ``pkgutil.walk_packages`` disabled in the child,
so ``import_all`` imports nothing) the second family fails, ``No module named
'robofmu.components.robots.serial'`` (3rrp first) or ``...robots.parallel`` (3rrp last), as
before the fix.

An audit hook (``sys.addaudithook``, event ``open``) in the child records every path Python opens
during each run: no run opens anything under another run's extraction folder (each is known from
the ``tempfile.mkdtemp`` event of fmpy's extraction), and each run does open its own robot's TOML
in its own folder, ``resources/robot/<robot>.toml`` (the hook sees the FMUs' reads; the bundled
package holds no robot's data). Opens by C code (dlopen, pythonfmu's C++)
are not Python's and not seen.

The results are finite, move (the plants fall or are pushed, the IK reaches its target through
the planar 2R model's forward kinematics), and equal the same runs in the project's venv, bit for
bit when both environments have the same numpy, scipy and pin.
"""
from __future__ import annotations

import functools
import json
import os
import random
import subprocess
import sys
import textwrap
import time
import zipfile
from importlib import metadata

import numpy as np
import pytest

from robofmu.components.robots import available, load_description, load_model

pytestmark = pytest.mark.slow

#: (robot, block, start values): robot models from different modules (robots.parallel for 3rrp,
#: robots.serial with Pinocchio for chess and planar2r) and the Newton-Raphson IK solver.
FAMILIES = [
    ("3rrp", "plant", {"tau[1]": 0.01, "qd0[2]": 0.3}),
    ("chess", "plant", {}),
    ("planar2r", "ik", {"x_ref[1]": 1.0, "x_ref[2]": 0.6}),
]
STOP, STEP, INTERVAL = 0.05, 1e-3, 0.01

CHILD = textwrap.dedent('''
    import importlib.metadata, importlib.util, json, os, sys
    mode, runs = sys.argv[1], json.loads(sys.argv[2])
    run = [-1]
    opens, folders = [], {}

    def hook(event, args):
        if event == "open" and isinstance(args[0], (str, bytes)):
            opens.append((run[0], os.fsdecode(args[0])))
        elif event == "tempfile.mkdtemp":
            folders.setdefault(run[0], []).append(args[0])

    versions = {}
    for name in ("numpy", "scipy", "pin", "FMPy"):
        try:
            versions[name] = importlib.metadata.version(name)
        except Exception:
            versions[name] = None
    sys.addaudithook(hook)
    installed = importlib.util.find_spec("robofmu") is not None
    if mode == "control":            # the old FMU script: nothing imported but what is used
        import pkgutil
        pkgutil.walk_packages = lambda *args, **kwargs: iter(())
    import fmpy
    results = []
    for k, (path, start) in enumerate(runs):
        run[0] = k
        try:
            rows = fmpy.simulate_fmu(path, stop_time=%(stop)r, step_size=%(step)r,
                                     output_interval=%(interval)r, start_values=start)
            results.append({"ok": True, "names": list(rows.dtype.names),
                            "rows": [[float(v) for v in row] for row in rows]})
        except Exception as exc:
            results.append({"ok": False, "error": f"{type(exc).__name__}: {exc}"})
        run[0] = None
        results[-1]["folders_left"] = [f for f in folders.get(k, []) if os.path.exists(f)]
    package = sys.modules.get("robofmu.components")
    modules = {name: getattr(m, "__file__", None) for name, m in sys.modules.items()
               if name.startswith("robofmu.components")}
    print("RESULT " + json.dumps({"installed": installed, "results": results, "opens": opens,
                                  "folders": folders, "modules": modules, "versions": versions,
                                  "executable": sys.executable}), flush=True)
''') % {"stop": STOP, "step": STEP, "interval": INTERVAL}


@pytest.fixture(scope="module")
def fresh_python(fmu_root, tmp_path_factory):
    """The python of a fresh venv: one FMU's requirements.txt and fmpy (the version of this venv's,
    the same host tool on both sides), robofmu not installed. pip's cache is the default one."""
    root = tmp_path_factory.mktemp("fresh_env")
    requirements = root / "requirements.txt"
    with zipfile.ZipFile(fmu_root / "chess" / "plant.fmu") as archive:
        requirements.write_bytes(archive.read("resources/requirements.txt"))
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    started = time.perf_counter()
    subprocess.run([sys.executable, "-m", "venv", str(root / "venv")], check=True, env=env, timeout=300)
    python = root / "venv" / "bin" / "python"
    # --no-compile: the children compile the few modules they import (about 20 s less here)
    done = subprocess.run([str(python), "-m", "pip", "install", "--quiet", "--disable-pip-version-check",
                           "--no-compile", "-r", str(requirements), f"fmpy=={metadata.version('fmpy')}"],
                          capture_output=True, text=True, env=env, timeout=1200)
    assert done.returncode == 0, done.stderr[-3000:]
    print(f"\nfresh venv: created and installed in {time.perf_counter() - started:.1f} s")
    probe = subprocess.run([str(python), "-c", "import robofmu"], capture_output=True, text=True,
                           env=env, cwd=root, timeout=60)
    assert probe.returncode != 0 and "No module named 'robofmu'" in probe.stderr
    return python


def _children(jobs, cwd):
    """Run CHILD for each (python, mode, [(fmu, start values)]) at once; their parsed results,
    with the child's exit status and output."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    procs = [subprocess.Popen([str(python), "-X", "faulthandler", "-c", CHILD, mode,
                               json.dumps([[str(p), s] for p, s in runs])],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=cwd, env=env)
             for python, mode, runs in jobs]
    found = []
    for proc in procs:
        out, err = proc.communicate(timeout=600)
        line = next((line for line in out.splitlines() if line.startswith("RESULT ")), None)
        assert line is not None, f"no result (exit status {proc.returncode}):\n{out[-2000:]}\n{err[-3000:]}"
        result = json.loads(line[7:])
        result.update(returncode=proc.returncode, output=out + err)
        found.append(result)
    return found


@functools.lru_cache(maxsize=None)
def _real(path: str) -> str:
    return os.path.realpath(path)


def _under(path: str, folder: str) -> bool:
    path, folder = _real(path), _real(folder)
    return path == folder or path.startswith(folder + os.sep)


def _check_isolation(result, runs):
    """No run opened a file of another run's extraction folder; each opened its own robot's TOML
    in its own; every folder was gone after its run."""
    extraction = {}
    for key, made in result["folders"].items():
        k = int(key)
        # fmpy's extraction folder of run k: the folder made in run k whose resources run k read
        [extraction[k]] = [f for f in made if any(r == k and _under(p, os.path.join(f, "resources"))
                                                   for r, p in result["opens"])]
    assert sorted(extraction) == list(range(len(runs)))
    for k, (fmu, _) in enumerate(runs):
        robot = fmu.parent.name
        toml = os.path.join(extraction[k], "resources", "robot", f"{robot}.toml")
        assert any(r == k and _real(p) == _real(toml) for r, p in result["opens"]), \
            f"run {k} ({fmu}) did not read its robot's TOML from its own folder"
        assert result["results"][k]["folders_left"] == [], f"run {k}'s extraction folder was not deleted"
    crossing = [(r, p) for r, p in result["opens"] for k, folder in extraction.items()
                if r != k and _under(p, folder)]
    assert not crossing, f"opened under another FMU's extraction folder: {crossing[:5]}"
    return extraction


def _sequences(fmu_root):
    families = [(fmu_root / robot / f"{block}.fmu", start) for robot, block, start in FAMILIES]
    everything = sorted(fmu_root.glob("*/*.fmu"))
    random.Random(20261203).shuffle(everything)
    assert len(everything) == sum(len(load_description(robot).fmu_blocks) for robot in available()) >= 29
    return {"families": families, "reversed": families[::-1], "every FMU": [(p, {}) for p in everything]}


def test_fresh_environment_runs_any_mix_of_fmus(fresh_python, fmu_root, tmp_path):
    sequences = _sequences(fmu_root)
    names = list(sequences)
    jobs = [(fresh_python, "fresh", sequences[n]) for n in names] + \
           [(sys.executable, "project", sequences[n]) for n in names]
    started = time.perf_counter()
    done = _children(jobs, tmp_path)
    fresh, project = done[:len(names)], done[len(names):]
    print(f"\n{len(jobs)} child processes in {time.perf_counter() - started:.1f} s")
    same_packages = fresh[0]["versions"] == project[0]["versions"]
    for name, mine, theirs in zip(names, fresh, project):
        runs = sequences[name]
        assert not mine["installed"] and theirs["installed"]
        assert mine["executable"].startswith(str(fresh_python.parent.parent))
        extraction = []
        for result in (mine, theirs):
            failed = [(runs[k][0], r["error"]) for k, r in enumerate(result["results"]) if not r["ok"]]
            assert not failed and result["returncode"] == 0, (failed, result["output"][-3000:])
            extraction.append(_check_isolation(result, runs))
        # the fresh host has no robofmu: the first FMU's bundle served every FMU, all of it imported
        first, modules = extraction[0][0], mine["modules"]
        assert len(modules) >= 30 and {"robofmu.components.robots.serial",
                                       "robofmu.components.robots.parallel"} <= set(modules)
        assert all(_under(f, first) for f in modules.values() if f), (first, modules)
        for k, ((fmu, _), a, b) in enumerate(zip(runs, mine["results"], theirs["results"])):
            assert a["names"] == b["names"]
            rows = np.array(a["rows"])
            assert rows.shape[0] >= 2 and np.isfinite(rows).all(), (fmu, rows)
            if same_packages:
                assert a["rows"] == b["rows"], f"{name}: {fmu} differs from the project venv's run"
            else:
                np.testing.assert_allclose(rows, np.array(b["rows"]), rtol=1e-9, atol=1e-12)
    # the results mean something: the plants move, the IK reaches its target
    results = {(p.parent.name, p.stem): r for (p, _), r in zip(sequences["families"], fresh[0]["results"])}
    rrp3, chess, ik = results["3rrp", "plant"], results["chess", "plant"], results["planar2r", "ik"]
    for plant in (rrp3, chess):          # 3rrp pushed (tau[1], qd0[2]), chess falling under gravity
        q = [plant["names"].index(f"q[{j}]") for j in (1, 2, 3)]
        assert np.abs(np.array(plant["rows"][-1])[q] - np.array(plant["rows"][0])[q]).max() > 1e-4
    planar = load_model("planar2r")
    q = np.array([ik["rows"][-1][ik["names"].index(f"q_ref[{j}]")] for j in (1, 2)])
    np.testing.assert_allclose(planar.fk(q), [1.0, 0.6], atol=1e-9)


def test_negative_control_without_the_eager_import_the_second_family_fails(fresh_python, fmu_root, tmp_path):
    """The old failure is real: with the bundle's eager import disabled in the child, the first
    family's run deletes the folder the package came from and another family's model module is
    then missing."""
    sequences = _sequences(fmu_root)
    forward, backward = _children([(fresh_python, "control", sequences["families"]),
                                   (fresh_python, "control", sequences["reversed"])], tmp_path)
    assert [r["ok"] for r in forward["results"]][:2] == [True, False]
    assert "No module named 'robofmu.components.robots.serial'" in forward["output"]
    assert [r["ok"] for r in backward["results"]] == [True, True, False]
    assert "No module named 'robofmu.components.robots.parallel'" in backward["output"]

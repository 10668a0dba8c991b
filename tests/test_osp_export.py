"""The OSP export (issue 30, point 1): ``OspSystemStructure.xml`` beside the FMUs carries each
block's sample time as its simulator's ``stepSize``; ``robofmu osp`` writes it.

What libcosim makes of the file is tested where libcosim runs (tests/test_libcosim.py: its run
equals the master's Jacobi run at the same rates to 1e-12, and a hand-written sampled loop).
Here: the file itself read back with ElementTree against the experiment (rates, base step,
initial values, the 35 scalar connections of the chess loop, the FMU copies), the times written
so that libcosim's truncation to nanoseconds reads them exactly, and the command's contract.
"""
from __future__ import annotations

import math
import random
from xml.etree import ElementTree as ET

import pytest

from misuse import assert_refused
from robofmu.system import experiment
from robofmu.system.cli import main
from robofmu.system.interop.osp import NS, OSP_FILE, export_osp, is_robofmu_osp, libcosim_ns, osp_seconds

Q = f"{{{NS}}}"


def _chess_pd(fmu_root, sample_time=0.004, delay=2):
    system = experiment.load("chess-pd", fmu_dir=fmu_root)
    system.block("controller").sample_time = sample_time
    system.block("controller").parameters["delay_steps"] = delay
    return system


def test_the_file_carries_each_blocks_rate_its_parameters_and_every_wire(fmu_root, tmp_path):
    system = _chess_pd(fmu_root)
    path = export_osp(system, tmp_path / "osp")
    assert path == tmp_path / "osp" / OSP_FILE and is_robofmu_osp(path)
    root = ET.parse(path).getroot()
    assert root.tag == f"{Q}OspSystemStructure" and root.get("version") == "0.1"
    assert libcosim_ns(root.findtext(f"{Q}BaseStepSize")) == 1_000_000                 # 1 ms
    assert float(root.findtext(f"{Q}EndTime")) == system.stop_time
    assert root.findtext(f"{Q}Algorithm") == "fixedStep"
    simulators = {s.get("name"): s for s in root.iter(f"{Q}Simulator")}
    assert list(simulators) == ["trajectory", "ik", "controller", "plant"]
    steps = {name: libcosim_ns(s.get("stepSize")) for name, s in simulators.items()}
    assert steps == {"trajectory": 1_000_000, "ik": 1_000_000, "controller": 4_000_000, "plant": 1_000_000}
    for name, s in simulators.items():              # byte for byte the experiment's FMU
        assert (path.parent / s.get("source")).read_bytes() == system.fmu_path(system.block(name)).read_bytes()
    initial = {v.get("variable"): (v[0].tag.removeprefix(Q), v[0].get("value"))
               for v in simulators["controller"].iter(f"{Q}InitialValue")}
    gains = system.block("controller").parameters
    assert initial["delay_steps"] == ("Integer", "2")
    for key in ("kp", "kd", "ki", "payload_mass"):
        assert initial[key][0] == "Real" and float(initial[key][1]) == gains[key]
    assert float(initial["kp"][1]) > 0
    assert not simulators["plant"].findall(f"{Q}InitialValues")           # no parameters given
    # x_ref, xd_ref, xdd_ref (3 each), q_ref, qd_ref, qdd_ref (4 each), tau, q, qd (4 each), grip twice
    connections = [tuple((v.get("simulator"), v.get("name")) for v in c) for c in root.iter(f"{Q}VariableConnection")]
    assert len(connections) == 3 * 3 + 3 * 4 + 3 * 4 + 2 == 35
    assert (("controller", "tau[3]"), ("plant", "tau[3]")) in connections
    assert (("plant", "qd[4]"), ("controller", "qd[4]")) in connections
    assert (("trajectory", "grip"), ("controller", "grip")) in connections
    # a file the export did not write is not taken for one
    foreign = tmp_path / "foreign.xml"
    foreign.write_text(path.read_text().replace("<!-- written by robofmu -->", ""))
    assert not is_robofmu_osp(foreign) and not is_robofmu_osp(tmp_path / "missing.xml")


def test_times_are_written_so_that_libcosims_truncation_reads_them_exactly():
    """libcosim reads seconds as trunc(s * 1e9) ns: 0.00013 as written by repr would be 129999 ns."""
    assert math.trunc(0.00013 * 1e9) == 129_999
    rng = random.Random(30)
    times = [0.00013, 1.025, 6.5e-05, 0.001, 0.004, 0.0025, 0.003, 1e-4, 1.5, 0.0]
    times += [rng.randint(1, 10**8) * 1e-9 for _ in range(2000)]
    for t in times:
        text = osp_seconds(t)
        assert libcosim_ns(text) == round(t * 1e9), (t, text)
        assert abs(float(text) - t) <= 2 * math.ulp(t), (t, text)          # the same time, to two ulps


def test_robofmu_osp_writes_a_multirate_experiment_and_replaces_only_its_own_folder(fmu_root, tmp_path, capfd):
    file = tmp_path / "slow-pd.toml"
    file.write_text('robot = "chess"\nloop = "computed-torque"\nstop_time = 0.2\nstep = 0.001\n\n'
                    '[[blocks]]\nname = "controller"\nsample_time = 0.004\n')
    out = tmp_path / "osp"
    for _ in range(2):                      # written, then replaced (its own folder)
        assert main(["osp", str(file), "--fmus", str(fmu_root), "--out", str(out)]) == 0
        said = capfd.readouterr()
        assert said.out.strip() == str((out / OSP_FILE).resolve()) and not said.err
    assert sorted(p.name for p in out.iterdir()) == sorted([OSP_FILE, "trajectory.fmu", "ik.fmu", "controller.fmu",
                                                            "plant.fmu"])
    steps = {s.get("name"): libcosim_ns(s.get("stepSize")) for s in ET.parse(out / OSP_FILE).getroot().iter(f"{Q}Simulator")}
    assert steps["controller"] == 4_000_000 and steps["plant"] == 1_000_000

    args = ["osp", file, "--fmus", fmu_root, "--out"]
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / OSP_FILE).write_text("<mine/>")
    assert_refused(capfd, args + [mine], "--out", str(mine), OSP_FILE, untouched=[mine / OSP_FILE])
    assert_refused(capfd, args + [fmu_root / "chess"], "--out", "plant.fmu",          # the FMU folder itself
                   untouched=[fmu_root / "chess" / "plant.fmu"])
    (tmp_path / "a-file").write_text("x")
    assert_refused(capfd, args + [tmp_path / "a-file"], "--out", "a-file", "not a folder")
    assert_refused(capfd, ["osp", "no-such-experiment", "--fmus", fmu_root], "no-such-experiment")
    assert_refused(capfd, ["osp", file, "--fmus", tmp_path / "no-fmus"], "--fmus", "no-fmus")
    file.write_text(file.read_text().replace("0.004", "0.0025"))
    assert_refused(capfd, args + [out], "controller", "sample_time = 0.0025 s", untouched=[out / OSP_FILE],
                   folders=[tmp_path])
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".osp.")]          # no staging left


def test_rates_follow_the_experiments_step(fmu_root, tmp_path):
    """Base step 0.13 ms (whose repr libcosim would truncate to 129999 ns), the controller every
    three steps, the rest every step (a block without sample_time included)."""
    system = _chess_pd(fmu_root, sample_time=0.00039, delay=0)
    system.step = 0.00013
    root = ET.parse(export_osp(system, tmp_path)).getroot()
    assert libcosim_ns(root.findtext(f"{Q}BaseStepSize")) == 130_000
    steps = {s.get("name"): libcosim_ns(s.get("stepSize")) for s in root.iter(f"{Q}Simulator")}
    assert steps == {"trajectory": 130_000, "ik": 130_000, "controller": 390_000, "plant": 130_000}
    system.block("controller").sample_time = 0.001          # no whole multiple: refused as the master does
    with pytest.raises(ValueError, match=r"block 'controller': sample_time = 0.001 s is not a whole multiple"):
        export_osp(system, tmp_path / "other")
    assert not (tmp_path / "other").exists()

"""Experiments without boilerplate (issue 28, point 3): ``loop = "computed-torque"`` derives the
blocks, connections, parameters and roles from the robot's blocks' declared ports.

- Every packaged experiment loads to the very System its explicit form gives, block for block
  (FMU path, resolved parameters), connection for connection (in order) and role for role. The
  explicit forms are the packaged files as they were before the short form, kept as test data in
  ``tests/data/explicit_experiments/`` (a base is looked for beside its file, so the explicit
  variants build on the explicit bases). The one difference is chess-loop's controller: the
  derived loop gives it the default gains (the values the explicit base left at the FMU's start
  values) and the pawn's mass.
- The derivation is checked per robot against the blocks' declared variables (built here with
  ``make_block``, not through the derivation): every input wired from an output of its name and
  length, or held at its declared start value; the IK in the loop exactly under a task-space
  profile; roles naming declared outputs.
- What a file gives beside ``loop`` overrides as documented; a robot by path works; mistakes are
  one line naming the file and the key.
- Slow: every short form plans without a warning, and two experiments (a closed chain with a held
  input and a Jacobian; an arm on a named joint-space profile) run bit for bit as their explicit
  forms through the master; a robot outside the package runs from the short form.
"""
from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from robofmu.components.blocks import make_block
from robofmu.components.robots import available, load_description
from robofmu.system import experiment
from robofmu.system.experiment import EXPERIMENTS_DIR, ExperimentError, derive_loop

EXPLICIT = Path(__file__).parent / "data" / "explicit_experiments"
#: The packaged experiments in the short form, and the keys such a file holds.
SHORT = sorted(p.stem for p in EXPERIMENTS_DIR.glob("*.toml") if "loop" in tomllib.loads(p.read_text()))
SHORT_KEYS = {"name", "description", "robot", "loop", "trajectory", "stop_time", "step", "abstract"}


def contents(system) -> dict:
    """What a System holds but its source file, comparable with ==."""
    return {"name": system.name, "description": system.description, "stop_time": system.stop_time,
            "step": system.step, "algorithm": system.algorithm, "fmu_dir": system.fmu_dir,
            "blocks": [(b.name, str(b.fmu), b.parameters) for b in system.blocks],
            "wires": [str(w) for w in system.wires], "extra": system.extra}


def declared(robot: str, fmu_block: str) -> dict:
    """{variable base: (causality, kind, [start values])} of one of the robot's FMUs, from a block
    built here."""
    description = load_description(robot)
    kind, _, described = description.block_of(fmu_block)
    block = make_block(described, kind)
    ports: dict = {}
    for v in block.variables:
        ports.setdefault(v.base, (v.causality, v.kind, []))[2].append(v.start)
    return ports


def write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


# -- the packaged experiments ----------------------------------------------------------------------
def test_the_packaged_standard_loops_are_short():
    """Eleven files moved; each holds only the short form's keys; each has its explicit form."""
    assert len(SHORT) == 11, SHORT
    for name in SHORT:
        assert set(tomllib.loads((EXPERIMENTS_DIR / f"{name}.toml").read_text())) <= SHORT_KEYS, name
        assert (EXPLICIT / f"{name}.toml").is_file(), name
    explicit = {p.stem for p in EXPLICIT.glob("*.toml")}
    assert explicit <= {p.stem for p in EXPERIMENTS_DIR.glob("*.toml")}
    for path in EXPLICIT.glob("*.toml"):            # the references derive nothing themselves
        data = tomllib.loads(path.read_text())
        assert "loop" not in data and ("blocks" in data or "base" in data), path.name


@pytest.mark.parametrize("name", sorted(p.stem for p in EXPLICIT.glob("*.toml")))
def test_derived_diagram_equals_the_explicit_one(name):
    derived = contents(experiment.load(name))
    explicit = contents(experiment.load(EXPLICIT / f"{name}.toml"))
    if name == "chess-loop":
        controller = declared("chess", "controller")
        given = derived["blocks"][2][2]
        assert derived["blocks"][2][0] == "controller" and explicit["blocks"][2][2] == {}
        assert {k: given.pop(k) for k in ("kp", "kd", "ki")} == \
            {k: controller[k][2][0] for k in ("kp", "kd", "ki")} == {"kp": 400.0, "kd": 20.0, "ki": 0.0}
        assert given.pop("payload_mass") == load_description("chess").payload.mass == 0.03
        assert controller["payload_mass"][2] == [0.0]          # the explicit base's controller knew no pawn
    assert derived == explicit


def test_the_roles_follow_the_wires():
    """ur5-pose's roles as the explicit file names them, derived from the wires' sources; 3rrp's
    pose output x is the plant's, not the fk block's (both have one)."""
    ur5 = experiment.load("ur5-pose").extra["roles"]
    assert ur5 == {"q": "plant.q", "qd": "plant.qd", "q_ref": "ik.q_ref", "tau": "controller.tau",
                   "x_ref": "trajectory.x_ref", "quat_ref": "trajectory.quat_ref"}
    assert experiment.load("ur5-joint").extra["roles"]["q_ref"] == "trajectory.q_ref"
    assert experiment.load("3rrp-circle").extra["roles"]["x"] == "plant.x"
    assert "x" in declared("3rrp", "fk") and "x" in declared("3rrp", "plant")
    assert experiment.load("chess-pd").extra["roles"]["grip"] == "trajectory.grip"


# -- the derivation, robot by robot ------------------------------------------------------------------
def profiles(robot: str) -> list[str | None]:
    return [None, *load_description(robot).profiles]


@pytest.mark.parametrize("robot, profile", [(r, p) for r in available() for p in profiles(r)])
def test_the_loop_wires_declared_ports(tmp_path, robot, profile):
    """Against blocks built here: each wire joins an output to an input of the same name, kind and
    length; every other input is held at its declared start; the IK is in the loop exactly when
    the trajectory gives a task-space reference; the controller starts with the default gains."""
    description = load_description(robot)
    loop = derive_loop(description, profile)
    stems = {b["name"]: Path(b["fmu"]).stem for b in loop["blocks"]}
    assert all(b["fmu"] == f"{robot}/{stems[b['name']]}.fmu" for b in loop["blocks"])
    trajectory = f"trajectory_{profile}" if profile else "trajectory"
    assert stems.get("trajectory") == (trajectory if "trajectory" in description.blocks else None)
    ports = {name: declared(robot, stem) for name, stem in stems.items()}
    task_space = "trajectory" in ports and "x_ref" in ports["trajectory"]
    expected = [b for b in description.blocks if b != "ik" or task_space]
    assert list(stems) == expected
    wired = set()
    for text in loop["connections"]:
        wire = experiment.Wire.parse(text)
        out, into = ports[wire.src][wire.src_var], ports[wire.dst][wire.dst_var]
        assert wire.src_var == wire.dst_var and out[0] == "output" and into[0] == "input", text
        assert out[1] == into[1] and len(out[2]) == len(into[2]), text
        assert (wire.dst, wire.dst_var) not in wired, text
        wired.add((wire.dst, wire.dst_var))
    for block in loop["blocks"]:
        for base, (causality, _, starts) in ports[block["name"]].items():
            if causality == "input" and (block["name"], base) not in wired:
                held = block["parameters"][base]
                assert (held if isinstance(held, list) else [held]) == starts, (block["name"], base)
    source = {(w.dst, w.dst_var): w.src for w in map(experiment.Wire.parse, loop["connections"])}
    assert source["controller", "q_ref"] == ("ik" if task_space else "trajectory")
    assert source["controller", "q"] == source["controller", "qd"] == "plant"
    assert source["plant", "tau"] == "controller"
    gains = description.gains[description.default_gains]
    line = f'trajectory = "{profile}"\n' if profile else ""
    short = write(tmp_path / "short.toml", f'robot = "{robot}"\nloop = "computed-torque"\n{line}')
    resolved = experiment.load(short).block("controller").parameters
    assert (resolved["kp"], resolved["kd"], resolved["ki"]) == (gains.kp, gains.kd, gains.ki)
    for role, signal in loop["roles"].items():
        block, base = signal.split(".")
        assert ports[block][base][0] == "output" and base == role


# -- what a file gives beside the loop -----------------------------------------------------------------
def test_a_robot_outside_the_package(copy_robot, tmp_path):
    """``robot = "../arms/myarm.toml"`` (relative to the experiment), no name: planar2r-nr's
    explicit diagram with the FMUs under ``myarm/``, the robot's own gain, the file's stem."""
    toml = copy_robot("planar2r", edit=lambda d: (d.update(name="myarm"), d["gains"]["pd"].update(kp=300.0)),
                      stem="myarm")
    path = write(tmp_path / "exps" / "mine.toml",
                 f'robot = "../planar2r/{toml.name}"\nloop = "computed-torque"\nstop_time = 4.0\nstep = 0.001\n')
    system = experiment.load(path)
    reference = experiment.load(EXPLICIT / "planar2r-nr.toml")
    for block in reference.blocks:
        block.fmu = str(block.fmu).replace("planar2r/", "myarm/")
    reference.block("controller").parameters["kp"] = 300.0
    reference.extra["robot"] = str(toml)
    reference.name, reference.description = "mine", ""
    assert contents(system) == contents(reference)


def test_blocks_connections_roles_and_parameters_override(tmp_path):
    path = write(tmp_path / "over.toml", """
name = "over"
robot = "rrp"
loop = "computed-torque"
connections = ["plant.q -> probe.q", "trajectory.x_ref -> controller.q_ref[2]"]
roles = { q_ref = "trajectory.x_ref" }

[[blocks]]
name = "controller"
fmu = "elsewhere/controller.fmu"
parameters = { kp = 100.0 }

[[blocks]]
name = "probe"
fmu = "rrp/fk.fmu"

[parameters.plant]
q0 = [0.1, 0.2, 0.3]
[parameters.controller]
kd = 30.0
""")
    system = experiment.load(path)
    derived = experiment.load("rrp-line")
    assert [b.name for b in system.blocks] == [b.name for b in derived.blocks] + ["probe"]
    assert str(system.block("controller").fmu) == "elsewhere/controller.fmu"
    assert system.block("controller").parameters == {"kp": 100.0, "kd": 30.0}     # as written, then the table
    assert system.block("plant").parameters == {"q0": [0.1, 0.2, 0.3]}
    kept = [str(w) for w in derived.wires if str(w) != "ik.q_ref -> controller.q_ref"]
    assert [str(w) for w in system.wires] == kept + ["plant.q -> probe.q", "trajectory.x_ref -> controller.q_ref[2]"]
    assert system.extra["roles"] == {**derived.extra["roles"], "q_ref": "trajectory.x_ref"}


def test_an_input_the_file_wires_is_not_held(tmp_path):
    """3rrp's plant.f_ext is held at 0 in the derived loop; wired by the file, it is not."""
    assert experiment.load("3rrp-circle").block("plant").parameters == {"f_ext": [0.0, 0.0, 0.0]}
    path = write(tmp_path / "load.toml", 'robot = "3rrp"\nloop = "computed-torque"\n'
                                         'connections = ["fk.x -> plant.f_ext"]\n')
    system = experiment.load(path)
    assert system.name == "load" and system.block("plant").parameters == {}
    assert [str(w) for w in system.wires][-1] == "fk.x -> plant.f_ext"


def test_a_short_form_can_be_a_base(tmp_path):
    path = write(tmp_path / "pid.toml", 'name = "pid"\nbase = "chess-loop"\n[parameters.controller]\n'
                                        'kp = "robot:gains.pid.kp"\n')
    system = experiment.load(path)
    assert system.block("controller").parameters["kp"] == load_description("chess").gains["pid"].kp == 600.0
    assert system.block("controller").parameters["kd"] == 20.0
    assert [str(w) for w in system.wires] == [str(w) for w in experiment.load("chess-loop").wires]


# -- mistakes ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("text, key, fragment", [
    ('robot = "rrp"\nloop = "pid"\n', "loop", "must be 'computed-torque'"),
    ('loop = "computed-torque"\n', "robot", "missing key: `loop` derives the diagram from the robot"),
    ('name = "x"\nbase = "chess-loop"\nloop = "computed-torque"\n', "loop", "either `base` or `loop`"),
    ('name = "x"\nbase = "chess-loop"\ntrajectory = "joint"\n', "trajectory", "needs loop = \"computed-torque\""),
    ('robot = "ur5"\nloop = "computed-torque"\ntrajectory = "jiont"\n', "trajectory",
     "robot 'ur5' has no profile 'jiont' (its named profiles: joint)"),
    ('robot = "rrp"\nloop = "computed-torque"\ntrajectory = "joint"\n', "trajectory", "(its named profiles: none)"),
    ('robot = "rrp"\nloop = "computed-torque"\n[parameters.ikk]\nx = 1\n', "parameters.ikk",
     "parameters for unknown block 'ikk' (blocks: trajectory, ik, controller, plant, fk)"),
    ('robot = "rrpp"\nloop = "computed-torque"\n', "robot", "unknown robot 'rrpp'"),
    ('robot = "rrp"\nloop = ["computed-torque"]\n', "loop", "must be 'computed-torque'"),
])
def test_mistakes_name_the_file_and_key(tmp_path, text, key, fragment):
    path = write(tmp_path / "bad.toml", text)
    with pytest.raises(ExperimentError) as refused:
        experiment.load(path)
    assert refused.value.key == key and str(refused.value).startswith(f"{path}: {key}: "), str(refused.value)
    assert fragment in str(refused.value) and "\n" not in str(refused.value)


def test_a_robot_without_a_plant_has_no_loop(copy_robot, tmp_path):
    toml = copy_robot("rpp", edit=lambda d: d.update(blocks=["trajectory", "controller", "fk"]))
    path = write(tmp_path / "bad.toml", f'robot = "{toml}"\nloop = "computed-torque"\n')
    with pytest.raises(ExperimentError, match=r"bad\.toml: loop: robot 'rpp' has no plant block \(its blocks: "
                                              r"trajectory, controller, fk\); the computed-torque loop needs both$"):
        experiment.load(path)


def test_the_command_line_refuses_in_one_line(capfd, tmp_path):
    from misuse import assert_refused

    path = write(tmp_path / "bad.toml", 'robot = "ur5"\nloop = "computed-torque"\ntrajectory = "jiont"\n')
    assert_refused(capfd, ["run", path, "--out", tmp_path / "out"], str(path), "trajectory", "jiont",
                   folders=[tmp_path])
    assert not (tmp_path / "out").exists()


# -- through the master (slow) -------------------------------------------------------------------------
@pytest.mark.slow
def test_every_short_form_plans_without_a_warning(fmu_root):
    from robofmu.system.master import Master

    for name in SHORT:
        system = experiment.load(name, fmu_dir=fmu_root)
        assert Master(system).check() == [], name


@pytest.mark.slow
@pytest.mark.parametrize("name", ["3rrp-circle", "panda-joint"])
def test_the_short_form_runs_bit_for_bit_as_the_explicit_one(fmu_root, name):
    from robofmu.system.master import Master

    derived = Master(experiment.load(name, fmu_dir=fmu_root)).run(stop_time=1.0)
    explicit = Master(experiment.load(EXPLICIT / f"{name}.toml", fmu_dir=fmu_root)).run(stop_time=1.0)
    assert derived.columns == explicit.columns and len(derived.time) == 1001
    assert np.array_equal(derived.time, explicit.time) and np.array_equal(derived.data, explicit.data)
    assert np.ptp(derived.vector("plant.q"), axis=0).max() > 0.01          # the loop moved


@pytest.mark.slow
def test_a_robot_outside_the_package_runs_from_the_short_form(fmu_root, copy_robot, tmp_path, capfd):
    """``robofmu new``'s form: robot by path, loop, stop_time, step. myarm is planar2r with kp 300;
    its run equals the package robot's planar2r-nr at kp 300 bit for bit, and ``robofmu run``
    takes the file."""
    from robofmu.system.cli import main
    from robofmu.system.master import Master
    from robofmu.system.packaging.build import build

    toml = copy_robot("planar2r", edit=lambda d: (d.update(name="myarm"), d["gains"]["pd"].update(kp=300.0)),
                      stem="myarm")
    build(toml, tmp_path / "fmus", log=lambda *_: None)
    path = write(tmp_path / "myarm-line.toml", f'robot = "planar2r/{toml.name}"\nloop = "computed-torque"\n'
                                               'stop_time = 4.0\nstep = 0.001\n')
    own = Master(experiment.load(path, fmu_dir=tmp_path / "fmus")).run(stop_time=1.0)
    package = experiment.with_parameters(experiment.load("planar2r-nr", fmu_dir=fmu_root), {"controller.kp": 300.0})
    reference = Master(package).run(stop_time=1.0)
    assert own.columns == reference.columns and np.array_equal(own.data, reference.data)
    capfd.readouterr()
    assert main(["run", str(path), "--fmus", str(tmp_path / "fmus"), "--out", str(tmp_path / "out"),
                 "--stop-time", "0.5"]) == 0, capfd.readouterr()
    assert (tmp_path / "out" / "results.csv").is_file()

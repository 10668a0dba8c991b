"""The FMU contract, for every block of every described robot (test ids ``<robot>-<block>``).

What every FMU promises (docs/design.md, the public interfaces): it passes ``fmpy validate`` and
fmu-manipulation-toolbox's ``fmutool -check``;
every variable has a description, Reals an SI unit defined in UnitDefinitions; the model
structure declares each output's real dependencies (what the FMI-free block declares: the
feedthrough blocks on their inputs, plant and trajectory on none; the plant's q[i] on q0[i] at
initialization); model identifiers are unique across the collection; a vendor annotation names
robot and block; fmi2GetFMUstate/fmi2SetFMUstate roll back bit for bit; a non-finite input
fails the step naming the variable; an invalid parameter fails initialization naming it; each
FMU runs through libcosim and through ``fmpy.simulate_fmu``.

Numbers where cheap: a lone FMU's outputs equal those of its FMI-free block driven the same way
(robofmu.components.blocks), plus closed forms written here (the trajectories' first instants,
the rpp bang-bang at half time, the FK of rrp and rpp, free fall qdd = M^-1 (-g)).

What every robot model promises, whatever its mechanism (test ids ``<robot>``): J and J-dot q-dot
are the derivatives of FK; M is symmetric positive definite; T = qd^T M qd / 2, C qd + g = N,
g = dV/dq, inverse and forward dynamics invert each other, Mdot - 2C is skew; g and V scale with
the gravity set; T + V is conserved without torque; the reference motion starts at home at rest
and ends at rest. And every IK solver that accepts a robot (ids ``<robot>-<solver>``) follows its
reference motion: FK(IK(x)) = x, IK(FK(home)) = home, rates equal differences of its positions.
The robots' own test modules (test_rrp, test_planar2r, test_3rrp_kinematics, ...) keep what is
particular to each: its closed forms and the seed's numbers.
"""
from __future__ import annotations

import math
import sys
import re
import xml.etree.ElementTree as ET
import zipfile
from functools import lru_cache

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation
import pytest
from fmpy import read_model_description, simulate_fmu
from fmpy.validation import validate_fmu
from scipy.integrate import solve_ivp

from robofmu.components import SOURCE_HASH, robot_data_hash
from robofmu.components.blocks import make_block
from robofmu.components.blocks.text import parse_matrix, parse_vector
from robofmu.components.ik import solver_class, solvers
from robofmu.components.orientation import quaternion_of
from robofmu.components.robots import available, load_description, load_model
from robofmu.system.fmu import FMUInstance, FMUError
from robofmu.system.packaging.validate import checker_problems, problems_of

from fmu_util import open_block, robot_blocks
from robot_files import independent_model

ALL = robot_blocks()
WITH_INPUTS = robot_blocks(kinds=("ik", "controller", "plant", "fk", "jacobian"))
STATEFUL = {"plant", "controller", "ik"}        # controller: its integral (ki > 0); ik: its held solution
H = 0.01                                        # s, communication step of the rollback tests

#: SI base-unit exponents of every unit a block may declare (FMI 2.0 BaseUnit attributes).
SI = {"1": {}, "s": {"s": 1}, "m": {"m": 1}, "m/s": {"m": 1, "s": -1}, "m/s2": {"m": 1, "s": -2},
      "rad": {"rad": 1}, "rad/s": {"rad": 1, "s": -1}, "rad/s2": {"rad": 1, "s": -2}, "kg": {"kg": 1},
      "N": {"kg": 1, "m": 1, "s": -2}, "N.m": {"kg": 1, "m": 2, "s": -2}, "1/s": {"s": -1},
      "1/s2": {"s": -2}, "1/s3": {"s": -3}, "m/rad": {"m": 1, "rad": -1}, "rad/m": {"rad": 1, "m": -1},
      "N.m.s/rad": {"kg": 1, "m": 2, "s": -1, "rad": -1}, "N.s/m": {"kg": 1, "s": -1}, "kg.m2": {"kg": 1, "m": 2},
      "1/m": {"m": -1}}


def fmu(fmu_root, robot, block):
    return fmu_root / robot / f"{block}.fmu"


@lru_cache(maxsize=None)
def _xml(path) -> ET.Element:
    with zipfile.ZipFile(path) as z:
        return ET.fromstring(z.read("modelDescription.xml"))


def xml(fmu_root, robot, block) -> ET.Element:
    return _xml(fmu(fmu_root, robot, block))


def dependencies(root: ET.Element, section: str) -> dict:
    """Output name -> set of the variable names it depends on (None: attribute absent)."""
    names = [sv.get("name") for sv in root.find("ModelVariables")]
    out = {}
    for unknown in root.find("ModelStructure").find(section):
        deps = unknown.get("dependencies")
        out[names[int(unknown.get("index")) - 1]] = (
            None if deps is None else {names[int(i) - 1] for i in deps.split()})
    return out


def outputs_of(block) -> list[str]:
    return [v.name for v in block.variables if v.causality == "output"]


@lru_cache(maxsize=None)
def model(robot):
    return load_model(robot)


# -- the collection ----------------------------------------------------------------------------------
def test_the_collection_holds_every_block_of_every_robot(fmu_root):
    built = sorted(p.relative_to(fmu_root).as_posix() for p in fmu_root.glob("*/*.fmu"))
    expected = sorted(f"{r}/{b}.fmu" for r in available() for b in load_description(r).fmu_blocks)
    assert built == expected
    assert {"chess/ik.fmu", "rrp/ik.fmu", "rrp/fk.fmu", "rpp/fk.fmu", "ur5/trajectory_joint.fmu"} <= set(built)
    assert "rpp/ik.fmu" not in built and "chess/fk.fmu" not in built


def test_model_identifiers_are_unique_across_the_collection(fmu_root):
    ids, guids = [], []
    for path in sorted(fmu_root.glob("*/*.fmu")):
        root = _xml(path)
        identifier = root.find("CoSimulation").get("modelIdentifier")
        assert identifier == f"robofmu_{path.parent.name}_{path.stem}" == root.get("modelName")
        ids.append(identifier)
        guids.append(root.get("guid"))
    assert len(ids) == len(set(ids)) == len(guids) == len(set(guids)) == sum(
        len(load_description(r).fmu_blocks) for r in available())


# -- the model description -----------------------------------------------------------------------------
@pytest.mark.parametrize("robot, block", ALL)
def test_fmpy_validate_reports_no_problem(fmu_root, robot, block):
    assert validate_fmu(str(fmu(fmu_root, robot, block))) == []


@pytest.mark.parametrize("robot, block", ALL)
def test_fmu_manipulation_toolbox_check_reports_no_problem(fmu_root, robot, block):
    """``fmutool -check``'s checkers: the FMI 2.0 XSD schema, then the rules it cannot express."""
    assert checker_problems(fmu(fmu_root, robot, block)) == []


def test_both_checkers_can_fail(fmu_root, tmp_path):
    """A copy of a plant whose output q[1] claims variability="fixed" (an output cannot be fixed)
    and whose qd[1] is renamed q[1]: each checker names both faults."""
    broken = tmp_path / "plant.fmu"
    with zipfile.ZipFile(fmu(fmu_root, "chess", "plant")) as source, zipfile.ZipFile(broken, "w") as copy:
        for item in source.infolist():
            data = source.read(item.filename)
            if item.filename == "modelDescription.xml":
                text = data.decode()
                q1 = text.index('name="q[1]"')
                text = text[:q1] + text[q1:].replace('variability="continuous"', 'variability="fixed"', 1)
                data = text.replace('name="qd[1]"', 'name="q[1]"').encode()
            copy.writestr(item, data)
    toolbox = checker_problems(broken)
    assert any("'q[1]': causality='output' and variability='fixed'" in p for p in toolbox), toolbox
    assert any("'q[1]' is used by several variables" in p for p in toolbox), toolbox
    found = problems_of(broken)
    assert any(p.startswith("fmpy: ") and 'variability="fixed"' in p for p in found), found
    assert any(p.startswith("fmpy: ") and "is not unique" in p for p in found), found


@pytest.mark.parametrize("robot, block", ALL)
def test_variables_have_descriptions_si_units_and_structured_names(fmu_root, robot, block):
    root = xml(fmu_root, robot, block)
    definitions = root.find("UnitDefinitions")
    assert definitions is not None and len(definitions)
    units = {}
    for unit in definitions:
        (base,) = unit.findall("BaseUnit")
        units[unit.get("name")] = {k: int(v) for k, v in base.attrib.items()}
    assert all(units[name] == SI[name] for name in units), units        # SI base-unit exponents
    used = set()
    for sv in root.find("ModelVariables"):
        name = sv.get("name")
        assert sv.get("description"), name
        assert re.fullmatch(r"[a-z_0-9]+(\[\d+\])?|J\[\d+,\d+\]", name), name   # structured naming, 1-based
        assert not name.endswith("[0]"), name
        if sv[0].tag == "Real":
            assert sv[0].get("unit") in units, name
            used.add(sv[0].get("unit"))
        else:
            assert sv[0].get("unit") is None, name
    assert used == set(units)                                          # no unused definition


@pytest.mark.parametrize("robot, block", ALL)
def test_variables_are_the_blocks_declared_variables(fmu_root, robot, block):
    """Names, types, causalities, units, descriptions and start values are the FMI-free block's;
    the value reference of each is its slot."""
    logic = make_block(robot, block)
    md = read_model_description(str(fmu(fmu_root, robot, block)), validate=False)
    assert [v.name for v in md.modelVariables] == [v.name for v in logic.variables]
    for k, (fv, bv) in enumerate(zip(md.modelVariables, logic.variables)):
        assert fv.valueReference == k
        assert (fv.type, fv.causality, fv.description) == (bv.kind, bv.causality, bv.description)
        assert (fv.unit or None) == bv.unit
        if bv.causality in ("parameter", "input"):
            start = {"Real": float, "Integer": int, "Boolean": lambda s: s in ("true", "1"),
                     "String": str}[fv.type](fv.start)
            assert start == bv.start, fv.name
        else:
            assert fv.start is None and fv.initial == "calculated"


@pytest.mark.parametrize("robot, block", ALL)
def test_output_dependencies_are_what_the_block_declares(fmu_root, robot, block):
    root = xml(fmu_root, robot, block)
    logic = make_block(robot, block)
    declared = {v.name: v for v in logic.variables}
    inputs = {v.name for v in logic.variables if v.causality == "input"}
    outputs = dependencies(root, "Outputs")
    assert list(outputs) == outputs_of(logic)                  # every output, in order
    for name, deps in outputs.items():
        assert deps == set(declared[name].depends), name
        assert deps <= inputs, name
    n, m = model(robot).n, model(robot).m
    if block in ("plant", "trajectory"):                       # no direct feedthrough
        assert all(d == set() for d in outputs.values())
    else:                                                       # direct feedthrough
        assert type(logic).feedthrough and all(outputs.values())
    if block == "controller":                                   # on every input
        assert all(d == inputs for d in outputs.values()) and len(outputs) == n
        assert ("grip" in inputs) == (robot == "chess")
    pose = bool(model(robot).orientation_axes)
    if block == "fk":                                           # a pose task's quaternion too
        every = {f"q[{j}]" for j in range(1, n + 1)}
        assert outputs == {**{f"x[{i}]": every for i in range(1, m + 1)},
                           **({f"quat[{i}]": every for i in range(1, 5)} if pose else {})}
    if block == "jacobian":                                     # row-major J[i,j], each on every q
        assert outputs == {f"J[{i},{j}]": {f"q[{k}]" for k in range(1, n + 1)}
                           for i in range(1, m + 1) for j in range(1, n + 1)}
        assert list(outputs) == [f"J[{i},{j}]" for i in range(1, m + 1) for j in range(1, n + 1)]
    if block == "plant":                                        # a wrench input exactly with x outputs
        wrench = hasattr(model(robot), "wrench_torque")
        assert ({f"f_ext[{i}]" for i in range(1, m + 1)} <= inputs) == wrench
        assert ({f"x[{i}]" for i in range(1, m + 1)} <= set(outputs)) == wrench
    if block == "ik":
        x, xd, xdd = ({f"{b}[{i}]" for i in range(1, m + 1)} for b in ("x_ref", "xd_ref", "xdd_ref"))
        if pose:                                                # orientation beside position, each order
            x |= {f"quat_ref[{i}]" for i in range(1, 5)}
            xd |= {f"omega_ref[{i}]" for i in range(1, 4)}
            xdd |= {f"omegad_ref[{i}]" for i in range(1, 4)}
        for j in range(1, n + 1):
            assert outputs[f"q_ref[{j}]"] == x
            assert outputs[f"qd_ref[{j}]"] == x | xd
            assert outputs[f"qdd_ref[{j}]"] == x | xd | xdd
        assert outputs["reachable"] == x
    if block == "trajectory":
        assert ("grip" in outputs) == (robot == "chess")

    initial = dependencies(root, "InitialUnknowns")
    assert sorted(initial) == sorted(outputs)
    if block == "plant":
        for j in range(1, n + 1):
            assert initial[f"q[{j}]"] == {f"q0[{j}]"} and initial[f"qd[{j}]"] == {f"qd0[{j}]"}
        for i in range(1, m + 1):
            if f"x[{i}]" in initial:                          # the pose: FK of every q0
                assert initial[f"x[{i}]"] == {f"q0[{j}]" for j in range(1, n + 1)}
    else:                                   # attribute left out: depends on every known
        assert all(d is None for d in initial.values())


@pytest.mark.parametrize("robot, block", ALL)
def test_vendor_annotation_names_robot_and_block(fmu_root, robot, block):
    root = xml(fmu_root, robot, block)
    (tool,) = [t for t in root.find("VendorAnnotations") if t.get("name") == "robofmu"]
    (annotation,) = tool.findall("Block")
    description = load_description(robot)
    variant = description.trajectory.kind if block == "trajectory" else ""
    assert annotation.attrib == {"robot": robot, "kind": block, "variant": variant, "profile": "", "source": SOURCE_HASH,
                                 "robot_data": robot_data_hash(description.path, description.urdf, description.tables),
                                 "python": f"{sys.version_info.major}.{sys.version_info.minor}",
                                 "requirements": "resources/requirements.txt"}
    assert f"robofmu {block} block of robot '{robot}'" in root.get("description")


@pytest.mark.parametrize("robot", available())
def test_defaults_are_the_descriptions(fmu_root, robot):
    """Start values: the plant starts at rest at home; the controller has the pd gains; the
    trajectory's parameters are the description's [trajectory]."""
    description = load_description(robot)

    def starts(block):
        md = read_model_description(str(fmu(fmu_root, robot, block)), validate=False)
        return {v.name: v.start for v in md.modelVariables if v.start is not None}

    plant = starts("plant")
    home = description.configuration("home")
    assert [float(plant[f"q0[{j}]"]) for j in range(1, len(home) + 1)] == list(home)
    assert all(float(plant[f"qd0[{j}]"]) == 0.0 for j in range(1, len(home) + 1))
    assert float(plant["g"]) == description.gravity
    controller = starts("controller")
    pd = description.gain_set("pd")
    assert (float(controller["kp"]), float(controller["kd"]), float(controller["ki"])) == (pd.kp, pd.kd, pd.ki)
    trajectory = starts("trajectory")
    for key, value in description.trajectory.parameters.items():
        if key not in trajectory:                        # a vector of Real parameters
            assert [float(trajectory[f"{key}[{i}]"]) for i in range(1, len(value) + 1)] == value, key
        elif isinstance(value, list):                    # chess waypoints, durations: String parameters
            parse = parse_matrix if isinstance(value[0], list) else parse_vector
            assert parse(trajectory[key], key).tolist() == value, key
        else:
            assert float(trajectory[key]) == value, key


# -- driving a lone block ------------------------------------------------------------------------------
def read_outputs(b: FMUInstance) -> list:
    return [b.get(name) for name in b.variables if b.variables[name].causality == "output"]


def inputs_at(robot: str, block: str, t: float, k: int) -> dict:
    """Non-trivial input values at time t (step k) for every input base of ``block``."""
    rm = model(robot)
    home, n = rm.configuration("home"), rm.n
    w = np.arange(1, n + 1)
    if block == "ik":
        reference = make_block(robot, "trajectory")          # reachable targets: the robot's own path
        reference.configure()
        reference.output(0.2 + t)
        values = {b: reference.get(b) for b in ("x_ref", "xd_ref", "xdd_ref", "quat_ref", "omega_ref", "omegad_ref")
                  if f"{b}[1]" in {v.name for v in reference.variables}}
        if k == 5:                                            # an excursion out of the workspace (every
            values["x_ref"] = values["x_ref"] + 10.0          # arm reaches less than 10 m; 3rrp 0.23 m)
        return values
    return {
        "q_ref": home + 0.05 * np.sin(7 * t + w), "qd_ref": 0.1 * np.cos(7 * t + w),
        "qdd_ref": 0.2 * np.sin(5 * t + w), "q": home + 0.04 * np.cos(5 * t + w),
        "qd": 0.1 * np.sin(3 * t + w),
        "tau": rm.gravity_torque(home) * (1.0 + 0.1 * np.sin(9 * t + w)) + 0.01 * np.sin(t + w),
        "f_ext": 0.001 * np.sin(2 * t + np.arange(1, rm.m + 1)),
        "grip": k >= 3,
    }


def drive(b: FMUInstance, robot: str, block: str, k0: int, count: int) -> list:
    """Steps k0 .. k0 + count - 1: set the inputs, read every output, doStep; then read again."""
    bases = {v.name.split("[")[0] for v in b.variables.values() if v.causality == "input"}
    out = []
    for k in range(k0, k0 + count):
        t = k * H
        values = inputs_at(robot, block, t, k)
        assert bases <= set(values), f"no test values for inputs {bases - set(values)}"
        for base in sorted(bases):
            v = values[base]
            b.set(base, v.tolist() if isinstance(v, np.ndarray) else v)
        out.append(read_outputs(b))
        b.do_step(t, H)
    out.append(read_outputs(b))
    return out


@pytest.mark.parametrize("robot, block", ALL)
def test_fmu_state_rollback_reproduces_the_outputs_bit_for_bit(fmu_root, robot, block):
    parameters = {"ki": 50.0} if block == "controller" else None       # the integral is state
    b = open_block(fmu_root / robot, block, parameters=parameters)
    try:
        drive(b, robot, block, 0, 5)
        state = b.get_state()
        at_save = read_outputs(b)
        first = drive(b, robot, block, 5, 5)
        b.set_state(state)
        at_restore = read_outputs(b)
        second = drive(b, robot, block, 5, 5)
        assert at_restore == at_save                # inputs, time and state restored
        assert second == first                      # every output, every step, exactly
        if block == "ik":
            outputs = [name for name in b.variables if b.variables[name].causality == "output"]
            k = outputs.index("reachable")
            assert first[0][k] is False and first[1][k] is True         # the excursion at k = 5
        # negative controls: without rollback the outputs are those of the later state, and a
        # step from the saved time is refused (the communication point jumps backwards)
        assert read_outputs(b) != at_save
        with pytest.raises(FMUError, match="does not continue from the instance's time"):
            drive(b, robot, block, 5, 1)
        b.free_state(state)
    finally:
        b.close()
    # a fresh instance starting at the saved time lacks the saved internal state
    fresh = open_block(fmu_root / robot, block, parameters=parameters, start_time=5 * H)
    try:
        third = drive(fresh, robot, block, 5, 5)
    finally:
        fresh.close()
    if block in STATEFUL:
        assert third != first                       # the saved state mattered
    else:                                           # outputs are a function of time and inputs:
        assert third[1:] == first[1:]               # the same after the first doStep


# -- bad input ---------------------------------------------------------------------------------------
def _real_inputs(fmu_root, robot, block) -> list[str]:
    md = read_model_description(str(fmu(fmu_root, robot, block)), validate=False)
    return [v.name for v in md.modelVariables if v.causality == "input" and v.type == "Real"]


@pytest.mark.parametrize("which, value", [(0, float("nan")), (-1, float("inf")), (-1, -float("inf"))],
                         ids=["first-nan", "last-inf", "last-minus-inf"])
@pytest.mark.parametrize("robot, block", WITH_INPUTS)
def test_nonfinite_input_fails_the_step_naming_the_variable(fmu_root, robot, block, which, value):
    variable = _real_inputs(fmu_root, robot, block)[which]
    b = open_block(fmu_root / robot, block)
    try:
        b.do_step(0.0, H)
        before = read_outputs(b)
        b.set(variable, value)
        held = read_outputs(b)                       # no non-finite value leaves the block
        assert held == before and all(math.isfinite(v) for v in held if not isinstance(v, bool))
        with pytest.raises(FMUError) as info:
            b.do_step(H, H)
        text = str(info.value)
        assert f"input {variable} = {value} at t = 0.01 s is not finite; step refused" in text
        assert "(error)" in text                     # fmi2DoStep returned fmi2Error, not OK
        assert any(m.status == "ERROR" and variable in m.message for m in b.messages)
        assert read_outputs(b) == before             # the refused step changed nothing
    finally:
        b.close()


def _simulate_with_nonfinite_input(path, variable, debug_logging):
    """fmpy.simulate_fmu with ``variable`` turning NaN after 2.5 ms: the exception it raises and
    every (status, message) the FMU logged."""
    md = read_model_description(str(path), validate=False)
    names = [v.name for v in md.modelVariables if v.causality == "input" and v.type == "Real"]
    starts = {v.name: float(v.start) for v in md.modelVariables if v.name in names}
    dtype = [("time", float)] + [(n, float) for n in names]
    rows = [tuple([t] + [float("nan") if (n == variable and t > 0.0025) else starts[n] for n in names])
            for t in (0.0, 0.0025, 0.0026, 1.0)]
    messages = []
    with pytest.raises(Exception) as info:
        simulate_fmu(str(path), stop_time=0.01, step_size=1e-3, input=np.array(rows, dtype=dtype),
                     debug_logging=debug_logging,
                     logger=lambda env, instance, status, category, message: messages.append(
                         (status, message.decode())))
    return info.value, messages


@pytest.mark.parametrize("robot, block", WITH_INPUTS)
def test_nonfinite_input_message_reaches_the_importers_logger(fmu_root, robot, block):
    """Through fmpy.simulate_fmu with a logger of its own: the message names the variable, and
    the refused step makes the simulation raise (fmi2Error), not end early as if it had finished."""
    variable = _real_inputs(fmu_root, robot, block)[-1]
    error, messages = _simulate_with_nonfinite_input(fmu(fmu_root, robot, block), variable, True)
    assert "fmi2DoStep failed with status 3 (error)" in str(error)
    errors = [m for status, m in messages if status == 3]          # fmi2Error
    assert any(f"input {variable} = nan at t = 0.003 s is not finite; step refused" in m for m in errors), messages


def test_nonfinite_input_message_reaches_the_logger_with_debug_logging_off(fmu_root):
    """loggingOn = false switches debug messages off, not errors: the importer's logger gets the
    reason, and the simulation raises."""
    error, messages = _simulate_with_nonfinite_input(fmu(fmu_root, "rpp", "plant"), "tau[3]", False)
    assert "fmi2DoStep failed with status 3 (error)" in str(error)
    assert any(status == 3 and "input tau[3] = nan" in m for status, m in messages), messages


def _invalid_parameters():
    cases = []
    for robot in available():
        for block, parameters, message, what in [
            ("controller", {"kp": -400.0}, "parameter kp = -400 1/s2 is invalid: must be > 0", "kp"),
            ("controller", {"kd": float("nan")}, "parameter kd = nan 1/s is invalid", "kd"),
            ("plant", {"max_substep": -1e-3}, "parameter max_substep = -0.001 s is invalid: must be > 0",
             "max_substep-negative"),
            ("plant", {"max_substep": 0.0}, "parameter max_substep = 0 s is invalid: must be > 0",
             "max_substep-zero"),
            ("plant", {"g": -9.81}, "parameter g = -9.81 m/s2 is invalid: must be >= 0", "g"),
            ("plant", {"q0[2]": float("inf")}, "parameter q0[2] = inf is invalid: must be finite", "q0"),
        ]:
            cases.append(pytest.param(robot, block, parameters, message, id=f"{robot}-{block}-{what}"))
    cases += [
        pytest.param("rpp", "trajectory", {"a_max[1]": -1.0}, "parameter a_max[1] = -1 is invalid: must be > 0",
                     id="rpp-trajectory-a_max"),
        pytest.param("rpp", "trajectory", {"q_end[2]": float("nan")},
                     "parameter q_end[2] = nan is invalid: must be finite", id="rpp-trajectory-q_end"),
        pytest.param("rrp", "trajectory", {"v_max": 0.0}, "parameter v_max = 0 m/s is invalid: must be > 0",
                     id="rrp-trajectory-v_max"),
        pytest.param("rrp", "trajectory", {"a_max": -0.0375}, "parameter a_max = -0.0375 m/s2 is invalid",
                     id="rrp-trajectory-a_max"),
        pytest.param("rrp", "trajectory", {"direction": [0.0, 0.0, 0.0]},
                     "parameter direction = (0, ..., 0) is invalid: must not be the zero vector", id="rrp-trajectory-direction"),
        pytest.param("chess", "ik", {"elbow": "sideways"},
                     "parameter elbow = 'sideways' is invalid: must be one of 'up', 'down'", id="chess-ik-elbow"),
    ]
    return cases


@pytest.mark.parametrize("robot, block, parameters, message", _invalid_parameters())
def test_invalid_parameter_fails_initialization_naming_it(fmu_root, robot, block, parameters, message):
    b = FMUInstance(fmu(fmu_root, robot, block), block)
    try:
        with pytest.raises(FMUError) as info:
            b.initialize(0.0, parameters)
    finally:
        b.close()
    text = str(info.value)
    assert "fmi2ExitInitializationMode failed" in text and "(error)" in text     # fmi2Error
    assert f"initialization failed: {message}" in text
    assert any(message in m.message and m.status in ("ERROR", "FATAL") for m in b.messages)


# -- other importers, and numbers --------------------------------------------------------------------
def oracle(robot: str, block: str, steps: int, h: float, inputs: dict | None = None) -> dict:
    """Outputs of the FMI-free block after ``steps`` steps of ``h`` from its defaults."""
    logic = make_block(robot, block)
    for name, value in (inputs or {}).items():
        logic.set(name, value)
    logic.configure()
    for k in range(steps):
        logic.output(k * h)
        logic.advance(k * h, h)
    logic.output(steps * h)
    return {name: logic.get(name) for name in outputs_of(logic)}


def closed_form(robot: str, block: str, t: float, inputs: dict) -> dict:
    """Outputs written out by hand where that is cheap (lone FMU at its defaults, time t)."""
    d = load_description(robot)
    p = d.trajectory.parameters if d.trajectory is not None else {}
    rm = model(robot)
    if block == "trajectory" and robot == "chess":               # first move: dz = 0.15 m in 1 s
        a = 4.5 * 0.15
        return {"x_ref[1]": 0.21, "x_ref[2]": 0.0, "x_ref[3]": 0.5 * a * t * t, "xd_ref[3]": a * t,
                "xdd_ref[3]": a, "grip": False}
    if block == "trajectory" and robot == "rrp":                 # accelerating at a_max along the line
        u = np.array(p["direction"]) / np.linalg.norm(p["direction"])
        s, v = 0.5 * p["a_max"] * t * t, p["a_max"] * t
        return {**{f"x_ref[{i + 1}]": p["start"][i] + s * u[i] for i in range(3)},
                **{f"xd_ref[{i + 1}]": v * u[i] for i in range(3)},
                **{f"xdd_ref[{i + 1}]": p["a_max"] * u[i] for i in range(3)}}
    if block == "trajectory" and robot == "rpp":                 # synchronized bang-bang, first half
        dq = np.array(p["q_end"]) - np.array(p["q_start"])
        T = max(2.0 * math.sqrt(abs(x) / a) for x, a in zip(dq, p["a_max"]))
        a = 4.0 * dq / T ** 2
        return {**{f"q_ref[{j + 1}]": p["q_start"][j] + 0.5 * a[j] * t * t for j in range(3)},
                **{f"qd_ref[{j + 1}]": a[j] * t for j in range(3)}}
    if block == "controller":                                    # q = q_ref = home, rates 0: tau = g(home)
        return {f"tau[{j + 1}]": g for j, g in enumerate(gravity_at_home(robot))}
    if block == "ik":                                            # x_ref starts at FK(home)
        return {**{f"q_ref[{j + 1}]": q for j, q in enumerate(rm.configuration("home"))}, "reachable": True}
    if block == "fk":
        q = inputs["q"]
        if robot == "rrp":
            q1, q2, s3 = q
            x = [s3 * math.cos(q2) * math.cos(q1), s3 * math.cos(q2) * math.sin(q1), 0.125 + s3 * math.sin(q2)]
        elif robot == "rpp":
            q1, q2, q3 = q
            x = [-q2 * math.sin(q1), q2 * math.cos(q1), q3]
        elif robot == "planar2r":                               # q2 relative to link 1
            q1, q2 = q
            x = [math.cos(q1) + 0.5 * math.cos(q1 + q2), math.sin(q1) + 0.5 * math.sin(q1 + q2)]
        elif robot == "3rrp":                                    # loop closure by Newton, from the home pose
            x = list(closure_model().pose_from_joints(np.array(q), np.array([0.0, 0.0, -math.pi / 3])))
        elif robot == "rrp_offset":
            q1, q2, l3 = q
            x = [-0.5 * math.sin(q1) - l3 * math.sin(q2) * math.cos(q1),
                 0.5 * math.cos(q1) - l3 * math.sin(q2) * math.sin(q1), 1.0 + l3 * math.cos(q2)]
        elif d.urdf is not None:                                 # an arm from the wild: Pinocchio here
            placement = independent_placement(robot, np.array(q))
            x = placement.translation[list(d.task.axes)].tolist()
            if d.task.is_pose:
                quaternion = Rotation.from_matrix(placement.rotation).as_quat()
                quaternion = -quaternion if quaternion[3] < 0 else quaternion
                return {**{f"x[{i + 1}]": v for i, v in enumerate(x)},
                        **{f"quat[{i + 1}]": v for i, v in enumerate(quaternion)}}
        else:
            raise AssertionError(f"no closed-form FK written here for {robot!r}")
        return {f"x[{i + 1}]": v for i, v in enumerate(x)}
    return {}


def independent_placement(robot: str, q: np.ndarray):
    """The task frame's placement at q on a Pinocchio model built here from the robot's URDF file
    (:func:`robot_files.independent_model`), not through the robot model."""
    model, frame = independent_model(robot)
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    return data.oMf[frame]


def gravity_at_home(robot: str) -> np.ndarray:
    """g(home), not by the controller's path (M u + N, inverse dynamics): from the model's
    forward dynamics at rest with no torque, M qdd = -g, so g = -M qdd(tau = 0); for 3rrp,
    which moves in a horizontal plane, written out: zero."""
    rm = model(robot)
    home = rm.configuration("home")
    if robot == "3rrp":
        return np.zeros(3)
    return -rm.mass_matrix(home) @ rm.forward_dynamics(home, np.zeros(rm.n), np.zeros(rm.n))


@lru_cache(maxsize=None)
def closure_model():
    """The 3rrp's loop closures in the Lagrange formulation (independent of the robot model)."""
    from robofmu.components.robots.parallel_lagrange import LagrangeRRP3
    mech = load_description("3rrp").mechanism
    return LagrangeRRP3(mech.r, mech.link_mass, mech.link_com, mech.link_inertia, mech.ee_mass,
                        mech.ee_inertia, line_offsets=mech.line_offsets)


def _check(got: dict, expected: dict, atol: float, what: str):
    for name, value in expected.items():
        if isinstance(value, bool):
            assert got[name] is value, (what, name)
        else:
            assert got[name] == pytest.approx(value, rel=0, abs=atol), (what, name)


def fk_inputs(robot: str) -> list[float]:
    """A joint position off home (within the limits) for a lone fk block."""
    home = model(robot).configuration("home")
    return (home + 0.1 * np.sin(np.arange(1, len(home) + 1))).tolist()


@pytest.mark.interop
@pytest.mark.parametrize("robot, block", ALL)
def test_every_fmu_runs_through_libcosim(fmu_root, robot, block):
    """libcosimpy is a dev dependency: without it this fails (a contract skips no robot)."""
    from robofmu.system.interop.libcosim import CosimRun

    h, steps = 1e-3, 5
    inputs = {"q": fk_inputs(robot)} if block == "fk" else {}
    run = CosimRun(h)
    try:
        run.add(fmu(fmu_root, robot, block), block)
        for name, value in inputs.items():
            run.set_initial(block, name, value)
        run.step(steps)
        assert run.time == pytest.approx(steps * h, abs=1e-15)
        assert run.execution.status().error_code == 0
        names = [n for n, v in run.slaves[block].variables.items() if v.causality == "OUTPUT"]
        got = {name: run.get(block, name) for name in names}
    finally:
        run.close()
    expected = oracle(robot, block, steps, h, inputs)
    assert sorted(got) == sorted(expected)
    _check(got, expected, 1e-12, "block logic")
    _check(got, closed_form(robot, block, steps * h, inputs), 1e-12, "closed form")


@pytest.mark.parametrize("robot, block", ALL)
def test_every_fmu_runs_through_fmpy_simulate_fmu(fmu_root, robot, block):
    h, steps = 1e-3, 10
    inputs = {"q": fk_inputs(robot)} if block == "fk" else {}
    start_values = {f"q[{j}]": v for j, v in enumerate(inputs.get("q", []), start=1)}
    result = simulate_fmu(str(fmu(fmu_root, robot, block)), stop_time=steps * h, step_size=h,
                          start_values=start_values)
    np.testing.assert_allclose(result["time"], np.arange(steps + 1) * h, rtol=0, atol=1e-15)
    expected = oracle(robot, block, steps, h, inputs)
    assert sorted(result.dtype.names[1:]) == sorted(expected)
    got = {name: (bool(result[name][-1]) if result[name].dtype == bool else float(result[name][-1]))
           for name in expected}
    _check(got, expected, 1e-12, "block logic")
    _check(got, closed_form(robot, block, steps * h, inputs), 1e-12, "closed form")


def test_rpp_trajectory_fmu_at_half_time(fmu_root):
    """q_ref(T/2) = q_start + dq/2 and the peak speed 2 dq / T, T = max_j 2 sqrt(|dq_j| / a_j)."""
    p = load_description("rpp").trajectory.parameters
    q_start, q_end, a_max = (np.array(p[k]) for k in ("q_start", "q_end", "a_max"))
    dq = q_end - q_start
    T = max(2.0 * math.sqrt(abs(x) / a) for x, a in zip(dq, a_max))
    assert T == pytest.approx(math.sqrt(2 * math.pi / 3), rel=1e-15)     # q1 is the slowest joint
    outputs = [f"{b}[{j}]" for b in ("q_ref", "qd_ref") for j in (1, 2, 3)]
    result = simulate_fmu(str(fmu(fmu_root, "rpp", "trajectory")), stop_time=T / 2, step_size=T / 200,
                          output_interval=T / 200, output=outputs)
    assert len(result) == 101                              # 100 steps of T / 200
    assert result["time"][-1] == pytest.approx(T / 2, rel=1e-12)
    last = result[-1]
    np.testing.assert_allclose([last[f"q_ref[{j}]"] for j in (1, 2, 3)], q_start + dq / 2, rtol=0, atol=1e-12)
    np.testing.assert_allclose([last[f"qd_ref[{j}]"] for j in (1, 2, 3)], 2 * dq / T, rtol=0, atol=1e-12)
    assert (result[1]["q_ref[1]"] - q_start[0]) == pytest.approx(0.5 * 4 * dq[0] / T**2 * (T / 200) ** 2, rel=1e-9)


@pytest.mark.parametrize("robot", available())
def test_plant_with_zero_torque_falls_as_gravity_predicts(fmu_root, robot):
    """From rest at home with tau = 0: qdd(0) = M(q0)^-1 (-g(q0)); after a step of h,
    qd(h) = qdd(0) h + O(h^3) and q(h) = q0 + qdd(0) h^2 / 2 + O(h^4) (qd(0) = 0). A robot
    moving in a horizontal plane (3rrp) stays at rest."""
    rm = load_model(robot)
    q0 = rm.configuration("home")
    qdd = np.linalg.solve(rm.mass_matrix(q0), -rm.gravity_torque(q0))
    horizontal = robot == "3rrp"                           # robots.md: it moves in the horizontal plane
    if horizontal:                                         # gravity along z does no work there
        assert rm.potential_energy(q0) == 0.0
        np.testing.assert_array_equal(qdd, np.zeros(rm.n))
    else:
        assert np.max(np.abs(qdd)) > 1.0                   # gravity really acts
    if robot == "rpp":                                     # only the vertical slide falls, at g
        np.testing.assert_allclose(qdd, [0.0, 0.0, -9.81], atol=1e-12)
    h = 1e-4
    b = open_block(fmu_root / robot, "plant")
    try:
        assert b.get("tau") == [0.0] * rm.n
        np.testing.assert_array_equal(b.get("q"), q0)
        b.do_step(0.0, h)
        q, qd = np.array(b.get("q")), np.array(b.get("qd"))
    finally:
        b.close()
    if horizontal:                                         # stays at rest, exactly
        np.testing.assert_array_equal(qd, np.zeros(rm.n))
        np.testing.assert_array_equal(q, q0)
        return
    scale = np.max(np.abs(qdd))
    np.testing.assert_allclose(qd / h, qdd, rtol=0, atol=1e-5 * scale)
    np.testing.assert_allclose(2 * (q - q0) / h**2, qdd, rtol=0, atol=1e-5 * scale)


# == the robot model: what every robot's model promises (no FMU) =======================================
# Each robot's own test module compares its model with its specification (closed forms, seed
# values, an independent Lagrange derivation). The properties below hold for every model whatever
# its mechanism; they are checked here once, on every described robot, at the tolerances the
# robots' modules used when each restated them. Derivatives are fourth-order central differences
# (error O(h^4)): a finite-difference reference accurate enough for one tolerance on every robot.
def d1(f, x, v, h):
    """d/ds f(x + s v) at s = 0 (fourth-order central difference, step h)."""
    return (f(x - 2 * h * v) - 8 * f(x - h * v) + 8 * f(x + h * v) - f(x + 2 * h * v)) / (12 * h)


def d2(f, x, v, h):
    """d^2/ds^2 f(x + s v) at s = 0 (fourth-order central difference, step h)."""
    return (-f(x - 2 * h * v) + 16 * f(x - h * v) - 30 * f(x) + 16 * f(x + h * v) - f(x + 2 * h * v)) / (12 * h * h)


def displacement(rm, p, q):
    """The task displacement from joints q to p: FK(p) - FK(q) (angles wrapped), and for a pose
    task the rotation log3(R(q)^T R(p)) about the frame's own tracked axes; its derivatives in p
    at p = q are J's rows (first) and Jdot qd's (second: the term [theta']x theta' / 2 vanishes)."""
    d = task_difference(rm, rm.fk(p), rm.fk(q))
    if not rm.orientation_axes:
        return d
    return np.concatenate([d, pin.log3(rm.rotation(q).T @ rm.rotation(p))[list(rm.orientation_axes)]])


def task_difference(rm, a, b):
    """a - b in task coordinates, angles (unit rad) wrapped into [-pi, pi)."""
    d = np.array(a, dtype=float) - np.array(b, dtype=float)
    angle = np.array([u == "rad" for u in rm.task_units(0)])
    d[..., angle] = np.remainder(d[..., angle] + math.pi, 2 * math.pi) - math.pi
    return d


def configurations(rm, count: int, seed: int) -> np.ndarray:
    """``count`` joint positions uniform within the position limits (home +- pi for an unlimited
    joint), kept where FK exists (not a direct singularity) and cond J < 1e2."""
    rng = np.random.default_rng(seed)
    lower, upper = rm.position_limits()
    home = rm.configuration("home")
    lower = np.where(np.isfinite(lower), lower, home - math.pi)
    upper = np.where(np.isfinite(upper), upper, home + math.pi)
    found = []
    while len(found) < count:
        q = rng.uniform(lower, upper)
        try:
            s = np.linalg.svd(rm.jacobian(q), compute_uv=False)
        except ValueError:                                          # a direct singularity (3rrp)
            continue
        if s[-1] > 0 and s[0] / s[-1] < 1e2:
            found.append(q)
    return np.array(found)


def test_jacobian_is_the_derivative_of_fk(robot):
    """J = dFK/dq (was in test_planar2r, test_rrp_offset: 1e-9 absolute; test_3rrp_kinematics:
    1e-7 relative)."""
    rm = model(robot)
    for q in configurations(rm, 300, seed=1):
        J = rm.jacobian(q)
        fd = np.column_stack([d1(lambda p: displacement(rm, p, q), q, e, 1e-4) for e in np.eye(rm.n)])
        assert np.max(np.abs(J - fd)) < 1e-9, q
        assert np.linalg.norm(J - fd) < 1e-7 * np.linalg.norm(J), q


def test_jdot_qdot_is_the_derivative_of_j_along_qd_and_the_task_acceleration_at_zero_qdd(robot):
    """Jdot qd = d/dt [J(q + t qd)] qd = d^2/dt^2 FK(q + t qd) at t = 0 (was in test_planar2r,
    test_rrp_offset: 1e-8 and 1e-6 absolute; test_3rrp_kinematics: 1e-7 and 1e-5
    relative)."""
    rm = model(robot)
    rng = np.random.default_rng(2)
    for q in configurations(rm, 200, seed=2):
        qd = rng.uniform(-2.0, 2.0, rm.n)
        a = rm.jdot_qdot(q, qd)
        along = d1(rm.jacobian, q, qd, 3e-5) @ qd
        assert np.max(np.abs(a - along)) < 1e-8, q
        assert np.linalg.norm(a - along) < 1e-7 * np.linalg.norm(along), q
        second = d2(lambda p: displacement(rm, p, q), q, qd, 1e-4)
        assert np.max(np.abs(a - second)) < 1e-6, q


def test_mass_matrix_is_symmetric_positive_definite(robot):
    rm = model(robot)
    for q in configurations(rm, 200, seed=3):
        M = rm.mass_matrix(q)
        np.testing.assert_array_equal(M, M.T)
        assert np.linalg.eigvalsh(M).min() > 0.0, q


def test_dynamics_are_consistent(robot):
    """T = qd^T M qd / 2; C qd + g = N; g = dV/dq; inverse(forward(tau)) = tau and
    M qdd + N = tau; Mdot - 2C skew-symmetric (was in lagrange_checks for planar2r and rrp_offset,
    test_3rrp_kinematics)."""
    rm = model(robot)
    rng = np.random.default_rng(4)
    for q in configurations(rm, 200, seed=4):
        qd, tau = rng.uniform(-2.0, 2.0, rm.n), rng.uniform(-5.0, 5.0, rm.n)
        M, C, g = rm.mass_matrix(q), rm.coriolis_matrix(q, qd), rm.gravity_torque(q)
        assert rm.kinetic_energy(q, qd) == pytest.approx(0.5 * qd @ M @ qd, rel=1e-13)
        N = rm.nonlinear_effects(q, qd)                    # round-off of sums of terms as large as N
        np.testing.assert_allclose(C @ qd + g, N, rtol=1e-12, atol=1e-15 * max(1.0, np.abs(N).max()))
        dV = np.array([d1(lambda p: np.array(rm.potential_energy(p)), q, e, 1e-4) for e in np.eye(rm.n)])
        np.testing.assert_allclose(g, dV, rtol=0, atol=1e-9)
        qdd = rm.forward_dynamics(q, qd, tau)
        np.testing.assert_allclose(rm.inverse_dynamics(q, qd, qdd), tau, rtol=0, atol=1e-12)
        np.testing.assert_allclose(M @ qdd + rm.nonlinear_effects(q, qd), tau, rtol=0, atol=1e-12)
        Mdot = d1(rm.mass_matrix, q, qd, 1e-4)
        S = Mdot - 2 * C
        assert np.max(np.abs(S + S.T)) < 1e-9, q
        assert np.max(np.abs(S + S.T)) <= 1e-7 * np.max(np.abs(Mdot)) + 1e-12, q


def test_gravity_scales_with_set_gravity(robot):
    """g(q) and V(q) are proportional to the gravity's magnitude; none without gravity."""
    rm = load_model(robot)                                  # a model of its own: gravity is state
    g0 = load_description(robot).gravity
    for q in configurations(rm, 20, seed=5):
        g, V = rm.gravity_torque(q), rm.potential_energy(q)
        rm.set_gravity(3.7)
        np.testing.assert_allclose(rm.gravity_torque(q), 3.7 / g0 * g, rtol=1e-12,    # round-off of g's terms
                                   atol=1e-15 * max(1.0, np.abs(g).max()))
        assert rm.potential_energy(q) == pytest.approx(3.7 / g0 * V, rel=1e-12, abs=1e-15)
        rm.set_gravity(0.0)
        assert np.max(np.abs(rm.gravity_torque(q))) < 1e-14
        assert rm.potential_energy(q) == pytest.approx(0.0, abs=1e-14)
        rm.set_gravity(g0)


def test_gravity_jacobian_is_the_potentials_hessian(robot):
    """dg/dq (what the step analysis linearizes gravity with) is the Hessian of V: symmetric,
    v^T G v = d^2 V/ds^2 along random directions, and each column the derivative of g(q)
    (fourth-order central differences, step 1e-4 / 1e-3: truncation ~1e-12 / 1e-10 of the scale)."""
    rm = load_model(robot)
    rng = np.random.default_rng(11)
    for q in configurations(rm, 6, seed=13):
        G = rm.gravity_jacobian(q)
        scale = max(1.0, float(np.abs(G).max()))
        assert G.shape == (rm.n, rm.n)
        np.testing.assert_allclose(G, G.T, rtol=0, atol=1e-9 * scale)
        for v in rng.normal(size=(3, rm.n)):
            v /= np.linalg.norm(v)
            assert v @ G @ v == pytest.approx(d2(lambda p: rm.potential_energy(p), q, v, 1e-3), abs=1e-6 * scale)
        columns = np.column_stack([d1(rm.gravity_torque, q, e, 1e-4) for e in np.eye(rm.n)])
        np.testing.assert_allclose(G, columns, rtol=0, atol=1e-7 * scale)


def test_energy_is_conserved_without_torque(robot):
    """Free motion under gravity (DOP853, tolerances 1e-12) for 1 s: T + V within 1e-9 of its
    start, relative to max(|E0|, T0); the robot really moves (was in test_3rrp_kinematics)."""
    rm = model(robot)
    n = rm.n
    q0 = rm.configuration("home") + 0.05 * np.cos(2.0 * np.arange(n))
    qd0 = np.cos(np.arange(n) + 0.5)

    def f(_, x):
        return np.concatenate([x[n:], rm.forward_dynamics(x[:n], x[n:], np.zeros(n))])

    sol = solve_ivp(f, (0.0, 1.0), np.concatenate([q0, qd0]), method="DOP853", rtol=1e-12, atol=1e-12,
                    t_eval=np.linspace(0.0, 1.0, 101))
    assert sol.success
    energy = np.array([rm.kinetic_energy(x[:n], x[n:]) + rm.potential_energy(x[:n]) for x in sol.y.T])
    scale = max(abs(energy[0]), rm.kinetic_energy(q0, qd0))
    assert np.max(np.abs(energy - energy[0])) < 1e-9 * scale
    assert np.max(np.abs(sol.y[:n, -1] - q0)) > 0.1


def test_the_reference_starts_at_home_at_rest_and_ends_at_rest(robot):
    """The trajectory block's profile: at t = 0 the home configuration (or its FK), velocity 0;
    at its end velocity 0."""
    rm = model(robot)
    block = make_block(robot, "trajectory")
    block.configure()
    start = block.profile.evaluate(0.0)                    # (x, xd, xdd), a pose's (quat, omega, omegad) after
    x, xd = start[0], start[1]
    home = rm.configuration("home")
    if joint_space(block):
        np.testing.assert_allclose(x, home, rtol=0, atol=1e-15)
    else:
        np.testing.assert_allclose(task_difference(rm, x, rm.fk(home)), 0.0, rtol=0, atol=1e-15)
    if rm.orientation_axes:                                 # the frame's orientation at home, at rest
        angle = (Rotation.from_quat(start[3]).inv() * Rotation.from_matrix(rm.rotation(home))).magnitude()
        assert angle < 1e-15 and not start[4].any()
    np.testing.assert_array_equal(xd, np.zeros(len(xd)))
    end = block.profile.evaluate(block.profile.duration)
    for rate in (end[1],) + tuple(end[4:5]):
        np.testing.assert_array_equal(rate, np.zeros(len(rate)))


def joint_space(block) -> bool:
    """Whether a trajectory block's reference is in joint space (q_ref) rather than task space."""
    return any(v.name.startswith("q_ref[") for v in block.variables)


def task_reference(robot: str):
    """The robot's reference motion in task space: ``(evaluate, breakpoints, duration)`` of its
    trajectory block's profile, or for a joint-space profile of its image by FK
    (x = FK(q), xd = J qd, xdd = J qdd + Jdot qd)."""
    block = make_block(robot, "trajectory")
    block.configure()
    profile = block.profile
    if not joint_space(block):
        return profile.evaluate, np.asarray(profile.breakpoints), profile.duration
    rm = model(robot)

    def evaluate(t):
        q, qd, qdd = profile.evaluate(t)
        J = rm.jacobian(q)
        return rm.fk(q), J @ qd, J @ qdd + rm.jdot_qdot(q, qd)

    return evaluate, np.asarray(profile.breakpoints), profile.duration


def _accepting_solvers():
    """(robot, solver kind) for every IK solver whose constructor accepts the robot's model with its
    default parameters (a solver refuses a robot that is not its mechanism by ValueError)."""
    pairs = []
    for robot in available():
        for kind in solvers():
            try:
                solver_class(kind)(load_model(robot))
            except ValueError:
                continue
            pairs.append(pytest.param(robot, kind, id=f"{robot}-{kind}"))
    return pairs


def test_every_robot_with_an_ik_table_is_solved_by_its_solver():
    """The description's solver is among the accepting ones below, for every robot with [ik]."""
    kinds = {(p.values[0], p.values[1]) for p in _accepting_solvers()}
    for robot in available():
        ik = load_description(robot).ik
        if ik is not None:
            assert (robot, ik.kind) in kinds, robot


def pose_error(rm, q, target) -> float:
    """How far FK(q) is from ``target`` (the profile's values at one instant): the largest task
    difference for a position task; for a pose task the larger of the position distance (m) and
    the rotation angle |log3(R_target^T R(q))| (rad) over the tracked axes."""
    if not rm.orientation_axes:
        return float(np.max(np.abs(task_difference(rm, rm.fk(q), target[0]))))
    rotation = Rotation.from_quat(target[3]).as_matrix()
    angle = pin.log3(rotation.T @ rm.rotation(q))[list(rm.orientation_axes)]
    return max(float(np.linalg.norm(rm.fk(q) - target[0])), float(np.linalg.norm(angle)))


@pytest.mark.parametrize("robot, kind", _accepting_solvers())
def test_ik_solver_follows_the_reference_motion(robot, kind):
    """Every IK solver that accepts a robot, with its default parameters, along the robot's
    reference motion (sampled every 1 ms): FK(IK(x)) = x to 1e-12 (a pose task: position and
    orientation); IK(FK(home)) = home to 1e-15; away from the profile's breakpoints (where the
    acceleration jumps) its rates qd, qdd equal central differences of its positions (1e-8, 5e-4;
    fourth order, h = 1 ms, so that an iterative solver's residual, up to its tolerance 1e-12,
    stays below them; positions solved from the same start, so that a redundant arm's null space
    adds nothing) and, for a robot with an IK block, stay within the velocity limits (the block's
    default qd_limit). Was in test_ik (chess), test_planar2r and test_rrp_offset."""
    rm = model(robot)
    ik = solver_class(kind)(rm)
    has_ik = load_description(robot).ik is not None
    home = rm.configuration("home")
    orientation = [quaternion_of(rm.rotation(home))] if rm.orientation_axes else []
    np.testing.assert_allclose(ik.position(rm.fk(home), *orientation), home, rtol=0, atol=1e-15)
    evaluate, breakpoints, duration = task_reference(robot)
    pose = (lambda target: (target[0], target[3])) if rm.orientation_axes else (lambda target: (target[0],))
    worst, q = 0.0, None
    for t in np.arange(0.0, duration + 1e-9, 1e-3):
        target = evaluate(t)
        ik.start_from(q)                                   # as the IK block does: from its last solution
        q = ik.position(*pose(target))
        worst = max(worst, pose_error(rm, q, target))
    assert worst < 1e-12, worst
    ik.start_from(None)
    times = np.arange(0.01, duration, 0.013)
    h, checked = 1e-3, 0
    for t in times:
        if np.min(np.abs(t - breakpoints)) < 2.5 * h:      # the stencil reaches 2 h either side
            continue
        q, qd, qdd = ik.solve(*evaluate(t))
        ik.start_from(q)
        qm2, qm1, qp1, qp2 = (ik.position(*pose(evaluate(t + k * h))) for k in (-2, -1, 1, 2))
        if len(qd) == rm.task_rows:                        # square: q is a function of the target
            np.testing.assert_allclose(qd, (qm2 - 8 * qm1 + 8 * qp1 - qp2) / (12 * h), rtol=0, atol=1e-8)
            np.testing.assert_allclose(qdd, (-qm2 + 16 * qm1 - 30 * q + 16 * qp1 - qp2) / (12 * h * h),
                                       rtol=0, atol=5e-4)
        else:                                              # redundant: the task rows of the rates
            J = rm.jacobian(q)                             # (the null space: test_damped_least_squares)
            np.testing.assert_allclose(J @ qd, J @ (qm2 - 8 * qm1 + 8 * qp1 - qp2) / (12 * h), rtol=0,
                                       atol=1e-8)
        if has_ik:                                         # the reference its IK block follows
            assert np.all(np.abs(qd) < rm.velocity_limits()), t
        checked += 1

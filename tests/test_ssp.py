"""Experiments exported as SSP 1.0 packages, run by libcosim and by fmpy.ssp, against the master.

Every experiment (chess-pd, rrp-line, rpp-bangbang) exports a package that validates against
the SSP schemas and that libcosim runs equal to the master's Jacobi run to rounding (the lone
plant, too, for every robot). The rest is chess-pd's.

What each tool's algorithm does with the loop trajectory -> ik -> controller -> plant (ik and
controller have direct feedthrough, the plant has none; tau_k drives the plant's step from t_k,
r_k = IK(x(t_k)) is the joint reference, y_k = (q, qd)(t_k)):

- robofmu master, Gauss-Seidel: blocks evaluated in dependency order at every point, so
  tau_k = C(r_k, y_k): no delay anywhere.
- robofmu master, Jacobi (``algorithm="jacobi"``): all outputs read, then all inputs set, then
  all blocks step; a feedthrough block's output at t_k comes from its inputs of t_(k-1):
  tau_k = C(r_(k-2), y_(k-1)). It starts consistent (the point t0 is evaluated Gauss-Seidel).
- libcosim (fixed-step algorithm): inputs are transferred after each step and held over the
  next; outputs are read after the step. That is the same exchange, tau_k = C(r_(k-2), y_(k-1)),
  and libcosim passes connected values along in initialization mode, so it starts consistent
  too (tests/test_libcosim.py). Hence libcosim must reproduce the master's Jacobi run to
  rounding.
  Against Gauss-Seidel, the reference reaches the plant two steps late (one step per
  feedthrough block, ik and controller; the controller -> plant connection adds none, since the
  plant steps from t_k with the tau read at t_k in both) and the measured q one step late. The
  plant then follows a reference shifted by about 2h and the delayed feedback makes it lead by
  about h: |dq| <= (2 + 1) h max|qd_ref|, and about (2 - 1) h max|qd_ref| (measured per joint:
  0.95 .. 1.43 h max|qd_ref|), first order in h.
- fmpy.ssp (``simulate_ssp``): the same Jacobi exchange, but no exchange at initialization
  (connector values start at 0.0): step 0 runs with tau = 0 (the arm falls for one step), step 1
  with the controller's output for all-zero inputs, tau = N(0, 0); from step 2 on it equals
  libcosim's. (The ik block, fed x = 0 at step 0, holds its start solution r_0.) Each wrong torque
  step kicks the joint velocity by v = h |M(q0)^-1 dtau|; under computed torque the joint error
  obeys e'' + kd e' + kp e = 0 (omega_n = 20 rad/s, zeta = 0.5), so a kick v0 leaves
  |e(t)| <= v0 / omega_d exp(-zeta omega_n t): a difference proportional to h that dies out.
  fmpy also accumulates its time (t += h): at a breakpoint of the reference (where the LSPB
  acceleration jumps) it may evaluate the trajectory on the other side for one step, a kick of at
  most h max|jump of qdd_ref|.

The tolerances below are these bounds (the fmpy ones with a factor of 2 of margin: measured
0.2 .. 0.25 of the bound); each difference is also checked to halve (first order) when the step
halves from 1 ms to 0.5 ms (measured ratios 0.496 .. 0.500).
"""
from __future__ import annotations

import math
import re
import zipfile
from xml.etree import ElementTree as ET

import numpy as np
import pytest

from fmu_util import real_columns

from robofmu.components.control import ComputedTorque
from robofmu.components.ik import make_solver
from robofmu.components.robots import load_description, load_model
from robofmu.system import experiment as experiments
from robofmu.system.experiment import load
from robofmu.system.master import Master
from robofmu.system.interop.fmpy_ssp import run_ssp_fmpy
from robofmu.system.interop.libcosim import run_ssp_libcosim
from robofmu.system.interop.ssp import NS, element_names, export_ssp, ssd_text, ssp_identifier

STOP = 2.0                  # s: chess: first move (0-1 s), pause, start of the second move
STEPS = (1e-3, 5e-4)        # s
BLOCKS = ["trajectory", "ik", "controller", "plant"]
EXPERIMENTS = ["chess-pd", "rrp-line", "rpp-bangbang", "3rrp-circle", "ur5-pose", "panda-pose"]
#: Scalar connections of each experiment's loop (each wire expanded to its vector's length)
CONNECTIONS = {
    "chess-pd": 35,             # 3 x 3 + 3 x 4 + 2 x 4 + 4 + 2 (the grip twice)
    "rrp-line": 30,             # 3 x 3 + 3 x 3 + 2 x 3 + 3 + 3 (plant.q -> fk.q)
    "rpp-bangbang": 21,         # 3 x 3 + 2 x 3 + 3 + 3
    "3rrp-circle": 33,          # 3 x 3 + 3 x 3 + 2 x 3 + 3 + 3 + 3 (plant.q -> fk.q, jacobian.q)
    "ur5-pose": 61,             # 3 x 3 + 4 + 3 + 3 (the pose) + 3 x 6 + 2 x 6 + 6 + 6 (plant.q -> fk.q)
    "panda-pose": 68,           # 3 x 3 + 4 + 3 + 3 (the pose) + 3 x 7 + 2 x 7 + 7 + 7 (plant.q -> fk.q)
}


@pytest.fixture(scope="module")
def systems(fmu_root):
    """systems(name) -> System of an experiment (one per module: runs share it)."""
    cache = {}

    def get(name):
        if name not in cache:
            cache[name] = load(name, fmu_dir=fmu_root)
        return cache[name]

    return get


@pytest.fixture(scope="module")
def packages(systems, tmp_path_factory):
    """packages(name) -> the experiment's exported ``<name>.ssp``, written once."""
    folder, cache = tmp_path_factory.mktemp("ssp"), {}

    def get(name):
        if name not in cache:
            cache[name] = export_ssp(systems(name), folder / f"{name}.ssp")
        return cache[name]

    return get


@pytest.fixture(scope="module")
def system(systems):
    return systems("chess-pd")


@pytest.fixture(scope="module")
def ssp(packages):
    return packages("chess-pd")


@pytest.fixture(scope="module")
def runs(systems, packages):
    """runs(tool, h, name="chess-pd") -> Result, each computed once: 'gs', 'jacobi' (master),
    'libcosim', 'fmpy'."""
    cache = {}

    def get(tool, h, name="chess-pd"):
        if (name, tool, h) not in cache:
            if tool in ("gs", "jacobi"):
                cache[name, tool, h] = Master(systems(name)).run(STOP, h, "gauss-seidel" if tool == "gs" else "jacobi")
            elif tool == "libcosim":
                cache[name, tool, h] = run_ssp_libcosim(packages(name), STOP, h)
            else:
                cache[name, tool, h] = run_ssp_fmpy(packages(name), STOP, h)
        return cache[name, tool, h]

    return get


@pytest.fixture(scope="module")
def loop_model():
    """Closed-loop error dynamics of the PD computed-torque loop: (omega_d, decay rate) in 1/s."""
    g = load_description("chess").gain_set("pd")
    wn = math.sqrt(g.kp)
    zeta = g.kd / (2 * wn)
    return wn * math.sqrt(1 - zeta * zeta), zeta * wn


def kicks(gs, h):
    """Velocity kicks (rad/s, worst joint) of fmpy's two start-up steps: tau = 0 instead of
    tau_0, then tau = N(0, 0) instead of tau_0 (tau_0 = C(r_0, y_0), the consistent torque)."""
    robot = load_model("chess")
    q0, tau0, zero = gs.vector("plant.q")[0], gs.vector("controller.tau")[0], np.zeros(4)
    qdd = lambda tau: robot.forward_dynamics(q0, zero, tau)       # noqa: E731
    v_a = h * np.max(np.abs(qdd(tau0) - qdd(zero)))
    v_b = h * np.max(np.abs(qdd(tau0) - qdd(robot.nonlinear_effects(zero, zero))))
    return v_a, v_b


def joint_diff(a, b, name="plant.q"):
    """Worst-joint |a - b| of a recorded vector at the times both hold (fmpy has no t = 0 row)."""
    ta, tb = np.round(a.time, 9), np.round(b.time, 9)
    common, ia, ib = np.intersect1d(ta, tb, return_indices=True)
    assert len(common) >= min(len(ta), len(tb))
    return common, np.max(np.abs(a.vector(name)[ia] - b.vector(name)[ib]), axis=1)


# -- the package ------------------------------------------------------------------------------------------
STOP_TIMES = {"chess-pd": 13.0, "rrp-line": 3.0, "rpp-bangbang": 2.0, "3rrp-circle": 5.0,      # s, the experiments' own
              "ur5-pose": 3.0, "panda-pose": 3.0}
#: The SSD's system name of each experiment: an identifier OMSimulator takes (``^[a-zA-Z][a-zA-Z0-9_]*$``)
SYSTEM_NAMES = {"chess-pd": "chess_pd", "rrp-line": "rrp_line", "rpp-bangbang": "rpp_bangbang",
                "3rrp-circle": "x3rrp_circle", "ur5-pose": "ur5_pose", "panda-pose": "panda_pose"}
OMSIMULATOR_IDENT = r"[a-zA-Z][a-zA-Z0-9_]*"        # OMSimulator's ComRef::isValidIdent


@pytest.mark.parametrize("name", EXPERIMENTS)
def test_ssd_is_well_formed_with_components_connectors_and_connections(systems, packages, name):
    system, ssp = systems(name), packages(name)
    blocks = [b.name for b in system.blocks]
    assert name != "chess-pd" or blocks == BLOCKS
    description = load_description(system.extra["robot"])
    with zipfile.ZipFile(ssp) as zf:
        names = set(zf.namelist())
    bound = {f"resources/{b.name}.ssv" for b in system.blocks if b.parameters}     # values the experiment sets
    assert "resources/controller.ssv" in bound
    assert {"SystemStructure.ssd"} | bound | {f"resources/{b}.fmu" for b in blocks} == names

    root = ET.fromstring(ssd_text(ssp))                                   # well-formed XML
    assert root.tag == f"{{{NS['ssd']}}}SystemStructureDescription"
    assert (root.get("version"), root.get("name"), root.get("description")) == ("1.0", SYSTEM_NAMES[name], name)
    assert root.find("ssd:System", NS).get("name") == SYSTEM_NAMES[name]
    components = root.findall("ssd:System/ssd:Elements/ssd:Component", NS)
    assert [c.get("name") for c in components] == blocks
    assert [c.get("source") for c in components] == [f"resources/{b}.fmu" for b in blocks]

    master = Master(system)
    assert master.check() == []                                           # every input wired
    wired = {(link.target, link.input) for link in master.links}
    for comp in components:
        md = master.nodes[comp.get("name")].md
        # every output; every wired input (an input the experiment sets instead, as 3rrp-circle's
        # plant.f_ext = 0, is a value of the block's parameter set, not a connector)
        expected = {v.name: v for v in md.modelVariables if v.causality == "output"
                    or (v.causality == "input" and (comp.get("name"), v.name) in wired)}
        connectors = comp.findall("ssd:Connectors/ssd:Connector", NS)
        assert {c.get("name"): c.get("kind") for c in connectors} == \
               {n: v.causality for n, v in expected.items()}
        for c in connectors:
            (typ,) = list(c)
            assert typ.tag == f"{{{NS['ssc']}}}{expected[c.get('name')].type}"
    plant = components[blocks.index("plant")]
    if description.payload is not None:                                   # chess: the gripper
        assert plant.find("ssd:Connectors/ssd:Connector[@name='grip']/ssc:Boolean", NS) is not None
    unit = plant.find("ssd:Connectors/ssd:Connector[@name='q[2]']/ssc:Real", NS).get("unit")
    assert unit == load_model(description).joint_units()[1] == {"chess-pd": "rad", "rrp-line": "rad",
                                                                "rpp-bangbang": "m", "3rrp-circle": "rad",
                                                                "ur5-pose": "rad", "panda-pose": "rad"}[name]

    # every wire expanded to scalar variables (chess: 3 x 3 + 3 x 4 + 2 x 4 + 4 + 2 = 35)
    connections = [(c.get("startElement"), c.get("startConnector"), c.get("endElement"), c.get("endConnector"))
                   for c in root.findall("ssd:System/ssd:Connections/ssd:Connection", NS)]
    assert len(connections) == CONNECTIONS[name] == len(set(connections)) == len(master.links)
    reference = "ik" if "ik" in blocks else "trajectory"
    assert (reference, "q_ref[3]", "controller", "q_ref[3]") in connections
    if description.payload is not None:
        assert ("trajectory", "grip", "plant", "grip") in connections
    ends = [(d, i) for _, _, d, i in connections]
    inputs = [(c.get("name"), con.get("name")) for c in components
              for con in c.findall("ssd:Connectors/ssd:Connector[@kind='input']", NS)]
    assert sorted(ends) == sorted(inputs)                                 # each input driven once

    experiment = root.find("ssd:DefaultExperiment", NS)
    assert float(experiment.get("startTime")) == 0.0 and float(experiment.get("stopTime")) == STOP_TIMES[name]
    algo = experiment.find("ssd:Annotations/ssc:Annotation/osp:Algorithm/osp:FixedStepAlgorithm", NS)
    assert float(algo.get("baseStepSize")) == 1e-3

    # the controller's parameters, in an SSV file bound to it
    binding = components[blocks.index("controller")].find("ssd:ParameterBindings/ssd:ParameterBinding", NS)
    assert binding.get("source") == "resources/controller.ssv"
    with zipfile.ZipFile(ssp) as zf:
        ssv = ET.fromstring(zf.read("resources/controller.ssv"))
    assert ssv.get("name") == SYSTEM_NAMES[name]                          # the set ecos applies by name
    values = {p.get("name"): float(p.find("ssv:Real", NS).get("value"))
              for p in ssv.findall("ssv:Parameters/ssv:Parameter", NS)}
    payload = {} if description.payload is None else {"payload_mass": description.payload.mass}
    assert values == {**description.gain_set("pd").as_dict(), **payload}
    if name == "chess-pd":
        assert values == {"kp": 400.0, "kd": 20.0, "ki": 0.0, "payload_mass": 0.03}


@pytest.mark.parametrize("name", EXPERIMENTS)
def test_ssd_and_ssv_validate_against_the_ssp_schemas(systems, packages, tmp_path, name):
    from fmpy.ssp.ssd import read_ssd

    system = systems(name)
    blocks = [b.name for b in system.blocks]
    for path, external in ((packages(name), True), (export_ssp(system, tmp_path / "inline.ssp", inline=True), False)):
        ssd = read_ssd(str(path), validate=True)       # SSP 1.0 XSDs (fmpy's copies); the .ssv too
        assert [c.name for c in ssd.system.elements] == blocks
        assert len(ssd.system.connections) == CONNECTIONS[name]
        (binding,) = ssd.system.elements[blocks.index("controller")].parameterBindings
        assert (binding.source is not None) == external
        (pset,) = binding.parameterValues
        assert {p.name: float(p.value) for p in pset.parameters}["kp"] == 400.0
    with zipfile.ZipFile(tmp_path / "inline.ssp") as zf:
        assert not [n for n in zf.namelist() if n.endswith(".ssv")]


def test_identifiers_for_the_ssd_names():
    assert ssp_identifier("chess-pd") == "chess_pd"
    assert ssp_identifier("3rrp-circle") == "x3rrp_circle"
    assert ssp_identifier("rrp_offset-nr") == "rrp_offset_nr"
    assert ssp_identifier("_plant") == "x_plant"
    assert ssp_identifier("plänt 2.b") == "pl_nt_2_b"
    assert ssp_identifier("") == "x"
    assert ssp_identifier("plant") == "plant"
    # kept when already identifiers; the others made unique after them, in diagram order
    assert element_names(["plant-1", "plant_1", "ik", "plant.1", "2nd"]) == \
        {"plant-1": "plant_1_2", "plant_1": "plant_1", "ik": "ik", "plant.1": "plant_1_3", "2nd": "x2nd"}
    assert element_names(["a-b", "a_b_2", "a.b"]) == {"a-b": "a_b", "a_b_2": "a_b_2", "a.b": "a_b_3"}


@pytest.mark.parametrize("name", experiments.available())
def test_every_experiments_ssd_names_are_identifiers(fmu_root, tmp_path, name):
    """Every shipped experiment: the root and the system carry the experiment's name as an
    identifier every tool takes (OMSimulator's rule: a letter first), the experiment's own name is
    the SSD's description, the components are the blocks (all identifiers already), the
    connections name them, and every parameter set carries the system's name."""
    system = load(name, fmu_dir=fmu_root)
    path = export_ssp(system, tmp_path / "x.ssp")
    root = ET.fromstring(ssd_text(path))
    expected = name.replace("-", "_")
    expected = expected if expected[0].isalpha() else "x" + expected
    assert (root.get("name"), root.get("description")) == (expected, name)
    assert re.fullmatch(OMSIMULATOR_IDENT, expected)
    sys_el = root.find("ssd:System", NS)
    assert sys_el.get("name") == expected
    assert sys_el.get("description") == (system.description or None)
    components = [c.get("name") for c in sys_el.findall("ssd:Elements/ssd:Component", NS)]
    assert components == [b.name for b in system.blocks]
    assert all(re.fullmatch(OMSIMULATOR_IDENT, c) for c in components)
    ends = {c.get(k) for c in sys_el.findall("ssd:Connections/ssd:Connection", NS) for k in ("startElement", "endElement")}
    assert ends and ends <= set(components)
    with zipfile.ZipFile(path) as zf:
        sets = [ET.fromstring(zf.read(n)).get("name") for n in zf.namelist() if n.endswith(".ssv")]
    assert sets and set(sets) == {expected}


def test_blocks_that_are_no_identifiers_get_component_names_the_runners_use(fmu_root, tmp_path):
    """Lone plants named "plant-1", "plant_1" and "2nd plant": the components are plant_1_2,
    plant_1 and x2nd_plant (each renamed one with its block's name as description, its .ssv after
    the component), libcosim and fmpy.ssp name their columns after them, and each plant runs
    as the master runs the block: the one given another q0 falls from there."""
    from robofmu.system.diagram import BlockSpec, System

    q0 = load_model("chess").configuration("home") + np.array([0.0, 0.1, 0.0, 0.0])
    blocks = [BlockSpec("plant-1", "chess/plant.fmu"), BlockSpec("plant_1", "chess/plant.fmu"),
              BlockSpec("2nd plant", "chess/plant.fmu", {"q0": q0.tolist()})]
    lone = System(blocks, [], fmu_dir=fmu_root, name="3 plants", stop_time=0.01)
    path = export_ssp(lone, tmp_path / "plants.ssp")
    root = ET.fromstring(ssd_text(path))
    assert (root.get("name"), root.get("description")) == ("x3_plants", "3 plants")
    components = root.findall("ssd:System/ssd:Elements/ssd:Component", NS)
    assert [(c.get("name"), c.get("description")) for c in components] == \
        [("plant_1_2", "plant-1"), ("plant_1", None), ("x2nd_plant", "2nd plant")]
    with zipfile.ZipFile(path) as zf:
        assert [n for n in zf.namelist() if n.endswith(".ssv")] == ["resources/x2nd_plant.ssv"]
        assert ET.fromstring(zf.read("resources/x2nd_plant.ssv")).get("name") == "x3_plants"
    master = Master(lone).run(0.005, 1e-3, "jacobi")
    lc, fm = run_ssp_libcosim(path, 0.005, 1e-3), run_ssp_fmpy(path, 0.005, 1e-3)
    for element, block in (("plant_1_2", "plant-1"), ("plant_1", "plant_1"), ("x2nd_plant", "2nd plant")):
        np.testing.assert_allclose(lc.vector(f"{element}.q"), master.vector(f"{block}.q"), rtol=0, atol=1e-12)
        np.testing.assert_allclose(fm.vector(f"{element}.q"), master.vector(f"{block}.q")[1:], rtol=0, atol=1e-12)
    np.testing.assert_allclose(lc.vector("x2nd_plant.q")[0], q0, rtol=0, atol=1e-15)      # its parameter set
    assert np.max(np.abs(lc.vector("x2nd_plant.q")[0] - lc.vector("plant_1.q")[0])) == pytest.approx(0.1)
    # fmpy.ssp gives a component the parameters whose names start with its name: plant_1_2's q0
    # would reach plant_1 too, so run_ssp_fmpy refuses that package
    blocks[0] = BlockSpec("plant-1", "chess/plant.fmu", {"q0": q0.tolist()})
    clashing = export_ssp(System(blocks, [], fmu_dir=fmu_root, name="3 plants"), tmp_path / "clash.ssp")
    with pytest.raises(NotImplementedError, match=r"mix up the parameters of components \('plant_1', 'plant_1_2'\)"):
        run_ssp_fmpy(clashing, 0.005, 1e-3)


def test_parameter_bindings_reach_the_fmus(fmu_dir, tmp_path):
    """fmpy.ssp parses the bindings but applies none itself; run_ssp_fmpy applies them. The PID
    gains and a vector parameter (plant q0) must show in both tools' results."""
    robot = load_model("chess")
    s = load_description("chess").trajectory.parameters
    r0 = make_solver(robot).position(np.array(s["waypoints"][0]))
    q0 = r0 + np.array([0.0, 0.05, -0.05, 0.02])
    system = load("chess-pid", fmu_dir=fmu_dir.parent)
    system.block("plant").parameters["q0"] = q0.tolist()
    path = export_ssp(system, tmp_path / "pid.ssp")
    pid, pd = (load_description("chess").gain_set(g).as_dict() for g in ("pid", "pd"))
    h = 1e-3

    lc = run_ssp_libcosim(path, 0.01, h)
    gs = Master(system).run(0.01, h)
    np.testing.assert_allclose(lc.vector("plant.q")[0], q0, rtol=0, atol=1e-15)
    # consistent start: tau_0 = C(r_0, y_0) with the PID gains (the error is 0.05 rad)
    ref = gs.vector("ik.q_ref")[0], gs.vector("ik.qd_ref")[0], gs.vector("ik.qdd_ref")[0]
    tau_pid = ComputedTorque(robot, **pid).torque(*ref, q0, np.zeros(4))
    tau_pd = ComputedTorque(robot, **pd).torque(*ref, q0, np.zeros(4))
    np.testing.assert_allclose(lc.vector("controller.tau")[0], tau_pid, rtol=0, atol=1e-9)
    np.testing.assert_allclose(gs.vector("controller.tau")[0], tau_pid, rtol=0, atol=1e-9)
    assert np.max(np.abs(tau_pid - tau_pd)) > 0.1

    fm = run_ssp_fmpy(path, 0.01, h)
    q1, qd1 = fm.vector("plant.q")[0], fm.vector("plant.qd")[0]         # t = h, after a free-fall step
    assert np.max(np.abs(q1 - q0)) < 1e-4
    # fmpy's second step: the controller was fed q_ref = r_0 (ik held its start solution),
    # qd_ref = qdd_ref = 0, q(t1), qd(t1); its integral z = (r_0 - q1) h; tau read after the step
    law = ComputedTorque(robot, **pid)
    law.advance(r0, q1, h)
    expected = law.torque(r0, np.zeros(4), np.zeros(4), q1, qd1)
    np.testing.assert_allclose(fm.vector("controller.tau")[1], expected, rtol=0, atol=1e-9)


def test_unwired_inputs_keep_their_start_values(fmu_root, tmp_path, robot):
    """Only wired inputs become connectors: fmpy.ssp would wire an unconnected input connector to
    the source of the input before it (or crash), and set it every step. A lone plant (of every
    robot) keeps its start values (tau = 0, grip false where it has one) in both tools; an SSD
    with a loose input is refused."""
    from robofmu.system.diagram import BlockSpec, System

    lone = System([BlockSpec("plant", f"{robot}/plant.fmu")], [], fmu_dir=fmu_root, name="lone-plant",
                  stop_time=0.01)
    path = export_ssp(lone, tmp_path / "lone.ssp")
    root = ET.fromstring(ssd_text(path))
    kinds = {c.get("kind") for c in root.iter(f"{{{NS['ssd']}}}Connector")}
    assert kinds == {"output"} and root.find("ssd:System/ssd:Connections", NS) is None
    fm, lc = run_ssp_fmpy(path, 0.005, 1e-3), run_ssp_libcosim(path, 0.005, 1e-3)
    np.testing.assert_allclose(fm.vector("plant.q"), lc.vector("plant.q")[1:], rtol=0, atol=1e-12)
    moved = np.max(np.abs(lc.vector("plant.q")[-1] - lc.vector("plant.q")[0]))
    home = load_model(robot).configuration("home")
    if np.any(load_model(robot).gravity_torque(home)):
        assert moved > 1e-4                                   # falls
    else:
        assert moved == 0.0                                   # 3rrp, a horizontal plane: at rest

    text = ssd_text(path).replace(
        '<ssd:Connector name="q[1]" kind="output">',
        '<ssd:Connector name="tau[1]" kind="input"><ssc:Real unit="N.m" /></ssd:Connector>'
        '<ssd:Connector name="q[1]" kind="output">')
    loose = tmp_path / "loose.ssp"
    with zipfile.ZipFile(path) as src, zipfile.ZipFile(loose, "w") as dst:
        for item in src.namelist():
            dst.writestr(item, text if item == "SystemStructure.ssd" else src.read(item))
    with pytest.raises(ValueError, match=r"unconnected input connectors \(plant\.tau\[1\]\)"):
        run_ssp_fmpy(loose, 0.005, 1e-3)


# -- the algorithms ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("h", STEPS)
@pytest.mark.parametrize("experiment", EXPERIMENTS)
def test_libcosim_reproduces_the_master_in_jacobi_mode(runs, systems, experiment, h):
    """Same exchange (chess: tau_k = C(r_(k-2), y_(k-1)); one step per feedthrough block in
    every diagram), same consistent start: equal to rounding (libcosim counts time in integer
    nanoseconds, the master in k h). Every Real output libcosim records is compared, to 1e-12
    of its own range (at least 1 unit): the times differ by an ulp, the trajectories by 1-3
    ulp, the states by < 3e-14; the torque tau = M(q) (qdd_ref + kd de + kp e) + N multiplies
    such rounding by M (kp, kd): rpp's M_11 = 22 kg m^2 (chess: ~0.08) gives it torques of up
    to 100 N.m that agree to 1.5e-11 N.m (1.5e-13 of the range)."""
    lc, jac = runs("libcosim", h, experiment), runs("jacobi", h, experiment)
    np.testing.assert_allclose(lc.time, jac.time, rtol=0, atol=1e-12)
    real = real_columns(jac.columns)
    assert sorted(lc.columns) == sorted(real)
    vectors = ["plant.q", "plant.qd", "controller.tau", dict(systems(experiment).extra["roles"])["q_ref"]]
    assert all(f"{v}[1]" in lc.columns for v in vectors)
    for name in lc.columns:
        scale = max(1.0, np.max(np.abs(jac[name])))
        np.testing.assert_allclose(lc[name], jac[name], rtol=0, atol=1e-12 * scale, err_msg=name)
    for name in ("plant.q", "plant.qd") + (("controller.tau", "ik.q_ref") if experiment == "chess-pd" else ()):
        np.testing.assert_allclose(lc.vector(name), jac.vector(name), rtol=0, atol=1e-12, err_msg=name)
    # and the comparison is not vacuous: the master's Gauss-Seidel run is another run
    assert np.max(np.abs(runs("gs", h, experiment).vector("plant.q") - jac.vector("plant.q"))) > 1e-7


def test_libcosim_against_gauss_seidel_differs_by_its_delays(runs):
    """libcosim vs the master's Gauss-Seidel: the reference 2 steps late, the feedback 1 step late.
    Each joint's difference is at most (2 + 1) h max|qd_ref| and, since the two delays act in
    opposite directions, about (2 - 1) h max|qd_ref|: a real lag, first order in h."""
    worst = {}
    for h in STEPS:
        lc, gs = runs("libcosim", h), runs("gs", h)
        qd_ref = np.max(np.abs(gs.vector("ik.qd_ref")), axis=0)         # rad/s, per joint
        dq = np.max(np.abs(lc.vector("plant.q") - gs.vector("plant.q")), axis=0)
        lag = dq / (h * qd_ref)                                          # in steps; measured 0.95 .. 1.43
        assert np.all(lag <= 3.0), (h, lag)
        assert np.all(lag >= 0.5), (h, lag)
        worst[h] = dq.max()
    ratio = worst[STEPS[1]] / worst[STEPS[0]]
    assert 0.4 < ratio < 0.6, worst                                       # halves with h


def test_fmpy_ssp_differs_by_its_start_up_only(runs, loop_model):
    """fmpy.ssp vs libcosim and vs the master's Jacobi run: the two wrong start-up torques
    (and possibly one step of trajectory on the wrong side of a breakpoint), a transient that
    decays at the closed-loop rate; proportional to h."""
    omega_d, decay = loop_model
    worst = {}
    for h in STEPS:
        fm, lc, jac, gs = runs("fmpy", h), runs("libcosim", h), runs("jacobi", h), runs("gs", h)
        assert fm.time[0] == pytest.approx(h) and len(fm.time) == round(STOP / h)
        v_a, v_b = kicks(gs, h)
        jump = np.max(np.abs(np.diff(gs.vector("ik.qdd_ref"), axis=0)))
        for other in (lc, jac):
            t, dq = joint_diff(fm, other)
            bound = 2 * ((v_a + v_b) / omega_d * np.exp(-decay * t) + h * jump / omega_d) + 1e-9
            assert np.all(dq <= bound), (h, t[np.argmax(dq / bound)], np.max(dq / bound))
            t, dqd = joint_diff(fm, other, "plant.qd")
            omega_n = math.hypot(omega_d, decay)
            bound = 2 * ((v_a + v_b) * omega_n / omega_d * np.exp(-decay * t) + h * jump) + 1e-9
            assert np.all(dqd <= bound), (h, t[np.argmax(dqd / bound)], np.max(dqd / bound))
        # the start-up is really there (fmpy's first step is a free fall) ...
        assert np.max(np.abs(fm.vector("plant.qd")[0] - lc.vector("plant.qd")[1])) > 0.5 * v_a
        worst[h] = joint_diff(fm, lc)[1].max()
        # ... and so are the steps of delay against Gauss-Seidel, bounded as libcosim's plus the start-up
        t, dq = joint_diff(fm, gs)
        qd_ref = np.max(np.abs(gs.vector("ik.qd_ref")))
        assert dq.max() <= 2 * (3 * h * qd_ref + (v_a + v_b) / omega_d + h * jump / omega_d)
    ratio = worst[STEPS[1]] / worst[STEPS[0]]
    assert 0.4 < ratio < 0.6, worst                                       # halves with h

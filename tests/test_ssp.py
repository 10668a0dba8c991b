"""chess-pd exported as an SSP 1.0 package, run by libcosim and by fmpy.ssp, against the master.

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
import zipfile
from xml.etree import ElementTree as ET

import numpy as np
import pytest

from robofmu.components.control import ComputedTorque
from robofmu.components.ik import make_ik
from robofmu.components.robot import Robot, load_spec
from robofmu.system.experiment import load
from robofmu.system.master import Master
from robofmu.system.ssp import NS, export_ssp, run_ssp_fmpy, run_ssp_libcosim, ssd_text

STOP = 2.0                  # s: first move (0-1 s), pause, start of the second move
STEPS = (1e-3, 5e-4)        # s
BLOCKS = ["trajectory", "ik", "controller", "plant"]


@pytest.fixture(scope="module")
def system(fmu_dir):
    return load("chess-pd", fmu_dir=fmu_dir.parent)


@pytest.fixture(scope="module")
def ssp(system, tmp_path_factory):
    return export_ssp(system, tmp_path_factory.mktemp("ssp") / "chess-pd.ssp")


@pytest.fixture(scope="module")
def runs(system, ssp):
    """runs(tool, h) -> Result, each computed once: 'gs', 'jacobi' (master), 'libcosim', 'fmpy'."""
    cache = {}

    def get(tool, h):
        if (tool, h) not in cache:
            if tool in ("gs", "jacobi"):
                cache[tool, h] = Master(system).run(STOP, h, "gauss-seidel" if tool == "gs" else "jacobi")
            elif tool == "libcosim":
                pytest.importorskip("libcosimpy", reason="libcosimpy (dev extra) is not installed")
                cache[tool, h] = run_ssp_libcosim(ssp, STOP, h)
            else:
                cache[tool, h] = run_ssp_fmpy(ssp, STOP, h)
        return cache[tool, h]

    return get


@pytest.fixture(scope="module")
def loop_model():
    """Closed-loop error dynamics of the PD computed-torque loop: (omega_d, decay rate) in 1/s."""
    g = load_spec("chess").gains("pd")
    wn = math.sqrt(g["kp"])
    zeta = g["kd"] / (2 * wn)
    return wn * math.sqrt(1 - zeta * zeta), zeta * wn


def kicks(gs, h):
    """Velocity kicks (rad/s, worst joint) of fmpy's two start-up steps: tau = 0 instead of
    tau_0, then tau = N(0, 0) instead of tau_0 (tau_0 = C(r_0, y_0), the consistent torque)."""
    robot = Robot("chess")
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
def test_ssd_is_well_formed_with_components_connectors_and_connections(system, ssp):
    with zipfile.ZipFile(ssp) as zf:
        names = set(zf.namelist())
    assert {"SystemStructure.ssd", "resources/controller.ssv"} | {f"resources/{b}.fmu" for b in BLOCKS} == names

    root = ET.fromstring(ssd_text(ssp))                                   # well-formed XML
    assert root.tag == f"{{{NS['ssd']}}}SystemStructureDescription"
    assert (root.get("version"), root.get("name")) == ("1.0", "chess-pd")
    components = root.findall("ssd:System/ssd:Elements/ssd:Component", NS)
    assert [c.get("name") for c in components] == BLOCKS
    assert [c.get("source") for c in components] == [f"resources/{b}.fmu" for b in BLOCKS]

    master = Master(system)
    master.check()
    for comp in components:
        md = master.nodes[comp.get("name")].md
        expected = {v.name: v for v in md.modelVariables if v.causality in ("input", "output")}  # all wired
        connectors = comp.findall("ssd:Connectors/ssd:Connector", NS)
        assert {c.get("name"): c.get("kind") for c in connectors} == \
               {n: v.causality for n, v in expected.items()}
        for c in connectors:
            (typ,) = list(c)
            assert typ.tag == f"{{{NS['ssc']}}}{expected[c.get('name')].type}"
    plant = components[3]
    assert plant.find("ssd:Connectors/ssd:Connector[@name='grip']/ssc:Boolean", NS) is not None
    assert plant.find("ssd:Connectors/ssd:Connector[@name='q[2]']/ssc:Real", NS).get("unit") == "rad"

    # every wire expanded to scalar variables: 3 x 3 + 3 x 4 + 2 x 4 + 4 + 2 = 35
    connections = [(c.get("startElement"), c.get("startConnector"), c.get("endElement"), c.get("endConnector"))
                   for c in root.findall("ssd:System/ssd:Connections/ssd:Connection", NS)]
    assert len(connections) == 35 == len(set(connections))
    assert ("ik", "q_ref[3]", "controller", "q_ref[3]") in connections
    assert ("trajectory", "grip", "plant", "grip") in connections
    ends = [(d, i) for _, _, d, i in connections]
    inputs = [(c.get("name"), con.get("name")) for c in components
              for con in c.findall("ssd:Connectors/ssd:Connector[@kind='input']", NS)]
    assert sorted(ends) == sorted(inputs)                                 # each input driven once

    experiment = root.find("ssd:DefaultExperiment", NS)
    assert float(experiment.get("startTime")) == 0.0 and float(experiment.get("stopTime")) == 13.0
    algo = experiment.find("ssd:Annotations/ssc:Annotation/osp:Algorithm/osp:FixedStepAlgorithm", NS)
    assert float(algo.get("baseStepSize")) == 1e-3

    # the controller's parameters, in an SSV file bound to it
    binding = components[2].find("ssd:ParameterBindings/ssd:ParameterBinding", NS)
    assert binding.get("source") == "resources/controller.ssv"
    with zipfile.ZipFile(ssp) as zf:
        ssv = ET.fromstring(zf.read("resources/controller.ssv"))
    values = {p.get("name"): float(p.find("ssv:Real", NS).get("value"))
              for p in ssv.findall("ssv:Parameters/ssv:Parameter", NS)}
    spec = load_spec("chess")
    assert values == {**spec.gains("pd"), "payload_mass": spec.payload_mass}


def test_ssd_and_ssv_validate_against_the_ssp_schemas(ssp, system, tmp_path):
    from fmpy.ssp.ssd import read_ssd

    for path, external in ((ssp, True), (export_ssp(system, tmp_path / "inline.ssp", inline=True), False)):
        ssd = read_ssd(str(path), validate=True)       # SSP 1.0 XSDs (fmpy's copies); the .ssv too
        assert [c.name for c in ssd.system.elements] == BLOCKS
        assert len(ssd.system.connections) == 35
        (binding,) = ssd.system.elements[2].parameterBindings
        assert (binding.source is not None) == external
        (pset,) = binding.parameterValues
        assert {p.name: float(p.value) for p in pset.parameters}["kp"] == 400.0
    with zipfile.ZipFile(tmp_path / "inline.ssp") as zf:
        assert not [n for n in zf.namelist() if n.endswith(".ssv")]


def test_parameter_bindings_reach_the_fmus(fmu_dir, tmp_path):
    """fmpy.ssp parses the bindings but applies none itself; run_ssp_fmpy applies them. The PID
    gains and a vector parameter (plant q0) must show in both tools' results."""
    pytest.importorskip("libcosimpy", reason="libcosimpy (dev extra) is not installed")
    robot = Robot("chess")
    s = load_spec("chess").scenario
    r0 = make_ik(robot).position(np.array(s["waypoints"][0]))
    q0 = r0 + np.array([0.0, 0.05, -0.05, 0.02])
    system = load("chess-pid", fmu_dir=fmu_dir.parent)
    system.block("plant").parameters["q0"] = q0.tolist()
    path = export_ssp(system, tmp_path / "pid.ssp")
    pid, pd = load_spec("chess").gains("pid"), load_spec("chess").gains("pd")
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


def test_unwired_inputs_keep_their_start_values(fmu_dir, tmp_path):
    """Only wired inputs become connectors: fmpy.ssp would wire an unconnected input connector to
    the source of the input before it (or crash), and set it every step. A lone plant keeps its
    start values (tau = 0, grip false) in both tools; an SSD with a loose input is refused."""
    pytest.importorskip("libcosimpy", reason="libcosimpy (dev extra) is not installed")
    from robofmu.system.diagram import BlockSpec, System

    lone = System([BlockSpec("plant", "chess/plant.fmu")], [], fmu_dir=fmu_dir.parent, name="lone-plant",
                  stop_time=0.01)
    path = export_ssp(lone, tmp_path / "lone.ssp")
    root = ET.fromstring(ssd_text(path))
    kinds = {c.get("kind") for c in root.iter(f"{{{NS['ssd']}}}Connector")}
    assert kinds == {"output"} and root.find("ssd:System/ssd:Connections", NS) is None
    fm, lc = run_ssp_fmpy(path, 0.005, 1e-3), run_ssp_libcosim(path, 0.005, 1e-3)
    np.testing.assert_allclose(fm.vector("plant.q"), lc.vector("plant.q")[1:], rtol=0, atol=1e-12)
    assert np.max(np.abs(lc.vector("plant.q")[-1] - lc.vector("plant.q")[0])) > 1e-4      # falls

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
def test_libcosim_reproduces_the_master_in_jacobi_mode(runs, h):
    """Same exchange (tau_k = C(r_(k-2), y_(k-1))), same consistent start: equal to rounding
    (libcosim counts time in integer nanoseconds, the master in k h)."""
    lc, jac = runs("libcosim", h), runs("jacobi", h)
    np.testing.assert_allclose(lc.time, jac.time, rtol=0, atol=1e-12)
    for name in ("plant.q", "plant.qd", "controller.tau", "ik.q_ref"):
        np.testing.assert_allclose(lc.vector(name), jac.vector(name), rtol=0, atol=1e-12, err_msg=name)


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

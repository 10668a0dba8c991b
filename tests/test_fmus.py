"""The chess FMUs through fmpy: validity, model structure, numbers, state, one-process runs."""
import re
import xml.etree.ElementTree as ET
import zipfile

import numpy as np
import pytest
from fmpy import simulate_fmu
from fmpy.validation import validate_fmu
from scipy.integrate import solve_ivp

from robofmu.components.control import ComputedTorque
from robofmu.components.ik import ChessIK
from robofmu.components.robot import Robot

from fmu_util import ChessLoop, open_block

BLOCKS = ["trajectory", "ik", "controller", "plant"]


def description(path):
    with zipfile.ZipFile(path) as z:
        return ET.fromstring(z.read("modelDescription.xml"))


@pytest.mark.parametrize("block", BLOCKS)
def test_fmpy_validate_reports_no_problem(fmu_dir, block):
    assert validate_fmu(str(fmu_dir / f"{block}.fmu")) == []


def test_model_identifiers_are_unique(fmu_dir):
    ids = [description(fmu_dir / f"{b}.fmu").find("CoSimulation").get("modelIdentifier") for b in BLOCKS]
    assert ids == [f"robofmu_chess_{b}" for b in BLOCKS]


@pytest.mark.parametrize("block", BLOCKS)
def test_variables_have_units_descriptions_structured_names(fmu_dir, block):
    root = description(fmu_dir / f"{block}.fmu")
    units = {u.get("name") for u in root.find("UnitDefinitions")}
    for sv in root.find("ModelVariables"):
        assert sv.get("description"), sv.get("name")
        assert re.fullmatch(r"[a-z_0-9]+(\[\d+\])?", sv.get("name"))
        if sv[0].tag == "Real":
            assert sv[0].get("unit") in units, sv.get("name")


def _deps(root, section):
    names = [sv.get("name") for sv in root.find("ModelVariables")]
    out = {}
    for u in root.find("ModelStructure").find(section):
        deps = u.get("dependencies")
        out[names[int(u.get("index")) - 1]] = None if deps is None else {names[int(i) - 1] for i in deps.split()}
    return out


def test_output_dependencies(fmu_dir):
    plant = _deps(description(fmu_dir / "plant.fmu"), "Outputs")
    assert set(plant) == {f"{b}[{i}]" for b in ("q", "qd") for i in range(1, 5)}
    assert all(d == set() for d in plant.values())           # no direct feedthrough
    init = _deps(description(fmu_dir / "plant.fmu"), "InitialUnknowns")
    assert init["q[3]"] == {"q0[3]"} and init["qd[2]"] == {"qd0[2]"}

    ik = _deps(description(fmu_dir / "ik.fmu"), "Outputs")
    x = {f"x_ref[{i}]" for i in (1, 2, 3)}
    xd = {f"xd_ref[{i}]" for i in (1, 2, 3)}
    xdd = {f"xdd_ref[{i}]" for i in (1, 2, 3)}
    assert ik["q_ref[1]"] == x and ik["qd_ref[4]"] == x | xd and ik["qdd_ref[2]"] == x | xd | xdd
    assert ik["reachable"] == x

    ct = _deps(description(fmu_dir / "controller.fmu"), "Outputs")
    inputs = {f"{b}[{i}]" for b in ("q_ref", "qd_ref", "qdd_ref", "q", "qd") for i in range(1, 5)} | {"grip"}
    assert all(d == inputs for d in ct.values()) and len(ct) == 4

    tr = _deps(description(fmu_dir / "trajectory.fmu"), "Outputs")
    assert all(d == set() for d in tr.values()) and "grip" in tr
    for b in BLOCKS:
        assert description(fmu_dir / f"{b}.fmu").find("ModelStructure").find("InitialUnknowns") is not None


def test_plant_constant_torque_matches_solve_ivp(fmu_dir):
    robot = Robot("chess")
    plant = open_block(fmu_dir, "plant")
    q0 = np.array(plant.get("q"))
    tau = robot.gravity_torque(q0) + np.array([0.05, 0.1, -0.05, 0.01])
    plant.set("tau", tau.tolist())
    h = 1e-3
    for k in range(1000):
        plant.do_step(k * h, h)
    q_fmu = np.array(plant.get("q"))
    plant.close()

    def f(t, x):
        return np.concatenate([x[4:], robot.forward_dynamics(x[:4], x[4:], tau)])

    ref = solve_ivp(f, (0, 1.0), np.concatenate([q0, np.zeros(4)]), method="DOP853", rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(q_fmu, ref.y[:4, -1], atol=1e-6)
    assert np.max(np.abs(q_fmu - q0)) > 0.1                 # it really moved


def test_simulate_fmu_trajectory(fmu_dir):
    res = simulate_fmu(str(fmu_dir / "trajectory.fmu"), stop_time=0.5, step_size=1e-3, output_interval=0.1,
                       output=["x_ref[1]", "x_ref[3]", "xd_ref[3]", "grip"])
    a = 4.5 * 0.15                                               # first move: dz = 0.15 in 1 s
    row = res[np.argmin(np.abs(res["time"] - 0.2))]
    assert row["x_ref[3]"] == pytest.approx(0.5 * a * 0.2**2, abs=1e-12)
    assert row["xd_ref[3]"] == pytest.approx(a * 0.2, abs=1e-12)
    assert row["x_ref[1]"] == pytest.approx(0.21) and not row["grip"]


def test_simulate_fmu_plant_free_fall(fmu_dir):
    robot = Robot("chess")
    res = simulate_fmu(str(fmu_dir / "plant.fmu"), stop_time=0.3, step_size=1e-3, output_interval=0.3,
                       output=[f"q[{i}]" for i in range(1, 5)])
    q0 = ChessIK(robot).position(np.array([0.21, 0.0, 0.0]))

    def f(t, x):
        return np.concatenate([x[4:], robot.forward_dynamics(x[:4], x[4:], np.zeros(4))])

    ref = solve_ivp(f, (0, 0.3), np.concatenate([q0, np.zeros(4)]), method="DOP853", rtol=1e-11, atol=1e-12)
    got = np.array([res[-1][f"q[{i}]"] for i in range(1, 5)])
    np.testing.assert_allclose(got, ref.y[:4, -1], atol=1e-8)


def test_simulate_fmu_ik_and_controller(fmu_dir):
    robot = Robot("chess")
    res = simulate_fmu(str(fmu_dir / "ik.fmu"), stop_time=0.01, step_size=1e-3,
                       output=[f"q_ref[{i}]" for i in range(1, 5)] + ["reachable"])
    expected = ChessIK(robot).position(np.array([0.21, 0.0, 0.0]))   # inputs start at waypoint 1
    np.testing.assert_allclose([res[-1][f"q_ref[{i}]"] for i in range(1, 5)], expected, atol=1e-12)
    assert res[-1]["reachable"]
    res = simulate_fmu(str(fmu_dir / "controller.fmu"), stop_time=0.01, step_size=1e-3,
                       output=[f"tau[{i}]" for i in range(1, 5)])
    np.testing.assert_allclose([res[-1][f"tau[{i}]"] for i in range(1, 5)],
                               robot.gravity_torque(np.zeros(4)), atol=1e-12)


def test_feedthrough_outputs_follow_inputs_without_a_step(fmu_dir):
    robot = Robot("chess")
    ik = open_block(fmu_dir, "ik")
    x, xd, xdd = [0.25, 0.1, 0.12], [0.01, -0.02, 0.03], [0.1, 0.05, -0.2]
    ik.set("x_ref", x), ik.set("xd_ref", xd), ik.set("xdd_ref", xdd)
    q, qd, qdd = ChessIK(robot).solve(np.array(x), np.array(xd), np.array(xdd))
    np.testing.assert_allclose(ik.get("q_ref"), q, atol=1e-14)
    np.testing.assert_allclose(ik.get("qd_ref"), qd, atol=1e-14)
    np.testing.assert_allclose(ik.get("qdd_ref"), qdd, atol=1e-12)
    ik.close()

    ct = open_block(fmu_dir, "controller", parameters={"kp": 600.0, "kd": 25.0, "ki": 75.0})
    vals = {"q_ref": q, "qd_ref": qd, "qdd_ref": qdd, "q": q + 0.01, "qd": qd - 0.02}
    for k, v in vals.items():
        ct.set(k, v.tolist())
    law = ComputedTorque(Robot("chess"), 600.0, 25.0, 75.0)
    np.testing.assert_allclose(ct.get("tau"), law.torque(q, qd, qdd, q + 0.01, qd - 0.02), atol=1e-12)
    ct.do_step(0.0, 0.01)                        # the integral term takes the held error e = -0.01
    law.advance(q, q + 0.01, 0.01)
    np.testing.assert_allclose(ct.get("tau"), law.torque(q, qd, qdd, q + 0.01, qd - 0.02), atol=1e-12)
    assert law.z[0] == pytest.approx(-1e-4)
    ct.close()


def test_outputs_after_dostep_belong_to_the_end_of_the_step(fmu_dir):
    tr = open_block(fmu_dir, "trajectory")
    tr.do_step(0.0, 0.3)
    assert tr.get("x_ref[3]") == pytest.approx(0.5 * 4.5 * 0.15 * 0.3**2, abs=1e-15)
    tr.close()


def test_four_fmus_and_a_second_plant_in_one_process(fmu_dir):
    robot = Robot("chess")
    loop = ChessLoop(fmu_dir, controller={"payload_mass": 0.03})        # the model knows the pawn
    q0b = [0.5, 0.3, -0.6, -1.2]
    plant2 = open_block(fmu_dir, "plant", "plant2", parameters={"q0": q0b, "g": 0.0, "payload_mass": 0.0})
    plant2.set("tau", [0.0, 0.02, 0.0, -0.01])
    h, worst = 1e-3, 0.0
    for k in range(2000):
        x, _, y, _ = loop.step(h)
        worst = max(worst, np.max(np.abs(robot.fk(np.array(y[:4])) - np.array(x[:3]))))
        plant2.do_step(k * h, h)
    # the loop's plant tracked the task, unaffected by plant2
    assert worst < 1e-4
    # plant2 followed its own dynamics (no gravity, its own torque), unaffected by the loop
    robot.set_gravity(0.0)
    tau = np.array([0.0, 0.02, 0.0, -0.01])
    ref = solve_ivp(lambda t, s: np.concatenate([s[4:], robot.forward_dynamics(s[:4], s[4:], tau)]),
                    (0, 2.0), np.concatenate([q0b, np.zeros(4)]), method="DOP853", rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(plant2.get("q"), ref.y[:4, -1], atol=1e-7)
    loop.close()
    plant2.close()


def test_fmu_state_rollback_is_bit_for_bit(fmu_dir):
    loop = ChessLoop(fmu_dir, controller={"kp": 600.0, "kd": 25.0, "ki": 75.0})
    h = 1e-3
    for _ in range(500):
        loop.step(h)
    t_saved = loop.t
    states = [b.get_state() for b in loop.blocks]
    first = [loop.step(h) for _ in range(300)]
    for b, s in zip(loop.blocks, states):
        b.set_state(s)
    loop.t = t_saved
    second = [loop.step(h) for _ in range(300)]
    assert first == second                   # every output, every step, exactly
    # negative control: restoring every block but the controller (whose integral term has moved
    # on) changes the outputs, so the controller's internal state is part of what is restored
    for b, s in zip(loop.blocks, states):
        if b is not loop.ct:
            b.set_state(s)
    loop.t = t_saved
    third = [loop.step(h) for _ in range(300)]
    assert third != first
    loop.close()


def test_serialized_fmu_state_round_trip(fmu_dir):
    plant = open_block(fmu_dir, "plant")
    plant.set("tau", [0.1, 0.2, 0.0, 0.0])
    plant.set("grip", True)
    for k in range(50):
        plant.do_step(k * 1e-3, 1e-3)
    s = plant.slave
    blob = s.serializeFMUstate(s.getFMUstate())
    a = [plant.do_step((50 + k) * 1e-3, 1e-3) or plant.get("q") for k in range(50)]
    s.setFMUstate(s.deSerializeFMUstate(blob))
    b = [plant.do_step((50 + k) * 1e-3, 1e-3) or plant.get("q") for k in range(50)]
    assert a == b
    plant.close()

"""The chess FMUs through fmpy: numbers, state, one-process runs.

The FMU contract (validity, units, model structure, identifiers, rollback, bad input) is tested
for every robot's FMUs in test_contract.py.
"""
import numpy as np
import pytest
from fmpy import simulate_fmu
from scipy.integrate import solve_ivp

from robofmu.components.control import ComputedTorque
from robofmu.components.ik import make_solver
from robofmu.components.robots import load_model
from robofmu.system import experiment
from robofmu.system.diagram import BlockSpec, System
from robofmu.system.master import Master

from fmu_util import Loop, open_block


def test_plant_constant_torque_matches_solve_ivp(fmu_dir):
    robot = load_model("chess")
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
    robot = load_model("chess")
    res = simulate_fmu(str(fmu_dir / "plant.fmu"), stop_time=0.3, step_size=1e-3, output_interval=0.3,
                       output=[f"q[{i}]" for i in range(1, 5)])
    q0 = make_solver(robot).position(np.array([0.21, 0.0, 0.0]))

    def f(t, x):
        return np.concatenate([x[4:], robot.forward_dynamics(x[:4], x[4:], np.zeros(4))])

    ref = solve_ivp(f, (0, 0.3), np.concatenate([q0, np.zeros(4)]), method="DOP853", rtol=1e-11, atol=1e-12)
    got = np.array([res[-1][f"q[{i}]"] for i in range(1, 5)])
    np.testing.assert_allclose(got, ref.y[:4, -1], atol=1e-8)


def test_simulate_fmu_ik_and_controller(fmu_dir):
    robot = load_model("chess")
    res = simulate_fmu(str(fmu_dir / "ik.fmu"), stop_time=0.01, step_size=1e-3,
                       output=[f"q_ref[{i}]" for i in range(1, 5)] + ["reachable"])
    expected = make_solver(robot).position(np.array([0.21, 0.0, 0.0]))   # inputs start at waypoint 1
    np.testing.assert_allclose([res[-1][f"q_ref[{i}]"] for i in range(1, 5)], expected, atol=1e-12)
    assert res[-1]["reachable"]
    res = simulate_fmu(str(fmu_dir / "controller.fmu"), stop_time=0.01, step_size=1e-3,
                       output=[f"tau[{i}]" for i in range(1, 5)])
    np.testing.assert_allclose([res[-1][f"tau[{i}]"] for i in range(1, 5)],           # q = q_ref = home
                               robot.gravity_torque(robot.configuration("home")), atol=1e-12)


def test_feedthrough_outputs_follow_inputs_without_a_step(fmu_dir):
    robot = load_model("chess")
    ik = open_block(fmu_dir, "ik")
    x, xd, xdd = [0.25, 0.1, 0.12], [0.01, -0.02, 0.03], [0.1, 0.05, -0.2]
    ik.set("x_ref", x), ik.set("xd_ref", xd), ik.set("xdd_ref", xdd)
    q, qd, qdd = make_solver(robot).solve(np.array(x), np.array(xd), np.array(xdd))
    np.testing.assert_allclose(ik.get("q_ref"), q, atol=1e-14)
    np.testing.assert_allclose(ik.get("qd_ref"), qd, atol=1e-14)
    np.testing.assert_allclose(ik.get("qdd_ref"), qdd, atol=1e-12)
    ik.close()

    ct = open_block(fmu_dir, "controller", parameters={"kp": 600.0, "kd": 25.0, "ki": 75.0})
    vals = {"q_ref": q, "qd_ref": qd, "qdd_ref": qdd, "q": q + 0.01, "qd": qd - 0.02}
    for k, v in vals.items():
        ct.set(k, v.tolist())
    law = ComputedTorque(load_model("chess"), 600.0, 25.0, 75.0)
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


def test_four_fmus_and_a_second_plant_in_one_process(fmu_root):
    """The chess-pd loop (the controller's model knows the pawn) run by the master, with a
    second, unwired plant instance of the same FMU in the same process."""
    robot = load_model("chess")
    loop = experiment.load("chess-pd", fmu_dir=fmu_root)
    assert loop.block("controller").parameters["payload_mass"] == 0.03
    q0b = [0.5, 0.3, -0.6, -1.2]
    tau2 = [0.0, 0.02, 0.0, -0.01]
    plant2 = BlockSpec("plant2", "chess/plant.fmu",
                       {"q0": q0b, "g": 0.0, "payload_mass": 0.0, "tau": tau2})
    system = System(loop.blocks + [plant2], loop.wires, fmu_dir=fmu_root, name="loop-and-plant2",
                    stop_time=2.0, step=1e-3)
    master = Master(system)
    warnings = master.check()
    # unwired inputs keep their start values: said for plant2.grip, not for plant2.tau (given values)
    assert any("plant2.grip" in w for w in warnings), warnings
    assert not any("plant2.tau" in w for w in warnings), warnings
    result = master.run()
    assert len(result.time) == 2001
    q, x_ref = result.vector("plant.q"), result.vector("trajectory.x_ref")
    worst = max(np.max(np.abs(robot.fk(qk) - xk)) for qk, xk in zip(q, x_ref))
    # the loop's plant tracked the task, unaffected by plant2
    assert worst < 1e-4
    # plant2 followed its own dynamics (no gravity, its own torque), unaffected by the loop
    robot.set_gravity(0.0)
    tau = np.array(tau2)
    ref = solve_ivp(lambda t, s: np.concatenate([s[4:], robot.forward_dynamics(s[:4], s[4:], tau)]),
                    (0, 2.0), np.concatenate([q0b, np.zeros(4)]), method="DOP853", rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(result.vector("plant2.q")[-1], ref.y[:4, -1], atol=1e-7)


def test_fmu_state_rollback_is_bit_for_bit(fmu_root):
    # PID gains (kp 600, kd 25, ki 75), the pawn unknown to the controller's model
    loop = Loop("chess-pid-unknown-pawn", fmu_root)
    assert loop.plan.nodes["controller"].spec.parameters == {"kp": 600.0, "kd": 25.0, "ki": 75.0,
                                                              "payload_mass": 0.0}
    h = 1e-3
    for _ in range(500):
        loop.step(h)
    t_saved = loop.t
    states = loop.get_states()
    first = [loop.step(h) for _ in range(300)]
    loop.set_states(states, t_saved)
    second = [loop.step(h) for _ in range(300)]
    assert first == second                   # every output, every step, exactly
    assert len(first[0]) == 3 * 3 + 1 + 3 * 4 + 1 + 4 + 2 * 4 + 1 + 2 * 4  # trajectory, ik, controller, plant (q, qd,
    # within_limits, q_measured, qd_measured)
    # negative control: the controller's state saved at the same time by a loop whose arm started
    # elsewhere (same blocks, same controller parameters, another integral) changes the outputs,
    # so the controller's internal state is part of what is restored
    other = Loop("chess-pid-unknown-pawn", fmu_root, {"plant": {"q0": [0.01, 0.76, -2.36, 0.04]}})
    for _ in range(500):
        other.step(h)
    loop.set_states({**states, "controller": other.get_states()["controller"]}, t_saved)
    third = [loop.step(h) for _ in range(300)]
    assert third != first
    other.close()
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

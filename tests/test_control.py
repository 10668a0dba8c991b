"""Computed-torque law: with a perfect model the joint errors obey the linear error dynamics."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from robofmu.components.blocks import make_block
from robofmu.components.control import GAINS, ComputedTorque, check_gains
from robofmu.components.robots import RobotModel, available, load_description, load_model


def closed_loop(plant: RobotModel, law: ComputedTorque, q_ref, q0, t_end):
    """Continuous closed loop (plant + controller with integral state) at tight tolerance."""
    n = plant.n
    zeros = np.zeros(n)

    def f(t, x):
        q, qd, z = x[:n], x[n:2 * n], x[2 * n:]
        law.z[:] = z
        tau = law.torque(q_ref, zeros, zeros, q, qd)
        return np.concatenate([qd, plant.forward_dynamics(q, qd, tau), q_ref - q])

    x0 = np.concatenate([q0, zeros, zeros])
    return solve_ivp(f, (0, t_end), x0, method="DOP853", rtol=1e-11, atol=1e-12, dense_output=True)


def error_dynamics(kp, kd, ki):
    """State matrix of (z, e, e') with z' = e, e'' = -kd e' - kp e - ki z."""
    return np.array([[0, 1, 0], [0, 0, 1], [-ki, -kp, -kd]], dtype=float)


@pytest.mark.parametrize("gains", [dict(kp=400.0, kd=20.0, ki=0.0), dict(kp=600.0, kd=25.0, ki=75.0)])
def test_perfect_model_gives_linear_error_dynamics(gains):
    plant = load_model("chess")
    law = ComputedTorque(load_model("chess"), **gains)
    q_ref = np.array([0.4, 0.9, -1.6, -0.9])
    q0 = q_ref - np.array([0.05, -0.08, 0.1, 0.02])
    sol = closed_loop(plant, law, q_ref, q0, 1.0)
    A = error_dynamics(gains["kp"], gains["kd"], gains["ki"])
    for t in np.linspace(0.0, 1.0, 21):
        x = sol.sol(t)
        e = q_ref - x[:4]
        for j in range(4):
            predicted = expm(A * t) @ np.array([0.0, q_ref[j] - q0[j], 0.0])
            assert e[j] == pytest.approx(predicted[1], abs=1e-8)


def test_pd_closed_form_underdamped():
    # kp = 400, kd = 20: wn = 20 rad/s, zeta = 0.5
    wn, zeta = 20.0, 0.5
    wd = wn * np.sqrt(1 - zeta**2)
    plant, law = load_model("chess"), ComputedTorque(load_model("chess"), 400.0, 20.0)
    q_ref = np.array([0.0, 0.8, -1.5, -0.87])
    e0 = 0.1
    sol = closed_loop(plant, law, q_ref, q_ref - e0, 0.6)
    for t in (0.05, 0.1, 0.2, 0.4):
        expected = e0 * np.exp(-zeta * wn * t) * (np.cos(wd * t) + zeta / np.sqrt(1 - zeta**2) * np.sin(wd * t))
        np.testing.assert_allclose(q_ref - sol.sol(t)[:4], expected, atol=1e-8)


def test_unknown_payload_pd_keeps_a_static_error_pid_removes_it():
    """The pawn unknown to the model: PD settles at e = M^-1 (m g J_z) / kp, PID at 0."""
    plant = load_model("chess")
    plant.set_payload(0.03)
    q_ref = np.array([0.3, 0.8, -1.5, -0.87])
    pd = ComputedTorque(load_model("chess"), 400.0, 20.0)
    sol = closed_loop(plant, pd, q_ref, q_ref, 4.0)
    e_pd = q_ref - sol.y[:4, -1]
    model = load_model("chess")
    # at rest at q = q_ref - e: M_model(q) kp e + g_model(q) = g_true(q); fixed-point iteration
    expected = np.zeros(4)
    for _ in range(20):
        q = q_ref - expected
        expected = np.linalg.solve(model.mass_matrix(q), plant.gravity_torque(q) - model.gravity_torque(q)) / 400.0
    np.testing.assert_allclose(e_pd, expected, rtol=1e-6, atol=1e-12)
    assert np.max(np.abs(e_pd)) > 1e-4
    pid = ComputedTorque(load_model("chess"), 600.0, 25.0, 75.0)
    sol = closed_loop(plant, pid, q_ref, q_ref, 40.0)
    # the slowest closed-loop pole is near -ki/kp = -0.125 1/s: the error decays like exp(-t/8)
    e20 = np.max(np.abs(q_ref - sol.sol(20.0)[:4]))
    e40 = np.max(np.abs(q_ref - sol.sol(40.0)[:4]))
    assert e40 < 1e-2 * np.max(np.abs(e_pd))
    assert e40 < e20 * np.exp(-0.1 * 20.0)


def test_integral_advances_with_the_held_error():
    law = ComputedTorque(load_model("chess"), 1.0, 1.0, 2.0)
    law.advance(np.array([1.0, 0, 0, 0]), np.array([0.5, 0, 0, 0.25]), 0.01)
    np.testing.assert_allclose(law.z, [0.005, 0, 0, -0.0025])


@pytest.mark.parametrize("name, kwargs, rule", [
    ("kp", dict(kp=-1.0, kd=1.0), "> 0"), ("kd", dict(kp=1.0, kd=np.nan), "> 0"),
    ("ki", dict(kp=1.0, kd=1.0, ki=-0.1), ">= 0"),
    ("kp", dict(kp=0.0, kd=1.0), "> 0"), ("kd", dict(kp=1.0, kd=0.0), "> 0"),       # no restoring force, no damping
])
def test_invalid_gain_names_it(name, kwargs, rule):
    with pytest.raises(ValueError, match=rf"{name}: parameter {name} = \S+ \S+ is invalid: must be {rule}$"):
        ComputedTorque(load_model("chess"), **kwargs)


def test_one_gain_rule_for_the_law_the_block_and_the_descriptions():
    """kp > 0, kd > 0, ki >= 0: GAINS bounds the controller block's parameters (gain_scale > 0 keeps
    the scaled gains within it), every described gain set keeps it, the block starts at the
    description's default_gains."""
    assert [(r.name, r.low, r.above, r.default) for r in GAINS] == [("kp", None, 0.0, None), ("kd", None, 0.0, None),
                                                                      ("ki", 0.0, None, 0.0)]
    assert check_gains(400, 20) == (400.0, 20.0, 0.0)
    for robot in available():
        description = load_description(robot)
        for gains in description.gains.values():
            assert check_gains(gains.kp, gains.kd, gains.ki) == (gains.kp, gains.kd, gains.ki)
        if "controller" not in description.blocks:
            continue
        block = make_block(robot, "controller")
        start = description.gain_set(description.default_gains)
        for rule in GAINS:
            variable = block.variables[block.index[rule.name]]
            bounds = (variable.parameter.low, variable.parameter.above, variable.unit)
            assert bounds == (rule.low, rule.above, rule.unit)
            assert variable.start == getattr(start, rule.name)
        scale = block.variables[block.index["gain_scale"]].parameter
        assert (scale.low, scale.above) == (None, 0.0)


@pytest.mark.parametrize("robot", available())
def test_the_law_is_mass_matrix_times_command_plus_nonlinear_effects(robot, rng):
    """tau (one inverse-dynamics pass) = M(q) u + N(q, qd), M and N computed apart, on every robot."""
    model = load_model(robot)
    law = ComputedTorque(model, 400.0, 20.0, 75.0)
    law.z[:] = rng.normal(0.0, 1e-3, model.n)
    home = model.configuration("home")
    for _ in range(5):
        q = home + rng.normal(0.0, 0.05, model.n)
        qd, q_ref, qd_ref, qdd_ref = (rng.normal(0.0, 0.3, model.n) for _ in range(4))
        q_ref = q + 0.01 * q_ref
        u = qdd_ref + 20.0 * (qd_ref - qd) + 400.0 * (q_ref - q) + 75.0 * law.z
        expected = model.mass_matrix(q) @ u + model.nonlinear_effects(q, qd)
        np.testing.assert_allclose(law.torque(q_ref, qd_ref, qdd_ref, q, qd), expected,
                                   rtol=1e-12, atol=1e-12 * np.max(np.abs(expected)))

"""The generic blocks a closed-chain robot needs, checked on 3rrp (and the serial arms where generic):
the circle profile, the jacobian block, the plant with an end-effector wrench, the controller
starting at home.

Independent checks: the circle against robots.md's closed form for ``3rrp-circle`` and against
finite differences of itself; the Jacobian against finite differences of the pose found by the
Lagrange formulation's loop closures (``parallel_lagrange``, which does not import the robot
model) and, for the serial arms, of their FK; the wrench plant's first step against
qdd = M^-1 J^T f_ext and its x outputs against the loop closures.
"""
from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from robofmu.components.blocks import block_class, make_block
from robofmu.components.robots import available, load_description, load_model
from robofmu.components.robots.parallel_lagrange import LagrangeRRP3
from robofmu.components.trajectory import Circle

from fmu_util import open_block

HOME_POSE = np.array([0.0, 0.0, -math.pi / 3])          # robots.md: q = (0, 120, 240) deg


def closures() -> LagrangeRRP3:
    mech = load_description("3rrp").mechanism
    return LagrangeRRP3(mech.r, mech.link_mass, mech.link_com, mech.link_inertia, mech.ee_mass,
                        mech.ee_inertia, line_offsets=mech.line_offsets)


# -- the circle profile ----------------------------------------------------------------------------
def spec_circle(t: float):
    """robots.md 3rrp-circle written out: phi 0 -> 2 pi in 4 s by LSPB with cruise 1.5 (blend
    T/3, phidd = 4.5 * 2 pi / T^2), x = 0.05 (1 - cos phi), y = 0.05 sin phi,
    theta = -60 deg + 15 deg sin phi; with the derivatives by the chain rule."""
    T, d = 4.0, 2 * math.pi
    a = 4.5 * d / T ** 2
    if t < 0.0:                                   # at t = 0 it already accelerates (trajectory.py)
        phi, w, al = 0.0, 0.0, 0.0
    elif t >= T:
        phi, w, al = d, 0.0, 0.0
    elif t < T / 3:
        phi, w, al = 0.5 * a * t * t, a * t, a
    elif t <= 2 * T / 3:
        phi, w, al = 0.5 * a * (T / 3) ** 2 + 1.5 * d / T * (t - T / 3), 1.5 * d / T, 0.0
    else:
        r = T - t
        phi, w, al = d - 0.5 * a * r * r, a * r, -a
    A, th = 0.05, math.radians(15)
    x = [A * (1 - math.cos(phi)), A * math.sin(phi), -math.pi / 3 + th * math.sin(phi)]
    xd = [A * math.sin(phi) * w, A * math.cos(phi) * w, th * math.cos(phi) * w]
    xdd = [A * (math.cos(phi) * w * w + math.sin(phi) * al), A * (-math.sin(phi) * w * w + math.cos(phi) * al),
           th * (-math.sin(phi) * w * w + math.cos(phi) * al)]
    return np.array(x), np.array(xd), np.array(xdd)


@pytest.fixture(scope="module")
def circle_block():
    b = make_block("3rrp", "trajectory")
    b.configure()
    return b


@pytest.mark.parametrize("t", [-0.5, 0.0, 0.3, 4 / 3, 1.9, 2.0, 8 / 3, 3.1, 3.999, 4.0, 5.0])
def test_the_3rrp_circle_is_robots_md_closed_form(circle_block, t):
    circle_block.output(t)
    got = [circle_block.get(b) for b in ("x_ref", "xd_ref", "xdd_ref")]
    for g, e in zip(got, spec_circle(t)):
        np.testing.assert_allclose(g, e, rtol=0, atol=1e-13)


def test_the_3rrp_circle_starts_and_ends_at_the_home_pose_at_rest(circle_block):
    model = load_model("3rrp")
    for t in (0.0, 4.0):
        circle_block.output(t)
        np.testing.assert_allclose(circle_block.get("x_ref"), model.fk(model.configuration("home")), atol=1e-15)
        np.testing.assert_allclose(circle_block.get("xd_ref"), 0.0, atol=1e-15)
    assert circle_block.nominal_stop_time() == 4.0
    np.testing.assert_allclose(circle_block.breakpoints(), [0.0, 4 / 3, 8 / 3, 4.0], rtol=1e-15)


@pytest.mark.parametrize("sense, cruise, extra", [(1, 1.5, ()), (-1, 1.2, (0.3,)), (1, 2.0, (0.1, -2.0))])
def test_circle_derivatives_are_finite_differences(sense, cruise, extra):
    c = Circle([0.3, -0.1], 0.2, 0.7, sense, 2.5, cruise, offset=[0.5] * len(extra), amplitude=list(extra))
    assert c.dim == 2 + len(extra)
    eps = 1e-6
    for t in np.linspace(0.01, 2.49, 37):
        if np.min(np.abs(c.breakpoints - t)) < 1e-3:
            continue
        x, xd, xdd = c.evaluate(t, snap=False)
        xp, xdp, _ = c.evaluate(t + eps, snap=False)
        xm, xdm, _ = c.evaluate(t - eps, snap=False)
        np.testing.assert_allclose((xp - xm) / (2 * eps), xd, rtol=0, atol=1e-8)
        np.testing.assert_allclose((xdp - xdm) / (2 * eps), xdd, rtol=0, atol=1e-7)
        assert np.hypot(*(x[:2] - c.center)) == pytest.approx(0.2, abs=1e-15)    # on the circle
    x0, _, _ = c.evaluate(0.0)
    np.testing.assert_allclose(x0[:2], [0.3 + 0.2 * math.cos(0.7), -0.1 + 0.2 * math.sin(0.7)], atol=1e-15)
    _, xd, _ = c.evaluate(1.25)                     # mid-cruise: phid = cruise * 2 pi / T
    assert np.hypot(*xd[:2]) == pytest.approx(0.2 * cruise * 2 * math.pi / 2.5, rel=1e-12)
    # sense: counter-clockwise (angular momentum about the centre > 0) for +1
    x, xd, _ = c.evaluate(1.25)
    rel = x[:2] - c.center
    assert np.sign(rel[0] * xd[1] - rel[1] * xd[0]) == sense


@pytest.mark.parametrize("kwargs, message", [
    (dict(radius=0.0), "radius: must be > 0"),
    (dict(sense=0), "sense: must be 1"),
    (dict(duration=-1.0), "duration: must be > 0"),
    (dict(cruise_factor=1.0), "cruise_factor: must lie in (1, 2]"),
    (dict(center=[0.0]), "center: need 2 values"),
    (dict(offset=[0.0], amplitude=[]), "amplitude: need 1 values"),
])
def test_invalid_circle_names_the_argument(kwargs, message):
    args = dict(center=[0.0, 0.0], radius=1.0, start_angle=0.0, sense=1, duration=1.0) | kwargs
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)").replace("]", r"\]")):
        Circle(**args)


def test_circle_block_refuses_sense_zero(circle_block):
    b = make_block("3rrp", "trajectory")
    b.set("sense", 0)
    with pytest.raises(ValueError, match="parameter sense = 0 is invalid"):
        b.configure()


# -- the jacobian block ------------------------------------------------------------------------------
def test_3rrp_jacobian_block_is_finite_differences_of_the_loop_closures():
    b = make_block("3rrp", "jacobian")
    b.configure()
    lag = closures()
    rng = np.random.default_rng(9)
    home = load_model("3rrp").configuration("home")
    for _ in range(20):
        q = home + rng.uniform(-0.3, 0.3, 3)
        b.set("q", q)
        b.output(0.0)
        J = b.get("J").reshape(3, 3)
        pose = lag.pose_from_joints(q, HOME_POSE)
        eps = 1e-6
        fd = np.column_stack([(lag.pose_from_joints(q + eps * e, pose) - lag.pose_from_joints(q - eps * e, pose))
                              / (2 * eps) for e in np.eye(3)])
        np.testing.assert_allclose(J, fd, rtol=1e-7, atol=1e-9)


@pytest.mark.parametrize("robot", [r for r in available() if load_description(r).model_kind == "serial"])
def test_jacobian_block_takes_a_serial_arm_too(robot):
    """Generic: the block is built for any robot (no serial robot lists it: its J is what the
    IK already uses), J = finite differences of the arm's FK, units task over joint."""
    model = load_model(robot)
    b = block_class("jacobian")(model)
    b.configure()
    q = model.configuration("home") + 0.05
    b.set("q", q)
    b.output(0.0)
    J = b.get("J").reshape(model.task_rows, model.n)
    eps = 1e-6
    fd = np.column_stack([(model.fk(q + eps * e) - model.fk(q - eps * e)) / (2 * eps) for e in np.eye(model.n)])
    if model.orientation_axes:                      # a pose task: the rotation about the frame's own axes
        turn = np.column_stack([pin.log3(model.rotation(q - eps * e).T @ model.rotation(q + eps * e)) / (2 * eps)
                                for e in np.eye(model.n)])
        fd = np.vstack([fd, turn[list(model.orientation_axes)]])
    np.testing.assert_allclose(J, fd, rtol=0, atol=1e-8)
    units = {v.name: v.unit for v in b.variables}
    tasks = model.task_units(0) + ["rad"] * len(model.orientation_axes)
    for i in range(model.task_rows):
        for j in range(model.n):
            expected = {("m", "rad"): "m/rad", ("m", "m"): "1", ("rad", "rad"): "1"}[(tasks[i], model.joint_units(0)[j])]
            assert units[f"J[{i + 1},{j + 1}]"] == expected


def test_jacobian_fmu_outputs_and_names(fmu_root):
    b = open_block(fmu_root / "3rrp", "jacobian")
    try:
        names = [n for n, v in b.variables.items() if v.causality == "output"]
        assert names == [f"J[{i},{j}]" for i in (1, 2, 3) for j in (1, 2, 3)]
        assert b.names("J") == names                               # the base J, row-major
        units = [b.variables[n].unit for n in names]
        assert units == ["m/rad"] * 6 + ["1"] * 3
        J = np.array(b.get("J")).reshape(3, 3)
        np.testing.assert_allclose(J, load_model("3rrp").jacobian(load_model("3rrp").configuration("home")),
                                   rtol=0, atol=1e-15)
        # at home, written out: theta row 1/3 each (theta = mean of q - offsets), x row (0, -1, 1) r / sqrt(3)
        np.testing.assert_allclose(J[2], [1 / 3] * 3, atol=1e-15)
        np.testing.assert_allclose(J[0], [0.0, -0.2 / math.sqrt(3), 0.2 / math.sqrt(3)], atol=1e-15)
    finally:
        b.close()


# -- the plant with an end-effector wrench -------------------------------------------------------------
def test_3rrp_plant_under_a_wrench_accelerates_as_jt_f_predicts(fmu_root):
    model = load_model("3rrp")
    q0 = model.configuration("home")
    f = np.array([-0.001, 0.002, -0.0005])
    J = model.jacobian(q0)
    qdd = np.linalg.solve(model.mass_matrix(q0), J.T @ f)        # at rest: no velocity terms
    h = 1e-4
    b = open_block(fmu_root / "3rrp", "plant")
    try:
        np.testing.assert_allclose(b.get("x"), HOME_POSE, atol=1e-15)
        b.set("f_ext", f.tolist())
        b.do_step(0.0, h)
        q, qd, x = (np.array(b.get(n)) for n in ("q", "qd", "x"))
    finally:
        b.close()
    scale = np.max(np.abs(qdd))
    np.testing.assert_allclose(qd / h, qdd, rtol=0, atol=1e-5 * scale)
    np.testing.assert_allclose(2 * (q - q0) / h ** 2, qdd, rtol=0, atol=1e-5 * scale)
    np.testing.assert_allclose(x, closures().pose_from_joints(q, HOME_POSE), rtol=0, atol=1e-14)


def test_3rrp_plant_block_wrench_is_the_models_constrained_dynamics():
    """The block's derivative passes f_ext to forward_dynamics(q, qd, tau, f_ext)."""
    b = make_block("3rrp", "plant")
    b.configure()
    model = load_model("3rrp")
    x = np.concatenate([model.configuration("home") + [0.05, -0.02, 0.03], [0.3, -0.2, 0.1]])
    b.set_continuous_state(x)
    tau, f = np.array([0.01, -0.02, 0.005]), np.array([0.001, -0.003, 0.0002])
    b.set("tau", tau)
    b.set("f_ext", f)
    expected = model.forward_dynamics(x[:3], x[3:], tau + model.jacobian(x[:3]).T @ f)
    np.testing.assert_allclose(b.derivative(0.0), np.concatenate([x[3:], expected]), rtol=1e-12, atol=1e-14)


def test_only_a_model_with_a_wrench_gets_f_ext_and_x():
    for robot in available():
        names = {v.base for v in make_block(robot, "plant").variables}
        wrench = hasattr(load_model(robot), "wrench_torque")
        assert ("f_ext" in names) == ("x" in names) == wrench, robot
    assert hasattr(load_model("3rrp"), "wrench_torque")


# -- the controller at home --------------------------------------------------------------------------
def test_lone_3rrp_controller_fmu_initializes_and_holds_home(fmu_root):
    """q = 0 is a direct singularity of 3rrp: the controller's positions start at home instead."""
    b = open_block(fmu_root / "3rrp", "controller")
    try:
        home = load_model("3rrp").configuration("home").tolist()
        assert b.get("q") == home and b.get("q_ref") == home
        assert b.get("tau") == [0.0, 0.0, 0.0]            # no gravity in the horizontal plane
        b.do_step(0.0, 1e-3)
    finally:
        b.close()

"""Newton-Raphson IK (components/ik/newton.py): the tutorial's two examples (seed 003,
robots.md section 4), quadratic convergence, rates against finite differences, every failure
mode reported, and agreement with the closed forms of the robots that have one."""
from __future__ import annotations

import math

import numpy as np
import pytest

from robofmu.components.blocks import make_block
from robofmu.components.ik import Unreachable, make_solver, solver_class
from robofmu.components.robots import load_model

NewtonRaphson = solver_class("newton_raphson")


def planar_fk(q_abs):
    """robots.md section 4 with the tutorial's absolute angles, l1 = 1 m, l2 = 0.5 m."""
    return np.array([math.cos(q_abs[0]) + 0.5 * math.cos(q_abs[1]),
                     math.sin(q_abs[0]) + 0.5 * math.sin(q_abs[1])])


def offset_fk(q):
    q1, q2, l3 = q
    return np.array([-0.5 * math.sin(q1) - l3 * math.sin(q2) * math.cos(q1),
                     0.5 * math.cos(q1) - l3 * math.sin(q2) * math.sin(q1),
                     1.0 + l3 * math.cos(q2)])


def solve_from(robot, guess, target, **values):
    solver = NewtonRaphson(load_model(robot), q_guess=tuple(guess), **values)
    q = solver.position(np.array(target, dtype=float))
    return solver, q


# -- the tutorial's examples ------------------------------------------------------------------
def test_planar2r_example_converges_in_four_iterations():
    solver, q = solve_from("planar2r", (0.0, 1.0), (1.2, 0.6))
    np.testing.assert_allclose(q, [0.147142165383, 0.988432088926], atol=1e-12)
    assert q[0] + q[1] == pytest.approx(1.135574254309, abs=1e-12)       # the tutorial's q2 (absolute)
    assert solver.report["iterations"] == 4 and len(solver.history) == 5
    assert solver.report["residual"] < 1e-12
    np.testing.assert_allclose(planar_fk([q[0], q[0] + q[1]]), [1.2, 0.6], atol=1e-12)
    np.testing.assert_array_equal(solver.iterates[0], [0.0, 1.0])
    np.testing.assert_array_equal(solver.iterates[-1], q)
    for q_k, r_k in zip(solver.iterates, solver.history):        # each |F_k| is that of q_k
        a = [q_k[0], q_k[0] + q_k[1]]
        assert np.linalg.norm(planar_fk(a) - [1.2, 0.6]) == pytest.approx(r_k, rel=1e-9, abs=1e-15)


def test_rrp_offset_example_converges_in_five_iterations():
    solver, q = solve_from("rrp_offset", (0.0, 0.5, 0.5), (-0.6, 0.4, 1.5))
    np.testing.assert_allclose(q, [0.178160046146, 0.804633677101, 0.721110255093], atol=1e-12)
    assert solver.report["iterations"] == 5 and solver.report["residual"] < 1e-12
    np.testing.assert_allclose(offset_fk(q), [-0.6, 0.4, 1.5], atol=1e-12)


@pytest.mark.parametrize("robot, guess, target", [
    ("planar2r", (0.0, 1.0), (1.2, 0.6)),
    ("rrp_offset", (0.0, 0.5, 0.5), (-0.6, 0.4, 1.5)),
])
def test_convergence_is_quadratic(robot, guess, target):
    """|F_k+1| <= C |F_k|^2 with one C for every iteration that is not at round-off."""
    solver, _ = solve_from(robot, guess, target)
    history = np.array(solver.history)
    ratios = [history[k + 1] / history[k] ** 2 for k in range(len(history) - 1) if history[k + 1] > 1e-15]
    assert len(ratios) >= 3 and max(ratios) < 2.0
    linear = history[1:] / history[:-1]
    assert linear[-1] < 1e-6                                   # the last step gains > 6 digits


def test_planar2r_rates_of_the_tutorial():
    """xd = (0.1, -0.2) m/s gives qd_abs = (-1/6, -1/6) rad/s, i.e. URDF qd = (-1/6, 0); qd and
    qdd equal finite differences of the position solution along x(t) = x + xd t + xdd t^2/2."""
    model = load_model("planar2r")
    solver = NewtonRaphson(model, q_guess=(0.0, 1.0))
    x, xd, xdd = np.array([1.2, 0.6]), np.array([0.1, -0.2]), np.array([0.05, 0.1])
    q, qd, qdd = solver.solve(x, xd, xdd)
    np.testing.assert_allclose(qd, [-1.0 / 6.0, 0.0], atol=1e-10)
    h = 1e-4

    def q_at(t):
        solver.start_from(q)
        return solver.position(x + xd * t + 0.5 * xdd * t * t)

    fd_qd = (q_at(h) - q_at(-h)) / (2 * h)
    fd_qdd = (q_at(h) - 2 * q + q_at(-h)) / h ** 2
    np.testing.assert_allclose(qd, fd_qd, atol=1e-8)
    np.testing.assert_allclose(qdd, fd_qdd, atol=1e-5)
    # the same acceleration from the analytic derivative of the tutorial's (absolute) Jacobian
    a = np.array([q[0], q[0] + q[1]])
    a_dot = np.array([qd[0], qd[0] + qd[1]])
    J = np.array([[-math.sin(a[0]), -0.5 * math.sin(a[1])], [math.cos(a[0]), 0.5 * math.cos(a[1])]])
    Jdot = np.array([[-math.cos(a[0]) * a_dot[0], -0.5 * math.cos(a[1]) * a_dot[1]],
                     [-math.sin(a[0]) * a_dot[0], -0.5 * math.sin(a[1]) * a_dot[1]]])
    a_ddot = np.linalg.solve(J, xdd - Jdot @ a_dot)
    np.testing.assert_allclose(qdd, [a_ddot[0], a_ddot[1] - a_ddot[0]], atol=1e-10)


def test_rrp_offset_rates_against_finite_differences():
    model = load_model("rrp_offset")
    solver = NewtonRaphson(model, q_guess=(0.0, 0.5, 0.5))
    x, xd, xdd = np.array([-0.6, 0.4, 1.5]), np.array([0.05, -0.02, 0.1]), np.array([-0.1, 0.05, 0.02])
    q, qd, qdd = solver.solve(x, xd, xdd)
    h = 1e-4

    def q_at(t):
        solver.start_from(q)
        return solver.position(x + xd * t + 0.5 * xdd * t * t)

    np.testing.assert_allclose(qd, (q_at(h) - q_at(-h)) / (2 * h), atol=1e-8)
    np.testing.assert_allclose(qdd, (q_at(h) - 2 * q + q_at(-h)) / h ** 2, atol=1e-5)


# -- failure modes --------------------------------------------------------------------------------
def test_unreachable_target_is_reported_as_out_of_reach():
    solver = NewtonRaphson(load_model("planar2r"), q_guess=(0.0, 1.0))
    with pytest.raises(Unreachable, match=r"residual 1\.5 m .*out of reach"):
        solver.position(np.array([3.0, 0.0]))             # 1.5 m beyond the arm's reach of 1.5 m
    assert solver.report["residual"] == pytest.approx(1.5, abs=1e-5)   # the nearest the TCP gets
    solver = NewtonRaphson(load_model("planar2r"), q_guess=(0.0, 1.0))
    with pytest.raises(Unreachable, match=r"out of reach: no step lowers the residual below 0\.5 m"):
        solver.position(np.array([0.0, 0.0]))             # inside the inner circle, |l1 - l2| = 0.5 m


def test_target_on_a_singularity_is_reported():
    solver = NewtonRaphson(load_model("planar2r"), q_guess=(0.0, 1.0))
    with pytest.raises(Unreachable, match=r"singular"):
        solver.position(np.array([1.5, 0.0]))             # arm stretched: det J = l1 l2 sin q2 = 0


def plain_divergence_guess():
    """A start just off the stretched configuration: the first full Newton step is huge."""
    return (0.0, 1e-4)


def test_plain_method_diverges_where_the_damped_method_converges():
    target = np.array([0.6, 0.5])
    plain = NewtonRaphson(load_model("planar2r"), q_guess=plain_divergence_guess(), step_control="none")
    with pytest.raises(Unreachable, match=r"Newton-Raphson diverges from q = \[0.0, 0.0001\]: after 1 iterations"):
        plain.position(target)                         # the first step throws q far beyond the limits
    guarded = NewtonRaphson(load_model("planar2r"), q_guess=plain_divergence_guess())
    q = guarded.position(target)
    np.testing.assert_allclose(planar_fk([q[0], q[0] + q[1]]), target, atol=1e-12)


def test_zero_iteration_limit_accepts_only_a_converged_start():
    solver = NewtonRaphson(load_model("planar2r"), q_guess=(0.0, 1.0), max_iterations=0)
    with pytest.raises(Unreachable, match=r"did not converge within max_iterations = 0"):
        solver.position(np.array([1.2, 0.6]))
    start = np.array([0.147142165383, 0.988432088926])
    solver.start_from(NewtonRaphson(load_model("planar2r"), q_guess=(0.0, 1.0)).position(np.array([1.2, 0.6])))
    np.testing.assert_allclose(solver.position(np.array([1.2, 0.6])), start, atol=1e-12)
    assert solver.report["iterations"] == 0


def test_joint_limits_are_respected():
    """rrp_offset's slide has a lower limit: a target behind it, reachable only with l3 below it,
    is refused, and no iterate leaves the limits."""
    model = load_model("rrp_offset")
    lower, upper = model.position_limits()
    solver = NewtonRaphson(model, q_guess=(0.0, 0.5, 0.5))
    target = model.fk(np.array([0.3, 0.2, lower[2] * 0.5]))
    with pytest.raises(Unreachable):
        q = solver.position(target)
        assert np.all(q >= lower) and np.all(q <= upper)   # pragma: no cover - must not get here
    assert solver.report["residual"] > 1e-6


def test_a_guess_outside_the_limits_is_refused():
    model = load_model("rrp_offset")
    lower, _ = model.position_limits()
    with pytest.raises(ValueError, match=r"q_guess .* outside the joint limits"):
        NewtonRaphson(model, q_guess=(0.0, 0.5, lower[2] - 0.01))


@pytest.mark.parametrize("values, message", [
    ({"tolerance": 0.0}, r"parameter tolerance = 0 m is invalid: must be > 0"),
    ({"max_iterations": -1}, r"parameter max_iterations = -1 is invalid: must be >= 0"),
    ({"step_control": "magic"}, r"parameter step_control = 'magic' is invalid"),
    ({"q_guess": (0.0, float("nan"))}, r"parameter q_guess\[2\] = nan is invalid: must be finite"),
    ({"q_guess": (0.0, 1.0, 2.0)}, r"q_guess needs 2 values, got 3"),
])
def test_bad_parameters_are_refused_naming_them(values, message):
    with pytest.raises(ValueError, match=message):
        NewtonRaphson(load_model("planar2r"), **values)


# -- the IK block: reachable, warning, last valid solution held -----------------------------------
def ik_block(robot, **parameters):
    block = make_block(robot, "ik")
    for name, value in parameters.items():
        block.set(name, value)
    block.configure()
    return block


def feed(block, x, t):
    block.set("x_ref", x)
    block.output(t)
    return block.get("q_ref"), block.get("reachable")


@pytest.mark.parametrize("case, target, reason", [
    ("out of reach", (3.0, 0.0), "out of reach"),
    ("on a singularity", (1.5, 0.0), "singular"),
    ("zero iteration limit", None, "did not converge within max_iterations = 0"),
])
def test_block_reports_each_failure_and_holds_the_last_valid_solution(case, target, reason):
    block = ik_block("planar2r")
    valid, ok = feed(block, (1.2, 0.6), 0.0)
    assert ok and block.get("iterations") == 4
    block.advance(0.0, 1e-3)
    if target is None:                               # the limit bites at the next solve
        block = ik_block("planar2r", max_iterations=0)
        valid, ok = block.get("q_ref"), True
        target = (1.2, 0.6)
        q, reachable = feed(block, target, 0.0)
        np.testing.assert_array_equal(q, [0.0, 0.0])   # no valid solution yet: zeros, said so
    else:
        q, reachable = feed(block, target, 1e-3)
        np.testing.assert_array_equal(q, valid)
    assert not reachable
    warnings = [text for level, text in block.messages if level == "warning"]
    assert len(warnings) == 1 and reason in warnings[0]
    np.testing.assert_array_equal(block.get("qd_ref"), 0.0)
    assert np.isfinite(block.get("residual"))


def test_block_outputs_do_not_depend_on_how_often_they_are_evaluated():
    """The warm start is the solution of the last completed step: evaluating the outputs twice
    at one communication point gives the same iterations (not 0 the second time)."""
    block = ik_block("planar2r")
    feed(block, (1.2, 0.6), 0.0)
    block.advance(0.0, 1e-3)
    feed(block, (1.2001, 0.6), 1e-3)
    first = (block.get("iterations"), block.get("q_ref"))
    feed(block, (1.2001, 0.6), 1e-3)
    assert block.get("iterations") == first[0] > 0
    np.testing.assert_array_equal(block.get("q_ref"), first[1])


# -- against the closed forms ---------------------------------------------------------------------
def reference_task(robot, step=1e-3):
    """The robot's trajectory block sampled at ``step`` over its whole profile."""
    trajectory = make_block(robot, "trajectory")
    trajectory.configure()
    stop = trajectory.nominal_stop_time()
    for t in np.arange(0.0, stop + step / 2, step):
        trajectory.output(t)
        yield t, trajectory.get("x_ref")


@pytest.mark.parametrize("robot, closed_kind", [
    pytest.param("chess", None, marks=pytest.mark.slow), ("rrp", None),   # their own solvers are closed forms
    ("planar2r", "planar_elbow"), ("rrp_offset", "offset_rrp"),   # theirs is Newton-Raphson
])
def test_newton_raphson_agrees_with_the_closed_form_along_the_task(robot, closed_kind):
    """Warm-started at 1 ms, Newton-Raphson (with the closed form's held combinations, chess's
    tool pitch) equals the closed form to 1e-10 in at most 3 iterations per step."""
    model = load_model(robot)
    closed = make_solver(model) if closed_kind is None else solver_class(closed_kind)(model)
    assert closed.kind != "newton_raphson"
    newton = NewtonRaphson(model, constraint_rows=closed.constraint_rows,
                           constraint_values=closed.constraint_values, q_guess="home")
    worst, most = 0.0, 0
    previous = None
    for t, x in reference_task(robot):
        newton.start_from(previous)
        q = newton.position(x)
        worst = max(worst, float(np.max(np.abs(q - closed.position(x)))))
        if previous is not None:
            most = max(most, int(newton.report["iterations"]))
        previous = q
    assert worst < 1e-10
    assert most <= 3


def test_block_with_the_plain_method_reports_divergence_from_a_bad_guess():
    """The tutorial's plain method from a start next to the stretched singularity: reachable
    false, the warning names the divergence, and with no valid solution yet the block outputs
    zeros and says so."""
    block = ik_block("planar2r", step_control="none", q_guess=plain_divergence_guess())
    q, reachable = feed(block, (0.6, 0.5), 0.0)
    assert not reachable
    np.testing.assert_array_equal(q, [0.0, 0.0])
    (level, text), = block.messages
    assert level == "warning" and "diverges" in text and "no valid solution yet: outputs zero" in text

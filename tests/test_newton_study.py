"""Seed 003's tutorial (Newton-Raphson IK) reproduced: system/studies/newton.py on
system/studies/seed003_tutorial.toml, against the tutorial's printed values, an independent plain
Newton iteration, finite differences and sympy."""
from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp

from robofmu.components.ik import solver_class
from robofmu.components.robots import load_model
from robofmu.system.studies import newton as ns
from robofmu.system.studies.tables import STUDIES_DIR

STUDY = STUDIES_DIR / "seed003_tutorial.toml"


@pytest.fixture(scope="module")
def examples():
    return {e.robot: e for e in ns.run_study(STUDY)}


def plain_newton(model, q, x, tolerance=1e-12, max_iterations=20):
    """q_(k+1) = q_k - J(q_k)^-1 (fk(q_k) - x), numpy only: the iterates and their residuals."""
    q = np.array(q, dtype=float)
    iterates = [(q.copy(), float(np.linalg.norm(model.fk(q) - x)))]
    while iterates[-1][1] > tolerance and len(iterates) <= max_iterations:
        q = q - np.linalg.solve(model.jacobian(q), model.fk(q) - x)
        iterates.append((q.copy(), float(np.linalg.norm(model.fk(q) - x))))
    return iterates


def test_the_study_covers_both_robots_and_every_printed_value_agrees(examples):
    assert sorted(examples) == ["planar2r", "rrp_offset"]
    for example in examples.values():
        checks = example.checks()
        assert checks and all(ok for _, ok in checks), [what for what, ok in checks if not ok]


def test_planar2r_converges_in_4_iterations_to_the_printed_solution(examples):
    e = examples["planar2r"]
    assert e.iterations == 4 and len(e.iterates) == 5 and e.residual < 1e-12
    np.testing.assert_array_equal(e.iterates[0].q, [0.0, 1.0])          # the guess, (0, 1) rad absolute
    np.testing.assert_allclose(e.q, [0.147142165383, 0.988432088926], rtol=0, atol=5e-13)   # URDF, q2 relative
    np.testing.assert_allclose(e.seed(e.q), [0.147142165383, 1.135574254309], rtol=0, atol=5e-13)
    np.testing.assert_allclose(load_model("planar2r").fk(e.q), [1.2, 0.6], rtol=0, atol=1e-12)


def test_rrp_offset_converges_in_5_iterations_to_the_printed_solution(examples):
    e = examples["rrp_offset"]
    assert e.iterations == 5 and len(e.iterates) == 6 and e.residual < 1e-12
    np.testing.assert_array_equal(e.iterates[0].q, [0.0, 0.5, 0.5])
    np.testing.assert_allclose(e.q, [0.178160046146, 0.804633677101, 0.721110255093], rtol=0, atol=5e-13)
    np.testing.assert_array_equal(e.seed_from_joints, np.eye(3))


@pytest.mark.parametrize("robot", ["planar2r", "rrp_offset"])
def test_the_history_is_the_solvers_and_a_plain_newton_iteration_gives_it(examples, robot):
    e = examples[robot]
    model = load_model(robot)
    # the residuals are the solver's own report, and |F(q_k)| at the recorded iterates
    solver = solver_class("newton_raphson")(model, q_guess=tuple(e.guess), tolerance=1e-12)
    solver.position(e.target)
    assert [it.residual for it in e.iterates] == solver.history
    assert solver.report["iterations"] == e.iterations
    for it in e.iterates:
        assert it.residual == pytest.approx(np.linalg.norm(model.fk(it.q) - e.target), rel=1e-6, abs=1e-15)
    plain = plain_newton(model, e.guess, e.target)
    assert len(plain) == len(e.iterates)
    for (q, r), it in zip(plain, e.iterates):
        np.testing.assert_allclose(it.q, q, rtol=0, atol=1e-12)
        assert it.residual == pytest.approx(r, rel=1e-6, abs=1e-15)


@pytest.mark.parametrize("robot", ["planar2r", "rrp_offset"])
def test_convergence_is_quadratic(examples, robot):
    residuals = [it.residual for it in examples[robot].iterates]
    assert all(b < a for a, b in zip(residuals, residuals[1:]))
    ratios = ns.ratios(residuals)
    assert len(ratios) == len(residuals) - 1
    square, logs = zip(*ratios)
    assert max(square) < 2.0                              # |F_(k+1)| <= C |F_k|^2 throughout
    assert all(1.9 < v < 2.1 for v in logs[-2:])          # the exponent doubles near the root
    assert square[0] == pytest.approx(residuals[1] / residuals[0] ** 2)
    assert logs[0] == pytest.approx(math.log(residuals[1]) / math.log(residuals[0]))


def test_planar2r_both_elbow_branches(examples):
    e = examples["planar2r"]
    by_branch = {b.parameters["elbow"]: b for b in e.branches}
    assert all(b.kind == "planar_elbow" for b in e.branches) and sorted(by_branch) == ["down", "up"]
    np.testing.assert_allclose(by_branch["down"].q, e.q, rtol=0, atol=1e-12)     # the Newton-Raphson solution
    other = by_branch["up"]
    np.testing.assert_allclose(e.seed(other.q), [0.780153052619, -0.208279036307], rtol=0, atol=5e-13)
    np.testing.assert_allclose(other.q[1], -e.q[1], atol=1e-12)                 # the mirrored elbow
    assert max(b.residual for b in e.branches) < 1e-14


def test_rrp_offset_both_branches(examples):
    e = examples["rrp_offset"]
    by_branch = {b.parameters["branch"]: b for b in e.branches}
    assert sorted(by_branch) == ["negative", "positive"]
    np.testing.assert_allclose(by_branch["positive"].q, e.q, rtol=0, atol=1e-12)
    other = by_branch["negative"].q
    assert other[1] == pytest.approx(-e.q[1], abs=1e-12) and other[2] == pytest.approx(e.q[2], abs=1e-12)
    assert not np.allclose(other, e.q)
    np.testing.assert_allclose(load_model("rrp_offset").fk(other), e.target, rtol=0, atol=1e-14)


def test_planar2r_rates_are_the_tutorials_and_match_finite_differences(examples):
    e = examples["planar2r"]
    r = e.rates
    np.testing.assert_array_equal(r.xd, [0.1, -0.2])
    np.testing.assert_array_equal(r.xdd, [0.05, 0.1])
    np.testing.assert_allclose(e.seed(r.qd), [-1 / 6, -1 / 6], rtol=0, atol=1e-12)      # absolute angle rates
    np.testing.assert_allclose(r.qd, [-1 / 6, 0.0], rtol=0, atol=1e-12)                 # URDF: q2 relative
    np.testing.assert_allclose(r.qd_fd, r.qd, rtol=0, atol=1e-7)
    np.testing.assert_allclose(r.qdd_fd, r.qdd, rtol=0, atol=1e-7)
    # the definition: J qd = xd, J qdd + Jdot qd = xdd
    model = load_model("planar2r")
    np.testing.assert_allclose(model.jacobian(e.q) @ r.qd, r.xd, atol=1e-14)
    np.testing.assert_allclose(model.jacobian(e.q) @ r.qdd + model.jdot_qdot(e.q, r.qd), r.xdd, atol=1e-14)


def test_rrp_offset_rates_match_finite_differences(examples):
    e = examples["rrp_offset"]
    r = e.rates
    assert np.all(np.abs(r.qd) > 1e-3) and np.all(np.abs(r.qdd) > 1e-3)   # every joint moves and accelerates
    np.testing.assert_allclose(r.qd_fd, r.qd, rtol=0, atol=1e-7)
    np.testing.assert_allclose(r.qdd_fd, r.qdd, rtol=0, atol=1e-7)
    # an independent three-point estimate along x(t), with the closed-form solver (no Newton)
    model = load_model("rrp_offset")
    closed = solver_class("offset_rrp")(model, branch="positive")
    h = 1e-4
    x = {k: e.target + r.xd * k * h + 0.5 * r.xdd * (k * h) ** 2 for k in (-1, 0, 1)}
    q = {k: closed.position(v) for k, v in x.items()}
    np.testing.assert_allclose((q[1] - q[-1]) / (2 * h), r.qd, atol=1e-7)
    np.testing.assert_allclose((q[1] - 2 * q[0] + q[-1]) / h ** 2, r.qdd, atol=1e-5)


def test_the_printed_jdot_entry_differs_and_the_corrected_one_is_the_derivative(examples):
    j = examples["rrp_offset"].jdot
    assert j.entry == (2, 2) and j.coordinates == ["q1", "q2", "L3"]
    # J(2,2) as printed is the model's
    assert j.jacobian_value == pytest.approx(j.model_jacobian, abs=1e-15)
    # differentiate J(2,2) = -L3 cos q2 sin q1 here, independently of the module
    q1, q2, L3, q1d, q2d, L3d = sp.symbols("q1 q2 L3 q1d q2d L3d")
    J22 = -L3 * sp.cos(q2) * sp.sin(q1)
    derivative = sp.diff(J22, q1) * q1d + sp.diff(J22, q2) * q2d + sp.diff(J22, L3) * L3d
    corrected = -L3 * sp.cos(q2) * sp.cos(q1) * q1d + L3 * sp.sin(q2) * sp.sin(q1) * q2d - L3d * sp.cos(q2) * sp.sin(q1)
    printed = -L3 * sp.cos(q2) * sp.cos(q1) * q1d + L3 * sp.sin(q2) * sp.cos(q2) * q2d - L3d * sp.cos(q2) * sp.sin(q1)
    assert sp.simplify(derivative - corrected) == 0 and sp.simplify(derivative - printed) != 0
    assert sp.simplify(sp.sympify(j.corrected) - corrected) == 0 and sp.simplify(sp.sympify(j.printed) - printed) == 0
    assert j.corrected_is_derivative and not j.printed_is_derivative
    # numerically, at the example's state: the corrected one matches the model's Jdot, the printed one not
    assert j.corrected_value == pytest.approx(j.numerical, abs=1e-8)
    assert abs(j.printed_value - j.numerical) > 1e-3
    state = {sp.Symbol(k): v for k, v in j.state.items()}
    assert float(corrected.subs(state)) == pytest.approx(j.corrected_value, abs=1e-15)
    # the state is the example's: the Newton-Raphson solution and its rates
    e = examples["rrp_offset"]
    np.testing.assert_allclose([j.state[n] for n in ("q1", "q2", "L3")], e.q, rtol=0, atol=0)
    np.testing.assert_allclose([j.state[n] for n in ("q1d", "q2d", "L3d")], e.rates.qd, rtol=0, atol=0)
    # and the model's J changes along qd as the corrected entry says (an independent difference)
    model = load_model("rrp_offset")
    h = 1e-6
    fd = (model.jacobian(e.q + h * e.rates.qd)[1, 1] - model.jacobian(e.q - h * e.rates.qd)[1, 1]) / (2 * h)
    assert fd == pytest.approx(j.corrected_value, abs=1e-8)


def test_printed_values_match_to_half_a_unit_of_their_last_digit():
    assert ns.printed_tolerance("0.147142165383") == pytest.approx(5e-13)
    assert ns.printed_tolerance("12") == pytest.approx(0.5)
    assert ns.printed_tolerance("1.5e-3") == pytest.approx(5e-5)
    assert ns.printed_value("-1/6") == -1 / 6 and ns.printed_tolerance("-1/6") == pytest.approx(1e-12)
    assert ns.matches(0.1471421653834, "0.147142165383") and not ns.matches(0.1471421653836, "0.147142165383")
    assert ns.matches(-1 / 6, "-1/6") and not ns.matches(-0.1666666667, "-1/6")


def test_the_report_section(examples):
    lines = ns.report(STUDY, list(examples.values()), level=4)
    text = "\n".join(lines)
    assert "#### Planar 2R arm" in text and "#### RRP arm with a shoulder offset" in text
    assert "| 4 | (0.147142165383, 1.135574254309) |" in text
    assert "| 5 | (0.178160046146, 0.804633677101, 0.721110255093) |" in text
    assert "10 of 10 comparisons with the source agree." in text and "9 of 9 comparisons" in text
    assert "**differs**" not in text
    assert "| as printed | `-L3*cos(q2)*cos(q1)*q1d + L3*sin(q2)*cos(q2)*q2d - L3d*cos(q2)*sin(q1)`" in text
    headers = [line for line in text.splitlines() if line.startswith("| k |")]
    assert len(headers) == 2                # table rows keep their columns: every | in a cell is escaped
    for line in headers:
        assert line.replace("\\|", "").count("|") == 6


def test_the_study_runs_any_robot(tmp_path):
    """A study file of another robot (no coordinates of its own, a closed-form solver without branches)."""
    study = tmp_path / "other.toml"
    model = load_model("rrp")
    q = np.array([0.3, -0.2, 0.1])
    target = model.fk(q)
    study.write_text(f"""
[[examples]]
robot = "rrp"
guess = [0.0, 0.0, 0.125]
target = {list(map(float, target))}
[[examples.branches]]
solver = "spherical"
[examples.rates]
xd = [0.01, -0.02, 0.005]
xdd = [0.0, 0.01, -0.01]
""")
    (e,) = ns.run_study(study)
    np.testing.assert_allclose(e.q, q, atol=1e-12)
    np.testing.assert_allclose(e.branches[0].q, q, atol=1e-12)
    np.testing.assert_allclose(e.rates.qdd_fd, e.rates.qdd, atol=1e-7)
    assert e.names == ["q1", "q2", "q3"] and e.checks() == []
    text = "\n".join(ns.report(study, [e]))
    assert "### rrp" in text and "0 of 0 comparisons" in text

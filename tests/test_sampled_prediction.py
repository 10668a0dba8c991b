"""The sampled, delayed loop's prediction (system/stepresponse/sampled.py) against independent references.

The references: :func:`hand_loop`, the loop written out at the base step h with the plant's exact
ZOH over h from ``scipy.linalg.expm`` (not ``control.c2d``), the effort held over Ts and queued for
d samples; :func:`friction_loop`, the same with Coulomb friction integrated by ``solve_ivp``; the
characteristic polynomials derived by hand in sampled.py's notes; the Jury conditions derived
here with sympy. No FMUs.
"""
import math

import control
import numpy as np
import pytest
import scipy.linalg
import sympy
from scipy.integrate import solve_ivp

from robofmu.components.parameters import ParameterError
from robofmu.system.stepresponse import linear, sampled

PD = dict(kp=400.0, kd=20.0, ki=0.0)
PID = dict(kp=600.0, kd=25.0, ki=75.0)
H = 1e-3          # base step (s)
TS = 4e-3         # controller sample time (s), 4 H


def hand_loop(kp, kd, ki, h, ratio, d, steps, r=1.0, beta=0.0):
    """y at t = n h, n < steps: plant y'' = u - beta y' stepped exactly over h, controller every
    ``ratio`` steps, its effort applied d controller samples later (0 before)."""
    augmented = np.zeros((3, 3))
    augmented[0, 1], augmented[1, 1], augmented[1, 2] = 1.0, -beta, 1.0
    step = scipy.linalg.expm(augmented * h)
    phi, gamma = step[:2, :2], step[:2, 2]
    x, z, queue, u, ys = np.zeros(2), 0.0, [0.0] * d, 0.0, []
    for n in range(steps):
        if n % ratio == 0:
            queue.append(kp * (r - x[0]) - kd * x[1] + ki * z)
            z += ratio * h * (r - x[0])
            u = queue.pop(0)
        ys.append(x[0])
        x = phi @ x + gamma * u
    return np.array(ys)


def friction_loop(kp, kd, ki, ts, d, samples, r, coulomb_per_inertia, velocity_scale, method="LSODA"):
    """Errors r - y at t_k = k ts of the loop whose plant has tanh Coulomb friction unknown to the
    controller: y'' = u - (tau_c / m) tanh(y' / v_s), integrated over each held period."""
    def rhs(_, x, u):
        return [x[1], u - coulomb_per_inertia * math.tanh(x[1] / velocity_scale)]
    x, z, queue, errors = np.zeros(2), 0.0, [0.0] * d, []
    for _ in range(samples):
        errors.append(r - x[0])
        queue.append(kp * (r - x[0]) - kd * x[1] + ki * z)
        z += ts * (r - x[0])
        x = solve_ivp(rhs, (0.0, ts), x, method=method, rtol=1e-10, atol=1e-13, args=(queue.pop(0),)).y[:, -1]
    return np.array(errors)


def characteristic(kp, kd, ki, ts, d):
    """The hand-derived polynomial (sampled.py's notes), highest power first."""
    z = np.polynomial.Polynomial([0.0, 1.0])
    if ki == 0.0:
        p = z**d * (z - 1) ** 2 + kd * ts * (z - 1) + kp * ts**2 * (z + 1) / 2
    else:
        p = z**d * (z - 1) ** 3 + kd * ts * (z - 1) ** 2 + ts**2 / 2 * (z + 1) * (kp * (z - 1) + ki * ts)
    return p.coef[::-1]


# -- the prediction ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("h", [1e-3, 5e-3])
@pytest.mark.parametrize("gains", [PD, PID], ids=["pd", "pid"])
def test_at_the_communication_step_without_delay_it_is_discrete_prediction(gains, h):
    new, old = sampled.sampled_prediction(**gains, sample_time=h), linear.discrete_prediction(**gains, h=h)
    assert new.dt == old.dt == h
    for name in "ABCD":
        np.testing.assert_allclose(getattr(new, name), getattr(old, name), rtol=0, atol=1e-12)
    t = h * np.arange(400)
    np.testing.assert_allclose(sampled.predict_sampled(**gains, t=t, amplitude=0.02),
                               linear.predict(**gains, t=t, amplitude=0.02), rtol=0, atol=1e-12)


@pytest.mark.parametrize("beta", [0.0, 3.0])
@pytest.mark.parametrize("d", [0, 1, 2])
@pytest.mark.parametrize("gains", [PD, PID], ids=["pd", "pid"])
def test_base_step_grid_is_the_hand_written_multirate_loop(gains, d, beta):
    steps = 700
    t = H * np.arange(steps)
    ref = hand_loop(**gains, h=H, ratio=4, d=d, steps=steps, beta=beta)
    got = sampled.predict_sampled(**gains, t=t, sample_time=TS, delay_steps=d, damping=beta)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)
    # at the controller's samples it is the loop at dt = Ts
    at_samples = control.step_response(sampled.sampled_prediction(**gains, sample_time=TS, delay_steps=d,
                                                                   damping=beta), T=TS * np.arange(steps // 4)).outputs
    np.testing.assert_allclose(at_samples, ref[::4], rtol=0, atol=1e-12)
    # the grid, the hold and the delay each matter far beyond that tolerance
    assert np.max(np.abs(got - linear.predict(**gains, t=t))) > 0.01
    assert np.max(np.abs(got - hand_loop(**gains, h=H, ratio=4, d=d + 1, steps=steps, beta=beta))) > 0.01
    assert np.max(np.abs(got - hand_loop(**gains, h=H, ratio=4, d=d, steps=steps, beta=beta + 2.0))) > 0.003
    # nothing moves until the first effort arrives at t_d, then y = u t^2 / 2 (+ O(beta))
    assert np.all(got[: 4 * d + 1] == 0.0)
    assert got[4 * d + 1] == pytest.approx(gains["kp"] * H**2 / 2, rel=2 * beta * H)


@pytest.mark.parametrize("d", [0, 1, 2, 3])
@pytest.mark.parametrize("gains", [PD, PID], ids=["pd", "pid"])
def test_poles_are_the_roots_of_the_hand_derived_polynomial(gains, d):
    poles = control.poles(sampled.sampled_prediction(**gains, sample_time=TS, delay_steps=d))
    roots = np.roots(characteristic(**gains, ts=TS, d=d))
    assert len(poles) == len(roots) == d + (3 if gains["ki"] else 2)
    order = dict(key=lambda p: (round(p.real, 9), p.imag))
    np.testing.assert_allclose(sorted(poles.astype(complex), **order), sorted(roots, **order), atol=1e-9)
    assert sampled.spectral_radius(**gains, sample_time=TS, delay_steps=d) == pytest.approx(max(abs(roots)), abs=1e-9)


# -- the stability limit ----------------------------------------------------------------------------------
def test_limit_pd_without_delay_is_jurys_closed_form():
    kd = 20.0
    # z^2 + a1 z + a0 with a1 = kp T^2 / 2 + kd T - 2, a0 = 1 + kp T^2 / 2 - kd T: Jury asks
    # p(1) = kp T^2 > 0, p(-1) = 4 - 2 kd T > 0 and |a0| < 1, i.e. kp < 2 kd / T
    for ts in (1e-3, 4e-3, 1e-2):
        assert sampled.largest_stable_kp(kd, ts) == pytest.approx(2 * kd / ts, rel=1e-9)
    # zeta held (kd = 2 zeta sqrt(kp)): kp < 16 zeta^2 / T^2 from |a0| < 1, kp < 1 / (zeta T)^2 from p(-1)
    for zeta in (0.3, 0.5, 0.7, 1.0):
        assert sampled.largest_stable_kp(None, TS, zeta=zeta) == pytest.approx(min(16 * zeta**2, zeta**-2) / TS**2,
                                                                              rel=1e-9)


@pytest.mark.parametrize("kd, ts", [(20.0, 4e-3), (20.0, 1e-3), (60.0, 1e-2)])
def test_limit_pd_one_sample_late_is_jurys_bound_of_the_cubic(kd, ts):
    kp, k_d, t, z = sympy.symbols("kp kd T z", positive=True)
    phi = sympy.Matrix([[1, t], [0, 1]])
    gamma = sympy.Matrix([t**2 / 2, t])
    a = sympy.zeros(3, 3)                   # states (y, y', effort in flight)
    a[:2, :2], a[:2, 2], a[2, :2] = phi, gamma, -sympy.Matrix([[kp, k_d]])
    poly = sympy.Poly((z * sympy.eye(3) - a).det(), z)
    assert sympy.expand(poly.as_expr() - (z * (z - 1) ** 2 + k_d * t * (z - 1) + kp * t**2 * (z + 1) / 2)) == 0
    a3, a2, a1, a0 = poly.all_coeffs()
    jury = [poly.as_expr().subs(z, 1), -poly.as_expr().subs(z, -1), a3 - a0, a3 + a0,
            (a3**2 - a0**2) - (a0 * a2 - a1 * a3), (a3**2 - a0**2) + (a0 * a2 - a1 * a3)]
    values = {k_d: kd, t: ts}
    conditions = [sympy.lambdify(kp, c.subs(values)) for c in jury]

    def stable(x):
        return all(c(x) > 0 for c in conditions)

    bounds = sorted(float(r) for c in jury for r in sympy.solve(sympy.Eq(c.subs(values), 0), kp)
                    if r.is_real and r > 0)
    limit = next(b for b in bounds if stable(b * (1 - 1e-9)) and not stable(b * (1 + 1e-9)))
    assert sampled.largest_stable_kp(kd, ts, 1) == pytest.approx(limit, rel=1e-9)
    q = kd * ts                             # the closed form of the module notes
    assert limit == pytest.approx((2 * q - 3 + math.sqrt(9 - 8 * q)) / ts**2, rel=1e-12)
    assert limit < 2 * kd / ts / 2.5       # a sample of delay costs more than half of the gain


@pytest.mark.parametrize("kd, ki, d", [(20.0, 0.0, 2), (25.0, 75.0, 1), (25.0, 75.0, 0), (40.0, 400.0, 3)])
def test_limit_elsewhere_is_where_the_hand_polynomials_roots_leave_the_unit_circle(kd, ki, d):
    limit = sampled.largest_stable_kp(kd, TS, d, ki=ki)

    def radius(kp):
        return max(abs(np.roots(characteristic(kp, kd, ki, TS, d))))

    assert radius(limit * (1 - 1e-8)) < 1.0 < radius(limit * (1 + 1e-8))
    grid = np.linspace(ki / kd * 1.5 if ki else 1.0, limit, 60)[:-1]
    assert all(radius(kp) < 1.0 for kp in grid)       # an interval of stable kp below it


@pytest.mark.parametrize("gains", [dict(kd=20.0, ki=0.0), dict(kd=25.0, ki=75.0)], ids=["pd", "pid"])
def test_limit_at_4_ms_one_sample_late_holds_in_the_hand_written_loop(gains):
    limit = sampled.largest_stable_kp(gains["kd"], TS, 1, ki=gains["ki"])
    steps = 3000                                      # 3 s at 1 ms, 750 controller samples
    for factor, stable in ((0.9, True), (1.1, False)):
        kp = factor * limit
        error = 1.0 - hand_loop(kp, **gains, h=H, ratio=4, d=1, steps=steps)
        first, last = np.max(np.abs(error[1500:2000])), np.max(np.abs(error[2500:]))
        assert (sampled.spectral_radius(kp, **gains, sample_time=TS, delay_steps=1) < 1.0) == stable
        # the oscillation's envelope changes over 1 s (250 samples) as its pole pair's radius says
        # (a PID's slow real pole, the integral's, carries little of the error)
        poles = control.poles(sampled.sampled_prediction(kp, **gains, sample_time=TS, delay_steps=1))
        pair = max(abs(p) for p in poles if abs(p.imag) > 1e-9)
        assert math.log(last / first) == pytest.approx(250 * math.log(pair), rel=0.05)
        assert (last < first / 2.5) if stable else (last > 2.5 * first)


# -- friction the controller does not know ----------------------------------------------------------------
COULOMB, INERTIA = 1.0, 0.5        # N.m, kg.m^2: tau_c / m = 2 rad/s^2


def test_coulomb_friction_stops_a_pd_short_by_the_stick_error_and_the_prediction_misses_it():
    kp, kd, ts, amplitude = 400.0, 40.0, 2e-3, 0.05
    stick = sampled.friction_steady_state_error(kp, COULOMB, INERTIA)
    assert stick == COULOMB / (INERTIA * kp) == 0.005
    # v_s = 1e-4 rad/s: the creep time (about 50 s) is long against the 0.6 s run
    assert sampled.friction_creep_time(kp, kd, 0.0, ts, COULOMB, INERTIA, 1e-4, delay_steps=1) > 40.0
    errors = friction_loop(kp, kd, 0.0, ts, 1, 301, amplitude, COULOMB / INERTIA, 1e-4)
    assert errors[-1] == pytest.approx(stick, rel=0.01)
    predicted = amplitude - sampled.predict_sampled(kp, kd, 0.0, ts * np.arange(301), amplitude, delay_steps=1)
    assert abs(predicted[-1]) < 2e-4 * amplitude           # settled on r
    assert errors[-1] - predicted[-1] == pytest.approx(stick, rel=0.01)      # the miss


def test_a_pid_removes_the_stick_error():
    kp, kd, ki, ts = 800.0, 50.0, 4000.0, 4e-3        # (s + 20)^2 (s + 10)
    assert sampled.friction_steady_state_error(kp, COULOMB, INERTIA, ki=ki) == 0.0
    pd_stick = sampled.friction_steady_state_error(kp, COULOMB, INERTIA)
    errors = friction_loop(kp, kd, ki, ts, 1, 301, 0.05, COULOMB / INERTIA, 1e-4)
    assert np.max(np.abs(errors[225:])) < 0.05 * pd_stick          # from 0.9 s on


def test_the_smooth_model_creeps_out_of_the_band_with_the_predicted_time_constant():
    kp, kd, ts, v_s = 400.0, 40.0, 4e-3, 1e-2
    tau = sampled.friction_creep_time(kp, kd, 0.0, ts, COULOMB, INERTIA, v_s, delay_steps=1)
    # near rest tanh is linear: the slow root of s^2 + (kd + tau_c / (m v_s)) s + kp, sampled
    beta = COULOMB / (INERTIA * v_s)
    slow = (kd + beta - math.sqrt((kd + beta) ** 2 - 4 * kp)) / 2
    assert tau == pytest.approx(1 / slow, rel=0.01)
    errors = friction_loop(kp, kd, 0.0, ts, 1, 501, 0.05, COULOMB / INERTIA, v_s)
    stick = sampled.friction_steady_state_error(kp, COULOMB, INERTIA)
    assert errors[250] < 0.4 * stick                             # 1 s: well below the stick error
    assert math.log(errors[375] / errors[500]) == pytest.approx(0.5 / tau, rel=2e-3)


# -- mistakes -------------------------------------------------------------------------------------------
@pytest.mark.parametrize("call, named", [
    (lambda: sampled.sampled_prediction(400, 20, 0, 0.0), "sample_time"),
    (lambda: sampled.sampled_prediction(400, 20, 0, 1e-3, delay_steps=-1), "delay_steps"),
    (lambda: sampled.sampled_prediction(400, 20, 0, 1e-3, delay_steps=1.5), "delay_steps"),
    (lambda: sampled.sampled_prediction(400, 20, 0, 1e-3, damping=-1.0), "damping"),
    (lambda: sampled.sampled_prediction(400, 20, 0, 1e-3, damping=float("nan")), "damping"),
    (lambda: sampled.predict_sampled(400, 20, 0, H * np.arange(9), sample_time=2.5 * H), "sample_time"),
    (lambda: sampled.predict_sampled(400, 20, 0, H * np.arange(9), sample_time=0.5 * H), "sample_time"),
    (lambda: sampled.largest_stable_kp(20.0, TS, zeta=0.7), "zeta"),
    (lambda: sampled.largest_stable_kp(None, TS), "zeta"),
    (lambda: sampled.largest_stable_kp(None, TS, zeta=-0.7), "zeta"),
    (lambda: sampled.largest_stable_kp(600.0, TS), "kd = 600"),          # kd Ts > 2: no kp is stable
    (lambda: sampled.friction_steady_state_error(400, -1.0, 1.0), "coulomb"),
    (lambda: sampled.friction_steady_state_error(400, 1.0, 0.0), "inertia"),
    (lambda: sampled.friction_creep_time(400, 20, 0, TS, 1.0, 1.0, 0.0), "velocity_scale"),
])
def test_mistakes_are_one_line_naming_the_argument(call, named):
    with pytest.raises(ValueError) as caught:
        call()
    assert named in str(caught.value) and "\n" not in str(caught.value)


def test_gains_follow_the_projects_rule():
    for kp, kd, ki, name in ((0.0, 20.0, 0.0, "kp"), (400.0, -1.0, 0.0, "kd"), (400.0, 20.0, -1.0, "ki")):
        with pytest.raises(ParameterError) as caught:
            sampled.sampled_prediction(kp, kd, ki, TS)
        assert caught.value.name == name
    with pytest.raises(ParameterError):
        sampled.friction_steady_state_error(-400.0, 1.0, 1.0)

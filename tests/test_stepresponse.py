"""Step responses: co-simulated FMUs against the sampled-data (ZOH) prediction, step metrics
against python-control and closed forms, and gain design from settling time and overshoot."""
import argparse
import math

import control
import numpy as np
import pytest

from robofmu.system import stepresponse as sr

PD = dict(kp=400.0, kd=20.0, ki=0.0)
PID = dict(kp=600.0, kd=25.0, ki=75.0)
HEIGHT = 0.02        # rad, on every joint


# -- linear models ------------------------------------------------------------------------------------
def test_error_dynamics_forms():
    pd = sr.error_dynamics(**PD)
    np.testing.assert_allclose(pd.num[0][0], [400.0])
    np.testing.assert_allclose(pd.den[0][0], [1.0, 20.0, 400.0])
    pid = sr.error_dynamics(**PID)
    np.testing.assert_allclose(pid.num[0][0], [600.0, 75.0])
    np.testing.assert_allclose(pid.den[0][0], [1.0, 25.0, 600.0, 75.0])
    kick = sr.error_dynamics(**PID, velocity_reference=True)
    np.testing.assert_allclose(kick.num[0][0], [25.0, 600.0, 75.0])
    np.testing.assert_allclose(sr.error_dynamics(**PD, velocity_reference=True).num[0][0], [20.0, 400.0])
    for tf in (pd, pid, kick):
        assert control.dcgain(tf) == pytest.approx(1.0)


def test_zoh_of_continuous_loop_samples_it_exactly_sampled_loop_differs_by_o_h():
    t = np.arange(0, 601) * 1e-3
    for gains in (PD, PID):
        cont = sr.predict(**gains, t=t, model="continuous")
        np.testing.assert_allclose(sr.predict(**gains, t=t, model="zoh"), cont, atol=1e-10)
        d1 = np.max(np.abs(sr.predict(**gains, t=t, model="sampled") - cont))
        t5 = np.arange(0, 121) * 5e-3
        d5 = np.max(np.abs(sr.predict(**gains, t=t5, model="sampled")
                           - sr.predict(**gains, t=t5, model="continuous")))
        assert 0.003 < d1 < 0.01 and 4.0 < d5 / d1 < 6.0          # first order in h
    # the sampled loop's poles are the continuous ones mapped by exp(s h), up to O(h)
    poles = np.log(control.poles(sr.discrete_prediction(**PD, h=1e-4)).astype(complex)) / 1e-4
    np.testing.assert_allclose(sorted(poles, key=np.imag), sorted(control.poles(sr.error_dynamics(**PD)),
                                                                   key=np.imag), rtol=2e-3)


# -- co-simulation against the predictions ------------------------------------------------------------
@pytest.mark.parametrize("h", [1e-3, 5e-3])
@pytest.mark.parametrize("gains", [PD, PID], ids=["pd", "pid"])
def test_cosimulated_step_matches_sampled_data_prediction(fmu_dir, gains, h):
    result = sr.cosimulate_step(fmu_dir.parent, **gains, step=HEIGHT, h=h, t_end=0.8)       # the Master
    c = sr.compare(result)
    # every joint, every sample, within 1 % of the step height
    assert c.max_deviation("sampled") < 1.0, c.table()
    assert c.best() == "sampled"
    # c2d of the continuous loop is its exact samples: it misses the hold inside the loop
    np.testing.assert_allclose(c.predictions["zoh"], c.predictions["continuous"], atol=1e-12)
    if h == 5e-3:
        assert c.max_deviation("zoh") > 2.5
    # metrics: what the deviation bound implies (the settling time is discontinuous where an
    # extremum touches the band, so it is bracketed by the prediction's at bands 2 % -+ delta)
    t, pred = c.time, c.predictions["sampled"]
    for k, j in enumerate(c.joints):
        delta = c.deviation["sampled"][k] / 100.0
        m = c.metrics[f"joint {j}"]
        assert m.overshoot == pytest.approx(c.metrics["sampled"].overshoot, abs=100 * delta + 0.01)
        assert m.y0 == pytest.approx(c.q0[j - 1]) and m.steady_state == pytest.approx(c.q0[j - 1] + HEIGHT)
        ts = sr.step_metrics(t, c.response[:, k], y0=0.0, yf=HEIGHT).settling_time
        early = sr.step_metrics(t, pred, y0=0.0, yf=HEIGHT, settling=0.02 + delta).settling_time
        late = sr.step_metrics(t, pred, y0=0.0, yf=HEIGHT, settling=0.02 - delta).settling_time
        assert early <= ts <= late


def test_single_joint_step_leaves_the_others_and_derivative_kick_model_is_wrong(fmu_dir):
    result = sr.cosimulate_step(fmu_dir.parent, **PD, step=-0.03, h=2e-3, t_end=0.6, joint=3)
    c = sr.compare(result)
    assert c.joints == [3] and c.max_deviation("sampled") < 1.0
    assert c.crosstalk_percent < 0.5          # decoupled by the computed-torque law
    t = c.time
    kick = control.step_response(sr.error_dynamics(**PD, velocity_reference=True), T=t).outputs * -0.03
    assert np.max(np.abs(c.response[:, 0] - kick)) / 0.03 > 0.2


# -- step metrics -----------------------------------------------------------------------------------------
def second_order(zeta, wn, t):
    return control.step_response(control.tf([wn**2], [1, 2 * zeta * wn, wn**2]), T=t).outputs


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_step_metrics_of_offset_shifted_signal_agree_with_step_info(sign):
    t = np.linspace(0.0, 3.0, 3001)
    y = second_order(0.35, 9.0, t) + 0.01 * np.sin(25 * t) * np.exp(-t)
    t_shift, y0, amp = t + 2.5, 0.8, sign * 0.3
    ys = y0 + amp * y
    m = sr.step_metrics(t_shift, ys)
    ref = control.step_info(ys - y0, T=t_shift - t_shift[0])
    for key, value in m.step_info().items():
        assert value == pytest.approx(ref[key], rel=1e-12, abs=1e-12), key
    assert m.y0 == y0 and m.t0 == 2.5 and m.peak == pytest.approx(y0 + sign * ref["Peak"])
    # step_info on the raw signal is wrong on both counts (offset, time origin)
    raw = control.step_info(ys, T=t_shift)
    assert abs(raw["Overshoot"] - m.overshoot) > 1.0 and raw["PeakTime"] != pytest.approx(m.peak_time)
    # interpolated crossings agree to a sample
    mi = sr.step_metrics(t_shift, ys, interpolate=True)
    for key in ("rise_time", "settling_time", "peak_time"):
        assert getattr(mi, key) == pytest.approx(getattr(m, key), abs=1e-3), key


def test_step_metrics_closed_form_second_order_with_step_at_t0():
    zeta, wn = 0.5, 20.0
    wd = wn * math.sqrt(1 - zeta**2)
    t0, y0, amp = 0.3, 0.8, 0.05
    t = np.linspace(0.0, 1.3, 130001)
    after = t >= t0
    y = np.full_like(t, y0)
    y[after] = y0 + amp * second_order(zeta, wn, t[after] - t0)
    y[: np.argmax(after)] += 0.02 * np.sin(40 * t[: np.argmax(after)])      # ignored: before t0
    m = sr.step_metrics(t, y, yf=y0 + amp, t0=t0, interpolate=True)
    assert m.overshoot == pytest.approx(100 * math.exp(-zeta * math.pi / math.sqrt(1 - zeta**2)), rel=1e-6)
    assert m.peak_time == pytest.approx(math.pi / wd, abs=1e-7)
    assert m.peak == pytest.approx(y0 + amp * (1 + math.exp(-zeta * math.pi / math.sqrt(1 - zeta**2))), rel=1e-9)
    assert m.settling_time == pytest.approx(sr.second_order_settling_time(zeta, wn), abs=1e-6)
    assert m.steady_state == y0 + amp and m.y0 == y0 and m.t0 == t0
    # rise time 10 -> 90 %: solve the closed form
    from scipy.optimize import brentq
    s = lambda tt, lvl: 1 - math.exp(-zeta * wn * tt) * (math.cos(wd * tt) + zeta / math.sqrt(1 - zeta**2)
                                                          * math.sin(wd * tt)) - lvl
    tr = brentq(s, 1e-6, math.pi / wd, args=(0.9,)) - brentq(s, 1e-6, math.pi / wd, args=(0.1,))
    assert m.rise_time == pytest.approx(tr, abs=1e-7)


@pytest.mark.parametrize("zeta", [0.2, 0.45, 0.6901, 0.78, 1.0, 1.7])
def test_exact_second_order_settling_time(zeta):
    wn = 7.0
    ts = sr.second_order_settling_time(zeta, wn)
    t = np.linspace(0.0, 2.0 * ts, 200001)
    ref = control.step_info(second_order(zeta, wn, t), T=t, yfinal=1.0)["SettlingTime"]
    assert ts == pytest.approx(ref, abs=2 * (t[1] - t[0]))


def test_rule_of_thumb_misses_five_percent():
    zeta = sr.damping_from_overshoot(10.0)
    assert zeta == pytest.approx(0.5912, abs=1e-4)
    exact = sr.second_order_settling_time(zeta, 1.0)
    assert abs(4.0 / zeta / exact - 1.0) > 0.05


def test_step_metrics_of_a_flat_signal_are_nan():
    m = sr.step_metrics([0.0, 1.0, 2.0], [0.4, 0.4, 0.4])
    assert math.isnan(m.rise_time) and math.isnan(m.overshoot)


# -- gain design ---------------------------------------------------------------------------------------------
def test_pd_design_closed_form():
    d = sr.design_gains(0.3, 5.0)
    assert d.iterations == 0 and d.converged and d.ki == 0.0
    assert d.kp == pytest.approx(d.wn**2) and d.kd == pytest.approx(2 * d.zeta * d.wn)
    assert d.predicted.settling_time == pytest.approx(0.3, rel=1e-4)
    assert d.predicted.overshoot == pytest.approx(5.0, rel=1e-4)


@pytest.mark.parametrize("ts, os_, ki_ratio, h", [(0.3, 5.0, None, None), (0.5, 10.0, None, None),
                                                  (0.5, 10.0, 0.01, None), (0.3, 20.0, 0.01, 1e-3)])
def test_designed_gains_hit_request_in_cosimulation(fmu_dir, ts, os_, ki_ratio, h):
    d = sr.design_gains(ts, os_, ki_ratio=ki_ratio, h=h)
    assert d.converged
    hs = 1e-3
    result = sr.cosimulate_step(fmu_dir.parent, d.kp, d.kd, d.ki, step=HEIGHT, h=hs,
                                t_end=round(3 * ts / hs) * hs)
    c = sr.compare(result)
    for j in c.joints:
        m = c.metrics[f"joint {j}"]
        assert m.settling_time == pytest.approx(ts, rel=0.05), (j, m)
        assert m.overshoot == pytest.approx(os_, rel=0.05), (j, m)
        if h is not None:                   # designed for the sampled loop: much closer
            assert m.settling_time == pytest.approx(ts, rel=0.01) and m.overshoot == pytest.approx(os_, rel=0.02)


# -- command line ---------------------------------------------------------------------------------------------
def test_step_command(fmu_dir, tmp_path, capsys):
    parser = argparse.ArgumentParser(prog="robofmu")
    sub = parser.add_subparsers(dest="command")
    sr.add_step_command(sub)
    with pytest.raises(SystemExit) as info:
        parser.parse_args(["step", "--help"])
    assert info.value.code == 0
    assert "--settling-time" in capsys.readouterr().out
    args = parser.parse_args(["step", "--settling-time", "0.4", "--overshoot", "8", "--step-size", "0.005",
                              "--fmus", str(fmu_dir.parent), "--out", str(tmp_path)])
    assert args.func(args) == 0
    out = capsys.readouterr().out
    assert "sampled" in out and "overshoot" in out and "achieved" in out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["step_h5ms.png", "step_h5ms_compare.csv",
                                                          "step_h5ms_cosim.csv"]

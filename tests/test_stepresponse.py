"""Step responses: co-simulated FMUs against the sampled-data (ZOH) prediction, step metrics
against python-control and closed forms, and gain design from settling time and overshoot.

The FMUs come from the session fixture ``fmu_root`` (tests/conftest.py: every described robot,
built once per session)."""
import argparse
import math

import control
import numpy as np
import pytest

from robofmu.components.robots import load_description, load_model
from robofmu.system import defaults
from robofmu.system import stepresponse as sr
from robofmu.system.commands import step as step_command
from robofmu.system.stepresponse import comparison, design, experiment, figures, linear, metrics, sampled

PD = dict(kp=400.0, kd=20.0, ki=0.0)
PID = dict(kp=600.0, kd=25.0, ki=75.0)
HEIGHT = 0.02        # rad, the amplitude on every joint
#: The robots of the acceptance test: every revolute/prismatic mix of the collection.
ROBOTS = ("chess", "rrp", "rpp")


def test_package_reexports_every_public_name():
    for name in sr.__all__:
        module = next(m for m in (linear, metrics, design, sampled, experiment, comparison, figures) if name in m.__all__)
        assert getattr(sr, name) is getattr(module, name), name
    for name in ("design_gains", "compare", "cosimulate_step", "plot_comparison", "default_amplitudes",
                 "step_metrics", "predict", "error_dynamics", "discrete_prediction", "write_csv",
                 "predict_sampled", "predict_coupled", "sampled_prediction", "largest_stable_kp", "spectral_radius",
                 "friction_steady_state_error", "friction_creep_time", "FrictionMiss"):
        assert name in sr.__all__
    # the command is robofmu.system.commands.step: the package exports no command-line things
    assert not {"add_step_command", "add_parser", "main", "default_robot"} & set(dir(sr))


# -- linear models ------------------------------------------------------------------------------------
def test_error_dynamics_forms():
    pd = linear.error_dynamics(**PD)
    np.testing.assert_allclose(pd.num[0][0], [400.0])
    np.testing.assert_allclose(pd.den[0][0], [1.0, 20.0, 400.0])
    pid = linear.error_dynamics(**PID)
    np.testing.assert_allclose(pid.num[0][0], [600.0, 75.0])
    np.testing.assert_allclose(pid.den[0][0], [1.0, 25.0, 600.0, 75.0])
    kick = linear.error_dynamics(**PID, velocity_reference=True)
    np.testing.assert_allclose(kick.num[0][0], [25.0, 600.0, 75.0])
    np.testing.assert_allclose(linear.error_dynamics(**PD, velocity_reference=True).num[0][0], [20.0, 400.0])
    for tf in (pd, pid, kick):
        assert control.dcgain(tf) == pytest.approx(1.0)


def test_zoh_of_continuous_loop_samples_it_exactly_sampled_loop_differs_by_o_h():
    t = np.arange(0, 601) * 1e-3
    for gains in (PD, PID):
        cont = linear.predict(**gains, t=t, model="continuous")
        np.testing.assert_allclose(linear.predict(**gains, t=t, model="zoh"), cont, atol=1e-10)
        d1 = np.max(np.abs(linear.predict(**gains, t=t, model="sampled") - cont))
        t5 = np.arange(0, 121) * 5e-3
        d5 = np.max(np.abs(linear.predict(**gains, t=t5, model="sampled")
                           - linear.predict(**gains, t=t5, model="continuous")))
        assert 0.003 < d1 < 0.01 and 4.0 < d5 / d1 < 6.0          # first order in h
    # the sampled loop's poles are the continuous ones mapped by exp(s h), up to O(h)
    poles = np.log(control.poles(linear.discrete_prediction(**PD, h=1e-4)).astype(complex)) / 1e-4
    np.testing.assert_allclose(sorted(poles, key=np.imag), sorted(control.poles(linear.error_dynamics(**PD)),
                                                                   key=np.imag), rtol=2e-3)


# -- co-simulation against the predictions ------------------------------------------------------------
@pytest.mark.parametrize("h", [1e-3, 5e-3])
@pytest.mark.parametrize("gains", [PD, PID], ids=["pd", "pid"])
def test_cosimulated_step_matches_sampled_data_prediction(fmu_root, gains, h):
    result = experiment.cosimulate_step(fmu_root, **gains, robot="chess", amplitude=HEIGHT, h=h,
                                        stop_time=0.8)                                   # the Master
    c = comparison.compare(result)
    # every joint, every sample, within 1 % of the amplitude
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
        ts = metrics.step_metrics(t, c.response[:, k], y0=0.0, yf=HEIGHT).settling_time
        early = metrics.step_metrics(t, pred[:, k], y0=0.0, yf=HEIGHT, settling=0.02 + delta).settling_time
        late = metrics.step_metrics(t, pred[:, k], y0=0.0, yf=HEIGHT, settling=0.02 - delta).settling_time
        assert early <= ts <= late


def test_single_joint_step_leaves_the_others_and_derivative_kick_model_is_wrong(fmu_root):
    result = experiment.cosimulate_step(fmu_root, **PD, robot="chess", amplitude=-0.03, h=2e-3, stop_time=0.6,
                                        joint=3)
    c = comparison.compare(result)
    assert c.joints == [3] and c.max_deviation("sampled") < 1.0
    assert c.crosstalk_percent < 0.5          # decoupled by the computed-torque law
    t = c.time
    kick = control.step_response(linear.error_dynamics(**PD, velocity_reference=True), T=t).outputs * -0.03
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
    m = metrics.step_metrics(t_shift, ys)
    ref = control.step_info(ys - y0, T=t_shift - t_shift[0])
    for key, value in m.step_info().items():
        assert value == pytest.approx(ref[key], rel=1e-12, abs=1e-12), key
    assert m.y0 == y0 and m.t0 == 2.5 and m.peak == pytest.approx(y0 + sign * ref["Peak"])
    # step_info on the raw signal is wrong on both counts (offset, time origin)
    raw = control.step_info(ys, T=t_shift)
    assert abs(raw["Overshoot"] - m.overshoot) > 1.0 and raw["PeakTime"] != pytest.approx(m.peak_time)
    # interpolated crossings agree to a sample
    mi = metrics.step_metrics(t_shift, ys, interpolate=True)
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
    m = metrics.step_metrics(t, y, yf=y0 + amp, t0=t0, interpolate=True)
    assert m.overshoot == pytest.approx(100 * math.exp(-zeta * math.pi / math.sqrt(1 - zeta**2)), rel=1e-6)
    assert m.peak_time == pytest.approx(math.pi / wd, abs=1e-7)
    assert m.peak == pytest.approx(y0 + amp * (1 + math.exp(-zeta * math.pi / math.sqrt(1 - zeta**2))), rel=1e-9)
    assert m.settling_time == pytest.approx(metrics.second_order_settling_time(zeta, wn), abs=1e-6)
    assert m.steady_state == y0 + amp and m.y0 == y0 and m.t0 == t0
    # rise time 10 -> 90 %: solve the closed form
    from scipy.optimize import brentq
    def s(tt, lvl):
        return 1 - math.exp(-zeta * wn * tt) * (math.cos(wd * tt) + zeta / math.sqrt(1 - zeta**2)
                                                * math.sin(wd * tt)) - lvl
    tr = brentq(s, 1e-6, math.pi / wd, args=(0.9,)) - brentq(s, 1e-6, math.pi / wd, args=(0.1,))
    assert m.rise_time == pytest.approx(tr, abs=1e-7)


@pytest.mark.slow
@pytest.mark.parametrize("zeta", [0.2, 0.45, 0.6901, 0.78, 1.0, 1.7])
def test_exact_second_order_settling_time(zeta):
    wn = 7.0
    ts = metrics.second_order_settling_time(zeta, wn)
    t = np.linspace(0.0, 2.0 * ts, 200001)
    ref = control.step_info(second_order(zeta, wn, t), T=t, yfinal=1.0)["SettlingTime"]
    assert ts == pytest.approx(ref, abs=2 * (t[1] - t[0]))


def test_rule_of_thumb_misses_five_percent():
    zeta = metrics.damping_from_overshoot(10.0)
    assert zeta == pytest.approx(0.5912, abs=1e-4)
    exact = metrics.second_order_settling_time(zeta, 1.0)
    assert abs(4.0 / zeta / exact - 1.0) > 0.05


def test_step_metrics_of_a_flat_signal_are_nan():
    m = metrics.step_metrics([0.0, 1.0, 2.0], [0.4, 0.4, 0.4])
    assert math.isnan(m.rise_time) and math.isnan(m.overshoot)


# -- gain design ---------------------------------------------------------------------------------------------
def test_pd_design_closed_form():
    d = design.design_gains(0.3, 5.0)
    assert d.iterations == 0 and d.converged and d.ki == 0.0
    assert d.kp == pytest.approx(d.wn**2) and d.kd == pytest.approx(2 * d.zeta * d.wn)
    assert d.predicted.settling_time == pytest.approx(0.3, rel=1e-4)
    assert d.predicted.overshoot == pytest.approx(5.0, rel=1e-4)


@pytest.mark.parametrize("ts, os_, ki_ratio, h", [(0.3, 5.0, None, None), (0.5, 10.0, None, None),
                                                  (0.5, 10.0, 0.01, None), (0.3, 20.0, 0.01, 1e-3)])
def test_designed_gains_hit_request_in_cosimulation(fmu_root, ts, os_, ki_ratio, h):
    d = design.design_gains(ts, os_, ki_ratio=ki_ratio, h=h)
    assert d.converged
    hs = 1e-3
    result = experiment.cosimulate_step(fmu_root, d.kp, d.kd, d.ki, robot="chess", amplitude=HEIGHT, h=hs,
                                stop_time=round(3 * ts / hs) * hs)
    c = comparison.compare(result)
    for j in c.joints:
        m = c.metrics[f"joint {j}"]
        assert m.settling_time == pytest.approx(ts, rel=0.05), (j, m)
        assert m.overshoot == pytest.approx(os_, rel=0.05), (j, m)
        if h is not None:                   # designed for the sampled loop: much closer
            assert m.settling_time == pytest.approx(ts, rel=0.01) and m.overshoot == pytest.approx(os_, rel=0.02)


# -- command line ---------------------------------------------------------------------------------------------
def test_step_command(fmu_root, tmp_path, capsys):
    parser = argparse.ArgumentParser(prog="robofmu")
    sub = parser.add_subparsers(dest="command")
    step_command.add_parser(sub)
    with pytest.raises(SystemExit) as info:
        parser.parse_args(["step", "--help"])
    assert info.value.code == 0
    assert "--settling-time" in capsys.readouterr().out
    args = parser.parse_args(["step", "--settling-time", "0.4", "--overshoot", "8", "--step-size", "0.005",
                              "--fmus", str(fmu_root), "--out", str(tmp_path)])
    assert args.func(args) == 0
    out = capsys.readouterr().out
    assert "sampled" in out and "overshoot" in out and "achieved" in out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["step_h5ms.png", "step_h5ms_compare.csv",
                                                          "step_h5ms_cosim.csv"]


# -- every robot: revolute and prismatic joints ------------------------------------------------------------
def robot_gain_sets():
    """``(robot, gain set)`` for every gain set of every robot in :data:`ROBOTS`, ids ``robot-set``."""
    return [pytest.param(robot, name, id=f"{robot}-{name}")
            for robot in ROBOTS for name in load_description(robot).gains]


@pytest.mark.parametrize("robot_name, gain_set", robot_gain_sets())
def test_every_robot_step_matches_sampled_data_prediction(fmu_root, robot_name, gain_set):
    """Acceptance: from home, the default step on every joint through the controller and plant FMUs
    (1 ms) is python-control's sampled-data prediction to 1 % of the amplitude at every sample."""
    model = load_model(robot_name)
    gains = load_description(robot_name).gain_set(gain_set).as_dict()
    result = experiment.cosimulate_step(fmu_root, **gains, robot=robot_name, h=1e-3, stop_time=0.8)
    c = comparison.compare(result)
    assert c.joints == list(range(1, model.n + 1))
    np.testing.assert_allclose(c.q0, model.configuration("home"))
    for j, unit in zip(c.joints, model.joint_units(0)):
        assert c.unit(j) == unit and result.units[f"plant.q[{j}]"] == unit
        assert abs(c.amplitudes[j - 1]) == experiment.DEFAULT_AMPLITUDE[unit]
    np.testing.assert_array_equal(c.amplitudes, experiment.default_amplitudes(robot_name))   # within limits
    assert c.effort_units == model.effort_units()
    # the response is a step, not a flat line: it has arrived by the end
    np.testing.assert_allclose(c.response[-1], c.amplitudes, rtol=0.02)
    deviation = np.max(np.abs(c.response - c.predictions["sampled"]), axis=0) / np.abs(c.amplitudes) * 100.0
    np.testing.assert_allclose(deviation, c.deviation["sampled"])
    assert np.all(deviation < 1.0), c.table()
    assert any(model.prismatic) == ("m" in c.joint_units)


def test_step_setup_defaults_sequences_and_mistakes():
    rrp = load_model("rrp")
    setup = experiment.step_setup("rrp")
    assert setup.joints == [1, 2, 3] and setup.joint_units == rrp.joint_units(0)
    np.testing.assert_allclose(setup.q0, rrp.configuration("home"))
    np.testing.assert_allclose(setup.amplitudes, experiment.default_amplitudes("rrp"))
    np.testing.assert_allclose(setup.q_ref, setup.q0 + setup.amplitudes)
    one = experiment.step_setup("rrp", amplitude=[0.05], joint=[3])          # one amplitude per stepped joint
    np.testing.assert_allclose(one.q_ref - one.q0, [0.0, 0.0, 0.05])
    every = experiment.step_setup("rrp", amplitude=[0.01, -0.02, 0.03], joint=2, q0=[0.1, 0.2, 0.1])
    np.testing.assert_allclose(every.q_ref, [0.1, 0.18, 0.1])
    for kwargs, start in [(dict(joint=4), "joint:"), (dict(joint=[1, 1]), "joint:"),
                          (dict(q0=[0.0, 0.0]), "q0:"), (dict(amplitude=0.0), "amplitude:"),
                          (dict(amplitude=[0.1, 0.2]), "amplitude:"), (dict(amplitude=float("nan")), "amplitude:")]:
        with pytest.raises(ValueError) as info:
            experiment.step_setup("rrp", **kwargs)
        assert str(info.value).startswith(start), info.value
    with pytest.raises(ValueError, match="unknown robot"):
        experiment.step_setup("no-such-robot")


def test_comparison_csv_and_figure_carry_the_model_units(fmu_root, tmp_path):
    result = experiment.cosimulate_step(fmu_root, 400.0, 40.0, robot="rrp", joint=[2, 3], h=5e-3, stop_time=0.3)
    c = comparison.compare(result)
    assert c.joints == [2, 3] and c.crosstalk_joints == [1] and c.crosstalk.shape == (61, 1)
    assert c.predictions["sampled"].shape == (61, 2) and c.deviation["sampled"].shape == (2,)
    assert "q2 +0.02 rad, q3 -0.02 m" in c.table()
    path = comparison.write_csv(c, tmp_path / "compare.csv")
    header = path.read_text().splitlines()[0].split(",")
    assert header[:3] == ["time [s]", "cosim_q2 [rad]", "cosim_q3 [m]"]
    assert header[-3:] == ["tau1 [N.m]", "tau2 [N.m]", "tau3 [N]"]
    figure = figures.plot_comparison(c, tmp_path)
    assert figure.name == "step_rrp_kp400_kd40_ki0_h5ms_j2-3.png" and figure.stat().st_size > 0


# -- command line: every robot, one-line mistakes ------------------------------------------------------------
def step_parser():
    parser = argparse.ArgumentParser(prog="robofmu")
    sub = parser.add_subparsers(dest="command")
    step_command.add_parser(sub)
    return parser


def run_step(argv, capsys):
    """(exit status, stdout, stderr) of ``robofmu step ARGV``."""
    parser = step_parser()
    try:
        args = parser.parse_args(["step", *argv])
        status = args.func(args)
    except SystemExit as exc:
        status = exc.code
    out, err = capsys.readouterr()
    return status, out, err


def test_step_command_prismatic_robot(fmu_root, tmp_path, capsys):
    status, out, err = run_step(["--robot", "rpp", "--step-size", "0.005", "--stop-time", "0.4",
                                 "--amplitude", "0.01", "0.03", "0.03", "--fmus", str(fmu_root),
                                 "--out", str(tmp_path)], capsys)
    assert status == 0, err
    assert "rpp: step q1 +0.01 rad, q2 +0.03 m, q3 +0.03 m" in out and "best match" in out
    header = (tmp_path / "step_h5ms_compare.csv").read_text().splitlines()[0]
    assert "cosim_q2 [m]" in header and "tau1 [N.m]" in header and "tau3 [N]" in header


@pytest.mark.parametrize("argv, option", [
    (["--robot", "nobody"], "--robot"),
    (["--robot", "./nobody/nobody.toml"], "--robot"),      # a robot TOML path that does not exist
    (["--robot", "rrp", "--gains", "pid"], "--gains"),
    (["--kp", "-1"], "--kp"),
    (["--kd", "nan"], "--kd"),
    (["--kd", "0"], "--kd"),                      # the gains' rule: kd > 0
    (["--gains", "pdq"], "--gains"),
    (["--kp", "abc"], "--kp"),
    (["--settling-time", "0.3"], "--overshoot"),
    (["--settling-time", "0.3", "--overshoot", "120"], "--overshoot"),
    (["--settling-time", "-1", "--overshoot", "5"], "--settling-time"),
    (["--settling-time", "0.3", "--overshoot", "5", "--kp", "100"], "--kp"),
    (["--ki-ratio", "0.01"], "--ki-ratio"),
    (["--amplitude", "0"], "--amplitude"),
    (["--robot", "rrp", "--amplitude", "0.1", "0.2"], "--amplitude"),
    (["--robot", "rrp", "--joint", "4"], "--joint"),
    (["--robot", "rrp", "--q0", "0", "0"], "--q0"),
    (["--step-size", "0"], "--step-size"),
    (["--algorithm", "euler"], "--algorithm"),
    (["--bogus"], "--bogus"),
    (["--fmus", "/no/such/folder"], "--fmus"),
])
def test_step_command_mistakes_answer_in_one_line(fmu_root, capsys, argv, option):
    if "--fmus" not in argv:
        argv = [*argv, "--fmus", str(fmu_root)]
    status, out, err = run_step(argv, capsys)
    assert status == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and option in err and "Traceback" not in err, err
    assert err.startswith("robofmu step: ")


def test_step_command_old_spellings_work_and_warn_in_one_line_each(capsys):
    args = step_parser().parse_args(["step", "--driver", "master", "--t-end", "0.5", "--step-height", "0.01",
                                     "--height", "0.02", "0.03"])
    assert (args.algorithm, args.stop_time, args.amplitude) == ("gauss-seidel", 0.5, [0.02, 0.03])
    assert capsys.readouterr().err.splitlines() == [
        "robofmu step: --driver is deprecated; use --algorithm", "robofmu step: --t-end is deprecated; use --stop-time",
        "robofmu step: --step-height is deprecated; use --amplitude",
        "robofmu step: --height is deprecated; use --amplitude"]
    assert step_parser().parse_args(["step", "--driver", "jacobi"]).algorithm == "jacobi"


def test_step_command_defaults_come_from_the_shared_defaults_and_the_description():
    args = step_parser().parse_args(["step"])
    assert (args.step_size, args.algorithm, args.fmus) == (defaults.STEP_SIZE, defaults.ALGORITHM, defaults.FMU_FOLDER)
    assert args.robot is None and args.gains is None       # main: the first steppable robot, its default_gains


@pytest.mark.slow
def test_demo_cases_one_per_gain_set(fmu_root, tmp_path):
    cases = figures.demo_cases("chess", fmu_root, tmp_path, h=5e-3, stop_time=0.5)
    assert [label.split(":")[0] for label, _ in cases] == list(load_description("chess").gains)
    for label, (c, figure) in cases:
        assert c.max_deviation("sampled") < 1.0 and figure.parent == tmp_path and figure.is_file()

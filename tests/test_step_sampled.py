"""``robofmu step`` with the controller at its own sample time and a computation delay (issue 30, 5):
the co-simulated step against python-control's sampled, delayed prediction on every robot, the kp
stability limit checked just inside and just outside by co-simulation, and Coulomb friction unknown
to the controller reported against its closed form.

The FMUs come from the session fixture ``fmu_root`` (tests/conftest.py).
"""
import argparse
import math

import numpy as np
import pinocchio as pin
import pytest
import scipy.linalg

from robofmu.components.robots import load_description, load_model
from robofmu.system.commands import step as step_command
from robofmu.system.stepresponse import comparison, experiment, linear, sampled, steppable_robots

H = 1e-3              # base step (s)
TS = 2e-3             # the acceptance's controller sample time (s)
STOP = 0.8            # s

def acceptance_cases():
    return [pytest.param(robot, name, id=f"{robot}-{name}")
            for robot in steppable_robots() for name in load_description(robot).gains]


def hand_loop(kp, kd, ki, ratio, d, steps, r=1.0):
    """y at t = n H of the double integrator stepped exactly (expm) over H, the PD/PID law every
    ``ratio`` steps, its effort applied d samples later and, before sample d, the first sample's
    (what the controller block does: it has no earlier sample)."""
    augmented = np.zeros((3, 3))
    augmented[0, 1], augmented[1, 2] = 1.0, 1.0
    step = scipy.linalg.expm(augmented * H)
    phi, gamma = step[:2, :2], step[:2, 2]
    x, z, queue, u, ys = np.zeros(2), 0.0, [], 0.0, []
    for n in range(steps):
        if n % ratio == 0:
            queue.append(kp * (r - x[0]) - kd * x[1] + ki * z)
            z += ratio * H * (r - x[0])
            u = queue.pop(0) if len(queue) > d else queue[0]
        ys.append(x[0])
        x = phi @ x + gamma * u
    return np.array(ys)


def hand_loop_coupled(kp, kd, ki, ratio, d, steps, K, B, Bc, r):
    """y (steps, n) of y'' = u - K y - B y' stepped exactly (expm) over H, with the effort
    w = kp (r - y) - kd y' + ki z + K y + Bc y' computed every ``ratio`` steps and applied d
    samples later (before sample d, the first sample's)."""
    n = len(r)
    augmented = np.zeros((3 * n, 3 * n))
    augmented[:n, n:2 * n] = np.eye(n)
    augmented[n:2 * n, :n], augmented[n:2 * n, n:2 * n], augmented[n:2 * n, 2 * n:] = -K, -B, np.eye(n)
    step = scipy.linalg.expm(augmented * H)
    phi, gamma = step[:2 * n, :2 * n], step[:2 * n, 2 * n:]
    x, z, queue, u, ys = np.zeros(2 * n), np.zeros(n), [], np.zeros(n), []
    for k in range(steps):
        if k % ratio == 0:
            y, yd = x[:n], x[n:]
            queue.append(kp * (r - y) - kd * yd + ki * z + K @ y + Bc @ yd)
            z = z + ratio * H * (r - y)
            u = queue.pop(0) if len(queue) > d else queue[0]
        ys.append(x[:n].copy())
        x = phi @ x + gamma @ u
    return np.array(ys)


def step_parser():
    parser = argparse.ArgumentParser(prog="robofmu")
    step_command.add_parser(parser.add_subparsers(dest="command"))
    return parser


def run_step(argv, capsys):
    """(exit status, stdout, stderr) of ``robofmu step ARGV``."""
    try:
        args = step_parser().parse_args(["step", *argv])
        status = args.func(args)
    except SystemExit as exc:
        status = exc.code
    out, err = capsys.readouterr()
    return status, out, err


def envelope(c, start, stop):
    """max over stepped joints and t in [start, stop) of |q - q_ref| / |A|."""
    window = (c.time >= start) & (c.time < stop)
    return float(np.max(np.abs(c.response[window] - c.amplitudes) / np.abs(c.amplitudes)))


# -- the prediction of the block's start-up -------------------------------------------------------------
@pytest.mark.parametrize("d", [0, 1, 3])
@pytest.mark.parametrize("gains", [dict(kp=400.0, kd=20.0, ki=0.0), dict(kp=600.0, kd=25.0, ki=75.0)],
                         ids=["pd", "pid"])
def test_startup_first_is_the_hand_written_loop_of_the_controller_block(gains, d):
    t = np.arange(600) * H
    got = sampled.predict_sampled(**gains, t=t, sample_time=4 * H, delay_steps=d, startup="first")
    np.testing.assert_allclose(got, hand_loop(**gains, ratio=4, d=d, steps=600), atol=1e-12)
    rest = sampled.predict_sampled(**gains, t=t, sample_time=4 * H, delay_steps=d)
    assert (np.max(np.abs(got - rest)) > 0.02) == (d > 0)          # the start-up matters with a delay
    with pytest.raises(ValueError, match="startup"):
        sampled.predict_sampled(**gains, t=t, sample_time=4 * H, delay_steps=d, startup="warm")


@pytest.mark.parametrize("d", [0, 1, 3])
@pytest.mark.parametrize("gains", [dict(kp=400.0, kd=20.0, ki=0.0), dict(kp=600.0, kd=25.0, ki=75.0)],
                         ids=["pd", "pid"])
def test_coupled_prediction_is_the_hand_written_linear_loop(gains, d):
    """Three joints coupled by a stiffness and damping matrices (the size of rrp's gravity coupling)."""
    K = np.array([[0.0, 0.0, 0.0], [0.0, -0.8, 1260.0], [0.0, 9.8, 0.0]])
    B = np.array([[0.5, 0.1, 0.0], [0.1, 2.0, 0.0], [0.0, 0.0, 1.0]])
    Bc = 0.5 * B
    r = np.array([0.02, -0.02, 0.02])
    t = np.arange(600) * H
    got = sampled.predict_coupled(**gains, t=t, amplitudes=r, sample_time=4 * H, delay_steps=d, stiffness=K,
                                  damping=B, compensation=Bc, startup="first")
    np.testing.assert_allclose(got, hand_loop_coupled(**gains, ratio=4, d=d, steps=600, K=K, B=B, Bc=Bc, r=r),
                               rtol=0, atol=1e-12)
    # uncoupled (K = Bc = 0, B diagonal) each column is predict_sampled of its joint
    beta = np.diag(B)
    alone = sampled.predict_coupled(**gains, t=t, amplitudes=r, sample_time=4 * H, delay_steps=d,
                                    damping=np.diag(beta), startup="first")
    for j in range(3):
        np.testing.assert_allclose(alone[:, j], sampled.predict_sampled(**gains, t=t, amplitude=r[j], sample_time=4 * H,
                                                                        delay_steps=d, damping=beta[j],
                                                                        startup="first"), rtol=0, atol=1e-14)
    assert np.max(np.abs(got - alone)) > 0.01 * 0.02 * (d + 0.5)        # the coupling shows, growing with the lag
    with pytest.raises(ValueError, match="stiffness must be a finite \\(3, 3\\) matrix"):
        sampled.predict_coupled(**gains, t=t, amplitudes=r, stiffness=np.eye(2))


def hand_radius(kp, kd, ts, K, d=1):
    """Largest |eigenvalue| of the coupled PD loop with one sample of delay, built here: x = (y, y'),
    x+ = Phi x + Gamma u (expm at ts), u = the previous sample's w = F x."""
    n = K.shape[0]
    augmented = np.zeros((3 * n, 3 * n))
    augmented[:n, n:2 * n], augmented[n:2 * n, :n], augmented[n:2 * n, 2 * n:] = np.eye(n), -K, np.eye(n)
    step = scipy.linalg.expm(augmented * ts)
    phi, gamma = step[:2 * n, :2 * n], step[:2 * n, 2 * n:]
    F = np.hstack([K - kp * np.eye(n), -kd * np.eye(n)])
    loop = np.block([[phi, gamma], [F, np.zeros((n, n))]])
    return float(np.max(np.abs(np.linalg.eigvals(loop))))


def test_the_arms_kp_limit_is_where_the_coupled_loop_reaches_the_unit_circle():
    """With rrp's gravity coupling, 4 ms, one sample late, kd 40: the coupled loop's limit lies below
    the per-joint (Jury) limit, and a loop built here crosses |z| = 1 there; without coupling the two
    limits agree."""
    K = np.array([[0.0, 0.0, 0.0], [0.0, -0.8, 1260.0], [0.0, 9.8, 0.0]])
    ts, kd = 4e-3, 40.0
    arm = sampled.largest_stable_kp(kd, ts, 1, stiffness=K)
    alone = sampled.largest_stable_kp(kd, ts, 1)
    assert 0.95 * alone < arm < 0.995 * alone
    assert hand_radius(arm * (1 - 1e-6), kd, ts, K) < 1.0 < hand_radius(arm * (1 + 1e-6), kd, ts, K)
    assert sampled.spectral_radius(arm, kd, 0.0, ts, 1, stiffness=K) == pytest.approx(1.0, abs=1e-9)
    assert sampled.largest_stable_kp(kd, ts, 1, stiffness=np.zeros((3, 3))) == pytest.approx(alone, rel=1e-9)


# -- acceptance: every robot at 2 ms with one sample of delay -----------------------------------------
@pytest.mark.parametrize("robot_name, gain_set", acceptance_cases())
def test_sampled_delayed_step_matches_the_discrete_prediction(fmu_root, robot_name, gain_set):
    """The default step of every joint at once from home, the controller every 2 ms and one sample
    late: every joint within 1 % of its amplitude of python-control's prediction at every recorded
    1 ms sample."""
    gains = load_description(robot_name).gain_set(gain_set).as_dict()
    joints = list(range(1, load_model(robot_name).n + 1))
    result = experiment.cosimulate_step(fmu_root, **gains, robot=robot_name, h=H, stop_time=STOP,
                                        sample_time=TS, delay_steps=1)
    c = comparison.compare(result)
    assert (c.sample_time, c.delay_steps, c.joints) == (TS, 1, joints)
    assert c.max_deviation("sampled") < 1.0, c.table()
    assert c.best() == "sampled" and not c.divergence and not c.friction
    # the bar can fail: the single-rate model at h misses the sampled, delayed loop by more than 1.5 %
    single = linear.predict(**gains, t=c.time - c.time[0], model="sampled", h=H)
    assert np.max(np.abs(c.response - single[:, None] * c.amplitudes) / np.abs(c.amplitudes)) > 0.015
    np.testing.assert_allclose(c.response[-1], c.amplitudes, rtol=0.02)          # it arrived
    assert "controller every 2 ms, 1 sample late" in c.table()


def independent_stiffness(robot_name, q):
    """M^-1 dg/dq of the robot's URDF at q by a Pinocchio model built here, shape (n, n)."""
    model = pin.buildModelFromUrdf(str(load_description(robot_name).urdf))
    data = model.createData()
    q = np.asarray(q, dtype=float)
    mass = pin.crba(model, data, q)
    mass = np.triu(mass) + np.triu(mass, 1).T
    return np.linalg.solve(mass, pin.computeGeneralizedGravityDerivatives(model, data, q))


def test_rrp_gravity_coupling_is_what_the_decoupled_prediction_misses(fmu_root):
    """rrp's elevation q2 carries the slide s3 (0.125 m): the gravity torque on q2 is m g s3 cos(q2),
    so a moving slide changes it within the held, delayed effort ((M^-1 dg/dq)_23 about 1260 1/(m s^2)).
    Stepped together, the per-joint model misses q2 by an amount proportional to the effort's mean
    lag (d + 1/2) Ts: 2 ms, d = 1 (3 ms) six times 1 ms, d = 0 (0.5 ms), within 10 %, 3.9 % at 2 ms.
    The coupled prediction, linearized at the step's middle by an independent Pinocchio model, holds
    it within 0.2 %, and within a tenth of the decoupled miss."""
    gains = load_description("rrp").gain_set("pd").as_dict()
    misses = {}
    for ts, d in ((1e-3, 0), (2e-3, 1)):
        c = comparison.compare(experiment.cosimulate_step(fmu_root, **gains, robot="rrp", h=H, stop_time=STOP,
                                                          sample_time=ts, delay_steps=d))
        info = c.result.info
        middle = (np.asarray(info["q0"]) + np.asarray(info["q_ref"])) / 2
        np.testing.assert_allclose(info["linearization"]["stiffness"], independent_stiffness("rrp", middle),
                                   rtol=1e-9, atol=1e-9)
        decoupled = np.column_stack([sampled.predict_sampled(**gains, t=c.time - c.time[0], amplitude=a, sample_time=ts,
                                                             delay_steps=d, h=H, startup="first")
                                     for a in c.amplitudes])
        misses[ts, d] = np.max(np.abs(c.response - decoupled), axis=0) / np.abs(c.amplitudes) * 100.0
        assert c.max_deviation("sampled") < 0.2, c.table()
        assert c.deviation["sampled"][1] < 0.1 * misses[ts, d][1]
        assert c.kp_limit_arm < c.kp_limit and "the arm linearized at the step's middle" in c.table()
    assert misses[2e-3, 1][1] > 3.0                               # the decoupled model would miss 3.9 %
    assert misses[2e-3, 1][1] / misses[1e-3, 0][1] == pytest.approx(6.0, rel=0.1)


def test_without_rate_options_the_single_rate_run_is_unchanged(fmu_root):
    """Ts = h and d = 0 given explicitly is the same co-simulation bit for bit; its sampled model
    without the coupling is the single-rate one to 1e-12 of the amplitude, and with it (gravity's
    stiffness felt over the half step the effort lags) closer to the co-simulation."""
    kwargs = dict(robot="planar2r", h=H, stop_time=0.3)
    before = experiment.cosimulate_step(fmu_root, 400.0, 40.0, 0.0, **kwargs)
    after = experiment.cosimulate_step(fmu_root, 400.0, 40.0, 0.0, **kwargs, sample_time=H, delay_steps=0)
    np.testing.assert_array_equal(before.data, after.data)
    assert "sample_time" not in before.info and after.info["sample_time"] == H
    old, new = comparison.compare(before), comparison.compare(after)
    n = len(after.info["q0"])
    uncoupled = sampled.predict_coupled(400.0, 40.0, 0.0, new.time - new.time[0], new.amplitudes, sample_time=H,
                                        h=H, startup="first", stiffness=np.zeros((n, n)))
    np.testing.assert_allclose(uncoupled, old.predictions["sampled"], rtol=0, atol=1e-12 * 0.02)
    assert np.all(new.deviation["sampled"] < 0.5 * old.deviation["sampled"])
    assert old.sample_time is None and "stability limit" not in old.table() and "stability limit" in new.table()


# -- the stability limit, by co-simulation ------------------------------------------------------------
def test_kp_limit_at_4_ms_one_sample_late_holds_in_cosimulation(fmu_root, tmp_path, capsys):
    """rpp (kd 40) at 4 ms with one sample of delay: the limit is Jury's closed form; 0.9x of it
    decays as its predicted spectral radius says, 1.1x grows and is reported UNSTABLE by name."""
    kd, ts = 40.0, 4e-3
    q = kd * ts
    limit = sampled.largest_stable_kp(kd, ts, 1)
    assert limit == pytest.approx((2 * q - 3 + math.sqrt(9 - 8 * q)) / ts**2, rel=1e-9)          # 6155.5
    inside = comparison.compare(experiment.cosimulate_step(fmu_root, 0.9 * limit, kd, 0.0, robot="rpp", h=H,
                                                           stop_time=1.0, sample_time=ts, delay_steps=1))
    assert inside.kp_limit == pytest.approx(limit, rel=1e-12) and inside.spectral_radius < 1.0
    assert not inside.divergence
    assert envelope(inside, 0.8, 1.0) < 0.25 * envelope(inside, 0.0, 0.2)          # the error decays
    # at the predicted rate: 50 samples per 0.2 s window
    assert envelope(inside, 0.4, 0.6) / envelope(inside, 0.2, 0.4) == pytest.approx(
        inside.spectral_radius**50, rel=0.15)
    status, out, err = run_step(["--robot", "rpp", "--kp", repr(1.1 * limit), "--kd", "40", "--sample-time", "0.004",
                                 "--delay-steps", "1", "--stop-time", "1", "--fmus", str(fmu_root),
                                 "--out", str(tmp_path)], capsys)
    assert status == 0 and "Traceback" not in err, err
    line = next(line for line in out.splitlines() if line.startswith("UNSTABLE"))
    assert "block 'controller'" in line and "diverged" in line and "at t = " in line
    assert f"largest stable kp {limit:.6g}" in out and "110.0 % of it" in out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["step_h1ms_ts4ms_d1.png", "step_h1ms_ts4ms_d1_compare.csv",
                                                          "step_h1ms_ts4ms_d1_cosim.csv"]
    outside = comparison.compare(experiment.cosimulate_step(fmu_root, 1.1 * limit, kd, 0.0, robot="rpp", h=H,
                                                            stop_time=0.6, sample_time=ts, delay_steps=1))
    assert outside.spectral_radius > 1.0 and outside.divergence.startswith("UNSTABLE")
    assert envelope(outside, 0.4, 0.6) / envelope(outside, 0.2, 0.4) == pytest.approx(
        outside.spectral_radius**50, rel=0.15)


# -- Coulomb friction the controller does not know ----------------------------------------------------
def independent_inertia(robot_name, q):
    """1 / (M^-1)_jj of the robot's URDF by a Pinocchio model built here (CRBA), shape (n,)."""
    description = load_description(robot_name)
    model = pin.buildModelFromUrdf(str(description.urdf))
    data = model.createData()
    mass = pin.crba(model, data, np.asarray(q, dtype=float))
    mass = np.triu(mass) + np.triu(mass, 1).T
    return 1.0 / np.diag(np.linalg.inv(mass))


def test_unknown_coulomb_friction_stops_short_by_its_closed_form(fmu_root):
    """rpp, 2 ms, one sample late, Coulomb friction on q1 (14 N.m) and s3 (1.6 N), tanh over
    v_s = 1e-4: each stops short by tau_c / (m kp), m from an independent Pinocchio CRBA. The run
    (1 s) is short against the creep time (40 s): the measured stop is the prediction within
    T / creep + 2 % (its creep and its approach); the linear prediction misses all of it."""
    kp, kd, v_s = 400.0, 40.0, 1e-4
    coulomb = {1: 14.0, 3: 1.6}
    settings = {f"plant.{name}[{j}]": value for j, c in coulomb.items()
                for name, value in (("friction", c), ("friction_velocity", v_s))}
    result = experiment.cosimulate_step(fmu_root, kp, kd, 0.0, robot="rpp", h=H, stop_time=1.0, sample_time=TS,
                                        delay_steps=1, parameters=settings)
    c = comparison.compare(result)
    inertia = independent_inertia("rpp", result.info["q_ref"])
    assert [f.joint for f in c.friction] == [1, 3]
    for f in c.friction:
        k = c.joints.index(f.joint)
        amplitude = abs(c.amplitudes[k])
        expected = coulomb[f.joint] / (inertia[f.joint - 1] * kp)          # 0.004 (rad, m): 20 % of the step
        assert f.coulomb == coulomb[f.joint] and f.inertia == pytest.approx(inertia[f.joint - 1], rel=1e-9)
        assert f.predicted == pytest.approx(expected, rel=1e-9)
        assert f.creep_time > 20.0
        assert 1.0 - 1.0 / f.creep_time - 0.02 <= f.measured / expected <= 1.005
        assert f.miss == pytest.approx(f.measured, abs=0.01 * amplitude)    # the linear prediction settled on A
        assert c.deviation["sampled"][k] > 15.0
    assert c.deviation["sampled"][1] < 1.0                                  # s2 has no friction
    assert "friction unknown to the controller, q1: Coulomb 14 N.m" in c.table()


def test_friction_unknown_option_leaves_the_losses_to_the_plant(fmu_root, capsys):
    """--friction-unknown: the losses both models know become the plant's alone (loss_compensation 0)."""
    common = ["--robot", "rpp", "--sample-time", "0.002", "--stop-time", "0.2", "--fmus", str(fmu_root),
              "--set", "plant.friction[3]=1.6", "--set", "controller.friction[3]=1.6"]
    status, known, err = run_step(common, capsys)
    assert status == 0, err
    assert "friction unknown" not in known and "stability limit" in known
    status, unknown, err = run_step([*common, "--friction-unknown"], capsys)
    assert status == 0, err
    assert "friction unknown to the controller, q3: Coulomb 1.6 N, m 1:" in unknown


@pytest.mark.parametrize("argv, option", [
    (["--sample-time", "0.0025"], "--sample-time"),
    (["--sample-time", "0"], "--sample-time"),
    (["--sample-time", "nan"], "--sample-time"),
    (["--sample-time", "0.5", "--stop-time", "0.2"], "--sample-time"),
    (["--delay-steps", "-1"], "--delay-steps"),
    (["--delay-steps", "1001"], "--delay-steps"),
    (["--delay-steps", "0.5"], "--delay-steps"),
    (["--set", "plant.friction[1]"], "--set"),
    (["--set", "fk.x=1"], "--set"),
    (["--set", "controller.kp=100"], "--set"),
    (["--set", "plant.q0[1]=0.1"], "--set"),
])
def test_mistakes_answer_in_one_line_naming_the_option(fmu_root, capsys, argv, option):
    status, out, err = run_step(["--robot", "rpp", *argv, "--fmus", str(fmu_root)], capsys)
    assert status == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and option in err and "Traceback" not in err, err

"""The closed loops of the new robots through the master (1 ms), against their references."""
from __future__ import annotations

import numpy as np
import pytest

from robofmu.components.robots import load_model
from robofmu.components.trajectory import StraightLine
from robofmu.system import experiment
from robofmu.system.analysis import tracking
from robofmu.system.master import Master
from robofmu.system.roles import Roles


def run(name, fmu_root):
    system = experiment.load(name, fmu_dir=fmu_root)
    return system, Master(system).run()


def test_rrp_line_keeps_the_tcp_within_0_1_mm_of_the_path(fmu_root):
    system, result = run("rrp-line", fmu_root)
    line = StraightLine([0.125, 0.0, 0.125], -np.array([1.0, 1.0, 2.0]) / np.sqrt(6.0), 0.03125, 0.016, 0.0375)
    assert line.t1 == pytest.approx(0.42667, abs=5e-6) and line.duration == pytest.approx(2.3798, abs=5e-5)
    model = load_model("rrp")
    q = result.vector("plant.q")
    tcp = np.array([model.fk(v) for v in q])
    # distance to the straight line itself (independent of the timing) and to the reference point
    d = tcp - line.start
    off_line = np.linalg.norm(d - np.outer(d @ line.direction, line.direction), axis=1)
    assert off_line.max() < 1e-4
    x_ref = np.array([line.evaluate(t)[0] for t in result.time])
    np.testing.assert_allclose(result.vector("trajectory.x_ref"), x_ref, rtol=0, atol=1e-15)
    assert np.linalg.norm(tcp - x_ref, axis=1).max() < 1e-4
    np.testing.assert_allclose(result.vector("fk.x"), tcp, rtol=0, atol=1e-15)
    np.testing.assert_allclose(tcp[-1], line.end, atol=1e-6)       # at rest at the end of the line
    assert np.abs(result.vector("plant.qd")[-1]).max() < 1e-6
    assert result.units["controller.tau[3]"] == "N" and result.units["plant.q[3]"] == "m"


def test_rpp_bangbang_tracks_within_1_mrad_1_mm_and_ends_at_rest(fmu_root):
    system, result = run("rpp-bangbang", fmu_root)
    roles = Roles.of(system)
    m = tracking(result, roles)
    assert m.joint_units == ["rad", "m", "m"] and m.effort_units == ["N.m", "N", "N"]
    assert m.max_error.max() < 1e-3
    q_end = result.vector("plant.q")[-1]
    np.testing.assert_allclose(q_end, [np.pi / 2, 2.0, 2.0], atol=1e-6)
    assert np.abs(result.vector("plant.qd")[-1]).max() < 1e-5
    # the reference: synchronized bang-bang, T = 2 sqrt((pi/2) / 3), every joint at T/2 halfway
    T = 2.0 * np.sqrt((np.pi / 2) / 3.0)
    k = int(np.searchsorted(result.time, T / 2)) - 1             # the last point before the switch
    t = result.time[k]
    assert T / 2 - 1e-3 < t < T / 2
    a = 4.0 * np.array([np.pi / 2, 1.0, 1.0]) / T ** 2
    np.testing.assert_allclose(result.vector("trajectory.q_ref")[k], [0, 1, 1] + 0.5 * a * t ** 2, atol=1e-12)
    # the peak efforts are the inverse dynamics along the reference (perfect model), plus the
    # feedback on the tracking error the held effort leaves just after the switch (1 % on q2)
    model = load_model("rpp")
    qdd_ref, qd_ref, q_ref = (result.vector(f"trajectory.{b}") for b in ("qdd_ref", "qd_ref", "q_ref"))
    ideal = np.array([model.inverse_dynamics(*v) for v in zip(q_ref, qd_ref, qdd_ref)])
    np.testing.assert_allclose(m.peak_effort, np.abs(ideal).max(axis=0), rtol=0.015)


# Seed 003: LSPB waypoints through Newton-Raphson IK (warm-started from the last step's solution).
# (experiment, joints at the start, waypoints after the start, segment end times, stop time)
NR_RUNS = {
    "planar2r-nr": ([0.0, 1.0], [[1.2, 0.6], [0.6, 1.2]], [1.0, 3.5], 4.0),
    "rrp_offset-nr": ([0.0, 0.5, 0.5], [[-0.6, 0.4, 1.5], [-0.3, 0.7, 1.2]], [2.0, 4.5], 5.0),
}


@pytest.mark.parametrize("name", sorted(NR_RUNS))
def test_newton_raphson_runs_track_the_waypoints_within_0_1_mm(name, fmu_root):
    q0, waypoints, ends, stop = NR_RUNS[name]
    system, result = run(name, fmu_root)
    assert system.step == 0.001 and system.stop_time == stop and system.algorithm == "gauss-seidel"
    assert [b.name for b in system.blocks] == ["trajectory", "ik", "controller", "plant", "fk"]
    controller = next(b for b in system.blocks if b.name == "controller")
    assert (controller.parameters["kp"], controller.parameters["kd"]) == (400.0, 40.0)
    model = load_model(system.extra["robot"])
    assert len(result.time) == round(stop / 0.001) + 1 and result.time[-1] == pytest.approx(stop)
    x_ref = result.vector("trajectory.x_ref")
    np.testing.assert_allclose(x_ref[0], model.fk(np.array(q0)), atol=1e-15)
    for t, point in zip(ends, waypoints):              # the reference passes through the waypoints
        k = int(np.argmin(np.abs(result.time - t)))
        np.testing.assert_allclose(x_ref[k], point, atol=1e-12)
    # the TCP: the FK block's output is FK of the plant's q, within 0.1 mm of the reference throughout
    tcp = np.array([model.fk(v) for v in result.vector("plant.q")])
    np.testing.assert_allclose(result.vector("fk.x"), tcp, rtol=0, atol=1e-15)
    assert np.linalg.norm(tcp - x_ref, axis=1).max() < 1e-4
    # the IK found a solution at every communication point, in at most 3 Newton iterations after the
    # first point (warm start), to the tolerance of 1e-12 m
    assert result["ik.reachable"].min() == 1.0
    iterations, residual = result["ik.iterations"], result["ik.residual"]
    assert np.all(iterations == np.round(iterations)) and iterations[1:].max() <= 3
    assert residual.max() <= 1e-12
    assert result.units["ik.iterations"] == "1" and result.units["ik.residual"] == "m"
    # it is the robot's own solution: FK(q_ref) is the reference
    np.testing.assert_allclose([model.fk(v) for v in result.vector("ik.q_ref")], x_ref, rtol=0, atol=1e-11)
    # at rest at the last waypoint
    np.testing.assert_allclose(tcp[-1], waypoints[-1], atol=1e-6)
    assert np.abs(result.vector("plant.qd")[-1]).max() < 1e-6
    assert np.abs(result.vector("trajectory.xd_ref")[-1]).max() == 0.0
    assert iterations[-1] == 0                            # at rest: the warm start is already the solution

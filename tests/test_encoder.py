"""Encoder quantization and noise on the plant's measured outputs (issue 30, point 4).

``q_measured``, ``qd_measured`` are the plant's measurement; ``q``, ``qd`` stay the true state.
References: the resolution 2 pi / counts (revolute) or 1 / counts (prismatic) computed here, the
backward difference of the measured positions, NumPy's own Generator for the noise's statistics.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from robofmu.components.blocks import make_block


def run(plant, steps: int, h: float = 1e-3, tau=None):
    """Step the configured plant block with ``tau`` held (default: a torque that moves every joint);
    the true q, qd and the measured ones at every point, each (steps + 1, n)."""
    n = plant.robot.n
    plant.set("tau", np.full(n, 0.5) if tau is None else tau)
    plant.output(0.0)
    rows = {name: [plant.get(name)] for name in ("q", "qd", "q_measured", "qd_measured")}
    for k in range(steps):
        plant.advance(k * h, h)
        plant.output((k + 1) * h)
        for name in rows:
            rows[name].append(plant.get(name))
    return {name: np.array(values) for name, values in rows.items()}


def plant_of(robot: str, **parameters):
    plant = make_block(robot, "plant")
    for name, value in parameters.items():
        plant.set(name, value)
    plant.configure()
    return plant


def test_without_an_encoder_the_measurement_is_the_state():
    rows = run(plant_of("rrp"), 200)
    assert np.array_equal(rows["q_measured"], rows["q"]) and np.array_equal(rows["qd_measured"], rows["qd"])
    assert np.ptp(rows["q"], axis=0).min() > 1e-3                       # it moved


def test_quantized_positions_are_whole_counts_within_half_a_count():
    """rrp (revolute, revolute, prismatic): 4096 counts per revolution on joint 1, none on joint 2,
    20000 per metre on joint 3. Joint 1 reads multiples of 2 pi / 4096 rad, joint 3 of 50 um, each
    within half a count of the true q; joint 2 reads q; the measured velocity is the backward
    difference of the measured positions over the step (qd0 at the start)."""
    h = 1e-3
    plant = plant_of("rrp", encoder_counts=[4096.0, 0.0, 20000.0], g=0.0)
    rows = run(plant, 400, h)
    resolution = np.array([2.0 * math.pi / 4096.0, 0.0, 1.0 / 20000.0])
    for j in (0, 2):
        counts = rows["q_measured"][:, j] / resolution[j]
        assert np.max(np.abs(counts - np.round(counts))) < 1e-9
        assert np.max(np.abs(rows["q_measured"][:, j] - rows["q"][:, j])) <= 0.5 * resolution[j] * (1 + 1e-12)
        assert len(np.unique(np.round(counts))) > 5                         # several counts crossed
    assert np.array_equal(rows["q_measured"][:, 1], rows["q"][:, 1])
    assert np.array_equal(rows["qd_measured"][:, 1], rows["qd"][:, 1])
    difference = np.diff(rows["q_measured"][:, [0, 2]], axis=0) / h
    assert np.array_equal(rows["qd_measured"][1:, [0, 2]], difference)
    assert np.array_equal(rows["qd_measured"][0], rows["qd"][0])
    assert np.max(np.abs(rows["qd_measured"][:, 0] - rows["qd"][:, 0])) > 0.1   # not the true rate


def test_noise_is_reproducible_and_has_its_standard_deviation():
    """Noise std 1e-3 rad / 2e-3 m, no quantization: the error q_measured - q over 2000 points
    has mean 0 within 4 sigma / sqrt(N) and standard deviation within 4 / sqrt(2N) (9 %) of its
    own; the same seed gives the same numbers, another seed others; re-configuring (fmi2Reset,
    initialization) starts the sequence again."""
    std = np.array([1e-3, 1e-3, 2e-3])
    first = run(plant_of("rrp", encoder_noise=std, seed=11), 2000)
    again = run(plant_of("rrp", encoder_noise=std, seed=11), 2000)
    other = run(plant_of("rrp", encoder_noise=std, seed=12), 2000)
    assert np.array_equal(first["q_measured"], again["q_measured"])
    assert np.array_equal(first["q"], other["q"]) and not np.array_equal(first["q_measured"], other["q_measured"])
    error = first["q_measured"] - first["q"]
    count = error.shape[0]
    assert np.all(np.abs(error.mean(axis=0)) < 4.0 * std / math.sqrt(count))
    assert np.all(np.abs(error.std(axis=0) / std - 1.0) < 4.0 / math.sqrt(2.0 * count))
    plant = plant_of("rrp", encoder_noise=std, seed=11)
    run(plant, 50)
    plant.configure()                                                     # a reset
    assert np.array_equal(run(plant, 100)["q_measured"], first["q_measured"][:101])


def test_noise_then_quantization():
    """Noise of a tenth of a count before quantization: whole counts, within half a count plus
    the noise (5 sigma) of q."""
    resolution = 2.0 * math.pi / 1000.0
    plant = plant_of("chess", encoder_counts=[1000.0] * 4, encoder_noise=[0.1 * resolution] * 4, seed=3)
    rows = run(plant, 300, tau=np.zeros(4))
    counts = rows["q_measured"] / resolution
    assert np.max(np.abs(counts - np.round(counts))) < 1e-9
    assert np.max(np.abs(rows["q_measured"] - rows["q"])) <= resolution * (0.5 + 0.5)


def test_the_fmu_state_holds_the_generator_and_the_last_reading():
    plant = plant_of("rrp", encoder_counts=[4096.0, 4096.0, 1e4], encoder_noise=[1e-4] * 3, seed=5)
    run(plant, 100)
    saved = plant.internal_state()
    later = run(plant, 50)
    plant.set_internal_state(saved)
    assert all(np.array_equal(a, b) for a, b in zip(run(plant, 50).values(), later.values()))


@pytest.mark.parametrize("name, value, message", [
    ("encoder_counts", [0.0, -4096.0, 0.0], "parameter encoder_counts[2] = -4096 is invalid: must be finite and >= 0"),
    ("encoder_counts", [math.inf, 0.0, 0.0], "parameter encoder_counts[1] = inf is invalid: must be finite"),
    ("encoder_noise", [0.0, 0.0, math.nan], "parameter encoder_noise[3] = nan is invalid: must be finite"),
    ("encoder_noise", [0.0, 0.0, -1e-3], "parameter encoder_noise[3] = -0.001 is invalid: must be finite and >= 0"),
    ("seed", -1, "parameter seed = -1 is invalid: must be >= 0 and <= 2.14748e+09"),
])
def test_bad_encoder_parameters_are_refused_by_name(name, value, message):
    plant = make_block("rrp", "plant")
    plant.set(name, value)
    with pytest.raises(ValueError) as info:
        plant.configure()
    assert str(info.value) == message


def test_the_measured_ports_are_declared():
    """Outputs after every earlier variable (the value references of the others unchanged), units
    the joints', no input dependency; the counts' unit per revolution (1) or per metre (1/m)."""
    plant = make_block("rrp", "plant")
    names = [v.name for v in plant.variables]
    assert names.index("q_measured[1]") > names.index("within_limits")
    units = {v.name: v.unit for v in plant.variables}
    assert [units[f"q_measured[{j}]"] for j in (1, 3)] == ["rad", "m"]
    assert [units[f"qd_measured[{j}]"] for j in (1, 3)] == ["rad/s", "m/s"]
    assert [units[f"encoder_counts[{j}]"] for j in (1, 3)] == ["1", "1/m"]
    measured = [v for v in plant.variables if v.base in ("q_measured", "qd_measured")]
    assert all(v.causality == "output" and v.depends == () for v in measured)

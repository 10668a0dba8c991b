"""Block logic in Python floats: the same bits as the NumPy arithmetic it stands for.

FloatWriter against ``array[:] = values``; the plant's float RK4 against
:func:`~robofmu.components.integrators.rk4` (NumPy arrays) on every robot, bit for bit; the
computed-torque command against the NumPy expression of the law.
"""
import numpy as np
import pytest

from robofmu.components.control import ComputedTorque
from robofmu.components.floats import FloatWriter
from robofmu.components.integrators import rk4
from robofmu.components.plant import Plant
from robofmu.components.robots import load_model


def _bits(a) -> np.ndarray:
    return np.asarray(a, dtype=float).view(np.int64)


def test_float_writer_writes_the_bits_slice_assignment_writes(rng):
    values = rng.normal(size=7).tolist() + [np.nan, np.inf, -np.inf, -0.0, 5e-324]
    store, reference = np.zeros(15), np.zeros(15)
    FloatWriter(store[2:14])(values)           # a view, written in place
    reference[2:14] = values
    np.testing.assert_array_equal(_bits(store), _bits(reference))


@pytest.mark.parametrize("array", [np.zeros(6)[::2], np.zeros(3, dtype=np.float32),
                                   np.zeros(3, dtype=int)], ids=["strided", "float32", "int"])
def test_float_writer_refuses_an_array_it_cannot_write_whole(array):
    with pytest.raises(ValueError, match="C-contiguous float64"):
        FloatWriter(array)


def test_float_writer_refuses_a_read_only_array_and_a_wrong_count():
    frozen = np.zeros(3)
    frozen.flags.writeable = False
    with pytest.raises(ValueError, match="writeable"):
        FloatWriter(frozen)
    with pytest.raises(Exception, match="expected 3 items"):
        FloatWriter(np.zeros(3))([1.0, 2.0])


@pytest.mark.parametrize("h, max_substep", [(1e-3, 1e-3), (5e-3, 1e-3), (2e-3, 7e-4)])
def test_plant_step_is_integrators_rk4_bit_for_bit(robot, rng, h, max_substep):
    model, reference_model = load_model(robot), load_model(robot)
    n = model.n
    q0 = model.configuration("home") + rng.normal(0.0, 0.02, n)
    qd0 = rng.normal(0.0, 0.3, n)
    tau = rng.normal(0.0, 0.5, n) + model.gravity_torque(q0)
    plant = Plant(model, q0, qd0, max_substep=max_substep)
    x = np.concatenate([q0, qd0])

    def f(state):
        return np.concatenate([state[n:], reference_model.forward_dynamics(state[:n], state[n:], tau)])

    for k in range(20):
        plant.step(tau, h, k * h)
        x = rk4(f, x, h, max_substep)
        np.testing.assert_array_equal(_bits(plant.x), _bits(x), err_msg=f"{robot}: step {k}")
    assert np.max(np.abs(plant.x - np.concatenate([q0, qd0]))) > 1e-6      # it moved


@pytest.mark.parametrize("ki", [0.0, 75.0])
def test_computed_torque_command_is_the_numpy_expression_bit_for_bit(robot, rng, ki):
    model = load_model(robot)
    n = model.n
    law = ComputedTorque(model, 400.0, 20.0, ki)
    law.z[:] = rng.normal(0.0, 1e-3, n)
    q = model.configuration("home") + rng.normal(0.0, 0.05, n)
    q_ref, qd_ref, qdd_ref, qd = q + rng.normal(0.0, 0.01, n), *rng.normal(0.0, 0.3, (3, n))
    u = qdd_ref + (qd_ref - qd) * 20.0 + (q_ref - q) * 400.0
    if ki:
        u = u + law.z * ki
    tau = law.torque(q_ref, qd_ref, qdd_ref, q, qd)
    np.testing.assert_array_equal(_bits(tau), _bits(model.inverse_dynamics(q, qd, u)))
    z = law.z.copy()
    law.advance(q_ref, q, 1e-3)
    np.testing.assert_array_equal(_bits(law.z), _bits(z + (q_ref - q) * 1e-3))

"""Checks of a robot model's dynamics against an independent Lagrange derivation (sympy), shared
by the robots' own test modules. ``ref(name, q, qd)`` evaluates the derivation's ``M``, ``C``,
``g``, ``T`` (kinetic) and ``V`` (potential energy)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp


def assert_mass_coriolis_gravity_match(model, ref, q_samples, qd_samples, atol=1e-12):
    """M, C, g and N = C qd + g of ``model`` equal the derivation's at every sample."""
    err = {"M": 0.0, "C": 0.0, "g": 0.0, "N": 0.0}
    for q, qd in zip(q_samples, qd_samples):
        C, g = ref("C", q, qd), ref("g", q).ravel()
        err["M"] = max(err["M"], np.max(np.abs(model.mass_matrix(q) - ref("M", q))))
        err["C"] = max(err["C"], np.max(np.abs(model.coriolis_matrix(q, qd) - C)))   # the Christoffel C
        err["g"] = max(err["g"], np.max(np.abs(model.gravity_torque(q) - g)))
        err["N"] = max(err["N"], np.max(np.abs(model.nonlinear_effects(q, qd) - C @ qd - g)))
    assert max(err.values()) < atol, err


def assert_energies_match(model, ref, q_samples, qd_samples):
    """The model's kinetic and potential energies are the derivation's T and V at every sample.
    (T = qd^T M qd / 2, inverse(forward(tau)) = tau, Mdot - 2C skew: every robot, test_contract.py.)"""
    for q, qd in zip(q_samples, qd_samples):
        assert model.kinetic_energy(q, qd) == pytest.approx(float(ref("T", q, qd)), rel=1e-12)
        assert model.potential_energy(q) == pytest.approx(float(ref("V", q)), abs=1e-12)


def assert_energy_conserved_without_torque(model, ref, q0, qd0, duration, points=101):
    """Free motion under gravity (DOP853, rtol 1e-10): T + V of the derivation stays within 1e-7
    of its start, relative to |E0| + T0; the robot really moved (some joint by more than 0.1)."""
    n = model.n

    def f(_, x):
        return np.concatenate([x[n:], model.forward_dynamics(x[:n], x[n:], np.zeros(n))])

    sol = solve_ivp(f, (0.0, duration), np.concatenate([q0, qd0]), method="DOP853", rtol=1e-10,
                    atol=1e-12, t_eval=np.linspace(0.0, duration, points))
    assert sol.success
    energy = np.array([float(ref("T", x[:n], x[n:]) + ref("V", x[:n])) for x in sol.y.T])
    scale = abs(energy[0]) + model.kinetic_energy(q0, qd0)
    assert np.max(np.abs(energy - energy[0])) / scale < 1e-7
    assert np.max(np.abs(sol.y[:n, -1] - q0)) > 0.1

"""Checks of an IK solver's rates along an LSPB waypoint profile, shared by the robots' tests."""
from __future__ import annotations

import numpy as np


def rates_against_differences(ik, profile, times, h=1e-5) -> list[np.ndarray]:
    """At each of ``times`` away from the profile's blend switches (where the acceleration jumps),
    assert that the solver's qd and qdd equal central differences of its positions along the
    profile (1e-8, 5e-4); returns the qd of every point checked."""
    switches = np.concatenate([[s.start, s.start + (s.end - s.start) / 3, s.end - (s.end - s.start) / 3, s.end]
                               for s in profile.segments])
    checked = []
    for t in times:
        if np.min(np.abs(t - switches)) < 1e-3:
            continue
        x, xd, xdd = profile.evaluate(t)
        q, qd, qdd = ik.solve(x, xd, xdd)
        qp, qm = ik.position(profile.evaluate(t + h)[0]), ik.position(profile.evaluate(t - h)[0])
        np.testing.assert_allclose(qd, (qp - qm) / (2 * h), atol=1e-8)
        np.testing.assert_allclose(qdd, (qp - 2 * q + qm) / h**2, atol=5e-4)
        checked.append(qd)
    return checked

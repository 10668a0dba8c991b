"""Shared fixtures: the chess FMUs, built fresh from this checkout once per test session."""
from __future__ import annotations

import numpy as np
import pytest

import robofmu.components  # noqa: F401  (the installed copy first, before any FMU's bundle)
from robofmu.components.robot import Robot, load_spec


@pytest.fixture(scope="session")
def fmu_dir(tmp_path_factory):
    """Folder holding chess/{trajectory,ik,controller,plant}.fmu built from the current sources."""
    from robofmu.system.build import build

    out = tmp_path_factory.mktemp("fmus")
    build("chess", out, log=lambda *_: None)
    return out / "chess"


@pytest.fixture(scope="session")
def chess_spec():
    return load_spec("chess")


@pytest.fixture
def chess():
    return Robot("chess")


@pytest.fixture(scope="session")
def rng():
    return np.random.default_rng(20261122)

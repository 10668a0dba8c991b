"""Shared fixtures: every robot's FMUs, built fresh from this checkout once per test session.

- ``fmu_root``: the collection, ``<root>/<robot>/<block>.fmu`` for every described robot
  (:func:`robofmu.components.robots.available`), built once per session;
- ``fmu_dir``: ``<root>/chess`` (the chess tests name blocks relative to it);
- ``robot``: a parametrized fixture, one test per described robot (ids: the robot's name);
  :func:`fmu_util.robot_blocks` gives ``(robot, block)`` parameters with ids like ``rrp-plant``;
- ``raw_instances``: instances driven through the raw FMI functions (:class:`fmu_util.RawInstance`).

Markers (registered in pyproject.toml): whole modules get theirs from :data:`MODULE_MARKERS` here,
the one place they are assigned; a single test of 2 s or more carries ``@pytest.mark.slow`` itself.
``make check`` runs ``pytest -m "not slow and not interop"``; plain ``pytest`` runs everything.
"""
from __future__ import annotations

import numpy as np
import pytest

import robofmu.components  # noqa: F401  (the installed copy first, before any FMU's bundle)
from robofmu.components.robots import available, load_description, load_model


#: Markers of whole test modules, by file name. interop: another FMI tool, process or host runs
#: the FMUs; slow: (nearly) every test of the module takes 2 s or more; study: a study, sweep or
#: packaged experiment end to end.
MODULE_MARKERS = {
    "test_arms.py": ("slow", "study"),                   # two 3 s runs of the industrial arms
    "test_c_host.py": ("interop",),
    "test_container.py": ("interop",),
    "test_ecos.py": ("interop",),
    "test_experiments.py": ("slow", "study"),            # 14 of its 17 tests take 2 to 24 s
    "test_fresh_environment.py": ("interop", "slow"),
    "test_importers.py": ("interop",),
    "test_interop.py": ("interop",),
    "test_libcosim.py": ("interop",),
    "test_many_runs.py": ("slow",),
    "test_newton_study.py": ("study",),
    "test_sampled_loop_study.py": ("study",),
    "test_ssp.py": ("interop",),
    "test_step_sampled.py": ("study",),
    "test_stepresponse.py": ("study",),
    "test_sweep.py": ("slow", "study"),                  # dask clusters: 10 of its 22 tests take 2 to 30 s
    "test_sweep_axes.py": ("study",),
    "test_sweep_contract.py": ("study",),
    "test_sweep_design.py": ("study",),
    "test_sweep_report.py": ("study",),
}


@pytest.hookimpl(tryfirst=True)          # before -m deselects by them
def pytest_collection_modifyitems(items):
    for item in items:
        for name in MODULE_MARKERS.get(item.path.name, ()):
            item.add_marker(name)


@pytest.fixture(scope="session")
def fmu_root(tmp_path_factory):
    """Root of the FMU collection built from the current sources: ``<root>/<robot>/<block>.fmu``."""
    from robofmu.system.packaging.build import build

    out = tmp_path_factory.mktemp("fmus")
    for robot in available():
        build(robot, out, log=lambda *_: None)
    return out


@pytest.fixture(scope="session")
def fmu_dir(fmu_root):
    """Folder holding chess/{trajectory,ik,controller,plant}.fmu."""
    return fmu_root / "chess"


@pytest.fixture(params=available())
def robot(request) -> str:
    """Each described robot in turn (by name)."""
    return request.param


@pytest.fixture(scope="session")
def chess_description():
    return load_description("chess")


@pytest.fixture
def chess():
    """A fresh model of the chess arm (its own payload and gravity state)."""
    return load_model("chess")


@pytest.fixture(scope="session")
def rng():
    return np.random.default_rng(20261122)


@pytest.fixture
def raw_instances():
    """``open_(path, name="block", **kwargs)`` -> :class:`fmu_util.RawInstance` (raw FMI calls,
    messages recorded); every instance opened is closed after the test."""
    from fmu_util import RawInstance

    opened = []

    def open_(path, name="block", **kwargs):
        instance = RawInstance(path, name, **kwargs)
        opened.append(instance)
        return instance

    yield open_
    for instance in opened:
        instance.close()


@pytest.fixture
def copy_robot(tmp_path):
    """``copy_robot(robot, edit=None, stem=None)``: a robot's folder copied to tmp_path, its TOML
    edited (:func:`robot_files.robot_copier`); returns the TOML's path."""
    from robot_files import robot_copier
    return robot_copier(tmp_path)

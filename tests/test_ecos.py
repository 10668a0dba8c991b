"""Every robot's exported SSP package run by ecos (the Ecos platform's co-simulation engine, through
ecospy), against the master's Jacobi run.

ecos steps every component from t with the values transferred at t, then transfers the outputs:
the master's Jacobi exchange; its initialization passes connected values along once per
component, so the loop starts consistent. Hence, on one PD experiment per robot:

- the blocks without direct feedthrough (trajectory, plant) record what the master records, to
  rounding (ecos accumulates its time, t += h, n eps t off after n steps; the master computes k h);
- a feedthrough block (ik, controller, fk, jacobian) records, in ecos, its outputs for the inputs
  transferred after the step (ecos sets them and reads every output again), i.e. the master's
  value one row later. The Newton-Raphson IK's ``iterations`` is left out there: the solve ecos
  asks for is another solve than the master's (the same solution, another iteration count).
"""
from __future__ import annotations

import zipfile
from xml.etree import ElementTree as ET

import numpy as np
import pytest

from fmu_util import assert_same_run, real_columns, robot_experiments
from robofmu.system import experiment
from robofmu.system.plan import plan
from robofmu.system.master import Master, SimulationError
from robofmu.system.result import Result
from robofmu.system.interop.ecos import load_ecospy, run_ssp_ecos
from robofmu.system.interop.ssp import NS, export_ssp, ssd_text

load_ecospy()           # the dev extra: a missing ecospy or libtbb.so.12 fails here, never skips

STOP = 0.5                  # s


@pytest.fixture(scope="module")
def packages(fmu_root, tmp_path_factory):
    """packages(name) -> (System, its .ssp), exported once."""
    folder, cache = tmp_path_factory.mktemp("ecos"), {}

    def get(name):
        if name not in cache:
            system = experiment.load(name, fmu_dir=fmu_root)
            cache[name] = system, export_ssp(system, folder / f"{name}.ssp")
        return cache[name]

    return get


@pytest.mark.parametrize("name", robot_experiments())
def test_ecos_reproduces_the_master_in_jacobi_mode(packages, name):
    """The whole experiment (chess: the gripper closes at 6 s and opens at 11.5 s)."""
    system, path = packages(name)
    h = system.step
    ecos = run_ssp_ecos(path, system.stop_time, h)
    jacobi = Master(system).run(system.stop_time, h, "jacobi")
    n = len(jacobi.time) - 1                  # ecos adds h n times: rounding of at most n eps t
    np.testing.assert_allclose(ecos.time, jacobi.time, rtol=0, atol=n * np.finfo(float).eps * system.stop_time)
    real = real_columns(jacobi.columns)
    assert sorted(ecos.columns) == sorted(real)
    planned = plan(system)
    feedthrough = {b for b, node in planned.nodes.items() if any(node.feedthrough.values())}
    assert {"ik", "controller"} & feedthrough and "plant" not in feedthrough
    # ecos's accumulated time is off by up to n eps t (3.7e-11 s after 13 s at 1 ms): the references
    # move by their rate times that (measured: 5e-12 over the chess run), hence 1e-10 of the range
    if "ik.status" in jacobi.columns:                  # an IK that carries its solution forward: at the task
        columns = list(ecos.columns)
        shifted = Result(jacobi.time[:-1], columns, np.column_stack(
            [jacobi[c][1:] if c.split(".", 1)[0] in feedthrough else jacobi[c][:-1] for c in columns]))
        ours = Result(ecos.time[:-1], columns, np.column_stack([ecos[c][:-1] for c in columns]))
        assert_same_run(ours, shifted, name, 1e-10)
        return
    for column in ecos.columns:
        block = column.split(".", 1)[0]
        scale = max(1.0, np.max(np.abs(jacobi[column])))
        if block not in feedthrough:
            np.testing.assert_allclose(ecos[column], jacobi[column], rtol=0, atol=1e-10 * scale, err_msg=column)
        elif not column.endswith(".iterations"):
            np.testing.assert_allclose(ecos[column][:-1], jacobi[column][1:], rtol=0, atol=1e-10 * scale,
                                       err_msg=column)
    # not vacuous: the master's Gauss-Seidel run is another run
    gauss_seidel = Master(system).run(STOP, h, "gauss-seidel")
    assert np.max(np.abs(gauss_seidel.vector("plant.q") - jacobi.vector("plant.q")[:len(gauss_seidel.time)])) > 1e-9


@pytest.mark.parametrize("name, system_name", [("rrp-line", "rrp_line"), ("3rrp-circle", "x3rrp_circle")])
def test_ecos_applies_the_packages_parameter_set(packages, fmu_root, tmp_path, name, system_name):
    """A package whose controller gains differ from the experiment's: ecos's run follows them, so
    the SSV set (named after the system, the experiment's name as an identifier) is applied at
    initialization."""
    system, _ = packages(name)
    controller = next(b for b in system.blocks if b.name == "controller")
    softer = experiment.with_parameters(system, {"controller.kp": controller.parameters.get("kp", 400.0) / 4})
    path = export_ssp(softer, tmp_path / "softer.ssp")
    root = ET.fromstring(ssd_text(path))
    assert (root.find("ssd:System", NS).get("name"), root.get("description")) == (system_name, name)
    with zipfile.ZipFile(path) as zf:
        assert ET.fromstring(zf.read("resources/controller.ssv")).get("name") == system_name
    ecos = run_ssp_ecos(path, STOP, system.step)
    np.testing.assert_allclose(ecos.vector("plant.q"), Master(softer).run(STOP, system.step, "jacobi").vector("plant.q"),
                               rtol=0, atol=1e-12)
    assert np.max(np.abs(ecos.vector("plant.q") - Master(system).run(STOP, system.step, "jacobi").vector("plant.q"))) > 1e-9


def test_two_ecos_runs_in_one_process_are_identical(packages):
    _, path = packages("chess-pd")
    first, second = run_ssp_ecos(path, 0.1, 1e-3), run_ssp_ecos(path, 0.1, 1e-3)
    np.testing.assert_array_equal(first.data, second.data)


@pytest.mark.parametrize("change, block, time, rows", [
    ({"controller.kp": -1.0}, "controller", 0.0, 0),       # refused at initialization
    ({"controller.kd": 1e308}, "plant", 0.002, 3),          # an infinite torque: the plant refuses its step
])
def test_a_refusing_block_stops_ecos_as_it_stops_the_master(packages, tmp_path, change, block, time, rows):
    """ecos ignores FMI statuses; the runner reads the FMUs' messages from its debug log and stops
    at the first error, naming the block, the time and the FMU's reason, keeping the rows before."""
    system, _ = packages("chess-pd")
    broken = experiment.with_parameters(system, change)
    with pytest.raises(SimulationError) as master:
        Master(broken).run(STOP, system.step, "jacobi")
    with pytest.raises(SimulationError) as ecos:
        run_ssp_ecos(export_ssp(broken, tmp_path / "broken.ssp"), STOP, system.step)
    assert (ecos.value.block, ecos.value.time) == (master.value.block, master.value.time) == (block, time)
    assert master.value.reason.rsplit(f"{block}: ", 1)[-1] in str(ecos.value)     # the FMU's own words
    assert str(ecos.value).startswith(f"ecos: {block} at t = {time:g} s: fmi2Error: ")
    if rows:
        assert len(ecos.value.result.time) == rows
        np.testing.assert_allclose(ecos.value.result.vector("plant.q"), master.value.result.vector("plant.q")[:rows],
                                   rtol=0, atol=1e-12)
    else:
        assert ecos.value.result is None

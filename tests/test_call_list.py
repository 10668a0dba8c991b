"""The master's C call list (issue 30, the master's overhead): every exchange and every round of
steps made by one ctypes call into ``system/call_list.c`` gives a run bit for bit the one the
single ctypes calls give, on every packaged experiment, single-rate and multi-rate; it makes the
same calls (counted by kind); a call that fails in it is named by block and FMI function as a
single call's is; ``ROBOFMU_CALL_LIST=0`` and a missing compiler fall back to the single calls,
saying so in the result's info.
"""
from __future__ import annotations

import ctypes
import os
import subprocess
import sys
from collections import Counter

import numpy as np
import pytest
from fmu_util import refuse_plant_steps

from robofmu.system import call_list, experiment
from robofmu.system import master as master_module
from robofmu.system.master import Master, SimulationError

STOP = 0.05       # s: every kind of call made at least a few dozen times


def _single_calls(monkeypatch):
    monkeypatch.setattr(master_module, "runner", lambda: (None, "single ctypes calls: the test"))


def _counted(monkeypatch):
    """Count the calls, by kind and block, that the batches built for a run hold."""
    counts = Counter()
    original = master_module.batch

    def batch(run, calls):
        made = original(run, calls)
        for call in calls:
            counts[(call[2], call[3], call[4].signals is not None)] += 1
        return made
    monkeypatch.setattr(master_module, "batch", batch)
    return counts


def _run(system):
    return Master(system).run(stop_time=STOP)


@pytest.mark.parametrize("name", [name if name == "chess-pd" else pytest.param(name, marks=pytest.mark.slow)
                                  for name in experiment.available()])       # make check: chess-pd
def test_the_call_list_runs_every_experiment_bit_for_bit_as_the_single_calls(fmu_root, name, monkeypatch):
    system = experiment.load(name, fmu_dir=fmu_root)
    listed = _run(system)
    assert listed.info["calls"].startswith("call list (")
    with monkeypatch.context() as patch:
        _single_calls(patch)
        single = _run(system)
    assert single.info["calls"] == "single ctypes calls: the test"
    assert listed.columns == single.columns and len(listed.time) == round(STOP / system.step) + 1
    np.testing.assert_array_equal(listed.data, single.data)


@pytest.mark.slow
def test_the_experiments_exercise_every_kind_of_call_the_list_makes(fmu_root, monkeypatch):
    """Gathered Real inputs and Boolean inputs are in some packaged experiment, so the test above
    covers every branch of the C loop."""
    counts = _counted(monkeypatch)
    for name in experiment.available():
        _run(experiment.load(name, fmu_dir=fmu_root))
    kinds = {(call, gathered) for (_, call, gathered) in counts}
    assert {("fmi2GetReal", False), ("fmi2GetBoolean", False), ("fmi2SetReal", False), ("fmi2SetReal", True),
            ("fmi2SetBoolean", True), ("fmi2DoStep", False)} <= kinds


@pytest.mark.slow
def test_a_multirate_run_is_the_same_through_the_list(fmu_root, monkeypatch):
    system = experiment.load("chess-pd", fmu_dir=fmu_root)
    system.block("controller").sample_time = 0.004
    system.block("controller").parameters["delay_steps"] = 1
    listed = Master(system).run(stop_time=0.1)
    with monkeypatch.context() as patch:
        _single_calls(patch)
        single = Master(system).run(stop_time=0.1)
    assert listed.info["sample_times"]["controller"] == pytest.approx(0.004)
    np.testing.assert_array_equal(listed.data, single.data)


@pytest.mark.parametrize("list_on", [True, False])
def test_a_call_that_fails_in_the_list_is_named_by_block_and_function(fmu_root, monkeypatch, list_on):
    """The plant refuses its step from t = 0.02 s: the failure names the plant's fmi2DoStep at
    that time either way, and the rows up to it are kept."""
    refuse_plant_steps(monkeypatch, "chess", 0.02)
    if not list_on:
        _single_calls(monkeypatch)
    with pytest.raises(SimulationError) as failed:
        Master(experiment.load("chess-pd", fmu_dir=fmu_root)).run(stop_time=0.05)
    assert failed.value.block == "plant"
    assert "plant: fmi2DoStep failed at t = 0.02 s" in str(failed.value) and "refused for the test" in str(failed.value)
    assert failed.value.result.time[-1] == pytest.approx(0.02)


def test_the_c_loop_stops_at_the_first_failing_call_and_names_its_index():
    """Three calls of C functions made here: the second fails with fmi2Error (3); the third is
    not made. Booleans are set only when they change."""
    run, how = call_list.runner()
    assert run is not None, how
    made = []
    prototype = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p)

    def fake(status):
        def function(component, references, count, values):
            made.append((component, count))
            return status
        return prototype(function)

    ok, error = fake(0), fake(3)
    signals = np.array([1, 0, 1], dtype=np.int32)
    sources = np.array([2, 0], dtype=np.intp)
    values = np.zeros(2, dtype=np.int32)
    last, have = np.zeros(2, dtype=np.int32), np.zeros(1, dtype=np.int32)
    references = (ctypes.c_uint * 2)(5, 6)
    boolean = call_list.Record(ok, 7, references, 2, values, signals, sources, last, have)
    calls = [(None, (), "a", "fmi2SetBoolean", boolean)] * 2 + [
        (None, (), "b", "fmi2GetReal", call_list.Record(error, 8, references, 1, np.zeros(1))),
        (None, (), "c", "fmi2GetReal", call_list.Record(ok, 9, references, 1, np.zeros(1)))]
    (single,) = call_list.batch(run, calls)
    function, arguments, listed, _, _ = single
    assert function(*arguments) == 3
    assert listed.failed() == ("b", "fmi2GetReal")
    assert made == [(7, 2), (8, 1)]                      # the second set: unchanged, not made
    assert values.tolist() == [1, 1] and last.tolist() == [1, 1] and have[0] == 1
    signals[0] = 0                                       # source 0 changes: set again
    made.clear()
    assert function(*arguments) == 3 and made == [(7, 2), (8, 1)] and values.tolist() == [1, 0]


def test_without_the_list_the_master_says_why(tmp_path):
    code = ("from robofmu.system import call_list; run, how = call_list.runner(); "
            "print(run is None, how)")
    for environment, expected in (({"ROBOFMU_CALL_LIST": "0"}, "True single ctypes calls: ROBOFMU_CALL_LIST=0"),
                                  ({"CC": str(tmp_path / "no-such-cc"), "ROBOFMU_CACHE": str(tmp_path)},
                                   "True single ctypes calls:")):
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                              env={**os.environ, **environment})
        assert done.returncode == 0, done.stderr
        assert done.stdout.startswith(expected), done.stdout

"""Misuse of the FMU interface, for every block of every robot: each call in the wrong state, each
foreign or corrupt FMU state, each input that would make an output non-finite is refused with a
status that is not OK and a logged message naming the call or the variable; nothing is half-applied.
"""
from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException

from robofmu.components.robots import available, load_model
from robofmu.system.fmu import Block, FMUError

from fmu_util import open_block, robot_blocks

ALL = robot_blocks()
H = 1e-3


def status_of(exc: Exception) -> str:
    """The FMI status word an fmpy call failed with ("discard", "error", "fatal")."""
    found = re.search(r"status \d \((\w+)\)", str(exc))
    assert found, str(exc)
    return found.group(1)


def refused(block: Block, call: str, fn, *args) -> tuple[str, str]:
    """Call ``fn(*args)``, expect a refusal; its status and the messages logged meanwhile."""
    since = len(block.messages)
    with pytest.raises((FMUError, FMICallException)) as info:
        block._call(call, fn, *args)
    logged = " | ".join(m.message for m in block.messages[since:] if m.status in ("ERROR", "FATAL", "WARNING"))
    return status_of(info.value), logged


def outputs(block: Block) -> list:
    names = [v.name for v in block.md.modelVariables if v.causality == "output" and v.type == "Real"]
    return block.get_real([block.variables[n].valueReference for n in names])


# -- calls in the wrong state ----------------------------------------------------------------------
@pytest.mark.parametrize("robot, kind", ALL)
def test_do_step_before_initialization_is_refused(fmu_root, robot, kind):
    b = Block(fmu_root / robot / f"{kind}.fmu", kind)
    try:
        status, logged = refused(b, "fmi2DoStep", b.slave.doStep, 0.0, H)
        assert status in ("discard", "error")
        assert "fmi2DoStep: called before fmi2ExitInitializationMode" in logged
    finally:
        b.close()


@pytest.mark.parametrize("robot, kind", ALL)
def test_do_step_after_terminate_is_refused(fmu_root, robot, kind):
    b = open_block(fmu_root / robot, kind)
    try:
        b.do_step(0.0, H)
        b.slave.terminate()
        status, logged = refused(b, "fmi2DoStep", b.slave.doStep, H, H)
        assert status in ("discard", "error") and "fmi2DoStep: the instance is terminated" in logged
    finally:
        b.close()


@pytest.mark.parametrize("robot, kind", ALL)
def test_second_initialization_is_refused(fmu_root, robot, kind):
    b = open_block(fmu_root / robot, kind)
    try:
        b.do_step(0.0, H)
        before = outputs(b)
        status, logged = refused(b, "fmi2EnterInitializationMode", b.slave.enterInitializationMode)
        assert status in ("error", "fatal")
        assert "fmi2EnterInitializationMode: the instance is already initialized" in logged
    finally:
        b.close()
    assert len(before) > 0


@pytest.mark.parametrize("step, problem", [(-1e-3, "-0.001 s is invalid"), (0.0, "0.0 s is invalid"),
                                           (math.nan, "nan s is invalid"), (math.inf, "inf s is invalid")],
                         ids=["negative", "zero", "nan", "inf"])
@pytest.mark.parametrize("robot, kind", robot_blocks(kinds=("plant", "trajectory")))
def test_bad_communication_step_is_refused_and_loses_nothing(fmu_root, robot, kind, step, problem):
    b = open_block(fmu_root / robot, kind)
    try:
        b.do_step(0.0, H)
        before = outputs(b)
        status, logged = refused(b, "fmi2DoStep", b.slave.doStep, H, step)
        assert status in ("discard", "error")
        assert f"fmi2DoStep: communication step h = {problem}: must be finite and > 0" in logged
        assert outputs(b) == before                   # nothing moved
        b.do_step(H, H)                               # and the instance goes on
    finally:
        b.close()


@pytest.mark.parametrize("robot, kind", ALL)
def test_communication_point_jumping_backwards_is_refused(fmu_root, robot, kind):
    b = open_block(fmu_root / robot, kind)
    try:
        for k in range(3):
            b.do_step(k * H, H)
        before = outputs(b)
        status, logged = refused(b, "fmi2DoStep", b.slave.doStep, H, H)
        assert status in ("discard", "error")
        assert "communication point t = 0.001 s does not continue from the instance's time 0.003" in logged
        assert outputs(b) == before
    finally:
        b.close()


@pytest.mark.parametrize("robot", ["chess", "rrp", "rpp"])
def test_an_hour_long_plant_step_is_refused(fmu_root, robot):
    b = open_block(fmu_root / robot, "plant")
    try:
        before = outputs(b)
        status, logged = refused(b, "fmi2DoStep", b.slave.doStep, 0.0, 3600.0)
        assert status in ("discard", "error")
        assert "a step of 3600 s needs 3600000 RK4 sub-steps of max_substep = 0.001 s" in logged
        assert outputs(b) == before
    finally:
        b.close()


# -- FMU states that do not belong ------------------------------------------------------------------
def _saved(fmu_root, robot, kind, parameters=None, steps=3):
    b = open_block(fmu_root / robot, kind, parameters=parameters)
    for k in range(steps):
        b.do_step(k * H, H)
    return b, b.get_state()


@pytest.mark.parametrize("robot", ["chess", "rrp", "rpp"])
def test_state_of_another_block_kind_is_refused(fmu_root, robot):
    source, state = _saved(fmu_root, robot, "plant")
    target = open_block(fmu_root / robot, "controller")
    try:
        before = outputs(target)
        status, logged = refused(target, "fmi2SetFMUstate", target.slave.setFMUstate, state)
        assert status in ("error", "fatal")
        assert "fmi2SetFMUstate: the state belongs to another block: block 'plant' (this instance: " \
               "'controller')" in logged and "nothing restored" in logged
        assert outputs(target) == before
    finally:
        target.close()
        source.close()


@pytest.mark.parametrize("kind", ["plant", "controller", "fk"])
def test_state_of_another_robot_is_refused(fmu_root, kind):
    source, state = _saved(fmu_root, "rrp", kind)
    target = open_block(fmu_root / "rpp", kind)
    try:
        before = outputs(target)
        status, logged = refused(target, "fmi2SetFMUstate", target.slave.setFMUstate, state)
        assert status in ("error", "fatal")
        assert "robot 'rrp' (this instance: 'rpp')" in logged
        assert outputs(target) == before
    finally:
        target.close()
        source.close()


@pytest.mark.parametrize("robot", ["chess", "rrp", "rpp"])
def test_state_saved_with_other_parameters_is_refused(fmu_root, robot):
    source, state = _saved(fmu_root, robot, "controller", parameters={"kp": 100.0})
    target = open_block(fmu_root / robot, "controller")
    try:
        status, logged = refused(target, "fmi2SetFMUstate", target.slave.setFMUstate, state)
        assert status in ("error", "fatal")
        assert "the state was saved with other parameters: kp = 100.0 (this instance: 400.0)" in logged
    finally:
        target.close()
        source.close()


@pytest.mark.parametrize("robot", ["chess", "rrp", "rpp"])
def test_corrupt_serialized_state_is_refused(fmu_root, robot):
    source, state = _saved(fmu_root, robot, "plant")
    blob = source.slave.serializeFMUstate(state)
    source.close()
    target = open_block(fmu_root / robot, "plant")
    try:
        before = outputs(target)
        for bad, reason in ((b"not json at all", "the serialized state is corrupt"),
                            (bytes(blob)[:-7], "the serialized state is corrupt"),
                            (json.dumps({"time": 0.0}).encode(), "not a robofmu block state")):
            restored = target.slave.deSerializeFMUstate(bad)
            status, logged = refused(target, "fmi2SetFMUstate", target.slave.setFMUstate, restored)
            assert status in ("error", "fatal") and reason in logged
        assert outputs(target) == before
    finally:
        target.close()


@pytest.mark.parametrize("robot", ["chess", "rrp", "rpp"])
def test_non_finite_serialized_state_is_refused(fmu_root, robot):
    source, state = _saved(fmu_root, robot, "plant")
    document = json.loads(bytes(source.slave.serializeFMUstate(state)).decode())
    source.close()
    document["values"][0] = float("nan")
    target = open_block(fmu_root / robot, "plant")
    try:
        before = outputs(target)
        restored = target.slave.deSerializeFMUstate(json.dumps(document).encode())
        status, logged = refused(target, "fmi2SetFMUstate", target.slave.setFMUstate, restored)
        assert status in ("error", "fatal") and "the state holds non-finite values" in logged
        assert outputs(target) == before
    finally:
        target.close()


# -- inputs that would make an output non-finite ----------------------------------------------------
@pytest.mark.parametrize("robot", ["chess", "rrp", "rpp"])
def test_overflowing_controller_output_is_held_and_the_step_refused(fmu_root, robot):
    b = open_block(fmu_root / robot, "controller", parameters={"kp": 1e300})
    try:
        good = outputs(b)
        assert all(math.isfinite(v) for v in good)
        b.set("q_ref[1]", 1e10)                       # kp e = 1e310: overflows
        held = outputs(b)
        assert held == good                           # no inf leaves the block
        assert any("output tau[" in m.message and "would be" in m.message and "q_ref[1] = 1e+10" in m.message
                   for m in b.messages)
        status, logged = refused(b, "fmi2DoStep", b.slave.doStep, 0.0, H)
        assert status in ("discard", "error") and "step refused" in logged
    finally:
        b.close()


@pytest.mark.parametrize("robot, target", [("chess", [0.0, 0.0, 0.6]), ("rrp", [0.0, 0.0, 0.2])],
                         ids=["chess-on-the-base-axis", "rrp-on-the-base-axis"])
def test_ik_target_at_a_singularity_is_not_reachable(fmu_root, robot, target):
    b = open_block(fmu_root / robot, "ik")
    try:
        home = outputs(b)
        b.set("x_ref", target)
        assert b.get("reachable") is False
        assert outputs(b)[:load_model(robot).n] == home[:load_model(robot).n]      # last valid q held
        assert any("base axis" in m.message and m.status == "WARNING" for m in b.messages)
    finally:
        b.close()


def test_ik_rates_beyond_qd_limit_count_as_not_reachable(fmu_root):
    """Near the rrp's elevation singularity (q2 -> pi/2) a modest task speed needs huge joint
    rates: the block refuses to pass them on."""
    b = open_block(fmu_root / "rrp", "ik")
    try:
        b.set("x_ref", [1e-4, 0.0, 0.2])              # 1e-4 m off the base axis, arm nearly vertical
        b.set("xd_ref", [0.0, 0.01, 0.0])             # 10 mm/s sideways: q1 rate 100 rad/s
        assert b.get("reachable") is False
        assert any("too close to a singularity: joint rate qd_ref[1] = 100 exceeds qd_limit[1] = 5"
                   in m.message for m in b.messages)
        assert b.get("qd_ref") == [0.0, 0.0, 0.0]
        b.set("xd_ref", [0.0, 1e-4, 0.0])             # 1 rad/s: within the limit
        assert b.get("reachable") is True
        np.testing.assert_allclose(b.get("qd_ref"), [1.0, 0.0, 0.0], rtol=1e-9, atol=1e-12)
    finally:
        b.close()


@pytest.mark.parametrize("parameters, message", [
    ({"grip_open_after_move": 2}, "grip_open_after_move = 2 must come after grip_close_after_move = 3"),
    ({"grip_close_after_move": 0}, "grip_open_after_move = 6: the gripper never closes"),
    ({"durations": "1e-300 3 1 1 2 1 1"}, "the parameters give a non-finite reference"),
    ({"waypoints": "1e308 0 0; -1e308 0 0; 0 0 0; 0 0 0; 0 0 0; 0 0 0; 0 0 0; 0 0 0"},
     "the parameters give a non-finite reference"),
], ids=["open-before-close", "open-without-close", "tiny-duration", "huge-waypoints"])
def test_trajectory_refuses_inconsistent_or_non_finite_references(fmu_root, parameters, message):
    b = Block(fmu_root / "chess" / "trajectory.fmu", "trajectory")
    try:
        with pytest.raises(FMUError) as info:
            b.initialize(0.0, parameters)
        assert "fmi2ExitInitializationMode" in str(info.value) and message in str(info.value)
    finally:
        b.close()


@pytest.mark.parametrize("call, kind_of_reference", [
    ("getBoolean", "Real"), ("getReal", "Boolean"), ("getInteger", "Real"), ("getString", "Real"),
    ("setBoolean", "Real"), ("setReal", "Boolean")])
def test_value_reference_of_the_wrong_type_is_an_error_naming_the_variable(fmu_root, call, kind_of_reference):
    """An importer treating every port as Real (or any other type confusion) gets fmi2Error and
    the variable's name, never a NaN."""
    b = open_block(fmu_root / "chess", "plant")
    try:
        variable = "q[2]" if kind_of_reference == "Real" else "grip"
        vr = [b.variables[variable].valueReference]
        fn = getattr(b.slave, call)
        args = (vr,) if call.startswith("get") else (vr, [True] if call == "setBoolean" else [1.0])
        status, logged = refused(b, f"fmi2{call[0].upper()}{call[1:]}", fn, *args)
        assert status == "error"
        assert f"value references of ['{variable}'] do not name" in logged
        b.do_step(0.0, H)                             # the instance is still usable
    finally:
        b.close()


@pytest.mark.parametrize("robot", available())
@pytest.mark.parametrize("block_first", [False, True], ids=["alone", "after-a-robofmu-block"])
def test_bad_parameter_through_simulate_fmu_raises_with_the_fmus_message(fmu_root, robot, block_first, capfd):
    """fmpy.simulate_fmu with its defaults (debug logging off, its own printing logger): the run
    raises fmi2Error and the user sees the FMU's message naming the parameter, also once a robofmu
    Block has registered its logger with fmpy's process-wide logger proxy."""
    from fmpy import simulate_fmu

    if block_first:
        open_block(fmu_root / robot, "plant").close()
        capfd.readouterr()
    with pytest.raises(Exception, match=r"fmi2ExitInitializationMode failed with status 3 \(error\)"):
        simulate_fmu(str(fmu_root / robot / "plant.fmu"), stop_time=0.01, step_size=H,
                     start_values={"max_substep": -1.0})
    shown = capfd.readouterr()
    assert "initialization failed: parameter max_substep = -1 s is invalid: must be > 0" in shown.out + shown.err

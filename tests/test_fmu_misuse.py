"""Misuse of the FMU interface, for every block of every robot: each call in the wrong state, each
foreign or corrupt FMU state, each input that would make an output non-finite is refused with a
status that is not OK and a logged message naming the call or the variable; nothing is half-applied.
"""
from __future__ import annotations

import ctypes
import json
import math
import re

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException

from robofmu.components.fmi.contract import NOT_UTF8
from robofmu.components.robots import available, load_model
from robofmu.system.fmu import FMUInstance, FMUError

from fmu_util import ERROR, OK, open_block, robot_blocks

ALL = robot_blocks()
H = 1e-3


def status_of(exc: Exception) -> str:
    """The FMI status word an fmpy call failed with ("discard", "error", "fatal")."""
    found = re.search(r"status \d \((\w+)\)", str(exc))
    assert found, str(exc)
    return found.group(1)


def refused(block: FMUInstance, call: str, fn, *args) -> tuple[str, str]:
    """Call ``fn(*args)``, expect a refusal; its status and the messages logged meanwhile."""
    since = len(block.messages)
    with pytest.raises((FMUError, FMICallException)) as info:
        block._call(call, fn, *args)
    logged = " | ".join(m.message for m in block.messages[since:] if m.status in ("ERROR", "FATAL", "WARNING"))
    return status_of(info.value), logged


def outputs(block: FMUInstance) -> list:
    names = [v.name for v in block.md.modelVariables if v.causality == "output" and v.type == "Real"]
    return block.get_real([block.variables[n].valueReference for n in names])


# -- calls in the wrong state ----------------------------------------------------------------------
@pytest.mark.parametrize("robot, kind", ALL)
def test_do_step_before_initialization_is_refused(fmu_root, robot, kind):
    b = FMUInstance(fmu_root / robot / f"{kind}.fmu", kind)
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
    ({"durations": "1e-300 3 1 1 2 1 1"}, "initialization failed: durations: move 1 takes 1e-300 s, too short for "
     "waypoints rows 1 to 2 (coordinate 3 changes by 0.15): its acceleration would be inf (not finite)"),
    ({"waypoints": "1e308 0 0; -1e308 0 0; 0 0 0; 0 0 0; 0 0 0; 0 0 0; 0 0 0; 0 0 0"},
     "initialization failed: waypoints: rows 1 and 2 are too far apart: coordinate 1 goes from 1e+308 to -1e+308"),
], ids=["open-before-close", "open-without-close", "tiny-duration", "huge-waypoints"])
def test_trajectory_refuses_inconsistent_or_non_finite_references(fmu_root, parameters, message):
    b = FMUInstance(fmu_root / "chess" / "trajectory.fmu", "trajectory")
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
    FMUInstance has registered its logger with fmpy's process-wide logger proxy."""
    from fmpy import simulate_fmu

    if block_first:
        open_block(fmu_root / robot, "plant").close()
        capfd.readouterr()
    with pytest.raises(Exception, match=r"fmi2ExitInitializationMode failed with status 3 \(error\)"):
        simulate_fmu(str(fmu_root / robot / "plant.fmu"), stop_time=0.01, step_size=H,
                     start_values={"max_substep": -1.0})
    shown = capfd.readouterr()
    assert "initialization failed: parameter max_substep = -1 s is invalid: must be > 0" in shown.out + shown.err


# -- trajectory parameters whose profile overflows: refused naming them, for every variant --------
def _initialize_raw(instance, parameters: dict) -> int:
    """fmi2SetupExperiment .. fmi2ExitInitializationMode with ``parameters`` (Real or String) set;
    the exit's status."""
    assert instance.call("fmi2SetupExperiment", 0, 0.0, 0.0, 0, 0.0) == OK
    assert instance.call("fmi2EnterInitializationMode") == OK
    for name, value in parameters.items():
        if isinstance(value, str):
            status = instance.call("fmi2SetString", instance.refs([name]), 1,
                                   (ctypes.c_char_p * 1)(value.encode()))
        else:
            status = instance.set_real([name], [value])
        assert status == OK, instance.messages
    return instance.call("fmi2ExitInitializationMode")


@pytest.mark.parametrize("robot, parameters, messages", [
    ("chess", {"durations": "1e-300 3 1 1 2 1 1"},
     ["durations: move 1 takes 1e-300 s, too short for waypoints rows 1 to 2 (coordinate 3 changes by 0.15): its "
      "acceleration would be inf (not finite); give move 1 more time (durations) or bring the waypoints closer"]),
    ("chess", {"waypoints": "1e308 0 0; -1e308 0 0; 0 0 0; 0 0 0; 0 0 0; 0 0 0; 0 0 0; 0 0 0"},
     ["waypoints: rows 1 and 2 are too far apart: coordinate 1 goes from 1e+308 to -1e+308, a change of -inf"]),
    ("rrp", {"length": 1e300, "v_max": 1e300, "a_max": 1e-300},
     ["length = 1e+300 m, v_max = 1e+300 m/s, a_max = 1e-300 m/s2: the line would take inf s"]),
    ("rrp", {"start[3]": -1.7e308, "length": 1e308, "v_max": 1e300, "a_max": 1e300},
     ["start[3] = -1.7e+308 and length = 1e+308 m: the end point's coordinate 3 would be -inf"]),
    ("rpp", {"q_end[1]": 1e10, "a_max[1]": 1e-300},
     ["a_max[1] = 1e-300 is too small for joint 1's move of 1e+10 (q_start[1] to q_end[1]): it would take inf s"]),
    ("rpp", {"q_start[1]": -1e308, "q_end[1]": 1e308},
     ["q_start[1] = -1e+308 and q_end[1] = 1e+308 are too far apart: joint 1's move would be inf"]),
    ("3rrp", {"duration": 1e-300},
     ["duration = 1e-300 s is too short: once round the circle in it, the phase's acceleration would be inf rad/s2"]),
    ("3rrp", {"radius": 1e308},
     ["radius = 1e+308 m and duration = 4 s: the reference's peak speed would be inf (not finite)"]),
], ids=["waypoints-tiny-duration", "waypoints-huge-positions", "line-tiny-a_max", "line-huge-start",
        "bangbang-tiny-a_max", "bangbang-huge-positions", "circle-tiny-duration", "circle-huge-radius"])
def test_overflowing_trajectory_is_refused_naming_the_parameter(fmu_root, raw_instances, robot, parameters, messages):
    """Debug logging off: the exit fails with fmi2Error and the one message names the parameters and why;
    the outputs stay finite."""
    b = raw_instances(fmu_root / robot / "trajectory.fmu", "trajectory")
    assert _initialize_raw(b, parameters) == ERROR
    (text,) = b.texts("ERROR")
    assert text.startswith("trajectory: initialization failed: ")
    for message in messages:
        assert message in text
    status, values = b.get_real(b.names("Real", "output"))
    assert status == OK and np.all(np.isfinite(values))


# -- fmi2SetupExperiment: every refusal logs its reason, naming the argument -----------------------
@pytest.mark.parametrize("arguments, message", [
    ((0, 0.0, math.nan, 0, 0.0), "fmi2SetupExperiment: startTime = nan s is invalid: must be finite; nothing set"),
    ((0, 0.0, -math.inf, 0, 0.0), "fmi2SetupExperiment: startTime = -inf s is invalid: must be finite; nothing set"),
    ((0, 0.0, 1.0, 1, 0.5), "fmi2SetupExperiment: stopTime = 0.5 s is before startTime = 1.0 s; nothing set"),
    ((0, 0.0, 0.0, 1, math.nan), "fmi2SetupExperiment: stopTime = nan s is invalid: must be finite (or not defined: "
                                 "stopTimeDefined = fmi2False); nothing set"),
    ((0, 0.0, 0.0, 1, math.inf), "fmi2SetupExperiment: stopTime = inf s is invalid: must be finite"),
    ((1, -1e-6, 0.0, 0, 0.0), "fmi2SetupExperiment: tolerance = -1e-06 is invalid: must be finite and >= 0 (or not "
                              "defined: toleranceDefined = fmi2False); nothing set"),
    ((1, math.nan, 0.0, 0, 0.0), "fmi2SetupExperiment: tolerance = nan is invalid: must be finite and >= 0"),
    ((1, -1.0, math.nan, 1, -5.0), "fmi2SetupExperiment: startTime = nan s is invalid: must be finite; tolerance = "
                                   "-1.0 is invalid: must be finite and >= 0 (or not defined: toleranceDefined = "
                                   "fmi2False); nothing set"),
], ids=["start-nan", "start-minus-inf", "stop-before-start", "stop-nan", "stop-inf", "tolerance-negative",
        "tolerance-nan", "several"])
@pytest.mark.parametrize("logging_on", [False, True], ids=["logging-off", "logging-on"])
@pytest.mark.parametrize("robot, kind", [("rrp", "plant"), ("chess", "trajectory")])
def test_bad_setup_experiment_is_refused_naming_the_argument(fmu_root, raw_instances, robot, kind, arguments,
                                                             message, logging_on):
    b = raw_instances(fmu_root / robot / f"{kind}.fmu", kind, logging_on=logging_on)
    toleranceDefined, tolerance, start, stopDefined, stop = arguments
    status = b.call("fmi2SetupExperiment", toleranceDefined, ctypes.c_double(tolerance), ctypes.c_double(start),
                    stopDefined, ctypes.c_double(stop))
    assert status == ERROR
    (text,) = b.texts("ERROR", "FATAL")
    assert text.startswith(f"{kind}: {message}")
    assert b.call("fmi2SetupExperiment", 0, 0.0, 0.0, 1, 1.0) == OK      # nothing was set; it goes on
    assert b.call("fmi2EnterInitializationMode") == OK and b.call("fmi2ExitInitializationMode") == OK
    assert b.step(0.0) == OK and b.real_status(2) == (OK, H)      # fmi2LastSuccessfulTime: from t = 0


@pytest.mark.parametrize("arguments", [(0, -1.0, 2.0, 0, math.nan), (1, 0.0, 2.0, 1, 2.0), (1, 1e-6, -1.0, 1, 3.0)],
                         ids=["undefined-ignored", "stop-at-start-tolerance-zero", "negative-start"])
def test_valid_setup_experiment_is_accepted_silently(fmu_root, raw_instances, arguments):
    b = raw_instances(fmu_root / "rrp" / "plant.fmu", "plant")
    toleranceDefined, tolerance, start, stopDefined, stop = arguments
    assert b.call("fmi2SetupExperiment", toleranceDefined, ctypes.c_double(tolerance), ctypes.c_double(start),
                  stopDefined, ctypes.c_double(stop)) == OK
    assert b.messages == []
    assert b.call("fmi2EnterInitializationMode") == OK and b.call("fmi2ExitInitializationMode") == OK
    assert b.step(start) == OK and b.real_status(2) == (OK, start + H)


@pytest.mark.parametrize("terminated", [False, True], ids=["initialized", "terminated"])
def test_setup_experiment_after_initialization_is_refused(fmu_root, raw_instances, terminated):
    b = raw_instances(fmu_root / "rrp" / "plant.fmu", "plant")
    assert b.initialize() == OK
    if terminated:
        assert b.call("fmi2Terminate") == OK
    assert b.call("fmi2SetupExperiment", 0, 0.0, ctypes.c_double(5.0), 0, 0.0) == ERROR
    assert b.texts("ERROR") == [f"plant: fmi2SetupExperiment: the instance is already "
                                f"{'terminated' if terminated else 'initialized'}"]


# -- fmi2SetString of a value that is not valid UTF-8 ----------------------------------------------
STRING_PARAMETERS = [pytest.param("chess", "trajectory", "waypoints", "durations", id="chess-trajectory"),
                     pytest.param("chess", "ik", "elbow", None, id="chess-ik"),
                     pytest.param("planar2r", "ik", "step_control", None, id="planar2r-ik")]


def get_string(instance, name: str) -> str:
    out = (ctypes.c_char_p * 1)()
    assert instance.call("fmi2GetString", instance.refs([name]), 1, out) == OK
    return out[0].decode()


@pytest.mark.parametrize("robot, kind, name, other", STRING_PARAMETERS)
@pytest.mark.parametrize("value, problem", [
    (NOT_UTF8 + "fffe", "the value b'\\xff\\xfe' (2 bytes) is not valid UTF-8: invalid start byte at byte 0 (ff)"),
    (NOT_UTF8 + "75703a20c328", "the value b'up: \\xc3(' (6 bytes) is not valid UTF-8: invalid continuation byte "
                                "at byte 4 (c3)"),
    (None, "no value (a NULL string)"),
], ids=["ff-fe", "truncated-sequence", "null"])
def test_string_parameter_that_is_no_text_is_refused_naming_it(fmu_root, raw_instances, robot, kind, name, other,
                                                               value, problem):
    """What robofmu's export library forwards for bytes that are not UTF-8 (NOT_UTF8 + their hex;
    see the next test), and a NULL string: fmi2Error naming the parameter, debug logging off,
    nothing set (not even the valid value set in the same call), the instance usable."""
    b = raw_instances(fmu_root / robot / f"{kind}.fmu", kind)
    assert b.call("fmi2SetupExperiment", 0, 0.0, 0.0, 0, 0.0) == OK
    assert b.call("fmi2EnterInitializationMode") == OK
    before = {n: get_string(b, n) for n in (name, other) if n}
    names = [other, name] if other else [name]
    values = ([b"1 1 1 1 1 1 1"] if other else []) + [None if value is None else value.encode()]
    status = b.call("fmi2SetString", b.refs(names), len(names), (ctypes.c_char_p * len(names))(*values))
    assert status == ERROR
    assert b.texts("ERROR", "FATAL") == [f"{kind}: fmi2SetString: parameter {name}: {problem}; nothing set"]
    assert {n: get_string(b, n) for n in before} == before
    assert b.call("fmi2ExitInitializationMode") == OK
    assert b.step(0.0) == OK


_RAW_BYTES_SCRIPT = """
import ctypes, json, sys
sys.path.insert(0, sys.argv[1])
from pathlib import Path
from fmu_util import RawInstance
b = RawInstance(Path(sys.argv[2]), sys.argv[3])
calls = [b.call("fmi2SetupExperiment", 0, 0.0, 0.0, 0, 0.0), b.call("fmi2EnterInitializationMode"),
         b.call("fmi2SetString", b.refs([sys.argv[4]]), 1, (ctypes.c_char_p * 1)(b"\\xff\\xfe")),
         b.call("fmi2ExitInitializationMode")]
print(json.dumps({"statuses": calls, "messages": b.messages}), flush=True)
b.close()
"""


@pytest.mark.parametrize("robot, kind, name, other", STRING_PARAMETERS)
def test_raw_bytes_that_are_not_utf8_are_refused_naming_the_parameter(fmu_root, tmp_path, robot, kind, name, other):
    """b'\\xff\\xfe' through fmi2SetString: fmi2Error naming the parameter, then a normal
    initialization (in a child process: today's answer damages the instance)."""
    import subprocess
    import sys
    from pathlib import Path

    done = subprocess.run([sys.executable, "-c", _RAW_BYTES_SCRIPT, str(Path(__file__).parent),
                           str(fmu_root / robot / f"{kind}.fmu"), kind, name], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    answer = json.loads(done.stdout.splitlines()[-1])
    assert answer["statuses"] == [OK, OK, ERROR, OK]
    assert [m[2] for m in answer["messages"]] == [
        f"{kind}: fmi2SetString: parameter {name}: the value b'\\xff\\xfe' (2 bytes) is not valid UTF-8: "
        "invalid start byte at byte 0 (ff); nothing set"]

"""Bad input: clear errors naming the parameter or variable, FMI error statuses, nothing lost."""
import zipfile

import numpy as np
import pytest

from robofmu.system.fmu import FMUInstance, FMUError

from fmu_util import open_block


def _failed_init(fmu_dir, block, parameters):
    b = FMUInstance(fmu_dir / f"{block}.fmu", block)
    with pytest.raises(FMUError) as info:
        b.initialize(0.0, parameters)
    b.close()
    return str(info.value), b.messages


@pytest.mark.parametrize("block, parameters, names", [
    ("plant", {"payload_mass": -0.03}, "parameter payload_mass = -0.03 kg is invalid: must be >= 0"),
    ("plant", {"g": float("nan")}, "parameter g = nan"),
    ("plant", {"max_substep": 0.0}, "parameter max_substep = 0 s is invalid: must be > 0"),
    ("plant", {"q0[2]": float("inf")}, "parameter q0[2] = inf is invalid"),
    ("controller", {"kp": -400.0}, "parameter kp = -400 1/s2 is invalid: must be > 0"),
    ("controller", {"kd": float("nan")}, "parameter kd = nan"),
    ("controller", {"ki": -1.0}, "parameter ki = -1"),
    ("trajectory", {"waypoints": "0.21 0 0; 0.21 0 zero"}, "waypoints: malformed number"),
    ("trajectory", {"waypoints": "0.21 0 0; 0.21 0"}, "waypoints: rows must all have the same number"),
    ("trajectory", {"durations": "1 3 0 1 2 1 1"}, "durations: every move must take a positive"),
    ("trajectory", {"durations": "1 3 1 -1 2 1 1"}, "durations: every move must take a positive"),
    ("trajectory", {"durations": "1 3 1"}, "durations: need one duration per move (7), got 3"),
    ("trajectory", {"cruise_factor": 3.0}, "parameter cruise_factor = 3 is invalid: must be > 1 and <= 2"),
    ("trajectory", {"cruise_factor": 1.0}, "parameter cruise_factor = 1 is invalid: must be > 1 and <= 2"),
    ("trajectory", {"pause": -0.5}, "parameter pause = -0.5 s is invalid: must be >= 0"),
    ("trajectory", {"grip_close_after_move": 9}, "grip_close_after_move: must be 0 (never) or a move number 1..7"),
    ("ik", {"elbow": "sideways"}, "parameter elbow = 'sideways' is invalid: must be one of 'up', 'down'"),
])
def test_invalid_parameter_fails_initialization_naming_it(fmu_dir, block, parameters, names):
    text, messages = _failed_init(fmu_dir, block, parameters)
    assert "fmi2ExitInitializationMode failed" in text
    assert "(error)" in text                     # robofmu's export library returns fmi2Error
    assert names in text
    assert any(names in m.message and m.status in ("ERROR", "FATAL") for m in messages)


@pytest.mark.parametrize("block, variable", [
    ("controller", "q[2]"), ("controller", "qdd_ref[4]"), ("ik", "x_ref[1]"), ("ik", "xd_ref[3]"),
    ("plant", "tau[3]"),
])
@pytest.mark.parametrize("value", [float("nan"), float("inf")])
def test_nonfinite_input_fails_the_step_naming_the_variable(fmu_dir, block, variable, value):
    b = open_block(fmu_dir, block)
    b.do_step(0.0, 0.01)
    outputs = {"controller": "tau", "ik": "q_ref", "plant": "q"}[block]
    before = b.get(outputs)
    b.set(variable, value)
    held = b.get(outputs)                    # no NaN leaves the block
    assert np.all(np.isfinite(held)) and held == before
    with pytest.raises(FMUError) as info:
        b.do_step(0.01, 0.01)
    text = str(info.value)
    assert f"input {variable} = {value} at t = 0.01 s is not finite; step refused" in text
    assert "(error)" in text                     # a refused step is fmi2Error, not fmi2Discard
    assert any(m.status == "ERROR" and variable in m.message for m in b.messages)
    b.close()


def test_unreachable_target_warns_holds_and_recovers(fmu_dir):
    ik = open_block(fmu_dir, "ik")
    ik.set("x_ref", [0.25, 0.1, 0.12])
    ik.set("xd_ref", [0.01, 0.0, 0.0])
    good = ik.get("q_ref")
    assert ik.get("reachable") is True
    ik.do_step(0.0, 0.01)
    ik.set("x_ref", [0.9, 0.1, 0.12])            # beyond a2 + a3 from the shoulder
    assert ik.get("reachable") is False
    assert ik.get("q_ref") == good               # last valid solution held
    assert ik.get("qd_ref") == [0.0] * 4 and ik.get("qdd_ref") == [0.0] * 4
    ik.do_step(0.01, 0.01)                       # a warning, not a failure
    warnings = [m for m in ik.messages if m.status == "WARNING"]
    assert len(warnings) == 1 and "out of reach" in warnings[0].message
    assert "holding the last valid solution" in warnings[0].message
    ik.set("x_ref", [0.26, 0.1, 0.12])
    assert ik.get("reachable") is True and ik.get("q_ref") != good
    ik.close()


def test_diverging_plant_fails_with_time_and_joint(fmu_dir):
    plant = open_block(fmu_dir, "plant")
    for k in range(3):
        plant.do_step(k * 1e-3, 1e-3)
    q_before = plant.get("q")
    plant.set("tau", [0.0, 1e200, 0.0, 0.0])
    with pytest.raises(FMUError) as info:
        plant.do_step(0.003, 1e-3)
    text = str(info.value)
    assert "input tau[2] = 1e+200 N.m is too large" in text          # the input that drove it
    assert "became non-finite during the step from t = 0.003 s to 0.004 s (joint" in text
    assert plant.get("q") == q_before            # the state before the failing step is kept
    plant.close()


def test_exception_inside_a_step_is_logged_with_its_text():
    """Any Python exception in a step reaches the importer as a logged error with its text, in one
    line; its traceback follows as a debug message (fmi2OK: shown only with debug logging on)."""
    from pythonfmu.enums import Fmi2Status

    from robofmu.components.fmi.base import BlockSlave

    class Slave(BlockSlave):
        robot_name = "chess"
        block_kind = "controller"

    s = Slave(instance_name="c")
    s.exit_initialization_mode()

    def broken(*_):
        raise ZeroDivisionError("the integrator met a zero")

    s.logic.law.advance = broken
    assert s.do_step(0.0, 0.01) is False
    msg, trace = s.log_queue
    assert msg.status == Fmi2Status.error and "\n" not in msg.msg and "Traceback" not in msg.msg
    assert msg.msg == "c: step from t = 0 s failed: ZeroDivisionError: the integrator met a zero"
    assert trace.status == Fmi2Status.ok and "Traceback (most recent call last)" in trace.msg
    assert trace.msg.rstrip().endswith("ZeroDivisionError: the integrator met a zero")


def test_bundled_code_mismatch_fails_loudly(fmu_dir, tmp_path):
    """A FMU built from other robofmu sources than the loaded ones refuses to instantiate."""
    src, dst = fmu_dir / "controller.fmu", tmp_path / "controller.fmu"
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename.endswith("robofmu/components/control.py"):
                data += b"\n# edited after the build\n"
            zout.writestr(item, data)
    with pytest.raises(FMUError) as info:
        FMUInstance(dst, "controller")
    text = str(info.value)
    assert "fmi2Instantiate failed" in text
    assert "rebuild the FMUs with the same robofmu" in text


def test_missing_fmu_is_named(tmp_path):
    with pytest.raises(FileNotFoundError, match="plant: FMU .*nope.fmu does not exist"):
        FMUInstance(tmp_path / "nope.fmu", "plant")


def test_target_unreachable_from_the_start_warns_once(fmu_dir):
    ik = open_block(fmu_dir, "ik", parameters={"x_ref": [0.9, 0.0, 0.1]})
    for k in range(5):
        assert ik.get("reachable") is False and ik.get("q_ref") == [0.0] * 4
        ik.do_step(k * 0.01, 0.01)
    warnings = [m.message for m in ik.messages if m.status == "WARNING"]
    assert len(warnings) == 1 and "no valid solution yet: outputs zero" in warnings[0]
    ik.close()


@pytest.mark.parametrize("block, name, value", [("controller", "kp", 1e6), ("plant", "q0[1]", 0.5),
                                                 ("ik", "elbow", "down")])
def test_parameters_are_fixed_once_initialized(fmu_dir, block, name, value):
    b = open_block(fmu_dir, block)
    with pytest.raises(FMUError) as info:
        b.set(name, value)
    assert "parameters are fixed once initialized" in str(info.value) and name in str(info.value)
    b.close()

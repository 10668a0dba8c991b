"""Misuse of the blocks (issue 29, class 3): each refusal names its port or parameter in one
logged line, with debug logging on and off, and never carries a Python traceback.

Every case goes through the FMU (fmpy's FMU2Slave, the raw FMI functions, a logger of the test's
own: :class:`fmu_util.RawInstance`), with debug logging (``loggingOn``) off and on, and, where the
fast path and pythonfmu's calls take different ways, with robofmu's fast path on and off:

- a non-unit or zero quaternion on the IK's ``quat_ref``: the step is fmi2Error, its one error line
  names ``quat_ref`` and the norm (numpy's), outputs held; at most one warning before it;
- a huge effort on one joint of the plant: the step is fmi2Error and its line names that input
  (``tau[j]``), the state kept;
- a huge ``xd_ref[i]``: the IK's warning says "velocity limit" and names ``xd_ref[i]``, not a
  singularity; the joint rate it reports is the rate A^-1 xd of a finite-difference Jacobian;
- fmi2SetupExperiment with a NaN start, stop or tolerance: fmi2Error with a line naming it;
- Integer parameters beyond 32 bits: refused naming them by ``robofmu run --set``, the master's
  FMU interface and a robot TOML; a host that wraps them itself (fmpy's ctypes) cannot be helped;
- an unexpected exception: one line, its traceback only as a debug message.
"""
from __future__ import annotations

import ctypes
import math

import numpy as np
import pytest

from robofmu.components.robots import available, load_description, load_model
from robofmu.system.fmu import FMUInstance

from fmu_util import ERROR, OK
from misuse import assert_refused

LOGGING = [pytest.param(False, id="debug-off"), pytest.param(True, id="debug-on")]
FAST = [pytest.param(True, id="fast"), pytest.param(False, id="slow")]
IK_ROBOTS = [r for r in available() if "ik" in load_description(r).blocks]
POSE_ROBOTS = [r for r in IK_ROBOTS if load_description(r).task.is_pose]
PLANTS = [pytest.param(robot, j, id=f"{robot}-tau{j}") for robot in available()
          if "plant" in load_description(robot).blocks for j in range(1, load_model(robot).n + 1)]


def messages_since(r, since: int) -> list[tuple[str, str | None, str]]:
    return r.messages[since:]


def assert_one_line(messages, status: str, *names: str) -> str:
    """Exactly one message of ``status`` among ``messages``: one line, naming every one of
    ``names``; no message of the lot holds a traceback. Returns that line."""
    shown = "\n".join(f"{s} {c}: {m}" for s, c, m in messages)
    assert not any("Traceback" in m for _, _, m in messages), shown
    lines = [m for s, _, m in messages if s == status]
    assert len(lines) == 1, shown
    line = lines[0]
    assert "\n" not in line.strip(), shown
    for name in names:
        assert name in line, f"{name!r} is not named:\n{shown}"
    return line


# -- quat_ref ---------------------------------------------------------------------------------------
QUATERNIONS = [pytest.param([0.5, 0.5, 0.5, 0.9], id="norm-1.25"), pytest.param([0.0, 0.0, 0.0, 0.0], id="zero"),
               pytest.param([0.0, 0.0, 0.7, 0.7], id="norm-0.99")]


@pytest.mark.parametrize("quaternion", QUATERNIONS)
@pytest.mark.parametrize("fast", FAST)
@pytest.mark.parametrize("logging_on", LOGGING)
@pytest.mark.parametrize("robot", POSE_ROBOTS)
def test_a_quaternion_that_is_not_unit_is_refused_naming_quat_ref(fmu_root, raw_instances, robot, logging_on,
                                                                  fast, quaternion):
    r = raw_instances(fmu_root / robot / "ik.fmu", "ik", fast=fast, logging_on=logging_on)
    assert r.initialize() == OK
    outputs = r.names("Real", "output")
    assert r.step(0.0) == OK
    status, before = r.get_real(outputs)
    assert status == OK
    since = len(r.messages)
    names = [f"quat_ref[{i}]" for i in range(1, 5)]
    assert r.set_real(names, quaternion) == OK
    status, held = r.get_real(outputs)
    assert status == OK and np.array_equal(held, before)                 # held, nothing non-finite
    assert r.step(1e-3) == ERROR
    norm = float(np.linalg.norm(quaternion))
    logged = messages_since(r, since)
    line = assert_one_line(logged, "ERROR", "quat_ref", f"norm {norm:.9g}", "step refused")
    assert "orientation quaternion (x, y, z, w) =" not in line          # the port, not the solver's words
    warnings = [m for s, _, m in logged if s == "WARNING"]
    assert len(warnings) <= 1 and all("quat_ref" in w and "\n" not in w for w in warnings), logged
    unit = np.array(quaternion) / norm if norm > 0 else np.array([0.0, 0.0, 0.0, 1.0])
    assert r.set_real(names, unit.tolist()) == OK                           # the instance goes on
    assert r.step(1e-3) == OK


@pytest.mark.parametrize("logging_on", LOGGING)
@pytest.mark.parametrize("robot", POSE_ROBOTS)
def test_a_step_without_reading_the_outputs_logs_the_quaternion_once(fmu_root, raw_instances, robot, logging_on):
    """A host that steps without reading the IK's outputs in between: one line, the step's."""
    r = raw_instances(fmu_root / robot / "ik.fmu", "ik", logging_on=logging_on)
    assert r.initialize() == OK and r.step(0.0) == OK
    since = len(r.messages)
    assert r.set_real([f"quat_ref[{i}]" for i in range(1, 5)], [0.0, 0.0, 0.0, 2.0]) == OK
    assert r.step(1e-3) == ERROR
    logged = [m for m in messages_since(r, since) if m[0] != "OK"]
    assert len(logged) == 1, logged
    assert_one_line(logged, "ERROR", "input quat_ref = (0, 0, 0, 2) has norm 2, not 1")


# -- the plant ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("logging_on", LOGGING)
@pytest.mark.parametrize("robot, joint", PLANTS)
def test_a_huge_effort_is_named_as_the_input_that_made_the_state_non_finite(fmu_root, raw_instances, robot,
                                                                            joint, logging_on):
    r = raw_instances(fmu_root / robot / "plant.fmu", "plant", logging_on=logging_on)
    assert r.initialize() == OK
    state = r.names("Real", "output")
    assert r.step(0.0) == OK
    _, before = r.get_real(state)
    since = len(r.messages)
    assert r.set_real([f"tau[{joint}]"], [1e300]) == OK
    assert r.step(1e-3) == ERROR
    line = assert_one_line(messages_since(r, since), "ERROR", f"input tau[{joint}] = 1e+300")
    named = [f"tau[{j}]" for j in range(1, load_model(robot).n + 1) if f"tau[{j}] =" in line]
    assert named == [f"tau[{joint}]"], line                  # the one made huge, and no other
    assert "became non-finite during the step from t = 0.001 s to 0.002 s" in line
    _, after = r.get_real(state)
    assert np.array_equal(after, before)                     # the state before the failed step kept


# -- xd_ref ------------------------------------------------------------------------------------------
def finite_difference_jacobian(robot: str, q: np.ndarray, step: float = 1e-6) -> np.ndarray:
    """d fk / dq (m, n) by central differences of the position-task robot's fk."""
    model = load_model(robot)
    columns = []
    for k in range(model.n):
        dq = np.zeros(model.n)
        dq[k] = step
        columns.append((model.fk(q + dq) - model.fk(q - dq)) / (2 * step))
    return np.array(columns).T


def reachable_at_home(r) -> np.ndarray:
    """The IK's q_ref at its current target, checked reachable."""
    status, (flag,) = r.get_boolean(["reachable"])
    assert status == OK and flag == 1
    status, q = r.get_real([n for n in r.variables if n.startswith("q_ref[")])
    assert status == OK
    return q


@pytest.mark.parametrize("size", [pytest.param(1e6, id="1e6"), pytest.param(1e300, id="1e300")])
@pytest.mark.parametrize("logging_on", LOGGING)
@pytest.mark.parametrize("robot", IK_ROBOTS)
def test_a_huge_task_rate_is_named_not_blamed_on_a_singularity(fmu_root, raw_instances, robot, logging_on, size):
    r = raw_instances(fmu_root / robot / "ik.fmu", "ik", logging_on=logging_on)
    assert r.initialize() == OK
    m = len([n for n in r.variables if n.startswith("xd_ref[")])
    for i in range(1, m + 1):
        since = len(r.messages)
        zero = [f"xd_ref[{k}]" for k in range(1, m + 1)]
        assert r.set_real(zero, [0.0] * m) == OK
        reachable_at_home(r)
        assert r.set_real([f"xd_ref[{i}]"], [size]) == OK
        status, (flag,) = r.get_boolean(["reachable"])
        assert status == OK and flag == 0
        line = assert_one_line(messages_since(r, since), "WARNING", f"input xd_ref[{i}] = {size:.6g}")
        assert "singular" not in line and "well-conditioned" in line, line
        if size == 1e6:                                      # rates beyond the limits; 1e300: may overflow
            assert "velocity limit: joint rate qd_ref[" in line, line
        else:
            assert "velocity limit: joint rate qd_ref[" in line or "rates are not finite" in line, line


@pytest.mark.parametrize("robot", [r for r in IK_ROBOTS if not load_description(r).task.is_pose
                                   and load_model(r).m == load_model(r).n])
def test_the_velocity_limit_names_the_rate_a_finite_difference_jacobian_gives(fmu_root, raw_instances, robot):
    """The joint rate the message reports is J^-1 xd of a central-difference Jacobian, to 1e-5."""
    r = raw_instances(fmu_root / robot / "ik.fmu", "ik")
    assert r.initialize() == OK
    q = reachable_at_home(r)
    m = len([n for n in r.variables if n.startswith("xd_ref[")])
    xd = np.zeros(m)
    xd[0] = 1e3
    expected = np.linalg.solve(finite_difference_jacobian(robot, q), xd)
    since = len(r.messages)
    assert r.set_real(["xd_ref[1]"], [1e3]) == OK
    r.get_boolean(["reachable"])
    line = assert_one_line(messages_since(r, since), "WARNING", "velocity limit", "input xd_ref[1] = 1000")
    limits = np.array([r.variables[f"qd_limit[{j}]"].start for j in range(1, len(q) + 1)], dtype=float)
    j = int(np.argmax(np.abs(expected) / limits))
    reported = float(line.split(f"joint rate qd_ref[{j + 1}] = ")[1].split()[0])
    assert reported == pytest.approx(expected[j], rel=1e-5)
    driven = float(line.split("drives ")[1].split()[0])
    assert driven == pytest.approx(expected[j], rel=1e-5)        # xd_ref[1] alone drives all of it


# -- fmi2SetupExperiment -----------------------------------------------------------------------------
@pytest.mark.parametrize("arguments, name", [
    ((0, 0.0, math.nan, 0, 0.0), "startTime = nan s"),
    ((0, 0.0, 0.0, 1, math.nan), "stopTime = nan s"),
    ((1, math.nan, 0.0, 0, 0.0), "tolerance = nan"),
    ((0, 0.0, math.inf, 0, 0.0), "startTime = inf s"),
], ids=["start-nan", "stop-nan", "tolerance-nan", "start-inf"])
@pytest.mark.parametrize("logging_on", LOGGING)
def test_a_bad_setup_experiment_logs_its_reason(fmu_root, raw_instances, arguments, name, logging_on):
    r = raw_instances(fmu_root / "chess" / "plant.fmu", "plant", logging_on=logging_on)
    assert r.call("fmi2SetupExperiment", *arguments) == ERROR
    assert_one_line(r.messages, "ERROR", "fmi2SetupExperiment", name, "nothing set")
    assert r.initialize() == OK                                   # nothing was set: it goes on


# -- Integer parameters beyond 32 bits --------------------------------------------------------------
def test_run_set_refuses_an_integer_beyond_32_bits(fmu_root, tmp_path, capfd):
    out = tmp_path / "out"
    assert_refused(capfd, ["run", "ur5-pose", "--fmus", fmu_root, "--out", out, "--stop-time", "0.01",
                           "--set", f"ik.max_iterations={2**32 + 3}"],
                   "ik.max_iterations", "4294967299", "32-bit", folders=[tmp_path])
    assert not out.exists()


@pytest.mark.parametrize("value", [2**32 + 3, -2**31 - 1, 2**63])
def test_the_fmu_interface_refuses_an_integer_beyond_32_bits(fmu_root, value):
    b = FMUInstance(fmu_root / "ur5" / "ik.fmu", "ik")
    try:
        with pytest.raises(ValueError, match=rf"ik\.max_iterations = {value} is out of range: an FMI Integer "
                                             r"is a 32-bit integer, -2147483648\.\.2147483647"):
            b.set("max_iterations", value)
        assert b.get("max_iterations") == 20                        # nothing was set
        b.set("max_iterations", 2**31 - 1)                          # the largest fits
        assert b.get("max_iterations") == 2**31 - 1
    finally:
        b.close()


def test_a_robot_toml_integer_beyond_32_bits_is_refused_naming_it(copy_robot, tmp_path, capfd):
    def edit(data):
        data["trajectory"]["grip_close_after_move"] = 2**32 + 3

    toml = copy_robot("chess", edit)
    assert_refused(capfd, ["build", toml, "--out", tmp_path / "fmus"], str(toml), "trajectory.grip_close_after_move",
                   "4294967299", "32-bit", untouched=[toml], folders=[tmp_path])


def test_a_host_that_wraps_an_integer_itself_cannot_be_helped(fmu_root, raw_instances):
    """What the FMU can not see: fmpy's ctypes arrays (and any C host's int32 cast) wrap 2**32 + 3
    to 3 before the call, so fmi2SetInteger receives a valid 3 (documented in
    robofmu.components.fmi.variables)."""
    r = raw_instances(fmu_root / "ur5" / "ik.fmu", "ik")
    assert r.call("fmi2SetupExperiment", 0, 0.0, 0.0, 0, 0.0) == OK
    assert r.call("fmi2EnterInitializationMode") == OK
    vr = r.refs(["max_iterations"])
    assert r.call("fmi2SetInteger", vr, 1, (ctypes.c_int * 1)(2**32 + 3)) == OK
    out = (ctypes.c_int * 1)()
    assert r.call("fmi2GetInteger", vr, 1, out) == OK and out[0] == 3


# -- an unexpected exception -------------------------------------------------------------------------
def test_an_unexpected_exception_is_one_line_its_traceback_a_debug_message():
    """Behind no export library (a slave made in this process): the error line, then the
    traceback as an fmi2OK message, which robofmu's library passes on only with debug logging."""
    from pythonfmu.enums import Fmi2Status

    from robofmu.components.fmi.base import BlockSlave

    class Slave(BlockSlave):
        robot_name = "chess"
        block_kind = "ik"

    s = Slave(instance_name="ik")
    s.exit_initialization_mode()

    def broken(t):
        raise RuntimeError("no such frame\nsecond line")

    s.logic.output = broken
    s.set_real([s.logic.index["x_ref[1]"]], [0.2])
    s.get_real([s.logic.index["q_ref[1]"]])
    assert s.do_step(0.0, 0.01) is False
    logged = [(m.status, m.msg) for m in s.log_queue]
    errors = [text for status, text in logged if status == Fmi2Status.error]
    assert errors[0] == "ik: t = 0 s: evaluating outputs failed: RuntimeError: no such frame; second line"
    assert all("\n" not in text and "Traceback" not in text for text in errors), logged
    traces = [text for status, text in logged if status == Fmi2Status.ok]
    assert len(traces) == 1 and "Traceback (most recent call last)" in traces[0], logged
    assert errors[-1].endswith("step refused") and len(errors) == 2, logged


@pytest.mark.parametrize("logging_on", LOGGING)
def test_a_refused_initialization_is_one_line(fmu_root, raw_instances, logging_on):
    r = raw_instances(fmu_root / "chess" / "controller.fmu", "controller", logging_on=logging_on)
    assert r.initialize({"kp": -400.0}) == ERROR
    assert_one_line(r.messages, "ERROR", "initialization failed: parameter kp = -400 1/s2 is invalid")


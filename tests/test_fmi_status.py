"""FMI statuses and logging as the FMI 2.0 standard means them: robofmu's export library
(``robofmu.system.packaging.fmi_export``) in front of pythonfmu 0.7.0's.

- a refused step is fmi2Error (pythonfmu alone: fmi2Discard, which fmpy's ``simulate_fmu``
  takes for a normal end), and ``simulate_fmu`` raises with the FMU's message logged;
- invalid input to any other call is fmi2Error, and the instance stays usable (pythonfmu alone:
  fmi2Fatal, the instance unusable);
- warnings and errors reach the importer's logger with loggingOn = false; OK messages only with
  loggingOn (and its categories);
- a Python exception that reaches pythonfmu is still its fmi2Fatal, its text now logged.

The statuses are checked on the raw FMI functions (fmpy's wrappers raise on any status above
fmi2Warning), through fmpy's FMU2Slave with a logger of the test's own. A small pythonfmu slave
of the test's own (``probe``) exercises the library independently of the robofmu blocks.
"""
from __future__ import annotations

import ctypes
import math
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException

from robofmu.components.fmi import contract
from robofmu.system.packaging import fmi_export

from fmu_util import DISCARD, ERROR, FATAL, H, LABEL, OK, RawInstance, keep_alive



@pytest.fixture
def importer(raw_instances):
    """Instances as an importer makes them (the fast path as the environment says)."""
    def open_(path, name="probe", logging_on=False):
        return raw_instances(path, name, logging_on=logging_on)
    return open_


@pytest.fixture(scope="session")
def plant(fmu_root) -> Path:
    return fmu_root / "chess" / "plant.fmu"


# -- the FMUs ----------------------------------------------------------------------------------------
def test_every_fmu_carries_robofmus_library_in_front_of_pythonfmus(fmu_root):
    import pythonfmu
    pythonfmus = (Path(pythonfmu.__file__).parent / "resources" / "binaries" / "linux64"
                  / fmi_export.STOCK_LIBRARY).read_bytes()
    ours = fmi_export.library().read_bytes()
    fmus = sorted(fmu_root.glob("*/*.fmu"))
    assert fmus
    for path in fmus:
        identifier = read_model_description(str(path), validate=False).coSimulation.modelIdentifier
        with zipfile.ZipFile(path) as z:
            assert z.read(f"binaries/linux64/{identifier}.so") == ours, path
            assert z.read(f"binaries/linux64/{fmi_export.STOCK_LIBRARY}") == pythonfmus, path
            # pythonfmu's win64 DLL would bypass robofmu's library: dropped (linux64 only)
            assert sorted(n for n in z.namelist() if n.startswith("binaries/")) == sorted(
                [f"binaries/linux64/{identifier}.so", f"binaries/linux64/{fmi_export.STOCK_LIBRARY}"]), path
        assert fmi_export.installed(path)


def test_library_matches_the_fmi2_headers(tmp_path):
    """Every definition in robofmu_fmi2.c agrees with the standard's prototypes (fmpy's copy)."""
    import fmpy
    headers = Path(fmpy.__file__).parent / "c-code"
    cc = fmi_export._compiler()
    done = subprocess.run(cc + ["-shared", "-fPIC", "-Wall", "-Werror", "-DROBOFMU_CHECK_WITH_FMI2_HEADERS",
                                f"-I{headers}", *fmi_export.compile_flags(tmp_path), "-o", str(tmp_path / "check.so"),
                                str(fmi_export.SOURCE)],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


def test_the_status_category_is_the_same_on_both_sides():
    """One definition (the contract): the slave, the export package and the C library's
    generated header all take it from there, and the C source has no copy of its own."""
    assert fmi_export.STATUS_CATEGORY is contract.STATUS_CATEGORY
    assert fmi_export.STOCK_LIBRARY is contract.STOCK_LIBRARY
    header = fmi_export.contract_header.header()
    assert f'#define STATUS_CATEGORY "{contract.STATUS_CATEGORY}"' in header.splitlines()
    assert f'#define STOCK_LIBRARY "{contract.STOCK_LIBRARY}"' in header.splitlines()
    fmi_export.check_source(fmi_export.SOURCE)


def test_a_failing_compiler_fails_the_build_loudly(tmp_path, monkeypatch):
    monkeypatch.setenv("ROBOFMU_CACHE", str(tmp_path))
    monkeypatch.setenv("CC", "false")
    with pytest.raises(fmi_export.FmiExportError, match="compiling the FMI export library failed"):
        fmi_export.library()
    monkeypatch.setenv("CC", str(tmp_path / "no-such-compiler"))
    with pytest.raises(fmi_export.FmiExportError, match="does not run"):
        fmi_export.library()


def test_without_pythonfmus_library_instantiation_fails_naming_it(plant, tmp_path):
    broken = tmp_path / "plant.fmu"
    with zipfile.ZipFile(plant) as zin, zipfile.ZipFile(broken, "w") as zout:
        for item in zin.infolist():
            if not item.filename.endswith(fmi_export.STOCK_LIBRARY):
                zout.writestr(item, zin.read(item.filename))
    i = RawInstance(broken, "plant")
    try:
        assert not i.component
        assert any(s == "ERROR" and m.startswith("fmi2Instantiate: cannot instantiate, pythonfmu's export library: cannot load")
                   and fmi_export.STOCK_LIBRARY in m
                   for s, _, m in i.messages), i.messages
    finally:
        i.close()


# -- the robofmu blocks -----------------------------------------------------------------------------
@pytest.mark.parametrize("logging_on", [False, True], ids=["loggingOn-false", "loggingOn-true"])
def test_refused_step_message_reaches_the_logger(importer, plant, logging_on):
    p = importer(plant, "plant", logging_on)
    assert p.initialize() == OK
    assert p.step(0.0) == OK
    assert p.set_real(["tau[1]"], [math.nan]) == OK
    p.step(H)
    assert any(s == "ERROR" and c == "logStatusError" and "input tau[1] = nan at t = 0.001 s is not finite; "
               "step refused" in m for s, c, m in p.messages), p.messages
    assert all(c != fmi_export.STATUS_CATEGORY for _, c, _ in p.messages)      # never seen by the importer


@pytest.mark.parametrize("logging_on", [False, True], ids=["loggingOn-false", "loggingOn-true"])
def test_refused_step_is_an_error_not_a_discard(importer, plant, logging_on):
    p = importer(plant, "plant", logging_on)
    assert p.initialize() == OK
    assert p.step(0.0) == OK
    assert p.set_real(["tau[1]"], [math.nan]) == OK
    assert p.step(H) == ERROR


def test_simulate_fmu_raises_instead_of_truncating(plant):
    md = read_model_description(str(plant), validate=False)
    names = [v.name for v in md.modelVariables if v.causality == "input" and v.type == "Real"]
    rows = [tuple([t] + [math.nan if (n == "tau[1]" and t > 0.0025) else 0.0 for n in names])
            for t in (0.0, 0.0025, 0.0026, 1.0)]
    messages = []

    def logger(env, instance, status, category, message):
        messages.append((status, message.decode()))

    keep_alive(logger)
    with pytest.raises(FMICallException, match=r"fmi2DoStep failed with status 3 \(error\)"):
        simulate_fmu(str(plant), stop_time=0.01, step_size=H, debug_logging=False, logger=logger,
                     input=np.array(rows, dtype=[("time", float)] + [(n, float) for n in names]))
    assert any(status == ERROR and "input tau[1] = nan at t = 0.003 s is not finite" in m
               for status, m in messages), messages


def test_invalid_parameter_is_an_error_naming_it(importer, plant):
    p = importer(plant, "plant")
    assert p.initialize({"payload_mass": -1.0}) == ERROR
    assert any(s == "ERROR" and "parameter payload_mass = -1 kg is invalid: must be >= 0" in m
               for s, _, m in p.messages), p.messages
    assert not p.texts("FATAL")


def test_a_rejected_set_is_an_error_and_the_instance_goes_on(importer, plant):
    p = importer(plant, "plant")
    assert p.initialize() == OK
    assert p.set_real(["g"], [1.0]) == ERROR                         # a parameter, once initialized
    assert any("fmi2SetReal: value references of ['g'] do not name Real inputs" in m for m in p.texts("ERROR"))
    assert not p.texts("FATAL")
    assert p.step(0.0) == OK                                     # still usable
    status, (q,) = p.get_real(["q[1]"])
    assert status == OK and math.isfinite(q)
    assert p.call("fmi2Terminate") == OK


# -- the library itself, on a slave of the test's own -------------------------------------------------
_PROBE = '''
import ctypes

from pythonfmu import Fmi2Slave, Integer, Real
from pythonfmu.enums import Fmi2Causality, Fmi2Status, Fmi2Variability

_keepalive = globals()    # pythonfmu 0.7.0 releases one reference to these per instance


class RobofmuStatusProbe(Fmi2Slave):
    """do_step logs an OK and a warning message, then refuses the step (returns False) if
    ``request`` is not 0, with that status through robofmu's status category if it is > 0.
    Setting ``boom`` raises."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.request = 0
        self.boom = 0.0
        self.register_variable(Integer("request", causality=Fmi2Causality.input,
                                       variability=Fmi2Variability.discrete))
        self.register_variable(Real("boom", causality=Fmi2Causality.input, setter=self._explode))

    def _explode(self, value):
        # pythonfmu's exception handler releases these once too often (docs/design.md)
        for obj in (self, self.log_queue, type(self)):
            ctypes.pythonapi.Py_IncRef(ctypes.py_object(obj))
        raise ValueError(f"boom = {value}")

    def do_step(self, current_time, step_size):
        self.log("stepping 100% fine", Fmi2Status.ok)
        self.log("a warning", Fmi2Status.warning)
        if self.request > 0:
            self.log(f"refused with status {self.request}", Fmi2Status(self.request), "robofmu:status")
        return self.request == 0
'''


@pytest.fixture(scope="module")
def probe(tmp_path_factory) -> Path:
    from pythonfmu import FmuBuilder

    folder = tmp_path_factory.mktemp("probe")
    script = folder / "robofmu_status_probe.py"
    script.write_text(textwrap.dedent(_PROBE))
    try:
        path = FmuBuilder.build_FMU(script, dest=folder)
    finally:
        sys.modules.pop("robofmu_status_probe", None)
        while str(folder) in sys.path:
            sys.path.remove(str(folder))
    fmi_export.install(path)
    return path


def _requested(p: RawInstance, status: int) -> int:
    return p.call("fmi2SetInteger", p.refs(["request"]), 1, (ctypes.c_int * 1)(status))


@pytest.mark.parametrize("status", [DISCARD, ERROR, FATAL])
def test_the_slave_chooses_the_step_status(importer, probe, status):
    p = importer(probe)
    assert p.initialize() == OK
    assert p.step(0.0) == OK
    assert _requested(p, status) == OK
    assert p.step(H) == status
    assert (LABEL[status], ["logStatusDiscard", "logStatusError", "logStatusFatal"][status - DISCARD],
            f"refused with status {status}") in p.messages


def test_a_refusal_without_a_status_stays_a_discard(importer, probe):
    """do_step returning False with nothing logged under the status category: pythonfmu's
    fmi2Discard, as before (True/False keep their meaning)."""
    p = importer(probe)
    assert p.initialize() == OK
    assert p.step(0.0) == OK
    assert _requested(p, -1) == OK
    assert p.step(H) == DISCARD
    assert p.texts("ERROR", "FATAL") == []


def test_debug_messages_follow_logging_on_and_categories(importer, probe):
    p = importer(probe)                                          # loggingOn = false
    assert p.initialize() == OK
    assert p.step(0.0) == OK
    assert p.messages == [("WARNING", "logStatusWarning", "a warning")]
    p.messages.clear()

    def debug_logging(on, *categories):
        array = (ctypes.c_char_p * max(1, len(categories)))(*[c.encode() for c in categories])
        assert p.call("fmi2SetDebugLogging", int(on), len(categories), array) == OK

    debug_logging(True)
    assert p.step(H) == OK
    # the logger takes the message as a printf format: a '%' arrives doubled
    assert p.messages == [("OK", "logAll", "stepping 100%% fine"), ("WARNING", "logStatusWarning", "a warning")]
    p.messages.clear()
    debug_logging(True, "logStatusError")                        # OK messages are not of that category
    assert p.step(2 * H) == OK
    assert p.messages == [("WARNING", "logStatusWarning", "a warning")]
    p.messages.clear()
    debug_logging(True, "logAll")
    assert p.step(3 * H) == OK
    assert [s for s, _, _ in p.messages] == ["OK", "WARNING"]
    p.messages.clear()
    debug_logging(False)
    assert p.step(4 * H) == OK
    assert p.messages == [("WARNING", "logStatusWarning", "a warning")]


def test_a_percent_is_shown_as_one_through_fmpys_formatting_logger(probe, tmp_path):
    seen = []

    def logger(env, instance, status, category, message):
        seen.append(message.decode())

    keep_alive(logger)
    simulate_fmu(str(probe), stop_time=2 * H, step_size=H, debug_logging=True, logger=logger)
    assert "stepping 100% fine" in seen, seen


def test_pythonfmus_fatal_error_reaches_the_logger_with_the_exception(importer, probe):
    """A setter raising into pythonfmu (robofmu's slave never lets one): still pythonfmu's
    fmi2Fatal, and with loggingOn = false its text reaches the logger."""
    p = importer(probe)
    assert p.initialize() == OK
    assert p.set_real(["boom"], [1.0]) == FATAL
    assert any(s == "FATAL" and "Fatal py exception encountered: [setReal]" in m and "boom = 1.0" in m
               for s, _, m in p.messages), p.messages

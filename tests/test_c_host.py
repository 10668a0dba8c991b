"""Hosts that are not Python, and hosts that call the FMUs after Python is gone.

A plain C host (tests/c_host/host.c, compiled here with the machine's C compiler, as robofmu's
FMI library is) loads a FMU's binary with ``dlopen`` from an empty environment (``env={}``: no
libpython preloaded, no ``PATH``, no ``PYTHON*``): robofmu's library loads the libpython the FMU
records (resources/robofmu_python.txt) and starts it as the recorded program, so that the
interpreter finds the venv that built the FMU. Its results are the same, bit for bit, as fmpy's
in this process. The failure paths, each a segfault before robofmu's library guarded them:

- a deleted resource folder: fmi2Instantiate returns NULL and logs why (pythonfmu's constructor
  called a NULL class);
- calls after the interpreter was finalized (a host's exit handler or static destructor, as
  OMSimulator frees its FMUs): every call answers fmi2Error, free releases robofmu's part only
  (pythonfmu entered Python in PyGILState_Ensure); in the C host and in a Python host alike;
- a recorded runtime that is not there or of another Python version: fmi2Instantiate returns
  NULL, the message names the file or the versions and ``robofmu doctor``.
"""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

import elf
from robofmu.system.packaging import fmi_export

SOURCES = Path(__file__).resolve().parent / "c_host"
FMI_HEADERS = Path(__import__("fmpy").__file__).resolve().parent / "c-code"
STEPS = 100


@pytest.fixture(scope="module")
def programs(tmp_path_factory):
    """The compiled host and the late-free library: {"host": path, "late": path}."""
    out = tmp_path_factory.mktemp("c_host")
    cc = fmi_export._compiler()
    built = {"host": out / "host", "late": out / "late_free.so"}
    for command in (cc + ["-O1", "-Wall", "-Werror", f"-I{FMI_HEADERS}", "-o", str(built["host"]),
                          str(SOURCES / "host.c"), "-ldl", "-pthread"],
                    cc + ["-shared", "-fPIC", "-Wall", "-Werror", "-o", str(built["late"]), str(SOURCES / "late_free.c")]):
        done = subprocess.run(command, capture_output=True, text=True)
        assert done.returncode == 0, done.stderr
    return built


@pytest.fixture(scope="module")
def plant(fmu_root, tmp_path_factory):
    """The chess plant: (extracted folder, model identifier, value reference of q[2])."""
    path = fmu_root / "chess" / "plant.fmu"
    md = read_model_description(str(path), validate=False)
    folder = Path(extract(str(path), unzipdir=str(tmp_path_factory.mktemp("plant"))))
    vr = next(v.valueReference for v in md.modelVariables if v.name == "q[2]")
    return folder, md.coSimulation.modelIdentifier, vr


def host(programs, folder, identifier, scenario, *args, env=None):
    done = subprocess.run([str(programs["host"]), str(folder), identifier, scenario, *map(str, args)],
                          capture_output=True, text=True, env={} if env is None else env, timeout=300)
    return done.returncode, done.stdout.splitlines(), done.stderr


def fmpy_value(fmu_root, vr) -> float:
    """q[2] after STEPS steps of 1 ms, the plant run by fmpy in this process (the reference)."""
    path = fmu_root / "chess" / "plant.fmu"
    md = read_model_description(str(path), validate=False)
    folder = extract(str(path))
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=folder, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="reference")
    try:
        fmu.instantiate()
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        for k in range(STEPS):
            fmu.doStep(k * 1e-3, 1e-3)
        value = fmu.getReal([vr])[0]
        fmu.terminate()
    finally:
        fmu.freeInstance()
        shutil.rmtree(folder, ignore_errors=True)
    return value


def test_a_c_host_runs_the_fmu_from_an_empty_environment(programs, plant, fmu_root):
    folder, identifier, vr = plant
    expected = fmpy_value(fmu_root, vr)
    assert abs(expected) > 1e-4     # the arm moves under gravity: a value the run must have computed
    for scenario in ("run", "thread", "two"):
        status, lines, err = host(programs, folder, identifier, scenario, STEPS, vr)
        assert status == 0, (scenario, lines, err)
        values = [line.split(" = ")[1] for line in lines if line.startswith(f"value vr{vr} = ")]
        assert len(values) == (2 if scenario == "two" else 1), (scenario, lines)
        assert all(text.endswith(" (OK)") and float(text.split()[0]) == expected for text in values), (scenario, lines)
        assert not any(line.startswith("log ") for line in lines), lines      # nothing to report
        assert lines[-1] == "host: done"
    status, lines, _ = host(programs, folder, identifier, "run", STEPS, vr)
    assert "host: terminate OK, terminate OK" in lines        # a second fmi2Terminate is harmless


def test_calls_after_the_interpreter_is_finalized_answer_error(programs, plant):
    """The host frees the instance from an exit handler registered before it loaded the FMU: it
    runs after robofmu's library has finalized the embedded interpreter."""
    folder, identifier, vr = plant
    status, lines, err = host(programs, folder, identifier, "atexit-free", 10, vr)
    assert status == 0, (lines, err)
    assert lines[-1] == "host: after exit: terminate Error, terminate Error, get Error, step Error, freed"


def test_a_python_host_freeing_after_finalization_does_not_crash(programs, fmu_root, tmp_path):
    """As OMSimulator's Python API: the FMU is freed by a C exit handler, after Py_Finalize."""
    script = (
        "import ctypes, sys\n"
        "from fmpy import extract, read_model_description\n"
        "from fmpy.fmi2 import FMU2Slave\n"
        "path, late, folder = sys.argv[1:4]\n"
        "md = read_model_description(path, validate=False)\n"
        "fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(path, unzipdir=folder),\n"
        "                modelIdentifier=md.coSimulation.modelIdentifier, instanceName='late')\n"
        "fmu.instantiate(); fmu.setupExperiment(startTime=0.0)\n"
        "fmu.enterInitializationMode(); fmu.exitInitializationMode()\n"
        "for k in range(10):\n"
        "    fmu.doStep(k * 1e-3, 1e-3)\n"
        "address = lambda f: ctypes.cast(f, ctypes.c_void_p)\n"
        "assert ctypes.CDLL(late).free_at_exit(address(fmu.dll.fmi2Terminate), address(fmu.dll.fmi2FreeInstance),\n"
        "                                      ctypes.c_void_p(fmu.component)) == 0\n"
        "print('exiting', flush=True)\n")
    done = subprocess.run([sys.executable, "-c", script, str(fmu_root / "chess" / "plant.fmu"), str(programs["late"]),
                           str(tmp_path / "plant")], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.splitlines() == ["exiting", "late: terminate 3, freed"]     # 3: fmi2Error


def test_a_deleted_resource_folder_is_refused_with_a_message(programs, plant, tmp_path):
    folder, identifier, _ = plant
    copy = tmp_path / "copy"
    shutil.copytree(folder, copy)
    shutil.rmtree(copy / "resources")
    status, lines, err = host(programs, copy, identifier, "no-resources")
    assert status == 0, (lines, err)
    assert lines == [f"log Error logStatusError: fmi2Instantiate: cannot instantiate, the FMU's resource folder: "
                     f"{copy}/resources (from fmuResourceLocation \"file://{copy}/resources\") does not exist",
                     "host: fmi2Instantiate returned NULL"]
    # a folder that is there but is not this FMU's resources
    (copy / "resources").mkdir()
    status, lines, err = host(programs, copy, identifier, "no-resources")
    assert status == 0, (lines, err)
    assert lines[0].startswith(f"log Error logStatusError: fmi2Instantiate: cannot instantiate, the FMU's resource "
                               f"folder: {copy}/resources/slavemodule.txt cannot be read (No such file or directory)")


def test_a_missing_or_mismatched_runtime_names_what_is_missing(programs, plant, tmp_path):
    folder, identifier, vr = plant
    status, lines, _ = host(programs, folder, identifier, "run", 1, vr, env={"ROBOFMU_LIBPYTHON": "/nonexistent/libpython3.so"})
    assert status == 1
    assert lines[0].startswith("log Error logStatusError: fmi2Instantiate: cannot instantiate, the Python runtime: "
                               "cannot load the Python runtime /nonexistent/libpython3.so: ")
    assert "robofmu doctor --fmus FOLDER" in lines[0] and lines[-1] == "host: fmi2Instantiate returned NULL"

    copy = tmp_path / "copy"
    shutil.copytree(folder, copy)
    record = copy / "resources" / fmi_export.RUNTIME_RECORD
    record.write_text(record.read_text().replace(f"version={sys.version_info.major}.{sys.version_info.minor}\n",
                                                 "version=3.99\n"))
    status, lines, _ = host(programs, copy, identifier, "run", 1, vr)
    assert status == 1
    running = sys.version.split()[0]
    assert lines[0].startswith(f"log Error logStatusError: fmi2Instantiate: cannot instantiate, the Python runtime: "
                               f"this process runs Python {running}, the FMU was built for Python 3.99")


def test_the_fmu_records_this_python_and_carries_only_linux_binaries(fmu_root):
    import zipfile

    record = fmi_export.read_runtime(fmu_root / "chess" / "plant.fmu")
    assert record == fmi_export.runtime_record()
    assert record["program"] == sys.executable and Path(record["library"]).is_file()
    for path in fmu_root.glob("*/*.fmu"):
        with zipfile.ZipFile(path) as archive:
            binaries = sorted(n for n in archive.namelist() if n.startswith("binaries/"))
        identifier = path.parent.name
        assert [n.split("/")[1] for n in binaries] == ["linux64", "linux64"], (path, binaries)
        assert binaries[0] == f"binaries/linux64/{fmi_export.STOCK_LIBRARY}", binaries
        assert binaries[1].endswith(".so") and identifier in binaries[1]


#: The FMI 2.0 co-simulation functions a FMU's binary exports (the standard's fmi2Functions.h,
#: less the model-exchange ones).
FMI2_COSIMULATION = """fmi2GetTypesPlatform fmi2GetVersion fmi2SetDebugLogging fmi2Instantiate fmi2FreeInstance
    fmi2SetupExperiment fmi2EnterInitializationMode fmi2ExitInitializationMode fmi2Terminate fmi2Reset
    fmi2GetReal fmi2GetInteger fmi2GetBoolean fmi2GetString fmi2SetReal fmi2SetInteger fmi2SetBoolean
    fmi2SetString fmi2GetFMUstate fmi2SetFMUstate fmi2FreeFMUstate fmi2SerializedFMUstateSize
    fmi2SerializeFMUstate fmi2DeSerializeFMUstate fmi2GetDirectionalDerivative fmi2SetRealInputDerivatives
    fmi2GetRealOutputDerivatives fmi2DoStep fmi2CancelStep fmi2GetStatus fmi2GetRealStatus
    fmi2GetIntegerStatus fmi2GetBooleanStatus fmi2GetStringStatus""".split()


def test_every_platform_binary_exports_the_fmi_functions_and_robofmus_marker(fmu_root, tmp_path):
    import ctypes
    import zipfile

    paths = sorted(fmu_root.glob("*/*.fmu"))
    assert paths
    for path in paths:
        identifier = read_model_description(str(path), validate=False).coSimulation.modelIdentifier
        with zipfile.ZipFile(path) as archive:
            platforms = {n.split("/")[1] for n in archive.namelist() if n.startswith("binaries/")}
            assert platforms == {"linux64"}, (path, platforms)      # the only platform robofmu's library is built for
            exports = elf.exports(archive.read(f"binaries/linux64/{identifier}.so"))
        assert set(FMI2_COSIMULATION) <= exports, (path, set(FMI2_COSIMULATION) - exports)
        assert {"robofmu_fmi_library", "robofmu_fast_register"} <= exports, path
    # the marker answers, from a copy loaded on its own (pythonfmu's library is loaded later, by fmi2Instantiate)
    with zipfile.ZipFile(paths[0]) as archive:
        identifier = read_model_description(str(paths[0]), validate=False).coSimulation.modelIdentifier
        binary = tmp_path / "marker.so"
        binary.write_bytes(archive.read(f"binaries/linux64/{identifier}.so"))
    library = ctypes.CDLL(str(binary))
    library.robofmu_fmi_library.restype = ctypes.c_char_p
    assert library.robofmu_fmi_library().decode() == fmi_export.MARKER
    # pythonfmu's own library has no marker: the check tells the two apart
    import pythonfmu
    stock = (Path(pythonfmu.__file__).parent / "resources" / "binaries" / "linux64" / fmi_export.STOCK_LIBRARY).read_bytes()
    assert "robofmu_fmi_library" not in elf.exports(stock) and "fmi2DoStep" in elf.exports(stock)


def test_the_library_needs_no_glibc_newer_than_the_baseline(fmu_root, tmp_path):
    """Built by Zig (the dev extra) against glibc 2.17: FMUs built here load on older
    distributions (pythonfmu's own library, beside it, needs 2.32 at most)."""
    import os
    import zipfile

    if os.environ.get("CC"):
        pytest.skip(f"CC={os.environ['CC']} builds the library, not Zig")
    assert "ziglang" in fmi_export._compiler()
    baseline = tuple(map(int, fmi_export.GLIBC_BASELINE.split(".")))
    path = fmu_root / "chess" / "plant.fmu"
    identifier = read_model_description(str(path), validate=False).coSimulation.modelIdentifier
    with zipfile.ZipFile(path) as archive:
        needs = elf.version_needs(archive.read(f"binaries/linux64/{identifier}.so"))
    glibc = {v for versions in needs.values() for v in versions if v.startswith("GLIBC_")}
    assert glibc, needs                                         # the reader found them
    newest = max(tuple(map(int, v[len("GLIBC_"):].split("."))) for v in glibc)
    assert newest <= baseline, sorted(glibc)
    # negative control: the machine's compiler links dlopen and pthread at glibc 2.34 (Debian 12),
    # which the reader sees as newer than the baseline
    if shutil.which("cc"):
        built = tmp_path / "native.so"
        subprocess.run(["cc", "-shared", "-fPIC", *fmi_export.compile_flags(tmp_path), "-o", str(built),
                        str(fmi_export.SOURCE), "-ldl", "-pthread"],
                       check=True, capture_output=True)
        native = {v for vs in elf.version_needs(built.read_bytes()).values() for v in vs if v.startswith("GLIBC_")}
        assert max(tuple(map(int, v[len("GLIBC_"):].split("."))) for v in native) > baseline, sorted(native)

"""robofmu's FMI 2.0 export library, and putting it into the FMUs pythonfmu builds.

pythonfmu 0.7.0's export library (the C++ that turns FMI calls into calls of the Python slave)
decides three things in ways the FMI 2.0 standard does not mean:

- a step the slave refuses (``do_step`` returns False) is always fmi2Discard, with the
  instance marked as wanting to terminate, so fmpy's ``simulate_fmu`` ends the run early
  without an error; no other call can fail except by raising, which is fmi2Fatal;
- while the importer's loggingOn is false, no message reaches its logger, errors included.

(Its exception path, fmi2Fatal after releasing the instance's Python objects once too often,
stays as it is: robofmu's slave lets no exception reach it and fails calls as below instead.)

The PyPI release of pythonfmu 0.7.0 carries that library only compiled (its sdist has no C++
sources), so robofmu does not rebuild it: it puts a small library of its own in front of it,
compiled here from ``robofmu_fmi2.c`` with the machine's C compiler (once per source and
compiler, cached). Each FMU's ``binaries/linux64/<modelIdentifier>.so`` becomes that library;
pythonfmu's, unchanged, moves beside it as ``libpythonfmu-export.so``. The C source's header
comment says exactly what it changes; in short:

- a message the slave logs with the category :data:`STATUS_CATEGORY` makes the current FMI
  call return at least that message's status (the importer gets the message with pythonfmu's
  usual category, ``logStatusError`` ...);
- messages of status warning and above always reach the importer's logger, OK messages only
  with loggingOn (and its categories, if set);
- the fast path: robofmu's slave registers with it during fmi2Instantiate (its values array,
  masks, shared flags, three callables and NumPy's error state), and it then serves
  fmi2SetReal of inputs, fmi2GetReal, fmi2GetBoolean and fmi2DoStep of an initialized
  instance without pythonfmu's per-call Python lists; every other call, and any with a value reference it does not serve,
  still goes to pythonfmu. ``ROBOFMU_FMI_FAST_PATH=0`` in the environment at instantiation
  switches it off;
- the Python runtime: a host that is not Python needs no preloading; the library loads the
  libpython this build records in each FMU (``resources/robofmu_python.txt``,
  :func:`runtime_record`) and starts it as the recorded program (``ROBOFMU_LIBPYTHON`` and
  ``ROBOFMU_PYTHON`` override);
- no segfault path: a missing resource folder, and any call after the interpreter was
  finalized, are refused before they reach pythonfmu.

A FMU carries binaries for Linux x86_64 only (``binaries/linux64``): pythonfmu's ``win64`` DLL
would run the FMU without this library, so :func:`install` drops it.

What the C libraries share with the Python side (file names, the status category, the marker,
the fast path's struct and numbers) has one definition, :mod:`robofmu.components.fmi.contract`:
the names below are its, and :func:`library` compiles with the header ``robofmu_contract.h``
rendered from it (:mod:`.contract_header`), refusing a C source that defines any of it itself.
"""
from __future__ import annotations

import hashlib
import importlib.util
import os
import platform
import re
import shlex
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path
from xml.etree import ElementTree

# The contract's names, defined once (robofmu.components.fmi.contract): a message logged with
# STATUS_CATEGORY sets the status of the FMI call it is logged in; STOCK_LIBRARY, pythonfmu's
# export library, stands beside robofmu's in binaries/PLATFORM; MARKER is what robofmu's library
# answers from its marker export; RUNTIME_RECORD, in a FMU's resources, the Python runtime it
# was built for; FRONT_BEHIND, the runtime behind the front library of a FMU container.
from robofmu.components.fmi.contract import (FRONT_BEHIND, MARKER, MARKER_FUNCTION, PLATFORM, REGISTER,
                                             RUNTIME_RECORD, STATUS_CATEGORY, STOCK_LIBRARY)

from robofmu.system.compiled import cache_folder, machine_compiler

from . import contract_header

__all__ = ["MARKER", "RUNTIME_RECORD", "STATUS_CATEGORY", "STOCK_LIBRARY", "FmiExportError", "library", "install",
           "install_front", "installed", "read_runtime", "runtime_record"]

SOURCE = Path(__file__).resolve().parent / "robofmu_fmi2.c"
#: The front of a FMU container's runtime (:func:`install_front`).
FRONT_SOURCE = SOURCE.with_name("robofmu_front.c")
#: The FMI types and the forwarded functions both libraries share.
HEADER = SOURCE.with_name("fmi2_forward.h")
#: The functions each C source must define because the Python side calls them by name.
EXPORTS = {SOURCE.name: (MARKER_FUNCTION, REGISTER), FRONT_SOURCE.name: ()}
_FLAGS = ["-shared", "-fPIC", "-O2", "-Wall", "-fvisibility=hidden"]
_LIBS = ["-ldl", "-pthread"]


class FmiExportError(RuntimeError):
    """robofmu's export library cannot be built or put into a FMU."""


def forwarded_functions() -> list[str]:
    """The FMI functions robofmu's libraries take from the library behind them (the C header's list)."""
    names = re.findall(r"^\s*X\([^,]+,\s*(fmi2\w+)\s*,", HEADER.read_text(), flags=re.M)
    if not names:
        raise FmiExportError(f"{HEADER}: no forwarded FMI functions found")
    return names


#: The glibc the library is built against when Zig builds it (``ziglang``, the dev extra): the
#: FMUs then load on distributions back to it (pythonfmu's own library needs glibc 2.32).
GLIBC_BASELINE = "2.17"


def _compiler() -> list[str]:
    """The C compiler: ``$CC``; else Zig's (``python -m ziglang cc``, if installed) for
    x86_64 Linux against glibc :data:`GLIBC_BASELINE`; else the machine's cc, gcc or clang (the
    library then needs this machine's glibc, 2.34 on a current distribution)."""
    if os.environ.get("CC"):
        return shlex.split(os.environ["CC"])
    if importlib.util.find_spec("ziglang") is not None:
        return [sys.executable, "-m", "ziglang", "cc", "-target", f"x86_64-linux-gnu.{GLIBC_BASELINE}"]
    found = machine_compiler()
    if found:
        return found
    raise FmiExportError(
        f"robofmu build: no C compiler found ($CC, cc, gcc, clang). The FMUs need robofmu's FMI "
        f"export library, compiled from {SOURCE}; install one (Debian: apt-get install gcc) or set CC.")


def _cache_dir() -> Path:
    try:
        return cache_folder()
    except OSError as exc:
        raise FmiExportError(f"robofmu build: {exc}") from None


def check_source(source: Path = SOURCE) -> None:
    """Refuse a C source that breaks the contract's one definition (:func:`.contract_header.source_problems`:
    a contract constant or struct of its own, a copy of a contract string, no
    ``#include "robofmu_contract.h"``, a function the Python side calls missing), or one beside
    which a ``robofmu_contract.h`` lies (``#include "..."`` would take it before the generated one).

    Raises :class:`FmiExportError` naming every problem.
    """
    problems = contract_header.source_problems(source, EXPORTS.get(source.name, ()))
    if source.with_name(contract_header.HEADER_NAME).exists():
        problems.append(f"a {contract_header.HEADER_NAME} lies beside it, which it would include instead of "
                        "the generated one")
    if problems:
        raise FmiExportError(f"robofmu build: {source} breaks the contract with the Python side "
                             f"(robofmu.components.fmi.contract):\n  " + "\n  ".join(problems))


def compile_flags(folder: str | Path) -> list[str]:
    """The flags that let a C source of this package compile outside :func:`library` (a test's
    compile): ``robofmu_contract.h`` written into ``folder`` and ``folder`` on the include path."""
    return [f"-I{contract_header.write_header(folder).parent}"]


def library(log=None, source: Path = SOURCE) -> Path:
    """robofmu's export library for ``binaries/linux64`` (or, with ``source=FRONT_SOURCE``, the
    front of a FMU container's runtime), compiled if not cached yet, with the contract's
    header ``robofmu_contract.h`` (rendered from :mod:`robofmu.components.fmi.contract`, written
    beside the compiled library) on the include path.

    Raises :class:`FmiExportError` if the source breaks the contract (:func:`check_source`) or
    (with the compiler's output) if it cannot be compiled.
    """
    if not (sys.platform.startswith("linux") and platform.machine() in ("x86_64", "AMD64")):
        raise FmiExportError(f"robofmu build: the FMUs are built on Linux x86_64 (binaries/{PLATFORM}); "
                             f"this is {sys.platform} {platform.machine()}")
    cc = _compiler()
    try:
        version = subprocess.run(cc + ["--version"], capture_output=True, text=True, timeout=60).stdout
    except (OSError, subprocess.SubprocessError) as exc:
        raise FmiExportError(f"robofmu build: the C compiler {shlex.join(cc)} does not run: {exc}") from None
    check_source(source)
    key = hashlib.sha256(b"\0".join([source.read_bytes(), HEADER.read_bytes(), contract_header.header().encode(),
                                     shlex.join(cc + _FLAGS + _LIBS).encode(), version.encode()]))
    target = _cache_dir() / key.hexdigest()[:16] / f"{source.stem}.so"
    if target.is_file():
        return target
    partial = target.with_name(f".{target.name}.{os.getpid()}")
    command = cc + _FLAGS + compile_flags(target.parent) + ["-o", str(partial), str(source)] + _LIBS
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=300)
    except (OSError, subprocess.SubprocessError) as exc:
        raise FmiExportError(f"robofmu build: compiling the FMI export library failed: {exc}\n"
                             f"  {shlex.join(command)}") from None
    if done.returncode != 0 or not partial.is_file():
        partial.unlink(missing_ok=True)
        raise FmiExportError(
            f"robofmu build: compiling the FMI export library failed (exit status {done.returncode}):\n"
            f"  {shlex.join(command)}\n{done.stderr.strip() or done.stdout.strip()}")
    os.replace(partial, target)
    if log is not None:
        log(f"compiled robofmu's FMI library {source.name}: {target}")
    return target


def runtime_record() -> dict[str, str]:
    """The Python runtime of this process, as a FMU built here records it.

    Returns
    -------
    dict
        ``version`` (``"3.11"``), ``program`` (this interpreter's program, not resolved: a
        venv's ``bin/python`` makes the embedded interpreter find that venv) and ``library``
        (the full path of its libpython, ``""`` if it was built without one).
    """
    library = ""
    if sysconfig.get_config_var("Py_ENABLE_SHARED"):
        folder = Path(sysconfig.get_config_var("LIBDIR") or "")
        for name in (sysconfig.get_config_var("INSTSONAME"), sysconfig.get_config_var("LDLIBRARY")):
            if name and (folder / name).is_file():
                library = str(folder / name)
                break
    return {"version": f"{sys.version_info.major}.{sys.version_info.minor}", "program": sys.executable,
            "library": library}


def _record_text(record: dict[str, str]) -> str:
    return ("# The Python runtime this FMU was built for (robofmu build). A host that is not Python\n"
            "# loads `library` and starts it as `program`; ROBOFMU_LIBPYTHON and ROBOFMU_PYTHON override.\n"
            + "".join(f"{key}={record[key]}\n" for key in ("version", "program", "library")))


def read_runtime(fmu: str | Path) -> dict[str, str] | None:
    """The runtime record in ``fmu`` (a .fmu file), or None if it has none."""
    with zipfile.ZipFile(fmu) as z:
        try:
            text = z.read(f"resources/{RUNTIME_RECORD}").decode()
        except KeyError:
            return None
    return dict(line.split("=", 1) for line in text.splitlines() if "=" in line and not line.startswith("#"))


def _model_identifier(fmu: zipfile.ZipFile, path: Path) -> str:
    root = ElementTree.fromstring(fmu.read("modelDescription.xml"))
    node = root.find("CoSimulation")
    if node is None or not node.get("modelIdentifier"):
        raise FmiExportError(f"{path}: modelDescription.xml names no co-simulation model identifier")
    return node.get("modelIdentifier")


def _beside(info: zipfile.ZipInfo, name: str) -> zipfile.ZipInfo:
    """A new archive entry ``name`` with the date and attributes of ``info``."""
    entry = zipfile.ZipInfo(name, date_time=info.date_time)
    entry.compress_type = info.compress_type
    entry.external_attr = info.external_attr
    return entry


def installed(fmu: str | Path) -> bool:
    """Whether ``fmu`` carries robofmu's export library in front of pythonfmu's."""
    with zipfile.ZipFile(fmu) as z:
        return f"binaries/{PLATFORM}/{STOCK_LIBRARY}" in z.namelist()


def install(fmu: str | Path, ours: Path | None = None) -> None:
    """Put robofmu's export library into a FMU pythonfmu has just built (in place).

    ``binaries/linux64/<modelIdentifier>.so`` (pythonfmu's library, renamed by its builder)
    moves to ``binaries/linux64/libpythonfmu-export.so``; robofmu's library takes its name.
    The binaries pythonfmu ships for other platforms (``binaries/win64``: its own DLL, which
    would run the FMU without robofmu's library) are dropped: a FMU carries binaries only for
    the platforms robofmu's library is built for. ``resources/robofmu_python.txt`` records
    this process's Python runtime (:func:`runtime_record`), for hosts that are not Python.
    """
    _put_in_front(Path(fmu), library() if ours is None else Path(ours), STOCK_LIBRARY,
                  "pythonfmu's export library", "pythonfmu 0.7.0",
                  {f"resources/{RUNTIME_RECORD}": _record_text(runtime_record()).encode()})


def install_front(fmu: str | Path) -> None:
    """Put robofmu's front library (``robofmu_front.c``) into a FMU container that
    fmu-manipulation-toolbox has just built (in place): its runtime moves to
    ``binaries/linux64/libcontainer-runtime.so``, the front takes its name and relays its
    messages, the one it logs as an error on every run downgraded (``robofmu_front.c``). The
    runtime's binaries for other platforms are dropped: the block FMUs it holds run on Linux
    x86_64 only."""
    _put_in_front(Path(fmu), library(source=FRONT_SOURCE), FRONT_BEHIND, "the container runtime",
                  "fmu-manipulation-toolbox 2.0", {})


def _put_in_front(path: Path, ours: Path, behind: str, what: str, written_for: str,
                  extra: dict[str, bytes]) -> None:
    """``binaries/linux64/<modelIdentifier>.so`` of the FMU at ``path`` moves to ``behind``,
    ``ours`` takes its name; other platforms' binaries are dropped; ``extra`` entries added."""
    with zipfile.ZipFile(path) as z:
        identifier = _model_identifier(z, path)
        entry = f"binaries/{PLATFORM}/{identifier}.so"
        behind_entry = f"binaries/{PLATFORM}/{behind}"
        names = z.namelist()
        if behind_entry in names:
            raise FmiExportError(f"{path}: a robofmu library is already in front of {what}")
        if entry not in names:
            raise FmiExportError(f"{path}: no {entry}: its builder did not put {what} in")
        theirs = z.read(entry)
        missing = [name for name in forwarded_functions() if name.encode() + b"\0" not in theirs]
        if missing:
            raise FmiExportError(f"{path}: {what} lacks {', '.join(missing)}; robofmu's library in front of it "
                                 f"(system/packaging/fmi_export) was written for {written_for}")
        entries = [(info, z.read(info.filename)) for info in z.infolist()]
    partial = path.with_name(f".{path.name}.{os.getpid()}.partial")
    try:
        with zipfile.ZipFile(partial, "w") as out:
            for info, data in entries:
                if info.filename == entry:
                    out.writestr(info, ours.read_bytes())
                    out.writestr(_beside(info, behind_entry), theirs)
                elif not info.filename.startswith("binaries/") or info.filename.startswith(f"binaries/{PLATFORM}/"):
                    out.writestr(info, data)
            for name, data in extra.items():
                out.writestr(_beside(entries[0][0], name), data)
        os.replace(partial, path)
    finally:
        partial.unlink(missing_ok=True)

"""``robofmu doctor``: what a process needs to run the FMUs, and whether it works here.

The FMUs run Python inside the importing process (pythonfmu's C++ layer calls the interpreter
that is already loaded). A Python host (fmpy, libcosimpy) started from this installation's
interpreter needs nothing else. A host that is not Python (fmusim, OMSimulator, libcosim's
``cosim``, a C program) needs nothing either: each FMU records the Python it was built for in
``resources/robofmu_python.txt`` (version, program, libpython), and robofmu's FMI library loads
that libpython and starts it as that program (``robofmu_fmi2.c``, point 5). :func:`runtime_problems`
checks each record as such a host would meet it, from an empty environment.

The packages the FMUs need are read from robofmu's own metadata
(``importlib.metadata.requires("robofmu")``, else ``pyproject.toml``): the run-time requirements
whose modules the bundled ``robofmu.components`` imports (its source, read with ``ast`` by
:mod:`robofmu.system.packaging.requirements`, which also writes each FMU's requirements.txt), but
those every FMU carries in its resources (``pythonfmu``, ``robofmu``). robofmu's other
requirements (the master's and the analysis') are checked as installed, not imported.

Then it checks: each package importable (the FMUs' ones imported, with their version against the
requirement), libpython present, every described robot's FMUs present under ``--fmus`` and not
stale (:func:`robofmu.system.fmu.stale_reasons`: built from this code, each FMU's vendor
annotation ``source`` against :data:`robofmu.components.SOURCE_HASH`, with its robot's data as
described now, and robofmu's version), and one FMU instantiated and stepped through fmpy in a
fresh process. :func:`doctor` prints one line per check and per problem; it returns 0 when
everything checks, else 1.
"""
from __future__ import annotations

import importlib
import importlib.metadata as metadata
import importlib.util
import platform
import subprocess
import sys
import sysconfig
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from robofmu.system import defaults
from robofmu.system.packaging.requirements import REQUIREMENT_LINE, declared, needs, normalize

__all__ = ["Requirement", "doctor", "fmu_problems", "libpython", "requirements", "runtime_problems"]

#: Top-level packages every FMU carries in its resources (pythonfmu's builder bundles itself,
#: ``robofmu build`` bundles robofmu.components): the importing process needs no copy.
BUNDLED = {"pythonfmu", "robofmu"}



@dataclass
class Requirement:
    """One run-time requirement of robofmu.

    Attributes
    ----------
    text : str
        As declared (``"pin>=3.0"``).
    distribution : str
        Its distribution name (``"pin"``).
    specifier : str
        Its version specifier (``">=3.0"``, may be empty).
    modules : list of str
        The top-level modules the installed distribution provides (``["pinocchio"]``); empty
        when it is not installed.
    for_fmus : bool
        Whether the FMUs import it.
    """

    text: str
    distribution: str
    specifier: str
    modules: list[str] = field(default_factory=list)
    for_fmus: bool = False


def _modules_of(distribution: str) -> list[str]:
    """Top-level modules an installed distribution provides ([] if it is not installed)."""
    try:
        dist = metadata.distribution(distribution)
    except metadata.PackageNotFoundError:
        return []
    names: list[str] = []
    top_level = dist.read_text("top_level.txt")
    if top_level:
        names = [line.strip() for line in top_level.splitlines() if line.strip()]
    for file in dist.files or []:
        parts = file.parts
        if "site-packages" in parts:
            parts = parts[len(parts) - parts[::-1].index("site-packages"):]
        if not parts or parts[0] in ("..", "__pycache__"):
            continue
        name = parts[0][:-3] if len(parts) == 1 and parts[0].endswith(".py") else parts[0]
        if len(parts) == 1 and not parts[0].endswith(".py"):
            continue
        if name.isidentifier() and name not in names:
            names.append(name)
    return names


def requirements() -> list[Requirement]:
    """robofmu's run-time requirements, those the FMUs import marked :attr:`Requirement.for_fmus`.

    What the FMUs import is derived as ``robofmu build`` derives their requirements.txt
    (:func:`robofmu.system.packaging.requirements.needs` on the bundled ``robofmu.components``); a
    distribution they import that robofmu does not declare is added, and a module that no
    installed distribution provides is added under its own name (not installed)."""
    import robofmu.components as components

    needed = needs(Path(components.__file__).resolve().parent)
    for_fmus = {normalize(n.distribution) for n in needed if n.distribution}
    found, listed = [], set()
    for text in declared():
        match = REQUIREMENT_LINE.match(text)
        name, specifier = match.group(1), match.group(2)
        listed.add(normalize(name))
        found.append(Requirement(text.split(";")[0].strip(), name, specifier, _modules_of(name),
                                 normalize(name) in for_fmus and name.lower() not in BUNDLED))
    for n in needed:
        if n.distribution is None:
            found.append(Requirement(n.requirement, n.requirement, "", list(n.modules), True))
        elif normalize(n.distribution) not in listed and n.distribution.lower() not in BUNDLED:
            found.append(Requirement(n.requirement, n.distribution, REQUIREMENT_LINE.match(n.requirement).group(2),
                                     _modules_of(n.distribution), True))
    return found


def libpython() -> Path | None:
    """This interpreter's shared libpython (None if it was built without one)."""
    if not sysconfig.get_config_var("Py_ENABLE_SHARED"):
        return None
    libdir, soname = sysconfig.get_config_var("LIBDIR"), sysconfig.get_config_var("INSTSONAME")
    return Path(libdir) / soname if libdir and soname else None


def scripts_dir() -> Path:
    """The folder of this environment's ``python`` (the venv's ``bin``)."""
    return Path(sysconfig.get_path("scripts"))


#: Run by a FMU's recorded program in an empty environment: its libpython loads and is that
#: Python, and the FMU's requirements import (the modules as arguments).
_RUNTIME_CHECK = ("import ctypes, importlib, sys\n"
                  "library = ctypes.CDLL(sys.argv[1]) if sys.argv[1] else None\n"
                  "if library is not None:\n"
                  "    library.Py_GetVersion.restype = ctypes.c_char_p\n"
                  "for module in sys.argv[2:]:\n"
                  "    importlib.import_module(module)\n"
                  "print(library.Py_GetVersion().decode().split()[0] if library else '-')\n")


def _record_problem(record: dict[str, str], modules: list[str], timeout: float = 120.0) -> str | None:
    """Why a host that is not Python cannot start the runtime ``record`` names (None: it can)."""
    library, program = record.get("library", ""), record.get("program", "")
    if not library:
        return "records no libpython (its Python has no shared libpython): only a Python host can load it"
    for what, path in (("libpython", library), ("program", program)):
        if not Path(path).is_file():
            return f"its {what} {path} does not exist (rebuild the FMUs with an installed Python, or set " \
                   f"ROBOFMU_{'LIBPYTHON' if what == 'libpython' else 'PYTHON'})"
    try:
        done = subprocess.run([program, "-c", _RUNTIME_CHECK, library, *modules], capture_output=True,
                              text=True, timeout=timeout, env={})
    except (OSError, subprocess.TimeoutExpired) as exc:
        return f"its program {program} does not run: {exc}"
    if done.returncode != 0:
        lines = [line for line in done.stderr.splitlines() if line.strip()]
        return f"its program {program}, run with no environment, fails: {lines[-1].strip() if lines else done.returncode}"
    running = done.stdout.strip()
    if not running.startswith(record.get("version", "?") + "."):
        return f"its libpython {library} is Python {running}, the FMU was built for {record.get('version')}"
    return None


def runtime_problems(fmus: list[Path]) -> tuple[list[str], list[str]]:
    """(ok lines, problems): whether a host that is not Python, with no environment variable,
    can start the Python runtime each FMU records (grouped: one build records one runtime)."""
    from robofmu.system.packaging.fmi_export import RUNTIME_RECORD, read_runtime

    groups: dict[tuple, list[Path]] = {}
    fine, problems = [], []
    for path in fmus:
        record = read_runtime(path)
        if record is None:
            problems.append(f"{path}: no resources/{RUNTIME_RECORD}: built by an older robofmu; "
                            "a host that is not Python cannot load it; rebuild it (robofmu build)")
            continue
        with zipfile.ZipFile(path) as archive:
            wanted = archive.read("resources/requirements.txt").decode().splitlines()
        distributions = tuple(sorted(REQUIREMENT_LINE.match(line).group(1) for line in wanted
                                     if line.strip() and not line.lstrip().startswith("#")))
        groups.setdefault((tuple(sorted(record.items())), distributions), []).append(path)
    for (items, distributions), paths in groups.items():
        record = dict(items)
        modules = [m for name in distributions if name.lower() not in BUNDLED
                   for m in (_modules_of(name)[:1] or [name.replace("-", "_")])]
        what = (f"{len(paths)} FMU{'s' * (len(paths) != 1)} recording Python {record.get('version')} "
                f"(program {record.get('program')}, libpython {record.get('library') or '-'})")
        trouble = _record_problem(record, modules)
        if trouble:
            problems.append(f"{what}: {trouble}")
        else:
            fine.append(f"{what}: a host that is not Python loads them with no environment variable "
                        f"(checked from an empty environment: {', '.join(modules)} import)")
    return fine, problems


def _version_ok(version: str, specifier: str) -> bool | None:
    """Whether ``version`` satisfies ``specifier`` (None if ``packaging`` cannot tell)."""
    if not specifier:
        return True
    try:
        from packaging.specifiers import SpecifierSet
        from packaging.version import Version
    except ImportError:
        return None
    try:
        return Version(version) in SpecifierSet(specifier)
    except Exception:
        return None


def _package_checks(required: list[Requirement]) -> tuple[list[str], list[str]]:
    """(ok lines, problems) for every requirement: installed, version, the FMUs' ones imported."""
    fine, problems = [], []
    for r in required:
        try:
            version = metadata.version(r.distribution)
        except metadata.PackageNotFoundError:
            problems.append(f"{r.distribution}: not installed (needs {r.text}"
                            f"{', imported by the FMUs' if r.for_fmus else ''}): pip install '{r.text}'")
            continue
        if _version_ok(version, r.specifier) is False:
            problems.append(f"{r.distribution} {version}: does not satisfy {r.text}: pip install '{r.text}'")
            continue
        module = r.modules[0] if r.modules else r.distribution.replace("-", "_")
        if r.for_fmus:
            for module in r.modules or [module]:
                try:
                    importlib.import_module(module)
                except Exception as exc:
                    problems.append(f"{r.distribution} {version}: import {module} fails: "
                                    f"{' '.join(str(exc).split()) or type(exc).__name__}")
                    break
            else:
                fine.append(f"{r.distribution} {version} ({r.text}), imported as "
                            f"{', '.join(r.modules or [module])}: the FMUs import it")
        elif importlib.util.find_spec(module) is None:
            problems.append(f"{r.distribution} {version}: installed, but no module {module} to import")
        else:
            fine.append(f"{r.distribution} {version} ({r.text}): robofmu itself uses it (build, master, analysis)")
    return fine, problems


def fmu_problems(fmu_dir: Path) -> tuple[list[str], list[str], list[Path]]:
    """(ok lines, problems, good FMUs) of the FMU collection under ``fmu_dir``.

    Every block of every described robot must be at ``fmu_dir/<robot>/<block>.fmu`` and not be
    stale (:func:`robofmu.system.fmu.stale_reasons`: built from these sources, its vendor
    annotation's ``source`` is :data:`robofmu.components.SOURCE_HASH`, from its robot's data as
    described now, by this robofmu version).
    """
    from robofmu.components import SOURCE_HASH
    from robofmu.components.robots import available, load_description

    from robofmu.system.fmu import stale_reasons

    if not fmu_dir.is_dir():
        what = "is a file, not a folder" if fmu_dir.exists() else "no such folder"
        return [], [f"--fmus {fmu_dir}: {what}; build the FMUs: robofmu build --out {fmu_dir}"], []
    problems, good, counts = [], [], {}
    for robot in available():
        description = load_description(robot)
        for block in description.fmu_blocks:
            path = fmu_dir / robot / f"{block}.fmu"
            name = f"{robot}/{block}.fmu"
            build = f"robofmu build {robot} --out {fmu_dir}"
            if not path.is_file():
                problems.append(f"{fmu_dir / name}: missing; build it: {build}")
                continue
            try:
                reasons = stale_reasons(path, description)
            except Exception as exc:
                problems.append(f"{fmu_dir / name}: not a robofmu FMU ({' '.join(str(exc).split())}); "
                                f"rebuild it: {build}")
                continue
            if reasons:
                problems.append(f"{fmu_dir / name}: stale: {', '.join(reasons)}; rebuild it: {build}")
                continue
            good.append(path)
            counts[robot] = counts.get(robot, 0) + 1
    fine = []
    if good:
        fine.append(f"{len(good)} FMUs under {fmu_dir} built from these sources ({SOURCE_HASH[:12]}): "
                    + ", ".join(f"{robot} {n}" for robot, n in counts.items()))
    return fine, problems, good


#: Run in a fresh interpreter: simulate one FMU for 10 steps with fmpy (as any Python host would).
_STEP = ("import sys, fmpy\n"
         "rows = fmpy.simulate_fmu(sys.argv[1], stop_time=0.01, output_interval=0.001)\n"
         "print(len(rows))\n")


def step_problem(path: Path, timeout: float = 120.0) -> str | None:
    """Why ``path`` does not instantiate and step through fmpy in a fresh process (None: it does)."""
    try:
        done = subprocess.run([sys.executable, "-c", _STEP, str(path)], capture_output=True, text=True,
                              timeout=timeout)
    except subprocess.TimeoutExpired:
        return f"{path}: fmpy.simulate_fmu did not finish in {timeout:g} s"
    if done.returncode != 0 or done.stdout.strip() != "11":
        lines = [line for line in done.stderr.splitlines() if line.strip()]
        return (f"{path}: fmpy.simulate_fmu failed (exit status {done.returncode})"
                + (f": {lines[-1].strip()}" if lines else ""))
    return None


def doctor(fmu_dir: str | Path = defaults.FMU_FOLDER, say: Callable[[str], None] = print) -> int:
    """Print what a process needs to run the FMUs under ``fmu_dir``, and check it here.

    Parameters
    ----------
    fmu_dir : str or Path
        The FMU collection (``<robot>/<block>.fmu``).
    say : callable
        Receives each output line.

    Returns
    -------
    int
        0 when everything checks, 1 otherwise (each problem on a line of its own, ``problem: ...``).
    """
    fmu_dir = Path(fmu_dir)
    required = requirements()
    library = libpython()
    fmus = [r for r in required if r.for_fmus]
    others = [r for r in required if not r.for_fmus]
    say("robofmu doctor: what a process needs to run the robofmu FMUs")
    say("")
    say("The FMUs run Python inside the importing process (pythonfmu); they were built for")
    say(f"  python      {sys.executable} ({platform.python_implementation()} {platform.python_version()})")
    say(f"  libpython   {library if library else '(none: this Python has no shared libpython)'}")
    say(f"  venv bin    {scripts_dir()}")
    say(f"  packages    {', '.join(r.text for r in fmus) or '(none)'} (the FMUs import them); "
        f"robofmu also needs {', '.join(r.text for r in others) or 'nothing else'}")
    say("")
    say("A Python host (fmpy, libcosimpy) run by that python needs nothing else. A host that is not")
    say("Python (fmusim, OMSimulator, cosim, a C program) needs nothing either: each FMU records that")
    say("python and its libpython (resources/robofmu_python.txt), and loads them itself;")
    say("ROBOFMU_PYTHON and ROBOFMU_LIBPYTHON override the record.")
    say("")
    say("Checks:")
    fine, problems = _package_checks(required)
    if library is None:
        problems.append("libpython: this Python was built without a shared libpython "
                        "(Py_ENABLE_SHARED = 0); a non-Python host cannot load the FMUs")
    elif not library.is_file():
        problems.append(f"libpython: {library} does not exist")
    else:
        fine.append(f"libpython {library} exists")
    ok_fmus, fmu_trouble, good = fmu_problems(fmu_dir)
    fine += ok_fmus
    problems += fmu_trouble
    if good:
        ok_runtime, runtime_trouble = runtime_problems(good)
        fine += ok_runtime
        problems += runtime_trouble
        trouble = step_problem(good[0])
        if trouble:
            problems.append(trouble)
        else:
            fine.append(f"{good[0].relative_to(fmu_dir)} instantiates and steps through fmpy "
                        "(10 steps, a fresh process)")
    for line in fine:
        say(f"  ok       {line}")
    for line in problems:
        say(f"  problem: {line}")
    say("")
    if problems:
        say(f"{len(problems)} problem{'s' * (len(problems) != 1)}")
        return 1
    say("everything checks")
    return 0

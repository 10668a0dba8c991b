"""``robofmu doctor``: what a process needs to run the FMUs, and whether it works here.

The FMUs run Python inside the importing process (pythonfmu's C++ layer calls the interpreter
that is already loaded). A Python host (fmpy, libcosimpy) started from this installation's
interpreter needs nothing else. A non-Python host (libcosim's ``cosim``) must preload this
interpreter's libpython (``sysconfig``: ``LIBDIR`` / ``INSTSONAME``) and put the venv's ``bin``
first on ``PATH``, so that the embedded interpreter finds this environment's packages.

The packages the FMUs need are read from robofmu's own metadata
(``importlib.metadata.requires("robofmu")``, else ``pyproject.toml``): the run-time requirements
whose modules the bundled ``robofmu.components`` imports (its source, read with ``ast``), but
those every FMU carries in its resources (``pythonfmu``, ``robofmu``). robofmu's other
requirements (the master's and the analysis') are checked as installed, not imported.

Then it checks: each package importable (the FMUs' ones imported, with their version against the
requirement), libpython present, every described robot's FMUs present under ``--fmus`` and built
from these sources (each FMU's vendor annotation ``source`` against
:data:`robofmu.components.SOURCE_HASH`), and one FMU instantiated and stepped through fmpy in a
fresh process. :func:`doctor` prints one line per check and per problem; it returns 0 when
everything checks, else 1.
"""
from __future__ import annotations

import ast
import importlib
import importlib.metadata as metadata
import importlib.util
import platform
import re
import subprocess
import sys
import sysconfig
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

__all__ = ["Requirement", "doctor", "environment_lines", "fmu_problems", "libpython", "requirements"]

#: Top-level packages every FMU carries in its resources (pythonfmu's builder bundles itself,
#: ``robofmu build`` bundles robofmu.components): the importing process needs no copy.
BUNDLED = {"pythonfmu", "robofmu"}

_NAME = re.compile(r"^\s*([A-Za-z0-9][A-Za-z0-9._-]*)\s*(?:\[[^\]]*\])?\s*([^;]*?)\s*(?:;(.*))?$")


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


def _declared() -> list[str]:
    """robofmu's run-time requirements as declared (installed metadata, else pyproject.toml)."""
    try:
        declared = metadata.requires("robofmu") or []
    except metadata.PackageNotFoundError:
        pyproject = Path(__file__).resolve().parents[1] / "pyproject.toml"
        declared = tomllib.loads(pyproject.read_text())["project"].get("dependencies", [])
    return [r for r in declared if "extra" not in (_NAME.match(r).group(3) or "")]


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


def _imports_of_components() -> set[str]:
    """Top-level modules imported anywhere in the bundled ``robofmu.components`` sources."""
    import robofmu.components as components

    found: set[str] = set()
    for path in Path(components.__file__).resolve().parent.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                found |= {alias.name.split(".")[0] for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                found.add(node.module.split(".")[0])
    return found


def requirements() -> list[Requirement]:
    """robofmu's run-time requirements, those the FMUs import marked :attr:`Requirement.for_fmus`."""
    imported = _imports_of_components() - BUNDLED
    found = []
    for text in _declared():
        match = _NAME.match(text)
        name, specifier = match.group(1), match.group(2)
        modules = _modules_of(name)
        uses = bool(set(modules) & imported) or name.replace("-", "_").lower() in imported
        found.append(Requirement(text.split(";")[0].strip(), name, specifier, modules,
                                 uses and name.lower() not in BUNDLED))
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


def environment_lines() -> list[str]:
    """The shell lines a non-Python host needs before it loads the FMUs."""
    lines = []
    library = libpython()
    if library is not None:
        lines.append(f"export LD_PRELOAD={library}")
    lines.append(f"export PATH={scripts_dir()}:$PATH")
    return lines


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

    Every block of every described robot must be at ``fmu_dir/<robot>/<block>.fmu`` and be built
    from these sources (its vendor annotation's ``source`` is :data:`robofmu.components.SOURCE_HASH`).
    """
    from robofmu.components import SOURCE_HASH
    from robofmu.components.robots import available

    from .build import blocks_of
    from .replica import block_identity

    if not fmu_dir.is_dir():
        what = "is a file, not a folder" if fmu_dir.exists() else "no such folder"
        return [], [f"--fmus {fmu_dir}: {what}; build the FMUs: robofmu build --out {fmu_dir}"], []
    problems, good, counts = [], [], {}
    for robot in available():
        for block in blocks_of(robot):
            path = fmu_dir / robot / f"{block}.fmu"
            name = f"{robot}/{block}.fmu"
            build = f"robofmu build {robot} --out {fmu_dir}"
            if not path.is_file():
                problems.append(f"{fmu_dir / name}: missing; build it: {build}")
                continue
            try:
                identity = block_identity(path)
            except Exception as exc:
                problems.append(f"{fmu_dir / name}: not a robofmu FMU ({' '.join(str(exc).split())}); "
                                f"rebuild it: {build}")
                continue
            if identity.get("source") != SOURCE_HASH:
                problems.append(f"{fmu_dir / name}: stale: built from robofmu sources "
                                f"{identity.get('source', '?')[:12]}, these are {SOURCE_HASH[:12]}; "
                                f"rebuild it: {build}")
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


def doctor(fmu_dir: str | Path = "fmus", say: Callable[[str], None] = print) -> int:
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
    say("A Python host (fmpy, libcosimpy) run by that python needs nothing else. A non-Python host")
    say("(e.g. libcosim's cosim) needs, in its environment:")
    for line in environment_lines():
        say(f"  {line}")
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

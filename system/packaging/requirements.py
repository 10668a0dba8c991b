"""What the code bundled in a FMU needs from the importing process: the one derivation of
``resources/requirements.txt`` (``robofmu build``) and of the FMUs' packages (``robofmu doctor``).

The bundled code (a copy of ``robofmu.components``) is read with :mod:`ast`: every absolute
``import`` anywhere in it (function-level ones included), reduced to its top-level module, less the
standard library (:data:`sys.stdlib_module_names`) and the bundle itself (``robofmu``). Each module
is mapped to the installed distribution that provides it
(:func:`importlib.metadata.packages_distributions`, completed with the modules a distribution
installs in a nested ``site-packages``, as cmeel's ``pin`` does ``pinocchio``). The version
specifier is robofmu's declared requirement of that distribution (``numpy>=1.26``), else
``>=`` the installed version. A module no installed distribution provides fails the build
(:class:`UnmappedImport`, naming the module and the files importing it).

requirements.txt cannot require a Python version (pip has no such line, and an environment
marker would make pip skip the requirement, not fail): the file's first line is a comment naming
the build's Python (``# Python 3.11 ...``); the model description's vendor annotation records it
as data (``Block python="3.11"``).
"""
from __future__ import annotations

import ast
import importlib.metadata as metadata
import re
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path

__all__ = ["BUNDLE", "REQUIREMENT_LINE", "Import", "Need", "UnmappedImport", "declared", "imports_of", "module_distributions",
           "needs", "normalize", "requirement_lines", "requirements_text"]

#: The top-level package the FMUs bundle (its imports of itself are not requirements).
BUNDLE = "robofmu"

#: A requirement line: name, extras, specifier, marker.
REQUIREMENT_LINE = re.compile(r"^\s*([A-Za-z0-9][A-Za-z0-9._-]*)\s*(?:\[[^\]]*\])?\s*([^;]*?)\s*(?:;(.*))?$")


class UnmappedImport(ValueError):
    """The bundled code imports a module that no installed distribution provides."""


@dataclass(frozen=True)
class Import:
    """One absolute import statement: its top-level module, the file (relative to the scanned
    root's parent, e.g. ``robofmu/components/robots/serial.py``) and line."""

    module: str
    file: str
    line: int

    def __str__(self) -> str:
        return f"{self.file} line {self.line}"


@dataclass(frozen=True)
class Need:
    """One distribution the bundled code needs.

    Attributes
    ----------
    distribution : str or None
        Its name as installed (``"pin"``); None when no installed distribution provides the modules.
    requirement : str
        The requirement line (``"pin>=3.0"``); the module name when ``distribution`` is None.
    modules : tuple of str
        The top-level modules of it that the code imports (``("pinocchio",)``).
    imports : tuple of Import
        Where the code imports them.
    """

    distribution: str | None
    requirement: str
    modules: tuple[str, ...]
    imports: tuple[Import, ...]


def normalize(name: str) -> str:
    """A distribution name normalized (PEP 503)."""
    return re.sub(r"[-_.]+", "-", name).lower()


def imports_of(root: str | Path) -> list[Import]:
    """Every absolute import of the Python files under ``root`` (a package folder, or one file).

    ``import a.b`` and ``from a.b import c`` give module ``a``; relative imports are the package's
    own and are left out. Sorted by module, file, line."""
    root = Path(root)
    files = [root] if root.is_file() else sorted(root.rglob("*.py"))
    found = set()
    for path in files:
        if "__pycache__" in path.parts:
            continue
        name = path.relative_to(root.parent).as_posix()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, ast.Import):
                found |= {Import(alias.name.split(".")[0], name, node.lineno) for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                found.add(Import(node.module.split(".")[0], name, node.lineno))
    return sorted(found, key=lambda i: (i.module, i.file, i.line))


def module_distributions() -> dict[str, list[str]]:
    """Top-level module -> the installed distributions providing it (names as installed)."""
    found: dict[str, list[str]] = {}
    for module, names in metadata.packages_distributions().items():
        found[module] = list(dict.fromkeys(names))
    for dist in metadata.distributions():
        name = dist.metadata["Name"]
        for file in dist.files or []:
            parts = file.parts
            if "site-packages" not in parts:
                continue
            inner = parts[len(parts) - parts[::-1].index("site-packages"):]   # after the last one
            if not inner or inner[0] in ("..", "__pycache__"):
                continue
            module = inner[0].split(".")[0] if len(inner) == 1 else inner[0]
            if len(inner) == 1 and not inner[0].endswith((".py", ".so", ".pyd")):
                continue
            if module.isidentifier() and name not in found.setdefault(module, []):
                found[module].append(name)
    return found


def declared(project: str = "robofmu") -> list[str]:
    """robofmu's run-time requirements as declared (installed metadata, else pyproject.toml),
    extras' ones left out."""
    try:
        lines = metadata.requires(project) or []
    except metadata.PackageNotFoundError:
        pyproject = Path(__file__).resolve().parents[2] / "pyproject.toml"
        lines = tomllib.loads(pyproject.read_text())["project"].get("dependencies", [])
    return [r for r in lines if "extra" not in (REQUIREMENT_LINE.match(r).group(3) or "")]


def needs(root: str | Path, bundle: str = BUNDLE) -> list[Need]:
    """The distributions the code under ``root`` imports, sorted by name (unmapped modules last).

    Parameters
    ----------
    root : str or Path
        The bundled package's folder (``.../robofmu``), or one file.
    bundle : str
        The bundle's own top-level package, not a requirement.
    """
    outside: dict[str, list[Import]] = {}
    for imp in imports_of(root):
        if imp.module != bundle and imp.module not in sys.stdlib_module_names:
            outside.setdefault(imp.module, []).append(imp)
    specs = {normalize(REQUIREMENT_LINE.match(r).group(1)): r.split(";")[0].strip() for r in declared()}
    providers = module_distributions()
    by_distribution: dict[str, list[str]] = {}
    unmapped = []
    for module in sorted(outside):
        names = providers.get(module, [])
        if len(names) > 1 and any(normalize(n) in specs for n in names):     # several: the declared ones
            names = [n for n in names if normalize(n) in specs]
        if not names:
            unmapped.append(Need(None, module, (module,), tuple(outside[module])))
        for name in names:
            by_distribution.setdefault(name, []).append(module)
    found = []
    for name in sorted(by_distribution, key=normalize):
        modules = by_distribution[name]
        spec = specs.get(normalize(name)) or f"{name}>={metadata.version(name)}"
        found.append(Need(name, spec, tuple(modules), tuple(i for m in modules for i in outside[m])))
    return found + unmapped


def requirement_lines(root: str | Path, bundle: str = BUNDLE) -> list[str]:
    """The requirement lines of the code under ``root``; :class:`UnmappedImport` names every module
    no installed distribution provides and the files importing it."""
    found = needs(root, bundle)
    missing = [n for n in found if n.distribution is None]
    if missing:
        raise UnmappedImport(
            "the bundled code imports "
            + "; ".join(f"module {n.modules[0]!r} ({', '.join(map(str, n.imports))})" for n in missing)
            + ", which no installed distribution provides: install "
            + ("it" if len(missing) == 1 else "them") + " (the FMUs need it at run time), or remove the import")
    return [n.requirement for n in found]


def requirements_text(root: str | Path, bundle: str = BUNDLE) -> str:
    """``resources/requirements.txt`` of a FMU bundling the code under ``root``: a comment naming
    this Python (pip cannot require one), then one requirement per line."""
    python = f"{sys.version_info.major}.{sys.version_info.minor}"
    return (f"# Python {python}: the FMU runs in its importer's Python, which must be {python} "
            "(pip cannot require a Python version)\n"
            + "".join(f"{line}\n" for line in requirement_lines(root, bundle)))

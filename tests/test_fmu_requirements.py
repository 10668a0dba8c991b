"""The FMUs declare what they need: resources/requirements.txt (read by `pythonfmu deploy`) and
the Python version, in the model description.

requirements.txt is derived at build time from the bundled code's imports
(robofmu.system.packaging.requirements). The reference here is independent of that module: the test reads
the Python files inside the FMU zip itself (its own ast walk), finds the distribution owning each
imported module by the module's file on disk (importlib.util.find_spec against every installed
distribution's file list, not packages_distributions), and takes the specifiers from
pyproject.toml.
"""
from __future__ import annotations

import ast
import functools
import importlib.metadata as metadata
import importlib.util
import re
import shutil
import sys
import tomllib
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import pytest
from pythonfmu import deploy

import robofmu.components as components
from fmu_util import robot_blocks
from robofmu.system.packaging.requirements import UnmappedImport, requirement_lines

PYPROJECT = Path(__file__).resolve().parents[1] / "pyproject.toml"
PYTHON = f"{sys.version_info.major}.{sys.version_info.minor}"


def _canonical(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


@functools.lru_cache(maxsize=None)
def _owner(module: str) -> str | None:
    """The installed distribution whose file list holds ``module``'s file (None: none does)."""
    spec = importlib.util.find_spec(module)
    if spec is None:
        return None
    origin = spec.origin if spec.origin not in (None, "namespace") else \
        str(Path(next(iter(spec.submodule_search_locations))) / "__init__.py")
    where = Path(origin).resolve()
    for dist in metadata.distributions():
        for file in dist.files or []:
            if file.name == where.name and Path(dist.locate_file(file)).resolve() == where:
                return dist.metadata["Name"]
    return None


def _reference_lines(sources: dict[str, bytes]) -> list[str]:
    """The requirement lines of Python sources {name: text}, derived independently (see the module
    docstring): third-party top-level modules -> owning distribution -> pyproject's specifier,
    else >= the installed version; sorted by canonical name."""
    modules = set()
    for name, text in sources.items():
        for node in ast.walk(ast.parse(text, name)):
            if isinstance(node, ast.Import):
                modules |= {a.name.partition(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and not node.level:
                modules.add(node.module.partition(".")[0])
    modules -= set(sys.stdlib_module_names) | {"robofmu"}
    declared = {_canonical(re.match(r"[A-Za-z0-9._-]+", d).group()): d
                for d in tomllib.loads(PYPROJECT.read_text())["project"]["dependencies"]}
    owners = {_owner(m) for m in modules}
    assert None not in owners, f"no distribution owns one of {sorted(modules)}"
    return sorted((declared.get(_canonical(d)) or f"{d}>={metadata.version(d)}" for d in owners),
                  key=lambda line: _canonical(re.match(r"[A-Za-z0-9._-]+", line).group()))


def _bundled_sources(archive: zipfile.ZipFile) -> dict[str, bytes]:
    """The FMU's own code: its script (resources/*.py) and bundled package (resources/robofmu/);
    pythonfmu's copy of itself (resources/pythonfmu/) is pythonfmu's business."""
    return {n: archive.read(n) for n in archive.namelist()
            if n.endswith(".py") and (n.startswith("resources/robofmu/") or n.count("/") == 1)}


def _split(text: str) -> tuple[list[str], list[str]]:
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    return [line for line in lines if line.startswith("#")], [line for line in lines if not line.startswith("#")]


@pytest.mark.parametrize("robot, kind", robot_blocks())
def test_fmu_declares_its_requirements_and_python(fmu_root, robot, kind, monkeypatch):
    path = fmu_root / robot / f"{kind}.fmu"
    with zipfile.ZipFile(path) as archive:
        comments, lines = _split(archive.read("resources/requirements.txt").decode())
        sources = _bundled_sources(archive)
        root = ET.fromstring(archive.read("modelDescription.xml"))
    assert f"resources/robofmu_{robot}_{kind}.py" in sources and len(sources) > 20
    # exactly what the bundled code imports; scipy included (the IK solvers' and 3rrp's LAPACK)
    assert lines == _reference_lines(sources)
    assert [line.split(">")[0].split("=")[0] for line in lines] == ["numpy", "pin", "pythonfmu", "scipy"]
    assert "scipy>=1.11" in lines and "pythonfmu==0.7.0" in lines
    assert len(comments) == 1 and comments[0].startswith(f"# Python {PYTHON}:")
    block = root.find("VendorAnnotations/Tool[@name='robofmu']/Block")
    assert block.get("python") == PYTHON and block.get("requirements") == "resources/requirements.txt"
    assert f"Runs in Python {PYTHON} with the packages of resources/requirements.txt" in root.get("description")
    # pythonfmu deploy finds the file and hands it to pip (the install itself is not run here)
    calls = []
    monkeypatch.setattr(deploy.subprocess, "run", lambda args, **_kw: calls.append(args))
    deploy.deploy(path)
    assert calls and "pip" in " ".join(map(str, calls[0])) and any("requirements" in str(a) for a in calls[0])


def _package_with(tmp_path: Path, source: str) -> Path:
    """A copy of robofmu.components under tmp_path/robofmu with robots/extra.py = ``source``;
    returns the copy's ``components`` folder."""
    package = tmp_path / "robofmu" / "components"
    shutil.copytree(Path(components.__file__).parent, package,
                    ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    (package / "robots" / "extra.py").write_text(source)
    return package


@pytest.mark.slow
def test_a_new_third_party_import_becomes_a_requirement(tmp_path, monkeypatch):
    """A bundled module importing yaml (PyYAML: installed, robofmu declares no requirement on it):
    the derivation lists it at >= its installed version, and a FMU built from that code carries it."""
    version = metadata.version("PyYAML")
    package = _package_with(tmp_path, "import json\nimport yaml\nfrom robofmu.components import robots\n"
                                      "from . import model\n\n\ndef load(text):\n    import yaml.constructor\n")
    expected = ["numpy>=1.26", "pin>=3.0", "pythonfmu==0.7.0", f"PyYAML>={version}", "scipy>=1.11"]
    assert requirement_lines(package.parent) == expected
    assert requirement_lines(Path(components.__file__).parent) == \
        [line for line in expected if "PyYAML" not in line]
    # the build writes it into the FMU (the staged copy is scanned, not the installed sources)
    from robofmu.system.packaging.build import build

    monkeypatch.setattr(components, "__file__", str(package / "__init__.py"))
    monkeypatch.setattr(components, "SOURCE_HASH", components.source_hash(package))    # its check_bundle
    [fmu] = build("rrp", tmp_path / "fmus", blocks=["fk"], log=lambda *_: None)
    with zipfile.ZipFile(fmu) as archive:
        assert "resources/robofmu/components/robots/extra.py" in archive.namelist()
        _, lines = _split(archive.read("resources/requirements.txt").decode())
        assert lines == expected == _reference_lines(_bundled_sources(archive))


@pytest.mark.slow
def test_an_import_no_distribution_provides_fails_the_build(tmp_path, monkeypatch):
    package = _package_with(tmp_path, '"""extra"""\nimport math\nimport robofmu_no_such_module_zq.sub as s\n')
    with pytest.raises(UnmappedImport) as failure:
        requirement_lines(package.parent)
    assert "'robofmu_no_such_module_zq'" in str(failure.value)
    assert "robofmu/components/robots/extra.py line 3" in str(failure.value)
    from robofmu.system.packaging.build import build

    monkeypatch.setattr(components, "__file__", str(package / "__init__.py"))
    with pytest.raises(ValueError, match=r"'robofmu_no_such_module_zq' \(robofmu/components/robots/extra.py line 3\)"):
        build("rrp", tmp_path / "fmus", blocks=["fk"], log=lambda *_: None)
    assert not list((tmp_path / "fmus").rglob("*.fmu"))


@pytest.mark.slow
def test_doctor_checks_what_the_fmus_declare(fmu_root):
    """robofmu doctor's packages for the FMUs are the FMUs' requirements.txt, but pythonfmu (every
    FMU carries its own copy): one derivation for both."""
    from robofmu.system.packaging.doctor import requirements

    with zipfile.ZipFile(fmu_root / "chess" / "plant.fmu") as archive:
        _, lines = _split(archive.read("resources/requirements.txt").decode())
    assert sorted(r.text for r in requirements() if r.for_fmus) == \
        sorted(line for line in lines if not line.startswith("pythonfmu")) == ["numpy>=1.26", "pin>=3.0", "scipy>=1.11"]

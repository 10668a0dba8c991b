"""robofmu's version is written once, in pyproject.toml (the package metadata), and reaches the FMUs.

The build writes ``importlib.metadata.version("robofmu")`` into each FMU's generated script
(``robofmu_version``: where a FMU runs robofmu need not be installed); the slave makes the model
description's ``version`` of it and the bundled sources' hash, ``<version>+<hash>``.
"""
from __future__ import annotations

import pytest

import tomllib
import zipfile
from importlib import metadata
from pathlib import Path

from fmpy import read_model_description

from robofmu.components import SOURCE_HASH
from robofmu.components.fmi.base import BlockSlave
from robofmu.system.packaging import build

ROOT = Path(__file__).resolve().parents[1]


def test_the_package_metadata_is_pyprojects_version():
    declared = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    assert metadata.version("robofmu") == declared == build.robofmu_version()


@pytest.mark.slow
def test_every_fmus_version_is_robofmus(fmu_root):
    paths = sorted(fmu_root.glob("*/*.fmu"))
    assert paths
    for path in paths:
        md = read_model_description(str(path), validate=False)
        assert md.version == f"{metadata.version('robofmu')}+{SOURCE_HASH[:12]}", path
        with zipfile.ZipFile(path) as z:
            script = z.read(f"resources/{md.coSimulation.modelIdentifier}.py").decode()
        assert f"robofmu_version = {metadata.version('robofmu')!r}" in script, path


@pytest.mark.slow
def test_the_build_writes_the_metadatas_version_not_one_of_its_own(tmp_path, monkeypatch):
    """Another package version (as after a bump in pyproject.toml) is the built FMU's."""
    monkeypatch.setattr(build, "robofmu_version", lambda: "7.6.5rc4")
    (path,) = build.build("chess", tmp_path, blocks=["controller"], log=lambda *_: None)
    assert read_model_description(str(path), validate=False).version == f"7.6.5rc4+{SOURCE_HASH[:12]}"


def test_a_slave_outside_a_fmu_has_the_installed_version():
    cls = type("robofmu_chess_controller_probe", (BlockSlave,), {"robot_name": "chess", "block_kind": "controller"})
    assert cls(instance_name="c").version == f"{metadata.version('robofmu')}+{SOURCE_HASH[:12]}"
    cls.robofmu_version = "1.2.3"
    assert cls(instance_name="c").version == f"1.2.3+{SOURCE_HASH[:12]}"

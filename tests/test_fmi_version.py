"""robofmu's version is written once, in pyproject.toml (the package metadata), and reaches the FMUs.

The build writes ``importlib.metadata.version("robofmu")`` into each FMU's generated script
(``robofmu_version``: where a FMU runs robofmu need not be installed); the slave makes the model
description's ``version`` of it, the bundled code's hash and the hash of the robot data the FMU
carries: ``<version>+<code hash 12>.<robot data hash 8>``.
"""
from __future__ import annotations

import pytest

import tomllib
import zipfile
from importlib import metadata
from pathlib import Path

from fmpy import read_model_description

from robofmu.components import SOURCE_HASH, robot_data_hash
from robofmu.components.fmi.base import BlockSlave
from robofmu.components.robots import load_description
from robofmu.system.packaging import build

ROOT = Path(__file__).resolve().parents[1]


def local(robot: str) -> str:
    """The local part of a FMU's version for a package robot: code hash, robot data hash."""
    description = load_description(robot)
    return f"{SOURCE_HASH[:12]}.{robot_data_hash(description.path, description.urdf, description.tables)[:8]}"


def test_the_package_metadata_is_pyprojects_version():
    declared = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    assert metadata.version("robofmu") == declared == build.robofmu_version()


@pytest.mark.slow
def test_every_fmus_version_is_robofmus(fmu_root):
    paths = sorted(fmu_root.glob("*/*.fmu"))
    assert paths
    for path in paths:
        md = read_model_description(str(path), validate=False)
        assert md.version == f"{metadata.version('robofmu')}+{local(path.parent.name)}", path
        with zipfile.ZipFile(path) as z:
            script = z.read(f"resources/{md.coSimulation.modelIdentifier}.py").decode()
        assert f"robofmu_version = {metadata.version('robofmu')!r}" in script, path


@pytest.mark.slow
def test_the_build_writes_the_metadatas_version_not_one_of_its_own(tmp_path, monkeypatch):
    """Another package version (as after a bump in pyproject.toml) is the built FMU's."""
    monkeypatch.setattr(build, "robofmu_version", lambda: "7.6.5rc4")
    (path,) = build.build("chess", tmp_path, blocks=["controller"], log=lambda *_: None)
    assert read_model_description(str(path), validate=False).version == f"7.6.5rc4+{local('chess')}"


def test_a_slave_outside_a_fmu_has_the_installed_version():
    cls = type("robofmu_chess_controller_probe", (BlockSlave,), {"robot_name": "chess", "block_kind": "controller"})
    assert cls(instance_name="c").version == f"{metadata.version('robofmu')}+{local('chess')}"
    cls.robofmu_version = "1.2.3"
    assert cls(instance_name="c").version == f"1.2.3+{local('chess')}"


def test_the_version_follows_the_robots_data_not_another_robots(tmp_path):
    """Two robots of the same code differ in the robot data part of their version only; a change
    of one robot's TOML changes its FMU's version and no other's."""
    from robofmu.components.fmi.base import fmu_version

    chess, rrp = load_description("chess"), load_description("rrp")
    a = fmu_version("1.0", robot_data_hash(chess.path, chess.urdf))
    b = fmu_version("1.0", robot_data_hash(rrp.path, rrp.urdf))
    assert a.split(".")[:-1] == b.split(".")[:-1] and a != b
    changed = tmp_path / "chess.toml"
    changed.write_text(chess.path.read_text() + "\n# a comment is a change of the data\n")
    assert fmu_version("1.0", robot_data_hash(changed, chess.urdf)) != a

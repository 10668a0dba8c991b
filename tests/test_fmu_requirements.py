"""The FMUs declare what they need: resources/requirements.txt (read by `pythonfmu deploy`) and
the Python version, in the model description."""
from __future__ import annotations

import sys
import xml.etree.ElementTree as ET
import zipfile

import pytest
from pythonfmu import deploy

from fmu_util import robot_blocks


@pytest.mark.parametrize("robot, kind", robot_blocks())
def test_fmu_declares_its_requirements_and_python(fmu_root, robot, kind, monkeypatch):
    path = fmu_root / robot / f"{kind}.fmu"
    with zipfile.ZipFile(path) as archive:
        lines = archive.read("resources/requirements.txt").decode().split()
        root = ET.fromstring(archive.read("modelDescription.xml"))
    assert [line.split(">")[0].split("=")[0] for line in lines] == ["numpy", "pin", "pythonfmu"]
    assert "pythonfmu==0.7.0" in lines
    block = root.find("VendorAnnotations/Tool[@name='robofmu']/Block")
    python = f"{sys.version_info.major}.{sys.version_info.minor}"
    assert block.get("python") == python and block.get("requirements") == "resources/requirements.txt"
    assert f"Runs in Python {python} with the packages of resources/requirements.txt" in root.get("description")
    # pythonfmu deploy finds the file and hands it to pip (the install itself is not run here)
    calls = []
    monkeypatch.setattr(deploy.subprocess, "run", lambda args, **kw: calls.append(args))
    deploy.deploy(path)
    assert calls and "pip" in " ".join(map(str, calls[0])) and any("requirements" in str(a) for a in calls[0])

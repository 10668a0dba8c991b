"""Robot description files for tests: real descriptions copied to a folder, one key edited.

A copy is read with tomllib, edited, and written back by :func:`dump_toml`; the fixture
``copy_robot`` (tests/conftest.py) is :func:`robot_copier` of the test's ``tmp_path``.
"""
from __future__ import annotations

import json
import math
import re
import shutil
import tomllib

import pytest

from robofmu.components.robots import ROBOTS_DIR, DescriptionError
from robofmu.components.robots.description import read


# -- writing TOML ----------------------------------------------------------------------------------
def _key(k: str) -> str:
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else json.dumps(k)


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        return repr(v) if math.isfinite(v) else ("inf" if v > 0 else "-inf")
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(f"cannot write {v!r} as TOML")


def dump_toml(data: dict, prefix: str = "") -> str:
    """``data`` as TOML: scalars and arrays first, then one ``[table]`` per sub-table."""
    lines = [f"{_key(k)} = {_value(v)}" for k, v in data.items() if not isinstance(v, dict)]
    for k, v in data.items():
        if isinstance(v, dict):
            name = f"{prefix}{_key(k)}"
            lines += ["", f"[{name}]", dump_toml(v, name + ".")]
    return "\n".join(lines) + "\n"


def _parent(data: dict, dotted: str):
    *path, last = dotted.split(".")
    for k in path:
        data = data[k]
    return data, last


def set_key(data: dict, dotted: str, value) -> None:
    parent, last = _parent(data, dotted)
    parent[last] = value


def del_key(data: dict, dotted: str) -> None:
    parent, last = _parent(data, dotted)
    del parent[last]


def robot_copier(tmp_path):
    """``copy_robot(robot, edit=None, stem=None)``: the robot's folder copied to tmp_path, its TOML
    rewritten after ``edit(data)`` as ``<stem>.toml`` (default the robot's name); returns the path."""
    def make(robot: str, edit=None, stem: str | None = None):
        folder = tmp_path / robot
        if not folder.exists():
            shutil.copytree(ROBOTS_DIR / robot, folder, ignore=shutil.ignore_patterns("*.toml", "__pycache__"))
        data = tomllib.loads((ROBOTS_DIR / robot / f"{robot}.toml").read_text())
        if edit is not None:
            edit(data)
        path = folder / f"{stem or robot}.toml"
        path.write_text(dump_toml(data))
        return path
    return make


def refusal(path, key: str) -> str:
    """The DescriptionError of reading ``path``, checked to name the file and ``key``."""
    with pytest.raises(DescriptionError) as info:
        read(path)
    exc = info.value
    assert exc.key == key, str(exc)
    assert exc.path == path
    text = str(exc)
    assert text.startswith(f"{path}: {key}: "), text
    return text


def independent_model(robot: str):
    """Pinocchio's model of a URDF robot's file, built here and not through the robot model: its
    locked joints removed by hand (``pin.buildReducedModel`` at their values). Returns the model
    and the id of the task frame."""
    import pinocchio as pin

    from robofmu.components.robots import load_description

    description = load_description(robot)
    model = pin.buildModelFromUrdf(str(description.urdf))
    if description.locked:
        reference = pin.neutral(model)
        ids = [model.getJointId(name) for name in description.locked]
        for j, value in zip(ids, description.locked.values()):
            reference[model.joints[j].idx_q] = value
        model = pin.buildReducedModel(model, ids, reference)
    return model, model.getFrameId(description.task.frame)

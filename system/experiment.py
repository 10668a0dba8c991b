"""Named experiments: declarative TOML files under ``system/experiments/``.

An experiment file either describes a whole diagram (blocks, connections, timing) or names a
``base`` diagram and sets block parameters (``[parameters.<block>]``). A string parameter value
``"robot:gains.pid.kp"`` is read from the robot's description, so the seed's gains and the pawn's
mass live in one place.
"""
from __future__ import annotations

import tomllib
from pathlib import Path

from robofmu.components.robot import load_spec

from .diagram import System

EXPERIMENTS_DIR = Path(__file__).resolve().parent / "experiments"


def available() -> list[str]:
    """Names of the runnable experiments (diagram-only bases excluded)."""
    names = []
    for p in sorted(EXPERIMENTS_DIR.glob("*.toml")):
        if "base" in tomllib.loads(p.read_text()):
            names.append(p.stem)
    return names


def _path(name_or_path: str | Path) -> Path:
    p = Path(name_or_path)
    if p.suffix == ".toml" and p.is_file():
        return p
    candidate = EXPERIMENTS_DIR / f"{name_or_path}.toml"
    if candidate.is_file():
        return candidate
    raise ValueError(f"unknown experiment {str(name_or_path)!r}; available: {', '.join(available())}")


def _resolve(value, robot: str | None, where: str):
    if isinstance(value, str) and value.startswith("robot:"):
        if robot is None:
            raise ValueError(f"{where}: {value!r} needs a `robot` in the experiment")
        node = load_spec(robot).raw
        for key in value[len("robot:"):].split("."):
            if not isinstance(node, dict) or key not in node:
                raise ValueError(f"{where}: {value!r}: robot {robot!r} has no {key!r}")
            node = node[key]
        return node
    return value


def load(name_or_path: str | Path, fmu_dir: str | Path | None = None) -> System:
    """The :class:`System` of an experiment (by name or TOML path)."""
    path = _path(name_or_path)
    data = tomllib.loads(path.read_text())
    if "base" in data:
        base = tomllib.loads(_path(path.parent / f"{data['base']}.toml").read_text())
        overrides = data.pop("parameters", {})
        data.pop("base")
        merged = {**base, **data}
        blocks = [dict(b, parameters=dict(b.get("parameters", {}))) for b in base["blocks"]]
        names = [b["name"] for b in blocks]
        for block, params in overrides.items():
            if block not in names:
                raise ValueError(f"{path}: parameters for unknown block {block!r} (blocks: {', '.join(names)})")
            blocks[names.index(block)]["parameters"].update(params)
        merged["blocks"] = blocks
        data = merged
    robot = data.get("robot")
    for b in data["blocks"]:
        b["parameters"] = {k: _resolve(v, robot, f"{path.name}: {b['name']}.{k}")
                           for k, v in b.get("parameters", {}).items()}
    return System.from_dict(data, fmu_dir)

"""Named experiments: declarative TOML files under ``system/experiments/``.

An experiment file either describes a whole diagram (blocks, connections, timing, the robot and
the signal roles) or names a ``base`` diagram and sets block parameters
(``[parameters.<block>]``). A string parameter value ``"robot:gains.pid.kp"`` is read from the
robot's typed description (``gains.pid.kp``, ``payload.mass``, ``configurations.home``), so
the seed's gains and the pawn's mass live in one place.

``[roles]`` names the signals analysis and plots need, by what they mean: ``q`` (measured joint
positions), ``q_ref`` (joint reference), ``tau`` (joint efforts), and where the diagram has them
``x_ref`` (task reference) and ``grip`` (gripper). Nothing else in ``system/`` knows instance
names.
"""
from __future__ import annotations

import tomllib
from pathlib import Path

from robofmu.components.robots import load_description

from .diagram import System

EXPERIMENTS_DIR = Path(__file__).resolve().parent / "experiments"


#: Roles an experiment may name, and what each means.
ROLES = {"q": "measured joint positions", "qd": "measured joint velocities",
         "q_ref": "joint position reference", "tau": "joint efforts",
         "x_ref": "task-space reference", "grip": "gripper closed"}


def available() -> list[str]:
    """Names of the runnable experiments (bases that only hold a diagram are excluded)."""
    names = []
    for p in sorted(EXPERIMENTS_DIR.glob("*.toml")):
        if not tomllib.loads(p.read_text()).get("abstract", False):
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
        node = load_description(robot)
        for key in value[len("robot:"):].split("."):
            if isinstance(node, dict) and key in node:
                node = node[key]
            elif not isinstance(node, dict) and not key.startswith("_") and hasattr(node, key):
                node = getattr(node, key)
            else:
                raise ValueError(f"{where}: {value!r}: robot {robot!r} has no {key!r}")
        if isinstance(node, tuple):
            return list(node)
        if not isinstance(node, (int, float, str, list)):
            raise ValueError(f"{where}: {value!r} names a table of robot {robot!r}, not a value")
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
    if robot is not None:
        load_description(robot)          # an unknown robot fails here, naming the known ones
    roles = data.get("roles", {})
    unknown = sorted(set(roles) - set(ROLES))
    if unknown:
        raise ValueError(f"{path}: roles: unknown role {unknown[0]!r} (known: {', '.join(ROLES)})")
    data.pop("abstract", None)
    for b in data["blocks"]:
        b["parameters"] = {k: _resolve(v, robot, f"{path.name}: {b['name']}.{k}")
                           for k, v in b.get("parameters", {}).items()}
    return System.from_dict(data, fmu_dir)

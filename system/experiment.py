"""Named experiments: declarative TOML files under ``system/experiments/``.

An experiment file either describes a whole diagram (blocks, connections, timing, the robot and
the signal roles) or names a ``base`` diagram and sets block parameters
(``[parameters.<block>]``). A base is looked for beside the file first, then among the packaged
experiments, so a user's file anywhere can build on a packaged diagram; a base may have a base
of its own. A string parameter value ``"robot:gains.pid.kp"`` is read from the robot's typed
description (``gains.pid.kp``, ``payload.mass``, ``configurations.home``), so the seed's gains
and the pawn's mass live in one place. ``robot`` names a robot of the package, or a robot TOML
file by its path (``"myarm/myarm.toml"``: relative to the experiment file that says so; the
loaded System holds it as an absolute path). FMU paths are relative to the FMU folder (the
file's ``fmu_dir``, else ``fmus``, relative to the working folder; ``--fmus`` overrides).

``[roles]`` names the signals analysis and plots need, by what they mean: ``q`` (measured joint
positions), ``q_ref`` (joint reference), ``tau`` (joint efforts), and where the diagram has them
``x_ref`` (task reference), ``x`` (measured task coordinates, e.g. a plant's pose output) and
``grip`` (gripper). Nothing else in ``system/`` knows instance names.

**The short form.** ``loop = "computed-torque"`` derives the diagram from the robot instead of
listing it: ``robot``, ``loop``, ``stop_time`` and ``step`` are a whole experiment (``name``
defaults to the file's stem). The blocks are the robot's (``<robot>/<block>.fmu``, its
``blocks`` in order; ``trajectory = "<profile>"`` takes ``<robot>/trajectory_<profile>.fmu``),
less a block whose outputs the trajectory already gives (the IK under a joint-space profile).
Each input is wired from the one other block with an output of the same name (``ik.q_ref ->
controller.q_ref``, ``plant.q -> fk.q``, ``trajectory.grip -> plant.grip``); an input no block
gives is held at its declared start value, set as a parameter (a plant's ``f_ext``). The
controller starts with the robot's ``default_gains`` (``"robot:gains.<set>.kp"``, ...) and, for a
robot with a payload, ``payload_mass = "robot:payload.mass"``. Each role is the wired signal of its
name (``q``, ``qd``, ``q_ref``, ``tau``, ``x_ref``, ``quat_ref``, ``grip``); ``x`` is the plant's
pose output where it has one. The ports are read from the blocks' declared variables, so nothing
here knows a robot. What the file also gives overrides: a ``[[blocks]]`` table replaces the
derived block of its name as written (or adds a block), and one without ``fmu`` amends the derived
block of its name: its ``sample_time`` and ``parameters`` set over the derived ones (``[[blocks]]
name = "controller"  sample_time = 0.004``); ``connections`` are added, each replacing
the derived wiring of the input it drives (the whole vector); a ``[roles]`` entry replaces that
role; ``[parameters.<block>]`` sets parameters of the derived blocks. A file with a ``loop`` may
be a ``base``; a ``loop`` and a ``base`` in one file are refused.

A file that cannot be used is refused with an :class:`ExperimentError` (a ValueError) in one
line naming the file and the key: a TOML syntax error (with its line), a missing ``name``,
``blocks`` or block ``name`` / ``fmu``, a value of the wrong type, an unknown key, a base that
does not exist, an unknown loop or profile, an input two blocks could drive.
"""
from __future__ import annotations

import math
import os
import tomllib
from dataclasses import dataclass
from pathlib import Path

from robofmu.components.blocks import block_type
from robofmu.components.robots import RobotDescription, is_robot_file, load_description, load_model
from robofmu.components.robots.description import PROFILE_PREFIX
from robofmu.components.unknown_names import unknown_key

from robofmu.system import defaults
from robofmu.system.diagram import System, Wire, expand, parameter_address

EXPERIMENTS_DIR = Path(__file__).resolve().parent / "experiments"
#: The ``BLOCK.PARAM`` name of a block's sample time in an override (:func:`with_parameters`).
SAMPLE_TIME = "sample_time"


#: Roles an experiment may name, and what each means.
ROLES = {"q": "measured joint positions", "qd": "measured joint velocities",
         "q_ref": "joint position reference", "tau": "joint efforts",
         "x_ref": "task-space reference", "x": "measured task coordinates (a plant's pose output)",
         "quat_ref": "a pose task's orientation reference (unit quaternion x, y, z, w)",
         "grip": "gripper closed"}

#: Loops an experiment may derive (``loop = "..."``), and what each is.
LOOPS = {"computed-torque": "the robot's blocks: trajectory -> (ik ->) controller <-> plant, "
                            "fk and jacobian on the plant's q"}

#: Top-level keys of an experiment file, and what each must hold.
KEYS = {"name": "a string (the experiment's name)",
        "description": "a string",
        "robot": "a string (a robot of the package, or the path of a robot TOML relative to this file)",
        "stop_time": "a time in s > 0",
        "step": "a communication step in s > 0",
        "algorithm": " or ".join(repr(a) for a in defaults.ALGORITHMS),
        "blocks": "an array of [[blocks]] tables (name, fmu, parameters)",
        "connections": "an array of strings 'block.variable -> block.variable'",
        "roles": "a table of role = 'block.variable'",
        "fmu_dir": "a string (folder of the FMUs)",
        "abstract": "true or false (a base only, not listed as runnable)",
        "base": "a string (the name of the experiment this one builds on)",
        "parameters": "a table of [parameters.<block>] tables",
        "loop": " or ".join(repr(k) for k in LOOPS) + " (the diagram derived from the robot)",
        "trajectory": "a string (a named profile of the robot, [trajectories.<name>], for the loop)"}

#: Keys of one ``[[blocks]]`` table.
BLOCK_KEYS = {"name": "the instance name, a string",
              "fmu": "the FMU file relative to the FMU folder, a string",
              "parameters": "a table of parameter = value",
              "sample_time": "the block's sample time in s > 0, a whole multiple of the step (default: the step)"}


class ExperimentError(ValueError):
    """An experiment file that cannot be used; the message is one line naming the file and key.

    Attributes
    ----------
    path : Path or None
        The file (None: an unknown experiment name).
    key : str or None
        The key at fault (``"blocks[2].fmu"``), where there is one.
    """

    def __init__(self, path: Path | None, key: str | None, message: str):
        where = [str(path)] if path is not None else []
        where += [key] if key else []
        super().__init__(": ".join(where + [message]))
        self.path = path
        self.key = key


def _is_base(path: Path) -> bool:
    try:
        return bool(tomllib.loads(path.read_text()).get("abstract", False))
    except (OSError, ValueError):
        return False


def available() -> list[str]:
    """Names of the runnable experiments, sorted by name (a name before its variants:
    ``a``, ``a-b``); bases that only hold a diagram are excluded."""
    return sorted(p.stem for p in EXPERIMENTS_DIR.glob("*.toml") if not _is_base(p))


def _path(name_or_path: str | Path) -> Path:
    """The file of an experiment given by name (packaged) or path; ExperimentError if none."""
    p = Path(name_or_path)
    text = str(name_or_path)
    if p.suffix == ".toml" or "/" in text or "\\" in text:
        if p.is_file():
            return p
        if p.is_dir():
            raise ExperimentError(p, None, "is a folder, not an experiment file")
        if p.name == text and (EXPERIMENTS_DIR / p.name).is_file():
            return EXPERIMENTS_DIR / p.name          # `chess-pd.toml` for the packaged `chess-pd`
        raise ExperimentError(p, None, "no such experiment file")
    candidate = EXPERIMENTS_DIR / f"{text}.toml"
    if candidate.is_file():
        return candidate
    raise ExperimentError(None, None, f"unknown experiment {text!r}; available: {', '.join(available())}")


def _read(path: Path) -> dict:
    """The TOML table of ``path``; ExperimentError naming the file (and the line) otherwise."""
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise ExperimentError(path, None, f"not UTF-8 text (byte {exc.start})") from None
    except OSError as exc:
        raise ExperimentError(path, None, f"cannot read it: {exc.strerror or exc}") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        message = str(exc)
        if "(at end of document)" in message:
            message = message.replace("(at end of document)",
                                      f"(at line {max(1, text.count(chr(10)) + 1)}, the end of the file)")
        raise ExperimentError(path, None, f"invalid TOML: {message}") from None


def _kind(value) -> str:
    """What a TOML value is, for messages."""
    return {bool: "a boolean", int: "an integer", float: "a number", str: "a string", list: "an array",
            dict: "a table"}.get(type(value), type(value).__name__)


def _wrong(path: Path, key: str, expected: str, value) -> ExperimentError:
    return ExperimentError(path, key, f"must be {expected}, got {value!r} ({_kind(value)})"
                           if not isinstance(value, (dict, list)) else f"must be {expected}, got {_kind(value)}")


def _unknown(path: Path, key: str, known, where: str = "") -> ExperimentError:
    return ExperimentError(path, f"{where}{key}", unknown_key(key, known))


def _check_file(path: Path, data: dict) -> None:
    """Keys and types of one experiment file as written (before its base is merged)."""
    for key in data:
        if key not in KEYS:
            raise _unknown(path, key, KEYS)
    if "name" not in data and "loop" not in data:
        raise ExperimentError(path, "name", "missing key: every experiment file names its experiment "
                                            "(name = \"...\")")
    if "loop" in data:
        if not isinstance(data["loop"], str) or data["loop"] not in LOOPS:
            raise _wrong(path, "loop", KEYS["loop"], data["loop"])
        if "base" in data:
            raise ExperimentError(path, "loop", "a file with a `base` takes the base's diagram; give "
                                                "either `base` or `loop`")
        if "robot" not in data:
            raise ExperimentError(path, "robot", "missing key: `loop` derives the diagram from the robot "
                                                 "(robot = \"NAME\" or \"path/NAME.toml\")")
    elif "trajectory" in data:
        raise ExperimentError(path, "trajectory", "picks the profile of a derived loop; it needs "
                                                  "loop = \"computed-torque\"")
    for key in ("name", "description", "robot", "fmu_dir", "base", "trajectory"):
        if key in data and not (isinstance(data[key], str) and (data[key].strip() or key == "description")):
            raise _wrong(path, key, "a non-empty string" if key != "description" else "a string", data[key])
    for key in ("stop_time", "step"):
        if key in data:
            value = data[key]
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                    or value <= 0:
                raise _wrong(path, key, KEYS[key], value)
    if "algorithm" in data and data["algorithm"] not in defaults.ALGORITHMS:
        raise _wrong(path, "algorithm", KEYS["algorithm"], data["algorithm"])
    if "abstract" in data and not isinstance(data["abstract"], bool):
        raise _wrong(path, "abstract", KEYS["abstract"], data["abstract"])
    if "blocks" in data:
        if "base" in data:
            raise ExperimentError(path, "blocks", "a file with a `base` takes the base's blocks; set their "
                                                  "parameters in [parameters.<block>] tables")
        blocks = data["blocks"]
        if not isinstance(blocks, list) or not blocks:
            raise _wrong(path, "blocks", KEYS["blocks"] + ", at least one", blocks)
        names = set()
        for k, block in enumerate(blocks, 1):
            where = f"blocks[{k}]"
            if not isinstance(block, dict):
                raise _wrong(path, where, "a [[blocks]] table", block)
            for key in block:
                if key not in BLOCK_KEYS:
                    raise _unknown(path, key, BLOCK_KEYS, where=f"{where}.")
            for key in ("name", "fmu"):
                if key == "fmu" and "fmu" not in block and "loop" in data:
                    continue                     # sets sample_time / parameters of a derived block
                if key not in block:
                    label = f" ({block['name']!r})" if isinstance(block.get("name"), str) else ""
                    raise ExperimentError(path, f"{where}.{key}", f"missing key in block {k}{label}: "
                                                                  f"{key}, {BLOCK_KEYS[key]}")
                if not isinstance(block[key], str) or not block[key].strip():
                    raise _wrong(path, f"{where}.{key}", "a non-empty string", block[key])
            if block["name"] in names:
                raise ExperimentError(path, f"{where}.name", f"instance name {block['name']!r} is used twice")
            names.add(block["name"])
            if "parameters" in block and not isinstance(block["parameters"], dict):
                raise _wrong(path, f"{where}.parameters", BLOCK_KEYS["parameters"], block["parameters"])
            if "sample_time" in block:
                value = block["sample_time"]
                if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                        or value <= 0:
                    raise _wrong(path, f"{where}.sample_time", "a time in s > 0", value)
    if "connections" in data:
        wires = data["connections"]
        if not isinstance(wires, list):
            raise _wrong(path, "connections", KEYS["connections"], wires)
        for k, wire in enumerate(wires, 1):
            if not isinstance(wire, str):
                raise _wrong(path, f"connections[{k}]", "a string 'block.variable -> block.variable'", wire)
            try:
                Wire.parse(wire)
            except ValueError as exc:
                raise ExperimentError(path, f"connections[{k}]", str(exc)) from None
    if "roles" in data:
        roles = data["roles"]
        if not isinstance(roles, dict):
            raise _wrong(path, "roles", KEYS["roles"], roles)
        for role, signal in roles.items():
            if role not in ROLES:
                raise ExperimentError(path, "roles", f"unknown role {role!r} (known: {', '.join(ROLES)})")
            if not isinstance(signal, str) or "." not in signal:
                raise _wrong(path, f"roles.{role}", "a string 'block.variable'", signal)
    if "parameters" in data:
        if "base" not in data and "loop" not in data:
            raise ExperimentError(path, "parameters", "[parameters.<block>] tables need a `base` or a `loop`; "
                                                      "without one, set a block's parameters in its [[blocks]] "
                                                      "table")
        tables = data["parameters"]
        if not isinstance(tables, dict):
            raise _wrong(path, "parameters", KEYS["parameters"], tables)
        for block, values in tables.items():
            if not isinstance(values, dict):
                raise _wrong(path, f"parameters.{block}", "a table of parameter = value", values)


def _base_path(path: Path, base: str) -> Path:
    """The file of ``base`` named in ``path``: beside it, else among the packaged experiments."""
    name = base[:-len(".toml")] if base.endswith(".toml") else base
    for folder in (path.parent, EXPERIMENTS_DIR):
        candidate = folder / f"{name}.toml"
        if candidate.is_file():
            return candidate
    bases = sorted(p.stem for p in EXPERIMENTS_DIR.glob("*.toml"))
    raise ExperimentError(path, "base", f"no experiment {base!r}: neither {path.parent / (name + '.toml')} "
                                        f"nor a packaged one (packaged: {', '.join(bases)})")


def _merged(path: Path, seen: tuple[Path, ...] = ()) -> dict:
    """The checked content of ``path`` with its base (recursively) merged in."""
    if path.resolve() in seen:
        chain = " -> ".join(p.stem for p in (*seen, path.resolve()))
        raise ExperimentError(path, "base", f"the bases form a cycle: {chain}")
    data = _read(path)
    _check_file(path, data)
    if isinstance(data.get("robot"), str) and is_robot_file(data["robot"]):     # relative to this file
        data["robot"] = os.path.abspath(path.parent / os.path.expanduser(data["robot"]))
    if "base" in data:
        base = _merged(_base_path(path, data["base"]), (*seen, path.resolve()))
        overrides = data.pop("parameters", {})
        data.pop("base")
        merged = {**base, **data}
        blocks = [dict(b, parameters=dict(b.get("parameters", {}))) for b in base["blocks"]]
        names = [b["name"] for b in blocks]
        for block, params in overrides.items():
            if block not in names:
                raise ExperimentError(path, f"parameters.{block}",
                                      f"parameters for unknown block {block!r} (blocks: {', '.join(names)})")
            blocks[names.index(block)]["parameters"].update(params)
        merged["blocks"] = blocks
        if "abstract" not in data:
            merged.pop("abstract", None)
        data = merged
    elif "loop" in data:
        data = _with_loop(path, data)
    elif "blocks" not in data:
        raise ExperimentError(path, "blocks", "missing key: the experiment needs [[blocks]] tables (name, "
                                              "fmu, parameters), or a `base` to take them from")
    return data


# -- the short form: a loop derived from the robot's blocks ------------------------------------------
@dataclass(frozen=True)
class _Ports:
    """One derived block's FMU and declared ports (vector bases in declaration order)."""

    fmu: str
    inputs: dict                 # base -> start value (a list for a vector, a scalar otherwise)
    booleans: frozenset          # the Boolean inputs' bases
    outputs: tuple
    parameters: frozenset


def _ports(description, fmu_block: str) -> _Ports:
    """The ports ``fmu_block`` (a block or ``trajectory_<profile>``) of the robot declares."""
    kind, _, described = description.block_of(fmu_block)
    variables = block_type(described, kind)(load_model(described)).variables
    starts: dict = {}
    for v in variables:
        if v.causality == "input":
            starts.setdefault(v.base, []).append(v.start)
    vectors = {v.base for v in variables if v.name != v.base}
    return _Ports(fmu=f"{description.name}/{fmu_block}.fmu",
                  inputs={b: s if b in vectors else s[0] for b, s in starts.items()},
                  booleans=frozenset(v.base for v in variables if v.causality == "input" and v.kind == "Boolean"),
                  outputs=tuple(dict.fromkeys(v.base for v in variables if v.causality == "output")),
                  parameters=frozenset(v.base for v in variables if v.causality == "parameter"))


def derive_loop(description: RobotDescription, trajectory: str | None = None) -> dict:
    """The computed-torque loop of a robot as an experiment's tables (module docstring).

    Parameters
    ----------
    description : RobotDescription
        The robot (:func:`~robofmu.components.robots.load_description`).
    trajectory : str, optional
        A named profile (``[trajectories.<name>]``); default the robot's ``[trajectory]``.

    Returns
    -------
    dict
        ``blocks`` (list of {name, fmu, parameters}), ``connections`` (list of str) and
        ``roles`` (dict), as an explicit experiment file would give them.

    Raises
    ------
    ValueError
        One line: an unknown profile, a robot without controller and plant, an input two blocks
        could drive.
    """
    missing = [b for b in ("controller", "plant") if b not in description.blocks]
    if missing:
        raise ValueError(f"robot {description.name!r} has no {' or '.join(missing)} block (its blocks: "
                         f"{', '.join(description.blocks)}); the computed-torque loop needs both")
    ports = {kind: _ports(description, f"{PROFILE_PREFIX}{trajectory}" if kind == "trajectory" and trajectory
                          else kind) for kind in description.blocks}         # ValueError naming the profiles
    given = set(ports["trajectory"].outputs) if "trajectory" in ports else set()
    ports = {k: p for k, p in ports.items() if k in ("trajectory", "controller", "plant") or not given & set(p.outputs)}
    names = list(ports)
    found, held = [], {name: {} for name in names}
    for d, (dst, p) in enumerate(ports.items()):
        for i, (base, start) in enumerate(p.inputs.items()):
            sources = [src for src in names if src != dst and base in ports[src].outputs]
            if len(sources) > 1:
                raise ValueError(f"robot {description.name!r}: input {dst}.{base} is an output of "
                                 f"{' and '.join(sources)}; wire it in `connections`")
            if sources:
                found.append((d, i, base in p.booleans, Wire(sources[0], base, dst, base)))
            else:
                held[dst][base] = start
    # the loop's Real signals in block order, then its Boolean events, then the blocks only observing
    read = {wire.src for *_, wire in found}
    found.sort(key=lambda f: (f[3].dst not in read, f[2], f[0], f[1]))
    wires = [wire for *_, wire in found]
    parameters = {name: {} for name in names}
    gains = description.gain_set(description.default_gains).as_dict()
    parameters["controller"] = {k: f"robot:gains.{description.default_gains}.{k}" for k in gains
                                if k in ports["controller"].parameters}
    if description.payload is not None and "payload_mass" in ports["controller"].parameters:
        parameters["controller"]["payload_mass"] = "robot:payload.mass"
    roles = {}
    for role in ROLES:
        source = next((w.src for w in wires if w.src_var == role), None)
        if source is None and role == "x":          # a plant's pose output: the block giving q
            source = next((w.src for w in wires if w.src_var == "q" and "x" in ports[w.src].outputs), None)
        if source is not None:
            roles[role] = f"{source}.{role}"
    return {"blocks": [{"name": n, "fmu": ports[n].fmu, "parameters": {**parameters[n], **held[n]}} for n in names],
            "connections": [str(w) for w in wires], "roles": roles}


def _with_loop(path: Path, data: dict) -> dict:
    """``data`` (a checked file with a ``loop``) with the derived diagram and the file's overrides."""
    try:
        description = load_description(data["robot"])
    except ValueError as exc:
        raise ExperimentError(path, "robot", str(exc)) from None
    profile = data.get("trajectory")
    if profile is not None and profile not in description.profiles:
        raise ExperimentError(path, "trajectory", f"robot {description.name!r} has no profile {profile!r} "
                                                  f"(its named profiles: {', '.join(description.profiles) or 'none'})")
    try:
        derived = derive_loop(description, profile)
    except ValueError as exc:
        raise ExperimentError(path, "loop", str(exc)) from None
    blocks = derived["blocks"]
    own = [Wire.parse(w) for w in data.get("connections", [])]
    driven = {(w.dst, _base(w.dst_var)) for w in own}
    for block in blocks:                                 # an input the file wires is no longer held
        for dst, base in driven:
            if dst == block["name"]:
                block["parameters"].pop(base, None)
    for k, block in enumerate(data.get("blocks", []), 1):  # a block of the file replaces the derived one
        names = [b["name"] for b in blocks]
        if "fmu" not in block:                            # ... or, without `fmu`, amends it
            if block["name"] not in names:
                raise ExperimentError(path, f"blocks[{k}].fmu", f"missing key: {block['name']!r} is no derived "
                                                               f"block (derived: {', '.join(names)}), so it needs "
                                                               "its fmu")
            amended = blocks[names.index(block["name"])]
            amended["parameters"] = {**amended["parameters"], **block.get("parameters", {})}
            if "sample_time" in block:
                amended["sample_time"] = block["sample_time"]
        elif block["name"] in names:
            blocks[names.index(block["name"])] = block
        else:
            blocks.append(block)
    names = [b["name"] for b in blocks]
    for block, params in data.pop("parameters", {}).items():
        if block not in names:
            raise ExperimentError(path, f"parameters.{block}",
                                  f"parameters for unknown block {block!r} (blocks: {', '.join(names)})")
        blocks[names.index(block)]["parameters"] = {**blocks[names.index(block)].get("parameters", {}), **params}
    wires = [w for w in derived["connections"] if (Wire.parse(w).dst, Wire.parse(w).dst_var) not in driven]
    data["connections"] = wires + [str(w) for w in own]
    data["roles"] = {**derived["roles"], **data.get("roles", {})}
    data["blocks"] = blocks
    data.setdefault("name", path.stem)
    data.pop("loop")
    data.pop("trajectory", None)
    return data


def _base(variable: str) -> str:
    """``tau`` of ``tau[2]`` (a matrix entry ``J[1,2]``: ``J``)."""
    return variable.split("[", 1)[0]


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
    """The :class:`System` of an experiment (by name or TOML path).

    Parameters
    ----------
    name_or_path : str or Path
        A packaged experiment's name (``available()``) or an experiment file.
    fmu_dir : str or Path, optional
        FMU folder (default: the file's ``fmu_dir``, else ``fmus``).

    Returns
    -------
    System
        With :attr:`~robofmu.system.diagram.System.source` the experiment's file.

    Raises
    ------
    ExperimentError
        One line naming the file and the key: unknown experiment, unreadable file, TOML syntax
        error (with its line), missing or unknown key, a value of the wrong type, a base that
        does not exist, an unknown robot or role.
    """
    path = _path(name_or_path)
    data = _merged(path)
    robot = data.get("robot")
    if robot is not None:
        try:
            load_description(robot)          # an unknown robot fails here, naming the known ones
        except ValueError as exc:
            raise ExperimentError(path, "robot", str(exc)) from None
    data.pop("abstract", None)
    for b in data["blocks"]:
        try:
            b["parameters"] = {k: _resolve(v, robot, f"{b['name']}.{k}")
                               for k, v in b.get("parameters", {}).items()}
        except ValueError as exc:
            raise ExperimentError(path, None, str(exc)) from None
    try:
        system = System.from_dict(data, fmu_dir)
    except ValueError as exc:
        raise ExperimentError(path, None, str(exc)) from None
    system.source = path
    return system


def with_parameters(system: System, values: dict) -> System:
    """A copy of ``system`` with block parameters set, ``{"controller.kp": 400.0, ...}``: the one
    override of an experiment (``robofmu run --set``, a sweep's ``--vary``).

    ``BLOCK.sample_time`` (:data:`SAMPLE_TIME`) sets the block's sample time in s, as ``[[blocks]]
    sample_time`` does, not a FMU parameter. One number for a vector parameter
    (``plant.friction``) sets every element; ``plant.friction[2]`` sets one.

    Raises
    ------
    ValueError
        Naming the entry, for a name that is not ``BLOCK.PARAM`` or names no block of the
        experiment, or a sample time that is no number > 0. (An unknown parameter, a value of the
        wrong type, a sample time that is no whole multiple of the step, is refused when the
        diagram is planned: :meth:`robofmu.system.master.Master.check`.)
    """
    import copy

    configured = copy.deepcopy(system)
    names = [b.name for b in configured.blocks]
    for name, value in values.items():
        try:
            block, parameter = parameter_address(name)
        except ValueError:
            raise ValueError(f"{name}: expected BLOCK.PARAM (e.g. controller.kp)") from None
        if block not in names:
            raise ValueError(f"{name}: no block {block!r} in {system.name} (blocks: {', '.join(names)})")
        if parameter == SAMPLE_TIME:
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0 \
                    or not math.isfinite(value):
                raise ValueError(f"{name}: must be a time in s > 0, got {value!r}")
            configured.block(block).sample_time = float(value)
        else:
            configured.block(block).parameters[parameter] = spread_over_elements(configured, block, parameter, value)
    return configured


def spread_over_elements(system: System, block: str, parameter: str, value):
    """``value`` as given, or one number for a vector parameter (``plant.friction``: every joint's)
    repeated over its elements, their count read from the block's FMU (as given when unreadable)."""
    if isinstance(value, (list, tuple)):
        return value
    from robofmu.system.plan import described

    path = system.fmu_path(system.block(block))
    model_description = described(path)[1] if Path(path).is_file() else None
    if model_description is None:
        return value
    width = len(expand([v.name for v in model_description.modelVariables], parameter))
    return [value] * width if width > 1 else value

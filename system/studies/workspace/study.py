"""A workspace study file (``kind = "workspace"``, ``system/studies/*.toml`` or any path): its
reader and checks (:func:`read_study`, :func:`study_for`), the memory its grids take, and its
characteristic length."""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path


from robofmu.components.unknown_names import unknown_key
from robofmu.system.studies.tables import STUDIES_DIR
from robofmu.system.studies.workspace.measures import CHUNK, ZOOM_POINTS, Region
from robofmu.system.usage import UsageError, check_memory

#: The vectorized kinematics the analysis needs of a robot model.
REQUIRED = ("fk_many", "ik_many", "jacobian_many", "singular_values_many", "condition_number_many")
#: Largest joint grid (points per joint) the command accepts.
MAX_JOINT_GRID = 1000


@dataclass
class Study:
    path: Path
    robot: str
    title: str
    text: str
    length_spec: object                 # number (m) or [mechanism] parameter name
    length_text: str
    centre: tuple[float, float] | None
    theta: float                        # rad
    grids: dict
    regions: list[Region]
    expected: dict = field(default_factory=dict)
    notes: dict = field(default_factory=dict)


#: The keys of a workspace study file, of its [grids], [expected], [notes] and of each [[regions]].
TOP_KEYS = ("kind", "robot", "title", "text", "characteristic_length", "characteristic_length_text", "centre",
            "theta", "grids", "regions", "expected", "notes")
GRID_KEYS = ("positions", "orientations", "isotropy_positions", "isotropy_orientations", "rays", "ray_orientations",
             "joint", "region")
OPTIONAL_KEYS = {"expected": ("reachable", "reachable_text", "dexterous", "dexterous_text"),
                 "notes": ("full_grid",)}
REGION_KEYS = ("name", "radius", "theta")


def _known(table: dict, known, path: Path, where: str = "") -> None:
    """Refuse the first key of ``table`` that is not ``known`` (a typo would otherwise be a default)."""
    for key in table:
        if key not in known:
            raise UsageError(f"{path}: {where}{key}: {unknown_key(key, known)}")


def _need(table: dict, key: str, kinds, path: Path, where: str = ""):
    name = f"{where}{key}"
    if key not in table:
        raise UsageError(f"{path}: {name}: missing key")
    value = table[key]
    if isinstance(value, bool) or not isinstance(value, kinds):
        raise UsageError(f"{path}: {name}: must be {_kind_text(kinds)}, got {value!r}")
    return value


def _kind_text(kinds) -> str:
    kinds = set(kinds if isinstance(kinds, tuple) else (kinds,))
    if {int, float} <= kinds:
        kinds = (kinds - {int, float}) | {"number"}
    names = {int: "an integer", float: "a number", str: "a string", list: "an array", dict: "a table",
             "number": "a number"}
    return " or ".join(sorted(names[k] for k in kinds))


def read_study(path: str | Path) -> Study:
    """A workspace study file, checked (UsageError naming the file and key)."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise UsageError(f"{path}: no such study file") from None
    except OSError as exc:
        raise UsageError(f"{path}: cannot read it: {exc.strerror or exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise UsageError(f"{path}: invalid TOML: {exc}") from None
    if data.get("kind") != "workspace":
        raise UsageError(f"{path}: kind: must be \"workspace\", got {data.get('kind')!r}")
    _known(data, TOP_KEYS, path)
    grids = _need(data, "grids", dict, path)
    _known(grids, GRID_KEYS, path, "grids.")
    for table in ("expected", "notes"):
        _known(_need(data, table, dict, path) if table in data else {}, OPTIONAL_KEYS[table], path, f"{table}.")
    for key in ("positions", "orientations", "isotropy_positions", "isotropy_orientations", "rays",
                "ray_orientations"):
        if _need(grids, key, int, path, "grids.") < 4:
            raise UsageError(f"{path}: grids.{key}: must be >= 4, got {grids[key]}")
    joint = _need(grids, "joint", list, path, "grids.")
    region = _need(grids, "region", list, path, "grids.")
    for key, values, size in (("joint", joint, None), ("region", region, 3)):
        if not values or (size and len(values) != size) or not all(
                isinstance(v, int) and not isinstance(v, bool) and v >= 2 for v in values):
            raise UsageError(f"{path}: grids.{key}: must be {size or 'some'} whole numbers >= 2, got {values!r}")
    for key, need in grid_memory(grids).items():
        shown = grids[key] if key != "rays" else [grids["rays"], grids["ray_orientations"]]
        check_memory(need, f"{path}: grids.{key} = {shown}", "give a smaller grid")
    length = _need(data, "characteristic_length", (int, float, str), path)
    if not isinstance(length, str) and not (math.isfinite(length) and length > 0):
        raise UsageError(f"{path}: characteristic_length: must be a length > 0 m, got {length!r}")
    regions = []
    for i, entry in enumerate(_need(data, "regions", list, path), start=1):
        where = f"regions[{i}]."
        if not isinstance(entry, dict):
            raise UsageError(f"{path}: regions[{i}]: must be a table, got {entry!r}")
        _known(entry, REGION_KEYS, path, where)
        radius = float(_need(entry, "radius", (int, float), path, where))
        window = _need(entry, "theta", list, path, where)
        if not (len(window) == 2 and all(isinstance(v, (int, float)) for v in window)
                and window[0] < window[1] <= window[0] + 360.0) or not radius > 0:
            raise UsageError(f"{path}: {where}theta/radius: needs radius > 0 and theta = [low, high] deg, "
                             f"low < high <= low + 360, got radius {radius!r}, theta {window!r}")
        regions.append(Region(str(_need(entry, "name", str, path, where)), radius,
                              (math.radians(window[0]), math.radians(window[1]))))
    centre = data.get("centre")
    if centre is not None and not (isinstance(centre, list) and len(centre) == 2
                                   and all(isinstance(v, (int, float)) for v in centre)):
        raise UsageError(f"{path}: centre: must be [x, y] in m, got {centre!r}")
    theta = _need(data, "theta", (int, float), path)
    return Study(path, _need(data, "robot", str, path), data.get("title", f"Workspace of {data['robot']}"),
                 data.get("text", ""), length, data.get("characteristic_length_text", ""),
                 None if centre is None else (float(centre[0]), float(centre[1])), math.radians(theta),
                 dict(grids), regions, dict(data.get("expected", {})), dict(data.get("notes", {})))


#: Bytes held per grid point while a grid is evaluated (bounded above): float64 arrays of the
#: poses, their broadcast copies, masks and results; a joint grid's chunk holds its Jacobians and
#: singular values on up to four threads.
BYTES_PER_POINT, BYTES_PER_CONFIGURATION = 96, 1024


def grid_memory(grids: dict) -> dict[str, int]:
    """Bytes each of a study's grids needs at once (keys of ``[grids]``; ``rays`` covers the rays
    times ``ray_orientations``), so that a grid that cannot fit is refused before it is allocated."""
    r, b, t = grids["region"]
    largest = max(grids["joint"])
    return {"positions": BYTES_PER_POINT * grids["positions"] ** 2,
            "isotropy_positions": BYTES_PER_POINT * grids["isotropy_positions"] ** 2,
            "rays": BYTES_PER_POINT * grids["rays"] * max(grids["ray_orientations"], ZOOM_POINTS),
            "region": BYTES_PER_POINT * r * b * t,
            "joint": BYTES_PER_POINT * largest ** 2 + BYTES_PER_CONFIGURATION * max(CHUNK, largest ** 2)}


def studies() -> dict[str, Path]:
    """The packaged workspace studies by robot."""
    found = {}
    for path in sorted(STUDIES_DIR.glob("*.toml")):
        try:
            data = tomllib.loads(path.read_text())
        except (OSError, tomllib.TOMLDecodeError):
            continue
        if data.get("kind") == "workspace" and isinstance(data.get("robot"), str):
            found.setdefault(data["robot"], path)
    return found


def check_robot(robot: str):
    """The robot's model class if it has the vectorized kinematics; UsageError otherwise."""
    from robofmu.components.robots import available, load_description, model_class

    known = available()
    if robot not in known:
        raise UsageError(f"unknown robot {robot!r}; described robots: {', '.join(known)}")
    description = load_description(robot)
    cls = model_class(description.model_kind)
    missing = [name for name in REQUIRED if not callable(getattr(cls, name, None))]
    if missing:
        raise UsageError(f"robot {robot!r} ({cls.__name__}, a {description.model_kind} model) has no vectorized "
                         f"kinematics ({', '.join(missing)}): the workspace analysis covers robot models "
                         "that provide them, such as the parallel mechanisms")
    return cls


def study_for(robot_or_file: str) -> Study:
    """The study of a robot (the packaged one naming it) or a study file (``*.toml``); the robot
    is checked (:func:`check_robot`)."""
    if robot_or_file.endswith(".toml"):
        study = read_study(robot_or_file)
        try:
            check_robot(study.robot)
        except UsageError as exc:
            raise UsageError(f"{study.path}: robot: {exc}") from None
        return study
    check_robot(robot_or_file)
    found = studies()
    if robot_or_file not in found:
        raise UsageError(f"robot {robot_or_file!r} has no workspace study: add a system/studies/*.toml with "
                         f"kind = \"workspace\" and robot = {robot_or_file!r}, or give a study file"
                         + (f" (studies exist for {', '.join(sorted(found))})" if found else ""))
    return read_study(found[robot_or_file])


def characteristic_length(study: Study, model) -> float:
    """L (m): the study's number, or the named parameter of the robot's ``[mechanism]`` table."""
    spec = study.length_spec
    if isinstance(spec, str):
        mechanism = getattr(model.description, "mechanism", None)
        value = getattr(mechanism, spec, None)
        if not isinstance(value, (int, float)) or isinstance(value, bool) or not value > 0:
            raise UsageError(f"{study.path}: characteristic_length: {spec!r} names no length of robot "
                             f"{study.robot!r}'s [mechanism] table")
        return float(value)
    return float(spec)

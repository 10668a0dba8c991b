"""`robofmu workspace`: reachable and dexterous workspace, orientation range and isotropy of a
robot model with vectorized kinematics (a parallel mechanism).

What is computed (all NumPy-vectorized, chunked so that memory stays bounded):

- **Radii** by bisection along rays from a centre: for a bearing beta and an orientation theta,
  rho*(beta, theta) is the largest distance along the ray at which the pose has an IK solution
  (the feasible set along a ray at fixed theta is taken to be an interval from the centre). The
  reachable radius along the ray is max over theta of rho*, the dexterous one min over theta;
  both extremes are first found on a theta grid, then zoomed into (the maximum is a corner of
  rho*, where the leg that limits the reach changes, so a grid alone converges only linearly).
  The workspace radius is the smallest ray radius (the largest disc about the centre inside the
  workspace); the largest is reported too.
- **Maps** on a pose grid (x, y, theta) through ``ik_many``: reachable (some theta), dexterous
  (every theta of the grid), the orientation range (the measure of the feasible thetas), and the
  local isotropy 1/cond(J) at a chosen theta and at the best theta of a grid.
- **GII** = min sigma_min(J) / max sigma_max(J) over named regions (a disc about the centre and
  an orientation window, sampled on a polar grid through the IK) and over full joint grids
  q_j in [-pi, pi) of N points per joint, with the theta row of J multiplied by a characteristic
  length L (so that every row is in m/rad). On a full joint grid the exact singular values are
  computed only where the cheap bounds from the Frobenius norm F and |det J| (sqrt(F^2/3) <=
  sigma_max <= F, 2 |det| / F^2 <= sigma_min <= |det|^(1/3)) leave a configuration in the
  running the extremes; the result is exact.

The robot-specific choices (centre, orientation, grid sizes, regions, L, expected radii, the
report's text) are a study file ``system/studies/*.toml`` with ``kind = "workspace"``.
"""
from __future__ import annotations

import math
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from robofmu.system.analysis import markdown_table
from robofmu.system.usage import UsageError, check_memory
from robofmu.system.studies.tables import STUDIES_DIR

#: The vectorized kinematics the analysis needs of a robot model.
REQUIRED = ("fk_many", "ik_many", "jacobian_many", "singular_values_many", "condition_number_many")
#: Configurations per vectorized call (bounds the memory: a few tens of MB per chunk).
CHUNK = 1 << 17
#: Largest joint grid (points per joint) the command accepts.
MAX_JOINT_GRID = 1000
#: Bisection stops when the bracket is this small relative to the outer bound.
BISECTION_TOLERANCE = 1e-13
#: Zoom levels about the extreme orientation of each ray, and the points of each level.
ZOOM_LEVELS, ZOOM_POINTS = 6, 21
TWO_PI = 2.0 * math.pi


# -- the study -------------------------------------------------------------------------------------
@dataclass
class Region:
    name: str
    radius: float                       # fraction of the characteristic length
    theta: tuple[float, float]          # rad


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
    grids = _need(data, "grids", dict, path)
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


# -- vectorized building blocks ----------------------------------------------------------------------
def feasible(model, poses: np.ndarray) -> np.ndarray:
    """Whether each pose (..., 3) has an IK solution (the model's default branch), chunked."""
    poses = np.asarray(poses, dtype=float)
    flat = poses.reshape(-1, 3)
    out = np.empty(len(flat), dtype=bool)
    for i in range(0, len(flat), CHUNK):
        out[i:i + CHUNK] = np.isfinite(model.ik_many(flat[i:i + CHUNK])).all(-1)
    return out.reshape(poses.shape[:-1])


def isotropy(model, poses: np.ndarray, length: float) -> np.ndarray:
    """Local isotropy 1/cond(J) (theta row times ``length``) at poses (..., 3) through the IK;
    NaN where unreachable, 0 at an inverse singularity."""
    poses = np.asarray(poses, dtype=float)
    flat = poses.reshape(-1, 3)
    out = np.empty(len(flat))
    with np.errstate(invalid="ignore", divide="ignore"):
        for i in range(0, len(flat), CHUNK):
            q = model.ik_many(flat[i:i + CHUNK])
            out[i:i + CHUNK] = 1.0 / model.condition_number_many(q, length)
    return out.reshape(poses.shape[:-1])


def _poses(centre, rho, beta, theta) -> np.ndarray:
    rho, beta, theta = np.broadcast_arrays(rho, beta, theta)
    return np.stack([centre[0] + rho * np.cos(beta), centre[1] + rho * np.sin(beta), theta], axis=-1)


def ray_reach(model, centre, beta: np.ndarray, theta: np.ndarray, outer: float) -> np.ndarray:
    """rho*(beta, theta): the largest feasible distance along each ray (arrays broadcast), by
    bisection on [0, outer]; 0 where the centre itself is infeasible at theta."""
    beta, theta = np.broadcast_arrays(np.asarray(beta, float), np.asarray(theta, float))
    lo = np.zeros(beta.shape)
    hi = np.full(beta.shape, float(outer))
    inside = feasible(model, _poses(centre, lo, beta, theta))
    while np.max(hi - lo) > BISECTION_TOLERANCE * outer:
        mid = 0.5 * (lo + hi)
        ok = feasible(model, _poses(centre, mid, beta, theta))
        lo = np.where(ok, mid, lo)
        hi = np.where(ok, hi, mid)
    return np.where(inside, lo, 0.0)


@dataclass
class Radii:
    beta: np.ndarray            # ray bearings (rad)
    reachable: np.ndarray       # per ray: max over theta of rho* (m)
    dexterous: np.ndarray       # per ray: min over theta of rho* (m)
    theta_reach: np.ndarray     # the orientation reaching farthest (rad)
    outer: float
    seconds: float

    @property
    def reachable_radius(self) -> float:
        return float(self.reachable.min())

    @property
    def dexterous_radius(self) -> float:
        return float(self.dexterous.min())


def outer_bound(model, centre, samples: int = 24) -> float:
    """A distance from the centre beyond every reachable position: the farthest FK position of a
    coarse joint grid, times 1.5, doubled until no pose there is feasible."""
    g = -math.pi + TWO_PI * np.arange(samples) / samples
    q = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    with np.errstate(invalid="ignore"):
        x = model.fk_many(q)
    far = float(np.nanmax(np.hypot(x[:, 0] - centre[0], x[:, 1] - centre[1])))
    outer = 1.5 * far if far > 0 else 1.0
    beta = np.linspace(-math.pi, math.pi, 90, endpoint=False)[:, None]
    theta = np.linspace(-math.pi, math.pi, 90, endpoint=False)[None, :]
    for _ in range(60):
        if not feasible(model, _poses(centre, outer, beta, theta)).any():
            return outer
        outer *= 2.0
    raise ValueError("no bound on the workspace found: poses stay reachable arbitrarily far from the centre")


def radii(model, centre, rays: int, orientations: int, outer: float | None = None) -> Radii:
    """Reachable and dexterous radius along ``rays`` bearings (see the module docstring)."""
    start = time.perf_counter()
    outer = outer_bound(model, centre) if outer is None else outer
    beta = np.linspace(-math.pi, math.pi, rays, endpoint=False)
    step = TWO_PI / orientations
    theta = -math.pi + step * np.arange(orientations)
    rho = ray_reach(model, centre, beta[:, None], theta[None, :], outer)
    extremes = {}
    for name, pick in (("reachable", np.argmax), ("dexterous", np.argmin)):
        k = pick(rho, axis=1)
        best_theta = theta[k]
        best = rho[np.arange(rays), k]
        half = step
        for _ in range(ZOOM_LEVELS):
            local = best_theta[:, None] + np.linspace(-half, half, ZOOM_POINTS)[None, :]
            values = ray_reach(model, centre, beta[:, None], local, outer)
            j = pick(values, axis=1)
            found = values[np.arange(rays), j]
            better = found > best if name == "reachable" else found < best
            best = np.where(better, found, best)
            best_theta = np.where(better, local[np.arange(rays), j], best_theta)
            half = 2.0 * half / (ZOOM_POINTS - 1)
        extremes[name] = (best, best_theta)
    return Radii(beta, extremes["reachable"][0], extremes["dexterous"][0], extremes["reachable"][1], outer,
                 time.perf_counter() - start)


@dataclass
class Maps:
    x: np.ndarray                   # (n,) m
    y: np.ndarray                   # (n,) m
    count: np.ndarray               # (n, n) [iy, ix]: feasible orientations of the grid
    orientations: int
    theta: float                    # the chosen orientation (rad)
    isotropy_x: np.ndarray
    isotropy_y: np.ndarray
    isotropy_at: np.ndarray         # (m, m): 1/cond at theta
    isotropy_best: np.ndarray       # (m, m): max over the orientation grid
    best_theta: np.ndarray          # (m, m): its orientation (rad)
    seconds: float

    @property
    def reachable(self) -> np.ndarray:
        return self.count > 0

    @property
    def dexterous(self) -> np.ndarray:
        return self.count == self.orientations

    @property
    def orientation_range(self) -> np.ndarray:
        """Measure of the feasible orientations (rad), (n, n)."""
        return self.count * (TWO_PI / self.orientations)


def orientation_count(model, x: np.ndarray, y: np.ndarray, orientations: int) -> np.ndarray:
    """For positions (x, y) (arrays of one shape): how many of ``orientations`` equally spaced
    theta in [-pi, pi) have an IK solution."""
    count = np.zeros(np.shape(x), dtype=np.int64)
    for theta in -math.pi + TWO_PI * np.arange(orientations) / orientations:
        count += feasible(model, np.stack(np.broadcast_arrays(x, y, theta), axis=-1))
    return count


def maps(model, centre, half: float, grids: dict, theta: float, length: float) -> Maps:
    start = time.perf_counter()
    n, m = grids["positions"], grids["isotropy_positions"]
    xs = centre[0] + np.linspace(-half, half, n)
    ys = centre[1] + np.linspace(-half, half, n)
    X, Y = np.meshgrid(xs, ys)
    count = orientation_count(model, X, Y, grids["orientations"])
    ix = centre[0] + np.linspace(-half, half, m)
    iy = centre[1] + np.linspace(-half, half, m)
    X, Y = np.meshgrid(ix, iy)
    at = isotropy(model, np.stack(np.broadcast_arrays(X, Y, theta), axis=-1), length)
    best = np.full(X.shape, np.nan)
    best_theta = np.full(X.shape, np.nan)
    k = grids["isotropy_orientations"]
    for th in -math.pi + TWO_PI * np.arange(k) / k:
        value = isotropy(model, np.stack(np.broadcast_arrays(X, Y, th), axis=-1), length)
        better = value > np.where(np.isnan(best), -np.inf, best)
        best = np.where(better, value, best)
        best_theta = np.where(better, th, best_theta)
    return Maps(xs, ys, count, grids["orientations"], theta, ix, iy, at, best, best_theta,
                time.perf_counter() - start)


@dataclass
class GII:
    name: str
    samples: int
    unreachable: int
    sigma_min: float
    sigma_max: float
    seconds: float = 0.0
    reach: float = math.nan         # joint grids: farthest FK position from the centre (m)
    exact: int = 0                  # joint grids: configurations whose singular values were computed

    @property
    def gii(self) -> float:
        return self.sigma_min / self.sigma_max if self.sigma_max > 0 else math.nan


def region_gii(model, centre, region: Region, length: float, sizes) -> GII:
    """GII over a disc of radius ``region.radius * length`` about the centre and the region's
    orientation window, on a polar grid of ``sizes`` = (radii, bearings, orientations) through
    the IK (radius 0 and the disc's rim included; the window's ends included unless it is a
    full turn)."""
    start = time.perf_counter()
    n_r, n_b, n_t = sizes
    rho = np.linspace(0.0, region.radius * length, n_r)
    beta = np.linspace(-math.pi, math.pi, n_b, endpoint=False)
    low, high = region.theta
    theta = np.linspace(low, high, n_t, endpoint=high - low < TWO_PI - 1e-12)
    poses = _poses(centre, rho[:, None, None], beta[None, :, None], theta[None, None, :]).reshape(-1, 3)
    smin, smax, bad = math.inf, 0.0, 0
    with np.errstate(invalid="ignore", divide="ignore"):
        for i in range(0, len(poses), CHUNK):
            q = model.ik_many(poses[i:i + CHUNK])
            sv = model.singular_values_many(q, length)
            ok = np.isfinite(sv).all(-1)
            bad += int((~ok).sum())
            if ok.any():
                smin = min(smin, float(sv[ok, 2].min()))
                smax = max(smax, float(sv[ok, 0].max()))
    return GII(region.name, len(poses), bad, smin, smax, time.perf_counter() - start)


def _bounds(J: np.ndarray):
    """(F^2, |det J|) of matrices J (3, 3, k) (rows, columns, configurations)."""
    f2 = (J * J).sum((0, 1))
    det = (J[0, 0] * (J[1, 1] * J[2, 2] - J[1, 2] * J[2, 1])
           - J[0, 1] * (J[1, 0] * J[2, 2] - J[1, 2] * J[2, 0])
           + J[0, 2] * (J[1, 0] * J[2, 1] - J[1, 1] * J[2, 0]))
    return f2, np.abs(det)


def _joint_chunk(model, q: np.ndarray, length: float, centre, running: list):
    """(sigma_min, sigma_max, excluded, exact, reach) over configurations q (k, 3); ``running``
    = [an upper bound of min sigma_min, a lower bound of max sigma_max] found so far, tightened
    (shared between threads: a stale value only lets more candidates through)."""
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        x = model.fk_many(q)
        ok = np.isfinite(x).all(-1)
        bad = int((~ok).sum())
        reach = float(np.max(np.hypot(x[ok, 0] - centre[0], x[ok, 1] - centre[1]), initial=0.0))
        q = q[ok]
        J = np.ascontiguousarray(np.moveaxis(model.jacobian_many(q), (-2, -1), (0, 1)))
        J[2] *= length
        f2, det = _bounds(J)
        good = np.isfinite(f2) & np.isfinite(det)
        bad += int((~good).sum())
        if not good.any():
            return math.inf, 0.0, bad, 0, reach
        smin_hi = min(running[0], float(np.cbrt(det[good].min())))     # sigma_min <= |det|^(1/3)
        smax_lo = max(running[1], float(np.sqrt(f2[good].max() / 3.0)))   # sigma_max >= F / sqrt(3)
        running[0], running[1] = min(running[0], smin_hi), max(running[1], smax_lo)
        candidates = good & ((2.0 * det / f2 <= smin_hi) | (np.sqrt(f2) >= smax_lo))
        sv = model.singular_values_many(q[candidates], length)
        fine = np.isfinite(sv).all(-1)
        if not fine.any():
            return math.inf, 0.0, bad, len(sv), reach
        smin, smax = float(sv[fine, 2].min()), float(sv[fine, 0].max())
        running[0], running[1] = min(running[0], smin), max(running[1], smax)
        return smin, smax, bad, len(sv), reach


def joint_grid_gii(model, n: int, length: float, centre, workers: int | None = None) -> GII:
    """GII over the full joint grid q_j = -pi + 2 pi k / n (k = 0 .. n-1, n^3 configurations),
    exact (see the module docstring), in chunks on ``workers`` threads (NumPy releases the GIL;
    default: the CPUs, at most 4); direct singularities (no pose) are excluded and counted as
    ``unreachable``. Also the farthest FK position from the centre (``reach``)."""
    import os
    from concurrent.futures import ThreadPoolExecutor

    start = time.perf_counter()
    g = -math.pi + TWO_PI * np.arange(n) / n
    tail = np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1).reshape(-1, 2)
    rows = max(1, CHUNK // len(tail))
    running = [math.inf, 0.0]

    def chunk(i):
        first = g[i:i + rows]
        q = np.empty((len(first) * len(tail), 3))
        q[:, 0] = np.repeat(first, len(tail))
        q[:, 1:] = np.tile(tail, (len(first), 1))
        return _joint_chunk(model, q, length, centre, running)

    workers = workers or min(os.cpu_count() or 1, 4)
    with ThreadPoolExecutor(max_workers=workers) as pool:
        parts = list(pool.map(chunk, range(0, n, rows)))
    smin = min(p[0] for p in parts)
    smax = max(p[1] for p in parts)
    return GII(f"full joint grid {n}³", n ** 3, sum(p[2] for p in parts), smin, smax,
               time.perf_counter() - start, max(p[4] for p in parts), sum(p[3] for p in parts))


# -- the study run, figures, report -----------------------------------------------------------------
@dataclass
class Workspace:
    study: Study
    length: float
    centre: tuple[float, float]
    radii: Radii
    maps: Maps
    regions: list[GII]
    joint: list[GII]
    seconds: float


def run(study: Study, joint_grids: list[int] | None = None, progress=lambda text: None) -> Workspace:
    """Everything the study asks for (``joint_grids`` replaces its full joint grids)."""
    from robofmu.components.robots import load_model

    start = time.perf_counter()
    model = load_model(study.robot)
    length = characteristic_length(study, model)
    centre = study.centre
    if centre is None:
        home = model.fk_many(np.asarray(model.configuration("home"), dtype=float))
        centre = (float(home[0]), float(home[1]))
    grids = study.grids
    progress(f"radii: {grids['rays']} rays x {grids['ray_orientations']} orientations, bisection and zoom")
    r = radii(model, centre, grids["rays"], grids["ray_orientations"])
    half = 1.05 * float(r.reachable.max())
    progress(f"maps: {grids['positions']}² positions x {grids['orientations']} orientations")
    m = maps(model, centre, half, grids, study.theta, length)
    progress(f"GII over {len(study.regions)} regions")
    regions = [region_gii(model, centre, region, length, grids["region"]) for region in study.regions]
    joint = []
    for n in joint_grids or grids["joint"]:
        progress(f"GII over the full joint grid {n}³")
        joint.append(joint_grid_gii(model, n, length, centre))
    return Workspace(study, length, centre, r, m, regions, joint, time.perf_counter() - start)


def _save(fig, path: Path, tight: bool = True) -> Path:
    from robofmu.system import plots

    return plots.save_figure(fig, path, tight)


def figures(ws: Workspace, out: Path) -> dict[str, Path]:
    """The maps and the GII refinement as PNG files in ``out``."""
    import matplotlib.pyplot as plt

    from matplotlib.colors import ListedColormap

    out = Path(out)
    m, r, c = ws.maps, ws.radii, ws.centre
    extent = [m.x[0] * 1e3, m.x[-1] * 1e3, m.y[0] * 1e3, m.y[-1] * 1e3]
    ring = np.append(r.beta, r.beta[0])
    made = {}

    def rays(ax, values, style, label):
        v = np.append(values, values[0])
        ax.plot((c[0] + v * np.cos(ring)) * 1e3, (c[1] + v * np.sin(ring)) * 1e3, style, lw=1.2, label=label)

    fig, ax = plt.subplots(figsize=(6.4, 5.6))
    kind = np.where(m.dexterous, 2, np.where(m.reachable, 1, 0))
    ax.imshow(kind, origin="lower", extent=extent, cmap=ListedColormap(["white", "#9ecae1", "#3182bd"]),
              vmin=-0.5, vmax=2.5, interpolation="nearest")
    rays(ax, r.reachable, "k-", f"reachable boundary (rays), min radius {r.reachable_radius * 1e3:.3f} mm")
    rays(ax, r.dexterous, "r--", f"dexterous boundary (rays), min radius {r.dexterous_radius * 1e3:.3f} mm")
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title("Workspace: reachable (light, some θ) and dexterous (dark, every θ)")
    ax.legend(loc="lower left", fontsize=8)
    made["workspace"] = _save(fig, out / "workspace.png")

    fig, ax = plt.subplots(figsize=(6.4, 5.6))
    rng = np.where(m.reachable, np.degrees(m.orientation_range), np.nan)
    im = ax.imshow(rng, origin="lower", extent=extent, cmap="viridis", vmin=0, vmax=360)
    fig.colorbar(im, ax=ax, label="orientation range (deg)")
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title(f"Orientation range per position ({m.orientations} orientations)")
    made["orientation_range"] = _save(fig, out / "orientation_range.png")

    iso_extent = [m.isotropy_x[0] * 1e3, m.isotropy_x[-1] * 1e3, m.isotropy_y[0] * 1e3, m.isotropy_y[-1] * 1e3]
    fig, axes = plt.subplots(1, 2, figsize=(12, 5), constrained_layout=True)
    for ax, data, title in ((axes[0], m.isotropy_at, f"at θ = {math.degrees(m.theta):g}°"),
                            (axes[1], m.isotropy_best, "at the best θ")):
        im = ax.imshow(data, origin="lower", extent=iso_extent, cmap="magma", vmin=0, vmax=1)
        ax.set_aspect("equal")
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("y (mm)")
        ax.set_title(f"Local isotropy 1/cond(J) {title}")
    fig.colorbar(im, ax=axes, label=f"1/cond(J), θ row × L = {ws.length:g} m", shrink=0.85)
    made["isotropy"] = _save(fig, out / "isotropy.png", tight=False)

    if ws.joint:
        fig, ax = plt.subplots(figsize=(6.4, 4.6))
        n = np.array([round(g.samples ** (1 / 3)) for g in ws.joint])
        ax.loglog(n, [g.gii for g in ws.joint], "ko-", label="GII, full joint grid")
        ax.loglog(n, [g.sigma_min / ws.length for g in ws.joint], "b^--", label="min σ_min / L")
        ax.loglog(n, [g.sigma_max / ws.length for g in ws.joint], "rv--", label="max σ_max / L")
        for region in ws.regions:
            ax.axhline(region.gii, color="0.6", lw=0.8)
        if ws.regions:
            ax.axhline(ws.regions[0].gii, color="0.6", lw=0.8, label="GII of the regions")
        ax.set_xlabel("joint grid points per joint N")
        ax.set_title("Full joint grid: GII → 0 as the grid is refined")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
        made["gii"] = _save(fig, out / "gii.png")
    return made


def _relative(value: float, expected: float) -> str:
    return f"{(value / expected - 1.0) * 100:+.2e} %"


def report_lines(ws: Workspace, made: dict[str, Path], level: int = 2, prefix: str = "") -> list[str]:
    """The report (headings from ``level``); figures linked as ``prefix + name``."""
    h = "#" * level
    s, r, m = ws.study, ws.radii, ws.maps
    L = ws.length
    lines = [f"{h} {s.title}", "", s.text, "",
             f"Characteristic length L = {L:g} m: {s.length_text}", "",
             f"{h}# Reachable and dexterous radius", ""]
    rows = []
    for key, values, grid in (("reachable", r.reachable, m.reachable), ("dexterous", r.dexterous, m.dexterous)):
        cell = (m.x[1] - m.x[0]) * (m.y[1] - m.y[0])
        area = math.sqrt(grid.sum() * cell / math.pi)
        expected = s.expected.get(key)
        row = [key, f"{values.min() * 1e3:.6f}", f"{values.max() * 1e3:.6f}", f"{area * 1e3:.2f}"]
        if expected is not None:
            e = float(expected) * L
            row += [f"{s.expected.get(key + '_text', '')} = {e * 1e3:.6f}", _relative(values.min(), e)]
        else:
            row += ["—", "—"]
        rows.append(row)
    lines += [markdown_table(rows, ["workspace", "radius: min over rays (mm)", "max over rays (mm)",
                                    "√(area/π) of the pose-grid map (mm)", "expected (mm)",
                                    "min over rays vs expected"]),
              "",
              f"{len(r.beta)} rays from ({ws.centre[0]:g}, {ws.centre[1]:g}) m, {s.grids['ray_orientations']} "
              f"orientations each, bisection to {BISECTION_TOLERANCE:g} of {r.outer * 1e3:.1f} mm, then "
              f"{ZOOM_LEVELS} zoom levels of {ZOOM_POINTS} orientations about each ray's extreme "
              f"({r.seconds:.1f} s). The map: {len(m.x)}² positions × {m.orientations} orientations "
              f"({m.seconds:.1f} s with the isotropy maps).",
              "", f"![workspace]({prefix}{made['workspace'].name})", "",
              f"{h}# Orientation range per position", "",
              f"The measure of the orientations θ ∈ [-π, π) with an IK solution, on the grid of "
              f"{m.orientations} orientations (360° at the dexterous positions).",
              "", f"![orientation range]({prefix}{made['orientation_range'].name})", "",
              f"{h}# Isotropy", "",
              f"Local isotropy 1/cond(J) with the θ row of J multiplied by L = {L:g} m, on "
              f"{len(m.isotropy_x)}² positions: at θ = {math.degrees(m.theta):g}° and the best of "
              f"{s.grids['isotropy_orientations']} orientations (white: unreachable). Largest at θ = "
              f"{math.degrees(m.theta):g}°: {np.nanmax(m.isotropy_at):.4f}; at the best θ: "
              f"{np.nanmax(m.isotropy_best):.4f}.", "",
              f"![isotropy]({prefix}{made['isotropy'].name})", "",
              f"{h}# Global Isotropy Index", "",
              f"GII = min σ_min(J) / max σ_max(J) over a set of configurations, θ row × L = {L:g} m. "
              f"Regions: discs about the centre (radius as a fraction of L) and an orientation window, "
              f"sampled on a polar grid of {' × '.join(map(str, s.grids['region']))} (radii incl. the rim, "
              "bearings, orientations) through the IK.", ""]
    rows = [[g.name, f"{g.samples}", f"{g.unreachable}", f"{g.sigma_min / L:.6g}", f"{g.sigma_max / L:.6g}",
             f"{g.gii:.6g}"] for g in ws.regions]
    lines += [markdown_table(rows, ["region", "samples", "unreachable", "min σ_min / L", "max σ_max / L", "GII"]), ""]
    if ws.joint:
        rows = [[f"{round(g.samples ** (1 / 3))}³ = {g.samples}", f"{g.unreachable}", f"{g.sigma_min / L:.3e}",
                 f"{g.sigma_max / L:.3e}", f"{g.gii:.3e}", f"{g.reach * 1e3:.4f}", f"{g.exact}",
                 f"{g.seconds:.2f}"] for g in ws.joint]
        lines += [f"{h}## The full joint grid", "",
                  "q_j = -π + 2πk/N, k = 0 … N−1, every combination; configurations without a pose (direct "
                  "singularities) excluded. The exact singular values are computed only where the bounds "
                  "from ‖J‖_F and |det J| leave a configuration in the running for an extreme.", "",
                  markdown_table(rows, ["grid", "no pose", "min σ_min / L", "max σ_max / L", "GII",
                                        "farthest FK position (mm)", "exact SVDs", "time (s)"]), ""]
        if "gii" in made:
            lines += [f"![GII refinement]({prefix}{made['gii'].name})", ""]
    if s.notes.get("full_grid"):
        lines += [s.notes["full_grid"], ""]
    lines += [f"Whole analysis: {ws.seconds:.1f} s.", ""]
    return lines


def write(ws: Workspace, out: Path, level: int = 1) -> Path:
    """Figures and ``out/report.md``; returns the report's path."""
    made = figures(ws, out)
    path = Path(out) / "report.md"
    path.write_text("\n".join(report_lines(ws, made, level)) + "\n")
    return path

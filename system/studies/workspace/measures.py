"""The workspace measures on vectorized kinematics (``fk_many``, ``ik_many``, ...), chunked so that
memory stays bounded: radii by bisection along rays (:func:`radii`), maps on a pose grid
(:func:`maps`), the GII over a region (:func:`region_gii`) and over a full joint grid
(:func:`joint_grid_gii`)."""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

#: Configurations per vectorized call (bounds the memory: a few tens of MB per chunk).
CHUNK = 1 << 17
#: Bisection stops when the bracket is this small relative to the outer bound.
BISECTION_TOLERANCE = 1e-13
#: Zoom levels about the extreme orientation of each ray, and the points of each level.
ZOOM_LEVELS, ZOOM_POINTS = 6, 21
TWO_PI = 2.0 * math.pi


@dataclass
class Region:
    name: str
    radius: float                       # fraction of the characteristic length
    theta: tuple[float, float]          # rad


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

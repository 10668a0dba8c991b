"""Report tables for any experiment: the joint reference at chosen instants against a seed's
printed table, a joint-space profile's timing, and the dynamics beside a seed's Lagrange
derivation.

Everything robot- or seed-specific comes in as data (a CSV of printed values, a TOML of energy
expressions); the computations use the experiment's own block logic
(:class:`~robofmu.system.studies.replica.InProcessDiagram`) and robot model.
"""
from __future__ import annotations

import csv
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robofmu.system.analysis import markdown_table
from robofmu.system.studies.replica import InProcessDiagram
from robofmu.system.roles import Roles
from robofmu.system.units import printed

STUDIES_DIR = Path(__file__).resolve().parent


def _instance(base: str) -> str:
    return base.split(".")[0]


def sampled_joint_reference(diagram: InProcessDiagram, roles: Roles, times) -> np.ndarray:
    """q_ref, qd_ref, qdd_ref at ``times`` (s), shape (k, 3n), from the diagram's own blocks."""
    roles.require("q_ref")
    block = diagram.blocks[_instance(roles.q_ref)]
    bases = ("q_ref", "qd_ref", "qdd_ref")
    diagram.configure()
    rows = []
    for t in times:
        diagram.evaluate(float(t))
        rows.append(np.concatenate([block.get(b) for b in bases]))
    return np.array(rows)


@dataclass
class SeedComparison:
    """Our values beside a seed's printed ones.

    Attributes
    ----------
    times : ndarray, shape (k,)
    columns : list of str
    ours : ndarray, shape (k, c)
    printed : list of list of str
        The seed's cells as printed.
    differs : ndarray of bool, shape (k, c)
        Where |ours - seed| exceeds half a unit of the seed's last printed digit.
    """

    times: np.ndarray
    columns: list[str]
    ours: np.ndarray
    printed: list[list[str]]
    differs: np.ndarray

    def markdown(self, digits: int = 6) -> str:
        rows = []
        for k, t in enumerate(self.times):
            cells = [f"{t:.5g}"]
            for j in range(len(self.columns)):
                mine = f"{self.ours[k, j] + 0.0:.{digits}g}"
                cells.append(f"**{mine}** [{self.printed[k][j]}]" if self.differs[k, j] else mine)
            rows.append(cells)
        return markdown_table(rows, ["t (s)", *self.columns])


def _decimals(text: str) -> int:
    mantissa = text.lower().split("e")[0]
    return len(mantissa.split(".")[1]) if "." in mantissa else 0


def read_printed(path: Path) -> tuple[list[str], list[list[str]]]:
    """Header and rows of a CSV of printed values (``#`` lines are comments)."""
    with path.open() as f:
        lines = [line for line in f if not line.startswith("#")]
    rows = list(csv.reader(lines))
    return rows[0], rows[1:]


def compare_with_seed(diagram: InProcessDiagram, roles: Roles, path: Path) -> SeedComparison:
    """The joint reference at the seed table's instants against its printed values.

    The CSV has a time column, then positions, velocities and accelerations of every joint
    (SI units, as many decimals as the seed prints).
    """
    header, rows = read_printed(path)
    times = np.array([float(r[0]) for r in rows])
    ours = sampled_joint_reference(diagram, roles, times)
    if ours.shape[1] != len(header) - 1:
        raise ValueError(f"{path}: {len(header) - 1} value columns for {ours.shape[1]} reference values")
    cells = [r[1:] for r in rows]
    differs = np.zeros(ours.shape, dtype=bool)
    for k, row in enumerate(cells):
        for j, text in enumerate(row):
            half = 0.5 * 10.0 ** (-_decimals(text))
            differs[k, j] = abs(ours[k, j] - float(text)) > half * (1 + 1e-9)
    return SeedComparison(times, header[1:], ours, cells, differs)


def bangbang_table(diagram: InProcessDiagram, roles: Roles, peak_effort=None, effort_units=None) -> str:
    """Per joint: distance, acceleration limit, minimum time, rescaled acceleration, peak speed
    (and peak effort of the run), then the synchronized time and the switch time."""
    block = diagram.blocks[_instance(roles.q_ref)]
    diagram.configure()
    profile = block.profile
    units = block.robot.joint_units(0)
    rows = []
    for j in range(profile.dim):
        u = printed(units[j])
        row = [f"q{j + 1}", f"{profile.q_start[j]:.6g} → {profile.q_end[j]:.6g} {u}",
               f"{profile.a_max[j]:.6g} {u}/s²", f"{profile.t_min[j]:.5f} s",
               f"{profile.acceleration[j]:.6g} {u}/s²", f"{profile.peak_velocity[j]:.6g} {u}/s"]
        if peak_effort is not None:
            row.append(f"{peak_effort[j]:.4f} {printed(effort_units[j])}")
        rows.append(row)
    header = ["joint", "motion", "a_max", "T_min = 2√(Δq/a_max)", "a = 4Δq/T²", "peak speed a T/2"]
    if peak_effort is not None:
        header.append("peak effort (run)")
    return (markdown_table(rows, header) + f"\n\nSynchronized time T = max T_min = {profile.duration:.5f} s; "
            f"every joint switches from accelerating to braking at T/2 = {profile.switch_time:.5f} s.")


# -- dynamics beside a seed's Lagrange derivation ---------------------------------------------------
def lagrange(energies: dict):
    """M(q), C(q, qd) (Christoffel), G(q) from kinetic and potential energy expressions (sympy).

    Parameters
    ----------
    energies : dict
        ``coordinates`` (names), ``kinetic`` (expressions, summed), ``potential`` (expression),
        ``constants`` (name -> value); rates are the coordinate names with ``d`` appended.

    Returns
    -------
    q, qd : list of sympy symbols
    M, C, G : sympy matrices, shapes (n, n), (n, n), (n, 1)
    """
    import sympy as sp

    names = energies["coordinates"]
    q = sp.symbols(names)
    qd = sp.symbols([f"{n}d" for n in names])
    local = {str(s): s for s in (*q, *qd)}
    T = sum(sp.sympify(e, locals=local) for e in energies["kinetic"])
    V = sp.sympify(energies["potential"], locals=local)
    n = len(q)
    M = sp.Matrix(n, n, lambda i, j: sp.simplify(sp.diff(T, qd[i], qd[j])))
    C = sp.zeros(n, n)
    for i in range(n):
        for j in range(n):
            C[i, j] = sp.simplify(sum(sp.Rational(1, 2) * (sp.diff(M[i, j], q[k]) + sp.diff(M[i, k], q[j])
                                                           - sp.diff(M[j, k], q[i])) * qd[k] for k in range(n)))
    G = sp.Matrix([sp.simplify(sp.diff(V, qi)) for qi in q])
    return q, qd, M, C, G


@dataclass
class DynamicsComparison:
    """The seed's M, C, G beside the robot model's.

    Attributes
    ----------
    text : str
        The markdown: the seed's matrices and how closely the model agrees.
    largest_difference : float
        The largest entry difference found (the units of M, C and G's entries).
    """
    text: str
    largest_difference: float


def dynamics_table(robot: str, path: Path, samples: int = 50, seed: int = 1) -> DynamicsComparison:
    """The seed's M, C, G (from its energies by Lagrange) beside the robot model's, compared at
    random configurations and rates."""
    import sympy as sp

    from robofmu.components.robots import load_model

    energies = tomllib.loads(path.read_text())
    q, qd, M, C, G = lagrange(energies)
    constants = {sp.Symbol(k): v for k, v in energies["constants"].items()}
    numeric = [sp.lambdify([q, qd], X.subs(constants), "numpy") for X in (M, C, G)]
    model = load_model(robot)
    rng = np.random.default_rng(seed)
    worst = 0.0
    for _ in range(samples):
        qs = model.configuration("home") + rng.uniform(-1.0, 1.0, model.n)
        qds = rng.uniform(-2.0, 2.0, model.n)
        Ms, Cs, Gs = (np.array(f(qs, qds), dtype=float) for f in numeric)
        worst = max(worst, np.abs(Ms - model.mass_matrix(qs)).max(),
                    np.abs(Cs - model.coriolis_matrix(qs, qds)).max(),
                    np.abs(Gs.reshape(-1) - model.gravity_torque(qs)).max())
    lines = ["From the seed's energies " + ", ".join(f"`T{i + 1} = {e}`" for i, e in enumerate(energies["kinetic"]))
             + f" and `V = {energies['potential']}`, by Lagrange (C from the Christoffel symbols):", "",
             f"- M(q) = `{sp.sstr(M.tolist())}`", f"- C(q, q̇) = `{sp.sstr(C.tolist())}`",
             f"- G(q) = `{sp.sstr(list(G))}`", "",
             f"with {', '.join(f'{k} = {v:g}' for k, v in energies['constants'].items())}. The robot model "
             f"(Pinocchio on the URDF: CRBA, Coriolis matrix, generalized gravity) agrees at {samples} random "
             f"configurations and rates to {worst:.1e} (largest entry difference)."]
    if not math.isfinite(worst):
        raise ValueError("dynamics comparison produced a non-finite difference")
    return DynamicsComparison("\n".join(lines), float(worst))

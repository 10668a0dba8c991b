"""A tutorial on Newton-Raphson IK, reproduced for any robot: iteration histories, both closed-form
branches, the velocity and acceleration level, and a printed Jacobian derivative checked.

What is reproduced is data (a study TOML under ``system/studies/``, e.g. ``seed003_tutorial.toml``):
per example the robot, the initial guess, the target, the solver's settings, the closed-form
solvers and their branches, a task velocity and acceleration, and what the source prints (as
strings, the digits it shows, or sympy expressions such as ``"-1/6"``). A source may write the joints in
other coordinates than the robot's URDF (an absolute elbow angle instead of a relative one):
``seed_from_joints`` is the matrix M with q_seed = M q. Everything computed here comes from the
robot's own model and solvers (:mod:`robofmu.components.ik`):

- the iteration history of :class:`~robofmu.components.ik.newton.NewtonRaphsonIK` (iteration
  k, q_k, |F_k|, and |F_k| / |F_(k-1)|^2 and log|F_k| / log|F_(k-1)|, which tend to a constant
  and to 2 where the convergence is quadratic);
- every closed-form branch listed (``solver_class(kind)(model, **parameters)``);
- the rates q̇, q̈ = A^-1 [ẋ; 0], A^-1 [ẍ - J̇q̇; 0] (:meth:`IKSolver.rates`) beside central
  differences (five points) of the position solution along x(t) = x0 + ẋ t + ẍ t²/2;
- a printed entry of J̇ beside its correction: both expressions (strings, evaluated with sympy)
  against the time derivative of the printed J entry (sympy) and against central differences of
  the model's Jacobian along q̇.

A printed value *matches* when it is within half a unit of its last printed digit (an
expression: within 1e-12 relative); the module knows no robot.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from robofmu.components.ik import Unreachable, solver_class
from robofmu.components.robots import load_model

from robofmu.system.analysis import markdown_table

#: The iterative solver the study runs.
NEWTON = "newton_raphson"
#: Relative tolerance of a printed value given as an expression (not as digits).
EXACT = 1e-12


# -- printed values ---------------------------------------------------------------------------------
def printed_value(text) -> float:
    """The number a printed entry stands for: a decimal string, or a sympy expression (``"-1/6"``)."""
    if isinstance(text, (int, float)) and not isinstance(text, bool):
        return float(text)
    import sympy as sp

    return float(sp.sympify(str(text)))


def printed_tolerance(text) -> float:
    """Half a unit of the last printed digit of a decimal string; an expression is exact (relative
    :data:`EXACT`)."""
    s = str(text).strip().lower()
    mantissa, _, exponent = s.partition("e")
    try:
        float(s)
    except ValueError:
        return EXACT * max(1.0, abs(printed_value(text)))
    decimals = len(mantissa.split(".")[1]) if "." in mantissa else 0
    return 0.5 * 10.0 ** (-decimals + (int(exponent) if exponent else 0)) * (1 + 1e-9)


def matches(value: float, text) -> bool:
    """Whether ``value`` rounds to the printed ``text`` (see :func:`printed_tolerance`)."""
    return abs(value - printed_value(text)) <= printed_tolerance(text)


# -- results ------------------------------------------------------------------------------------------
@dataclass
class Iterate:
    """One Newton-Raphson iterate: k (0: the start), q_k (joint units), |F(q_k)|."""

    k: int
    q: np.ndarray
    residual: float


@dataclass
class Branch:
    """One closed-form solution: the solver kind and its parameters, q (or why there is none)."""

    kind: str
    parameters: dict
    q: np.ndarray | None
    residual: float
    printed: list | None
    problem: str = ""


@dataclass
class Rates:
    """Joint rates at the solution for a task velocity and acceleration, and their finite-difference
    estimates along x(t) = x0 + ẋ t + ẍ t²/2."""

    xd: np.ndarray
    xdd: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    qd_fd: np.ndarray
    qdd_fd: np.ndarray
    step: float
    printed: dict
    note: str = ""


@dataclass
class JdotCheck:
    """One entry of J̇ as printed and as corrected, at the example's state."""

    entry: tuple[int, int]
    coordinates: list[str]
    jacobian: str
    printed: str
    corrected: str
    jacobian_value: float          # the printed J entry at the state
    model_jacobian: float          # the model's J entry at the state (seed coordinates)
    derivative: str                # d/dt of the printed J entry (sympy)
    printed_is_derivative: bool
    corrected_is_derivative: bool
    printed_value: float
    corrected_value: float
    numerical: float               # central differences of the model's J along q̇
    state: dict


@dataclass
class Example:
    """One worked example of the study, computed."""

    spec: dict
    robot: str
    names: list[str]               # the source's joint coordinate names
    seed_from_joints: np.ndarray   # M: q_seed = M q
    target: np.ndarray
    guess: np.ndarray
    iterates: list[Iterate]
    q: np.ndarray
    iterations: int
    residual: float
    branches: list[Branch] = field(default_factory=list)
    rates: Rates | None = None
    jdot: JdotCheck | None = None

    def seed(self, q) -> np.ndarray:
        """Joint values in the source's coordinates."""
        return self.seed_from_joints @ np.asarray(q, dtype=float)

    @property
    def printed(self) -> dict:
        return dict(self.spec.get("printed", {}))

    def checks(self) -> list[tuple[str, bool]]:
        """Every comparison with what the source prints: (what, agrees)."""
        out = []
        p = self.printed
        if "iterations" in p:
            out.append((f"iterations {self.iterations} (printed {p['iterations']})", self.iterations == p["iterations"]))
        if "residual_below" in p:
            out.append((f"residual {self.residual:.3g} < {p['residual_below']:g}", self.residual < p["residual_below"]))
        if "q" in p:
            qs = self.seed(self.q)
            out += [(f"{n} = {v:.12f} (printed {t})", matches(v, t)) for n, v, t in zip(self.names, qs, p["q"])]
        for b in self.branches:
            if b.printed is not None and b.q is not None:
                qs = self.seed(b.q)
                out += [(f"{b.kind} {_params(b.parameters)}: {n} = {v:.12f} (printed {t})", matches(v, t))
                        for n, v, t in zip(self.names, qs, b.printed)]
            elif b.printed is not None:
                out.append((f"{b.kind} {_params(b.parameters)}: {b.problem}", False))
        if self.rates is not None:
            r = self.rates
            for key, values in (("qd", self.seed(r.qd)), ("qdd", self.seed(r.qdd))):
                for n, v, t in zip(self.names, values, r.printed.get(key, [])):
                    out.append((f"{key} {n} = {v:.12g} (printed {t})", matches(v, t)))
        if self.jdot is not None:
            j = self.jdot
            out.append(("the corrected J̇ entry is the time derivative of the J entry", j.corrected_is_derivative))
        return out


def _params(parameters: dict) -> str:
    return ", ".join(f"{k} = {v}" for k, v in parameters.items())


# -- the computations --------------------------------------------------------------------------------
def newton_history(model, guess, target, **settings):
    """Solve ``fk(q) = target`` from ``guess`` with the robot's NewtonRaphsonIK; returns the solver
    and its iterates (k, q_k, |F_k|; k = 0 is the start), as the solver records them."""
    solver = solver_class(NEWTON)(model, q_guess=tuple(float(v) for v in guess), **settings)
    solver.position(np.asarray(target, dtype=float))
    iterates = [Iterate(k, np.array(q), r) for k, (q, r) in enumerate(zip(solver.iterates, solver.history))]
    return solver, iterates


def ratios(residuals) -> list[tuple[float, float]]:
    """Per iterate k >= 1: (|F_k| / |F_(k-1)|^2, log|F_k| / log|F_(k-1)|); NaN where undefined."""
    out = []
    for before, after in zip(residuals[:-1], residuals[1:]):
        square = after / before ** 2 if before > 0 else math.nan
        logs = math.log(after) / math.log(before) if 0 < after and 0 < before != 1.0 else math.nan
        out.append((square, logs))
    return out


def _five_point(f, h: float):
    """First and second derivative at 0 of ``f`` (array-valued) by five-point central differences."""
    v = {k: np.asarray(f(k * h), dtype=float) for k in (-2, -1, 0, 1, 2)}
    first = (v[-2] - 8.0 * v[-1] + 8.0 * v[1] - v[2]) / (12.0 * h)
    second = (-v[-2] + 16.0 * v[-1] - 30.0 * v[0] + 16.0 * v[1] - v[2]) / (12.0 * h * h)
    return first, second


def rates_check(model, q, spec: dict, settings: dict, fd: dict) -> Rates:
    """q̇, q̈ at ``q`` for the task velocity and acceleration of ``spec``, beside five-point central
    differences of the Newton-Raphson position solution along x(t) (warm-started from ``q``)."""
    x0 = np.asarray(model.fk(q), dtype=float)
    xd, xdd = (np.asarray(spec[k], dtype=float) for k in ("xd", "xdd"))
    solver = solver_class(NEWTON)(model, q_guess=tuple(float(v) for v in q), **settings)
    qd, qdd = solver.rates(q, xd, xdd)
    step = float(fd["step"])
    precise = solver_class(NEWTON)(model, q_guess=tuple(float(v) for v in q),
                                   **{**settings, "tolerance": float(fd["tolerance"])})

    def position(t):
        precise.start_from(q)
        return precise.position(x0 + xd * t + 0.5 * xdd * t * t)

    qd_fd, qdd_fd = _five_point(position, step)
    return Rates(xd, xdd, qd, qdd, qd_fd, qdd_fd, step, dict(spec.get("printed", {})), spec.get("note", ""))


def jdot_check(model, M: np.ndarray, q, qd, spec: dict, step: float) -> JdotCheck:
    """A printed J̇ entry and its correction at (q, q̇), against sympy and the model's Jacobian.

    The source's Jacobian is J_s = J M^-1 (its coordinates q_s = M q); its rates are named after
    its coordinates with ``d`` appended (``L3`` -> ``L3d``).
    """
    import sympy as sp

    names = list(spec["coordinates"])
    qs = sp.symbols(names)
    qds = sp.symbols([f"{n}d" for n in names])
    local = {str(s): s for s in (*qs, *qds)}
    J = sp.sympify(spec["jacobian"], locals=local)
    printed, corrected = (sp.sympify(spec[k], locals=local) for k in ("printed", "corrected"))
    derivative = sp.expand(sum(sp.diff(J, a) * b for a, b in zip(qs, qds)))
    row, col = (int(v) for v in spec["entry"])
    Minv = np.linalg.inv(M)
    q_seed, qd_seed = M @ q, M @ qd
    state = {**{str(s): float(v) for s, v in zip(qs, q_seed)}, **{str(s): float(v) for s, v in zip(qds, qd_seed)}}
    subs = {sp.Symbol(k): v for k, v in state.items()}

    def seed_jacobian(t):
        return (np.asarray(model.jacobian(q + t * qd), dtype=float) @ Minv)[row - 1, col - 1]

    numerical, _ = _five_point(seed_jacobian, step)
    return JdotCheck(
        entry=(row, col), coordinates=names, jacobian=spec["jacobian"], printed=spec["printed"],
        corrected=spec["corrected"], jacobian_value=float(J.subs(subs)), model_jacobian=float(seed_jacobian(0.0)),
        derivative=sp.sstr(sp.simplify(derivative)),
        printed_is_derivative=sp.simplify(printed - derivative) == 0,
        corrected_is_derivative=sp.simplify(corrected - derivative) == 0,
        printed_value=float(printed.subs(subs)), corrected_value=float(corrected.subs(subs)),
        numerical=float(numerical), state=state)


def run_example(spec: dict, fd: dict) -> Example:
    """Compute one example of a study (see the module notes)."""
    model = load_model(spec["robot"])
    n = model.n
    M = np.asarray(spec.get("seed_from_joints", np.eye(n)), dtype=float)
    names = list(spec.get("seed_coordinates", [f"q{j + 1}" for j in range(n)]))
    settings = dict(spec.get("solver", {}))
    target = np.asarray(spec["target"], dtype=float)
    guess = np.asarray(spec["guess"], dtype=float)
    solver, iterates = newton_history(model, guess, target, **settings)
    q = iterates[-1].q
    example = Example(spec, spec["robot"], names, M, target, guess, iterates, q,
                      int(solver.report["iterations"]), float(solver.report["residual"]))
    for b in spec.get("branches", []):
        parameters = dict(b.get("parameters", {}))
        try:
            qb = solver_class(b["solver"])(model, **parameters).position(target)
            example.branches.append(Branch(b["solver"], parameters, qb, float(np.linalg.norm(model.fk(qb) - target)),
                                           b.get("q")))
        except (Unreachable, ValueError) as exc:
            example.branches.append(Branch(b["solver"], parameters, None, math.nan, b.get("q"), str(exc)))
    if "rates" in spec:
        example.rates = rates_check(model, q, spec["rates"], settings, fd)
    if "jdot" in spec:
        if example.rates is None:
            raise ValueError(f"example {spec.get('name', spec['robot'])!r}: [jdot] needs [rates] (the state's q̇)")
        example.jdot = jdot_check(model, M, q, example.rates.qd, spec["jdot"], float(fd["step"]))
    return example


def load_study(path: Path) -> dict:
    """The study's TOML table."""
    return tomllib.loads(Path(path).read_text())


def run_study(path: Path) -> list[Example]:
    """Every example of the study file ``path``."""
    plan = load_study(path)
    fd = {"step": 1e-2, "tolerance": 1e-14, **plan.get("finite_differences", {})}
    return [run_example(spec, fd) for spec in plan["examples"]]


# -- the report -------------------------------------------------------------------------------------
def _vector(values, digits: int = 12) -> str:
    return "(" + ", ".join(f"{v + 0.0:.{digits}f}" for v in values) + ")"


def _short(values) -> str:
    return "(" + ", ".join(f"{v + 0.0:.6g}" for v in values) + ")"


def _g(value: float, digits: int = 4) -> str:
    return "—" if not math.isfinite(value) else f"{value:.{digits}g}"


def iteration_table(example: Example) -> str:
    """k, q_k (the source's coordinates), |F_k| and the two convergence ratios."""
    rs = [it.residual for it in example.iterates]
    ratio = [(math.nan, math.nan), *ratios(rs)]
    rows = [[it.k, _vector(example.seed(it.q)), f"{it.residual:.3e}", _g(ratio[it.k][0]), _g(ratio[it.k][1])]
            for it in example.iterates]
    return markdown_table(rows, ["k", f"q_k = ({', '.join(example.names)})", r"\|F_k\| (m)",
                                 r"\|F_k\| / \|F_(k-1)\|²", r"log\|F_k\| / log\|F_(k-1)\|"])


def branch_table(example: Example) -> str:
    rows = []
    for b in example.branches:
        if b.q is None:
            rows.append([f"`{b.kind}` {_params(b.parameters)}", "—", "—", "—", b.problem])
            continue
        seed = example.seed(b.q)
        shown = ", ".join(b.printed) if b.printed is not None else "not printed"
        agree = ("matches" if all(matches(v, t) for v, t in zip(seed, b.printed)) else "**differs**") \
            if b.printed is not None else ""
        same = "yes" if np.allclose(b.q, example.q, rtol=0, atol=1e-9) else "no"
        rows.append([f"`{b.kind}` {_params(b.parameters)}", _vector(seed), f"{b.residual:.1e}",
                     same, f"{shown} {agree}".strip()])
    return markdown_table(rows, ["closed form, branch", f"q = ({', '.join(example.names)})", r"\|FK(q) − x\| (m)",
                                 "Newton-Raphson's solution", "printed"])


def rates_table(example: Example) -> str:
    r = example.rates
    rows = []
    for key, label, analytic, fd in (("qd", "q̇ = A⁻¹[ẋ; 0]", r.qd, r.qd_fd),
                                     ("qdd", "q̈ = A⁻¹[ẍ − J̇q̇; 0]", r.qdd, r.qdd_fd)):
        printed = r.printed.get(key)
        shown = ", ".join(str(t) for t in printed) if printed else "not printed"
        if printed:
            ok = all(matches(v, t) for v, t in zip(example.seed(analytic), printed))
            shown += " (matches)" if ok else " (**differs**)"
        rows.append([label, _vector(example.seed(analytic), 9), _vector(example.seed(fd), 9),
                     f"{np.abs(analytic - fd).max():.1e}", shown])
    return markdown_table(rows, ["joint rates", f"({', '.join(example.names)})",
                                 f"five-point differences along x(t), step {r.step:g} s", "max difference",
                                 "printed"])


def jdot_table(j: JdotCheck) -> str:
    row, col = j.entry
    rows = [["as printed", f"`{j.printed}`", f"{j.printed_value:.12f}", f"{j.printed_value - j.numerical:.2e}",
             "yes" if j.printed_is_derivative else "**no**"],
            ["corrected", f"`{j.corrected}`", f"{j.corrected_value:.12f}", f"{j.corrected_value - j.numerical:.2e}",
             "yes" if j.corrected_is_derivative else "**no**"],
            ["numerical", f"central differences of the model's J({row},{col}) along q̇", f"{j.numerical:.12f}", "",
             ""]]
    return markdown_table(rows, [f"J̇({row},{col})", "expression", "value at the state", "minus numerical",
                                 f"= d/dt of J({row},{col})"])


def report(path: Path, examples: list[Example] | None = None, level: int = 3) -> list[str]:
    """The markdown lines of the study's report: its ``text``, then per example a heading of
    ``level`` and its tables (``examples``: already computed, else :func:`run_study`)."""
    plan = load_study(path)
    examples = run_study(path) if examples is None else examples
    lines = [plan.get("text", ""), ""]
    for example in examples:
        spec = example.spec
        lines += [f"{'#' * level} {spec.get('name', example.robot)}", "", spec.get("text", ""), "",
                  f"Target x = {_short(example.target)} m from the guess ({', '.join(example.names)}) = "
                  f"{_short(example.seed(example.guess))} (the robot's joints {_short(example.guess)}); "
                  f"the robot's NewtonRaphsonIK with "
                  f"{_params(spec.get('solver', {})) or 'its defaults'}:", "",
                  iteration_table(example), "",
                  f"Converged in {example.iterations} iterations to |F| = {example.residual:.2e} m: "
                  f"q = {_vector(example.q)} (the robot's joints)."]
        if not np.allclose(example.seed_from_joints, np.eye(len(example.q))):
            lines[-1] += f" In the source's coordinates ({', '.join(example.names)}) = {_vector(example.seed(example.q))}."
        lines.append("")
        if example.branches:
            lines += ["Closed-form solutions of the same target:", "", branch_table(example), ""]
        if example.rates is not None:
            r = example.rates
            lines += [f"Velocity and acceleration level at this solution for ẋ = {_short(r.xd)} m/s, "
                      f"ẍ = {_short(r.xdd)} m/s²{f' ({r.note})' if r.note else ''}:",
                      "", rates_table(example), ""]
        if example.jdot is not None:
            j = example.jdot
            state = ", ".join(f"{k} = {v:.6g}" for k, v in j.state.items())
            lines += [f"The printed J̇({j.entry[0]},{j.entry[1]}), with J({j.entry[0]},{j.entry[1]}) = `{j.jacobian}` "
                      f"({j.jacobian_value:.12f} at the state; the model's: {j.model_jacobian:.12f}), "
                      f"whose time derivative is `{j.derivative}`; at the state {state}:", "", jdot_table(j), ""]
            if spec["jdot"].get("note"):
                lines += [spec["jdot"]["note"], ""]
        checks = example.checks()
        failed = [what for what, ok in checks if not ok]
        lines += [f"{len(checks) - len(failed)} of {len(checks)} comparisons with the source agree"
                  + (": " + "; ".join(failed) + " differ." if failed else "."), ""]
    return lines

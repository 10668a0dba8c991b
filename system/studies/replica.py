"""Any robofmu diagram in one Python process: the FMUs' own block logic, without FMI.

Each FMU of an experiment names its robot and block kind in its model description (a robofmu
vendor annotation); :class:`InProcessDiagram` builds the same FMI-free blocks
(:mod:`robofmu.components.blocks`), applies the FMUs' start values and the experiment's
parameters, and wires them as the experiment says (the master's checked plan). Two ways to run:

- :meth:`InProcessDiagram.sampled`: the master's Gauss-Seidel loop, call for call (outputs in
  evaluation order, late inputs after the pass, every block advances over [t, t + h] with its
  inputs held), so it agrees with the master to the last bit; without FMI calls it shows what
  the FMI layer costs (``benchmarks/loop.py``).
- :meth:`InProcessDiagram.monolithic`: the whole diagram as one ODE in the blocks' continuous
  states (plant (q, qd), controller integral z): the controller acts continuously, no input is
  held. Integrated by DOP853 at tight tolerances piecewise between the blocks' breakpoints
  (where the right-hand side jumps), it is the reference the co-simulation converges to.
"""
from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

from robofmu.components import SOURCE_HASH
from robofmu.components.blocks import Block, block_class
from robofmu.components.robots import load_description, load_model
from robofmu.components.robots.description import PROFILE_PREFIX

from robofmu.system import defaults
from robofmu.system.plan import plan as check_plan, start_values, step_count
from robofmu.system.diagram import System, coerce, expand, spread
from robofmu.system.fmu import block_identity
from robofmu.system.result import Result

__all__ = ["InProcessDiagram", "Monolithic"]

#: Offset (s) by which blocks are evaluated inside a piece when the integrator asks for the
#: piece's very ends, so that the piece's branch is used there (a piece's right-hand side is
#: the smooth continuation of its interior). Moves the reference by < 1e-12.
INSIDE = 1e-11


@dataclass
class _Wire:
    """Copies of one destination block's inputs from one source block (index arrays; a slice
    copy where both sides are consecutive slots, as wired vectors are)."""

    source: Block
    source_slots: np.ndarray
    target: Block
    target_slots: np.ndarray

    def __post_init__(self):
        self._views = None
        if _consecutive(self.source_slots) and _consecutive(self.target_slots):
            self._views = (self.source.values[self.source_slots[0]:self.source_slots[-1] + 1],
                           self.target.values[self.target_slots[0]:self.target_slots[-1] + 1])

    def apply(self) -> None:
        if self._views is not None:
            self._views[1][:] = self._views[0]
        else:
            self.target.values[self.target_slots] = self.source.values[self.source_slots]


def _description(system: System, robot: str):
    """The description of the robot a FMU names: the experiment's robot where it is that one (a
    robot TOML anywhere, by path), else the package's robot of that name."""
    given = system.extra.get("robot")
    if isinstance(given, str):
        description = load_description(given)
        if description.name == robot:
            return description
    return load_description(robot)


def _consecutive(slots: np.ndarray) -> bool:
    return len(slots) > 0 and bool(np.all(np.diff(slots) == 1))


class InProcessDiagram:
    """An experiment's diagram built from the FMUs' FMI-free block logic.

    Parameters
    ----------
    system : System
        The experiment (its FMU files must exist: they are the source of the blocks'
        identities and defaults).

    Raises
    ------
    DiagramError
        If the diagram cannot run (the master's checks).
    ValueError
        If a FMU is not a robofmu block or was built from other sources than this process runs,
        or if a block has a sample time of its own (the replica steps every block at the base step).
    """

    def __init__(self, system: System):
        self.system = system
        self.plan = check_plan(system)
        slower = [b.name for b in system.blocks
                  if b.sample_time is not None and not math.isclose(b.sample_time, system.step, rel_tol=1e-9)]
        if slower:
            raise ValueError(f"{system.name}: blocks {', '.join(slower)} have a sample time of their own; the "
                             "in-process replica and the monolithic reference step every block at the base step")
        self.order = list(self.plan.order)
        self.blocks: dict[str, Block] = {}
        for name, node in self.plan.nodes.items():
            identity = block_identity(node.path)
            if identity.get("source") != SOURCE_HASH:
                raise ValueError(f"block {name!r}: {node.path} was built from other robofmu sources "
                                 "than this process runs; rebuild the FMUs (`robofmu build`)")
            description = _description(system, identity["robot"])
            if identity.get("profile"):                  # a named profile's trajectory FMU
                description = description.block_of(PROFILE_PREFIX + identity['profile'])[2]
            block = block_class(identity["kind"], identity.get("variant", ""))(load_model(description))
            for variable, value in start_values(node.model_description).items():
                block.set(variable, value)
            for base, value in node.spec.parameters.items():
                names = expand(node.variables, base)
                for scalar, item in zip(names, spread(names, value, f"{name}.{base}")):
                    block.set(scalar, coerce(node.variables[scalar].type, item, f"{name}.{scalar}"))
            self.blocks[name] = block
        rank = {name: k for k, name in enumerate(self.order)}
        early: dict[str, list] = {name: [] for name in self.order}
        late: dict[str, list] = {name: [] for name in self.order}
        for link in self.plan.links:
            phase = early if rank[link.source] < rank[link.target] else late
            phase[link.target].append(link)
        self.early = {name: self._wires(links) for name, links in early.items()}
        self.late = [w for name in self.order for w in self._wires(late[name])]
        self._pass = []                   # evaluate(t) as one flat list: (op, takes t), in order
        for name in self.order:
            self._pass += [(wire.apply, False) for wire in self.early[name]] + [(self.blocks[name].output, True)]
        self._pass += [(wire.apply, False) for wire in self.late]
        self.columns = self._recorded()

    def _wires(self, links) -> list[_Wire]:
        by_source: dict[str, list] = {}
        for link in links:
            by_source.setdefault(link.source, []).append(link)
        wires = []
        for source, group in by_source.items():
            src, dst = self.blocks[source], self.blocks[group[0].target]
            wires.append(_Wire(src, np.array([src.index[lk.output] for lk in group]),
                               dst, np.array([dst.index[lk.input] for lk in group])))
        return wires

    def _recorded(self):
        """Every output of every block (Reals, then Booleans, as the master records them): their
        column names, and where :meth:`_row` gathers them from."""
        columns, record, self.units = [], [], {}
        for kind in ("Real", "Boolean"):
            for name in self.order:
                block = self.blocks[name]
                slots = [k for k, v in enumerate(block.variables) if v.causality == "output" and v.kind == kind]
                columns += [f"{name}.{block.variables[k].name}" for k in slots]
                self.units.update({f"{name}.{block.variables[k].name}": block.variables[k].unit
                                   for k in slots if block.variables[k].unit})
                record.append((name, slots))
        self._sources = [self.blocks[name].values for name in self.order]   # never replaced
        offsets = dict(zip(self.order, np.cumsum([0] + [len(v) for v in self._sources])))
        self._stacked = np.zeros(sum(len(v) for v in self._sources))
        self._gather = np.array([offsets[name] + k for name, slots in record for k in slots], dtype=np.intp)
        return columns

    # -- shared pieces -------------------------------------------------------------------------------
    def configure(self) -> None:
        """Configure every block (validates parameters, resets state)."""
        for name in self.order:
            try:
                self.blocks[name].configure()
            except ValueError as exc:
                raise ValueError(f"block {name!r}: {exc}") from None

    def evaluate(self, t: float) -> None:
        """One Gauss-Seidel pass at ``t``: every block's outputs, then the late inputs."""
        for op, timed in self._pass:
            if timed:
                op(t)
            else:
                op()

    def _row(self, out: np.ndarray) -> None:
        np.concatenate(self._sources, out=self._stacked)      # every block's values, then one gather
        self._stacked.take(self._gather, out=out)

    # -- sampled (the master's loop) -------------------------------------------------------------------
    def sampled(self, step: float, stop_time: float, start_time: float = 0.0) -> Result:
        """The diagram co-simulated in-process at communication step ``step`` (s).

        Returns
        -------
        Result
            The master's columns (every output); ``info["wall_time"]`` is the loop's wall time (s).
        """
        h = float(step)
        n_steps = step_count(start_time, stop_time, h)
        self.configure()
        times = start_time + h * np.arange(n_steps + 1)
        data = np.empty((n_steps + 1, len(self.columns)))
        blocks = [self.blocks[name] for name in self.order]
        advances = [block.advance for block in blocks]
        t_block = times[0]                 # the blocks' own time: t_k + h after a step, as in a FMU
        wall = _time.perf_counter()
        for k in range(n_steps + 1):
            self.evaluate(t_block)
            self._row(data[k])
            if k == n_steps:
                break
            t = times[k]
            for advance in advances:
                advance(t, h)
            t_block = t + h
        return Result(times, list(self.columns), data,
                      {"algorithm": "in-process", "step": h, "wall_time": _time.perf_counter() - wall},
                      dict(self.units))

    # -- monolithic ---------------------------------------------------------------------------------
    def monolithic(self, stop_time: float, start_time: float = 0.0, rtol: float = defaults.REFERENCE_RTOL,
                   atol: float = 1e-12) -> "Monolithic":
        """Integrate the diagram as one ODE from ``start_time`` to ``stop_time`` (s)."""
        return Monolithic(self, start_time, stop_time, rtol, atol)


class Monolithic:
    """The diagram as one ODE in the blocks' continuous states, solved piecewise.

    Use :meth:`evaluate` to sample every output at any times in the solved interval.

    Attributes
    ----------
    stats : dict
        ``nfev`` (right-hand side evaluations), ``pieces``, ``wall_time`` (s).
    """

    def __init__(self, diagram: InProcessDiagram, start_time: float, stop_time: float,
                 rtol: float, atol: float):
        self.diagram = diagram
        diagram.configure()
        self.stateful = [diagram.blocks[n] for n in diagram.order if diagram.blocks[n].continuous_state().size]
        self.sizes = [b.continuous_state().size for b in self.stateful]
        self.cuts = np.cumsum([0] + self.sizes)
        x0 = np.concatenate([b.continuous_state() for b in self.stateful]) if self.stateful else np.zeros(0)
        breaks = np.unique(np.concatenate([b.breakpoints() for b in diagram.blocks.values()] + [[]]))
        breaks = breaks[(breaks > start_time) & (breaks < stop_time)]
        if breaks.size:
            breaks = breaks[np.concatenate([[True], np.diff(breaks) > 1e-9])]
        bounds = np.concatenate([[start_time], breaks, [stop_time]])
        self.pieces = []
        nfev, wall = 0, _time.perf_counter()
        x = x0
        for block in diagram.blocks.values():
            block.snap = False         # inside a piece: the piece's own branch, never a neighbour's
        for lo, hi in zip(bounds[:-1], bounds[1:]):
            sol = solve_ivp(self._rhs, (lo, hi), x, method=defaults.REFERENCE_SOLVER, rtol=rtol, atol=atol,
                            dense_output=True, args=(lo, hi))
            if not sol.success:
                raise RuntimeError(f"monolithic reference: integration failed on [{lo}, {hi}] s: {sol.message}")
            nfev += sol.nfev
            self.pieces.append((lo, hi, sol.sol))
            x = sol.y[:, -1]
        self.start_time, self.stop_time = start_time, stop_time
        self.stats = {"nfev": nfev, "pieces": len(self.pieces), "wall_time": _time.perf_counter() - wall}

    def _set_states(self, x: np.ndarray) -> None:
        for block, a, b in zip(self.stateful, self.cuts[:-1], self.cuts[1:]):
            block.set_continuous_state(x[a:b])

    def _rhs(self, t, x, lo, hi):
        self._set_states(x)
        inside = min(max(t, lo + INSIDE), hi - INSIDE)
        self.diagram.evaluate(inside)
        return np.concatenate([b.derivative(inside) for b in self.stateful]) if self.stateful else x * 0.0

    def state(self, t: float) -> np.ndarray:
        """The continuous states at ``t`` (s), concatenated in evaluation order."""
        for lo, hi, sol in self.pieces:
            if t <= hi + 1e-12:
                return sol(min(max(t, lo), hi))
        raise ValueError(f"t = {t} s lies beyond the solved interval (to {self.stop_time} s)")

    def evaluate(self, times) -> Result:
        """Every output at ``times`` (s), as the blocks compute them at those instants.

        At a breakpoint the blocks read their profiles at the instant itself (as a sampled
        block does); the states are continuous there.
        """
        times = np.asarray(times, dtype=float)
        diagram = self.diagram
        for block in diagram.blocks.values():
            block.snap = True
        data = np.empty((len(times), len(diagram.columns)))
        for k, t in enumerate(times):
            self._set_states(self.state(t))
            diagram.evaluate(t)
            diagram._row(data[k])
        return Result(times, list(diagram.columns), data, {"algorithm": "monolithic", **self.stats},
                      dict(diagram.units))

"""The co-simulation master: checks a diagram, initializes its FMUs and steps them.

At every communication point t the master evaluates the diagram in dependency order
(Gauss-Seidel: a direct-feedthrough block reads inputs its upstream blocks produced at t, so
trajectory -> ik -> controller -> plant has no step of delay); inputs that come from blocks
evaluated later (the plant's torque: the plant has no feedthrough, so it is evaluated before the
controller) are set once the pass is over. It records every output, then calls doStep(t, h) on
each block, so the plant integrates [t, t + h] with the torque computed at t. The Jacobi option reads all outputs first and then sets all inputs,
so each feedthrough block lags one step (for comparison).

Values move between FMUs through preallocated buffers: one batched fmi2GetReal per block into a
signal vector, one batched fmi2SetReal per block from it; nothing is allocated per step.
"""
from __future__ import annotations

import csv
import ctypes
import math
import time as _time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
from fmpy import read_model_description
from fmpy.fmi2 import fmi2True

from .diagram import System, coerce, expand, select, spread
from .fmu import STATUS, Block, FMUError, LogMessage

ALGORITHMS = ("gauss-seidel", "jacobi")


def step_count(start_time: float, stop_time: float, step: float) -> int:
    """Number of communication steps of ``step`` s from start to stop; ValueError unless whole."""
    if not (step > 0 and math.isfinite(step)):
        raise ValueError(f"communication step must be > 0 s, got {step}")
    n = int(round((stop_time - start_time) / step))
    if n < 1 or abs(start_time + n * step - stop_time) > 1e-9 * max(1.0, abs(stop_time)):
        raise ValueError(f"stop time {stop_time} s is not start time {start_time} s plus a whole "
                         f"number of {step} s steps")
    return n


class DiagramError(ValueError):
    """The diagram cannot run; ``problems`` lists every reason, each naming blocks and variables."""

    def __init__(self, system: str, problems: list[str]):
        super().__init__(f"{system}: the diagram cannot run:\n  - " + "\n  - ".join(problems))
        self.problems = problems


class SimulationError(RuntimeError):
    """A run failed; ``result`` holds everything recorded up to the failure."""

    def __init__(self, message: str, block: str | None, time: float | None, result: "Result | None"):
        super().__init__(message)
        self.block = block
        self.time = time
        self.result = result


@dataclass
class Result:
    """Recorded signals: ``time`` (n,) in s and ``data`` (n, m), one column per signal."""

    time: np.ndarray
    columns: list[str]
    data: np.ndarray
    info: dict = field(default_factory=dict)

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.data[:, self.columns.index(name)]
        except ValueError:
            raise KeyError(f"no recorded signal {name!r}") from None

    def vector(self, name: str) -> np.ndarray:
        """All indices of a recorded vector, e.g. ``plant.q`` -> shape (n, 4)."""
        cols = [i for i, c in enumerate(self.columns) if c.startswith(name + "[")]
        if not cols:
            raise KeyError(f"no recorded vector {name!r}")
        return self.data[:, cols]

    def to_csv(self, path: str | Path) -> Path:
        """``time`` then one column per signal (``instance.variable``), full precision."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["time", *self.columns])
            for t, row in zip(self.time, self.data):
                w.writerow([repr(float(t)), *(repr(float(v)) for v in row)])
        return path

    @classmethod
    def from_csv(cls, path: str | Path) -> "Result":
        with Path(path).open() as f:
            rows = list(csv.reader(f))
        data = np.array([[float(v) for v in r] for r in rows[1:]]).reshape(-1, len(rows[0]))
        return cls(data[:, 0], rows[0][1:], data[:, 1:])


class _Port:
    """Preallocated ctypes views for one batched get or set of one type on one block."""

    def __init__(self, vrs: list[int], buffer: np.ndarray, ctype):
        self.n = len(vrs)
        self.vr = (ctypes.c_uint * max(self.n, 1))(*vrs)
        self.buffer = buffer
        self.c = (ctype * self.n).from_buffer(buffer) if self.n else None


@dataclass
class _Node:
    spec: object
    path: Path
    md: object
    variables: dict
    feedthrough: dict = field(default_factory=dict)   # output name -> set of input names


class Master:
    """Runs a :class:`System`.

    Parameters
    ----------
    system : System
    record : list of str, optional
        ``instance.variable`` patterns (fnmatch) of the outputs to record; default all outputs.
    progress : callable, optional
        ``progress(fraction, t)`` about 20 times in a run.
    log : callable, optional
        Receives every FMU log message as it arrives.
    """

    def __init__(self, system: System, record: list[str] | None = None,
                 progress: Callable[[float, float], None] | None = None,
                 log: Callable[[LogMessage], None] | None = None):
        self.system = system
        self.record = record
        self.progress = progress
        self.log = log
        self.warnings: list[str] = []
        self.order: list[str] = []
        self.nodes: dict[str, _Node] = {}
        self.blocks: dict[str, Block] = {}
        self._checked = False

    # -- checks ------------------------------------------------------------------------------------
    def check(self) -> list[str]:
        """Refuse a diagram that cannot run (DiagramError); return the warnings."""
        from fmpy.validation import validate_fmu

        s = self.system
        problems: list[str] = []
        self.nodes = {}
        for spec in s.blocks:
            path = s.fmu_path(spec)
            if not path.is_file():
                problems.append(f"block {spec.name!r}: FMU {path} does not exist (run `robofmu build`)")
                continue
            try:
                found = validate_fmu(str(path))
                md = read_model_description(str(path), validate=False)
            except Exception as exc:
                problems.append(f"block {spec.name!r}: {path} is not a valid FMU: {exc}")
                continue
            if found:
                problems.append(f"block {spec.name!r}: {path} is not a valid FMU: " + "; ".join(map(str, found)))
                continue
            if md.coSimulation is None:
                problems.append(f"block {spec.name!r}: {path} is not a co-simulation FMU")
                continue
            node = _Node(spec, path, md, {v.name: v for v in md.modelVariables})
            inputs = {n for n, v in node.variables.items() if v.causality == "input"}
            for u in md.outputs:
                deps = u.dependencies
                node.feedthrough[u.variable.name] = inputs if deps is None else {d.name for d in deps} & inputs
            self.nodes[spec.name] = node

        def names(node: _Node, base: str) -> list[str]:
            return expand(node.variables, base)

        for spec in s.blocks:
            node = self.nodes.get(spec.name)
            if node is None:
                continue
            for pname, value in spec.parameters.items():
                vs = names(node, pname)
                if not vs:
                    problems.append(f"block {spec.name!r}: unknown parameter {pname!r} in {node.path.name}")
                    continue
                if any(node.variables[v].causality not in ("parameter", "input") for v in vs):
                    problems.append(f"block {spec.name!r}: {pname!r} is a {node.variables[vs[0]].causality}, "
                                    "not a parameter")
                    continue
                try:
                    for v, x in zip(vs, spread(vs, value, f"{spec.name}.{pname}")):
                        coerce(node.variables[v].type, x, f"{spec.name}.{v}")
                except ValueError as exc:
                    problems.append(f"block {spec.name!r}: parameter {exc}")

        self.links: list[tuple[str, str, str, str]] = []   # src, out, dst, in (scalar names)
        driven: dict[tuple[str, str], str] = {}
        for wire in s.wires:
            src, dst = self.nodes.get(wire.src), self.nodes.get(wire.dst)
            for end, node in ((wire.src, src), (wire.dst, dst)):
                if node is None and end not in [b.name for b in s.blocks]:
                    problems.append(f"connection {wire}: no block {end!r}")
            if src is None or dst is None:
                continue
            outs, ins = names(src, wire.src_var), names(dst, wire.dst_var)
            if not outs:
                problems.append(f"connection {wire}: {wire.src} has no variable {wire.src_var!r}")
                continue
            if not ins:
                problems.append(f"connection {wire}: {wire.dst} has no variable {wire.dst_var!r}")
                continue
            if len(outs) != len(ins):
                problems.append(f"connection {wire}: {len(outs)} source variables for {len(ins)} inputs")
                continue
            for o, i in zip(outs, ins):
                vo, vi = src.variables[o], dst.variables[i]
                where = f"connection {wire.src}.{o} -> {wire.dst}.{i}"
                if vo.causality != "output":
                    problems.append(f"{where}: {wire.src}.{o} is a {vo.causality}, not an output")
                if vi.causality != "input":
                    problems.append(f"{where}: {wire.dst}.{i} is a {vi.causality}, not an input")
                if vo.type != vi.type:
                    problems.append(f"{where}: type mismatch ({vo.type} -> {vi.type})")
                uo, ui = _unit(vo), _unit(vi)
                if uo and ui and uo != ui:
                    problems.append(f"{where}: unit mismatch ({uo} -> {ui})")
                key = (wire.dst, i)
                if key in driven:
                    problems.append(f"input {wire.dst}.{i} is driven twice: by {driven[key]} and {wire.src}.{o}")
                driven[key] = f"{wire.src}.{o}"
                self.links.append((wire.src, o, wire.dst, i))

        problems += self._algebraic_loops()
        if problems:
            raise DiagramError(s.name, problems)

        self.warnings = []
        for name, node in self.nodes.items():
            for v in node.md.modelVariables:
                if v.causality == "input" and (name, v.name) not in driven:
                    self.warnings.append(f"input {name}.{v.name} is not connected: it keeps its start value {v.start}")
        self.order = self._evaluation_order()
        self._checked = True
        return self.warnings

    def _algebraic_loops(self) -> list[str]:
        """Cycles through direct feedthrough, on the variable graph: output -> wired input ->
        the outputs of that block depending on it."""
        succ: dict[tuple, list[tuple]] = {}
        for src, o, dst, i in self.links:
            for out, deps in self.nodes[dst].feedthrough.items():
                if i in deps:
                    succ.setdefault((src, o), []).append((dst, out))
        problems, state, stack = [], {}, []

        def visit(v):
            state[v] = 1
            stack.append(v)
            for w in succ.get(v, []):
                if state.get(w) == 1:
                    cycle = stack[stack.index(w):] + [w]
                    problems.append("algebraic loop through direct feedthrough: "
                                    + " -> ".join(f"{b}.{n}" for b, n in cycle))
                elif w not in state:
                    visit(w)
            stack.pop()
            state[v] = 2

        for v in list(succ):
            if v not in state:
                visit(v)
        return problems[:1] if problems else []

    def _evaluation_order(self) -> list[str]:
        """Blocks in an order where every feedthrough input is produced before it is read."""
        names = [b.name for b in self.system.blocks]
        after: dict[str, set[str]] = {n: set() for n in names}
        for src, o, dst, i in self.links:
            if src != dst and any(i in deps for deps in self.nodes[dst].feedthrough.values()):
                after[dst].add(src)
        order, done = [], set()
        while len(order) < len(names):
            ready = [n for n in names if n not in done and after[n] <= done]
            if not ready:
                stuck = [n for n in names if n not in done]
                raise DiagramError(self.system.name, [
                    "blocks feed each other's feedthrough inputs in a cycle and cannot be ordered: "
                    + ", ".join(stuck)])
            order.append(ready[0])
            done.add(ready[0])
        return order

    # -- run ----------------------------------------------------------------------------------------
    def run(self, stop_time: float | None = None, step: float | None = None,
            algorithm: str | None = None, start_time: float = 0.0,
            csv_path: str | Path | None = None) -> Result:
        """Initialize every block and step the diagram from ``start_time`` to ``stop_time``.

        On a failure, raises SimulationError naming the block, the time and the FMU's message;
        its ``result`` holds every point recorded so far (also written to ``csv_path`` if given).
        """
        s = self.system
        stop_time = s.stop_time if stop_time is None else float(stop_time)
        h = s.step if step is None else float(step)
        algorithm = s.algorithm if algorithm is None else algorithm
        if algorithm not in ALGORITHMS:
            raise ValueError(f"algorithm {algorithm!r}: choose one of {', '.join(ALGORITHMS)}")
        n_steps = step_count(start_time, stop_time, h)
        if not self._checked:
            self.check()
        try:
            self._instantiate(start_time, stop_time)
            return self._loop(start_time, h, n_steps, algorithm, csv_path)
        finally:
            self.close()

    def _instantiate(self, t0: float, t_end: float) -> None:
        self.blocks = {}
        for name in self.order:
            node = self.nodes[name]
            try:
                block = Block(node.path, name, echo=self.log)
            except FMUError as exc:
                raise SimulationError(str(exc), name, None, None) from None
            self.blocks[name] = block
            try:
                block.initialize(t0, node.spec.parameters, stop_time=t_end)
            except FMUError as exc:
                raise SimulationError(f"{exc}", name, t0, None) from None

    def _layout(self):
        """Signal vectors, ports and recorded columns."""
        real_out, bool_out = [], []
        for name in self.order:
            for v in self.nodes[name].md.modelVariables:
                if v.causality == "output" and v.type == "Real":
                    real_out.append((name, v.name, v.valueReference))
                elif v.causality == "output" and v.type == "Boolean":
                    bool_out.append((name, v.name, v.valueReference))
        self.sig = np.zeros(len(real_out))
        self.bsig = np.zeros(len(bool_out), dtype=np.int32)
        ridx = {(b, n): k for k, (b, n, _) in enumerate(real_out)}
        bidx = {(b, n): k for k, (b, n, _) in enumerate(bool_out)}
        self.ports = {}
        rank = {n: k for k, n in enumerate(self.order)}
        for name in self.order:
            rows = [k for k, (b, _, _) in enumerate(real_out) if b == name]
            brows = [k for k, (b, _, _) in enumerate(bool_out) if b == name]
            get_r = _Port([real_out[k][2] for k in rows], self.sig[rows[0]:rows[-1] + 1] if rows else np.zeros(0),
                          ctypes.c_double)
            get_b = _Port([bool_out[k][2] for k in brows], self.bsig[brows[0]:brows[-1] + 1] if brows
                          else np.zeros(0, dtype=np.int32), ctypes.c_int)
            # Inputs from blocks evaluated earlier are set before this block's outputs are read;
            # inputs from blocks evaluated later cannot affect those outputs (the order is
            # topological in the feedthrough graph) and are set after the pass, before doStep.
            links = [lk for lk in self.links if lk[2] == name]
            early = _Inputs([lk for lk in links if rank[lk[0]] < rank[name]], self.nodes[name].variables, ridx, bidx)
            late = _Inputs([lk for lk in links if rank[lk[0]] >= rank[name]], self.nodes[name].variables, ridx, bidx)
            self.ports[name] = (get_r, get_b, early, late)
        self.real_names = [f"{b}.{n}" for b, n, _ in real_out]
        self.bool_names = [f"{b}.{n}" for b, n, _ in bool_out]
        columns = self.real_names + self.bool_names
        keep = select(columns, self.record)
        self.columns = [columns[k] for k in keep]
        self.keep = np.array(keep, dtype=np.intp)

    def _operations(self, algorithm: str):
        """One exchange and one step as flat lists of closures over preallocated buffers.

        Gauss-Seidel: for each block in evaluation order, set its inputs from blocks evaluated
        before it, then read its outputs; after the pass, set the inputs that come from blocks
        evaluated later. Jacobi: read every output, then set every input.
        """
        sig, bsig = self.sig, self.bsig
        early, pull, late, steps = [], [], [], []
        for name in self.order:
            fn = _Raw(self.blocks[name].slave)
            get_r, get_b, inputs_early, inputs_late = self.ports[name]
            ops = []
            for port, f, call in ((get_r, fn.get_real, "fmi2GetReal"), (get_b, fn.get_bool, "fmi2GetBoolean")):
                if port.n:
                    ops.append(_get(f, fn.c, port, name, call))
            pull.append(ops)
            early.append(_sets(fn, inputs_early, sig, bsig, name))
            late.append(_sets(fn, inputs_late, sig, bsig, name))
            steps.append(_step(fn, name))
        gauss_seidel = [op for e, p in zip(early, pull) for op in e + p] + [op for ops in late for op in ops]
        if algorithm == "gauss-seidel":
            return gauss_seidel, gauss_seidel, steps
        jacobi = [op for ops in pull for op in ops] + [op for e, lt in zip(early, late) for op in e + lt]
        return gauss_seidel, jacobi, steps     # Jacobi, too, starts from a consistent first exchange

    def _loop(self, t0: float, h: float, n_steps: int, algorithm: str, csv_path) -> Result:
        self._layout()
        sig, bsig = self.sig, self.bsig
        nr = len(sig)
        row = np.zeros(nr + len(bsig))
        record_all = np.array_equal(self.keep, np.arange(len(row)))
        rec = np.empty((n_steps + 1, len(self.keep)))
        times = t0 + h * np.arange(n_steps + 1)
        first, exchange, steps = self._operations(algorithm)
        every = max(1, n_steps // 20)
        t, k, n_rec = t0, 0, 0
        wall = _time.perf_counter()
        try:
            for k in range(n_steps + 1):
                t = times[k]
                for op in (first if k == 0 else exchange):    # Jacobi, too, starts consistent
                    op()
                if not math.isfinite(sig.dot(sig)) and not np.isfinite(sig).all():
                    bad = self.real_names[int(np.flatnonzero(~np.isfinite(sig))[0])]
                    raise _Failure(bad.split(".")[0], f"output {bad} is not finite "
                                   f"({sig[self.real_names.index(bad)]}) at t = {t:.9g} s")
                if record_all:
                    rec[k, :nr] = sig
                    rec[k, nr:] = bsig
                else:
                    row[:nr] = sig
                    row[nr:] = bsig
                    rec[k] = row[self.keep]
                n_rec = k + 1
                if k == n_steps:
                    break
                for op in steps:
                    op(t, h)
                if self.progress is not None and (k + 1) % every == 0:
                    self.progress((k + 1) / n_steps, t + h)
        except _Failure as exc:
            if exc.call:
                logged = [m.message for m in self.blocks[exc.block].messages
                          if m.status in ("ERROR", "FATAL", "DISCARD")]
                message = (f"{exc.block}: {exc.call} failed at t = {t:.9g} s"
                           + (": " + logged[-1] if logged else f" (status {exc.message})"))
            else:
                message = f"{exc.block}: {exc.message}"
            result = Result(times[:n_rec].copy(), list(self.columns), rec[:n_rec].copy(),
                            {"failed": message, "algorithm": algorithm, "step": h})
            if csv_path is not None:
                result.to_csv(csv_path)
            raise SimulationError(message + (f"\nresults up to t = {times[n_rec - 1]:.9g} s kept"
                                             + (f" in {csv_path}" if csv_path else "") if n_rec else ""),
                                  exc.block, float(t), result) from None
        result = Result(times, list(self.columns), rec,
                        {"algorithm": algorithm, "step": h, "wall_time": _time.perf_counter() - wall,
                         "order": list(self.order)})
        if csv_path is not None:
            result.to_csv(csv_path)
        return result

    def close(self) -> None:
        for b in self.blocks.values():
            b.close()
        self.blocks = {}


class _Inputs:
    """The wired inputs of one block fed in one phase: value references, buffers, sources."""

    def __init__(self, links, variables, ridx, bidx):
        rl = [lk for lk in links if variables[lk[3]].type == "Real"]
        bl = [lk for lk in links if variables[lk[3]].type == "Boolean"]
        self.real = _Port([variables[i].valueReference for _, _, _, i in rl], np.zeros(len(rl)), ctypes.c_double)
        self.boolean = _Port([variables[i].valueReference for _, _, _, i in bl],
                             np.zeros(len(bl), dtype=np.int32), ctypes.c_int)
        self.src_r = np.array([ridx[(s, o)] for s, o, _, _ in rl], dtype=np.intp)
        self.src_b = np.array([bidx[(s, o)] for s, o, _, _ in bl], dtype=np.intp)
        self.last_b = b""          # bytes of the values last set (none yet)


class _Raw:
    """A block's FMI functions as fmpy loaded them (prototypes set), called without fmpy's
    per-call Python wrapper: the master checks the returned status itself."""

    def __init__(self, slave):
        f = slave._functions
        self.c = slave.component
        self.get_real, self.set_real = f["fmi2GetReal"], f["fmi2SetReal"]
        self.get_bool, self.set_bool = f["fmi2GetBoolean"], f["fmi2SetBoolean"]
        self.do_step = f["fmi2DoStep"]


class _Failure(Exception):
    """A block failed: an FMI call returned an error status (``call`` set), or an output is bad."""

    def __init__(self, block: str, message: str, call: str | None = None):
        super().__init__(message)
        self.block = block
        self.message = message
        self.call = call


def _status(status: int) -> str:
    return STATUS[status].lower() if 0 <= status < len(STATUS) else str(status)


def _get(f, c, port: _Port, name: str, call: str):
    """A closure reading one block's outputs of one type into the signal vector."""
    def op(f=f, c=c, vr=port.vr, n=port.n, buf=port.c):
        status = f(c, vr, n, buf)
        if status > 1:
            raise _Failure(name, _status(status), call)
    return op


def _sets(fn: _Raw, inputs: _Inputs, sig, bsig, name: str) -> list:
    """Closures setting one block's inputs (of one phase) from the signal vectors."""
    ops = []
    real, boolean = inputs.real, inputs.boolean
    if real.n:
        def set_real(take=sig.take, src=inputs.src_r, out=real.buffer, f=fn.set_real, c=fn.c, vr=real.vr,
                     n=real.n, buf=real.c):
            take(src, out=out)
            status = f(c, vr, n, buf)
            if status > 1:
                raise _Failure(name, _status(status), "fmi2SetReal")
        ops.append(set_real)
    if boolean.n:
        def set_boolean(take=bsig.take, src=inputs.src_b, out=boolean.buffer, f=fn.set_bool, c=fn.c,
                        vr=boolean.vr, n=boolean.n, buf=boolean.c):
            take(src, out=out)
            now = out.tobytes()
            if now != inputs.last_b:       # discrete inputs: set only when they change
                status = f(c, vr, n, buf)
                if status > 1:
                    raise _Failure(name, _status(status), "fmi2SetBoolean")
                inputs.last_b = now
        ops.append(set_boolean)
    return ops


def _step(fn: _Raw, name: str):
    def op(t, h, f=fn.do_step, c=fn.c):
        status = f(c, t, h, fmi2True)
        if status > 1:
            raise _Failure(name, _status(status), "fmi2DoStep")
    return op


def _unit(v) -> str | None:
    if v.unit:
        return v.unit
    if v.declaredType is not None and getattr(v.declaredType, "unit", None):
        return v.declaredType.unit
    return None

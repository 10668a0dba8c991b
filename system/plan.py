"""The plan of a run: everything known about it before any FMU is instantiated, in one pass.

:func:`plan` reads the System, its FMUs' model descriptions (each parsed once per file:
:func:`described`) and the run's :class:`Times`, and either refuses it or returns a frozen
:class:`Plan` the master reads as it is:

- the blocks (:class:`Node`: FMU, model description, variables, direct-feedthrough map), the
  wires expanded to scalar :class:`Link` s, the warnings (unconnected inputs the experiment gives
  no value) and an evaluation order in which every feedthrough input is produced before it is read;
- the recorded columns (``record``: exact names, vector bases, fnmatch patterns);
- the times (:func:`times`: start, stop, base step, number of base steps), each block's sample
  time as a whole number of base steps (:attr:`Plan.ratios`), and whether the recording fits in
  memory (:attr:`Plan.memory`).

A diagram that cannot run is refused with a :class:`DiagramError` listing every problem at once,
each naming blocks and variables; bad times with a ValueError naming the value (worded by the
caller: ``Master.run``'s arguments, ``robofmu run``'s options).

Here too are the facts read from a model description: a variable's unit (:func:`variable_unit`)
and a block's defaults, the start values of its parameters and inputs (:func:`start_values`).
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable, NamedTuple

from robofmu.components.unknown_names import nearest
from robofmu.system.diagram import BlockSpec, System, bases, coerce, expand, select, spread, unmatched

__all__ = ["DiagramError", "Link", "Node", "Plan", "Times", "available_memory", "described", "gigabytes",
           "memory_shortfall", "plan", "single_rate", "start_values", "step_count", "times", "variable_unit"]


# -- times ---------------------------------------------------------------------------------------
def step_count(start_time: float, stop_time: float, step: float) -> int:
    """Number of communication steps from ``start_time`` to ``stop_time``.

    Parameters
    ----------
    start_time, stop_time : float
        Interval (s).
    step : float
        Communication step (s), > 0 and finite.

    Returns
    -------
    int
        n >= 1 with ``start_time + n * step == stop_time`` (to 1e-9 relative).

    Raises
    ------
    ValueError
        If the step is not positive and finite, or the interval is not a whole number of steps.
    """
    if not (step > 0 and math.isfinite(step)):
        raise ValueError(f"communication step must be > 0 s, got {step}")
    n = int(round((stop_time - start_time) / step))
    if n < 1 or abs(start_time + n * step - stop_time) > 1e-9 * max(1.0, abs(stop_time)):
        raise ValueError(f"stop time {stop_time} s is not start time {start_time} s plus a whole "
                         f"number of {step} s steps")
    return n


@dataclass(frozen=True)
class Times:
    """A run's times (s): ``start + n_steps * step == stop``; ``step`` is the base step."""

    start: float
    stop: float
    step: float
    n_steps: int


def times(system: System, start_time: float = 0.0, stop_time: float | None = None, step: float | None = None,
          named: Callable[[str, float, bool], str] | None = None) -> Times:
    """The run's :class:`Times`, checked: the one check of a run's start, stop and base step.

    Parameters
    ----------
    system : System
        Its ``stop_time`` and ``step`` are the defaults.
    start_time, stop_time, step : float, optional
        (s); None: the system's.
    named : callable, optional
        ``named(key, value, given)`` -> how a message names the value of ``key`` (``start_time``,
        ``stop_time``, ``step``; ``given``: False where it is the system's default). Default:
        ``step = 0.001 s`` (``(system 'chess-pd')`` after a default).

    Raises
    ------
    ValueError
        One line naming the value: not finite, a step not > 0, a stop not after the start, more
        steps than memory can record, a stop time shorter than one step or not a whole number of
        steps.
    """
    given = {"start_time": True, "stop_time": stop_time is not None, "step": step is not None}
    values = {"start_time": float(start_time),
              "stop_time": float(system.stop_time if stop_time is None else stop_time),
              "step": float(system.step if step is None else step)}
    worded = named is not None
    if named is None:
        def named(key, value, given_):
            return f"{key} = {value!r} s" + ("" if given_ else f" (system {system.name!r})")

    def name(key: str) -> str:
        return named(key, values[key], given[key])

    for key, value in values.items():
        if not math.isfinite(value):
            raise ValueError(f"{name(key)} is invalid: must be a finite time")
    start, stop, h = values["start_time"], values["stop_time"], values["step"]
    if not h > 0.0:
        raise ValueError(f"{name('step')} is invalid: must be > 0")
    if not stop > start:
        raise ValueError(f"{name('stop_time')} is invalid: must be after {name('start_time')}")
    ratio = (stop - start) / h
    if not ratio <= 1e15:
        raise ValueError(f"{name('stop_time')}, {name('start_time')} and {name('step')} make {ratio:.3g} steps, far "
                         "more than memory can record")
    if worded and round(ratio) < 1:
        raise ValueError(f"{name('stop_time')} is shorter than one step of {name('step')}")
    try:
        n = step_count(start, stop, h)
    except ValueError as exc:
        raise ValueError(f"{name('stop_time')} is not a whole number of steps of {name('step')}" if worded
                         else str(exc)) from None
    return Times(start, stop, h, n)


# -- memory --------------------------------------------------------------------------------------
def available_memory() -> int | None:
    """Bytes of memory available to a new allocation (``MemAvailable``), or None if unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        return None


def gigabytes(n: int) -> str:
    """A byte count for messages: 38.5 GB, 288 TB."""
    for size, unit in ((1e12, "TB"), (1e9, "GB"), (1e6, "MB")):
        if n >= size or unit == "MB":
            return f"{n / size:.3g} {unit}"


def memory_shortfall(need: int) -> str | None:
    """The one memory rule: None if ``need`` bytes fit in half the memory available (or it is
    unknown), else "<need> of memory, more than half of the <available> available"."""
    free = available_memory()
    if free is None or need <= free / 2:
        return None
    return f"{gigabytes(need)} of memory, more than half of the {gigabytes(free)} available"


def _memory_problem(n_steps: int, columns: int) -> str | None:
    """Why (n + 1) rows x (columns + time) x 8 bytes would not fit (:func:`memory_shortfall`)."""
    shortfall = memory_shortfall((n_steps + 1) * (columns + 1) * 8)
    return None if shortfall is None else f"{n_steps} steps x {columns} recorded signals need {shortfall}"


class DiagramError(ValueError):
    """The diagram cannot run; ``problems`` lists every reason, each naming blocks and variables."""

    def __init__(self, system: str, problems: list[str]):
        super().__init__(f"{system}: the diagram cannot run:\n  - " + "\n  - ".join(problems))
        self.problems = problems


# -- sample rates --------------------------------------------------------------------------------
def _ratios(system: System, step: float) -> tuple[dict[str, int], list[str]]:
    """Each block's sample time in base steps (1: the base step), and the sample times that are
    no whole multiple of ``step``."""
    ratios, problems = {}, []
    for spec in system.blocks:
        sample = spec.sample_time
        if sample is None:
            ratios[spec.name] = 1
            continue
        r = round(sample / step) if math.isfinite(sample) and sample > 0 else 0
        if r < 1 or abs(r * step - sample) > 1e-9 * sample:
            problems.append(f"block {spec.name!r}: sample_time = {sample:g} s is not a whole multiple of the base "
                            f"step {step:g} s")
        ratios[spec.name] = max(r, 1)
    return ratios, problems


def single_rate(system: System, format_: str) -> None:
    """Refuse (ValueError, one line) to export a multi-rate ``system`` to ``format_``, a format
    without a standard rate per component (SSP, an FMU container)."""
    ratios, problems = _ratios(system, system.step)
    if problems:
        raise DiagramError(system.name, problems)
    slow = {name: r for name, r in ratios.items() if r != 1}
    if slow:
        named = ", ".join(f"{name} every {r * system.step:g} s" for name, r in slow.items())
        raise ValueError(f"{system.name}: multi-rate ({named}, the rest every {system.step:g} s): {format_} has "
                         "no standard rate per component: robofmu exports it single-rate only (`robofmu osp` carries the rates)")


# -- facts of a model description ------------------------------------------------------------------
def variable_unit(variable) -> str | None:
    """The unit of a fmpy ``ScalarVariable``: its own ``unit``, else its declared type's, else None."""
    if variable.unit:
        return variable.unit
    declared = variable.declaredType
    if declared is not None and getattr(declared, "unit", None):
        return declared.unit
    return None


def start_values(model_description, causalities: tuple[str, ...] = ("parameter", "input"),
                 vectors: bool = False) -> dict:
    """A FMU's defaults: the start values of its parameters and inputs, typed.

    Parameters
    ----------
    model_description : fmpy.model_description.ModelDescription
        E.g. ``described(path)[1]``.
    causalities : tuple of str
        The causalities to include (default parameters and inputs).
    vectors : bool
        False: one entry per scalar variable (``q0[1]``, ``q0[2]``, ...). True: the elements of
        a vector base gathered into one list under the base (``q0``: [..], in index order).

    Returns
    -------
    dict
        Variable name -> value (float for Real, int for Integer and Enumeration, bool for
        Boolean, str for String), parsed by :func:`~robofmu.system.diagram.coerce`; variables
        without a start value are left out. Values are in the variables' units
        (:func:`variable_unit`).
    """
    values = {variable.name: coerce(variable.type, variable.start, f"start value of {variable.name}")
              for variable in model_description.modelVariables
              if variable.causality in causalities and variable.start is not None}
    if not vectors:
        return values
    grouped: dict = {}
    for name in values:
        base = name.split("[", 1)[0] if name.endswith("]") else name
        if base in grouped:
            continue
        members = expand(values, base)
        grouped[base] = values[base] if members == [base] else [values[m] for m in members]
    return grouped


#: (file identity) -> (validation problems, model description): an FMU file is validated and
#: read once per process while it stays the same file (a sweep plans the same diagram per run).
_DESCRIBED: dict[tuple, tuple[list, object]] = {}


def described(path: Path) -> tuple[list, object]:
    """fmpy's validation problems and model description of the FMU file ``path``: one validating
    read of its modelDescription.xml (what ``fmpy.validation.validate_fmu`` checks), cached by
    file identity (path, inode, size, mtime)."""
    import zipfile

    from fmpy import read_model_description
    from fmpy.model_description import ValidationError

    info = os.stat(path)
    identity = (os.path.realpath(path), info.st_ino, info.st_size, info.st_mtime_ns)
    if identity not in _DESCRIBED:
        found, model_description = [], None
        with zipfile.ZipFile(path) as archive:        # validate_fmu's one check beyond the XML
            found += [f'The file path "{f.orig_filename}" contains a backslash.' for f in archive.filelist
                      if "\\" in f.orig_filename]
        try:
            model_description = read_model_description(str(path), validate=True, validate_variable_names=True,
                                                        validate_model_structure=True)
        except ValidationError as exc:
            found += exc.problems
        except Exception as exc:
            found.append(str(exc))
        _DESCRIBED[identity] = (found, model_description)
    return _DESCRIBED[identity]


# -- the plan --------------------------------------------------------------------------------------
class Link(NamedTuple):
    """One scalar connection: ``source.output -> target.input`` (instance and variable names)."""

    source: str
    output: str
    target: str
    input: str


@dataclass(frozen=True)
class Node:
    """One block of a planned diagram.

    Parameters
    ----------
    spec : BlockSpec
    path : Path
        Its FMU file.
    model_description : fmpy.model_description.ModelDescription
    variables : dict
        Variable name -> fmpy ``ScalarVariable``.
    feedthrough : dict of str to set of str
        Output name -> the input names it depends on directly (all inputs when the model
        structure declares no dependencies for it).
    """

    spec: BlockSpec
    path: Path
    model_description: object
    variables: dict
    feedthrough: dict[str, set[str]] = field(default_factory=dict)

    @property
    def md(self):
        """Short name of :attr:`model_description`."""
        return self.model_description


@dataclass(frozen=True)
class Plan:
    """A run that can start.

    Parameters
    ----------
    system : System
    nodes : dict of str to Node
        By instance name, in the order of ``system.blocks``.
    links : list of Link
        Every wire expanded to scalar connections, in wire order.
    warnings : list of str
        Unconnected inputs the block's parameters give no value (they keep their start values;
        an input set there, e.g. a constant load, is meant to be held and is not warned about).
    order : list of str
        Instance names in an evaluation order: every block after the blocks feeding its
        direct-feedthrough inputs.
    recorded : tuple of str
        The recorded outputs (``instance.variable``, Real and Boolean, in evaluation order).
    times : Times or None
        The run's times (None: planned without them; :meth:`timed` adds them).
    ratios : dict of str to int
        Each block's sample time in base steps (1: every base step), against ``times.step``
        (the system's step without times).
    memory : str or None
        Why the recording would not fit in half the memory available (None: it fits, or no times).
    """

    system: System
    nodes: dict[str, Node]
    links: list[Link]
    warnings: list[str]
    order: list[str]
    recorded: tuple[str, ...] = ()
    times: Times | None = None
    ratios: dict[str, int] = field(default_factory=dict)
    memory: str | None = None

    @property
    def multirate(self) -> bool:
        """Whether some block samples slower than the base step."""
        return any(r != 1 for r in self.ratios.values())

    def timed(self, run_times: Times) -> "Plan":
        """This plan with ``run_times``: the blocks' ratios against its base step and the memory
        check of its recording (DiagramError for a sample time that is no whole multiple)."""
        ratios, problems = _ratios(self.system, run_times.step)
        if problems:
            raise DiagramError(self.system.name, problems)
        return replace(self, times=run_times, ratios=ratios,
                       memory=_memory_problem(run_times.n_steps, len(self.recorded)))


def plan(system: System, record: list[str] | None = None, run_times: Times | None = None) -> Plan:
    """Check ``system`` against its FMUs' model descriptions and plan its run.

    Nothing is instantiated. The checks: FMU missing or invalid (fmpy's validation), not
    co-simulation, unknown block, variable or parameter, a parameter value of the wrong type or
    length, causality (output -> input, parameter or input for parameters), type mismatch, unit
    mismatch (where both ends declare one), vector length mismatch, an input driven twice, an
    algebraic loop (a cycle through direct feedthrough; the same at any sample rates: a held
    output is still the output of the same inputs), blocks whose feedthrough inputs feed each
    other in a cycle (no evaluation order), a ``record`` entry that names no output, a sample
    time that is no whole multiple of the base step.

    Parameters
    ----------
    system : System
    record : list of str, optional
        Recorded outputs: exact names, vector bases or fnmatch patterns; default all.
    run_times : Times, optional
        The run's (:func:`times`); None: planned without times, the ratios against the system's step.

    Returns
    -------
    Plan

    Raises
    ------
    DiagramError
        Listing every problem found (the ordering cycle alone, as it is looked for only in an
        otherwise valid diagram).
    """
    nodes, problems = _load(system)
    problems += _parameter_problems(system, nodes)
    links, driven, wire_problems = _links(system, nodes)
    problems += wire_problems
    problems += _algebraic_loops(nodes, links)
    ratios, rate_problems = _ratios(system, system.step if run_times is None else run_times.step)
    problems += rate_problems
    if problems:
        raise DiagramError(system.name, problems)
    given = {(spec.name, variable) for spec in system.blocks if spec.name in nodes
             for base in spec.parameters for variable in expand(nodes[spec.name].variables, base)}
    warnings = [f"input {name}.{variable.name} is not connected: it keeps its start value {variable.start}"
                for name, node in nodes.items() for variable in node.model_description.modelVariables
                if variable.causality == "input" and (name, variable.name) not in driven
                and (name, variable.name) not in given]       # an input given a value is no surprise
    order = _evaluation_order(system, nodes, links)
    outputs = [f"{name}.{v.name}" for name in order for v in nodes[name].model_description.modelVariables
               if v.causality == "output" and v.type in ("Real", "Boolean")]
    missing = unmatched(outputs, record)
    if missing:
        raise DiagramError(system.name, [_unrecorded(entry, outputs) for entry in missing])
    planned = Plan(system, nodes, links, warnings, order, tuple(outputs[k] for k in select(outputs, record)),
                   ratios=ratios)
    return planned if run_times is None else planned.timed(run_times)


def _compact(names: list[str]) -> list[str]:
    """Signal names with each vector written once: ``plant.q[1..4]``, ``trajectory.grip``."""
    bases: dict[str, list[int]] = {}
    for name in names:
        head, bracket, rest = name.partition("[")
        if bracket and rest[:-1].isdigit():
            bases.setdefault(head, []).append(int(rest[:-1]))
        else:
            bases.setdefault(name, [])
    return [f"{base}[{min(i)}..{max(i)}]" if len(i) > 1 else f"{base}[{i[0]}]" if i else base
            for base, i in bases.items()]


def _unrecorded(entry: str, outputs: list[str]) -> str:
    """The problem of a ``record`` entry naming no output, with some of the outputs it could name."""
    block = entry.split(".", 1)[0]
    near = [o for o in outputs if o.split(".", 1)[0] == block]
    shown = _compact(near or outputs)
    return (f"record: {entry!r} names no output ({'outputs of ' + block if near else 'outputs'}: "
            f"{', '.join(shown[:12])}{', ...' if len(shown) > 12 else ''})")


def _load(system: System) -> tuple[dict[str, Node], list[str]]:
    """The nodes whose FMU is a valid co-simulation FMU, and the problems of the others."""
    nodes: dict[str, Node] = {}
    problems: list[str] = []
    for spec in system.blocks:
        path = system.fmu_path(spec)
        if not path.is_file():
            problems.append(f"block {spec.name!r}: FMU {path} does not exist (run `robofmu build`)")
            continue
        try:
            found, model_description = described(path)
        except Exception as exc:
            problems.append(f"block {spec.name!r}: {path} is not a valid FMU: {exc}")
            continue
        if found:
            problems.append(f"block {spec.name!r}: {path} is not a valid FMU: " + "; ".join(map(str, found)))
            continue
        if model_description.coSimulation is None:
            problems.append(f"block {spec.name!r}: {path} is not a co-simulation FMU")
            continue
        variables = {v.name: v for v in model_description.modelVariables}
        inputs = {name for name, v in variables.items() if v.causality == "input"}
        feedthrough = {unknown.variable.name: inputs if unknown.dependencies is None
                       else {d.name for d in unknown.dependencies} & inputs
                       for unknown in model_description.outputs}
        nodes[spec.name] = Node(spec, path, model_description, variables, feedthrough)
    return nodes, problems


def _parameter_problems(system: System, nodes: dict[str, Node]) -> list[str]:
    """Unknown parameters, parameters that are not parameters, values of the wrong type or length."""
    problems = []
    for spec in system.blocks:
        node = nodes.get(spec.name)
        if node is None:
            continue
        for base, value in spec.parameters.items():
            names = expand(node.variables, base)
            if not names:
                settable = [n for n, v in node.variables.items() if v.causality in ("parameter", "input")]
                problems.append(f"block {spec.name!r}: unknown parameter {base!r} in {node.path.name}"
                                + nearest(base, bases(settable)))
                continue
            if any(node.variables[name].causality not in ("parameter", "input") for name in names):
                problems.append(f"block {spec.name!r}: {base!r} is a {node.variables[names[0]].causality}, "
                                "not a parameter")
                continue
            try:
                for name, element in zip(names, spread(names, value, f"{spec.name}.{base}")):
                    coerce(node.variables[name].type, element, f"{spec.name}.{name}")
            except ValueError as exc:
                problems.append(f"block {spec.name!r}: parameter {exc}")
    return problems


def _links(system: System, nodes: dict[str, Node]):
    """The wires as scalar links; which inputs are driven (and by what); the wires' problems."""
    problems: list[str] = []
    links: list[Link] = []
    driven: dict[tuple[str, str], str] = {}
    block_names = [b.name for b in system.blocks]
    for wire in system.wires:
        source, target = nodes.get(wire.src), nodes.get(wire.dst)
        for end, node in ((wire.src, source), (wire.dst, target)):
            if node is None and end not in block_names:
                problems.append(f"connection {wire}: no block {end!r}")
        if source is None or target is None:
            continue
        outputs, inputs = expand(source.variables, wire.src_var), expand(target.variables, wire.dst_var)
        if not outputs:
            problems.append(f"connection {wire}: {wire.src} has no variable {wire.src_var!r}")
            continue
        if not inputs:
            problems.append(f"connection {wire}: {wire.dst} has no variable {wire.dst_var!r}")
            continue
        if len(outputs) != len(inputs):
            problems.append(f"connection {wire}: {len(outputs)} source variables for {len(inputs)} inputs")
            continue
        for output, input_ in zip(outputs, inputs):
            produced, consumed = source.variables[output], target.variables[input_]
            where = f"connection {wire.src}.{output} -> {wire.dst}.{input_}"
            if produced.causality != "output":
                problems.append(f"{where}: {wire.src}.{output} is a {produced.causality}, not an output")
            if consumed.causality != "input":
                problems.append(f"{where}: {wire.dst}.{input_} is a {consumed.causality}, not an input")
            if produced.type != consumed.type:
                problems.append(f"{where}: type mismatch ({produced.type} -> {consumed.type})")
            unit_out, unit_in = variable_unit(produced), variable_unit(consumed)
            if unit_out and unit_in and unit_out != unit_in:
                problems.append(f"{where}: unit mismatch ({unit_out} -> {unit_in})")
            key = (wire.dst, input_)
            if key in driven:
                problems.append(f"input {wire.dst}.{input_} is driven twice: by {driven[key]} and "
                                f"{wire.src}.{output}")
            driven[key] = f"{wire.src}.{output}"
            links.append(Link(wire.src, output, wire.dst, input_))
    return links, driven, problems


def _algebraic_loops(nodes: dict[str, Node], links: list[Link]) -> list[str]:
    """The first cycle through direct feedthrough, on the variable graph: output -> wired
    input -> the outputs of that block depending on it ([] if there is none)."""
    successors: dict[tuple[str, str], list[tuple[str, str]]] = {}
    for link in links:
        for output, dependencies in nodes[link.target].feedthrough.items():
            if link.input in dependencies:
                successors.setdefault((link.source, link.output), []).append((link.target, output))
    problems: list[str] = []
    state: dict[tuple[str, str], int] = {}       # 1: on the path being explored, 2: done
    path: list[tuple[str, str]] = []

    def visit(vertex):
        state[vertex] = 1
        path.append(vertex)
        for successor in successors.get(vertex, []):
            if state.get(successor) == 1:
                cycle = path[path.index(successor):] + [successor]
                problems.append("algebraic loop through direct feedthrough: "
                                + " -> ".join(f"{block}.{name}" for block, name in cycle))
            elif successor not in state:
                visit(successor)
        path.pop()
        state[vertex] = 2

    for vertex in list(successors):
        if vertex not in state:
            visit(vertex)
    return problems[:1]


def _evaluation_order(system: System, nodes: dict[str, Node], links: list[Link]) -> list[str]:
    """Blocks in an order where every feedthrough input is produced before it is read (the
    first ready block in diagram order at each place); DiagramError if there is none."""
    names = [b.name for b in system.blocks]
    after: dict[str, set[str]] = {name: set() for name in names}
    for link in links:
        if link.source != link.target and any(link.input in dependencies
                                               for dependencies in nodes[link.target].feedthrough.values()):
            after[link.target].add(link.source)
    order: list[str] = []
    done: set[str] = set()
    while len(order) < len(names):
        ready = [name for name in names if name not in done and after[name] <= done]
        if not ready:
            stuck = [name for name in names if name not in done]
            raise DiagramError(system.name, [
                "blocks feed each other's feedthrough inputs in a cycle and cannot be ordered: "
                + ", ".join(stuck)])
        order.append(ready[0])
        done.add(ready[0])
    return order

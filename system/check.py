"""The plan of a diagram: everything known about it before any FMU is instantiated.

:func:`plan` reads the System and the model descriptions of its FMUs, nothing else, and either
refuses the diagram (:class:`DiagramError`, listing every problem at once, each naming blocks and
variables) or returns a :class:`Plan`: the blocks with their model descriptions and
direct-feedthrough maps, the wires expanded to scalar :class:`Link` s, the warnings (unconnected
inputs the experiment gives no value) and an evaluation order in which every feedthrough input
is produced before it is read.

The master (:meth:`Master.check <robofmu.system.master.Master.check>`) runs from a plan, the SSP
export writes one. The helpers here are the one place for facts read from a model description:
a variable's unit (:func:`variable_unit`) and a block's defaults, the start values of its
parameters and inputs (:func:`start_values`).
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

from robofmu.system.diagram import BlockSpec, System, coerce, expand, spread


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


class DiagramError(ValueError):
    """The diagram cannot run; ``problems`` lists every reason, each naming blocks and variables."""

    def __init__(self, system: str, problems: list[str]):
        super().__init__(f"{system}: the diagram cannot run:\n  - " + "\n  - ".join(problems))
        self.problems = problems


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
        E.g. ``fmpy.read_model_description(path, validate=False)``.
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


# -- the plan --------------------------------------------------------------------------------------
class Link(NamedTuple):
    """One scalar connection: ``source.output -> target.input`` (instance and variable names)."""

    source: str
    output: str
    target: str
    input: str


@dataclass
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


@dataclass
class Plan:
    """A diagram that can run.

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
    """

    system: System
    nodes: dict[str, Node]
    links: list[Link]
    warnings: list[str]
    order: list[str]


def plan(system: System) -> Plan:
    """Check ``system`` against its FMUs' model descriptions and plan its evaluation.

    Nothing is instantiated. The checks: FMU missing or invalid (``fmpy.validation``), not
    co-simulation, unknown block, variable or parameter, a parameter value of the wrong type or
    length, causality (output -> input, parameter or input for parameters), type mismatch, unit
    mismatch (where both ends declare one), vector length mismatch, an input driven twice, an
    algebraic loop (a cycle through direct feedthrough) and blocks whose feedthrough inputs feed
    each other in a cycle (no evaluation order).

    Parameters
    ----------
    system : System

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
    if problems:
        raise DiagramError(system.name, problems)
    given = {(spec.name, variable) for spec in system.blocks if spec.name in nodes
             for base in spec.parameters for variable in expand(nodes[spec.name].variables, base)}
    warnings = [f"input {name}.{variable.name} is not connected: it keeps its start value {variable.start}"
                for name, node in nodes.items() for variable in node.model_description.modelVariables
                if variable.causality == "input" and (name, variable.name) not in driven
                and (name, variable.name) not in given]       # an input given a value is no surprise
    return Plan(system, nodes, links, warnings, _evaluation_order(system, nodes, links))


#: (file identity) -> (validation problems, model description): an FMU file is validated and
#: read once per process while it stays the same file (a sweep plans the same diagram per run).
_DESCRIBED: dict[tuple, tuple[list, object]] = {}


def _described(path: Path) -> tuple[list, object]:
    """fmpy's validation problems and model description of the FMU file ``path`` (cached)."""
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu

    info = os.stat(path)
    identity = (os.path.realpath(path), info.st_ino, info.st_size, info.st_mtime_ns)
    if identity not in _DESCRIBED:
        found = validate_fmu(str(path))
        _DESCRIBED[identity] = (found, read_model_description(str(path), validate=False))
    return _DESCRIBED[identity]


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
            found, model_description = _described(path)
        except Exception as exc:
            problems.append(f"block {spec.name!r}: {path} is not a valid FMU: {exc}")
            continue
        if found:
            problems.append(f"block {spec.name!r}: {path} is not a valid FMU: " + "; ".join(map(str, found)))
            continue
        if model_description.coSimulation is None:
            problems.append(f"block {spec.name!r}: {path} is not a co-simulation FMU")
            continue
        node = Node(spec, path, model_description, {v.name: v for v in model_description.modelVariables})
        inputs = {name for name, v in node.variables.items() if v.causality == "input"}
        for unknown in model_description.outputs:
            dependencies = unknown.dependencies
            node.feedthrough[unknown.variable.name] = (
                inputs if dependencies is None else {d.name for d in dependencies} & inputs)
        nodes[spec.name] = node
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
                problems.append(f"block {spec.name!r}: unknown parameter {base!r} in {node.path.name}")
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

"""A whole diagram as one FMU: an FMU container (fmu-manipulation-toolbox) of the blocks' FMUs.

:func:`export_container` packages an experiment's diagram into a single FMI 2.0 co-simulation
FMU that any importer can run as one block (a Simulink FMU block, fmpy, libcosim, ...): the
container's own binary (``container.so`` of `fmu-manipulation-toolbox
<https://github.com/grouperenault/fmu_manipulation_toolbox>`_) instantiates the embedded block
FMUs, sets the experiment's parameters as their start values, passes the wired values between
them at every step of its internal fixed step (the experiment's communication step) and steps
them. Wires become the container's local variables, unwired outputs its outputs; both are
named ``instance.variable`` as in the master's results (``plant.q[2]``, ``ik.reachable``).
With ``expose_signals=True`` (``robofmu container --expose-signals``) the wired signals are
outputs instead of locals, under the same names and value references, for importers that record
outputs only (fmusim's CSV, ``fmpy.simulate_fmu``'s default, cosimtlk's ``read_outputs``): the
toolbox declares a wire as a local, and export_container then turns each of those variables
into an output in the container's modelDescription.xml (its ``ModelStructure`` listing them).
The runtime reads the same storage either way, so the values are those of the locals, bit for
bit (tests/test_container.py).

How it schedules the blocks (measured equal to the master's runs bit for bit, every recorded
output, on every robot: tests/test_container.py):

``algorithm="jacobi"``
    The container's parallel mode: every block steps from t with the values wired at t, then the
    wired values are passed on. A feedthrough block's output at t + h comes from its inputs at t:
    the master's Jacobi exchange.
``algorithm="gauss-seidel"``
    The container's sequential mode, with the blocks in this order: first every block without
    direct feedthrough (the plant, the trajectory: their outputs at t + h do not depend on their
    inputs at t + h), each before the blocks it takes inputs from (the plant before the
    trajectory that sets its ``grip``), then the feedthrough blocks in the diagram's evaluation
    order. Each block gets the values its sources have produced last. Within a step from t the
    blocks without feedthrough step with their inputs of t (the plant with the torque and the
    grip of t); the feedthrough blocks (ik, controller) then step with their inputs of t + h,
    so that their outputs, read after the step, are the master's Gauss-Seidel values at t + h.
    A feedthrough block with a state of its own (the PID's integral) advances it over [t, t + h]
    with its inputs at t + h, not at t: there the two runs differ by a term of first order in h
    (ki h |de|); a PD loop is reproduced bit for bit.

In both modes the container initializes the blocks in that order, each with the initial outputs
of the blocks feeding it, so the loop starts consistent at t0, as the master's does.

The embedded FMUs are robofmu's pythonfmu FMUs, so the process that runs the container needs
what ``robofmu doctor`` lists (a host that is not Python needs nothing: each block FMU loads the
Python it records).

What the container logs (fmu-manipulation-toolbox 2.0, its runtime ``container.so``)
    The runtime logs ``Solver configure....`` with status fmi2Error at every fmi2Instantiate of a
    successful run, whatever the importer's debug logging: a trace of its solver set-up, compiled
    in (``container_configure()`` calls ``container_configure_c_locale()``, whose first statement
    logs it through a logger fixed to status 3, before ``container.txt`` is read; the string at
    0x4c400 of the wheel's ``resources/linux64/container.so``, logged by the call at 0x17212). No
    container option, configuration file or log level reaches it, so export_container puts
    robofmu's front library in front of the runtime (``system/packaging/fmi_export/robofmu_front.c``,
    :func:`robofmu.system.packaging.fmi_export.install_front`): that message reaches the importer as what
    it is, an fmi2OK message shown with debug logging only; every other message, status and
    call is the runtime's. Hosts no longer report a bit-exact run as "1 error". Two lines come
    unconditionally, as fmi2Warning: the version (``FMUContainer 'V2.0'``) and the mode
    (``Container use SEQUENTIAL mode.``, ``Container use PARALLEL mode with MONO thread.``).
    A block that refuses a call still reaches the host as fmi2Error with the block's own
    message (``<block>.fmu: <instance>.<block>.fmu: ...``). The runtime's binaries for other
    platforms are dropped, as the block FMUs it holds run on Linux x86_64 only.
"""
from __future__ import annotations

import re
import shutil
import tempfile
import time as _time
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np

from robofmu.system.packaging import fmi_export
from robofmu.system.plan import Plan, plan, single_rate, step_count
from robofmu.system.diagram import System, select
from robofmu.system.defaults import ALGORITHMS
from robofmu.system.master import SimulationError
from robofmu.system.result import Result
from robofmu.system.interop.ssp import parameter_values
from robofmu.system.packaging.validate import toolbox_errors_only
from robofmu.system.usage import atomic_file

__all__ = ["container_order", "export_container", "is_robofmu_container", "model_identifier", "run_container"]


def container_order(planned: Plan) -> list[str]:
    """The instance names in the order the container initializes and (sequential mode) steps
    them: the blocks without direct feedthrough first, each before the blocks it takes inputs
    from, then the others in evaluation order (see the module notes).

    Raises
    ------
    ValueError
        Blocks without direct feedthrough feed each other in a cycle: no sequential order steps
        each of them with its inputs of t.
    """
    stateful = [b for b in planned.order if not any(planned.nodes[b].feedthrough.values())]
    readers = {b: {link.target for link in planned.links if link.source == b and link.target in stateful} - {b}
               for b in stateful}
    order: list[str] = []
    while len(order) < len(stateful):
        ready = [b for b in stateful if b not in order and readers[b] <= set(order)]
        if not ready:
            cycle = [b for b in stateful if b not in order]
            raise ValueError(f"blocks without direct feedthrough feed each other ({', '.join(cycle)}): a "
                             "sequential container cannot step each with its inputs of t; use jacobi")
        order.append(ready[0])
    return order + [b for b in planned.order if b not in stateful]


def model_identifier(path: Path) -> str:
    """The container's model identifier: its file's stem as a C identifier (``2-link arm.fmu``:
    ``_2_link_arm``), the prefix of its binary's FMI functions."""
    return re.sub(r"\W|^(?=\d)", "_", Path(path).stem)


def export_container(system: System, path: str | Path, algorithm: str | None = None,
                     expose_signals: bool = False) -> Path:
    """Write ``system``'s diagram as one FMU container at ``path``; returns the path.

    The diagram is planned first as the master plans it (FMUs valid, wires typed and matching,
    no algebraic loop): a diagram the master refuses is not packaged (DiagramError).

    Parameters
    ----------
    system : System
        E.g. ``experiment.load("chess-pd", fmu_dir="fmus")``.
    path : str or Path
        The ``.fmu`` file to write (parent folders are created). Its stem gives the
        container's model identifier (:func:`model_identifier`).
    algorithm : {"gauss-seidel", "jacobi"}, optional
        The master algorithm the container reproduces (default: the experiment's).
    expose_signals : bool
        Declare the wired signals (``plant.q[1]``, ``controller.tau[2]``, ...) as the
        container's outputs instead of its locals: same names, same value references, same
        values (see the module notes). Default: locals, as the toolbox declares them.

    Raises
    ------
    ValueError
        An unknown algorithm, a diagram the master refuses (DiagramError), a multi-rate diagram
        (the container steps every block at one step: refused in one line,
        :func:`~robofmu.system.plan.single_rate`), or a parameter the container cannot take
        (fmu-manipulation-toolbox's message).
    """
    from fmu_manipulation_toolbox.container import FMUContainer, FMUContainerError

    algorithm = algorithm or system.algorithm
    if algorithm not in ALGORITHMS:
        raise ValueError(f"algorithm {algorithm!r}: choose one of {', '.join(ALGORITHMS)}")
    path = Path(path)
    single_rate(system, "an FMU container")          # no standard rate per component
    planned = plan(system)
    try:
        order = container_order(planned)
    except ValueError:
        if algorithm == "gauss-seidel":
            raise
        order = planned.order                # parallel mode: any order steps them alike
    fmu_name = {b: f"{b}.fmu" for b in order}          # the container names a block by a file name
    path.parent.mkdir(parents=True, exist_ok=True)
    # the toolbox logs every build step and warns of what is meant here (the loop through the
    # controller is initialized without the values it gets from the loop): its errors only
    with tempfile.TemporaryDirectory(prefix=".container-", dir=path.parent) as folder, toolbox_errors_only():
        try:
            container = FMUContainer(model_identifier(path), folder)
            container.start_time, container.stop_time = 0.0, system.stop_time
            for block, name in fmu_name.items():
                container.get_fmu(str(planned.nodes[block].path.resolve()), name)
            for link in planned.links:
                container.add_link(fmu_name[link.source], link.output, fmu_name[link.target], link.input)
            sources = {(link.source, link.output) for link in planned.links}
            targets = {(link.target, link.input) for link in planned.links}
            for block, name in fmu_name.items():
                node = planned.nodes[block]
                for v in node.model_description.modelVariables:          # a wired output is a local
                    if v.causality == "output" and (block, v.name) not in sources:
                        container.add_output(name, v.name, f"{block}.{v.name}")
                    elif v.causality == "input" and (block, v.name) not in targets:
                        container.add_input(f"{block}.{v.name}", name, v.name)
                for variable, _, text in parameter_values(block, node.variables, node.spec.parameters):
                    container.add_start_value(name, variable, text)
            container.make_fmu(path.name, system.step, sequential=algorithm == "gauss-seidel")
        except FMUContainerError as exc:
            raise ValueError(f"{system.name}: fmu-manipulation-toolbox cannot build the container: "
                             f"{getattr(exc, 'reason', exc)}") from None
        if expose_signals:
            _locals_as_outputs(Path(folder) / path.name, [f"{block}.{output}" for block, output in sorted(sources)])
        fmi_export.install_front(Path(folder) / path.name)
        with atomic_file(path) as partial:          # the earlier container stays until it is whole
            shutil.move(Path(folder) / path.name, partial)
    return path


def is_robofmu_container(path: str | Path) -> bool:
    """Whether ``path`` is a FMU container :func:`export_container` wrote (robofmu's front in
    front of the container runtime, :data:`~robofmu.components.fmi.contract.FRONT_BEHIND`): the
    only kind of file ``robofmu container --out`` replaces."""
    from robofmu.components.fmi.contract import FRONT_BEHIND, PLATFORM

    try:
        with zipfile.ZipFile(path) as zf:
            return f"binaries/{PLATFORM}/{FRONT_BEHIND}" in zf.namelist()
    except (OSError, zipfile.BadZipFile):
        return False


def _locals_as_outputs(fmu: Path, names: list[str]) -> None:
    """Turn the local variables ``names`` of a container's modelDescription.xml into outputs, in
    place: causality ``output``, listed (with the outputs already there, by ascending index) in
    ``ModelStructure/Outputs`` and ``InitialUnknowns`` (FMI 2.0 sections 2.2.8: every output is
    an output unknown, and an initial unknown when its ``initial`` is calculated). Nothing else in
    the FMU changes: the runtime reads ``container.txt``, where a local's value reference maps to
    the same storage whatever its causality."""
    if not names:
        return
    with zipfile.ZipFile(fmu) as zf:
        entries = [(info, zf.read(info)) for info in zf.infolist()]
    md_info, text = next((info, data) for info, data in entries if info.filename == "modelDescription.xml")
    root = ET.fromstring(text)
    variables = root.find("ModelVariables").findall("ScalarVariable")
    by_name = {v.get("name"): v for v in variables}
    missing = [n for n in names if by_name.get(n) is None or by_name[n].get("causality") != "local"]
    if missing:                    # the toolbox no longer names a wire's local after its source
        raise ValueError(f"{fmu.name}: fmu-manipulation-toolbox declared no local variable for the wired "
                         f"signals {', '.join(missing)}: cannot expose them as outputs")
    for name in names:
        by_name[name].set("causality", "output")
    index = {id(v): k for k, v in enumerate(variables, start=1)}
    outputs = sorted(index[id(v)] for v in variables if v.get("causality") == "output")
    initial = sorted(index[id(v)] for v in variables if v.get("causality") == "output"
                     and v.get("initial", "calculated") in ("approx", "calculated"))
    structure = root.find("ModelStructure")
    for tag, wanted, position in (("Outputs", outputs, 0), ("InitialUnknowns", initial, None)):
        section = structure.find(tag)
        kept = {} if section is None else {int(u.get("index")): u for u in section.findall("Unknown")}
        if not wanted and not kept:
            continue
        if section is None:
            section = ET.Element(tag)
            structure.insert(len(structure) if position is None else position, section)
        for unknown in list(section):
            section.remove(unknown)
        for k in sorted(set(wanted) | set(kept)):
            section.append(kept.get(k, ET.Element("Unknown", {"index": str(k)})))
    data = ET.tostring(root, encoding="UTF-8", xml_declaration=True)
    with zipfile.ZipFile(fmu, "w") as zf:
        for info, content in entries:
            zf.writestr(info, data if info is md_info else content)


#: An embedded block's message as the container relays it: ``<block>.fmu: <instance>.<block>.fmu: text``.
_RELAYED = re.compile(r"^(?P<block>[^:]+)\.fmu: (?:\S+\.(?P=block)\.fmu: )?(?P<text>.*)$", re.S)


def run_container(path: str | Path, stop_time: float, step: float | None = None, start_time: float = 0.0,
                  record: list[str] | None = None) -> Result:
    """Simulate a container FMU through fmpy, recording its outputs and locals at every step.

    Parameters
    ----------
    path : str or Path
        A container written by :func:`export_container`.
    stop_time : float
        s, a whole number of steps after ``start_time``.
    step : float, optional
        Communication step (s); default: the container's internal step.
    start_time : float
        s.
    record : list of str, optional
        ``instance.variable`` names, vector bases or fnmatch patterns (default: every Real and
        Boolean output and local; Booleans as 0/1).

    Returns
    -------
    Result
        Rows at t0, t0 + h, ..., t0 + n h; ``info["wall_time"]`` is the stepping loop's, and
        ``info["messages"]`` holds what the container and its blocks logged.

    Raises
    ------
    SimulationError
        The container failed (a block refused its initialization or a step): the block, the
        time, the block's own message, and every row recorded before (``result``).
    """
    from robofmu.system.fmu import FMUInstance, FMUError

    path = Path(path)
    with FMUInstance(path, path.stem) as box:
        step = step if step is not None else float(box.md.defaultExperiment.stepSize)
        n = step_count(start_time, stop_time, step)
        signals = [v.name for v in box.md.modelVariables
                   if v.type in ("Real", "Boolean") and v.causality in ("output", "local")]
        keep = [signals[k] for k in select(signals, record)]
        kinds = {kind: ([j for j, name in enumerate(keep) if box.variables[name].type == kind],
                        [box.variables[name].valueReference for name in keep if box.variables[name].type == kind])
                 for kind in ("Real", "Boolean")}
        (real_columns, reals), (boolean_columns, booleans) = kinds["Real"], kinds["Boolean"]
        times = start_time + step * np.arange(n + 1)
        data = np.empty((n + 1, len(keep)))

        def record_row(k: int) -> None:
            data[k, real_columns] = box.get_real(reals)
            if booleans:
                data[k, boolean_columns] = box.get_boolean(booleans)

        k, wall = 0, 0.0
        try:
            box.initialize(start_time, stop_time=start_time + n * step)
            record_row(0)
            wall = _time.perf_counter()
            for k in range(1, n + 1):
                box.do_step(times[k - 1], step)
                record_row(k)
            wall = _time.perf_counter() - wall
        except FMUError as exc:
            relayed = [m for m in (_RELAYED.match(m.message) for m in box.messages
                                   if m.status in ("ERROR", "FATAL")) if m]
            block, said = (relayed[-1]["block"], relayed[-1]["text"]) if relayed else (path.stem, str(exc))
            t = times[k - 1] if k else start_time
            partial = Result(times[:k], keep, data[:k].copy(), {"tool": "fmpy", "container": path.name}) if k else None
            message = f"{path.name}: {block} at t = {t:.9g} s: {said}"
            raise SimulationError(message + (f"; {k} rows recorded before it" if k else ""), block, t, partial,
                                  reason=message) from None
        messages = [m.message for m in box.messages]
    return Result(times, keep, data, {"tool": "fmpy", "container": path.name, "step": step, "wall_time": wall,
                                      "messages": messages})

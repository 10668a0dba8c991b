"""Export an experiment as libcosim's own configuration (``OspSystemStructure.xml``), rates
included, and run it with libcosim.

:func:`export_osp` writes a folder holding ``OspSystemStructure.xml`` beside a copy of every FMU
of the diagram::

    OspSystemStructure.xml
    trajectory.fmu  ik.fmu  controller.fmu  plant.fmu

The file (OSP system structure 0.1, libcosim's schema) names the fixed-step algorithm, its
``BaseStepSize`` (the experiment's step), ``StartTime`` and ``EndTime``; one ``<Simulator name
source stepSize>`` per block, ``stepSize`` its sample time (the base step unless the block gives
``sample_time``), with the block's parameters as ``<InitialValues>`` (vector bases expanded,
``q0[1]`` ..); one ``<VariableConnection>`` per scalar pair of the planned wires, the output
first. Block names are kept (libcosim takes any name). An XML comment marks the file as
robofmu's (:func:`is_robofmu_osp`): libcosim validates the file against its schema, which has
no place for a tool's name.

Times are written so that libcosim reads them exactly: it converts seconds to integer
nanoseconds by truncation (``duration_cast``), so 0.00013 s (0.00013 x 1e9 = 129999.99999999999)
would become 129999 ns; :func:`osp_seconds` writes the nearest double at or above the intended
nanosecond count instead.

What libcosim does with the rates (its ``fixed_step_algorithm.cpp``, as read in libcosim's
source and as libcosimpy 0.0.6's library behaves in tests/test_libcosim.py): a simulator's
decimation factor is its ``stepSize`` over the base step (integer division; robofmu writes whole
multiples only). At base step k a simulator whose factor r divides k steps ``doStep(t_k, r h)``;
after the base step, every simulator that has just finished its step (r divides k + 1) has its
outputs transferred (libcosim's current source only along connections whose two ends' factors
both divide k + 1: the same values arrive), and a value set on a simulator reaches its FMU only
just before its next step. Outputs are read after each step and transferred after it: libcosim
is Jacobi, at every rate. So a controller at 4 ms samples the plant's outputs at t_k (k = 0, 4,
..), and the effort it computes there reaches the plant at t_k+4, held for the plant's next four
steps: one controller sample of delay (at initialization libcosim passes the values along until
they are consistent, so over the first sample the plant gets the effort of t_0). That is, step
for step, robofmu's master with ``algorithm = "jacobi"`` at the same rates (its due blocks'
outputs read, then their inputs set, a block not due left alone): the tests run both (chess-pd
with the controller at 4 ms or 3 ms, ur5-pose with all but the plant at 4 ms) and compare every
recorded output to 1e-12, and compare libcosim with a hand-written sampled loop. (The master's
default, Gauss-Seidel, hands the controller's effort of t_k to the plant at t_k.) A controller's
``delay_steps`` d adds to that sample only from d = 2 on: with d >= 1 its effort does not depend
on the inputs of its own sample, so reading it before they are set (Jacobi) loses nothing, and
d = 0 and d = 1 give the same run.
"""
from __future__ import annotations

import math
import shutil
import time as _time
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np

from robofmu.system.diagram import System
from robofmu.system.interop.ssp import fmu_names, parameter_values, xml_bytes
from robofmu.system.plan import plan, step_count
from robofmu.system.result import Result
from robofmu.system.usage import atomic_file

NS = "http://opensimulationplatform.com/MSMI/OSPSystemStructure"
#: The file libcosim (and the OSP tools) look for in a configuration folder.
OSP_FILE = "OspSystemStructure.xml"
#: The comment :func:`export_osp` writes first in the file: what :func:`is_robofmu_osp` recognizes.
MARK = " written by robofmu "
NANO = 1_000_000_000


def osp_seconds(t: float) -> str:
    """Text of a time (s) that libcosim reads as ``t`` rounded to whole nanoseconds.

    libcosim truncates ``seconds * 1e9`` to an integer (``duration_cast``); the text is the
    smallest double at or above the rounded count's seconds whose product truncates to it.
    """
    ns = round(float(t) * NANO)
    x = ns / NANO
    while math.trunc(x * NANO) < ns:
        x = math.nextafter(x, math.inf)
    return repr(x)


def libcosim_ns(text: str) -> int:
    """The integer nanoseconds libcosim makes of a time written in seconds (truncation)."""
    return math.trunc(float(text) * NANO)


def export_osp(system: System, folder: str | Path) -> Path:
    """Write ``system`` as ``OspSystemStructure.xml`` and its FMUs into ``folder``; returns the
    XML file's path.

    The diagram is planned first exactly as the master plans it
    (:func:`~robofmu.system.plan.plan`: FMUs valid, wires typed and matching, no algebraic loop,
    every ``sample_time`` a whole multiple of the step; nothing is instantiated): a diagram the
    master refuses is not exported (DiagramError). Each FMU is copied once (names made unique:
    ``plant.fmu``, ``plant_2.fmu``), every file written atomically, the XML last. Replacing files
    is the caller's decision (``robofmu osp`` replaces only files robofmu wrote).

    Parameters
    ----------
    system : System
        E.g. ``experiment.load("chess-pd", fmu_dir="fmus")``.
    folder : str or Path
        The configuration folder (created with its parents).
    """
    folder = Path(folder)
    planned = plan(system)
    sources = fmu_names(system)

    ET.register_namespace("", NS)
    root = ET.Element(f"{{{NS}}}OspSystemStructure", {"version": "0.1"})
    root.append(ET.Comment(MARK))
    for tag, text in (("StartTime", osp_seconds(0.0)), ("EndTime", osp_seconds(system.stop_time)),
                      ("BaseStepSize", osp_seconds(system.step)), ("Algorithm", "fixedStep")):
        ET.SubElement(root, f"{{{NS}}}{tag}").text = text
    simulators = ET.SubElement(root, f"{{{NS}}}Simulators")
    for spec in system.blocks:
        node = planned.nodes[spec.name]
        sim = ET.SubElement(simulators, f"{{{NS}}}Simulator",
                            {"name": spec.name, "source": sources[system.fmu_path(spec).resolve()],
                             "stepSize": osp_seconds(planned.ratios[spec.name] * system.step)})
        values = parameter_values(spec.name, node.variables, spec.parameters)
        if values:
            initial = ET.SubElement(sim, f"{{{NS}}}InitialValues")
            for name, kind, text in values:
                value = ET.SubElement(initial, f"{{{NS}}}InitialValue", {"variable": name})
                ET.SubElement(value, f"{{{NS}}}{kind}", {"value": text})
    if planned.links:
        connections = ET.SubElement(root, f"{{{NS}}}Connections")
        for src, out, dst, inp in planned.links:
            connection = ET.SubElement(connections, f"{{{NS}}}VariableConnection")
            ET.SubElement(connection, f"{{{NS}}}Variable", {"simulator": src, "name": out})
            ET.SubElement(connection, f"{{{NS}}}Variable", {"simulator": dst, "name": inp})

    folder.mkdir(parents=True, exist_ok=True)
    for fmu, name in sources.items():
        with atomic_file(folder / name) as partial:
            shutil.copyfile(fmu, partial)
    path = folder / OSP_FILE
    with atomic_file(path) as partial:
        partial.write_bytes(xml_bytes(root))
    return path


def is_robofmu_osp(path: str | Path) -> bool:
    """Whether ``path`` is an ``OspSystemStructure.xml`` :func:`export_osp` wrote (its first
    comment is :data:`MARK`)."""
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    try:
        root = ET.parse(path, parser).getroot()
    except (OSError, ET.ParseError):
        return False
    return (root.tag == f"{{{NS}}}OspSystemStructure" and len(root) > 0 and root[0].tag is ET.Comment
            and root[0].text == MARK)


def run_osp_libcosim(path: str | Path, stop_time: float | None = None, record: list[str] | None = None,
                     log_level: str | None = "WARNING") -> Result:
    """Run an OSP configuration (a folder or its ``OspSystemStructure.xml``) with libcosim's
    fixed-step algorithm at the rates it gives (see the module notes).

    Returns a :class:`~robofmu.system.result.Result` with the Real outputs matching ``record``
    (fnmatch patterns on ``instance.variable``; default all) at every base step t0 .. t0 + n h;
    a simulator stepped every r base steps is observed when it finishes a step, and its outputs
    are held in between (what the master records). ``stop_time`` defaults to the file's
    ``EndTime``.
    """
    from robofmu.system.interop.libcosim import CosimRun

    path = Path(path)
    config = path / OSP_FILE if path.is_dir() else path
    root = ET.parse(config).getroot()
    text = {tag: root.findtext(f"{{{NS}}}{tag}") for tag in ("StartTime", "EndTime", "BaseStepSize")}
    base_ns = libcosim_ns(text["BaseStepSize"])
    start = libcosim_ns(text["StartTime"] or "0") / NANO
    stop = float(text["EndTime"]) if stop_time is None else float(stop_time)
    step = base_ns / NANO
    n = step_count(start, stop, step)
    run = CosimRun.from_osp(config, step, log_level, last_value=False)
    try:
        keep = run.observe_real_outputs(record, n)
        wall = _time.perf_counter()
        run.step(n)
        wall = _time.perf_counter() - wall
        data = np.empty((n + 1, len(keep)))
        for j, (inst, name) in enumerate(keep):
            _, steps, values = run.series(inst, name, count=n + 1)
            steps = np.asarray(steps, dtype=np.int64)
            if len(steps) == 0 or steps[0] != 0 or np.any(np.diff(steps) <= 0) or steps[-1] > n:
                raise RuntimeError(f"libcosim observed {inst}.{name} at steps {steps.tolist()[:5]}..., "
                                   f"not from 0 to at most {n}")
            # held between the simulator's observations: the value of its last finished step
            data[:, j] = np.asarray(values)[np.searchsorted(steps, np.arange(n + 1), side="right") - 1]
        times = start + step * np.arange(n + 1)
        return Result(times, [f"{i}.{v}" for i, v in keep], data,
                      {"tool": "libcosim", "algorithm": "jacobi (libcosim fixed-step, OSP rates)", "step": step,
                       "wall_time": wall})
    finally:
        run.close()

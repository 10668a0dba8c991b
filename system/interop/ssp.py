"""Export a diagram as an SSP 1.0 package, and run such a package with fmpy.ssp, libcosim and ecos.

:func:`export_ssp` writes ``<name>.ssp``: a zip holding ``SystemStructure.ssd`` and, under
``resources/``, every FMU of the diagram and one SSV parameter set per block with parameters::

    SystemStructure.ssd
    resources/trajectory.fmu  resources/ik.fmu  resources/controller.fmu  resources/plant.fmu
    resources/controller.ssv          (kp, kd, ki, payload_mass of chess-pd)

The SSD declares, per component, a connector for every output and every wired input of its FMU (typed:
``ssc:Real`` with the FMU's unit, ``ssc:Boolean``, ``ssc:Integer``, ``ssc:String``), one
``ssd:Connection`` per scalar pair (a wire of vector bases ``ik.q_ref -> controller.q_ref`` becomes
``q_ref[1]`` .. ``q_ref[4]``: 35 connections for the chess loop), the units used (``ssd:Units``),
and ``ssd:DefaultExperiment`` with the start and stop time, annotated (OSP annotation
``com.opensimulationplatform``) with a fixed-step algorithm of the diagram's step. Parameters are
bound per component (``ssd:ParameterBinding source="resources/<block>.ssv"``; ``inline=True``
puts the ``ssv:ParameterSet`` into the SSD instead); every set carries the system's name, so that a
tool applying one set by name (ecos) applies them all. Vector parameters (``q0 = [..]``) are
expanded to ``q0[1]`` .. ``q0[n]``. Namespace prefixes are exactly ``ssd``, ``ssc``, ``ssv``:
libcosim reads the SSD with boost::property_tree, which matches prefixed names literally.

Names: the SSD (its root), its system and its components are named by identifiers that every
tool takes (:func:`ssp_identifier`: ASCII letters, digits and underscores, starting with a
letter, OMSimulator's rule ``^[a-zA-Z][a-zA-Z0-9_]*$``; SSP itself only asks for unique names).
An experiment ``chess-pd`` gives the system (and the parameter sets) ``chess_pd``,
``3rrp-circle`` gives ``x3rrp_circle``; the experiment's own name is the root's ``description``
(the system's is the experiment's description). A block keeps its name when it is such an
identifier (every block of the shipped experiments: ``plant``, ``ik``, ...); another is renamed
the same way, made unique with ``_2``, ``_3``, .. (:func:`element_names`), and its component's
``description`` holds the block's name. The runners name their columns after the components,
``element.connector``.

What the two importers support (fmpy 0.3.32, libcosimpy 0.0.6) and how the runners cope:

fmpy.ssp (``fmpy.ssp.simulation.simulate_ssp``)
    - Reads and schema-validates the SSD, parses ParameterBindings (inline and ``.ssv``), but
      **never applies them**: only a ``parameter_set`` argument is applied (before
      fmi2EnterInitializationMode, names ``component.variable``). :func:`run_ssp_fmpy` collects
      the bindings of the SSD itself and passes them as that parameter set, with typed values
      (fmpy sets a Boolean as ``value != 0.0``, so the string ``"false"`` would become true).
      String parameters cannot be set by fmpy.ssp at all (``set_value`` raises): refused here.
    - Master algorithm: Jacobi. At every step each component gets the values its input
      connectors received at the end of the previous step, does its step, and its outputs are
      read *after* the step; then all connections are applied at once. There is **no exchange
      at initialization**: connector values start at 0.0, so the first step runs with every
      connected input 0 (the plant gets tau = 0: one step of free fall; ``ik`` gets x = 0,
      outside its workspace, and holds its start solution with zero velocity and acceleration,
      warning once), the second feeds the plant the controller's torque for all-zero inputs,
      N(0, 0). From the third step on the exchange is libcosim's (one step of delay through
      each feedthrough block).
    - Time is accumulated (``time += h``): after 1500 steps of 1 ms it is 1.4999999999999456,
      so a block evaluated at a discontinuity (the trajectory's acceleration at a move
      boundary or blend) may see the other side of it for one step.
    - An input connector without a connection breaks ``get_connections``: it is wired to the
      source of the input connector examined before it (or fails with UnboundLocalError if
      there is none), and every connected-or-not input connector would be set at every step
      (0 unless connected). :func:`export_ssp` therefore declares connectors for the outputs and
      the *wired* inputs only (SSP requires only connectors used by connections); unwired inputs
      keep their start values in both tools. :func:`run_ssp_fmpy` refuses an SSD that has any.
    - Records only connector values, one row per step *after* the step, labelled with the
      time *before* it (the row labelled t holds the values at t + h), and no row for the start
      time; the loop runs ``while time < stop_time`` with ``time += h`` accumulated. The runner
      asks for ``stop_time - h/2`` (exactly n steps) and relabels: its Result has rows at
      t0 + h .. t0 + n h.
    - Every run extracts the package and each FMU again (new folders, deleted after the run) and
      frees its instances, which unloads its copies of the binaries: runs one after the other
      in one process are independent, and give identical results.

libcosim (``CosimExecution.from_ssp_file`` -> ``cosim_ssp_fixed_step_execution_create``)
    - Loads a ``.ssp`` archive (or a folder/``.ssd``), FMUs by relative ``source``; reads
      connector types (a connector without a type element is rejected), connections (with
      ``ssc:LinearTransformation``), DefaultExperiment ``startTime`` and the OSP fixed-step
      annotation; applies the **first** parameter set bound to each component (inline or
      ``.ssv``) as initial values; a parameter it cannot apply is only logged as a warning.
      It ignores ``stopTime``, system-level bindings and ParameterMapping.
    - Components are stored in a hash map: slave indices do not follow the SSD order, so the
      runner looks them up by instance name.
    - Master algorithm: the fixed-step (Jacobi) algorithm. Initialization passes connected
      values along in initialization mode (outputs read there), so the loop starts consistent
      at t0 (tests/test_libcosim.py). Then at every step all slaves step from t with the inputs
      transferred at t, outputs are read after the step and transferred: a feedthrough block's
      output at t + h is computed from its inputs at t. The reference reaches the plant two
      steps late (ik, controller each hold one), the measured q one step late; controller ->
      plant adds no delay of its own (the plant has no feedthrough: it steps from t with the
      torque read at t, as in Gauss-Seidel).
    - Time is integer nanoseconds: no drift. Only Real variables can be recorded as time
      series; Boolean outputs are not in the Result. A FMU failing initialization aborts the
      process (see system/interop/libcosim.py).

Both runners register :func:`robofmu.system.interop.libcosim.guard_pythonfmu_exit`: pythonfmu 0.7.0's
export library writes into freed memory when a process that used it exits (sometimes an abort or
a segfault after the last line of a script that ran two simulations); see system/interop/libcosim.py.
"""
from __future__ import annotations

import math
import re
import time as _time
import zipfile
from contextlib import contextmanager
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np

from robofmu.system.plan import plan, single_rate, step_count, variable_unit
from robofmu.system.diagram import System, coerce, expand, select, spread
from robofmu.system.result import Result
from robofmu.system.usage import atomic_file

NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations",
}
OSP_ANNOTATION = "com.opensimulationplatform"
SSD_NAME = "SystemStructure.ssd"
#: The SSD's ``generationTool``: what :func:`is_robofmu_ssp` recognizes.
GENERATION_TOOL = "robofmu"
_TYPES = {"Real": "Real", "Integer": "Integer", "Boolean": "Boolean", "String": "String"}

for _prefix, _uri in NS.items():
    ET.register_namespace(_prefix, _uri)


def _q(tag: str) -> str:
    prefix, name = tag.split(":")
    return f"{{{NS[prefix]}}}{name}"


def _fmt_real(value: float) -> str:
    """xs:double text of a float, exact (repr) and with XML's spellings of the non-finite."""
    value = float(value)
    if math.isnan(value):
        return "NaN"
    if math.isinf(value):
        return "INF" if value > 0 else "-INF"
    return repr(value)


def parameter_values(block: str, variables: dict, parameters: dict) -> list[tuple[str, str, str]]:
    """(scalar name, SSV type, value text) of a block's parameters, vector bases expanded."""
    out = []
    for base, value in parameters.items():
        names = expand(variables, base)
        if not names:
            raise ValueError(f"block {block!r}: unknown parameter {base!r}")
        for name, v in zip(names, spread(names, value, f"block {block!r}: {base}")):
            kind = variables[name].type
            if kind not in ("Real", "Integer", "Boolean", "String"):
                raise ValueError(f"block {block!r}: parameter {name} has type {kind}, which this export "
                                 "does not support (libcosim cannot take SSP enumerations either)")
            v = coerce(kind, v, f"block {block!r}: {name}")
            text = _fmt_real(v) if kind == "Real" else str(v).lower() if kind == "Boolean" else str(v)
            out.append((name, kind, text))
    return out


_IDENTIFIER = re.compile(r"[A-Za-z][A-Za-z0-9_]*")


def ssp_identifier(name: str) -> str:
    """``name`` as an identifier every SSP tool takes: each character other than an ASCII letter,
    digit or underscore becomes ``_``, and a name that then does not start with a letter gets an
    ``x`` in front (``chess-pd``: ``chess_pd``; ``3rrp-circle``: ``x3rrp_circle``; ``_a``:
    ``x_a``). Distinct names can give the same identifier: :func:`element_names` keeps them apart."""
    text = re.sub(r"[^A-Za-z0-9_]", "_", name)
    return text if _IDENTIFIER.fullmatch(text) else "x" + text


def element_names(blocks: list[str]) -> dict[str, str]:
    """The component name of each block (instance names, in diagram order): the block's own name
    when it is already an identifier (:func:`ssp_identifier`'s rule), otherwise its identifier,
    followed by ``_2``, ``_3``, .. if an earlier block (or a name kept as it is) has it already.
    Deterministic, and injective."""
    taken = {b for b in blocks if _IDENTIFIER.fullmatch(b)}
    names: dict[str, str] = {}
    for block in blocks:
        if _IDENTIFIER.fullmatch(block):
            names[block] = block
            continue
        base = name = ssp_identifier(block)
        k = 1
        while name in taken:
            k += 1
            name = f"{base}_{k}"
        taken.add(name)
        names[block] = name
    return names


def fmu_names(system: System) -> dict[Path, str]:
    """The file name of each distinct FMU of ``system`` in an export (absolute FMU path -> name):
    the FMU's own name, ``_2``, ``_3`` .. added where two files share one."""
    sources: dict[Path, str] = {}
    used: set[str] = set()
    for spec in system.blocks:
        fmu = system.fmu_path(spec).resolve()
        if fmu in sources:
            continue
        stem, k, name = fmu.stem, 1, fmu.name
        while name in used:
            k += 1
            name = f"{stem}_{k}.fmu"
        used.add(name)
        sources[fmu] = name
    return sources


def xml_bytes(root: ET.Element) -> bytes:
    """An XML document's bytes as the exports write them: indented, UTF-8, declared."""
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="utf-8", xml_declaration=True) + b"\n"


def _parameter_set(parent, name: str, values) -> ET.Element:
    attrs = {"version": "1.0", "name": name}
    pset = ET.SubElement(parent, _q("ssv:ParameterSet"), attrs) if parent is not None \
        else ET.Element(_q("ssv:ParameterSet"), attrs)
    params = ET.SubElement(pset, _q("ssv:Parameters"))
    for pname, kind, text in values:
        p = ET.SubElement(params, _q("ssv:Parameter"), {"name": pname})
        ET.SubElement(p, _q(f"ssv:{kind}"), {"value": text})
    return pset


def export_ssp(system: System, path: str | Path, inline: bool = False) -> Path:
    """Write ``system`` as an SSP 1.0 package (``.ssp`` zip) at ``path``; returns the path.

    The diagram is planned first exactly as the master plans it (:func:`~robofmu.system.plan.plan`:
    FMUs valid, wires typed and matching, no algebraic loop; nothing is instantiated): a diagram
    the master refuses is not exported (DiagramError). SSP has no standard rate per component:
    a multi-rate system (a block's ``sample_time`` other than the step) is refused in one line
    saying so (ValueError; :func:`~robofmu.system.plan.single_rate`), and so is libcosim's run
    of the export.

    Parameters
    ----------
    system : System
        E.g. ``experiment.load("chess-pd", fmu_dir="fmus")``.
    path : str or Path
        The ``.ssp`` file to write (parent folders are created).
    inline : bool
        Parameter sets inline in the SSD instead of ``resources/<block>.ssv`` files.
    """
    path = Path(path)
    single_rate(system, "SSP")          # no standard rate per component
    planned = plan(system)

    sources = fmu_names(system)         # FMUs under resources/: one copy per distinct file

    wired = {(link.target, link.input) for link in planned.links}
    system_name = ssp_identifier(system.name)
    element = element_names([spec.name for spec in system.blocks])
    root = ET.Element(_q("ssd:SystemStructureDescription"),
                      {"version": "1.0", "name": system_name, "description": system.name, "generationTool": GENERATION_TOOL})
    sys_attrs = {"name": system_name}
    if system.description:
        sys_attrs["description"] = system.description
    sys_el = ET.SubElement(root, _q("ssd:System"), sys_attrs)
    elements = ET.SubElement(sys_el, _q("ssd:Elements"))
    ssv_files: dict[str, bytes] = {}
    units: dict[str, object] = {}
    for spec in system.blocks:
        node = planned.nodes[spec.name]
        fmu = system.fmu_path(spec).resolve()
        attrs = {"name": element[spec.name]}
        if element[spec.name] != spec.name:
            attrs["description"] = spec.name
        comp = ET.SubElement(elements, _q("ssd:Component"),
                             {**attrs, "type": "application/x-fmu-sharedlibrary",
                              "source": f"resources/{sources[fmu]}", "implementation": "CoSimulation"})
        ports = [v for v in node.model_description.modelVariables
                 if v.causality == "output" or (v.causality == "input" and (spec.name, v.name) in wired)]
        connectors = ET.SubElement(comp, _q("ssd:Connectors")) if ports else None
        for v in ports:     # unwired inputs: none (they keep their start values; fmpy.ssp could not take them)
            kind = _TYPES.get(v.type)
            if kind is None:
                raise ValueError(f"block {spec.name!r}: {v.name} has type {v.type}, which this export does not "
                                 "support (libcosim cannot take SSP enumerations either)")
            con = ET.SubElement(connectors, _q("ssd:Connector"), {"name": v.name, "kind": v.causality})
            attrs = {}
            if kind == "Real" and variable_unit(v):
                attrs["unit"] = variable_unit(v)
            ET.SubElement(con, _q(f"ssc:{kind}"), attrs)
        for u in node.model_description.unitDefinitions:
            units.setdefault(u.name, u)
        values = parameter_values(spec.name, node.variables, spec.parameters)
        if values:
            bindings = ET.SubElement(comp, _q("ssd:ParameterBindings"))
            set_name = system_name          # one named set over the components (ecos applies sets by name)
            if inline:
                binding = ET.SubElement(bindings, _q("ssd:ParameterBinding"),
                                        {"type": "application/x-ssp-parameter-set"})
                _parameter_set(ET.SubElement(binding, _q("ssd:ParameterValues")), set_name, values)
            else:
                source = f"resources/{element[spec.name]}.ssv"
                ET.SubElement(bindings, _q("ssd:ParameterBinding"),
                              {"type": "application/x-ssp-parameter-set", "source": source})
                ssv_files[source] = xml_bytes(_parameter_set(None, set_name, values))

    connections = ET.SubElement(sys_el, _q("ssd:Connections")) if planned.links else None
    for src, out, dst, inp in planned.links:
        ET.SubElement(connections, _q("ssd:Connection"),
                      {"startElement": element[src], "startConnector": out, "endElement": element[dst],
                       "endConnector": inp})

    used_units = {c.get("unit") for c in root.iter(_q("ssc:Real")) if c.get("unit")}
    if used_units:
        units_el = ET.SubElement(root, _q("ssd:Units"))
        for name in sorted(used_units):
            b = getattr(units.get(name), "baseUnit", None)
            if b is None:           # not defined by the FMUs: named only
                continue
            attrs = {k: str(getattr(b, k)) for k in ("kg", "m", "s", "A", "K", "mol", "cd", "rad") if getattr(b, k)}
            if b.factor != 1.0:
                attrs["factor"] = _fmt_real(b.factor)
            if b.offset != 0.0:
                attrs["offset"] = _fmt_real(b.offset)
            ET.SubElement(ET.SubElement(units_el, _q("ssc:Unit"), {"name": name}), _q("ssc:BaseUnit"), attrs)
        if not len(units_el):
            root.remove(units_el)

    exp = ET.SubElement(root, _q("ssd:DefaultExperiment"),
                        {"startTime": "0.0", "stopTime": _fmt_real(system.stop_time)})
    ann = ET.SubElement(ET.SubElement(exp, _q("ssd:Annotations")), _q("ssc:Annotation"),
                        {"type": OSP_ANNOTATION})
    ET.SubElement(ET.SubElement(ann, _q("osp:Algorithm")), _q("osp:FixedStepAlgorithm"),
                  {"baseStepSize": _fmt_real(system.step)})

    with atomic_file(path) as partial, zipfile.ZipFile(partial, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        zf.writestr(SSD_NAME, xml_bytes(root))
        for fmu, name in sources.items():
            zf.write(fmu, f"resources/{name}")
        for name, data in ssv_files.items():
            zf.writestr(name, data)
    return path


def is_robofmu_ssp(path: str | Path) -> bool:
    """Whether ``path`` is an SSP package :func:`export_ssp` wrote (its SSD's generationTool is
    :data:`GENERATION_TOOL`): the only kind of file ``robofmu ssp --out`` replaces."""
    try:
        root = ET.fromstring(ssd_text(path))
    except (OSError, KeyError, zipfile.BadZipFile, ET.ParseError):
        return False
    return root.get("generationTool") == GENERATION_TOOL


# -- running ------------------------------------------------------------------------------------
def _fmpy_parameter_set(ssd):
    """The parameter bindings of every component, as one fmpy ParameterSet with typed values."""
    from fmpy.ssp.ssd import Parameter, ParameterSet, find_components

    components = find_components(ssd.system)
    names = [c.name for c in components]
    out = ParameterSet(name="bindings")
    for comp in components:
        for binding in comp.parameterBindings:
            if binding.prefix or binding.parameterMapping:
                raise NotImplementedError(f"{comp.name}: parameter binding with a prefix or a mapping")
            if not binding.parameterValues:
                continue
            pset = binding.parameterValues[0]     # as libcosim: the first set of a binding
            for p in pset.parameters:
                if p.type not in ("Real", "Integer", "Boolean"):
                    raise NotImplementedError(f"{comp.name}.{p.name}: fmpy.ssp cannot set a {p.type} parameter")
                value = coerce(p.type, p.value, f"{comp.name}.{p.name}")
                out.parameters.append(Parameter(name=f"{comp.name}.{p.name}", type=p.type, value=value))
    # fmpy matches a parameter to a component by string prefix: "plant2.x" also starts with "plant"
    # (element_names makes such pairs: plant_1, plant_1_2), so it would set plant2's x on plant too
    clash = [(a, p.name.split(".", 1)[0]) for p in out.parameters for a in names
             if p.name.startswith(a) and not p.name.startswith(f"{a}.")]
    if clash:
        raise NotImplementedError(f"fmpy.ssp would mix up the parameters of components {clash[0]}")
    return out


def run_ssp_fmpy(path: str | Path, stop_time: float, step: float, start_time: float = 0.0,
                 record: list[str] | None = None) -> Result:
    """Simulate an SSP with ``fmpy.ssp.simulation.simulate_ssp`` (Jacobi, see the module notes).

    Parameter bindings of the SSD are applied (fmpy would ignore them) as start values before
    initialization. Returns a :class:`~robofmu.system.result.Result` with the output connectors
    (``instance.variable``, Booleans as 0/1) matching ``record`` (fnmatch patterns; default
    all), at t0 + h .. t0 + n h (fmpy records no row for the start time).
    """
    from fmpy.ssp.simulation import simulate_ssp
    from fmpy.ssp.ssd import find_components, read_ssd

    from robofmu.system.interop.libcosim import guard_pythonfmu_exit       # ctypes only: libcosimpy is not needed

    guard_pythonfmu_exit()
    path = Path(path)
    n = step_count(start_time, stop_time, step)
    ssd = read_ssd(str(path))
    connected = {(c.endElement, c.endConnector) for c in ssd.system.connections}
    loose = [f"{comp.name}.{con.name}" for comp in find_components(ssd.system) for con in comp.connectors
             if con.kind == "input" and (comp.name, con.name) not in connected]
    if loose:
        raise ValueError(f"{path.name}: fmpy.ssp cannot run an SSD with unconnected input connectors "
                         f"({', '.join(loose)}): it wires each to the source of the input before it, "
                         "or fails; remove them (unwired inputs then keep their start values)")
    outputs = {f"{comp.name}.{con.name}" for comp in find_components(ssd.system)
               for con in comp.connectors if con.kind == "output"}
    parameters = _fmpy_parameter_set(ssd)
    wall = _time.perf_counter()
    # fmpy loops `while time < stop_time: ...; time += h`: ask for half a step less than the
    # stop time so that accumulated rounding can neither add nor drop a step
    rows = simulate_ssp(str(path), start_time=start_time, stop_time=start_time + (n - 0.5) * step,
                        step_size=step, parameter_set=parameters if parameters.parameters else None)
    wall = _time.perf_counter() - wall
    if len(rows) != n:
        raise RuntimeError(f"fmpy.ssp made {len(rows)} steps, expected {n}")
    names = [c for c in rows.dtype.names[1:] if c in outputs]
    keep = [names[k] for k in select(names, record)]
    data = np.column_stack([rows[c].astype(float) for c in keep]) if keep else np.zeros((n, 0))
    return Result(start_time + step * np.arange(1, n + 1), keep, data,
                  {"tool": "fmpy.ssp", "algorithm": "jacobi (no initial exchange)", "step": step,
                   "wall_time": wall})


def run_ssp_libcosim(path: str | Path, stop_time: float, step: float, start_time: float = 0.0,
                     record: list[str] | None = None, log_level: str | None = "WARNING") -> Result:
    """Simulate an SSP with libcosim's fixed-step algorithm (see the module notes).

    ``start_time`` must be the SSD's DefaultExperiment start time (libcosim starts there).
    Returns a :class:`~robofmu.system.result.Result` with the Real outputs matching ``record``
    (fnmatch patterns on ``instance.variable``; default all Real outputs) at t0, t0 + h, ..,
    t0 + n h, recorded by a time-series observer (Boolean outputs cannot be recorded).
    """
    from robofmu.system.interop.libcosim import NANO, CosimRun

    path = Path(path)
    n = step_count(start_time, stop_time, step)
    run = CosimRun.from_ssp(path, step, log_level, last_value=False)
    try:
        t0 = run.execution.status().current_time / NANO
        if abs(t0 - start_time) > 1e-9:
            raise ValueError(f"{path.name} starts at t = {t0} s, not {start_time} s")
        candidates = [(inst, v.name) for inst, slave in run.slaves.items() for v in slave.variables.values()
                      if v.causality == "OUTPUT" and v.type == "REAL"]
        candidates.sort(key=lambda c: (run.slaves[c[0]].index, run.slaves[c[0]].variables[c[1]].reference))
        columns = [f"{i}.{v}" for i, v in candidates]
        keep = [candidates[k] for k in select(columns, record)]
        for inst, name in keep:
            run.observe_series(inst, name, buffer_size=n + 1)
        wall = _time.perf_counter()
        run.step(n)
        wall = _time.perf_counter() - wall
        data = np.empty((n + 1, len(keep)))
        times = None
        for j, (inst, name) in enumerate(keep):
            t, steps, values = run.series(inst, name, count=n + 1)
            if len(values) != n + 1:
                raise RuntimeError(f"libcosim recorded {len(values)} samples of {inst}.{name}, expected {n + 1}")
            data[:, j] = values
            times = np.asarray(t)
        if times is None:
            times = start_time + step * np.arange(n + 1)
        return Result(times, [f"{i}.{v}" for i, v in keep], data,
                      {"tool": "libcosim", "algorithm": "jacobi (libcosim fixed-step)", "step": step,
                       "wall_time": wall})
    finally:
        run.close()


def load_ecospy():
    """ecospy, its library loaded. Its wheel's libecosc.so needs oneTBB's libtbb.so.12, which it
    does not ship: the ``tbb`` wheel (dev extra) puts one in this environment's lib folder, loaded
    here first (globally) so that the dynamic loader finds it by its soname."""
    import ctypes
    import sys

    for folder in {sys.prefix, sys.base_prefix}:
        tbb = Path(folder) / "lib" / "libtbb.so.12"
        if tbb.is_file():
            ctypes.CDLL(str(tbb), mode=ctypes.RTLD_GLOBAL)
            break
    import ecospy

    return ecospy


#: An FMU's error as ecos logs it at level debug: ``[<FMU path>] fmi2Error <message>``.
_ECOS_FAILURE = re.compile(r"\[([^\]]*)\] (fmi2Error|fmi2Fatal) (.*)")


@contextmanager
def _stdout_captured():
    """File descriptor 1 (where ecos's C++ logger writes) into a temporary file while the block
    runs. Yields ``written()``: the text written since its last call. Afterwards the lines that
    are not ecos's debug log are written to the real stdout again."""
    import ctypes
    import os
    import sys
    import tempfile

    libc = ctypes.CDLL(None)
    sys.stdout.flush()
    libc.fflush(None)
    saved = os.dup(1)
    log = tempfile.TemporaryFile()
    os.dup2(log.fileno(), 1)
    offset = 0

    def written() -> str:
        nonlocal offset
        libc.fflush(None)
        size = os.fstat(log.fileno()).st_size
        if size == offset:
            return ""
        text = os.pread(log.fileno(), size - offset, offset).decode(errors="replace")
        offset = size
        return text

    try:
        yield written
    finally:
        sys.stdout.flush()
        libc.fflush(None)
        os.dup2(saved, 1)
        os.close(saved)
        log.seek(0)
        others = [line for line in log.read().decode(errors="replace").splitlines(keepends=True)
                  if line.strip() and "[ecos] [debug]" not in line]
        log.close()
        if others:
            sys.stdout.write("".join(others))


def run_ssp_ecos(path: str | Path, stop_time: float, step: float, start_time: float = 0.0,
                 record: list[str] | None = None) -> Result:
    """Simulate an SSP with ecos (``ecospy``), the Ecos platform's co-simulation engine.

    ecos loads the package itself (FMUs, connections, the parameter sets of the SSV files; they
    all carry the system's name, which :func:`export_ssp` gives them, and that set is applied at
    initialization). Its fixed-step algorithm is libcosim's Jacobi exchange, and its
    initialization passes connected values along as often as there are components (consistent
    at t0), so the states (the plant's q, qd) equal the master's Jacobi run to rounding.

    What it records differs for a feedthrough block: after every step ecos transfers the
    outputs, sets the inputs and reads every output again, so :meth:`get_real` returns a
    feedthrough block's outputs computed from its inputs of t + h, where the master's Jacobi
    run records those of its step (from its inputs of t): the master's value one row later.

    ecos (0.7) ignores the status of every FMI call and logs the FMUs' messages at its debug
    level only: a block that refuses its initialization or a step would go unnoticed. The runner
    therefore runs ecos at debug level with file descriptor 1 captured, and stops at the first
    ``fmi2Error`` or ``fmi2Fatal`` an FMU logs (robofmu's FMUs log every error they return).

    Returns a :class:`~robofmu.system.result.Result` with the Real outputs matching ``record``
    (fnmatch patterns on ``instance.variable``; default all) at t0, t0 + h, .., t0 + n h.

    Raises
    ------
    SimulationError
        An FMU reported an error: its message, the component, the time, and every row recorded
        before it (``result``).
    """
    from robofmu.system.interop.libcosim import guard_pythonfmu_exit       # ctypes only: libcosimpy is not needed
    from robofmu.system.master import SimulationError

    ecospy = load_ecospy()
    guard_pythonfmu_exit()
    path = Path(path)
    n = step_count(start_time, stop_time, step)
    system = ET.fromstring(ssd_text(path)).find("ssd:System", NS)
    components = list(system.iterfind("ssd:Elements/ssd:Component", NS))
    columns = [f"{comp.get('name')}.{con.get('name')}" for comp in components
               for con in comp.iterfind("ssd:Connectors/ssd:Connector", NS)
               if con.get("kind") == "output" and con.find("ssc:Real", NS) is not None]
    keep = [columns[k] for k in select(columns, record)]
    identifiers = [c.replace(".", "::", 1) for c in keep]
    data = np.empty((n + 1, len(keep)))
    times = np.empty(n + 1)

    def check(log: str, k: int, t: float) -> None:
        failure = _ECOS_FAILURE.search(log)
        if failure is None:
            return
        source = Path(failure.group(1)).name                    # ecos names an instance by its FMU's path
        named = [c.get("name") for c in components if Path(c.get("source", "")).name == source]
        block = named[0] if len(named) == 1 else source
        partial = Result(times[:k], keep, data[:k].copy(), {"tool": "ecos", "step": step}) if k else None
        said = failure.group(3).strip().removeprefix(f"{failure.group(1)}: ")     # the FMU names itself too
        message = f"ecos: {block} at t = {t:.9g} s: {failure.group(2)}: {said}"
        raise SimulationError(message + (f"; {k} rows recorded before it" if k else ""), block, t, partial,
                              reason=message)

    ecospy.EcosLib.set_log_level("debug")
    try:
        with _stdout_captured() as written, ecospy.EcosSimulation(step_size=step, ssp_path=str(path)) as sim:
            sim.init(start_time, parameter_set=system.get("name"))
            check(written(), 0, start_time)
            get = sim.get_real
            times[0], data[0] = sim.get_time(), [get(i) for i in identifiers]
            wall = _time.perf_counter()
            for k in range(1, n + 1):
                sim.step()
                check(written(), k, times[k - 1])
                times[k], data[k] = sim.get_time(), [get(i) for i in identifiers]
            wall = _time.perf_counter() - wall
            sim.terminate()
    finally:
        ecospy.EcosLib.set_log_level("warn")
    return Result(times, keep, data, {"tool": "ecos", "algorithm": "jacobi (ecos fixed-step)", "step": step,
                                      "wall_time": wall})


def ssd_text(path: str | Path) -> str:
    """The SystemStructure.ssd of an SSP package, as text."""
    with zipfile.ZipFile(path) as zf:
        return zf.read(SSD_NAME).decode("utf-8")

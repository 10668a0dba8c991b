"""Export a diagram as an SSP 1.0 package.

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

Three tools run such a package: fmpy.ssp (:func:`robofmu.system.interop.fmpy_ssp.run_ssp_fmpy`),
libcosim (:func:`robofmu.system.interop.libcosim.run_ssp_libcosim`) and ecos
(:func:`robofmu.system.interop.ecos.run_ssp_ecos`); each module says what its tool supports.
"""
from __future__ import annotations

import math
import re
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET


from robofmu.system.plan import plan, single_rate, variable_unit
from robofmu.system.diagram import System, coerce, expand, spread
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


def ssd_text(path: str | Path) -> str:
    """The SystemStructure.ssd of an SSP package, as text."""
    with zipfile.ZipFile(path) as zf:
        return zf.read(SSD_NAME).decode("utf-8")

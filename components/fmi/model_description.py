"""Completing the model description pythonfmu writes: units, InitialUnknowns, output
dependencies, round-trip start values and a robofmu vendor annotation naming robot and block.
"""
from __future__ import annotations

import sys
from xml.etree.ElementTree import Element, SubElement

from .. import SOURCE_HASH

#: The Python (major.minor) the FMUs are built with and run in (pythonfmu loads libpython).
PYTHON = f"{sys.version_info.major}.{sys.version_info.minor}"

#: SI base-unit exponents of every unit a block may use (FMI 2.0 UnitDefinitions).
UNITS = {
    "1": {},
    "s": {"s": 1},
    "m": {"m": 1},
    "m/s": {"m": 1, "s": -1},
    "m/s2": {"m": 1, "s": -2},
    "rad": {"rad": 1},
    "rad/s": {"rad": 1, "s": -1},
    "rad/s2": {"rad": 1, "s": -2},
    "kg": {"kg": 1},
    "N": {"kg": 1, "m": 1, "s": -2},
    "N.m": {"kg": 1, "m": 2, "s": -2},
    "1/s2": {"s": -2},
    "1/s": {"s": -1},
    "1/s3": {"s": -3},
    "m/rad": {"m": 1, "rad": -1},       # Jacobian entries: task unit over joint unit
    "rad/m": {"rad": 1, "m": -1},
    "N.m.s/rad": {"kg": 1, "m": 2, "s": -1, "rad": -1},     # joint damping, friction, armature, encoder
    "N.s/m": {"kg": 1, "s": -1},
    "kg.m2": {"kg": 1, "m": 2},
    "1/m": {"m": -1},
}

#: Tool name of the vendor annotation that tells robot and block kind of a FMU.
VENDOR_TOOL = "robofmu"


def complete(root: Element, logic, robot: str, kind: str, profile: str = "", robot_data: str = "") -> Element:
    """Complete pythonfmu's ``root`` for block ``logic`` (a :class:`~robofmu.components.blocks.Block`).

    The vendor annotation names robot, kind, variant and profile (a named profile's trajectory
    FMU: ``[trajectories.<profile>]``; empty otherwise), the code's hash (``source``:
    :data:`~robofmu.components.SOURCE_HASH`) and the hash of the robot's data the FMU carries
    (``robot_data``: :func:`~robofmu.components.robot_data_hash`), what ``robofmu build`` and
    the master compare to tell a stale FMU and why."""
    meta = {v.name: v for v in logic.variables}
    used = sorted({v.unit for v in meta.values() if v.unit})
    units = Element("UnitDefinitions")
    for name in used:
        unit = SubElement(units, "Unit", name=name)
        SubElement(unit, "BaseUnit", {k: str(e) for k, e in UNITS[name].items()})
    tags = [c.tag for c in root]
    root.insert(tags.index("CoSimulation") + 1, units)
    annotations = Element("VendorAnnotations")
    tool = SubElement(annotations, "Tool", name=VENDOR_TOOL)
    SubElement(tool, "Block", robot=robot, kind=kind, variant=logic.variant, profile=profile, source=SOURCE_HASH,
               robot_data=robot_data, python=PYTHON, requirements="resources/requirements.txt")
    root.insert([c.tag for c in root].index("ModelVariables"), annotations)

    index = {}
    for i, sv in enumerate(root.find("ModelVariables"), start=1):
        var = meta[sv.get("name")]
        index[var.name] = i
        if var.unit:
            sv[0].set("unit", var.unit)
        if var.kind == "Real" and sv[0].get("start") is not None:
            sv[0].set("start", repr(float(var.start)))   # pythonfmu's %.16g does not round-trip

    structure = root.find("ModelStructure")
    for child in list(structure):
        structure.remove(child)
    outputs = [v for v in meta.values() if v.causality == "output"]
    if outputs:
        node = SubElement(structure, "Outputs")
        for v in outputs:
            attrib = {"index": str(index[v.name])}
            if v.depends is not None:
                attrib["dependencies"] = " ".join(str(i) for i in sorted(index[d] for d in v.depends))
            SubElement(node, "Unknown", attrib)
        node = SubElement(structure, "InitialUnknowns")
        for v in sorted(outputs, key=lambda v: index[v.name]):
            # at initialization outputs also depend on parameters: without an explicit list
            # the attribute is left out, which declares a dependency on every known
            attrib = {"index": str(index[v.name])}
            if v.initial_depends is not None:
                attrib["dependencies"] = " ".join(str(i) for i in sorted(index[d] for d in v.initial_depends))
            SubElement(node, "Unknown", attrib)
    return root

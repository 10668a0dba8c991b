"""The one checked reader through which every URDF reaches Pinocchio (and every SRDF's states).

:func:`read_urdf` refuses, in one line naming the user's file and the element
(:class:`UrdfError`: ``<path>: <element>: <problem>; <what to do>``), what urdfdom would report
on stderr, blame on something else or let through: a DTD or entity declaration (before anything
is expanded: URDFs need none), text that is not XML, duplicate or missing links and joints, a
link with two parents, no single root, a non-finite or missing number, a zero axis, swapped
limits, a robot with no movable joint. What it returns (:class:`Urdf`) holds the robot's joints
and links as data and :attr:`Urdf.text`, the XML Pinocchio reads: a ``continuous`` joint as an
unbounded ``revolute`` one (one coordinate, an angle; position limits [0, 0], which Pinocchio
keeps and :attr:`UrdfJoint.lower`/``upper`` tell as none), a ``<mimic>`` on a ``fixed`` joint
dropped (as URDF readers do), and a link whose name is also a joint's renamed
(``<name>__link``, :attr:`Urdf.frames`), so that every frame of Pinocchio's model has its own
name. A ``.xacro`` file is expanded by the ``xacro`` package first.
"""
from __future__ import annotations

import contextlib
import importlib
import io
import math
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree
from xml.parsers import expat

__all__ = ["UrdfError", "UrdfJoint", "Urdf", "read_urdf", "expand_xacro", "srdf_states", "MOVABLE"]

#: Joint types with a coordinate of their own (a mimic follower aside).
MOVABLE = ("revolute", "prismatic", "continuous")
_TYPES = MOVABLE + ("fixed", "floating", "planar")
#: The suffix that marks a link renamed because a joint has its name.
CLASH_SUFFIX = "__link"


class UrdfError(ValueError):
    """A URDF (or SRDF) robofmu refuses: message ``'<path>: <element>: <problem>; <fix>'`` (one line)."""

    def __init__(self, path, element: str, problem: str, fix: str = ""):
        super().__init__(f"{path}: {element}: {problem}" + (f"; {fix}" if fix else ""))
        self.path = Path(path)
        self.element = element


@dataclass(frozen=True)
class UrdfJoint:
    """One ``<joint>`` as data.

    Attributes
    ----------
    name, type : str
        Type among 'revolute' 'prismatic' 'continuous' 'fixed' 'floating' 'planar'.
    parent, child : str
        Link names (the user's).
    axis : tuple of 3 floats
        As written (default (1, 0, 0)).
    lower, upper : float
        Position limits (rad, m); -inf/inf where there are none (no <limit>, [0, 0], continuous).
    velocity, effort : float
        Limits (rad/s or m/s, N.m or N); inf where there is none (0 or no <limit>).
    mimic : str or None
        The leader's name (None for a fixed joint's ignored mimic).
    multiplier, offset : float
        The mimic relation q = multiplier * q_leader + offset (rad or m).
    damping, friction : float
        ``<dynamics damping= friction=>``: viscous damping (N.m.s/rad or N.s/m) and Coulomb
        friction (N.m or N), each >= 0; 0 where the URDF gives none.
    """

    name: str
    type: str
    parent: str
    child: str
    axis: tuple[float, float, float]
    lower: float
    upper: float
    velocity: float
    effort: float
    mimic: str | None
    multiplier: float = 1.0
    offset: float = 0.0
    damping: float = 0.0
    friction: float = 0.0

    @property
    def movable(self) -> bool:
        """Revolute, prismatic or continuous, and not a mimic follower: a coordinate of its own."""
        return self.type in MOVABLE and self.mimic is None

    def clip(self, value: float) -> float:
        """``value`` clipped into the position limits."""
        return min(max(value, self.lower), self.upper)


@dataclass(frozen=True)
class Urdf:
    """A checked URDF.

    Attributes
    ----------
    path : Path
        The user's file (never a temporary copy).
    name : str
        ``<robot name=...>``.
    links : tuple of str
        Document order.
    joints : dict of str to UrdfJoint
        Document order.
    root : str
        The root link.
    masses : dict of str to float
        Link -> mass (kg), 0 without ``<inertial>``.
    text : str
        The checked XML Pinocchio reads (see the module's docstring).
    frames : dict of str to str
        Each link's name -> its frame's name in ``text`` (``<name>__link`` on a clash).
    clashes : tuple of str
        Names that are both a link and a joint.
    """

    path: Path
    name: str
    links: tuple[str, ...]
    joints: dict[str, UrdfJoint]
    root: str
    masses: dict[str, float]
    text: str
    frames: dict[str, str]
    clashes: tuple[str, ...]

    def children(self, link: str) -> list[UrdfJoint]:
        """The joints whose parent is ``link``, in document order."""
        return [j for j in self.joints.values() if j.parent == link]

    def leaves(self) -> list[str]:
        """The links no joint leaves from, in document order."""
        parents = {j.parent for j in self.joints.values()}
        return [link for link in self.links if link not in parents]

    def parent_joint(self, link: str) -> UrdfJoint | None:
        """The joint whose child is ``link`` (None for the root)."""
        return next((j for j in self.joints.values() if j.child == link), None)

    def chain(self, base: str, tip: str) -> list[UrdfJoint]:
        """The joints from link ``base`` down to link ``tip``, base first; UrdfError if either is no
        link or ``tip`` is not below ``base``."""
        for link in (base, tip):
            if link not in self.frames:
                raise UrdfError(self.path, f"link {link!r}", "no such link",
                                f"its links: {', '.join(self.links[:12])}" + (", ..." if len(self.links) > 12 else ""))
        joints, link = [], tip
        while link != base:
            joint = self.parent_joint(link)
            if joint is None:
                path = self._above(tip)[::-1]
                shown = ", ".join(path[:8]) + (", ..." if len(path) > 8 else "")
                fix = (f"swap them: the base link first, [{tip!r}, {base!r}]" if tip in self._above(base) else
                       f"give a base link above it (the links above it, from the root: {shown})")
                raise UrdfError(self.path, f"link {tip!r}", f"is not below link {base!r}", fix)
            joints.append(joint)
            link = joint.parent
        return joints[::-1]

    def _above(self, link: str) -> list[str]:
        """The links above ``link``, its parent first, up to the root."""
        found = []
        while (joint := self.parent_joint(link)) is not None:
            link = joint.parent
            found.append(link)
        return found

    def xml(self, drop_mimic=()) -> str:
        """:attr:`text` without the ``<mimic>`` of the joints ``drop_mimic`` (locked followers:
        plain joints for Pinocchio, then held)."""
        root = ElementTree.fromstring(self.text)
        for joint in root.findall("joint"):
            mimic = joint.find("mimic")
            if joint.get("name") in drop_mimic and mimic is not None:
                joint.remove(mimic)
        return ElementTree.tostring(root, encoding="unicode")

    @property
    def total_mass(self) -> float:
        """The sum of the links' masses (kg)."""
        return math.fsum(self.masses.values())


class _Declaration(Exception):
    """A DTD or entity declaration met while parsing (raised from expat's handlers)."""


def _parse(path: Path, data: bytes, what: str = "URDF") -> ElementTree.Element:
    """The XML tree of ``data``, refusing a DTD or an entity declaration before expat expands
    anything (an entity bomb never grows) and text that is not XML, naming ``path`` and the line."""
    parser = expat.ParserCreate()

    def doctype(*_):
        raise _Declaration("a DTD (<!DOCTYPE>)")

    def entity(*_):
        raise _Declaration("an entity declaration (<!ENTITY>)")

    parser.StartDoctypeDeclHandler = doctype
    parser.EntityDeclHandler = entity
    try:
        parser.Parse(data, True)
    except _Declaration as exc:
        raise UrdfError(path, f"line {parser.CurrentLineNumber}", f"holds {exc}: {what}s need none",
                        "remove it") from None
    except expat.ExpatError as exc:
        raise UrdfError(path, f"line {exc.lineno}", f"not XML: {expat.errors.messages[exc.code]} "
                                                    f"(column {exc.offset + 1})",
                        f"give a well-formed {what} file") from None
    return ElementTree.fromstring(data)


class _Numbers:
    """Reads numbers from attributes, refusing non-finite or missing ones naming the element."""

    def __init__(self, path: Path, owner: str):
        self.path, self.owner = path, owner

    def fail(self, problem: str, fix: str = ""):
        raise UrdfError(self.path, self.owner, problem, fix)

    def get(self, element, where: str, attribute: str, count: int = 1, default=None) -> tuple[float, ...]:
        text = None if element is None else element.get(attribute)
        label = f"{where} {attribute}" if where else attribute
        if text is None:
            if default is None:
                self.fail(f"{label}: missing", f"give {count} finite number{'s' if count > 1 else ''}")
            return tuple(default)
        words = text.split()
        if len(words) != count:
            self.fail(f"{label}: {text!r} is not {count} number{'s' if count > 1 else ''}",
                      f"give {count} finite number{'s' if count > 1 else ''}")
        values = []
        for word in words:
            try:
                value = float(word)
            except ValueError:
                value = math.nan
            if not math.isfinite(value):
                self.fail(f"{label}: {word!r} is not a finite number", "give a finite number")
            values.append(value)
        return tuple(values)

    def one(self, element, where: str, attribute: str, default: float | None = None) -> float:
        return self.get(element, where, attribute, 1, None if default is None else (default,))[0]

    def origin(self, element, where: str) -> None:
        origin = element.find("origin")
        if origin is not None:
            prefix = f"{where}/origin" if where else "origin"
            self.get(origin, prefix, "xyz", 3, (0.0, 0.0, 0.0))
            self.get(origin, prefix, "rpy", 3, (0.0, 0.0, 0.0))


def _name(path: Path, element, kind: str, index: int) -> str:
    name = element.get("name")
    if not name:
        raise UrdfError(path, f"{kind} #{index + 1}", "has no name", f"give every <{kind}> a unique name")
    return name


def _link(path: Path, element, name: str) -> float:
    """The link's mass (kg), its <inertial> checked."""
    numbers = _Numbers(path, f"link {name!r}")
    inertial = element.find("inertial")
    if inertial is None:
        return 0.0
    numbers.origin(inertial, "inertial")
    mass_element = inertial.find("mass")
    if mass_element is None:
        numbers.fail("inertial: no <mass>", "give <mass value=...> in kg")
    mass = numbers.one(mass_element, "inertial/mass", "value")
    if mass < 0.0:
        numbers.fail(f"inertial/mass value: {mass:g} kg is negative", "give a mass >= 0")
    inertia = inertial.find("inertia")
    if inertia is None:
        numbers.fail("inertial: no <inertia>", "give <inertia ixx= ixy= ixz= iyy= iyz= izz=> in kg m^2")
    for attribute in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"):
        numbers.one(inertia, "inertial/inertia", attribute)
    return mass


def _joint(path: Path, element, name: str) -> UrdfJoint:
    numbers = _Numbers(path, f"joint {name!r}")
    kind = element.get("type")
    if kind not in _TYPES:
        numbers.fail(f"type {kind!r} is no URDF joint type", f"use one of {', '.join(_TYPES)}")
    ends = {}
    for end in ("parent", "child"):
        tag = element.find(end)
        if tag is None or not tag.get("link"):
            numbers.fail(f"no <{end} link=...>", f"name the joint's {end} link")
        ends[end] = tag.get("link")
    numbers.origin(element, "")
    axis = numbers.get(element.find("axis"), "axis", "xyz", 3, (1.0, 0.0, 0.0))
    if kind in MOVABLE + ("planar",) and math.fsum(a * a for a in axis) == 0.0:
        numbers.fail(f"axis xyz {' '.join(f'{a:g}' for a in axis)} has zero length",
                     "give the direction the joint turns about or slides along")
    limit = element.find("limit")
    if limit is None and kind in ("revolute", "prismatic"):
        numbers.fail(f"a {kind} joint needs a <limit>", "give <limit lower= upper= velocity= effort=>")
    lower = upper = 0.0
    velocity = effort = 0.0
    if limit is not None:
        lower, upper = numbers.one(limit, "limit", "lower", 0.0), numbers.one(limit, "limit", "upper", 0.0)
        effort, velocity = numbers.one(limit, "limit", "effort"), numbers.one(limit, "limit", "velocity")
        if lower > upper:
            numbers.fail(f"limit lower {lower:g} above upper {upper:g}", "swap them")
        for key, value in (("velocity", velocity), ("effort", effort)):
            if value < 0.0:
                numbers.fail(f"limit {key} {value:g} is negative", "give a limit >= 0 (0: none)")
    losses = {"damping": 0.0, "friction": 0.0}
    dynamics = element.find("dynamics")
    if dynamics is not None:
        for key in losses:
            losses[key] = numbers.one(dynamics, "dynamics", key, 0.0)
            if losses[key] < 0.0:
                numbers.fail(f"dynamics {key} {losses[key]:g} is negative", "give a coefficient >= 0 (0: none)")
    mimic, multiplier, offset = None, 1.0, 0.0
    tag = element.find("mimic")
    if tag is not None and kind != "fixed":
        mimic = tag.get("joint")
        if not mimic:
            numbers.fail("mimic: no joint", "name the joint it mimics: <mimic joint=...>")
        multiplier = numbers.one(tag, "mimic", "multiplier", 1.0)
        offset = numbers.one(tag, "mimic", "offset", 0.0)
    if kind not in ("revolute", "prismatic") or (lower == 0.0 and upper == 0.0):
        lower, upper = -math.inf, math.inf
    return UrdfJoint(name, kind, ends["parent"], ends["child"], axis, lower, upper,
                     velocity if velocity > 0.0 else math.inf, effort if effort > 0.0 else math.inf,
                     mimic, multiplier, offset, losses["damping"], losses["friction"])


def expand_xacro(path: str | Path, xacro_args: dict | None = None) -> bytes:
    """The URDF that ``path`` (a ``.xacro`` file) expands to with ``xacro_args``, as bytes (UTF-8);
    UrdfError naming the file for a DTD or entity in it, or what xacro refuses."""
    path = Path(path)
    # Imported by name, not by an import statement: a FMU carries the expanded URDF and never
    # runs xacro, so xacro must not become a requirement of the FMUs (system/packaging/requirements).
    try:
        xacro = importlib.import_module("xacro")
    except ImportError:
        raise UrdfError(path, "xacro", "the xacro package is not installed", "pip install xacro") from None
    _parse(path, path.read_bytes(), "xacro file")          # no DTD or entity in what xacro reads
    chatter = io.StringIO()
    try:
        with contextlib.redirect_stderr(chatter), contextlib.redirect_stdout(chatter):
            document = xacro.process_file(str(path), mappings={str(k): str(v) for k, v in (xacro_args or {}).items()})
    except Exception as exc:             # xacro's own errors (XacroException, NameError, XML) as one line
        problem = " ".join(str(exc).split()) or type(exc).__name__
        raise UrdfError(path, "xacro", f"does not expand: {problem}",
                        "fix the file or its xacro_args") from None
    return document.toxml(encoding="utf-8")


def read_urdf(path: str | Path, xacro_args: dict | None = None) -> Urdf:
    """Read and check a URDF file (a ``.xacro`` file expanded first, with ``xacro_args``).

    Parameters
    ----------
    path : str or Path
        The URDF (or ``*.xacro``) file.
    xacro_args : dict of str to str, optional
        The xacro arguments (``<xacro:arg>``); only for a ``.xacro`` file.

    Raises
    ------
    UrdfError
        Naming the file and the element (see the module's docstring).
    """
    path = Path(path)
    if path.suffix == ".xacro":
        data = expand_xacro(path, xacro_args)
    else:
        if xacro_args:
            raise UrdfError(path, "xacro_args", "given for a file that is not a .xacro file",
                            "drop them, or name the .xacro file")
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise UrdfError(path, "(file)", f"cannot be read: {exc.strerror or exc}", "give an existing URDF") from None
    root = _parse(path, data)
    if root.tag != "robot":
        raise UrdfError(path, f"<{root.tag}>", "the root element is not <robot>", "give a URDF (<robot name=...>)")
    if not root.get("name"):
        raise UrdfError(path, "<robot>", "has no name", "give <robot name=...>")
    links, masses = [], {}
    for index, element in enumerate(root.findall("link")):
        name = _name(path, element, "link", index)
        if name in masses:
            raise UrdfError(path, f"link {name!r}", "defined twice", "give each link a name of its own")
        links.append(name)
        masses[name] = _link(path, element, name)
    joints: dict[str, UrdfJoint] = {}
    parents: dict[str, str] = {}
    for index, element in enumerate(root.findall("joint")):
        name = _name(path, element, "joint", index)
        if name in joints:
            raise UrdfError(path, f"joint {name!r}", "defined twice", "give each joint a name of its own")
        joint = _joint(path, element, name)
        for end in (joint.parent, joint.child):
            if end not in masses:
                raise UrdfError(path, f"joint {name!r}", f"names no link {end!r}", "define the link or fix the name")
        if joint.child in parents:
            raise UrdfError(path, f"link {joint.child!r}", f"is the child of joints {parents[joint.child]!r} and "
                                                           f"{name!r}", "a link has one parent joint")
        parents[joint.child] = name
        joints[name] = joint
    for joint in joints.values():
        if joint.mimic is not None and joint.mimic not in joints:
            raise UrdfError(path, f"joint {joint.name!r}", f"mimics no joint {joint.mimic!r}",
                            "name an existing joint in <mimic joint=...>")
    if not links:
        raise UrdfError(path, f"robot {root.get('name')!r}", "has no <link>", "describe the robot's links and joints")
    roots = [link for link in links if link not in parents]
    if len(roots) != 1:
        raise UrdfError(path, f"robot {root.get('name')!r}",
                        f"has {'no root link' if not roots else 'several root links: ' + ', '.join(map(repr, roots))}",
                        "connect the links into one tree")
    reached, stack = {roots[0]}, [roots[0]]
    while stack:
        link = stack.pop()
        for joint in joints.values():
            if joint.parent == link and joint.child not in reached:
                reached.add(joint.child)
                stack.append(joint.child)
    if len(reached) != len(links):
        loop = next(link for link in links if link not in reached)
        raise UrdfError(path, f"link {loop!r}", "is on a loop of joints, not below the root", "a URDF is a tree")
    if not any(joint.movable for joint in joints.values()):
        raise UrdfError(path, f"robot {root.get('name')!r}", "has no movable joint (revolute, prismatic or continuous)",
                        "give the robot a joint that moves")
    clashes = tuple(link for link in links if link in joints)
    frames = {link: link for link in links}
    taken = set(links) | set(joints)
    for link in clashes:
        renamed = link + CLASH_SUFFIX
        while renamed in taken:
            renamed += "_"
        frames[link] = renamed
        taken.add(renamed)
    return Urdf(path, root.get("name"), tuple(links), joints, roots[0], masses, _text(root, frames),
                frames, clashes)


def _text(root: ElementTree.Element, frames: dict[str, str]) -> str:
    """The XML Pinocchio reads: continuous joints as revolute with limits [0, 0], mimic tags on
    fixed joints dropped, links renamed by ``frames``."""
    for link in root.findall("link"):
        link.set("name", frames[link.get("name")])
    for joint in root.findall("joint"):
        for end in ("parent", "child"):
            tag = joint.find(end)
            tag.set("link", frames[tag.get("link")])
        mimic = joint.find("mimic")
        if mimic is not None and joint.get("type") == "fixed":
            joint.remove(mimic)
        if joint.get("type") == "continuous":
            joint.set("type", "revolute")
            limit = joint.find("limit")
            if limit is None:
                limit = ElementTree.SubElement(joint, "limit", effort="0", velocity="0")
            limit.set("lower", "0")
            limit.set("upper", "0")
    return ElementTree.tostring(root, encoding="unicode")


def srdf_states(path: str | Path) -> dict[str, dict[str, float]]:
    """The ``<group_state>`` s of an SRDF file: state name -> {joint: value (rad, m)}.

    States of the same name in several groups are merged (a joint given twice must have one
    value); a joint with several values (a floating or planar joint) is left out.

    Raises
    ------
    UrdfError
        Naming the SRDF and the element: not XML, a DTD or entity, a value that is not a finite
        number, a joint given two values in one state, no group_state at all.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise UrdfError(path, "(file)", f"cannot be read: {exc.strerror or exc}", "give an existing SRDF") from None
    root = _parse(path, data, "SRDF")
    if root.tag != "robot":
        raise UrdfError(path, f"<{root.tag}>", "the root element is not <robot>", "give an SRDF (<robot name=...>)")
    states: dict[str, dict[str, float]] = {}
    for index, element in enumerate(root.iter("group_state")):
        name = _name(path, element, "group_state", index)
        state = states.setdefault(name, {})
        for joint in element.findall("joint"):
            joint_name = joint.get("name")
            if not joint_name:
                raise UrdfError(path, f"group_state {name!r}", "a <joint> has no name", "name it")
            words = (joint.get("value") or "").split()
            numbers = _Numbers(path, f"group_state {name!r}")
            if len(words) != 1:
                if not words:
                    numbers.fail(f"joint {joint_name!r}: no value", "give value=...")
                continue
            value = numbers.one(joint, f"joint {joint_name!r}:", "value")
            if state.get(joint_name, value) != value:
                numbers.fail(f"joint {joint_name!r}: given {state[joint_name]:g} and {value:g}", "give it one value")
            state[joint_name] = value
    if not states:
        raise UrdfError(path, f"robot {root.get('name')!r}", "has no <group_state>", "name a state in the SRDF")
    return states

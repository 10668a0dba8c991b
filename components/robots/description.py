"""A robot's description: its ``<name>.toml`` beside its URDF, read into typed, validated values.

The TOML holds what the URDF cannot: the task coordinates, named configurations, gravity, the
payload, the seed's gains, the blocks the robot gets, the IK solver and the reference trajectory
(the trajectory block's defaults). Nothing outside this module reads the raw TOML; a missing or
malformed key raises :class:`DescriptionError` naming the file and the key.

Schema (every table but those marked optional is required)::

    name = "rrp"                         # the folder's name
    summary = "Spherical RRP arm (seed 000)"
    urdf = "rrp.urdf"                    # relative to the TOML, or a file of an installed
                                         # distribution: { distribution = "example-robot-data",
                                         # path = "ur_description/urdf/ur5_robot.urdf" } (the one
                                         # file of that distribution whose path ends so);
                                         # a ".xacro" file is expanded by the xacro package
    xacro_args = { prefix = "arm_" }     # optional, only for a .xacro urdf: its <xacro:arg>s
    srdf = "arm.srdf"                    # optional: an SRDF (or { distribution, path }) whose
                                         # group_states configurations may name
    blocks = ["trajectory", "ik", "controller", "plant", "fk"]
    default_gains = "pd"                 # the controller's start values: one of the [gains.*] sets

    [task]
    frame = "tcp"                        # URDF frame whose position is the task point
    coordinates = ["x", "y", "z"]        # names of the task coordinates
    axes = [0, 1, 2]                     # optional: which world axes of that position (default all)
    orientation_axes = [0, 1, 2]         # optional: which of the frame's own axes of its orientation
                                         # are tracked too (a pose task; default none: position only)

    [joints]                             # optional
    locked = { finger = 0.02 }           # joints held at a value (rad, m), removed from the model
    chain = ["base_link", "tool_link"]   # optional: one chain of a larger robot; every joint off
                                         # it is locked (at `locked`, else the SRDF state `home`
                                         # names, else 0 clipped into its limits), floating and
                                         # planar joints dropped, mimic followers with their leader
    saturate_effort = false              # the controller clips tau to the effort limits
    urdf_dynamics = false                # true: the URDF's <dynamics damping friction> act in the plant
                                         # (default false: many URDFs carry a simulator's placeholders)
    [joints.limits.elbow]                # a joint's limits where the URDF has none (or others):
    lower = -2.0                         # rad or m; upper too; velocity (rad/s, m/s); effort
    velocity = 3.0                       # (N.m, N); inf: none. A URDF joint whose position
                                         # limits are [0, 0] (its <limit> gives none) is unlimited
    [joints.dynamics.elbow]              # a joint's losses and rotor inertia (the plant's defaults,
    damping = 0.5                        # over the URDF's <dynamics>): viscous damping (N.m.s/rad,
    friction = 0.2                       # N.s/m), Coulomb friction (N.m, N), armature (rotor
    armature = 0.01                      # inertia at the joint, kg m^2 or kg); each >= 0

    [configurations]
    home = [0.0, 0.0, 0.125]             # joint positions (rad, m); `home` is required; any
                                         # configuration may be "srdf:<group_state>" (joints the
                                         # state does not name: 0 clipped into their limits)

    [gravity]                            # optional
    magnitude = 9.81                     # m/s^2
    direction = [0.0, 0.0, -1.0]         # unit vector in the world frame

    [payload]                            # optional: a point mass carried while gripping
    mass = 0.03                          # kg
    frame = "tcp"

    [gains.pd]                           # at least one set; kp > 0 (1/s^2), kd > 0 (1/s), ki >= 0
    kp = 400.0                           # (1/s^3, default 0): the gains' rule, control.GAINS
    kd = 40.0
    ki = 0.0

    [trajectory]                         # the reference scenario (trajectory block defaults)
    profile = "line"                     # a registered profile; its own parameters follow
    ...

    [trajectories.joint]                 # optional: more profiles, each its own trajectory FMU
    profile = "joint_bangbang"           # (fmus/<robot>/trajectory_joint.fmu); an experiment
    ...                                  # picks one by its FMU

    [ik]                                 # optional (a robot whose trajectory is in joint space has none)
    solver = "spherical"                 # a registered solver; its own parameters follow
    ...

A closed-chain mechanism, which a URDF cannot express, gives a ``[mechanism]`` table instead of
``urdf`` (exactly one of the two)::

    [mechanism]
    kind = "planar_3rrp"                 # a kind of :data:`MECHANISMS`; its own keys follow
    r = 0.2                              # ...

Its ``[task]`` then holds ``coordinates`` only (the mechanism's own task coordinates, e.g. x, y,
theta) and optionally ``frame`` (the mechanism's task body, default ``end_effector``); ``axes`` is
not used. ``[trajectory]`` is needed exactly when ``blocks`` lists "trajectory", like ``[ik]``.
The robot model class is picked by the description's :attr:`RobotDescription.model_kind`
(``"serial"`` for a URDF, else the mechanism's kind).
"""
from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from ..control import GAINS, check_gains
from ..parameters import ParameterError
from ..unknown_names import unknown_key

__all__ = ["DescriptionError", "Gains", "TaskSpace", "Payload", "Choice", "Planar3RRPMechanism",
           "MECHANISMS", "RobotDescription", "read"]

#: Blocks a description may list (each built as ``fmus/<robot>/<block>.fmu``).
KNOWN_BLOCKS = ("trajectory", "ik", "controller", "plant", "fk", "jacobian")
#: A profile parameter given as a file name with this suffix is a CSV table beside the TOML.
TABLE_SUFFIX = ".csv"
#: A named profile's trajectory FMU is ``trajectory_<name>``.
PROFILE_PREFIX = "trajectory_"


class DescriptionError(ValueError):
    """A robot description is malformed; the message names the file and the key."""

    def __init__(self, path: Path, key: str, problem: str):
        super().__init__(f"{path}: {key}: {problem}")
        self.path = path
        self.key = key


@dataclass(frozen=True)
class Gains:
    """Computed-torque gains, the same on every joint: kp (1/s^2), kd (1/s), ki (1/s^3)."""

    kp: float
    kd: float
    ki: float = 0.0

    def as_dict(self) -> dict[str, float]:
        return {"kp": self.kp, "kd": self.kd, "ki": self.ki}


@dataclass(frozen=True)
class TaskSpace:
    """The task coordinates: components ``axes`` of the position of URDF frame ``frame``, and, for a
    pose task, the rotations about the frame's own axes ``orientation_axes`` (0, 1, 2: its x, y, z)
    of its orientation (none: a position task).

    For a closed-chain mechanism ``frame`` names its task body (``end_effector``) and the
    coordinates are the mechanism's own (planar x, y along world axes 0, 1 and theta about
    world axis 2: ``axes`` = (0, 1, 2), given for completeness, not read)."""

    frame: str
    coordinates: tuple[str, ...]
    axes: tuple[int, ...]
    orientation_axes: tuple[int, ...] = ()

    @property
    def is_pose(self) -> bool:
        """Whether the task tracks an orientation too (ports ``quat``, ``omega``, ``omegad``)."""
        return bool(self.orientation_axes)


@dataclass(frozen=True)
class Payload:
    """A point mass (kg) carried at URDF frame ``frame`` while the gripper is closed."""

    mass: float
    frame: str


@dataclass(frozen=True)
class Choice:
    """A registered implementation (``kind``) with its own parameters, as the TOML gives them."""

    kind: str
    parameters: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Planar3RRPMechanism:
    """``[mechanism] kind = "planar_3rrp"``: three legs, each an actuated revolute joint at the
    origin O (angle q_i), a link of length ``r`` to its tip Q_i, a passive revolute joint at Q_i
    and a massless slider by which Q_i runs on a line of the end effector through its point Z at
    angle theta + ``line_offsets[i]``.

    Attributes
    ----------
    kind : str
        ``"planar_3rrp"``.
    r : float
        Link length (m), > 0.
    line_offsets : tuple of 3 floats
        Angles of the three lines relative to theta (rad); three directions 120 degrees apart
        (their unit vectors sum to zero), e.g. (pi/3, pi, -pi/3).
    link_com : float
        Centre of mass of each link as a fraction of r from O, in [0, 1].
    link_mass : float
        Mass of each link (kg), >= 0.
    link_inertia : float
        Moment of inertia of each link about its own centre of mass, about z (kg m^2), >= 0.
    ee_mass : float
        End-effector mass (kg) at Z, >= 0.
    ee_inertia : float
        End-effector moment of inertia about Z, about z (kg m^2), >= 0.
    velocity_limits : tuple of 3 floats
        Actuated joint rate limits (rad/s), > 0.
    position_lower, position_upper : tuple of 3 floats
        Actuated joint position limits (rad); -inf / +inf (the default) where there are none.
    """

    kind: str
    r: float
    line_offsets: tuple[float, float, float]
    link_com: float
    link_mass: float
    link_inertia: float
    ee_mass: float
    ee_inertia: float
    velocity_limits: tuple[float, ...]
    position_lower: tuple[float, ...]
    position_upper: tuple[float, ...]

    @property
    def link_inertia_about_origin(self) -> float:
        """Each link's moment of inertia about O (kg m^2): I_c + m (link_com r)^2."""
        return self.link_inertia + self.link_mass * (self.link_com * self.r) ** 2


@dataclass(frozen=True)
class RobotDescription:
    """Everything known about one robot beyond its URDF.

    Attributes
    ----------
    name, summary : str
    path : Path
        The TOML file.
    urdf : Path or None
        The URDF of a serial (tree) robot; None for a closed-chain mechanism.
    blocks : tuple of str
        The blocks this robot gets, in diagram order.
    task : TaskSpace
    configurations : dict of str to tuple of float
        Named joint configurations (rad, m); always holds ``home``.
    gravity : float
        Magnitude (m/s^2), >= 0.
    gravity_direction : tuple of 3 floats
        Unit vector in the world frame.
    payload : Payload or None
    gains : dict of str to Gains
        The seed's gain sets by name ("pd", "pid"), each by the gains' rule
        (:func:`~robofmu.components.control.check_gains`).
    default_gains : str
        The gain set the controller block starts with (and ``robofmu step`` uses): a key of
        ``gains``.
    trajectory : Choice or None
        Reference profile and its parameters (the trajectory block's defaults); None for a robot
        without a trajectory block.
    ik : Choice or None
        IK solver and its parameters; None for robots without an IK block.
    locked : dict of str to float
        Joints of the URDF held at a value (rad, m) and removed from the model (``[joints] locked``).
    xacro_args : dict of str to str
        The arguments of a ``.xacro`` URDF (empty for a plain URDF, and for the expanded copy an
        FMU carries).
    srdf : Path or None
        The SRDF whose ``group_state`` s configurations may name (``srdf``).
    states : dict of str to dict of str to float
        The SRDF's states: name -> {joint: value (rad, m)} (:func:`~.urdf.srdf_states`).
    srdf_configurations : dict of str to str
        The configurations given as ``"srdf:<state>"``: configuration -> state (resolved into
        ``configurations`` in the model's joint order).
    chain : tuple of 2 str or None
        ``[joints] chain``: the base and tip links of the one chain the model keeps.
    tables : tuple of str
        The CSV tables the profiles read (a profile parameter given as ``"file.csv"``), as paths
        relative to the TOML: robot data, carried by each FMU beside the TOML.
    profiles : dict of str to Choice
        More reference profiles by name (``[trajectories.<name>]``), each built as the FMU
        ``trajectory_<name>`` (:meth:`fmu_blocks`, :meth:`block_of`).
    joint_limits : dict of str to dict of str to float
        Limits by joint that replace the URDF's (``[joints.limits.<joint>]``: ``lower``, ``upper``
        (rad, m), ``velocity`` (rad/s, m/s), ``effort`` (N.m, N); inf: none).
    urdf_dynamics : bool
        Whether the URDF's ``<dynamics damping friction>`` are the joints' losses
        (``[joints] urdf_dynamics``, default False: only ``[joints.dynamics]`` counts).
    saturate_effort : bool
        Whether the controller clips its efforts to the effort limits.
    joint_dynamics : dict of str to dict of str to float
        Losses and rotor inertia by joint that replace the URDF's (``[joints.dynamics.<joint>]``:
        ``damping`` (N.m.s/rad, N.s/m), ``friction`` (N.m, N), ``armature`` (kg m^2, kg); each
        finite and >= 0).
    mechanism : Planar3RRPMechanism or None
        The closed-chain mechanism's parameters (``[mechanism]``); None for a URDF robot.
    """

    name: str
    summary: str
    path: Path
    urdf: Path | None
    blocks: tuple[str, ...]
    task: TaskSpace
    configurations: dict[str, tuple[float, ...]]
    gravity: float
    gravity_direction: tuple[float, float, float]
    payload: Payload | None
    gains: dict[str, Gains]
    default_gains: str
    trajectory: Choice | None
    ik: Choice | None
    mechanism: Planar3RRPMechanism | None = None
    locked: dict[str, float] = field(default_factory=dict)
    profiles: dict[str, Choice] = field(default_factory=dict)
    tables: tuple[str, ...] = ()
    joint_limits: dict[str, dict[str, float]] = field(default_factory=dict)
    saturate_effort: bool = False
    urdf_dynamics: bool = False
    joint_dynamics: dict[str, dict[str, float]] = field(default_factory=dict)
    xacro_args: dict[str, str] = field(default_factory=dict)
    srdf: Path | None = None
    states: dict[str, dict[str, float]] = field(default_factory=dict)
    srdf_configurations: dict[str, str] = field(default_factory=dict)
    chain: tuple[str, str] | None = None

    @property
    def home_state(self) -> dict[str, float]:
        """The SRDF state ``home`` names ({joint: value}), empty if home is given as numbers."""
        return self.states.get(self.srdf_configurations.get("home", ""), {})

    @property
    def model_kind(self) -> str:
        """Which robot-model class serves this robot: ``"serial"`` (a URDF) or the mechanism's kind."""
        return "serial" if self.mechanism is None else self.mechanism.kind

    def configuration(self, name: str) -> tuple[float, ...]:
        """Joint positions of a named configuration; ValueError naming the known ones."""
        try:
            return self.configurations[name]
        except KeyError:
            raise ValueError(f"robot {self.name!r} has no configuration {name!r}; known: "
                             f"{', '.join(self.configurations)}") from None

    @property
    def fmu_blocks(self) -> tuple[str, ...]:
        """The FMUs this robot gets, by file stem: its ``blocks``, then ``trajectory_<name>`` for
        each named profile."""
        return self.blocks + tuple(f"{PROFILE_PREFIX}{name}" for name in self.profiles)

    def block_of(self, fmu_block: str) -> tuple[str, str, "RobotDescription"]:
        """(block kind, profile name or "", the description the block reads) of one of
        :attr:`fmu_blocks`: ``trajectory_<name>`` is a trajectory block whose ``[trajectory]``
        is the profile ``<name>``. ValueError naming the known ones otherwise."""
        if fmu_block in self.blocks:
            return fmu_block, "", self
        name = fmu_block[len(PROFILE_PREFIX):] if fmu_block.startswith(PROFILE_PREFIX) else None
        if name not in self.profiles:
            raise ValueError(f"robot {self.name!r} has no block {fmu_block!r}; its blocks: "
                             f"{', '.join(self.fmu_blocks)}")
        return "trajectory", name, replace(self, trajectory=self.profiles[name])

    def gain_set(self, name: str) -> Gains:
        """A gain set by name; ValueError naming the known ones."""
        try:
            return self.gains[name]
        except KeyError:
            raise ValueError(f"robot {self.name!r} has no gains {name!r}; known: "
                             f"{', '.join(self.gains)}") from None


# -- reading ---------------------------------------------------------------------------------------
class _Table:
    """A TOML table with typed accessors whose errors name the file and the dotted key."""

    def __init__(self, path: Path, data: dict, prefix: str = ""):
        self.path, self.data, self.prefix = path, data, prefix

    def key(self, name: str) -> str:
        return f"{self.prefix}{name}"

    def fail(self, name: str, problem: str):
        raise DescriptionError(self.path, self.key(name), problem)

    def _get(self, name: str, default):
        if name in self.data:
            return self.data[name]
        if default is _REQUIRED:
            self.fail(name, "missing")
        return default

    def string(self, name: str, default=None) -> str:
        value = self._get(name, default)
        if not isinstance(value, str) or not value:
            self.fail(name, f"must be a non-empty string, got {value!r}")
        return value

    def number(self, name: str, default=None, low: float | None = None) -> float:
        value = self._get(name, default)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            self.fail(name, f"must be a finite number, got {value!r}")
        if low is not None and value < low:
            self.fail(name, f"must be >= {low:g}, got {value!r}")
        return float(value)

    def numbers(self, name: str, default=None, length: int | None = None,
                infinite: bool = False) -> tuple[float, ...]:
        value = self._get(name, default)
        if not isinstance(value, list) or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool)
                and (math.isfinite(v) or (infinite and not math.isnan(v))) for v in value):
            what = "numbers (inf allowed)" if infinite else "finite numbers"
            self.fail(name, f"must be a list of {what}, got {value!r}")
        if length is not None and len(value) != length:
            self.fail(name, f"must have {length} values, got {len(value)}")
        return tuple(float(v) for v in value)

    def strings(self, name: str, default=None) -> tuple[str, ...]:
        value = self._get(name, default)
        if not isinstance(value, list) or not value or not all(isinstance(v, str) and v for v in value):
            self.fail(name, f"must be a non-empty list of strings, got {value!r}")
        return tuple(value)

    def table(self, name: str, default=None) -> "_Table | None":
        value = self._get(name, default)
        if value is None:
            return None
        if not isinstance(value, dict):
            self.fail(name, f"must be a table, got {value!r}")
        return _Table(self.path, value, f"{self.prefix}{name}.")

    def unknown(self, known: set[str]) -> None:
        extra = sorted(set(self.data) - known)
        if extra:
            self.fail(extra[0], unknown_key(extra[0], known))


_REQUIRED = object()


def _positive(table: _Table, name: str, default=None) -> float:
    value = table.number(name, default)
    if not value > 0.0:
        table.fail(name, f"must be > 0, got {value!r}")
    return value


def _planar_3rrp(table: _Table, kind: str) -> Planar3RRPMechanism:
    """Read ``[mechanism] kind = "planar_3rrp"`` (see :class:`Planar3RRPMechanism`)."""
    table.unknown({"kind", "r", "line_offsets", "link_com", "link_mass", "link_inertia", "ee_mass",
                   "ee_inertia", "velocity_limits", "position_lower", "position_upper"})
    offsets = table.numbers("line_offsets", _REQUIRED, length=3)
    cx, cy = sum(math.cos(a) for a in offsets), sum(math.sin(a) for a in offsets)
    if math.hypot(cx, cy) > 1e-9:
        table.fail("line_offsets", f"must be three directions 120 degrees apart (unit vectors summing to "
                                   f"zero), got {list(offsets)} (sum of length {math.hypot(cx, cy):.3g})")
    com = table.number("link_com", _REQUIRED, low=0.0)
    if com > 1.0:
        table.fail("link_com", f"must be a fraction of r in [0, 1], got {com!r}")
    velocity = table.numbers("velocity_limits", _REQUIRED, length=3)
    if not all(v > 0.0 for v in velocity):
        table.fail("velocity_limits", f"must all be > 0, got {list(velocity)}")
    inf = float("inf")
    lower = table.numbers("position_lower", [-inf] * 3, length=3, infinite=True)
    upper = table.numbers("position_upper", [inf] * 3, length=3, infinite=True)
    if not all(lo < hi for lo, hi in zip(lower, upper)):
        table.fail("position_upper", f"must exceed position_lower element by element, got {list(upper)} "
                                     f"and {list(lower)}")
    mechanism = Planar3RRPMechanism(
        kind=kind, r=_positive(table, "r", _REQUIRED), line_offsets=offsets, link_com=com,
        link_mass=table.number("link_mass", _REQUIRED, low=0.0),
        link_inertia=table.number("link_inertia", _REQUIRED, low=0.0),
        ee_mass=table.number("ee_mass", _REQUIRED, low=0.0),
        ee_inertia=table.number("ee_inertia", _REQUIRED, low=0.0),
        velocity_limits=velocity, position_lower=lower, position_upper=upper)
    if not mechanism.link_inertia_about_origin > 0.0:
        table.fail("link_inertia", "each link needs a positive moment of inertia about O "
                                   "(link_inertia + link_mass (link_com r)^2 > 0)")
    return mechanism


#: Readers of ``[mechanism]`` by ``kind``: each validates its own keys (DescriptionError naming them).
MECHANISMS = {"planar_3rrp": _planar_3rrp}


def _choice(table: _Table, selector: str) -> Choice:
    kind = table.string(selector, _REQUIRED)
    return Choice(kind, {k: v for k, v in table.data.items() if k != selector})


def _distribution_file(table: _Table, reference: "_Table", key: str = "urdf") -> Path:
    """The one file of an installed distribution whose path ends with ``path`` (for ``key``)."""
    from importlib import metadata

    reference.unknown({"distribution", "path"})
    name, tail = reference.string("distribution", _REQUIRED), reference.string("path", _REQUIRED)
    try:
        distribution = metadata.distribution(name)
    except metadata.PackageNotFoundError:
        table.fail(key, f"the distribution {name!r} is not installed (pip install {name})")
    suffix = "/" + tail.strip("/")
    found = [f for f in distribution.files or () if ("/" + str(f)).endswith(suffix)]
    if len(found) != 1:
        table.fail(key, f"the distribution {name!r} has {len(found)} files whose path ends with {tail!r}"
                           + (f": {', '.join(map(str, found[:5]))}" if found else "") + "; exactly one is needed")
    return Path(distribution.locate_file(found[0]))


def _urdf(top: _Table, path: Path, urdf: Path | None) -> Path:
    """The URDF file the description names (``urdf``, given: the caller's copy of it)."""
    if urdf is not None:
        urdf = Path(urdf)
    elif isinstance(top.data.get("urdf"), dict):
        urdf = _distribution_file(top, top.table("urdf", _REQUIRED))
    else:
        urdf = path.parent / top.string("urdf", _REQUIRED)
    if not urdf.is_file():
        top.fail("urdf", f"no such file {urdf}")
    return urdf


def _srdf(top: _Table, path: Path, srdf: Path | None) -> Path | None:
    """The SRDF file the description names (``srdf``; given: the caller's copy of it), or None."""
    if "srdf" not in top.data:
        return None
    if srdf is None:
        srdf = (_distribution_file(top, top.table("srdf", _REQUIRED), "srdf") if isinstance(top.data["srdf"], dict)
                else path.parent / top.string("srdf", _REQUIRED))
    if not Path(srdf).is_file():
        top.fail("srdf", f"no such file {srdf}")
    return Path(srdf)


def _named_urdf(top: _Table) -> str:
    """The file name the ``urdf`` key gives (its ``path`` for a distribution's file)."""
    value = top.data.get("urdf")
    return str(value.get("path", "")) if isinstance(value, dict) else str(value or "")


def _resolve_states(description: RobotDescription) -> RobotDescription:
    """``description`` with each ``"srdf:<state>"`` configuration resolved to joint values in the
    model's joint order (joints the state does not name: 0 clipped into their limits)."""
    from .serial import reduced_model          # the model's joint order is Pinocchio's

    model, urdf = reduced_model(description)
    joints = [j for j in range(1, model.njoints) if model.joints[j].nv == 1]
    configurations = dict(description.configurations)
    for name, state in description.srdf_configurations.items():
        key = f"configurations.{name}"
        if state not in description.states:
            raise DescriptionError(description.path, key, f"no group_state {state!r} in {description.srdf} (its "
                                                          f"states: {', '.join(description.states)})")
        values = description.states[state]
        unknown = [joint for joint in values if joint not in urdf.joints]
        if unknown:
            prefix, _, bare = unknown[0].rpartition("/")
            why = (f" (the URDF's is {bare!r}: the SRDF's names carry the prefix '{prefix}/')" if bare in urdf.joints
                   else "")
            raise DescriptionError(description.path, key, f"the SRDF state {state!r} names joint {unknown[0]!r}, "
                                                          f"which {urdf.path.name} lacks{why}: the SRDF is written for "
                                                          f"another URDF; write {name} as numbers, one per joint: "
                                                          f"{', '.join(model.names[j] for j in joints)}")
        configurations[name] = tuple(
            float(values[model.names[j]]) if model.names[j] in values else
            min(max(0.0, float(model.lowerPositionLimit[model.joints[j].idx_q])),
                float(model.upperPositionLimit[model.joints[j].idx_q])) for j in joints)
    return replace(description, configurations=configurations)


def read(path: str | Path, urdf: str | Path | None = None, srdf: str | Path | None = None) -> RobotDescription:
    """Read and validate one description file.

    Each top-level table has its reader below (``_read_*``), all on one validator
    (:class:`_Table`), called in the file's order of dependence: a table's reader gets what the
    tables it depends on gave.

    Parameters
    ----------
    path : str or Path
        The TOML file.
    urdf : str or Path, optional
        A copy of the URDF to read instead of the one the ``urdf`` key names (an FMU carries its
        robot's URDF in its own resources; a xacro robot's expanded, so ``xacro_args`` are
        not applied to it).
    srdf : str or Path, optional
        A copy of the SRDF to read instead of the one the ``srdf`` key names; with ``urdf`` and
        no ``srdf``, the file beside that copy with the suffix ``.srdf`` (how a FMU carries it).

    Raises
    ------
    DescriptionError
        Naming the file and the key for a missing, malformed or unknown entry.
    """
    path = Path(path)
    top = _Table(path, _toml(path))
    top.unknown(TOP_KEYS)
    copy = urdf is not None
    if copy and srdf is None:
        srdf = Path(urdf).with_suffix(".srdf")
    name = top.string("name", _REQUIRED)
    if name != path.stem:
        top.fail("name", f"must be the file's name {path.stem!r}, got {name!r}")
    urdf, mechanism, xacro_args = _read_source(top, urdf, copy)
    blocks = top.strings("blocks", _REQUIRED)
    for b in blocks:
        if b not in KNOWN_BLOCKS:
            top.fail("blocks", f"unknown block {b!r} (known: {', '.join(KNOWN_BLOCKS)})")
    task_space = _read_task(top, mechanism)
    srdf = None if urdf is None else _srdf(top, path, srdf)
    states = _read_states(top, srdf, copy)
    conf = top.table("configurations", _REQUIRED)
    configurations, named_states = _read_configurations(conf, srdf)
    magnitude, direction = _read_gravity(top)
    payload = _read_payload(top, task_space)
    gains, default_gains = _read_gains(top)
    trajectory, profiles = _read_trajectories(top, blocks)
    ik_table = top.table("ik", None)
    ik = _choice(ik_table, "solver") if ik_table is not None else None
    if ("ik" in blocks) != (ik is not None):
        top.fail("ik", "an [ik] table is needed exactly when `blocks` lists 'ik'")
    joints = _read_joints(top, mechanism)
    description = RobotDescription(
        name=name, summary=top.string("summary", _REQUIRED), path=path, urdf=urdf, blocks=blocks,
        task=task_space, configurations=configurations, gravity=magnitude,
        gravity_direction=direction, payload=payload, gains=gains, default_gains=default_gains,
        trajectory=trajectory, ik=ik,
        mechanism=mechanism, locked=joints.locked, profiles=profiles,
        tables=_profile_tables(path, trajectory, profiles), joint_limits=joints.limits,
        saturate_effort=joints.saturate_effort, urdf_dynamics=joints.urdf_dynamics,
        joint_dynamics=joints.dynamics, xacro_args=xacro_args, srdf=srdf, states=states,
        srdf_configurations=named_states, chain=joints.chain)
    if not named_states:
        return description
    description = _resolve_states(description)
    if len({len(v) for v in description.configurations.values()}) != 1:
        conf.fail("home", "every configuration needs as many joint values as the model has joints, got "
                          f"{sorted({len(v) for v in description.configurations.values()})}")
    return description


#: The top-level keys of a robot description.
TOP_KEYS = frozenset({"name", "summary", "urdf", "mechanism", "blocks", "task", "configurations", "gravity",
                      "payload", "gains", "default_gains", "trajectory", "trajectories", "ik", "joints",
                      "xacro_args", "srdf"})


def _toml(path: Path) -> dict:
    try:
        return tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise DescriptionError(path, "(file)", "does not exist") from None
    except tomllib.TOMLDecodeError as exc:
        raise DescriptionError(path, "(syntax)", str(exc)) from None


def _read_source(top: _Table, urdf: str | Path | None, copy: bool
                 ) -> tuple[Path | None, Planar3RRPMechanism | None, dict[str, str]]:
    """``urdf`` (and ``xacro_args``) or ``[mechanism]``: the URDF's path, the mechanism, the
    xacro arguments as strings (none for a copy: it is expanded already)."""
    mech = top.table("mechanism", None)
    if mech is None:
        urdf = _urdf(top, top.path, urdf)
        arguments = top.table("xacro_args", None)
        if arguments is None:
            return urdf, None, {}
        if not _named_urdf(top).endswith(".xacro"):
            top.fail("xacro_args", f"only for a .xacro urdf, and {_named_urdf(top)!r} is none: drop them")
        for key, value in arguments.data.items():
            if isinstance(value, (dict, list)):
                arguments.fail(key, f"must be a string or a number, got {value!r}")
        return urdf, None, ({} if copy else {key: str(value).lower() if isinstance(value, bool) else str(value)
                                             for key, value in arguments.data.items()})
    if "urdf" in top.data:
        top.fail("mechanism", "a robot has either a `urdf` or a [mechanism] table, not both")
    for key in ("xacro_args", "srdf"):
        if key in top.data:
            top.fail(key, "only for a robot with a `urdf`")
    kind = mech.string("kind", _REQUIRED)
    if kind not in MECHANISMS:
        mech.fail("kind", f"unknown mechanism {kind!r} (known: {', '.join(sorted(MECHANISMS))})")
    return None, MECHANISMS[kind](mech, kind), {}


def _read_task(top: _Table, mechanism: Planar3RRPMechanism | None) -> TaskSpace:
    """``[task]``: a frame's position axes and orientation axes, or a mechanism's own coordinates."""
    task = top.table("task", _REQUIRED)
    if mechanism is not None:   # the mechanism's own task coordinates: planar x, y along world x, y,
        task.unknown({"frame", "coordinates"})                       # theta about world z
        coordinates = task.strings("coordinates", _REQUIRED)
        return TaskSpace(task.string("frame", "end_effector"), coordinates, (0, 1, 2)[:len(coordinates)])
    task.unknown({"frame", "coordinates", "axes", "orientation_axes"})
    coordinates = task.strings("coordinates", _REQUIRED)
    axes = _axes(task, "axes", list(range(len(coordinates))), "world axes")
    if len(axes) != len(coordinates):
        task.fail("axes", f"must have {len(coordinates)} values, got {len(axes)} (one per coordinate)")
    orientation = _axes(task, "orientation_axes", [], "axes of the frame") if "orientation_axes" in task.data \
        else ()
    if "orientation_axes" in task.data and not orientation:
        task.fail("orientation_axes", "must name at least one axis (leave the key out for a position task)")
    return TaskSpace(task.string("frame", _REQUIRED), coordinates, axes, orientation)


def _read_states(top: _Table, srdf: Path | None, copy: bool) -> dict:
    """The SRDF's group states (none without an SRDF)."""
    if srdf is None:
        return {}
    from .urdf import UrdfError, srdf_states
    try:
        return srdf_states(srdf)
    except UrdfError as exc:
        if copy:
            raise
        top.fail("srdf", str(exc))


def _read_configurations(conf: _Table, srdf: Path | None) -> tuple[dict, dict]:
    """``[configurations]``: the configurations given as numbers, and those naming an SRDF state
    (name: state)."""
    named_states = {k: v[len(SRDF_PREFIX):] for k, v in conf.data.items()
                    if isinstance(v, str) and v.startswith(SRDF_PREFIX)}
    for k, v in named_states.items():
        if not v:
            conf.fail(k, f"names no SRDF state: give \"{SRDF_PREFIX}<group_state>\"")
        if srdf is None:
            conf.fail(k, f"names an SRDF state, {SRDF_PREFIX + v!r}, but the robot has no `srdf` file")
    configurations = {k: conf.numbers(k, _REQUIRED) for k in conf.data if k not in named_states}
    if "home" not in conf.data:
        conf.fail("home", "missing")
    lengths = {len(v) for v in configurations.values()}
    if len(lengths) > 1:
        conf.fail("home", f"every configuration needs the same number of joints, got {sorted(lengths)}")
    return configurations, named_states


def _read_gravity(top: _Table) -> tuple[float, tuple[float, ...]]:
    """``[gravity]``: magnitude (m/s^2) and unit direction."""
    grav = top.table("gravity", {})
    grav.unknown({"magnitude", "direction"})
    magnitude = grav.number("magnitude", 9.81, low=0.0)
    direction = grav.numbers("direction", [0.0, 0.0, -1.0], length=3)
    norm = math.sqrt(sum(d * d for d in direction))
    if abs(norm - 1.0) > 1e-12:
        grav.fail("direction", f"must be a unit vector, got length {norm:.6g}")
    return magnitude, direction


def _read_payload(top: _Table, task_space: TaskSpace) -> Payload | None:
    """``[payload]`` (on the task frame unless it names one)."""
    pay = top.table("payload", None)
    if pay is None:
        return None
    pay.unknown({"mass", "frame"})
    return Payload(pay.number("mass", _REQUIRED, low=0.0), pay.string("frame", task_space.frame))


def _read_gains(top: _Table) -> tuple[dict[str, Gains], str]:
    """``[gains.<set>]`` (checked by the controller's rules) and ``default_gains``."""
    gains_table = top.table("gains", _REQUIRED)
    gains = {}
    for set_name in gains_table.data:
        g = gains_table.table(set_name, _REQUIRED)
        g.unknown({rule.name for rule in GAINS})
        values = [g.number(rule.name, _REQUIRED if rule.default is None else rule.default) for rule in GAINS]
        try:
            gains[set_name] = Gains(*check_gains(*values))
        except ParameterError as exc:
            g.fail(exc.name, exc.problem)
    if not gains:
        top.fail("gains", "needs at least one gain set, e.g. [gains.pd]")
    default_gains = top.string("default_gains", _REQUIRED)
    if default_gains not in gains:
        top.fail("default_gains", f"names no gain set of this robot: {default_gains!r} (its sets: "
                                  f"{', '.join(gains)})")
    return gains, default_gains


def _read_trajectories(top: _Table, blocks: tuple[str, ...]) -> tuple[Choice | None, dict[str, Choice]]:
    """``[trajectory]`` (exactly with the trajectory block) and the named ``[trajectories.<name>]``."""
    trajectory_table = top.table("trajectory", _REQUIRED if "trajectory" in blocks else None)
    if trajectory_table is not None and "trajectory" not in blocks:
        top.fail("trajectory", "a [trajectory] table is needed exactly when `blocks` lists 'trajectory'")
    trajectory = _choice(trajectory_table, "profile") if trajectory_table is not None else None
    profiles = {}
    named = top.table("trajectories", None)
    if named is not None:
        if trajectory is None:
            top.fail("trajectories", "named profiles need the trajectory block and its default [trajectory]")
        for profile in named.data:
            if not re.fullmatch(r"[a-z][a-z0-9_]*", profile):
                named.fail(profile, "a profile's name is lower-case letters, digits and _ (it names an FMU)")
            profiles[profile] = _choice(named.table(profile, _REQUIRED), "profile")
    return trajectory, profiles


@dataclass(frozen=True)
class _Joints:
    """What ``[joints]`` gives (its defaults where the table is missing)."""

    locked: dict = field(default_factory=dict)
    limits: dict = field(default_factory=dict)
    saturate_effort: bool = False
    chain: tuple[str, ...] | None = None
    dynamics: dict = field(default_factory=dict)
    urdf_dynamics: bool = False


def _read_joints(top: _Table, mechanism: Planar3RRPMechanism | None) -> _Joints:
    """``[joints]``: locked joints, limits, losses, the kept chain, effort saturation."""
    joints = top.table("joints", None)
    if joints is None:
        return _Joints()
    if mechanism is not None:
        top.fail("joints", "a [mechanism] describes its joints in its own table")
    joints.unknown({"locked", "limits", "saturate_effort", "chain", "dynamics", "urdf_dynamics"})
    chain = None
    if "chain" in joints.data:
        chain = joints.strings("chain", _REQUIRED)
        if len(chain) != 2:
            joints.fail("chain", f"must be two link names [base, tip], got {list(chain)}")
    held = joints.table("locked", {})
    locked = {joint: held.number(joint, _REQUIRED) for joint in held.data}
    limits, losses = {}, {}
    given = joints.table("limits", {})
    for joint in given.data:
        table = given.table(joint, _REQUIRED)
        table.unknown(set(LIMIT_KEYS))
        limits[joint] = {key: _limit(table, key) for key in LIMIT_KEYS if key in table.data}
        low, high = limits[joint].get("lower", -math.inf), limits[joint].get("upper", math.inf)
        if not low < high:
            table.fail("upper", f"must exceed lower, got {high!r} <= {low!r}")
    given = joints.table("dynamics", {})
    for joint in given.data:
        table = given.table(joint, _REQUIRED)
        table.unknown(set(DYNAMICS_KEYS))
        losses[joint] = {key: table.number(key, _REQUIRED, low=0.0) for key in DYNAMICS_KEYS if key in table.data}
    saturate = joints.data.get("saturate_effort", False)
    if not isinstance(saturate, bool):
        joints.fail("saturate_effort", f"must be true or false, got {saturate!r}")
    urdf_dynamics = joints.data.get("urdf_dynamics", False)
    if not isinstance(urdf_dynamics, bool):
        joints.fail("urdf_dynamics", f"must be true or false, got {urdf_dynamics!r}")
    return _Joints(locked, limits, saturate, chain, losses, urdf_dynamics)


def _profile_tables(path: Path, trajectory: Choice | None, profiles: dict[str, Choice]) -> tuple[str, ...]:
    """The data tables (CSV, beside the TOML) the profiles' parameters name, each once."""
    tables = []
    for where, choice in [("trajectory", trajectory)] + [(f"trajectories.{k}", v) for k, v in profiles.items()]:
        for key, value in (choice.parameters.items() if choice is not None else ()):
            if isinstance(value, str) and value.lower().endswith(TABLE_SUFFIX):
                table = (path.parent / value)
                if not table.is_file():
                    raise DescriptionError(path, f"{where}.{key}", f"no such table {table}")
                if Path(value).is_absolute() or ".." in Path(value).parts:
                    raise DescriptionError(path, f"{where}.{key}", "a table lives in the robot's folder: give "
                                                                   f"its path relative to the TOML, got {value!r}")
                tables.append(value)
    return tuple(dict.fromkeys(tables))


#: A configuration given as ``"srdf:<state>"`` is the SRDF's group_state of that name.
SRDF_PREFIX = "srdf:"


#: The keys of a ``[joints.dynamics.<joint>]`` table.
DYNAMICS_KEYS = ("damping", "friction", "armature")


#: The keys of a ``[joints.limits.<joint>]`` table.
LIMIT_KEYS = ("lower", "upper", "velocity", "effort")


def _limit(table: _Table, key: str) -> float:
    """A limit: a number (inf: none); velocity and effort > 0."""
    value = table._get(key, _REQUIRED)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or math.isnan(value):
        table.fail(key, f"must be a number (inf: no limit), got {value!r}")
    if key in ("velocity", "effort") and not value > 0.0:
        table.fail(key, f"must be > 0 (inf: no limit), got {value!r}")
    return float(value)


def _axes(table: _Table, name: str, default, what: str) -> tuple[int, ...]:
    """Distinct axes among 0, 1, 2."""
    axes = table.numbers(name, default)
    if any(a not in (0.0, 1.0, 2.0) for a in axes) or len(set(axes)) != len(axes):
        table.fail(name, f"must be distinct {what} among 0, 1, 2, got {list(axes)}")
    return tuple(int(a) for a in axes)

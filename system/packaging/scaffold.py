"""``robofmu new``: a robot TOML and its demonstration experiment from a URDF, chosen by stated rules.

The rules (docs/robots.md, "Your arm in one minute"):

- **The chain.** The tool is ``--frame``, or else the one leaf link that movable joints reach
  (:func:`tool_leaves`; a leaf below the last movable joint through fixed joints only, such as
  ``tool0``, counts). Several leaves (a gripper's fingers, two arms, fixed frames beside the
  flange) are listed and ``--frame`` asked for. The chain runs from the URDF's root link to the
  tool; every movable joint off it is locked (``[joints] chain``), mimic followers with their
  leader.
- **Home.** An SRDF ``group_state`` that names every joint of the chain, the best of them by the
  posture rule's measures, when one passes the rule's constraints; otherwise the rule's posture
  (:func:`rule_home`): seeded samples inside every limit by a margin of :data:`MARGIN` of the
  joint's range, the tool at least :data:`HEIGHT` of the reach above the chain's first joint, and
  of these the one whose task Jacobian has the largest smallest singular value, at least
  :data:`SIGMA_FACTOR` times the IK's ``singular_value``.
- **The task.** A pose (``orientation_axes = [0, 1, 2]``) for a chain of six joints or more,
  else the position (x, y, z); damped least-squares IK (its null space draws a redundant arm to
  home); computed torque at wn = 20 rad/s (kp = wn^2, kd = 2 wn).
- **The move.** A ``pose_line`` (a position task: ``line``) of :data:`MOVE` of the reach along a
  direction tangent to the tool's circle about the first joint and down, turning
  :data:`ROTATION` about the tool's z axis, in :data:`DURATION`; checked by the build's own
  reference check, and halved (or, refused on a velocity limit, slowed to twice the duration)
  until it passes.

Everything here is FMI-free; :mod:`robofmu.system.commands.new` prints and writes.
"""
from __future__ import annotations

import json
import math
import os
import re
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["MARK", "Chain", "NoDemonstration", "Plan", "Posture", "ScaffoldError", "choose_chain", "describe_move", "plan",
           "chain_model", "first_move", "posture", "resolve_file", "rule_home", "singular_value", "tool_leaves", "write_files"]

#: The first line of every file ``robofmu new`` writes: such a file it may replace.
MARK = "# Written by robofmu new"
#: The posture rule: distance from every position limit, as a fraction of the joint's range.
MARGIN = 0.15
#: The posture rule: the tool this fraction of the reach above the chain's first joint (m/m).
HEIGHT = 0.1
#: The posture rule: smallest singular value of the task Jacobian over the IK's singular_value.
SIGMA_FACTOR = 2.5
#: The posture rule: seeded samples (numpy's default_rng(SEED)) and local refinements.
SAMPLES, REFINEMENTS, SEED = 3000, 300, 0
#: The first demonstration move: its length over the reach, its turn (rad), its duration (s).
MOVE, ROTATION, DURATION = 0.1, math.pi / 6, 2.0
#: The closest a joint of the accepted move may come to a position limit (rad or m).
GAP = 0.01
#: Halvings of the move and doublings of its duration tried before giving up.
SHRINKS, SLOWDOWNS = 5, 3
#: Computed-torque gains at this natural frequency (rad/s), critically damped.
OMEGA_N = 20.0
#: Time after the move in the experiment (s), and its communication step (s).
HOLD, STEP = 1.0, 1e-3


class ScaffoldError(ValueError):
    """A mistake in what ``robofmu new`` was asked: one line naming the option or the user's file."""


class NoDemonstration(ValueError):
    """No demonstration move passes the build's reference check (the last refusal's words)."""


def singular_value() -> float:
    """The damped least-squares IK's default ``singular_value`` (its declared parameter)."""
    from robofmu.components.ik import solver_class

    return float(next(p.default for p in solver_class("damped_least_squares").parameters
                      if p.name == "singular_value"))


# -- files given on the command line ---------------------------------------------------------------
def resolve_file(value: str, option: str) -> tuple[Path, str | dict]:
    """The file ``--urdf``/``--srdf`` names, and how a TOML refers to it: a path, or
    ``DIST:PATH``, the one file of an installed distribution whose path ends with PATH (the
    TOML's ``{ distribution, path }``). ScaffoldError naming the option otherwise."""
    path = Path(value)
    if path.is_file():
        return path.resolve(), str(path)
    if ":" in value and not path.exists():
        from robofmu.components.robots import description as schema

        distribution, tail = value.split(":", 1)
        reference = {"distribution": distribution, "path": tail}
        try:
            found = schema._distribution_file(schema._Table(Path(option), {}),
                                              schema._Table(Path(option), reference, "urdf."))
        except schema.DescriptionError as exc:
            problem = str(exc)[len(f"{exc.path}: {exc.key}: "):]
            raise ScaffoldError(f"{option} {value}: {problem}") from None
        return found, reference
    raise ScaffoldError(f"{option} {value}: no such file (or DIST:PATH, a file of an installed distribution)")


# -- the chain ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Chain:
    """The serial chain a new robot's task runs on.

    Attributes
    ----------
    base, tool : str
        The URDF's root link and the tool link (the user's names).
    joints : tuple of str
        The chain's movable joints, root to tool (the model's joints, in order).
    locked : tuple of str
        Movable joints off the chain (locked by ``[joints] chain``), mimic followers of a locked
        leader included.
    followers : tuple of str
        Mimic followers of a chain joint (they move with it, no coordinate of their own).
    """

    base: str
    tool: str
    joints: tuple[str, ...]
    locked: tuple[str, ...]
    followers: tuple[str, ...]


def tool_leaves(urdf) -> dict[str, tuple[str, ...]]:
    """Each leaf link of ``urdf`` that a movable joint moves, with the movable joints from the
    root to it (root first); leaves no joint moves (base decorations) are left out."""
    found = {}
    for leaf in urdf.leaves():
        joints = tuple(j.name for j in urdf.chain(urdf.root, leaf) if j.movable)
        if joints:
            found[leaf] = joints
    return found


def _leaf_list(leaves: dict[str, tuple[str, ...]], most: int = 12) -> str:
    """The leaves, those with the most joints first, at most ``most`` of them."""
    ranked = sorted(leaves.items(), key=lambda item: -len(item[1]))
    shown = [f"{leaf} ({len(joints)} joint{'s' * (len(joints) != 1)})" for leaf, joints in ranked[:most]]
    more = f" and {len(leaves) - most} more (robofmu inspect lists them)" if len(leaves) > most else ""
    return ", ".join(shown) + more


def choose_chain(urdf, frame: str | None = None) -> Chain:
    """The chain from ``urdf``'s root to the tool ``frame`` (a link), or to the one leaf movable
    joints reach. ScaffoldError naming ``--frame``: several leaves (listed), no such link, a
    link no joint moves, a joint on the chain robofmu cannot move (floating, planar)."""
    leaves = tool_leaves(urdf)
    source = urdf.path.name
    if frame is None:
        if not leaves:
            raise ScaffoldError(f"{urdf.path}: no movable joint reaches a leaf link; robofmu new needs an arm")
        if len(leaves) > 1:
            raise ScaffoldError(f"--frame: {source} has {len(leaves)} leaf links that joints move: "
                                f"{_leaf_list(leaves)}; choose the tool with --frame LINK")
        frame = next(iter(leaves))
    elif frame not in urdf.links:
        hint = f" (a joint of that name moves link {urdf.joints[frame].child!r})" if frame in urdf.joints else ""
        raise ScaffoldError(f"--frame {frame}: no link {frame!r} in {source}{hint}; its leaf links: "
                            f"{_leaf_list(leaves)}")
    path = urdf.chain(urdf.root, frame)
    for joint in path:
        if joint.type in ("floating", "planar"):
            raise ScaffoldError(f"--frame {frame}: joint {joint.name!r} on the chain from {urdf.root!r} is "
                                f"{joint.type}; robofmu moves revolute, prismatic and continuous joints")
    joints = tuple(j.name for j in path if j.movable)
    if not joints:
        raise ScaffoldError(f"--frame {frame}: no joint moves link {frame!r} (it is fixed to {urdf.root!r}); "
                            f"its leaf links: {_leaf_list(leaves)}")
    on_chain = set(joints)
    followers = tuple(j.name for j in urdf.joints.values() if j.mimic in on_chain)
    locked = tuple(j.name for j in urdf.joints.values()
                   if j.name not in on_chain and j.name not in followers and (j.movable or j.mimic))
    return Chain(urdf.root, frame, joints, locked, followers)


# -- postures ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Posture:
    """A posture and the rule's measures of it.

    Attributes
    ----------
    q : tuple of float
        Joint positions (rad, m), the model's joints in order.
    sigma_min : float
        Smallest singular value of the task Jacobian at q (1).
    margin : float
        Smallest distance of a joint to its position limits over the joint's range (1; inf
        without limits).
    height : float
        The tool's height above the chain's first joint (m).
    source : str
        Where it comes from: "srdf:<state>" or "rule".
    """

    q: tuple[float, ...]
    sigma_min: float
    margin: float
    height: float
    source: str = "rule"


def _spans(robot) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    lower, upper = robot.position_limits()
    bounded = np.isfinite(lower) & np.isfinite(upper)
    return lower, upper, np.where(bounded, upper - lower, np.inf)


def _base_point(robot) -> np.ndarray:
    """The chain's first joint's origin (m, world): its placement on the fixed base."""
    return np.array(robot.model.jointPlacements[1].translation)


def posture(robot, q, source: str = "rule") -> Posture:
    """The rule's measures of posture ``q`` of ``robot`` (a serial robot model)."""
    q = np.asarray(q, dtype=float)
    lower, upper, span = _spans(robot)
    with np.errstate(invalid="ignore"):
        margin = float(np.min(np.where(np.isfinite(span), np.minimum(q - lower, upper - q) / span, np.inf)))
    sigma = float(np.linalg.svd(robot.jacobian(q), compute_uv=False)[-1])
    height = float(robot.pose(q).translation[2] - _base_point(robot)[2])
    return Posture(tuple(float(v) for v in q), sigma, margin, height, source)


def reach(robot, samples: int = SAMPLES, seed: int = SEED) -> float:
    """The largest distance (m) from the chain's first joint to the tool over seeded postures
    inside the limits (unbounded joints over one turn)."""
    lower, upper, span = _spans(robot)
    low, high = np.where(np.isfinite(span), lower, -math.pi), np.where(np.isfinite(span), upper, math.pi)
    base = _base_point(robot)
    rng = np.random.default_rng(seed)
    return max(float(np.linalg.norm(robot.pose(q).translation - base))
               for q in low + (high - low) * rng.random((samples // 3, len(low))))


def _acceptable(found: Posture, length: float, sigma_floor: float) -> bool:
    return found.margin >= MARGIN - 1e-9 and found.height >= HEIGHT * length and found.sigma_min >= sigma_floor


def _failed(found: Posture, length: float, sigma_floor: float) -> str:
    """What keeps ``found`` from the posture rule, in words."""
    return ", ".join(problem for problem, bad in (
        (f"a joint {found.margin * 100:.0f} % of its range from a limit (< {MARGIN * 100:g} %)",
         found.margin < MARGIN - 1e-9),
        (f"the tool {found.height:.3g} m above the first joint (< {HEIGHT * length:.3g} m)", found.height < HEIGHT * length),
        (f"smallest singular value {found.sigma_min:.3g} (< {sigma_floor:g})", found.sigma_min < sigma_floor)) if bad)


def rule_home(robot, length: float, samples: int = SAMPLES, seed: int = SEED) -> Posture | None:
    """The rule's home posture: of ``samples`` seeded postures (and ``REFINEMENTS`` seeded
    perturbations of the best) inside every limit by :data:`MARGIN` of its range (unbounded
    joints within one turn), the tool :data:`HEIGHT` x ``length`` (the reach, m) above the chain's
    first joint, the one with the largest smallest singular value of the task Jacobian, rounded
    to 1 mrad (1 mm). None if none has that height."""
    lower, upper, span = _spans(robot)
    bounded = np.isfinite(span)
    low = np.where(bounded, lower + MARGIN * np.where(bounded, span, 0.0), -math.pi)
    high = np.where(bounded, upper - MARGIN * np.where(bounded, span, 0.0), math.pi)
    low, high = np.ceil(low * 1000.0) / 1000.0, np.floor(high * 1000.0) / 1000.0
    rng = np.random.default_rng(seed)
    candidates = np.vstack([np.round((low + high) / 2.0, 3), low + (high - low) * rng.random((samples, len(low)))])
    best = None
    for q in np.clip(np.round(candidates, 3), low, high):
        found = posture(robot, q)
        if found.height >= HEIGHT * length and (best is None or found.sigma_min > best.sigma_min):
            best = found
    if best is None:
        return None
    scale = np.where(bounded, 0.05 * np.where(bounded, span, 0.0), 0.2)
    for _ in range(REFINEMENTS):
        q = np.clip(np.round(np.array(best.q) + scale * rng.standard_normal(len(low)), 3), low, high)
        found = posture(robot, q)
        if found.height >= HEIGHT * length and found.sigma_min > best.sigma_min:
            best = found
    return best


# -- the plan ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Plan:
    """What ``robofmu new`` chose, and the two files' text.

    Attributes
    ----------
    name : str
    chain : Chain
    pose : bool
        A pose task (else the position).
    home : Posture
    reach : float
        m.
    trajectory : dict
        The ``[trajectory]`` table written.
    duration : float
        The move's duration (s).
    check : ReferenceCheck
        The build's reference check of the written robot.
    notes : tuple of str
        Why, in a few lines (the home's source when an SRDF state was passed over, the shrinks).
    robot_text, experiment_text : str
        ``NAME.toml`` and ``NAME-pose.toml`` (``NAME-line.toml`` for a position task).
    """

    name: str
    chain: Chain
    pose: bool
    home: Posture
    reach: float
    trajectory: dict
    duration: float
    check: object
    notes: tuple[str, ...]
    robot_text: str
    experiment_text: str

    @property
    def experiment_name(self) -> str:
        return f"{self.name}-{'pose' if self.pose else 'line'}"


def _toml(value) -> str:
    """A TOML value: a number, string, list or inline table."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(float(value)) if isinstance(value, float) else str(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    return "{ " + ", ".join(f"{k} = {_toml(v)}" for k, v in value.items()) + " }"


def _robot_text(name: str, header: list[str], summary: str, urdf, xacro_args: dict, srdf, chain: Chain,
                pose: bool, home, trajectory: dict) -> str:
    """A robot TOML (the description schema of robofmu.components.robots.description)."""
    kp, kd = OMEGA_N ** 2, 2.0 * OMEGA_N
    lines = [MARK + " (robofmu new --force replaces it): edit freely, then robofmu build this file.",
             *[f"# {line}" for line in header],
             f"name = {_toml(name)}", f"summary = {_toml(summary)}", f"urdf = {_toml(urdf)}"]
    if xacro_args:
        lines.append(f"xacro_args = {_toml(xacro_args)}")
    if srdf is not None:
        lines.append(f"srdf = {_toml(srdf)}")
    lines += ['blocks = ["trajectory", "ik", "controller", "plant", "fk"]', 'default_gains = "pd"', ""]
    if chain.locked:
        lines += ["[joints]                          # every movable joint off the chain base -> tool is locked",
                  f"chain = {_toml([chain.base, chain.tool])}", ""]
    lines += ["[task]", f"frame = {_toml(chain.tool)}", 'coordinates = ["x", "y", "z"]']
    lines += ["orientation_axes = [0, 1, 2]", ""] if pose else [""]
    lines += ["[configurations]", f"home = {_toml(home)}", "",
              f"[gains.pd]                        # computed torque, critically damped: wn = {OMEGA_N:g} rad/s",
              f"kp = {kp!r}", f"kd = {kd!r}", "ki = 0.0", "",
              "[ik]", 'solver = "damped_least_squares"' + ("   # the null space draws the arm to home"
                                                          if len(chain.joints) > (6 if pose else 3) else ""), "",
              "[trajectory]"]
    lines += [f"{key} = {_toml(value)}" for key, value in trajectory.items()]
    return "\n".join(lines) + "\n"


def _experiment_text(name: str, experiment: str, description: str, stop_time: float) -> str:
    return "\n".join([
        MARK + " (robofmu new --force replaces it): the standard loop of robot " + name + ".",
        f"name = {_toml(experiment)}", f"robot = {_toml(name + '.toml')}",
        f"description = {_toml(description)}", 'loop = "computed-torque"',
        f"stop_time = {stop_time!r}", f"step = {STEP!r}"]) + "\n"


def _direction(robot, q) -> np.ndarray:
    """Unit direction of the move: tangent to the tool's circle about the first joint's vertical,
    and down by half as much (world x and down when the tool is on that vertical)."""
    radial = robot.pose(q).translation - _base_point(robot)
    radial[2] = 0.0
    norm = float(np.linalg.norm(radial))
    tangent = np.array([-radial[1], radial[0], 0.0]) / norm if norm > 1e-6 else np.array([1.0, 0.0, 0.0])
    d = tangent + np.array([0.0, 0.0, -0.5])
    return d / np.linalg.norm(d)


def _move(robot, home, pose: bool, length: float, scale: float, duration: float) -> dict:
    """The ``[trajectory]`` table of the demonstration at ``scale`` of the first move."""
    d = _direction(robot, np.array(home))
    distance = round(scale * MOVE * length, 4)
    if pose:
        return {"profile": "pose_line", "displacement": [round(float(v), 4) for v in distance * d],
                "rotation": [0.0, 0.0, scale * ROTATION], "duration": duration}
    # from the tool at home; a trapezoid whose ramps take a third of the duration each (L the length
    # of the rounded displacement): cruise v = L / (T - ramp), acceleration v / ramp
    displacement = [round(float(v), 4) for v in distance * d]
    length = float(np.linalg.norm(displacement))
    ramp = duration / 3.0
    cruise = length / (duration - ramp)
    return {"profile": "line", "displacement": displacement, "v_max": cruise, "a_max": cruise / ramp}


def first_move(pose: bool) -> dict:
    """A ``[trajectory]`` table that stands still, for a model loaded before its move is chosen."""
    if pose:
        return {"profile": "pose_line", "displacement": [0.0, 0.0, 0.0], "rotation": [0.0, 0.0, 0.0],
                "duration": DURATION}
    return {"profile": "line", "displacement": [0.0, 0.0, 0.01], "v_max": 1.0, "a_max": 1.0}


def chain_model(urdf, chain: Chain, xacro_args: dict | None = None):
    """The serial robot model (Pinocchio's, through the robot description) of ``chain`` of the
    checked URDF ``urdf``: its task the tool's pose from six joints, else its position. ValueError
    naming the URDF where the model refuses it."""
    from robofmu.components.robots import load_model
    from robofmu.components.robots.description import read

    pose = len(chain.joints) >= 6
    with tempfile.TemporaryDirectory(prefix="robofmu-inspect-") as folder:
        path = Path(folder) / "inspected.toml"
        path.write_text(_robot_text("inspected", [], "inspected", str(urdf.path), dict(xacro_args or {}), None, chain,
                                    pose, [0.0] * len(chain.joints), first_move(pose)))
        try:
            return load_model(read(path))
        except ValueError as exc:
            raise ScaffoldError(_own_words(exc, folder, "inspected", urdf.path)) from None


def _reference(path: Path, given, out: Path):
    """How the TOML in ``out`` names a file: a distribution's ``{distribution, path}`` as given, an
    absolute path as given, a relative one relative to ``out``."""
    if not isinstance(given, str) or Path(given).is_absolute():
        return given
    return os.path.relpath(path, out.resolve())


def plan(name: str, urdf_path: Path, urdf_ref, out: Path, frame: str | None = None,
         srdf: tuple[Path, object] | None = None, xacro_args: dict | None = None) -> Plan:
    """Choose the chain, home, task and move of robot ``name`` from its URDF, check them as
    ``robofmu build`` will, and return the files' text.

    Parameters
    ----------
    name : str
        The robot's name (letters, digits, underscores).
    urdf_path : Path
        The URDF (or xacro) file.
    urdf_ref : str or dict
        How the TOML names it (a path as the user gave it, or ``{distribution, path}``).
    out : Path
        The folder the files go to (the TOML's path to the URDF is relative to it).
    frame : str, optional
        The tool link (``--frame``).
    srdf : (Path, str or dict), optional
        The SRDF file and how the TOML names it.
    xacro_args : dict, optional
        ``--xacro-arg`` values.

    Raises
    ------
    ScaffoldError
        A mistake in what was asked (one line naming the option or file).
    NoDemonstration
        No move passes the reference check.
    """
    from robofmu.components.preflight import ReferenceRefused, check_reference
    from robofmu.components.robots import load_model
    from robofmu.components.robots.description import read
    from robofmu.components.robots.urdf import read_urdf

    if not re.fullmatch(r"[A-Za-z0-9_]+", name):
        raise ScaffoldError(f"NAME {name!r}: a robot's name is letters, digits and underscores (it names its "
                            "FMUs' model identifiers)")
    xacro_args = dict(xacro_args or {})
    urdf = read_urdf(urdf_path, xacro_args or None)
    chain = choose_chain(urdf, frame)
    n = len(chain.joints)
    if n < 3:
        raise ScaffoldError(f"--frame {chain.tool}: the chain from {chain.base!r} has {n} joint(s); robofmu new "
                            "makes a position task (3 joints or more) or a pose task (6 or more)")
    pose = n >= 6
    states = {}
    if srdf is not None:
        from robofmu.components.robots.urdf import srdf_states

        states = {state: values for state, values in srdf_states(srdf[0]).items()
                  if set(chain.joints) <= set(values)}
    urdf_ref = _reference(urdf_path, urdf_ref, out)
    srdf_ref = None if srdf is None else _reference(srdf[0], srdf[1], out)
    placeholder = [0.0] * n
    target = out / f"{name}.toml"

    with tempfile.TemporaryDirectory(prefix="robofmu-new-") as folder:
        def describe(home, trajectory, header=()):
            text = _robot_text(name, list(header), summary, str(urdf_path) if isinstance(urdf_ref, str) else urdf_ref,
                               xacro_args, None if srdf is None else str(srdf[0]), chain, pose, home, trajectory)
            path = Path(folder) / f"{name}.toml"
            path.write_text(text)
            return read(path)

        what = f"pose of {chain.tool}" if pose else f"position of {chain.tool}"
        locked = f", {len(chain.locked)} joints locked" if chain.locked else ""
        summary = f"{urdf.name} ({urdf_path.name}): {n} joints {chain.base} -> {chain.tool}{locked}: {what}"
        first = first_move(pose)
        try:
            robot = load_model(describe(placeholder, first))
        except ValueError as exc:
            raise ScaffoldError(_own_words(exc, folder, name, target)) from None
        length = reach(robot)
        notes = []
        sigma_floor = SIGMA_FACTOR * singular_value()
        home, home_value = None, None
        if states:
            scored = []
            for state in states:
                described = describe(f"srdf:{state}", first)
                q = load_model(described).configuration("home")
                scored.append(posture(robot, q, f"srdf:{state}"))
            good = [p for p in scored if _acceptable(p, length, sigma_floor)]
            if good:
                home = max(good, key=lambda p: p.sigma_min)
                home_value = home.source
            else:
                notes.append("no SRDF state passes the posture rule: " + "; ".join(
                    f"{p.source[5:]}: {_failed(p, length, sigma_floor)}" for p in scored))
        elif srdf is not None:
            notes.append(f"no group_state of {srdf[0].name} names every joint of the chain")
        if home is None:
            home = rule_home(robot, length)
            if home is None or not _acceptable(home, length, sigma_floor):
                found = "no posture puts the tool above its base" if home is None else (
                    f"the best posture's smallest singular value is {home.sigma_min:.3g} (needed "
                    f">= {sigma_floor:g})")
                raise NoDemonstration(f"{urdf.path}: no home posture by the rule for tool {chain.tool!r}: {found}; "
                                      "give an SRDF with a group_state (--srdf) or another --frame")
            home_value = list(home.q)

        duration, scale, tries = DURATION, 1.0, []
        while True:
            trajectory = _move(robot, home.q, pose, length, scale, duration)
            try:
                check = check_reference(describe(home_value, trajectory))
                if check.position_margin >= GAP:
                    break
                refusal = (f"a joint comes within {check.position_margin:.3g} of a position limit (less than "
                           f"{GAP:g})")
            except ReferenceRefused as exc:
                refusal = _own_words(exc, folder, name, target)
            tries.append(f"{describe_move(trajectory, duration)}: {refusal}")
            if "velocity" in refusal and duration < DURATION * 2 ** SLOWDOWNS:
                duration *= 2.0
            elif scale > 0.5 ** SHRINKS:
                scale /= 2.0
            else:
                raise NoDemonstration(f"no demonstration move passes the build's reference check after "
                                      f"{len(tries)} tries; the last: {tries[-1]}")
        if tries:
            notes.append(f"{len(tries)} larger or faster moves refused by the reference check, the first: {tries[0]}")
        lossy = [j for j in chain.joints if urdf.joints[j].damping or urdf.joints[j].friction]
        if lossy:
            notes.append(f"the URDF gives {len(lossy)} chain joints <dynamics> (damping up to "
                         f"{max(urdf.joints[j].damping for j in lossy):g}, friction up to "
                         f"{max(urdf.joints[j].friction for j in lossy):g}); the plant ignores them unless "
                         "[joints] urdf_dynamics = true")
        move_time = duration
        header = [f"chain: {chain.base} -> {chain.tool}, {n} joints; tool {what}",
                  f"home: {home.source}: smallest singular value {home.sigma_min:.3g}, joints at least "
                  f"{home.margin * 100:.0f} % of their range inside their limits, tool {home.height:.3g} m above "
                  "the first joint"]
        robot_text = _robot_text(name, header, summary, urdf_ref, xacro_args, srdf_ref, chain, pose, home_value,
                                 trajectory)
    experiment = f"{name}-{'pose' if pose else 'line'}"
    said = describe_move(trajectory, move_time)
    experiment_text = _experiment_text(name, experiment, f"{name}: {said}, then holds; damped least-squares "
                                       f"{'pose' if pose else 'position'} IK, computed-torque PD kp "
                                       f"{OMEGA_N ** 2:g}, kd {2 * OMEGA_N:g}", move_time + HOLD)
    return Plan(name, chain, pose, home, length, trajectory, move_time, check, tuple(notes), robot_text,
                experiment_text)


def describe_move(trajectory: dict, duration: float) -> str:
    """A move in words: its length, turn and duration."""
    distance = float(np.linalg.norm(trajectory["displacement"]))
    if trajectory["profile"] == "pose_line":
        turn = math.degrees(trajectory["rotation"][2])
        return f"the tool moves {distance * 1000:.4g} mm in a straight line turning {turn:.4g} deg in {duration:g} s"
    return f"the tool moves {distance * 1000:.4g} mm in a straight line in {duration:g} s"


def _own_words(exc: Exception, folder: str, name: str, target: Path) -> str:
    """A model's refusal with the temporary TOML's path replaced by the TOML's own."""
    return " ".join(str(exc).replace(str(Path(folder) / f"{name}.toml"), str(target)).split())


# -- writing ------------------------------------------------------------------------------------------
def _ours(path: Path) -> bool:
    """Whether ``path`` is a file robofmu new wrote (its first line is :data:`MARK`)."""
    try:
        with path.open("r", encoding="utf-8", errors="replace") as f:
            return f.readline().startswith(MARK)
    except OSError:
        return False


def check_targets(paths, force: bool) -> None:
    """Refuse (ScaffoldError naming the file) an existing file robofmu new did not write (unless
    ``force``) and a folder in a file's place."""
    for path in paths:
        if path.is_dir():
            raise ScaffoldError(f"{path}: is a folder; robofmu new writes a file there (choose --out or NAME)")
        if path.exists() and not force and not _ours(path):
            raise ScaffoldError(f"{path}: exists and was not written by robofmu new; move it away or pass --force")


def write_files(texts: dict[Path, str], force: bool = False) -> list[Path]:
    """Write each file atomically (:func:`robofmu.system.usage.atomic_file`: a temporary sibling
    renamed into place), every text before the first rename; returns the paths written."""
    from contextlib import ExitStack

    from robofmu.system.usage import atomic_file

    check_targets(texts, force)
    with ExitStack() as stack:
        for path, text in texts.items():
            stack.enter_context(atomic_file(path)).write_text(text)
    return list(texts)

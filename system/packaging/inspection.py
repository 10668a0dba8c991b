"""``robofmu inspect``: what a user needs to write a robot's task by hand, on one screen of tables.

From a URDF (or a robot TOML): the joints (type, position, velocity and effort limits, mimic,
continuous), the leaf links joints move and their chains, the frames and what each is (a link, a
fixed joint, a joint) with name clashes marked, the total mass; and at home (the TOML's, or for a
bare URDF the posture rule's of :mod:`.scaffold`, else zeros clipped into the limits: it says
which) the tool's pose (position, quaternion x y z w), the task Jacobian's smallest singular
value and each joint's distance to its limits. FMI-free; :mod:`robofmu.system.commands.inspect`
prints it.
"""
from __future__ import annotations

import math
import textwrap
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["AtHome", "Inspection", "inspect", "render"]


@dataclass(frozen=True)
class AtHome:
    """The tool at a home posture.

    Attributes
    ----------
    source : str
        Which home: "the TOML's home", "the SRDF state <s>", "the posture rule's home" or "zeros
        clipped into the limits".
    tool : str
        The task frame (a link).
    joints : tuple of str
        The model's joints, in order.
    q : tuple of float
        Home (rad, m), one per joint.
    position : tuple of 3 floats
        The tool's origin (m, world).
    quaternion : tuple of 4 floats
        Its orientation (x, y, z, w; tool to world; w >= 0).
    sigma_min : float
        Smallest singular value of the task Jacobian (1).
    pose : bool
        Whether the task is the pose (else the position).
    lower_gap, upper_gap : tuple of float
        Each joint's distance to its lower and upper limit (rad, m; inf without).
    """

    source: str
    tool: str
    joints: tuple[str, ...]
    q: tuple[float, ...]
    position: tuple[float, float, float]
    quaternion: tuple[float, float, float, float]
    sigma_min: float
    pose: bool
    lower_gap: tuple[float, ...]
    upper_gap: tuple[float, ...]


@dataclass(frozen=True)
class Inspection:
    """A robot as :func:`render` shows it.

    Attributes
    ----------
    source : Path
        The file inspected (a URDF or a robot TOML).
    urdf : Urdf
        The checked URDF (robofmu.components.robots.urdf).
    leaves : dict of str to tuple of str
        Each leaf link joints move, with the movable joints from the root to it.
    roles : dict of str to str
        A joint's role in the model: "chain", "locked <value>", "mimics <leader>".
    limits : dict of str to tuple of 4 floats
        The model's limits of its joints (lower, upper, velocity, effort; a TOML's own over the
        URDF's).
    home : AtHome or None
        None where no tool is known (several leaves and no --frame).
    why_no_home : str
    """

    source: Path
    urdf: object
    leaves: dict[str, tuple[str, ...]]
    roles: dict[str, str]
    limits: dict[str, tuple[float, float, float, float]]
    home: AtHome | None
    why_no_home: str = ""


def _at_home(robot, q, source: str, pose: bool, tool: str) -> AtHome:
    import pinocchio as pin

    q = np.asarray(q, dtype=float)
    lower, upper = robot.position_limits()
    xyzquat = pin.SE3ToXYZQUAT(robot.pose(q))
    quaternion = xyzquat[3:] if xyzquat[6] >= 0.0 else -xyzquat[3:]
    sigma = float(np.linalg.svd(robot.jacobian(q), compute_uv=False)[-1])
    return AtHome(source, tool, tuple(robot.joint_names), tuple(float(v) for v in q),
                  tuple(float(v) for v in xyzquat[:3]), tuple(float(v) for v in quaternion), sigma, pose,
                  tuple(float(v) for v in q - lower), tuple(float(v) for v in upper - q))


def _model_limits(robot) -> dict[str, tuple[float, float, float, float]]:
    lower, upper = robot.position_limits()
    return {name: (float(lo), float(hi), float(v), float(e)) for name, lo, hi, v, e in
            zip(robot.joint_names, lower, upper, robot.velocity_limits(), robot.effort_limits())}


def inspect(target: str | Path, frame: str | None = None) -> Inspection:
    """Inspect a URDF (``frame``: the tool link, as ``robofmu new --frame``) or a robot TOML.

    Raises
    ------
    ValueError
        A file that cannot be read (UrdfError, DescriptionError, ScaffoldError naming it).
    """
    from robofmu.components.robots.urdf import read_urdf

    from . import scaffold

    path = Path(target)
    if path.suffix == ".toml":
        from robofmu.components.robots import load_description, load_model
        from robofmu.components.robots.serial import lock_values

        description = load_description(path)
        if description.urdf is None:
            raise scaffold.ScaffoldError(f"{path}: a [mechanism] robot has no URDF to inspect")
        if frame is not None:
            raise scaffold.ScaffoldError(f"--frame {frame}: a robot TOML names its tool ([task] frame "
                                         f"{description.task.frame!r})")
        urdf = read_urdf(description.urdf, description.xacro_args or None)
        robot = load_model(description)
        roles = {name: "chain" for name in robot.joint_names}
        roles.update({name: "locked" if value is None else f"locked {value:g}"
                      for name, value in lock_values(description, urdf).items()})
        roles.update({j.name: f"mimics {j.mimic}" for j in urdf.joints.values() if j.mimic and j.name not in roles})
        which = description.srdf_configurations.get("home")
        home = _at_home(robot, robot.configuration("home"), f"the SRDF state {which}" if which else "the TOML's home",
                        description.task.is_pose, description.task.frame)
        return Inspection(path, urdf, scaffold.tool_leaves(urdf), roles, _model_limits(robot), home)

    urdf = read_urdf(path)
    leaves = scaffold.tool_leaves(urdf)
    limits = {j.name: (j.lower, j.upper, j.velocity, j.effort) for j in urdf.joints.values() if j.movable}
    roles = {j.name: f"mimics {j.mimic}" for j in urdf.joints.values() if j.mimic}
    try:
        chain = scaffold.choose_chain(urdf, frame)
    except scaffold.ScaffoldError as exc:
        if frame is not None:
            raise
        return Inspection(path, urdf, leaves, roles, limits, None, f"{exc}".replace("choose the tool", "give the tool"))
    robot = scaffold.chain_model(urdf, chain)
    pose = len(chain.joints) >= 6
    roles.update({name: "chain" for name in chain.joints})
    roles.update({name: "locked" for name in chain.locked})
    found = scaffold.rule_home(robot, scaffold.reach(robot))
    if found is not None and found.sigma_min >= scaffold.SIGMA_FACTOR * scaffold.singular_value():
        q, source = found.q, "the posture rule's home (robofmu new's)"
    else:
        lower, upper = robot.position_limits()
        q, source = np.clip(np.zeros(robot.n), lower, upper), "zeros clipped into the limits (no posture passes the rule)"
    limits.update(_model_limits(robot))
    return Inspection(path, urdf, leaves, roles, limits, _at_home(robot, q, source, pose, chain.tool))


# -- rendering --------------------------------------------------------------------------------------
def _number(value: float) -> str:
    return "-" if not math.isfinite(value) else f"{value:.4g}"


def _table(header: list[str], rows: list[list[str]]) -> list[str]:
    widths = [max(len(str(c)) for c in column) for column in zip(header, *rows)]
    line = lambda cells: "  ".join(str(c).ljust(w) for c, w in zip(cells, widths)).rstrip()
    return [line(header), line(["-" * w for w in widths])] + [line(r) for r in rows]


def _wrapped(label: str, names: list[str], width: int = 100) -> list[str]:
    text = ", ".join(names) if names else "none"
    return textwrap.wrap(f"{label}: {text}", width, subsequent_indent="  ")


def render(found: Inspection) -> str:
    """The tables, one screen for an arm (a robot with many leaves lists them on wrapped lines)."""
    urdf = found.urdf
    home = found.home
    index = {name: k for k, name in enumerate(home.joints)} if home else {}
    # home's joints first, in home's order (the model's, not the file's), then the others as in the file
    movable = sorted((j for j in urdf.joints.values() if j.type != "fixed"), key=lambda j: index.get(j.name, len(index)))
    out = [f"{urdf.name} ({found.source}): {len(urdf.links)} links, {len(urdf.joints)} joints "
           f"({sum(j.movable for j in movable)} movable), total mass {urdf.total_mass:.4g} kg", ""]
    rows = []
    for j in movable:
        lower, upper, velocity, effort = found.limits.get(j.name, (j.lower, j.upper, j.velocity, j.effort))
        k = index.get(j.name)
        gap = "" if k is None else _number(min(home.lower_gap[k], home.upper_gap[k]))
        rows.append([j.name, j.type + (" (unbounded)" if j.type == "continuous" else ""), _number(lower),
                     _number(upper), _number(velocity), _number(effort), j.mimic or "",
                     found.roles.get(j.name, ""), "" if k is None else f"{home.q[k]:.4g}", gap])
    out += ["joints (" + ("those home gives first, in its order; " if home else "") +
            "rad or m; rad/s or m/s; N.m or N; '-': none)"]
    out += _table(["joint", "type", "lower", "upper", "velocity", "effort", "mimic", "role", "home", "to limit"], rows)
    out += ["", "leaf links that joints move (the possible tools), most joints first"]
    ranked = sorted(found.leaves.items(), key=lambda item: -len(item[1]))
    out += _table(["leaf", "joints", "chain"], [[leaf, str(len(js)), f"{js[0]} .. {js[-1]}" if len(js) > 1 else js[0]]
                                              for leaf, js in ranked[:15]])
    if len(ranked) > 15:
        out += _wrapped(f"  and {len(ranked) - 15} more", [leaf for leaf, _ in ranked[15:]])
    clash = set(urdf.clashes)
    mark = lambda name: name + ("*" if name in clash else "")
    out += ["", "frames (* a link and a joint share the name: as a task frame it means the link)"]
    out += _wrapped("links", [mark(link) for link in urdf.links])
    out += _wrapped("fixed joints", [mark(j.name) for j in urdf.joints.values() if j.type == "fixed"])
    out += _wrapped("joints", [mark(j.name) for j in movable])
    out += [""]
    if home is None:
        out += [f"at home: no tool: {found.why_no_home}"]
    else:
        k = int(np.argmin(np.minimum(home.lower_gap, home.upper_gap)))
        side = "lower" if home.lower_gap[k] <= home.upper_gap[k] else "upper"
        out += [f"at home ({home.source}), tool {home.tool}, {'pose' if home.pose else 'position'} task:",
                f"  home: [{', '.join(f'{v:.6g}' for v in home.q)}]",
                f"  position (m): {' '.join(f'{v:.6f}' for v in home.position)}",
                f"  quaternion (x y z w): {' '.join(f'{v:.6f}' for v in home.quaternion)}",
                f"  smallest singular value of the task Jacobian: {home.sigma_min:.4g}",
                f"  closest to a limit: {home.joints[k]}, {min(home.lower_gap[k], home.upper_gap[k]):.4g} from its "
                f"{side} limit"]
    return "\n".join(out)

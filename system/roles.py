"""What the signals of an experiment mean: its ``[roles]`` and its robot.

Analysis, plots, the convergence study and the report read signals by role (``q``: measured
joint positions, ``q_ref``: joint reference, ``tau``: efforts, ``x_ref``: task reference,
``grip``: gripper), never by instance name; units come from the recorded FMUs.
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import pinocchio as pin

from robofmu.components.orientation import rotation_of
from robofmu.components.robots import RobotModel, load_model

from robofmu.system import experiment
from robofmu.system.diagram import System, expand
from robofmu.system.result import Result
from robofmu.system.usage import UsageError


@dataclass(frozen=True)
class Roles:
    """Signal bases by role (``None`` where the experiment has none) and the robot's name.

    Attributes
    ----------
    robot : str
    q, qd, q_ref, tau : str or None
        Vector bases, e.g. ``"plant.q"``.
    x_ref, x, grip : str or None
        ``x``: measured task coordinates (a plant's pose output).
    quat_ref : str or None
        A pose task's orientation reference, a unit quaternion (x, y, z, w).
    """

    robot: str
    q: str | None = None
    qd: str | None = None
    q_ref: str | None = None
    tau: str | None = None
    x_ref: str | None = None
    x: str | None = None
    quat_ref: str | None = None
    grip: str | None = None

    @classmethod
    def of(cls, system: System) -> "Roles":
        """The roles an experiment declares; ValueError if it names no robot."""
        robot = system.extra.get("robot")
        if not robot:
            raise ValueError(f"{system.name}: the experiment names no `robot`")
        return cls(robot=str(robot), **dict(system.extra.get("roles", {})))

    def signals(self) -> list[str]:
        """The vector bases of every role the experiment declares (what analysis reads)."""
        return [getattr(self, f.name) for f in fields(self) if f.name != "robot" and getattr(self, f.name) is not None]

    def require(self, *names: str) -> None:
        missing = [n for n in names if getattr(self, n) is None]
        if missing:
            raise ValueError(f"the experiment declares no role {', '.join(missing)} in [roles]")

    def model(self) -> RobotModel:
        """A new model of the experiment's robot."""
        return load_model(self.robot)

    def vector(self, result: Result, role: str) -> np.ndarray:
        """The recorded vector of a role, shape (k, n)."""
        self.require(role)
        return result.vector(getattr(self, role))

    def tcp_error(self, result: Result, model: RobotModel | None = None,
                  poses: np.ndarray | None = None) -> np.ndarray | None:
        """The task point's distance |FK(q) - x_ref| (m) at every recorded point, over the task
        coordinates measured in m (:func:`task_axes`; a pose's angle is apart, see
        :meth:`task_errors`), or None without an x_ref role. ``poses``: as in :meth:`task_errors`."""
        errors = self.task_errors(result, model, poses)
        return None if errors is None else errors[0]

    def poses(self, result: Result, model: RobotModel | None = None) -> np.ndarray:
        """FK(q) at every recorded point, shape (k, m) (task units)."""
        model = model or self.model()
        return np.array([model.fk(v) for v in self.vector(result, "q")])

    def measures_orientation(self, model: RobotModel) -> bool:
        """Whether :meth:`task_errors` gives an orientation error on this robot: a task reference
        and either task coordinates in rad or a pose task with a ``quat_ref`` role."""
        return self.x_ref is not None and bool(task_axes(model)[1] or (model.orientation_axes and self.quat_ref))

    def task_errors(self, result: Result, model: RobotModel | None = None, poses: np.ndarray | None = None):
        """(position, orientation) errors at every recorded point, FK(q) against x_ref: the
        task point's distance (m, :meth:`tcp_error`) and the orientation error (rad): for a pose
        task with a ``quat_ref`` role the rotation angle from the reference to the frame's
        orientation over the tracked axes, |S_o log3(R_ref^T R(q))|, else max_i |FK(q)_i - x_ref_i|
        over the coordinates measured in rad (None where the task has none); None without an
        x_ref role. ``poses``: FK(q) of the result where the caller has it (:meth:`poses`), else
        computed."""
        if self.x_ref is None or self.q is None:
            return None
        model = model or self.model()
        if poses is None:
            poses = self.poses(result, model)
        difference = poses - result.vector(self.x_ref)
        position, angle = task_axes(model)
        orientation = np.abs(difference[:, angle]).max(axis=1) if angle else None
        if model.orientation_axes and self.quat_ref is not None:
            orientation = orientation_errors(model, self.vector(result, "q"), result.vector(self.quat_ref))
        return np.linalg.norm(difference[:, position], axis=1), orientation

    def events(self, result: Result) -> dict[str, float]:
        """Instants where the gripper closes and opens (s), from the recorded ``grip`` role."""
        if self.grip is None or self.grip not in result.columns:
            return {}
        closed = result[self.grip] > 0.5
        change = np.flatnonzero(np.diff(closed.astype(int)))
        events = {}
        for k in change:
            events["grip closes" if closed[k + 1] else "grip opens"] = float(result.time[k + 1])
        return events


def orientation_errors(model: RobotModel, q: np.ndarray, quaternions: np.ndarray) -> np.ndarray:
    """|S_o log3(R_ref^T R(q))| (rad) at every row of ``q`` (k, n) against the reference
    quaternions (k, 4) (x, y, z, w), over the model's tracked orientation axes."""
    rows = list(model.orientation_axes)
    return np.array([np.linalg.norm(pin.log3(rotation_of(reference).T @ model.rotation(joints))[rows])
                     for joints, reference in zip(q, quaternions)])


def task_axes(model: RobotModel) -> tuple[list[int], list[int]]:
    """Indices of the model's task coordinates measured in m (the task point) and in rad (an
    orientation), from its task units."""
    units = model.task_units(0)
    return ([i for i, u in enumerate(units) if u == "m"], [i for i, u in enumerate(units) if u == "rad"])


#: The roles the analysis of a run reads (``tau`` too where the diagram has efforts: an
#: unactuated run, whose plant's efforts are unwired at their start values, declares none).
NEEDED_ROLES = ("q", "q_ref")


def check_roles(system: System, master, needed: tuple[str, ...] = NEEDED_ROLES) -> Roles:
    """The roles of ``system``, checked against the outputs of ``master``'s planned blocks.

    Raises
    ------
    UsageError
        Naming the file and key: no robot, a role in ``needed`` missing, a role naming no block
        or no output of its block.
    """
    source = system.source or system.name
    if not system.extra.get("robot"):
        raise UsageError(f"{source}: robot: missing key: `robofmu run` needs the experiment's robot "
                         "(its analysis uses the robot's model)")
    roles = Roles.of(system)
    missing = [r for r in needed if getattr(roles, r) is None]
    if missing:
        raise UsageError(f"{source}: roles: `robofmu run` needs the roles {', '.join(needed)}; "
                         f"missing: {', '.join(missing)}")
    for role in experiment.ROLES:
        signal = getattr(roles, role)
        if signal is None:
            continue
        block, _, base = signal.partition(".")
        node = master.nodes.get(block)
        if node is None:
            raise UsageError(f"{source}: roles.{role}: {signal!r} names no block "
                             f"(blocks: {', '.join(master.nodes)})")
        outputs = [name for name, v in node.variables.items() if v.causality == "output"]
        if not expand(outputs, base):
            bases = sorted({name.split("[")[0] for name in outputs})
            raise UsageError(f"{source}: roles.{role}: {signal!r} names no output of {block} "
                             f"(outputs: {', '.join(bases)})")
    return roles

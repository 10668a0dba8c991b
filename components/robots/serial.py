"""A serial robot from its URDF, with kinematics and dynamics from Pinocchio.

Joint coordinates q are the URDF's revolute (rad) and prismatic (m) joints, in URDF order, but
those the description locks (``[joints] locked``: Pinocchio's reduced model, the locked joints
fixed at their values). Task coordinates are the chosen world axes of the task frame's position
(m); a pose task adds rotations about the frame's own axes (see :class:`SerialRobot`).
"""
from __future__ import annotations

import contextlib
import math
import os
import sys
import tempfile
from functools import lru_cache

import numpy as np
import pinocchio as pin

from ..orientation import canonical
from .description import DescriptionError, RobotDescription
from .model import RobotModel, TaskIndex, derivative_unit
from .urdf import MOVABLE, Urdf, UrdfError, read_urdf


#: What a joint that robofmu does not take is, by a word of Pinocchio's joint model name.
_JOINT_KINDS = {"Spherical": "spherical", "FreeFlyer": "floating", "Planar": "planar",
                "Translation": "a translation", "Composite": "composite"}


@lru_cache(maxsize=32)
def _read(path: str, version: tuple[int, int], xacro_args: tuple[tuple[str, str], ...]) -> Urdf:
    del version
    return read_urdf(path, dict(xacro_args) or None)


def robot_urdf(description: RobotDescription) -> Urdf:
    """The description's URDF, read and checked (:func:`~.urdf.read_urdf`; a ``.xacro`` file
    expanded with its ``xacro_args``); cached per file and its modification time."""
    stat = description.urdf.stat()
    return _read(str(description.urdf), (stat.st_mtime_ns, stat.st_size), tuple(sorted(description.xacro_args.items())))


@contextlib.contextmanager
def _stderr_to(sink):
    """File descriptor 2 sent to ``sink`` (a file) meanwhile: urdfdom prints its errors there."""
    sys.stderr.flush()
    saved = os.dup(2)
    os.dup2(sink.fileno(), 2)
    try:
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def _parse(urdf: Urdf, text: str, mimic: bool) -> pin.Model:
    """Pinocchio's model of ``text`` (from ``urdf``), urdfdom's lines on stderr kept to the message."""
    with tempfile.TemporaryFile(mode="w+") as sink:
        try:
            with _stderr_to(sink):
                return pin.buildModelFromXML(text, mimic)
        except (ValueError, RuntimeError) as exc:
            sink.seek(0)
            said = " ".join(line.strip() for line in sink if line.strip() and not line.strip().startswith("at line"))
            raise UrdfError(urdf.path, "urdfdom", f"Pinocchio's URDF parser refuses it: {said or exc}",
                            "fix the URDF") from None


def lock_values(description: RobotDescription, urdf: Urdf) -> dict[str, float | None]:
    """The joints the description removes from the model, each with its value (rad, m; None: a
    floating or planar joint, held at Pinocchio's neutral placement).

    ``[joints] locked`` first; then, with ``[joints] chain = [base, tip]``, every joint off the
    chain from link ``base`` to link ``tip`` (above ``base`` too): at its ``locked`` value, else
    at the value of the SRDF state ``home`` uses, else at 0 clipped into its limits; a mimic
    follower with its leader (q = multiplier q_leader + offset), else it stays a mimic joint."""
    locked: dict[str, float | None] = dict(description.locked)
    movable = [name for name, joint in urdf.joints.items() if joint.type in MOVABLE]
    for joint in locked:
        if joint not in urdf.joints or urdf.joints[joint].type == "fixed":
            problem = (f"joint {joint!r} is fixed in {urdf.path.name} (nothing to lock): remove it" if joint in urdf.joints
                       else f"no joint {joint!r} in {urdf.path.name}")
            raise ValueError(f"{description.path}: joints.locked.{joint}: {problem} (its movable joints: "
                             f"{', '.join(movable)})")
    if description.chain is None:
        return locked
    base, tip = description.chain
    try:
        on = {joint.name for joint in urdf.chain(base, tip)}
    except UrdfError as exc:
        raise DescriptionError(description.path, "joints.chain", str(exc).removeprefix(f"{exc.path}: ")) from None
    for name in on:
        joint = urdf.joints[name]
        if joint.type in ("floating", "planar"):
            raise DescriptionError(description.path, "joints.chain", f"joint {name!r} on the chain from {base!r} to "
                                                                    f"{tip!r} is {joint.type}: start the chain below it")
    state = description.home_state
    for joint in urdf.joints.values():
        if joint.name in on or joint.name in locked or joint.mimic is not None:
            continue
        if joint.type in ("floating", "planar"):
            locked[joint.name] = None
        elif joint.type in MOVABLE:
            locked[joint.name] = joint.clip(state.get(joint.name, 0.0))
    for joint in urdf.joints.values():
        if joint.mimic is not None and joint.name not in on and joint.mimic in locked and joint.name not in locked:
            leader = locked[joint.mimic]
            locked[joint.name] = joint.clip(joint.multiplier * leader + joint.offset)
    return locked


def _urdf_model(description: RobotDescription, urdf: Urdf, locked: dict[str, float | None]) -> pin.Model:
    """Pinocchio's model of the description's checked URDF (:attr:`Urdf.text`: a ``continuous``
    joint an unbounded revolute one, one angle).

    A joint that mimics another (``<mimic>``) moves with it (Pinocchio's mimic joint: no
    coordinate of its own) unless it is locked; a mimic joint whose leader is locked must be
    locked too."""
    followers = {joint.name: joint.mimic for joint in urdf.joints.values() if joint.mimic is not None}
    for follower, leader in followers.items():
        if leader in locked and follower not in locked:
            raise ValueError(f"{description.path}: joints.locked: joint {follower!r} mimics the locked joint "
                             f"{leader!r}: lock it too")
    free = [follower for follower in followers if follower not in locked]
    if free and len(free) < len(followers):          # locked followers become plain joints, then locked
        return _parse(urdf, urdf.xml(drop_mimic=[f for f in followers if f in locked]), True)
    return _parse(urdf, urdf.text, bool(free))


def _locked(model: pin.Model, description: RobotDescription, urdf: Urdf, locked: dict[str, float | None]) -> pin.Model:
    """The model without the locked joints, each fixed at its value (Pinocchio's reduced model);
    the model itself if it locks none."""
    if not locked:
        return model
    reference = pin.neutral(model)
    ids = []
    for joint, value in locked.items():
        key = f"joints.locked.{joint}" if joint in description.locked else "joints.chain"
        j = model.getJointId(joint)
        if value is not None:
            if model.joints[j].nq != 1:
                raise ValueError(f"{description.path}: {key}: only a revolute or prismatic joint can be locked")
            low, high = urdf.joints[joint].lower, urdf.joints[joint].upper
            if not low <= value <= high:
                raise ValueError(f"{description.path}: {key}: {value:g} lies outside the joint's limits "
                                 f"[{low:g}, {high:g}]")
            reference[model.joints[j].idx_q] = value
        ids.append(j)
    return pin.buildReducedModel(model, ids, reference)


def _absent(joint: str, urdf: Urdf, description: RobotDescription) -> str:
    """Why the model has no joint ``joint``, and the fix: not in the URDF, fixed, or removed by
    ``[joints] locked`` or ``chain``."""
    if joint not in urdf.joints:
        return f"no joint {joint!r} in {urdf.path.name}"
    if urdf.joints[joint].type == "fixed":
        return f"joint {joint!r} is fixed in {urdf.path.name}: remove the table"
    if joint in description.locked:
        return f"joint {joint!r} is locked (joints.locked): remove the table or unlock it"
    return (f"joint {joint!r} is off joints.chain {list(description.chain or ())}, so locked: remove the table "
            "or give a chain through it")


def _set_limits(model: pin.Model, description: RobotDescription, urdf: Urdf) -> None:
    """The joint limits as data: the checked URDF's (:class:`~.urdf.UrdfJoint`: none where it
    gives none), the description's ``[joints.limits.<joint>]`` over them."""
    fields = {"lower": "lowerPositionLimit", "upper": "upperPositionLimit", "velocity": "velocityLimit",
              "effort": "effortLimit"}
    arrays = {key: getattr(model, name).copy() for key, name in fields.items()}
    def index(j: int, key: str) -> int:         # positions by q, rates and efforts by v (a floating joint: nq != nv)
        return model.joints[j].idx_q if key in ("lower", "upper") else model.joints[j].idx_v

    for j in range(1, model.njoints):
        if model.joints[j].nv == 1 and model.names[j] in urdf.joints:
            for key in fields:
                arrays[key][index(j, key)] = getattr(urdf.joints[model.names[j]], key)
    for joint, limits in description.joint_limits.items():
        if not model.existJointName(joint):
            raise ValueError(f"{description.path}: joints.limits.{joint}: {_absent(joint, urdf, description)} "
                             f"(the model's joints: {', '.join(model.names[1:])})")
        j = model.getJointId(joint)
        for key, value in limits.items():
            arrays[key][index(j, key)] = value
        k = model.joints[j].idx_q
        if not arrays["lower"][k] < arrays["upper"][k]:
            raise ValueError(f"{description.path}: joints.limits.{joint}: lower {arrays['lower'][k]:g} must be "
                             f"below upper {arrays['upper'][k]:g}")
    for key, name in fields.items():
        setattr(model, name, arrays[key])


def _set_dynamics(model: pin.Model, description: RobotDescription, urdf: Urdf) -> None:
    """The joints' losses and rotor inertias as data, in Pinocchio's ``damping``, ``friction`` and
    ``armature`` (one per velocity coordinate): the checked URDF's ``<dynamics>`` (damping,
    friction; no armature) where the description asks for them (``[joints] urdf_dynamics``), the
    description's ``[joints.dynamics.<joint>]`` over them. Pinocchio's
    CRBA, RNEA, ABA and kinetic energy add ``armature`` to M's diagonal; ``damping`` and
    ``friction`` are data only (the plant and the controller apply them)."""
    fields = {"damping": "damping", "friction": "friction", "armature": "armature"}
    arrays = {key: np.zeros(model.nv) for key in fields}
    for j in range(1, model.njoints if description.urdf_dynamics else 1):
        if model.joints[j].nv == 1 and model.names[j] in urdf.joints:
            for key in ("damping", "friction"):
                arrays[key][model.joints[j].idx_v] = getattr(urdf.joints[model.names[j]], key)
    for joint, values in description.joint_dynamics.items():
        j = model.getJointId(joint) if model.existJointName(joint) else 0
        if j == 0 or model.joints[j].nv != 1:
            absent = _absent(joint, urdf, description) if j == 0 else f"joint {joint!r} has no coordinate of its own"
            raise ValueError(f"{description.path}: joints.dynamics.{joint}: {absent} "
                             f"(the model's joints: {', '.join(n for n in model.names[1:])})")
        for key, value in values.items():
            arrays[key][model.joints[j].idx_v] = value
    for key, name in fields.items():
        setattr(model, name, arrays[key])


def reduced_model(description: RobotDescription) -> tuple[pin.Model, Urdf]:
    """The model of the robot's free joints (locked ones and those off ``[joints] chain`` removed),
    its limits set, and the checked URDF it comes from. ValueError naming the file and key."""
    urdf = robot_urdf(description)
    locked = lock_values(description, urdf)
    model = _locked(_urdf_model(description, urdf, locked), description, urdf, locked)
    if model.nv == 0:
        keys = " and ".join(k for k, v in (("joints.locked", description.locked), ("joints.chain", description.chain))
                            if v)
        raise ValueError(f"{description.path}: {keys}: no joint is left to move (every movable joint of "
                         f"{urdf.path.name} is locked); unlock one")
    _set_limits(model, description, urdf)
    _set_dynamics(model, description, urdf)
    return model, urdf


class SerialRobot(RobotModel):
    """Kinematics and rigid-body dynamics of a serial robot, on its own Pinocchio model and data.

    Each instance owns its model, so a payload set on one (``set_payload``) leaves the others
    alone: the plant and the controller each hold their own.

    A pose task (``[task] orientation_axes``) has :attr:`task_rows` = m + len(orientation_axes)
    rows of velocity: first the task position's (world axes, m/s), then the angular velocity
    about the task frame's own axes ``orientation_axes`` (rad/s); :meth:`jacobian` and
    :meth:`jdot_qdot` have these rows. :meth:`fk` is the position only; :meth:`rotation` the
    frame's orientation (3, 3), frame to world.

    Parameters
    ----------
    description : RobotDescription
    gravity : float, optional
        Magnitude of gravity (m/s^2) along the description's direction. Default: the
        description's.
    """

    def __init__(self, description: RobotDescription, gravity: float | None = None):
        self.description = description
        self.model, self.urdf = reduced_model(description)
        self.data = self.model.createData()
        self._check_joints_and_links()
        self.n = self.model.nv
        if len(description.configuration("home")) != self.n:
            raise ValueError(f"{description.path}: configurations.home: {self._home_length()}")
        self.task_id = self._frame(description.task.frame, "task.frame")
        self.task_index = TaskIndex(description.task.axes, description.task.orientation_axes)
        self.m = len(self.task_index.position)
        self.orientation_axes = self.task_index.orientation
        self._direction = np.array(description.gravity_direction)
        self.set_gravity(description.gravity if gravity is None else gravity)
        self.payload = 0.0
        if description.payload is not None:
            frame = self.model.frames[self._frame(description.payload.frame, "payload.frame")]
            self._payload_joint = frame.parentJoint
            self._payload_lever = frame.placement.translation.copy()
            self._bare_inertia = self.model.inertias[self._payload_joint].copy()
        self._zero = np.zeros(self.n)
        joints = [j for j in range(1, self.model.njoints) if self.model.joints[j].nv]   # not a mimic
        self.joint_names = [self.model.names[j] for j in joints]
        self.prismatic = [self.model.joints[j].shortname().startswith("JointModelP") for j in joints]
        self._mimic = len(joints) < self.model.njoints - 1   # Pinocchio's ABA and energies take none

    def _home_length(self) -> str:
        """What a home of the wrong length lacks: the model's joints in home's order, the joints
        the description removes, and the fix."""
        names = [self.model.names[j] for j in range(1, self.model.njoints) if self.model.joints[j].nv]
        removed = lock_values(self.description, self.urdf)
        got = len(self.description.configuration("home"))
        off = ""
        if removed:
            shown = ", ".join(list(removed)[:4]) + (f" and {len(removed) - 4} more" if len(removed) > 4 else "")
            keys = [k for k, v in (("joints.locked", self.description.locked), ("joints.chain", self.description.chain))
                    if v]
            off = f"; {shown} locked ({' and '.join(keys)})"
        fix = "give one value per joint" + (", or lock a joint (joints.locked, joints.chain)" if got < self.n else "")
        return (f"needs {self.n} joint values, one per joint the model moves, in this order: {', '.join(names)}"
                f"{off}; got {got}: {fix}")

    def _check_joints_and_links(self) -> None:
        """Refuse, naming the joint or link, what the run would otherwise discover at t = 0: a joint
        that is not revolute or prismatic (a continuous joint is q = (cos, sin) in Pinocchio), and a
        moving link without a valid inertia (no mass, or a rotational inertia that no body has:
        not symmetric positive semi-definite, or breaking the triangle inequality), which makes
        M(q) singular."""
        model, urdf = self.model, self.urdf.path
        names = {frame: link for link, frame in self.urdf.frames.items()}
        for j in range(1, model.njoints):
            joint, kind = model.names[j], model.joints[j].shortname()
            mimic = kind == "JointModelMimic"
            if not mimic and (not kind.startswith(("JointModelR", "JointModelP")) or model.joints[j].nq != 1):
                what = next((text for word, text in _JOINT_KINDS.items() if word in kind), kind)
                raise ValueError(f"{urdf}: joint {joint!r}: is {what}; robofmu moves revolute, prismatic and "
                                 "continuous joints: give a [joints] chain that leaves it out")
            link = next(f.name for f in model.frames if f.type == pin.FrameType.BODY and f.parentJoint == j)
            link = names.get(link, link)
            inertia = model.inertias[j]
            rotational = np.asarray(inertia.inertia)
            eigenvalues = np.linalg.eigvalsh(rotational) if np.all(np.isfinite(rotational)) else np.full(3, np.nan)
            tolerance = 1e-12 * max(1.0, float(np.max(np.abs(rotational))))
            if not (math.isfinite(inertia.mass) and inertia.mass > 0.0):
                raise ValueError(f"{urdf}: link {link!r} (moved by joint {joint!r}) has no mass "
                                 f"({inertia.mass:g} kg): give it an <inertial> with mass > 0")
            if not (np.allclose(rotational, rotational.T, atol=tolerance) and eigenvalues.min() >= -tolerance
                    and 2.0 * eigenvalues.max() <= eigenvalues.sum() + tolerance):
                raise ValueError(f"{urdf}: link {link!r} (moved by joint {joint!r}) has an inertia no body has "
                                 f"(principal moments {', '.join(f'{v:g}' for v in eigenvalues)} kg m^2: each "
                                 "must be >= 0 and at most the sum of the other two)")

    def _frame(self, frame: str, key: str) -> int:
        """The frame a user's name means: a link's (renamed in the model on a clash with a joint's
        name, :attr:`Urdf.frames`), else a joint's; refused unless some joint moves it."""
        if frame in self.urdf.frames:
            fid = self.model.getFrameId(self.urdf.frames[frame], pin.FrameType.BODY)
        else:
            fid = self.model.getFrameId(frame)
        if fid >= len(self.model.frames):
            raise ValueError(f"{self.description.path}: {key}: no frame {frame!r} in {self.urdf.path.name} "
                             "(a link or joint of the URDF)")
        if self.model.frames[fid].parentJoint == 0:
            raise ValueError(f"{self.description.path}: {key}: no joint moves {frame!r} (it is fixed to the "
                             "world, or every joint above it is locked); choose a frame below a moving joint")
        return fid

    def task_units(self, order: int = 0) -> list[str]:
        return [derivative_unit("m", order)] * self.m

    def position_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """The URDF's joint limits (Pinocchio's lower/upperPositionLimit)."""
        return self.model.lowerPositionLimit.copy(), self.model.upperPositionLimit.copy()

    def velocity_limits(self) -> np.ndarray:
        """The URDF's joint velocity limits (Pinocchio's velocityLimit)."""
        return self.model.velocityLimit.copy()

    def effort_limits(self) -> np.ndarray:
        """The URDF's joint effort limits (Pinocchio's effortLimit)."""
        return self.model.effortLimit.copy()

    def joint_losses(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The robot data's viscous damping (N.m.s/rad, N.s/m), Coulomb friction (N.m, N) and
        armature (kg m^2, kg) per joint, each shape (n,) (new arrays): the URDF's ``<dynamics>``,
        the description's ``[joints.dynamics]`` over them; armature as last set."""
        return self.model.damping.copy(), self.model.friction.copy(), self.model.armature.copy()

    # -- parameters -------------------------------------------------------------------------
    def set_armature(self, armature) -> None:
        """Rotor inertia reflected at each joint (kg m^2 or kg), shape (n,): added to M(q)'s
        diagonal by Pinocchio's CRBA, RNEA, ABA and kinetic energy."""
        self.model.armature = np.array(armature, dtype=float)

    def set_gravity(self, magnitude: float) -> None:
        self.gravity = float(magnitude)
        self.model.gravity.linear = self.gravity * self._direction

    def set_payload(self, mass: float) -> None:
        mass = float(mass)
        if mass == self.payload:
            return
        if self.description.payload is None:
            raise ValueError(f"robot {self.description.name!r} describes no payload frame")
        inertia = self._bare_inertia.copy()
        if mass > 0.0:
            inertia += pin.Inertia(mass, self._payload_lever, np.zeros((3, 3)))
        self.model.inertias[self._payload_joint] = inertia
        self.payload = mass

    # -- kinematics -------------------------------------------------------------------------
    def fk(self, q: np.ndarray) -> np.ndarray:
        pin.forwardKinematics(self.model, self.data, q)
        return pin.updateFramePlacement(self.model, self.data, self.task_id).translation[self.task_index.linear]

    def rotation(self, q: np.ndarray) -> np.ndarray:
        pin.forwardKinematics(self.model, self.data, q)
        return pin.updateFramePlacement(self.model, self.data, self.task_id).rotation.copy()

    def fk_quaternion(self, q: np.ndarray) -> tuple[list[float], list[float]]:
        pin.forwardKinematics(self.model, self.data, q)
        pose = pin.SE3ToXYZQUAT(pin.updateFramePlacement(self.model, self.data, self.task_id)).tolist()
        return [pose[axis] for axis in self.task_index.position], canonical(pose[3:])    # (x, y, z, qx, qy, qz, qw)

    def pose(self, q: np.ndarray) -> pin.SE3:
        """The task frame's placement (frame to world) at ``q``: a new ``pinocchio.SE3``."""
        pin.forwardKinematics(self.model, self.data, q)
        return pin.updateFramePlacement(self.model, self.data, self.task_id).copy()

    def kinematics(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The task frame's position (3,) and orientation (3, 3) (world), and its full Jacobian
        (6, n): rows world linear velocity, then angular velocity about the frame's own axes.
        New arrays, from one pass of Pinocchio's kinematics."""
        J = pin.computeFrameJacobian(self.model, self.data, q, self.task_id, pin.LOCAL_WORLD_ALIGNED)
        placement = self.data.oMf[self.task_id]
        rotation = placement.rotation.copy()
        J[3:] = rotation.T.dot(J[3:])
        return placement.translation.copy(), rotation, J

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        if not self.orientation_axes:
            return pin.computeFrameJacobian(self.model, self.data, q, self.task_id,
                                            pin.LOCAL_WORLD_ALIGNED)[self.task_index.linear]
        full = self.kinematics(q)[2]                          # angular rows about the frame's own axes
        return full[self.task_index.six]

    def _pose_rows(self, world: np.ndarray, local: np.ndarray) -> np.ndarray:
        """A pose task's rows: the task axes of ``world``'s linear part (world-aligned), then the
        tracked axes of ``local``'s angular part (about the frame's own axes); both stacked as
        Pinocchio's 6-row [linear; angular]. ``world`` itself where every row is tracked."""
        index = self.task_index
        if index.is_full_pose:
            world[3:] = local[3:]
            return world
        return np.concatenate([world[index.linear], local[3:][index.angular]])

    def jdot_qdot(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        model, data, frame = self.model, self.data, self.task_id
        pin.forwardKinematics(model, data, q, qd, self._zero)
        acceleration = pin.getFrameClassicalAcceleration(model, data, frame, pin.LOCAL_WORLD_ALIGNED)
        if not self.orientation_axes:
            return acceleration.linear[self.task_index.linear]
        # d/dt (R^T omega) = R^T omega_dot (the term dR^T/dt omega = -R^T (omega x omega) vanishes):
        # the angular part of the classical acceleration in the frame's own axes (LOCAL)
        local = pin.getFrameClassicalAcceleration(model, data, frame, pin.LOCAL)
        return self._pose_rows(acceleration.vector, local.vector)

    def jacobian_derivative(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """dJ/dt (task_rows, n) of :meth:`jacobian` along the motion (q, qd): Pinocchio's frame
        Jacobian time variation, world-aligned for the position rows and in the frame's own axes
        (LOCAL, the derivative of R^T J_w: R^T (dJ_w/dt - [omega]x J_w)) for the angular rows.
        A new array."""
        model, data, frame = self.model, self.data, self.task_id
        pin.computeJointJacobiansTimeVariation(model, data, q, qd)
        derivative = pin.getFrameJacobianTimeVariation(model, data, frame, pin.LOCAL_WORLD_ALIGNED)
        if not self.orientation_axes:
            return derivative[self.task_index.linear]
        return self._pose_rows(derivative, pin.getFrameJacobianTimeVariation(model, data, frame, pin.LOCAL))

    # -- dynamics ---------------------------------------------------------------------------
    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        upper = pin.crba(self.model, self.data, q)
        return np.triu(upper) + np.triu(upper, 1).T

    def nonlinear_effects(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        return pin.nonLinearEffects(self.model, self.data, q, qd).copy()

    def coriolis_matrix(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        return pin.computeCoriolisMatrix(self.model, self.data, q, qd).copy()

    def gravity_torque(self, q: np.ndarray) -> np.ndarray:
        return pin.computeGeneralizedGravity(self.model, self.data, q).copy()

    def gravity_jacobian(self, q: np.ndarray) -> np.ndarray:
        if self._mimic:                          # Pinocchio's derivatives take no mimic joint
            return super().gravity_jacobian(q)
        return pin.computeGeneralizedGravityDerivatives(self.model, self.data, q).copy()

    def forward_dynamics(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> np.ndarray:
        if self._mimic:                          # M qdd = tau - N, M from CRBA (ABA takes no mimic joint)
            return np.linalg.solve(self.mass_matrix(q), tau - self.nonlinear_effects(q, qd))
        return pin.aba(self.model, self.data, q, qd, tau).copy()

    def inverse_dynamics(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        return pin.rnea(self.model, self.data, q, qd, qdd).copy()

    def forward_dynamics_floats(self, q, qd, tau) -> list[float]:
        if self._mimic:
            return self.forward_dynamics(q, qd, tau).tolist()
        return pin.aba(self.model, self.data, q, qd, tau).tolist()

    def inverse_dynamics_into(self, q, qd, qdd, out) -> None:
        out[:] = pin.rnea(self.model, self.data, q, qd, qdd)

    def kinetic_energy(self, q: np.ndarray, qd: np.ndarray) -> float:
        # Pinocchio 4.1's computeKineticEnergy leaves out the armature of a RevoluteUnaligned
        # joint (its CRBA, RNEA and ABA take it: tests/test_joint_losses.py): with armature, from M
        if self._mimic or self.model.armature.any():
            return 0.5 * float(qd @ self.mass_matrix(q) @ qd)
        return float(pin.computeKineticEnergy(self.model, self.data, q, qd))

    def potential_energy(self, q: np.ndarray) -> float:
        """Gravitational potential energy (J), zero at the world origin's height."""
        if self._mimic:                          # -sum of m_i g . c_i over the bodies
            pin.forwardKinematics(self.model, self.data, q)
            return -sum(inertia.mass * float(self.model.gravity.linear @ (placement.act(inertia.lever)))
                        for inertia, placement in zip(self.model.inertias[1:], self.data.oMi[1:]))
        return float(pin.computePotentialEnergy(self.model, self.data, q))

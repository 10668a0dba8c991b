"""The co-simulated step experiment of any robot: its diagram and its run (the comparison with the
linear predictions is :mod:`.comparison`, the figure :mod:`.figures`).

The experiment is a two-block diagram built here, whatever the robot: the robot's
``controller`` FMU (computed torque) and its ``plant`` FMU (the manipulator dynamics), with
``plant.q -> controller.q``, ``plant.qd -> controller.qd`` and ``controller.tau -> plant.tau``.
The controller's reference inputs stay unconnected: ``q_ref`` starts at ``q0 + A`` (A the
amplitude, held from t = 0), ``qd_ref`` and ``qdd_ref`` at 0, a gripper input (where the robot
has one) open. The plant starts at rest at ``q0``, by default the robot's ``home`` configuration. The master
(:class:`~robofmu.system.master.Master`, Gauss-Seidel by default) runs it; :func:`~.comparison.compare` sets
the recorded positions against :func:`~.linear.predict` for every model, joint by joint.

Units come from the robot model: a revolute joint's position is in rad and its effort in N.m,
a prismatic joint's in m and N. The size of the reference step, its amplitude, is in each joint's
own unit ("step" alone is the communication step, ``h``).

A robot is given as everywhere in robofmu: a robot of the package by name, the path of a robot
TOML anywhere (str or Path), or its :class:`~robofmu.components.robots.RobotDescription`; it is
resolved once per call (:func:`~robofmu.components.robots.load_description`). Its FMUs are
``<fmu_dir>/<its name>/{controller,plant}.fmu``, as ``robofmu build`` writes them.

The loop as it runs on a robot (any of ``sample_time``, ``delay_steps``, ``parameters`` given to
:func:`cosimulate_step`): the controller samples every ``sample_time`` Ts (a whole number of base
steps h; the plant still steps at h) and outputs its effort ``delay_steps`` = d samples late, and
block parameters may make the plant's joint losses differ from what the controller compensates
(``plant.friction[j]``, ``controller.loss_compensation`` = 0, ...). :func:`~.comparison.compare` then predicts
with :func:`~.sampled.predict_coupled` (the ``sampled`` model, at Ts with d, the controller's
start-up (the effort of its first sample until sample d), and the loop linearized at the step's
middle: gravity's stiffness and the viscous damping, which couple the joints through the held,
delayed effort),
gives the kp stability limit (:func:`~.sampled.largest_stable_kp`, kd held) and, for Coulomb
friction the controller does not know, the stop short predicted, measured and missed
(:class:`~.comparison.FrictionMiss`). A response whose error grows is reported as unstable by name, with
or without these options.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from robofmu.components.control import check_gains
from robofmu.components.robots import ROBOTS_DIR, RobotDescription, available, load_description, load_model

from robofmu.system import defaults
from robofmu.system.diagram import BlockSpec, System, expand, spread
from robofmu.system.master import Master, Result
from robofmu.system.stepresponse.linear import check_step

__all__ = ["CONTROLLER", "PLANT", "DEFAULT_AMPLITUDE", "StepSetup", "steppable_robots", "default_amplitudes",
           "step_setup", "step_system", "cosimulate_step"]

#: Instance names of the two blocks of the step diagram (they prefix the recorded columns).
CONTROLLER = "controller"
PLANT = "plant"

#: Default amplitude by joint unit: 0.02 rad (about 1.15 degrees) for a revolute joint, 0.02 m
#: for a prismatic one. No robot description or seed document gives another value. The
#: predictions are linear in the amplitude and hold the inertia and gravity of the start pose, so
#: a small step keeps the configuration-dependent terms small, while the response stays many
#: orders above the plant's integration error.
DEFAULT_AMPLITUDE = {"rad": 0.02, "m": 0.02}

#: A robot as the functions here take it: a package robot's name, a robot TOML's path, or its description.
Robot = str | Path | RobotDescription


def steppable_robots() -> list[str]:
    """The package's robots a step experiment can run on: those with a controller and a plant
    block, sorted by name. (A robot TOML of one's own steps too when it has both blocks.)"""
    return [name for name in available() if {CONTROLLER, PLANT} <= set(load_description(name).blocks)]


def _description(robot: Robot) -> RobotDescription:
    """``robot``'s description: itself, or :func:`load_description` of a name or TOML path (ValueError
    in one line: an unknown robot, a missing file, a malformed description naming file and key)."""
    return robot if isinstance(robot, RobotDescription) else load_description(robot)


def steppable(robot: Robot) -> RobotDescription:
    """:func:`_description`, refused (ValueError starting ``robot:``) without a controller or plant block."""
    description = _description(robot)
    missing = [block for block in (CONTROLLER, PLANT) if block not in description.blocks]
    if missing:
        raise ValueError(f"robot: {description.name!r} has no {' and no '.join(missing)} block "
                         f"(its blocks: {', '.join(description.blocks)})")
    return description


def _robot_argument(description: RobotDescription) -> str:
    """How to name a robot again, to ``robofmu build`` or :func:`load_description`: its name for a
    robot of the package, else the (absolute) path of its TOML."""
    packaged = ROBOTS_DIR / description.name / f"{description.name}.toml"
    if packaged.is_file() and Path(description.path).resolve() == packaged.resolve():
        return description.name
    return str(Path(description.path).resolve())


def default_amplitudes(robot: Robot) -> np.ndarray:
    """The default amplitude of every joint of ``robot`` (:data:`DEFAULT_AMPLITUDE`), signed
    so that the step from ``home`` stays within the joint's limits (downward where home + amplitude
    would pass the upper limit, as the rrp slide's home at its full extension).

    Parameters
    ----------
    robot : str, Path or RobotDescription
        A robot of the package by name (``robofmu.components.robots.available()``), the path of a
        robot TOML, or a description.

    Returns
    -------
    numpy.ndarray, shape (n,)
        In each joint's unit (rad or m).
    """
    model = load_model(_description(robot))
    return _signed_amplitudes(model, model.configuration("home"))


def _signed_amplitudes(model, start: np.ndarray) -> np.ndarray:
    """:data:`DEFAULT_AMPLITUDE` per joint, negative where ``start`` + amplitude passes the upper limit."""
    amplitudes = np.array([DEFAULT_AMPLITUDE[unit] for unit in model.joint_units(0)])
    _, upper = model.position_limits()
    return np.where(start + amplitudes > upper, -amplitudes, amplitudes)


@dataclass(frozen=True)
class StepSetup:
    """A step experiment resolved against a robot: who steps, from where, by how much.

    Attributes
    ----------
    robot : str
        The robot's name (its FMUs' folder under the FMU collection).
    joints : list of int
        Stepped joints, numbered from 1 like the FMU variables.
    q0 : numpy.ndarray, shape (n,)
        Start configuration (joint units), at rest.
    amplitudes : numpy.ndarray, shape (n,)
        Amplitude of every joint (joint units); those of unstepped joints are the scale their
        crosstalk is measured in.
    q_ref : numpy.ndarray, shape (n,)
        The held reference: ``q0`` plus ``amplitudes`` on the stepped joints.
    joint_units, effort_units, symbols : list of str, length n
        From the robot model: "rad" / "m", "N.m" / "N", "q1", "q2", ...
    """

    robot: str
    joints: list
    q0: np.ndarray
    amplitudes: np.ndarray
    q_ref: np.ndarray
    joint_units: list
    effort_units: list
    symbols: list


def step_setup(robot: Robot, amplitude: float | Sequence[float] | None = None,
               joint: int | Sequence[int] | None = None,
               q0: Sequence[float] | None = None) -> StepSetup:
    """Resolve the stepped joints, start configuration and amplitudes of a step of ``robot``.

    Parameters
    ----------
    robot : str, Path or RobotDescription
        A robot with a controller and a plant block: a robot of the package by name, the path of
        a robot TOML, or a description.
    amplitude : float, sequence of float or None
        Size of the reference step (joint units). None: :data:`DEFAULT_AMPLITUDE` per joint,
        downward where it would pass the joint's upper limit. A float: that amplitude on every
        stepped joint, in each joint's unit. A sequence: one amplitude per joint of the robot
        (shape (n,)) or one per stepped joint (shape (len(joints),)).
    joint : int, sequence of int or None
        Stepped joint(s), from 1; None: every joint.
    q0 : sequence of float, shape (n,), optional
        Start configuration (joint units); default the description's ``home``.

    Returns
    -------
    StepSetup

    Raises
    ------
    ValueError
        Unknown robot, a robot TOML that does not exist or is not a valid description, no
        controller or plant block, a joint out of range or repeated, a ``q0`` or ``amplitude`` of
        the wrong length, a non-finite value or a zero amplitude; the message starts with the
        argument's name (but for :func:`~robofmu.components.robots.load_description`'s own).
    """
    description = steppable(robot)
    robot = description.name
    model = load_model(description)
    n = model.n
    if joint is None:
        joints = list(range(1, n + 1))
    else:
        joints = [joint] if isinstance(joint, (int, np.integer)) else list(joint)
        for j in joints:
            if isinstance(j, bool) or not isinstance(j, (int, np.integer)) or not 1 <= j <= n:
                raise ValueError(f"joint: {j!r} is not a joint of {robot!r}; its joints are 1 .. {n}")
        if len(set(joints)) != len(joints) or not joints:
            raise ValueError(f"joint: each joint at most once, at least one, got {joints}")
        joints = [int(j) for j in joints]
    start = model.configuration("home") if q0 is None else np.asarray(q0, dtype=float).reshape(-1)
    if start.size != n:
        raise ValueError(f"q0: {robot!r} has {n} joints, got {start.size} values")
    if not np.all(np.isfinite(start)):
        raise ValueError(f"q0: must be finite, got {start.tolist()}")
    amplitudes = _signed_amplitudes(model, start)
    if amplitude is not None:
        values = np.atleast_1d(np.asarray(amplitude, dtype=float)).reshape(-1)
        if values.size == 1:
            amplitudes[:] = values[0]
        elif values.size == n:
            amplitudes = values.copy()
        elif values.size == len(joints):
            amplitudes[np.array(joints) - 1] = values
        else:
            counts = f"{n} (one per joint)" + (f" or {len(joints)} (one per stepped joint)"
                                                 if len(joints) != n else "")
            raise ValueError(f"amplitude: give one amplitude or {counts}, got {values.size}")
    stepped = np.array(joints) - 1
    if not np.all(np.isfinite(amplitudes)) or np.any(amplitudes[stepped] == 0.0):
        raise ValueError(f"amplitude: must be finite and not 0, got {amplitudes[stepped].tolist()}")
    q_ref = start.copy()
    q_ref[stepped] += amplitudes[stepped]
    return StepSetup(robot, joints, start, amplitudes, q_ref, model.joint_units(0), model.effort_units(),
                     model.joint_symbols())


def step_text(joints: Sequence[int], amplitudes: Sequence[float], symbols: Sequence[str],
               units: Sequence[str]) -> str:
    """``q1 +0.02 rad, q3 +0.02 m``: stepped joints (from 1) with their amplitudes (one per stepped
    joint) and units (``symbols`` and ``units``: one per joint of the robot)."""
    return ", ".join(f"{symbols[j - 1]} {a:+g} {units[j - 1]}" for j, a in zip(joints, amplitudes))


def step_system(fmu_dir: str | Path, kp: float, kd: float, ki: float = 0.0, *, robot: Robot,
                amplitude: float | Sequence[float] | None = None, h: float = defaults.STEP_SIZE,
                stop_time: float = defaults.STOP_TIME, joint: int | Sequence[int] | None = None,
                q0: Sequence[float] | None = None, algorithm: str = defaults.ALGORITHM,
                sample_time: float | None = None, delay_steps: int | None = None,
                parameters: dict | None = None) -> System:
    """The step-experiment diagram of ``robot``: controller + plant, q and qd fed back, tau forward.

    The controller's q_ref input (unconnected) starts at q0 + amplitude on the stepped joints;
    qd_ref, qdd_ref and a gripper input keep their start values 0 / false (the master warns
    that they are unconnected). The controller's model is the plant's (same gravity, no
    payload: the gripper is open).

    Parameters
    ----------
    fmu_dir : str or Path
        Folder holding ``<name>/controller.fmu`` and ``<name>/plant.fmu``, ``<name>`` the robot's
        name (its description's ``name``, also for a robot TOML given by path).
    kp, kd, ki : float
        Gains (1/s^2, 1/s, 1/s^3), the same on every joint, by the gains' rule
        (:func:`~robofmu.components.control.check_gains`: ParameterError naming the gain).
    robot : str, Path or RobotDescription
        A robot with a controller and a plant block: by name, robot TOML path or description.
    amplitude, joint, q0
        As for :func:`step_setup` (joint units; default amplitudes, every joint, ``home``).
    h, stop_time : float
        Communication step and stop time (s).
    algorithm : one of :data:`~robofmu.system.defaults.ALGORITHMS`
        The system's master algorithm.
    sample_time : float, optional
        The controller's sample time Ts (s), a whole multiple of ``h`` (checked when the
        diagram is planned); None: every step.
    delay_steps : int, optional
        The controller's ``delay_steps`` d (its samples); None: its default, 0.
    parameters : dict, optional
        ``{"plant.friction[2]": 0.5, "controller.loss_compensation": 0.0, ...}`` set over the
        above (:func:`~robofmu.system.experiment.with_parameters`: ValueError naming the entry).

    Returns
    -------
    System
        Named ``<name>-step``; ``extra["robot"]`` names the robot again (:func:`_robot_argument`:
        its name for a robot of the package, else its TOML's absolute path); blocks
        :data:`CONTROLLER` and :data:`PLANT`.
    """
    from robofmu.system.experiment import with_parameters

    kp, kd, ki = check_gains(kp, kd, ki)
    description = steppable(robot)
    setup = step_setup(description, amplitude, joint, q0)
    name = description.name
    controller = {"kp": kp, "kd": kd, "ki": ki, "q_ref": setup.q_ref.tolist()}
    if delay_steps is not None:
        controller["delay_steps"] = int(delay_steps)
    system = System(
        blocks=[BlockSpec(CONTROLLER, f"{name}/controller.fmu", controller,
                          None if sample_time is None else float(sample_time)),
                BlockSpec(PLANT, f"{name}/plant.fmu", {"q0": setup.q0.tolist()})],
        wires=[f"{PLANT}.q -> {CONTROLLER}.q", f"{PLANT}.qd -> {CONTROLLER}.qd",
               f"{CONTROLLER}.tau -> {PLANT}.tau"],
        fmu_dir=Path(fmu_dir), name=f"{name}-step", stop_time=float(stop_time), step=float(h),
        algorithm=algorithm, extra={"robot": _robot_argument(description)},
        description="reference step " + step_text(setup.joints, setup.amplitudes[np.array(setup.joints) - 1],
                                                   setup.symbols, setup.joint_units))
    return with_parameters(system, parameters) if parameters else system


def _parameter_values(system: System, block: str) -> dict:
    """What ``block`` of ``system`` starts with: its FMU's parameter and input defaults with the system's
    settings over them, one entry per scalar variable (``friction[2]``)."""
    from robofmu.system.plan import described, start_values

    spec = system.block(block)
    values = start_values(described(system.fmu_path(spec))[1])
    for base, value in spec.parameters.items():
        names = expand(values, base)
        values.update(zip(names, spread(names, value, f"{block}.{base}")))
    return values


def _vector(values: dict, base: str, n: int) -> np.ndarray:
    """The elements of ``base`` in ``values`` as floats, shape (n,); zeros where the block has none."""
    names = expand(values, base)
    return np.array([float(values[name]) for name in names]) if len(names) == n else np.zeros(n)


def _unknown_losses(system: System, description: RobotDescription, q0: np.ndarray, q_ref: np.ndarray) -> dict:
    """Per joint (lists, n): the plant's damping and Coulomb friction the controller does not add
    (the plant's minus ``loss_compensation`` times the controller's own), the plant's friction
    velocity scale, and the inertia m = 1 / (M^-1)_jj (kg.m^2 or kg) of the plant's model (its
    armature included) at the held reference; and ``linearization``, the coupled loop's matrices
    of :func:`~.sampled.predict_coupled` (lists, n x n) at the step's middle q* = (q0 + q_ref) / 2,
    where a tangent's error over the step is smallest: ``stiffness`` M^-1 dg/dq, ``damping``
    M^-1 D (the plant's) and ``compensation`` M^-1 D_c (what the controller adds)."""
    n = q_ref.size
    plant, controller = _parameter_values(system, PLANT), _parameter_values(system, CONTROLLER)
    known = float(controller.get("loss_compensation", 1.0))
    model = load_model(description)
    if callable(getattr(model, "set_armature", None)) and expand(plant, "armature"):
        model.set_armature(_vector(plant, "armature", n))
    inertia = 1.0 / np.diag(np.linalg.inv(model.mass_matrix(q_ref)))
    damping, compensated = _vector(plant, "damping", n), known * _vector(controller, "damping", n)
    middle = (q0 + q_ref) / 2.0
    mass = model.mass_matrix(middle)
    return {"unknown_damping": (damping - compensated).tolist(),
            "unknown_friction": (_vector(plant, "friction", n) - known * _vector(controller, "friction", n)).tolist(),
            "friction_velocity": _vector(plant, "friction_velocity", n).tolist(),
            "inertia": inertia.tolist(),
            "linearization": {"q": middle.tolist(),
                              "stiffness": np.linalg.solve(mass, model.gravity_jacobian(middle)).tolist(),
                              "damping": np.linalg.solve(mass, np.diag(damping)).tolist(),
                              "compensation": np.linalg.solve(mass, np.diag(compensated)).tolist()}}


def cosimulate_step(fmu_dir: str | Path, kp: float, kd: float, ki: float = 0.0, *, robot: Robot,
                    amplitude: float | Sequence[float] | None = None, h: float = defaults.STEP_SIZE,
                    stop_time: float = defaults.STOP_TIME, joint: int | Sequence[int] | None = None,
                    q0: Sequence[float] | None = None, algorithm: str = defaults.ALGORITHM,
                    sample_time: float | None = None, delay_steps: int | None = None,
                    parameters: dict | None = None) -> Result:
    """Co-simulate a reference step of ``robot``'s computed-torque loop (controller + plant FMUs).

    Parameters
    ----------
    fmu_dir : str or Path
        Folder holding ``<name>/{controller,plant}.fmu`` (e.g. ``fmus``), ``<name>`` the robot's name.
    kp, kd, ki : float
        Gains (1/s^2, 1/s, 1/s^3).
    robot : str, Path or RobotDescription
        A robot with a controller and a plant block: by name, robot TOML path or description.
    amplitude : float, sequence of float or None
        Size of the reference step in joint units (see :func:`step_setup`); default
        :data:`DEFAULT_AMPLITUDE` (0.02 rad or 0.02 m per joint).
    h : float
        Communication step (s).
    stop_time : float
        Stop time (s), a whole number of steps.
    joint : int, sequence of int or None
        Stepped joint(s), from 1; None: every joint.
    q0 : sequence of float, shape (n,), optional
        Start configuration (joint units); default the robot's ``home``.
    algorithm : one of :data:`~robofmu.system.defaults.ALGORITHMS`
        The :class:`~robofmu.system.master.Master`'s algorithm: "gauss-seidel" (default) or "jacobi".
    sample_time, delay_steps, parameters
        The controller's sample time Ts (s) and delay d (samples), block parameters over the
        diagram's, as for :func:`step_system`.

    Returns
    -------
    Result
        Recorded ``plant.q[j]``, ``plant.qd[j]`` (rad or m, rad/s or m/s) and
        ``controller.tau[j]`` (N.m or N) at t_k = k h, shape (n_steps + 1,) each, with their
        units; ``info`` adds ``robot`` (its name), ``robot_file`` (its TOML), ``kp, kd, ki, h,
        amplitudes (list, n), joints, q0, q_ref (lists, n), joint_units, effort_units, symbols
        (lists, n), algorithm, warnings``; when any of ``sample_time``, ``delay_steps``,
        ``parameters`` is given also ``sample_time`` (s, h if not given), ``delay_steps`` and
        the unknown losses (:func:`_unknown_losses`: ``unknown_damping``, ``unknown_friction``,
        ``friction_velocity``, ``inertia``, lists of n).
    """
    h = check_step(h)
    if algorithm not in defaults.ALGORITHMS:
        raise ValueError(f"algorithm {algorithm!r}: choose one of {', '.join(defaults.ALGORITHMS)}")
    description = steppable(robot)
    setup = step_setup(description, amplitude, joint, q0)
    system = step_system(fmu_dir, kp, kd, ki, robot=description, amplitude=setup.amplitudes, h=h,
                         stop_time=stop_time, joint=setup.joints, q0=setup.q0, algorithm=algorithm,
                         sample_time=sample_time, delay_steps=delay_steps, parameters=parameters)
    master = Master(system, record=[f"{PLANT}.q*", f"{CONTROLLER}.tau*"])
    diagram_warnings = master.check()
    sampled = {}
    if sample_time is not None or delay_steps is not None or parameters:
        sampled = dict(sample_time=h if sample_time is None else float(sample_time),
                       delay_steps=0 if delay_steps is None else int(delay_steps),
                       **_unknown_losses(system, description, setup.q0, setup.q_ref))
    result = master.run(float(stop_time), h, algorithm)
    result.info.update(robot=description.name, robot_file=str(description.path), kp=float(kp), kd=float(kd),
                       ki=float(ki), h=h,
                       amplitudes=setup.amplitudes.tolist(), joints=list(setup.joints), q0=setup.q0.tolist(),
                       q_ref=setup.q_ref.tolist(), joint_units=list(setup.joint_units),
                       effort_units=list(setup.effort_units), symbols=list(setup.symbols),
                       algorithm=algorithm, warnings=diagram_warnings, **sampled)
    return result

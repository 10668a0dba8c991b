"""The co-simulated step experiment of any robot, and its comparison with the linear predictions.

The experiment is a two-block diagram built here, whatever the robot: the robot's
``controller`` FMU (computed torque) and its ``plant`` FMU (the manipulator dynamics), with
``plant.q -> controller.q``, ``plant.qd -> controller.qd`` and ``controller.tau -> plant.tau``.
The controller's reference inputs stay unconnected: ``q_ref`` starts at ``q0 + A`` (A the
amplitude, held from t = 0), ``qd_ref`` and ``qdd_ref`` at 0, a gripper input (where the robot
has one) open. The plant starts at rest at ``q0``, by default the robot's ``home`` configuration. The master
(:class:`~robofmu.system.master.Master`, Gauss-Seidel by default) runs it; :func:`compare` sets
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
(``plant.friction[j]``, ``controller.loss_compensation`` = 0, ...). :func:`compare` then predicts
with :func:`~.sampled.predict_coupled` (the ``sampled`` model, at Ts with d, the controller's
start-up (the effort of its first sample until sample d), and the loop linearized at the step's
middle: gravity's stiffness and the viscous damping, which couple the joints through the held,
delayed effort),
gives the kp stability limit (:func:`~.sampled.largest_stable_kp`, kd held) and, for Coulomb
friction the controller does not know, the stop short predicted, measured and missed
(:class:`FrictionMiss`). A response whose error grows is reported as unstable by name, with
or without these options.
"""
from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from robofmu.components.control import check_gains
from robofmu.components.robots import ROBOTS_DIR, RobotDescription, available, load_description, load_model

from robofmu.system import defaults
from robofmu.system.diagram import BlockSpec, System, expand, spread
from robofmu.system.master import Master, Result
from robofmu.system.stepresponse.linear import MODEL_TEXT, MODELS, check_step, predict
from robofmu.system.stepresponse.metrics import StepMetrics, step_metrics
from robofmu.system.stepresponse.sampled import (friction_creep_time, friction_steady_state_error,
                                                 largest_stable_kp, predict_coupled, spectral_radius)

__all__ = ["CONTROLLER", "PLANT", "DEFAULT_AMPLITUDE", "StepSetup", "Comparison", "FrictionMiss",
           "steppable_robots", "default_amplitudes", "step_setup", "step_system", "cosimulate_step", "compare",
           "write_csv", "plot_comparison", "demo_cases"]

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


def _steppable(robot: Robot) -> RobotDescription:
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
    description = _steppable(robot)
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


def _step_text(joints: Sequence[int], amplitudes: Sequence[float], symbols: Sequence[str],
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
    description = _steppable(robot)
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
        description="reference step " + _step_text(setup.joints, setup.amplitudes[np.array(setup.joints) - 1],
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
    description = _steppable(robot)
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


# -- comparison ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class FrictionMiss:
    """Coulomb friction the controller does not know, on one stepped joint: what it costs.

    Attributes
    ----------
    joint : int
        The joint (from 1).
    coulomb : float
        tau_c unknown to the controller (N.m or N).
    inertia : float
        m = 1 / (M^-1)_jj at the held reference (kg.m^2 or kg).
    predicted : float
        The stop short e = tau_c / (m kp) (0 for a PID) of
        :func:`~.sampled.friction_steady_state_error`, joint unit.
    creep_time : float
        (s) :func:`~.sampled.friction_creep_time`: the smooth model's way out of the stick band;
        a run much shorter than it ends near ``predicted``.
    measured : float
        How far short of the reference the co-simulation ended, sign(A) (A - y(t_end)), joint unit.
    miss : float
        How far the linear prediction (the ``sampled`` model, which settles on the reference) is
        off at the end, sign(A) (y_predicted(t_end) - y(t_end)), joint unit.
    """

    joint: int
    coulomb: float
    inertia: float
    predicted: float
    creep_time: float
    measured: float
    miss: float


@dataclass
class Comparison:
    """A co-simulated step against the linear predictions (see :func:`compare`).

    With n samples, n_joints joints of which k are stepped:

    Attributes
    ----------
    time : ndarray, shape (n,)
        Communication points (s).
    joints : list of int, length k
        Stepped joints (from 1).
    amplitudes : ndarray, shape (k,)
        Amplitude of each stepped joint (its unit).
    response : ndarray, shape (n, k)
        Co-simulated q - q0 of the stepped joints (their units).
    crosstalk_joints : list of int, length n_joints - k
        The other joints (from 1).
    crosstalk : ndarray, shape (n, n_joints - k)
        Co-simulated q - q0 of the other joints (their units; 0 with perfect decoupling).
    predictions : dict of str -> ndarray, shape (n, k)
        q - q0 predicted by each model in :data:`~.linear.MODELS`, per stepped joint (its unit).
    deviation : dict of str -> ndarray, shape (k,)
        max over samples of |co-simulated - predicted| in % of |amplitude|, per stepped joint.
    crosstalk_percent : float
        max over the other joints of max |q - q0| in % of that joint's own amplitude
        (``Result.info["amplitudes"]``); 0 if every joint is stepped.
    metrics : dict of str -> StepMetrics
        ``"joint <j>"`` for each stepped joint (absolute positions, its unit, from q0 to
        q0 + amplitude) and one per model, of the unit step response (from 0 to 1: peak and final
        values are fractions of the amplitude; times and percentages are the same as for any
        amplitude, the models being linear).
    result : Result
        The co-simulation.
    gains : dict
        kp, kd, ki (1/s^2, 1/s, 1/s^3).
    h : float
        Communication step (s).
    algorithm : str
        The master's algorithm (one of :data:`~robofmu.system.defaults.ALGORITHMS`).
    robot : str
        The robot's name.
    q0 : list of float, length n_joints
        Start configuration (joint units).
    joint_units, effort_units, symbols : list of str, length n_joints
        From the robot model ("rad" / "m", "N.m" / "N", "q1", ...).
    sample_time : float or None
        The controller's sample time Ts (s) of a step run as on a robot (:func:`cosimulate_step`
        with ``sample_time``, ``delay_steps`` or ``parameters``); None: every step, the
        ``sampled`` model being :func:`~.linear.discrete_prediction`.
    delay_steps : int
        The controller's delay d (samples).
    kp_limit : float or None
        The largest stable kp (1/s^2) at Ts and d with kd and ki held, the model exact
        (:func:`~.sampled.largest_stable_kp`); None without ``sample_time``, or if no kp is stable.
    kp_limit_arm : float or None
        The same for the joints' coupled loop linearized at the step's middle
        (:func:`~.sampled.predict_coupled`'s, ``largest_stable_kp`` with its matrices): gravity's
        stiffness felt through the held, delayed effort lowers it a little.
    spectral_radius : float or None
        Largest |pole| of the predicted (coupled) loop at the run's gains (< 1: stable).
    friction : list of FrictionMiss
        One per stepped joint with Coulomb friction unknown to the controller.
    divergence : str
        "" unless the co-simulated error grew: then one line naming the block, the joint and the time.
    """

    time: np.ndarray
    joints: list
    amplitudes: np.ndarray
    response: np.ndarray
    crosstalk_joints: list
    crosstalk: np.ndarray
    predictions: dict
    deviation: dict
    crosstalk_percent: float
    metrics: dict
    result: Result
    gains: dict
    h: float
    algorithm: str = defaults.ALGORITHM
    robot: str = ""
    q0: list = field(default_factory=list)
    joint_units: list = field(default_factory=list)
    effort_units: list = field(default_factory=list)
    symbols: list = field(default_factory=list)
    sample_time: float | None = None
    delay_steps: int = 0
    kp_limit: float | None = None
    kp_limit_arm: float | None = None
    spectral_radius: float | None = None
    friction: list = field(default_factory=list)
    divergence: str = ""

    def model_text(self, model: str) -> str:
        """One line describing ``model`` (:data:`~.linear.MODEL_TEXT`; ``sampled`` at Ts with d)."""
        if model == "sampled" and self.sample_time is not None:
            return (f"sampled-data loop, controller every {self.sample_time * 1e3:g} ms, "
                    f"{self.delay_steps} sample{'s' * (self.delay_steps != 1)} late (predict_coupled)")
        return MODEL_TEXT[model]

    def unit(self, joint: int) -> str:
        """Unit of joint ``joint``'s position (from 1): "rad" or "m"."""
        return self.joint_units[joint - 1]

    def symbol(self, joint: int) -> str:
        """Label of joint ``joint`` (from 1), e.g. "q2"."""
        return self.symbols[joint - 1]

    def effort(self) -> np.ndarray:
        """Co-simulated actuator efforts ``controller.tau``, shape (n, n_joints) (N.m or N)."""
        return self.result.vector(f"{CONTROLLER}.tau")

    def best(self) -> str:
        """The model with the smallest max deviation."""
        return min(self.deviation, key=lambda model: float(np.max(self.deviation[model])))

    def max_deviation(self, model: str = "sampled") -> float:
        """max over stepped joints and samples of |co-simulated - predicted|, % of the amplitude."""
        return float(np.max(self.deviation[model]))

    def step_text(self) -> str:
        """``q1 +0.02 rad, q3 +0.02 m``: the stepped joints with their amplitudes and units."""
        return _step_text(self.joints, self.amplitudes, self.symbols, self.joint_units)

    def table(self) -> str:
        """Metrics of every stepped joint and model, then the deviations, as aligned text."""
        g = self.gains
        start = ", ".join(f"{q:g} {u}" for q, u in zip(self.q0, self.joint_units))
        rate = ("" if self.sample_time is None else
                f"; controller every {self.sample_time * 1e3:g} ms, {self.delay_steps} sample"
                f"{'s' * (self.delay_steps != 1)} late")
        lines = [f"{self.robot}: step {self.step_text()} from q0 = ({start}); kp {g['kp']:g}, "
                 f"kd {g['kd']:g}, ki {g['ki']:g}; h {self.h * 1e3:g} ms{rate}; algorithm {self.algorithm}",
                 f"{'response':<24}{'rise (s)':>10}{'settle (s)':>12}{'overshoot %':>13}"
                 f"{'peak time (s)':>15}{'peak':>12}{'final':>12}  unit"]
        for name, m in self.metrics.items():
            unit = self.unit(int(name.split()[1])) if name.startswith("joint ") else "amplitude"
            lines.append(f"{name:<24}{m.rise_time:>10.4f}{m.settling_time:>12.4f}{m.overshoot:>13.3f}"
                         f"{m.peak_time:>15.4f}{m.peak:>12.5f}{m.steady_state:>12.5f}  {unit}")
        lines.append("max |co-simulated - predicted| over all samples, % of the amplitude:")
        for model in self.deviation:
            per_joint = ", ".join(f"{self.symbol(j)} {d:.3f}"
                                  for j, d in zip(self.joints, self.deviation[model]))
            lines.append(f"  {model:<11} {self.max_deviation(model):8.3f} %   ({per_joint})  "
                         f"{self.model_text(model)}")
        if self.crosstalk.size:
            lines.append(f"  unstepped joints moved by at most {self.crosstalk_percent:.3f} % of their "
                         "amplitude")
        lines.append(f"best match: {self.best()}")
        lines.extend(self._sampled_lines())
        if self.divergence:
            lines.append(self.divergence)
        return "\n".join(lines)

    def _sampled_lines(self) -> list[str]:
        """The stability limit and the unknown friction's cost, for a run with ``sample_time``."""
        if self.sample_time is None:
            return []
        g, ts, d = self.gains, self.sample_time, self.delay_steps
        where = f"Ts {ts * 1e3:g} ms, d {d}, kd {g['kd']:g}" + (f", ki {g['ki']:g}" if g["ki"] else "")
        if self.kp_limit is None:
            lines = [f"stability limit: no kp is stable at {where}"]
        else:
            lines = [f"stability limit: largest stable kp {self.kp_limit:.6g} 1/s^2 at {where} held (python-control's "
                     f"discrete poles); kp {g['kp']:g} is {g['kp'] / self.kp_limit * 100:.1f} % of it, spectral "
                     f"radius {self.spectral_radius:.5f}"]
            if self.kp_limit_arm is not None and abs(self.kp_limit_arm / self.kp_limit - 1.0) > 1e-6:
                lines.append(f"  the arm linearized at the step's middle (gravity and damping felt through the held "
                             f"effort): largest stable kp {self.kp_limit_arm:.6g} 1/s^2, kp {g['kp']:g} is "
                             f"{g['kp'] / self.kp_limit_arm * 100:.1f} % of it")
        for f in self.friction:
            k = self.joints.index(f.joint)
            unit, amplitude = self.unit(f.joint), abs(float(self.amplitudes[k]))
            effort = self.effort_units[f.joint - 1]
            off = f" ({(f.measured / f.predicted - 1) * 100:+.1f} %)" if f.predicted else ""
            lines.append(f"friction unknown to the controller, {self.symbol(f.joint)}: Coulomb {f.coulomb:g} {effort}, "
                         f"m {f.inertia:.5g}: stops short by {f.predicted:.5g} {unit} predicted (tau_c / (m kp); "
                         f"creep time {f.creep_time:.3g} s), measured {f.measured:.5g} {unit}{off} at "
                         f"t = {self.time[-1]:g} s; the linear prediction misses it by {f.miss:.5g} {unit} "
                         f"({abs(f.miss) / amplitude * 100:.2f} % of the amplitude)")
        return lines


def _units_of(result: Result, n: int) -> tuple[list, list, list]:
    """Joint units, effort units and symbols of a step result: its ``info``, else its columns'."""
    info = result.info
    joint_units = info.get("joint_units") or [result.units.get(f"{PLANT}.q[{j}]", "")
                                              for j in range(1, n + 1)]
    effort_units = info.get("effort_units") or [result.units.get(f"{CONTROLLER}.tau[{j}]", "")
                                                for j in range(1, n + 1)]
    symbols = info.get("symbols") or [f"q{j}" for j in range(1, n + 1)]
    return list(joint_units), list(effort_units), list(symbols)


def compare(result: Result, models: Sequence[str] = MODELS, settling: float = 0.02,
            interpolate: bool = True) -> Comparison:
    """Compare a co-simulated step (from :func:`cosimulate_step`) with the linear predictions.

    Parameters
    ----------
    result : Result
        From :func:`cosimulate_step` (its ``info`` carries gains, h, amplitudes, joints, q0, units).
    models : sequence of str
        Predictions to compute, from :data:`~.linear.MODELS`.
    settling : float
        Settling band for the metrics (0.02: 2 %).
    interpolate : bool
        Passed to :func:`~.metrics.step_metrics`.

    Returns
    -------
    Comparison
        Deviations (max over samples of |co-simulated - predicted|, % of each joint's amplitude)
        and the metrics of both (steady state taken as the reference q0 + amplitude, which a
        perfect model reaches; the record may end before the PID's slow integral mode has).
        For a run with ``sample_time`` in its ``info`` (see :func:`cosimulate_step`) the
        ``sampled`` model is :func:`~.sampled.predict_coupled` at Ts with d, the run's
        ``linearization`` and the controller's start-up (``startup="first"``; the model's metrics
        are those of the first stepped joint's), with the stability limit and the friction rows.
    """
    info = result.info
    kp, kd, ki, h = info["kp"], info["kd"], info["ki"], info["h"]
    joints, q0 = list(info["joints"]), np.asarray(info["q0"], dtype=float)
    all_amplitudes = np.asarray(info["amplitudes"], dtype=float)
    t = result.time
    y = result.vector(f"{PLANT}.q") - q0
    stepped = np.array(joints) - 1
    others = [j for j in range(1, q0.size + 1) if j not in joints]
    amplitudes = all_amplitudes[stepped]
    response = y[:, stepped]
    crosstalk = y[:, np.array(others, dtype=int) - 1] if others else np.zeros((len(t), 0))
    ts, d = info.get("sample_time"), int(info.get("delay_steps", 0))
    beta = (np.asarray(info["unknown_damping"])[stepped] / np.asarray(info["inertia"])[stepped]
            if ts is not None else np.zeros(len(joints)))
    unit_responses, predictions, deviation = {}, {}, {}
    for model in models:
        if model == "sampled" and ts is not None:
            step = np.zeros(q0.size)
            step[stepped] = amplitudes
            linearization = info["linearization"]
            every = predict_coupled(kp, kd, ki, t - t[0], step, sample_time=ts, delay_steps=d, h=h, startup="first",
                                    **{key: linearization[key] for key in ("stiffness", "damping", "compensation")})
            predictions[model] = every[:, stepped]
            unit_responses[model] = predictions[model][:, 0] / amplitudes[0]
        else:
            unit_responses[model] = predict(kp, kd, ki, t - t[0], 1.0, model, h)
            predictions[model] = unit_responses[model][:, None] * amplitudes[None, :]
        deviation[model] = np.max(np.abs(response - predictions[model]), axis=0) / np.abs(amplitudes) * 100.0
    metrics: dict[str, StepMetrics] = {}
    for j, amplitude, column in zip(joints, amplitudes, response.T):
        start = q0[j - 1]
        metrics[f"joint {j}"] = step_metrics(t, column + start, y0=start, yf=start + amplitude,
                                             settling=settling, interpolate=interpolate)
    for model, unit_response in unit_responses.items():
        metrics[model] = step_metrics(t, unit_response, y0=0.0, yf=1.0, settling=settling,
                                      interpolate=interpolate)
    crosstalk_percent = 0.0
    if others:
        scale = np.abs(all_amplitudes[np.array(others) - 1])
        crosstalk_percent = float(np.max(np.max(np.abs(crosstalk), axis=0) / scale) * 100.0)
    joint_units, effort_units, symbols = _units_of(result, q0.size)
    sampled = {}
    if ts is not None:
        arm = {key: info["linearization"][key] for key in ("stiffness", "damping", "compensation")}
        limits = []
        for terms in ({}, arm):
            try:
                limits.append(largest_stable_kp(kd, ts, d, ki, **terms))
            except ValueError:               # no kp is stable at this kd, ki, Ts and d
                limits.append(None)
        sampled = dict(sample_time=ts, delay_steps=d, kp_limit=limits[0], kp_limit_arm=limits[1],
                       spectral_radius=spectral_radius(kp, kd, ki, ts, d, **arm),
                       friction=_friction_misses(info, joints, amplitudes, response, predictions.get("sampled"), beta))
    rate = "" if ts is None else f", controller every {ts * 1e3:g} ms, {d} sample{'s' * (d != 1)} late"
    return Comparison(time=t, joints=joints, amplitudes=amplitudes, response=response,
                      crosstalk_joints=others, crosstalk=crosstalk, predictions=predictions,
                      deviation=deviation, crosstalk_percent=crosstalk_percent, metrics=metrics,
                      result=result, gains={"kp": kp, "kd": kd, "ki": ki}, h=h,
                      algorithm=info.get("algorithm", defaults.ALGORITHM), robot=info.get("robot", ""),
                      q0=q0.tolist(), joint_units=joint_units, effort_units=effort_units,
                      symbols=symbols, divergence=_divergence(t, response, amplitudes, joints, symbols, kp, rate),
                      **sampled)


def _friction_misses(info: dict, joints: list, amplitudes: np.ndarray, response: np.ndarray,
                     predicted: np.ndarray | None, beta: np.ndarray) -> list[FrictionMiss]:
    """A :class:`FrictionMiss` per stepped joint whose plant has Coulomb friction the controller
    does not add (``info``'s unknown losses, from :func:`cosimulate_step`)."""
    misses = []
    for k, j in enumerate(joints):
        coulomb = float(info["unknown_friction"][j - 1])
        if coulomb <= 0.0:
            continue
        inertia, sign = float(info["inertia"][j - 1]), float(np.sign(amplitudes[k]))
        creep = friction_creep_time(info["kp"], info["kd"], info["ki"], info["sample_time"], coulomb, inertia,
                                    float(info["friction_velocity"][j - 1]), info["delay_steps"], float(beta[k]))
        end = float(response[-1, k])
        misses.append(FrictionMiss(
            joint=j, coulomb=coulomb, inertia=inertia,
            predicted=friction_steady_state_error(info["kp"], coulomb, inertia, info["ki"]), creep_time=creep,
            measured=sign * (float(amplitudes[k]) - end),
            miss=sign * ((float(predicted[-1, k]) if predicted is not None else float(amplitudes[k])) - end)))
    return misses


def _divergence(t: np.ndarray, response: np.ndarray, amplitudes: np.ndarray, joints: list, symbols: list,
                kp: float, rate: str) -> str:
    """"" for a step whose error |y - A| shrinks; else one line: unstable, the controller's loop,
    the joint whose error grew most from the run's first fifth to its last, and when.

    The error of a stable loop decays (its largest value after the step's first fifth is below
    the first fifth's); that of a loop beyond its stability limit grows geometrically."""
    fifth = max(len(t) // 5, 1)
    if len(t) < 10:
        return ""
    error = np.abs(response - amplitudes[None, :]) / np.abs(amplitudes)[None, :]
    first, last = np.max(error[:fifth], axis=0), np.max(error[-fifth:], axis=0)
    growth = last / first
    k = int(np.argmax(growth))
    if not growth[k] > 1.0:
        return ""
    at = len(t) - fifth + int(np.argmax(error[-fifth:, k]))
    return (f"UNSTABLE: the loop of block {CONTROLLER!r} (kp {kp:g}{rate}) diverged: joint {joints[k]} "
            f"({symbols[joints[k] - 1]}) |q - q_ref| grew from {first[k]:.3g} to {last[k]:.3g} times the amplitude "
            f"(at t = {t[at]:g} s)")


# -- output -------------------------------------------------------------------------------------
def write_csv(comparison: Comparison, path: str | Path) -> Path:
    """Write the comparison as CSV, units in the header.

    Columns: ``time [s]``; ``cosim_<q> [<unit>]`` (co-simulated q - q0) of each stepped joint;
    ``pred_<model>_<q> [<unit>]`` (predicted q - q0) for each model and stepped joint;
    ``tau<j> [<unit>]`` (co-simulated effort, N.m or N) of every joint. Full precision
    (``repr``). Parent folders are created.

    Parameters
    ----------
    comparison : Comparison
    path : str or Path

    Returns
    -------
    Path
        The file written.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    c = comparison
    effort = c.effort()
    header = (["time [s]"] + [f"cosim_{c.symbol(j)} [{c.unit(j)}]" for j in c.joints]
              + [f"pred_{model}_{c.symbol(j)} [{c.unit(j)}]" for model in c.predictions for j in c.joints]
              + [f"tau{j} [{unit}]" for j, unit in enumerate(c.effort_units, start=1)])
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        for k, tk in enumerate(c.time):
            predicted = (v for model in c.predictions for v in c.predictions[model][k])
            row = [float(tk), *c.response[k], *predicted, *effort[k]]
            writer.writerow([repr(float(v)) for v in row])
    return path


def _display(unit: str) -> str:
    """A unit for a figure: products with a middle dot (N.m -> N·m)."""
    return unit.replace(".", "\u00b7")


def _groups(joints: Sequence[int], units: Sequence[str]) -> dict[str, list[int]]:
    """Joints (from 1) grouped by unit, in order of first appearance."""
    groups: dict[str, list[int]] = {}
    for j in joints:
        groups.setdefault(units[j - 1], []).append(j)
    return groups


def plot_comparison(comparison: Comparison, out_dir: str | Path, name: str | None = None) -> Path:
    """Figure of the co-simulated step against the continuous, c2d and sampled-data predictions
    (the sampled-data loop at the controller's sample time and delay, where the run has them).

    One panel of q - q0 per position unit of the stepped joints (rad, m) with the co-simulated
    responses and the predictions; then co-simulated minus predicted, in % of each joint's
    amplitude, with the 1 % band; then one panel of the actuator efforts per effort unit (N.m, N).
    Labels and units come from the robot model.

    Parameters
    ----------
    comparison : Comparison
    out_dir : str or Path
        Folder for the PNG (created).
    name : str, optional
        File stem; default from robot, gains, communication step and stepped joints.

    Returns
    -------
    Path
        The PNG written.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    c = comparison
    g = c.gains
    if name is None:
        name = (f"step_{c.robot}_kp{g['kp']:g}_kd{g['kd']:g}_ki{g['ki']:g}_h{c.h * 1e3:g}ms_"
                f"j{'-'.join(map(str, c.joints))}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    position_groups = _groups(c.joints, c.joint_units)
    effort_groups = _groups(range(1, len(c.effort_units) + 1), c.effort_units)
    ratios = [3] * len(position_groups) + [2] + [2] * len(effort_groups)
    fig, axes = plt.subplots(len(ratios), 1, figsize=(8, 1.6 * sum(ratios) / 2 + 1.5), sharex=True,
                             gridspec_kw={"height_ratios": ratios}, squeeze=False)
    axes = axes[:, 0]
    styles = {"continuous": dict(color="k", lw=1.2, ls="-"),
              "zoh": dict(color="tab:orange", lw=0, marker=".", ms=3),
              "sampled": dict(color="tab:blue", lw=1.2, ls="--")}
    column = {j: k for k, j in enumerate(c.joints)}
    for ax, (unit, joints) in zip(axes, position_groups.items()):
        for j in joints:
            ax.plot(c.time, c.response[:, column[j]], lw=2.5, alpha=0.45,
                    label=f"co-simulated {c.symbol(j)} ({c.amplitudes[column[j]]:+g} {_display(unit)})")
        for model in c.predictions:
            drawn = set()
            for j in joints:
                amplitude = float(c.amplitudes[column[j]])
                if amplitude in drawn:
                    continue
                ax.plot(c.time, c.predictions[model][:, column[j]], **styles.get(model, {}),
                        label=c.model_text(model) if not drawn else None)
                drawn.add(amplitude)
        for amplitude in {float(c.amplitudes[column[j]]) for j in joints}:
            ax.axhline(amplitude, color="grey", lw=0.6)
        ax.set_ylabel(f"q - q0 ({_display(unit)})")
        ax.legend(fontsize=8)
    deviation_axis = axes[len(position_groups)]
    for model in c.predictions:
        for k, j in enumerate(c.joints):
            percent = (c.response[:, k] - c.predictions[model][:, k]) / abs(c.amplitudes[k]) * 100.0
            deviation_axis.plot(c.time, percent, color=styles.get(model, {}).get("color"),
                                lw=0.9 if model != "continuous" else 0.7,
                                ls=":" if model == "continuous" else "-", alpha=0.85,
                                label=f"vs {model} (max {c.max_deviation(model):.2f} %)" if k == 0 else None)
    for sign in (-1.0, 1.0):
        deviation_axis.axhline(sign, color="grey", ls=":", lw=0.8)
    deviation_axis.plot([], [], color="grey", ls=":", label="1 % of the amplitude")
    deviation_axis.set_ylabel("co-sim - prediction\n(% of amplitude)")
    deviation_axis.legend(fontsize=7, ncol=2)
    effort = c.effort()
    for ax, (unit, joints) in zip(axes[len(position_groups) + 1:], effort_groups.items()):
        for j in joints:
            ax.plot(c.time, effort[:, j - 1], lw=1.0, label=f"tau{j} ({c.symbol(j)})")
        ax.set_ylabel(f"effort ({_display(unit)})")
        ax.legend(fontsize=7, ncol=min(4, len(joints)))
    rate = "" if c.sample_time is None else f", controller every {c.sample_time * 1e3:g} ms, d = {c.delay_steps}"
    axes[0].set_title(f"{c.robot}: step {c.step_text()}\nkp {g['kp']:.4g}, kd {g['kd']:.4g}, "
                      f"ki {g['ki']:.4g}; h = {c.h * 1e3:g} ms{rate} ({c.algorithm})", fontsize=10)
    axes[-1].set_xlabel("t (s)")
    for ax in axes:
        ax.grid(alpha=0.3)
    from robofmu.system.plots import save_figure

    return save_figure(fig, out / f"{name}.png", dpi=120)


def demo_cases(robot: Robot, fmu_dir: str | Path, out_dir: str | Path, h: float = defaults.STEP_SIZE,
               stop_time: float = defaults.STOP_TIME) -> list[tuple[str, tuple[Comparison, Path]]]:
    """The default step of ``robot`` under each gain set of its description, compared and plotted.

    Every joint steps by its :data:`DEFAULT_AMPLITUDE` from the ``home`` configuration.

    Parameters
    ----------
    robot : str, Path or RobotDescription
        A robot with a controller and a plant block: by name, robot TOML path or description.
    fmu_dir : str or Path
        Folder holding ``<name>/{controller,plant}.fmu``, ``<name>`` the robot's name.
    out_dir : str or Path
        Folder for the figures, ``step_<name>_<gain set>.png`` (created).
    h, stop_time : float
        Communication step and stop time (s).

    Returns
    -------
    list of (str, (Comparison, Path))
        One per gain set, in the description's order: the label ``"<set>: kp .., kd .., ki .."``
        and the comparison with its figure.
    """
    cases = []
    description = _steppable(robot)
    for name, gains in description.gains.items():
        comparison = compare(cosimulate_step(fmu_dir, gains.kp, gains.kd, gains.ki, robot=description, h=h,
                                             stop_time=stop_time))
        figure = plot_comparison(comparison, out_dir, name=f"step_{description.name}_{name}")
        cases.append((f"{name}: kp {gains.kp:g}, kd {gains.kd:g}, ki {gains.ki:g}", (comparison, figure)))
    return cases

"""Trajectory blocks: the reference a robot follows, from its description's ``[trajectory]``.

``waypoints``: task space, LSPB moves through waypoints with pauses (and gripper events); the
waypoints a list of rows, or a CSV table beside the robot's TOML (``waypoints = "path.csv"``),
the first row the start, or, given ``start`` or ``start_configuration`` (the task point at that
configuration, default ``"home"``), the points after it, or with ``relative = true`` the offsets
from it;
``line``: task space, a straight line at minimum time with a trapezoidal speed, from ``start``
(default: the task point at ``start_configuration``, ``"home"``) by ``displacement``, or along
``direction`` for ``length``;
``joint_bangbang``: joint space, the synchronized minimum-time bang-bang;
``circle``: task space, once round a circle in the first two task coordinates with an LSPB
phase (further task coordinates offset + amplitude sin phi);
``pose_line``: a pose task, the frame's origin on a straight line and its orientation by slerp
(shortest rotation), on one time law: LSPB of a duration, or minimum time under speed and
acceleration limits;
``pose_waypoints``: a pose task through poses (a list of rows or a CSV table, columns x, y, z,
qx, qy, qz, qw), one pose line per leg on LSPB, with pauses.
Outputs at time t belong to t; no inputs.
"""
from __future__ import annotations

import numpy as np

from dataclasses import replace

from ..orientation import COMPONENTS, quaternion_of
from ..parameters import Parameter
from ..pose_trajectory import POSE_COLUMNS, PoseLine, PoseWaypoints
from ..trajectory import Circle, StraightLine, SynchronizedBangBang, WaypointTrajectory
from ..waypoint_table import read_table
from .base import Block
from .text import format_matrix, format_vector, parse_matrix, parse_vector


class _Reference(Block):
    """Common part: three outputs (position, velocity, acceleration) of one profile."""

    kind = "trajectory"
    summary = "reference profile"
    abstract = True
    profile = None
    #: What the profile's outputs are, in the order of ``evaluate``.
    quantities = ("position", "velocity", "acceleration")

    def declare_outputs(self, bases, units, describe):
        n = len(units[0])
        out = []
        for base, unit, what in zip(bases, units, ("position", "velocity", "acceleration")):
            out.append(self.reals(base, n, "output", unit, lambda i, w=what: describe(i, w), depends=[]))
        self.outputs = out

    def given(self, vectors: dict[str, int], parameters: dict | None = None) -> tuple[dict, dict]:
        """The description's ``[trajectory]`` values (or ``parameters``, some of them): the vectors
        (checked for their lengths) and the rest."""
        given = dict(self.description.trajectory.parameters if parameters is None else parameters)
        for key, length in vectors.items():
            value = given.get(key)
            if value is None:
                self.table_error("trajectory", key, "missing")
            if not isinstance(value, list) or (length and len(value) != length):
                self.table_error("trajectory", key, f"needs {length or 'a list of'} values, got {value!r}")
        return {k: given.pop(k) for k in vectors}, given

    def configure(self):
        """Refuse a profile whose reference is not finite anywhere (checked at and between its
        breakpoints, where its extremes lie). The profiles refuse the overflows they foresee
        naming the parameters (components/trajectory.py); this check, the last line, names the
        block's parameters and the instant."""
        breaks = np.asarray(self.profile.breakpoints, dtype=float)
        times = np.concatenate([breaks, breaks[:-1] / 2 + breaks[1:] / 2])    # no overflow of the sum
        for t in times:
            with np.errstate(all="ignore"):
                values = self.profile.evaluate(float(t))
            for what, value in zip(self.quantities, values):
                if not np.all(np.isfinite(value)):
                    raise ValueError(f"the parameters ({', '.join(self.parameter_names())}) give a non-finite "
                                     f"reference {what} at t = {t:g} s ({np.asarray(value).tolist()})")
        self._views = tuple(self.values[s] for s in self.outputs)   # made once: values is never replaced
        super().configure()

    def output(self, t):
        self.profile.evaluate_into(t, *self._views, self.snap)

    def read_waypoints(self, columns) -> None:
        """Given ``waypoints = "file.csv"`` (a table beside the robot's TOML, one column per name of
        ``columns``), its rows in the description's place."""
        table = self.description.trajectory.parameters.get("waypoints")
        if isinstance(table, str):
            try:
                rows = read_table(self.description.path.parent / table, columns)
            except ValueError as exc:
                self.table_error("trajectory", "waypoints", str(exc))
            self.description = replace(self.description, trajectory=replace(
                self.description.trajectory, parameters={**self.description.trajectory.parameters, "waypoints": rows}))

    def start_point(self, given: dict, length: int, fk) -> tuple[str, list]:
        """Pops ``start_configuration`` (default ``"home"``) and ``start`` of ``given``: the
        configuration's name and the start, ``start`` if given (``length`` values), else
        ``fk(q)`` of the configuration's joints q (a list). Table errors naming the key."""
        named = given.pop("start_configuration", "home")
        if not isinstance(named, str) or named not in self.description.configurations:
            self.table_error("trajectory", "start_configuration", f"no configuration {named!r} (described: "
                             f"{', '.join(self.description.configurations)})")
        start = given.pop("start", None)
        if start is None:
            return named, np.asarray(fk(self.robot.configuration(named)), dtype=float).tolist()
        if not isinstance(start, list) or len(start) != length:
            self.table_error("trajectory", "start", f"needs {length} values, got {start!r}")
        return named, start

    def string_parameter(self, name, description, start):
        self.setting(Parameter(name, "String", "", description, start), start)

    def parameter_names(self) -> list[str]:
        """The block's parameters, each vector once by its base (``start``, ``length``)."""
        names = []
        for v in self.variables:
            base = v.name.split("[", 1)[0]
            if v.causality == "parameter" and base not in names:
                names.append(base)
        return names

    def breakpoints(self):
        return self.profile.breakpoints

    def nominal_stop_time(self):
        """The profile's end with the default parameters."""
        try:
            self.configure()
        except ValueError:
            return None
        return float(self.profile.breakpoints[-1])


def _task(block):
    coords = block.description.task.coordinates
    units = [block.robot.task_units(k) for k in range(3)]
    return coords, units


class WaypointsBlock(_Reference):
    variant = "waypoints"
    summary = ("task-space reference through waypoints, one LSPB move per leg (cruise speed "
               "cruise_factor x mean speed) with pauses between moves; outputs at time t belong to t")
    settings_declared = (
        Parameter("pause", "Real", "s", "Rest between two moves", 0.0, low=0.0),
        Parameter("cruise_factor", "Real", "1", "Cruise speed over the move's mean speed, in (1, 2]", 1.5,
                  above=1.0, high=2.0),
        Parameter("grip_close_after_move", "Integer", "", "The gripper closes at the end of this move "
                  "(1-based; 0: never)", 0, low=0),
        Parameter("grip_open_after_move", "Integer", "", "The gripper opens at the end of this move "
                  "(1-based; 0: never)", 0, low=0),
    )

    def declare(self):
        self.read_waypoints(self.description.task.coordinates)
        coords, units = _task(self)
        parameters = dict(self.description.trajectory.parameters)
        self.relative = parameters.pop("relative", False)
        if not isinstance(self.relative, bool):
            self.table_error("trajectory", "relative", f"must be true or false, got {self.relative!r}")
        self.has_start = self.relative or "start" in parameters or "start_configuration" in parameters
        if self.has_start:
            named, start = self.start_point(parameters, len(coords), self.robot.fk)
            self.reals("start", len(coords), "parameter", units[0],
                       lambda i: f"Start point, coordinate {coords[i - 1]} (default: at configuration {named!r})",
                       start)
        vectors, rest = self.given({"waypoints": 0, "durations": 0}, parameters)
        given = {**vectors, **rest}
        values = self.table_values("trajectory", self.settings_declared, rest)
        row = ("offset from start" if self.relative else "point after start") if self.has_start else "point"
        self.string_parameter("waypoints", f"Waypoints ({', '.join(units[0])}), one row per {row} "
                              f"('{' '.join(coords)}'), rows separated by ';'", format_matrix(given["waypoints"]))
        self.string_parameter("durations", "Duration of each move (s), space-separated; one per leg",
                              format_vector(given["durations"]))
        self.has_grip = "grip_close_after_move" in given
        for p in self.settings_declared:
            if p.name.startswith("grip") and not self.has_grip:
                continue
            self.declare_parameter(p, values[p.name])
        self.declare_outputs(("x_ref", "xd_ref", "xdd_ref"), units,
                             lambda i, w: f"Reference task {w} along {coords[i - 1]}")
        if self.has_grip:
            self.grip = self.boolean("grip", "output", "Gripper closed (carrying the payload)", depends=[])

    def configure(self):
        m = self.robot.m
        close = self.parameter("grip_close_after_move") if self.has_grip else 0
        open_ = self.parameter("grip_open_after_move") if self.has_grip else 0
        self.profile = WaypointTrajectory(
            parse_matrix(str(self.settings["waypoints"]), "parameter waypoints", columns=m),
            parse_vector(str(self.settings["durations"]), "parameter durations"),
            pause=self.parameter("pause"), cruise_factor=self.parameter("cruise_factor"),
            grip_close_after_move=close, grip_open_after_move=open_,
            start=self.finite_vector("start") if self.has_start else None, relative=self.relative)
        super().configure()

    def output(self, t):
        if not self.has_grip:
            super().output(t)
            return
        snapped = self.profile.snap(t)        # the grip always snaps; snapped once for both
        self.values[self.grip] = self.profile.grip(snapped, snap=False)
        self.profile.evaluate_into(snapped if self.snap else t, *self._views, False)

    def events(self):
        found = {"grip closes": self.profile.grip_close_time, "grip opens": self.profile.grip_open_time}
        return {k: float(v) for k, v in found.items() if np.isfinite(v)}


class LineBlock(_Reference):
    variant = "line"
    summary = ("task-space straight line at minimum time with a trapezoidal speed profile (v_max, "
               "a_max), then at rest; outputs at time t belong to t")
    length = Parameter("length", "Real", "m", "Path length", None, above=0.0)
    limits = (
        Parameter("v_max", "Real", "m/s", "Speed limit along the path", None, above=0.0),
        Parameter("a_max", "Real", "m/s2", "Acceleration limit along the path", None, above=0.0),
    )

    def declare(self):
        coords, units = _task(self)
        m = len(coords)
        parameters = dict(self.description.trajectory.parameters)
        named, start = self.start_point(parameters, m, self.robot.fk)
        self.by_displacement = "displacement" in parameters
        if self.by_displacement and {"direction", "length"} & set(parameters):
            self.table_error("trajectory", "displacement", "give either displacement or direction and length, "
                             "not both")
        given, rest = self.given({"displacement": m} if self.by_displacement else {"direction": m}, parameters)
        self.scalars = self.limits if self.by_displacement else (self.length,) + self.limits
        values = self.table_values("trajectory", self.scalars, rest)
        self.reals("start", m, "parameter", units[0],
                   lambda i: f"Start point, coordinate {coords[i - 1]} (default: at configuration {named!r})", start)
        if self.by_displacement:
            self.reals("displacement", m, "parameter", units[0],
                       lambda i: f"Displacement from the start point, coordinate {coords[i - 1]}",
                       given["displacement"])
        else:
            self.reals("direction", m, "parameter", "1", lambda i: f"Direction of travel, component "
                       f"{coords[i - 1]} (normalized by the block)", given["direction"])
        for p in self.scalars:
            self.declare_parameter(p, values[p.name])
        self.declare_outputs(("x_ref", "xd_ref", "xdd_ref"), units,
                             lambda i, w: f"Reference task {w} along {coords[i - 1]}")

    def configure(self):
        way = "displacement" if self.by_displacement else "direction"
        vector = self.finite_vector(way)
        if not vector.any():
            raise ValueError(f"parameter {way} = (0, ..., 0) is invalid: must not be the zero vector")
        start, v_max, a_max = self.finite_vector("start"), self.parameter("v_max"), self.parameter("a_max")
        self.profile = (StraightLine.by_displacement(start, vector, v_max, a_max) if self.by_displacement else
                        StraightLine(start, vector, self.parameter("length"), v_max, a_max))
        super().configure()


class JointBangBangBlock(_Reference):
    variant = "joint_bangbang"
    summary = ("joint-space synchronized minimum-time bang-bang from q_start to q_end (every joint "
               "finishes at the slowest joint's minimum time), then at rest; outputs at t belong to t")

    def declare(self):
        n = self.robot.n
        given, rest = self.given({"q_start": n, "q_end": n, "a_max": n})
        self.table_values("trajectory", (), rest)            # refuses any other key
        units = [self.robot.joint_units(k) for k in range(3)]
        self.reals("q_start", n, "parameter", units[0], "Joint {i} start position (at rest)", given["q_start"])
        self.reals("q_end", n, "parameter", units[0], "Joint {i} end position (at rest)", given["q_end"])
        self.reals("a_max", n, "parameter", units[2], "Joint {i} acceleration limit", given["a_max"])
        self.declare_outputs(("q_ref", "qd_ref", "qdd_ref"), units,
                             lambda i, w: f"Joint {i} reference {w}")

    def configure(self):
        self.profile = SynchronizedBangBang(self.finite_vector("q_start"), self.finite_vector("q_end"),
                                            self.finite_vector("a_max", above=0.0))
        super().configure()


class CircleBlock(_Reference):
    variant = "circle"
    summary = ("task-space circle run once: phi 0 -> 2 pi by LSPB (cruise_factor x mean speed), at rest "
               "at both ends; x[1:2] = center + radius (cos, sin)(start_angle + sense phi), further "
               "coordinates offset + amplitude sin phi; outputs at time t belong to t")
    scalars = (
        Parameter("radius", "Real", "m", "Circle radius (in the first two task coordinates)", None, above=0.0),
        Parameter("start_angle", "Real", "rad", "Direction of the start point from the centre", None),
        Parameter("sense", "Integer", "", "1: counter-clockwise, -1: clockwise", 1, low=-1, high=1),
        Parameter("duration", "Real", "s", "Time once round the circle", None, above=0.0),
        Parameter("cruise_factor", "Real", "1", "Cruise phase rate over the mean rate, in (1, 2]", 1.5,
                  above=1.0, high=2.0),
    )

    def declare(self):
        coords, units = _task(self)
        m = len(coords)
        if m < 2 or units[0][0] != units[0][1]:
            self.table_error("trajectory", "profile", "a circle needs two task coordinates of one unit "
                             f"first, got {list(coords)} ({', '.join(units[0])})")
        extra = m - 2
        given, rest = self.given({"center": 2, **({"offset": extra, "amplitude": extra} if extra else {})})
        values = self.table_values("trajectory", self.scalars, rest)
        self.reals("center", 2, "parameter", units[0][:2],
                   lambda i: f"Circle centre, coordinate {coords[i - 1]}", given["center"])
        for p in self.scalars:
            self.declare_parameter(p, values[p.name])
        if extra:
            self.reals("offset", extra, "parameter", units[0][2:],
                       lambda i: f"Task coordinate {coords[i + 1]}: offset of offset + amplitude sin phi",
                       given["offset"])
            self.reals("amplitude", extra, "parameter", units[0][2:],
                       lambda i: f"Task coordinate {coords[i + 1]}: amplitude of offset + amplitude sin phi",
                       given["amplitude"])
        self.extra = extra
        self.declare_outputs(("x_ref", "xd_ref", "xdd_ref"), units,
                             lambda i, w: f"Reference task {w} along {coords[i - 1]}")

    def configure(self):
        sense = self.parameter("sense")
        if sense == 0:
            raise ValueError("parameter sense = 0 is invalid: must be 1 (counter-clockwise) or -1 (clockwise)")
        extra = self.extra
        self.profile = Circle(self.finite_vector("center"), self.parameter("radius"),
                              self.parameter("start_angle"), sense, self.parameter("duration"),
                              self.parameter("cruise_factor"),
                              self.finite_vector("offset") if extra else (),
                              self.finite_vector("amplitude") if extra else ())
        super().configure()


class _PoseReference(_Reference):
    """Common part of the pose profiles: a pose task, and its six outputs (position, velocity,
    acceleration, quaternion, angular velocity, angular acceleration)."""

    abstract = True
    quantities = ("position", "velocity", "acceleration", "orientation", "angular velocity",
                  "angular acceleration")

    def require_pose_task(self) -> str:
        """The task's frame; a table error unless the task is a full pose."""
        task = self.description.task
        if not task.is_pose or list(task.axes) != [0, 1, 2]:
            self.table_error("trajectory", "profile", f"{self.variant} needs a pose task: [task] with the three "
                             "world axes of the position and orientation_axes")
        return task.frame

    def declare_pose_outputs(self, frame: str) -> None:
        axis = lambda i: "xyz"[i - 1]
        out = []
        for base, unit, what in (("x_ref", "m", "position"), ("xd_ref", "m/s", "velocity"),
                                 ("xdd_ref", "m/s2", "acceleration")):
            out.append(self.reals(base, 3, "output", unit, lambda i, w=what: f"Reference {w} of frame {frame}, "
                                  f"world {axis(i)}", depends=[]))
        out.append(self.reals("quat_ref", 4, "output", "1",
                              lambda i: f"Reference orientation of frame {frame}: unit quaternion component "
                                        f"{COMPONENTS[i - 1]} (x, y, z, w; frame to world)", depends=[]))
        for base, unit, what in (("omega_ref", "rad/s", "angular velocity"),
                                 ("omegad_ref", "rad/s2", "angular acceleration")):
            out.append(self.reals(base, 3, "output", unit, lambda i, w=what: f"Reference {w} of frame {frame} "
                                  f"about world {axis(i)}", depends=[]))
        self.outputs = out


class PoseLineBlock(_PoseReference):
    variant = "pose_line"
    summary = ("pose reference: the task frame's origin on a straight line by displacement, its orientation "
               "turning by rotation (about its own start axes, shortest rotation: slerp), both on one time law "
               "(LSPB of duration, or minimum time under v_max, a_max, omega_max, alpha_max), then at rest; "
               "orientation as a unit quaternion (x, y, z, w), angular rates in the world frame; outputs at "
               "time t belong to t")
    lspb = (
        Parameter("duration", "Real", "s", "Duration of the move", None, above=0.0),
        Parameter("cruise_factor", "Real", "1", "Cruise speed over the move's mean speed, in (1, 2]", 1.5,
                  above=1.0, high=2.0),
    )
    limits = (
        Parameter("v_max", "Real", "m/s", "Speed limit of the origin along the line", None, above=0.0),
        Parameter("a_max", "Real", "m/s2", "Acceleration limit of the origin along the line", None, above=0.0),
        Parameter("omega_max", "Real", "rad/s", "Angular speed limit", None, above=0.0),
        Parameter("alpha_max", "Real", "rad/s2", "Angular acceleration limit", None, above=0.0),
    )

    def declare(self):
        robot = self.robot
        frame = self.require_pose_task()
        given = dict(self.description.trajectory.parameters)
        named, given["start"] = self.start_point(given, 3, robot.fk)
        defaults = {"start_quaternion": quaternion_of(robot.rotation(robot.configuration(named)))}
        for key, length in (("start", 3), ("start_quaternion", 4), ("displacement", 3), ("rotation", 3)):
            value = given.pop(key, defaults.get(key))
            if value is None:
                self.table_error("trajectory", key, "missing")
            if not isinstance(value, list) or len(value) != length:
                self.table_error("trajectory", key, f"needs {length} values, got {value!r}")
            given[f"_{key}"] = value
        at_limits = any(p.name in given for p in self.limits)
        if at_limits and "duration" in given:
            self.table_error("trajectory", "duration", "give either duration (an LSPB time law) or the limits "
                             f"{', '.join(p.name for p in self.limits)} (minimum time), not both")
        self.scalars = self.limits if at_limits else self.lspb
        values = self.table_values("trajectory", self.scalars,
                                   {k: v for k, v in given.items() if not k.startswith("_")})
        axis = lambda i: "xyz"[i - 1]
        self.reals("start", 3, "parameter", "m", lambda i: f"Start position of frame {frame}, world {axis(i)} "
                   f"(default: at configuration {named!r})", given["_start"])
        self.reals("start_quaternion", 4, "parameter", "1",
                   lambda i: f"Start orientation of frame {frame}: unit quaternion component {COMPONENTS[i - 1]} "
                             f"(x, y, z, w; frame to world; default: at configuration {named!r})",
                   given["_start_quaternion"])
        self.reals("displacement", 3, "parameter", "m", lambda i: f"Displacement of the origin, world {axis(i)}",
                   given["_displacement"])
        self.reals("rotation", 3, "parameter", "rad",
                   lambda i: f"Rotation vector (axis times angle, at most pi) about the start frame's own "
                             f"axis {axis(i)}", given["_rotation"])
        for p in self.scalars:
            self.declare_parameter(p, values[p.name])
        self.declare_pose_outputs(frame)

    def configure(self):
        time_law = {p.name: self.parameter(p.name) for p in self.scalars}
        self.profile = PoseLine(self.finite_vector("start"), self.finite_vector("displacement"),
                                self.finite_vector("start_quaternion"), self.finite_vector("rotation"), **time_law)
        super().configure()


class PoseWaypointsBlock(_PoseReference):
    variant = "pose_waypoints"
    summary = ("pose reference through waypoints (x, y, z, qx, qy, qz, qw per row): one LSPB move per leg, the "
               "origin on a straight line and the orientation by slerp (shortest rotation), with pauses between "
               "moves; orientation as a unit quaternion (x, y, z, w), angular rates in the world frame; outputs at "
               "time t belong to t")
    settings_declared = (
        Parameter("pause", "Real", "s", "Rest between two moves", 0.0, low=0.0),
        Parameter("cruise_factor", "Real", "1", "Cruise speed over the move's mean speed, in (1, 2]", 1.5,
                  above=1.0, high=2.0),
    )

    def declare(self):
        frame = self.require_pose_task()
        self.read_waypoints(POSE_COLUMNS)
        vectors, rest = self.given({"waypoints": 0, "durations": 0})
        values = self.table_values("trajectory", self.settings_declared, rest)
        self.string_parameter("waypoints", f"Poses of frame {frame}, one row per pose ('{' '.join(POSE_COLUMNS)}': "
                              "origin in m, world; unit quaternion x, y, z, w, frame to world), rows separated "
                              "by ';'", format_matrix(vectors["waypoints"]))
        self.string_parameter("durations", "Duration of each move (s), space-separated; one per leg",
                              format_vector(vectors["durations"]))
        for p in self.settings_declared:
            self.declare_parameter(p, values[p.name])
        self.declare_pose_outputs(frame)

    def configure(self):
        self.profile = PoseWaypoints(
            parse_matrix(str(self.settings["waypoints"]), "parameter waypoints", columns=len(POSE_COLUMNS)),
            parse_vector(str(self.settings["durations"]), "parameter durations"),
            pause=self.parameter("pause"), cruise_factor=self.parameter("cruise_factor"))
        super().configure()

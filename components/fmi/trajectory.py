"""Trajectory block: the task-space reference of the robot's scenario (LSPB through waypoints)."""
from __future__ import annotations

from ..trajectory import (WaypointTrajectory, format_matrix, format_vector, parse_matrix,
                          parse_vector)
from .base import DERIVATIVE_UNITS, BlockSlave



class TrajectorySlave(BlockSlave):
    block = "trajectory"
    summary = ("task-space reference through waypoints, one LSPB move per leg (cruise speed "
               "cruise_factor x mean speed) with pauses between moves; outputs at time t belong "
               "to t (no inputs)")

    def declare(self):
        s = self.spec.scenario
        coords = self.spec.task_coordinates
        m = len(coords)
        self.string("waypoints", "Waypoints (m), one 'x y z' row per point, rows separated by ';'",
                    format_matrix(s["waypoints"]))
        self.string("durations", "Duration of each move (s), space-separated; one per leg",
                    format_vector(s["durations"]))
        self.real("pause", "parameter", "s", "Rest between two moves", s.get("pause", 0.0))
        self.real("cruise_factor", "parameter", "1",
                  "Cruise speed over the move's mean speed, in (1, 2]", s.get("cruise_factor", 1.5))
        self.has_grip = "grip_close_after_move" in s
        if self.has_grip:
            self.integer("grip_close_after_move",
                         "The gripper closes at the end of this move (1-based; 0: never)",
                         s["grip_close_after_move"])
            self.integer("grip_open_after_move",
                         "The gripper opens at the end of this move (1-based; 0: never)",
                         s["grip_open_after_move"])
        units = [DERIVATIVE_UNITS[u] for u in self.spec.task_units]
        self.x = self.reals("x_ref", m, "output", [u[0] for u in units],
                            lambda i: f"Reference TCP coordinate {coords[i - 1]}", depends=[])
        self.xd = self.reals("xd_ref", m, "output", [u[1] for u in units],
                             lambda i: f"Reference TCP velocity along {coords[i - 1]}", depends=[])
        self.xdd = self.reals("xdd_ref", m, "output", [u[2] for u in units],
                              lambda i: f"Reference TCP acceleration along {coords[i - 1]}", depends=[])
        if self.has_grip:
            self.boolean("grip", "output", "Gripper closed (carrying the piece)", depends=[])

    def initialize(self):
        m = len(self.spec.task_coordinates)
        close = open_ = 0
        if self.has_grip:
            close = int(self.other["grip_close_after_move"])
            open_ = int(self.other["grip_open_after_move"])
        self.trajectory = WaypointTrajectory(
            parse_matrix(str(self.other["waypoints"]), "parameter waypoints", columns=m),
            parse_vector(str(self.other["durations"]), "parameter durations"),
            pause=self.param("pause"),
            cruise_factor=self.param("cruise_factor"),
            grip_close_after_move=close, grip_open_after_move=open_,
        )
        self._output(self.time)

    def _output(self, t):
        r = self.r
        r[self.x], r[self.xd], r[self.xdd] = self.trajectory.evaluate(t)
        if self.has_grip:
            self.other["grip"] = self.trajectory.grip(t)

    def step(self, t, h):
        self._output(t + h)
        return True

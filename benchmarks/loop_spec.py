"""The chess-pd loop as plain numbers, for the same loop written outside robofmu (the C++ floor,
the peers of ``make bench-peers``).

Everything comes from the configured FMI-free blocks of the experiment (its FMUs' start values
and the experiment's parameters, as :class:`robofmu.system.studies.replica.InProcessDiagram` builds
them), so a change to the robot's description or the experiment reaches every peer. Only the
loop the peers implement is supported: a ``waypoints`` trajectory, the ``pitch_elbow`` IK, the
computed-torque controller and the RK4 plant.

    .venv/bin/python benchmarks/loop_spec.py [--experiment chess-pd] [--fmus fmus] OUT.json
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

import robofmu.components  # noqa: F401  (the installed copy before any bundled one)


def spec(experiment: str = "chess-pd", fmu_dir: str | Path = "fmus") -> dict:
    """The loop's numbers (SI units), JSON-compatible.

    Keys: ``urdf`` (absolute path), ``tcp_frame``, ``gravity`` (3-vector, m/s2), ``h`` and
    ``stop`` (s), ``n_steps``; ``trajectory``: ``waypoints`` (k+1, 3), ``durations`` (k,),
    ``pause``, ``cruise_factor``, ``breakpoints`` (sorted; times within ``snap_tolerance`` of one
    are evaluated at it), ``grip_close``, ``grip_open`` (s; the gripper is closed on
    [grip_close, grip_open)); ``ik``: ``a1``..``a4`` (m), ``tool_pitch`` (rad), ``elbow_sign``
    (+1 up, -1 down), ``qd_limit`` (n,); ``controller``: ``kp``, ``kd``, ``ki``,
    ``payload_mass`` (kg, the controller's belief while gripping); ``plant``: ``q0``, ``qd0``,
    ``payload_mass`` (kg, carried while gripping), ``max_substep`` (s); ``payload``: the
    ``joint`` (1-based Pinocchio joint index) and ``lever`` (m, the point mass's position in
    that joint's frame).
    """
    from robofmu.components.profile import SNAP_TOLERANCE
    from robofmu.components.trajectory import WaypointTrajectory
    from robofmu.system.plan import step_count
    from robofmu.system.experiment import load
    from robofmu.system.studies.replica import InProcessDiagram

    system = load(experiment, fmu_dir=fmu_dir)
    diagram = InProcessDiagram(system)
    diagram.configure()
    kinds = {block.kind: block for block in diagram.blocks.values()}
    trajectory, ik, controller, plant = (kinds[k] for k in ("trajectory", "ik", "controller", "plant"))
    profile = trajectory.profile
    if not isinstance(profile, WaypointTrajectory) or ik.solver.kind != "pitch_elbow":
        raise ValueError(f"{experiment}: the peers implement a waypoints trajectory and the pitch_elbow IK only")
    robot = plant.robot
    description = robot.description
    solver = ik.solver
    h = float(system.step)
    return {
        "experiment": experiment,
        "urdf": str(Path(description.urdf).resolve()),
        "tcp_frame": description.task.frame,
        "gravity": (robot.gravity * np.asarray(description.gravity_direction)).tolist(),
        "h": h,
        "stop": float(system.stop_time),
        "n_steps": step_count(0.0, system.stop_time, h),
        "trajectory": {
            "waypoints": profile.waypoints.tolist(),
            "durations": profile.durations.tolist(),
            "pause": profile.pause,
            "cruise_factor": profile.cruise_factor,
            "breakpoints": np.asarray(profile.breakpoints).tolist(),
            "snap_tolerance": SNAP_TOLERANCE,
            "grip_close": float(profile.grip_close_time),
            "grip_open": float(profile.grip_open_time),
        },
        "ik": {"a1": solver.a1, "a2": solver.a2, "a3": solver.a3, "a4": solver.a4,
               "tool_pitch": solver.tool_pitch, "elbow_sign": solver._sign,
               "qd_limit": ik.qd_limit.tolist()},
        "controller": {"kp": controller.law.kp, "kd": controller.law.kd, "ki": controller.law.ki,
                       "payload_mass": controller.payload_mass},
        "plant": {"q0": plant.plant.q.tolist(), "qd0": plant.plant.qd.tolist(),
                  "payload_mass": plant.plant.payload_mass, "max_substep": plant.plant.max_substep},
        "payload": {"joint": int(robot._payload_joint), "lever": robot._payload_lever.tolist()},
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", help="JSON file to write")
    parser.add_argument("--experiment", default="chess-pd")
    parser.add_argument("--fmus", default="fmus")
    args = parser.parse_args(argv)
    Path(args.out).write_text(json.dumps(spec(args.experiment, args.fmus), indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

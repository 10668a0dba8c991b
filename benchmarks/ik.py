"""Benchmark: Newton-Raphson IK beside the closed form, per communication step along each task.

For every robot with an IK, its reference task (the trajectory block sampled at 1 ms) is solved
step by step at position, velocity and acceleration level (``IKSolver.solve``) by every solver
that applies to the robot: the closed forms whose geometry check accepts it and Newton-Raphson
(warm-started from the previous step's solution, holding the closed form's joint combinations
where it has some, as chess's tool pitch). A solver applies if it agrees with the robot's own
solver at the task's first point. The IK block itself (FMI-free logic and through FMI) is timed
on the same inputs, as the master drives it.

    make bench            # or: .venv/bin/python benchmarks/ik.py [--fmus DIR] [ROBOT ...]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

import robofmu.components  # noqa: F401  (the installed copy before any bundled one)
from robofmu.components.blocks import make_block
from robofmu.components.ik import make_solver, solver_class, solvers
from robofmu.components.robots import available, load_description, load_model
from robofmu.system.fmu import FMUInstance

H = 1e-3
NEWTON = "newton_raphson"


#: The IK's task inputs, in the order of ``IKSolver.solve``'s arguments; a pose task's last three.
TASK_INPUTS = ("x_ref", "xd_ref", "xdd_ref")
POSE_INPUTS = ("quat_ref", "omega_ref", "omegad_ref")


def task_inputs(robot: str) -> tuple[str, ...]:
    """The IK block's inputs for the robot's task: position, or pose (a task with orientation axes)."""
    return TASK_INPUTS + (POSE_INPUTS if load_model(robot).orientation_axes else ())


def task(robot: str, steps: int | None = None) -> list[tuple[np.ndarray, ...]]:
    """The robot's reference task at 1 ms (its first ``steps`` points): per step, the arguments of
    ``IKSolver.solve``, ``(x, xd, xdd)`` or for a pose task ``(x, xd, xdd, quaternion, omega, omegad)``."""
    trajectory = make_block(robot, "trajectory")
    trajectory.configure()
    names = task_inputs(robot)
    rows = []
    for t in np.arange(0.0, trajectory.nominal_stop_time() + H / 2, H)[:steps]:
        trajectory.output(t)
        rows.append(tuple(np.array(trajectory.get(name), dtype=float) for name in names))
    return rows


def applicable(robot: str, samples: list) -> dict:
    """{solver kind: solver} of every solver that agrees with the robot's own at the first point."""
    model = load_model(robot)
    own = make_solver(model)
    reference = own.solve(*samples[0])[0]
    own.start_from(None)
    found = {own.kind: own}
    for kind in solvers():
        if kind in found:
            continue
        try:
            if kind == NEWTON:
                solver = solver_class(kind)(load_model(robot), constraint_rows=own.constraint_rows,
                                            constraint_values=own.constraint_values, q_guess=tuple(reference))
            else:
                solver = solver_class(kind)(load_model(robot))
            if np.allclose(solver.solve(*samples[0])[0], reference, atol=1e-9):
                found[kind] = solver
        except Exception:        # the solver's geometry check refuses this robot, or no solution
            continue
    return found


def per_step(solver, samples: list, repeats: int) -> tuple[float, float]:
    """(best seconds per step, mean iterations per step) solving the task, warm-started."""
    best, iterations = float("inf"), 0.0
    for _ in range(repeats):
        solver.start_from(None)
        previous = None
        count = 0.0
        t0 = time.perf_counter()
        for inputs in samples:
            solver.start_from(previous)
            previous, _, _ = solver.solve(*inputs)
            count += solver.report.get("iterations", 0.0)
        best = min(best, (time.perf_counter() - t0) / len(samples))
        iterations = count / len(samples)
    return best, iterations


def block_per_step(robot: str, path: Path, samples: list, repeats: int) -> tuple[float, float]:
    """(direct, through FMI) best seconds per step of the robot's IK block along the task."""
    logic = make_block(robot, "ik")
    logic.configure()
    names = task_inputs(robot)
    slots = np.concatenate([np.arange(logic.slot(b).start, logic.slot(b).stop) for b in names])
    flat = np.array([np.concatenate(inputs) for inputs in samples])

    def direct():
        logic.configure()
        for k, row in enumerate(flat):
            logic.values[slots] = row
            logic.output(k * H)
            logic.advance(k * H, H)

    fmu = FMUInstance(path, "ik")
    try:
        fmu.initialize()
        vin = fmu.vrs(*names)
        vout = [v.valueReference for v in fmu.md.modelVariables if v.causality == "output" and v.type == "Real"]
        slave = fmu.slave

        def through_fmi():
            for k, row in enumerate(flat):
                slave.setReal(vin, list(row))
                slave.getReal(vout)
                slave.doStep(k * H, H)

        t_direct = min(_timed(direct) for _ in range(repeats)) / len(flat)
        t_fmi = _timed(through_fmi) / len(flat)         # one pass: time runs forward only
    finally:
        fmu.close()
    return t_direct, t_fmi


def _timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("robots", nargs="*", help="robots (default: every described robot with an IK)")
    parser.add_argument("--fmus", default="fmus", help="FMU root folder (default fmus)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--steps", type=int, help="the first STEPS points of each task (default: all)")
    parser.add_argument("--quick", action="store_true", help="a smoke test: 20 points, one repeat")
    args = parser.parse_args(argv)
    if args.quick:
        args.steps, args.repeats = 20, 1
    robots = args.robots or [r for r in available() if "ik" in load_description(r).blocks]
    print(f"{'robot':<12}{'solver':<16}{'us/step':>9}{'iterations':>12}{'vs closed form':>16}")
    print("-" * 65)
    blocks = []
    for robot in robots:
        samples = task(robot, args.steps)
        found = applicable(robot, samples)
        times = {kind: per_step(solver, samples, args.repeats) for kind, solver in found.items()}
        closed = [t for kind, (t, _) in times.items() if kind != NEWTON]
        for kind, (seconds, iterations) in times.items():
            ratio = f"{seconds / min(closed):>16.2f}" if closed else f"{'-':>16}"
            print(f"{robot:<12}{kind:<16}{seconds * 1e6:>9.1f}{iterations:>12.2f}{ratio}")
        path = Path(args.fmus) / robot / "ik.fmu"
        if path.is_file():
            blocks.append((robot, load_description(robot).ik.kind, *block_per_step(robot, path, samples, args.repeats)))
    print(f"\nsolver.solve (position, velocity, acceleration) per 1 ms step along each robot's "
          f"reference task, best of {args.repeats}; Newton-Raphson warm-started")
    if blocks:
        print(f"\n{'robot':<12}{'IK block':<16}{'direct (us)':>13}{'through FMI (us)':>18}{'ratio':>8}")
        print("-" * 67)
        for robot, kind, t_direct, t_fmi in blocks:
            print(f"{robot:<12}{kind:<16}{t_direct * 1e6:>13.1f}{t_fmi * 1e6:>18.1f}{t_fmi / t_direct:>8.2f}")
        print("\nthe robot's IK block along its task: set inputs, get outputs, doStep")
    return 0


if __name__ == "__main__":
    sys.exit(main())

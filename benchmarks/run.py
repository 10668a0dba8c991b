"""Benchmark: the FMI cost of one communication step per block, beside the same logic called directly.

For each chess block, one communication step is what a master does at every point: set the
inputs (one batched call per type), doStep, get the outputs. The direct column runs the same
FMI-free logic (robofmu.components) on the same data. Times are the best of several repeats.

    make bench            # or: .venv/bin/python benchmarks/run.py [--fmus DIR] [--steps N]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

import robofmu.components  # noqa: F401  (the installed copy before any bundled one)
from robofmu.components.control import ComputedTorque
from robofmu.components.ik import make_ik
from robofmu.components.plant import Plant
from robofmu.components.robot import Robot, load_spec
from robofmu.components.trajectory import WaypointTrajectory
from robofmu.system.fmu import Block

H = 1e-3


def best_of(fn, steps: int, repeats: int) -> float:
    """Best wall time per step (s) of ``fn(k)`` over ``steps`` calls, best of ``repeats``."""
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        for k in range(steps):
            fn(k)
        best = min(best, (time.perf_counter() - t0) / steps)
    return best


def cases(fmu_dir: Path):
    spec = load_spec("chess")
    s = spec.scenario
    robot = Robot(spec)
    traj = WaypointTrajectory.from_scenario(s)
    ik = make_ik(robot)
    x = [np.array(v) for v in traj.evaluate(2.0)]
    q, qd, qdd = ik.solve(*x)
    xs = np.concatenate(x).tolist()

    # trajectory: no inputs; outputs x_ref, xd_ref, xdd_ref, grip
    tr = Block(fmu_dir / "trajectory.fmu", "trajectory")
    tr.initialize()
    v_tr = tr.vrs("x_ref", "xd_ref", "xdd_ref")
    v_grip = tr.vrs("grip")

    def tr_fmi(k):
        tr.slave.doStep(k * H, H)
        tr.slave.getReal(v_tr)
        tr.slave.getBoolean(v_grip)

    def tr_direct(k):
        traj.evaluate((k + 1) * H)
        traj.grip((k + 1) * H)

    yield "trajectory", tr_direct, tr_fmi, tr

    ikb = Block(fmu_dir / "ik.fmu", "ik")
    ikb.initialize()
    v_in, v_out, v_r = ikb.vrs("x_ref", "xd_ref", "xdd_ref"), ikb.vrs("q_ref", "qd_ref", "qdd_ref"), ikb.vrs("reachable")

    def ik_fmi(k):
        ikb.slave.setReal(v_in, xs)
        ikb.slave.getReal(v_out)
        ikb.slave.getBoolean(v_r)
        ikb.slave.doStep(k * H, H)

    def ik_direct(k):
        ik.solve(*x)

    yield "ik", ik_direct, ik_fmi, ikb

    ct = Block(fmu_dir / "controller.fmu", "controller")
    ct.initialize()
    law = ComputedTorque(Robot(spec), 400.0, 20.0)
    v_cin, v_tau, v_g = ct.vrs("q_ref", "qd_ref", "qdd_ref", "q", "qd"), ct.vrs("tau"), ct.vrs("grip")
    cin = np.concatenate([q, qd, qdd, q + 1e-3, qd]).tolist()

    def ct_fmi(k):
        ct.slave.setReal(v_cin, cin)
        ct.slave.setBoolean(v_g, [False])
        ct.slave.getReal(v_tau)
        ct.slave.doStep(k * H, H)

    def ct_direct(k):
        law.torque(q, qd, qdd, q + 1e-3, qd)
        law.advance(q, q + 1e-3, H)

    yield "controller", ct_direct, ct_fmi, ct

    pl = Block(fmu_dir / "plant.fmu", "plant")
    pl.initialize()
    plant = Plant(Robot(spec), q, np.zeros(4), payload_mass=0.03)
    tau = robot.gravity_torque(q)
    v_tau_in, v_pg, v_y = pl.vrs("tau"), pl.vrs("grip"), pl.vrs("q", "qd")
    taus = tau.tolist()

    def pl_fmi(k):
        pl.slave.setReal(v_tau_in, taus)
        pl.slave.setBoolean(v_pg, [False])
        pl.slave.doStep(k * H, H)
        pl.slave.getReal(v_y)

    def pl_direct(k):
        plant.set_grip(False)
        plant.step(tau, H, k * H)

    yield "plant", pl_direct, pl_fmi, pl


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fmus", default="fmus/chess", help="folder of the chess FMUs (default fmus/chess)")
    parser.add_argument("--steps", type=int, default=2000, help="communication steps per repeat")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    fmu_dir = Path(args.fmus)
    if not (fmu_dir / "plant.fmu").is_file():
        print(f"no FMUs in {fmu_dir}: run `make fmus` first", file=sys.stderr)
        return 2
    print(f"One communication step (h = {H * 1e3:g} ms): set inputs, doStep, get outputs; "
          f"best of {args.repeats} x {args.steps} steps\n")
    header = f"{'block':<12}{'direct (us)':>13}{'FMI (us)':>11}{'FMI/direct':>12}{'overhead (us)':>15}"
    print(header)
    print("-" * len(header))
    for name, direct, fmi, block in cases(fmu_dir):
        d = best_of(direct, args.steps, args.repeats)
        f = best_of(fmi, args.steps, args.repeats)
        print(f"{name:<12}{d * 1e6:>13.1f}{f * 1e6:>11.1f}{f / d:>12.2f}{(f - d) * 1e6:>15.1f}")
        block.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Benchmark: where one block-step of an experiment's blocks goes — the block's logic, robofmu's
FMU-side wrapper, and the FMI boundary — and how many FMI calls the master makes per step.

For each block of the experiment (default chess-pd), one communication step as the master
makes it (set the wired Real inputs, get the outputs it reads, doStep), fed with the block's
start values, timed three ways in this process:

- ``logic``: the FMI-free block (``robofmu.components.blocks``): set inputs, output, advance;
- ``in-process slave``: robofmu's pythonfmu slave class (``BlockSlave``) called directly from
  Python as robofmu's export library calls it on its fast path (the values written in place,
  ``_fast_refresh`` before reading outputs, ``_fast_step``; the library's own C share left to
  the boundary): logic + the FMU-side wrapper;
- ``through FMI``: the built FMU, called through the master's own bound functions
  (``ctypes.PyDLL``, preallocated arrays): logic + wrapper + the boundary (ctypes, pythonfmu's
  C++ layer, robofmu's export library).

``wrapper`` is the second minus the first, ``boundary`` the third minus the second; the three
take turns, best of ``--repeats``.

    make bench            # or: .venv/bin/python benchmarks/split.py [--experiment chess-pd] [--fmus DIR]
"""
from __future__ import annotations

import argparse
import ctypes
import sys

import numpy as np

import robofmu.components  # noqa: F401  (the installed copy before any bundled one)
from robofmu.components.blocks import make_block
from robofmu.components.fmi.base import BlockSlave
from robofmu.components.fmi.contract import FAST_CHECK
from robofmu.components.fmi.quiet import quietly
from robofmu.system import experiment
from robofmu.system.fmu import FMUInstance
from robofmu.system.exchange import Fmi2Functions
from robofmu.system.master import Master
from run import H, best_of          # benchmarks/run.py, beside this file


def ports(master: Master, name: str):
    """The value references the master sets (Real inputs wired) and gets (outputs read) on ``name``."""
    get_real, get_boolean, early, late = master.ports[name]
    inputs = list(early.real.references)[:early.real.count] + list(late.real.references)[:late.real.count]
    return inputs, list(get_real.references)[:get_real.count], list(get_boolean.references)[:get_boolean.count]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--experiment", default="chess-pd")
    parser.add_argument("--fmus", default="fmus")
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=9)
    parser.add_argument("--quick", action="store_true", help="a smoke test: 20 steps, one repeat")
    args = parser.parse_args(argv)
    if args.quick:
        args.steps, args.repeats = 20, 1
    system = experiment.load(args.experiment, fmu_dir=args.fmus)
    robot = system.extra["robot"]
    master = Master(system)
    master.check()
    master._layout()
    rows, calls = [], 0
    for name in master.order:
        node = master.nodes[name]
        kind = node.path.stem
        vin, vout, vbool = ports(master, name)
        starts = {v.valueReference: float(v.start) if v.start is not None else 0.0
                  for v in node.model_description.modelVariables if v.type == "Real"}
        values = [starts[vr] for vr in vin]
        calls += bool(vin) + bool(vout) + bool(vbool) + 1

        logic = make_block(robot, kind)
        logic.configure()
        clock = [0]

        def direct(k, logic=logic, slots=np.array(vin, dtype=np.intp), start=np.array(values), clock=clock):
            t = clock[0] * H
            logic.values[slots] = start
            logic.output(t)
            logic.advance(t, H)
            clock[0] += 1

        cls = type(f"bench_{robot}_{kind}", (BlockSlave,), {"robot_name": robot, "block_kind": kind})
        slave = cls(instance_name=name)
        slave.setup_experiment(0.0)
        slave.enter_initialization_mode()
        slave.exit_initialization_mode()
        slave_clock = [0]

        slots_in, start_in = np.array(vin, dtype=np.intp), np.array(values)

        # The slave as robofmu's export library calls it on its fast path (robofmu_fmi2.c); the
        # library's own share (copying values in and out, saving them before a refresh, checking
        # the outputs, NumPy's error state) is C, counted in the boundary: here only the part
        # without which the slave would not take its usual way (the outputs current after a
        # checked refresh), NumPy's error state set once around all steps (quietly).
        slave._output_now, slave._advance_now = slave.logic.output, slave.logic.advance

        def in_process(k, slave=slave, clock=slave_clock, shared=slave._shared, held=slave.values):
            if vin:                       # fmi2SetReal: the values written, the outputs stale
                held[slots_in] = start_in
                shared.dirty = 1
            if slave._fast_refresh() & FAST_CHECK:       # fmi2GetReal / fmi2GetBoolean
                shared.dirty = 0                          # the library found them finite
            slave._fast_step(clock[0] * H, H)     # fmi2DoStep
            clock[0] += 1

        fmu = FMUInstance(node.path, name)
        fmu.initialize()
        functions = Fmi2Functions(fmu.slave)
        c_in = (ctypes.c_uint * max(1, len(vin)))(*vin)
        c_values = (ctypes.c_double * max(1, len(vin)))(*values)
        c_out = (ctypes.c_uint * max(1, len(vout)))(*vout)
        c_read = (ctypes.c_double * max(1, len(vout)))()
        c_bool = (ctypes.c_uint * max(1, len(vbool)))(*vbool)
        c_bools = (ctypes.c_int * max(1, len(vbool)))()
        fmi_clock = [0]

        # the arguments of their C types converted once into ctypes parameters, as the master
        # passes them (Fmi2Functions); the time an fmi2Real set per step
        c = functions.argument
        set_in = (c, ctypes.byref(c_in), ctypes.c_size_t.from_param(len(vin)), ctypes.byref(c_values))
        get_out = (c, ctypes.byref(c_out), ctypes.c_size_t.from_param(len(vout)), ctypes.byref(c_read))
        get_bool = (c, ctypes.byref(c_bool), ctypes.c_size_t.from_param(len(vbool)), ctypes.byref(c_bools))
        t_arg = ctypes.c_double()
        step = (c, t_arg, ctypes.c_double.from_param(H), ctypes.c_int.from_param(1))

        def through_fmi(k, f=functions, clock=fmi_clock):
            if vin:
                f.set_real(*set_in)
            f.get_real(*get_out)
            if vbool:
                f.get_boolean(*get_bool)
            t_arg.value = clock[0] * H
            if f.do_step(*step) > 1:
                raise RuntimeError(f"{name}: fmi2DoStep failed: {fmu.messages[-1:]}")
            clock[0] += 1

        try:
            t_logic, t_slave, t_fmi = (float("inf"),) * 3
            for _ in range(args.repeats):        # taking turns: load on the machine hits all three alike
                t_logic = min(t_logic, best_of(direct, args.steps, 1))
                t_slave = min(t_slave, quietly(best_of, in_process, args.steps, 1))
                t_fmi = min(t_fmi, best_of(through_fmi, args.steps, 1))
        finally:
            fmu.close()
        rows.append((name, t_logic, t_slave - t_logic, t_fmi - t_slave, t_fmi, bool(vin) + bool(vout) + bool(vbool) + 1))
    print(f"\n## Where a step goes: {args.experiment} (best of {args.repeats} x {args.steps} steps, µs per step)\n")
    print("| block | logic | FMU-side wrapper | FMI boundary | total | FMI calls |")
    print("|---|---|---|---|---|---|")
    for name, logic, wrapper, boundary, total, n in rows:
        print(f"| {name} | {logic * 1e6:.1f} | {wrapper * 1e6:.1f} | {boundary * 1e6:.1f} | {total * 1e6:.1f} | {n} |")
    total = [sum(r[k] for r in rows) for k in range(1, 5)]
    print(f"| all | {total[0] * 1e6:.1f} | {total[1] * 1e6:.1f} | {total[2] * 1e6:.1f} | {total[3] * 1e6:.1f} | {calls} |")
    print(f"\nFMU-side wrapper: {total[1] / len(rows) * 1e6:.1f} µs per block-step on average "
          f"({len(rows)} blocks); {calls} FMI calls per communication step (Boolean inputs only when they change).")
    return 0


if __name__ == "__main__":
    sys.exit(main())

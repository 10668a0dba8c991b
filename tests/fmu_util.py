"""Helpers for tests that drive the FMUs through fmpy (via robofmu.system.fmu.Block).

- :func:`open_block`: one instantiated, initialized FMU;
- :func:`robot_blocks`: ``(robot, block)`` test parameters over the whole collection;
- :class:`Loop`: an experiment's diagram stepped by hand, for tests that need the blocks between
  two steps (FMU state). Its topology is the experiment's (``robofmu.system.check.plan``: the
  wires and the evaluation order), nothing is wired here; a test that only needs a loop run
  drives :class:`robofmu.system.master.Master` instead.
"""
from __future__ import annotations

from pathlib import Path

import pytest

from robofmu.components.robots import available, load_description
from robofmu.system import experiment
from robofmu.system.check import plan
from robofmu.system.fmu import Block


def open_block(fmu_dir, block, name=None, parameters=None, start_time=0.0):
    """Instantiate and initialize ``fmu_dir/<block>.fmu``."""
    b = Block(Path(fmu_dir) / f"{block}.fmu", name or block)
    b.initialize(start_time, parameters)
    return b


def robot_blocks(kinds=None, robots=None) -> list:
    """``pytest.param(robot, block, id="robot-block")`` for every block of every described robot
    (optionally only blocks of ``kinds`` / robots in ``robots``), in description order."""
    params = []
    for robot in available() if robots is None else robots:
        for block in load_description(robot).blocks:
            if kinds is None or block in kinds:
                params.append(pytest.param(robot, block, id=f"{robot}-{block}"))
    return params


class Loop:
    """The diagram of an experiment, exchanged and stepped by hand like the master does.

    At each communication point the blocks are evaluated in the plan's order (Gauss-Seidel): a
    block gets the inputs produced by blocks evaluated before it, then its outputs are read;
    inputs from blocks evaluated later are set after the pass. Then every block steps.

    Parameters
    ----------
    name : str
        Experiment name (``system/experiments/<name>.toml``).
    fmu_root : Path
        Root of the FMU collection.
    parameters : dict, optional
        ``{instance: {parameter: value}}`` over the experiment's own.
    """

    def __init__(self, name: str, fmu_root, parameters: dict | None = None):
        system = experiment.load(name, fmu_dir=fmu_root)
        for instance, values in (parameters or {}).items():
            system.block(instance).parameters.update(values)
        self.plan = plan(system)
        self.order = list(self.plan.order)
        self.blocks: dict[str, Block] = {}
        try:
            for instance in self.order:
                node = self.plan.nodes[instance]
                b = Block(node.path, instance)
                self.blocks[instance] = b
                b.initialize(0.0, node.spec.parameters)
        except Exception:
            self.close()
            raise
        rank = {instance: k for k, instance in enumerate(self.order)}
        self._outputs = {}
        for instance in self.order:
            variables = self.plan.nodes[instance].variables
            reals = [v.name for v in variables.values() if v.causality == "output" and v.type == "Real"]
            booleans = [v.name for v in variables.values() if v.causality == "output" and v.type == "Boolean"]
            self._outputs[instance] = (reals, [variables[n].valueReference for n in reals],
                                       booleans, [variables[n].valueReference for n in booleans])
        links = self.plan.links
        self._early = {i: [l for l in links if l.target == i and rank[l.source] < rank[i]] for i in self.order}
        self._late = {i: [l for l in links if l.target == i and rank[l.source] >= rank[i]] for i in self.order}
        self.t = 0.0

    def __getitem__(self, instance: str) -> Block:
        return self.blocks[instance]

    def _set(self, instance: str, links, signals: dict) -> None:
        block = self.blocks[instance]
        variables = self.plan.nodes[instance].variables
        reals = [l for l in links if variables[l.input].type == "Real"]
        if reals:
            block.set_real([variables[l.input].valueReference for l in reals],
                           [signals[f"{l.source}.{l.output}"] for l in reals])
        for l in links:
            if variables[l.input].type != "Real":
                block.set(l.input, signals[f"{l.source}.{l.output}"])

    def exchange(self) -> dict:
        """Evaluate the diagram at the current point; every output by ``instance.variable``."""
        signals = {}
        for instance in self.order:
            self._set(instance, self._early[instance], signals)
            reals, real_vrs, booleans, boolean_vrs = self._outputs[instance]
            block = self.blocks[instance]
            if reals:
                signals.update(zip((f"{instance}.{n}" for n in reals), block.get_real(real_vrs)))
            if booleans:
                values = block.slave.getBoolean(boolean_vrs)
                signals.update(zip((f"{instance}.{n}" for n in booleans), (bool(v) for v in values)))
        for instance in self.order:
            self._set(instance, self._late[instance], signals)
        return signals

    def step(self, h: float) -> dict:
        """Exchange at t, then doStep(t, h) on every block; returns the outputs at t."""
        out = self.exchange()
        for instance in self.order:
            self.blocks[instance].do_step(self.t, h)
        self.t += h
        return out

    def get_states(self) -> dict:
        return {instance: b.get_state() for instance, b in self.blocks.items()}

    def set_states(self, states: dict, t: float) -> None:
        for instance, state in states.items():
            self.blocks[instance].set_state(state)
        self.t = t

    def close(self) -> None:
        for b in self.blocks.values():
            b.close()

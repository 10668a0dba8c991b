"""Run an SSP package (:func:`~robofmu.system.interop.ssp.export_ssp`) with fmpy.ssp (fmpy 0.3.32).

What ``fmpy.ssp.simulation.simulate_ssp`` does, and how :func:`run_ssp_fmpy` copes:
    - Reads and schema-validates the SSD, parses ParameterBindings (inline and ``.ssv``), but
      **never applies them**: only a ``parameter_set`` argument is applied (before
      fmi2EnterInitializationMode, names ``component.variable``). :func:`run_ssp_fmpy` collects
      the bindings of the SSD itself and passes them as that parameter set, with typed values
      (fmpy sets a Boolean as ``value != 0.0``, so the string ``"false"`` would become true).
      String parameters cannot be set by fmpy.ssp at all (``set_value`` raises): refused here.
    - Master algorithm: Jacobi. At every step each component gets the values its input
      connectors received at the end of the previous step, does its step, and its outputs are
      read *after* the step; then all connections are applied at once. There is **no exchange
      at initialization**: connector values start at 0.0, so the first step runs with every
      connected input 0 (the plant gets tau = 0: one step of free fall; ``ik`` gets x = 0,
      outside its workspace, and holds its start solution with zero velocity and acceleration,
      warning once), the second feeds the plant the controller's torque for all-zero inputs,
      N(0, 0). From the third step on the exchange is libcosim's (one step of delay through
      each feedthrough block).
    - Time is accumulated (``time += h``): after 1500 steps of 1 ms it is 1.4999999999999456,
      so a block evaluated at a discontinuity (the trajectory's acceleration at a move
      boundary or blend) may see the other side of it for one step.
    - An input connector without a connection breaks ``get_connections``: it is wired to the
      source of the input connector examined before it (or fails with UnboundLocalError if
      there is none), and every connected-or-not input connector would be set at every step
      (0 unless connected). :func:`export_ssp` therefore declares connectors for the outputs and
      the *wired* inputs only (SSP requires only connectors used by connections); unwired inputs
      keep their start values in both tools. :func:`run_ssp_fmpy` refuses an SSD that has any.
    - Records only connector values, one row per step *after* the step, labelled with the
      time *before* it (the row labelled t holds the values at t + h), and no row for the start
      time; the loop runs ``while time < stop_time`` with ``time += h`` accumulated. The runner
      asks for ``stop_time - h/2`` (exactly n steps) and relabels: its Result has rows at
      t0 + h .. t0 + n h.
    - Every run extracts the package and each FMU again (new folders, deleted after the run) and
      frees its instances, which unloads its copies of the binaries: runs one after the other
      in one process are independent, and give identical results.

The runner registers :func:`robofmu.system.interop.libcosim.guard_pythonfmu_exit`: pythonfmu 0.7.0's
export library writes into freed memory when a process that used it exits (sometimes an abort or
a segfault after the last line of a script that ran two simulations); see system/interop/libcosim.py.
"""
from __future__ import annotations

import time as _time
from pathlib import Path

import numpy as np

from robofmu.system.diagram import coerce, select
from robofmu.system.plan import step_count
from robofmu.system.result import Result


def _fmpy_parameter_set(ssd):
    """The parameter bindings of every component, as one fmpy ParameterSet with typed values."""
    from fmpy.ssp.ssd import Parameter, ParameterSet, find_components

    components = find_components(ssd.system)
    names = [c.name for c in components]
    out = ParameterSet(name="bindings")
    for comp in components:
        for binding in comp.parameterBindings:
            if binding.prefix or binding.parameterMapping:
                raise NotImplementedError(f"{comp.name}: parameter binding with a prefix or a mapping")
            if not binding.parameterValues:
                continue
            pset = binding.parameterValues[0]     # as libcosim: the first set of a binding
            for p in pset.parameters:
                if p.type not in ("Real", "Integer", "Boolean"):
                    raise NotImplementedError(f"{comp.name}.{p.name}: fmpy.ssp cannot set a {p.type} parameter")
                value = coerce(p.type, p.value, f"{comp.name}.{p.name}")
                out.parameters.append(Parameter(name=f"{comp.name}.{p.name}", type=p.type, value=value))
    # fmpy matches a parameter to a component by string prefix: "plant2.x" also starts with "plant"
    # (element_names makes such pairs: plant_1, plant_1_2), so it would set plant2's x on plant too
    clash = [(a, p.name.split(".", 1)[0]) for p in out.parameters for a in names
             if p.name.startswith(a) and not p.name.startswith(f"{a}.")]
    if clash:
        raise NotImplementedError(f"fmpy.ssp would mix up the parameters of components {clash[0]}")
    return out


def run_ssp_fmpy(path: str | Path, stop_time: float, step: float, start_time: float = 0.0,
                 record: list[str] | None = None) -> Result:
    """Simulate an SSP with ``fmpy.ssp.simulation.simulate_ssp`` (Jacobi, see the module notes).

    Parameter bindings of the SSD are applied (fmpy would ignore them) as start values before
    initialization. Returns a :class:`~robofmu.system.result.Result` with the output connectors
    (``instance.variable``, Booleans as 0/1) matching ``record`` (fnmatch patterns; default
    all), at t0 + h .. t0 + n h (fmpy records no row for the start time).
    """
    from fmpy.ssp.simulation import simulate_ssp
    from fmpy.ssp.ssd import find_components, read_ssd

    from robofmu.system.interop.libcosim import guard_pythonfmu_exit       # ctypes only: libcosimpy is not needed

    guard_pythonfmu_exit()
    path = Path(path)
    n = step_count(start_time, stop_time, step)
    ssd = read_ssd(str(path))
    connected = {(c.endElement, c.endConnector) for c in ssd.system.connections}
    loose = [f"{comp.name}.{con.name}" for comp in find_components(ssd.system) for con in comp.connectors
             if con.kind == "input" and (comp.name, con.name) not in connected]
    if loose:
        raise ValueError(f"{path.name}: fmpy.ssp cannot run an SSD with unconnected input connectors "
                         f"({', '.join(loose)}): it wires each to the source of the input before it, "
                         "or fails; remove them (unwired inputs then keep their start values)")
    outputs = {f"{comp.name}.{con.name}" for comp in find_components(ssd.system)
               for con in comp.connectors if con.kind == "output"}
    parameters = _fmpy_parameter_set(ssd)
    wall = _time.perf_counter()
    # fmpy loops `while time < stop_time: ...; time += h`: ask for half a step less than the
    # stop time so that accumulated rounding can neither add nor drop a step
    rows = simulate_ssp(str(path), start_time=start_time, stop_time=start_time + (n - 0.5) * step,
                        step_size=step, parameter_set=parameters if parameters.parameters else None)
    wall = _time.perf_counter() - wall
    if len(rows) != n:
        raise RuntimeError(f"fmpy.ssp made {len(rows)} steps, expected {n}")
    names = [c for c in rows.dtype.names[1:] if c in outputs]
    keep = [names[k] for k in select(names, record)]
    data = np.column_stack([rows[c].astype(float) for c in keep]) if keep else np.zeros((n, 0))
    return Result(start_time + step * np.arange(1, n + 1), keep, data,
                  {"tool": "fmpy.ssp", "algorithm": "jacobi (no initial exchange)", "step": step,
                   "wall_time": wall})

"""The same diagram in other FMI tools, measured against the master.

For one experiment :func:`compare_tools` runs

- the diagram as one FMU container (:mod:`robofmu.system.interop.container`, run by fmpy), in sequential
  mode against the master's Gauss-Seidel run and in parallel mode against its Jacobi run: every
  recorded output compared (but the Newton-Raphson IK's ``iterations``, a solver count that the
  container's extra read after the step changes: see :mod:`~robofmu.system.interop.container`);
- the SSP export (:mod:`robofmu.system.interop.ssp`) in libcosim and in ecos, where installed (the dev
  extra), against the master's Jacobi run: the joint positions (the experiment's ``q`` role)
  compared, a signal both tools record at the master's moments (ecos reads a feedthrough
  block's outputs one step later: see :func:`~robofmu.system.interop.ecos.run_ssp_ecos`).

Each comparison is the largest absolute difference over the run, with the unit of the compared
signals.
"""
from __future__ import annotations

import importlib.util
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robofmu.system.diagram import System
from robofmu.system.defaults import ALGORITHMS
from robofmu.system.master import Master
from robofmu.system.result import Result

__all__ = ["ToolRun", "compare_tools"]


@dataclass
class ToolRun:
    """One tool's run of a diagram beside the master's.

    Attributes
    ----------
    tool : str
        E.g. ``"container (fmpy)"``, ``"libcosim"``.
    algorithm : str
        The master algorithm it is compared with (``"gauss-seidel"`` or ``"jacobi"``).
    compared : str
        What is compared: ``"every output"`` or a signal's name (``"plant.q"``).
    difference : float
        Largest |tool - master| over the run and the compared signals (NaN: not run).
    seconds : float
        Wall time of the tool's run (s): loading the FMUs included, building the container or
        exporting the SSP not.
    note : str
        Why it was not run, if it was not.
    """

    tool: str
    algorithm: str
    compared: str
    difference: float
    seconds: float = float("nan")
    note: str = ""


def _largest(tool: Result, master: Result, columns: list[str], rename: dict[str, str] | None = None) -> float:
    """Largest |tool - master| over ``columns`` (the tool's names); ``rename`` maps the tool's
    instance names to the master's (an SSP component named apart from its block)."""
    rename = rename or {}

    def master_column(column: str) -> str:
        instance, variable = column.split(".", 1)
        return f"{rename.get(instance, instance)}.{variable}"

    return max((float(np.max(np.abs(tool[c] - master[master_column(c)]))) for c in columns), default=0.0)


def compare_tools(system: System, stop_time: float, folder: Path) -> list[ToolRun]:
    """Run ``system`` to ``stop_time`` in the other tools (files written under ``folder``).

    Returns
    -------
    list of ToolRun
        Container (Gauss-Seidel), container (Jacobi), libcosim, ecos, in that order.
    """
    from robofmu.system.interop.container import export_container, run_container
    from robofmu.system.interop.ecos import run_ssp_ecos
    from robofmu.system.interop.libcosim import run_ssp_libcosim
    from robofmu.system.interop.ssp import element_names, export_ssp

    folder = Path(folder)
    h = system.step
    masters = {a: Master(system).run(stop_time, h, a) for a in ALGORITHMS}
    runs = []
    for algorithm, master in masters.items():
        path = export_container(system, folder / f"{system.name}-{algorithm}.fmu", algorithm)
        start = time.perf_counter()
        boxed = run_container(path, stop_time, h)
        seconds = time.perf_counter() - start
        columns = [c for c in master.columns if not (algorithm == "gauss-seidel" and c.endswith(".iterations"))]
        runs.append(ToolRun("container (fmpy)", algorithm, "every output", _largest(boxed, master, columns), seconds))
    q = system.extra["roles"]["q"]
    ssp = export_ssp(system, folder / f"{system.name}.ssp")
    element = element_names([b.name for b in system.blocks])      # the SSD's component names
    block = {name: b for b, name in element.items()}
    instance, variable = q.split(".", 1)
    for tool, module, run in (("libcosim", "libcosimpy", run_ssp_libcosim), ("ecos", "ecospy", run_ssp_ecos)):
        if importlib.util.find_spec(module) is None:
            runs.append(ToolRun(tool, "jacobi", q, float("nan"), note=f"{module} is not installed (dev extra)"))
            continue
        start = time.perf_counter()
        result = run(ssp, stop_time, h, record=[f"{element[instance]}.{variable}"])
        runs.append(ToolRun(tool, "jacobi", q, _largest(result, masters["jacobi"], result.columns, block),
                            time.perf_counter() - start))
    return runs

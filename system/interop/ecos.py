"""Run an SSP package (:func:`~robofmu.system.interop.ssp.export_ssp`) with ecos (``ecospy``), the Ecos
platform's co-simulation engine: :func:`run_ssp_ecos`; :func:`load_ecospy` loads its library."""
from __future__ import annotations

import re
import time as _time
from contextlib import contextmanager
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np

from robofmu.system.diagram import select
from robofmu.system.interop.ssp import NS, ssd_text
from robofmu.system.plan import step_count
from robofmu.system.result import Result


def load_ecospy():
    """ecospy, its library loaded. Its wheel's libecosc.so needs oneTBB's libtbb.so.12, which it
    does not ship: the ``tbb`` wheel (dev extra) puts one in this environment's lib folder, loaded
    here first (globally) so that the dynamic loader finds it by its soname."""
    import ctypes
    import sys

    for folder in {sys.prefix, sys.base_prefix}:
        tbb = Path(folder) / "lib" / "libtbb.so.12"
        if tbb.is_file():
            ctypes.CDLL(str(tbb), mode=ctypes.RTLD_GLOBAL)
            break
    import ecospy

    return ecospy


#: An FMU's error as ecos logs it at level debug: ``[<FMU path>] fmi2Error <message>``.
_ECOS_FAILURE = re.compile(r"\[([^\]]*)\] (fmi2Error|fmi2Fatal) (.*)")


@contextmanager
def _stdout_captured():
    """File descriptor 1 (where ecos's C++ logger writes) into a temporary file while the block
    runs. Yields ``written()``: the text written since its last call. Afterwards the lines that
    are not ecos's debug log are written to the real stdout again."""
    import ctypes
    import os
    import sys
    import tempfile

    libc = ctypes.CDLL(None)
    sys.stdout.flush()
    libc.fflush(None)
    saved = os.dup(1)
    log = tempfile.TemporaryFile()
    os.dup2(log.fileno(), 1)
    offset = 0

    def written() -> str:
        nonlocal offset
        libc.fflush(None)
        size = os.fstat(log.fileno()).st_size
        if size == offset:
            return ""
        text = os.pread(log.fileno(), size - offset, offset).decode(errors="replace")
        offset = size
        return text

    try:
        yield written
    finally:
        sys.stdout.flush()
        libc.fflush(None)
        os.dup2(saved, 1)
        os.close(saved)
        log.seek(0)
        others = [line for line in log.read().decode(errors="replace").splitlines(keepends=True)
                  if line.strip() and "[ecos] [debug]" not in line]
        log.close()
        if others:
            sys.stdout.write("".join(others))


def run_ssp_ecos(path: str | Path, stop_time: float, step: float, start_time: float = 0.0,
                 record: list[str] | None = None) -> Result:
    """Simulate an SSP with ecos (``ecospy``), the Ecos platform's co-simulation engine.

    ecos loads the package itself (FMUs, connections, the parameter sets of the SSV files; they
    all carry the system's name, which :func:`export_ssp` gives them, and that set is applied at
    initialization). Its fixed-step algorithm is libcosim's Jacobi exchange, and its
    initialization passes connected values along as often as there are components (consistent
    at t0), so the states (the plant's q, qd) equal the master's Jacobi run to rounding.

    What it records differs for a feedthrough block: after every step ecos transfers the
    outputs, sets the inputs and reads every output again, so :meth:`get_real` returns a
    feedthrough block's outputs computed from its inputs of t + h, where the master's Jacobi
    run records those of its step (from its inputs of t): the master's value one row later.

    ecos (0.7) ignores the status of every FMI call and logs the FMUs' messages at its debug
    level only: a block that refuses its initialization or a step would go unnoticed. The runner
    therefore runs ecos at debug level with file descriptor 1 captured, and stops at the first
    ``fmi2Error`` or ``fmi2Fatal`` an FMU logs (robofmu's FMUs log every error they return).

    Returns a :class:`~robofmu.system.result.Result` with the Real outputs matching ``record``
    (fnmatch patterns on ``instance.variable``; default all) at t0, t0 + h, .., t0 + n h.

    Raises
    ------
    SimulationError
        An FMU reported an error: its message, the component, the time, and every row recorded
        before it (``result``).
    """
    from robofmu.system.interop.libcosim import guard_pythonfmu_exit       # ctypes only: libcosimpy is not needed
    from robofmu.system.master import SimulationError

    ecospy = load_ecospy()
    guard_pythonfmu_exit()
    path = Path(path)
    n = step_count(start_time, stop_time, step)
    system = ET.fromstring(ssd_text(path)).find("ssd:System", NS)
    components = list(system.iterfind("ssd:Elements/ssd:Component", NS))
    columns = [f"{comp.get('name')}.{con.get('name')}" for comp in components
               for con in comp.iterfind("ssd:Connectors/ssd:Connector", NS)
               if con.get("kind") == "output" and con.find("ssc:Real", NS) is not None]
    keep = [columns[k] for k in select(columns, record)]
    identifiers = [c.replace(".", "::", 1) for c in keep]
    data = np.empty((n + 1, len(keep)))
    times = np.empty(n + 1)

    def check(log: str, k: int, t: float) -> None:
        failure = _ECOS_FAILURE.search(log)
        if failure is None:
            return
        source = Path(failure.group(1)).name                    # ecos names an instance by its FMU's path
        named = [c.get("name") for c in components if Path(c.get("source", "")).name == source]
        block = named[0] if len(named) == 1 else source
        partial = Result(times[:k], keep, data[:k].copy(), {"tool": "ecos", "step": step}) if k else None
        said = failure.group(3).strip().removeprefix(f"{failure.group(1)}: ")     # the FMU names itself too
        message = f"ecos: {block} at t = {t:.9g} s: {failure.group(2)}: {said}"
        raise SimulationError(message + (f"; {k} rows recorded before it" if k else ""), block, t, partial,
                              reason=message)

    ecospy.EcosLib.set_log_level("debug")
    try:
        with _stdout_captured() as written, ecospy.EcosSimulation(step_size=step, ssp_path=str(path)) as sim:
            sim.init(start_time, parameter_set=system.get("name"))
            check(written(), 0, start_time)
            get = sim.get_real
            times[0], data[0] = sim.get_time(), [get(i) for i in identifiers]
            wall = _time.perf_counter()
            for k in range(1, n + 1):
                sim.step()
                check(written(), k, times[k - 1])
                times[k], data[k] = sim.get_time(), [get(i) for i in identifiers]
            wall = _time.perf_counter() - wall
            sim.terminate()
    finally:
        ecospy.EcosLib.set_log_level("warn")
    return Result(times, keep, data, {"tool": "ecos", "algorithm": "jacobi (ecos fixed-step)", "step": step,
                                      "wall_time": wall})

"""The defaults of the co-simulation, one place for each (python-control's ``config.defaults``).

Every module, command and docstring that needs one of these reads it from here.
"""
from __future__ import annotations

from robofmu import components

#: The master algorithms: ``gauss-seidel`` evaluates the blocks' outputs in dependency order at
#: each communication point (no step of delay along a feedthrough chain); ``jacobi`` exchanges
#: all outputs of the previous communication point.
ALGORITHMS = ("gauss-seidel", "jacobi")

#: The algorithm an experiment uses when it names none.
ALGORITHM = "gauss-seidel"

#: The communication step an experiment uses when it names none, in s (the FMUs' default
#: experiment's, defined with them in :mod:`robofmu.components`).
STEP_SIZE = components.STEP_SIZE

#: The stop time an experiment uses when it names none, in s.
STOP_TIME = 1.0

#: The folder of the built FMUs (``DIR/<robot>/<block>.fmu``), relative to the working folder.
FMU_FOLDER = "fmus"

#: The folder under which commands write their outputs when given no ``--out``.
RESULTS_FOLDER = "results"

#: The monolithic reference of the accuracy studies: scipy's DOP853 at these tolerances.
REFERENCE_SOLVER = "DOP853"
REFERENCE_RTOL = 1e-10

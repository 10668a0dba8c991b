"""Other FMI tools: the same diagrams outside robofmu's master.

An experiment exported as an SSP 1.0 package (:mod:`.ssp`, which libcosim, ecos and ``fmpy.ssp``
run), as libcosim's own configuration with a rate per block (:mod:`.osp`), as one FMU container of fmu-manipulation-toolbox (:mod:`.container`), run by libcosim
through its Python binding (:mod:`.libcosim`), and each tool's run compared with the master's
(:mod:`.compare`). Imports the co-simulation core (``robofmu.system``) and
:mod:`robofmu.system.packaging` for the FMI library a container carries; nothing here is imported
by the core.
"""

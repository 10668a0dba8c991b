"""FMU packaging: the block FMUs as files any FMI host loads.

:mod:`.build` turns each robot's blocks into FMI 2.0 co-simulation FMUs with pythonfmu and
completes their model description; :mod:`.fmi_export` is the C library in front of pythonfmu's
(Python runtime loading, crash guards, the fast path's shared layout); :mod:`.requirements`
derives each FMU's ``requirements.txt`` from the imports of its bundled code; :mod:`.validate`
runs fmpy's and fmu-manipulation-toolbox's checkers; :mod:`.doctor` tells what an importing
process needs and checks it. Imports :mod:`robofmu.components` (the code it bundles) and the
core's FMU wrapper only.
"""

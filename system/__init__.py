"""robofmu system: building FMUs, the co-simulation master, experiments, analysis, CLI."""
# Load the installed robofmu.components before any FMU's bundled copy can be imported in its place.
import robofmu.components  # noqa: F401

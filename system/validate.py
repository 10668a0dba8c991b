"""FMU validation through fmpy (the checks of ``fmpy validate``)."""
from __future__ import annotations

from pathlib import Path


def problems_of(fmu: str | Path) -> list[str]:
    """Problems fmpy finds in a FMU's model description (empty list: valid)."""
    from fmpy.validation import validate_fmu

    return list(validate_fmu(str(fmu)))

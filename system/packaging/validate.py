"""FMU validation by two independent checkers: fmpy's (``fmpy validate``) and
fmu-manipulation-toolbox's (``fmutool -check``: the FMI XSD schema, then the rules the schema
cannot express: unique names, causality / variability / initial combinations, start values,
the model structure's references)."""
from __future__ import annotations

import logging
from contextlib import contextmanager
from pathlib import Path


def fmpy_problems(fmu: str | Path) -> list[str]:
    """Problems fmpy finds in a FMU's model description (empty list: valid)."""
    from fmpy.validation import validate_fmu

    return list(validate_fmu(str(fmu)))


class _Errors(logging.Handler):
    """The error records of a logger, kept (and so not printed by logging's last resort)."""

    def __init__(self):
        super().__init__(logging.ERROR)
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


@contextmanager
def toolbox_errors_only(handler: logging.Handler | None = None):
    """While the block runs, fmu-manipulation-toolbox's logger passes on its errors only (its
    INFO and WARNING lines are a console tool's), to ``handler`` where one is given."""
    logger = logging.getLogger("fmu_manipulation_toolbox")
    level = logger.level
    logger.setLevel(logging.ERROR)
    if handler is not None:
        logger.addHandler(handler)
    try:
        yield
    finally:
        if handler is not None:
            logger.removeHandler(handler)
        logger.setLevel(level)


def checker_problems(fmu: str | Path) -> list[str]:
    """Problems fmu-manipulation-toolbox's checkers (those of ``fmutool -check``) find in a FMU's
    model description (empty list: valid)."""
    from fmu_manipulation_toolbox.checker import get_checkers
    from fmu_manipulation_toolbox.operations import FMU, FMUError

    errors = _Errors()
    with toolbox_errors_only(errors):
        try:
            with FMU(str(fmu)) as opened:
                for checker in get_checkers():
                    opened.apply_operation(checker())
        except FMUError as exc:
            errors.messages.append(f"cannot be read: {exc}")
    return errors.messages


def problems_of(fmu: str | Path) -> list[str]:
    """Problems either checker finds (empty list: valid), each named by its tool."""
    return ([f"fmpy: {p}" for p in fmpy_problems(fmu)] +
            [f"fmu-manipulation-toolbox: {p}" for p in checker_problems(fmu)])

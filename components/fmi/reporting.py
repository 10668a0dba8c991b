"""How the slave tells the importer: failed calls, refused steps, warnings, interruptions.

In a robofmu FMU, robofmu's export library stands in front of pythonfmu's and returns the
status of every message logged with the category :data:`.contract.STATUS_CATEGORY` from the FMI
call it is logged in. So a refused step or invalid input is fmi2Error
(:meth:`Reporting.fail`, :meth:`Reporting._raise_to_importer`), and the instance stays usable.
Behind pythonfmu's library alone (its win64 one, or a slave used without a FMU) only raising
fails a call (fmi2Fatal), and a refused step is fmi2Discard.

Every failure is logged in one line (:func:`one_line`). A block's refusal (:data:`REFUSALS`:
invalid parameters or inputs, a refused step) says what is wrong in its own words; any other
exception is unexpected and is named by its type, its traceback logged after it as a debug
message (fmi2OK, category ``logAll``: an importer sees it only with debug logging on).
"""
from __future__ import annotations

import sys
import traceback
from pathlib import Path

from pythonfmu.enums import Fmi2Status

from ..blocks import StepRefused
from .contract import PLATFORM, STATUS_CATEGORY, STOCK_LIBRARY

__all__ = ["INTERRUPTION", "REFUSALS", "CallFailed", "Reporting", "behind_robofmu_library", "one_line"]

#: How a KeyboardInterrupt (Ctrl-C) raised in the block's Python code during an FMI call is
#: logged (with fmi2Error, the call abandoned): ``"<call> " + INTERRUPTION + " at t = ..."``.
#: The master reports a failed call whose message holds it as an interruption
#: (``robofmu.system.master``: the same text).
INTERRUPTION = "interrupted: KeyboardInterrupt (Ctrl-C) in the block's Python code"


#: The exceptions that are a block's refusal, not a bug: a ValueError (an invalid parameter or
#: input, named in the message: the project's ParameterError, DescriptionError, Unreachable are
#: ValueErrors) and a refused step (:class:`~robofmu.components.blocks.StepRefused`).
REFUSALS = (ValueError, StepRefused)


class CallFailed(RuntimeError):
    """The current FMI call fails; its message has been logged."""


def one_line(exc: BaseException) -> str:
    """``exc`` in one line: a refusal (:data:`REFUSALS`) by its message, any other exception by
    its type and message (the message's lines joined by "; ")."""
    text = "; ".join(line.strip() for line in str(exc).splitlines() if line.strip())
    return text if isinstance(exc, REFUSALS) else f"{type(exc).__name__}: {text}"


def behind_robofmu_library(resources) -> bool:
    """Whether robofmu's export library stands in front of the instance whose resources folder
    is ``resources``: its FMU keeps pythonfmu's own library beside robofmu's in
    ``binaries/linux64`` (``robofmu.system.packaging.fmi_export``)."""
    return (bool(resources) and sys.platform.startswith("linux")
            and (Path(resources).parent / "binaries" / PLATFORM / STOCK_LIBRARY).is_file())


class Reporting:
    """The slave's messages to the importer (a mixin of :class:`~.base.BlockSlave`).

    Uses the slave's ``instance_name``, ``time``, ``log`` (pythonfmu's) and ``_statuses``
    (:func:`behind_robofmu_library` of its resources).
    """

    def fail(self, message: str, status: Fmi2Status = Fmi2Status.error) -> bool:
        """Refuse the step: log ``message``, return False. Behind robofmu's export library
        fmi2DoStep returns ``status`` (fmi2Error; fmi2Discard only where a smaller step could
        succeed and the importer retries), behind pythonfmu's alone fmi2Discard."""
        self._report(message, status)
        return False

    def _report(self, message: str, status: Fmi2Status = Fmi2Status.error) -> None:
        """Log ``message``; behind robofmu's export library the current FMI call returns ``status``."""
        self.log(f"{self.instance_name}: {message}", status, STATUS_CATEGORY if self._statuses else None)

    def warn(self, message: str) -> None:
        self.log(f"{self.instance_name}: {message}", Fmi2Status.warning)

    def _raise_to_importer(self, message: str, cause: BaseException | None = None):
        """Log ``message`` as an error (and the traceback of an unexpected ``cause``, see
        :meth:`_trace`) and abandon the current FMI call, which fails with fmi2Error behind
        robofmu's export library (the entry point returns normally, see
        :func:`.pythonfmu_workarounds.fmi_entry`) and with fmi2Fatal behind pythonfmu's alone."""
        self._report(message)
        if cause is not None:
            self._trace(cause)
        raise CallFailed(f"{self.instance_name}: {message}")

    def _trace(self, exc: BaseException) -> None:
        """The traceback of an unexpected exception (not one of :data:`REFUSALS`) as a debug
        message: fmi2OK, shown by robofmu's export library only while debug logging is on."""
        if not isinstance(exc, REFUSALS):
            trace = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
            self.log(f"{self.instance_name}: {trace}", Fmi2Status.ok)

    def _report_failure(self, exc: BaseException, call: str) -> None:
        """Log the exception that failed ``call`` in one line (a :class:`CallFailed` is logged
        already); a KeyboardInterrupt as an interruption (:data:`INTERRUPTION`), which the
        master recognizes."""
        if isinstance(exc, KeyboardInterrupt):
            self._report(f"{call} {INTERRUPTION} at t = {self.time:.9g} s; the call is abandoned")
        elif not isinstance(exc, CallFailed):
            self._report(f"{call} failed: {one_line(exc)}")
            self._trace(exc)

    def _log_from_block(self, level: str, text: str) -> None:
        """The block's logger (``Block.logger``): its warnings and errors as the slave's messages."""
        status = Fmi2Status.warning if level == "warning" else Fmi2Status.error
        self.log(f"{self.instance_name}: {text}", status)

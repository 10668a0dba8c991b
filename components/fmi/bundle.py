"""Import the whole bundled package at once, when a process first loads it.

All pythonfmu FMUs of a process share one interpreter and ``sys.modules``. In a host where
robofmu is not installed, ``robofmu.components`` is imported from the first FMU's extraction
folder (its ``resources``, which pythonfmu puts first on ``sys.path``), and a submodule imported
later (``robots.serial``, ``robots.parallel``: the robot-model classes are imported when first
used) would be looked up in that folder, which its importer may have deleted since (fmpy does after
every run): a FMU of another robot family then fails with ``No module named
'robofmu.components.robots.serial'``. The generated FMU script (``robofmu build``) calls
:func:`import_all` before anything else of the package, so every module is imported while that
folder exists, and no FMU reads a file of another FMU's extraction folder later. The bundle is
code only (:func:`robofmu.components.code_files`: no robot's data folder); robot data is read
from each instance's own folder, ``resources/robot/`` (``BlockSlave._own_description``).

Importing every module has no side effect but definitions (a few hundredths of a second once per
process); later calls return at once.
"""
from __future__ import annotations

import importlib
import pkgutil
import sys

__all__ = ["import_all"]

_PACKAGE = __name__.rsplit(".", 2)[0]       # robofmu.components
_done = False


def _raise(name: str) -> None:
    raise    # noqa: PLE0704  (pkgutil calls onerror inside its except clause: re-raise that error)


def import_all() -> list[str]:
    """Import every module of the loaded ``robofmu.components`` (wherever it was loaded from).

    Returns the names of the modules imported by this call: all of them the first time in a
    process, none afterwards. An error importing any of them propagates (a broken bundle fails
    at once, not at its first use)."""
    global _done
    if _done:
        return []
    package = sys.modules[_PACKAGE]
    names = []
    for info in pkgutil.walk_packages(package.__path__, prefix=_PACKAGE + ".", onerror=_raise):
        importlib.import_module(info.name)
        names.append(info.name)
    _done = True
    return names

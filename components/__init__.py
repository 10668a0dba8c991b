"""robofmu components: robot models, trajectory profiles, IK, control laws, integrators.

Everything here is FMI-free except the ``fmi`` subpackage, the thin pythonfmu wrappers.

Every FMU bundles a copy of this package. All pythonfmu FMUs of one process share one
interpreter, so the first copy imported wins for all of them; :func:`check_bundle` makes a FMU
whose bundled copy differs from the one already loaded fail loudly instead of silently running
other code than it was built with.
"""
from __future__ import annotations

import hashlib
from pathlib import Path

__all__ = ["SOURCE_HASH", "STEP_SIZE", "source_hash", "check_bundle"]

#: The communication step (s) of every FMU's default experiment, and of an experiment that names
#: none (``robofmu.system.defaults.STEP_SIZE`` is this): 1 ms.
STEP_SIZE = 1e-3

_PACKAGE_DIR = Path(__file__).resolve().parent
_HASHED_SUFFIXES = (".py", ".urdf", ".toml")


def source_hash(package_dir: str | Path) -> str:
    """SHA-256 over the package's source and robot data files (path and content), hex.

    Parameters
    ----------
    package_dir : str or Path
        A copy of this package (the installed one, or one bundled inside a FMU).
    """
    root = Path(package_dir)
    digest = hashlib.sha256()
    files = sorted(
        p for p in root.rglob("*")
        if p.is_file() and p.suffix in _HASHED_SUFFIXES and "__pycache__" not in p.parts
    )
    for path in files:
        digest.update(path.relative_to(root).as_posix().encode())
        digest.update(b"\0")
        digest.update(path.read_bytes())
        digest.update(b"\0")
    return digest.hexdigest()


SOURCE_HASH = source_hash(_PACKAGE_DIR)


def check_bundle(resources: str | Path) -> None:
    """Fail loudly if the copy bundled in a FMU's ``resources`` folder is not the one loaded.

    Called when every block instance is created, with the instance's resources folder (which
    holds ``robofmu/components``).
    """
    bundled = Path(resources).resolve() / "robofmu" / "components"
    if not bundled.is_dir():
        raise ImportError(f"robofmu: FMU resources lack the bundled package at {bundled}")
    if bundled == _PACKAGE_DIR:
        return
    theirs = source_hash(bundled)
    if theirs != SOURCE_HASH:
        raise ImportError(
            "robofmu: this FMU was built from robofmu.components "
            f"{theirs[:12]}, but this process already runs robofmu.components {SOURCE_HASH[:12]} "
            f"from {_PACKAGE_DIR}. All FMUs of one process share one Python interpreter; "
            "rebuild the FMUs with the same robofmu (`robofmu build` / `make fmus`)."
        )

"""robofmu components: robot models, trajectory profiles, IK, control laws, integrators.

Everything here is FMI-free except the ``fmi`` subpackage, the thin pythonfmu wrappers.

Every FMU bundles a copy of this package's code (:func:`code_files`: its Python modules, no
robot's data folder) and its own robot's data beside it (``resources/robot/``). All pythonfmu
FMUs of one process share one interpreter, so the first copy imported wins for all of them;
:func:`check_bundle` makes a FMU whose bundled code differs from the code already loaded fail
loudly instead of silently running other code than it was built with. Robot data is not part of
that comparison: each instance reads its own robot's files from its own folder, so adding or
changing one robot leaves every other robot's FMUs valid (:func:`robot_data_hash` tells a
FMU's robot data apart).
"""
from __future__ import annotations

import hashlib
from pathlib import Path

__all__ = ["SOURCE_HASH", "STEP_SIZE", "code_files", "source_hash", "robot_data_hash", "description_hash", "check_bundle"]

#: The communication step (s) of every FMU's default experiment, and of an experiment that names
#: none (``robofmu.system.defaults.STEP_SIZE`` is this): 1 ms.
STEP_SIZE = 1e-3

_PACKAGE_DIR = Path(__file__).resolve().parent


def _in_robot_data(root: Path, relative: Path) -> bool:
    """Whether ``relative`` (a path inside the package at ``root``) lies in a robot's data folder:
    a folder of ``robots/`` that is not a Python package (``robots/<name>/``: a robot's TOML and
    URDF)."""
    parts = relative.parts
    return len(parts) > 2 and parts[0] == "robots" and not (root / "robots" / parts[1] / "__init__.py").is_file()


def code_files(package_dir: str | Path) -> list[Path]:
    """The package's code, sorted, relative to ``package_dir``: every ``.py`` file outside
    ``__pycache__`` and outside the robots' data folders (``robots/<name>/``). What an FMU bundles
    and :func:`source_hash` covers.

    Parameters
    ----------
    package_dir : str or Path
        A copy of this package (the installed one, or one bundled inside a FMU).
    """
    root = Path(package_dir)
    found = []
    for path in root.rglob("*.py"):
        relative = path.relative_to(root)
        if path.is_file() and "__pycache__" not in relative.parts and not _in_robot_data(root, relative):
            found.append(relative)
    return sorted(found, key=lambda p: p.as_posix())


def source_hash(package_dir: str | Path) -> str:
    """SHA-256 over the package's code (:func:`code_files`: path and content), hex.

    Robot data (``robots/<name>/*.toml``, ``*.urdf``) is not code: adding a robot, or changing
    one, leaves the hash as it is.

    Parameters
    ----------
    package_dir : str or Path
        A copy of this package (the installed one, or one bundled inside a FMU).
    """
    root = Path(package_dir)
    digest = hashlib.sha256()
    for relative in code_files(root):
        digest.update(relative.as_posix().encode())
        digest.update(b"\0")
        digest.update((root / relative).read_bytes())
        digest.update(b"\0")
    return digest.hexdigest()


SOURCE_HASH = source_hash(_PACKAGE_DIR)


def robot_data_hash(toml: str | Path, urdf: str | Path | None = None, tables=(), srdf: str | Path | None = None,
                    xacro_args: dict | None = None) -> str:
    """SHA-256 over one robot's data, hex: its TOML's bytes, then its URDF's (None: a closed-chain
    mechanism, described by its TOML alone; a ``.xacro`` file: the URDF it expands to with
    ``xacro_args``), then its SRDF's (``srdf``, if any), then each CSV table a profile reads
    (``tables``: paths relative to the TOML, in the description's order). File names and folders
    do not count, so the robot's files where they are described (a URDF perhaps in another
    distribution, a xacro file) and the copies an FMU carries (``resources/robot/<name>.toml``,
    ``<name>.urdf`` expanded, ``<name>.srdf``, the tables beside them) hash alike."""
    digest = hashlib.sha256()
    digest.update(b"toml\0")
    digest.update(Path(toml).read_bytes())
    if urdf is not None:
        digest.update(b"\0urdf\0")
        if Path(urdf).suffix == ".xacro":
            from .robots.urdf import expand_xacro

            digest.update(expand_xacro(urdf, xacro_args))
        else:
            digest.update(Path(urdf).read_bytes())
    if srdf is not None:
        digest.update(b"\0srdf\0")
        digest.update(Path(srdf).read_bytes())
    for table in tables:
        digest.update(b"\0table\0" + str(table).encode() + b"\0")
        digest.update((Path(toml).parent / table).read_bytes())
    return digest.hexdigest()


def description_hash(description) -> str:
    """:func:`robot_data_hash` of a :class:`~robofmu.components.robots.RobotDescription`."""
    return robot_data_hash(description.path, description.urdf, description.tables, description.srdf,
                           description.xacro_args)


def check_bundle(resources: str | Path) -> None:
    """Fail loudly if the code bundled in a FMU's ``resources`` folder is not the code loaded.

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

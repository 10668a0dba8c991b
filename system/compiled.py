"""The C libraries robofmu compiles on this machine (FMI export library, the master's call
list): where they are cached, each under a key of its source and compiler, and the machine's
C compiler."""
from __future__ import annotations

import os
import shutil
import sys
import tempfile
from pathlib import Path

__all__ = ["cache_folder", "machine_compiler"]


def cache_folder() -> Path:
    """The first writable of ``$ROBOFMU_CACHE/fmi-export``, ``<sys.prefix>/share/robofmu/fmi-export``
    and ``<tmp>/robofmu-cache-<uid>/fmi-export``, created if needed.

    Raises
    ------
    OSError
        If none of them can be written.
    """
    for candidate in (os.environ.get("ROBOFMU_CACHE"),
                      Path(sys.prefix) / "share" / "robofmu",
                      Path(tempfile.gettempdir()) / f"robofmu-cache-{os.getuid()}"):
        if not candidate:
            continue
        folder = Path(candidate) / "fmi-export"
        try:
            folder.mkdir(parents=True, exist_ok=True)
            probe = folder / f".probe-{os.getpid()}"
            probe.write_bytes(b"")
            probe.unlink()
            return folder
        except OSError:
            continue
    raise OSError("no writable folder for robofmu's compiled C libraries "
                  "(ROBOFMU_CACHE, <sys.prefix>/share/robofmu, the temporary folder)")


def machine_compiler() -> list[str] | None:
    """The machine's C compiler, the first of cc, gcc and clang on the PATH, or None."""
    for name in ("cc", "gcc", "clang"):
        path = shutil.which(name)
        if path:
            return [path]
    return None

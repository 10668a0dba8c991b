"""The misuse suite's one contract (tests/test_misuse_*.py), for every refusal of the command line.

A mistake in what was asked is answered by ``robofmu <command>: ...`` in one line on stderr,
naming the offending file, key, element, option or port, with exit status 2 (1 for a failed
run, 130 for Ctrl-C), never a traceback; nothing is left half-written (a temporary sibling is
named ``.<name>.<random>.partial``, see :data:`PARTIAL`) and no file that was there is changed.

:func:`assert_refused` runs the command in this process (pytest's ``capfd`` captures file
descriptor 2 too, so a C library's own chatter on stderr counts as a second line).
"""
from __future__ import annotations

from pathlib import Path

from robofmu.system.cli import main

#: How a temporary sibling written before its rename ends (robofmu.system.usage's atomic writes).
PARTIAL = ".partial"


def snapshot(*paths: Path) -> dict[Path, bytes | None]:
    """The bytes of each file (None where there is none), to compare after a refusal."""
    return {Path(p): (Path(p).read_bytes() if Path(p).is_file() else None) for p in paths}


def partial_files(folder: Path) -> list[Path]:
    """Temporary siblings left under ``folder`` (none after any command, interrupted or not)."""
    folder = Path(folder)
    return sorted(p for p in folder.rglob(f"*{PARTIAL}")) if folder.exists() else []


def assert_refused(capfd, argv: list[str], *names: str, status: int = 2, untouched=(),
                   folders=()) -> str:
    """Run ``robofmu argv`` and assert the common contract of a refusal; returns its line.

    Parameters
    ----------
    capfd : pytest fixture
        Captures stdout and stderr at the file-descriptor level.
    argv : list of str
        The command line after ``robofmu`` (the command first).
    names : str
        What the one line must name (a path, a key, an option, a port), each as a substring.
    status : int
        The exit status expected (2: a mistake in what was asked).
    untouched : iterable of Path
        Files that must be byte for byte as before (or still absent).
    folders : iterable of Path
        Folders that must hold no temporary sibling afterwards.
    """
    argv = [str(a) for a in argv]
    before = snapshot(*untouched)
    capfd.readouterr()
    code = main(argv)
    out, err = capfd.readouterr()
    lines = [line for line in err.splitlines() if line.strip()]
    shown = f"robofmu {' '.join(argv)}\n--- stdout\n{out}--- stderr\n{err}"
    assert code == status, f"exit status {code}, expected {status}:\n{shown}"
    assert "Traceback" not in out + err, shown
    assert len(lines) == 1, f"expected one line on stderr:\n{shown}"
    line = lines[0]
    assert line.startswith(f"robofmu {argv[0]}: "), shown
    for name in names:
        assert str(name) in line, f"{name!r} is not named:\n{shown}"
    assert snapshot(*untouched) == before, f"a file was changed:\n{shown}"
    for folder in folders:
        assert not partial_files(folder), f"left behind: {partial_files(folder)}\n{shown}"
    return line

"""The markers the fast loop (``make check``: -m "not slow and not interop") relies on."""
from __future__ import annotations

from pathlib import Path

import conftest

TESTS = Path(__file__).resolve().parent


def test_module_markers_name_existing_modules_and_registered_markers(pytestconfig):
    registered = {line.split(":")[0].strip() for line in pytestconfig.getini("markers")}
    assert {"slow", "interop", "study"} <= registered
    for name, markers in conftest.MODULE_MARKERS.items():
        assert (TESTS / name).is_file(), name
        assert set(markers) <= registered, (name, markers)

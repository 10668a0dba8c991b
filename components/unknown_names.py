"""How robofmu words a name it does not know, a TOML key or a block's parameter: the names it
knows, and the nearest of them where one is close (``did you mean``)."""
from __future__ import annotations

import difflib
from typing import Iterable


def nearest(name: str, known: Iterable[str]) -> str:
    """``; did you mean 'x'?`` for the known name closest to ``name``
    (:func:`difflib.get_close_matches`), or ``""`` where none is close."""
    close = difflib.get_close_matches(name, list(known), n=1)
    return f"; did you mean {close[0]!r}?" if close else ""


def unknown_key(key: str, known: Iterable[str]) -> str:
    """The problem of an unknown ``key`` among ``known``: ``unknown key (known: a, b); did you
    mean 'b'?``, the hint only where a known key is close."""
    known = sorted(known)
    return f"unknown key (known: {', '.join(known)})" + nearest(key, known)

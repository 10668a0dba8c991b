"""How every reader of robofmu's TOML files (robot descriptions, experiments, the demo plan)
words a key it does not know: the keys it knows, and the nearest of them where one is close."""
from __future__ import annotations

import difflib
from typing import Iterable


def unknown_key(key: str, known: Iterable[str]) -> str:
    """The problem of an unknown ``key`` among ``known``: ``unknown key (known: a, b); did you
    mean 'b'?``, the hint only where a known key is close (:func:`difflib.get_close_matches`)."""
    known = sorted(known)
    close = difflib.get_close_matches(key, known, n=1)
    return f"unknown key (known: {', '.join(known)})" + (f"; did you mean {close[0]!r}?" if close else "")

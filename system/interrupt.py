"""Ctrl-C as a flag: a SIGINT handler that notes the signal for a loop to check.

A long loop (the master's communication steps, a sweep's records) stops at its next check when
the flag is set; whether the handler also raises KeyboardInterrupt, as Python's own does, is
the caller's choice.
"""
from __future__ import annotations

import signal
import threading
from contextlib import contextmanager


@contextmanager
def sigint_flag(raise_interrupt: bool = False):
    """While the block runs, SIGINT sets ``flag[0]`` (the list yielded) and, if
    ``raise_interrupt``, also raises KeyboardInterrupt.

    The previous handler is restored afterwards. Outside the main thread, or when the current
    handler was not installed from Python (``signal.getsignal`` is None), nothing is installed
    and the flag stays False.
    """
    flag = [False]
    previous = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.getsignal(signal.SIGINT)
    if previous is None:
        yield flag
        return

    def note(_signum, _frame):
        flag[0] = True
        if raise_interrupt:
            raise KeyboardInterrupt

    signal.signal(signal.SIGINT, note)
    try:
        yield flag
    finally:
        signal.signal(signal.SIGINT, previous)

"""Ctrl-C during a chunked run: the flag that stops the runs (:func:`interrupt_runs`) and
SIGINT raising while the driver waits on Dask.
"""

from __future__ import annotations

import signal
import threading

__all__ = ["interrupt_runs"]


#: set by :func:`interrupt_runs`: every chunked run waiting on Dask in this process stops
#: as Ctrl-C stops it (a scenario batch runs them in threads, where no signal arrives)
_INTERRUPT = threading.Event()


def interrupt_runs(on: bool = True) -> None:
    """Make every chunked run that waits on Dask in this process stop as Ctrl-C stops
    it: its chunks are cancelled and its Solution says "interrupted" (``on=False``
    clears the request). For runs in threads (a scenario batch), which no signal reaches."""
    if on:
        _INTERRUPT.set()
    else:
        _INTERRUPT.clear()


class _SigintRaises:
    """While waiting for the workers (main thread only): Ctrl-C raises
    KeyboardInterrupt at once (no kernel of ours runs in this process then)."""

    def __enter__(self):
        self._previous = None
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, signal.default_int_handler)
        return self

    def __exit__(self, *exc):
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
        return False

"""The hooks a chunked run adds to each chunk's solve: one wall-clock deadline for the whole call,
progress reports to the driver, the in-process progress board, and the pause that lets a
chunk be re-chunked or its work stolen (:class:`_Pause`).
"""

from __future__ import annotations

import threading
import time

import numpy as np

from verified.driver.hooks import Hook, StopAfterWall, part_hooks


# ----------------------------------------------------------------------------- hooks
class _Deadline(Hook):
    """Stop after the step during which the absolute wall-clock ``deadline`` (time.time())
    passed: :class:`StopAfterWall` made one deadline for all chunks."""

    def __init__(self, deadline: float, seconds: float):
        self.deadline, self.seconds = deadline, seconds

    def after_step(self, step, sets, run):
        if time.time() >= self.deadline:
            run.stop(f"wall-clock limit of {self.seconds:g} s reached")
        return None


class _Report(Hook):
    """On a Dask worker: publish ``(chunk, piece, t)`` on the run's topic every ``every``
    s (the combined progress, and the driver's estimate of each piece's time left)."""

    def __init__(self, topic: str, index: int, every: float = 0.3, piece: int | None = None):
        self.topic, self.index, self.every, self.piece = topic, index, every, piece
        self._last = 0.0

    def after_step(self, step, sets, run):
        now = time.monotonic()
        if now - self._last >= self.every:
            self._last = now
            try:
                from distributed import get_worker  # (the optional extra, loaded on a Dask worker)
                get_worker().log_event(self.topic, {"i": self.index, "p": self.piece, "t": float(step.t)})
            except Exception:  # noqa: BLE001 - progress is best effort
                pass
        return None


class _Local(Hook):
    """In-process: forwards ``t`` of chunk ``index`` to the combined progress."""

    def __init__(self, board, index):
        self.board, self.index = board, index

    def after_step(self, step, sets, run):
        self.board.update(self.index, float(step.t))
        return None


class _Board:
    """The combined progress of all chunks: ``progress(mean t, t_end)``."""

    def __init__(self, progress, t0, t1, sizes):
        self.progress, self.t0, self.t1 = progress, t0, t1
        self.w = np.asarray(sizes, float) / float(np.sum(sizes))
        self.t = np.full(len(sizes), float(t0))
        self.lock = threading.Lock()

    def update(self, index, t):
        with self.lock:
            self.t[index] = max(self.t[index], t)

    def emit(self):
        if self.progress is not None:
            with self.lock:
                mean = float(self.t0 + np.dot(self.w, self.t - self.t0))
            self.progress(min(mean, self.t1), self.t1)


def _split_hooks(hooks, t_start_wall: float):
    """(hooks for the chunks, the run's deadline or None): StopAfterWall becomes one
    deadline for the whole call; ``after_solve`` stages stay with the whole call
    (:func:`verified.driver.hooks.part_hooks`)."""
    out, deadline = [], None
    for h in part_hooks(hooks):
        if isinstance(h, StopAfterWall):
            d = t_start_wall + h.seconds
            deadline = d if deadline is None else min(deadline, d)
            out.append(_Deadline(d, h.seconds))
        else:
            out.append(h)
    return out, deadline


#: on a Dask worker: the task keys of the pieces the driver asked to pause (a lagging
#: piece whose sets go to idle workers; :func:`_request_pause`, run on the workers'
#: event loop while the piece's task runs in the worker's thread)
_PAUSE_REQUESTS: set = set()


async def _request_pause(key: str) -> None:
    """On every worker (``client.run(..., wait=False)``, which takes a coroutine): ask the
    piece running as task ``key`` to pause after its current step (a worker not running
    it just keeps the key)."""
    _PAUSE_REQUESTS.add(key)


class _Pause(Hook):
    """Re-chunking: stop after the step at which the run holds ``at`` sets or more (set
    growth), after step ``at_step`` (a replayed cut), or after the step during which the
    driver asked task ``key`` to pause (a lag: :data:`_PAUSE_REQUESTS`), and keep where it
    stands (:class:`verified.solver.Start`) in ``start``; never on the step that records
    the last output (the run is done then). ``steps``: the steps taken when it paused
    (what a replay needs); ``why``: "sets", "lag" or "replay"."""

    def __init__(self, at: int | None = None, at_step: int | None = None, key: str | None = None):
        self.at = None if at is None else int(at)
        self.at_step = None if at_step is None else int(at_step)
        self.key = key
        self.start = None
        self.steps = 0
        self.why = None

    def after_step(self, step, sets, run):
        self.steps += 1
        if self.at_step is not None and self.steps == self.at_step:
            why = "replay"
        elif self.at is not None and sets.n_sets >= self.at:
            why = "sets"
        elif self.key is not None and sets.n_sets >= 2 and self.key in _PAUSE_REQUESTS:
            why = "lag"
        else:
            return None
        if run.landed_on_last_output(step):
            return None
        if getattr(getattr(run, "pieces", None), "events", None):
            # some of its pieces broke down: its Solution stops at the first failure and
            # only its surviving part goes on, which new chunks cut from its sets could
            # not be stitched to; it goes on whole, as a chunk without re-chunking
            return None
        self.start = run.resume_point()
        self.why = why
        run.stop(f"paused at {sets.n_sets} sets to be cut into new chunks", "stopped")
        return None


class _EmitEvery(Hook):
    """In-process: call the combined progress after every step of any chunk."""

    def __init__(self, board):
        self.board = board

    def after_step(self, step, sets, run):
        self.board.emit()
        return None

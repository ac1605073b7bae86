"""What a worker process holds and runs: the problem's Taylor tapes built once per process
(:class:`_Problem`, :func:`_prepared`), the kernels warmed before the first chunk
(:func:`prepare_worker`, :func:`_warm_problem`), and one chunk's solve (:func:`_run_chunk`).
"""

from __future__ import annotations

import ctypes
import os
import time
from dataclasses import dataclass

from verified.arith.interval import Interval
from verified.driver.batch import VerifiedODE, solve_batch
from verified.execution.hooks import _PAUSE_REQUESTS, _Pause, _Report
from verified.execution.rechunk import _Piece

__all__ = ["prepare_worker"]


# ----------------------------------------------------------------------------- problem
@dataclass
class _Problem:
    """What every worker needs once: the ODE graph and its arithmetic (the Taylor
    tapes are built on the worker, once, and kept under ``token``)."""

    graph: object
    arithmetic: str
    token: str


_PREPARED: dict = {}  # token -> VerifiedODE, per process (each worker builds its tapes once)
_MALLOC_TUNED = False


def _tune_malloc():
    """Once per worker process: let glibc keep freed memory (trim above 256 MB, mmap
    only blocks above 32 MB). Dask's nannies start workers with
    MALLOC_TRIM_THRESHOLD_=65536, which returns every large temporary array to the OS
    and faults it back in on the next step, at a clear cost in CPU (docs/lab/code_notes.md)."""
    global _MALLOC_TUNED
    if _MALLOC_TUNED:
        return
    _MALLOC_TUNED = True
    try:
        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(-1, 256 * 2**20)  # M_TRIM_THRESHOLD
        libc.mallopt(-3, 32 * 2**20)   # M_MMAP_THRESHOLD
    except (OSError, AttributeError):  # not glibc: nothing to tune
        pass


def _prepared(problem: _Problem):
    _tune_malloc()
    ode = _PREPARED.get(problem.token)
    if ode is None:
        ode = _PREPARED[problem.token] = VerifiedODE(problem.graph, problem.arithmetic)
    return ode


_WORKER_READY = False


def prepare_worker() -> float:
    """Once per worker process, when it joins a local cluster: the solver's modules
    imported (unpickling this function did that) and glibc tuned. No kernel is compiled
    or loaded here: each run's first task on a worker (:func:`_warm_problem`) loads the
    kernels that run needs from numba's on-disk cache (or, where the machine has never
    compiled them, compiles them, as the first in-process run would). This used to run
    a tiny solve in both the interval and the affine arithmetic, which compiled the
    affine kernels in every worker of a first cluster although a first-order interval
    run never calls them (docs/lab/parallel.md). Returns the seconds it took."""
    global _WORKER_READY
    t = time.perf_counter()
    if not _WORKER_READY:
        _WORKER_READY = True
        _tune_malloc()
    return time.perf_counter() - t


def _warm_problem(problem: _Problem, box_lo, box_hi, params, kwargs: dict) -> float:
    """On each worker before the chunks: build the problem's Taylor tapes and take one
    step from one box with the run's settings (first calls of the kernels on this
    graph). Returns the seconds spent (0 when this worker already had the problem)."""
    if problem.token in _PREPARED:
        return 0.0
    t = time.perf_counter()
    ode = _prepared(problem)
    kw = {k: v for k, v in kwargs.items() if k in ("order", "tol", "error_basis", "set_order", "set_step", "model_degree", "h_min",
                                                 "wrap_target")}
    t0, t1 = kwargs["t_span"]
    try:
        solve_batch(ode, Interval(box_lo, box_hi), (t0, t1), params=params, max_steps=1, **kw)
    except Exception:  # noqa: BLE001 - the chunk itself will report a real problem
        pass
    return time.perf_counter() - t


_WARM_HERE: set = set()  # problem tokens whose kernels this (driving) process has loaded


def _warm_here(graph, arithmetic, piece, kwargs) -> None:
    """In the driving process (a daemon thread): one step of one box with the run's
    settings, so that the first cut of a paused piece's sets (:meth:`_Pieces._cut`) does
    not load the set kernels on the critical path (measured: 1.3 s in a process that had
    run nothing)."""
    kw = {k: v for k, v in kwargs.items() if k in ("order", "tol", "error_basis", "set_order", "set_step",
                                                 "model_degree", "h_min", "wrap_target")}
    params = piece.params[:1] if piece.params is not None and piece.params.ndim == 2 else piece.params
    try:
        solve_batch(VerifiedODE(graph, arithmetic), Interval(piece.lo[:1], piece.hi[:1]), kwargs["t_span"],
                    params=params, max_steps=1, **kw)
    except Exception:  # noqa: BLE001 - best effort: the cut itself reports a real problem
        pass


def _solve_piece(ode, piece: _Piece, kwargs: dict, extra_hooks=(), key: str | None = None):
    """``solve`` of one piece; returns ``(Solution, Start or None)`` (None: it did not
    pause for re-chunking). ``key``: the Dask task key under which the driver may ask a
    stealable piece to pause. A paused piece's ``stats["pause"]`` is ``(steps, why)``."""
    kw = dict(kwargs)
    key = key if piece.stealable else None
    pause = (_Pause(piece.pause_at, piece.at_step, key)
             if piece.pause_at is not None or piece.at_step is not None or key is not None else None)
    kw["hooks"] = list(kw.get("hooks") or ()) + list(extra_hooks) + ([pause] if pause is not None else [])
    kw["max_boxes"] = piece.max_boxes
    sol = solve_batch(ode, Interval(piece.lo, piece.hi), kw.pop("t_span"), params=piece.params, start=piece.start,
                      **kw)  # (one batch: never a cluster of its own)
    paused = pause.start if pause is not None and pause.start is not None and sol.status == "stopped" else None
    if paused is not None:
        sol.stats["pause"] = (pause.steps, pause.why)  # (a tuple: not summed by the merge)
    return sol, paused


def _run_chunk(problem: _Problem, piece: _Piece, kwargs: dict, topic: str, key: str | None = None):
    """One piece on a worker (a Dask task): ``(Solution, Start or None)``."""
    t, t_unix, t_cpu = time.perf_counter(), time.time(), time.thread_time()
    ode = _prepared(problem)
    try:
        sol, paused = _solve_piece(ode, piece, kwargs, [_Report(topic, piece.family, piece=key)],
                                   key=key)
    finally:
        _PAUSE_REQUESTS.discard(key)
    sol.stats["chunk_task_s"] = time.perf_counter() - t
    sol.stats["chunk_cpu_s"] = (time.thread_time() - t_cpu,)  # (this task's thread; a tuple: not summed)
    sol.stats["worker_pid"] = os.getpid()
    sol.stats["chunk_span_unix"] = (t_unix, time.time())  # (not summed by the merge: a tuple)
    return sol, paused

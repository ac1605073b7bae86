"""Chunked execution of a verified run: independent pieces, own step sizes, one Solution.

The initial boxes of a run (after ``subdivision``) are independent: the union of
their solutions is the reachable set. :func:`solve_parallel` (what
``solve(..., workers=, client=, chunks=)`` delegates to) partitions them into
contiguous *chunks*, runs each chunk as its own one-batch solve
(:func:`verified.driver.batch.solve_batch`, what ``solve(..., workers=1)`` runs) --
with its own step sizes, wrapping control and (with ``adaptive``) its own splitting
-- and merges the chunk Solutions into one :class:`~verified.solver.Solution`.

Where the chunks run:

* in this process, one after the other (``workers=1`` with ``chunks > 1``, an adaptive
  ``workers=1`` run with ``rechunk=True``, or when Dask is not installed): only the
  per-chunk step sizes change; a plan of one chunk (the default for fewer than
  ``2 * MIN_CHUNK_BOXES`` boxes, :func:`plan_chunks`) with ``workers > 1`` is one
  in-process batch, exactly ``solve``'s result: a local cluster's worker would run it
  on the same cores after a Dask round trip (and, on a first call, the cluster's
  start);
* on a local Dask cluster (one process per worker, 1 thread each), created on first
  use and kept for later calls (:func:`local_client`); each worker loads the kernels a
  run needs from numba's on-disk cache before that run's first chunk
  (:func:`_warm_problem`) and compiles none at start (:func:`prepare_worker`). On
  POSIX the workers are fresh interpreters (``python -m dask spec``, under a nanny that restarts a worker process
  that dies) with the scheduler in this process, not ``LocalCluster``'s spawned
  processes, which re-run the calling script's top level: a script needs no
  ``if __name__ == "__main__":`` guard (:func:`start_local_cluster`). So
  ``workers=None``, the default of ``solve``, means "every core when worthwhile"
  (:func:`auto_workers`: at least ``AUTO_MIN_PIECES`` boxes, Dask installed, more
  than one core; else one in-process batch, also silently without Dask); ``workers=1``
  is one in-process batch;
* on an existing Dask cluster: ``client=`` a ``distributed.Client`` or a scheduler
  address ``"tcp://host:port"`` (:func:`connect`: an unreachable address is a one-line
  :class:`SchedulerError` after ``CONNECT_TIMEOUT`` seconds, never a hang).

On Dask the ODE graph is sent once per worker (one small task returns it; each worker
fetches it from a peer when its first chunk needs it, builds the Taylor tapes once and
keeps them for every chunk; a worker new to it also takes one warm-up step first),
chunks are ordinary tasks, so Dask's scheduler retries a chunk whose worker died (up to
``distributed.scheduler.allowed-failures`` times) and the result is complete; a
cluster left without any worker for ``NO_WORKERS_TIMEOUT`` seconds ends the run with
:class:`WorkersLostError` (Dask would wait for ever). Each
worker process lets glibc keep freed memory (:func:`_tune_malloc`: Dask's
``MALLOC_TRIM_THRESHOLD_=65536`` costs CPU per chunk; docs/lab/code_notes.md).

Re-chunking (``rechunk``; with ``adaptive`` the sets a chunk's splitting creates): a
chunk runs until it holds ``RECHUNK_GROWTH`` (2) times as many sets as it started with
(and at least 2x the plan's mean chunk size and 2x ``RECHUNK_MIN_SETS`` = 64), stops
after that step (a hook, :class:`_Pause`) and returns its Solution so far and its sets
with their exact time (:class:`verified.solver.Start`). The driver cuts the sets into
contiguous pieces of about the plan's mean chunk size (at least ``RECHUNK_MIN_SETS``)
and runs each as a new chunk from that time (``solve(start=)``): on Dask at once, on
whichever worker is free, so the sets of one busy chunk spread over idle workers; in this
process depth-first. Every set goes to exactly one piece, so their union is the paused
chunk's set. What changes against the chunk run whole: each piece has its own step sizes;
a piece starts with the wrapping control's limit of the paused chunk but without the
stepper's guesses from its last step; the split due after the step a chunk paused at is
decided again by its pieces' first step; splitting judges a set against the union the
piece was cut from (``split_ratio`` times the widths of that union over the piece's own,
:attr:`Start.split_scale`); ``max_boxes`` is each initial chunk's budget: a piece may grow
to its parent's budget less the sets its siblings held when cut (so the pieces of one
chunk together may exceed it: each checks only its own). Measured on the mixed batch
(``benchmarks/bench_parallel.py --only rechunk``): see the benchmark. Default
(``rechunk=None``): on for adaptive runs on Dask, off in this process (one core gains
nothing from it); never with a consistency test (its record cannot be continued:
``rechunk=True`` is an error then) or with per-box exact parameters that differ.

Work stealing (on Dask, unless ``rechunk=False``; never with a consistency test): the
driver keeps each running piece's rate from its progress reports (over the last
``RATE_WINDOW`` s: a piece whose steps shorten late would look nearly done at its mean
rate). When a worker thread holds none of the run's pieces, the running piece with the
most time left -- if more than ``STEAL_MIN_S`` and it started with at least
``2 * STEAL_MIN_SETS`` sets -- is asked to pause after its current step (``client.run``
sets a flag in the workers that its :class:`_Pause` hook reads), and its sets are cut, as
above, into twice as many pieces as there are free threads (at least ``STEAL_MIN_SETS``
sets each: the last, smaller pieces even out the end). A piece in which some initial
pieces broke down is not paused (as above). Which pieces are cut, and when, depends on
timing; the result depends only on the cuts: ``Solution.stats["cuts"]`` records each
(the piece's place in the tree ``path``, ``steps`` taken when it paused, ``k`` pieces,
``why``: "sets", "lag" or "replay") and ``with replaying(sol): solve(..., workers=1,
chunks=len(sol.chunks))`` with ``sol``'s arguments reproduces ``sol`` in this process
float for float. When there are no more chunks than workers, chunk i is offered to
worker i first (Dask would otherwise queue several on the worker that holds the graph).

What the merged Solution means (the union is the same set a single batch encloses,
up to the step-size differences):

``t``, ``boxes``, ``hull``
    Every chunk has the same output times; ``boxes[k]`` concatenates the chunks' boxes
    at ``t[k]`` in chunk order (= the order of the initial boxes). Only the output
    times *every* chunk reached are kept.
``tube_t``, ``tube``, ``tube_hull``
    The chunks step at their own times. The merged tube is on the common grid: the
    union of all chunks' step boundaries up to ``t_reached``; ``tube[j]`` holds one box
    per chunk, the hull of that chunk's tube boxes over its step that contains
    ``[tube_t[j], tube_t[j + 1]]`` (sound: that step's boxes enclose the chunk's
    solutions on the whole step). The exact per-chunk tubes, at their own times, are in
    ``sol.chunks[i]["tube_t"]`` / ``["tube"]``.
``t_reached``, ``status``, ``reason``
    ``t_reached`` is the smallest over the chunks; ``status`` the worst
    (breakdown > interrupted > stopped > completed), ``reason`` names the chunk
    (``"chunk 3 (boxes 96..127): ..."``), or, where some initial pieces broke down,
    which (``"3 of 64 pieces failed (pieces 5, 17, 40 at t = 0.31: ...); 61 pieces
    verified to t = 2"``). A chunk that never ran (Ctrl-C, cancelled) counts as
    reaching ``t0``.
``piece_results``, ``surviving``
    Per initial piece its status, ``t_reached`` and reason: a chunk's own report where
    it ran as one batch (its pieces break down alone there, :mod:`verified.driver.batch`),
    else (not run, re-chunked) the chunk's outcome for each of its pieces. ``surviving``
    (where some pieces broke down and others went on): the chunks' parts that went on
    merged as above (a chunk without a failed piece whole, else its ``surviving``). A
    chunk in which a piece broke down is not re-chunked after that.
``stats``
    Counters summed over the chunks (``steps`` is the total of chunk steps,
    ``steps_max`` the longest chunk's), ``wall_s`` of the whole call, plus
    ``chunks``, ``workers``, ``backend`` ("inprocess", "dask-local", "dask"), ``rechunk``
    (on or off), ``pieces`` (solves run: chunks and pieces cut from them), ``rechunks``
    (chunks or pieces that paused and were cut),
    ``chunk_wall_s`` (each chunk's own solve time), ``setup_s`` (cluster start and
    graph shipping), ``sent_bytes`` / ``received_bytes`` (pickled sizes per run),
    ``merge_s`` (stitching and merging the chunks here after the last result; a family
    of pieces is stitched as soon as its last piece is in, during the run: ``stitch_s``),
    ``steal`` (on or off), ``cuts`` (see work stealing); on Dask ``warm_s`` (each new
    worker's first step of this problem: its kernels loaded) and ``timeline`` (per
    piece run: worker pid, parent piece, sets, start time, steps, task start and end on
    the worker, its thread's CPU seconds, result here, why it paused; seconds after the
    call: where the time went, benchmarks/bench_parallel.py).
``chunks``
    Per initial chunk: boxes, status, steps, its tube, ...; with re-chunking ``pieces``:
    each piece's parent, start time, sets at its start, status, steps, wall time, worker.
    A re-chunked chunk's outputs are the boxes of its pieces that recorded each output
    (depth-first order), its tube one box per piece live on each interval of the union
    of its pieces' step times (the hull of that piece's step), ``t_reached`` and
    ``status`` those of its earliest worst piece not cut.
``consistency``
    With an energy test: the chunks' records interleaved by time (RA(t), H_H, H_V
    points of every chunk sorted by t; the tests of every chunk); each chunk's own
    record in ``sol.chunks[i]["consistency"]``.

Hooks: on Dask every chunk gets its own (pickled) copy of ``hooks`` and
``consistency``; in-process the hooks are shared by the chunks (one run after the
other) and ``consistency`` is copied per chunk. :class:`verified.driver.hooks.StopAfterWall`
becomes one wall-clock deadline for the whole call (a chunk that starts after it stops
after one step). ``progress(t, t_end)`` is called in this process with the chunks'
mean time reached (workers report every ~0.3 s). Ctrl-C while waiting cancels the
chunks still running and returns what is verified (``status="interrupted"``).

This module knows nothing about robots.
"""

from __future__ import annotations

import atexit
import contextlib
import contextvars
import copy
import ctypes
import hashlib
import importlib
import inspect
import json
import logging
import math
import os
import pickle
import queue
import signal
import subprocess
import sys
import threading
import time
import uuid
import warnings
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from verified.driver.hooks import Hook, StopAfterWall
from verified.arith.interval import Interval, concatenate, hull, stack
from verified.driver.batch import VerifiedODE, solve_batch
from verified.driver.solution import PieceResult, Solution, Start, pieces_summary
from verified.driver.solver_args import (
    _subdivision, check_arithmetic, check_graph, check_params, check_settings, initial_boxes
)

__all__ = ["solve_parallel", "plan_chunks", "merge_solutions", "local_client", "connect", "close_local_clients",
           "default_workers", "dask_available", "auto_workers", "subprocess_workers_supported", "SchedulerError",
           "WorkerStartError", "WorkersLostError", "NO_WORKERS_TIMEOUT", "CONNECT_TIMEOUT", "CHUNK_TARGET",
           "MIN_CHUNK_BOXES", "RECHUNK_GROWTH", "interrupt_runs", "start_local_cluster", "prepare_worker", "replaying",
           "STEAL_MIN_S", "STEAL_MIN_SETS"]

#: seconds to wait for a scheduler before :class:`SchedulerError`
CONNECT_TIMEOUT = 10.0

#: seconds on top of the connect timeout for the scheduler's handshake (:func:`connect`)
HANDSHAKE_GRACE = 5.0

#: set by :func:`interrupt_runs`: every chunked run waiting on Dask in this process stops
#: as Ctrl-C stops it (a scenario batch runs them in threads, where no signal arrives)
_INTERRUPT = threading.Event()
#: default chunk size aimed at (boxes): below ~128 boxes per batch the fixed cost of a
#: step (Python per step and chunk) shows (docs/lab/code_notes.md)
CHUNK_TARGET = 512
#: at most this many chunks per worker by default (load balance against fixed costs)
MAX_CHUNKS_PER_WORKER = 4
#: the default plan never makes a chunk smaller than this (boxes). A step of the batched
#: solver costs ~2 ms of Python whatever the batch size plus ~0.15 ms per box, so a
#: small batch split in two pays the fixed cost twice; from 64 boxes per chunk splitting
#: costs no extra CPU (docs/lab/code_notes.md). The price: 64-127 boxes are not split
#: (ask with ``chunks=2``). An explicit ``chunks=`` is
#: not bound by it
MIN_CHUNK_BOXES = 64
#: ``workers="auto"`` uses a cluster only from this many boxes on (and >= 2 per worker):
#: below, the default plan is one chunk, which runs in this process anyway (the
#: cluster's start, once per process, is the reason; docs/lab/code_notes.md)
AUTO_MIN_PIECES = 2 * MIN_CHUNK_BOXES
#: what ``workers=None`` means: True, every core when worthwhile (:func:`auto_workers`);
#: False, one in-process batch (the benchmarks that time one core against one core,
#: against CAPD or earlier runs, set it; an explicit ``workers=`` is unaffected)
DEFAULT_PARALLEL = True
#: re-chunking (``rechunk``): a piece pauses once it holds this many times as many sets
#: as it started with (and at least this many times the plan's mean chunk size and
#: ``RECHUNK_MIN_SETS``), and its sets are cut into pieces of about the larger of the two
RECHUNK_GROWTH = 2
#: pieces cut from a paused chunk hold at least this many sets (the fixed cost of a step,
#: ~2 ms of Python per step and batch, against ~0.15 ms per set: MIN_CHUNK_BOXES); a test
#: may lower it
RECHUNK_MIN_SETS = MIN_CHUNK_BOXES
#: work stealing (``rechunk``, on Dask): when a worker thread is free and no piece waits
#: for one, the running piece with the most time left (estimated from its progress
#: reports), if that is more than STEAL_MIN_S seconds, is asked to pause after its step
#: and its sets are cut into new pieces for the free threads; a piece starting with
#: fewer than 2 * STEAL_MIN_SETS sets is not cut (a test may lower both)
STEAL_MIN_S = 1.0
#: seconds of a piece's latest progress reports its rate is taken over
RATE_WINDOW = 1.5
STEAL_MIN_SETS = MIN_CHUNK_BOXES // 2
#: solve's default max_boxes (each initial chunk's budget of sets)
_MAX_BOXES = inspect.signature(solve_batch).parameters["max_boxes"].default
_STATUS_RANK = {"completed": 0, "stopped": 1, "interrupted": 2, "breakdown": 3}


class SchedulerError(ConnectionError):
    """A Dask scheduler that cannot be reached (the message names the address)."""


class WorkerStartError(RuntimeError):
    """Local Dask workers that could not be started (the message says why and what to do)."""


class WorkersLostError(RuntimeError):
    """Every worker of the Dask cluster left during a run and none came back within
    :data:`NO_WORKERS_TIMEOUT` seconds (the message names the chunks left)."""


#: seconds a run waits for a cluster without any worker before :class:`WorkersLostError`
#: (Dask itself would keep the chunks waiting for ever: its ``no-workers-timeout`` is off)
NO_WORKERS_TIMEOUT = 60.0


def dask_available() -> bool:
    """Whether dask.distributed (an optional extra) can be imported: imported here, not
    only found, so that an installation that fails to import counts as missing."""
    try:
        importlib.import_module("distributed")
    except ImportError:
        return False
    return True


def default_workers() -> int:
    """The cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def _in_dask_worker() -> bool:
    if "distributed" not in sys.modules:
        return False
    try:
        from distributed import get_worker  # (the optional extra, already in sys.modules here)
        get_worker()
    except ValueError:
        return False
    return True


def _box_count(ode, x0, subdivision) -> int:
    """The number of initial boxes ``solve`` would run (0 when the arguments are bad:
    solve's own checks report them)."""
    try:
        graph = ode.graph if isinstance(ode, VerifiedODE) else ode
        n = int(graph.n_inputs)
        nb = initial_boxes(x0, n, None).shape[0]
        if subdivision is not None:
            nb *= math.prod(int(k) for k in np.broadcast_to(_subdivision(subdivision, n), (n,)))
        return int(nb)
    except Exception:  # noqa: BLE001
        return 0


def auto_workers(ode, x0, subdivision=None):
    """What ``solve(..., workers=None)`` means: ``"auto"`` (a local cluster of every
    core) when that is worthwhile, else None (one batch in this process). Worthwhile:
    at least ``AUTO_MIN_PIECES`` boxes (and 2 per core), more than one core,
    dask.distributed installed (an optional extra), workers that do not re-run the
    calling script (POSIX, :func:`subprocess_workers_supported`) and not already on a
    Dask worker (a chunk, or a user's task, runs in its process)."""
    if not DEFAULT_PARALLEL:
        return None
    n = default_workers()
    if n < 2:
        return None
    nb = _box_count(ode, x0, subdivision)
    if nb < max(AUTO_MIN_PIECES, 2 * n):
        return None
    if not subprocess_workers_supported() or not dask_available() or _in_dask_worker():
        return None
    return "auto"


def plan_chunks(n_pieces: int, workers: int, chunks: int | None = None,
                max_per_worker: int = MAX_CHUNKS_PER_WORKER) -> list[tuple[int, int]]:
    """Contiguous ``(start, stop)`` ranges of the initial boxes, one per chunk.

    Default (``chunks=None``): ``workers`` chunks, more (up to ``max_per_worker`` per
    worker) when each would still hold ``CHUNK_TARGET`` boxes, fewer when a chunk would
    hold less than ``MIN_CHUNK_BOXES`` boxes (a batch below ``2 * MIN_CHUNK_BOXES`` is one
    chunk). An explicit ``chunks`` is used as given (never more chunks than boxes).
    Neighbouring boxes behave alike, so contiguous chunks keep the boxes that need
    short steps together."""
    if chunks is None:
        per = max(1, min(max_per_worker, n_pieces // max(1, workers * CHUNK_TARGET)))
        chunks = max(1, min(workers * per, n_pieces // MIN_CHUNK_BOXES))
    chunks = max(1, min(int(chunks), n_pieces))
    edges = np.linspace(0, n_pieces, chunks + 1).round().astype(int)
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:]) if b > a]


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
    deadline for the whole call."""
    out, deadline = [], None
    for h in list(hooks or ()):
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


# ----------------------------------------------------------------------------- pieces
@dataclass
class _Piece:
    """One solve of a chunked run: an initial chunk (``start`` None) or a piece cut from
    the sets of a paused one (``parent``), continuing at ``start.t_exact``."""

    family: int  # the initial chunk it descends from
    parent: int | None
    lo: np.ndarray  # (B, n) boxes it starts from (with start: the hull of its sets)
    hi: np.ndarray
    params: object
    start: Start | None
    max_boxes: int
    pause_at: int | None
    path: tuple = ()  # (family, child position, ...): its place in the tree, what a replay names
    at_step: int | None = None  # a replayed cut: pause after this many steps ...
    cut_k: int | None = None  # ... into this many pieces
    stealable: bool = False  # the driver may ask it to pause when it lags (its sets resumable)
    sol: Solution | None = None
    paused: Start | None = None
    children: list = field(default_factory=list)


def _resume_params(params):
    """``(ok, params)``: what a piece cut from a chunk with these parameters gets
    (``solve(start=)`` takes the parameters as given to the chunk, or their hull). Per-box
    exact parameters that differ cannot follow sets that split: no re-chunking then."""
    if params is None or params.ndim == 1:
        return True, params
    if (params.width() > 0).any():
        return True, hull(params, axis=0)  # carried as states, clipped to this hull as in the chunk
    if (params.lo == params.lo[:1]).all() and (params.hi == params.hi[:1]).all():
        return True, params[0]
    return False, None


class _Pieces:
    """The pieces of a chunked run: the initial chunks and, with re-chunking, the pieces
    cut from the sets of those that paused (their sets doubled, they lagged, or a replay
    said so); :meth:`families` stitches each initial chunk's pieces into one Solution for
    :func:`merge_solutions`, each as soon as its last piece is in (:meth:`done`), so the
    stitching is off the critical path of a run whose chunks end at different times.

    ``replay``: ``{path: (steps, k)}`` from a run's ``stats["cuts"]``: the piece at that
    place pauses after that many steps and is cut into ``k`` pieces, which reproduces that
    run's pieces (and, the arithmetic being deterministic, its result float for float)."""

    def __init__(self, boxes, ranges, chunk_params, rechunk: bool, max_boxes: int, steal: bool = False,
                 replay: dict | None = None, outs=None, t0=None):
        self.n = boxes.shape[-1]
        self.ranges = ranges
        # pieces of about the plan's mean chunk size, not below RECHUNK_MIN_SETS
        self.target = max(1, RECHUNK_MIN_SETS, int(round(boxes.shape[0] / len(ranges))))
        self.rechunk, self.steal = bool(rechunk), bool(steal)
        self.replay = dict(replay or {})
        self.outs, self.t0 = outs, t0
        self.items: list[_Piece] = []
        self.cuts = 0
        self.cut_log: list = []  # per cut: path, steps, k, why (Solution.stats["cuts"])
        self.family_params = []
        self.resumable = []
        self.stitched: dict = {}  # family -> its Solution, stitched when its last piece came in
        self.stitch_s = 0.0
        for i, (a, b) in enumerate(ranges):
            p = chunk_params(a, b)
            ok, rp = _resume_params(p)
            self.family_params.append(rp)
            self.resumable.append(ok)
            self._add(_Piece(family=i, parent=None, lo=boxes.lo[a:b], hi=boxes.hi[a:b], params=p, start=None,
                             max_boxes=max_boxes, pause_at=self._pause_at(b - a) if rechunk and ok else None,
                             path=(i,)))

    def _add(self, piece: _Piece) -> int:
        got = self.replay.get(piece.path)
        if got is not None and self.resumable[piece.family]:
            piece.at_step, piece.cut_k = int(got[0]), int(got[1])
        piece.stealable = (self.steal and self.resumable[piece.family] and got is None
                           and piece.lo.shape[0] >= 2 * STEAL_MIN_SETS)
        self.items.append(piece)
        return len(self.items) - 1

    def _pause_at(self, n_sets: int) -> int:
        return RECHUNK_GROWTH * max(int(n_sets), self.target)

    def done(self, index: int, sol, paused, k: int | None = None, why: str | None = None) -> list[int]:
        """Record piece ``index``'s Solution; when it paused (``paused``: its Start), cut
        its sets into new pieces (``k`` of them; None: a replay's number, else about the
        plan's mean chunk size each) and return their indices (to be run). A family whose
        last piece this was is stitched now."""
        piece = self.items[index]
        piece.sol, piece.paused = sol, paused
        new = [] if paused is None else self._cut(index, piece.cut_k if piece.cut_k is not None else k, why)
        if not new and self.outs is not None and self._family_done(piece.family):
            t = time.perf_counter()
            self.stitched[piece.family] = self._stitch(piece.family, self.outs, self.t0)
            self.stitch_s += time.perf_counter() - t
        return new

    def _family_done(self, family: int) -> bool:
        return all(self.items[i].sol is not None for i in _dfs(self.items, family))

    def _cut(self, index: int, k: int | None = None, why: str | None = None) -> list[int]:
        parent = self.items[index]
        st = parent.paused
        sets = st.sets
        S = sets.n_sets
        if k is None:
            k = int(S // self.target)
        k = max(2, min(S, int(k)))
        edges = np.linspace(0, S, k + 1).round().astype(int)
        # every set in exactly one piece: contiguous ranges covering 0..S (none empty)
        edges = np.unique(edges)
        if edges[0] != 0 or edges[-1] != S:  # (cannot happen: linspace's ends are exact)
            raise RuntimeError(f"re-chunking would not cover the {S} sets (a bug)")
        X = sets.hull()  # (S, N)
        W = np.asarray(hull(X, axis=0).width(), float)  # the union the parent's splitting judged against
        # (the paused run's own scale: the Start it was given; a pause hook's Start has none)
        own = None if parent.start is None else parent.start.split_scale
        scale0 = np.ones_like(W) if own is None else np.asarray(own, float)
        new = []
        for j, (a, b) in enumerate(zip(edges[:-1], edges[1:])):
            idx = np.arange(a, b)
            part = sets.take(idx)
            Xp = X[idx]
            Wp = np.asarray(hull(Xp, axis=0).width(), float)
            with np.errstate(divide="ignore", invalid="ignore"):
                scale = np.where(Wp > 0, scale0 * W / Wp, scale0)
            start = Start(sets=part, t_exact=st.t_exact, h_limit=st.h_limit, split_scale=scale)
            # splitting budget: the parent's, less the sets its other pieces held when cut
            budget = int(max(b - a, parent.max_boxes - (S - (b - a))))
            new.append(self._add(_Piece(family=parent.family, parent=index, lo=np.asarray(Xp.lo[:, :self.n]),
                                        hi=np.asarray(Xp.hi[:, :self.n]), params=self.family_params[parent.family],
                                        start=start, max_boxes=budget,
                                        pause_at=self._pause_at(b - a) if self.rechunk else None,
                                        path=parent.path + (j,))))
        parent.children = new
        self.cuts += 1
        steps, why = parent.sol.stats.get("pause", (None, why)) if parent.sol is not None else (None, why)
        self.cut_log.append(dict(path=list(parent.path), steps=steps, k=len(new), sets=int(S),
                                 t=float(st.t_exact), why=why))
        return new

    # ------------------------------------------------------------------ stitching
    def _dfs(self, root: int) -> list[int]:
        return _dfs(self.items, root)

    def families(self, outs, t0):
        """One Solution per initial chunk (None: it never ran): see :func:`_stitch`; the
        families stitched as they completed are taken as they are."""
        return [self.stitched[i] if i in self.stitched else self._stitch(i, outs, t0)
                for i in range(len(self.ranges))]

    def _stitch(self, root: int, outs, t0):
        """See :func:`stitch`."""
        return stitch(self.items, root, outs, t0, self.n)


def stitch(items: list, root: int, outs, t0, n: int):
    """The pieces of initial chunk ``root`` as one Solution, as if that chunk had run
    alone. ``items``: the pieces (:class:`_Piece`: ``sol``, ``start``, ``parent``,
    ``children``, ``lo``), a piece's children continuing from its sets where it stopped
    (``start``); ``outs``: the run's output times (every child's outputs after its start
    are among them). ``t``/``boxes``: the outputs every path of pieces recorded (each
    output's boxes concatenated over the pieces that recorded it, depth-first order);
    the tube on the union of the pieces' step times, one box per piece live on each
    interval (the hull of its step's boxes); ``t_reached``/``status``/``reason`` those of
    the earliest worst leaf (a piece not cut; one that never ran counts as interrupted
    at its start); counters summed over the pieces."""
    if items[root].sol is None or not items[root].children:
        return items[root].sol  # (not re-chunked: the chunk's own Solution)
    order = _dfs(items, root)
    index_of = {float(t): j for j, t in enumerate(outs)}
    recorded = {}
    for i in order:
        sol = items[i].sol
        if sol is None:
            recorded[i] = {}
            continue
        ts = np.asarray(sol.t, float)
        first = 0 if items[i].start is None else 1  # a continued piece's t[0] is its start
        recorded[i] = {index_of[float(t)]: j for j, t in enumerate(ts[first:], first)}
    leaves = [i for i in order if not items[i].children]
    worst, reason, t_reached, reason_t = "completed", "", math.inf, math.inf
    k_f = len(outs)
    for leaf in leaves:
        sol = items[leaf].sol
        if sol is None:
            st = "interrupted"
            tr = float(items[leaf].start.t_exact) if items[leaf].start is not None else float(t0)
            why = "interrupted before this piece ran"
        else:
            st, tr, why = sol.status, float(sol.t_reached), sol.reason
        rank = _STATUS_RANK.get(st, 3)
        if st != "completed" and (rank > _STATUS_RANK[worst] or (rank == _STATUS_RANK[worst] and tr < reason_t)):
            worst, reason_t = st, tr
            reason = why if items[leaf].start is None else f"piece at t = {float(items[leaf].start.t_exact):g}: {why}"
        t_reached = min(t_reached, tr)
        got, i = set(), leaf
        while i is not None:
            got |= set(recorded[i])
            i = items[i].parent
        k = 0
        while k < len(outs) and k in got:
            k += 1
        k_f = min(k_f, k)
    boxes = []
    for k in range(k_f):
        parts = [items[i].sol.boxes[recorded[i][k]] for i in order if k in recorded[i]]
        boxes.append(concatenate(parts, axis=0))
    ran = [i for i in order if items[i].sol is not None]
    grid = np.unique(np.concatenate([np.asarray(items[i].sol.tube_t, float) for i in ran]))
    grid = grid[grid <= t_reached]
    tube = []
    lo_h, hi_h = [], []
    if grid.size > 1:
        # grid step j is [grid[j], grid[j+1]]: found by its start (its midpoint, for a step
        # one ulp long, rounds to its end)
        starts = grid[:-1]
        rows_lo = [[] for _ in starts]
        rows_hi = [[] for _ in starts]
        for i in order:
            sol = items[i].sol
            if sol is None or not len(sol.tube):
                continue
            tt = np.asarray(sol.tube_t, float)
            tl, th = _chunk_tube_hulls(sol)
            js = np.flatnonzero((starts >= tt[0]) & (starts < tt[-1]))
            for j, s in zip(js, np.searchsorted(tt, starts[js], side="right") - 1):
                rows_lo[j].append(tl[s])
                rows_hi[j].append(th[s])
        for j in range(starts.size):
            if not rows_lo[j]:  # every path of pieces covers every interval up to t_reached
                raise RuntimeError(f"re-chunking lost the tube on [{grid[j]}, {grid[j + 1]}] (a bug)")
            lo, hi = np.array(rows_lo[j]), np.array(rows_hi[j])
            tube.append(Interval._from_bounds(lo, hi))
            lo_h.append(lo.min(axis=0))
            hi_h.append(hi.max(axis=0))
    tube_hull = (Interval._from_bounds(np.array(lo_h), np.array(hi_h)) if tube
                 else Interval._from_bounds(np.zeros((0, n)), np.zeros((0, n))))
    stats = {}
    for i in ran:
        for key, v in items[i].sol.stats.items():
            if key in ("order", "worker_pid", "chunk_task_s", "boxes", "final_boxes", "max_boxes") \
                    or isinstance(v, bool):
                continue
            if isinstance(v, (int, float, np.integer, np.floating)):
                stats[key] = stats.get(key, 0) + v
    r = items[root].sol
    stats["order"] = r.stats.get("order")
    stats["worker_pid"] = r.stats.get("worker_pid")
    stats["boxes"] = r.stats.get("boxes")
    done = [items[i].sol for i in leaves if items[i].sol is not None]
    stats["final_boxes"] = sum(s.stats.get("final_boxes", 0) for s in done)
    stats["max_boxes"] = sum(s.stats.get("max_boxes", 0) for s in done)  # (approximate: at different times)
    stats["pieces"] = len(ran)
    stats["rechunks"] = sum(1 for i in order if items[i].children)
    sol = Solution(t=np.asarray(outs[:k_f], float), boxes=boxes, hull=stack([hull(b, axis=0) for b in boxes], axis=0),
                   tube_t=grid, tube=tube, tube_hull=tube_hull, t_reached=float(grid[-1]), status=worst,
                   reason=reason if worst != "completed" else "", stats=stats, state_names=r.state_names,
                   consistency=r.consistency if len(ran) == 1 else None)
    sol.pieces = [dict(parent=items[i].parent, t_start=float(items[i].start.t_exact) if items[i].start else float(t0),
                       sets=(items[i].lo.shape[0]), status=None if items[i].sol is None else items[i].sol.status,
                       t_reached=None if items[i].sol is None else float(items[i].sol.t_reached),
                       steps=None if items[i].sol is None else items[i].sol.stats.get("steps"),
                       wall_s=None if items[i].sol is None else items[i].sol.stats.get("wall_s"),
                       worker_pid=None if items[i].sol is None else items[i].sol.stats.get("worker_pid"))
                  for i in order]
    return sol


def _dfs(items: list, root: int) -> list[int]:
    """Piece ``root`` and its descendants, depth first (children in order)."""
    out, stack = [], [root]
    while stack:
        i = stack.pop()
        out.append(i)
        stack.extend(reversed(items[i].children))
    return out


# ----------------------------------------------------------------------------- Dask
_LOCAL: dict = {}  # workers -> (cluster, client)

#: seconds to wait for the local workers to connect (:func:`local_client`)
LOCAL_START_TIMEOUT = 120.0


def subprocess_workers_supported() -> bool:
    """Whether :func:`local_client` starts its workers as fresh interpreters (every POSIX
    system; Dask's subprocess workers do not run on Windows)."""
    return os.name == "posix"


def _worker_env() -> dict:
    """The environment of a local worker process: this one's, with this process's
    ``sys.path`` (a spawned process got it; a fresh interpreter needs it on
    ``PYTHONPATH``: the script's folder, a path added at run time) and Dask
    configuration (also what was set at run time with ``dask.config.set``)."""
    import dask.config  # (optional extra, only to start local workers)
    env = dict(os.environ)
    path = [os.getcwd() if p == "" else p for p in sys.path]
    env["PYTHONPATH"] = os.pathsep.join(dict.fromkeys(path))
    # (its errors only, as LocalCluster(silence_logs=ERROR): a nanny left without this
    # process logs its goodbye at INFO)
    config = dask.config.merge(dask.config.global_config, {"logging": {"distributed": "error"}})
    env["DASK_INTERNAL_INHERIT_CONFIG"] = dask.config.serialize(config)
    return env


def _subprocess_worker_class():
    """:class:`distributed.deploy.subprocess.SubprocessWorker` started as its own session
    (Ctrl-C in a terminal reaches the whole foreground process group: the workers would
    shut down with this process's KeyboardInterrupt) with :func:`_worker_env`."""
    # (asyncio: ~60 ms to import, only for this class; distributed: the optional extra)
    import asyncio

    from distributed.deploy.subprocess import SubprocessWorker

    class _Worker(SubprocessWorker):
        async def _start(self) -> None:
            opts = dict(self.worker_kwargs)
            if self.name is not None:
                opts.setdefault("name", self.name)  # the cluster tracks its workers by name
            cmd = [sys.executable, "-m", "dask", "spec", self.scheduler,
                   "--spec", json.dumps({"cls": self.worker_class, "opts": opts})]
            self.process = await asyncio.create_subprocess_exec(
                *cmd, env=_worker_env(), stdin=subprocess.DEVNULL, start_new_session=True)

    return _Worker


def start_local_cluster(workers: int):
    """(cluster, client): ``workers`` 1-thread worker processes on this machine (what
    :func:`local_client` starts, before it runs :func:`prepare_worker` in each; the caller
    closes both).

    Not ``LocalCluster``: its nannies start the workers with multiprocessing's "spawn",
    which first re-runs the calling script's top level (``__main__``) in every worker,
    so a script without ``if __name__ == "__main__":`` ran itself again in each and
    failed. Here (POSIX) the scheduler runs in this process, as in ``LocalCluster``, and
    each worker is a nanny started as a fresh interpreter, ``python -m dask spec``
    (Dask's :mod:`distributed.deploy.subprocess`), whose ``__main__`` is Dask's command
    line: the script is never imported there. Its nanny restarts a worker process that
    dies (a killed worker's chunk is retried by the scheduler). The workers are their
    own session (a terminal's Ctrl-C does not stop them) and leave when this process
    does: a worker that loses the scheduler closes, and its nanny with it."""
    # (dask.distributed: an optional extra, imported only when a cluster is asked for)
    from distributed import Client, Scheduler, SpecCluster
    from distributed.worker_memory import parse_memory_limit

    host = "127.0.0.1"
    worker = {"cls": _subprocess_worker_class(),
              "options": {"worker_class": "distributed.Nanny",
                          "worker_kwargs": {"host": host, "nthreads": 1, "silence_logs": logging.ERROR,
                                            "memory_limit": parse_memory_limit("auto", 1, workers,
                                                                                logger=logging.getLogger(__name__))}}}
    # the scheduler's HTTP server on a free port (":8787" warns when another cluster runs)
    scheduler = {"cls": Scheduler, "options": {"host": host, "port": 0, "dashboard": True,
                                               "dashboard_address": ":0"}}
    cluster = SpecCluster(workers={i: worker for i in range(workers)}, worker=worker, scheduler=scheduler,
                          name="mbs-verified-local", silence_logs=logging.ERROR)
    try:
        client = Client(cluster, set_as_default=False)
        # the nannies only start their processes: wait until every worker has connected,
        # and give up at once when one of those processes has exited
        deadline = time.monotonic() + LOCAL_START_TIMEOUT
        while True:
            try:
                client.wait_for_workers(workers, timeout=0.5)
                break
            except TimeoutError:
                codes = [getattr(getattr(w, "process", None), "returncode", None) for w in cluster.workers.values()]
                dead = [c for c in codes if c is not None]
                if dead:
                    raise RuntimeError(f"a worker process exited with code {dead[0]} while starting "
                                       "(its error is above)") from None
                if time.monotonic() > deadline:
                    raise RuntimeError(f"the workers did not connect within {LOCAL_START_TIMEOUT:g} s") from None
    except BaseException:
        cluster.close()
        raise
    return cluster, client


def local_client(workers: int):
    """A ``distributed.Client`` of a local cluster with ``workers`` processes of one
    thread each, created on first use (:func:`prepare_worker` run in every worker) and
    kept for later calls until :func:`close_local_clients` / exit.

    On POSIX the workers are fresh interpreters (:func:`start_local_cluster`): the
    calling script needs no ``if __name__ == "__main__":`` guard. Elsewhere it is a
    ``LocalCluster``, whose spawned workers re-run an unguarded script's top level:
    :class:`WorkerStartError` says so."""
    got = _LOCAL.get(workers)
    if got is not None and got[1].status == "running":
        return got[1]
    if subprocess_workers_supported():
        try:
            cluster, client = start_local_cluster(workers)
        except Exception as exc:  # noqa: BLE001 - one line, the cause named
            why = " ".join(str(exc).split()) or type(exc).__name__
            raise WorkerStartError(f"could not start {workers} local Dask worker processes ({why}); pass "
                                   "workers=1 to run in this process") from None
    else:  # pragma: no cover - Windows
        from distributed import Client, LocalCluster  # (optional extra, only for a cluster)
        try:
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0",
                                   silence_logs=logging.ERROR)
        except RuntimeError as exc:
            # Dask spawns its worker processes, and a spawned process first re-runs the
            # calling script's top level: unguarded, that reaches this call again while the
            # process is still starting, and the parent only sees "Nanny failed to start"
            raise WorkerStartError(
                f"could not start {workers} local Dask worker processes ({exc}); worker processes re-run "
                "the calling script's top level, so put it under `if __name__ == \"__main__\":`, or pass "
                "workers=1 to run in this process") from None
        client = Client(cluster, set_as_default=False)
    client.run(prepare_worker)
    client.register_worker_callbacks(prepare_worker)  # also workers restarted later (a killed worker)
    _LOCAL[workers] = (cluster, client)
    return client


def close_local_clients():
    """Shut down the local clusters :func:`local_client` started."""
    # the nannies' and scheduler's goodbyes (INFO lines, a WARNING about the graph)
    quiet = [logging.getLogger(n) for n in list(logging.root.manager.loggerDict) if n.startswith("distributed")]
    levels = [lg.level for lg in quiet]
    for lg in quiet:
        lg.setLevel(logging.CRITICAL)
    try:
        while _LOCAL:
            _, (cluster, client) = _LOCAL.popitem()
            for key in [k for k in _SHIPPED if k[0] == id(client)]:
                _SHIPPED.pop(key)
            try:
                client.close()
                cluster.close()
            except Exception:  # noqa: BLE001 - shutting down anyway
                pass
    finally:
        for lg, lv in zip(quiet, levels):
            lg.setLevel(lv)


atexit.register(close_local_clients)


def connect(address: str, timeout: float | None = None):
    """A ``distributed.Client`` for the scheduler at ``address`` (``tcp://host:port``).
    Raises :class:`SchedulerError` naming the address when it cannot be reached within
    ``timeout`` seconds (default :data:`CONNECT_TIMEOUT`)."""
    if not isinstance(address, str) or "://" not in address and ":" not in address:
        raise ValueError(f"scheduler address must look like tcp://host:port, got {address!r}")
    try:
        from distributed import Client  # (optional extra: its absence is the error below)
    except ImportError:
        raise SchedulerError(f"cannot use the Dask scheduler at {address}: dask.distributed is not installed "
                             "(pip install 'mbs-verified[parallel]')") from None
    timeout = CONNECT_TIMEOUT if timeout is None else float(timeout)
    # Client(timeout=) bounds the connection but not the handshake: an address that
    # accepts connections and does not answer as a scheduler (a dashboard port, an HTTP
    # server) hung for ever. So the client is made in a daemon thread and waited for.
    out: dict = {}

    def make():
        try:
            out["client"] = Client(address, timeout=timeout, set_as_default=False)
        except BaseException as e:  # noqa: BLE001 - reported below, in one line
            out["error"] = e
    th = threading.Thread(target=make, name="mbs-verified-connect", daemon=True)
    th.start()
    th.join(timeout + HANDSHAKE_GRACE)
    if "client" in out:
        return out["client"]
    e = out.get("error")
    why = "no answer as a Dask scheduler" if e is None else type(e).__name__
    raise SchedulerError(f"cannot reach the Dask scheduler at {address} within {timeout:g} s ({why})")


def _identity(x):
    return x


def _thread_count(client) -> int:
    """Threads of the workers connected to ``client``'s scheduler now (0 when it cannot
    be asked)."""
    try:
        return int(sum(client.nthreads().values()))
    except Exception:  # noqa: BLE001 - the scheduler may be gone too: not this check's error
        return -1


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


# ----------------------------------------------------------------------------- driver
_REPLAY: contextvars.ContextVar = contextvars.ContextVar("mbs_verified_replay", default=None)


@contextlib.contextmanager
def replaying(run):
    """Inside ``with replaying(sol):`` a chunked ``solve`` (``chunks=``, ``workers=``,
    ``client=``) runs ``sol``'s plan and cuts: its chunks' boxes and, from
    ``sol.stats["cuts"]``, each re-chunked piece paused after the same number of steps
    and cut into the same number of pieces; no new cut is made (no stealing). Work
    stealing depends on timing; the result depends only on the cuts, so
    ``with replaying(sol): solve(..., workers=1, chunks=len(sol.chunks))`` with ``sol``'s
    other arguments reproduces ``sol`` in this process float for float. ``run``: a
    chunked run's Solution, or its ``stats["cuts"]`` (then the plan is this call's)."""
    token = _REPLAY.set(run)
    try:
        yield
    finally:
        _REPLAY.reset(token)


def solve_parallel(ode, x0, t_span, *, workers=None, client=None, chunks=None, **kwargs):
    """``solve(ode, x0, t_span, **kwargs)`` in chunks (see the module docstring).

    workers : None, "auto" or an int >= 1. None and "auto": every core of this machine
        (:func:`default_workers`) when Dask is installed and there are at least
        ``AUTO_MIN_PIECES`` boxes, else in-process, silently (on Windows, whose local
        workers would re-run an unguarded script, None is in-process and "auto" a
        ``LocalCluster``). 1: in-process. An int > 1 without Dask warns and runs
        in-process. A plan of one chunk runs in-process too. Ignored when ``client``
        is given (then even one chunk runs on that cluster).
    client : None, a ``distributed.Client`` or a scheduler address (str)
    chunks : None (default plan, :func:`plan_chunks`: no chunk below
        ``MIN_CHUNK_BOXES`` boxes) or the number of chunks, used as given
    rechunk : None, True or False (in ``kwargs``; module docstring): cut the sets of a
        chunk whose adaptive splitting doubled them into new chunks. None: on for
        ``adaptive`` runs on Dask (a local cluster or ``client``), off in this process.
        True also in this process, and with ``workers > 1`` also for a plan of one chunk
        (which then runs on the cluster instead of here).
    """

    wall0 = time.perf_counter()
    t_wall0 = time.time()
    # the same argument checks as solve, before any work
    settings = {k: kwargs[k] for k in ("t_eval", "order", "tol", "h_max", "h_min", "max_steps", "max_width",
                                       "adaptive", "split_ratio", "max_boxes", "wrap_target", "merge_slack",
                                       "error_basis", "progress") if k in kwargs}
    t0, t1, outs, _ = check_settings(t_span=t_span, **settings)
    graph = check_graph(ode.graph if isinstance(ode, VerifiedODE) else ode)
    arithmetic = kwargs.get("arithmetic")
    if isinstance(ode, VerifiedODE):
        if arithmetic is not None and check_arithmetic(arithmetic) != ode.arithmetic:
            raise ValueError(f"arithmetic={arithmetic!r} differs from the VerifiedODE's {ode.arithmetic!r}")
        arithmetic = ode.arithmetic
    arithmetic = check_arithmetic("interval" if arithmetic is None else arithmetic)
    if chunks is not None and (isinstance(chunks, bool) or not isinstance(chunks, (int, np.integer)) or chunks < 1):
        raise ValueError(f"chunks must be None or an integer >= 1, got {chunks!r}")
    rechunk = kwargs.pop("rechunk", None)
    if rechunk is not None and not isinstance(rechunk, (bool, np.bool_)):
        raise ValueError(f"rechunk must be None, True or False, got {rechunk!r}")
    if rechunk and kwargs.get("consistency") is not None:
        raise ValueError("rechunk=True cannot continue a consistency test in new chunks: pass rechunk=False "
                         "(or None)")
    kwargs.pop("start", None)
    replay = kwargs.pop("replay", None)
    if replay is None:
        replay = _REPLAY.get()
    replay_ranges = None
    if replay is not None:
        if isinstance(replay, Solution):  # its plan and its cuts
            if not replay.chunks or "cuts" not in replay.stats:
                raise ValueError("replay=: a Solution of a chunked run (with chunks and stats['cuts'])")
            replay_ranges = [tuple(int(v) for v in c["boxes"]) for c in replay.chunks]
            replay = replay.stats["cuts"]
        try:
            replay = {tuple(int(v) for v in c["path"]): (int(c["steps"]), int(c["k"])) for c in replay}
        except (TypeError, KeyError, ValueError):
            raise ValueError("replay must be a chunked run's Solution or its stats['cuts'] (dicts with path, "
                             "steps and k)") from None
    if workers is not None and workers != "auto" and (isinstance(workers, bool) or
                                                      not isinstance(workers, (int, np.integer)) or workers < 1):
        raise ValueError(f"workers must be None, 'auto' or an integer >= 1, got {workers!r}")
    boxes = initial_boxes(x0, graph.n_inputs, kwargs.pop("subdivision", None))
    nb = boxes.shape[0]
    params = check_params(kwargs.pop("params", None), graph, nb, None)
    progress = kwargs.pop("progress", None)
    consistency = kwargs.pop("consistency", None)
    hooks_in = kwargs.pop("hooks", ()) or ()
    hooks, deadline = _split_hooks(hooks_in, t_wall0)

    # where to run
    backend, own_client = "inprocess", None
    if client is not None:
        if isinstance(client, str):
            client = connect(client)
            own_client = client
        backend = "dask"
        n_workers = max(1, len(client.scheduler_info().get("workers", {})))
    else:
        auto = workers is None or (isinstance(workers, str) and workers == "auto")
        n_workers = default_workers() if auto else int(workers)
        if auto and (nb < max(AUTO_MIN_PIECES, 2 * n_workers) or _in_dask_worker()
                     or (workers is None and not subprocess_workers_supported())):
            n_workers = 1  # not worth a cluster (or one that would re-run the script: Windows)
        if n_workers > 1 and nb >= 2:
            if dask_available():
                backend = "dask-local"
            elif not auto:
                warnings.warn(f"workers={workers}: dask.distributed is not installed "
                              "(pip install 'mbs-verified[parallel]'); running the chunks in this process",
                              RuntimeWarning, stacklevel=3)
    if backend == "inprocess":
        n_workers = 1
    # with a wall-clock cap every chunk should be running when it strikes: one per worker
    ranges = plan_chunks(nb, n_workers, chunks, max_per_worker=1 if deadline is not None else MAX_CHUNKS_PER_WORKER)
    if replay_ranges is not None:
        if replay_ranges[0][0] != 0 or replay_ranges[-1][1] != nb or any(
                a[1] != b[0] for a, b in zip(replay_ranges, replay_ranges[1:])):
            raise ValueError(f"replay=: its chunks {replay_ranges} do not cover the {nb} boxes of this run")
        ranges = replay_ranges
    adaptive = bool(kwargs.get("adaptive", False))
    rechunk_on = adaptive and consistency is None and (bool(rechunk) if rechunk is not None
                                                       else backend != "inprocess")
    if backend == "dask-local" and len(ranges) == 1 and not (rechunk_on and rechunk):
        # one chunk on a local cluster runs on the same cores as this process, only later
        # (a Dask round trip) and, on a first call, after the cluster's start: run it
        # here (docs/lab/code_notes.md)
        backend, n_workers = "inprocess", 1
    cluster_start_s = None
    if backend == "dask-local" and workers is None:
        # the default must not fail a run that this process can do alone (a cluster that
        # cannot start: no `python -m dask` for this interpreter, no free port, ...):
        # warn and run it here as one batch
        fresh, t_start = n_workers not in _LOCAL, time.perf_counter()
        try:
            local_client(n_workers)
            cluster_start_s = time.perf_counter() - t_start if fresh else None
        except WorkerStartError as exc:
            warnings.warn(f"{exc}; workers=None runs in this process", RuntimeWarning, stacklevel=3)
            backend, n_workers = "inprocess", 1
            ranges = [(0, nb)] if chunks is None else plan_chunks(nb, 1, chunks)
            rechunk_on = adaptive and consistency is None and bool(rechunk)
    if backend == "inprocess" and len(ranges) == 1 and not rechunk_on and not replay:  # one batch: solve's own result
        sol = solve_batch(ode, boxes, (t0, t1), params=params, progress=progress, consistency=consistency,
                          hooks=list(hooks_in), **kwargs)
        sol.stats.update(chunks=1, workers=1, backend="inprocess")
        return sol
    base = dict(kwargs, t_span=(t0, t1))
    base.pop("max_boxes", None)  # (per piece: _Piece.max_boxes)
    board = _Board(progress, t0, t1, [b - a for a, b in ranges])
    interrupted = False
    # work stealing: a lagging piece's sets go to free threads (Dask only; not with a
    # consistency test, whose record cannot be continued; not when replaying a run's cuts)
    steal = backend != "inprocess" and consistency is None and replay is None and rechunk is not False
    stats_extra = {"chunks": len(ranges), "workers": n_workers, "backend": backend, "rechunk": rechunk_on,
                   "steal": steal}

    def chunk_params(a, b):
        if params is None:
            return None
        return params[a:b] if params.ndim == 2 else params

    pieces = _Pieces(boxes, ranges, chunk_params, rechunk_on, int(kwargs.get("max_boxes", _MAX_BOXES)),
                     steal=steal, replay=replay, outs=outs, t0=t0)
    if backend == "inprocess":
        prob = ode if isinstance(ode, VerifiedODE) else VerifiedODE(graph, arithmetic)
        stats_extra["setup_s"] = time.perf_counter() - wall0
        todo = deque(range(len(pieces.items)))
        try:
            while todo:
                i = todo.popleft()
                piece = pieces.items[i]
                kw = dict(base)
                if not isinstance(kw.get("error_basis", "qr"), str):
                    kw["error_basis"] = copy.deepcopy(kw["error_basis"])
                kw["consistency"] = None if consistency is None else copy.deepcopy(consistency)
                kw["hooks"] = hooks + ([_Local(board, piece.family)] if progress is not None else [])
                if progress is not None:
                    kw["hooks"].append(_EmitEvery(board))
                sol, paused = _solve_piece(prob, piece, kw)
                todo.extendleft(reversed(pieces.done(i, sol, paused)))  # depth first: its pieces next
                if sol.status == "interrupted":
                    interrupted = True
                    break
        except KeyboardInterrupt:
            interrupted = True
        stats_extra["sent_bytes"] = stats_extra["received_bytes"] = 0
    else:
        c = client if backend == "dask" else None
        setup_t = time.perf_counter()
        try:
            if c is None:
                fresh = n_workers not in _LOCAL
                c = local_client(n_workers)
                if fresh:
                    stats_extra["cluster_start_s"] = time.perf_counter() - setup_t
            if cluster_start_s is not None:
                stats_extra["cluster_start_s"] = cluster_start_s
            interrupted, sizes = _run_on_dask(c, graph, arithmetic, pieces, base, consistency, hooks, board, t_wall0)
            stats_extra.update(sizes)
        finally:
            if own_client is not None:
                own_client.close()
        stats_extra["setup_s"] = stats_extra.pop("setup_s", time.perf_counter() - setup_t)
    t_merge = time.perf_counter()
    results = pieces.families(outs, t0)
    stats_extra["pieces"] = sum(1 for p in pieces.items if p.sol is not None)
    stats_extra["rechunks"] = pieces.cuts
    stats_extra["cuts"] = pieces.cut_log
    stats_extra["stitch_s"] = pieces.stitch_s  # (stitching of families as they completed, during the run)
    sol = merge_solutions(results, ranges, boxes[:, :graph.n_inputs], outs, t0,
                          tuple(graph.input_names[:graph.n_inputs]), interrupted=interrupted)
    stats_extra["merge_s"] = time.perf_counter() - t_merge
    board.emit()
    sol.stats.update(stats_extra)
    sol.stats["wall_s"] = time.perf_counter() - wall0
    return sol


class _EmitEvery(Hook):
    """In-process: call the combined progress after every step of any chunk."""

    def __init__(self, board):
        self.board = board

    def after_step(self, step, sets, run):
        self.board.emit()
        return None


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


_SHIPPED: dict = {}  # (client id, token) -> (future of the shipped problem, workers warmed)


def _run_on_dask(client, graph, arithmetic, pieces: _Pieces, base, consistency, hooks, board, t_wall0=None):
    """Run the pieces on ``client``'s cluster: the initial chunks at once, a piece cut
    from a paused one as soon as the paused one's result arrives. Returns
    ``(interrupted, sizes)``; the Solutions are in ``pieces``. ``sizes["timeline"]``:
    per piece run, its worker's pid and when (s after ``t_wall0``, ``time.time()``) its
    task started and ended on the worker and its result was here (the worker's clock:
    comparable on one machine only)."""
    t_wall0 = time.time() if t_wall0 is None else t_wall0
    timeline = []
    t_setup = time.perf_counter()
    blob = pickle.dumps(graph)
    problem = _Problem(graph=graph, arithmetic=arithmetic,
                       token=hashlib.sha1(blob + arithmetic.encode()).hexdigest())
    workers = set(client.scheduler_info().get("workers", {}))
    # the graph goes to every worker once per client (a worker started later, e.g. after
    # one was killed, fetches it from a peer); later runs reuse the copies
    got = _SHIPPED.get((id(client), problem.token))
    sent = 0
    if got is None or got[0].status != "finished":
        # a task returning the problem (not client.scatter): a worker fetches it from a
        # peer the first time one of its chunks needs it and keeps it; if every copy is
        # lost (workers killed) the scheduler recomputes it instead of failing the run
        fut_problem = client.submit(_identity, problem, key=f"verified-problem-{problem.token}", pure=False)
        got = _SHIPPED[(id(client), problem.token)] = (fut_problem, set())
        sent += len(blob) * max(1, len(workers))
    fut_problem, warmed = got
    topic = f"mbs-verified-progress-{uuid.uuid4().hex}"
    steal = any(p.stealable for p in pieces.items) or pieces.steal
    seen: dict = {}  # task key -> deque of (monotonic, t) of its reports over the last RATE_WINDOW s

    def on_report(event):
        msg = event[1]
        board.update(msg["i"], msg["t"])
        key = msg.get("p")
        if key is not None:
            now = time.monotonic()
            got = seen.setdefault(key, deque())
            got.append((now, msg["t"]))
            while len(got) > 2 and now - got[1][0] >= RATE_WINDOW:
                got.popleft()

    if board.progress is not None or steal:
        client.subscribe_topic(topic, on_report)
    kw = dict(base)
    kw["consistency"] = consistency
    kw["hooks"] = hooks
    kw_bytes = len(pickle.dumps(kw))
    # workers new to this problem build its tapes and take a first step before the
    # chunks (queued first on each; their seconds come back as warm_s)
    first = pieces.items[0]
    warm = [client.submit(_warm_problem, fut_problem, first.lo[:1], first.hi[:1],
                          first.params[:1] if first.params is not None and first.params.ndim == 2 else first.params,
                          kw, workers=[addr], allow_other_workers=True, pure=False)  # a dead worker cannot block
            for addr in sorted(workers - warmed)]
    warmed |= workers
    done_q: queue.Queue = queue.Queue()
    running: dict = {}  # piece index -> future
    keys: dict = {}  # piece index -> its task key
    asked: dict = {}  # piece index -> when the driver asked it to pause (it lagged)
    t1 = float(base["t_span"][1])
    threads = [_thread_count(client)]

    def submit(i, where=None):
        nonlocal sent
        piece = pieces.items[i]
        sent += len(pickle.dumps(piece)) + kw_bytes
        key = keys[i] = f"verified-chunk-{i}-{topic[-12:]}"
        f = client.submit(_run_chunk, fut_problem, piece, kw, topic, key, key=key, pure=False, workers=where,
                          allow_other_workers=where is not None)  # (a preference: a dead worker cannot block)
        running[i] = f
        f.add_done_callback(lambda fut, i=i: done_q.put(i))

    def free_threads():
        """Threads without a piece of this run (running or queued there): Dask may queue
        two pieces on one worker while another idles (the problem's graph was on that one)."""
        try:
            proc = client.processing()
            nthreads = client.nthreads()
        except Exception:  # noqa: BLE001 - asked again at the next tick
            return 0
        ours = {keys[i] for i in running}
        return sum(max(0, nthreads.get(w, 1) - sum(1 for k in ks if k in ours)) for w, ks in proc.items())

    def time_left(i, now):
        """Seconds piece i still needs at its rate over the last RATE_WINDOW s (a piece
        whose steps shorten, as near a separatrix, slows down late: its mean rate since
        the start would say it is nearly done); None: not two reports yet."""
        got = seen.get(keys[i])
        if got is None or len(got) < 2:
            return None
        (wa, ta), (wb, tb) = got[0], got[-1]
        if wb - wa < 0.25:
            return None
        if tb <= ta:
            return math.inf  # (no progress in the window: stuck on short steps)
        return (t1 - tb) * (wb - wa) / (tb - ta) - (now - wb)

    def maybe_steal():
        """A thread is free and nothing waits for one: ask the running piece with the
        most time left (at least STEAL_MIN_S) to pause; its sets go to the free threads."""
        now = time.monotonic()
        if not steal or len(running) > threads[0] or now - last_free[0] < 0.5:
            return
        if any(i in running and now - a < 2.0 for i, a in asked.items()):
            return  # (one request at a time; one not answered in 2 s, e.g. on its last step, is given up)
        last_free[0] = now
        if free_threads() <= 0:
            return
        best, left = None, STEAL_MIN_S
        for i in running:
            if pieces.items[i].stealable and i not in asked:
                r = time_left(i, now)
                if r is not None and r > left:
                    best, left = i, r
        if best is not None:
            asked[best] = now
            client.run(_request_pause, keys[best], wait=False)

    last_free = [0.0]
    if steal and problem.token not in _WARM_HERE:
        # a cut runs here, on the paused piece's sets (their hulls: the set kernels): load
        # those kernels now, in the background, not on the run's critical path at its end
        _WARM_HERE.add(problem.token)
        threading.Thread(target=_warm_here, args=(graph, arithmetic, first, kw), daemon=True,
                         name="mbs-verified-warm").start()
    # the initial chunks spread over the workers when there are no more chunks than
    # workers (else Dask may queue several on the worker that holds the graph)
    addrs = sorted(workers)
    spread = steal and 0 < len(pieces.items) <= len(addrs)
    for i in range(len(pieces.items)):
        submit(i, [addrs[i]] if spread else None)
    setup_s = time.perf_counter() - t_setup
    interrupted = False
    received = 0

    def take(i):
        nonlocal received
        f = running.pop(i)
        out = f.result()  # (a chunk that raised raises here, as before)
        received += len(pickle.dumps(out))
        sol, paused = out
        a, b = sol.stats.get("chunk_span_unix", (math.nan, math.nan))
        why = sol.stats.get("pause", (None, None))[1] if paused is not None else None
        timeline.append(dict(piece=i, parent=pieces.items[i].parent, worker_pid=sol.stats.get("worker_pid"),
                             start_s=a - t_wall0, end_s=b - t_wall0, received_s=time.time() - t_wall0,
                             cpu_s=sol.stats.get("chunk_cpu_s", (math.nan,))[0], sets=int(pieces.items[i].lo.shape[0]),
                             t_start=float(pieces.items[i].start.t_exact) if pieces.items[i].start else None,
                             steps=sol.stats.get("steps"), paused=why))
        board.update(pieces.items[i].family, sol.t_reached)
        # a piece that lagged goes to every free thread, twice as many pieces as threads
        # (so the last of them, smaller, even out the end); set growth: the plan's size
        k = max(2, 2 * (threads[0] - len(running))) if why == "lag" else None
        if why == "lag" and paused is not None:
            k = min(k, max(2, paused.sets.n_sets // STEAL_MIN_SETS))
        return pieces.done(i, sol, paused, k=k, why=why)

    last_check, lost_since = time.monotonic(), None
    try:
        with _SigintRaises():
            while running:
                try:
                    i = done_q.get(timeout=0.25)
                except queue.Empty:
                    if _INTERRUPT.is_set():
                        raise KeyboardInterrupt
                    board.emit()
                    now = time.monotonic()
                    if now - last_check >= 1.0:  # a cluster left without workers: say so, never hang
                        last_check = now
                        n_now = _thread_count(client)
                        threads[0] = n_now if n_now > 0 else threads[0]  # (-1: not known now)
                        lost_since = (lost_since or now) if n_now == 0 else None
                        if lost_since is not None and now - lost_since >= NO_WORKERS_TIMEOUT:
                            client.cancel(list(running.values()))
                            raise WorkersLostError(
                                f"every Dask worker left and none joined within {NO_WORKERS_TIMEOUT:g} s; "
                                f"{len(running)} of {len(pieces.items)} chunks did not finish (start workers "
                                "for the scheduler, or run with workers=1)")
                    maybe_steal()
                    continue
                for j in take(i):
                    submit(j)
                maybe_steal()
    except KeyboardInterrupt:
        interrupted = True
        for i, f in list(running.items()):
            if f.done() and f.status == "finished":
                take(i)  # (pieces it cuts are not run: they count as interrupted)
        client.cancel(list(running.values()))
    finally:
        if board.progress is not None or steal:
            try:
                client.unsubscribe_topic(topic)
            except Exception:  # noqa: BLE001
                pass
    warm_s = [f.result() if f.status == "finished" else None for f in warm]
    return interrupted, {"sent_bytes": sent, "received_bytes": received, "setup_s": setup_s, "warm_s": warm_s,
                         "timeline": timeline}


# ----------------------------------------------------------------------------- merge
def _chunk_tube_hulls(sol):
    """(S, n) lo/hi arrays: the hull of each step's tube boxes of one chunk."""
    if not len(sol.tube):
        n = sol.hull.shape[-1]
        return np.zeros((0, n)), np.zeros((0, n))
    th = sol.tube_hull
    return np.asarray(th.lo, float), np.asarray(th.hi, float)


def merge_solutions(results, ranges, initial, outs, t0, state_names, interrupted=False):
    """One :class:`~verified.solver.Solution` from the chunk Solutions (``None``: a
    chunk that did not run). See the module docstring for what each field means.

    Per initial piece (``piece_results``): a chunk's own report (offset to the run's
    indices) where it ran as one batch; every piece of a chunk that did not run, or of
    a re-chunked chunk, with that chunk's status. Where some pieces broke down and
    others went on, ``reason`` says which (:func:`verified.driver.solution.pieces_summary`) and
    ``surviving`` merges the chunks' surviving parts (a chunk without a failed piece
    whole, a chunk with some its ``surviving``)."""
    sol = _merge(results, ranges, initial, outs, t0, state_names, interrupted)
    sol.piece_results = _merge_piece_results(results, ranges, initial, t0)
    if any(p.failed for p in sol.piece_results):
        summary = pieces_summary(sol.piece_results)
        if summary:
            sol.reason = summary
        parts = [(i, r.surviving if r.surviving is not None else r) for i, r in enumerate(results)
                 if r is not None and (r.surviving is not None or r.status != "breakdown")]
        if parts:
            ids = [i for i, _ in parts]
            sub = concatenate([initial[ranges[i][0]:ranges[i][1]] for i in ids], axis=0)
            sol.surviving = _merge([r for _, r in parts], [ranges[i] for i in ids], sub, outs, t0, state_names,
                                   interrupted, ids=ids)
            sol.surviving.piece_results = sol.piece_results
    return sol


def _merge_piece_results(results, ranges, initial, t0) -> list:
    """``piece_results`` of a chunked run (see :func:`merge_solutions`)."""
    out = []
    for sol, (a, b) in zip(results, ranges):
        own = sol.piece_results if sol is not None and sol.pieces is None else None
        if own is not None and len(own) == b - a:
            out += [PieceResult(a + p.index, initial[a + p.index], p.status, float(p.t_reached), p.reason)
                    for p in own]
            continue
        if sol is None:
            st, tr, why = "interrupted", float(t0), "interrupted before this chunk finished"
        else:
            st, tr, why = sol.status, float(sol.t_reached), sol.reason
        out += [PieceResult(i, initial[i], st, tr, why if st != "completed" else "") for i in range(a, b)]
    return out


def _merge(results, ranges, initial, outs, t0, state_names, interrupted=False, ids=None):
    """The Solution of :func:`merge_solutions` without the per-piece fields (``ids``: the
    chunks' numbers in the run, for the reason; default their positions)."""
    ids = list(range(len(results))) if ids is None else list(ids)
    n = initial.shape[-1]
    # status, reason, t_reached: the worst status; the reason of the earliest chunk of that status
    worst, t_reached, reason, reason_t = "completed", math.inf, "", math.inf
    for i, sol, (a, b) in zip(ids, results, ranges):
        if sol is None:
            st, tr, why = "interrupted", float(t0), "interrupted before this chunk finished"
        else:
            st, tr, why = sol.status, float(sol.t_reached), sol.reason
        rank = _STATUS_RANK.get(st, 3)
        if st != "completed" and (rank > _STATUS_RANK[worst] or (rank == _STATUS_RANK[worst] and tr < reason_t)):
            worst, reason, reason_t = st, f"chunk {i} (boxes {a}..{b - 1}): {why}", tr
        t_reached = min(t_reached, tr)
    if interrupted and worst == "completed":
        worst, reason = "interrupted", "interrupted (KeyboardInterrupt)"
    done = [s for s in results if s is not None]
    # outputs every chunk reached
    k = min((len(s.t) for s in results), default=1) if all(s is not None for s in results) else 1
    out_t = np.asarray(outs[:k], float) if k else np.zeros(0)
    if k >= 1 and all(s is not None for s in results):
        out_boxes = [concatenate([s.boxes[j] for s in results], axis=0) for j in range(k)]
        out_t = np.asarray(results[0].t[:k], float)
    else:
        out_boxes = [initial]
        out_t = np.asarray([t0], float)
        k = 1
    # tube on the common grid of step boundaries
    if len(done) == len(results) and t_reached > t0:
        grid = np.unique(np.concatenate([np.asarray(s.tube_t, float) for s in results]))
        grid = grid[grid <= t_reached]
    else:
        grid = np.asarray([float(t0)])
    steps = grid.size - 1
    if steps > 0:
        C = len(results)
        lo = np.empty((steps, C, n))
        hi = np.empty((steps, C, n))
        # each grid step [g_i, g_i+1] lies in the chunk's last step starting at or before g_i
        # (not found from the midpoints: the midpoint of a last step one ulp long rounds to
        # its end, past the chunk's last step)
        starts = grid[:-1]
        for c, s in enumerate(results):
            tl, th = _chunk_tube_hulls(s)
            j = np.searchsorted(np.asarray(s.tube_t, float), starts, side="right") - 1
            if j.size and (j.max() >= len(tl) or j.min() < 0):  # (every chunk's tube reaches t_reached)
                raise RuntimeError(f"chunk {c}'s tube does not cover [{grid[0]}, {grid[-1]}] (a bug)")
            lo[:, c, :], hi[:, c, :] = tl[j], th[j]
        tube = [Interval._from_bounds(lo[j], hi[j]) for j in range(steps)]
        tube_hull = Interval._from_bounds(lo.min(axis=1), hi.max(axis=1))
    else:
        tube = []
        tube_hull = Interval._from_bounds(np.zeros((0, n)), np.zeros((0, n)))
    # statistics
    stats = {}
    for s in done:
        for key, v in s.stats.items():
            if key in ("order", "wall_s", "worker_pid", "chunk_task_s") or isinstance(v, bool):
                continue
            if isinstance(v, (int, float, np.integer, np.floating)):
                stats[key] = stats.get(key, 0) + v
    if done:
        stats["order"] = done[0].stats.get("order")
        stats["steps_max"] = max(s.stats.get("steps", 0) for s in done)
    stats["boxes"] = int(initial.shape[0])
    stats["chunk_wall_s"] = [None if s is None else s.stats.get("wall_s") for s in results]
    stats["chunk_steps"] = [None if s is None else s.stats.get("steps") for s in results]
    hull_k = stack([hull(b, axis=0) for b in out_boxes], axis=0)
    sol = Solution(t=out_t, boxes=out_boxes, hull=hull_k, tube_t=grid, tube=tube, tube_hull=tube_hull,
                   t_reached=float(grid[-1]), status=worst,
                   reason="" if worst == "completed" else reason, stats=stats, state_names=state_names,
                   consistency=_merge_records([s.consistency for s in done]))
    sol.chunks = [dict(boxes=(a, b), status=None if s is None else s.status,
                       t_reached=None if s is None else float(s.t_reached),
                       reason=None if s is None else s.reason,
                       steps=None if s is None else s.stats.get("steps"),
                       wall_s=None if s is None else s.stats.get("wall_s"),
                       worker_pid=None if s is None else s.stats.get("worker_pid"),
                       tube_t=None if s is None else s.tube_t, tube=None if s is None else s.tube,
                       consistency=None if s is None else s.consistency,
                       pieces=getattr(s, "pieces", None))
                  for s, (a, b) in zip(results, ranges)]
    return sol


def _merge_records(records):
    """The chunks' consistency records on the union of their step times (None without a
    test). At each time every chunk that has started contributes its latest entry (its
    series is a step function of time): ``RA`` is the largest of them and ``h_h``,
    ``h_v`` their hull, as one in-process record takes them over all sets; ``h_h_set``
    and ``h_v_set`` are those of the chunk with that ``RA``. (The series interleaved
    by time alternated between the chunks: a sawtooth in Fig. 2.)"""
    records = [r for r in records if r is not None]
    if not records:
        return None
    if len(records) == 1:
        return records[0]
    # (only with a consistency test: verified.consistency.energy_test costs ~0.2 s to import)
    from verified.consistency.energy_test import ConsistencyRecord
    tests = sorted((t for r in records for t in r.tests), key=lambda t: t.t)
    series = [r for r in records if len(r.ra_t)]
    if not series:
        return ConsistencyRecord(ra_t=np.zeros(0), ra=np.zeros(0), h_h=records[0].h_h, h_v=records[0].h_v,
                                 tests=tests)
    grid = np.unique(np.concatenate([np.asarray(r.ra_t, float) for r in series]))
    at = [np.searchsorted(np.asarray(r.ra_t, float), grid, side="right") - 1 for r in series]  # (G,) each
    ra = np.full((len(series), grid.size), -np.inf)
    for c, (r, k) in enumerate(zip(series, at)):
        ra[c, k >= 0] = np.asarray(r.ra, float)[k[k >= 0]]
    best = np.argmax(ra, axis=0)

    def hull_of(name):
        lo = np.full(grid.size, np.inf)
        hi = np.full(grid.size, -np.inf)
        for r, k in zip(series, at):
            v = getattr(r, name)
            if v is None or np.shape(v.lo) != np.shape(r.ra_t):
                return None
            on = k >= 0
            lo[on] = np.minimum(lo[on], np.asarray(v.lo)[k[on]])
            hi[on] = np.maximum(hi[on], np.asarray(v.hi)[k[on]])
        return Interval._from_bounds(lo, hi)

    def of_best(name):
        parts = [getattr(r, name) for r in series]
        if any(v is None or np.shape(v.lo) != np.shape(r.ra_t) for v, r in zip(parts, series)):
            return None
        lo = np.array([parts[b].lo[at[b][j]] for j, b in enumerate(best)], float)
        hi = np.array([parts[b].hi[at[b][j]] for j, b in enumerate(best)], float)
        return Interval._from_bounds(lo, hi)

    h_h, h_v = hull_of("h_h"), hull_of("h_v")
    return ConsistencyRecord(ra_t=grid, ra=ra.max(axis=0), h_h=h_h if h_h is not None else records[0].h_h,
                             h_v=h_v if h_v is not None else records[0].h_v, tests=tests,
                             h_h_set=of_best("h_h_set"), h_v_set=of_best("h_v_set"))

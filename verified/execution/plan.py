"""How many workers and how many chunks: Dask's presence, the machine's cores, the default
``workers`` (:func:`auto_workers`) and the partition of a run's pieces into contiguous chunks
(:func:`plan_chunks`). The overview of chunked execution is :mod:`verified.execution`.
"""

from __future__ import annotations

import importlib
import math
import os
import sys

import numpy as np

from verified.driver.batch import VerifiedODE
from verified.driver.solver_args import _subdivision, initial_boxes

__all__ = ["plan_chunks", "default_workers", "dask_available", "auto_workers", "subprocess_workers_supported", "CHUNK_TARGET", "MIN_CHUNK_BOXES"]


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


def subprocess_workers_supported() -> bool:
    """Whether :func:`local_client` starts its workers as fresh interpreters (every POSIX
    system; Dask's subprocess workers do not run on Windows)."""
    return os.name == "posix"

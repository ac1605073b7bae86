""":func:`solve_parallel`: what ``solve(..., workers=, client=, chunks=)`` delegates to: plans the
chunks, runs them in this process or on Dask, and merges their Solutions
(:mod:`verified.execution` describes the whole).
"""

from __future__ import annotations

import atexit
import contextlib
import contextvars
import copy
import inspect
import time
from collections import deque

import numpy as np

from verified.driver.batch import VerifiedODE, solve_batch
from verified.driver.solution import Solution
from verified.driver.solver_args import check_arithmetic, check_graph, check_params, check_settings, initial_boxes
from verified.driver.user_warnings import warn_at_caller
from verified.execution.cluster import WorkerStartError, _LOCAL, close_local_clients, connect, local_client
from verified.execution.dask_run import _run_on_dask
from verified.execution.hooks import _Board, _EmitEvery, _Local, _split_hooks
from verified.execution.merge import merge_solutions
from verified.execution.plan import (
    AUTO_MIN_PIECES, MAX_CHUNKS_PER_WORKER, _in_dask_worker, dask_available, default_workers, plan_chunks,
    subprocess_workers_supported
)
from verified.execution.rechunk import _Pieces
from verified.execution.worker import _solve_piece

__all__ = ["solve_parallel", "replaying"]


#: solve's default max_boxes (each initial chunk's budget of sets)
_MAX_BOXES = inspect.signature(solve_batch).parameters["max_boxes"].default


atexit.register(close_local_clients)


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
    t0, t1, outs, graph, arithmetic, rechunk, replay, replay_ranges = _checked_args(ode, t_span, workers, chunks,
                                                                                    kwargs)
    boxes = initial_boxes(x0, graph.n_inputs, kwargs.pop("subdivision", None))
    nb = boxes.shape[0]
    params = check_params(kwargs.pop("params", None), graph, nb, None)
    progress = kwargs.pop("progress", None)
    consistency = kwargs.pop("consistency", None)
    hooks_in = kwargs.pop("hooks", ()) or ()
    hooks, deadline = _split_hooks(hooks_in, t_wall0)
    backend, n_workers, client, own_client = _where(client, workers, nb)
    try:
        adaptive = bool(kwargs.get("adaptive", False))
        backend, n_workers, ranges, rechunk_on, cluster_start_s = _plan(
            backend, n_workers, nb, workers, chunks, deadline, replay_ranges, adaptive, consistency, rechunk)
        if backend == "inprocess" and len(ranges) == 1 and not rechunk_on and not replay:  # (one batch)
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
            interrupted = _run_here(prob, pieces, base, consistency, hooks, progress, board)
            stats_extra["sent_bytes"] = stats_extra["received_bytes"] = 0
        else:
            c = client if backend == "dask" else None
            interrupted = _run_there(c, n_workers, cluster_start_s, graph, arithmetic, pieces, base,
                                     consistency, hooks, board, t_wall0, stats_extra)
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
    finally:
        if own_client is not None:  # (a Client this call connected: closed whatever happens)
            own_client.close()


def _checked_args(ode, t_span, workers, chunks, kwargs: dict):
    """solve's argument checks, before any work, in solve's order; takes ``rechunk``,
    ``start`` and ``replay`` out of ``kwargs`` (in place). Returns ``(t0, t1, outs,
    graph, arithmetic, rechunk, replay, replay_ranges)``: ``replay`` as ``{path: (steps,
    k)}`` (None: no replay; from ``replay=`` or :func:`replaying`), ``replay_ranges`` the
    replayed Solution's chunks (None: this call's plan)."""
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
    return t0, t1, outs, graph, arithmetic, rechunk, replay, replay_ranges


def _where(client, workers, nb: int):
    """Where to run ``nb`` boxes: ``(backend, n_workers, client, own_client)``, backend
    "dask" (``client``; a scheduler address is connected to here, and that Client,
    ``own_client``, is closed after the run), "dask-local" (a local cluster of
    ``n_workers``) or "inprocess" (``n_workers`` 1). Warns (at solve's caller) when
    ``workers > 1`` asks for Dask that is not installed."""
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
                warn_at_caller(f"workers={workers}: dask.distributed is not installed "
                               "(pip install 'mbs-verified[parallel]'); running the chunks in this process",
                               RuntimeWarning)
    if backend == "inprocess":
        n_workers = 1
    return backend, n_workers, client, own_client


def _plan(backend, n_workers, nb, workers, chunks, deadline, replay_ranges, adaptive, consistency, rechunk):
    """The chunks of ``nb`` boxes and whether to re-chunk them: ``(backend, n_workers,
    ranges, rechunk_on, cluster_start_s)``. A replay's chunks replace the plan (they must
    cover the boxes); one chunk for a local cluster runs here instead; with
    ``workers=None`` a local cluster that cannot start warns (at solve's caller) and the
    run stays here. ``cluster_start_s``: the seconds that start took (None: started
    before, or not started here)."""
    # with a wall-clock cap every chunk should be running when it strikes: one per worker
    ranges = plan_chunks(nb, n_workers, chunks, max_per_worker=1 if deadline is not None else MAX_CHUNKS_PER_WORKER)
    if replay_ranges is not None:
        if replay_ranges[0][0] != 0 or replay_ranges[-1][1] != nb or any(
                a[1] != b[0] for a, b in zip(replay_ranges, replay_ranges[1:])):
            raise ValueError(f"replay=: its chunks {replay_ranges} do not cover the {nb} boxes of this run")
        ranges = replay_ranges
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
            warn_at_caller(f"{exc}; workers=None runs in this process", RuntimeWarning)
            backend, n_workers = "inprocess", 1
            ranges = [(0, nb)] if chunks is None else plan_chunks(nb, 1, chunks)
            rechunk_on = adaptive and consistency is None and bool(rechunk)
    return backend, n_workers, ranges, rechunk_on, cluster_start_s


def _run_here(prob, pieces: _Pieces, base: dict, consistency, hooks: list, progress, board) -> bool:
    """Run the pieces one after another in this process, depth first (a paused piece's
    pieces next); returns whether the run was interrupted (a piece's status, or Ctrl-C).
    Each piece gets its own copies of the mutable arguments (error basis, consistency
    test) and of the hooks list."""
    interrupted = False
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
    return interrupted


def _run_there(c, n_workers, cluster_start_s, graph, arithmetic, pieces: _Pieces, base: dict,
               consistency, hooks: list, board, t_wall0, stats_extra: dict) -> bool:
    """Run the pieces on Dask: on ``c`` or (None) the local cluster of ``n_workers``,
    started here if need be. Returns whether the run was interrupted; the cluster's
    start, :func:`_run_on_dask`'s sizes and ``setup_s`` go into ``stats_extra``."""
    setup_t = time.perf_counter()
    if c is None:
        fresh = n_workers not in _LOCAL
        c = local_client(n_workers)
        if fresh:
            stats_extra["cluster_start_s"] = time.perf_counter() - setup_t
    if cluster_start_s is not None:
        stats_extra["cluster_start_s"] = cluster_start_s
    interrupted, sizes = _run_on_dask(c, graph, arithmetic, pieces, base, consistency, hooks, board, t_wall0)
    stats_extra.update(sizes)
    stats_extra["setup_s"] = stats_extra.pop("setup_s", time.perf_counter() - setup_t)
    return interrupted

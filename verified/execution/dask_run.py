"""Running the chunks of one call on a Dask cluster: the graph shipped once per worker, chunks as
ordinary tasks, progress, re-chunking and work stealing from the running pieces' rates
(:func:`_run_on_dask`).
"""

from __future__ import annotations

import hashlib
import math
import pickle
import queue
import threading
import time
import uuid
from collections import deque

from verified.execution.cluster import _SHIPPED, _identity, _thread_count
from verified.execution.hooks import _request_pause
from verified.execution.interrupt import _INTERRUPT, _SigintRaises
from verified.execution.rechunk import STEAL_MIN_SETS, _Pieces
from verified.execution.worker import _Problem, _WARM_HERE, _run_chunk, _warm_here, _warm_problem

__all__ = ["WorkersLostError", "NO_WORKERS_TIMEOUT", "STEAL_MIN_S"]


#: work stealing (``rechunk``, on Dask): when a worker thread is free and no piece waits
#: for one, the running piece with the most time left (estimated from its progress
#: reports), if that is more than STEAL_MIN_S seconds, is asked to pause after its step
#: and its sets are cut into new pieces for the free threads; a piece starting with
#: fewer than 2 * STEAL_MIN_SETS sets is not cut (a test may lower both)
STEAL_MIN_S = 1.0
#: seconds of a piece's latest progress reports its rate is taken over
RATE_WINDOW = 1.5


class WorkersLostError(RuntimeError):
    """Every worker of the Dask cluster left during a run and none came back within
    :data:`NO_WORKERS_TIMEOUT` seconds (the message names the chunks left)."""


#: seconds a run waits for a cluster without any worker before :class:`WorkersLostError`
#: (Dask itself would keep the chunks waiting for ever: its ``no-workers-timeout`` is off)
NO_WORKERS_TIMEOUT = 60.0


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

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
    return _DaskRun(client, pieces, board, t_wall0).run(graph, arithmetic, base, consistency, hooks)


class _DaskRun:
    """One :func:`_run_on_dask` call: the state its steps share (the pieces running and
    their task keys, their progress reports, the steal requests, the bytes sent and
    received, the timeline), one method per step or decision. The module's constants
    (STEAL_MIN_S, STEAL_MIN_SETS, NO_WORKERS_TIMEOUT) are read when used, so that a test
    may lower them."""

    def __init__(self, client, pieces: _Pieces, board, t_wall0: float):
        self.client, self.pieces, self.board, self.t_wall0 = client, pieces, board, t_wall0
        self.timeline: list = []
        self.sent = 0
        self.received = 0
        self.seen: dict = {}  # task key -> deque of (monotonic, t) of its reports over the last RATE_WINDOW s
        self.done_q: queue.Queue = queue.Queue()
        self.running: dict = {}  # piece index -> future
        self.keys: dict = {}  # piece index -> its task key
        self.asked: dict = {}  # piece index -> when the driver asked it to pause (it lagged)
        self.last_free = 0.0  # when _maybe_steal last looked for free threads
        self.last_check, self.lost_since = None, None  # (the workers' count: _check_workers)

    def run(self, graph, arithmetic, base, consistency, hooks):
        """The whole call: ship the problem, warm new workers, submit the initial chunks,
        wait for the pieces (:meth:`_wait`); returns :func:`_run_on_dask`'s result."""
        t_setup = time.perf_counter()
        self._ship(graph, arithmetic)
        self.topic = f"mbs-verified-progress-{uuid.uuid4().hex}"
        self.steal = any(p.stealable for p in self.pieces.items) or self.pieces.steal
        if self._listening():
            self.client.subscribe_topic(self.topic, self._on_report)
        kw = dict(base)
        kw["consistency"] = consistency
        kw["hooks"] = hooks
        self.kw, self.kw_bytes = kw, len(pickle.dumps(kw))
        warm = self._warm_workers()
        self.t1 = float(base["t_span"][1])
        self.threads = _thread_count(self.client)
        first = self.pieces.items[0]
        if self.steal and self.problem.token not in _WARM_HERE:
            # a cut runs here, on the paused piece's sets (their hulls: the set kernels): load
            # those kernels now, in the background, not on the run's critical path at its end
            _WARM_HERE.add(self.problem.token)
            threading.Thread(target=_warm_here, args=(graph, arithmetic, first, kw), daemon=True,
                             name="mbs-verified-warm").start()
        # the initial chunks spread over the workers when there are no more chunks than
        # workers (else Dask may queue several on the worker that holds the graph)
        addrs = sorted(self.workers)
        spread = self.steal and 0 < len(self.pieces.items) <= len(addrs)
        for i in range(len(self.pieces.items)):
            self._submit(i, [addrs[i]] if spread else None)
        setup_s = time.perf_counter() - t_setup
        interrupted = self._wait()
        warm_s = [f.result() if f.status == "finished" else None for f in warm]
        return interrupted, {"sent_bytes": self.sent, "received_bytes": self.received, "setup_s": setup_s,
                             "warm_s": warm_s, "timeline": self.timeline}

    def _listening(self) -> bool:
        """Whether this run subscribes to its pieces' progress reports (for the progress
        board, or for the rates work stealing needs)."""
        return self.board.progress is not None or self.steal

    def _ship(self, graph, arithmetic):
        """The problem's future (``fut_problem``) and the set of workers that hold its
        tapes already (``warmed``), shared by the runs of this client."""
        blob = pickle.dumps(graph)
        self.problem = _Problem(graph=graph, arithmetic=arithmetic,
                                token=hashlib.sha1(blob + arithmetic.encode()).hexdigest())
        self.workers = set(self.client.scheduler_info().get("workers", {}))
        # the graph goes to every worker once per client (a worker started later, e.g. after
        # one was killed, fetches it from a peer); later runs reuse the copies
        got = _SHIPPED.get((id(self.client), self.problem.token))
        if got is None or got[0].status != "finished":
            # a task returning the problem (not client.scatter): a worker fetches it from a
            # peer the first time one of its chunks needs it and keeps it; if every copy is
            # lost (workers killed) the scheduler recomputes it instead of failing the run
            fut_problem = self.client.submit(_identity, self.problem, key=f"verified-problem-{self.problem.token}",
                                             pure=False)
            got = _SHIPPED[(id(self.client), self.problem.token)] = (fut_problem, set())
            self.sent += len(blob) * max(1, len(self.workers))
        self.fut_problem, self.warmed = got

    def _warm_workers(self) -> list:
        """Futures of the warm-up tasks of the workers new to this problem."""
        # workers new to this problem build its tapes and take a first step before the
        # chunks (queued first on each; their seconds come back as warm_s)
        first = self.pieces.items[0]
        warm = [self.client.submit(_warm_problem, self.fut_problem, first.lo[:1], first.hi[:1],
                                   first.params[:1] if first.params is not None and first.params.ndim == 2
                                   else first.params,
                                   self.kw, workers=[addr], allow_other_workers=True,
                                   pure=False)  # a dead worker cannot block
                for addr in sorted(self.workers - self.warmed)]
        self.warmed |= self.workers
        return warm

    def _on_report(self, event):
        """A piece's progress report: to the board, and into its rate window."""
        msg = event[1]
        self.board.update(msg["i"], msg["t"])
        key = msg.get("p")
        if key is not None:
            now = time.monotonic()
            got = self.seen.setdefault(key, deque())
            got.append((now, msg["t"]))
            while len(got) > 2 and now - got[1][0] >= RATE_WINDOW:
                got.popleft()

    def _submit(self, i, where=None):
        """Submit piece ``i`` (``where``: the workers it prefers)."""
        piece = self.pieces.items[i]
        self.sent += len(pickle.dumps(piece)) + self.kw_bytes
        key = self.keys[i] = f"verified-chunk-{i}-{self.topic[-12:]}"
        f = self.client.submit(_run_chunk, self.fut_problem, piece, self.kw, self.topic, key, key=key, pure=False,
                               workers=where,
                               allow_other_workers=where is not None)  # (a preference: a dead worker cannot block)
        self.running[i] = f
        f.add_done_callback(lambda fut, i=i: self.done_q.put(i))

    def _free_threads(self):
        """Threads without a piece of this run (running or queued there): Dask may queue
        two pieces on one worker while another idles (the problem's graph was on that one)."""
        try:
            proc = self.client.processing()
            nthreads = self.client.nthreads()
        except Exception:  # noqa: BLE001 - asked again at the next tick
            return 0
        ours = {self.keys[i] for i in self.running}
        return sum(max(0, nthreads.get(w, 1) - sum(1 for k in ks if k in ours)) for w, ks in proc.items())

    def _time_left(self, i, now):
        """Seconds piece i still needs at its rate over the last RATE_WINDOW s (a piece
        whose steps shorten, as near a separatrix, slows down late: its mean rate since
        the start would say it is nearly done); None: not two reports yet."""
        got = self.seen.get(self.keys[i])
        if got is None or len(got) < 2:
            return None
        (wa, ta), (wb, tb) = got[0], got[-1]
        if wb - wa < 0.25:
            return None
        if tb <= ta:
            return math.inf  # (no progress in the window: stuck on short steps)
        return (self.t1 - tb) * (wb - wa) / (tb - ta) - (now - wb)

    def _maybe_steal(self):
        """A thread is free and nothing waits for one: ask the running piece with the
        most time left (at least STEAL_MIN_S) to pause; its sets go to the free threads."""
        now = time.monotonic()
        if not self.steal or len(self.running) > self.threads or now - self.last_free < 0.5:
            return
        if any(i in self.running and now - a < 2.0 for i, a in self.asked.items()):
            return  # (one request at a time; one not answered in 2 s, e.g. on its last step, is given up)
        self.last_free = now
        if self._free_threads() <= 0:
            return
        best, left = None, STEAL_MIN_S
        for i in self.running:
            if self.pieces.items[i].stealable and i not in self.asked:
                r = self._time_left(i, now)
                if r is not None and r > left:
                    best, left = i, r
        if best is not None:
            self.asked[best] = now
            self.client.run(_request_pause, self.keys[best], wait=False)

    def _take(self, i):
        """Piece ``i``'s result: into the timeline, the board and the pieces; returns the
        pieces cut from it (to be submitted)."""
        f = self.running.pop(i)
        out = f.result()  # (a chunk that raised raises here, as before)
        self.received += len(pickle.dumps(out))
        sol, paused = out
        a, b = sol.stats.get("chunk_span_unix", (math.nan, math.nan))
        why = sol.stats.get("pause", (None, None))[1] if paused is not None else None
        items, t_wall0 = self.pieces.items, self.t_wall0
        self.timeline.append(dict(piece=i, parent=items[i].parent, worker_pid=sol.stats.get("worker_pid"),
                                  start_s=a - t_wall0, end_s=b - t_wall0, received_s=time.time() - t_wall0,
                                  cpu_s=sol.stats.get("chunk_cpu_s", (math.nan,))[0], sets=int(items[i].lo.shape[0]),
                                  t_start=float(items[i].start.t_exact) if items[i].start else None,
                                  steps=sol.stats.get("steps"), paused=why))
        self.board.update(items[i].family, sol.t_reached)
        # a piece that lagged goes to every free thread, twice as many pieces as threads
        # (so the last of them, smaller, even out the end); set growth: the plan's size
        k = max(2, 2 * (self.threads - len(self.running))) if why == "lag" else None
        if why == "lag" and paused is not None:
            k = min(k, max(2, paused.sets.n_sets // STEAL_MIN_SETS))
        return self.pieces.done(i, sol, paused, k=k, why=why)

    def _check_workers(self):
        """At most once a second: the cluster's thread count (kept when not known now);
        raises WorkersLostError once it has had no worker for NO_WORKERS_TIMEOUT s (its
        chunks cancelled)."""
        now = time.monotonic()
        if now - self.last_check >= 1.0:  # a cluster left without workers: say so, never hang
            self.last_check = now
            n_now = _thread_count(self.client)
            self.threads = n_now if n_now > 0 else self.threads  # (-1: not known now)
            self.lost_since = (self.lost_since or now) if n_now == 0 else None
            if self.lost_since is not None and now - self.lost_since >= NO_WORKERS_TIMEOUT:
                self.client.cancel(list(self.running.values()))
                raise WorkersLostError(
                    f"every Dask worker left and none joined within {NO_WORKERS_TIMEOUT:g} s; "
                    f"{len(self.running)} of {len(self.pieces.items)} chunks did not finish (start workers "
                    "for the scheduler, or run with workers=1)")

    def _wait(self) -> bool:
        """Until no piece runs: take each result as it arrives and submit the pieces cut
        from it; between results, the board, the workers' check and work stealing.
        Ctrl-C (or interrupt_runs) cancels the rest, keeping the results already in.
        Returns whether the run was interrupted; unsubscribes from the reports."""
        interrupted = False
        self.last_check, self.lost_since = time.monotonic(), None
        try:
            with _SigintRaises():
                while self.running:
                    try:
                        i = self.done_q.get(timeout=0.25)
                    except queue.Empty:
                        if _INTERRUPT.is_set():
                            raise KeyboardInterrupt
                        self.board.emit()
                        self._check_workers()
                        self._maybe_steal()
                        continue
                    for j in self._take(i):
                        self._submit(j)
                    self._maybe_steal()
        except KeyboardInterrupt:
            interrupted = True
            for i, f in list(self.running.items()):
                if f.done() and f.status == "finished":
                    self._take(i)  # (pieces it cuts are not run: they count as interrupted)
            self.client.cancel(list(self.running.values()))
        finally:
            if self._listening():
                try:
                    self.client.unsubscribe_topic(self.topic)
                except Exception:  # noqa: BLE001
                    pass
        return interrupted

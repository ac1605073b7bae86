"""Re-chunking: a paused chunk's sets cut into pieces that run on from the same exact time
(:class:`_Pieces`), and the pieces' records stitched back into one chunk's record
(:func:`stitch`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from verified.arith.interval import Interval, concatenate, hull, stack
from verified.driver.solution import Solution, Start
from verified.execution.merge import _STATUS_RANK, _chunk_tube_hulls
from verified.execution.plan import MIN_CHUNK_BOXES

__all__ = ["RECHUNK_GROWTH", "STEAL_MIN_SETS"]


#: re-chunking (``rechunk``): a piece pauses once it holds this many times as many sets
#: as it started with (and at least this many times the plan's mean chunk size and
#: ``RECHUNK_MIN_SETS``), and its sets are cut into pieces of about the larger of the two
RECHUNK_GROWTH = 2
#: pieces cut from a paused chunk hold at least this many sets (the fixed cost of a step,
#: ~2 ms of Python per step and batch, against ~0.15 ms per set: MIN_CHUNK_BOXES); a test
#: may lower it
RECHUNK_MIN_SETS = MIN_CHUNK_BOXES
STEAL_MIN_SETS = MIN_CHUNK_BOXES // 2


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
    recorded = _recorded_outputs(items, order, outs)
    leaves = [i for i in order if not items[i].children]
    worst, reason, t_reached, k_f = _leaves_outcome(items, leaves, recorded, outs, t0)
    boxes = []
    for k in range(k_f):
        parts = [items[i].sol.boxes[recorded[i][k]] for i in order if k in recorded[i]]
        boxes.append(concatenate(parts, axis=0))
    ran = [i for i in order if items[i].sol is not None]
    grid, tube, tube_hull = _stitched_tube(items, order, ran, t_reached, n)
    r = items[root].sol
    stats = _stitched_stats(items, order, ran, leaves, r)
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


def _recorded_outputs(items: list, order: list[int], outs) -> dict:
    """Per piece of ``order``: ``{output index: its row in the piece's t/boxes}`` for the
    outputs it recorded (a piece that never ran: none; a continued piece's ``t[0]`` is its
    start, not an output of its own)."""
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
    return recorded


def _leaves_outcome(items: list, leaves: list[int], recorded: dict, outs, t0):
    """``(status, reason, t_reached, k_f)`` of the stitched chunk from its leaves: the
    earliest worst leaf's status and reason (a leaf that never ran is interrupted at its
    start), the least ``t_reached``, and ``k_f``: how many leading outputs every path of
    pieces (a leaf and its ancestors) recorded."""
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
    return worst, reason, t_reached, k_f


def _stitched_tube(items: list, order: list[int], ran: list[int], t_reached: float, n: int):
    """``(grid, tube, tube_hull)``: the union of the pieces' step times up to ``t_reached``
    and, on each of its intervals, one box per piece live there (the hull of that piece's
    step's boxes), in depth-first order; raises RuntimeError where no piece covers an
    interval (every path of pieces covers every interval up to ``t_reached``)."""
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
    return grid, tube, tube_hull


def _stitched_stats(items: list, order: list[int], ran: list[int], leaves: list[int], r) -> dict:
    """The stitched chunk's stats: numeric counters summed over the pieces that ran (in
    depth-first order); ``order``/``worker_pid``/``boxes`` the root's (``r``: its
    Solution), ``final_boxes``/``max_boxes`` summed over the leaves that ran, and how
    many pieces ran and were cut."""
    stats = {}
    for i in ran:
        for key, v in items[i].sol.stats.items():
            if key in ("order", "worker_pid", "chunk_task_s", "boxes", "final_boxes", "max_boxes") \
                    or isinstance(v, bool):
                continue
            if isinstance(v, (int, float, np.integer, np.floating)):
                stats[key] = stats.get(key, 0) + v
    stats["order"] = r.stats.get("order")
    stats["worker_pid"] = r.stats.get("worker_pid")
    stats["boxes"] = r.stats.get("boxes")
    done = [items[i].sol for i in leaves if items[i].sol is not None]
    stats["final_boxes"] = sum(s.stats.get("final_boxes", 0) for s in done)
    stats["max_boxes"] = sum(s.stats.get("max_boxes", 0) for s in done)  # (approximate: at different times)
    stats["pieces"] = len(ran)
    stats["rechunks"] = sum(1 for i in order if items[i].children)
    return stats


def _dfs(items: list, root: int) -> list[int]:
    """Piece ``root`` and its descendants, depth first (children in order)."""
    out, stack = [], [root]
    while stack:
        i = stack.pop()
        out.append(i)
        stack.extend(reversed(items[i].children))
    return out

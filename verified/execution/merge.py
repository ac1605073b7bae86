"""The chunks' Solutions merged into one (:func:`merge_solutions`): outputs at the common times,
tubes on the common grid, the worst status, counters, consistency records.
"""

from __future__ import annotations

import math

import numpy as np

from verified.arith.interval import Interval, concatenate, hull, stack
from verified.driver.solution import PieceResult, Solution, pieces_summary

__all__ = ["merge_solutions"]


_STATUS_RANK = {"completed": 0, "stopped": 1, "interrupted": 2, "breakdown": 3}


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

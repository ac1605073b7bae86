"""One Solution from runs that continue each other in time.

``parts[k + 1]`` continued ``parts[k]`` from its sets where it stopped
(``solve(..., start=...)`` at ``parts[k].t_reached``): a failed attempt's record and the
stronger method that took its sets over (:mod:`verified.auto`), or the phases of a run
whose energy test was suspended and resumed (:mod:`verified.consistency.energy_cadence`). Every part
encloses every solution of the same initial set over its own span, so the outputs and
steps laid end to end enclose them over the whole span: nothing is wrapped or hulled
(each output keeps the boxes and set views of the part that recorded it, each step its
tube boxes and view).
"""

from __future__ import annotations

import numpy as np

from verified.arith.interval import Interval, stack_hulls
from verified.driver.solution import Solution

__all__ = ["chain_in_time", "records_in_time"]

#: statistics that are not summed over the parts
_NOT_SUMMED = ("order", "worker_pid", "boxes", "final_boxes", "max_boxes", "wall_s")


def chain_in_time(parts: list) -> Solution:
    """``parts`` (Solutions, each continued from the previous one's last sets at its
    ``t_reached``) as one: outputs and steps in time order (a continued part's first
    output, its start, is the previous part's last state and is left out),
    ``t_reached``/``status``/``reason`` of the last part, counters summed, the energy
    test's records laid end to end (:func:`records_in_time`). Raises ValueError when a
    part does not start where the previous one stopped (a bug)."""
    parts = [p for p in parts if p is not None]
    first = parts[0]
    if len(parts) == 1:
        return first
    n_out = len(first.t)
    t = list(np.asarray(first.t, float))
    boxes = list(first.boxes)
    views = _padded(first.views, n_out)
    tube_t = list(np.asarray(first.tube_t, float))
    tube = list(first.tube)
    tube_views = _padded(first.tube_views, len(first.tube))
    for p in parts[1:]:
        pt = np.asarray(p.tube_t, float)
        if pt[0] != tube_t[-1]:
            raise ValueError(f"a part starts at t = {pt[0]!r}, not where the previous one stopped "
                             f"(t = {tube_t[-1]!r})")
        k = len(p.t)
        t += list(np.asarray(p.t, float)[1:])
        boxes += list(p.boxes[1:])
        views += _padded(p.views, k)[1:]
        tube_t += list(pt[1:])
        tube += list(p.tube)
        tube_views += _padded(p.tube_views, len(p.tube))
    last = parts[-1]
    n = first.hull.shape[-1]
    empty = Interval._from_bounds(np.zeros((0, n)), np.zeros((0, n)))
    stats = {}
    for p in parts:
        for key, v in p.stats.items():
            if key in _NOT_SUMMED or isinstance(v, (bool, np.bool_)) \
                    or not isinstance(v, (int, float, np.integer, np.floating)):
                continue
            stats[key] = stats.get(key, 0) + v
    for key in ("order", "boxes"):
        if key in first.stats:
            stats[key] = first.stats[key]
    by_order = {}  # (a per-step order: the parts' counts added)
    for p in parts:
        for k, v in (p.stats.get("steps_by_order") or {}).items():
            by_order[k] = by_order.get(k, 0) + v
    if by_order:
        stats["steps_by_order"] = dict(sorted(by_order.items()))
    stats["final_boxes"] = last.stats.get("final_boxes")
    stats["max_boxes"] = max((p.stats.get("max_boxes") or 0) for p in parts)
    stats["wall_s"] = sum(float(p.stats.get("wall_s") or 0.0) for p in parts)
    return Solution(
        t=np.array(t), boxes=boxes, hull=stack_hulls(boxes), tube_t=np.array(tube_t), tube=tube,
        tube_hull=stack_hulls(tube) if tube else empty, t_reached=float(last.t_reached), status=last.status,
        reason=last.reason, stats=stats, state_names=first.state_names,
        consistency=records_in_time([p.consistency for p in parts]),
        views=views if any(v is not None for v in views) else [],
        tube_views=tube_views if any(v is not None for v in tube_views) else [],
        method=last.method)


def _padded(views, k: int) -> list:
    """``views`` as a list of ``k`` entries (None where a part kept none)."""
    views = list(views or [])
    return (views + [None] * k)[:k]


def records_in_time(records):
    """Consistency records (:class:`verified.consistency.reduction_area.ConsistencyRecord`) of runs
    one after the other, laid end to end (series and tests in time order; a span
    without a test has no entries); None when no part had a test."""
    records = [r for r in records if r is not None]
    if not records:
        return None
    if len(records) == 1:
        return records[0]
    from verified.consistency.reduction_area import ConsistencyRecord

    def series(name):
        vals = [getattr(r, name) for r in records]
        if any(v is None for v in vals):
            return None
        vals = [v for v, r in zip(vals, records) if len(r.ra_t)]
        if not vals:
            return getattr(records[0], name)
        if isinstance(vals[0], Interval):
            return Interval._from_bounds(np.concatenate([np.asarray(v.lo) for v in vals]),
                                         np.concatenate([np.asarray(v.hi) for v in vals]))
        return np.concatenate([np.asarray(v) for v in vals])
    return ConsistencyRecord(ra_t=series("ra_t"), ra=series("ra"), h_h=series("h_h"), h_v=series("h_v"),
                             tests=[t for r in records for t in r.tests], h_h_set=series("h_h_set"),
                             h_v_set=series("h_v_set"))

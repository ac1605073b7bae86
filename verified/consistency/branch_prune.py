"""Branch and prune at ``t*``: cut sets into parts, discard the inconsistent ones (paper sec. 4).

This module owns the pruning test and the cutting, without state of its own: a set
``S = c + C r0 + Q r`` (:class:`verified.sets.first_order.DoubletonSets`, ``B`` sets of ``n``
states, ``2n`` parameters ``(r0, r)``) holds no true state when one of its checked
quantities misses its allowed range. The quantities are ``G = H(x) - h`` (must be 0:
the paper's ``H_H(S) ∩ H_V(S) = ∅``) and every constraint ``g`` (must lie in
``[lower, upper]``), each enclosed both naively on the hull and in mean-value form
``G(S) ⊆ G(c) + (DG C) r0 + (DG Q) r``, intersected (:func:`checks`). Either
excluding the range proves the part empty of true states. Second-order sets
(:class:`verified.sets.second_order.QuadraticSets`) are cut and checked the same way
through the same interface (``direction_columns`` ``[C + S r0 | Q]``,
``direction_widths``, ``subdivide_along``, ``take``, ``concatenate``).

:func:`branch_and_prune` cuts each set into a tree of parts (bisection rounds, or
one grid; :data:`STRATEGIES`), pruning between rounds, and returns what survives as
the largest consistent subtrees. The graphs come lifted onto the solver's states
(:class:`verified.consistency.graphs.LiftedGraphs`); the hook that decides when
to test is :class:`verified.consistency.energy_test.EnergyTest`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from verified.arith import linalg
from verified.arith.interval import Interval, concatenate, point

__all__ = ["STRATEGIES", "PruneResult", "branch_and_prune", "checks", "inconsistent", "largest_consistent_subtrees",
           "pick", "worth_refining"]

#: ways to split a set at ``t*`` (compared in benchmarks/bench_consistency.py)
STRATEGIES = ("gradient", "widest", "grid")


def checks(lifted, sets, t: Interval):
    """Per set, the enclosure of every checked quantity and its allowed range:
    a list of ``(enclosure (B, m), lower (m,), upper (m,), gradient-in-directions
    (B, m, 2n))``. ``t`` encloses the time (s) for time-dependent constraints."""
    nb = sets.n_sets
    X = sets.hull()
    cols = sets.direction_columns()  # (B, n, 2n)
    params = concatenate([sets.r0, sets.r], axis=1)  # (B, 2n): the set's parameters
    widths = params.width()
    out = []
    todo = []
    if lifted.energy is not None:
        todo.append((lifted.residual, None, np.zeros(1), np.zeros(1)))
    for c, g in lifted.constraints:
        todo.append((g, t if c.time_dependent else None, np.array(c.lower), np.array(c.upper)))
    for g, tt, lo, hi in todo:
        extra = None if tt is None else Interval._from_bounds(np.full((nb, 1), tt.lo), np.full((nb, 1), tt.hi))
        naive = lifted.eval(g, X, extra)  # (B, m)
        D = lifted.jac(g, X.hull(point(sets.c)), extra)[..., : lifted.n_aug]  # (B, m, n)
        Dcols = linalg.matmul(D, cols)  # (B, m, 2n)
        centre = lifted.eval(g, point(sets.c), extra)
        mv = centre + linalg.matvec(Dcols, params)
        enc = naive.intersect(mv)
        influence = Dcols.mag() * widths[:, None, :]  # (B, m, 2n)
        out.append((enc, lo, hi, influence))
    return out


def inconsistent(checks) -> np.ndarray:
    """(B,) whether some checked quantity of a set misses its allowed range (or its
    enclosure is empty): the set then holds no true state."""
    bad = None
    for enc, lo, hi, _ in checks:
        b = (enc.is_empty() | (enc.hi < lo) | (enc.lo > hi)).any(axis=1)
        bad = b if bad is None else bad | b
    return bad


def pick(sets, checks, strategy: str, k: int = 1) -> np.ndarray:
    """Directions (B, k) to cut, best first, by the chosen strategy."""
    if strategy == "widest" or not checks:
        score = sets.direction_widths()
    else:
        score = 0
        for enc, _, _, infl in checks:
            w = enc.width()
            w = np.where(np.isfinite(w) & (w > 0), w, 1.0)
            score = score + (infl / w[:, :, None]).sum(axis=1)
    return np.argsort(-score, axis=1, kind="stable")[:, :k]


@dataclass
class PruneResult:
    """What :func:`branch_and_prune` made of ``B`` sets.

    ``parts`` are the surviving sets and ``root`` (len ``parts``) the index of the set
    each came from; ``alive`` (B,) which sets passed the test before any cut;
    ``tested_hulls`` (per cutting round, (k, n_x) state hulls of the parts made) and
    ``tested_kept`` (per round, (k,) bool) are what the record shows."""

    parts: object  # DoubletonSets or QuadraticSets, as the sets tested
    root: np.ndarray
    alive: np.ndarray
    tested_hulls: list
    tested_kept: list

    @property
    def n_pruned(self) -> int:
        """Sets and parts found inconsistent (each counted where it was tested)."""
        return int((~self.alive).sum()) + sum(int((~k).sum()) for k in self.tested_kept)


def branch_and_prune(lifted, sets, t_iv: Interval, *, strategy: str, test_splits: int, refine: str,
                     min_gain: float) -> PruneResult:
    """Branch and prune all ``sets`` at the time enclosed by ``t_iv``.

    Each set is cut (bisection rounds, or one grid) into a tree of parts; parts
    inconsistent with a constraint are discarded between rounds. What survives
    is returned as the largest consistent subtrees: a node none of whose
    descendants was pruned stays one set (``refine="pruned"``), so splitting
    costs integration time only where something was cut away. See
    :class:`verified.consistency.energy_test.EnergyTest` for ``strategy``, ``test_splits``,
    ``refine`` and ``min_gain``."""
    chk = checks(lifted, sets, t_iv)
    alive = ~inconsistent(chk)
    tested_hulls, tested_kept = [], []
    # levels[l] = (kept parts at depth l, fan-out to them, ok mask over all children made)
    idx = np.flatnonzero(alive)
    levels = [(sets.take(idx), 1, alive)]
    cur_checks = [(e[alive], lo, hi, inf[alive]) for e, lo, hi, inf in chk]
    if strategy == "grid":
        k = max(2, int(round(np.sqrt(test_splits))))
        plan = [k * k]
    else:
        plan = [2] * max(1, int(round(np.log2(test_splits))))
    for fan in plan:
        cur = levels[-1][0]
        if cur.n_sets == 0:
            break
        if fan == 2:
            children = cur.subdivide_along(pick(cur, cur_checks, strategy, 1)[:, 0], 2)
        else:
            k = int(round(np.sqrt(fan)))
            d = pick(cur, cur_checks, strategy, 2)
            children = cur.subdivide_along(d[:, 0], k).subdivide_along(np.repeat(d[:, 1], k), k)
        ch_checks = checks(lifted, children, t_iv)
        ok = ~inconsistent(ch_checks)
        tested_hulls.append(children.hull()[:, : lifted.n_x])
        tested_kept.append(ok)
        levels.append((children.take(np.flatnonzero(ok)), fan, ok))
        cur_checks = [(e[ok], lo, hi, inf[ok]) for e, lo, hi, inf in ch_checks]
    parts, root = largest_consistent_subtrees(levels, refine)
    if refine == "pruned" and parts.n_sets:
        parts, root = worth_refining(sets, parts, root, min_gain)
    return PruneResult(parts, root, alive, tested_hulls, tested_kept)


def worth_refining(sets, parts, root, min_gain: float):
    """Keep the parts of a set only where they narrow its hull by ``min_gain``."""
    nb0 = sets.n_sets
    ph = parts.hull()
    lo = np.full((nb0, ph.shape[1]), np.inf)
    hi = np.full((nb0, ph.shape[1]), -np.inf)
    np.minimum.at(lo, root, ph.lo)
    np.maximum.at(hi, root, ph.hi)
    own = sets.hull().width()
    kept_w = hi - lo
    has = np.bincount(root, minlength=nb0) > 0
    gain = ((own - kept_w) > min_gain * own).any(axis=1) & has
    whole = has & ~gain
    use_parts = gain[root]
    out = type(sets).concatenate([sets.take(np.flatnonzero(whole)), parts.take(np.flatnonzero(use_parts))])
    return out, np.concatenate([np.flatnonzero(whole), root[use_parts]])


def largest_consistent_subtrees(levels, refine: str):
    """From the pruned tree, the maximal nodes with no pruned descendant (all
    kept leaves with ``refine="always"``). Returns the nodes to keep and the
    index of the set each came from.

    ``levels[l] = (kept parts at depth l, fan-out to them, ok mask over all children
    made)``, depth 0 being the sets themselves (fan-out 1)."""
    depth = len(levels) - 1
    roots = [np.flatnonzero(levels[0][2])]
    for l in range(1, depth + 1):
        _, fan, ok = levels[l]
        parent_root = np.repeat(roots[-1], fan)
        roots.append(parent_root[ok])
    if refine == "always" or depth == 0:
        return levels[-1][0], roots[-1]
    clean = [None] * (depth + 1)
    clean[depth] = np.ones(levels[depth][0].n_sets, dtype=bool)
    for l in range(depth - 1, -1, -1):
        _, fan, ok = levels[l + 1]
        filtered = np.cumsum(ok) - 1  # index among kept children of each child made
        child_clean = np.zeros(ok.size, dtype=bool)
        child_clean[ok] = clean[l + 1][filtered[ok]]
        clean[l] = child_clean.reshape(-1, fan).all(axis=1)
    pick_sets, pick_root = [], []
    for l in range(depth + 1):
        if l == 0:
            take = clean[0]
        else:
            _, fan, ok = levels[l]
            parent_of_made = np.repeat(np.arange(ok.size // fan), fan)
            take = clean[l] & ~clean[l - 1][parent_of_made[ok]]
        pick_sets.append(levels[l][0].take(np.flatnonzero(take)))
        pick_root.append(roots[l][take])
    return type(levels[0][0]).concatenate(pick_sets), np.concatenate(pick_root)

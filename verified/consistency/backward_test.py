"""The backward consistency test (paper sec. 4, cases A/B/C).

This module owns one job: decide, for the parts the energy test keeps at ``t*``,
whether they can have come from the forward sets one step earlier. Each part is
integrated back over the last step (size ``h`` in s) with a verified stepper of the
negated ODE, and its backward image (a box over the ``n`` integrated states) is
compared with the forward sets' hulls there. No state of its own: the stepper and
the previous step are passed in by :class:`verified.consistency.energy_test.EnergyTest`.
"""

from __future__ import annotations

import numpy as np

from verified.arith.interval import Interval

__all__ = ["backward_test"]


def backward_test(parts, root, prev_sets, h_step, stepper, depth: int):
    """Integrate each part back over the last step (``h_step``) and compare with the
    forward sets there (``prev_sets``, sec. 4): a part whose backward image meets none
    of them holds no true state (case A, deleted); one inside a forward set is
    consistent (case B, kept); the rest (case C) is bisected and retested down to
    ``depth``. A part is kept whole unless every one of its pieces ends
    in case A (keeping pieces would multiply the sets).

    Returns ``(kept parts, their root set indices, the root index of each deleted
    part, backward runs)`` (``runs``: pieces integrated back, over all depths)."""
    F = prev_sets.hull()  # (P, n)
    alive = np.zeros(parts.n_sets, dtype=bool)  # some piece not in case A
    cur, owner = parts, np.arange(parts.n_sets)
    runs = 0
    for d in range(depth + 1):
        if cur.n_sets == 0:
            break
        runs += cur.n_sets
        back = _one_step(stepper, cur, h_step)
        if back is None:  # no validated backward step: undecided, keep
            alive[owner] = True
            break
        meets = _meets_any(back, F)  # (K,)
        undecided = meets & ~_inside_any(back, F)
        alive[owner[meets & ~undecided]] = True  # case B
        if d == depth:
            alive[owner[undecided]] = True
            break
        und = cur.take(np.flatnonzero(undecided))
        cur = und.subdivide_along(np.argmax(und.direction_widths(), axis=1), 2)
        owner = np.repeat(owner[undecided], 2)
    return parts.take(np.flatnonzero(alive)), root[alive], root[~alive], runs


def _one_step(stepper, sets, h):
    """One verified Lohner step of size ``h`` (float or Interval) for all ``sets``, or None."""
    X = sets.hull()
    cX = stepper.coefficients(X)
    if not (np.isfinite(cX.lo).all() and np.isfinite(cX.hi).all()):
        return None
    hh = float(h.hi) if isinstance(h, Interval) else float(h)
    validated = stepper.apriori(X, cX, hh)
    if validated is None:
        return None
    E, cE = validated
    return stepper.step(sets, h, X, E, cE).sets.hull()


def _meets_any(boxes: Interval, F: Interval) -> np.ndarray:
    """(K,) whether each box meets at least one of the boxes F (P, n)."""
    lo = np.maximum(boxes.lo[:, None, :], F.lo[None, :, :])
    hi = np.minimum(boxes.hi[:, None, :], F.hi[None, :, :])
    return (lo <= hi).all(axis=2).any(axis=1)


def _inside_any(boxes: Interval, F: Interval) -> np.ndarray:
    """(K,) whether each box lies inside one of the boxes F."""
    return ((boxes.lo[:, None, :] >= F.lo[None, :, :]) & (boxes.hi[:, None, :] <= F.hi[None, :, :])).all(axis=2).any(axis=1)

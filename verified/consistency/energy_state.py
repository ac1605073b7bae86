"""The energy state ``h`` (``H_V``, eq. (12)) in the solver's doubleton sets.

This module owns how ``h`` enters and is re-entered into the sets
``S = c + C r0 + Q r`` (:class:`verified.sets.first_order.DoubletonSets`, ``B`` sets of ``n``
states): at ``t0`` it starts correlated with the initial states
(:func:`initial_sets`), and :func:`reset_h` restarts it from ``H`` where the integrated
``h`` has become wider than ``H_H``. Both use the mean value form
``H(x) ∈ H(c) + DH(X) (C r0 + Q r)`` of the energy (J) over a set. The lifted energy
graph comes from :mod:`verified.consistency.graphs`.
"""

from __future__ import annotations

from dataclasses import fields

import numpy as np

from verified.arith import linalg
from verified.arith.interval import Interval, concatenate, point
from verified.sets.first_order import DoubletonSets

__all__ = ["assign", "initial_sets", "reset_h"]


def initial_sets(lifted, sets):
    """Append ``h(0) = H(x0)`` to the initial sets, correlated with their parameters:
    ``H(x0) ∈ H(c) + DH(X0) (x0 - c)`` (mean value theorem), the midpoint of ``DH(X0)``
    times the parameter columns entering the linear part and everything else the error
    part. Doubleton sets (columns ``C``) and second-order sets
    (:class:`verified.sets.second_order.QuadraticSets`: columns ``C + S r0``, see its
    ``direction_columns``; ``h`` gets no quadratic term of its own) alike.
    ``lifted``: the :class:`verified.consistency.graphs.LiftedGraphs` of the run."""
    if lifted.energy is None:
        return sets
    nb, n = sets.c.shape
    m = sets.C.shape[2]
    X0 = sets.hull().hull(point(sets.c))  # (the segments from c into the set)
    Hc = lifted.eval(lifted.energy, point(sets.c))[:, 0]  # (B,)
    DH = lifted.jac(lifted.energy, X0)[:, 0, :]  # (B, n)
    rows = _row_times(DH, sets.direction_columns())  # (B, m + n): over r0, then over r
    row = rows[:, :m]
    row_mid = row.mid()  # (B, m)
    c_h = Hc.mid()
    # everything that is not row_mid . r0, enclosed: H(c) - c_h, (row - row_mid) r0, (DH Q) r
    rest = (Hc - c_h) + _dot(row - row_mid, sets.r0) + _dot(rows[:, m:], sets.r)
    c = np.concatenate([sets.c, c_h[:, None]], axis=1)
    # h gets a parameter of its own (width 0), so that a set of n states starting
    # from boxes keeps n parameters (the square C the QR-Lohner steppers start from)
    C = np.zeros((nb, n + 1, m + 1))
    C[:, :n, :m] = sets.C
    C[:, n, :m] = row_mid
    Q = np.zeros((nb, n + 1, n + 1))
    Q[:, :n, :n] = sets.Q
    Q[:, n, n] = 1.0
    r0 = concatenate([sets.r0, point(np.zeros((nb, 1)))], axis=1)
    r = concatenate([sets.r, rest.reshape((nb, 1))], axis=1)
    if isinstance(sets, DoubletonSets):
        return DoubletonSets(c, C, r0, Q, r)
    S = np.zeros((nb, n + 1, m + 1, m + 1))
    S[:, :n, :m, :m] = sets.S
    return type(sets)(c=c, C=C, r0=r0, S=S, Q=Q, r=r)


def reset_h(lifted, sets):
    """``(sets, resets)``: ``h`` restarted from ``H`` over the set where ``H_V`` has
    become wider than ``H_H`` (the integrated ``h`` then carries no information and
    only grows; with the unsimplified ``dH/dt`` over wide sets it grew past the
    solver's width limit and ended the run before the states did,
    docs/lab/code_notes.md). ``resets`` is
    how many sets were restarted; ``sets`` is changed in place (:func:`assign`).

    Sound: every true trajectory has ``h(t) = H(x(t))`` (eq. (12) is an identity
    along it), so ``h`` may be re-initialized from the state part of the set, as at
    ``t0`` (:func:`initial_sets`): ``H(x) ∈ H(c) + DH(X) (C r0 + Q r)``, its
    ``r0`` part (midpoint) linear, the rest a fresh error. Done only for sets whose
    ``Q`` keeps ``h`` in its own column and row (block diagonal, as
    :class:`verified.sets.bases.BlockBasis` keeps it; a QR basis that mixed ``h``
    into the state directions cannot be separated without wrapping)."""
    n_s = lifted.n_s
    nb = sets.n_sets
    if nb == 0:
        return sets, 0
    X = sets.hull()
    with np.errstate(all="ignore"):
        hh = lifted.eval(lifted.energy, X[:, :n_s])[:, 0]
    hv = X[:, n_s]
    block = (sets.Q[:, :n_s, n_s] == 0).all(axis=1) & (sets.Q[:, n_s, :n_s] == 0).all(axis=1)
    redo = block & np.isfinite(hh.lo) & np.isfinite(hh.hi) & ~(hv.width() <= hh.width())
    if not redo.any():
        return sets, 0
    idx = np.flatnonzero(redo)
    S = sets.take(idx)
    cx = S.c[:, :n_s]
    Xs = X[idx][:, :n_s].hull(point(cx))
    with np.errstate(all="ignore"):
        Hc = lifted.eval(lifted.energy, point(cx))[:, 0]
        DH = lifted.jac(lifted.energy, Xs)[:, 0, :]  # (k, n_s)
    rowC = _row_times(DH, S.C[:, :n_s, :])  # (k, N) over r0
    rowQ = _row_times(DH, S.Q[:, :n_s, :])  # (k, N) over r (its h entry is 0: block)
    row_mid = rowC.mid()
    c_h = Hc.mid()
    rest = (Hc - c_h) + _dot(rowC - row_mid, S.r0) + _dot(rowQ, S.r)
    ok = np.isfinite(rest.lo) & np.isfinite(rest.hi) & np.isfinite(row_mid).all(axis=1)
    if not ok.any():
        return sets, 0
    idx, S = idx[ok], S.take(np.flatnonzero(ok))
    row_mid, c_h, rest = row_mid[ok], c_h[ok], rest[ok]
    c, C, Q = sets.c.copy(), sets.C.copy(), sets.Q.copy()
    r = sets.r.copy()
    c[idx, n_s] = c_h
    C[idx, n_s, :] = row_mid
    r.lo[idx, n_s], r.hi[idx, n_s] = rest.lo, rest.hi
    assign(sets, DoubletonSets(c, C, sets.r0, Q, r))
    return sets, int(idx.size)


def assign(sets: DoubletonSets, new: DoubletonSets) -> None:
    """Make ``sets`` hold ``new`` (the same sets in the same order, contracted): in
    place, so the solver still sees the step's own sets (adaptive splitting uses the
    step's per-set widths, and a rollback to the step before stays possible); both
    enclose the same true states set by set."""
    for f in fields(new):  # (c, C, r0, Q, r, and S for second-order sets)
        setattr(sets, f.name, getattr(new, f.name))


def _row_times(row: Interval, M: np.ndarray) -> Interval:
    """``row @ M`` per set: (B, n) interval times (B, n, k) floats -> (B, k)."""
    nb, n = row.shape
    return linalg.matmul(row.reshape((nb, 1, n)), M)[:, 0, :]


def _dot(a: Interval, b: Interval) -> Interval:
    """Per-set dot product of two (B, n) interval arrays -> (B,)."""
    return (a * b).sum(axis=1)

"""Energy contraction: narrow QR-Lohner sets with the energy relation ``H(x) - h = 0``.

The energy test (:class:`verified.consistency.energy_test.EnergyTest`) integrates ``h`` with
``h' = dH/dt`` alongside the state (``H_V``, the paper's eq. (12)), starting from
``h(0) = H(x(0))``. Every true trajectory therefore satisfies

    G(x, h) = H(x) - h = 0        at every time t.

A doubleton set ``S = {c + C a + Q b : a in r0, b in r}`` (:class:`~verified.sets.first_order.DoubletonSets`)
is a parametrization: a state of the set is ``x(a, b)`` for some parameter ``(a, b)``
of the box ``R = r0 x r``. In mean-value form over the set
(:func:`verified.consistency.contractor.mean_value_row`),

    G(x(a, b)) in G(c) + sum_j g_j (a, b)_j + rem,      g = mid(DG(S) [C | Q]),

so a parameter of a true state satisfies the linear row
``0 in G(c) + g . (a, b) + rem`` and Gauss-Seidel on that row
(:func:`verified.consistency.contractor.contract_linear_row`) narrows every component of ``R``,
``r0`` as well as ``r``.

Why contracting ``r0`` is sound. ``r0`` is the box of initial parameters the set's
history started from; narrowing it narrows the set of initial states the set
represents. That is sound only if no true trajectory is lost, and none is: a true
state ``x`` at time ``t`` has ``H(x) - h(t) = 0`` (for *every* true trajectory, by
eq. (12)), so a parameter ``(a, b)`` violating the row at ``t`` maps to a point that
is no true state at ``t``; any true state of the set has some parameter ``(a, b)``
in ``R`` with ``x = x(a, b)``, that parameter satisfies the row, and the contracted
box keeps it. The set after contraction therefore holds every true state the set
held before (its parametrization changed, not the true states it encloses). Nothing
relies on ``a`` being *the* initial parameter of a particular trajectory.

Recentring. The Lohner step, the mean-value forms and ``merge_overlapping`` assume
``0 in r0`` and ``0 in r`` (the centre ``c`` is in the set). A contracted box may
miss 0, so each set is recentred: with ``d = mid(R')``,
``x = (c + C d_a + Q d_b) + C (a - d_a) + Q (b - d_b)``; the centre's float rounding
is enclosed and folded into ``r`` through ``Q^-1`` (as ``DoubletonSets.subdivide_along``
does), so the new set covers the contracted one.

A set whose row has no solution in ``R`` holds no true state and is dropped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from verified.arith import linalg
from verified.consistency.contractor import contract_linear_row, mean_value_row
from verified.graph import Graph
from verified.arith.interval import Interval
from verified.sets.second_order import QuadraticSets
from verified.sets.first_order import DoubletonSets

__all__ = ["EnergyContraction", "ContractionResult", "recentre"]


@dataclass
class ContractionResult:
    """``sets``: the contracted (and recentred) sets that may hold true states;
    ``empty``: bool (B,) over the input sets, True where a set was proven to hold
    none (it is not in ``sets``); ``ratio``: float (B,) width of each input set's
    parameter box after / before (1 = no narrowing; 0 for empty sets); ``params``:
    Interval (B_kept, 2N), the contracted parameter boxes ``(r0, r)`` of the kept sets
    before recentring (in the input sets' parametrization)."""

    sets: DoubletonSets
    empty: np.ndarray
    ratio: np.ndarray
    params: Interval | None = None


def recentre(c: np.ndarray, C: np.ndarray, r0: Interval, Q: np.ndarray, r: Interval) -> DoubletonSets:
    """Doubleton sets covering ``{c + C a + Q b : a in r0, b in r}`` whose ``r0`` and
    ``r`` are centred at 0 (see the module docstring). Components already containing 0
    are left as they are only when they are centred already; the shift is exact in
    the parameters (floats ``d``) and its image ``C d_a + Q d_b`` is enclosed."""
    nb, n = c.shape
    da = r0.mid()
    db = r.mid()
    r0n = r0 - Interval._from_bounds(da, da)
    rn = r - Interval._from_bounds(db, db)
    exact_c = (linalg.matvec(C, Interval._from_bounds(da, da)) + linalg.matvec(Q, Interval._from_bounds(db, db))) + c
    c_new = exact_c.mid()
    e = exact_c - c_new  # the float centre's rounding, enclosed
    rn = rn + linalg.solve(Q, e)
    return DoubletonSets(c_new, C.copy(), r0n, Q.copy(), rn)


class EnergyContraction:
    """Contract doubleton sets over ``N`` states with ``residual(x) = 0`` (one output),
    e.g. ``H(x) - h`` on the state augmented by ``h`` (see the module docstring).

    Parameters
    ----------
    residual : Graph
        ``N`` inputs, one output, 0 at every true state.
    sweeps : int
        Gauss-Seidel sweeps over the ``2N`` parameters per call.
    contract_r0 : bool
        Narrow the initial parameters ``r0`` too (sound, see the module docstring).
    """

    def __init__(self, residual: Graph, *, sweeps: int = 1, contract_r0: bool = True):
        if not isinstance(residual, Graph) or residual.n_outputs != 1:
            raise ValueError("residual must be a Graph with one output")
        self.residual = residual
        self.sweeps = max(1, int(sweeps))
        self.contract_r0 = bool(contract_r0)

    def contract(self, sets: DoubletonSets, params: Interval | None = None) -> ContractionResult:
        """Contract every set of the batch (``params``: the residual's parameters,
        (p,) or (B, p), or None)."""
        nb, N = sets.c.shape
        if self.residual.n_inputs != N:
            raise ValueError(f"the residual takes {self.residual.n_inputs} states, the sets have {N}")
        if nb == 0:
            return ContractionResult(sets, np.zeros(0, bool), np.ones(0), None)
        m = sets.C.shape[2]
        A = sets.direction_columns()  # (B, N, m + N): floats, or intervals for second-order sets
        R = _concat(sets.r0, sets.r)
        p = params
        if p is not None and p.ndim == 1:
            p = p.broadcast_to((nb, p.shape[-1]))
        with np.errstate(all="ignore"):
            a, g0, rem = mean_value_row(self.residual, sets.c, A, R, 0.0, p)
            ok = np.isfinite(a).all(axis=1) & np.isfinite(g0.lo) & np.isfinite(g0.hi) \
                & np.isfinite(rem.lo) & np.isfinite(rem.hi)
            a = np.where(ok[:, None], a, 0.0)
            g0 = Interval._from_bounds(np.where(ok, g0.lo, -np.inf), np.where(ok, g0.hi, np.inf))
            which = np.ones(m + N, bool)
            if not self.contract_r0:
                which[:m] = False
            Rn, empty = contract_linear_row(a, g0, R, rem, which=which, sweeps=self.sweeps)
        empty = empty & ok
        keep = np.flatnonzero(~empty)
        w0 = R.width().sum(axis=1)
        w1 = np.where(empty, 0.0, Rn.width().sum(axis=1))
        ratio = np.where(w0 > 0, w1 / np.where(w0 > 0, w0, 1.0), 1.0)
        Rk = Rn[keep]
        if isinstance(sets, QuadraticSets):
            # recentred as a whole batch (a centred set is left as it is; the
            # recentring encloses its own rounding, QuadraticSets.recentred)
            kept = QuadraticSets(c=sets.c[keep], C=sets.C[keep], r0=Rk[:, :m], S=sets.S[keep], Q=sets.Q[keep],
                                 r=Rk[:, m:]).recentred()
            return ContractionResult(kept, empty, ratio, Rk)
        kept = DoubletonSets(sets.c[keep], sets.C[keep], Rk[:, :m], sets.Q[keep], Rk[:, m:])
        # recentre only the sets whose box no longer holds 0 (the others stay as they are)
        off = ~((Rk.lo <= 0) & (0 <= Rk.hi)).all(axis=1)
        if off.any():
            idx = np.flatnonzero(off)
            moved = recentre(kept.c[idx], kept.C[idx], kept.r0[idx], kept.Q[idx], kept.r[idx])
            kept = kept.replaced(idx, moved)
        return ContractionResult(kept, empty, ratio, Rk)


def _concat(a: Interval, b: Interval) -> Interval:
    return Interval._from_bounds(np.concatenate([a.lo, b.lo], axis=1), np.concatenate([a.hi, b.hi], axis=1))

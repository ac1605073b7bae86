"""First-order sets: :class:`DoubletonSets`, the QR-Lohner doubleton ``c + C r0 + Q r``
(CAPD's ``Rect2``) advanced by :class:`verified.steppers.lohner.LohnerStepper`; it
implements :class:`verified.sets.protocol.SetBatch`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from verified.arith import linalg
from verified.arith.interval import Interval, concatenate, point
from verified.sets.bases import orthonormal_basis

__all__ = ["DoubletonSets"]


def parameter_cuts(r0: Interval, r: Interval, which, pieces: int):
    """The float breakpoints for cutting each set of a batch into ``pieces`` along one
    parameter direction (``which[b]`` in ``[0, m + n)``: ``r0_j`` for ``j < m``, else
    ``r_{j-m}``), shared by :meth:`DoubletonSets.subdivide_along` and
    :meth:`verified.sets.second_order.QuadraticSets.subdivide_along`.

    Returns None when there is nothing to cut (one piece, no sets), else ``(in_r0,
    j, j0, j1, cuts)``: ``in_r0`` (B,) whether the direction is a parameter, ``j`` its
    index in ``r0`` or ``r`` (``j0``, ``j1`` clipped so both branches can be indexed)
    and ``cuts`` (B, pieces + 1) from the interval's lower to its upper end, monotone
    despite rounding, so consecutive parts share their breakpoints exactly."""
    nb, m = r0.shape
    n = r.shape[1]
    which = np.asarray(which, dtype=np.int64).reshape(nb)
    pieces = int(pieces)
    if pieces < 1:
        raise ValueError(f"pieces must be >= 1, got {pieces}")
    if pieces == 1 or nb == 0:
        return None
    rows = np.arange(nb)
    in_r0 = which < m
    j = np.where(in_r0, which, which - m)
    j0, j1 = np.minimum(j, m - 1), np.minimum(j, n - 1)  # (both branches are indexed)
    lo = np.where(in_r0, r0.lo[rows, j0], r.lo[rows, j1])
    hi = np.where(in_r0, r0.hi[rows, j0], r.hi[rows, j1])
    frac = np.arange(pieces + 1) / pieces
    cuts = lo[:, None] + (hi - lo)[:, None] * frac[None, :]
    cuts[:, 0], cuts[:, -1] = lo, hi
    cuts = np.maximum.accumulate(np.minimum(cuts, hi[:, None]), axis=1)  # monotone despite rounding
    return in_r0, j, j0, j1, cuts


@dataclass
class DoubletonSets:
    """A batch of sets ``c + C r0 + Q r``; every array has the batch as first axis."""

    c: np.ndarray  # (B, n)
    C: np.ndarray  # (B, n, m): m = n at the start, more after absorb_error
    r0: Interval  # (B, m), contains 0 (absorbed errors need not)
    Q: np.ndarray  # (B, n, n)
    r: Interval  # (B, n)

    @classmethod
    def from_boxes(cls, boxes: Interval) -> "DoubletonSets":
        nb, n = boxes.shape
        c = boxes.mid()
        eye = np.broadcast_to(np.eye(n), (nb, n, n)).copy()
        return cls(c=c, C=eye, r0=boxes - c, Q=eye.copy(), r=point(np.zeros((nb, n))))

    @property
    def n_sets(self) -> int:
        return self.c.shape[0]

    def hull(self) -> Interval:
        """Interval hull of each set, shape (B, n)."""
        return (linalg.matvec(self.C, self.r0) + linalg.matvec(self.Q, self.r)) + self.c

    def affine_forms(self, extra: int = 0, own_symbols: int | None = None) -> np.ndarray:
        """Affine forms of the sets over their own parameters, shape (n + extra, B, k + 2)
        (the ``extra`` rows are zero, for inputs the caller fills).

        ``x = c + C a + Q b`` with ``a = mid(r0') + rad(r0') eps_a`` and likewise ``b``,
        where ``r0' = hull(r0, 0)`` and ``r' = hull(r, 0)``: the forms cover the set and
        its centre ``c`` (a mean-value form needs every segment from ``c`` into the set).
        Column 0 is the centre, then the ``eps_a`` and ``eps_b`` coefficients, the last
        an error radius holding every rounding.

        With absorbed errors, at most ``own_symbols`` parameters (default ``n + 2 w``,
        ``w`` the number of initial parameters of nonzero width: an exact state such as
        a controller's time must not change what the others get) keep a
        symbol of their own: the first ``n`` (the initial box) and the absorbed ones
        giving the set the most width; the others share ``n`` symbols, one per state
        (their box in state coordinates). What the forms feed (Jacobian enclosures)
        costs in proportion to the symbols; sharing all of them costs reach, hence the
        widest keep their own (docs/lab/code_notes.md).
        """
        nb, n = self.c.shape
        m = self.C.shape[2]
        if own_symbols is None:  # n + 2w: initial parameters of no width (an exact time state) count for none
            live = int((self.r0.width()[:, :n] > 0).any(axis=0).sum()) if m > n else n
            own_symbols = n + 2 * live
        own = max(n, int(own_symbols))
        r0 = self.r0.hull(0.0)
        r = self.r.hull(0.0)
        ma, ra = r0.mid(), r0.rad()
        mb, rb = r.mid(), r.rad()
        centre = point(self.c) + linalg.matvec(self.C, point(ma)) + linalg.matvec(self.Q, point(mb))
        C, shared = self.C, None
        if m > own:
            widths = np.abs(C[:, :, n:]).sum(axis=1) * ra[:, n:]
            order = np.argsort(-widths, axis=1, kind="stable") + n
            mine = np.concatenate([np.broadcast_to(np.arange(n), (nb, n)), order[:, : own - n]], axis=1)
            rest = order[:, own - n:]
            rest_C = np.take_along_axis(C, rest[:, None, :], axis=2)
            shared = (np.abs(rest_C) * np.take_along_axis(ra, rest, axis=1)[:, None, :]).sum(axis=-1)
            shared = shared * (1.0 + 2.0**-40) + 1e-300  # (B, n): their box, rounded up
            C, ra = np.take_along_axis(C, mine[:, None, :], axis=2), np.take_along_axis(ra, mine, axis=1)
        k = C.shape[2]
        ka = k if shared is None else k + n
        cols_a = Interval(C) * ra[:, None, :]
        cols_b = Interval(self.Q) * rb[:, None, :]
        F = np.zeros((n + extra, nb, ka + n + 2))
        F[:n, :, 0] = centre.mid().T
        F[:n, :, 1 : k + 1] = cols_a.mid().transpose(1, 0, 2)
        if shared is not None:
            F[:n, :, k + 1 : ka + 1] = np.eye(n)[:, None, :] * shared.T[:, :, None]
        F[:n, :, ka + 1 : ka + n + 1] = cols_b.mid().transpose(1, 0, 2)
        err = centre.rad() + cols_a.rad().sum(axis=-1) + cols_b.rad().sum(axis=-1)
        F[:n, :, ka + n + 1] = (err * (1.0 + 2.0**-40) + 1e-300).T
        return F

    def absorb_error(self) -> "DoubletonSets":
        """The same sets with the error part ``Q r`` turned into ``n`` new parameters:
        ``C <- [C | Q]``, ``r0 <- [r0; r]``, ``Q <- I``, ``r <- 0`` (exact: nothing is
        widened).

        Why: ``r`` is an interval vector multiplied by ``|Q'^-1 J Q|`` every step; in an
        orthonormal basis that wraps at the rate of ``||J||``, not of the flow's growth.
        A robot's Jacobian is strongly non-normal (``||J||`` far above its eigenvalues'
        moduli), so ``r`` grows fast while the exactly carried ``C r0`` stays near the
        true hull (docs/lab/code_notes.md). Absorbed, the
        error is carried by the float matrix ``C`` (``C' = mid(J C)``) and wraps no
        more. (Folding the least wide absorbed columns back into ``r`` to bound their
        number, a zonotope's order reduction, costs far more steps for little reach:
        stopping at a cap is better; docs/lab/code_notes.md.)
        """
        nb, n = self.c.shape
        eye = np.broadcast_to(np.eye(n), (nb, n, n)).copy()
        return DoubletonSets(c=self.c, C=np.concatenate([self.C, self.Q], axis=2),
                             r0=concatenate([self.r0, self.r], axis=1), Q=eye, r=point(np.zeros((nb, n))))

    def recentred(self) -> "DoubletonSets":
        """The same sets with every parameter interval and the error vector centred on 0:
        ``c += C mid(r0) + Q mid(r)``, ``r0 -= mid(r0)``, ``r -= mid(r)``; the float
        centre's rounding is enclosed and folded into ``r`` (``r += Q^-1 d``).

        Why: absorbed errors and merged parameters need not be centred, and the forms
        the Jacobian is taken over (:meth:`affine_forms`) must hold the centre ``c``, so
        they use ``hull(r0, 0)``: a parameter in [0.9, 1.1] then counts as [0, 1.1]."""
        mid0, mid_r = self.r0.mid(), self.r.mid()
        if not (mid0.any() or mid_r.any()):
            return self
        exact_c = point(self.c) + linalg.matvec(self.C, point(mid0)) + linalg.matvec(self.Q, point(mid_r))
        c_new = exact_c.mid()
        d = exact_c - c_new  # the float centre's rounding, enclosed
        r = (self.r - mid_r) + linalg.solve(self.Q, d)
        if not (np.isfinite(r.lo).all() and np.isfinite(r.hi).all() and np.isfinite(c_new).all()):
            return self
        return DoubletonSets(c=c_new, C=self.C, r0=self.r0 - mid0, Q=self.Q, r=r)

    def merge_params(self, count: int, keep_first: int, steer: int | None = None) -> "DoubletonSets":
        """The same sets with their ``count`` least wide parameters past the first
        ``keep_first`` replaced by ``n`` parameters that cover them (a zonotope's order
        reduction into a parallelepiped): ``sum_{j in S} C_j r0_j`` lies in ``B b`` with
        ``B`` the orthonormal basis of those columns (QR, widest first) and ``b`` an
        enclosure of ``B^-1 C_S r0_S``. Nothing true is lost; the merged part widens
        once, to the parallelepiped, and is then carried by ``C`` like any parameter.

        Why not fold them into the error part ``Q r`` instead: ``r`` is multiplied by
        ``|Q'^-1 J Q|`` every step, which for a robot's strongly non-normal Jacobian
        grows at the rate of ``||J||``, far above its eigenvalues (docs/lab/code_notes.md);
        a parameter is carried by ``mid(J C)``, whose rounding is all that wraps.
        Returns ``m - count + n`` parameters per set (``count >= n`` to shrink)."""
        nb, n = self.c.shape
        m = self.C.shape[2]
        count = int(count)
        if count <= 0 or keep_first + count > m:
            return self
        # (B, m): width each parameter gives the first ``steer`` states (the ones that
        # steer the step; a state a hook appended, such as the energy's h, does not decide)
        w = np.abs(self.C[:, :steer]).sum(axis=1) * self.r0.width()
        w[:, :keep_first] = np.inf
        # the same columns for every set of the batch (it keeps one parameter count)
        sel = np.sort(np.argsort(w.max(axis=0), kind="stable")[:count])
        rest = np.setdiff1d(np.arange(m), sel)
        CS = self.C[:, :, sel]  # (B, n, count)
        Bq = orthonormal_basis(CS, self.r0.width()[:, sel])  # (B, n, n): Lohner's sorted QR
        if Bq.shape[2] < n:  # fewer columns than states cannot happen (count >= n), kept safe
            return self
        eye = point(np.broadcast_to(np.eye(n), (nb, n, n)))
        B_inv = linalg.solve(Bq[:, None, :, :], eye).swapaxes(-1, -2)  # rigorous rows of B^-1
        b = linalg.matvec(linalg.matmul(B_inv, CS), self.r0[:, sel])
        if not (np.isfinite(b.lo).all() and np.isfinite(b.hi).all()):
            return self
        C = np.concatenate([self.C[:, :, rest], Bq], axis=2)
        r0 = concatenate([self.r0[:, rest], b], axis=1)
        return DoubletonSets(c=self.c, C=C, r0=r0, Q=self.Q, r=self.r)

    def take(self, index) -> "DoubletonSets":
        return DoubletonSets(self.c[index], self.C[index], self.r0[index], self.Q[index], self.r[index])

    def replaced(self, idx: np.ndarray, part: "DoubletonSets") -> "DoubletonSets":
        """The same batch with the sets at ``idx`` replaced by ``part`` (as many sets,
        the same parameter count), the order kept (contractors, the energy shell)."""
        c, C, Q = self.c.copy(), self.C.copy(), self.Q.copy()
        r0, r = self.r0.copy(), self.r.copy()
        c[idx], C[idx], Q[idx] = part.c, part.C, part.Q
        r0.lo[idx], r0.hi[idx] = part.r0.lo, part.r0.hi
        r.lo[idx], r.hi[idx] = part.r.lo, part.r.hi
        return DoubletonSets(c, C, r0, Q, r)

    def linear_width(self) -> np.ndarray:
        """Width of the linear part ``C r0`` per box and component, shape (B, n)."""
        return linalg.matvec(self.C, self.r0).width()

    def split(self, mask: np.ndarray) -> "DoubletonSets":
        """Split the sets selected by ``mask`` in two along their widest direction.

        A set is ``{c + C a + Q b : a in r0, b in r}``; the direction is the component of
        ``a`` or of ``b`` contributing most to the set's width (``|C_j| w(r0_j)`` or
        ``|Q_j| w(r_j)``), so accumulated error can be split as well as the initial box.
        Each half is recentred: its piece is shifted to be centred and the shift moves
        into the centre ``c``; the rounding of that float centre is enclosed and folded
        into the error vector (``r += Q^-1 d``). The union of the halves covers the set.
        """
        idx = np.flatnonzero(mask)
        if idx.size == 0:
            return self
        part = self.take(idx)
        halves = part.subdivide_along(np.argmax(part.direction_widths(), axis=1), 2)
        keep = self.take(np.flatnonzero(~mask))
        return DoubletonSets.concatenate([keep, halves])

    def direction_widths(self) -> np.ndarray:
        """Per set, the width each parameter direction gives the set, shape (B, m + n):
        ``sum_i |C_ij| w(r0_j)`` for the ``r0`` directions, then ``|Q_ij| w(r_j)``."""
        return np.concatenate(
            [np.abs(self.C).sum(axis=1) * self.r0.width(), np.abs(self.Q).sum(axis=1) * self.r.width()], axis=1
        )

    def direction_columns(self) -> np.ndarray:
        """The columns of ``[C | Q]``, shape (B, n, m + n): direction ``j`` moves the set
        along column ``j`` per unit of its parameter (``r0_j`` or ``r_{j-m}``)."""
        return np.concatenate([self.C, self.Q], axis=2)

    def subdivide_along(self, which: np.ndarray, pieces: int) -> "DoubletonSets":
        """Cut every set into ``pieces`` equal parts along one parameter direction.

        ``which[b]`` in ``[0, m + n)`` picks ``r0_j`` (``j < m``) or ``r_{j-m}`` of set ``b``.
        Returns ``B * pieces`` sets, set-major (the parts of set ``b`` are rows
        ``b * pieces .. (b + 1) * pieces - 1``). Each part is recentred: its shift
        moves into the float centre ``c`` and the rounding of that centre is enclosed
        and folded into the error vector (``r += Q^-1 d``). Consecutive parts share
        their float breakpoints, so the union of the parts covers the set exactly.
        """
        nb, n = self.c.shape
        cut = parameter_cuts(self.r0, self.r, which, pieces)
        if cut is None:
            return self
        in_r0, j, j0, j1, cuts = cut
        pieces = cuts.shape[1] - 1
        rows = np.arange(nb)
        column = np.where(in_r0[:, None], self.C[rows, :, j0], self.Q[rows, :, j1])
        parts = []
        for p in range(pieces):
            a, b = cuts[:, p], cuts[:, p + 1]
            sh = 0.5 * a + 0.5 * b
            piece = Interval._from_bounds(a, b) - sh  # outward rounded: contains the centred part
            r0 = self.r0.copy()
            r = self.r.copy()
            for vec, sel in ((r0, in_r0), (r, ~in_r0)):
                rr = rows[sel]
                vec.lo[rr, j[sel]] = piece.lo[sel]
                vec.hi[rr, j[sel]] = piece.hi[sel]
            exact_c = self.c + Interval._from_bounds(column, column) * sh[:, None]
            c_new = exact_c.mid()
            d = exact_c - c_new  # the float centre's rounding, enclosed
            r = r + linalg.solve(self.Q, d)
            parts.append(DoubletonSets(c_new, self.C.copy(), r0, self.Q.copy(), r))
        order = np.arange(nb * pieces).reshape(pieces, nb).T.ravel()  # set-major
        return DoubletonSets.concatenate(parts).take(order)

    def merge_overlapping(self, slack: float = 0.05) -> tuple["DoubletonSets", int]:
        """Merge neighbouring sets whose union is covered by one of them, nearly.

        Sets are ordered along the direction in which their centres spread most, and
        each pair of neighbours ``(A, B)`` (disjoint pairs, greedily) is tested: A's
        error box is widened to ``r' = hull(r_A, Q_A^-1 (hull(B) - c_A))``, which covers
        B (take ``a = 0`` in ``r0_A``, which contains 0). The pair becomes that one set
        when its hull is at most ``1 + slack`` times as wide (in every component) as
        the hull of ``A ∪ B``: heavily overlapping sets cost one set instead of two.

        Returns the merged batch and the number of merges.
        """
        nb, n = self.c.shape
        if nb < 2:
            return self, 0
        spread = self.c.max(axis=0) - self.c.min(axis=0)
        order = np.argsort(self.c[:, int(np.argmax(spread))], kind="stable")
        a_idx, b_idx = order[0:-1:2], order[1::2]
        A, B = self.take(a_idx), self.take(b_idx)
        XA, XB = A.hull(), B.hull()
        cover = linalg.solve(A.Q, XB - A.c, on_failure="entire")
        r_new = A.r.hull(cover)
        merged = DoubletonSets(A.c, A.C, A.r0, A.Q, r_new)
        ok = (merged.hull().width() <= (1.0 + slack) * XA.hull(XB).width() + 1e-300).all(axis=1)
        ok &= np.isfinite(r_new.lo).all(axis=1) & np.isfinite(r_new.hi).all(axis=1)
        if not ok.any():
            return self, 0
        keep = np.ones(nb, dtype=bool)
        keep[b_idx[ok]] = False
        keep[a_idx[ok]] = False
        return DoubletonSets.concatenate([self.take(np.flatnonzero(keep)), merged.take(np.flatnonzero(ok))]), int(ok.sum())

    def with_params(self, m: int) -> "DoubletonSets":
        """The same sets with ``m`` parameters (>= the current number): zero columns of
        ``C`` with ``r0 = 0`` appended (sets with absorbed errors can then be batched)."""
        nb, n, m0 = self.C.shape
        if m == m0:
            return self
        C = np.concatenate([self.C, np.zeros((nb, n, m - m0))], axis=2)
        return DoubletonSets(self.c, C, concatenate([self.r0, point(np.zeros((nb, m - m0)))], axis=1), self.Q, self.r)

    @staticmethod
    def concatenate(parts) -> "DoubletonSets":
        m = max(p.C.shape[2] for p in parts)
        parts = [p.with_params(m) for p in parts]
        return DoubletonSets(
            c=np.concatenate([p.c for p in parts]),
            C=np.concatenate([p.C for p in parts]),
            r0=concatenate([p.r0 for p in parts], axis=0),
            Q=np.concatenate([p.Q for p in parts]),
            r=concatenate([p.r for p in parts], axis=0),
        )

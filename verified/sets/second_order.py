"""Second-order sets: the QR-Lohner doubleton plus a quadratic term in the initial box.

A batch of ``B`` sets is carried as

    x  in  c + C u + q(u) + Q r,     u in r0,     q_i(u) = u^T S_i u,

with ``c``, ``C``, ``S`` (symmetric ``S_i``) and ``Q`` float arrays, ``r0`` the initial
radius box (fixed) and ``r`` the accumulated error in the basis ``Q`` (as in
:class:`verified.sets.first_order.DoubletonSets`, which is this with ``S = 0``).

Why: a first-order (doubleton) step bounds the curvature of the flow over the set,
``(J(X) - J(c)) C u``, as an interval and wraps it into ``r`` every step. That term
is quadratic in the set's size, and once wrapped it is multiplied by the interval
Jacobian again and again: on robot arms and over the pendulum's top it grows into a
finite-time blow-up (issue 17; docs/lab/code_notes.md). Here the quadratic part
of the flow is carried exactly in ``S``; only third-order terms are wrapped. This is
a Taylor model of order 2 in the initial conditions (Makino & Berz; COSY-VI,
TaylorModels.jl carry higher orders).

One step of size ``h`` (``P`` the order-``K`` Taylor polynomial map of the flow, ``R``
the Lagrange remainder over the a-priori enclosure, as in :mod:`verified.steppers.lohner`):
with ``v = C u + q(u)`` and ``w = Q r``,

    phi(h, c + v + w) in P(c + v) + J w + R                     (mean value in w, J over the set)
    P(c + v) = P(c) + DP(c) v + 1/2 v^T H(c) v + 1/2 v^T (H(xi) - H(c)) v

(Taylor with Lagrange remainder, ``xi`` on the segment ``[c, c + v]``, inside the box
``U = c + C r0 + range(q)``). Expanding ``v``:

    C'   = mid(DP(c) C)
    S'_i = mid(sum_k DP(c)_ik S_k + 1/2 C^T H_i(c) C)
    into r:  (DP(c) C - C') u,  (S' - mid S')[u, u],
             H(c)[C u, q(u)] + 1/2 H(c)[q, q]                     (third and fourth order)
             1/2 (H(U) - H(c))[v, v]                              (third order)
             P(c) + R - c'

The Jacobian for the error part is the first-order enclosure over the set intersected
with its second-order mean value form ``DP(c) + H(set)[x - c]``. When the error part
``Q r`` grows to ``absorb_ratio`` of the carried part, it becomes ``n`` new parameters
(:meth:`QuadraticSets.absorb_error`: exact, nothing is widened), up to ``max_params``.

``DP`` and ``H`` come from the Taylor coefficients of the second variational
equations (:func:`verified.series.variational.second_variational_graph`) at the centres (thin
enclosures) and over ``U``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from verified.arith import linalg
from verified.arith.interval import Interval, concatenate, point, sqr
from verified.sets.bases import orthonormal_basis, scaled_basis
from verified.sets.first_order import DoubletonSets, parameter_cuts

__all__ = ["QuadraticSets", "quadratic_range"]


def quadratic_range(S, u: Interval) -> Interval:
    """Enclosure of ``q_i(u) = u^T S_i u`` over the boxes ``u`` (B, m): shape (B, n).

    ``S`` (B, n, m, m), float or Interval, symmetric in its last two axes (only
    ``S_ijj`` and ``S_ijk + S_ikj`` for ``j < k`` are used). Diagonal terms use the
    square ``u_j^2`` (never negative), the others the products ``u_j u_k``."""
    S = S if isinstance(S, Interval) else point(np.asarray(S, dtype=float))
    B, n = u.shape  # (n here counts the parameters u, m in the docstring)
    jj = np.arange(n)
    sq = sqr(u)  # the square: never below 0 (a product u_j u_j would reach -rad^2)
    diag = Interval._from_bounds(S.lo[:, :, jj, jj], S.hi[:, :, jj, jj])  # (B, n_i, n_j)
    total = linalg.matvec(diag, sq)
    if n > 1:
        j, k = linalg.upper_pairs(n, 1)
        off = Interval._from_bounds(S.lo[:, :, j, k], S.hi[:, :, j, k]) + \
            Interval._from_bounds(S.lo[:, :, k, j], S.hi[:, :, k, j])  # (B, n_i, pairs)
        prod = Interval._from_bounds(u.lo[:, j], u.hi[:, j]) * Interval._from_bounds(u.lo[:, k], u.hi[:, k])
        total = total + linalg.matvec(off, prod)
    return total


def _linear_quadratic_range(C: np.ndarray, S: np.ndarray, u: Interval) -> Interval:
    """Enclosure of ``C u + u^T S_i u`` over the boxes ``u`` (B, m), shape (B, n), with
    ``C`` (B, n, m) and ``S`` (B, n, m, m) float (symmetric in its last two axes).

    Per parameter ``j`` the terms ``a u_j + s u_j^2`` (``a = C_ij``, ``s = S_ijj``) form
    one quadratic whose range over ``[l, h]`` is the hull of its values at ``l``, ``h``
    and, where the vertex ``-a / (2 s)`` may lie inside, ``-a^2 / (4 s)`` (all in
    outward-rounded interval arithmetic); the cross terms are bounded as in
    :func:`quadratic_range`."""
    B, n, m = C.shape
    jj = np.arange(m)
    a = point(C)
    s = point(np.ascontiguousarray(S[:, :, jj, jj]))
    # the ends as point intervals (B, 1, m): the operations with ``a`` and ``s`` broadcast
    # them (their squares once per parameter, not once per state)
    ul, uh = u.lo[:, None, :], u.hi[:, None, :]
    lo = Interval._from_bounds(ul, ul)
    hi = Interval._from_bounds(uh, uh)
    f_lo = a * lo + s * sqr(lo)
    f_hi = a * hi + s * sqr(hi)
    r_lo = np.minimum(f_lo.lo, f_hi.lo)
    r_hi = np.maximum(f_lo.hi, f_hi.hi)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        nz = s.lo != 0.0
        safe = point(np.where(nz, s.lo, 1.0))
        v = -(a / (safe * 2.0))  # the vertex (where s != 0)
        inside = nz & (v.hi >= u.lo[:, None, :]) & (v.lo <= u.hi[:, None, :])
        top = -(sqr(a) / (safe * 4.0))  # the value there
    r_lo = np.where(inside, np.minimum(r_lo, top.lo), r_lo)
    r_hi = np.where(inside, np.maximum(r_hi, top.hi), r_hi)
    total = Interval._from_bounds(r_lo, r_hi).sum(axis=-1)
    if m > 1:
        j, k = linalg.upper_pairs(m, 1)
        off = point(S[:, :, j, k]) + point(S[:, :, k, j])  # (B, n, pairs)
        prod = Interval._from_bounds(u.lo[:, j], u.hi[:, j]) * Interval._from_bounds(u.lo[:, k], u.hi[:, k])
        total = total + linalg.matvec(off, prod)
    return total


def _bilinear(H: Interval, a: Interval, b: Interval) -> Interval:
    """``sum_jk H_ijk a_j b_k`` for H (B, n, n, n), a, b (B, n): shape (B, n)."""
    B, n = a.shape
    Hb = linalg.matvec(H.reshape((B, n * n, n)), b).reshape((B, n, n))
    return linalg.matvec(Hb, a)


@dataclass
class QuadraticSets:
    """A batch of sets ``c + C u + q(u) + Q r``, ``u`` in ``r0``, ``q_i(u) = u^T S_i u``.

    Shapes: c (B, n), C (B, n, m), r0 (B, m) Interval, S (B, n, m, m) (symmetric in
    the last two axes), Q (B, n, n), r (B, n) Interval. ``m = n`` at the start;
    :meth:`absorb_error` appends the error part as ``n`` new parameters."""

    c: np.ndarray
    C: np.ndarray
    r0: Interval
    S: np.ndarray
    Q: np.ndarray
    r: Interval

    @classmethod
    def from_boxes(cls, boxes: Interval) -> "QuadraticSets":
        d = DoubletonSets.from_boxes(boxes)
        nb, n = boxes.shape
        return cls(c=d.c, C=d.C, r0=d.r0, S=np.zeros((nb, n, n, n)), Q=d.Q, r=d.r)

    @property
    def n_sets(self) -> int:
        return self.c.shape[0]

    def doubleton(self) -> DoubletonSets:
        """The first-order part ``c + C r0 + Q r`` (without ``q``)."""
        return DoubletonSets(self.c, self.C, self.r0, self.Q, self.r)

    def q_range(self) -> Interval:
        """Enclosure of the quadratic part ``q(u)`` over ``r0``, shape (B, n)."""
        return quadratic_range(self.S, self.r0)

    def hull(self) -> Interval:
        """Interval hull of each set, shape (B, n): ``C u + q(u)`` per parameter as one
        quadratic in ``u_j`` (its exact range: ends and vertex), the cross terms
        ``u_j u_k`` bounded, plus ``c + Q r``. (Bounding ``C u`` and ``q(u)`` apart lost
        the cancellation between ``a u_j`` and ``s u_j^2``; docs/lab/code_notes.md.)"""
        return _linear_quadratic_range(self.C, self.S, self.r0) + linalg.matvec(self.Q, self.r) + self.c

    def affine_forms(self, extra: int = 0, own_symbols: int | None = None) -> np.ndarray:
        """Affine forms of the sets over their own ``m + n`` parameters (each its own
        symbol: ``own_symbols`` is accepted for the doubleton's signature), shape
        (n + extra, B, m + n + 2), as :meth:`DoubletonSets.affine_forms`: ``x = c + C a +
        Q b + e`` with ``a`` over ``hull(r0, 0)``, ``b`` over ``hull(r, 0)`` and the range of
        ``q`` (with 0) in the error term ``e``. The forms cover the set and every segment
        from ``c + C a + q`` (any ``a``) into it, and from ``c`` to ``c + C u + q(u)``."""
        nb, n = self.c.shape
        m = self.C.shape[2]
        r0 = self.r0.hull(0.0)
        r = self.r.hull(0.0)
        qr = self.q_range().hull(0.0)
        centre = (point(self.c) + linalg.matvec(self.C, point(r0.mid())) + linalg.matvec(self.Q, point(r.mid()))
                  + point(qr.mid()))
        cols_a = Interval(self.C) * r0.rad()[:, None, :]
        cols_b = Interval(self.Q) * r.rad()[:, None, :]
        F = np.zeros((n + extra, nb, m + n + 2))
        F[:n, :, 0] = centre.mid().T
        F[:n, :, 1:m + 1] = cols_a.mid().transpose(1, 0, 2)
        F[:n, :, m + 1:m + n + 1] = cols_b.mid().transpose(1, 0, 2)
        err = centre.rad() + cols_a.rad().sum(axis=-1) + cols_b.rad().sum(axis=-1) + qr.rad()
        F[:n, :, m + n + 1] = (err * (1.0 + 2.0**-40) + 1e-300).T
        return F

    def absorb_error(self) -> "QuadraticSets":
        """The same sets with the error part ``Q r`` turned into ``n`` new parameters:
        ``C <- [C | Q]``, ``r0 <- [r0; r]``, ``S`` padded with zeros, ``r <- 0``. Exact (no
        enclosure is widened): afterwards the Jacobian's spread over the set acts on
        the absorbed error through the quadratic term, which is carried, instead of
        multiplying an interval vector every step."""
        nb, n = self.c.shape
        m = self.C.shape[2]
        S = np.zeros((nb, n, m + n, m + n))
        S[:, :, :m, :m] = self.S
        return QuadraticSets(c=self.c, C=np.concatenate([self.C, self.Q], axis=2),
                             r0=concatenate([self.r0, self.r], axis=1), S=S,
                             Q=np.broadcast_to(np.eye(n), (nb, n, n)).copy(), r=point(np.zeros((nb, n))))

    def recentred(self) -> "QuadraticSets":
        """The same sets with the parameter box and the error vector centred on 0, as
        :meth:`verified.sets.first_order.DoubletonSets.recentred`. With ``u = mu + delta``:
        ``q_i(u) = q_i(mu) + 2 mu^T S_i delta + q_i(delta)``, so ``c += C mu + q(mu) + Q
        mid(r)``, ``C += 2 (S mu)`` per state, ``S`` unchanged; the rounding of the new
        float ``c`` and ``C`` (times ``delta``) is enclosed and folded into ``r``.

        Why: a quadratic term over a box away from 0 (absorbed errors, merged
        parameters) is bounded by its size there, not by its variation over the box."""
        mu, mid_r = self.r0.mid(), self.r.mid()
        if not (mu.any() or mid_r.any()):
            return self
        nb, n = self.c.shape
        mu_i = point(mu)
        exact_c = (point(self.c) + linalg.matvec(self.C, mu_i) + quadratic_range(self.S, mu_i)
                   + linalg.matvec(self.Q, point(mid_r)))
        Smu = linalg.matvec(point(self.S.reshape(nb, n * self.S.shape[2], self.S.shape[3])), mu_i)
        C_exact = point(self.C) + Smu.reshape(self.C.shape) * 2.0
        C_new = C_exact.mid()
        delta = self.r0 - mu
        c_new = exact_c.mid()
        d = (exact_c - c_new) + linalg.matvec(C_exact - C_new, delta)
        r = (self.r - mid_r) + linalg.solve(self.Q, d)
        if not (np.isfinite(r.lo).all() and np.isfinite(r.hi).all() and np.isfinite(c_new).all()
                and np.isfinite(C_new).all()):
            return self
        return QuadraticSets(c=c_new, C=C_new, r0=delta, S=self.S, Q=self.Q, r=r)

    #: merge into a basis orthonormal in units of the set's extent per state
    #: (:func:`verified.sets.bases.scaled_basis`); False: in raw units
    SCALED_MERGE = True

    def merge_params(self, count: int, keep_first: int, steer: int | None = None) -> "QuadraticSets":
        """The same sets with their ``count`` least wide parameters past the first
        ``keep_first`` replaced by ``n`` covering ones, as
        :meth:`verified.sets.first_order.DoubletonSets.merge_params`; here the merged part is
        ``C_S u_S`` plus every quadratic term with a merged parameter in it (their
        range over ``r0``), enclosed in ``B b`` with ``B`` the orthonormal basis of the
        merged columns. The quadratic terms among the kept parameters stay; the new
        parameters start without any. Returns ``m - count + n`` parameters per set."""
        nb, n = self.c.shape
        m = self.C.shape[2]
        count = int(count)
        if count < n or keep_first + count > m:
            return self
        mag = self.r0.mag()
        # the width each parameter gives the first ``steer`` states (None: all): linear,
        # and through the quadratic terms it is in. A state a hook appended (the
        # energy's h, in J) must not decide: with it, the UR5 tracking a quintic in mode
        # ii merged away what its joints needed (docs/lab/code_notes.md)
        w = (np.abs(self.C[:, :steer]).sum(axis=1) * self.r0.width()
             + np.einsum("bijk,bk->bj", np.abs(self.S[:, :steer]), mag) * mag)
        w[:, :keep_first] = np.inf
        sel = np.sort(np.argsort(w.max(axis=0), kind="stable")[:count])
        rest = np.setdiff1d(np.arange(m), sel)
        CS = self.C[:, :, sel]
        # (B, n, n): Lohner's sorted QR, orthonormal in units of the set's extent per state
        Bq = scaled_basis(CS, self.r0.width()[:, sel], self.hull().width()) if self.SCALED_MERGE \
            else orthonormal_basis(CS, self.r0.width()[:, sel])
        # every quadratic term with a merged parameter in it: S with the kept block zeroed
        S_cross = self.S.copy()
        S_cross[np.ix_(np.arange(nb), np.arange(n), rest, rest)] = 0.0
        eye = point(np.broadcast_to(np.eye(n), (nb, n, n)))
        B_inv = linalg.solve(Bq[:, None, :, :], eye).swapaxes(-1, -2)  # rigorous rows of B^-1
        b = (linalg.matvec(linalg.matmul(B_inv, CS), self.r0[:, sel])
             + linalg.matvec(B_inv, quadratic_range(S_cross, self.r0)))
        if not (np.isfinite(b.lo).all() and np.isfinite(b.hi).all()):
            return self
        k = rest.size
        S = np.zeros((nb, n, k + n, k + n))
        S[:, :, :k, :k] = self.S[np.ix_(np.arange(nb), np.arange(n), rest, rest)]
        return QuadraticSets(c=self.c, C=np.concatenate([self.C[:, :, rest], Bq], axis=2),
                             r0=concatenate([self.r0[:, rest], b], axis=1), S=S, Q=self.Q, r=self.r)

    def take(self, index) -> "QuadraticSets":
        return QuadraticSets(self.c[index], self.C[index], self.r0[index], self.S[index], self.Q[index], self.r[index])

    def with_params(self, m: int) -> "QuadraticSets":
        """The same sets with ``m`` parameters (>= the current number): zero columns of
        ``C``, zero rows and columns of ``S`` and ``r0 = 0`` appended (the same sets;
        a fresh set can then join a batch whose errors were absorbed)."""
        nb, n, m0 = self.C.shape
        if m == m0:
            return self
        if m < m0:
            raise ValueError(f"with_params: {m} parameters, fewer than the sets' {m0}")
        C = np.concatenate([self.C, np.zeros((nb, n, m - m0))], axis=2)
        S = np.zeros((nb, n, m, m))
        S[:, :, :m0, :m0] = self.S
        r0 = concatenate([self.r0, point(np.zeros((nb, m - m0)))], axis=1)
        return QuadraticSets(c=self.c, C=C, r0=r0, S=S, Q=self.Q, r=self.r)

    def replaced(self, idx: np.ndarray, part: "QuadraticSets") -> "QuadraticSets":
        """The same batch with the sets at ``idx`` replaced by ``part`` (as many sets,
        the same parameter count), the order kept (the energy shell)."""
        c, C, S, Q = self.c.copy(), self.C.copy(), self.S.copy(), self.Q.copy()
        r0, r = self.r0.copy(), self.r.copy()
        c[idx], C[idx], S[idx], Q[idx] = part.c, part.C, part.S, part.Q
        r0.lo[idx], r0.hi[idx] = part.r0.lo, part.r0.hi
        r.lo[idx], r.hi[idx] = part.r.lo, part.r.hi
        return QuadraticSets(c=c, C=C, r0=r0, S=S, Q=Q, r=r)

    def linear_width(self) -> np.ndarray:
        """Width of the part carried without wrapping, ``C r0 + q(r0)``, shape (B, n).

        Kept for the same ``C``, ``S`` and ``r0`` objects (a step asks twice: the
        absorption test and the wrapping control, on the same sets unless absorbed;
        a field replaced, as :func:`verified.consistency.energy_state.assign` does, is
        a new object and computes it again; the arrays are never changed in place).
        The caller gets a copy."""
        key = (self.C, self.S, self.r0.lo, self.r0.hi)
        memo = self.__dict__.get("_linear_width_memo")
        if memo is None or any(a is not b for a, b in zip(memo[0], key)):
            memo = (key, (linalg.matvec(self.C, self.r0) + self.q_range()).width())
            self.__dict__["_linear_width_memo"] = memo
        return memo[1].copy()

    def split_widths(self) -> np.ndarray:
        """The width each parameter and each error component gives the set, summed over
        the states: ``|C_j| w(r0_j)`` plus the quadratic terms ``u_j`` is in (their size
        over ``r0``), and ``|Q_l| w(r_l)``; shape (B, m + n)."""
        mag = self.r0.mag()
        w_par = (np.abs(self.C).sum(axis=1) * self.r0.width()
                 + np.einsum("bijk,bk->bj", np.abs(self.S) + np.abs(self.S).transpose(0, 1, 3, 2), mag) * mag)
        w_err = np.abs(self.Q).sum(axis=1) * self.r.width()
        return np.concatenate([w_par, w_err], axis=1)

    def split(self, mask: np.ndarray) -> "QuadraticSets":
        """The sets selected by ``mask`` (B,) cut in two along the parameter or error
        component that gives them the most width (:meth:`split_widths`): that interval
        of ``r0`` (or of ``r``) is halved at a float, so the two halves' union is the set
        exactly; each half is recentred (:meth:`recentred`, sound by construction).
        Halving a parameter quarters the quadratic terms it is in and divides the
        third-order remainder of a step over it by about 8."""
        idx = np.flatnonzero(mask)
        if idx.size == 0:
            return self
        part = self.take(idx)
        m = part.C.shape[2]
        along = np.argmax(part.split_widths(), axis=1)  # (k,)
        rows = np.arange(idx.size)
        halves = []
        for side in (0, 1):
            r0_lo, r0_hi = part.r0.lo.copy(), part.r0.hi.copy()
            r_lo, r_hi = part.r.lo.copy(), part.r.hi.copy()
            on_par = along < m
            j = np.where(on_par, along, 0)
            l = np.where(on_par, 0, along - m)
            mid_p = 0.5 * r0_lo[rows, j] + 0.5 * r0_hi[rows, j]
            mid_r = 0.5 * r_lo[rows, l] + 0.5 * r_hi[rows, l]
            if side == 0:
                r0_hi[rows[on_par], j[on_par]] = mid_p[on_par]
                r_hi[rows[~on_par], l[~on_par]] = mid_r[~on_par]
            else:
                r0_lo[rows[on_par], j[on_par]] = mid_p[on_par]
                r_lo[rows[~on_par], l[~on_par]] = mid_r[~on_par]
            half = QuadraticSets(c=part.c.copy(), C=part.C.copy(), r0=Interval._from_bounds(r0_lo, r0_hi),
                                 S=part.S.copy(), Q=part.Q.copy(), r=Interval._from_bounds(r_lo, r_hi))
            halves.append(half.recentred())
        keep = self.take(np.flatnonzero(~np.asarray(mask, dtype=bool)))
        return QuadraticSets.concatenate([keep] + halves)

    def direction_widths(self) -> np.ndarray:
        """The width each parameter direction gives the set, shape (B, m + n): the
        interface :mod:`verified.consistency.branch_prune` picks cuts with (:meth:`split_widths`)."""
        return self.split_widths()

    def direction_columns(self) -> Interval:
        """``x - c = (C + S u) u + Q r`` exactly (``q_i(u) = (S_i u) . u``), so with ``S u``
        enclosed over ``r0`` the columns of ``[C + S r0 | Q]``, Interval (B, n, m + n),
        give the set in mean-value form: for every point ``x(u, r)`` of the set,
        ``g(x) in g(c) + Dg(X) [C + S r0 | Q] (u, r)`` with ``X`` any box holding the
        segment from ``c`` to ``x`` (the energy test's checks and contraction)."""
        nb, n = self.c.shape
        m = self.C.shape[2]
        Su = linalg.matvec(point(self.S.reshape(nb, n * m, m)), self.r0).reshape((nb, n, m))
        return concatenate([Su + self.C, point(self.Q)], axis=2)

    def subdivide_along(self, which: np.ndarray, pieces: int) -> "QuadraticSets":
        """Cut every set into ``pieces`` parts along one parameter direction, as
        :meth:`verified.sets.first_order.DoubletonSets.subdivide_along`: ``which[b]`` in ``[0, m + n)``
        picks ``r0_j`` (``j < m``) or ``r_{j-m}``; set-major order; consecutive parts share
        their float breakpoints, so the parts' union is the set exactly; each part is
        recentred (:meth:`recentred`, which encloses its rounding)."""
        nb = self.n_sets
        cut = parameter_cuts(self.r0, self.r, which, pieces)
        if cut is None:
            return self
        in_r0, j, _, _, cuts = cut
        pieces = cuts.shape[1] - 1
        rows = np.arange(nb)
        parts = []
        for p in range(pieces):
            r0_lo, r0_hi = self.r0.lo.copy(), self.r0.hi.copy()
            r_lo, r_hi = self.r.lo.copy(), self.r.hi.copy()
            a, b = rows[in_r0], rows[~in_r0]
            r0_lo[a, j[in_r0]], r0_hi[a, j[in_r0]] = cuts[in_r0, p], cuts[in_r0, p + 1]
            r_lo[b, j[~in_r0]], r_hi[b, j[~in_r0]] = cuts[~in_r0, p], cuts[~in_r0, p + 1]
            parts.append(QuadraticSets(c=self.c.copy(), C=self.C.copy(), r0=Interval._from_bounds(r0_lo, r0_hi),
                                       S=self.S.copy(), Q=self.Q.copy(), r=Interval._from_bounds(r_lo, r_hi)))
        order = np.arange(nb * pieces).reshape(pieces, nb).T.ravel()  # set-major
        return QuadraticSets.concatenate(parts).take(order).recentred()

    def merge_overlapping(self, slack: float = 0.05) -> tuple["QuadraticSets", int]:
        return self, 0  # (no merging of second-order sets)

    @staticmethod
    def concatenate(parts) -> "QuadraticSets":
        return QuadraticSets(
            c=np.concatenate([p.c for p in parts]),
            C=np.concatenate([p.C for p in parts]),
            r0=concatenate([p.r0 for p in parts], axis=0),
            S=np.concatenate([p.S for p in parts]),
            Q=np.concatenate([p.Q for p in parts]),
            r=concatenate([p.r for p in parts], axis=0),
        )

"""One verified Taylor step for a batch of doubleton sets (QR-Lohner, as CAPD's Rect2).

A batch of ``B`` sets is carried as

    x  in  c + C r0 + Q r                         (all shapes per box: c (n,), C, Q (n, n))

with ``c`` a float centre, ``C`` a float matrix acting on the fixed initial radius box
``r0`` (so the main linear part of the flow wraps nothing), and ``Q r`` the accumulated
errors, ``Q`` re-orthogonalized every step (Lohner's QR method) and ``r`` an interval
vector. A step of size ``h``:

1. ``X`` = interval hull of the set; Taylor coefficients ``x_[i](X)`` (:mod:`verified.taylor`).
2. A-priori enclosure ``E`` of all solutions from ``X`` over ``[0, h]`` by the high-order
   enclosure test of Nedialkov, Jackson & Pryce (2001): if
   ``sum_{i<K} [0,h]^i x_[i](X) + [0,h]^K x_[K](E~) ⊆ E~`` then the solutions exist on
   ``[0, h]`` and stay in ``E~``.
3. ``y = Φ(c) + h^K x_[K](E)``: the Taylor polynomial at the centre plus the Lagrange
   remainder (valid for every solution from ``X``).
4. ``J`` = enclosure of ``DΦ`` over ``X`` from the Taylor coefficients of the variational
   equations (:mod:`verified.variational`); by the mean value theorem
   ``φ(h, x) ∈ y + J (x - c)`` for all ``x`` in the set.
5. New set: ``c' = mid(y)``, ``C' = mid(J C)``,
   ``r' = (Q'^-1 J Q) r + Q'^-1 ((J C - C') r0 + y - c')`` with ``Q'`` from the QR
   factorization of ``mid(J Q)`` (columns sorted by their share of the set's size),
   ``Q'^-1`` enclosed rigorously. With ``error_basis="auto"``, ``Q' = I`` (a plain
   box) is used instead for the sets where that encloses the error part more tightly
   at this step: better on short horizons and wide sets, worse on long ones.

Everything is batched: the Taylor coefficients run in the compiled interpreter over all
boxes at once, the interval matrix products in compiled kernels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import linalg
from .interval import Interval, concatenate, point


@dataclass
class DoubletonSets:
    """A batch of sets ``c + C r0 + Q r``; every array has the batch as first axis."""

    c: np.ndarray  # (B, n)
    C: np.ndarray  # (B, n, n)
    r0: Interval  # (B, n), contains 0
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

    def affine_forms(self, extra: int = 0) -> np.ndarray:
        """Affine forms of the sets over their own ``2n`` parameters, shape
        (n + extra, B, 2n + 2) (the ``extra`` rows are zero, for inputs the caller fills).

        ``x = c + C a + Q b`` with ``a = mid(r0') + rad(r0') eps_a`` and likewise ``b``,
        where ``r0' = hull(r0, 0)`` and ``r' = hull(r, 0)``: the forms cover the set and
        its centre ``c`` (a mean-value form needs every segment from ``c`` into the set).
        Column 0 is the centre, ``1..n`` the ``eps_a``, ``n+1..2n`` the ``eps_b``
        coefficients, the last an error radius holding every rounding.
        """
        nb, n = self.c.shape
        r0 = self.r0.hull(0.0)
        r = self.r.hull(0.0)
        ma, ra = r0.mid(), r0.rad()
        mb, rb = r.mid(), r.rad()
        centre = point(self.c) + linalg.matvec(self.C, point(ma)) + linalg.matvec(self.Q, point(mb))
        cols_a = Interval(self.C) * ra[:, None, :]
        cols_b = Interval(self.Q) * rb[:, None, :]
        F = np.zeros((n + extra, nb, 2 * n + 2))
        F[:n, :, 0] = centre.mid().T
        F[:n, :, 1 : n + 1] = cols_a.mid().transpose(1, 0, 2)
        F[:n, :, n + 1 : 2 * n + 1] = cols_b.mid().transpose(1, 0, 2)
        err = centre.rad() + cols_a.rad().sum(axis=-1) + cols_b.rad().sum(axis=-1)
        F[:n, :, 2 * n + 1] = (err * (1.0 + 2.0**-40) + 1e-300).T
        return F

    def take(self, index) -> "DoubletonSets":
        return DoubletonSets(self.c[index], self.C[index], self.r0[index], self.Q[index], self.r[index])

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
        """Per set, the width each parameter direction gives the set, shape (B, 2n):
        ``sum_i |C_ij| w(r0_j)`` for the ``r0`` directions, then ``|Q_ij| w(r_j)``."""
        return np.concatenate(
            [np.abs(self.C).sum(axis=1) * self.r0.width(), np.abs(self.Q).sum(axis=1) * self.r.width()], axis=1
        )

    def direction_columns(self) -> np.ndarray:
        """The columns of ``[C | Q]``, shape (B, n, 2n): direction ``j`` moves the set
        along column ``j`` per unit of its parameter (``r0_j`` or ``r_{j-n}``)."""
        return np.concatenate([self.C, self.Q], axis=2)

    def subdivide_along(self, which: np.ndarray, pieces: int) -> "DoubletonSets":
        """Cut every set into ``pieces`` equal parts along one parameter direction.

        ``which[b]`` in ``[0, 2n)`` picks ``r0_j`` (``j < n``) or ``r_{j-n}`` of set ``b``.
        Returns ``B * pieces`` sets, set-major (the parts of set ``b`` are rows
        ``b * pieces .. (b + 1) * pieces - 1``). Each part is recentred: its shift
        moves into the float centre ``c`` and the rounding of that centre is enclosed
        and folded into the error vector (``r += Q^-1 d``). Consecutive parts share
        their float breakpoints, so the union of the parts covers the set exactly.
        """
        nb, n = self.c.shape
        which = np.asarray(which, dtype=np.int64).reshape(nb)
        pieces = int(pieces)
        if pieces < 1:
            raise ValueError(f"pieces must be >= 1, got {pieces}")
        if pieces == 1 or nb == 0:
            return self
        rows = np.arange(nb)
        in_r0 = which < n
        j = np.where(in_r0, which, which - n)
        lo = np.where(in_r0, self.r0.lo[rows, j], self.r.lo[rows, j])
        hi = np.where(in_r0, self.r0.hi[rows, j], self.r.hi[rows, j])
        frac = np.arange(pieces + 1) / pieces
        cuts = lo[:, None] + (hi - lo)[:, None] * frac[None, :]
        cuts[:, 0], cuts[:, -1] = lo, hi
        cuts = np.maximum.accumulate(np.minimum(cuts, hi[:, None]), axis=1)  # monotone despite rounding
        column = np.where(in_r0[:, None], self.C[rows, :, j], self.Q[rows, :, j])
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

    @staticmethod
    def concatenate(parts) -> "DoubletonSets":
        return DoubletonSets(
            c=np.concatenate([p.c for p in parts]),
            C=np.concatenate([p.C for p in parts]),
            r0=concatenate([p.r0 for p in parts], axis=0),
            Q=np.concatenate([p.Q for p in parts]),
            r=concatenate([p.r for p in parts], axis=0),
        )


def horner(coeffs: Interval, h) -> Interval:
    """``sum_i coeffs[:, i] * h^i`` along axis 1 (``h`` a float or an Interval such as [0, h])."""
    acc = coeffs[:, -1]
    for i in range(coeffs.shape[1] - 2, -1, -1):
        acc = acc * h + coeffs[:, i]
    return acc


def _inflate(x: Interval, factor=0.1, absolute=1e-14) -> Interval:
    r = x.rad() * factor + absolute * (1.0 + x.mag())
    return Interval._from_bounds(x.lo - r, x.hi + r)


class LohnerStepper:
    """Verified steps of order ``order`` for the ODE behind ``taylor`` (and its variational ODE)."""

    def __init__(self, taylor, variational, order: int, params=None, error_basis: str = "qr"):
        if error_basis not in ("qr", "auto"):
            raise ValueError(f"error_basis must be 'qr' or 'auto', got {error_basis!r}")
        self.error_basis = error_basis
        self.taylor = taylor
        self.variational = variational
        self.order = int(order)
        self.n = taylor.n
        self.params = params
        # an affine Jacobian evaluator can take the set's own forms (see step)
        self.jacobian_over_set = hasattr(variational, "series")

    # -------------------------------------------------------------- pieces
    def coefficients(self, x: Interval) -> Interval:
        return self.taylor.coefficients(x, self.order, self._params(x.shape[0]))

    def _params(self, nb):
        if self.params is None:
            return None
        p = self.params
        return p if p.ndim == 2 else p.broadcast_to((nb, p.shape[-1]))

    def apriori(self, X: Interval, cX: Interval, h: float, tries: int = 4):
        """Validated enclosure over [0, h] of all solutions from X, and its coefficients.

        Returns ``(E, cE)`` or ``None`` if the test fails (the caller shrinks ``h``).
        """
        K = self.order
        H = Interval(0.0, h)
        base = horner(cX[:, :K], H)
        HK = H**K
        guess = _inflate(base + HK * cX[:, K])
        for _ in range(tries):
            if not np.isfinite(guess.lo).all() or not np.isfinite(guess.hi).all():
                return None
            cE = self.coefficients(guess)
            new = base + HK * cE[:, K]
            if new.interior_subset(guess).all():
                return new, cE
            guess = _inflate(guess.hull(new), factor=0.5)
        return None

    def suggest_step(self, cX: Interval, tol: float, components: int | None = None) -> float:
        """Step size that makes the order-K term of every box about ``tol`` (x 0.9),
        judged on the first ``components`` states (default: all)."""
        mags = np.maximum(cX[:, self.order, :components].mag(), 1e-300)
        return float(0.9 * np.min((tol / mags) ** (1.0 / self.order)))

    def step(self, sets: DoubletonSets, h: float, X: Interval, E: Interval, cE: Interval):
        """Advance all sets by ``h`` given the hull ``X`` and its a-priori enclosure ``E``."""
        K = self.order
        n = self.n
        nb = sets.n_sets
        # 3. centre polynomial plus remainder
        cP = self.coefficients(point(sets.c))
        y = horner(cP[:, :K], h) + cE[:, K] * (Interval(h) ** K)
        # 4. Jacobian of the Taylor map over X. The mean value form needs it on every
        # segment from c to a point of the set; c lies in X whenever r0 and r contain
        # 0 (they do by construction), and the hull below makes that unconditional.
        if self.jacobian_over_set:
            # affine forms over the set's own parameters: the set (a parallelepiped
            # plus an error box, often flat in the state space) instead of its hull
            forms = sets.affine_forms(extra=n * n)
            forms[n:, :, 0] = np.eye(n).reshape(-1)[:, None]
            vc = self.variational.series(forms, K - 1, self._params(nb))
        else:
            Xc = X.hull(point(sets.c))
            v0 = point(np.broadcast_to(np.eye(n).reshape(-1), (nb, n * n)))
            vc = self.variational.coefficients(concatenate([Xc, v0], axis=1), K - 1, self._params(nb))
        V = vc[:, :, n:].reshape((nb, K, n, n))
        J = horner(V, h)
        # 5. doubleton update
        c_new = y.mid()
        s = y - c_new
        JC = linalg.matmul(J, sets.C)
        C_new = JC.mid()
        dC = JC - C_new
        JQ = linalg.matmul(J, sets.Q)
        nonlinear = linalg.matvec(dC, sets.r0)
        incoming = nonlinear + s
        # Lohner's ordering: by the error each column carries. Before any error has
        # accumulated (r = 0, the first step) use the error arriving now instead: the
        # column norms alone can put a parameter's column first and smear the error
        # across axes. (Adding the arriving error at every step was measured to be
        # much worse on long horizons: T = 3 ratio 7.2 instead of 1.23.)
        r_w = sets.r.width()
        arriving = np.einsum("bij,bi->bj", np.abs(sets.Q), incoming.width())
        carried = np.where((r_w.sum(axis=1) > 0)[:, None], r_w, arriving) + 1e-300
        Q_new = self._orthonormal_basis(JQ.mid(), carried)
        Q_inv = linalg.solve(Q_new[:, None, :, :], point(np.broadcast_to(np.eye(n), (nb, n, n))))  # rows: columns of inverse
        Q_inv = Q_inv.swapaxes(-1, -2)
        r_qr = linalg.matvec(linalg.matmul(Q_inv, JQ), sets.r) + linalg.matvec(Q_inv, incoming)
        Q_out, r_new = Q_new, r_qr
        if self.error_basis == "auto":
            # The QR basis can smear an error lying along a coordinate axis into the
            # other axes (for example into an uncertain parameter that never changes);
            # the plain box J Q r + incoming cannot. "auto" keeps, per set, whichever
            # encloses the error part more tightly now (both are valid enclosures).
            r_box = linalg.matvec(JQ, sets.r) + incoming
            use_box = r_box.width().sum(axis=1) <= linalg.matvec(Q_new, r_qr).width().sum(axis=1)
            Q_out = np.where(use_box[:, None, None], np.eye(n), Q_new)
            r_new = Interval._from_bounds(
                np.where(use_box[:, None], r_box.lo, r_qr.lo), np.where(use_box[:, None], r_box.hi, r_qr.hi)
            )
        self.last_nonlinear_width = nonlinear.width()  # (B, n): drives adaptive splitting
        return DoubletonSets(c=c_new, C=C_new, r0=sets.r0, Q=Q_out, r=r_new)

    @staticmethod
    def _orthonormal_basis(A: np.ndarray, widths: np.ndarray) -> np.ndarray:
        """Q of the QR factorization of A with columns sorted by |A_j| * widths_j (Lohner)."""
        size = np.linalg.norm(A, axis=1) * widths
        order = np.argsort(-size, axis=1, kind="stable")
        A_sorted = np.take_along_axis(A, order[:, None, :], axis=2)
        Q, _ = np.linalg.qr(A_sorted)
        return Q

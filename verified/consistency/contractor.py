# Whole: HC4's projections and the linear contractors share the guard and meet helpers.
"""Contractors: narrow boxes and parametrized sets with constraints, soundly.

Three tools, all batched over boxes (numpy arrays, one Python loop per graph node or per
component, never per box), every rounding outward:

* :class:`HC4` / :func:`hc4` -- forward-backward contraction (HC4-revise) of boxes
  against ``lo_j <= g_j(x) <= hi_j`` for any :class:`~verified.graph.Graph`.
* :func:`contract_linear_row` (with :func:`mean_value_row`) -- Gauss-Seidel on one
  linear row ``0 in g0 + sum_j a_j r_j + rem``: how the energy relation ``H(x) - h = 0``
  narrows the parameters ``r`` of a set ``x = c + A r`` (a QR-Lohner set, issue 13).
* :class:`EnergyShell` -- for ``H = qd^T M(q) qd / 2 + V(q)`` and a known bound
  ``H(x(t)) <= Hmax`` (conservative or dissipative systems; the paper's eq. (4), with
  ``H_V`` of eq. (12) giving ``Hmax``), contract boxes in ``(q, qd)`` to the shell.

Soundness contract: a point ``x`` of the input box that satisfies the constraints is in
the contracted box; a box is reported empty only if it holds no such point. "Satisfies"
uses the evaluator's semantics (IEEE 1788 style): a point where ``g`` is undefined
(``sqrt`` of a negative number, ``log`` of a non-positive one, division by 0) does not
satisfy. The contractor never needs that a projection be exact: where an inverse is
hard (periodic functions over many periods, tan across a pole) or an op is unknown
(e.g. ``MID``), the argument is left unchanged, which is always sound.

Rounding: projections use the outward-rounded operations of :mod:`verified.arith.interval`.
Where an inverse function has no rigorous interval version here (``asin``, ``acos``,
integer roots, ``tan`` of a branch), a float candidate is computed and *verified* by a
forward interval evaluation at that point before it is used; a candidate that cannot be
verified is discarded (no contraction), so the inverse's accuracy never matters for
soundness, only the forward functions' (the trust model of the whole library).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from verified.arith import interval as iv
from verified.arith import linalg
from verified.graph.evaluate import IntervalDomain, eval_interval, jacobian_interval
from verified.arith.exact import pi_multiple_enclosure
from verified.graph import Graph, GraphBuilder, Op
from verified.graph.ops import embed
from verified.arith.interval import Interval

__all__ = [
    "ContractResult",
    "HC4",
    "hc4",
    "contract_linear_row",
    "mean_value_row",
    "EnergyShell",
]

_INF = np.inf
# [float pi, next double]: float pi is below the true pi (3.14159265358979311... < 3.14159265358979323...)
_PI = Interval._from_bounds(*(np.array(t) for t in pi_multiple_enclosure(0, 1)[:2]))
# Candidate margins (relative) tried from tight to loose by the verified inverse cuts.
_MARGINS = (0.0, 2.0**-52, 2.0**-50, 2.0**-46, 2.0**-40, 2.0**-30, 2.0**-20, 2.0**-10)
_SHAVE_PIECES = 3  # monotone pieces a periodic projection walks in from each end


class ContractResult(NamedTuple):
    """``boxes``: Interval (B, n), each a subset of its input box (empty rows are
    ``[inf, -inf]``); ``empty``: bool (B,), True where the box is proven to hold no
    point that satisfies the constraints; ``iterations``: passes run."""

    boxes: Interval
    empty: np.ndarray
    iterations: int


# ----------------------------------------------------------------------------- helpers


def _I(lo, hi):
    return Interval._from_bounds(lo, hi)


def _guard(lo, hi):
    """A NaN bound means "no information" (it must never mean empty): -inf / +inf."""
    return np.where(np.isnan(lo), -_INF, lo), np.where(np.isnan(hi), _INF, hi)


def _meet(alo, ahi, blo, bhi):
    lo, hi = _guard(blo, bhi)
    return np.maximum(alo, lo), np.minimum(ahi, hi)


def _hull_pieces(pieces):
    """Hull of (lo, hi) pieces where empty pieces (lo > hi) are neutral."""
    lo = np.full(np.shape(pieces[0][0]), _INF)
    hi = np.full(np.shape(pieces[0][0]), -_INF)
    for pl, ph in pieces:
        ok = pl <= ph
        lo = np.where(ok, np.minimum(lo, pl), lo)
        hi = np.where(ok, np.maximum(hi, ph), hi)
    return lo, hi


def _point(c):
    return _I(c, c)


def _relational_div(zlo, zhi, ylo, yhi, xlo, xhi):
    """Project ``x * y = z`` onto ``x``: ``{x in X : exists y in Y, z in Z, x y = z}``
    (enclosure, met with X). With 0 in Y and 0 in Z nothing is known (y = 0 allows any
    x). Otherwise Y is split at 0 into at most two signed parts; each gives a (maybe
    half-unbounded) quotient ``Z / Y_part`` that is met with X separately, so the gap
    between two rays is kept (e.g. ``x y = 1, y in [-1, 1], x in [0.5, 3]`` gives
    ``x in [1, 3]``)."""
    both_zero = (zlo <= 0) & (0 <= zhi) & (ylo <= 0) & (0 <= yhi)
    Z = _I(zlo, zhi)
    with np.errstate(all="ignore"):
        neg_hi = np.minimum(yhi, 0.0)
        pos_lo = np.maximum(ylo, 0.0)
        has_neg = ylo < 0
        has_pos = yhi > 0
        # Y = [0, 0] exactly: x * 0 = z needs z = 0 (handled by both_zero); else empty
        q1 = Z / _I(np.where(has_neg, ylo, 1.0), np.where(has_neg, neg_hi, 1.0))
        q2 = Z / _I(np.where(has_pos, pos_lo, 1.0), np.where(has_pos, yhi, 1.0))
    l1, h1 = _meet(xlo, xhi, q1.lo, q1.hi)
    l2, h2 = _meet(xlo, xhi, q2.lo, q2.hi)
    l1 = np.where(has_neg, l1, _INF)
    h1 = np.where(has_neg, h1, -_INF)
    l2 = np.where(has_pos, l2, _INF)
    h2 = np.where(has_pos, h2, -_INF)
    lo, hi = _hull_pieces([(l1, h1), (l2, h2)])
    return np.where(both_zero, xlo, lo), np.where(both_zero, xhi, hi)


def _mono_cut(a, b, zlo, zhi, fn, inc, inv_zlo, inv_zhi):
    """Verified narrowing of a piece ``[a, b]`` on which ``fn`` is monotone
    (increasing where ``inc``, else decreasing), under ``zlo <= fn(x) <= zhi``.

    ``inv_zlo`` / ``inv_zhi``: float guesses of ``fn^-1(zlo)`` and ``fn^-1(zhi)`` on
    this piece (any value, even NaN, is sound). The lower end moves towards the guess
    for ``zlo`` where ``fn`` increases and for ``zhi`` where it decreases. A guess ``c`` is used only if the interval value ``fn([c, c])`` certainly
    violates the constraint on the side being cut: then every point of ``[a, c]``
    (resp. ``[c, b]``) violates it too by monotonicity, and the end moves to ``c``
    (not to the float after ``c``: the variable is real, and a true value, e.g. of an
    intermediate node, may lie strictly between ``c`` and the next float). Only where
    the verified ``c`` is the far end of the piece is the whole piece inconsistent. Guesses are clipped to ``[a, b]`` and tried with outward margins from
    tight to loose. Returns ``(lo, hi)``; ``lo > hi`` where the whole piece violates.
    """
    inv_low = np.where(inc, inv_zlo, inv_zhi)
    inv_high = np.where(inc, inv_zhi, inv_zlo)
    new_a = a.copy()
    new_b = b.copy()
    done_a = ~(a <= b)
    done_b = done_a.copy()
    with np.errstate(all="ignore"):
        # margins relative to the guess and to the piece's width (for guesses near 0)
        w = np.where(np.isfinite(b - a), np.minimum(b - a, 1.0), 1.0)
        for m in _MARGINS:
            if done_a.all() and done_b.all():
                break
            ca = np.clip(inv_low - ((np.abs(inv_low) + w) * m + (5e-324 if m else 0.0)), a, b)
            fa = fn(_point(np.where(np.isfinite(ca), ca, 0.0)))
            ok = ~done_a & np.isfinite(ca) & np.where(inc, fa.hi < zlo, fa.lo > zhi)
            new_a = np.where(ok, np.where(ca >= b, np.nextafter(b, _INF), ca), new_a)
            done_a |= ok
            cb = np.clip(inv_high + ((np.abs(inv_high) + w) * m + (5e-324 if m else 0.0)), a, b)
            fb = fn(_point(np.where(np.isfinite(cb), cb, 0.0)))
            ok = ~done_b & np.isfinite(cb) & np.where(inc, fb.lo > zhi, fb.hi < zlo)
            new_b = np.where(ok, np.where(cb <= a, np.nextafter(a, -_INF), cb), new_b)
            done_b |= ok
    return new_a, new_b


def _root_guess(z, k):
    """Float guess of the real k-th root (signed for odd k; of max(z, 0) for even k)."""
    with np.errstate(all="ignore"):
        if k % 2:
            return np.sign(z) * np.abs(z) ** (1.0 / k)
        return np.maximum(z, 0.0) ** (1.0 / k)


def _project_pow(xlo, xhi, zlo, zhi, k):
    """``z = x**k`` onto x (k >= 3): verified roots, two monotone pieces for even k."""
    fn = lambda t: iv.ipow(t, k)  # noqa: E731
    if k % 2:  # increasing everywhere
        return _mono_cut(xlo, xhi, zlo, zhi, fn, np.ones_like(xlo, bool),
                         _root_guess(zlo, k), _root_guess(zhi, k))
    # x <= 0: decreasing; x >= 0: increasing
    nlo, nhi = _mono_cut(xlo, np.minimum(xhi, 0.0), zlo, zhi, fn, np.zeros_like(xlo, bool),
                         -_root_guess(zlo, k), -_root_guess(zhi, k))
    plo, phi = _mono_cut(np.maximum(xlo, 0.0), xhi, zlo, zhi, fn, np.ones_like(xlo, bool),
                         _root_guess(zlo, k), _root_guess(zhi, k))
    return _hull_pieces([(nlo, nhi), (plo, phi)])


# Periodic ops. Their "critical points" (extrema of sin / cos, poles of tan) lie at
# c_k = (k + s) pi; on branch k, between c_{k-1} and c_k, the function is monotone and
# has a float-computable inverse around the branch centre (k - 1/2 + s) pi.
def _sin_inverse(k, zt):
    centre = (k - 0.5 + 0.5) * np.pi
    with np.errstate(all="ignore"):
        return centre + np.where(k % 2 == 0, 1.0, -1.0) * np.arcsin(np.clip(zt, -1.0, 1.0))


def _cos_inverse(k, zt):
    centre = (k - 0.5) * np.pi
    with np.errstate(all="ignore"):
        return centre + np.where(k % 2 == 0, 1.0, -1.0) * np.arcsin(np.clip(zt, -1.0, 1.0))


def _tan_inverse(k, zt):
    with np.errstate(all="ignore"):
        return k * np.pi + np.arctan(zt)


_PERIODIC = {
    # op: (forward, s, increasing on branch k?, inverse guess)
    Op.SIN: (iv.sin, 0.5, lambda k: k % 2 == 0, _sin_inverse),
    Op.COS: (iv.cos, 0.0, lambda k: k % 2 == 0, _cos_inverse),
    Op.TAN: (iv.tan, 0.5, lambda k: np.ones_like(k, bool), _tan_inverse),
}


def _crit(k, s):
    """Enclosure of ``(k + s) pi`` (k + s exact in floats for |k| < 2**50)."""
    return _I(np.asarray(k + s, float), np.asarray(k + s, float)) * _PI


def _project_periodic(op, xlo, xhi, zlo, zhi):
    """``z = f(x)`` for f in sin, cos, tan onto x: shave each end of X through at most
    ``_SHAVE_PIECES`` monotone pieces (a piece wholly inconsistent is skipped together
    with the critical point after it, if f there misses Z too). Elements whose bounds
    are infinite or beyond 2**50 are left unchanged."""
    fn, s, inc_of, inverse = _PERIODIC[op]
    Z = _I(zlo, zhi)
    ok0 = np.isfinite(xlo) & np.isfinite(xhi) & (np.abs(xlo) < 2.0**50) & (np.abs(xhi) < 2.0**50) & (xlo <= xhi)
    xl = np.where(ok0, xlo, 0.0)
    xh = np.where(ok0, xhi, 0.0)
    # ---- from below
    new_lo = xl.copy()
    active = ok0.copy()
    cur = xl.copy()
    with np.errstate(all="ignore"):
        k = np.ceil(xl / np.pi - s)
    k = np.where(active, k, 0.0)
    prev = _crit(k - 1, s)
    active &= prev.hi < cur  # branch k really starts below cur
    for _ in range(_SHAVE_PIECES):
        if not active.any():
            break
        C = _crit(k, s)
        end = np.minimum(C.lo, xh)
        a, b = _mono_cut(cur, end, zlo, zhi, fn, inc_of(k), inverse(k, zlo), inverse(k, zhi))
        cut_lo = a  # _mono_cut's lower end is the one that moved up from cur
        found = active & (cut_lo <= end)
        new_lo = np.where(found, cut_lo, new_lo)
        active &= ~found
        # whole piece inconsistent: past it lies the critical point C
        whole = active & (end >= xh)  # the piece reached the top of X: X is empty
        new_lo = np.where(whole, np.nextafter(xh, _INF), new_lo)
        active &= ~whole
        mid_hi = np.minimum(C.hi, xh)
        fm = fn(_I(np.where(active, C.lo, 0.0), np.where(active, np.maximum(mid_hi, C.lo), 0.0)))
        hit = active & fm.overlaps(Z)
        new_lo = np.where(hit, C.lo, new_lo)
        active &= ~hit
        # [.., mid_hi] is inconsistent; reals above mid_hi may not be (no nextafter)
        gone = active & (mid_hi >= xh)
        new_lo = np.where(gone, np.nextafter(xh, _INF), new_lo)
        cur = np.where(active, mid_hi, cur)
        active &= ~gone
        new_lo = np.where(active, cur, new_lo)  # everything below cur is inconsistent
        k = k + 1
    # ---- from above
    new_hi = xh.copy()
    active = ok0 & (new_lo <= xh)
    cur = xh.copy()
    with np.errstate(all="ignore"):
        k = np.floor(xh / np.pi - s)  # c_k at or below cur: the top piece is branch k + 1
    k = np.where(active, k, 0.0)
    nxt = _crit(k + 1, s)
    active &= nxt.lo > cur
    for _ in range(_SHAVE_PIECES):
        if not active.any():
            break
        C = _crit(k, s)
        start = np.maximum(C.hi, xl)
        a, b = _mono_cut(start, cur, zlo, zhi, fn, inc_of(k + 1), inverse(k + 1, zlo), inverse(k + 1, zhi))
        found = active & (b >= start)
        new_hi = np.where(found, b, new_hi)
        active &= ~found
        whole = active & (start <= xl)
        new_hi = np.where(whole, np.nextafter(xl, -_INF), new_hi)
        active &= ~whole
        mid_lo = np.maximum(C.lo, xl)
        fm = fn(_I(np.where(active, np.minimum(mid_lo, C.hi), 0.0), np.where(active, C.hi, 0.0)))
        hit = active & fm.overlaps(Z)
        new_hi = np.where(hit, C.hi, new_hi)
        active &= ~hit
        gone = active & (mid_lo <= xl)
        new_hi = np.where(gone, np.nextafter(xl, -_INF), new_hi)
        cur = np.where(active, mid_lo, cur)
        active &= ~gone
        new_hi = np.where(active, cur, new_hi)
        k = k - 1
    lo = np.where(ok0, np.maximum(new_lo, xlo), xlo)
    hi = np.where(ok0, np.minimum(new_hi, xhi), xhi)
    return lo, hi


def _project_atan(xlo, xhi, zlo, zhi):
    """``z = atan(x)``: increasing everywhere; guesses are ``tan`` of the bounds inside
    (-pi/2, pi/2) (outside it the guess is +-inf and no cut is made on that side)."""
    half = 1.5707963267948966
    with np.errstate(all="ignore"):
        glo = np.where(zlo > -half, np.tan(np.clip(zlo, -half, half)), -_INF)
        ghi = np.where(zhi < half, np.tan(np.clip(zhi, -half, half)), _INF)
    return _mono_cut(xlo, xhi, zlo, zhi, iv.atan, np.ones_like(xlo, bool), glo, ghi)


# ----------------------------------------------------------------------------- HC4


class HC4:
    """Forward-backward (HC4-revise) contractor for one graph.

    ``HC4(graph).contract(boxes, lo, hi, params)`` narrows each box to a sub-box that
    still holds every point ``x`` of it with ``lo_j <= g_j(x, p) <= hi_j`` for all
    outputs ``j`` and some ``p`` in ``params``.

    One pass: (1) forward, every node's interval value over the box (the same
    outward-rounded operations as :class:`~verified.graph.evaluate.IntervalDomain`); (2) each
    constrained output's value is met with ``[lo_j, hi_j]``; (3) backward, nodes in
    reverse topological order project their (narrowed) value onto their arguments
    (inverse operations, outward rounded) and meet. Reverse order means every user of a
    node has projected onto it before the node projects further, so a node used several
    times carries the intersection of all its projections. Any empty meet proves the box
    empty. Parameters are only evaluated, never narrowed.
    """

    def __init__(self, graph: Graph):
        self.graph = graph
        self._domain = IntervalDomain()
        self.n_inputs = graph.n_inputs
        self.n_params = graph.n_params

    def _needed(self, constrained):
        need = np.zeros(len(self.graph.nodes), bool)
        for j, o in enumerate(self.graph.outputs):
            if constrained[j]:
                need[o] = True
        for i in range(len(self.graph.nodes) - 1, -1, -1):
            if need[i]:
                for a in self.graph.nodes[i].args:
                    need[a] = True
        return need

    # -- one pass over a batch of rows
    def _pass(self, xlo, xhi, plo, phi, clo, chi, need):
        """Arrays: x (B, n), p (B, p), c (B, m) -> (x'lo, x'hi (B, n), dead (B,))."""
        B = xlo.shape[0]
        nodes = self.graph.nodes
        dom = self._domain
        lo: list = [None] * len(nodes)
        hi: list = [None] * len(nodes)
        shape = (B,)
        with np.errstate(all="ignore"):
            for i, (op, args, data) in enumerate(nodes):
                if op == Op.CONST:
                    l, h = np.full(shape, data[0]), np.full(shape, data[1])
                elif op == Op.INPUT:
                    l, h = xlo[:, data], xhi[:, data]
                elif op == Op.PARAM:
                    l, h = plo[:, data], phi[:, data]
                else:
                    vals = [_I(lo[a], hi[a]) for a in args]
                    fn = getattr(dom, op.name.lower(), None)
                    try:
                        v = None if fn is None else (fn(vals[0], data) if op == Op.POW else fn(*vals))
                    except Exception:  # an evaluator the contractor does not know: no information
                        v = None
                    if v is None:
                        l, h = np.full(shape, -_INF), np.full(shape, _INF)
                    else:
                        l, h = _guard(*np.broadcast_arrays(np.asarray(v.lo, float), np.asarray(v.hi, float)))
                        l = np.broadcast_to(l, shape)
                        h = np.broadcast_to(h, shape)
                lo[i], hi[i] = l, h
            dead = np.zeros(B, bool)
            for j, o in enumerate(self.graph.outputs):
                lo[o], hi[o] = _meet(lo[o], hi[o], clo[:, j], chi[:, j])
            for i in range(len(nodes) - 1, -1, -1):
                if not need[i]:
                    continue
                op, args, data = nodes[i]
                zl, zh = lo[i], hi[i]
                dead |= ~(zl <= zh)
                if op in (Op.CONST, Op.INPUT, Op.PARAM) or not args:
                    continue
                self._backward(op, args, data, zl, zh, lo, hi)
            # inputs: meet of all INPUT nodes for each index (hash-consing makes one)
            nlo, nhi = xlo.copy(), xhi.copy()
            for i, (op, args, data) in enumerate(nodes):
                if op == Op.INPUT and need[i]:
                    nlo[:, data], nhi[:, data] = _meet(nlo[:, data], nhi[:, data], lo[i], hi[i])
            dead |= ~(nlo <= nhi).all(axis=1)
        return nlo, nhi, dead

    def _backward(self, op, args, data, zl, zh, lo, hi):
        """Project node value [zl, zh] onto the arguments, meeting into lo/hi in place."""
        Z = _I(zl, zh)
        a = args[0]
        if op == Op.ADD:  # z = x + y
            b = args[1]
            p = Z - _I(lo[b], hi[b])
            lo[a], hi[a] = _meet(lo[a], hi[a], p.lo, p.hi)
            p = Z - _I(lo[a], hi[a])
            lo[b], hi[b] = _meet(lo[b], hi[b], p.lo, p.hi)
        elif op == Op.SUB:  # z = x - y: x = z + y, y = x - z
            b = args[1]
            p = Z + _I(lo[b], hi[b])
            lo[a], hi[a] = _meet(lo[a], hi[a], p.lo, p.hi)
            p = _I(lo[a], hi[a]) - Z
            lo[b], hi[b] = _meet(lo[b], hi[b], p.lo, p.hi)
        elif op == Op.MUL:  # z = x y
            b = args[1]
            if a == b:  # x * x (the builder makes sqr, but a hand-built graph may not)
                self._backward(Op.SQR, (a,), None, zl, zh, lo, hi)
                return
            lo[a], hi[a] = _relational_div(zl, zh, lo[b], hi[b], lo[a], hi[a])
            lo[b], hi[b] = _relational_div(zl, zh, lo[a], hi[a], lo[b], hi[b])
        elif op == Op.DIV:  # z = x / y (y != 0): x = z y, and y x... y z = x
            b = args[1]
            p = Z * _I(lo[b], hi[b])
            lo[a], hi[a] = _meet(lo[a], hi[a], p.lo, p.hi)
            if a != b:
                lo[b], hi[b] = _relational_div(lo[a], hi[a], zl, zh, lo[b], hi[b])
        elif op == Op.NEG:
            lo[a], hi[a] = _meet(lo[a], hi[a], -zh, -zl)
        elif op == Op.SQR:  # |x| = sqrt(z), z >= 0
            s = iv.sqrt(_I(np.maximum(zl, 0.0), zh))  # empty where zh < 0
            pl, ph = _meet(lo[a], hi[a], s.lo, s.hi)
            nl, nh = _meet(lo[a], hi[a], -s.hi, -s.lo)
            lo[a], hi[a] = _hull_pieces([(pl, ph), (nl, nh)])
        elif op == Op.POW:
            lo[a], hi[a] = _project_pow(lo[a], hi[a], zl, zh, int(data))
        elif op == Op.SQRT:  # x = z^2, z >= 0
            p = iv.sqr(_I(np.maximum(zl, 0.0), zh))
            lo[a], hi[a] = _meet(lo[a], hi[a], p.lo, p.hi)
        elif op == Op.EXP:  # x = log(z), z > 0 (log is empty for zh <= 0)
            p = iv.log(Z)
            lo[a], hi[a] = _meet(lo[a], hi[a], p.lo, p.hi)
        elif op == Op.LOG:  # x = exp(z)
            p = iv.exp(Z)
            lo[a], hi[a] = _meet(lo[a], hi[a], p.lo, p.hi)
        elif op in _PERIODIC:
            lo[a], hi[a] = _project_periodic(op, lo[a], hi[a], zl, zh)
        elif op == Op.ATAN:
            lo[a], hi[a] = _project_atan(lo[a], hi[a], zl, zh)
        # any other op (MID, future ops): no contraction, which is always sound

    def contract(self, boxes, lo=None, hi=None, params=None, *, max_iter: int = 1,
                 tol: float = 1e-3) -> ContractResult:
        """Contract ``boxes`` under ``lo <= g(x, p) <= hi``.

        Args:
            boxes: Interval (B, n) (or (n,) for one box), ``n = graph.n_inputs``.
            lo, hi: float bounds on the outputs, shape (m,) or (B, m); ``None`` or
                ``-inf`` / ``inf`` entries leave that side free (exact floats: pass
                ``Hmax.hi`` for an interval bound).
            params: Interval or floats of shape (p,) or (B, p); not narrowed.
            max_iter: passes at most (each pass: forward, backward).
            tol: a box is passed again only while some component's width shrank by
                more than ``tol`` times its previous width.

        Returns: :class:`ContractResult` (boxes (B, n), empty (B,), iterations).
        """
        boxes = boxes if isinstance(boxes, Interval) else Interval(boxes)
        single = boxes.ndim == 1
        if single:
            boxes = boxes.reshape(1, -1)
        B, n = boxes.shape
        if n != self.n_inputs:
            raise ValueError(f"boxes must have {self.n_inputs} components, got {n}")
        m = self.graph.n_outputs
        clo = np.broadcast_to(np.asarray(-_INF if lo is None else lo, float), (B, m)).copy()
        chi = np.broadcast_to(np.asarray(_INF if hi is None else hi, float), (B, m)).copy()
        clo = np.where(np.isnan(clo), -_INF, clo)
        chi = np.where(np.isnan(chi), _INF, chi)
        if params is None:
            if self.n_params:
                raise ValueError(f"the graph has {self.n_params} parameters; pass params")
            plo = phi = np.zeros((B, 0))
        else:
            P = params if isinstance(params, Interval) else Interval(params)
            plo = np.broadcast_to(P.lo, (B, self.n_params))
            phi = np.broadcast_to(P.hi, (B, self.n_params))
        need = self._needed(np.isfinite(clo).any(0) | np.isfinite(chi).any(0))
        xlo, xhi = boxes.lo.astype(float).copy(), boxes.hi.astype(float).copy()
        dead = ~(xlo <= xhi).all(axis=1)
        rows = np.flatnonzero(~dead)
        it = 0
        for it in range(1, max(1, int(max_iter)) + 1):
            if rows.size == 0:
                it -= 1
                break
            ol, oh = xlo[rows], xhi[rows]
            nl, nh, d = self._pass(ol, oh, plo[rows], phi[rows], clo[rows], chi[rows], need)
            # the meets only shrink; keep the input box as a hard bound anyway
            nl = np.maximum(nl, ol)
            nh = np.minimum(nh, oh)
            xlo[rows], xhi[rows] = nl, nh
            dead[rows] |= d
            with np.errstate(all="ignore"):
                w_old = oh - ol
                w_new = np.where(nh >= nl, nh - nl, 0.0)
                shrunk = ((w_old - w_new) > tol * w_old) | ((w_old == _INF) & (w_new < _INF))
            go = ~d & shrunk.any(axis=1)
            rows = rows[go]
        xlo[dead] = _INF
        xhi[dead] = -_INF
        out = _I(xlo, xhi)
        if single:
            out = out.reshape(-1)
        return ContractResult(out, dead if not single else dead.reshape(1), it)


def hc4(graph: Graph, boxes, lo=None, hi=None, params=None, *, max_iter: int = 1,
        tol: float = 1e-3) -> ContractResult:
    """One-shot :meth:`HC4.contract` (build an :class:`HC4` once to reuse it)."""
    return HC4(graph).contract(boxes, lo, hi, params, max_iter=max_iter, tol=tol)


# ----------------------------------------------------------------------------- linear row


def contract_linear_row(a, g0, r, rem=0.0, *, which=None, sweeps: int = 1):
    """Gauss-Seidel on one linear row: narrow ``r`` under ``0 in g0 + sum_j a_j r_j + rem``.

    For component ``i``: ``a_i r_i in -g0 - rem - sum_{j != i} a_j r_j`` (the sum with
    the components already narrowed in this sweep), and ``r_i`` is met with the
    relational quotient (a coefficient containing 0 keeps the gap between two rays, or
    gives nothing when the right side holds 0 too). Cost O(m^2) per set.

    Args:
        a: coefficients, float array or Interval, shape (B, m) or (m,).
        g0: Interval or float, shape (B,) or (): e.g. ``G(c) = H(c) - h``.
        r: Interval (B, m): the parameter box of each set.
        rem: Interval or float, shape (B,) or (): everything else (the mean-value
            remainder); a bound that must hold for the true ``r``.
        which: optional bool (m,): narrow only these components (others are used).
        sweeps: Gauss-Seidel sweeps over the components.

    Returns: ``(r_new, empty)``: Interval (B, m) with ``r_new ⊆ r``, and bool (B,)
    where no ``r`` in the box satisfies the row (then ``r_new`` rows are empty).
    """
    r = r if isinstance(r, Interval) else Interval(r)
    B, m = r.shape
    A = a if isinstance(a, Interval) else Interval(np.asarray(a, float))
    alo = np.broadcast_to(A.lo, (B, m))
    ahi = np.broadcast_to(A.hi, (B, m))
    G = (g0 if isinstance(g0, Interval) else Interval(np.asarray(g0, float))) + rem
    rhs = -G  # sum_j a_j r_j in rhs
    rhs_lo = np.broadcast_to(rhs.lo, (B,))
    rhs_hi = np.broadcast_to(rhs.hi, (B,))
    which = np.ones(m, bool) if which is None else np.asarray(which, bool)
    rlo, rhi = r.lo.copy(), r.hi.copy()
    with np.errstate(all="ignore"):
        terms = _I(alo, ahi) * _I(rlo, rhi)  # (B, m)
        tlo, thi = terms.lo.copy(), terms.hi.copy()
        for _ in range(max(1, int(sweeps))):
            for i in range(m):
                if not which[i]:
                    continue
                others = np.delete(np.arange(m), i)
                if others.size:
                    s = _I(tlo[:, others], thi[:, others]).sum(axis=-1)
                    t = _I(rhs_lo, rhs_hi) - s
                else:
                    t = _I(rhs_lo, rhs_hi)
                rlo[:, i], rhi[:, i] = _relational_div(t.lo, t.hi, alo[:, i], ahi[:, i], rlo[:, i], rhi[:, i])
                ti = _I(alo[:, i], ahi[:, i]) * _I(rlo[:, i], rhi[:, i])
                tlo[:, i], thi[:, i] = ti.lo, ti.hi
        # the row itself must be consistent with the (narrowed) box
        total = _I(tlo, thi).sum(axis=-1)
    empty = ~(rlo <= rhi).all(axis=1) | ~total.overlaps(_I(rhs_lo, rhs_hi))
    rlo = np.maximum(rlo, r.lo)
    rhi = np.minimum(rhi, r.hi)
    rlo[empty] = _INF
    rhi[empty] = -_INF
    return _I(rlo, rhi), empty


def mean_value_row(graph: Graph, c, A, R, h=0.0, params=None, *, output: int = 0):
    """Mean-value form of ``G(x) = g(x) - h`` over the set ``x = c + A r, r in R``.

    ``g(c + A r) - h in (g(c) - h) + sum_j a_j r_j + rem`` for every ``r`` in ``R`` with
    ``a = mid(grad g(X)) A`` (floats) and ``rem = sum_j ((grad g(X) A)_j - a_j) r_j``
    (intervals), where ``X = c + A hull(R, 0)`` holds every segment from ``c`` into the
    set (the mean value theorem needs it). Feed the result to
    :func:`contract_linear_row`: ``contract_linear_row(a, g0, R, rem)``.

    Args:
        graph: ``g`` with ``n`` inputs; output ``output`` is used.
        c: float (B, n) or thin Interval (B, n): the set's centre.
        A: float (B, n, m) or (n, m), or Interval (B, n, m): then the set is every
            ``c + A' r`` with ``A'`` a point matrix of ``A`` (which may depend on ``r``).
        R: Interval (B, m).
        h: Interval or float, shape (B,) or (): the level (e.g. the ``H_V`` enclosure).
        params: as for :meth:`HC4.contract`.

    Returns: ``(a (B, m) float, g0 Interval (B,), rem Interval (B,))``.
    """
    R = R if isinstance(R, Interval) else Interval(R)
    B, m = R.shape
    Cc = c if isinstance(c, Interval) else Interval(np.asarray(c, float))
    n = Cc.shape[-1]
    if isinstance(A, Interval):
        # columns known only as intervals (second-order sets: C + S r0): X still holds
        # every segment from c, as x - c = A_point (r) for some point matrix in A
        A = A.broadcast_to((B, n, m))
    else:
        A = np.broadcast_to(np.asarray(A, float), (B, n, m))
    R0 = R.hull(0.0)
    X = linalg.matvec(A, R0) + Cc  # (B, n)
    p = params
    gc = eval_interval(graph, Cc.broadcast_to((B, n)), p)[..., output]
    hI = h if isinstance(h, Interval) else Interval(np.asarray(h, float))
    g0 = gc - hI
    J = jacobian_interval(graph, X, p)[..., output, :]  # (B, n)
    DA = linalg.matmul(J.reshape(B, 1, n), A).reshape(B, m)  # interval (B, m)
    a = DA.mid()
    rem = ((DA - a) * R).sum(axis=-1)
    return a, g0, rem


# ----------------------------------------------------------------------------- energy shell


class EnergyShell:
    """Contract boxes in ``(q, qd)`` to the energy shell ``hmin <= T + V <= hmax``.

    ``T(q, qd) = qd^T M(q) qd / 2`` (eq. (4) with the kinetic energy of eq. (13)), ``V``
    the potential energy. For a conservative or dissipative system ``H(x(t)) <= Hmax``
    for all ``t`` (``Hmax`` = the upper end of the ``H_V`` enclosure, eq. (12)), so every
    true state lies in the shell and the enclosure may be held inside it.

    Two contractions, alternated ``rounds`` times:

    1. HC4 on the graph ``[T + V, T]`` with ``hmin <= T + V <= hmax`` and ``T >= 0``
       (``M`` positive semidefinite: the second output lets the backward pass use
       ``V <= hmax - T <= hmax`` even where the interval value of the quadratic form
       dips below 0).
    2. The exact per-component bound of the ellipsoid: for fixed ``q``,
       ``min {qd^T M qd : qd_i = v} = v^2 / (M^-1)_ii``, so
       ``qd_i^2 <= 2 (hmax - V(q)) (M(q)^-1)_ii``; over the box
       ``|qd_i| <= sqrt(2 (hmax - min V(Q)) max (M^-1)_ii(Q))``, with ``M^-1``
       enclosed by an interval linear solve of the symmetric part of ``M(Q)``.

    Requires ``M(q)`` symmetric positive definite for every ``q`` of the boxes (a
    mechanical mass matrix); the solve gives no bound where it cannot verify ``M(Q)``.

    Args:
        M: Graph ``q -> n_q * n_q`` entries of ``M(q)`` (row-major), ``n_q`` inputs.
        V: Graph ``q -> [V]``, ``n_q`` inputs (same parameters as ``M``, if any).
    """

    def __init__(self, M: Graph, V: Graph):
        nq = V.n_inputs
        if M.n_inputs != nq or M.n_outputs != nq * nq or V.n_outputs != 1:
            raise ValueError(f"EnergyShell needs M: q -> {nq}x{nq} entries and V: q -> [V] "
                             f"with {nq} inputs; got M {M.n_inputs} -> {M.n_outputs}, "
                             f"V {V.n_inputs} -> {V.n_outputs}")
        if M.n_params != V.n_params:
            raise ValueError("M and V must take the same parameters")
        self.nq = nq
        self.M_graph, self.V_graph = M, V
        b = GraphBuilder(2 * nq, M.n_params,
                         input_names=[f"q{i + 1}" for i in range(nq)] + [f"qd{i + 1}" for i in range(nq)],
                         param_names=M.param_names)
        q = [b.input(i) for i in range(nq)]
        qd = [b.input(nq + i) for i in range(nq)]
        p = [b.param(i) for i in range(M.n_params)]
        Mij = embed(b, M, q, p)
        (v,) = embed(b, V, q, p)
        # 2 T = sum_i M_ii qd_i^2 + sum_{i<j} (M_ij + M_ji) qd_i qd_j (exact for any M)
        terms = []
        for i in range(nq):
            terms.append(b.mul(Mij[i * nq + i], b.sqr(qd[i])))
            for j in range(i + 1, nq):
                terms.append(b.mul(b.add(Mij[i * nq + j], Mij[j * nq + i]), b.mul(qd[i], qd[j])))
        two_t = terms[0]
        for t in terms[1:]:
            two_t = b.add(two_t, t)
        T = b.mul(b.const(0.5), two_t)
        self.graph = b.build([b.add(T, v), T], ["H", "T"])
        self._hc4 = HC4(self.graph)

    def ellipsoid_bound(self, boxes: Interval, hmax, params=None, *, pieces: int = 256):
        """Upper bound of ``|qd_i|`` over the shell part of each box: float (B, n_q)
        (``inf`` where it cannot be verified; ``-1`` where ``V(q) > hmax`` on the whole
        box, i.e. no state of the box is in the shell).

        The ``q`` part of each box is cut into a grid of at most ``pieces`` sub-boxes
        (the same number of cuts per component) and the bound is the largest over them:
        the interval solve with ``M(Q)`` loses the correlation between the entries of
        ``M`` over a wide ``Q`` (for the double pendulum over ``q2 in [-pi, pi]`` it
        cannot prove ``M(Q)`` regular), over small pieces it can.
        """
        nq = self.nq
        B = boxes.shape[0]
        k = max(1, int(np.floor(pieces ** (1.0 / nq) + 1e-9)))
        qlo, qhi = boxes.lo[:, :nq], boxes.hi[:, :nq]
        finite = (np.isfinite(qlo) & np.isfinite(qhi) & (qlo <= qhi)).all(axis=1)
        # rows with an unbounded (or empty) q get a stand-in box and no bound below
        Qall = _I(np.where(finite[:, None], qlo, 0.0), np.where(finite[:, None], qhi, 0.0)).subdivide(k)
        P = Qall.shape[1]
        Q = Qall.reshape(B * P, nq)
        BP = B * P
        hm = np.repeat(np.broadcast_to(np.asarray(hmax, float), (B,)), P)
        prm = params
        if params is not None:
            Pi = params if isinstance(params, Interval) else Interval(params)
            if Pi.ndim == 2:
                prm = Interval._from_bounds(np.repeat(Pi.lo, P, axis=0), np.repeat(Pi.hi, P, axis=0))
        Mq = eval_interval(self.M_graph, Q, prm).reshape(BP, nq, nq)
        Ms = (Mq + Mq.swapaxes(-1, -2)) * 0.5
        Vq = eval_interval(self.V_graph, Q, prm)[..., 0]
        slack = _I(hm, hm) - Vq  # hmax - V(q) over each piece
        with np.errstate(all="ignore"):
            dhi = linalg.inverse_diagonal(Ms).hi  # (BP, nq): max of (M^-1)_ii
            s_hi = slack.hi
            sp = np.maximum(s_hi, 0.0)[:, None]
            dp = np.maximum(dhi, 0.0)
            bound = iv.sqrt(_I(sp, sp) * _I(dp, dp) * 2.0).hi
        ok = np.isfinite(dhi) & (dhi > 0) & np.isfinite(bound)
        bound = np.where(ok, bound, _INF)
        # a piece where V > hmax everywhere holds no state of the shell: it adds nothing
        bound = np.where((s_hi < 0)[:, None], -1.0, bound)
        bound = bound.reshape(B, P, nq).max(axis=1)
        return np.where(finite[:, None], bound, _INF)

    def contract(self, boxes, hmax, hmin=None, params=None, *, rounds: int = 2,
                 max_iter: int = 2, tol: float = 1e-3, pieces: int = 256) -> ContractResult:
        """Contract ``boxes`` (Interval (B, 2 n_q), columns ``q`` then ``qd``) to the
        shell ``hmin <= H <= hmax`` (floats or arrays of shape (B,); an interval level
        passes its ``.hi`` / ``.lo``). ``rounds`` alternations of the ellipsoid bound
        (over ``pieces`` sub-boxes of ``q``) and HC4 (``max_iter``, ``tol``).
        Returns :class:`ContractResult`."""
        boxes = boxes if isinstance(boxes, Interval) else Interval(boxes)
        single = boxes.ndim == 1
        if single:
            boxes = boxes.reshape(1, -1)
        B, n = boxes.shape
        nq = self.nq
        if n != 2 * nq:
            raise ValueError(f"boxes must have {2 * nq} components (q, qd), got {n}")
        hmax = np.broadcast_to(np.asarray(hmax, float), (B,))
        hmin = np.broadcast_to(np.asarray(-_INF if hmin is None else hmin, float), (B,))
        lo = np.stack([hmin, np.zeros(B)], axis=1)
        hi = np.stack([hmax, np.full(B, _INF)], axis=1)
        xlo, xhi = boxes.lo.copy(), boxes.hi.copy()
        dead = ~(xlo <= xhi).all(axis=1)
        its = 0
        for _ in range(max(1, int(rounds))):
            live = np.flatnonzero(~dead)
            if live.size == 0:
                break
            cur = _I(xlo[live], xhi[live])
            bnd = self.ellipsoid_bound(cur, hmax[live], params, pieces=pieces)
            l = np.maximum(xlo[live, nq:], -bnd)
            h = np.minimum(xhi[live, nq:], bnd)
            xlo[live, nq:], xhi[live, nq:] = l, h
            dead[live] |= ~(l <= h).all(axis=1)
            live = np.flatnonzero(~dead)
            if live.size == 0:
                break
            res = self._hc4.contract(_I(xlo[live], xhi[live]), lo[live], hi[live], params,
                                     max_iter=max_iter, tol=tol)
            its += res.iterations
            xlo[live], xhi[live] = np.where(res.empty[:, None], xlo[live], res.boxes.lo), \
                np.where(res.empty[:, None], xhi[live], res.boxes.hi)
            dead[live] |= res.empty
        xlo[dead] = _INF
        xhi[dead] = -_INF
        out = _I(xlo, xhi)
        if single:
            out = out.reshape(-1)
        return ContractResult(out, dead, its)

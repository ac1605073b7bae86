# Whole: its numba kernels and their helpers are one compilation unit.
"""Taylor coefficients of ODE solutions as Taylor models of degree 2 to 4 in a set's symbols.

Affine arithmetic (:mod:`verified.series.affine_taylor`) carries the first-order dependence
of every intermediate on the set's noise symbols exactly and bounds every product's
quadratic part by its full range. In a robot's model graph those quadratic parts
cancel (entries of ``K M K^T`` near 0 at the centre, differences of large torques),
but their bounds add up: on a robot the enclosures of ``qdd`` and ``d qdd / dq`` come
out several times the sampled range, and inside the solver the Jacobian's spread over
a set, many times the true one, made the QR-Lohner error part grow every step
whatever the step size (docs/lab/code_notes.md). Here every value is a *Taylor model* of degree 2 (COSY-VI,
Flow*, TaylorModels.jl; Makino & Berz 2003)::

    x  =  c + sum_i a_i eps_i + sum_{i <= j < mq} q_ij eps_i eps_j
            + sum_{i <= j <= k < m3} t_ijk eps_i eps_j eps_k + [-e, e]

over ``m`` symbols ``eps_i in [-1, 1]``, with the quadratic monomials kept for the
first ``mq`` symbols (the set's own, widest ones), the cubic ones for the first
``m3 <= mq`` (``m3 = 0``: degree 2) and a rigorous remainder radius ``e >= 0``. Kept
terms are carried exactly, so their cancellations are exact; only the higher orders,
products with symbols past the caps and rounding are bounded. Degree 3 exists because
a robot's graph cancels most of its cubic terms too, which degree 2 bounds per
operation (``test_degree_three_is_tighter_on_the_arm`` shows it on the 3-link arm);
degree 4 (quartic monomials in the first ``m4 <= m3`` symbols) for the same reason one
order up: sums such as a rotated vector's components cancel their fourth-order terms
(docs/lab/code_notes.md).

*Star* monomials ``eps_i eps_j`` with ``i < ms <= mq`` and ``j >= mq`` (the first ``ms``
symbols times every symbol past the quadratic block) keep, exactly, the cross terms of
the wide symbols with the many narrow ones a long run accumulates (the error a set
absorbs into parameters). Bounded per operation instead, those cross terms were linear
in the narrow symbols' size and, amplified through a deep graph, fed the error they
came from: the remainder per step grew with the number of parameters at an unchanged
set width and robot runs broke down early; with every pair of symbols kept they
complete (docs/lab/code_notes.md). The star keeps the
pairs that matter at ``ms (m - mq)`` monomials instead of ``m^2 / 2`` (or fewer: ``ns``
symbols past the quadratic ones instead of all). A star monomial
is off-diagonal (``eps_i eps_j`` in ``[-1, 1]``) and of degree 2: products that would
raise it are bounded.

Rules (all bounds rounded upward by :func:`verified.series.affine_taylor._up`, every float
coefficient's rounding error added to ``e``):

* ``x + y``, ``x - y``, ``x / k``, ``d x``: coefficient by coefficient.
* ``x * y``: the centres times every monomial of the other, and every product of
  two non-constant monomials whose result the model keeps (:func:`product_table`:
  linear x linear into quadratic, linear x quadratic into cubic, linear x cubic
  and quadratic x quadratic into quartic), exactly up to
  rounding; ``e`` gains the sum of ``|x_a| |y_b|`` over every other pair (``S_x S_y``
  minus the kept pairs' sum, ``S`` the sums of |non-constant coefficients|), and
  ``(|c_x| + S_x) e_y + (|c_y| + S_y) e_x + e_x e_y``.
* ``f(x)`` for sqrt, exp, log, sin, cos, tan, atan and ``1/x``: the expansion about
  the centre ``c`` with ``d = x - c`` (a model with centre 0) of the model's degree,
  ``f(c) + f'(c) d + f''(xi)/2 d^2`` (degree 2) or ``f(c) + f'(c) d + f''(c)/2 d^2 +
  f'''(xi)/6 d^3`` (degree 3) or, one term more, ``... + f'''(c)/6 d^3 + f''''(xi)/24
  d^4`` (degree 4): every derivative at ``c`` by the midpoint of its enclosure, the
  last over the range ``X`` of ``x``; ``e`` gains their radii times ``1, W, W^2 (, W^3,
  W^4)`` (``W >= |d|``). Where that error alone exceeds the plain image
  ``f(X)``, the image replaces the model (as in the affine kernel).
* Higher orders in time: the recurrences of :mod:`verified.series.taylor`, built from these.

A NaN anywhere gives ``[-inf, inf]``; a domain violation or overflow an infinite ``e``.
"""

from __future__ import annotations

import functools
import math
import os
from typing import NamedTuple

import numpy as np
from numba import njit

from verified.arith import _kernels as _k
from verified.series.affine_taylor import (
    _U, _UPF, _TINY, _centre_product, _deriv, _pm, _up, _value, _wide_symbol_forms, box_forms
)
from verified.arith.interval import Interval, _as_interval
from verified.arith.linalg import upper_pairs
from verified.series.recursion import recursion, register, rules_named
from verified.series.taylor import (
    T_ADD, T_ATAN, T_AUX, T_CONST, T_COS, T_DIV, T_EXP, T_INPUT, T_LOG, T_MID, T_MUL, T_NEG, T_PARAM, T_SIN, T_SQR,
    T_SQRT, T_SUB, T_TAN, _Tape
)

__all__ = ["TaylorModelODE", "model_length", "forms_to_models", "models_to_interval", "product_table",
           "QUADRATIC_SYMBOLS", "star_count", "star_base", "star_span"]

INF = math.inf

# Integer constants handed to other compiled functions are written ``np.int64(k)``, not ``k``:
# numba compiles a callee once per distinct integer *literal* argument, so the eight kinds of
# the unary expansion were eight compilations of it and of everything it calls, which
# multiplied a first run's compile time (docs/lab/code_notes.md, compile time).
# Except ``_abs_sum``'s start: its reassociated loop vectorizes better from a literal start
# (the kernel ran 1.5x slower without; docs/lab/robot_speed.md).

#: default cap on the symbols that get quadratic monomials (the rest stay linear):
#: the model's length grows as mq^2 / 2 and a product's cost with it
QUADRATIC_SYMBOLS = 12


def cubic_count(m3: int) -> int:
    """Number of cubic monomials ``eps_i eps_j eps_k`` (i <= j <= k < m3)."""
    return m3 * (m3 + 1) * (m3 + 2) // 6


def quartic_count(m4: int) -> int:
    """Number of quartic monomials ``eps_i eps_j eps_k eps_l`` (i <= j <= k <= l < m4)."""
    return m4 * (m4 + 1) * (m4 + 2) * (m4 + 3) // 24


def star_span(m: int, mq: int, ns: int | None) -> int:
    """The symbols past the quadratic ones that star monomials reach (``ns``; None: all)."""
    return max(m - mq, 0) if ns is None else int(ns)


def star_count(m: int, mq: int, ms: int, ns: int | None = None) -> int:
    """Number of star monomials ``eps_i eps_j`` (i < ms, mq <= j < mq + ns)."""
    return ms * star_span(m, mq, ns)


def model_length(m: int, mq: int, m3: int = 0, m4: int = 0, ms: int = 0, ns: int | None = None) -> int:
    """Length of a model over ``m`` symbols, ``mq`` of them with quadratic monomials, the
    first ``m3 <= mq`` with cubic ones, the first ``m4 <= m3`` with quartic ones and the
    first ``ms <= mq`` with star monomials (with the ``ns`` symbols after the quadratic
    ones; None: all of them): centre, ``m`` linear, ``mq (mq + 1) / 2`` quadratic, ``m3
    (m3 + 1) (m3 + 2) / 6`` cubic, :func:`quartic_count` quartic, :func:`star_count`
    star coefficients, remainder."""
    return m + mq * (mq + 1) // 2 + cubic_count(m3) + quartic_count(m4) + star_count(m, mq, ms, ns) + 2


def star_base(m: int, mq: int, m3: int = 0, m4: int = 0) -> int:
    """Storage index of the first star monomial (after the quartic ones)."""
    return m + 1 + mq * (mq + 1) // 2 + cubic_count(m3) + quartic_count(m4)


def _star_pairs(m: int, mq: int, ms: int, ns: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Symbol indices (i, j), i < ms, mq <= j < mq + ns, of the star coefficients in
    storage order (``j``-major)."""
    span = star_span(m, mq, ns)
    if ms <= 0 or span <= 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    jj, ii = np.meshgrid(np.arange(mq, mq + span), np.arange(ms), indexing="ij")
    return ii.ravel().astype(np.int64), jj.ravel().astype(np.int64)


def _pairs(mq: int) -> tuple[np.ndarray, np.ndarray]:
    """Symbol indices (i, j), i <= j < mq, of the quadratic coefficients, in storage order."""
    return upper_pairs(mq)


def _triples(m3: int) -> np.ndarray:
    """Symbol indices (i, j, k), i <= j <= k < m3, of the cubic coefficients, in storage
    order, shape (cubic_count(m3), 3)."""
    return np.array([(i, j, k) for i in range(m3) for j in range(i, m3) for k in range(j, m3)],
                    dtype=np.int64).reshape(-1, 3)


def _quads(m4: int) -> np.ndarray:
    """Symbol indices (i, j, k, l), i <= j <= k <= l < m4, of the quartic coefficients, in
    storage order, shape (quartic_count(m4), 4)."""
    return np.array([(i, j, k, l) for i in range(m4) for j in range(i, m4) for k in range(j, m4)
                     for l in range(k, m4)], dtype=np.int64).reshape(-1, 4)


#: a product's kept pairs are summed in floats; _acc_mul bounds that sum's rounding for up to
#: 2^14 terms
_MAX_PAIRS = 2**14

#: the most kept pairs of a product that land on one monomial (_acc_mul's rounding bound
#: relies on it; product_table checks it): 14 for a quartic eps_i eps_j eps_k eps_l
_MAX_HITS = 16.0


@functools.lru_cache(maxsize=64)
def product_table(m: int, mq: int, m3: int = 0, m4: int = 0, ms: int = 0,
                  ns: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The products of non-constant monomials a model keeps: ``(PA, PB, PC)`` with
    ``x[PA[t]] * y[PB[t]]`` a multiple of monomial ``PC[t]`` (storage indices of a model
    of :func:`model_length`); ordered pairs, so ``x_i y_j`` and ``x_j y_i`` are two
    entries. Every other product of non-constant monomials is bounded by :func:`_acc_mul`."""
    if not 0 <= m4 <= m3 <= mq <= m:
        raise ValueError(f"need 0 <= quartic symbols <= cubic symbols <= quadratic symbols <= symbols, "
                         f"got {m4}, {m3}, {mq}, {m}")
    if not 0 <= ms <= mq:
        raise ValueError(f"need 0 <= star symbols <= quadratic symbols, got {ms}, {mq}")
    if not 0 <= star_span(m, mq, ns) <= m - mq:
        raise ValueError(f"star monomials reach {ns} symbols, past the {mq} quadratic ones of {m}")
    pi, pj = _pairs(mq)
    quad = {(int(i), int(j)): m + 1 + p for p, (i, j) in enumerate(zip(pi, pj))}
    base3 = m + 1 + pi.size
    cubic = {tuple(int(v) for v in t): base3 + p for p, t in enumerate(_triples(m3))}
    base4 = base3 + cubic_count(m3)
    quartic = {tuple(int(v) for v in t): base4 + p for p, t in enumerate(_quads(m4))}
    A, B, C = [], [], []
    for i in range(mq):
        for j in range(mq):
            A.append(1 + i)
            B.append(1 + j)
            C.append(quad[(min(i, j), max(i, j))])
    for (j, k), q in quad.items():
        if k >= m3:
            continue
        for i in range(m3):
            c = cubic[tuple(sorted((i, j, k)))]
            A += [1 + i, q]
            B += [q, 1 + i]
            C += [c, c]
    # degree 4 among the first m4 symbols: linear x cubic (both orders), quadratic x quadratic
    for t, c3 in cubic.items():
        if t[2] >= m4:
            continue
        for i in range(m4):
            c = quartic[tuple(sorted((i,) + t))]
            A += [1 + i, c3]
            B += [c3, 1 + i]
            C += [c, c]
    for (i, j), qa in quad.items():
        if j >= m4:
            continue
        for (k, l), qb in quad.items():
            if l >= m4:
                continue
            A.append(qa)
            B.append(qb)
            C.append(quartic[tuple(sorted((i, j, k, l)))])
    # star: linear x linear with one symbol among the first ms and the other past mq
    si, sj = _star_pairs(m, mq, ms, ns)
    if si.size:
        idx = star_base(m, mq, m3, m4) + np.arange(si.size)
        A += list(1 + si) + list(1 + sj)
        B += list(1 + sj) + list(1 + si)
        C += list(idx) + list(idx)
    hits = np.bincount(np.asarray(C, dtype=np.int64)).max() if C else 0
    if hits > _MAX_HITS:  # (a new monomial class would break _acc_mul's rounding bound)
        raise ValueError(f"{hits} kept products land on one monomial, more than _acc_mul allows ({_MAX_HITS:g})")
    if len(A) > _MAX_PAIRS:
        raise ValueError(f"{len(A)} kept products per model product exceed {_MAX_PAIRS}: fewer quadratic "
                         f"or cubic symbols")
    return tuple(np.asarray(v, dtype=np.int64) for v in (A, B, C))


# --------------------------------------------------------------------------
# Model operations on 1-D arrays of length L = m + nq + 2: [0] centre, [1..m] linear,
# [m+1 .. m+nq] quadratic (pair p = (PI[p], PJ[p])), [L-1] remainder radius.
# --------------------------------------------------------------------------
@njit(cache=True, forceinline=False, _nrt=True)
def _clear(T):
    for i in range(T.size):
        T[i] = 0.0


@njit(cache=True)
def _poison(T):
    """The model that stands for 'unknown': all of the real line."""
    _clear(T)
    T[T.size - 1] = INF


@njit(cache=True, fastmath={"reassoc"}, forceinline=False, _nrt=True)
def _abs_sum(x, lo, hi):
    """An upper bound of ``sum |x[lo:hi]|``.

    The only function of this module compiled with reassociation (``fastmath``
    ``reassoc``, which lets LLVM vectorize the sum): a float sum of ``n`` non-negative
    terms, in any order, is within ``(n - 1) u`` of the exact sum relative to it
    (Higham, *Accuracy and Stability*, 4.2), which the factor ``1 + n 2^-52`` covers
    with the rounding of that product. No other operation may be reassociated: the
    model coefficients' rounding bounds depend on the order of their operations. It
    must not be inlined by numba (``inline="always"``), which would compile it with the
    caller's flags. Reassociation is what makes it fast (docs/lab/code_notes.md)."""
    t = 0.0
    for i in range(lo, hi):
        t += abs(x[i])
    return _up(t * (1.0 + (hi - lo + 1) * 2.0**-52))


@njit(cache=True)
def _spread(x):
    """Sum of |coefficients| of the non-constant monomials, rounded up: a bound of
    |x - c - e| over the symbols' box."""
    return _abs_sum(x, 1, x.size - 1)


@njit(cache=True)
def _width_bound(x):
    """An upper bound of |x - c| over the symbols' box (every monomial and the remainder)."""
    return _up(_spread(x) + x[x.size - 1])


@njit(cache=True, forceinline=False, _nrt=True)
def _acc_mul(T, x, y, PA, PB, PC, w):
    """T += w * x * y, truncated to the monomials of :func:`product_table` (``w`` any
    float: its rounding is bounded).

    The centre times every monomial and the table's pairs are kept; every other pair of
    non-constant monomials (degree above the model's, or a symbol without monomials of
    that degree) is bounded by its ``|x_a| |y_b|``: their sum is ``Sx Sy`` (``S`` the
    spreads) minus the kept pairs' sum, the latter taken as a lower bound.

    Rounding, in units of ``u = 2^-53`` (``rnd * 2^-52`` below, a factor 2 to spare):
    the centre terms ``w x0 y_i + w y0 x_i`` added to ``T_i`` err by at most ``3 |p1| +
    3 |p2| + |T_i'|`` (two products, two sums), and ``sum |p1| <= |w x0| Sy (1 + 2u)^2``;
    a kept pair's ``T_s += w (x_a y_b)`` by ``2 |q| + |T_s'|``, where ``T_s'``, a partial
    sum, is at most ``|T_s|`` after the centre terms plus the ``|q|`` of the pairs into
    ``s`` so far, so the pairs' sum of ``|T_s'|`` is at most ``_MAX_HITS`` (the most
    pairs into one monomial, checked by :func:`product_table`) times ``sum |T_s| + sum
    |q|``. Bounding the rounding from these sums, not term by term, keeps the loops
    free of sequential float reductions (numba vectorizes them), which makes them
    faster (docs/lab/code_notes.md)."""
    E = T.size - 1
    x0 = x[0]
    y0 = y[0]
    rnd = _centre_product(T, x0, y0, w)
    for i in range(1, E):
        T[i] = T[i] + (w * (x0 * y[i]) + w * (y0 * x[i]))
    sx = _spread(x)
    sy = _spread(y)
    tc = _spread(T)
    aw = abs(w)
    rnd += 2.0 * _up(_pm(aw, _pm(abs(x0), sy) + _pm(abs(y0), sx)) * (1.0 + 2.0**-48)) + tc
    kept = 0.0
    for t in range(PA.size):
        p = x[PA[t]] * y[PB[t]]
        kept += abs(p)
        s = PC[t]
        T[s] = T[s] + w * p
    # |computed kept - true kept| <= (size + 1) u kept, size <= 2^14: 2^-36 covers it
    kq = _up(_pm(aw, kept) * (1.0 + 2.0**-36))
    rnd += 3.0 * kq + _MAX_HITS * (tc + kq)
    dropped = max(_pm(sx, sy) * _UPF - kept * (1.0 - 2.0**-36), 0.0)
    ex = x[E]
    ey = y[E]
    nl = dropped + _pm(abs(x0) + sx, ey) + _pm(abs(y0) + sy, ex) + _pm(ex, ey)
    T[E] = _up(T[E] + _pm(aw, _up(nl)) + _up(rnd) * _U)


@njit(cache=True, forceinline=False, _nrt=True)
def _acc_add(T, x, sign):
    """T += sign * x (sign = +1 or -1)."""
    E = T.size - 1
    for i in range(E):
        T[i] = T[i] + sign * x[i]
    # one rounding per coefficient, at most u |result| (the sum bound is vectorized)
    T[E] = _up(T[E] + x[E] + _abs_sum(T, 0, E) * _U)


@njit(cache=True, forceinline=False, _nrt=True)
def _scale_into(Z, x, d):
    """Z = d * x for a float d."""
    E = Z.size - 1
    for i in range(E):
        Z[i] = d * x[i]
    Z[E] = _up(_pm(abs(d), x[E]) + _abs_sum(Z, 0, E) * _U)


@njit(cache=True, forceinline=False, _nrt=True)
def _div_int_into(Z, x, kf):
    """Z = x / kf for a positive integer kf."""
    E = Z.size - 1
    for i in range(E):
        Z[i] = x[i] / kf
    Z[E] = _up(x[E] / kf + _abs_sum(Z, 0, E) * _U)


# --------------------------------------------------------------------------
# Linear orders (TaylorModelODE.linear_orders): from the order ``linear_orders`` on,
# the kernel's models are centre, linear part and remainder only, and only the prefix
# [0, l) of the linear part can be nonzero (the fresh symbols of the orders above are exact
# zeros): these operations read and write that prefix and the remainder, nothing else
# (the rest of the work arrays is left over from earlier calls). An operand of a lower
# order keeps its nonlinear block [q0, E) (``h`` 1, its prefix the whole linear part): a
# result takes the centre times that block into its remainder.
# --------------------------------------------------------------------------
@njit(cache=True)
def _abs_sum_from(x, lo, hi):
    """:func:`_abs_sum` of ``x[lo:hi]`` for a start ``lo`` known only at run time: over the
    slice from a literal 0 (a loop from a variable start keeps numba's check for negative
    indices, which keeps LLVM from vectorizing it: 7x slower)."""
    return _abs_sum(x[lo:hi], 0, hi - lo)


@njit(cache=True, forceinline=False, _nrt=True)
def _clear_pre(T, l):
    """Zero the prefix [0, l) and the remainder."""
    for i in range(l):
        T[i] = 0.0
    T[T.size - 1] = 0.0


@njit(cache=True, forceinline=False, _nrt=True)
def _copy_pre(Z, x, l):
    """Z = x on the prefix [0, l) and the remainder (x without a nonlinear block)."""
    for i in range(l):
        Z[i] = x[i]
    Z[Z.size - 1] = x[x.size - 1]


@njit(cache=True, forceinline=False, _nrt=True)
def _neg_pre(Z, x, l):
    """Z = -x on the prefix (exact), the same remainder."""
    for i in range(l):
        Z[i] = -x[i]
    Z[Z.size - 1] = x[x.size - 1]


@njit(cache=True, forceinline=False, _nrt=True)
def _acc_add_pre(T, x, sign, lt, lx):
    """:func:`_acc_add` on prefixes (``lx <= lt``; x without a nonlinear block)."""
    E = T.size - 1
    for i in range(lx):
        T[i] = T[i] + sign * x[i]
    T[E] = _up(T[E] + x[E] + _abs_sum(T, 0, lt) * _U)


@njit(cache=True, forceinline=False, _nrt=True)
def _add_pre(Z, x, y, sign, l):
    """Z = x + sign * y on the prefix (sign = +1 or -1; x, y without nonlinear blocks):
    one rounding per coefficient, at most u |result|."""
    E = Z.size - 1
    for i in range(l):
        Z[i] = x[i] + sign * y[i]
    Z[E] = _up(x[E] + y[E] + _abs_sum(Z, 0, l) * _U)


@njit(cache=True, forceinline=False, _nrt=True)
def _div_int_pre(Z, x, kf, l):
    """:func:`_div_int_into` on the prefix (x without a nonlinear block)."""
    E = Z.size - 1
    for i in range(l):
        Z[i] = x[i] / kf
    Z[E] = _up(x[E] / kf + _abs_sum(Z, 0, l) * _U)


@njit(cache=True, forceinline=False, _nrt=True)
def _sweep_nonlinear(Y, q0):
    """Y's nonlinear coefficients (the block [q0, E)) into its remainder: each monomial
    lies in [-1, 1], so their sum of |.|, rounded up, bounds them; the block is zeroed."""
    E = Y.size - 1
    if q0 >= E:
        return
    s = _abs_sum_from(Y, q0, E)
    Yq = Y[q0:E]
    for i in range(Yq.size):
        Yq[i] = 0.0
    Y[E] = _up(Y[E] + s)


@njit(cache=True, inline="always")
def _centre_terms_pre(T, x, y, w, lx, ly):
    """T_i += w x0 y_i + w y0 x_i for the linear coefficients 1 <= i < max(lx, ly) of the
    operands' prefixes (past one prefix its terms are exact zeros). Inlined by numba: a
    call per product term cost as much as its loop (docs/lab/robot_speed.md); it has no
    ``fastmath``, so inlining changes no float operation."""
    x0 = x[0]
    y0 = y[0]
    lc = min(lx, ly)
    for i in range(1, lc):
        T[i] = T[i] + (w * (x0 * y[i]) + w * (y0 * x[i]))
    # (the tails start where the other prefix ends: slices from 0, see _abs_sum_from)
    if ly > lc:
        Tl = T[lc:ly]
        yl = y[lc:ly]
        for i in range(Tl.size):
            Tl[i] = Tl[i] + w * (x0 * yl[i])
    if lx > lc:
        Tl = T[lc:lx]
        xl = x[lc:lx]
        for i in range(Tl.size):
            Tl[i] = Tl[i] + w * (y0 * xl[i])


@njit(cache=True, forceinline=False, _nrt=True)
def _acc_mul_pre(T, x, y, w, lt, lx, hx, ly, hy, q0):
    """T += w * x * y into a result without nonlinear coefficients (prefix ``lt``):
    :func:`_acc_mul` with an empty product table, on the operands' prefixes ``lx, ly <= lt``
    (past one operand's prefix its terms are exact zeros). An operand with its nonlinear
    block (``hx``/``hy`` 1, a lower order's model: prefix ``q0``) has that block's
    products with the other's centre, ``|y0| sum |x_nl|``, bounded into the remainder
    (every monomial lies in [-1, 1]); every pair of non-constant monomials is bounded by
    ``Sx Sy`` (``dropped``), the remainders as in :func:`_acc_mul`, and the rounding
    likewise (the centre terms' bound over the operands' whole spreads)."""
    E = T.size - 1
    x0 = x[0]
    y0 = y[0]
    rnd = _centre_product(T, x0, y0, w)
    lx = min(lx, lt)  # (a lower order's model is zero past lt: no fresh symbols above its order)
    ly = min(ly, lt)
    _centre_terms_pre(T, x, y, w, lx, ly)
    swept = 0.0
    sx = _abs_sum(x, 1, lx)
    if hx:
        nx = _abs_sum_from(x, q0, E)
        swept += _pm(abs(y0), nx)
        sx = _up(sx + nx)
    sy = _abs_sum(y, 1, ly)
    if hy:
        ny = _abs_sum_from(y, q0, E)
        swept += _pm(abs(x0), ny)
        sy = _up(sy + ny)
    tc = _abs_sum(T, 1, lt)
    aw = abs(w)
    rnd += 2.0 * _up(_pm(aw, _pm(abs(x0), sy) + _pm(abs(y0), sx)) * (1.0 + 2.0**-48)) + tc
    dropped = _pm(sx, sy) * _UPF
    ex = x[E]
    ey = y[E]
    nl = dropped + swept + _pm(abs(x0) + sx, ey) + _pm(abs(y0) + sy, ex) + _pm(ex, ey)
    T[E] = _up(T[E] + _pm(aw, _up(nl)) + _up(rnd) * _U)


@njit(cache=True, forceinline=False, _nrt=True)
def _frozen_point_into(Z, x):
    """Z = the graph op ``mid``: the model's centre as an exact point (unknown stays unknown)."""
    c = x[0]
    w = _width_bound(x)
    _clear(Z)
    if math.isfinite(c) and math.isfinite(w):
        Z[0] = c
    else:
        Z[Z.size - 1] = INF


@njit(cache=True)
def _deriv2(kind, lo, hi):
    """Interval enclosure of f'' over [lo, hi] (kinds as :func:`verified.series.affine_taylor._deriv`)."""
    if kind == 0:  # sqrt: -1 / (4 x sqrt(x))
        sl, sh = _k.sqrt(lo, hi)
        pl, ph = _k.mul(lo, hi, sl, sh)
        ql, qh = _k.mul(4.0, 4.0, pl, ph)
        rl, rh = _k.div(1.0, 1.0, ql, qh)
        return -rh, -rl
    if kind == 1:  # exp
        return _k.exp(lo, hi)
    if kind == 2:  # log: -1 / x^2
        ql, qh = _k.sqr(lo, hi)
        rl, rh = _k.div(1.0, 1.0, ql, qh)
        return -rh, -rl
    if kind == 3:  # sin: -sin
        sl, sh = _k.sin(lo, hi)
        return -sh, -sl
    if kind == 4:  # cos: -cos
        cl, ch = _k.cos(lo, hi)
        return -ch, -cl
    if kind == 5:  # tan: 2 t (1 + t^2)
        tl, th = _k.tan(lo, hi)
        ql, qh = _k.sqr(tl, th)
        al, ah = _k.add(1.0, 1.0, ql, qh)
        pl, ph = _k.mul(tl, th, al, ah)
        return _k.mul(2.0, 2.0, pl, ph)
    if kind == 6:  # atan: -2 x / (1 + x^2)^2
        ql, qh = _k.sqr(lo, hi)
        al, ah = _k.add(1.0, 1.0, ql, qh)
        bl, bh = _k.sqr(al, ah)
        nl, nh = _k.mul(-2.0, -2.0, lo, hi)
        return _k.div(nl, nh, bl, bh)
    # 7: reciprocal: 2 / x^3
    cl, ch = _k.ipow(lo, hi, np.int64(3))
    return _k.div(2.0, 2.0, cl, ch)


@njit(cache=True)
def _deriv3(kind, lo, hi):
    """Interval enclosure of the third derivative over [lo, hi] (kinds as :func:`_deriv2`)."""
    if kind == 0:  # sqrt: 3 / (8 x^2 sqrt(x))
        sl, sh = _k.sqrt(lo, hi)
        ql, qh = _k.sqr(lo, hi)
        pl, ph = _k.mul(ql, qh, sl, sh)
        dl, dh = _k.mul(8.0, 8.0, pl, ph)
        return _k.div(3.0, 3.0, dl, dh)
    if kind == 1:  # exp
        return _k.exp(lo, hi)
    if kind == 2:  # log: 2 / x^3
        cl, ch = _k.ipow(lo, hi, np.int64(3))
        return _k.div(2.0, 2.0, cl, ch)
    if kind == 3:  # sin: -cos
        cl, ch = _k.cos(lo, hi)
        return -ch, -cl
    if kind == 4:  # cos: sin
        return _k.sin(lo, hi)
    if kind == 5:  # tan: (2 + 6 t^2)(1 + t^2)
        tl, th = _k.tan(lo, hi)
        ql, qh = _k.sqr(tl, th)
        al, ah = _k.add(1.0, 1.0, ql, qh)
        sl, sh = _k.mul(6.0, 6.0, ql, qh)
        bl, bh = _k.add(2.0, 2.0, sl, sh)
        return _k.mul(al, ah, bl, bh)
    if kind == 6:  # atan: (6 x^2 - 2) / (1 + x^2)^3
        ql, qh = _k.sqr(lo, hi)
        al, ah = _k.add(1.0, 1.0, ql, qh)
        cl, ch = _k.ipow(al, ah, np.int64(3))
        sl, sh = _k.mul(6.0, 6.0, ql, qh)
        nl, nh = _k.sub(sl, sh, 2.0, 2.0)
        return _k.div(nl, nh, cl, ch)
    # 7: reciprocal: -6 / x^4
    fl, fh = _k.ipow(lo, hi, np.int64(4))
    rl, rh = _k.div(6.0, 6.0, fl, fh)
    return -rh, -rl


@njit(cache=True)
def _deriv4(kind, lo, hi):
    """Interval enclosure of the fourth derivative over [lo, hi] (kinds as :func:`_deriv2`)."""
    if kind == 0:  # sqrt: -15 / (16 x^3 sqrt(x))
        sl, sh = _k.sqrt(lo, hi)
        cl, ch = _k.ipow(lo, hi, np.int64(3))
        pl, ph = _k.mul(cl, ch, sl, sh)
        dl, dh = _k.mul(16.0, 16.0, pl, ph)
        rl, rh = _k.div(15.0, 15.0, dl, dh)
        return -rh, -rl
    if kind == 1:  # exp
        return _k.exp(lo, hi)
    if kind == 2:  # log: -6 / x^4
        fl, fh = _k.ipow(lo, hi, np.int64(4))
        rl, rh = _k.div(6.0, 6.0, fl, fh)
        return -rh, -rl
    if kind == 3:  # sin: sin
        return _k.sin(lo, hi)
    if kind == 4:  # cos: cos
        return _k.cos(lo, hi)
    if kind == 5:  # tan: 8 t (1 + t^2) (2 + 3 t^2)
        tl, th = _k.tan(lo, hi)
        ql, qh = _k.sqr(tl, th)
        al, ah = _k.add(1.0, 1.0, ql, qh)
        sl, sh = _k.mul(3.0, 3.0, ql, qh)
        bl, bh = _k.add(2.0, 2.0, sl, sh)
        pl, ph = _k.mul(al, ah, bl, bh)
        ul, uh = _k.mul(8.0, 8.0, tl, th)
        return _k.mul(ul, uh, pl, ph)
    if kind == 6:  # atan: 24 x (1 - x^2) / (1 + x^2)^4
        ql, qh = _k.sqr(lo, hi)
        al, ah = _k.add(1.0, 1.0, ql, qh)
        cl, ch = _k.ipow(al, ah, np.int64(4))
        ol, oh = _k.sub(1.0, 1.0, ql, qh)
        ul, uh = _k.mul(24.0, 24.0, lo, hi)
        nl, nh = _k.mul(ul, uh, ol, oh)
        return _k.div(nl, nh, cl, ch)
    # 7: reciprocal: 24 / x^5
    fl, fh = _k.ipow(lo, hi, np.int64(5))
    return _k.div(24.0, 24.0, fl, fh)


@njit(cache=True)
def _mid_rad(lo, hi):
    """(midpoint, radius rounded up) of [lo, hi]: the midpoint stands for the interval."""
    mid = 0.5 * lo + 0.5 * hi
    return mid, _up(max(hi - mid, mid - lo))


@njit(cache=True, forceinline=False, _nrt=True)
def _unary_into(Z, x, PA, PB, PC, deg, kind, D, D2, D3, known_lo=-INF):
    """Z = f(x) by the expansion of degree ``deg`` (2, 3 or 4) about the centre ``c``
    (module docstring), with ``d = x - c``: ``f(c) + f'(c) d + f2(xi)/2 d^2`` (deg 2),
    ``f(c) + f'(c) d + f2(c)/2 d^2 + f3(xi)/6 d^3`` (deg 3) or ``... + f3(c)/6 d^3 +
    f4(xi)/24 d^4`` (deg 4), ``f2, f3, f4`` the second to fourth derivatives, ``xi`` in
    the range of x. ``D``, ``D2``, ``D3``: scratch of the model's length. ``known_lo``: a
    lower bound of x known from elsewhere (1 for ``1 + u^2``); the range used for the
    last derivative is cut to it."""
    E = Z.size - 1
    c = x[0]
    W = _width_bound(x)
    if not (math.isfinite(c) and math.isfinite(W)):
        _poison(Z)
        return
    xlo = max(_k.rd(c - W), min(known_lo, c))
    xhi = _k.ru(c + W)
    if not xlo <= xhi:
        _poison(Z)
        return
    fl, fh = _value(kind, c, c)
    dl, dh = _deriv(kind, c, c)
    kl, kh = 0.0, 0.0
    if deg >= 4:
        hl, hh = _deriv2(kind, c, c)  # f2 and f3 at the centre, f4 over the range
        kl, kh = _deriv3(kind, c, c)
        sl, sh = _deriv4(kind, xlo, xhi)
    elif deg >= 3:
        hl, hh = _deriv2(kind, c, c)  # f2 at the centre, f3 over the range
        sl, sh = _deriv3(kind, xlo, xhi)
    else:
        hl, hh = 0.0, 0.0
        sl, sh = _deriv2(kind, xlo, xhi)
    if not (fl <= fh and dl <= dh and sl <= sh and hl <= hh and kl <= kh and math.isfinite(kl)
            and math.isfinite(kh)):
        _poison(Z)  # outside the domain, or a pole within reach
        return
    if not (math.isfinite(fl) and math.isfinite(fh) and math.isfinite(dl) and math.isfinite(dh)
            and math.isfinite(sl) and math.isfinite(sh) and math.isfinite(hl) and math.isfinite(hh)):
        _poison(Z)
        return
    f0, frad = _mid_rad(fl, fh)
    d1, r1 = _mid_rad(dl, dh)
    # f2/2, f3/6 and f4/24: halving is exact away from underflow (_TINY in _up covers
    # that); the divisions by 6 and 24 round, which a relative slack on the radius covers
    top = 2.0 if deg < 3 else (6.0 if deg == 3 else 24.0)
    s, rl = _mid_rad(sl / top, sh / top)
    rl = _up(rl + (abs(sl) + abs(sh)) * _U)
    for i in range(D.size):  # D = x - c: the same model with centre 0 (exact)
        D[i] = x[i]
    D[0] = 0.0
    _scale_into(Z, D, d1)  # d1 d, with the remainder |d1| e_x and the rounding
    Z[0] = f0
    W2 = _pm(W, W)
    if deg >= 3:
        h2, r2 = _mid_rad(0.5 * hl, 0.5 * hh)
        _acc_mul(Z, D, D, PA, PB, PC, h2)  # + f2(c)/2 d^2
        _clear(D2)
        _acc_mul(D2, D, D, PA, PB, PC, 1.0)  # d^2
        if deg >= 4:
            t3, r3 = _mid_rad(kl / 6.0, kh / 6.0)
            r3 = _up(r3 + (abs(kl) + abs(kh)) * _U)
            _acc_mul(Z, D2, D, PA, PB, PC, t3)  # + f3(c)/6 d^3
            _clear(D3)
            _acc_mul(D3, D2, D, PA, PB, PC, 1.0)  # d^3
            _acc_mul(Z, D3, D, PA, PB, PC, s)  # + f4/24 d^4 (truncated, bounded)
            W3 = _pm(W2, W)
            Z[E] = _up(Z[E] + frad + _pm(r1, W) + _pm(r2, W2) + _pm(r3, W3) + _pm(rl, _pm(W3, W)) + _TINY)
        else:
            _acc_mul(Z, D2, D, PA, PB, PC, s)  # + f3/6 d^3 (truncated, bounded)
            Z[E] = _up(Z[E] + frad + _pm(r1, W) + _pm(r2, W2) + _pm(rl, _pm(W2, W)) + _TINY)
    else:
        _acc_mul(Z, D, D, PA, PB, PC, s)  # + s d^2 (truncated, bounded)
        Z[E] = _up(Z[E] + frad + _pm(r1, W) + _pm(rl, W2) + _TINY)
    gl, gh = _value(kind, xlo, xhi)
    if gl <= gh and math.isfinite(gl) and math.isfinite(gh):
        g0, grad = _mid_rad(gl, gh)
        if grad < Z[E]:
            _clear(Z)
            Z[0] = g0
            Z[E] = grad


@njit(cache=True, forceinline=False, _nrt=True)
def _sqrconv(Z, F, u, k, j0, b, PA, PB, PC):
    """Z += sum_{j=j0}^{k-j0} F[u, j] F[u, k-j] (pairs of equal terms once, times 2)."""
    for j in range(j0, (k + 1) // 2):
        _acc_mul(Z, F[u, j, b], F[u, k - j, b], PA, PB, PC, 2.0)
    if k % 2 == 0 and k // 2 >= j0:
        _acc_mul(Z, F[u, k // 2, b], F[u, k // 2, b], PA, PB, PC, 1.0)


@njit(cache=True)
def _model_sums(F, C, s, j, b, LV, HV, q0):
    """The spread of the model F[s, j, b] (returned) and its nonlinear block's sum of |.|,
    both rounded up, into ``C[s, j, b]`` (the
    spread over its prefix ``LV[j]`` and, if ``HV[j]``, its block; the block's sum 0
    without one): computed at its first use in a kernel call and kept in ``C[s, j, b]``
    (-1: not yet; the pool's change of a model marks it so again). A convolution reads
    each model at every later order: its sums cost one pass, not one per use."""
    sp = C[s, j, b, 0]
    if sp < 0.0:
        x = F[s, j, b]
        E = x.size - 1
        if HV[j]:
            sp = _abs_sum(x, 1, E)
            C[s, j, b, 1] = _abs_sum_from(x, q0, E)
        else:
            sp = _abs_sum(x, 1, LV[j])
            C[s, j, b, 1] = 0.0
        C[s, j, b, 0] = sp
    return sp


@njit(cache=True, forceinline=False, _nrt=True)
def _conv_pre(T, F, C, u, v, k, j0, j1, wa, wb, b, LV, HV, q0, fresh):
    """T += sum_{j0 <= j < j1} (wa + wb j) F[u, j, b] F[v, k - j, b] (``fresh`` 1: T = that
    sum, T's contents ignored; an int64, not a literal, as every flag here) into a result at the
    linear order k (prefix ``LV[k]``): :func:`_acc_mul_pre` for each term, in one call,
    with the operands' sums from :func:`_model_sums`. Each term's centre loop is
    :func:`_acc_mul_pre`'s (the same float operations on T); its rounding bound sums
    theirs, the sum of ``|T_i|`` after each term taken as at most the number of terms
    times ``sum |T_i|`` before the first plus every term's centre products' bound (the
    partial sums' magnitudes, with their roundings inside the factor ``1 + 2^-40``)."""
    E = T.size - 1
    lt = LV[k]
    if fresh:
        _clear_pre(T, lt)
        tc0 = 0.0
    else:
        tc0 = _abs_sum(T, 1, lt)
    rnd = 0.0
    cen = 0.0
    acc = T[E]
    for j in range(j0, j1):
        w = wa + wb * j
        x = F[u, j, b]
        y = F[v, k - j, b]
        lx = min(LV[j], lt)  # (a lower order's model is zero past lt: no fresh symbols above its order)
        ly = min(LV[k - j], lt)
        sx = C[u, j, b, 0]  # (the cache read here: a call per operand costs as much as its loop)
        if sx < 0.0:
            sx = _model_sums(F, C, u, j, b, LV, HV, q0)
        nx = C[u, j, b, 1]
        sy = C[v, k - j, b, 0]
        if sy < 0.0:
            sy = _model_sums(F, C, v, k - j, b, LV, HV, q0)
        ny = C[v, k - j, b, 1]
        x0 = x[0]
        y0 = y[0]
        rnd += _centre_product(T, x0, y0, w)
        _centre_terms_pre(T, x, y, w, lx, ly)
        aw = abs(w)
        ct = _up(_pm(aw, _pm(abs(x0), sy) + _pm(abs(y0), sx)) * (1.0 + 2.0**-48))
        cen += ct
        rnd += 2.0 * ct
        swept = _pm(abs(y0), nx) + _pm(abs(x0), ny)  # (the lower orders' blocks times the centres)
        ex = x[E]
        ey = y[E]
        nl = _pm(sx, sy) * _UPF + swept + _pm(abs(x0) + sx, ey) + _pm(abs(y0) + sy, ex) + _pm(ex, ey)
        acc = _up(acc + _pm(aw, _up(nl)))
    # the centre loops' partial sums: sum_i |T_i| after each term <= tc0 + the terms' bound
    rnd += (j1 - j0) * _up(_up(tc0 + cen) * _UPF)
    T[E] = _up(acc + _up(rnd) * _U)


@njit(cache=True, forceinline=False, _nrt=True)
def _sqrconv_pre(Z, F, C, u, k, j0, b, LV, HV, q0, fresh):
    """:func:`_sqrconv` at a linear order (:func:`_conv_pre`; the order-j models'
    prefixes and blocks ``LV[j], HV[j]``; ``fresh``: Z = the sum)."""
    _conv_pre(Z, F, C, u, u, k, j0, (k + 1) // 2, 2.0, 0.0, b, LV, HV, q0, fresh)
    if k % 2 == 0 and k // 2 >= j0:
        h = k // 2
        _conv_pre(Z, F, C, u, u, k, h, h + 1, 1.0, 0.0, b, LV, HV, q0, np.int64(0))


@njit(cache=True, forceinline=False, _nrt=True)
def _quotient_step_pre(Z, F, C, s, u, v, k, b, rec, T, S, LV, HV, q0):
    """:func:`_quotient_step` at a linear order (``rec``: an order-0 model)."""
    lk = LV[k]
    _conv_pre(S, F, C, s, v, k, np.int64(1), k, 0.0, 1.0, b, LV, HV, q0, np.int64(1))
    _div_int_pre(T, S, float(k), lk)
    _add_pre(S, F[u, k, b], T, -1.0, lk)
    _clear_pre(Z, lk)
    _acc_mul_pre(Z, S, rec, 1.0, lk, lk, np.int64(0), LV[0], HV[0], q0)


@njit(cache=True, forceinline=False, _nrt=True)
def _quotient_step(Z, F, s, u, v, k, b, PA, PB, PC, rec, T, S):
    """Z = (F[u, k] - (1/k) sum_{j=1}^{k-1} j F[s, j] F[v, k-j]) * rec (log, atan)."""
    _clear(S)
    for j in range(1, k):
        _acc_mul(S, F[s, j, b], F[v, k - j, b], PA, PB, PC, float(j))
    _div_int_into(T, S, float(k))
    _clear(S)
    _acc_add(S, F[u, k, b], 1.0)
    _acc_add(S, T, -1.0)
    _clear(Z)
    _acc_mul(Z, S, rec, PA, PB, PC, 1.0)


# The helpers the rules call carry ``forceinline=False, _nrt=True``: numba compiles a callee
# with the flags of the function being compiled where it sets none of its own (``forceinline``,
# ``nrt``, ``fastmath``, ``error_model``), and the rules are compiled with ``forceinline`` and
# without reference counting (recursion._stub). Without them every helper (``_unary_into``,
# ``_acc_mul``, ...) became ``alwaysinline``, inlined at every call in every rule (the first
# compile took 205 s of CPU against 33 s), and, compiled without reference counting, LLVM
# vectorized ``_abs_sum``'s reassociated sums otherwise: other (equally rigorous) bounds than
# the kernel's before the table, in the last bits. With them the helpers compile as they did
# under the hand-written kernel, whichever caller compiles them first (docs/lab/recursion_engine.md).
class ModelTable(NamedTuple):
    """Taylor models of every tape slot and of the state, every set of the batch (the table
    of :func:`verified.series.recursion.recursion` that :func:`_model_kernel` runs). Its
    rules are the functions ``_tm_*`` below (plain functions: numba compiles them into the
    engine), each with the loop over the sets inside it and its two bodies side by side:
    whole models (``HV[k]``) and, at the linear orders, the prefix operations
    (:func:`_acc_mul_pre`). Every array exists before the engine runs: the rules make none."""

    F: np.ndarray  # (slots, order + 1, B, L): the model of coefficient k of slot s for set b
    REC: np.ndarray  # (slots, B, L): the reciprocal of slot s's order-0 divisor (div, sqrt, log, atan)
    out: np.ndarray  # (n, order + 1, B, L): x_[k] of state i
    P: np.ndarray  # (p, B, L): the parameters' models
    C: np.ndarray  # (slots, order + 1, B, 2): the models' sums (_model_sums; -1: not yet)
    T: np.ndarray  # (L,): scratch models
    S: np.ndarray
    D: np.ndarray  # (L,): scratch of the unary expansion (_unary_into)
    D2: np.ndarray
    D3: np.ndarray
    used: np.ndarray  # (B,): the pool symbols handed out so far, per set
    PA: np.ndarray  # the product table (product_table) ...
    PB: np.ndarray
    PC: np.ndarray
    NA: np.ndarray  # ... and the empty one, for the orders k >= product_orders (_products)
    NB: np.ndarray
    NC: np.ndarray
    LV: np.ndarray  # (order + 1,): order k's prefix of the linear part (its length q0 where whole)
    HV: np.ndarray  # (order + 1,): 1 where order k's models are whole, 0 at the linear orders
    op: np.ndarray  # the tape's opcodes (the pool skips inputs, parameters, constants and mid)
    deg: int  # the models' degree (2, 3 or 4)
    q0: int  # storage index of the first nonlinear coefficient
    fresh0: int  # the coefficients' fresh symbols (-1: none)
    pool0: int  # the pool's first symbol (-1: no pool), its size, threshold and orders
    pool_n: int
    pool_tol: float
    pool_orders: int
    product_orders: int


@njit(inline="always")
def _products(ar, k):
    """The product table of order ``k``: the empty one from ``product_orders`` on, where
    :func:`_acc_mul` bounds every pair of non-constant monomials into the remainder (see
    :attr:`TaylorModelODE.product_orders`)."""
    if 0 <= ar.product_orders <= k:
        return ar.NA, ar.NB, ar.NC
    return ar.PA, ar.PB, ar.PC


def _tm_const(ar, s, lo, hi):
    F = ar.F
    E = F.shape[3] - 1
    for b in range(F.shape[2]):
        Z = F[s, 0, b]
        _clear(Z)
        mid = 0.5 * lo + 0.5 * hi
        Z[0] = mid
        Z[E] = _up(max(hi - mid, mid - lo))


def _tm_param(ar, s, i):
    F = ar.F
    for b in range(F.shape[2]):
        Z = F[s, 0, b]
        x = ar.P[i, b]
        for j in range(Z.size):
            Z[j] = x[j]


def _tm_mid(ar, s, u):
    F = ar.F
    for b in range(F.shape[2]):
        _frozen_point_into(F[s, 0, b], F[u, 0, b])


def _tm_state(ar, s, k, i):
    F = ar.F
    for b in range(F.shape[2]):
        Z = F[s, k, b]
        x = ar.out[i, k, b]
        if ar.HV[k]:
            for j in range(Z.size):
                Z[j] = x[j]
        else:
            _copy_pre(Z, x, ar.LV[k])


def _tm_add(ar, s, k, u, v):
    F = ar.F
    for b in range(F.shape[2]):
        Z = F[s, k, b]
        if ar.HV[k]:
            _clear(Z)
            _acc_add(Z, F[u, k, b], 1.0)
            _acc_add(Z, F[v, k, b], 1.0)
        else:
            _add_pre(Z, F[u, k, b], F[v, k, b], 1.0, ar.LV[k])


def _tm_sub(ar, s, k, u, v):
    F = ar.F
    for b in range(F.shape[2]):
        Z = F[s, k, b]
        if ar.HV[k]:
            _clear(Z)
            _acc_add(Z, F[u, k, b], 1.0)
            _acc_add(Z, F[v, k, b], -1.0)
        else:
            _add_pre(Z, F[u, k, b], F[v, k, b], -1.0, ar.LV[k])


def _tm_neg(ar, s, k, u):
    F = ar.F
    E = F.shape[3] - 1
    for b in range(F.shape[2]):
        Z = F[s, k, b]
        if ar.HV[k]:
            for i in range(E):
                Z[i] = -F[u, k, b, i]
            Z[E] = F[u, k, b, E]
        else:
            _neg_pre(Z, F[u, k, b], ar.LV[k])


def _tm_mul_const(ar, s, k, u, v, ku, kv):
    F = ar.F
    PA, PB, PC = _products(ar, k)
    for b in range(F.shape[2]):
        Z = F[s, k, b]
        if ar.HV[k]:
            _clear(Z)
            _acc_mul(Z, F[u, ku, b], F[v, kv, b], PA, PB, PC, 1.0)
        else:  # (the one term j = ku of the convolution)
            _conv_pre(Z, F, ar.C, u, v, k, ku, ku + 1, 1.0, 0.0, b, ar.LV, ar.HV, ar.q0, np.int64(1))


def _tm_mul(ar, s, k, u, v):
    F = ar.F
    PA, PB, PC = _products(ar, k)
    for b in range(F.shape[2]):
        Z = F[s, k, b]
        if ar.HV[k]:
            _clear(Z)
            for j in range(k + 1):
                _acc_mul(Z, F[u, j, b], F[v, k - j, b], PA, PB, PC, 1.0)
        else:
            _conv_pre(Z, F, ar.C, u, v, k, np.int64(0), k + 1, 1.0, 0.0, b, ar.LV, ar.HV, ar.q0, np.int64(1))


def _tm_sqr(ar, s, k, u):
    F = ar.F
    PA, PB, PC = _products(ar, k)
    for b in range(F.shape[2]):
        Z = F[s, k, b]
        if ar.HV[k]:
            _clear(Z)
            _sqrconv(Z, F, u, k, np.int64(0), b, PA, PB, PC)
        else:
            _sqrconv_pre(Z, F, ar.C, u, k, np.int64(0), b, ar.LV, ar.HV, ar.q0, np.int64(1))


@njit(inline="always")  # (numba inlines it into the rules div and div_const: one body for both)
def _quotient_rule(F, C, REC, T, D, D2, D3, PA, PB, PC, deg, LV, HV, q0, s, k, u, v, series):
    """Slot ``s = u / v`` at order ``k``, every set (the rules ``div``, ``series`` 1, and
    ``div_const``, 0: v constant, its orders >= 1 zero): ``(u_k - sum_{j=1}^{k} v_j s_{k-j})``
    times the reciprocal of ``v_0``, which order 0 computes into ``REC[s]``."""
    lk = LV[k]
    for b in range(F.shape[2]):
        Z = F[s, k, b]
        if HV[k]:
            if k == 0:
                _unary_into(REC[s, b], F[v, 0, b], PA, PB, PC, deg, np.int64(7), D, D2, D3, -INF)
            _clear(T)
            _acc_add(T, F[u, k, b], 1.0)
            if series:
                for j in range(1, k + 1):
                    _acc_mul(T, F[v, j, b], F[s, k - j, b], PA, PB, PC, -1.0)
            _clear(Z)
            _acc_mul(Z, T, REC[s, b], PA, PB, PC, 1.0)
        else:
            _clear_pre(T, lk)
            _acc_add_pre(T, F[u, k, b], 1.0, lk, lk)
            if series:
                _conv_pre(T, F, C, v, s, k, np.int64(1), k + 1, -1.0, 0.0, b, LV, HV, q0, np.int64(0))
            _clear_pre(Z, lk)
            _acc_mul_pre(Z, T, REC[s, b], 1.0, lk, lk, np.int64(0), LV[0], HV[0], q0)


def _tm_div_const(ar, s, k, u, v):
    PA, PB, PC = _products(ar, k)
    _quotient_rule(ar.F, ar.C, ar.REC, ar.T, ar.D, ar.D2, ar.D3, PA, PB, PC, ar.deg, ar.LV, ar.HV, ar.q0,
                   s, k, u, v, np.int64(0))


def _tm_div(ar, s, k, u, v):
    PA, PB, PC = _products(ar, k)
    _quotient_rule(ar.F, ar.C, ar.REC, ar.T, ar.D, ar.D2, ar.D3, PA, PB, PC, ar.deg, ar.LV, ar.HV, ar.q0,
                   s, k, u, v, np.int64(1))


def _tm_sqrt0(ar, s, u):
    F = ar.F
    PA, PB, PC = _products(ar, np.int64(0))
    for b in range(F.shape[2]):
        Z = F[s, 0, b]
        _unary_into(Z, F[u, 0, b], PA, PB, PC, ar.deg, np.int64(0), ar.D, ar.D2, ar.D3, -INF)
        _scale_into(ar.T, Z, 2.0)
        _unary_into(ar.REC[s, b], ar.T, PA, PB, PC, ar.deg, np.int64(7), ar.D, ar.D2, ar.D3, -INF)


def _tm_sqrt(ar, s, k, u):
    F = ar.F
    T = ar.T
    S = ar.S
    lk = ar.LV[k]
    PA, PB, PC = _products(ar, k)
    for b in range(F.shape[2]):
        Z = F[s, k, b]
        if ar.HV[k]:
            _clear(T)
            _acc_add(T, F[u, k, b], 1.0)
            _clear(S)
            _sqrconv(S, F, s, k, np.int64(1), b, PA, PB, PC)
            _acc_add(T, S, -1.0)
            _clear(Z)
            _acc_mul(Z, T, ar.REC[s, b], PA, PB, PC, 1.0)
        else:
            _sqrconv_pre(S, F, ar.C, s, k, np.int64(1), b, ar.LV, ar.HV, ar.q0, np.int64(1))
            _add_pre(T, F[u, k, b], S, -1.0, lk)
            _clear_pre(Z, lk)
            _acc_mul_pre(Z, T, ar.REC[s, b], 1.0, lk, lk, np.int64(0), ar.LV[0], ar.HV[0], ar.q0)


def _tm_exp0(ar, s, u):
    F = ar.F
    PA, PB, PC = _products(ar, np.int64(0))
    for b in range(F.shape[2]):
        _unary_into(F[s, 0, b], F[u, 0, b], PA, PB, PC, ar.deg, np.int64(1), ar.D, ar.D2, ar.D3, -INF)


def _tm_exp(ar, s, k, u):
    F = ar.F
    T = ar.T
    fk = float(k)
    PA, PB, PC = _products(ar, k)
    for b in range(F.shape[2]):
        Z = F[s, k, b]
        if ar.HV[k]:
            _clear(T)
            for j in range(1, k + 1):
                _acc_mul(T, F[u, j, b], F[s, k - j, b], PA, PB, PC, float(j))
            _div_int_into(Z, T, fk)
        else:
            _conv_pre(T, F, ar.C, u, s, k, np.int64(1), k + 1, 0.0, 1.0, b, ar.LV, ar.HV, ar.q0, np.int64(1))
            _div_int_pre(Z, T, fk, ar.LV[k])


def _tm_log0(ar, s, u):
    F = ar.F
    PA, PB, PC = _products(ar, np.int64(0))
    for b in range(F.shape[2]):
        _unary_into(F[s, 0, b], F[u, 0, b], PA, PB, PC, ar.deg, np.int64(2), ar.D, ar.D2, ar.D3, -INF)
        _unary_into(ar.REC[s, b], F[u, 0, b], PA, PB, PC, ar.deg, np.int64(7), ar.D, ar.D2, ar.D3, -INF)


def _tm_log(ar, s, k, u):
    F = ar.F
    PA, PB, PC = _products(ar, k)
    for b in range(F.shape[2]):
        if ar.HV[k]:
            _quotient_step(F[s, k, b], F, s, u, u, k, b, PA, PB, PC, ar.REC[s, b], ar.T, ar.S)
        else:
            _quotient_step_pre(F[s, k, b], F, ar.C, s, u, u, k, b, ar.REC[s, b], ar.T, ar.S, ar.LV, ar.HV, ar.q0)


def _tm_sincos0(ar, ss, cs, u):
    F = ar.F
    PA, PB, PC = _products(ar, np.int64(0))
    for b in range(F.shape[2]):
        _unary_into(F[ss, 0, b], F[u, 0, b], PA, PB, PC, ar.deg, np.int64(3), ar.D, ar.D2, ar.D3, -INF)
        _unary_into(F[cs, 0, b], F[u, 0, b], PA, PB, PC, ar.deg, np.int64(4), ar.D, ar.D2, ar.D3, -INF)


def _tm_sincos(ar, ss, cs, k, u):
    F = ar.F
    T = ar.T
    fk = float(k)
    PA, PB, PC = _products(ar, k)
    for b in range(F.shape[2]):
        if ar.HV[k]:
            _clear(T)
            for j in range(1, k + 1):
                _acc_mul(T, F[u, j, b], F[cs, k - j, b], PA, PB, PC, float(j))
            _div_int_into(F[ss, k, b], T, fk)
            _clear(T)
            for j in range(1, k + 1):
                _acc_mul(T, F[u, j, b], F[ss, k - j, b], PA, PB, PC, -float(j))
            _div_int_into(F[cs, k, b], T, fk)
        else:
            _conv_pre(T, F, ar.C, u, cs, k, np.int64(1), k + 1, 0.0, 1.0, b, ar.LV, ar.HV, ar.q0, np.int64(1))
            _div_int_pre(F[ss, k, b], T, fk, ar.LV[k])
            _conv_pre(T, F, ar.C, u, ss, k, np.int64(1), k + 1, 0.0, -1.0, b, ar.LV, ar.HV, ar.q0, np.int64(1))
            _div_int_pre(F[cs, k, b], T, fk, ar.LV[k])


def _tm_tan0(ar, s, vs, u):
    F = ar.F  # vs: v = 1 + tan^2 = tan'
    PA, PB, PC = _products(ar, np.int64(0))
    for b in range(F.shape[2]):
        Z = F[s, 0, b]
        _unary_into(Z, F[u, 0, b], PA, PB, PC, ar.deg, np.int64(5), ar.D, ar.D2, ar.D3, -INF)
        V = F[vs, 0, b]
        _clear(V)
        V[0] = 1.0
        _acc_mul(V, Z, Z, PA, PB, PC, 1.0)


def _tm_tan(ar, s, vs, k, u):
    F = ar.F
    T = ar.T
    fk = float(k)
    PA, PB, PC = _products(ar, k)
    for b in range(F.shape[2]):
        Z = F[s, k, b]
        V = F[vs, k, b]
        if ar.HV[k]:
            _clear(T)
            for j in range(1, k + 1):
                _acc_mul(T, F[u, j, b], F[vs, k - j, b], PA, PB, PC, float(j))
            _div_int_into(Z, T, fk)
            _clear(V)
            _sqrconv(V, F, s, k, np.int64(0), b, PA, PB, PC)
        else:
            _conv_pre(T, F, ar.C, u, vs, k, np.int64(1), k + 1, 0.0, 1.0, b, ar.LV, ar.HV, ar.q0, np.int64(1))
            _div_int_pre(Z, T, fk, ar.LV[k])
            _sqrconv_pre(V, F, ar.C, s, k, np.int64(0), b, ar.LV, ar.HV, ar.q0, np.int64(1))


def _tm_atan0(ar, s, vs, u):
    F = ar.F  # vs: v = 1 + u^2, atan(u)' = u' / v
    PA, PB, PC = _products(ar, np.int64(0))
    for b in range(F.shape[2]):
        _unary_into(F[s, 0, b], F[u, 0, b], PA, PB, PC, ar.deg, np.int64(6), ar.D, ar.D2, ar.D3, -INF)
        V = F[vs, 0, b]
        _clear(V)
        V[0] = 1.0
        _acc_mul(V, F[u, 0, b], F[u, 0, b], PA, PB, PC, 1.0)
        _unary_into(ar.REC[s, b], V, PA, PB, PC, ar.deg, np.int64(7), ar.D, ar.D2, ar.D3, 1.0)  # v0 >= 1


def _tm_atan(ar, s, vs, k, u):
    F = ar.F
    PA, PB, PC = _products(ar, k)
    for b in range(F.shape[2]):
        Z = F[s, k, b]
        V = F[vs, k, b]
        if ar.HV[k]:
            _clear(V)
            _sqrconv(V, F, u, k, np.int64(0), b, PA, PB, PC)
            _quotient_step(Z, F, s, u, vs, k, b, PA, PB, PC, ar.REC[s, b], ar.T, ar.S)
        else:
            _sqrconv_pre(V, F, ar.C, u, k, np.int64(0), b, ar.LV, ar.HV, ar.q0, np.int64(1))
            _quotient_step_pre(Z, F, ar.C, s, u, vs, k, b, ar.REC[s, b], ar.T, ar.S, ar.LV, ar.HV, ar.q0)


def _tm_slot_done(ar, s, k):
    """The pool: a remainder born in slot ``s`` becomes the coefficient of a symbol of its
    own (zero in every input: nothing upstream carries it), so the operations downstream
    carry it linearly, with its cancellations."""
    o = ar.op[s]
    if k >= ar.pool_orders or ar.pool0 < 0 or o == T_INPUT or o == T_PARAM or o == T_CONST or o == T_MID:
        return
    F = ar.F
    E = F.shape[3] - 1
    used = ar.used
    for b in range(F.shape[2]):
        if used[b] < ar.pool_n:
            Z = F[s, k, b]
            if ar.HV[k]:
                mag = 0.0  # sum |Z[1:E]| in index order from 0.0, as numpy's sum in numba (no allocation)
                for i in range(1, E):
                    mag += abs(Z[i])
            else:
                mag = _abs_sum(Z, 1, ar.LV[k])
            if Z[E] > ar.pool_tol * (mag + abs(Z[0])) and Z[E] < np.inf:
                Z[1 + ar.pool0 + used[b]] = Z[E]
                Z[E] = 0.0
                ar.C[s, k, b, 0] = -1.0  # (its sums change)
                used[b] += 1


def _tm_integrate(ar, i, o, k):
    F = ar.F
    E = F.shape[3] - 1
    n = ar.out.shape[0]
    fk = float(k)
    for b in range(F.shape[2]):
        Y = ar.out[i, k + 1, b]
        if ar.HV[k]:
            _div_int_into(Y, F[o, k, b], fk + 1.0)
            if not ar.HV[k + 1]:
                _sweep_nonlinear(Y, ar.q0)  # (x_[linear_orders]: its block into the remainder)
        else:
            _div_int_pre(Y, F[o, k, b], fk + 1.0, ar.LV[k])
        if ar.fresh0 >= 0:
            # e [-1, 1] = e delta: exact, and later orders carry delta linearly
            Y[1 + ar.fresh0 + k * n + i] = Y[E]
            Y[E] = 0.0


register(ModelTable, **rules_named(globals(), "_tm_"))


@njit(cache=True)
def _model_kernel(op, a0, a1, aux, idx, cst, clo, chi, outputs, X, P, order, PA, PB, PC, deg, fresh0, F, REC,
                  pool0=-1, pool_n=0, pool_tol=0.0, pool_orders=1, product_orders=-1, q0=-1, linear_orders=-1):
    """Taylor models of x_[0..order]; X (n, B, L) and P (p, B, L) are the input models:
    the recursion (:mod:`verified.series.recursion`) with the model table
    (:class:`ModelTable`, rules ``_tm_*``).

    ``F`` (slots, order + 1, B, L) and ``REC`` (slots, B, L) are the caller's work
    arrays, any contents: every entry the loop reads is written first, except the
    orders >= 1 of constant slots, which are zeroed here. (Fresh arrays per call cost
    page faults, a large share of the kernel's time on robots; docs/lab/code_notes.md.)

    Returns (n, order + 1, B, L). ``fresh0 >= 0``: the remainder of ``x_[k]_i`` (k >= 1)
    moves into the linear coefficient of symbol ``fresh0 + (k - 1) n + i`` (zero in the
    inputs; see :meth:`TaylorModelODE._run`); ``pool0 >= 0``: the pool (``_tm_slot_done``).

    ``linear_orders >= 1`` (with ``q0``, the storage index of the first nonlinear
    coefficient): the orders ``k >= linear_orders`` keep no nonlinear coefficients
    (:attr:`TaylorModelODE.linear_orders`; their products must keep no pairs,
    ``product_orders <= linear_orders``, which the caller checks): their models are
    nonzero only in the prefix ``LV[k]`` of the linear part (with ``fresh0 >= 0`` the
    fresh symbols of the orders above k are exact zeros) and the remainder, their
    operations read and write only those (:func:`_acc_mul_pre`), and ``x_[linear_orders]``
    has its nonlinear block swept into its remainder before its fresh symbol takes it.
    The lower orders' models are whole (``LV`` = q0, ``HV`` = 1)."""
    nslots = op.size
    n, nb, L = X.shape
    LV = np.empty(order + 1, np.int64)
    HV = np.empty(order + 1, np.int64)
    for k in range(order + 1):
        lin = linear_orders >= 1 and k >= linear_orders and q0 >= 0
        LV[k] = (min(q0, 1 + fresh0 + k * n) if fresh0 >= 0 else q0) if lin else max(q0, 0)
        HV[k] = 0 if lin else 1
    # (REC[s, b], the reciprocal of slot s's order-0 divisor, is written before it is read)
    for s in range(nslots):
        if cst[s]:  # a constant's coefficients >= 1 are read as exact zeros
            for k in range(1, order + 1):
                for b in range(nb):
                    if HV[k]:
                        _clear(F[s, k, b])
                    else:
                        _clear_pre(F[s, k, b], LV[k])
    out = np.zeros((n, order + 1, nb, L))
    for i in range(n):  # (a loop: a slice assignment compiles numba's broadcasting errors)
        for b in range(nb):
            for j in range(L):
                out[i, 0, b, j] = X[i, b, j]
    ar = ModelTable(F, REC, out, P, np.full((nslots, order + 1, nb, 2), -1.0), np.zeros(L), np.zeros(L),
                    np.zeros(L), np.zeros(L), np.zeros(L), np.zeros(nb, dtype=np.int64), PA, PB, PC,
                    PA[:0].copy(), PB[:0].copy(), PC[:0].copy(), LV, HV, op, deg, q0, fresh0, pool0, pool_n,
                    pool_tol, pool_orders, product_orders)
    recursion(op, a0, a1, aux, idx, cst, clo, chi, outputs, order, ar)
    return out


# --------------------------------------------------------------------------
# Affine forms / boxes <-> models <-> intervals
# --------------------------------------------------------------------------
def forms_to_models(F: np.ndarray, mq: int, m3: int = 0, m4: int = 0, ms: int = 0,
                    ns: int | None = None) -> np.ndarray:
    """Affine forms ``(..., m + 2)`` (centre, ``m`` symbols, error radius) as models with
    zero quadratic, cubic, quartic and star parts, ``(..., L)``."""
    m = F.shape[-1] - 2
    out = np.zeros(F.shape[:-1] + (model_length(m, mq, m3, m4, ms, ns),))
    out[..., : m + 1] = F[..., : m + 1]
    out[..., -1] = F[..., -1]
    return out


@functools.lru_cache(maxsize=64)
def _diagonal_mask(mq: int, length: int) -> np.ndarray:
    """Read-only mask over a model's ``length`` coefficients past the linear ones: True
    at the quadratic diagonal ``eps_i^2`` (storage order of :func:`_pairs`)."""
    pi, pj = _pairs(mq)
    diag = np.zeros(length, dtype=bool)
    diag[: pi.size] = (pi == pj)
    diag.flags.writeable = False
    return diag


@functools.lru_cache(maxsize=64)
def _diagonal_split(mq: int, length: int) -> tuple[np.ndarray, np.ndarray]:
    """Positions (int64, increasing) of the quadratic diagonal and of every other
    coefficient among a model's ``length`` coefficients past the linear ones: the
    elements ``Q[..., diag]`` and ``Q[..., ~diag]`` of :func:`_diagonal_mask`, in order."""
    diag = _diagonal_mask(mq, length)
    on, off = np.flatnonzero(diag), np.flatnonzero(~diag)
    on.flags.writeable = False
    off.flags.writeable = False
    return on, off


@njit(cache=True)
def _pairwise_block(a, s, n):
    """numpy's pairwise sum of ``a[s:s + n]`` for ``n <= 128`` (its leaf): below 8 terms
    one by one from 0, else 8 running sums combined as ((r0 + r1) + (r2 + r3)) + ((r4 +
    r5) + (r6 + r7)), then the tail one by one."""
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[s + i]
        return res
    r0, r1, r2, r3 = a[s], a[s + 1], a[s + 2], a[s + 3]
    r4, r5, r6, r7 = a[s + 4], a[s + 5], a[s + 6], a[s + 7]
    stop = n - (n % 8)
    i = 8
    while i < stop:
        r0 += a[s + i]
        r1 += a[s + i + 1]
        r2 += a[s + i + 2]
        r3 += a[s + i + 3]
        r4 += a[s + i + 4]
        r5 += a[s + i + 5]
        r6 += a[s + i + 6]
        r7 += a[s + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[s + i]
        i += 1
    return res


@njit(cache=True)
def _pairwise_sum(a, n):
    """``a[:n].sum()`` bit for bit as numpy sums a contiguous float64 row: 0 plus its
    pairwise sum (a block of up to 128 by :func:`_pairwise_block`, a longer one as its
    two halves, the first a multiple of 8 long, added). Without recursion (a recursive
    function loaded from numba's cache crashed): the halves on an explicit stack."""
    if n <= 128:
        return 0.0 + _pairwise_block(a, np.int64(0), n)
    st = np.empty(64, np.int64)   # block starts
    ln = np.empty(64, np.int64)   # block lengths
    ph = np.empty(64, np.int64)   # 0: left half next, 1: right half next, 2: add them
    vals = np.empty(64)
    top = 0
    nv = 0
    st[0], ln[0], ph[0] = 0, n, 0  # (stores, not calls: no literal typing)
    while top >= 0:
        s, k = st[top], ln[top]
        if k <= 128:
            vals[nv] = _pairwise_block(a, s, k)
            nv += 1
            top -= 1
            continue
        k2 = k // 2
        k2 -= k2 % 8
        if ph[top] == 0:
            ph[top] = 1
            top += 1
            st[top], ln[top], ph[top] = s, k2, 0
        elif ph[top] == 1:
            ph[top] = 2
            top += 1
            st[top], ln[top], ph[top] = s + k2, k - k2, 0
        else:
            nv -= 1
            vals[nv - 1] = vals[nv - 1] + vals[nv]
            top -= 1
    return 0.0 + vals[0]


@njit(cache=True)
def _models_to_interval_rows(F, m, on, off, pairwise_masked, lo, hi):
    """:func:`_models_to_interval_np` on models ``F`` (R, L), C-contiguous, into ``lo``,
    ``hi`` (R,): the same float operations in the same order. The sums over the
    linear coefficients are numpy's pairwise sums of contiguous rows; those over the
    diagonal and the other quadratic-and-higher coefficients are over numpy's masked
    copies, whose memory puts the row index innermost: one term after the other from
    0 when there is more than one row (``pairwise_masked`` False), pairwise for one row."""
    R, L = F.shape
    buf = np.empty(max(m, on.size, off.size, 1))
    q0 = m + 1
    for r in range(R):
        for j in range(m):
            buf[j] = abs(F[r, 1 + j])
        s_lin = _pairwise_sum(buf, m)
        if pairwise_masked:
            for j in range(off.size):
                buf[j] = abs(F[r, q0 + off[j]])
            s_off = _pairwise_sum(buf, off.size)
            for j in range(on.size):
                x = F[r, q0 + on[j]]
                buf[j] = x if (x > 0.0 or x != x) else 0.0
            s_pos = _pairwise_sum(buf, on.size)
            for j in range(on.size):
                x = -F[r, q0 + on[j]]
                buf[j] = x if (x > 0.0 or x != x) else 0.0
            s_neg = _pairwise_sum(buf, on.size)
        else:
            s_off = 0.0
            for j in range(off.size):
                s_off += abs(F[r, q0 + off[j]])
            s_pos = 0.0
            s_neg = 0.0
            for j in range(on.size):
                x = F[r, q0 + on[j]]
                s_pos += x if (x > 0.0 or x != x) else 0.0
                x = -x
                s_neg += x if (x > 0.0 or x != x) else 0.0
        rr = (s_lin + s_off) * _UPF + _TINY
        pos = s_pos * _UPF + _TINY
        neg = s_neg * _UPF + _TINY
        e = F[r, L - 1]
        c = F[r, 0]
        l = c - ((rr + neg + e) * _UPF + _TINY)
        h = c + ((rr + pos + e) * _UPF + _TINY)
        l = l - (abs(l) * _k.EPS + _k.ETA)
        h = h + (abs(h) * _k.EPS + _k.ETA)
        if l != l or h != h:
            l = -INF
            h = INF
        lo[r] = l
        hi[r] = h


def models_to_interval(F: np.ndarray, m: int, mq: int) -> tuple[np.ndarray, np.ndarray]:
    """Interval ranges of models ``(..., L)`` (rounded outward); NaN gives ``[-inf, inf]``.

    ``eps_i^2`` lies in ``[0, 1]``, so a diagonal coefficient ``q_ii`` moves only one
    bound; every other monomial (cubic, quartic and star ones included, after the
    quadratic ones) lies in ``[-1, 1]``.

    One compiled pass (:func:`_models_to_interval_rows`) that gives bit for bit what
    the numpy expression :func:`_models_to_interval_np` gives (its sums in numpy's
    order); that expression for models whose memory is not in row order (numpy's sums
    follow the memory layout)."""
    L = F.shape[-1]
    lead = F.shape[:-1]
    if (F.dtype != np.float64 or F.ndim < 1 or L < m + 2 or F.size == 0
            or not _row_ordered(F)):
        return _models_to_interval_np(F, m, mq)
    on, off = _diagonal_split(mq, L - m - 2)
    F2 = np.ascontiguousarray(F).reshape(-1, L)
    lo = np.empty(F2.shape[0])
    hi = np.empty(F2.shape[0])
    _models_to_interval_rows(F2, int(m), on, off, F2.shape[0] == 1, lo, hi)
    return lo.reshape(lead), hi.reshape(lead)


def _row_ordered(F: np.ndarray) -> bool:
    """Whether ``np.abs(F)`` is C-contiguous (numpy keeps the operand's layout): the
    strides of the axes longer than 1 decrease (a C-contiguous array or a slice of one)."""
    st = [s for s, d in zip(F.strides, F.shape) if d > 1]
    return all(a > b > 0 for a, b in zip(st, st[1:])) and (not st or st[-1] > 0)


def _models_to_interval_np(F: np.ndarray, m: int, mq: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`models_to_interval` as numpy expressions (the reference of the compiled pass,
    and its fallback for models in another memory order)."""
    diag = _diagonal_mask(mq, F.shape[-1] - m - 2)
    c = F[..., 0]
    with np.errstate(invalid="ignore", over="ignore"):
        Q = F[..., m + 1: -1]
        qd = Q[..., diag]
        R = (np.abs(F[..., 1: m + 1]).sum(axis=-1) + np.abs(Q[..., ~diag]).sum(axis=-1)) * _UPF + _TINY
        pos = np.maximum(qd, 0.0).sum(axis=-1) * _UPF + _TINY
        neg = np.maximum(-qd, 0.0).sum(axis=-1) * _UPF + _TINY
        e = F[..., -1]
        lo = c - ((R + neg + e) * _UPF + _TINY)
        hi = c + ((R + pos + e) * _UPF + _TINY)
        lo = lo - (np.abs(lo) * _k.EPS + _k.ETA)
        hi = hi + (np.abs(hi) * _k.EPS + _k.ETA)
    bad = np.isnan(lo) | np.isnan(hi)
    return np.where(bad, -np.inf, lo), np.where(bad, np.inf, hi)


def _memory_bytes() -> float:
    """Physical memory of this machine in bytes (inf where the OS does not say)."""
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return math.inf


class TaylorModelODE:
    """Taylor-coefficient enclosures like :class:`verified.series.affine_taylor.AffineTaylorODE`,
    computed in Taylor models of degree 2, 3 or 4 over the symbols of the inputs.

    ``quadratic_symbols``: at most this many symbols (the first ones: a set's own
    parameters come first in :meth:`verified.sets.first_order.DoubletonSets.affine_forms`) get
    quadratic monomials; the others stay linear. Cost per product grows as its square.
    ``cubic_symbols``: at most this many of those also get cubic monomials (0: degree 2);
    cost per product grows as its cube, and on robots the remainder falls by an order
    of magnitude or more from degree 2 (docs/lab/code_notes.md).
    ``quartic_symbols``: at most this many of the cubic ones also get quartic monomials
    (0: degree 3 or less); cost per product grows as its fourth power.
    ``star_symbols``: at most this many of the quadratic ones also get star monomials
    with every symbol past the quadratic ones (module docstring); cost per product
    grows as its product with the number of symbols.
    One box at a time (no batching over boxes inside the kernel): meant for few sets of
    deep graphs (robots), where the affine kernel's batching gains little.
    """

    #: a set's forms should give every parameter a symbol of its own (the linear part
    #: costs O(m) per operation; the quadratic monomials go to the widest ones)
    all_symbols = True
    #: the recursion's orders ``k >= product_orders`` (the coefficients ``x_[k+1]`` and
    #: up) keep no product of two non-constant monomials: ``_acc_mul`` bounds each such
    #: pair by ``|x_a| |y_b|`` into the remainder, as it does for any pair past the
    #: model's degree (sound at any value; -1 keeps them at every order). Those
    #: coefficients enter a step multiplied by ``h^(k+1)``, so their quadratic parts
    #: hardly matter, while the kept products' gather and scatter are a large share of a
    #: product's cost (measured in docs/lab/robot_speed.md)
    product_orders = 5
    #: the recursion's orders ``k >= linear_orders`` (and ``>= product_orders``, ``>= 1``)
    #: drop their models' nonlinear coefficients: centre, linear part and remainder only
    #: (-1: never; so too with ``product_orders`` -1). With no pair kept those coefficients
    #: are only the centres' multiples of the lower orders' blocks; instead every
    #: product's centre times an operand's block goes into the remainder, and
    #: ``x_[linear_orders]``'s own block too (its fresh symbol then takes it), while the
    #: loops skip the blocks and the later orders' fresh symbols, one fused pass per
    #: convolution (:func:`_conv_pre`). One order past ``product_orders``: on the UR5 the
    #: kernel costs 14-19 % less a call, and the widths at T = 1 are those of whole models
    #: to 0.3 % (at ``product_orders`` itself: 0.5 % wider, 3 steps more; measured in
    #: docs/lab/robot_speed.md)
    linear_orders = 6

    def __init__(self, graph, quadratic_symbols: int = QUADRATIC_SYMBOLS, cubic_symbols: int = 0,
                 quartic_symbols: int = 0, star_symbols: int = 0):
        if graph.n_outputs != graph.n_inputs:
            raise ValueError(
                f"an ODE right-hand side needs as many outputs as inputs, got {graph.n_inputs} "
                f"inputs and {graph.n_outputs} outputs"
            )
        q = int(quadratic_symbols)
        if q < 0:
            raise ValueError(f"quadratic_symbols must be >= 0, got {quadratic_symbols!r}")
        c3 = int(cubic_symbols)
        if c3 < 0:
            raise ValueError(f"cubic_symbols must be >= 0, got {cubic_symbols!r}")
        self.cubic_symbols = c3
        c4 = int(quartic_symbols)
        if c4 < 0:
            raise ValueError(f"quartic_symbols must be >= 0, got {quartic_symbols!r}")
        self.quartic_symbols = c4
        cs = int(star_symbols)
        if cs < 0:
            raise ValueError(f"star_symbols must be >= 0, got {star_symbols!r}")
        self.star_symbols = cs
        self.graph = graph
        self.n = graph.n_inputs
        self.n_params = graph.n_params
        self.quadratic_symbols = q
        self._tape = _Tape(graph)

    def symbol_caps(self, m: int) -> tuple[int, int, int, int]:
        """``(mq, m3, m4, ms)``: the symbols with quadratic, cubic, quartic and star
        monomials in a model over ``m``."""
        mq = min(m, self.quadratic_symbols)
        m3 = min(mq, self.cubic_symbols)
        return mq, m3, min(m3, self.quartic_symbols), min(mq, self.star_symbols)

    def _run(self, X, P, order, m, mq, m3=0, m4=0, ms=0, ns=None, fresh=False, pool=0, pool_tol=1e-8, pool_orders=1):
        """The kernel on input models ``X`` (n, B, L) and parameter models ``P`` (p, B, L),
        ``L = model_length(m, mq, m3, m4, ms, ns)``: (n, order + 1, B, L).

        ``fresh``: the last ``n order`` of the ``m`` symbols are fresh, one per state and
        order (zero in ``X`` and ``P``): the remainder of each ``x_[k]_i`` becomes the
        coefficient of its own symbol once computed, so the later orders carry it
        linearly (its cancellations kept) instead of bounding it through every
        operation. Sound as affine arithmetic's fresh symbols are: the true coefficient
        is the polynomial at some value of that symbol in ``[-1, 1]``.

        ``pool``: the ``pool`` symbols before the fresh ones (or last, without them),
        zero in ``X`` and ``P``, are handed out at the orders ``k < pool_orders`` (default:
        order 0 only), in order of computation (order by order, each in the tape's order),
        to the slots whose remainder exceeds ``pool_tol`` times their model's magnitude
        (per set, until the pool runs out): that remainder becomes the
        coefficient of the slot's own symbol, so every operation downstream carries it
        linearly and its cancellations are kept. A remainder born in one product and
        spread over many results (a bias force transmitted to every joint's torque, then
        the mass-matrix solve's preconditioned rows) then cancels where the values do,
        instead of adding up as independent radii (docs/lab/code_notes.md). Sound for the
        same reason as ``fresh``: a slot's true value is its polynomial plus ``e delta``
        for some ``delta`` in ``[-1, 1]``, which every later operation treats as a symbol.
        The orders without kept products: :attr:`product_orders`."""
        t = self._tape
        PA, PB, PC = product_table(m, mq, m3, m4, ms, ns)
        L = model_length(m, mq, m3, m4, ms, ns)
        if X.shape[-1] != L or P.shape[-1] != L:
            raise ValueError(f"models of length {L} expected for {m} symbols ({mq} quadratic, {m3} cubic, "
                             f"{m4} quartic, {ms} star), got {X.shape[-1]} and {P.shape[-1]}")
        # (the first symbol with linear terms only: the fresh and pool symbols must be past it)
        linear_only = mq + star_span(m, mq, ns if ms else 0)
        fresh0 = m - self.n * int(order) if fresh else -1
        if fresh and fresh0 < linear_only:
            raise ValueError(f"{self.n * int(order)} fresh symbols among {m} overlap the {mq} quadratic ones "
                             f"or the star's")
        pool0 = (fresh0 if fresh else m) - int(pool) if pool else -1
        if pool and pool0 < linear_only:
            raise ValueError(f"{int(pool)} pool symbols among {m} overlap the {mq} quadratic ones or the star's")
        F, REC = self._work(t.op.size, int(order), X.shape[1], L)
        po = int(self.product_orders)
        # (the linear orders keep no products: product_orders <= linear_orders)
        lo = int(self.linear_orders)
        linear_orders = max(lo, po, 1) if (lo >= 0 and po >= 0) else -1
        return _model_kernel(t.op, t.a0, t.a1, t.aux, t.idx, t.cst, t.clo, t.chi, t.outputs,
                             np.ascontiguousarray(X), np.ascontiguousarray(P), int(order), PA, PB, PC,
                             4 if m4 > 0 else (3 if m3 > 0 else 2), fresh0, F, REC,
                             pool0, int(pool), float(pool_tol), int(pool_orders), po, int(m) + 1, linear_orders)

    def __getstate__(self):
        # the kernel's work memory is scratch (tens to hundreds of MB): not pickled
        state = self.__dict__.copy()
        state.pop("_work_buffers", None)
        return state

    def _work(self, slots: int, order: int, nb: int, L: int):
        """The kernel's work arrays, C-contiguous views of buffers kept between calls
        and grown as needed (the model length changes as a set gains parameters). Safe
        to share: the kernel holds the GIL and returns fresh arrays."""
        shape = (slots, order + 1, nb, L)
        sizes = (int(np.prod(shape)), slots * nb * L)
        bufs = getattr(self, "_work_buffers", None)
        if bufs is None or bufs[0].size < sizes[0] or bufs[1].size < sizes[1]:
            grown = (int(sizes[0] * 1.25), int(sizes[1] * 1.25))
            need, have = 8.0 * sum(grown), _memory_bytes()
            if need > have:  # (a one-line error naming the sizes, not numpy's allocation failure)
                raise MemoryError(
                    f"the Taylor-model kernel needs {need / 2**30:.1f} GiB of work memory ({nb} sets x {slots} "
                    f"graph slots x order {order} x models of {L} coefficients), more than this machine's "
                    f"{have / 2**30:.1f} GiB: fewer sets per batch (chunks=), fewer symbols "
                    f"(params_per_state, model_caps) or a lower order")
            bufs = (np.empty(grown[0]), np.empty(grown[1]))
            self._work_buffers = bufs
        return bufs[0][:sizes[0]].reshape(shape), bufs[1][:sizes[1]].reshape((slots, nb, L))

    def _interval(self, out, m, mq):
        lo, hi = models_to_interval(out, m, mq)  # (n, K + 1, B)
        return Interval._from_bounds(np.ascontiguousarray(lo.transpose(2, 1, 0)),
                                     np.ascontiguousarray(hi.transpose(2, 1, 0)))

    def series(self, X, order, params=None, *, caps=None, fresh=False, pool=0) -> Interval:
        """Interval enclosures of ``x_[0..order]`` from input affine forms ``X``
        (n, B, m + 2) over ``m`` symbols of the caller's choosing (a set's own
        parameters first). Parameters are intervals without symbols. (B, order + 1, n).

        ``caps``: ``(mq, m3, m4, ms)`` for these forms instead of :meth:`symbol_caps`
        (each at most ``m``). ``fresh``: the recursion with fresh symbols per
        coefficient (:meth:`_run`), appended after the ``m`` symbols; ``pool``: that many
        symbols before them for the remainders born inside the graph at order 0
        (:meth:`_run`'s ``pool``)."""
        n, nb, m2 = X.shape
        if n != self.n:
            raise ValueError(f"forms must have shape ({self.n}, B, m + 2), got {X.shape}")
        if self.n_params and params is None:
            raise ValueError(f"the graph has {self.n_params} parameters: series needs their box")
        m = m2 - 2
        mq, m3, m4, ms = self.symbol_caps(m) if caps is None else (min(int(k), m) for k in caps)
        # the widest symbols (over the batch) first: they get the quadratic monomials
        widths = np.abs(X[:, :, 1: m + 1]).sum(axis=0).max(axis=0)
        perm = np.argsort(-widths, kind="stable")
        extra = (self.n * int(order) if fresh else 0) + int(pool)  # fresh and pool symbols, zero in the inputs
        X = np.concatenate([X[:, :, :1], X[:, :, 1: m + 1][:, :, perm], np.zeros((n, nb, extra)), X[:, :, m + 1:]],
                           axis=2)
        m += extra
        Xm = forms_to_models(X, mq, m3, m4, ms)
        P = np.zeros((self.n_params, nb, model_length(m, mq, m3, m4, ms)))
        if self.n_params:
            p = _as_interval(params).broadcast_to((nb, self.n_params))
            P = forms_to_models(box_forms(p.lo, p.hi, np.full(self.n_params, -1), m), mq, m3, m4, ms)
        return self._interval(self._run(Xm, P, int(order), m, mq, m3, m4, ms, fresh=bool(fresh), pool=int(pool)), m, mq)

    def coefficients(self, x, order, params=None) -> Interval:
        """Interval enclosures of ``x_[0..order]`` over boxes ``x`` (B, n) (one symbol
        per wide input or parameter), shape (B, order + 1, n)."""
        order = int(order)
        if order < 1:
            raise ValueError(f"order must be >= 1, got {order}")
        X, P, m = _wide_symbol_forms(self.graph, x, params, extra=0)
        mq, m3, m4, ms = self.symbol_caps(m)
        return self._interval(self._run(forms_to_models(X, mq, m3, m4, ms), forms_to_models(P, mq, m3, m4, ms),
                                        order, m, mq, m3, m4, ms), m, mq)

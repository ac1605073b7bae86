# Whole: its numba kernels and their helpers are one compilation unit.
"""Taylor coefficients of ODE solutions in affine arithmetic over the box's own symbols.

Plain interval evaluation of a deep model graph (a robot's crba/rnea followed by an
elimination) over a box forgets that every intermediate depends on the same few
initial values, and through the Taylor recursion that loss compounds order by order:
the high coefficients come out orders of magnitude wider than their values at the
centre (docs/lab/code_notes.md). Here every coefficient of every tape slot is an
*affine form* in ``m`` noise symbols ``eps_i in [-1, 1]`` (kv's affine ODE solver;
Comba & Stolfi's affine arithmetic)::

    x  =  c + sum_i a_i eps_i + [-e, e]

with a float centre ``c``, float coefficients ``a_i`` and a rigorous error radius
``e >= 0``. Linear dependence on the symbols is carried exactly, so only
second-order terms and rounding are bounded; the symbols are the wide inputs (and
wide parameters) of the box, ``x_j = mid_j + rad_j eps_j``.

Rules (``R_x = sum |a_i|``, all error sums rounded upward, see :func:`_up`):

* ``x + y``, ``x - y``, ``x / k``: term by term; each float rounding enters ``e``.
* ``x * y = c_x c_y + sum (c_x b_i + c_y a_i) eps_i`` with
  ``e = (R_x + e_x)(R_y + e_y) + |c_x| e_y + |c_y| e_x``.
* ``x^2``: the quadratic part ``(l + d)^2`` lies in ``[0, (R_x + e_x)^2]``: half of
  that moves into the centre, half into ``e``, plus ``2 |c_x| e_x``.
* ``f(x)`` for ``f`` in sqrt, exp, log, sin, cos, tan, atan and ``1/x`` (order 0 of
  every recurrence): the mean-value form about the centre, ``f(c) + d (x - c) +
  (f'(xi) - d)(x - c)`` with ``d`` a float near ``f'(c)``: the coefficients become
  ``d a_i`` and ``e`` gains ``|d| e_x + |f'(X) - d| (R_x + e_x)``, with ``f'(X)`` an
  interval enclosure over the range ``X`` of ``x``. Sound for any ``d``. Where the
  form's error part alone exceeds the plain image ``f(X)`` (wide ranges), the image
  replaces the form.
* Higher orders use the same recurrences as :mod:`verified.series.taylor` built from these
  operations (division by a series through the reciprocal of its order-0 form).

An overflow or a domain violation (log of a form whose range reaches 0) makes ``e``
infinite; a NaN anywhere turns the output into ``[-inf, inf]``, never into a finite
interval. :func:`forms_to_interval` gives the interval ranges.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from verified.arith import _kernels as _k
from verified.arith.interval import Interval, _as_interval
from verified.series.recursion import recursion, register, rules_named
from verified.series.taylor import (
    T_ADD, T_ATAN, T_AUX, T_CONST, T_COS, T_DIV, T_EXP, T_INPUT, T_LOG, T_MID, T_MUL, T_NEG, T_PARAM, T_SIN, T_SQR,
    T_SQRT, T_SUB, T_TAN, _Tape
)

__all__ = ["AffineTaylorODE", "affine_range", "forms_to_interval", "box_forms"]

_UPF = 1.0 + 2.0**-40  # covers the relative rounding of up to 2^12 operations on non-negatives
_TINY = 1e-300  # covers the absolute (underflow) rounding of as many
_U = 2.0**-52  # bound on the relative rounding error of one operation (round to nearest: 2^-53)
INF = math.inf

# Integer constants handed to other compiled functions are written ``np.int64(k)``, not ``k``:
# numba compiles a callee once per distinct integer *literal* argument, so the eight kinds of
# the unary expansion were eight compilations of it and of everything it calls, which
# multiplied a first run's compile time (docs/lab/code_notes.md, compile time).
_NO_SLOTS = np.zeros(0, dtype=np.int64)


@njit(cache=True, inline="always")
def _up(x):
    """An upper bound of a non-negative quantity computed in a few float operations."""
    return x * _UPF + _TINY


@njit(cache=True, inline="always")
def _pm(a, b):
    """Product of two non-negative bounds with 0 * inf = 0 (a zero radius stays exact)."""
    if a == 0.0 or b == 0.0:
        return 0.0
    return a * b


@njit(cache=True, forceinline=False, _nrt=True)
def _clear(T, m):
    for i in range(m + 2):
        T[i] = 0.0


@njit(cache=True, forceinline=False, _nrt=True)
def _poison(T, m):
    """The form that stands for 'unknown': all of the real line."""
    for i in range(m + 1):
        T[i] = 0.0
    T[m + 1] = INF


@njit(cache=True, inline="always")
def _centre_product(T, x0, y0, w):
    """T[0] += w (x0 y0) for the centres of a product's operands, and the bound of its two
    roundings in units of ``u = 2^-53``: ``2 |w x0 y0| + |T[0]|``. Inlined by numba (the
    same float operations as written out in the caller); the Taylor-model products use it
    too."""
    t0 = w * (x0 * y0)
    c = T[0] + t0
    T[0] = c
    return 2.0 * abs(t0) + abs(c)


@njit(cache=True, forceinline=False, _nrt=True)
def _acc_mul(T, x, y, m, w):
    """T += w * x * y for forms x, y (1-D arrays of m + 2) and an exact small weight w."""
    e = T[m + 1]
    x0 = x[0]
    y0 = y[0]
    rnd = _centre_product(T, x0, y0, w)
    rx = 0.0
    ry = 0.0
    for i in range(1, m + 1):
        xi = x[i]
        yi = y[i]
        rx += abs(xi)
        ry += abs(yi)
        p = w * (x0 * yi + y0 * xi)
        ti = T[i] + p
        rnd += 2.0 * (abs(w * x0 * yi) + abs(w * y0 * xi)) + abs(ti)
        T[i] = ti
    ex = x[m + 1]
    ey = y[m + 1]
    aw = abs(w)
    nl = _pm(_up(rx) + ex, _up(ry) + ey) + _pm(abs(x0), ey) + _pm(abs(y0), ex)
    T[m + 1] = _up(e + _pm(aw, nl) + rnd * _U)


@njit(cache=True, forceinline=False, _nrt=True)
def _acc_sqr(T, x, m, w):
    """T += w * x^2 (w >= 0 exact): the quadratic part is in [0, (R + e)^2]."""
    x0 = x[0]
    r = 0.0
    for i in range(1, m + 1):
        r += abs(x[i])
    ex = x[m + 1]
    q = _up(_up(r) + ex)
    q2 = _pm(q, q)
    half = 0.5 * q2 * w  # exact halving; w small integer
    t0 = w * (x0 * x0) + half
    c = T[0] + t0
    rnd = 2.0 * abs(t0) + abs(c) + abs(half)
    T[0] = c
    for i in range(1, m + 1):
        p = 2.0 * w * (x0 * x[i])
        ti = T[i] + p
        rnd += 2.0 * abs(p) + abs(ti)
        T[i] = ti
    T[m + 1] = _up(T[m + 1] + _up(half) + _pm(2.0 * w * abs(x0), ex) + rnd * _U)


@njit(cache=True, forceinline=False, _nrt=True)
def _acc_add(T, x, m, sign):
    """T += sign * x (sign = +1 or -1)."""
    rnd = 0.0
    for i in range(m + 1):
        t = T[i] + sign * x[i]
        rnd += abs(t)
        T[i] = t
    T[m + 1] = _up(T[m + 1] + x[m + 1] + rnd * _U)


@njit(cache=True, forceinline=False, _nrt=True)
def _scale_into(Z, x, m, d):
    """Z = d * x for a float d (exact or not: the product's rounding is bounded)."""
    rnd = 0.0
    for i in range(m + 1):
        t = d * x[i]
        rnd += abs(t)
        Z[i] = t
    Z[m + 1] = _up(_pm(abs(d), x[m + 1]) + rnd * _U)


@njit(cache=True, forceinline=False, _nrt=True)
def _frozen_point_into(Z, x, m):
    """Z = the graph op ``mid`` of the form x: its centre as an exact point; a form
    without finite centre and radius stays 'unknown' (all of the real line)."""
    c = x[0]
    w = x[m + 1]
    for i in range(1, m + 1):
        w += abs(x[i])
    _clear(Z, m)
    if math.isfinite(c) and math.isfinite(w):
        Z[0] = c
    else:
        Z[m + 1] = INF


@njit(cache=True, forceinline=False, _nrt=True)
def _div_int_into(Z, x, m, kf):
    """Z = x / kf for a positive integer kf."""
    rnd = 0.0
    for i in range(m + 1):
        t = x[i] / kf
        rnd += abs(t)
        Z[i] = t
    Z[m + 1] = _up(x[m + 1] / kf + rnd * _U)


@njit(cache=True, forceinline=False, _nrt=True)
def _deriv(kind, lo, hi):
    """Interval enclosure of f' over [lo, hi] for the unary functions below."""
    if kind == 0:  # sqrt: 1 / (2 sqrt(x))
        sl, sh = _k.sqrt(lo, hi)
        dl, dh = _k.mul(2.0, 2.0, sl, sh)
        return _k.div(1.0, 1.0, dl, dh)
    if kind == 1:  # exp
        return _k.exp(lo, hi)
    if kind == 2:  # log: 1 / x
        return _k.div(1.0, 1.0, lo, hi)
    if kind == 3:  # sin: cos
        return _k.cos(lo, hi)
    if kind == 4:  # cos: -sin
        sl, sh = _k.sin(lo, hi)
        return -sh, -sl
    if kind == 5:  # tan: 1 + tan^2
        tl, th = _k.tan(lo, hi)
        ql, qh = _k.sqr(tl, th)
        return _k.add(1.0, 1.0, ql, qh)
    if kind == 6:  # atan: 1 / (1 + x^2)
        ql, qh = _k.sqr(lo, hi)
        dl, dh = _k.add(1.0, 1.0, ql, qh)
        return _k.div(1.0, 1.0, dl, dh)
    # 7: reciprocal: -1 / x^2
    ql, qh = _k.sqr(lo, hi)
    rl, rh = _k.div(1.0, 1.0, ql, qh)
    return -rh, -rl


@njit(cache=True, forceinline=False, _nrt=True)
def _value(kind, lo, hi):
    """Interval enclosure of f over [lo, hi]."""
    if kind == 0:
        return _k.sqrt(lo, hi)
    if kind == 1:
        return _k.exp(lo, hi)
    if kind == 2:
        return _k.log(lo, hi)
    if kind == 3:
        return _k.sin(lo, hi)
    if kind == 4:
        return _k.cos(lo, hi)
    if kind == 5:
        return _k.tan(lo, hi)
    if kind == 6:
        return _k.atan(lo, hi)
    return _k.div(1.0, 1.0, lo, hi)


@njit(cache=True, forceinline=False, _nrt=True)
def _unary_into(Z, x, m, kind, known_lo=-INF):
    """Z = f(x) by the mean-value form about the centre (module docstring).

    ``known_lo`` is a lower bound of x known from elsewhere (1 for ``1 + u^2``, whose
    affine form loses the sign of the square and can reach below 0); the range used
    for ``f'`` is the form's range cut to it, which still holds every value of x."""
    c = x[0]
    r = 0.0
    for i in range(1, m + 1):
        r += abs(x[i])
    ex = x[m + 1]
    w = _up(_up(r) + ex)
    if not (math.isfinite(c) and math.isfinite(w)):
        _poison(Z, m)
        return
    # the expansion point c must stay inside the range over which f' is enclosed
    xlo = max(_k.rd(c - w), min(known_lo, c))
    xhi = _k.ru(c + w)
    if not xlo <= xhi:
        _poison(Z, m)
        return
    fl, fh = _value(kind, c, c)
    dl, dh = _deriv(kind, c, c)
    sl, sh = _deriv(kind, xlo, xhi)
    if not (fl <= fh and dl <= dh and sl <= sh) or not (math.isfinite(fl) and math.isfinite(fh)):
        _poison(Z, m)  # outside the domain, or a pole of tan / 1/x within reach
        return
    if not (math.isfinite(sl) and math.isfinite(sh)):
        _poison(Z, m)
        return
    f0 = 0.5 * fl + 0.5 * fh
    frad = max(fh - f0, f0 - fl)
    d = 0.5 * dl + 0.5 * dh
    slope = max(abs(sl - d), abs(sh - d))  # |f'(X) - d|, up to the rounding below
    rnd = 0.0
    for i in range(1, m + 1):
        t = d * x[i]
        rnd += abs(t)
        Z[i] = t
    Z[0] = f0
    Z[m + 1] = _up(_up(frad) + _pm(abs(d), ex) + _pm(_up(slope) + _up(slope) * _U, w) + rnd * _U)
    # Over a wide range the mean-value form can be far wider than the plain image f(X)
    # (sin over [0, 10]: [-8.8, 6.9]). When the form's error part alone exceeds the
    # image, its symbols carry little, and the image as a form without symbols is the
    # tighter enclosure (both are valid). Comparing the whole form instead dropped the
    # symbols of narrow arguments, where the two are about equal.
    gl, gh = _value(kind, xlo, xhi)
    if gl <= gh and math.isfinite(gl) and math.isfinite(gh):
        g0 = 0.5 * gl + 0.5 * gh
        grad = _up(max(gh - g0, g0 - gl))
        if grad < Z[m + 1]:
            for i in range(1, m + 1):
                Z[i] = 0.0
            Z[0] = g0
            Z[m + 1] = grad


# --------------------------------------------------------------------------
# The reference interpreter: one box at a time, every loop over all m symbols; the
# recursion of verified.series.recursion with the affine table below (AffineTable, its
# rules _ar_*). F[s, k, b, :] is the form of coefficient k of tape slot s for box b:
# index 0 the centre, 1..m the symbol coefficients, m + 1 the error radius. The solver
# runs the batched interpreter below (_affine_kernel), which computes the same numbers
# faster; this one is the plain statement of the rules that tests/verified/test_affine_taylor.py
# checks it against, bit for bit. A change to a rule goes into both.
# --------------------------------------------------------------------------
class AffineTable(NamedTuple):
    """Affine forms of every tape slot and of the state, one box after the other (the
    table of :func:`verified.series.recursion.recursion` that :func:`_affine_kernel_reference`
    runs). Its rules are the functions ``_ar_*`` below (plain functions: numba compiles
    them into the engine); every operation on forms is one of the helpers above."""

    F: np.ndarray  # (slots, order + 1, B, m + 2): coefficient k of slot s for box b
    REC: np.ndarray  # (slots, B, m + 2): the reciprocal of the order-0 divisor of a slot
    out: np.ndarray  # (n, order + 1, B, m + 2): x_[k] of state i
    P: np.ndarray  # (p, B, m + 2): the parameters
    T: np.ndarray  # (m + 2,): scratch forms
    S: np.ndarray
    sel: np.ndarray  # fresh symbols of slots (see _affine_kernel_reference)
    sel_base: int
    m0: int  # fresh symbols of the coefficients: 1 + m0 + k n_fresh + i for x_[k+1], i
    n_fresh: int


def _ar_const(ar, s, lo, hi):
    F = ar.F
    m = F.shape[3] - 2
    for b in range(F.shape[2]):
        mid = 0.5 * lo + 0.5 * hi
        F[s, 0, b, 0] = mid
        F[s, 0, b, m + 1] = _up(max(hi - mid, mid - lo))


def _ar_param(ar, s, i):
    F = ar.F
    for b in range(F.shape[2]):
        for j in range(F.shape[3]):
            F[s, 0, b, j] = ar.P[i, b, j]


def _ar_mid(ar, s, u):  # the centre of u_[0], frozen as a point: a constant series
    F = ar.F
    for b in range(F.shape[2]):
        _frozen_point_into(F[s, 0, b], F[u, 0, b], F.shape[3] - 2)


def _ar_state(ar, s, k, i):
    F = ar.F
    for b in range(F.shape[2]):
        for j in range(F.shape[3]):
            F[s, k, b, j] = ar.out[i, k, b, j]


def _ar_add(ar, s, k, u, v):
    F = ar.F
    m = F.shape[3] - 2
    for b in range(F.shape[2]):
        Z = F[s, k, b]
        _clear(Z, m)
        _acc_add(Z, F[u, k, b], m, 1.0)
        _acc_add(Z, F[v, k, b], m, 1.0)


def _ar_sub(ar, s, k, u, v):
    F = ar.F
    m = F.shape[3] - 2
    for b in range(F.shape[2]):
        Z = F[s, k, b]
        _clear(Z, m)
        _acc_add(Z, F[u, k, b], m, 1.0)
        _acc_add(Z, F[v, k, b], m, -1.0)


def _ar_neg(ar, s, k, u):
    F = ar.F
    m = F.shape[3] - 2
    for b in range(F.shape[2]):
        for i in range(m + 1):
            F[s, k, b, i] = -F[u, k, b, i]
        F[s, k, b, m + 1] = F[u, k, b, m + 1]


def _ar_mul_const(ar, s, k, u, v, ku, kv):  # (c w)_[k] = c_[0] w_[k]: the other terms are exact zeros
    F = ar.F
    m = F.shape[3] - 2
    for b in range(F.shape[2]):
        Z = F[s, k, b]
        _clear(Z, m)
        _acc_mul(Z, F[u, ku, b], F[v, kv, b], m, 1.0)


def _ar_mul(ar, s, k, u, v):
    F = ar.F
    m = F.shape[3] - 2
    for b in range(F.shape[2]):
        Z = F[s, k, b]
        _clear(Z, m)
        for j in range(k + 1):
            _acc_mul(Z, F[u, j, b], F[v, k - j, b], m, 1.0)


def _ar_sqr(ar, s, k, u):
    F = ar.F
    m = F.shape[3] - 2
    for b in range(F.shape[2]):
        Z = F[s, k, b]
        _clear(Z, m)
        _sqrconv(Z, F, u, k, np.int64(0), b, m)


def _ar_div_const(ar, s, k, u, v):  # w_k = u_k / v_0 (times the form of 1 / v_0)
    F, T = ar.F, ar.T
    m = F.shape[3] - 2
    for b in range(F.shape[2]):
        if k == 0:
            _unary_into(ar.REC[s, b], F[v, 0, b], m, np.int64(7), -INF)
        _clear(T, m)
        _acc_add(T, F[u, k, b], m, 1.0)
        Z = F[s, k, b]
        _clear(Z, m)
        _acc_mul(Z, T, ar.REC[s, b], m, 1.0)


def _ar_div(ar, s, k, u, v):
    F, T = ar.F, ar.T
    m = F.shape[3] - 2
    for b in range(F.shape[2]):
        if k == 0:
            _unary_into(ar.REC[s, b], F[v, 0, b], m, np.int64(7), -INF)
        # w_k = (u_k - sum_{j=1}^k v_j w_{k-j}) / v_0
        _clear(T, m)
        _acc_add(T, F[u, k, b], m, 1.0)
        for j in range(1, k + 1):
            _acc_mul(T, F[v, j, b], F[s, k - j, b], m, -1.0)
        Z = F[s, k, b]
        _clear(Z, m)
        _acc_mul(Z, T, ar.REC[s, b], m, 1.0)


def _ar_sqrt0(ar, s, u):
    F, T = ar.F, ar.T
    m = F.shape[3] - 2
    for b in range(F.shape[2]):
        Z = F[s, 0, b]
        _unary_into(Z, F[u, 0, b], m, np.int64(0), -INF)
        _scale_into(T, Z, m, 2.0)
        _unary_into(ar.REC[s, b], T, m, np.int64(7), -INF)


def _ar_sqrt(ar, s, k, u):
    F, T, S = ar.F, ar.T, ar.S
    m = F.shape[3] - 2
    for b in range(F.shape[2]):
        # w_k = (u_k - sum_{j=1}^{k-1} w_j w_{k-j}) / (2 w_0)
        _clear(T, m)
        _acc_add(T, F[u, k, b], m, 1.0)
        _clear(S, m)
        _sqrconv(S, F, s, k, np.int64(1), b, m)
        _acc_add(T, S, m, -1.0)
        Z = F[s, k, b]
        _clear(Z, m)
        _acc_mul(Z, T, ar.REC[s, b], m, 1.0)


def _ar_exp0(ar, s, u):
    F = ar.F
    m = F.shape[3] - 2
    for b in range(F.shape[2]):
        _unary_into(F[s, 0, b], F[u, 0, b], m, np.int64(1), -INF)


def _ar_exp(ar, s, k, u):
    F, T = ar.F, ar.T
    m = F.shape[3] - 2
    for b in range(F.shape[2]):
        _clear(T, m)
        for j in range(1, k + 1):
            _acc_mul(T, F[u, j, b], F[s, k - j, b], m, float(j))
        _div_int_into(F[s, k, b], T, m, float(k))


def _ar_log0(ar, s, u):
    F = ar.F
    m = F.shape[3] - 2
    for b in range(F.shape[2]):
        _unary_into(F[s, 0, b], F[u, 0, b], m, np.int64(2), -INF)
        _unary_into(ar.REC[s, b], F[u, 0, b], m, np.int64(7), -INF)


def _ar_log(ar, s, k, u):
    F = ar.F
    m = F.shape[3] - 2
    for b in range(F.shape[2]):
        # w_k = (u_k - (1/k) sum_{j=1}^{k-1} j w_j u_{k-j}) / u_0
        _quotient_step(F[s, k, b], F, s, u, u, k, b, m, ar.REC[s, b], ar.T, ar.S)


def _ar_sincos0(ar, ss, cs, u):
    F = ar.F
    m = F.shape[3] - 2
    for b in range(F.shape[2]):
        _unary_into(F[ss, 0, b], F[u, 0, b], m, np.int64(3), -INF)
        _unary_into(F[cs, 0, b], F[u, 0, b], m, np.int64(4), -INF)


def _ar_sincos(ar, ss, cs, k, u):
    F, T = ar.F, ar.T
    m = F.shape[3] - 2
    fk = float(k)
    for b in range(F.shape[2]):
        _clear(T, m)
        for j in range(1, k + 1):
            _acc_mul(T, F[u, j, b], F[cs, k - j, b], m, float(j))
        _div_int_into(F[ss, k, b], T, m, fk)
        _clear(T, m)
        for j in range(1, k + 1):
            _acc_mul(T, F[u, j, b], F[ss, k - j, b], m, -float(j))
        _div_int_into(F[cs, k, b], T, m, fk)


def _ar_tan0(ar, s, vs, u):  # vs: v = 1 + tan^2 = tan'
    F = ar.F
    m = F.shape[3] - 2
    for b in range(F.shape[2]):
        Z = F[s, 0, b]
        _unary_into(Z, F[u, 0, b], m, np.int64(5), -INF)
        V = F[vs, 0, b]
        _clear(V, m)
        V[0] = 1.0
        _acc_sqr(V, Z, m, 1.0)


def _ar_tan(ar, s, vs, k, u):
    F, T = ar.F, ar.T
    m = F.shape[3] - 2
    for b in range(F.shape[2]):
        _clear(T, m)
        for j in range(1, k + 1):
            _acc_mul(T, F[u, j, b], F[vs, k - j, b], m, float(j))
        _div_int_into(F[s, k, b], T, m, float(k))
        V = F[vs, k, b]
        _clear(V, m)
        _sqrconv(V, F, s, k, np.int64(0), b, m)


def _ar_atan0(ar, s, vs, u):  # vs: v = 1 + u^2, atan(u)' = u' / v
    F = ar.F
    m = F.shape[3] - 2
    for b in range(F.shape[2]):
        _unary_into(F[s, 0, b], F[u, 0, b], m, np.int64(6), -INF)
        V = F[vs, 0, b]
        _clear(V, m)
        V[0] = 1.0
        _acc_sqr(V, F[u, 0, b], m, 1.0)
        _unary_into(ar.REC[s, b], V, m, np.int64(7), 1.0)  # v0 = 1 + u0^2 >= 1


def _ar_atan(ar, s, vs, k, u):
    F = ar.F
    m = F.shape[3] - 2
    for b in range(F.shape[2]):
        V = F[vs, k, b]
        _clear(V, m)
        _sqrconv(V, F, u, k, np.int64(0), b, m)
        # a_k = (u_k - (1/k) sum_{j=1}^{k-1} j a_j v_{k-j}) / v_0
        _quotient_step(F[s, k, b], F, s, u, vs, k, b, m, ar.REC[s, b], ar.T, ar.S)


def _ar_slot_done(ar, s, k):
    sel = ar.sel
    if k == 0 and sel.size > 0 and sel[s] >= 0:
        # this slot's error becomes a symbol of its own (fresh_slots)
        F = ar.F
        m = F.shape[3] - 2
        for b in range(F.shape[2]):
            F[s, 0, b, ar.sel_base + sel[s]] = F[s, 0, b, m + 1]
            F[s, 0, b, m + 1] = 0.0


def _ar_integrate(ar, i, o, k):  # x_[k+1] = f_[k] / (k + 1)
    F, out = ar.F, ar.out
    m = F.shape[3] - 2
    fk = float(k)
    for b in range(F.shape[2]):
        _div_int_into(out[i, k + 1, b], F[o, k, b], m, fk + 1.0)
        if i < ar.n_fresh:
            # the error of x_[k+1] becomes a symbol of its own: later orders then
            # carry it with its dependencies instead of as a bare radius
            out[i, k + 1, b, 1 + ar.m0 + k * ar.n_fresh + i] = out[i, k + 1, b, m + 1]
            out[i, k + 1, b, m + 1] = 0.0


register(AffineTable, **rules_named(globals(), "_ar_"))


@njit(cache=True, forceinline=False, _nrt=True)
def _affine_kernel_reference(op, a0, a1, aux, idx, cst, clo, chi, outputs, X, P, order, m0, n_fresh,
                             sel, sel_base):
    """Affine forms of x_[0..order]; X (n, B, m+2) and P (p, B, m+2) are the input forms:
    the recursion (:mod:`verified.series.recursion`) with the affine table.

    ``sel`` (empty ``_NO_SLOTS``, or one entry per tape slot; passed explicitly, as every
    argument: numba cannot cache a signature with an omitted default, and every process
    would compile the kernel again): where ``sel[s] >= 0`` the error radius
    of slot ``s``'s order-0 form becomes the coefficient of symbol ``sel_base + sel[s]``
    (a fresh symbol: ``[-e, e] = e * eps`` with ``eps`` used nowhere else, so sound),
    and later operations carry it with its signs (see ``AffineTaylorODE(fresh_slots=)``).

    Returns the forms of the coefficients, (n, order + 1, B, m + 2), and those of every
    tape slot, (slots, order + 1, B, m + 2) (for diagnosis).
    """
    nslots = op.size
    n, nb, m2 = X.shape
    F = np.zeros((nslots, order + 1, nb, m2))
    out = np.zeros((n, order + 1, nb, m2))
    for i in range(n):  # (a loop: a slice assignment compiles numba's broadcasting errors)
        for b in range(nb):
            for j in range(m2):
                out[i, 0, b, j] = X[i, b, j]
    ar = AffineTable(F, np.zeros((nslots, nb, m2)), out, P, np.zeros(m2), np.zeros(m2), sel, sel_base, m0, n_fresh)
    recursion(op, a0, a1, aux, idx, cst, clo, chi, outputs, order, ar)
    return out, F


@njit(cache=True, forceinline=False, _nrt=True)
def _created_errors(op, a0, a1, F, b, m):
    """Per tape slot, the error its own rule added at order 0 for box ``b``: its error
    radius minus what its operands' radii propagate to it (taken at the centres).
    ``F`` (slots, K, B, m + 2) from :func:`_affine_kernel_reference`. Returns (slots,)."""
    nslots = op.size
    created = np.zeros(nslots)
    for s in range(nslots):
        o = op[s]
        u = a0[s]
        v = a1[s]
        e = F[s, 0, b, m + 1]
        c = 0.0
        if o == T_MUL:
            c = e - (abs(F[u, 0, b, 0]) * F[v, 0, b, m + 1] + abs(F[v, 0, b, 0]) * F[u, 0, b, m + 1])
        elif o == T_DIV:
            cv = F[v, 0, b, 0]
            if cv != 0.0:
                c = e - (F[u, 0, b, m + 1] / abs(cv) + abs(F[u, 0, b, 0]) * F[v, 0, b, m + 1] / (cv * cv))
        elif o == T_SQR or o == T_SQRT or o == T_EXP or o == T_LOG or o == T_SIN or o == T_COS \
                or o == T_TAN or o == T_ATAN:
            c = e - F[u, 0, b, m + 1]
        created[s] = c if c > 0.0 else 0.0
    return created


@njit(cache=True, forceinline=False, _nrt=True)
def _weighted_attribution(op, a0, a1, F, m, outputs):
    """How much of the outputs' error radii each tape slot creates (order 0), summed over
    the boxes: :func:`_created_errors` times the sum over paths to the ``outputs`` of
    ``|d output / d slot|`` at the centres (one reverse sweep: error radii propagate with
    these absolute factors and never cancel). A heuristic that ranks slots for
    ``AffineTaylorODE(fresh_slots=)``; it bounds nothing. Returns (slots,)."""
    nslots = op.size
    nb = F.shape[2]
    total = np.zeros(nslots)
    w = np.zeros(nslots)
    for b in range(nb):
        created = _created_errors(op, a0, a1, F, b, m)
        w[:] = 0.0
        for i in range(outputs.size):
            w[outputs[i]] += 1.0
        for s in range(nslots - 1, -1, -1):
            ws = w[s]
            if ws == 0.0:
                continue
            o = op[s]
            u = a0[s]
            v = a1[s]
            if o == T_ADD or o == T_SUB:
                w[u] += ws
                w[v] += ws
            elif o == T_NEG:
                w[u] += ws
            elif o == T_MUL:
                w[u] += ws * abs(F[v, 0, b, 0])
                w[v] += ws * abs(F[u, 0, b, 0])
            elif o == T_DIV:
                cv = F[v, 0, b, 0]
                if cv != 0.0:
                    w[u] += ws / abs(cv)
                    w[v] += ws * abs(F[u, 0, b, 0]) / (cv * cv)
            elif o == T_SQR:
                w[u] += ws * 2.0 * abs(F[u, 0, b, 0])
            elif o == T_SIN:
                w[u] += ws * abs(math.cos(F[u, 0, b, 0]))
            elif o == T_COS:
                w[u] += ws * abs(math.sin(F[u, 0, b, 0]))
            elif o == T_SQRT or o == T_EXP or o == T_LOG or o == T_TAN or o == T_ATAN:
                w[u] += ws  # (a rough factor: this only ranks slots)
        for s in range(nslots):
            total[s] += created[s] * w[s]
    return total


@njit(cache=True, forceinline=False, _nrt=True)
def _quotient_step(Z, F, s, u, v, k, b, m, rec, T, S):
    """Z = (F[u, k] - (1/k) sum_{j=1}^{k-1} j F[s, j] F[v, k-j]) * rec, the recurrence of
    log (v = u) and atan (v = 1 + u^2), ``rec`` the form of 1 / v_0; T, S are scratch."""
    _clear(S, m)
    for j in range(1, k):
        _acc_mul(S, F[s, j, b], F[v, k - j, b], m, float(j))
    _div_int_into(T, S, m, float(k))
    _clear(S, m)
    _acc_add(S, F[u, k, b], m, 1.0)
    _acc_add(S, T, m, -1.0)
    _clear(Z, m)
    _acc_mul(Z, S, rec, m, 1.0)


@njit(cache=True, forceinline=False, _nrt=True)
def _sqrconv(Z, F, u, k, j0, b, m):
    """Z += sum_{j=j0}^{k-j0} F[u, j] F[u, k-j], pairing equal terms (the middle one squared)."""
    for j in range(j0, (k + 1) // 2):
        _acc_mul(Z, F[u, j, b], F[u, k - j, b], m, 2.0)
    if k % 2 == 0 and k // 2 >= j0:
        _acc_sqr(Z, F[u, k // 2, b], m, 1.0)


# --------------------------------------------------------------------------
# The batched interpreter (the one the solver runs). Same operations, in the same
# order and with the same roundings as _affine_kernel_reference, so the same bits;
# three things make it faster:
#
# * boxes are processed in chunks of up to ``lanes`` lanes, laid out box-innermost in
#   one array A[row, lane]: the form of coefficient k of slot s is rows
#   (s (K + 1) + k) (m + 2) + 0..m+1 (then the reciprocals, two scratch forms and the
#   coefficients x_[k]; see _affine_kernel). Every
#   loop over a form's entries runs over the lanes innermost, with no dependence
#   between lanes, so it compiles to SIMD instructions (no fastmath: each lane does
#   exactly the reference's operations). Below _VEC_MIN lanes the lanes are taken one
#   at a time instead (entries innermost), as the reference does;
# * the working arrays hold one chunk, not the whole batch (the reference allocated
#   slots x orders x boxes x entries: 2 GB for the UR5 at 64 boxes);
# * loops over symbols stop at L[s, k], a bound, from the tape's structure, of the
#   highest symbol that can be nonzero in the forms of slot s at order k. With fresh
#   symbols the order-k forms carry at most m0 + k n of them instead of m0 + K n. The
#   entries beyond are exact zeros in the reference too, where they add exact zeros
#   to every sum (or |T_i| for an untouched T_i, which is kept): the same bits. (One
#   exception: once a centre is infinite, the reference's inf * 0 puts NaN into such
#   entries, where this kernel keeps 0; the range is [-inf, inf] either way.)
#
# Every helper below takes forms as first rows z, x, y of A (result z = "Z"), works on
# lanes 0..cb-1 and touches entries 0..L and m + 1 only.
# --------------------------------------------------------------------------
_VEC_MIN = 8  # from this many lanes on, lanes innermost (break-even, docs/lab/code_notes.md)
_CHUNK = 32  # lanes per chunk (SIMD width times enough independent work)
_CHUNK_BYTES = 256 * 2**20  # at most this much working memory per chunk (fewer lanes then)


@njit(cache=True, forceinline=False, _nrt=False)  # no arrays made: no reference counting per call
def _b_clear(F, z, L, m, nl):
    """Z = 0 (entries 0..L and m + 1), F the flat view of A (rows, nl lanes). Rows
    z..z+L of A are one contiguous run of (L + 1) nl numbers: cleared as such, all
    lanes (those beyond cb belong to no box of this chunk and are never output)."""
    for q in range(z * nl, (z + L + 1) * nl):
        F[q] = 0.0
    for q in range((z + m + 1) * nl, (z + m + 2) * nl):
        F[q] = 0.0


@njit(cache=True, forceinline=False, _nrt=False)  # no arrays made: no reference counting per call
def _b_copy(F, z, x, L, m, nl, sign):
    """Z = sign * x for sign = +1 or -1 (entries 0..L), error radius copied; all
    lanes, as :func:`_b_clear`."""
    d = (x - z) * nl
    for q in range(z * nl, (z + L + 1) * nl):
        F[q] = sign * F[q + d]
    for q in range((z + m + 1) * nl, (z + m + 2) * nl):
        F[q] = F[q + d]


@njit(cache=True, forceinline=False, _nrt=False)  # no arrays made: no reference counting per call
def _b_acc_mul(A, z, x, y, lz, lxy, m, w, cb, R):
    """Z += w * x * y (:func:`_acc_mul`) for x, y without symbols beyond ``lxy`` and Z
    without symbols beyond ``lz``; returns Z's new bound. R is scratch (>= 3, lanes).
    Beyond lxy the reference's terms are x_i = y_i = 0: Z_i stays, its rounding sum
    gains |Z_i| (the tail loops)."""
    aw = abs(w)
    if cb < _VEC_MIN:
        for c in range(cb):
            e = A[z + m + 1, c]
            x0 = A[x + 0, c]
            y0 = A[y + 0, c]
            t0 = w * (x0 * y0)
            cc = A[z + 0, c] + t0
            rnd = 2.0 * abs(t0) + abs(cc)
            A[z + 0, c] = cc
            rx = 0.0
            ry = 0.0
            for i in range(1, lxy + 1):
                xi = A[x + i, c]
                yi = A[y + i, c]
                rx += abs(xi)
                ry += abs(yi)
                p = w * (x0 * yi + y0 * xi)
                ti = A[z + i, c] + p
                rnd += 2.0 * (abs(w * x0 * yi) + abs(w * y0 * xi)) + abs(ti)
                A[z + i, c] = ti
            for i in range(lxy + 1, lz + 1):
                rnd += abs(A[z + i, c])
            ex = A[x + m + 1, c]
            ey = A[y + m + 1, c]
            nl = _pm(_up(rx) + ex, _up(ry) + ey) + _pm(abs(x0), ey) + _pm(abs(y0), ex)
            A[z + m + 1, c] = _up(e + _pm(aw, nl) + rnd * _U)
        return max(lz, lxy)
    for c in range(cb):
        x0 = A[x + 0, c]
        y0 = A[y + 0, c]
        t0 = w * (x0 * y0)
        cc = A[z + 0, c] + t0
        R[2, c] = 2.0 * abs(t0) + abs(cc)
        A[z + 0, c] = cc
        R[0, c] = 0.0
        R[1, c] = 0.0
    for i in range(1, lxy + 1):
        for c in range(cb):
            xi = A[x + i, c]
            yi = A[y + i, c]
            x0 = A[x + 0, c]
            y0 = A[y + 0, c]
            R[0, c] += abs(xi)
            R[1, c] += abs(yi)
            p = w * (x0 * yi + y0 * xi)
            ti = A[z + i, c] + p
            R[2, c] += 2.0 * (abs(w * x0 * yi) + abs(w * y0 * xi)) + abs(ti)
            A[z + i, c] = ti
    for i in range(lxy + 1, lz + 1):
        for c in range(cb):
            R[2, c] += abs(A[z + i, c])
    for c in range(cb):
        x0 = A[x + 0, c]
        y0 = A[y + 0, c]
        ex = A[x + m + 1, c]
        ey = A[y + m + 1, c]
        nl = _pm(_up(R[0, c]) + ex, _up(R[1, c]) + ey) + _pm(abs(x0), ey) + _pm(abs(y0), ex)
        A[z + m + 1, c] = _up(A[z + m + 1, c] + _pm(aw, nl) + R[2, c] * _U)
    return max(lz, lxy)


@njit(cache=True, forceinline=False, _nrt=False)  # no arrays made: no reference counting per call
def _b_acc_sqr(A, z, x, lz, lx, m, w, cb, R):
    """Z += w * x^2 (:func:`_acc_sqr`); bounds as in :func:`_b_acc_mul`."""
    if cb < _VEC_MIN:
        for c in range(cb):
            x0 = A[x + 0, c]
            r = 0.0
            for i in range(1, lx + 1):
                r += abs(A[x + i, c])
            ex = A[x + m + 1, c]
            q = _up(_up(r) + ex)
            q2 = _pm(q, q)
            half = 0.5 * q2 * w
            t0 = w * (x0 * x0) + half
            cc = A[z + 0, c] + t0
            rnd = 2.0 * abs(t0) + abs(cc) + abs(half)
            A[z + 0, c] = cc
            for i in range(1, lx + 1):
                p = 2.0 * w * (x0 * A[x + i, c])
                ti = A[z + i, c] + p
                rnd += 2.0 * abs(p) + abs(ti)
                A[z + i, c] = ti
            for i in range(lx + 1, lz + 1):
                rnd += abs(A[z + i, c])
            A[z + m + 1, c] = _up(A[z + m + 1, c] + _up(half) + _pm(2.0 * w * abs(x0), ex) + rnd * _U)
        return max(lz, lx)
    for c in range(cb):
        R[0, c] = 0.0
    for i in range(1, lx + 1):
        for c in range(cb):
            R[0, c] += abs(A[x + i, c])
    for c in range(cb):
        x0 = A[x + 0, c]
        q = _up(_up(R[0, c]) + A[x + m + 1, c])
        q2 = _pm(q, q)
        half = 0.5 * q2 * w
        t0 = w * (x0 * x0) + half
        cc = A[z + 0, c] + t0
        R[2, c] = 2.0 * abs(t0) + abs(cc) + abs(half)
        R[1, c] = half
        A[z + 0, c] = cc
    for i in range(1, lx + 1):
        for c in range(cb):
            p = 2.0 * w * (A[x + 0, c] * A[x + i, c])
            ti = A[z + i, c] + p
            R[2, c] += 2.0 * abs(p) + abs(ti)
            A[z + i, c] = ti
    for i in range(lx + 1, lz + 1):
        for c in range(cb):
            R[2, c] += abs(A[z + i, c])
    for c in range(cb):
        x0 = A[x + 0, c]
        ex = A[x + m + 1, c]
        A[z + m + 1, c] = _up(A[z + m + 1, c] + _up(R[1, c]) + _pm(2.0 * w * abs(x0), ex) + R[2, c] * _U)
    return max(lz, lx)


@njit(cache=True, forceinline=False, _nrt=False)  # no arrays made: no reference counting per call
def _b_acc_add(A, z, x, lz, lx, m, sign, cb, R):
    """Z += sign * x (:func:`_acc_add`); bounds as in :func:`_b_acc_mul`."""
    if cb < _VEC_MIN:
        for c in range(cb):
            rnd = 0.0
            for i in range(lx + 1):
                t = A[z + i, c] + sign * A[x + i, c]
                rnd += abs(t)
                A[z + i, c] = t
            for i in range(lx + 1, lz + 1):
                rnd += abs(A[z + i, c])
            A[z + m + 1, c] = _up(A[z + m + 1, c] + A[x + m + 1, c] + rnd * _U)
        return max(lz, lx)
    for c in range(cb):
        R[2, c] = 0.0
    for i in range(lx + 1):
        for c in range(cb):
            t = A[z + i, c] + sign * A[x + i, c]
            R[2, c] += abs(t)
            A[z + i, c] = t
    for i in range(lx + 1, lz + 1):
        for c in range(cb):
            R[2, c] += abs(A[z + i, c])
    for c in range(cb):
        A[z + m + 1, c] = _up(A[z + m + 1, c] + A[x + m + 1, c] + R[2, c] * _U)
    return max(lz, lx)


@njit(cache=True, forceinline=False, _nrt=False)  # no arrays made: no reference counting per call
def _b_div_int_into(A, z, x, L, m, kf, cb, R):
    """Z = x / kf for a positive integer kf (:func:`_div_int_into`)."""
    if cb < _VEC_MIN:
        for c in range(cb):
            rnd = 0.0
            for i in range(L + 1):
                t = A[x + i, c] / kf
                rnd += abs(t)
                A[z + i, c] = t
            A[z + m + 1, c] = _up(A[x + m + 1, c] / kf + rnd * _U)
        return
    for c in range(cb):
        R[2, c] = 0.0
    for i in range(L + 1):
        for c in range(cb):
            t = A[x + i, c] / kf
            R[2, c] += abs(t)
            A[z + i, c] = t
    for c in range(cb):
        A[z + m + 1, c] = _up(A[x + m + 1, c] / kf + R[2, c] * _U)


@njit(cache=True, forceinline=False, _nrt=False)  # no arrays made: no reference counting per call
def _b_scale_into(A, z, x, L, m, d, cb):
    """Z = d * x (:func:`_scale_into`); rare (sqrt at order 0), lanes one at a time."""
    for c in range(cb):
        rnd = 0.0
        for i in range(L + 1):
            t = d * A[x + i, c]
            rnd += abs(t)
            A[z + i, c] = t
        A[z + m + 1, c] = _up(_pm(abs(d), A[x + m + 1, c]) + rnd * _U)


@njit(cache=True, forceinline=False, _nrt=False)  # no arrays made: no reference counting per call
def _b_frozen_point_into(A, z, x, L, m, cb):
    """The graph op ``mid`` (:func:`_frozen_point_into`); Z has no symbols."""
    for c in range(cb):
        c0 = A[x + 0, c]
        w = A[x + m + 1, c]
        for i in range(1, L + 1):
            w += abs(A[x + i, c])
        A[z + 0, c] = 0.0
        A[z + m + 1, c] = 0.0
        if math.isfinite(c0) and math.isfinite(w):
            A[z + 0, c] = c0
        else:
            A[z + m + 1, c] = INF


@njit(cache=True, forceinline=False, _nrt=False)  # no arrays made: no reference counting per call
def _b_unary_into(A, z, x, L, m, kind, known_lo, cb):
    """Z = f(x) by the mean-value form (:func:`_unary_into`), lane by lane."""
    for c in range(cb):
        c0 = A[x + 0, c]
        r = 0.0
        for i in range(1, L + 1):
            r += abs(A[x + i, c])
        ex = A[x + m + 1, c]
        w = _up(_up(r) + ex)
        poison = not (math.isfinite(c0) and math.isfinite(w))
        if not poison:
            xlo = max(_k.rd(c0 - w), min(known_lo, c0))
            xhi = _k.ru(c0 + w)
            poison = not xlo <= xhi
        if not poison:
            fl, fh = _value(kind, c0, c0)
            dl, dh = _deriv(kind, c0, c0)
            sl, sh = _deriv(kind, xlo, xhi)
            poison = (not (fl <= fh and dl <= dh and sl <= sh) or not (math.isfinite(fl) and math.isfinite(fh))
                      or not (math.isfinite(sl) and math.isfinite(sh)))
        if poison:
            for i in range(L + 1):
                A[z + i, c] = 0.0
            A[z + m + 1, c] = INF
            continue
        f0 = 0.5 * fl + 0.5 * fh
        frad = max(fh - f0, f0 - fl)
        d = 0.5 * dl + 0.5 * dh
        slope = max(abs(sl - d), abs(sh - d))
        rnd = 0.0
        for i in range(1, L + 1):
            t = d * A[x + i, c]
            rnd += abs(t)
            A[z + i, c] = t
        A[z + 0, c] = f0
        e = _up(_up(frad) + _pm(abs(d), ex) + _pm(_up(slope) + _up(slope) * _U, w) + rnd * _U)
        A[z + m + 1, c] = e
        gl, gh = _value(kind, xlo, xhi)
        if gl <= gh and math.isfinite(gl) and math.isfinite(gh):
            g0 = 0.5 * gl + 0.5 * gh
            grad = _up(max(gh - g0, g0 - gl))
            if grad < e:
                for i in range(1, L + 1):
                    A[z + i, c] = 0.0
                A[z + 0, c] = g0
                A[z + m + 1, c] = grad


@njit(cache=True, forceinline=False, _nrt=False)  # no arrays made: no reference counting per call
def _b_sqrconv(A, z, u, us, L, k, j0, lz, m, cb, R):
    """Z += sum_{j=j0}^{k-j0} u_j u_{k-j} (:func:`_sqrconv`); ``u`` is the row of the
    order-0 form of slot ``us``, its order j at ``u + j (m + 2)``, bounds L[us, j];
    returns Z's new bound."""
    m2 = m + 2
    for j in range(j0, (k + 1) // 2):
        lz = _b_acc_mul(A, z, u + j * m2, u + (k - j) * m2, lz, max(L[us, j], L[us, k - j]), m, 2.0, cb, R)
    if k % 2 == 0 and k // 2 >= j0:
        lz = _b_acc_sqr(A, z, u + (k // 2) * m2, lz, L[us, k // 2], m, 1.0, cb, R)
    return lz


@njit(cache=True, forceinline=False, _nrt=False)  # no arrays made: no reference counting per call
def _b_quotient_step(A, Af, s, ss, u, us, v, vs, L, k, rec, t, sc, Ls, m, cb, R):
    """w_k = (u_k - (1/k) sum_{j=1}^{k-1} j w_j v_{k-j}) * rec (:func:`_quotient_step`),
    with ``s, u, v`` the rows of the order-0 forms of slots ``ss, us, vs`` (w, u, v),
    ``rec`` of 1 / v_0 (bound L[ss, 0]), ``t, sc`` scratch rows, Ls the bound of w_k."""
    m2 = m + 2
    CB = A.shape[1]
    _b_clear(Af, sc, Ls, m, CB)
    ls = 0
    for j in range(1, k):
        ls = _b_acc_mul(A, sc, s + j * m2, v + (k - j) * m2, ls, max(L[ss, j], L[vs, k - j]), m, float(j), cb, R)
    _b_div_int_into(A, t, sc, Ls, m, float(k), cb, R)
    _b_clear(Af, sc, Ls, m, CB)
    lt = _b_acc_add(A, sc, u + k * m2, np.int64(0), L[us, k], m, 1.0, cb, R)
    lt = _b_acc_add(A, sc, t, lt, ls, m, -1.0, cb, R)
    _b_clear(Af, s + k * m2, Ls, m, CB)
    _b_acc_mul(A, s + k * m2, sc, rec, np.int64(0), max(lt, L[ss, 0]), m, 1.0, cb, R)


@njit(cache=True, forceinline=False, _nrt=True)
def _live_counts(op, a0, a1, aux, idx, cst, outputs, Lx, Lp, order, m0, n_fresh, sel, sel_base):
    """Bounds of the highest nonzero symbol: L[s, k] for the forms of slot s at order k
    (and of everything its recurrence reads and writes: operands at orders <= k, its
    own and its partner's earlier orders, its reciprocal, scratch) and Lo[i, k] for the
    coefficient forms x_[k] (inputs ``Lx``, parameters ``Lp`` at order 0). Computed
    order by order in (order, slot) tables of int32 (a big tape's operands are far
    apart: one order's row stays in cache), returned as (slot, order)."""
    nslots = op.size
    n = outputs.size
    LT = np.zeros((order + 1, nslots), np.int32)
    PT = np.zeros((order + 1, nslots), np.int32)  # max over orders <= k
    Lo = np.zeros((n, order + 1), np.int64)
    Lo[:, 0] = Lx
    for k in range(order):
        for s in range(nslots):
            o = op[s]
            if o == T_AUX:
                continue  # set with its owner
            if k > 0 and cst[s]:
                lv = 0
            elif o == T_CONST or o == T_MID:
                lv = 0
            elif o == T_PARAM:
                lv = Lp[idx[s]]
            elif o == T_INPUT:
                lv = Lo[idx[s], k]
            else:
                lv = 0
                if a0[s] >= 0:
                    lv = max(lv, PT[k, a0[s]])
                if a1[s] >= 0:
                    lv = max(lv, PT[k, a1[s]])
                if k > 0:
                    lv = max(lv, PT[k - 1, s])
                    if aux[s] >= 0:
                        lv = max(lv, PT[k - 1, aux[s]])
            if k == 0 and sel.size > 0 and sel[s] >= 0:
                lv = max(lv, sel_base + sel[s])  # its error's fresh symbol (fresh_slots)
            LT[k, s] = lv
            PT[k, s] = lv if k == 0 else max(PT[k - 1, s], lv)
            if aux[s] >= 0:
                a = aux[s]
                LT[k, a] = lv
                PT[k, a] = lv if k == 0 else max(PT[k - 1, a], lv)
        for i in range(n):
            lv = LT[k, outputs[i]]
            if i < n_fresh:
                lv = max(lv, m0 + k * n_fresh + i + 1)
            Lo[i, k + 1] = lv
    return np.ascontiguousarray(LT.T), Lo


@njit(cache=True, forceinline=False, _nrt=True)
def _highest_nonzero(A):
    """Per row j of forms A (rows, B, m + 2): the highest symbol index i in 1..m with
    A[j, b, i] != 0 for some box b (NaN counts as nonzero), 0 if none."""
    rows, nb, m2 = A.shape
    out = np.zeros(rows, np.int64)
    for j in range(rows):
        for b in range(nb):
            for i in range(m2 - 2, out[j], -1):
                if A[j, b, i] != 0.0 or A[j, b, i] != A[j, b, i]:
                    out[j] = i
                    break
    return out


@njit(cache=True, forceinline=False, _nrt=True)
def _affine_work_size(nslots, order, m2, n, CB):
    """Floats of :func:`_affine_kernel_into`'s working forms (their layout is there):
    per lane, ``order + 1`` forms per slot, a reciprocal per slot, two scratch forms
    and ``order + 1`` coefficient forms per state, each of ``m2`` entries."""
    return (nslots * (order + 2) + 2 + n * (order + 1)) * m2 * CB


@njit(cache=True, forceinline=False, _nrt=True)
def _affine_kernel(op, a0, a1, aux, idx, cst, clo, chi, outputs, X, P, order, m0, n_fresh, keep, lanes,
                   sel, sel_base):
    """:func:`_affine_kernel_into` with work memory of its own."""
    return _affine_kernel_into(op, a0, a1, aux, idx, cst, clo, chi, outputs, X, P, order, m0, n_fresh, keep, lanes,
                               sel, sel_base, np.empty(0))


# --------------------------------------------------------------------------
# The batched interpreter as a table of the recursion (verified.series.recursion):
# LaneTable and its rules _ln_*, the branches of the kernel once written out in its own
# loop, moved one to one (docs/lab/recursion_engine.md). The table is one chunk of
# lanes: the entry _affine_kernel_into runs the engine once per chunk, copying the
# chunk's X in before and the coefficients and kept forms out after. A rule reads its
# rows from the slot numbers the engine passes: the order-k form of slot s starts at
# row s KM + k m2.
# --------------------------------------------------------------------------
class LaneTable(NamedTuple):
    """The working forms of one chunk of boxes (the layout of :func:`_affine_kernel_into`);
    the table it runs per chunk. Its rules are the functions ``_ln_*`` below, plain
    functions compiled into the engine; every operation on forms is a ``_b_*`` helper."""

    A: np.ndarray  # (rows, CB): the forms, lanes innermost
    Af: np.ndarray  # the same numbers, flat (for runs of whole rows)
    L: np.ndarray  # (slots, order + 1): bound of the highest nonzero symbol (_live_counts)
    R: np.ndarray  # (3, CB): per-lane sums
    P: np.ndarray  # (p, B, m + 2): the parameters
    b0: int  # the chunk's first box
    cb: int  # its boxes: lanes 0..cb-1
    m: int
    KM: int  # rows per slot, (order + 1) (m + 2)
    RB: int  # first row of the reciprocals
    TB: int  # scratch forms T and S
    SB: int
    OB: int  # first row of the coefficients x_[k]
    sel: np.ndarray  # fresh symbols of slots (see _affine_kernel_reference)
    sel_base: int
    m0: int  # fresh symbols of the coefficients: 1 + m0 + k n_fresh + i for x_[k+1], i
    n_fresh: int


def _ln_const(ar, s, lo, hi):
    A, m, z = ar.A, ar.m, s * ar.KM
    mid = 0.5 * lo + 0.5 * hi
    e = _up(max(hi - mid, mid - lo))
    for c in range(ar.cb):
        A[z, c] = mid
        A[z + m + 1, c] = e


def _ln_param(ar, s, i):
    A, P, m, z, b0 = ar.A, ar.P, ar.m, s * ar.KM, ar.b0
    for r in range(ar.L[s, 0] + 1):
        for c in range(ar.cb):
            A[z + r, c] = P[i, b0 + c, r]
    for c in range(ar.cb):
        A[z + m + 1, c] = P[i, b0 + c, m + 1]


def _ln_mid(ar, s, u):  # the centre of u_[0], frozen as a point: a constant series
    _b_frozen_point_into(ar.A, s * ar.KM, u * ar.KM, ar.L[u, 0], ar.m, ar.cb)


def _ln_state(ar, s, k, i):
    m2 = ar.m + 2
    _b_copy(ar.Af, s * ar.KM + k * m2, ar.OB + i * ar.KM + k * m2, ar.L[s, k], ar.m, ar.A.shape[1], 1.0)


def _ln_add(ar, s, k, u, v):
    A, L, m, KM, cb, R = ar.A, ar.L, ar.m, ar.KM, ar.cb, ar.R
    z = s * KM + k * (m + 2)
    _b_clear(ar.Af, z, L[s, k], m, A.shape[1])
    lz = _b_acc_add(A, z, u * KM + k * (m + 2), np.int64(0), L[u, k], m, 1.0, cb, R)
    _b_acc_add(A, z, v * KM + k * (m + 2), lz, L[v, k], m, 1.0, cb, R)


def _ln_sub(ar, s, k, u, v):
    A, L, m, KM, cb, R = ar.A, ar.L, ar.m, ar.KM, ar.cb, ar.R
    z = s * KM + k * (m + 2)
    _b_clear(ar.Af, z, L[s, k], m, A.shape[1])
    lz = _b_acc_add(A, z, u * KM + k * (m + 2), np.int64(0), L[u, k], m, 1.0, cb, R)
    _b_acc_add(A, z, v * KM + k * (m + 2), lz, L[v, k], m, -1.0, cb, R)


def _ln_neg(ar, s, k, u):
    m2 = ar.m + 2
    _b_copy(ar.Af, s * ar.KM + k * m2, u * ar.KM + k * m2, ar.L[s, k], ar.m, ar.A.shape[1], -1.0)


def _ln_mul_const(ar, s, k, u, v, ku, kv):  # (c w)_[k] = c_[0] w_[k]: the other terms are exact zeros
    A, L, m, KM = ar.A, ar.L, ar.m, ar.KM
    m2 = m + 2
    z = s * KM + k * m2
    _b_clear(ar.Af, z, L[s, k], m, A.shape[1])
    _b_acc_mul(A, z, u * KM + ku * m2, v * KM + kv * m2, np.int64(0), max(L[u, ku], L[v, kv]), m, 1.0, ar.cb, ar.R)


def _ln_mul(ar, s, k, u, v):
    A, L, m, KM, cb, R = ar.A, ar.L, ar.m, ar.KM, ar.cb, ar.R
    m2 = m + 2
    z = s * KM + k * m2
    _b_clear(ar.Af, z, L[s, k], m, A.shape[1])
    lz = 0
    for j in range(k + 1):
        lz = _b_acc_mul(A, z, u * KM + j * m2, v * KM + (k - j) * m2, lz, max(L[u, j], L[v, k - j]), m, 1.0, cb, R)


def _ln_sqr(ar, s, k, u):
    A, L, m, KM = ar.A, ar.L, ar.m, ar.KM
    z = s * KM + k * (m + 2)
    _b_clear(ar.Af, z, L[s, k], m, A.shape[1])
    _b_sqrconv(A, z, u * KM, u, L, k, np.int64(0), np.int64(0), m, ar.cb, ar.R)


def _ln_div_const(ar, s, k, u, v):  # w_k = u_k / v_0 (times the form of 1 / v_0)
    A, Af, L, m, KM, cb, R, TB = ar.A, ar.Af, ar.L, ar.m, ar.KM, ar.cb, ar.R, ar.TB
    m2 = m + 2
    z, rec, Ls = s * KM + k * m2, ar.RB + s * m2, L[s, k]
    if k == 0:
        _b_unary_into(A, rec, v * KM, Ls, m, np.int64(7), -INF, cb)
    _b_clear(Af, TB, Ls, m, A.shape[1])
    lt = _b_acc_add(A, TB, u * KM + k * m2, np.int64(0), L[u, k], m, 1.0, cb, R)
    _b_clear(Af, z, Ls, m, A.shape[1])
    _b_acc_mul(A, z, TB, rec, np.int64(0), max(lt, L[s, 0]), m, 1.0, cb, R)


def _ln_div(ar, s, k, u, v):  # w_k = (u_k - sum_{j=1}^k v_j w_{k-j}) / v_0
    A, Af, L, m, KM, cb, R, TB = ar.A, ar.Af, ar.L, ar.m, ar.KM, ar.cb, ar.R, ar.TB
    m2 = m + 2
    z, rec, Ls = s * KM + k * m2, ar.RB + s * m2, L[s, k]
    if k == 0:
        _b_unary_into(A, rec, v * KM, Ls, m, np.int64(7), -INF, cb)
    _b_clear(Af, TB, Ls, m, A.shape[1])
    lt = _b_acc_add(A, TB, u * KM + k * m2, np.int64(0), L[u, k], m, 1.0, cb, R)
    for j in range(1, k + 1):
        lt = _b_acc_mul(A, TB, v * KM + j * m2, s * KM + (k - j) * m2, lt, max(L[v, j], L[s, k - j]), m, -1.0, cb, R)
    _b_clear(Af, z, Ls, m, A.shape[1])
    _b_acc_mul(A, z, TB, rec, np.int64(0), max(lt, L[s, 0]), m, 1.0, cb, R)


def _ln_sqrt0(ar, s, u):
    A, m, cb, TB, Ls = ar.A, ar.m, ar.cb, ar.TB, ar.L[s, 0]
    z = s * ar.KM
    _b_unary_into(A, z, u * ar.KM, Ls, m, np.int64(0), -INF, cb)
    _b_scale_into(A, TB, z, Ls, m, 2.0, cb)
    _b_unary_into(A, ar.RB + s * (m + 2), TB, Ls, m, np.int64(7), -INF, cb)


def _ln_sqrt(ar, s, k, u):  # w_k = (u_k - sum_{j=1}^{k-1} w_j w_{k-j}) / (2 w_0)
    A, Af, L, m, KM, cb, R, TB, SB = ar.A, ar.Af, ar.L, ar.m, ar.KM, ar.cb, ar.R, ar.TB, ar.SB
    m2 = m + 2
    z, Ls = s * KM + k * m2, L[s, k]
    _b_clear(Af, TB, Ls, m, A.shape[1])
    lt = _b_acc_add(A, TB, u * KM + k * m2, np.int64(0), L[u, k], m, 1.0, cb, R)
    _b_clear(Af, SB, Ls, m, A.shape[1])
    ls = _b_sqrconv(A, SB, s * KM, s, L, k, np.int64(1), np.int64(0), m, cb, R)
    lt = _b_acc_add(A, TB, SB, lt, ls, m, -1.0, cb, R)
    _b_clear(Af, z, Ls, m, A.shape[1])
    _b_acc_mul(A, z, TB, ar.RB + s * m2, np.int64(0), max(lt, L[s, 0]), m, 1.0, cb, R)


def _ln_exp0(ar, s, u):
    _b_unary_into(ar.A, s * ar.KM, u * ar.KM, ar.L[s, 0], ar.m, np.int64(1), -INF, ar.cb)


def _ln_exp(ar, s, k, u):
    A, L, m, KM, cb, R, TB = ar.A, ar.L, ar.m, ar.KM, ar.cb, ar.R, ar.TB
    m2 = m + 2
    Ls = L[s, k]
    _b_clear(ar.Af, TB, Ls, m, A.shape[1])
    lt = 0
    for j in range(1, k + 1):
        lt = _b_acc_mul(A, TB, u * KM + j * m2, s * KM + (k - j) * m2, lt, max(L[u, j], L[s, k - j]), m, float(j),
                        cb, R)
    _b_div_int_into(A, s * KM + k * m2, TB, Ls, m, float(k), cb, R)


def _ln_log0(ar, s, u):
    A, m, cb, Ls = ar.A, ar.m, ar.cb, ar.L[s, 0]
    _b_unary_into(A, s * ar.KM, u * ar.KM, Ls, m, np.int64(2), -INF, cb)
    _b_unary_into(A, ar.RB + s * (m + 2), u * ar.KM, Ls, m, np.int64(7), -INF, cb)


def _ln_log(ar, s, k, u):  # w_k = (u_k - (1/k) sum_{j=1}^{k-1} j w_j u_{k-j}) / u_0
    m, KM = ar.m, ar.KM
    _b_quotient_step(ar.A, ar.Af, s * KM, s, u * KM, u, u * KM, u, ar.L, k, ar.RB + s * (m + 2), ar.TB, ar.SB,
                     ar.L[s, k], m, ar.cb, ar.R)


def _ln_sincos0(ar, ss, cs, u):  # (both partners have the bounds of either: see _live_counts)
    A, m, KM, cb, Ls = ar.A, ar.m, ar.KM, ar.cb, ar.L[ss, 0]
    _b_unary_into(A, ss * KM, u * KM, Ls, m, np.int64(3), -INF, cb)
    _b_unary_into(A, cs * KM, u * KM, Ls, m, np.int64(4), -INF, cb)


def _ln_sincos(ar, ss, cs, k, u):
    A, Af, L, m, KM, cb, R, TB = ar.A, ar.Af, ar.L, ar.m, ar.KM, ar.cb, ar.R, ar.TB
    m2 = m + 2
    fk, Ls = float(k), L[ss, k]
    _b_clear(Af, TB, Ls, m, A.shape[1])
    lt = 0
    for j in range(1, k + 1):
        lt = _b_acc_mul(A, TB, u * KM + j * m2, cs * KM + (k - j) * m2, lt, max(L[u, j], L[ss, k - j]), m, float(j),
                        cb, R)
    _b_div_int_into(A, ss * KM + k * m2, TB, Ls, m, fk, cb, R)
    _b_clear(Af, TB, Ls, m, A.shape[1])
    lt = 0
    for j in range(1, k + 1):
        lt = _b_acc_mul(A, TB, u * KM + j * m2, ss * KM + (k - j) * m2, lt, max(L[u, j], L[ss, k - j]), m,
                        -float(j), cb, R)
    _b_div_int_into(A, cs * KM + k * m2, TB, Ls, m, fk, cb, R)


def _ln_tan0(ar, s, vs, u):  # vs: v = 1 + tan^2 = tan'
    A, m, KM, cb, Ls = ar.A, ar.m, ar.KM, ar.cb, ar.L[s, 0]
    _b_unary_into(A, s * KM, u * KM, Ls, m, np.int64(5), -INF, cb)
    _b_clear(ar.Af, vs * KM, Ls, m, A.shape[1])
    for c in range(cb):
        A[vs * KM, c] = 1.0
    _b_acc_sqr(A, vs * KM, s * KM, np.int64(0), Ls, m, 1.0, cb, ar.R)


def _ln_tan(ar, s, vs, k, u):
    A, Af, L, m, KM, cb, R, TB = ar.A, ar.Af, ar.L, ar.m, ar.KM, ar.cb, ar.R, ar.TB
    m2 = m + 2
    Ls = L[s, k]
    _b_clear(Af, TB, Ls, m, A.shape[1])
    lt = 0
    for j in range(1, k + 1):
        lt = _b_acc_mul(A, TB, u * KM + j * m2, vs * KM + (k - j) * m2, lt, max(L[u, j], L[s, k - j]), m, float(j),
                        cb, R)
    _b_div_int_into(A, s * KM + k * m2, TB, Ls, m, float(k), cb, R)
    _b_clear(Af, vs * KM + k * m2, Ls, m, A.shape[1])
    _b_sqrconv(A, vs * KM + k * m2, s * KM, s, L, k, np.int64(0), np.int64(0), m, cb, R)


def _ln_atan0(ar, s, vs, u):  # vs: v = 1 + u^2, atan(u)' = u' / v
    A, L, m, KM, cb, Ls = ar.A, ar.L, ar.m, ar.KM, ar.cb, ar.L[s, 0]
    _b_unary_into(A, s * KM, u * KM, Ls, m, np.int64(6), -INF, cb)
    _b_clear(ar.Af, vs * KM, Ls, m, A.shape[1])
    for c in range(cb):
        A[vs * KM, c] = 1.0
    _b_acc_sqr(A, vs * KM, u * KM, np.int64(0), L[u, 0], m, 1.0, cb, ar.R)
    _b_unary_into(A, ar.RB + s * (m + 2), vs * KM, Ls, m, np.int64(7), 1.0, cb)  # v0 = 1 + u0^2 >= 1


def _ln_atan(ar, s, vs, k, u):
    A, L, m, KM = ar.A, ar.L, ar.m, ar.KM
    m2 = m + 2
    Ls = L[s, k]
    _b_clear(ar.Af, vs * KM + k * m2, Ls, m, A.shape[1])
    _b_sqrconv(A, vs * KM + k * m2, u * KM, u, L, k, np.int64(0), np.int64(0), m, ar.cb, ar.R)
    # a_k = (u_k - (1/k) sum_{j=1}^{k-1} j a_j v_{k-j}) / v_0
    _b_quotient_step(A, ar.Af, s * KM, s, u * KM, u, vs * KM, vs, L, k, ar.RB + s * m2, ar.TB, ar.SB, Ls, m, ar.cb,
                     ar.R)


def _ln_slot_done(ar, s, k):
    sel = ar.sel
    if k == 0 and sel.size > 0 and sel[s] >= 0:
        # this slot's error becomes a symbol of its own (fresh_slots)
        A, m, z = ar.A, ar.m, s * ar.KM
        for c in range(ar.cb):
            A[z + ar.sel_base + sel[s], c] = A[z + m + 1, c]
            A[z + m + 1, c] = 0.0


def _ln_integrate(ar, i, o, k):  # x_[k+1] = f_[k] / (k + 1)
    A, m, KM = ar.A, ar.m, ar.KM
    m2 = m + 2
    z = ar.OB + i * KM + (k + 1) * m2
    _b_div_int_into(A, z, o * KM + k * m2, ar.L[o, k], m, float(k) + 1.0, ar.cb, ar.R)
    if i < ar.n_fresh:
        # the error of x_[k+1] becomes a symbol of its own: later orders then
        # carry it with its dependencies instead of as a bare radius
        sym = 1 + ar.m0 + k * ar.n_fresh + i
        for c in range(ar.cb):
            A[z + sym, c] = A[z + m + 1, c]
            A[z + m + 1, c] = 0.0


register(LaneTable, **rules_named(globals(), "_ln_"))


@njit(cache=True, forceinline=False, _nrt=True)
def _affine_kernel_into(op, a0, a1, aux, idx, cst, clo, chi, outputs, X, P, order, m0, n_fresh, keep, lanes,
                        sel, sel_base, work):
    """Affine forms of x_[0..order]; X (n, B, m+2) and P (p, B, m+2) are the input forms:
    the recursion (:mod:`verified.series.recursion`) with the table :class:`LaneTable`,
    once per chunk of ``lanes`` boxes.

    Returns the forms of the coefficients, (B, order + 1, n, m + 2), and the order-0
    forms of the slots ``keep``, (len(keep), B, m + 2).
    The same numbers as :func:`_affine_kernel_reference` (see the comment above).
    ``work``: a flat float array for the working forms, zeroed here, used when large
    enough (the caller keeps it between calls: fresh memory costs page faults of tens
    of MB per call on a 7-dof arm's tape), else the kernel allocates its own.
    """
    nslots = op.size
    n, nb, m2 = X.shape
    m = m2 - 2
    Lx = _highest_nonzero(X)
    Lp = _highest_nonzero(P)
    L, Lo = _live_counts(op, a0, a1, aux, idx, cst, outputs, Lx, Lp, order, m0, n_fresh, sel, sel_base)
    res = np.zeros((nb, order + 1, n, m2))
    kept = np.zeros((keep.size, nb, m2))
    CB = max(1, min(nb, lanes))
    K1 = order + 1
    KM = K1 * m2  # rows per slot
    # rows of A: slot forms (s, k) at s KM + k m2; the reciprocal of slot s at
    # RB + s m2; scratch forms T, S at TB, SB; the coefficient x_[k] of input i at
    # OB + i KM + k m2
    RB = nslots * KM
    TB = RB + nslots * m2
    SB = TB + m2
    OB = SB + m2
    size = _affine_work_size(nslots, order, m2, n, CB)
    if work.size >= size:
        Af = work[:size]
        Af[:] = 0.0  # (the loops rely on exact zeros past each form's last symbol)
    else:
        Af = np.zeros(size)
    A = Af.reshape((OB + n * KM, CB))  # the same numbers; Af for runs of whole rows
    R = np.zeros((3, CB))  # per-lane sums
    for b0 in range(0, nb, CB):
        cb = min(CB, nb - b0)
        for i in range(n):
            for r in range(m2):
                for c in range(cb):
                    A[OB + i * KM + r, c] = X[i, b0 + c, r]
        ar = LaneTable(A, Af, L, R, P, b0, cb, m, KM, RB, TB, SB, OB, sel, sel_base, m0, n_fresh)
        recursion(op, a0, a1, aux, idx, cst, clo, chi, outputs, order, ar)
        for c in range(cb):
            for k in range(K1):
                for i in range(n):
                    for r in range(m2):
                        res[b0 + c, k, i, r] = A[OB + i * KM + k * m2 + r, c]
            for j in range(keep.size):
                for r in range(m2):
                    kept[j, b0 + c, r] = A[keep[j] * KM + r, c]
    return res, kept


def _lanes(tape, order, m, n, nb):
    """Boxes per chunk for a batch of nb: at most _CHUNK, fewer if the chunk's arrays
    would pass _CHUNK_BYTES; chunks of about equal width (33 boxes: 17 + 16 lanes, both
    SIMD, not 32 + 1)."""
    per_box = (tape.op.size * (order + 2) + n * (order + 1) + 2) * (m + 2) * 8
    cap = int(max(1, min(_CHUNK, _CHUNK_BYTES // per_box)))
    chunks = -(-max(nb, 1) // cap)
    return -(-max(nb, 1) // chunks)


# --------------------------------------------------------------------------
# Forms <-> intervals
# --------------------------------------------------------------------------
def box_forms(lo: np.ndarray, hi: np.ndarray, symbols: np.ndarray, m: int) -> np.ndarray:
    """Affine forms of boxes: component ``j`` gets symbol ``symbols[j]`` (or none if < 0).

    ``lo, hi`` have shape (B, d); returns (d, B, m + 2) with ``x_j = mid_j + rad_j eps``
    (``rad`` rounded up so the form covers ``[lo, hi]``). Infinite bounds give the
    form of the whole real line.
    """
    nb, d = lo.shape
    F = np.zeros((d, nb, m + 2))
    with np.errstate(invalid="ignore", over="ignore"):
        mid = 0.5 * lo + 0.5 * hi
        rad = np.maximum(hi - mid, mid - lo)
        rad = rad + (np.abs(rad) * _k.EPS + _k.ETA)  # upward
    finite = np.isfinite(lo) & np.isfinite(hi) & np.isfinite(rad)
    for j in range(d):
        F[j, :, 0] = np.where(finite[:, j], mid[:, j], 0.0)
        if symbols[j] >= 0:
            F[j, :, 1 + symbols[j]] = np.where(finite[:, j], rad[:, j], 0.0)
            F[j, :, m + 1] = np.where(finite[:, j], 0.0, np.inf)
        else:
            F[j, :, m + 1] = np.where(finite[:, j], rad[:, j], np.inf)
    return F


def forms_to_interval(F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Interval ranges ``[c - R - e, c + R + e]`` of forms ``F[..., m + 2]`` (rounded
    outward); a NaN anywhere in a form gives ``[-inf, inf]``."""
    c = F[..., 0]
    with np.errstate(invalid="ignore", over="ignore"):
        R = np.abs(F[..., 1:-1]).sum(axis=-1) * _UPF + _TINY
        w = (R + F[..., -1]) * _UPF + _TINY
        lo = c - w
        hi = c + w
        lo = lo - (np.abs(lo) * _k.EPS + _k.ETA)
        hi = hi + (np.abs(hi) * _k.EPS + _k.ETA)
    # a NaN in a form's centre, symbols or error makes lo and hi NaN (no pass over F)
    bad = np.isnan(lo) | np.isnan(hi)
    lo = np.where(bad, -np.inf, lo)
    hi = np.where(bad, np.inf, hi)
    return lo, hi


def _wide_symbol_forms(graph, x, params, extra: int):
    """Input and parameter forms (n, B, m + 2), (p, B, m + 2) over one symbol per input
    or parameter that is wide in some box, ``m = m0 + extra`` (``extra`` symbols left for
    the caller); returns ``(X, P, m0)``. Checks the shapes of ``x`` (B, n) and ``params``."""
    x = _as_interval(x)
    n = graph.n_inputs
    if x.ndim != 2 or x.shape[-1] != n:
        raise ValueError(f"boxes must have shape (B, {n}), got {x.shape}")
    nb = x.shape[0]
    if graph.n_params:
        if params is None:
            raise ValueError(f"this graph has {graph.n_params} parameters {graph.param_names}; pass params")
        p = _as_interval(params)
        if p.shape[-1:] != (graph.n_params,):
            raise ValueError(f"params must have shape (..., {graph.n_params}), got {p.shape}")
        p = p.broadcast_to((nb, graph.n_params))
        plo, phi = p.lo, p.hi
    else:
        plo = phi = np.zeros((nb, 0))
    xwide = (x.hi > x.lo).any(axis=0)
    pwide = (phi > plo).any(axis=0)
    m0 = int(xwide.sum() + pwide.sum())
    m = m0 + int(extra)
    X = box_forms(x.lo, x.hi, np.where(xwide, np.cumsum(xwide) - 1, -1), m)
    P = box_forms(np.ascontiguousarray(plo), np.ascontiguousarray(phi),
                  np.where(pwide, xwide.sum() + np.cumsum(pwide) - 1, -1), m)
    return X, P, m0


#: :func:`affine_range` over up to this many boxes runs the per-box kernel, above it the
#: batched one (their numbers are equal; per call the per-box one took 0.95-1.23x the
#: batched one's time up to 64 boxes, 2.3-4.1x from 256 on; docs/lab/recursion_engine.md)
RANGE_PER_BOX_UP_TO = 64


def affine_range(graph, x, params=None) -> Interval:
    """Enclosure of a graph's outputs over boxes ``x`` (B, n_inputs) in affine
    arithmetic (one symbol per wide input or parameter): any graph, square or not.

    Tighter than ``graph.eval_interval`` where the outputs depend on the inputs through
    deep expressions (the LDL^T pivots of a 5-link arm's mass matrix over a box of
    radius 1e-3: interval [-0.29, 0.39], affine > 0). Returns (B, n_outputs).
    """
    tape = _Tape(graph)
    X, P, m = _wide_symbol_forms(graph, x, params, extra=0)
    nb = X.shape[1]
    # the kernel integrates n "state outputs", not used here: any valid slots will do
    dummy = np.full(graph.n_inputs, tape.outputs[0] if tape.outputs.size else 0, dtype=np.int64)
    if nb > RANGE_PER_BOX_UP_TO:
        # many boxes: the batched kernel (2-4x faster from 256 boxes on)
        _, G = _affine_kernel(tape.op, tape.a0, tape.a1, tape.aux, tape.idx, tape.cst, tape.clo, tape.chi, dummy,
                              X, P, 1, m, 0, tape.outputs, _lanes(tape, 1, m, graph.n_inputs, nb), _NO_SLOTS, 0)
    else:
        G = _output_forms_per_box(tape, X, P, m, dummy)
    lo, hi = forms_to_interval(G.transpose(1, 0, 2))
    return Interval._from_bounds(lo, hi)


def _output_forms_per_box(tape, X, P, m: int, dummy) -> np.ndarray:
    """The outputs' affine forms (outputs, boxes, m + 2) by the per-box kernel, for
    :func:`affine_range` over few boxes (a robot's frames, the mass-matrix proof of one
    piece): one pass at order 0 gives every slot's form, the batched kernel's numbers
    (tests/verified/test_affine_taylor.py) at 0.95-1.23x its time, and such a run then
    never compiles the batched kernel, ~60 s of CPU once per installation
    (docs/lab/recursion_engine.md). The kernel keeps every slot's forms, slots x 2 x
    boxes x (m + 2): boxes in chunks."""
    nb = X.shape[1]
    per_box = tape.op.size * 2 * (m + 2) * 8
    step = int(max(1, min(nb, _CHUNK_BYTES // max(per_box, 1))))
    parts = []
    for b0 in range(0, max(nb, 1), step):
        b1 = min(nb, b0 + step)
        _, F = _affine_kernel_reference(tape.op, tape.a0, tape.a1, tape.aux, tape.idx, tape.cst, tape.clo,
                                        tape.chi, dummy, np.ascontiguousarray(X[:, b0:b1]),
                                        np.ascontiguousarray(P[:, b0:b1]), 1, m, 0, _NO_SLOTS, 0)
        parts.append(F[tape.outputs, 0])  # (outputs, boxes, m + 2)
    return np.concatenate(parts, axis=1) if len(parts) > 1 else parts[0]


class AffineTaylorODE:
    """Taylor-coefficient enclosures like :class:`verified.series.taylor.TaylorODE`, computed in
    affine arithmetic over one noise symbol per wide input (and wide parameter).

    Same call and result shapes as ``TaylorODE.coefficients``; tighter over boxes of
    deep graphs, about ``m + 1`` times the work per operation for ``m`` symbols.

    ``fresh_slots`` (for :meth:`series`, default 0): at every call, the order-0 errors
    of the ``fresh_slots`` tape slots that create the most error in the outputs
    (:func:`_weighted_attribution`, from a first pass over the same forms) become symbols
    of their own. A lumped error radius propagates through every later operation by
    absolute values; as a symbol it propagates with its signs, and the paths that carry
    it to an output cancel as the true derivatives do. Why: on a robot much of a step's
    Jacobian error comes from the small errors of a few slots (``sin`` and ``cos`` of
    joint angles) carried to the output along hundreds of paths, and fresh symbols for
    them make it several times narrower at a moderate cost
    (``benchmarks/bench_jacobian_spread.py``, docs/lab/code_notes.md).
    Only for batches of at most ``fresh_slots_batch`` sets (default 1): the fresh symbols
    make every later form as long as the longest, which the batched kernel otherwise
    avoids, and on a batch the longer steps did not pay for the cost per step
    (docs/lab/code_notes.md).
    """

    def __init__(self, graph, fresh_symbols=None, fresh_slots: int = 0, fresh_slots_batch: int = 1):
        if graph.n_outputs != graph.n_inputs:
            raise ValueError(
                f"an ODE right-hand side needs as many outputs as inputs, got {graph.n_inputs} "
                f"inputs and {graph.n_outputs} outputs"
            )
        self.graph = graph
        self.n = graph.n_inputs
        self.n_params = graph.n_params
        self._tape = _Tape(graph)
        n_fresh = self.n if fresh_symbols is None else int(fresh_symbols)
        if not 0 <= n_fresh <= self.n:
            raise ValueError(f"fresh_symbols must be in [0, {self.n}], got {fresh_symbols!r}")
        self.n_fresh = n_fresh
        if isinstance(fresh_slots, bool) or not isinstance(fresh_slots, (int, np.integer)) or fresh_slots < 0:
            raise ValueError(f"fresh_slots must be an integer >= 0, got {fresh_slots!r}")
        self.fresh_slots = int(fresh_slots)
        if isinstance(fresh_slots_batch, bool) or not isinstance(fresh_slots_batch, (int, np.integer)) \
                or fresh_slots_batch < 1:
            raise ValueError(f"fresh_slots_batch must be an integer >= 1, got {fresh_slots_batch!r}")
        self.fresh_slots_batch = int(fresh_slots_batch)
        self.last_fresh_slots = _NO_SLOTS  # the slots chosen at the last series() call

    def forms(self, x, order, params=None):
        """Affine forms of ``x_[0..order]``: array (B, order + 1, n, m + 2) and ``m``."""
        order = int(order)
        if order < 1:
            raise ValueError(f"order must be >= 1, got {order}")
        X, P, m0 = _wide_symbol_forms(self.graph, x, params, extra=self.n_fresh * order)
        return self._run(X, P, order, m0), m0 + self.n_fresh * order

    def series(self, X, order, params=None):
        """Interval enclosures of ``x_[0..order]`` from given input forms ``X``
        (n, B, m0 + 2) over ``m0`` symbols of the caller's choosing (for example a
        set's own parameters, :meth:`verified.steppers.lohner.DoubletonSets.affine_forms`).
        Parameters are taken as intervals without symbols. Returns (B, order + 1, n).
        """
        n, nb, m2 = X.shape
        m0 = m2 - 2
        order = int(order)
        k_sel = min(self.fresh_slots, self._tape.op.size) if nb <= self.fresh_slots_batch else 0
        m = m0 + self.n_fresh * order + k_sel
        Xf = np.zeros((n, nb, m + 2))
        Xf[..., : m0 + 1] = X[..., : m0 + 1]
        Xf[..., m + 1] = X[..., m0 + 1]
        if self.n_params:
            p = _as_interval(params).broadcast_to((nb, self.n_params))
            P = box_forms(p.lo, p.hi, np.full(self.n_params, -1), m)
        else:
            P = np.zeros((0, nb, m + 2))
        sel = self._rank_fresh_slots(Xf, P, m0, k_sel) if k_sel else _NO_SLOTS
        lo, hi = forms_to_interval(self._run(Xf, P, order, m0, sel, 1 + m0 + self.n_fresh * order))
        return Interval._from_bounds(lo, hi)

    def _rank_fresh_slots(self, X, P, m0, k_sel):
        """``sel`` for the kernels: the ``k_sel`` slots of most attributed error over the
        forms ``X`` (summed over the sets), numbered 0.. in tape order (their symbols are
        the last ``k_sel`` columns of the forms), -1 elsewhere. One order-1 pass of the
        reference kernel over the same forms gives the slots' centres and errors."""
        t = self._tape
        _, F1 = _affine_kernel_reference(t.op, t.a0, t.a1, t.aux, t.idx, t.cst, t.clo, t.chi, t.outputs, X, P,
                                         1, m0, self.n_fresh, _NO_SLOTS, 0)
        score = _weighted_attribution(t.op, t.a0, t.a1, F1, X.shape[2] - 2, t.outputs)
        top = np.argsort(-score, kind="stable")[:k_sel]
        top = np.sort(top[score[top] > 0.0])
        sel = np.full(t.op.size, -1, dtype=np.int64)
        sel[top] = np.arange(top.size)
        self.last_fresh_slots = top
        return sel

    def _run(self, X, P, order, m0, sel=_NO_SLOTS, sel_base=0):
        """The coefficient forms (B, order + 1, n, m + 2) by the kernel that suits the
        batch; ``sel``/``sel_base``: fresh symbols for chosen slots (:meth:`_rank_fresh_slots`)."""
        t = self._tape
        args = (t.op, t.a0, t.a1, t.aux, t.idx, t.cst, t.clo, t.chi, t.outputs, X, P, order, m0, self.n_fresh)
        if X.shape[1] == 1 and self.n_fresh == 0:
            # one box, no fresh symbols (the variational series of a single set): nothing
            # to skip and no lanes to fill, and on big tapes the per-box reference is
            # faster (docs/lab/code_notes.md). Same bits.
            F, _ = _affine_kernel_reference(*args, sel, sel_base)
            return np.ascontiguousarray(F.transpose(2, 1, 0, 3))
        lanes = _lanes(t, order, X.shape[2] - 2, self.n, X.shape[1])
        F, _ = _affine_kernel_into(*args, _NO_SLOTS, lanes, sel, sel_base, self._work(t, order, X.shape[2], lanes,
                                                                                     X.shape[1]))
        return F

    def __getstate__(self):
        # the kernel's work memory is scratch (tens to hundreds of MB): not pickled
        state = self.__dict__.copy()
        state.pop("_work_buffer", None)
        return state

    def _work(self, tape, order, m2, lanes, nb):
        """A flat work buffer for :func:`_affine_kernel_into`, kept between calls and
        grown as needed (safe to share: the kernel holds the GIL)."""
        size = _affine_work_size(tape.op.size, order, m2, self.n, max(1, min(nb, lanes)))
        buf = getattr(self, "_work_buffer", None)
        if buf is None or buf.size < size:
            buf = np.empty(int(size * 1.25))
            self._work_buffer = buf
        return buf

    def coefficients(self, x, order, params=None):
        """Interval enclosures of ``x_[0..order]``, shape (B, order + 1, n)."""
        F, _ = self.forms(x, order, params)
        lo, hi = forms_to_interval(F)
        return Interval._from_bounds(lo, hi)

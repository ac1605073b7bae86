# Whole: the compiled interval kernels are one compilation unit (numba, cached per module).
"""Compiled interval kernels: outward rounding, scalar interval operations, array loops.

This module is the bottom layer of ``verified`` (the layering follows
IntervalArithmetic.jl: rounding -> scalar operations -> arrays -> linear algebra).
Every scalar operation takes interval endpoints as plain floats and returns a
``(lo, hi)`` tuple; the array loops apply one of them to flat float64 arrays.
Nothing here validates user input: :mod:`verified.arith.interval` does that.

Conventions
-----------
* An interval is a pair ``lo <= hi`` of float64, possibly infinite (``[-inf, x]``).
* The empty set is ``(+inf, -inf)``. Every operation maps an empty operand to empty.
* A NaN never stands for anything: it marks a bug or an invalid user input.

Rounding model (the proof obligations)
--------------------------------------
IEEE 754 ``+ - * /`` and ``sqrt`` round to nearest, so the exact result ``z`` of
one such operation with result ``r`` satisfies ``|z - r| <= ulp(r)/2 <= |r| 2^-53``
(plus half a subnormal step on underflow). :func:`rd` and :func:`ru` move ``r``
outward by ``|r| 2^-52 + 2^-1074`` which always reaches the next float in that
direction, so ``rd(r) <= z <= ru(r)``. This is much cheaper than
``np.nextafter`` (docs/lab/code_notes.md) and gives results at most two ulps wider than the exact ones.

For ``exp log sin cos tan atan`` we rely on the platform libm (glibc on Linux,
which documents errors of at most 1-2 ulp; the tests check it against python-flint,
docs/lab/code_notes.md). We allow ``|r| 2^-49 + 4*2^-1074`` (8 ulps plus four
subnormal steps) on top of the libm result: :func:`rd_t`, :func:`ru_t`.
"""

import math

import numpy as np
from numba import njit

INF = math.inf
MAXF = float(np.finfo(np.float64).max)
EPS = 2.0**-52  # outward step for correctly rounded operations
ETA = 5e-324  # smallest positive subnormal
TRANS_REL = 2.0**-49  # libm allowance, relative (8 ulp)
TRANS_ABS = 4 * 5e-324  # libm allowance, absolute (subnormal results)

_CACHE = True  # numba on-disk cache next to this file (falls back to a user dir)


# --------------------------------------------------------------------------
# Rounding
# --------------------------------------------------------------------------
@njit(cache=_CACHE)
def rd(x):
    """Lower bound of the exact value of one correctly rounded operation with result ``x``."""
    if x == INF:  # the exact value overflowed: it is at least MAXF
        return MAXF
    return x - (abs(x) * EPS + ETA)


def kernel_array(a):
    """``a`` as a C-contiguous, writable float64 array for a compiled kernel (a copy only
    when it is not one already). numba compiles a separate specialization for a
    read-only argument (``np.broadcast_to`` views, and ``np.ascontiguousarray`` keeps them
    read-only): a full test run compiled four versions of ``mul_loop`` and two of the
    Taylor kernel, each once more on a cold cache. (Not ``np.require``: it costs more per
    call, and the interval operations call this on every operand; docs/lab/code_notes.md.)"""
    a = np.ascontiguousarray(a, dtype=np.float64)
    return a if a.flags.writeable else a.copy()


@njit(cache=_CACHE)
def ru(x):
    """Upper bound of the exact value of one correctly rounded operation with result ``x``."""
    if x == -INF:
        return -MAXF
    return x + (abs(x) * EPS + ETA)


@njit(cache=_CACHE)
def rd_t(x):
    """Lower bound of the exact value of a libm transcendental with result ``x``."""
    if x == INF:
        return MAXF
    return x - (abs(x) * TRANS_REL + TRANS_ABS)


@njit(cache=_CACHE)
def ru_t(x):
    """Upper bound of the exact value of a libm transcendental with result ``x``."""
    if x == -INF:
        return -MAXF
    return x + (abs(x) * TRANS_REL + TRANS_ABS)


# --------------------------------------------------------------------------
# Scalar interval operations: endpoints in, (lo, hi) out
# --------------------------------------------------------------------------
@njit(cache=_CACHE)
def is_empty(a, b):
    return not (a <= b)


@njit(cache=_CACHE)
def add(a, b, c, d):
    if is_empty(a, b) or is_empty(c, d):
        return INF, -INF
    return rd(a + c), ru(b + d)


@njit(cache=_CACHE)
def sub(a, b, c, d):
    if is_empty(a, b) or is_empty(c, d):
        return INF, -INF
    return rd(a - d), ru(b - c)


@njit(cache=_CACHE)
def _prod(x, y):
    # 0 * inf is NaN in IEEE arithmetic but 0 times any real number is 0.
    p = x * y
    if p != p:
        return 0.0
    return p


@njit(cache=_CACHE)
def mul(a, b, c, d):
    if is_empty(a, b) or is_empty(c, d):
        return INF, -INF
    p1 = _prod(a, c)
    p2 = _prod(a, d)
    p3 = _prod(b, c)
    p4 = _prod(b, d)
    lo = min(min(p1, p2), min(p3, p4))
    hi = max(max(p1, p2), max(p3, p4))
    return rd(lo), ru(hi)


@njit(cache=_CACHE)
def div(a, b, c, d):
    """``[a, b] / [c, d]``; the hull of the exact image when ``0 in [c, d]`` (IEEE 1788)."""
    if is_empty(a, b) or is_empty(c, d):
        return INF, -INF
    if c > 0.0:  # x / y increases with x; pick the divisor end by the sign of x
        return rd(a / (d if a >= 0.0 else c)), ru(b / (c if b >= 0.0 else d))
    if d < 0.0:  # x / y decreases with x
        return rd(b / (d if b >= 0.0 else c)), ru(a / (c if a >= 0.0 else d))
    # The divisor contains zero.
    if c == 0.0 and d == 0.0:
        return INF, -INF  # x / {0} is empty
    if a == 0.0 and b == 0.0:
        return 0.0, 0.0
    if c < 0.0 and d > 0.0:
        return -INF, INF
    if c == 0.0:  # divisor [0, d], d > 0
        if a >= 0.0:
            return max(rd(a / d), 0.0), INF
        if b <= 0.0:
            return -INF, min(ru(b / d), 0.0)
        return -INF, INF
    # divisor [c, 0], c < 0
    if a >= 0.0:
        return -INF, min(ru(a / c), 0.0)
    if b <= 0.0:
        return max(rd(b / c), 0.0), INF
    return -INF, INF


@njit(cache=_CACHE)
def sqr(a, b):
    if is_empty(a, b):
        return INF, -INF
    if a >= 0.0:
        return max(rd(a * a), 0.0), ru(b * b)
    if b <= 0.0:
        return max(rd(b * b), 0.0), ru(a * a)
    m = max(-a, b)
    return 0.0, ru(m * m)


@njit(cache=_CACHE)
def _pow_pos_lo(x, n):
    """Lower bound of ``x ** n`` for ``x >= 0`` and ``n >= 0``, by repeated squaring.

    A product of lower bounds of non-negative factors, each rounded down (and kept
    >= 0), is a lower bound of the exact product; so is every square. ``log2(n)``
    squarings instead of ``n`` products: cheaper and fewer roundings."""
    r = 1.0
    base = x
    while n > 0:
        if n & 1:
            r = max(rd(r * base), 0.0)
        n >>= 1
        if n > 0:
            base = max(rd(base * base), 0.0)
    return r


@njit(cache=_CACHE)
def _pow_pos_hi(x, n):
    """Upper bound of ``x ** n`` for ``x >= 0``, ``n >= 0`` (see :func:`_pow_pos_lo`)."""
    r = 1.0
    base = x
    while n > 0:
        if n & 1:
            r = ru(r * base)
        n >>= 1
        if n > 0:
            base = ru(base * base)
    return r


@njit(cache=_CACHE)
def ipow(a, b, n):
    """``[a, b] ** n`` for an integer ``n`` (``n < 0`` goes through division)."""
    if is_empty(a, b):
        return INF, -INF
    if n == 0:
        return 1.0, 1.0
    if n < 0:
        plo, phi = _ipow_nonneg(a, b, -n)
        return div(1.0, 1.0, plo, phi)
    return _ipow_nonneg(a, b, n)


@njit(cache=_CACHE)
def _ipow_nonneg(a, b, n):
    if n % 2 == 1:  # odd powers are increasing
        lo = _pow_pos_lo(a, n) if a >= 0.0 else -_pow_pos_hi(-a, n)
        hi = _pow_pos_hi(b, n) if b >= 0.0 else -_pow_pos_lo(-b, n)
        return lo, hi
    if a >= 0.0:
        return _pow_pos_lo(a, n), _pow_pos_hi(b, n)
    if b <= 0.0:
        return _pow_pos_lo(-b, n), _pow_pos_hi(-a, n)
    return 0.0, _pow_pos_hi(max(-a, b), n)


@njit(cache=_CACHE)
def sqrt(a, b):
    """Square root restricted to its domain ``[0, inf]`` (empty if ``b < 0``)."""
    if is_empty(a, b) or b < 0.0:
        return INF, -INF
    lo = 0.0 if a <= 0.0 else max(rd(math.sqrt(a)), 0.0)
    return lo, ru(math.sqrt(b))


@njit(cache=_CACHE)
def exp(a, b):
    if is_empty(a, b):
        return INF, -INF
    return max(rd_t(math.exp(a)), 0.0), ru_t(math.exp(b))


@njit(cache=_CACHE)
def log(a, b):
    """Natural logarithm restricted to its domain ``(0, inf]`` (empty if ``b <= 0``)."""
    if is_empty(a, b) or b <= 0.0:
        return INF, -INF
    lo = -INF if a <= 0.0 else rd_t(math.log(a))
    return lo, ru_t(math.log(b))


@njit(cache=_CACHE)
def atan(a, b):
    if is_empty(a, b):
        return INF, -INF
    return rd_t(math.atan(a)), ru_t(math.atan(b))


@njit(cache=_CACHE)
def _err_t(y):
    return abs(y) * TRANS_REL + TRANS_ABS


@njit(cache=_CACHE)
def _periodic_narrow(fa, fb, da, db):
    """Range of sin or cos over ``[a, b]`` with ``b - a <= 3 < pi``.

    ``fa, fb`` are libm values of the function at the endpoints, ``da, db`` libm
    values of its derivative. Critical points are pi apart, so at most one lies in
    ``[a, b]``; it is a maximum iff the derivative goes from >= 0 to <= 0 and a
    minimum iff it goes from <= 0 to >= 0. Where a derivative's sign is uncertain
    within the libm error, both cases are assumed (sound, and costless: the function
    is within rounding of its extreme value there).
    """
    ea = _err_t(fa)
    eb = _err_t(fb)
    lo = min(fa - ea, fb - eb)
    hi = max(fa + ea, fb + eb)
    eda = _err_t(da)
    edb = _err_t(db)
    # A maximum (value 1) lies within 1.5 < pi/2 of the nearer endpoint, where the
    # function is therefore positive; likewise a minimum makes one endpoint negative.
    # This settles derivative signs lost in rounding (cos of [5e-324, 5e-324]).
    if da + eda >= 0.0 and db - edb <= 0.0 and max(fa + ea, fb + eb) > 0.0:
        hi = 1.0
    if da - eda <= 0.0 and db + edb >= 0.0 and min(fa - ea, fb - eb) < 0.0:
        lo = -1.0
    return max(lo, -1.0), min(hi, 1.0)


@njit(cache=_CACHE)
def _sin_narrow(a, b):
    return _periodic_narrow(math.sin(a), math.sin(b), math.cos(a), math.cos(b))


@njit(cache=_CACHE)
def _cos_narrow(a, b):
    return _periodic_narrow(math.cos(a), math.cos(b), -math.sin(a), -math.sin(b))


_FULL_PERIOD = 6.2831853  # just below 2 pi: wider intervals map onto [-1, 1]


_NARROW = 3.0  # widest piece handed to _periodic_narrow (< pi: one critical point at most)


@njit(cache=_CACHE)
def _periodic(a, b, is_cos):
    """Range of sin or cos over ``[a, b]``.

    An interval of width >= 2 pi maps onto [-1, 1]. A narrower one is cut into at
    most three pieces, each of which must be at most 3 < pi wide so that
    :func:`_periodic_narrow` (one critical point at most) applies. The cut points are
    floats: where the floats are sparse (ulp 4 for ``|x|`` in [2^54, 2^55), so an
    interval one ulp wide is 4 > pi wide and cannot be cut at all), a piece can stay
    wider than 3; the range is then taken as [-1, 1]: sound, and only reached for
    ``|x| >= 2^54`` where such an interval is at least one ulp = 4 > pi wide.
    """
    if is_empty(a, b):
        return INF, -INF
    w = b - a
    if not (w < _FULL_PERIOD):  # also catches infinite bounds
        return -1.0, 1.0
    if w <= _NARROW:
        return _cos_narrow(a, b) if is_cos else _sin_narrow(a, b)
    # Three pieces whose union is exactly [a, b]; in exact arithmetic each is < 2.1 wide.
    m1 = min(a + w / 3.0, b)
    m2 = max(min(a + 2.0 * w / 3.0, b), m1)
    lo = 1.0
    hi = -1.0
    for (p, q) in ((a, m1), (m1, m2), (m2, b)):
        if not (q - p <= _NARROW):  # rounding of the cut points left a piece too wide
            return -1.0, 1.0
        l, h = _cos_narrow(p, q) if is_cos else _sin_narrow(p, q)
        lo = min(lo, l)
        hi = max(hi, h)
    return lo, hi


@njit(cache=_CACHE)
def sin(a, b):
    return _periodic(a, b, np.bool_(False))  # (not literals: one compilation)


@njit(cache=_CACHE)
def cos(a, b):
    return _periodic(a, b, np.bool_(True))  # (not literals: one compilation)


@njit(cache=_CACHE)
def tan(a, b):
    """Tangent; the whole real line when ``[a, b]`` may contain a pole."""
    if is_empty(a, b):
        return INF, -INF
    if not (b - a < 3.14159265):  # any interval of width >= pi holds a pole
        return -INF, INF
    ca = math.cos(a)
    cb = math.cos(b)
    # Poles are pi apart: at most one lies in [a, b], and it does iff cos changes sign.
    if abs(ca) <= _err_t(ca) or abs(cb) <= _err_t(cb) or (ca > 0.0) != (cb > 0.0):
        return -INF, INF
    return rd_t(math.tan(a)), ru_t(math.tan(b))


@njit(cache=_CACHE)
def iabs(a, b):
    if is_empty(a, b):
        return INF, -INF
    if a >= 0.0:
        return a, b
    if b <= 0.0:
        return -b, -a
    return 0.0, max(-a, b)


@njit(cache=_CACHE)
def imin(a, b, c, d):
    if is_empty(a, b) or is_empty(c, d):
        return INF, -INF
    return min(a, c), min(b, d)


@njit(cache=_CACHE)
def imax(a, b, c, d):
    if is_empty(a, b) or is_empty(c, d):
        return INF, -INF
    return max(a, c), max(b, d)


# --------------------------------------------------------------------------
# Array loops: flat endpoint arrays in, results written to flat ``lo, hi``.
# The caller allocates the outputs with numpy, which asks the kernel for huge
# pages on big arrays: allocating inside numba is slower through page faults.
# One explicit loop per operation: a shared loop that switches on an op code runs
# slower, and numba cannot cache loops made by a factory function
# (docs/lab/code_notes.md).
# --------------------------------------------------------------------------
@njit(cache=_CACHE)
def _add_careful(a, b, c, d, lo, hi):
    for i in range(a.size):
        lo[i], hi[i] = add(a[i], b[i], c[i], d[i])


@njit(cache=_CACHE)
def _sub_careful(a, b, c, d, lo, hi):
    for i in range(a.size):
        lo[i], hi[i] = sub(a[i], b[i], c[i], d[i])


@njit(cache=_CACHE)
def _mul_careful(a, b, c, d, lo, hi):
    for i in range(a.size):
        lo[i], hi[i] = mul(a[i], b[i], c[i], d[i])


@njit(cache=_CACHE)
def _div_careful(a, b, c, d, lo, hi):
    for i in range(a.size):
        lo[i], hi[i] = div(a[i], b[i], c[i], d[i])


# Fast paths. The common case (non-empty, finite operands and results, divisor
# away from zero) is written with selects only, so LLVM vectorizes the loop; any
# other element makes the loop report failure and the careful loop above redoes
# the whole array. Both give the same bounds wherever the fast path applies.
@njit(cache=_CACHE, error_model="numpy")
def _fast_ok(a, b, c, d, lo, hi):
    return (a <= b) & (c <= d) & (abs(a) <= MAXF) & (abs(b) <= MAXF) & (abs(c) <= MAXF) & (
        abs(d) <= MAXF) & (abs(lo) <= MAXF) & (abs(hi) <= MAXF)


@njit(cache=_CACHE, error_model="numpy")
def add_loop(a, b, c, d, lo, hi):
    ok = True
    for i in range(a.size):
        l = a[i] + c[i]
        h = b[i] + d[i]
        lo[i] = l - (abs(l) * EPS + ETA)
        hi[i] = h + (abs(h) * EPS + ETA)
        ok &= _fast_ok(a[i], b[i], c[i], d[i], l, h)
    if not ok:
        _add_careful(a, b, c, d, lo, hi)


@njit(cache=_CACHE, error_model="numpy")
def sub_loop(a, b, c, d, lo, hi):
    ok = True
    for i in range(a.size):
        l = a[i] - d[i]
        h = b[i] - c[i]
        lo[i] = l - (abs(l) * EPS + ETA)
        hi[i] = h + (abs(h) * EPS + ETA)
        ok &= _fast_ok(a[i], b[i], c[i], d[i], l, h)
    if not ok:
        _sub_careful(a, b, c, d, lo, hi)


@njit(cache=_CACHE, error_model="numpy")
def mul_loop(a, b, c, d, lo, hi):
    ok = True
    for i in range(a.size):
        p1 = a[i] * c[i]
        p2 = a[i] * d[i]
        p3 = b[i] * c[i]
        p4 = b[i] * d[i]
        l = min(min(p1, p2), min(p3, p4))
        h = max(max(p1, p2), max(p3, p4))
        lo[i] = l - (abs(l) * EPS + ETA)
        hi[i] = h + (abs(h) * EPS + ETA)
        ok &= _fast_ok(a[i], b[i], c[i], d[i], l, h)
    if not ok:
        _mul_careful(a, b, c, d, lo, hi)


@njit(cache=_CACHE)
def horner_loop(clo, chi, hl, hh, lo, hi):
    """Interval Horner sums ``acc = c[m, K-1]; acc = acc * h + c[m, i]`` (i = K-2 .. 0)
    for every row ``m`` of the (M, K) coefficient bounds ``clo``/``chi`` at the interval
    ``[hl, hh]``, into ``lo``/``hi`` (M,): the same outward-rounded ``mul`` and ``add``
    per operation as the interval operators, in one compiled pass instead of 2 (K - 1)
    array operations (the Lohner and second-order steps' polynomial sums)."""
    K = clo.shape[1]
    for m in range(clo.shape[0]):
        al = clo[m, K - 1]
        ah = chi[m, K - 1]
        for i in range(K - 2, -1, -1):
            al, ah = mul(al, ah, hl, hh)
            al, ah = add(al, ah, clo[m, i], chi[m, i])
        lo[m] = al
        hi[m] = ah


@njit(cache=_CACHE, error_model="numpy")
def div_loop(a, b, c, d, lo, hi):
    ok = True
    for i in range(a.size):
        ai = a[i]
        bi = b[i]
        ci = c[i]
        di = d[i]
        # Same divisor choice as `div` for c > 0 and for d < 0, unified.
        pos = ci > 0.0
        nl = ai if pos else bi
        nh = bi if pos else ai
        l = nl / (di if nl >= 0.0 else ci)
        h = nh / (ci if nh >= 0.0 else di)
        lo[i] = l - (abs(l) * EPS + ETA)
        hi[i] = h + (abs(h) * EPS + ETA)
        ok &= _fast_ok(ai, bi, ci, di, l, h) & ((ci > 0.0) | (di < 0.0))
    if not ok:
        _div_careful(a, b, c, d, lo, hi)


@njit(cache=_CACHE)
def imin_loop(a, b, c, d, lo, hi):
    for i in range(a.size):
        lo[i], hi[i] = imin(a[i], b[i], c[i], d[i])


@njit(cache=_CACHE)
def imax_loop(a, b, c, d, lo, hi):
    for i in range(a.size):
        lo[i], hi[i] = imax(a[i], b[i], c[i], d[i])


@njit(cache=_CACHE)
def sqr_loop(a, b, lo, hi):
    for i in range(a.size):
        lo[i], hi[i] = sqr(a[i], b[i])


@njit(cache=_CACHE)
def sqrt_loop(a, b, lo, hi):
    for i in range(a.size):
        lo[i], hi[i] = sqrt(a[i], b[i])


@njit(cache=_CACHE)
def exp_loop(a, b, lo, hi):
    for i in range(a.size):
        lo[i], hi[i] = exp(a[i], b[i])


@njit(cache=_CACHE)
def log_loop(a, b, lo, hi):
    for i in range(a.size):
        lo[i], hi[i] = log(a[i], b[i])


@njit(cache=_CACHE)
def sin_loop(a, b, lo, hi):
    for i in range(a.size):
        lo[i], hi[i] = sin(a[i], b[i])


@njit(cache=_CACHE)
def cos_loop(a, b, lo, hi):
    for i in range(a.size):
        lo[i], hi[i] = cos(a[i], b[i])


@njit(cache=_CACHE)
def tan_loop(a, b, lo, hi):
    for i in range(a.size):
        lo[i], hi[i] = tan(a[i], b[i])


@njit(cache=_CACHE)
def atan_loop(a, b, lo, hi):
    for i in range(a.size):
        lo[i], hi[i] = atan(a[i], b[i])


@njit(cache=_CACHE)
def iabs_loop(a, b, lo, hi):
    for i in range(a.size):
        lo[i], hi[i] = iabs(a[i], b[i])


@njit(cache=_CACHE)
def ipow_loop(a, b, n, lo, hi):
    for i in range(a.size):
        lo[i], hi[i] = ipow(a[i], b[i], n)


# ----------------------------------------------------------------- matrix products
@njit(cache=True)
def matvec_bounds(alo, ahi, xlo, xhi):
    """Bounds of the interval matrix-vector products ``a[b] @ x[b]`` of a batch: ``alo``,
    ``ahi`` (nb, n, k), ``xlo``, ``xhi`` (nb, k) -> ``clo``, ``chi`` (nb, n): the same
    ``mul`` and ``add`` in the same order as :func:`matmul_bounds` with one column."""
    nb, n, k = alo.shape
    clo = np.empty((nb, n))
    chi = np.empty((nb, n))
    for b in range(nb):
        for i in range(n):
            sl = 0.0
            sh = 0.0
            for t in range(k):
                pl, ph = mul(alo[b, i, t], ahi[b, i, t], xlo[b, t], xhi[b, t])
                sl, sh = add(sl, sh, pl, ph)
            clo[b, i] = sl
            chi[b, i] = sh
    return clo, chi


@njit(cache=True)
def matmul_bounds(alo, ahi, blo, bhi):
    """Bounds of the interval matrix products ``a[b] @ b[b]`` of a batch: ``alo``,
    ``ahi`` (nb, n, k), ``blo``, ``bhi`` (nb, k, m) -> ``clo``, ``chi`` (nb, n, m)."""
    nb, n, k = alo.shape
    m = blo.shape[2]
    clo = np.empty((nb, n, m))
    chi = np.empty((nb, n, m))
    for b in range(nb):
        for i in range(n):
            for j in range(m):
                sl = 0.0
                sh = 0.0
                for t in range(k):
                    pl, ph = mul(alo[b, i, t], ahi[b, i, t], blo[b, t, j], bhi[b, t, j])
                    sl, sh = add(sl, sh, pl, ph)
                clo[b, i, j] = sl
                chi[b, i, j] = sh
    return clo, chi


# ----------------------------------------------------------------- the step's tube box
@njit(cache=True)
def _np_max(a, b):
    """``np.maximum(a, b)`` of two floats: NaN from either, else ``a if a > b else b``
    (the second of two equal values: ``np.maximum(0.0, -0.0)`` is ``-0.0``)."""
    if a != a:
        return a
    if b != b:
        return b
    return a if a > b else b


@njit(cache=True)
def _np_min(a, b):
    """``np.minimum(a, b)`` of two floats (see :func:`_np_max`)."""
    if a != a:
        return a
    if b != b:
        return b
    return a if a < b else b


@njit(cache=True)
def tube_box_bounds(xlo, xhi, vlo, vhi, clo, chi, taus, K):
    """The box of :func:`verified.steppers.tm_flow.step_tube` from the ranges of
    ``x(tau_j)`` and ``x'(tau_j)`` without their Lagrange terms, ``xlo``, ``xhi``, ``vlo``,
    ``vhi`` (P, n, B), the coefficients over the a-priori enclosure ``clo``, ``chi`` (B,
    K + 1, n) and the times ``taus`` (P,) (finite, non-negative, increasing): ``lo``, ``hi``
    (B, n). The same scalar ``add``, ``sub``, ``mul`` and ``ipow`` with the same operands
    in the same order as the interval expressions there (the arrays' fast loops give
    the same bounds as these), and numpy's ``maximum``, ``minimum`` and its reduction
    over the pieces (first to last)."""
    P = taus.size
    n = xlo.shape[1]
    nb = xlo.shape[2]
    lo = np.empty((nb, n))
    hi = np.empty((nb, n))
    fK = float(K)
    Xl = np.empty(P)
    Xh = np.empty(P)
    Vl = np.empty(P)
    Vh = np.empty(P)
    for b in range(nb):
        for i in range(n):
            kl, kh = clo[b, K, i], chi[b, K, i]
            c2l, c2h = clo[b, 2, i], chi[b, 2, i]
            for j in range(P):
                # X = x + cK * t ** K, V = x' + K * (cK * t ** (K - 1))
                tl, th = ipow(taus[j], taus[j], K)
                pl, ph = mul(kl, kh, tl, th)
                Xl[j], Xh[j] = add(xlo[j, i, b], xhi[j, i, b], pl, ph)
                tl, th = ipow(taus[j], taus[j], K - 1)
                pl, ph = mul(kl, kh, tl, th)
                pl, ph = mul(fK, fK, pl, ph)
                Vl[j], Vh[j] = add(vlo[j, i, b], vhi[j, i, b], pl, ph)
            accl = 0.0
            acch = 0.0
            for j in range(P - 1):
                # d = [0, hi(tau_j+1 - tau_j)], bend = c2 * d ** 2
                dh = sub(taus[j + 1], taus[j + 1], taus[j], taus[j])[1]
                d2l, d2h = ipow(0.0, dh, np.int64(2))  # (not a literal: tests/verified/test_kernel_literals.py)
                bl, bh = mul(c2l, c2h, d2l, d2h)
                # left = X_j + V_j d + bend, right = X_j+1 - V_j+1 d + bend
                pl, ph = mul(Vl[j], Vh[j], 0.0, dh)
                sl, sh = add(Xl[j], Xh[j], pl, ph)
                ll, lh = add(sl, sh, bl, bh)
                pl, ph = mul(Vl[j + 1], Vh[j + 1], 0.0, dh)
                sl, sh = sub(Xl[j + 1], Xh[j + 1], pl, ph)
                rl, rh = add(sl, sh, bl, bh)
                # their intersection (empty: [inf, -inf]); where empty, left alone
                el = _np_max(ll, rl)
                eh = _np_min(lh, rh)
                if el > eh:
                    el, eh = INF, -INF
                if el > eh:
                    el, eh = ll, lh
                if j == 0:
                    accl, acch = el, eh
                else:
                    accl = _np_min(accl, el)
                    acch = _np_max(acch, eh)
            lo[b, i] = accl
            hi[b, i] = acch
    return lo, hi


# ----------------------------------------------------------------- midpoint, radius, width
@njit(cache=True)
def _mid1(a, b):
    """:meth:`verified.arith.interval.Interval.mid` of one interval: ``0.5 a + 0.5 b`` (0
    for NaN), clipped as the ``clip`` ufunc does (``min(max(m, lower), upper)``, NaN
    kept) into ``[np.maximum(a, -MAXF), np.minimum(b, MAXF)]``."""
    m = 0.5 * a + 0.5 * b
    if m != m:
        m = 0.0
    return _np_min(_np_max(m, _np_max(a, -MAXF)), _np_min(b, MAXF))


@njit(cache=True)
def mid_loop(lo, hi, out):
    for i in range(lo.size):
        out[i] = _mid1(lo[i], hi[i])


@njit(cache=True)
def rad_loop(lo, hi, out):
    """``np.maximum(ru(m - lo), ru(hi - m))`` with ``m`` the midpoint (:func:`_mid1`)."""
    for i in range(lo.size):
        m = _mid1(lo[i], hi[i])
        out[i] = _np_max(ru(m - lo[i]), ru(hi[i] - m))


@njit(cache=True)
def width_loop(lo, hi, out):
    """``ru(hi - lo)``, 0 where ``lo > hi`` (empty)."""
    for i in range(lo.size):
        out[i] = 0.0 if lo[i] > hi[i] else ru(hi[i] - lo[i])

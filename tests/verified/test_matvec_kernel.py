"""The batched matrix-vector product's compiled path (verified.arith.interval.matvec ->
``_kernels.matvec_bounds``) against the one it replaces (``matmul`` with one column),
bit for bit: the same outward-rounded ``mul`` and ``add`` in the same order, so every
enclosure is unchanged. (``matmul`` itself is checked against exact arithmetic in
test_linalg.py.) It bites: the products summed from the last term, and a sum without
its outward rounding, fail the same comparison."""

from __future__ import annotations

import numpy as np

from verified.arith import _kernels as _k
from verified.arith.interval import Interval, _as_interval, matmul, matvec

SHAPES = [((1, 4, 4), (1, 4)), ((3, 6, 10), (3, 10)), ((2, 5, 4, 7), (2, 5, 7)), ((4, 3), (3,)),
          ((2, 4, 3), (1, 3)), ((4, 3), (2, 3)), ((1, 1, 1), (1, 1))]


def _reference(a, x):
    a, x = _as_interval(a), _as_interval(x)
    return matmul(a, x.reshape(x.shape + (1,)))[..., 0]


def _same(r, s):
    return (r.shape == s.shape and np.array_equal(r.lo.view(np.int64), s.lo.view(np.int64))
            and np.array_equal(r.hi.view(np.int64), s.hi.view(np.int64)))


def _mismatches(fn, seed=0):
    rng = np.random.default_rng(seed)
    bad = 0
    for sa, sx in SHAPES:
        for _ in range(40):
            lo = rng.standard_normal(sa) * 10.0 ** rng.integers(-300, 300, sa)
            hi = lo + np.abs(rng.standard_normal(sa)) * (rng.random(sa) < 0.5)
            if rng.random() < 0.2:
                hi.reshape(-1)[0] = np.inf
            xl = rng.standard_normal(sx) * 10.0 ** rng.integers(-300, 300, sx)
            x = Interval(xl, xl + np.abs(rng.standard_normal(sx)) * (rng.random(sx) < 0.5))
            a = Interval(lo, hi, allow_unbounded=True)
            for A in (a, lo):  # an interval matrix, and a float one (exact points)
                bad += not _same(fn(A, x), _reference(A, x))
    return bad


def test_matvec_is_matmul_with_one_column_bit_for_bit():
    assert _mismatches(matvec) == 0


def test_the_comparison_bites():
    def reversed_sum(a, x):
        a, x = _as_interval(a), _as_interval(x)
        lo = np.empty(np.broadcast_shapes(a.shape[:-1], x.shape[:-1] + (a.shape[-2],)))
        hi = np.empty_like(lo)
        A = a.broadcast_to(lo.shape + (a.shape[-1],))
        X = x.broadcast_to(lo.shape[:-1] + (x.shape[-1],))
        for idx in np.ndindex(lo.shape):
            sl = sh = 0.0
            for t in reversed(range(a.shape[-1])):
                pl, ph = _k.mul(A.lo[idx + (t,)], A.hi[idx + (t,)], X.lo[idx[:-1] + (t,)], X.hi[idx[:-1] + (t,)])
                sl, sh = _k.add(sl, sh, pl, ph)
            lo[idx], hi[idx] = sl, sh
        return Interval._from_bounds(lo, hi)

    def unrounded(a, x):
        r = matvec(a, x)
        return Interval._from_bounds(r.lo + (np.abs(r.lo) * _k.EPS + _k.ETA), r.hi)

    assert _mismatches(reversed_sum) > 0
    assert _mismatches(unrounded) > 0

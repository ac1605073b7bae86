"""The compiled ranges of Taylor models (verified.series.taylor_model.models_to_interval)
against the numpy expression they replace (``_models_to_interval_np``), bit for bit.

The compiled pass must round exactly as the numpy code did (same float operations, the
sums in numpy's order: pairwise along a contiguous row, one term after another along
the masked copies' outer axis), so every enclosure of the composition step is
unchanged. The oracle is that numpy code (itself checked against arb in
test_taylor_model.py). It bites: a sum in another order, and a range without its
outward rounding, fail the same comparison.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import verified.series.taylor_model as tm

LEADS = [(), (1,), (3,), (1, 1), (4, 1), (1, 5), (4, 13, 1), (4, 13, 2), (1, 13, 1), (2, 3, 4, 1)]


def _cases(seed=7):
    """(F, m, mq): models of random length and magnitude, some with NaN / inf / zeros,
    C-contiguous and sliced views (as the step passes them)."""
    rng = np.random.default_rng(seed)
    for lead in LEADS:
        for mq in (0, 1, 5, 16, 32):
            for m in (mq, mq + 3, mq + 150):
                L = m + mq * (mq + 1) // 2 + int(rng.integers(0, 2500)) + 2
                F = rng.standard_normal(lead + (L,)) * 10.0 ** rng.integers(-30, 30, lead + (L,))
                if rng.random() < 0.3:
                    F.reshape(-1)[rng.integers(0, F.size, 3)] = rng.choice([np.nan, np.inf, -np.inf, 0.0, -0.0], 3)
                yield F, m, mq
                if len(lead) >= 2 and lead[1] > 2:
                    yield F[:, 1:-1], m, mq
                if len(lead) >= 1 and lead[0] > 1:
                    yield F[1:], m, mq


def _same_bits(a, b):
    return a.shape == b.shape and np.array_equal(np.asarray(a).view(np.int64), np.asarray(b).view(np.int64))


def _mismatches(fn):
    bad = 0
    for F, m, mq in _cases():
        lo, hi = fn(F, m, mq)
        rlo, rhi = tm._models_to_interval_np(F, m, mq)
        bad += not (_same_bits(lo, rlo) and _same_bits(hi, rhi))
    return bad


def test_compiled_ranges_are_the_numpy_ranges_bit_for_bit():
    assert _mismatches(tm.models_to_interval) == 0


def test_pairwise_sum_is_numpys():
    rng = np.random.default_rng(3)
    for n in [*range(0, 300), 511, 512, 513, 1025, 2048, 4099, 8192, 8193, 20000]:
        a = rng.standard_normal(n) * 10.0 ** rng.integers(-20, 20, n)
        assert tm._pairwise_sum(a, n) == a.sum(), n


def test_the_comparison_bites():
    """A sum in another order (one term after another: what a plain loop gives) and a
    range without its last outward step both differ from the reference somewhere."""
    def sequential(F, m, mq):  # the same operations, every sum a plain loop in order
        diag = tm._diagonal_mask(mq, F.shape[-1] - m - 2)
        G = np.ascontiguousarray(F).reshape(-1, F.shape[-1])
        lo, hi = np.empty(G.shape[0]), np.empty(G.shape[0])
        for r, row in enumerate(G):
            Q = row[m + 1: -1]
            s = 0.0
            for x in row[1: m + 1]:
                s += abs(x)
            t = 0.0
            for x in Q[~diag]:
                t += abs(x)
            p = n = 0.0
            for x in Q[diag]:
                p += max(x, 0.0) if x == x else x
                n += max(-x, 0.0) if x == x else x
            R = (s + t) * tm._UPF + tm._TINY
            pos, neg = p * tm._UPF + tm._TINY, n * tm._UPF + tm._TINY
            lo_, hi_ = row[0] - ((R + neg + row[-1]) * tm._UPF + tm._TINY), row[0] + ((R + pos + row[-1]) * tm._UPF + tm._TINY)
            lo_, hi_ = lo_ - (abs(lo_) * tm._k.EPS + tm._k.ETA), hi_ + (abs(hi_) * tm._k.EPS + tm._k.ETA)
            lo[r], hi[r] = (-math.inf, math.inf) if (lo_ != lo_ or hi_ != hi_) else (lo_, hi_)
        return lo.reshape(F.shape[:-1]), hi.reshape(F.shape[:-1])

    def unrounded(F, m, mq):
        lo, hi = tm.models_to_interval(F, m, mq)
        return lo + (np.abs(lo) * tm._k.EPS + tm._k.ETA), hi

    assert _mismatches(sequential) > 0
    assert _mismatches(unrounded) > 0


def test_other_memory_order_falls_back_to_numpy():
    rng = np.random.default_rng(5)
    F = rng.standard_normal((40, 6, 3)).transpose(1, 2, 0)  # (6, 3, 40): the last axis strided
    lo, hi = tm.models_to_interval(F, 4, 2)
    rlo, rhi = tm._models_to_interval_np(F, 4, 2)
    assert _same_bits(lo, rlo) and _same_bits(hi, rhi)

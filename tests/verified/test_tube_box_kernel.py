"""The composition step's tube box (verified.steppers.tm_flow.step_tube) in one compiled
pass (``_kernels.tube_box_bounds``) against the interval expressions it replaces
(``_tube_box_np``, and ``_step_tube_np`` from the models), bit for bit, on inputs with
zeros of both signs, infinities, NaN and empty intervals: the same outward-rounded
``add``, ``sub``, ``mul`` and ``ipow`` on the same operands in the same order, and
numpy's ``maximum``/``minimum`` (NaN and signed zeros included), so every enclosure
is unchanged. It bites: the box without its last outward step, and the intersection
dropped (the left bound alone), fail the same comparison."""

from __future__ import annotations

import numpy as np

from oracles.special_floats import special_floats
from verified.arith import _kernels as _k
from verified.arith.interval import Interval
from verified.series.taylor_model import model_length
from verified.steppers import tm_flow
from verified.steppers.tm_flow import _step_tube_np, _tube_box_np, step_tube


def _same(r, s):
    return (r.shape == s.shape and np.array_equal(r.lo.view(np.int64), s.lo.view(np.int64))
            and np.array_equal(r.hi.view(np.int64), s.hi.view(np.int64)))


def _values(rng, shape):
    return special_floats(rng, shape)


def _bounds(rng, shape):
    lo = _values(rng, shape)
    with np.errstate(invalid="ignore"):
            hi = np.where(rng.random(shape) < 0.3, lo, lo + np.abs(_values(rng, shape)))
    if rng.random() < 0.5:  # some inverted (empty) and ordinary narrow ones too
        hi = np.where(rng.random(shape) < 0.1, lo - 1.0, hi)
    return lo, hi


def _kernel(xlo, xhi, vlo, vhi, cE, taus, K):
    lo, hi = _k.tube_box_bounds(xlo, xhi, vlo, vhi, cE.lo, cE.hi, taus, K)
    return Interval._from_bounds(lo, hi)


def _mismatches(fn, seed=0):
    rng = np.random.default_rng(seed)
    bad = 0
    for _ in range(300):
        P, n, nb, K = int(rng.integers(2, 7)), int(rng.integers(1, 5)), int(rng.integers(1, 4)), int(rng.integers(2, 7))
        xlo, xhi = _bounds(rng, (P, n, nb))
        vlo, vhi = _bounds(rng, (P, n, nb))
        clo, chi = _bounds(rng, (nb, K + 1, n))
        h = float(np.abs(rng.standard_normal()) * 10.0 ** rng.integers(-8, 2)) * (rng.random() < 0.95)
        taus = np.array([h * j / (P - 1) for j in range(P - 1)] + [h])
        cE = Interval._from_bounds(clo, chi)
        ref = _tube_box_np(Interval._from_bounds(np.ascontiguousarray(xlo.transpose(0, 2, 1)),
                                                 np.ascontiguousarray(xhi.transpose(0, 2, 1))),
                           Interval._from_bounds(np.ascontiguousarray(vlo.transpose(0, 2, 1)),
                                                 np.ascontiguousarray(vhi.transpose(0, 2, 1))), cE, taus, K)
        bad += not _same(fn(xlo, xhi, vlo, vhi, cE, taus, K), ref)
    return bad


def test_tube_box_kernel_is_the_interval_expression_bit_for_bit():
    assert _mismatches(_kernel) == 0


def test_the_comparison_bites():
    def unrounded(*args):
        r = _kernel(*args)
        with np.errstate(invalid="ignore"):
            return Interval._from_bounds(r.lo + (np.abs(r.lo) * _k.EPS + _k.ETA), r.hi)

    def left_only(xlo, xhi, vlo, vhi, cE, taus, K):
        # right's bound made useless: the box is the left bound's alone
        return _kernel(xlo, xhi, vlo, vhi, Interval._from_bounds(cE.lo, cE.hi), taus, K).hull(
            _kernel(xlo, xhi, np.full_like(vlo, -1e300), np.full_like(vhi, 1e300), cE, taus, K))

    assert _mismatches(unrounded) > 0
    assert _mismatches(left_only) > 0


def test_numpy_maximum_minimum_semantics():
    rng = np.random.default_rng(3)
    a = _values(rng, 4000)
    b = np.where(rng.random(4000) < 0.5, _values(rng, 4000), np.where(a == 0, -a, a))
    for fn, ref in ((_k._np_max, np.maximum), (_k._np_min, np.minimum)):
        got = np.array([fn(x, y) for x, y in zip(a, b)])
        assert np.array_equal(got.view(np.int64), ref(a, b).view(np.int64))


def test_step_tube_from_models_bit_for_bit():
    rng = np.random.default_rng(1)
    for _ in range(60):
        n, K, nb, M = int(rng.integers(1, 4)), int(rng.integers(2, 6)), int(rng.integers(1, 3)), int(rng.integers(1, 5))
        mq = int(rng.integers(0, M + 1))
        L = model_length(M, mq)
        out = rng.standard_normal((n, K, nb, L)) * 10.0 ** rng.integers(-6, 3, (n, K, nb, L))
        out[..., -1] = np.abs(out[..., -1])
        if rng.random() < 0.2:
            out.reshape(-1)[rng.integers(out.size)] = rng.choice([np.inf, -np.inf, np.nan, -0.0])
        clo, chi = _bounds(rng, (nb, K + 2, n))
        cE = Interval._from_bounds(clo, chi)
        h = float(np.abs(rng.standard_normal()) * 10.0 ** rng.integers(-6, 1))
        for pieces in (1, 2, tm_flow.TUBE_PIECES):
            assert _same(step_tube(out, cE, h, M, mq, pieces), _step_tube_np(out, cE, h, M, mq, pieces))

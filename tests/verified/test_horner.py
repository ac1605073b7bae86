"""The compiled interval Horner sum of the Lohner and second-order steps
(``verified.steppers.lohner.horner`` over ``verified.arith._kernels.horner_loop``): bit for bit the
sum the interval operators give (which the arb oracle checks operation by operation),
and every exact polynomial value at a point of the boxes lies inside it."""

from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import verified.arith._kernels as _k
import verified.steppers.lohner as lohner
from verified.arith.interval import Interval
from verified.steppers.lohner import _horner_python, horner

_finite = st.floats(min_value=-1e3, max_value=1e3, allow_nan=False, allow_infinity=False)


def _coeffs(rng, shape, spread=1e-3):
    c = rng.normal(size=shape) * rng.choice([1e-8, 1.0, 1e4], size=shape)
    w = np.abs(rng.normal(size=shape)) * spread * np.abs(c)
    return Interval(c - w, c + w)


@pytest.mark.parametrize("shape", [(3, 13, 4), (2, 12, 4, 4), (5, 1, 3), (1, 2, 2, 3, 2)])
@pytest.mark.parametrize("h", [0.01, 0.3, Interval(0.0, 0.03), Interval(-0.02, 0.0200001)])
def test_compiled_horner_equals_the_operators_bit_for_bit(shape, h):
    rng = np.random.default_rng(sum(shape))
    C = _coeffs(rng, shape)
    a, b = horner(C, h), _horner_python(C, h)
    assert a.shape == b.shape == shape[:1] + shape[2:]
    assert np.array_equal(a.lo, b.lo) and np.array_equal(a.hi, b.hi)


def test_edge_values_follow_the_operators():
    """Infinite coefficients, zero times infinity and an empty entry give what the
    operators give (their careful paths)."""
    inf = np.inf
    lo = np.array([[[0.0, -inf, 1.0], [1.0, 2.0, -inf], [np.inf, 0.0, 0.0]]]).transpose(0, 2, 1)
    hi = np.array([[[0.0, inf, 1.0], [2.0, 3.0, inf], [-np.inf, 0.0, 0.0]]]).transpose(0, 2, 1)
    C = Interval._from_bounds(lo, hi)
    for h in [0.0, 0.5, Interval(0.0, 1.0)]:
        a, b = horner(C, h), _horner_python(C, h)
        assert np.array_equal(a.lo, b.lo, equal_nan=True) and np.array_equal(a.hi, b.hi, equal_nan=True)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(_finite, _finite), min_size=1, max_size=9), _finite, st.floats(0.0, 1.0))
def test_exact_values_lie_inside(pairs, h, frac):
    """sum c_i t^i in exact rational arithmetic, at a point of every coefficient interval
    and at a point t of [h, h + 0.1], lies in the compiled sum."""
    lo = np.array([min(a, b) for a, b in pairs])
    hi = np.array([max(a, b) for a, b in pairs])
    C = Interval(lo[None, :, None], hi[None, :, None])
    H = Interval(h, h + 0.1)
    out = horner(C, H)
    cs = [Fraction(l) + (Fraction(u) - Fraction(l)) * Fraction(frac) for l, u in zip(lo, hi)]
    t = Fraction(h) + Fraction(0.1) * Fraction(frac) if h + 0.1 > h else Fraction(h)
    t = min(max(t, Fraction(H.lo.item())), Fraction(H.hi.item()))
    exact = sum(c * t**i for i, c in enumerate(cs))
    assert Fraction(out.lo.item()) <= exact <= Fraction(out.hi.item())


def test_a_kernel_without_outward_rounding_is_caught(monkeypatch):
    """The oracle bites: a Horner loop that rounds to nearest differs from the operators."""
    def nearest(clo, chi, hl, hh, lo, hi):
        K = clo.shape[1]
        for m in range(clo.shape[0]):
            al, ah = clo[m, K - 1], chi[m, K - 1]
            for i in range(K - 2, -1, -1):
                p = [al * hl, al * hh, ah * hl, ah * hh]
                al, ah = min(p) + clo[m, i], max(p) + chi[m, i]
            lo[m], hi[m] = al, ah
    monkeypatch.setattr(_k, "horner_loop", nearest)
    rng = np.random.default_rng(1)
    C = _coeffs(rng, (3, 8, 4))
    a, b = lohner.horner(C, 0.1), _horner_python(C, 0.1)
    assert not (np.array_equal(a.lo, b.lo) and np.array_equal(a.hi, b.hi))

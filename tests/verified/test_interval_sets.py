"""Set operations on Interval arrays: intersection, hull, midpoint, radius, width,
containment, bisection and subdivision."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import verified.arith.interval as iv
from verified.arith.interval import Interval

floats = st.floats(-1e12, 1e12, allow_nan=False)


@st.composite
def boxes(draw, n=3, batch=4):
    a = draw(arrays(np.float64, (batch, n), elements=floats))
    b = draw(arrays(np.float64, (batch, n), elements=floats))
    return Interval(np.minimum(a, b), np.maximum(a, b))


@settings(max_examples=100, deadline=None)
@given(boxes())
def test_mid_rad_width_enclose_the_interval(x):
    m = x.mid()
    assert x.contains(m).all()
    r = x.rad()
    assert ((m - r) <= x.lo).all() and (x.hi <= (m + r)).all()
    assert (x.width() >= x.hi - x.lo).all()


def test_mid_of_unbounded_intervals_is_finite_and_inside():
    x = Interval([-np.inf, 1.0, -np.inf], [np.inf, np.inf, -3.0], allow_unbounded=True)
    m = x.mid()
    assert np.isfinite(m).all() and x.contains(m).all()


@settings(max_examples=100, deadline=None)
@given(boxes(), boxes())
def test_intersection_and_hull(x, y):
    i = x.intersect(y)
    h = x.hull(y)
    assert x.issubset(h).all() and y.issubset(h).all()
    assert i.issubset(x).all() and i.issubset(y).all()
    disjoint = (x.hi < y.lo) | (y.hi < x.lo)
    assert (i.is_empty() == disjoint).all()
    # a point in both lies in the intersection
    p = np.clip(x.mid(), y.lo, y.hi)
    both = x.contains(p) & y.contains(p)
    assert i.contains(p)[both].all()


def test_empty_is_neutral_for_hull_and_absorbing_for_arithmetic():
    e = iv.empty(2)
    x = Interval([1.0, 2.0], [3.0, 4.0])
    assert e.is_empty().all()
    assert e.hull(x).equals(x).all()
    for r in (e + x, x * e, e / x, iv.sin(e), iv.sqrt(e), iv.ipow(e, 3)):
        assert r.is_empty().all()
    assert e.issubset(x).all()


@settings(max_examples=100, deadline=None)
@given(boxes(), st.integers(0, 2))
def test_bisect_covers_exactly(x, index):
    left, right = x.bisect(index)
    assert (left.lo == x.lo).all() and (right.hi == x.hi).all()
    assert (left.hi[:, index] == right.lo[:, index]).all()
    others = [j for j in range(3) if j != index]
    assert (left.hi[:, others] == x.hi[:, others]).all() and (right.lo[:, others] == x.lo[:, others]).all()
    assert left.issubset(x).all() and right.issubset(x).all()


def test_bisect_default_splits_the_widest_component_per_box():
    x = Interval([[0.0, 0.0], [0.0, 0.0]], [[1.0, 5.0], [7.0, 2.0]])
    left, right = x.bisect()
    assert left.hi.tolist() == [[1.0, 2.5], [3.5, 2.0]]
    assert right.lo.tolist() == [[0.0, 2.5], [3.5, 0.0]]


@settings(max_examples=50, deadline=None)
@given(boxes(batch=2), st.lists(st.integers(1, 5), min_size=3, max_size=3))
def test_subdivide_covers_the_box(x, pieces):
    parts = x.subdivide(pieces)
    assert parts.shape == (2, int(np.prod(pieces)), 3)
    assert parts.issubset(x[:, None, :]).all()
    # every sampled point of the box lies in some piece
    rng = np.random.default_rng(0)
    pts = x.lo[:, None, :] + rng.uniform(0, 1, (2, 200, 3)) * (x.hi - x.lo)[:, None, :]
    inside = (parts.lo[:, None, :, :] <= pts[:, :, None, :]) & (pts[:, :, None, :] <= parts.hi[:, None, :, :])
    assert inside.all(-1).any(-1).all()


def test_subdivide_rejects_zero_pieces():
    with pytest.raises(ValueError, match="pieces"):
        Interval([0.0], [1.0]).subdivide(0)


def test_indexing_setitem_stack_concatenate_sum():
    x = Interval(np.zeros((3, 2)), np.ones((3, 2)))
    x[1, 0] = Interval(-2.0, 5.0)
    assert x[1, 0].lo == -2.0 and x[1].hi.tolist() == [5.0, 1.0]
    s = iv.stack([x[:, 0], x[:, 1]], axis=-1)
    assert s.equals(x).all()
    c = iv.concatenate([x, x], axis=0)
    assert c.shape == (6, 2)
    t = x.sum(axis=0)
    assert t.shape == (2,) and t.contains([3.0, 3.0]).all() and t.lo[0] <= -2.0 and t.hi[0] >= 7.0


def test_fraction_and_big_int_operands_are_enclosed_not_rounded():
    from fractions import Fraction

    third = Interval(1.0) * Fraction(1, 3)
    assert Fraction(float(third.lo)) <= Fraction(1, 3) <= Fraction(float(third.hi))
    big = 2**60 + 1
    s = Interval(0.0) + big
    assert Fraction(float(s.lo)) <= big <= Fraction(float(s.hi))

"""Interval.mid, rad and width in one compiled pass each (``_kernels.mid_loop``,
``rad_loop``, ``width_loop``) against the numpy expressions they replace
(``_mid_np``, ``_rad_np``, ``_width_np``), bit for bit, on bounds with zeros of both
signs, infinities, NaN, empty and unbounded intervals, in several shapes and layouts
(0-d ones keep their numpy result types; a NaN's sign bit aside, see ``_same``). It bites: a radius without its outward
step, a midpoint clipped without the finite limits, and a width that is not 0 on
empty intervals fail the same comparison."""

from __future__ import annotations

import numpy as np

from oracles.special_floats import special_floats
from verified.arith import _kernels as _k
from verified.arith.interval import Interval, _mid_np, _rad_np, _width_np

SHAPES = [(), (1,), (7,), (3, 5), (2, 3, 4), (0, 3), (600,)]


def _values(rng, shape):
    return special_floats(rng, shape, max_exponent=309, largest=True)


def _cases(seed=0):
    rng = np.random.default_rng(seed)
    for shape in SHAPES:
        for _ in range(30):
            lo = _values(rng, shape)
            with np.errstate(invalid="ignore", over="ignore"):
                pick = rng.random(shape)
                hi = np.where(pick < 0.3, lo, np.where(pick < 0.6, _values(rng, shape),
                                                       lo + np.abs(_values(rng, shape))))
            yield lo, hi
            if lo.ndim >= 2:  # a transposed (not contiguous) layout
                yield lo.T, hi.T


def _same(a, b):
    """The same type and shape, NaN where ``b`` has NaN, every other element bit for bit
    (zeros' signs included). A NaN's sign bit is not compared: IEEE 754 leaves open
    which operand's NaN an operation passes on, and numpy's loops and the compiled one
    pass on different ones (rad and width of ``[-inf, -inf]``, ``inf - inf``); no
    code reads a NaN's sign."""
    if type(a) is not type(b) or np.shape(a) != np.shape(b):
        return False
    a, b = np.asarray(a), np.asarray(b)
    nan = np.isnan(b)
    return bool(np.array_equal(np.isnan(a), nan)
                and np.array_equal(a[~nan].view(np.int64), b[~nan].view(np.int64)))


def _mismatches(mid, rad, width):
    bad = 0
    for lo, hi in _cases():
        iv = Interval._from_bounds(lo, hi)
        bad += not _same(mid(iv), _mid_np(lo, hi))
        bad += not _same(rad(iv), _rad_np(lo, hi))
        bad += not _same(width(iv), _width_np(lo, hi))
    return bad


def test_mid_rad_width_are_the_numpy_expressions_bit_for_bit():
    assert _mismatches(Interval.mid, Interval.rad, Interval.width) == 0


def test_the_comparison_bites():
    def unrounded_rad(iv):
        m = iv.mid()
        with np.errstate(invalid="ignore", over="ignore"):
            return np.maximum(m - iv.lo, iv.hi - m)

    def unclipped_mid(iv):
        with np.errstate(invalid="ignore", over="ignore"):
            m = 0.5 * iv.lo + 0.5 * iv.hi
        return np.where(np.isnan(m), 0.0, m)[()]

    def width_of_empty(iv):
        with np.errstate(invalid="ignore", over="ignore"):
            return np.asarray(iv.hi - iv.lo + (np.abs(iv.hi - iv.lo) * _k.EPS + _k.ETA))

    assert _mismatches(Interval.mid, unrounded_rad, Interval.width) > 0
    assert _mismatches(unclipped_mid, Interval.rad, Interval.width) > 0
    assert _mismatches(Interval.mid, Interval.rad, width_of_empty) > 0

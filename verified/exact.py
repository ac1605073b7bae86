"""Exact numbers as tight double enclosures: the one place that rounds outward.

A rational ``q`` (``int``, ``Fraction``) lies between two neighbouring doubles; a
number ``a + b pi`` (``a``, ``b`` rational, ``b != 0``) is irrational and lies strictly
between the doubles either side of its nearest one. Every module that turns an exact
number into floats calls these functions instead of repeating the rule:

- :mod:`verified.interval` (``Fraction``, ``Decimal`` and big-int operands),
- :mod:`verified.graph` (constant nodes, :func:`verified.graph.enclose_rational`),
- :mod:`verified.stepper` and :mod:`verified.solver` (the exact step times and the gap
  to the next output time),
- :mod:`mbs.app.scene` (numbers and ``pi`` expressions in scene files),
- :mod:`models.pendulum`, :mod:`models.double_pendulum` (the paper's initial boxes).

Rounding is never to nearest: ``lo <= exact <= hi`` always, with ``lo == hi`` only when
the exact number is a double.
"""
from __future__ import annotations

import math
from fractions import Fraction

__all__ = ["enclose_fraction", "enclose_pi_multiple"]

#: working precision (bits) of the ``a + b pi`` evaluation: the 200-bit value is within
#: 2^-190 (relative) of the true one, far below half an ulp of a double
PI_PRECISION_BITS = 200


def enclose_fraction(q: Fraction | int) -> tuple[float, float]:
    """``(lo, hi)``: the tightest doubles with ``lo <= q <= hi`` (``lo == hi == q``
    when ``q`` is a double).

    ``q``: an ``int`` or ``Fraction`` (exact). Raises ``OverflowError`` when ``q``
    rounds beyond the double range (``float(q)`` does); the caller words the error.
    A ``q`` just above the largest double gives ``hi = inf``: callers that need finite
    bounds check for it."""
    f = float(q)  # correctly rounded for int and Fraction
    exact = Fraction(f)
    lo = f if exact <= q else math.nextafter(f, -math.inf)
    hi = f if exact >= q else math.nextafter(f, math.inf)
    return lo, hi


def enclose_pi_multiple(a: Fraction, b: Fraction) -> tuple[float, float]:
    """``(lo, hi)`` doubles around ``a + b pi`` (``a``, ``b`` rational).

    ``b == 0``: :func:`enclose_fraction` of ``a``. Otherwise the value is irrational,
    so it is never a double: the nearest double to a 200-bit evaluation and one ulp
    either side enclose it (the evaluation error is far below half an ulp)."""
    a, b = Fraction(a), Fraction(b)
    if b == 0:
        return enclose_fraction(a)
    import mpmath  # sympy's dependency; imported here so that intervals do without it

    with mpmath.workprec(PI_PRECISION_BITS):
        v = mpmath.mpf(a.numerator) / a.denominator + mpmath.mpf(b.numerator) / b.denominator * mpmath.pi
        f = float(v)
    return math.nextafter(f, -math.inf), math.nextafter(f, math.inf)

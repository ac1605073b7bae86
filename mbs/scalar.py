"""Generic-scalar helpers.

The numeric algorithms of :mod:`mbs.numeric` are written once over a *generic scalar*:
Python floats, numpy arrays holding a batch of states (shape ``(B,)``),
``verified.arith.interval.Interval`` objects and ``verified.graph.Tracer`` nodes.  They only
use ``+ - * /``, ``**`` with integer exponents, and the numpy ufuncs ``np.sin``,
``np.cos``, ``np.sqrt``, ``np.square`` (which dispatch through ``__array_ufunc__``).

The same small vector helpers are reused by :mod:`mbs.symbolic` with sympy expressions
as scalars; for these, :func:`sin` / :func:`cos` dispatch to sympy.

Constant folding: model constants (masses, lengths, axes) are plain Python floats (or
sympy numbers).  The helpers skip multiplications by exact constant 0 and 1 so that a
traced expression graph does not fill up with ``0*x`` nodes.  These tests look at
*constants only*, never at state values, so they are valid for every scalar type.
"""
from __future__ import annotations

import numbers
import sys

import numpy as np


def _sympy():
    """The sympy module if it has been imported (a sympy object can only exist then);
    keeps ``import mbs`` and the numeric path free of the sympy import cost."""
    return sys.modules.get("sympy")


def is_sympy(x) -> bool:
    sp = _sympy()
    return sp is not None and isinstance(x, sp.Basic)


def is_const(x) -> bool:
    """True for exact model constants (Python/numpy real numbers, sympy numbers)."""
    if isinstance(x, (numbers.Real, np.floating, np.integer)) and not isinstance(x, bool):
        return True
    if is_sympy(x):
        return bool(x.is_Number)
    return False


def is_zero(x) -> bool:
    return is_const(x) and x == 0


def is_one(x) -> bool:
    return is_const(x) and x == 1


def is_minus_one(x) -> bool:
    return is_const(x) and x == -1


def sin(x):
    if is_sympy(x):
        return _sympy().sin(x)
    return np.sin(x)


def cos(x):
    if is_sympy(x):
        return _sympy().cos(x)
    return np.cos(x)


def add(a, b):
    if is_zero(a):
        return b
    if is_zero(b):
        return a
    return a + b


def sub(a, b):
    if is_zero(b):
        return a
    if is_zero(a):
        return -b
    return a - b


def mul(a, b):
    if is_zero(a) or is_zero(b):
        return _sympy().S.Zero if (is_sympy(a) or is_sympy(b)) else 0.0
    if is_one(a):
        return b
    if is_one(b):
        return a
    if is_minus_one(a):
        return -b
    if is_minus_one(b):
        return -a
    return a * b


def div(a, b):
    """a / b.  ``0 / b`` folds to 0 only for a *nonzero constant* b: folding it for a
    state-dependent b (a Tracer, an Interval, an array) would drop b from the result, and
    with it the only sign that b can be 0 there (an LDL^T pivot of a singular mass
    matrix); ``0 / 0`` is never 0."""
    if is_zero(b):
        raise ZeroDivisionError("division by the constant 0")
    if is_zero(a) and is_const(b):
        return a
    if is_one(b):
        return a
    return a / b


def neg(a):
    if is_zero(a):
        return a
    return -a


def square(a):
    """a**2; ``np.square`` for numeric scalars (tight for intervals), ``**2`` for sympy."""
    if is_sympy(a):
        return a ** 2
    if is_const(a):
        return a * a
    return np.square(a)


def dot(a, b):
    s = 0
    for x, y in zip(a, b):
        s = add(s, mul(x, y))
    return s


def total(items):
    s = 0
    for x in items:
        s = add(s, x)
    return s

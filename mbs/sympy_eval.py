"""Evaluate sympy expressions over the generic scalar (float, batch, Interval, Tracer).

:func:`compile_generic` runs ``sympy.cse`` once and returns a function that evaluates the
common subexpressions in order with ``+ - * /``, ``np.square`` / integer powers,
``np.sqrt`` and ``np.sin``/``np.cos`` (:mod:`mbs.scalar`), so tracing it with
``verified.graph.trace`` gives an expression graph with the sharing cse found.
"""
from __future__ import annotations

from fractions import Fraction

import numpy as np
import sympy

from verified.graph import from_sympy
from verified.arith.interval import Interval

from . import scalar as S
from .errors import ModelError


def _pow(b, e):
    if e == 2:
        return S.square(b)
    if e == 1:
        return b
    if isinstance(e, int) and e > 2:
        r = b
        for _ in range(e - 1):
            r = r * b
        return r
    if isinstance(e, int) and e < 0:
        return 1.0 / _pow(b, -e)
    if e == 0.5:
        return np.sqrt(b)
    if e == -0.5:
        return 1.0 / np.sqrt(b)
    return b ** e


def _number(x, exact=False):
    """A sympy number as int / float / Fraction.  Integers and dyadic rationals and
    (53-bit) Floats are exact doubles; other rationals become ``Fraction`` when
    ``exact`` (Interval and Tracer enclose them outward).  Irrational constants are
    enclosed by the caller in exact mode (see ``_enclosure``); here they are rounded."""
    if x.is_Integer:
        return int(x)
    if x.is_Rational:
        q = Fraction(int(x.p), int(x.q))
        if exact and (q.denominator & (q.denominator - 1)) != 0:
            return q
        return float(q)
    return float(x)


def _enclosure(x):
    """0-d Interval enclosing the exact value of a constant sympy expression."""
    # interval evaluation of the expression tree (sqrt(3) is sqrt of [3, 3], ...)
    y = from_sympy([x], inputs=[]).eval_interval(Interval([]))
    return Interval(float(y.lo[0]), float(y.hi[0]))


def _is_plain(v):
    return isinstance(v, (int, float, np.floating, np.integer)) or (
        isinstance(v, np.ndarray) and v.dtype.kind in "fiu")


class GenericFunction:
    """f(*args) -> list of values of ``exprs`` at the generic scalars ``args``."""

    def __init__(self, exprs, args, cse=True):
        self.args = list(args)
        exprs = [sympy.sympify(e) for e in exprs]
        if cse:
            self.repl, self.reduced = sympy.cse(exprs, order="none")
        else:
            self.repl, self.reduced = [], exprs
        free = set().union(*(e.free_symbols for e in exprs)) if exprs else set()
        missing = free - set(self.args)
        if missing:
            raise ModelError(f"expressions depend on {sorted(map(str, missing))}, "
                             f"which are not inputs {list(map(str, self.args))}")

    def __call__(self, *values):
        env = dict(zip(self.args, values))
        exact = not all(_is_plain(v) for v in values)
        memo = {}
        def ev(e):
            if e in env:
                return env[e]
            r = memo.get(e)
            if r is not None:
                return r
            if exact and e.is_number and not e.is_Rational:
                # pi, sqrt(3)/2, ...: a rigorous enclosure, never a rounded double,
                # when evaluating over intervals or tracing into a graph
                r = _enclosure(e)
            elif e.is_Number or e.is_NumberSymbol:
                r = _number(e, exact)
            elif e.is_Add:
                r = 0
                for a in e.args:
                    r = S.add(r, ev(a))
            elif e.is_Mul:
                coeff, rest = e.as_coeff_mul()
                r = 1
                for a in rest:
                    r = S.mul(r, ev(a))
                if coeff != 1:
                    r = S.mul(_number(coeff, exact), r)
            elif e.is_Pow:
                b, x = e.args
                if x.is_Integer:
                    r = _pow(ev(b), int(x))
                elif x == sympy.Rational(1, 2):
                    r = np.sqrt(ev(b))
                elif x == sympy.Rational(-1, 2):
                    r = 1.0 / np.sqrt(ev(b))
                else:
                    r = ev(b) ** ev(x)
            elif isinstance(e, sympy.sin):
                r = S.sin(ev(e.args[0]))
            elif isinstance(e, sympy.cos):
                r = S.cos(ev(e.args[0]))
            elif isinstance(e, sympy.tan):
                a = ev(e.args[0])
                r = S.sin(a) / S.cos(a)
            else:
                raise ModelError(f"cannot evaluate {type(e).__name__} over the generic scalar: {e}")
            memo[e] = r
            return r
        for sym, sub in self.repl:
            env[sym] = ev(sub)
        return [ev(e) for e in self.reduced]


def compile_generic(exprs, args, cse=True) -> GenericFunction:
    return GenericFunction(exprs, args, cse=cse)

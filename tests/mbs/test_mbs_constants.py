"""Irrational constants in symbolic models become rigorous enclosures in graphs."""

import flint
import sympy as sp

from mbs.sympy_eval import GenericFunction
from verified.graph import trace
from verified.arith.interval import Interval


def test_irrational_constants_are_enclosed_when_traced_or_evaluated_on_intervals():
    x = sp.Symbol("x")
    f = GenericFunction([x * sp.sqrt(3) / 2 + sp.pi], [x])
    g = trace(lambda v, p: f(v[0]), 1)
    y = g.eval_interval(Interval([1.0]))
    exact = flint.arb(3).sqrt() / 2 + flint.arb.pi()
    assert bool(flint.arb(float(y.lo[0])) <= exact) and bool(flint.arb(float(y.hi[0])) >= exact)
    (z,) = f(Interval(1.0))
    assert bool(flint.arb(float(z.lo)) <= exact) and bool(flint.arb(float(z.hi)) >= exact)
    # plain floats still give plain floats
    assert isinstance(f(1.0)[0], float)

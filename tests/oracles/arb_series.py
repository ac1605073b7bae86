"""Exact Taylor coefficients of ODE solutions through points (python-flint arb_series,
Picard iteration at 256 bits) and the containment check of interval/affine Taylor
coefficients against them (moved from tests/test_affine_taylor.py)."""
from __future__ import annotations

import contextlib
import math

import flint
import numpy as np
from flint import arb, arb_series

from oracles.arb_graph import ArbDomain, box_samples
from verified.graph import evaluate as ev
from verified.series.affine_taylor import AffineTaylorODE
from verified.arith.interval import Interval

INF = math.inf


# --------------------------------------------------------------------------- exact oracle


class ArbSeriesDomain(ArbDomain):
    """Graph values as arb power series in t (flint.arb_series) or arb constants: the
    reference domain of tests/oracles/arb_graph.py with the functions applied to series."""

    def sqrt(self, a):
        return a.sqrt()

    def exp(self, a):
        return a.exp()

    def log(self, a):
        return a.log()

    def sin(self, a):
        return a.sin()

    def cos(self, a):
        return a.cos()

    def tan(self, a):
        return a.tan()

    def atan(self, a):
        return a.atan()


@contextlib.contextmanager
def arb_precision(bits=256, cap=None):
    """flint's global precision (and series length cap) for a block, restored after."""
    old = flint.ctx.prec, flint.ctx.cap
    flint.ctx.prec = bits
    if cap is not None:
        flint.ctx.cap = cap
    try:
        yield
    finally:
        flint.ctx.prec, flint.ctx.cap = old


def arb_taylor(graph, x0, p, order):
    """Exact (arb) x_[0..order] of the solution of x' = f(x, p) through the float point x0:
    object array (order + 1, n). Picard iteration on series truncated after t^order."""
    with arb_precision(256, cap=order + 1):
        c0 = [arb(float(v)) for v in x0]
        ps = [arb(float(v)) for v in (() if p is None else p)]
        xs = [arb_series([c]) for c in c0]
        dom = ArbSeriesDomain()
        for _ in range(order):
            fs = ev.evaluate(graph, dom, xs, ps)
            xs = [c + (f if isinstance(f, arb_series) else arb_series([f])).integral() for c, f in zip(c0, fs)]
        out = np.empty((order + 1, len(c0)), dtype=object)
        for i, s in enumerate(xs):
            cs = s.coeffs()
            for k in range(order + 1):
                out[k, i] = cs[k] if k < len(cs) else arb(0)
        return out


def assert_inside(lo, hi, exact, what=""):
    """Elementwise: certainly lo <= exact <= hi (floats lo, hi; arb exact); never NaN."""
    for idx in np.ndindex(exact.shape):
        l, h, e = float(lo[idx]), float(hi[idx]), exact[idx]
        ok = not (math.isnan(l) or math.isnan(h))
        ok = ok and (l == -INF or bool(arb(l) <= e)) and (h == INF or bool(e <= arb(h)))
        if not ok:
            raise AssertionError(f"{what}: exact {e.str(20, radius=True)} outside [{l!r}, {h!r}] at (k, i) = {idx}")


def affine_coefficients(graph, lo, hi, order, plo=None, phi=None, fresh_symbols=None):
    ode = AffineTaylorODE(graph, fresh_symbols=fresh_symbols)
    params = None if not graph.n_params else Interval(np.asarray(plo, float), np.asarray(phi, float),
                                                      allow_unbounded=True)
    C = ode.coefficients(Interval(np.asarray(lo, float), np.asarray(hi, float), allow_unbounded=True), order, params)
    assert not (np.isnan(C.lo).any() or np.isnan(C.hi).any())
    assert (C.lo <= C.hi).all()
    return C


def check_affine_taylor(graph, lo, hi, order, plo=None, phi=None, *, fresh_symbols=None, n_random=4, seed=0,
                        C=None):
    """Assert the affine enclosures of x_[0..order] over each box [lo, hi] (B, n) (and the
    parameter box [plo, phi]) contain the exact coefficients at the box corners (n <= 6),
    its centre and random points (paired with corners/random points of the parameter box)."""
    rng = np.random.default_rng(seed)
    lo, hi = np.atleast_2d(np.asarray(lo, float)), np.atleast_2d(np.asarray(hi, float))
    if C is None:
        C = affine_coefficients(graph, lo, hi, order, plo, phi, fresh_symbols)
    pts = box_samples(lo, hi, n_random, rng)  # (S, B, n)
    if graph.n_params:
        ppts = box_samples(np.atleast_2d(plo), np.atleast_2d(phi), n_random, rng)[:, 0]
        ppts = ppts[rng.permutation(len(ppts))]
    for s in range(pts.shape[0]):
        p = ppts[s % len(ppts)] if graph.n_params else None
        for b in range(pts.shape[1]):
            exact = arb_taylor(graph, pts[s, b], p, order)
            assert_inside(C.lo[b], C.hi[b], exact, f"box {b}, point {pts[s, b].tolist()}, p {p}")
    return C


def check_series_contains(graph, X, C, order, plo=None, phi=None, *, n_random=6, seed=0):
    """Enclosures C (B, order + 1, n) of x_[0..order] from caller forms X (n, B, m0 + 2)
    (any evaluator's ``series``), parameters as intervals without symbols: the exact
    coefficients at points c + A eps + delta (eps in [-1, 1]^m0, |delta| <= 0.9 e,
    extremes included) and at sampled parameters must be inside."""
    rng = np.random.default_rng(seed)
    n, nb, m2 = X.shape
    assert C.shape == (nb, order + 1, n)
    ppts = box_samples(np.atleast_2d(plo), np.atleast_2d(phi), n_random, rng)[:, 0] if graph.n_params else [None]
    for b in range(nb):
        for s in range(n_random):
            eps = rng.choice([-1.0, 1.0], m2 - 2) if s % 2 else rng.uniform(-1, 1, m2 - 2)
            delta = 0.9 * X[:, b, -1] * (rng.choice([-1.0, 1.0], n) if s % 3 == 0 else rng.uniform(-1, 1, n))
            x = X[:, b, 0] + X[:, b, 1:-1] @ eps + delta
            p = ppts[s % len(ppts)]
            assert_inside(C.lo[b], C.hi[b], arb_taylor(graph, x, p, order), f"series, box {b}, x {x.tolist()}, p {p}")
    return C


def has_op(graph, op):
    return any(node.op == op for node in graph.nodes)

"""Exact (python-flint arb, 256 bits) evaluation of graphs, the containment checks built
on it, box sampling and random straight-line programs (moved from
tests/test_graph_interval.py; see its docstring for the two oracles)."""
from __future__ import annotations

import itertools

import flint
import numpy as np
import sympy as sp
from hypothesis import strategies as st

from verified.graph import evaluate as ev
from verified.arith.interval import Interval

arb = flint.arb
# the reference must be far more precise than the floats it judges; this module used
# to pass only when arb_oracle (which sets 256 bits) happened to be imported first
flint.ctx.prec = 256

FLOAT_REF_RTOL = 1e-12  # allowance for rounding errors of the float reference only


# --------------------------------------------------------------------------- exact oracle

_f = {name: np.frompyfunc(lambda t, name=name: getattr(t, name)(), 1, 1)
      for name in ("sqrt", "exp", "log", "sin", "cos", "tan", "atan")}
_to_arb = np.frompyfunc(lambda v: arb(float(v)), 1, 1)


class ArbDomain(ev.Domain):
    """Reference evaluator: arb balls in numpy object arrays (one Python call per element)."""

    def const(self, lo, hi, value):
        return arb(value)

    def sqr(self, a):
        return a * a

    def pow(self, a, k):
        return a**k

    def sqrt(self, a):
        return _f["sqrt"](a)

    def exp(self, a):
        return _f["exp"](a)

    def log(self, a):
        return _f["log"](a)

    def sin(self, a):
        return _f["sin"](a)

    def cos(self, a):
        return _f["cos"](a)

    def tan(self, a):
        return _f["tan"](a)

    def atan(self, a):
        return _f["atan"](a)

    def mid(self, a):
        # exact math: a graph's outputs do not depend on which point mid freezes
        # (verified.graph.GraphBuilder.mid), so the value itself is a valid choice
        return a

    def point(self, array):
        return _to_arb(np.asarray(array, dtype=float))

    def expand(self, a):
        return _obj(a)[..., None]

    def pack(self, values, shape, axis=-1):
        return np.stack([np.broadcast_to(_obj(v), shape) for v in values], axis=axis)


def _obj(v):
    if isinstance(v, np.ndarray):
        return v
    out = np.empty((), dtype=object)
    out[()] = v
    return out


_SYMPY_JACOBIANS: dict = {}


def sympy_jacobian(graph):
    """Independent float reference for Jacobians: sympy's diff of graph.to_sympy(), lambdified.

    Returns f(X, P) -> (..., m, n)."""
    key = id(graph)
    if key not in _SYMPY_JACOBIANS:
        xs = sp.symbols(f"x0:{graph.n_inputs}")
        ps = sp.symbols(f"p0:{graph.n_params}")
        jac = sp.Matrix(graph.to_sympy(xs, ps)).jacobian(xs)
        f = sp.lambdify(list(xs) + list(ps), jac.tolist(), "numpy")

        def ref(X, P=None):
            P = np.zeros((0,)) if P is None else np.asarray(P, dtype=float)
            shape = np.broadcast_shapes(X.shape[:-1], P.shape[:-1])
            args = [np.broadcast_to(X[..., i], shape) for i in range(graph.n_inputs)]
            args += [np.broadcast_to(P[..., j], shape) for j in range(graph.n_params)]
            cols = [[np.broadcast_to(np.asarray(v, dtype=float), shape) for v in row] for row in f(*args)]
            return np.moveaxis(np.array(cols), [0, 1], [-2, -1])

        _SYMPY_JACOBIANS[key] = (graph, ref)  # keep graph alive so id() stays unique
    return _SYMPY_JACOBIANS[key][1]


def arb_eval(graph, X, P=None, jacobian=False):
    """Exact (arb) values (..., m) or Jacobians (..., m, n) at float points X."""
    X = np.asarray(X, dtype=float)
    P = np.zeros((0,)) if P is None else np.asarray(P, dtype=float)
    shape = np.broadcast_shapes(X.shape[:-1], P.shape[:-1])
    xs = [_to_arb(X[..., i]) for i in range(graph.n_inputs)]
    ps = [_to_arb(P[..., j]) for j in range(graph.n_params)]
    dom = ArbDomain()
    if not jacobian:
        return dom.pack(ev.evaluate(graph, dom, xs, ps), shape)
    return ev._jacobian(graph, dom, xs, ps, shape, "x")


_le = np.frompyfunc(lambda a, b: bool(a <= b), 2, 1)


def _arb_inside(lo, hi, exact):
    """Elementwise: certainly lo <= exact <= hi (exact: object array of arb)."""
    lo_a, hi_a = _to_arb(lo), _to_arb(hi)
    return (_le(lo_a, exact) & _le(exact, hi_a)).astype(bool)


# --------------------------------------------------------------------------- sampling


def box_samples(lo, hi, n_random, rng):
    """Points in boxes lo..hi (B, n): all corners (n <= 6), the center, random points -> (S, B, n)."""
    n = lo.shape[-1]
    pts = []
    if n <= 6:
        for corner in itertools.product((0, 1), repeat=n):
            pts.append(np.where(np.array(corner, dtype=bool), hi, lo))
    pts.append(0.5 * (lo + hi))
    for _ in range(n_random):
        pts.append(lo + (hi - lo) * rng.uniform(size=lo.shape))
    return np.clip(np.stack(pts), lo, hi)


def assert_encloses_float(Y, y, what=""):
    """Interval Y (broadcast against y) contains float reference values y (allowance FLOAT_REF_RTOL)."""
    tol = FLOAT_REF_RTOL * (1.0 + np.abs(y))
    ok = (Y.lo - tol <= y) & (y <= Y.hi + tol)
    if not ok.all():
        idx = tuple(np.argwhere(~ok)[0])
        raise AssertionError(f"{what}: sample value {y[idx]!r} outside enclosure at {idx}")


def assert_encloses_arb(Y, exact, what=""):
    lo, hi = np.broadcast_to(Y.lo, exact.shape), np.broadcast_to(Y.hi, exact.shape)
    ok = _arb_inside(lo, hi, exact)
    if not ok.all():
        idx = tuple(np.argwhere(~ok)[0])
        raise AssertionError(f"{what}: exact value {exact[idx]} outside [{lo[idx]!r}, {hi[idx]!r}] at {idx}")


def check_graph_enclosure(graph, lo, hi, P=None, *, n_random=8, rng=None, exact=False, jacobian=False):
    """Assert the graph's interval evaluation (or Jacobian) on boxes [lo, hi] (B, n)
    contains the values at sampled points (float, or arb if ``exact``)."""
    rng = rng or np.random.default_rng(0)
    box = Interval(lo, hi)
    pts = box_samples(lo, hi, n_random, rng)  # (S, B, n)
    if jacobian:
        Y = graph.jacobian_interval(box, P)  # (B, m, n)
        # exact: arb through the same dual-number rules (checks rounding);
        # float: sympy's own differentiation (checks the rules themselves)
        ref = arb_eval(graph, pts, P, jacobian=True) if exact else sympy_jacobian(graph)(pts, P)
    else:
        Y = graph.eval_interval(box, P)  # (B, m)
        ref = arb_eval(graph, pts, P) if exact else graph.eval_float(pts, P)
    if exact:
        assert_encloses_arb(Y, ref, "arb oracle")
    else:
        assert_encloses_float(Y, ref, "float oracle")


def random_boxes(n, count, rng, center_scale=2.0, max_rad=0.3):
    c = rng.uniform(-center_scale, center_scale, size=(count, n))
    r = rng.uniform(0, max_rad, size=(count, n)) * (rng.uniform(size=(count, 1)) < 0.9)  # some point boxes
    return c - r, c + r


# --------------------------------------------------------------------------- random programs

_CONSTS = [0.0, 1.0, -1.0, 2.0, 0.5, 0.1, 3.0, 0.25]
_OPS = ["add", "sub", "mul", "neg", "sqr", "pow3", "sin", "cos", "atan", "divc", "expsin", "self_sub", "const"]


def run_program(program, x0, x1):
    """Straight-line generic-scalar code: each instruction appends one value."""
    vals = [x0, x1]
    for op, i, j, c in program:
        # operands counted back from the newest value: programs build on their own results
        a, b = vals[-1 - i % len(vals)], vals[-1 - j % len(vals)]
        k = _CONSTS[c % len(_CONSTS)]
        if op == "add":
            v = a + b
        elif op == "sub":
            v = a - b
        elif op == "mul":
            v = a * b
        elif op == "neg":
            v = -a
        elif op == "sqr":
            v = np.square(a)
        elif op == "pow3":
            v = a**3
        elif op == "sin":
            v = np.sin(a)
        elif op == "cos":
            v = np.cos(a)
        elif op == "atan":
            v = np.arctan(a)
        elif op == "divc":
            v = a / (2.0 + np.cos(b))
        elif op == "expsin":
            v = np.exp(np.sin(a))
        elif op == "self_sub":
            v = a - a
        else:
            v = a * k + k
        vals.append(v)
    return vals[2:]  # every value is an output, so no instruction is dead code


_program = st.lists(
    st.tuples(st.sampled_from(_OPS), st.integers(0, 8), st.integers(0, 8), st.integers(0, 7)), min_size=1, max_size=25
)

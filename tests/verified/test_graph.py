"""Tests of the expression graph (IR): front ends, float evaluation, derivatives,
constants, sharing, serialization and error messages.

Interval soundness tests are in tests/verified/test_graph_interval.py; the reference
models (double pendulum, pendulum energy, every opcode) in tests/oracles/graph_models.py.
"""
from __future__ import annotations

import json
import math
from fractions import Fraction

import numpy as np
import pytest
import sympy as sp

from oracles.graph_models import (SP, all_ops, double_pendulum_matrices, double_pendulum_rhs, generic_model,
                                  pendulum_energy)
from verified.graph import Graph, GraphBuilder, Node, Op, Tracer, from_sympy, trace

RNG_SEED = 20261122


def rand_points(n, count=200, scale=2.0, seed=RNG_SEED):
    return np.random.default_rng(seed).uniform(-scale, scale, size=(count, n))


# --------------------------------------------------------------------------- model sanity


def test_double_pendulum_model_solves_eq22():
    """The written-out RHS solves A(x) x_dot = b(x) (guards the reference model itself)."""
    X = rand_points(4, 50)
    rhs = np.array(double_pendulum_rhs(X.T)).T
    A, b = double_pendulum_matrices(X.T)
    A = np.moveaxis(np.array([[np.broadcast_to(a, X.shape[:1]) for a in row] for row in A]), [0, 1], [-2, -1])
    b = np.moveaxis(np.array(b), 0, -1)
    np.testing.assert_allclose(rhs[:, 2:], np.linalg.solve(A, b[..., None])[..., 0], rtol=1e-12, atol=1e-12)


# --------------------------------------------------------------------------- float evaluation


@pytest.fixture(scope="module")
def pendulum_syms():
    return sp.symbols("x1:5")


def test_trace_double_pendulum_matches_numpy():
    g = trace(lambda x, p: double_pendulum_rhs(x), 4, input_names=["x1", "x2", "x3", "x4"])
    X = rand_points(4)
    want = np.array(double_pendulum_rhs(X.T)).T
    np.testing.assert_allclose(g.eval_float(X), want, rtol=1e-12, atol=1e-12)
    assert g.n_outputs == 4 and g.input_names == ("x1", "x2", "x3", "x4")


@pytest.mark.parametrize("cse", [True, False])
def test_from_sympy_double_pendulum_matches_lambdify(pendulum_syms, cse):
    xs = pendulum_syms
    exprs = double_pendulum_rhs(xs, SP, 1, 1, 1, 1, sp.Rational(981, 100))
    g = from_sympy(sp.Matrix(exprs), xs, cse=cse)
    X = rand_points(4)
    f = sp.lambdify(xs, exprs, "numpy")
    want = np.array([np.broadcast_to(v, X.shape[:1]) for v in f(*X.T)]).T
    np.testing.assert_allclose(g.eval_float(X), want, rtol=1e-12, atol=1e-12)


def test_from_sympy_and_trace_agree_on_energy_with_params():
    q, qd, m, l, gr = sp.symbols("q qd m l g")
    H = pendulum_energy((q, qd), (m, l, gr), SP)
    g1 = from_sympy(H, [q, qd], [m, l, gr])
    g2 = trace(pendulum_energy, 2, 3, input_names=["q", "qd"], param_names=["m", "l", "g"])
    X = rand_points(2, 100, scale=3.0)
    P = np.array([1.0, 1.0, 9.81])
    want = 0.5 * P[0] * P[1] ** 2 * X[:, 1] ** 2 + P[0] * P[2] * P[1] * (1 - np.cos(X[:, 0]))
    for g in (g1, g2):
        out = g.eval_float(X, P)
        assert out.shape == (100, 1)
        np.testing.assert_allclose(out[:, 0], want, rtol=1e-12, atol=1e-12)
    assert g1.param_names == ("m", "l", "g") and g2.input_names == ("q", "qd")


def test_all_ops_trace_sympy_numpy_agree():
    a, b, c = sp.symbols("a b c")
    g_sym = from_sympy(all_ops((a, b), (c,), SP), [a, b], [c])
    g_tr = trace(all_ops, 2, 1)
    X = rand_points(2, 100)
    P = np.random.default_rng(1).uniform(-1, 1, size=(100, 1))
    want = np.array(all_ops(X.T, P.T)).T
    for g in (g_sym, g_tr):
        np.testing.assert_allclose(g.eval_float(X, P), want, rtol=1e-12, atol=1e-12)
    used = set(g_tr.op_counts()) | set(g_sym.op_counts())
    # mid (a frozen point) is no function of sympy's or numpy's: tests/verified/test_preconditioned.py
    every = {op.name.lower() for op in Op} - {"mid"}
    assert used >= every, f"missing opcodes: {every - used}"


def test_batch_shapes_and_param_broadcasting():
    g = trace(lambda x, p: [x[0] * p[0] + x[1], np.sin(x[1]) * p[1]], 2, 2)
    X = np.random.default_rng(2).normal(size=(3, 5, 2))
    P = np.array([2.0, -1.0])
    out = g.eval_float(X, P)
    assert out.shape == (3, 5, 2)
    np.testing.assert_allclose(out[..., 0], X[..., 0] * 2 + X[..., 1])
    P2 = np.random.default_rng(3).normal(size=(3, 1, 2))
    out2 = g.eval_float(X, P2)
    np.testing.assert_allclose(out2[..., 1], np.sin(X[..., 1]) * P2[..., 1])
    assert g.eval_float(X[0, 0]).shape == (2,) if g.n_params == 0 else g.eval_float(X[0, 0], P).shape == (2,)
    J = g.jacobian_float(X, P)
    assert J.shape == (3, 5, 2, 2)
    Jp = g.jacobian_float(X, P, wrt="p")
    np.testing.assert_allclose(Jp[..., 0, 0], X[..., 0])
    Jxp = g.jacobian_float(X, P, wrt="xp")
    assert Jxp.shape == (3, 5, 2, 4)
    np.testing.assert_allclose(Jxp[..., :2], J)
    np.testing.assert_allclose(Jxp[..., 2:], Jp)


def test_constant_output_is_broadcast():
    g = trace(lambda x, p: [2.5, x[0], 7], 1)
    out = g.eval_float(np.zeros((4, 1)))
    assert out.shape == (4, 3)
    np.testing.assert_array_equal(out[:, 0], 2.5)
    np.testing.assert_array_equal(out[:, 2], 7.0)
    J = g.jacobian_float(np.zeros((4, 1)))
    np.testing.assert_array_equal(J[:, :, 0], [[0.0, 1.0, 0.0]] * 4)


def test_no_inputs_graph():
    g = trace(lambda x, p: [p[0] * 2.0], 0, 1)
    np.testing.assert_array_equal(g.eval_float(None, [3.0]), [6.0])
    np.testing.assert_array_equal(g.eval_float(np.zeros((2, 0)), [3.0]), [[6.0], [6.0]])


# --------------------------------------------------------------------------- derivatives


@pytest.mark.parametrize("which", ["double_pendulum", "all_ops"])
def test_jacobian_float_matches_sympy_diff(which, pendulum_syms):
    if which == "double_pendulum":
        xs, ps = list(pendulum_syms), []
        exprs = sp.Matrix(double_pendulum_rhs(xs, SP, 1, 1, 1, 1, sp.Rational(981, 100)))
        traced = trace(lambda x, p: double_pendulum_rhs(x), 4)
        P = None
    else:
        xs, ps = list(sp.symbols("a b")), [sp.Symbol("c")]
        exprs = sp.Matrix(all_ops(xs, ps, SP))
        traced = trace(all_ops, 2, 1)
        P = np.array([0.7])
    jac = exprs.jacobian(xs)
    fj = sp.lambdify(xs + ps, jac, "numpy")
    X = rand_points(len(xs), 60)
    args = list(X.T) + ([np.full(len(X), P[0])] if P is not None else [])
    want = np.stack([np.asarray(fj(*[a[i] for a in args]), dtype=float) for i in range(len(X))])
    for g in (from_sympy(exprs, xs, ps), traced):
        np.testing.assert_allclose(g.jacobian_float(X, P), want, rtol=1e-10, atol=1e-10)


def test_jacobian_wrt_params_matches_sympy():
    q, qd, m, l, gr = sp.symbols("q qd m l g")
    H = sp.Matrix([pendulum_energy((q, qd), (m, l, gr), SP)])
    g = from_sympy(H, [q, qd], [m, l, gr])
    fj = sp.lambdify([q, qd, m, l, gr], H.jacobian([q, qd, m, l, gr]), "numpy")
    x, p = np.array([0.4, -1.3]), np.array([1.2, 0.8, 9.81])
    np.testing.assert_allclose(g.jacobian_float(x, p, wrt="xp"), fj(*x, *p), rtol=1e-13)


# --------------------------------------------------------------------------- constants


@pytest.fixture
def arb():
    import flint
    old = flint.ctx.prec
    flint.ctx.prec = 256
    yield flint.arb
    flint.ctx.prec = old


def _const_of(graph: Graph, out: int = 0):
    node = graph.nodes[graph.outputs[out]]
    assert node.op == Op.CONST, graph
    return node.data


def _assert_encloses(arb, lo, hi, exact):
    # arb comparisons are "certainly" comparisons: True only if it holds for every
    # point of the ball, so this is a rigorous check
    assert arb(lo) <= exact, (lo, exact)
    assert exact <= arb(hi), (hi, exact)


@pytest.mark.parametrize(
    "expr, exact",
    [
        (sp.pi, lambda a: a.pi()),
        (sp.E, lambda a: a.const_e()),
        (sp.EulerGamma, lambda a: a.const_euler()),
        (sp.Rational(1, 3), lambda a: a(1) / 3),
        (sp.Rational(-2, 7), lambda a: a(-2) / 7),
        (sp.pi / 3, lambda a: a.pi() / 3),
        (-3 * sp.pi / 4, lambda a: -3 * a.pi() / 4),
        (sp.Integer(2**60 + 1), lambda a: a(2**60 + 1)),
        (sp.Float("0.1", 30), lambda a: a("0.1")),  # 30-digit Float: not a double
    ],
)
def test_sympy_constants_enclose_exact_value(arb, expr, exact):
    g = from_sympy(expr, [])
    lo, hi, value = _const_of(g)
    _assert_encloses(arb, lo, hi, exact(arb))
    assert lo <= value <= hi
    assert hi == lo or np.nextafter(lo, np.inf) == hi or np.nextafter(np.nextafter(lo, np.inf), np.inf) == hi


def test_constant_enclosure_used_by_interval_eval(arb):
    x = sp.Symbol("x")
    g = from_sympy(sp.pi * x + sp.Rational(1, 3), [x])
    y = g.eval_interval(np.array([[1.0]]))
    _assert_encloses(arb, float(y.lo[0, 0]), float(y.hi[0, 0]), arb.pi() + arb(1) / 3)


def test_exact_constants_are_points():
    x = sp.Symbol("x")
    for c in (sp.Integer(3), sp.Rational(1, 4), sp.Float(0.1), sp.Integer(-(2**53))):
        lo, hi, value = _const_of(from_sympy(c, [x]))
        assert lo == hi == value == float(c)
    # a Python float in traced code is exact: the double itself
    lo, hi, value = _const_of(trace(lambda x, p: 0.1, 0))
    assert lo == hi == value == 0.1
    # a Fraction is enclosed
    lo, hi, value = _const_of(trace(lambda x, p: Fraction(1, 10), 0))
    assert Fraction(lo) < Fraction(1, 10) < Fraction(hi) and value == 0.1


def test_float_eval_uses_nearest_double():
    g = from_sympy(sp.pi, [])
    assert g.eval_float(None)[0] == math.pi


# --------------------------------------------------------------------------- sharing and simplification


def test_builder_hash_conses_and_normalizes_commutative_args():
    b = GraphBuilder(2)
    x, y = b.input(0), b.input(1)
    s1, s2 = b.sin(b.mul(x, y)), b.sin(b.mul(y, x))
    assert s1 == s2
    assert b.add(s1, x) == b.add(x, s2)
    assert b.sub(s1, x) != b.sub(x, s1)
    assert b.const(2.0) == b.const(2)
    n_before = len(b)
    b.sin(b.mul(x, y))
    assert len(b) == n_before


def test_cse_graph_smaller_than_tree():
    x, y = sp.symbols("x y")
    t = sp.sin(x * y) + sp.cos(x * y)
    expr = t**2 * sp.exp(t) + sp.log(t**2 + 1)
    tree_size = sum(1 for node in sp.preorder_traversal(expr) if node.args)  # operation nodes
    for cse in (True, False):
        g = from_sympy(expr, [x, y], cse=cse)
        assert g.n_ops < tree_size, (g.n_ops, tree_size)
    # tracing shares equal subexpressions too
    g = trace(lambda v, p: [np.sin(v[0] * v[1]) * np.sin(v[1] * v[0]), np.sin(v[0] * v[1])], 2)
    assert g.n_ops == 3  # mul, sin, sqr
    assert g.op_counts()["sin"] == 1


@pytest.mark.parametrize(
    "fn, n_ops",
    [
        (lambda x: x * 1, 0),
        (lambda x: 1.0 * x + 0, 0),
        (lambda x: x - 0.0, 0),
        (lambda x: 0 - x, 1),  # neg
        (lambda x: -(-x), 0),
        (lambda x: x / 1, 0),
        (lambda x: x * -1.0, 1),
        (lambda x: x * 0, 0),
        (lambda x: x - x, 0),
        (lambda x: x * x, 1),  # sqr
        (lambda x: x**0, 0),
        (lambda x: x**1, 0),
        (lambda x: x + (-x) * 2, 2),  # x - (x*2): mul, sub
    ],
)
def test_exact_simplifications(fn, n_ops):
    g = trace(lambda v, p: fn(v[0]), 1)
    assert g.n_ops == n_ops, g
    X = np.array([[-1.5], [0.0], [2.25]])
    np.testing.assert_array_equal(g.eval_float(X)[:, 0], [fn(v) for v in X[:, 0]])


@pytest.mark.parametrize(
    "fn, ops",
    [
        (lambda a, b: b + (-a), {"sub": 1}),
        (lambda a, b: (-a) + b, {"sub": 1}),
        (lambda a, b: b - (-a), {"add": 1}),
        (lambda a, b: (-a) * b, {"mul": 1, "neg": 1}),
        (lambda a, b: (-a) * (-b), {"mul": 1}),
        (lambda a, b: (-a) / b, {"div": 1, "neg": 1}),
        (lambda a, b: a / (-b), {"div": 1, "neg": 1}),
        (lambda a, b: b - 2.0 * (-a), {"add": 1, "mul": 1}),
        (lambda a, b: np.square(-a) + b * b, {"sqr": 2, "add": 1}),
        (lambda a, b: a * b - b * a, {}),
    ],
)
def test_negation_rules_are_exact(fn, ops):
    g = trace(lambda x, p: fn(x[0], x[1]), 2)
    counts = {k: v for k, v in g.op_counts().items() if k not in ("input", "const")}
    assert counts == ops, g
    X = np.random.default_rng(9).uniform(-3, 3, size=(100, 2))
    np.testing.assert_array_equal(g.eval_float(X)[:, 0], np.broadcast_to(fn(X[:, 0], X[:, 1]), (100,)))


def test_constant_folding_only_when_exact():
    folded = trace(lambda x, p: 0.5 + 0.25 * 2, 0)
    assert folded.n_ops == 0 and _const_of(folded)[2] == 1.0
    inexact = trace(lambda x, p: (x[0] * 0 + 0.1) + 0.2, 1)
    assert inexact.n_ops == 1 and inexact.op_counts()["add"] == 1  # 0.1 + 0.2 is not exact
    third = trace(lambda x, p: Fraction(1) / 3, 0)
    lo, hi, _ = _const_of(third)
    assert lo < hi  # Fraction(1)/3 is a rational constant, enclosed
    div = trace(lambda x, p: [x[0] * 0 + 1.0 / 3.0 * 1], 1)
    assert div.n_ops == 0  # 1.0/3.0 is Python float arithmetic: an exact double constant
    assert trace(lambda x, p: np.sqrt(x[0] * 0 + 4.0), 1).n_ops == 0
    assert trace(lambda x, p: np.sqrt(x[0] * 0 + 2.0), 1).n_ops == 1


def test_unused_nodes_are_pruned():
    def f(x, p):
        np.exp(x[0])  # computed but unused
        return x[0] + x[1]

    g = trace(f, 2)
    assert g.n_ops == 1 and "exp" not in g.op_counts()


# --------------------------------------------------------------------------- sympy front end details


def test_sympy_powers():
    x, y = sp.symbols("x y", positive=True)
    cases = {
        x**2: "sqr",
        x**5: "pow",
        x**-3: "div",
        sp.sqrt(x): "sqrt",
        1 / sp.sqrt(x): "div",
        x ** sp.Rational(3, 2): "pow",
        x ** sp.Rational(-5, 2): "div",
        x * y**-2: "div",
    }
    X = np.random.default_rng(4).uniform(0.2, 3.0, size=(50, 2))
    for expr, op in cases.items():
        g = from_sympy(expr, [x, y], cse=False)
        assert op in g.op_counts(), (expr, g)
        want = sp.lambdify([x, y], expr, "numpy")(X[:, 0], X[:, 1])
        np.testing.assert_allclose(g.eval_float(X)[:, 0], want, rtol=1e-13)
    assert from_sympy(x * y**-2, [x, y]).op_counts()["div"] == 1


def test_sympy_subtraction_and_negation():
    x, y = sp.symbols("x y")
    g = from_sympy(x - 3 * y, [x, y])
    assert g.op_counts().get("neg", 0) == 0 and g.op_counts()["sub"] == 1
    g2 = from_sympy(-x - y, [x, y])
    np.testing.assert_allclose(g2.eval_float([[1.0, 2.0]]), [[-3.0]])


def test_sympy_function_of_time_inputs():
    t = sp.Symbol("t")
    q = sp.Function("q")(t)
    qd = sp.Derivative(q, t)
    g = from_sympy(sp.sin(q) * qd, [q, qd])
    np.testing.assert_allclose(g.eval_float([[0.5, 2.0]]), [[np.sin(0.5) * 2.0]])


def test_to_sympy_roundtrip(pendulum_syms):
    exprs = double_pendulum_rhs(pendulum_syms, SP, 1, 1, 1, 1, sp.Rational(981, 100))
    g = from_sympy(exprs, pendulum_syms)
    back = g.to_sympy()
    f = sp.lambdify(sp.symbols("x1:5"), back, "numpy")
    X = rand_points(4, 20)
    np.testing.assert_allclose(np.array([np.broadcast_to(v, (20,)) for v in f(*X.T)]).T, g.eval_float(X), rtol=1e-12)


# --------------------------------------------------------------------------- tracer protocol


def test_generic_model_code_runs_on_floats_arrays_and_tracers():
    g = trace(lambda v, p: generic_model(v[0], p[0], p[1], v[1]), 2, 2)
    q, x = np.linspace(-1, 1, 7), np.linspace(2, 3, 7)
    assert generic_model(0.3, 2.0, 3.0, 0.5) == g.eval_float([0.3, 0.5], [2.0, 3.0])[0]
    np.testing.assert_array_equal(g.eval_float(np.stack([q, x], -1), [2.0, 3.0])[:, 0], generic_model(q, 2.0, 3.0, x))


def test_tracer_numpy_interop():
    def f(x, p):
        a, b = x
        v = np.array([a, b])  # object array of Tracers
        w = np.array([[1.0, 2.0], [3.0, 4.0]]) @ v
        return [
            np.float64(2.0) * a,
            a * np.int64(3),
            np.power(a, 3),
            np.square(b),
            np.add(a, 1),
            np.subtract(1, b),
            np.multiply(a, b),
            np.true_divide(a, b),
            np.negative(a),
            *np.sin(v),
            *w,
            np.sum(v),
            a ** Fraction(1, 2),
            a**0.5,
            a**-1.5,
            2 / b,
        ]

    g = trace(f, 2)
    a, b = 1.7, -0.6
    want = [2 * a, 3 * a, a**3, b * b, a + 1, 1 - b, a * b, a / b, -a, np.sin(a), np.sin(b), a + 2 * b,
            3 * a + 4 * b, a + b, np.sqrt(a), np.sqrt(a), 1 / np.sqrt(a) ** 3, 2 / b]
    np.testing.assert_allclose(g.eval_float([a, b]), want, rtol=1e-15)


def test_tracer_control_flow_raises():
    for bad in (
        lambda x, p: x[0] if x[0] > 0 else -x[0],
        lambda x, p: bool(x[0]),
        lambda x, p: x[0] == 1,
        lambda x, p: float(x[0]),
        lambda x, p: math.sin(x[0]),
    ):
        with pytest.raises(TypeError, match="data-dependent control flow cannot be traced"):
            trace(bad, 1)


def test_tracer_unsupported_operations_raise():
    with pytest.raises(TypeError, match="absolute"):
        trace(lambda x, p: np.abs(x[0]), 1)
    with pytest.raises(NotImplementedError, match="abs"):
        trace(lambda x, p: abs(x[0]), 1)
    with pytest.raises(NotImplementedError, match="half-integer"):
        trace(lambda x, p: x[0] ** (1 / 3), 1)
    with pytest.raises(NotImplementedError, match="exponent"):
        trace(lambda x, p: 2 ** x[0], 1)
    with pytest.raises(NotImplementedError, match="exponent"):
        trace(lambda x, p: x[0] ** x[0], 1)
    with pytest.raises(TypeError, match="str"):
        trace(lambda x, p: x[0] + "a", 1)
    with pytest.raises(TypeError, match="output 0"):
        trace(lambda x, p: "a", 1)
    with pytest.raises(ZeroDivisionError, match="constant 0"):
        trace(lambda x, p: x[0] / 0, 1)
    other = trace(lambda x, p: x[0], 1)  # noqa: F841 (a different trace)
    saved = []
    trace(lambda x, p: saved.append(x[0]) or x[0], 1)
    with pytest.raises(ValueError, match="different trace"):
        trace(lambda x, p: x[0] + saved[0], 1)
    with pytest.raises(ValueError, match="different trace"):
        trace(lambda x, p: saved[0], 1)


def test_tracer_repr():
    b = GraphBuilder(1)
    t = Tracer(b, b.input(0))
    assert "input" in repr(t) and "sin" in repr(np.sin(t))


# --------------------------------------------------------------------------- errors


def test_from_sympy_unsupported_raise_with_subexpression():
    x, y, z = sp.symbols("x y z")
    cases = [
        (sp.Abs(x) + 1, NotImplementedError, "Abs"),
        (sp.sign(x) * y, NotImplementedError, "sign"),
        (sp.Piecewise((x, x > 0), (y, True)), NotImplementedError, "Piecewise"),
        (x ** sp.Rational(1, 3), NotImplementedError, "1/3"),
        (2**x, NotImplementedError, "2\\*\\*x"),
        (x**y, NotImplementedError, "x\\*\\*y"),
        (sp.sinh(x), NotImplementedError, "sinh"),
        (x + z, ValueError, "unknown symbol z"),
        (x + sp.I, NotImplementedError, "I"),
        (x + sp.oo, NotImplementedError, "oo"),
    ]
    for expr, exc, pattern in cases:
        with pytest.raises(exc, match=pattern):
            from_sympy(expr, [x], [y])
    with pytest.raises(ValueError, match="distinct"):
        from_sympy(x, [x], [x])


def test_eval_shape_errors_say_expected_and_got():
    g = trace(lambda x, p: x[0] * p[0], 2, 1, input_names=["q", "qd"], param_names=["m"])
    with pytest.raises(ValueError, match=r"x must have shape \(\.\.\., 2\) for \(q, qd\); got shape \(5, 3\)"):
        g.eval_float(np.zeros((5, 3)), [1.0])
    with pytest.raises(ValueError, match=r"p must have shape \(\.\.\., 1\) for \(m\); got shape \(2,\)"):
        g.eval_float(np.zeros((5, 2)), [1.0, 2.0])
    with pytest.raises(ValueError, match="1 parameters"):
        g.jacobian_float(np.zeros((5, 2)))
    with pytest.raises(ValueError, match="got shape \\(\\)"):
        g.eval_float(1.0, [1.0])
    with pytest.raises(ValueError, match="wrt"):
        g.jacobian_float(np.zeros(2), [1.0], wrt="q")


def test_graph_validation_errors():
    with pytest.raises(ValueError, match="topological"):
        Graph([Node(Op.INPUT, (), 0), Node(Op.SIN, (2,), None), Node(Op.INPUT, (), 0)], [1], ["x"])
    with pytest.raises(ValueError, match="arguments"):
        Graph([Node(Op.INPUT, (), 0), Node(Op.ADD, (0,), None)], [1], ["x"])
    with pytest.raises(ValueError, match="lo <= value <= hi"):
        Graph([Node(Op.CONST, (), (1.0, 0.5, 0.7))], [0], [])
    with pytest.raises(ValueError, match="index 1 out of range"):
        Graph([Node(Op.INPUT, (), 1)], [0], ["x"])
    with pytest.raises(ValueError, match="exponent"):
        Graph([Node(Op.INPUT, (), 0), Node(Op.POW, (0,), 2)], [1], ["x"])
    with pytest.raises(ValueError, match="finite"):
        GraphBuilder(0).const(float("nan"))


# --------------------------------------------------------------------------- serialization and display


def test_to_dict_from_dict_roundtrip_through_json(pendulum_syms):
    exprs = double_pendulum_rhs(pendulum_syms, SP, 1, 1, 1, 1, sp.Rational(981, 100)) + [sp.pi * pendulum_syms[0]]
    g = from_sympy(exprs, pendulum_syms, output_names=["d1", "d2", "d3", "d4", "pix"])
    g2 = Graph.from_dict(json.loads(json.dumps(g.to_dict())))
    assert g2 == g
    assert g2.output_names == ("d1", "d2", "d3", "d4", "pix")
    X = rand_points(4, 10)
    np.testing.assert_array_equal(g2.eval_float(X), g.eval_float(X))
    d = g.to_dict()
    d["version"] = 99
    with pytest.raises(ValueError, match="version"):
        Graph.from_dict(d)
    d = g.to_dict()
    d["nodes"][5][0] = "frobnicate"
    with pytest.raises(ValueError, match="frobnicate"):
        Graph.from_dict(d)
    with pytest.raises(ValueError, match="format"):
        Graph.from_dict({"nodes": []})


def test_repr_is_readable():
    g = trace(lambda x, p: [np.sin(x[0]) * p[0], x[0] ** 3], 1, 1, input_names=["q"], param_names=["l"])
    text = repr(g)
    assert "n_ops=3" in text and "sin(%0)" in text and "input q" in text and "param l" in text
    assert "pow(%0, 3)" in text and "outputs: y0=" in text
    big = trace(lambda x, p: sum(np.sin(x[0] * k) for k in range(2, 60)), 1)
    assert "more nodes" in repr(big) and len(big.pretty().splitlines()) > len(repr(big).splitlines())


def test_tracer_accepts_rigorous_irrational_constants(arb):
    from verified.arith.interval import Interval

    g = trace(lambda x, p: [x[0] * sp.pi, sp.pi / 3 + x[0], x[0] * sp.sqrt(2), x[0] * Interval(1.0, 1.5)], 1)
    Y = g.eval_interval(np.array([1.0]))
    _assert_encloses(arb, float(Y.lo[0]), float(Y.hi[0]), arb.pi())
    _assert_encloses(arb, float(Y.lo[1]), float(Y.hi[1]), arb.pi() / 3 + 1)
    _assert_encloses(arb, float(Y.lo[2]), float(Y.hi[2]), arb(2).sqrt())
    assert 0.999999 < Y.lo[3] <= 1.0 and 1.5 <= Y.hi[3] < 1.500001
    np.testing.assert_allclose(g.eval_float([1.0]), [np.pi, np.pi / 3 + 1, np.sqrt(2), 1.25])
    with pytest.raises(TypeError):
        trace(lambda x, p: x[0] * sp.Symbol("z"), 1)


def test_tracer_broadcasts_over_float_arrays():
    g = trace(lambda x, p: list(np.array([1.0, 2.0]) * x[0] + np.sin(x[1]) * np.array([3, 4])), 2)
    np.testing.assert_allclose(g.eval_float([0.5, 0.3]), [0.5 + 3 * np.sin(0.3), 1 + 4 * np.sin(0.3)], rtol=1e-15)


def test_custom_domain_walks_each_node_once():
    """Evaluators are pluggable: a Domain subclass that renders expressions as strings."""
    from verified.graph.evaluate import Domain

    calls = []

    class Render(Domain):
        def const(self, lo, hi, value):
            return repr(value)

        def __getattribute__(self, name):
            attr = object.__getattribute__(self, name)
            if name in {op.name.lower() for op in Op} - {"const", "input", "param"}:
                def op(*args):
                    calls.append(name)
                    return f"{name}({', '.join(map(str, args))})"
                return op
            return attr

    g = trace(lambda x, p: [np.sin(x[0] * p[0]) + x[0] ** 3, np.sin(x[0] * p[0])], 1, 1)
    out = g.evaluate(Render(), ["q"], ["l"])
    assert out == ["add(sin(mul(q, l)), pow(q, 3))", "sin(mul(q, l))"]
    assert sorted(calls) == sorted(["mul", "sin", "pow", "add"])  # shared sin evaluated once


def test_select_fingerprint_and_pickle():
    import pickle

    g = trace(lambda x, p: [np.sin(x[0]) * x[1], np.cos(x[1]), x[0] + 1.0], 2, output_names=["a", "b", "c"])
    sub = g.select(["c", 0])
    assert sub.output_names == ("c", "a") and sub.n_inputs == 2
    assert sub.n_ops == 3 and "cos" not in sub.op_counts()
    X = rand_points(2, 7)
    np.testing.assert_array_equal(sub.eval_float(X), g.eval_float(X)[:, [2, 0]])
    with pytest.raises(ValueError, match="no output named 'z'"):
        g.select(["z"])
    with pytest.raises(IndexError):
        g.select([3])
    assert g.fingerprint() == Graph.from_dict(g.to_dict()).fingerprint() != sub.fingerprint()
    assert len(g.fingerprint()) == 64
    g2 = pickle.loads(pickle.dumps(g))
    assert g2 == g and hash(g2) == hash(g)


def test_gradient_graph_and_params_to_inputs():
    from verified.graph.evaluate import eval_float
    from verified.graph import trace
    from verified.graph.ops import gradient_graph, params_to_inputs
    g = trace(lambda x, p: [x[0] * x[0] * x[1] + x[1].sin() * p[0]], 2, 1)
    x, p = np.array([[0.3, -1.2]]), np.array([[2.0]])
    d = eval_float(gradient_graph(g), x, p)[0]
    assert np.allclose(d, [2 * 0.3 * -1.2, 0.3 ** 2 + np.cos(-1.2) * 2.0], rtol=1e-14)
    assert np.allclose(eval_float(gradient_graph(g, 1), x, p)[0], d[:1], rtol=1e-14)
    y = params_to_inputs(g)
    assert y.n_inputs == 3 and y.n_params == 0
    assert eval_float(y, np.c_[x, p])[0, 0] == eval_float(g, x, p)[0, 0]


@pytest.mark.parametrize("a, b", [(Fraction(0), Fraction(1)), (Fraction(0), Fraction(-3, 4)), (Fraction(1, 3), Fraction(2)),
                                  (Fraction(-355, 113), Fraction(1)),
                                  # within 2^-260 of -pi: cancels more than the first 200 bits
                                  (Fraction(-1455086307567065297120939771110919450613573509313569719835088604471755577864741,
                                            2**260), Fraction(1))])
def test_pi_multiples_are_enclosed_by_verified_exact(arb, a, b):
    """Issue 15: multiples of pi have one home, verified.arith.exact; the one-ulp enclosure
    (constant nodes, the contractor's pi) and the two-ulp one (scenes, models) both
    contain a + b pi, also when a + b pi cancels beyond the first working precision."""
    from verified.consistency.contractor import _PI
    from verified.arith.exact import enclose_pi_multiple, pi_multiple_enclosure
    exact = arb(a.numerator) / a.denominator + arb(b.numerator) / b.denominator * arb.pi()
    lo, hi, value = pi_multiple_enclosure(a, b)
    _assert_encloses(arb, lo, hi, exact)
    assert np.nextafter(lo, np.inf) == hi and value in (lo, hi)
    _assert_encloses(arb, *enclose_pi_multiple(a, b), exact)
    assert (float(_PI.lo), float(_PI.hi)) == pi_multiple_enclosure(0, 1)[:2] == (math.pi, np.nextafter(math.pi, np.inf))
    if a == 0:
        assert _const_of(from_sympy(sp.Rational(b.numerator, b.denominator) * sp.pi, [])) == (lo, hi, value)

"""The Taylor recursion and its tables (verified.series.recursion): the interval and affine
tables against exact (arb) coefficients, and the checks bite on a table with a wrong rule."""

from typing import NamedTuple

import numpy as np
import pytest
from numba import njit
from oracles.arb_series import arb_taylor, assert_inside
from oracles.graph_models import all_ops

from verified.arith import _kernels as _k
from verified.arith.interval import Interval
from verified.graph import trace
from verified.series import affine_taylor, recursion, taylor
from verified.series.taylor import TaylorODE


def _all_ops_graph():
    """Every opcode but mid (the oracle reads it as the identity, not as a frozen point):
    all_ops (add sub neg mul sqr div sqrt exp log sin cos tan atan, a parameter, constant
    factors and divisors) and two more states, a cos sharing its sin's slots."""
    def f(x, p):
        a, b = x[0], x[1]
        return all_ops((a, b), p)[:2] + [-(a * np.sin(x[2])) + np.cos(x[2]) * b, x[0] - x[3] / 3.0]
    return trace(f, 4, 1)


def test_interval_table_contains_the_exact_coefficients():
    g = _all_ops_graph()
    x0 = np.array([[0.3, -0.2, 0.5, 0.1], [-0.4, 0.25, -0.1, 0.7]])
    order = 7
    C = TaylorODE(g).coefficients(Interval(x0, x0), order, params=Interval([0.7], [0.7]))
    for b in range(2):
        assert_inside(C.lo[b], C.hi[b], arb_taylor(g, x0[b], [0.7], order), f"point {b}")


# --------------------------------------------------------------------------
# A table with one wrong rule: the product's convolution drops its last term.
# --------------------------------------------------------------------------
class _DropsATerm(NamedTuple):
    lo: np.ndarray
    hi: np.ndarray
    xlo: np.ndarray
    xhi: np.ndarray
    plo: np.ndarray
    phi: np.ndarray


def _mul_without_last_term(ar, s, k, u, v):
    tlo, thi = ar.lo, ar.hi
    for b in range(tlo.shape[2]):
        sl = 0.0
        sh = 0.0
        for j in range(k):  # (the term j = k, u_k v_0, is missing)
            pl, ph = _k.mul(tlo[u, j, b], thi[u, j, b], tlo[v, k - j, b], thi[v, k - j, b])
            sl, sh = _k.add(sl, sh, pl, ph)
        tlo[s, k, b] = sl
        thi[s, k, b] = sh


recursion.register(_DropsATerm, **{name: getattr(taylor, "_iv_" + name) for name in recursion.RULES if name != "mul"},
                   mul=_mul_without_last_term)


@njit
def _run(op, a0, a1, aux, idx, cst, clo, chi, outputs, order, ar):
    recursion.recursion(op, a0, a1, aux, idx, cst, clo, chi, outputs, order, ar)


def _coefficients(table, graph, x0, order):
    """x_[0..order] (order + 1, n) as (lo, hi) for the point x0, with the rules of ``table``."""
    t = taylor._Tape(graph)
    n, ns = len(x0), t.op.size
    X = np.zeros((n, order + 1, 1))
    X[:, 0, 0] = x0
    ar = table(np.zeros((ns, order + 1, 1)), np.zeros((ns, order + 1, 1)), X, X.copy(), np.zeros((0, 1)),
               np.zeros((0, 1)))
    _run(t.op, t.a0, t.a1, t.aux, t.idx, t.cst, t.clo, t.chi, t.outputs, order, ar)
    return ar.xlo[:, :, 0].T, ar.xhi[:, :, 0].T


@pytest.mark.slow  # (compiles a mutant table through the engine: 13-29 s; the default run stays under 3 minutes)
def test_the_exact_check_bites_on_a_wrong_rule():
    """Both tables through the same engine: the interval table's coefficients contain the
    exact ones, those of the table whose product drops a term do not."""
    g = trace(lambda x, p: [x[0] * x[1], -x[0]], 2)
    x0 = np.array([0.6, -0.3])
    exact = arb_taylor(g, x0, None, 6)
    lo, hi = _coefficients(taylor.IntervalTable, g, x0, 6)
    assert_inside(lo, hi, exact, "interval table")
    lo, hi = _coefficients(_DropsATerm, g, x0, 6)
    with pytest.raises(AssertionError, match="outside"):
        assert_inside(lo, hi, exact, "a product without its last term")


# --------------------------------------------------------------------------
# The affine table (affine_taylor.AffineTable, the reference kernel's) through the same
# engine, and a copy whose product drops the last term of its convolution.
# --------------------------------------------------------------------------
class _AffineDropsATerm(NamedTuple):
    F: np.ndarray
    REC: np.ndarray
    out: np.ndarray
    P: np.ndarray
    T: np.ndarray
    S: np.ndarray
    sel: np.ndarray
    sel_base: int
    m0: int
    n_fresh: int


def _affine_mul_without_last_term(ar, s, k, u, v):
    F = ar.F
    m = F.shape[3] - 2
    for b in range(F.shape[2]):
        Z = F[s, k, b]
        affine_taylor._clear(Z, m)
        for j in range(k):  # (the term j = k, u_k v_0, is missing)
            affine_taylor._acc_mul(Z, F[u, j, b], F[v, k - j, b], m, 1.0)


recursion.register(_AffineDropsATerm, **{name: getattr(affine_taylor, "_ar_" + name) for name in recursion.RULES
                                         if name != "mul"}, mul=_affine_mul_without_last_term)


def _affine_coefficients(table, graph, X, order):
    """The forms of x_[0..order] (n, order + 1, B, m + 2) from the input forms X (n, B, m + 2),
    with the rules of ``table``."""
    t = taylor._Tape(graph)
    n, nb, m2 = X.shape
    ns = t.op.size
    out = np.zeros((n, order + 1, nb, m2))
    out[:, 0] = X
    ar = table(np.zeros((ns, order + 1, nb, m2)), np.zeros((ns, nb, m2)), out, np.zeros((0, nb, m2)), np.zeros(m2),
               np.zeros(m2), affine_taylor._NO_SLOTS, 0, 0, 0)
    _run(t.op, t.a0, t.a1, t.aux, t.idx, t.cst, t.clo, t.chi, t.outputs, order, ar)
    return ar.out


@pytest.mark.slow  # (compiles a mutant table through the engine: 13-29 s; the default run stays under 3 minutes)
def test_the_affine_checks_bite_on_a_wrong_rule():
    """The affine table run through the engine here is the reference kernel, bit for bit,
    and its forms contain the exact coefficients at the centre; the table whose product
    drops a term fails both."""
    g = trace(lambda x, p: [x[0] * x[1], -x[0]], 2)
    x0 = np.array([0.6, -0.3])
    order = 6
    X = np.zeros((2, 1, 4))  # centre x0, one symbol per state, no error
    X[:, 0, 0] = x0
    X[0, 0, 1] = X[1, 0, 2] = 1e-3
    t = taylor._Tape(g)
    ref, _ = affine_taylor._affine_kernel_reference(t.op, t.a0, t.a1, t.aux, t.idx, t.cst, t.clo, t.chi, t.outputs, X,
                                                    np.zeros((0, 1, 4)), order, 2, 0, affine_taylor._NO_SLOTS, 0)
    exact = arb_taylor(g, x0, None, order)
    good = _affine_coefficients(affine_taylor.AffineTable, g, X, order)
    assert np.array_equal(good, ref)
    lo, hi = affine_taylor.forms_to_interval(good[:, :, 0])
    assert_inside(lo.T, hi.T, exact, "affine table")
    bad = _affine_coefficients(_AffineDropsATerm, g, X, order)
    assert not np.array_equal(bad, ref)
    lo, hi = affine_taylor.forms_to_interval(bad[:, :, 0])
    with pytest.raises(AssertionError, match="outside"):
        assert_inside(lo.T, hi.T, exact, "an affine product without its last term")


def test_register_checks_the_rules():
    rules = {name: getattr(taylor, "_iv_" + name) for name in recursion.RULES}
    with pytest.raises(ValueError, match="missing rules"):
        recursion.register(_DropsATerm, **{k: v for k, v in rules.items() if k != "sqr"})
    with pytest.raises(ValueError, match="must take"):
        recursion.register(_DropsATerm, **dict(rules, add=lambda ar, s, k, a, b: None))


def test_rules_named_collects_a_tables_rules_and_names_a_missing_one():
    rules = recursion.rules_named(vars(taylor), "_iv_")
    assert set(rules) == set(recursion.RULES) and rules["add"] is taylor._iv_add
    namespace = {k: v for k, v in vars(taylor).items() if k != "_iv_sqr"}
    with pytest.raises(ValueError, match="_iv_sqr"):
        recursion.rules_named(namespace, "_iv_")

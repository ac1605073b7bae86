"""The Taylor recursion and its tables (verified.series.recursion): the interval table
against exact (arb) coefficients, and the check bites on a table with a wrong rule."""

from typing import NamedTuple

import numpy as np
import pytest
from numba import njit
from oracles.arb_series import arb_taylor, assert_inside
from oracles.graph_models import all_ops

from verified.arith import _kernels as _k
from verified.arith.interval import Interval
from verified.graph import trace
from verified.series import recursion, taylor
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


def test_register_checks_the_rules():
    rules = {name: getattr(taylor, "_iv_" + name) for name in recursion.RULES}
    with pytest.raises(ValueError, match="missing rules"):
        recursion.register(_DropsATerm, **{k: v for k, v in rules.items() if k != "sqr"})
    with pytest.raises(ValueError, match="must take"):
        recursion.register(_DropsATerm, **dict(rules, add=lambda ar, s, k, a, b: None))

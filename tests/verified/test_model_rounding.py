"""The Taylor-model kernel's coefficient loops against exact rationals, and the kernels' work memory.

``verified.series.taylor_model._acc_mul``, ``_acc_add``, ``_scale_into`` and ``_div_int_into``
bound the rounding of their float coefficient updates from sums of magnitudes (vectorized,
``_abs_sum``), not term by term. Oracle: the same operation in ``fractions.Fraction`` (exact);
the computed model must contain it, i.e. the sum of ``|computed - exact|`` over its
coefficients must not exceed the remainder it adds. The inputs are chosen to cancel
(``T`` close to ``-w x y``), where rounding is all there is. The oracle bites: a product
without its rounding term fails.

The model and affine kernels reuse their work memory between calls: garbage (NaN) in it
must change no result, on graphs with every operation the kernels have and the 3-link arm.
"""

from __future__ import annotations

import pickle
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import verified.series.taylor_model as tm
from oracles.graph_models import all_ops
from oracles.taylor_cases import _arm
from verified.series.affine_taylor import AffineTaylorODE
from verified.graph import trace
from verified.arith.interval import Interval
from verified.series.taylor_model import TaylorModelODE

pytestmark = pytest.mark.slow  # (the kernel module compiles in the slow step, as test_taylor_model)

M = 5  # symbols, all with quadratic monomials: a product of linear models drops no pair
PA, PB, PC = tm.product_table(M, M)
L = tm.model_length(M, M)
E = L - 1

finite = st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False, allow_subnormal=False)


def _exact_product(T0, x, y, w):
    """T0 + w x y for linear models x, y (centre and M linear coefficients), exactly."""
    F = [Fraction(v) for v in T0[:E]]
    fw = Fraction(w)
    for a in range(M + 1):
        for b in range(M + 1):
            if x[a] == 0.0 or y[b] == 0.0:
                continue
            p = fw * Fraction(x[a]) * Fraction(y[b])
            if a == 0:
                F[b] += p
            elif b == 0:
                F[a] += p
            else:
                i, j = min(a, b) - 1, max(a, b) - 1
                F[M + 1 + _pair_index(i, j)] += p
    return F


def _pair_index(i, j):
    pi, pj = tm._pairs(M)
    return int(np.flatnonzero((pi == i) & (pj == j))[0])


def _excess(T, exact, e0=0.0):
    """sum |T - exact| minus the remainder T gained over e0 (> 0: not contained)."""
    dev = sum(abs(Fraction(T[i]) - exact[i]) for i in range(E))
    return dev - (Fraction(T[E]) - Fraction(e0))


def _linear(c, lin):
    x = np.zeros(L)
    x[0] = c
    x[1: M + 1] = lin
    return x


def _cancelling_start(x, y, w, jitter):
    """T0 = -(w x y) rounded, plus a small jitter: the update cancels to rounding level."""
    T0 = np.zeros(L)
    T0[0] = -(w * (x[0] * y[0])) + jitter
    for i in range(1, M + 1):
        T0[i] = -(w * (x[0] * y[i]) + w * (y[0] * x[i])) * (1.0 + jitter * 1e-9)
    return T0


@settings(max_examples=150, deadline=None)
@given(cx=finite, cy=finite, lx=st.lists(finite, min_size=M, max_size=M), ly=st.lists(finite, min_size=M, max_size=M),
       w=st.floats(-1e3, 1e3, allow_nan=False, allow_subnormal=False), jitter=st.floats(-1.0, 1.0),
       cancel=st.booleans())
def test_product_contains_the_exact_product(cx, cy, lx, ly, w, jitter, cancel):
    x, y = _linear(cx, lx), _linear(cy, ly)
    T0 = _cancelling_start(x, y, w, jitter) if cancel else np.zeros(L)
    exact = _exact_product(T0, x, y, w)
    T = T0.copy()
    tm._acc_mul(T, x, y, PA, PB, PC, w)
    assert _excess(T, exact) <= 0


@settings(max_examples=100, deadline=None)
@given(a=st.lists(finite, min_size=L - 1, max_size=L - 1), b=st.lists(finite, min_size=L - 1, max_size=L - 1),
       d=st.floats(-1e3, 1e3, allow_nan=False, allow_subnormal=False), k=st.integers(1, 40),
       sign=st.sampled_from([1.0, -1.0]))
def test_sum_scale_and_division_contain_the_exact_results(a, b, d, k, sign):
    x = np.array(a + [0.0])
    T = np.array(b + [0.0])
    exact = [Fraction(T[i]) + Fraction(sign) * Fraction(x[i]) for i in range(E)]
    tm._acc_add(T, x, sign)
    assert _excess(T, exact) <= 0
    Z = np.zeros(L)
    tm._scale_into(Z, x, d)
    assert _excess(Z, [Fraction(d) * Fraction(v) for v in x[:E]]) <= 0
    tm._div_int_into(Z, x, float(k))
    assert _excess(Z, [Fraction(v) / k for v in x[:E]]) <= 0


def test_the_oracle_bites_a_product_without_its_rounding():
    """The same product with its rounding term dropped is caught on a cancelling input."""

    def product_without_rounding(T, x, y, w):
        x0, y0 = x[0], y[0]
        T[0] = T[0] + w * (x0 * y0)
        for i in range(1, E):
            T[i] = T[i] + (w * (x0 * y[i]) + w * (y0 * x[i]))
        for t in range(PA.size):
            T[PC[t]] = T[PC[t]] + w * (x[PA[t]] * y[PB[t]])
        # (every pair is kept here: no truncation term; and no rounding term: the bug)

    rng = np.random.default_rng(3)
    caught = 0
    for _ in range(20):
        x = _linear(*rng.uniform(-1e3, 1e3, 1), rng.uniform(-1e3, 1e3, M) / 3.0)
        y = _linear(*rng.uniform(-1e3, 1e3, 1), rng.uniform(-1e3, 1e3, M) / 7.0)
        w = float(rng.uniform(0.1, 10.0)) / 3.0
        T0 = _cancelling_start(x, y, w, float(rng.uniform(-1, 1)))
        exact = _exact_product(T0, x, y, w)
        T = T0.copy()
        product_without_rounding(T, x, y, w)
        caught += _excess(T, exact) > 0
        T = T0.copy()
        tm._acc_mul(T, x, y, PA, PB, PC, w)
        assert _excess(T, exact) <= 0
    assert caught > 0


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), k=st.integers(1, 6), lo=st.integers(1, 6), kind=st.integers(0, 3),
       fresh=st.booleans(), cancel=st.booleans(), scale=st.sampled_from([1e-3, 1.0, 1e3]))
def test_linear_order_convolution_contains_the_exact_sum(seed, k, lo, kind, fresh, cancel, scale):
    """``_conv_pre`` (a linear order's convolution, TaylorModelODE.linear_orders)
    against the exact sum of its products: the lower orders' models (j < lo) are whole,
    the others prefix-only; every product's pairs and the lower orders' quadratic parts
    times the centres are bounded into the remainder, and the rounding of the fused
    loops too, on inputs that cancel to rounding level."""
    rng = np.random.default_rng(seed)
    lo = min(lo, k)
    wa, wb, j0 = [(1.0, 0.0, 0), (-1.0, 0.0, 1), (0.0, 1.0, 1), (0.0, -1.0, 1)][kind]
    q0 = M + 1
    F = np.zeros((2, k + 1, 1, L))
    for s in range(2):
        for j in range(k + 1):
            F[s, j, 0, : M + 1] = rng.uniform(-1, 1, M + 1) * scale / 3.0
            if j < lo:  # a whole model: a quadratic block too
                F[s, j, 0, q0:E] = rng.uniform(-1, 1, E - q0) * scale / 7.0
            F[s, j, 0, E] = abs(rng.uniform(0, 1)) * scale * 1e-6
    LV = np.full(k + 1, q0, np.int64)
    HV = np.array([1 if j < lo else 0 for j in range(k + 1)], np.int64)
    C = np.full((2, k + 1, 1, 2), -1.0)
    terms = []
    for j in range(j0, k + 1):
        w = wa + wb * j
        x, y = F[0, j, 0], F[1, k - j, 0]
        terms.append((w, x, y))
    T0 = np.zeros(L)
    if cancel and not fresh:
        for w, x, y in terms:
            T0[: M + 1] -= w * x[0] * y[: M + 1] + w * y[0] * x[: M + 1]
            T0[0] += w * x[0] * y[0]
        T0[: M + 1] *= 1.0 + rng.uniform(-1e-9, 1e-9, M + 1)
    elif not fresh:
        T0[: M + 1] = rng.uniform(-1, 1, M + 1) * scale
    exact = [Fraction(v) for v in T0[:E]]
    for w, x, y in terms:
        # x y with both quadratic blocks: each block times the other's centre, the rest of
        # the products as pairs (their exact values; _excess counts what the model lacks)
        fw = Fraction(w)
        for a in list(range(M + 1)) + list(range(q0, E)):
            for b in list(range(M + 1)) + list(range(q0, E)):
                if x[a] == 0.0 or y[b] == 0.0:
                    continue
                p = fw * Fraction(x[a]) * Fraction(y[b])
                if a == 0:
                    exact[b] += p
                elif b == 0:
                    exact[a] += p
                else:  # a monomial of degree 2 or more: none kept, put in a slot the model has zero in
                    exact.append(p)
    T = T0.copy()
    tm._conv_pre(T, F, C, 0, 1, k, j0, k + 1, wa, wb, 0, LV, HV, q0, 1 if fresh else 0)
    dev = sum(abs(Fraction(T[i]) - exact[i]) for i in range(E)) + sum(abs(v) for v in exact[E:])
    assert dev - (Fraction(T[E]) - Fraction(T0[E])) <= 0


def test_the_convolution_oracle_bites_a_lost_block():
    """The convolution with the lower orders' blocks times the centres left out of the
    remainder is caught by the same check (a block-heavy, cancelling input)."""
    import inspect
    from numba import njit

    src = inspect.getsource(tm._conv_pre.py_func).split("\n", 1)[1]
    ns = dict(vars(tm))
    exec(src.replace("nl = _pm(sx, sy) * _UPF + swept + ", "nl = _pm(sx, sy) * _UPF + 0.0 + "), ns)
    broken = njit(ns["_conv_pre"])
    q0, k = M + 1, 3
    F = np.zeros((2, k + 1, 1, L))
    F[0, 0, 0, 0] = 1.0
    F[0, 0, 0, q0:E] = 0.5  # x_0: a centre and a quadratic block, no linear part
    F[1, k, 0, 0] = 4.0      # y_k: a large centre, nothing else
    LV = np.full(k + 1, q0, np.int64)
    HV = np.array([1, 0, 0, 0], np.int64)
    exact_dev = Fraction(4) * Fraction(0.5) * (E - q0)  # y_k0 x_0's block, all in the remainder
    for f, ok in ((tm._conv_pre, True), (broken, False)):
        T = np.zeros(L)
        f(T, F, np.full((2, k + 1, 1, 2), -1.0), 0, 1, k, 0, 1, 1.0, 0.0, 0, LV, HV, q0, 1)
        assert (Fraction(T[E]) >= exact_dev) == ok


def test_product_table_refuses_more_hits_than_the_rounding_bound_allows(monkeypatch):
    # every table the models use lands at most 14 pairs on one monomial (a quartic one)
    PA4, PB4, PC4 = tm.product_table(8, 8, 8, 8)
    assert np.bincount(PC4).max() <= tm._MAX_HITS
    tm.product_table.cache_clear()
    monkeypatch.setattr(tm, "_MAX_HITS", 2.0)
    with pytest.raises(ValueError, match="land on one monomial"):
        tm.product_table(4, 4, 4)
    tm.product_table.cache_clear()


def _poison_work(ev):
    bufs = getattr(ev, "_work_buffers", None) or (getattr(ev, "_work_buffer", None),)
    assert all(b is not None and b.size for b in bufs), "the kernel kept no work memory: nothing tested"
    for b in bufs:
        b[...] = np.nan


@pytest.mark.parametrize("make", [lambda g: TaylorModelODE(g, 12, 6, 4, 2), lambda g: AffineTaylorODE(g)],
                         ids=["models", "affine"])
def test_garbage_in_reused_work_memory_changes_nothing(make):
    _, arm = _arm()
    q = np.array([0.5, -0.3, 0.2, 0.1, -0.2, 0.3])
    graphs = [(arm, Interval(q - 0.01, q + 0.01), None)]
    g = trace(lambda x, p: all_ops((x[0], x[1]), p), 4, 1)  # every opcode, as a 4-state ODE
    x = np.array([0.4, -0.3, 0.2, 0.1])
    graphs.append((g, Interval(x - 0.05, x + 0.05), Interval(np.array([0.6]), np.array([0.8]))))
    for graph, box, params in graphs:
        # two boxes, one a point (one box alone takes the affine reference kernel, which keeps none)
        box = Interval(np.stack([box.lo, box.mid()]), np.stack([box.hi, box.mid()]))
        fresh = make(graph).coefficients(box, 6, params)
        ev = make(graph)
        ev.coefficients(Interval(box.lo - 0.1, box.hi + 0.1), 6, params)  # fills the work memory
        _poison_work(ev)
        again = ev.coefficients(box, 6, params)
        np.testing.assert_array_equal(again.lo, fresh.lo)
        np.testing.assert_array_equal(again.hi, fresh.hi)
        # the work memory is scratch: not pickled (a pickled evaluator computes the same)
        copy = pickle.loads(pickle.dumps(ev))
        assert not hasattr(copy, "_work_buffers") and not hasattr(copy, "_work_buffer")
        np.testing.assert_array_equal(copy.coefficients(box, 6, params).hi, fresh.hi)


# --------------------------------------------------------------------------- the affine kernel's product
# verified.series.affine_taylor._acc_mul (whose bits the batched kernel reproduces, test_affine_taylor)
# bounds its rounding from partial sums of magnitudes too. With y a constant form the product
# is linear, so rounding is all its error radius has to cover.

@settings(max_examples=150, deadline=None)
@given(cx=finite, lin=st.lists(finite, min_size=7, max_size=7), cy=finite,
       w=st.sampled_from([1.0, 2.0, -1.0, 3.0, 0.5]), jitter=st.floats(-1.0, 1.0), cancel=st.booleans())
def test_affine_product_contains_the_exact_product(cx, lin, cy, w, jitter, cancel):
    from verified.series import affine_taylor as at

    m = len(lin)
    x = np.array([cx] + lin + [0.0])
    y = np.zeros(m + 2)
    y[0] = cy
    T0 = np.zeros(m + 2)
    if cancel:
        T0[: m + 1] = -(w * (cy * x[: m + 1])) * (1.0 + jitter * 1e-9)
    exact = [Fraction(T0[i]) + Fraction(w) * Fraction(cy) * Fraction(x[i]) for i in range(m + 1)]
    T = T0.copy()
    at._acc_mul(T, x, y, m, w)
    dev = sum(abs(Fraction(T[i]) - exact[i]) for i in range(m + 1))
    assert dev <= Fraction(T[m + 1])

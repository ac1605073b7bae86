"""Taylor models of degree 2, 3 and 4 (verified.series.taylor_model) against exact arithmetic.

Oracle: the exact Taylor coefficients of the solution through points of the box (or of
the caller's forms), computed by python-flint ``arb_series`` at 256 bits with no
recurrence of ours (tests/oracles/arb_series.arb_taylor); containment is decided by
certain arb comparisons, no allowance. Tightness against Pinocchio's derivatives on the
3-link arm (the reason the models exist). The oracle bites: a kernel whose products
drop their truncation bound (degree 2, 3 and 4), a cubic or quartic expansion without
its Lagrange term, and a conversion that drops the remainder, fail.
"""

from __future__ import annotations

import inspect

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import verified.series.taylor_model as tm
from oracles.arb_graph import _program, box_samples, random_boxes
from oracles.arb_series import arb_precision, arb_taylor, check_affine_taylor, check_series_contains
from oracles.graph_models import all_ops
# the arm_pin fixture: tests/verified/conftest.py
from oracles.taylor_cases import ARM_Q0, CASES, _arm, _dp_graph, _program_ode, _radius, case_graph, random_forms
from verified.series.affine_taylor import AffineTaylorODE
from verified.graph import trace
from verified.arith.interval import Interval
from verified.series.taylor_model import TaylorModelODE, model_length, models_to_interval

# The whole module runs in the slow CI step: the kernel's first compile costs ~17 s cold, which
# the default run (3-minute budget) cannot carry; the tests themselves take ~6 s warm.
pytestmark = pytest.mark.slow

QUAD = [0, 1, 12]  # no quadratic monomials, one symbol's, all (up to 12)
CUBIC = [0, 1, 12]  # likewise cubic ones (capped by the quadratic symbols)
QUARTIC = [0, 1, 12]  # likewise quartic ones (capped by the cubic symbols)
STAR = [0, 1, 12]  # likewise star ones (capped by the quadratic symbols; none when all are quadratic)


def tm_coefficients(graph, lo, hi, order, plo=None, phi=None, quadratic_symbols=12, cubic_symbols=0,
                    quartic_symbols=0, star_symbols=0):
    params = None if not graph.n_params else Interval(np.asarray(plo, float), np.asarray(phi, float))
    ev = TaylorModelODE(graph, quadratic_symbols, cubic_symbols, quartic_symbols, star_symbols)
    C = ev.coefficients(Interval(np.asarray(lo, float), np.asarray(hi, float)), order, params)
    assert not (np.isnan(C.lo).any() or np.isnan(C.hi).any())
    assert (C.lo <= C.hi).all()
    return C


def check_tm(graph, lo, hi, order, plo=None, phi=None, *, quadratic_symbols=12, cubic_symbols=0,
             quartic_symbols=0, star_symbols=0, n_random=4, seed=0):
    """The model enclosures of x_[0..order] over each box contain the exact coefficients at
    its corners (n <= 6), centre and random points (with points of the parameter box)."""
    C = tm_coefficients(graph, np.atleast_2d(lo), np.atleast_2d(hi), order, plo, phi, quadratic_symbols,
                        cubic_symbols, quartic_symbols, star_symbols)
    return check_affine_taylor(graph, lo, hi, order, plo, phi, n_random=n_random, seed=seed, C=C)


def check_tm_series(graph, X, order, plo=None, phi=None, *, quadratic_symbols=12, cubic_symbols=0, n_random=6,
                    seed=0):
    """TaylorModelODE.series on caller forms X (n, B, m0 + 2), against the exact coefficients."""
    params = Interval(np.asarray(plo, float), np.asarray(phi, float)) if graph.n_params else None
    C = TaylorModelODE(graph, quadratic_symbols, cubic_symbols).series(X, order, params)
    return check_series_contains(graph, X, C, order, plo, phi, n_random=n_random, seed=seed)


def _pointwise_ode():
    """Two states through every unary expansion the solver's graphs use most (sin, cos,
    exp, sqrt, 1/x) and products."""
    return trace(lambda x, p: [np.sin(x[1]) * x[0] + np.cos(x[0] * x[1]),
                               np.exp(-x[0]) / (1.5 + x[0] * x[0]) + np.sqrt(2.0 + x[1])], 2)


def check_models_pointwise(graph, c, r, order, *, quadratic_symbols=12, cubic_symbols=0, quartic_symbols=0,
                           star_symbols=0, fresh=False, pool=0, pool_tol=0.0, pool_orders=1, n_points=12, seed=0,
                           product_orders=None, linear_orders=None):
    """The models themselves, not only their ranges: inputs ``c + r eps`` (one symbol per
    state, ``c`` and ``r`` dyadic), and at dyadic points ``eps`` (corners included) the exact
    coefficients (arb) must lie within the model's polynomial at ``eps`` (evaluated in arb)
    plus or minus its remainder. ``fresh``: ``n order`` fresh symbols follow (the
    coefficients' remainders move there, ``TaylorModelODE._run(fresh=True)``), whose
    values are unknown: their terms count as remainder. ``pool``: that many symbols
    before them for the remainders born inside the graph (``_run(pool=...)``), likewise.
    ``product_orders``: the evaluator's :attr:`TaylorModelODE.product_orders` (None: its default);
    ``linear_orders`` likewise."""
    from flint import arb

    c, r = np.asarray(c, float), np.asarray(r, float)
    n = m = c.size
    ev = TaylorModelODE(graph, quadratic_symbols, cubic_symbols, quartic_symbols, star_symbols)
    if product_orders is not None:
        ev.product_orders = product_orders
    if linear_orders is not None:
        ev.linear_orders = linear_orders
    mq, m3, m4, ms = ev.symbol_caps(m)
    ns = m - mq  # the star reaches the states' symbols, not the fresh ones
    mt = m + pool + (n * order if fresh else 0)
    X = np.zeros((n, 1, mt + 2))
    X[:, 0, 0] = c
    X[np.arange(n), 0, 1 + np.arange(n)] = r
    out = ev._run(tm.forms_to_models(X, mq, m3, m4, ms, ns), np.zeros((0, 1, model_length(mt, mq, m3, m4, ms, ns))),
                  order, mt, mq, m3, m4, ms, ns, fresh=fresh, pool=pool, pool_tol=pool_tol, pool_orders=pool_orders)
    pool_used = None
    if fresh or pool:
        # the fresh and pool symbols' coefficients join the remainder; the model without them
        held = np.abs(out[..., 1 + m: 1 + mt]).sum(axis=-1) * (1 + 2.0**-40) + out[..., -1]
        if fresh:
            assert out[:, 1:, :, -1].max() == 0.0  # (moved, not kept)
        pool_used = bool(np.abs(out[..., 1 + m: 1 + m + pool]).max() > 0) if pool else False
        out = np.concatenate([out[..., : 1 + m], out[..., 1 + mt:]], axis=-1)
        out[..., -1] = held
    pi, pj = tm._pairs(mq)
    si, sj = tm._star_pairs(m, mq, ms, ns)
    tri = tm._triples(m3)
    qua = tm._quads(m4)
    rng = np.random.default_rng(seed)
    for s in range(n_points):
        eps = rng.choice([-1.0, 1.0], m) if s % 2 == 0 else rng.integers(-8, 9, m) / 8.0
        x = c + r * eps  # exact: dyadic
        exact = arb_taylor(graph, x, None, order)
        with arb_precision(256):
            e = [arb(float(v)) for v in eps]
            mons = ([arb(1)] + e + [e[i] * e[j] for i, j in zip(pi, pj)]
                    + [e[i] * e[j] * e[k] for i, j, k in tri]
                    + [e[i] * e[j] * e[k] * e[l] for i, j, k, l in qua]
                    + [e[i] * e[j] for i, j in zip(si, sj)])
            for k in range(order + 1):
                for i in range(n):
                    coef = out[i, k, 0]
                    poly = sum((arb(float(a)) * mo for a, mo in zip(coef[:-1], mons)), arb(0))
                    assert abs(exact[k, i] - poly) <= arb(float(coef[-1])), (
                        f"x_[{k}][{i}] outside its model at eps {eps.tolist()}: exact {exact[k, i]}, "
                        f"polynomial {poly}, remainder {coef[-1]}")
    return pool_used if pool else None


# --------------------------------------------------------------------------- default run


def test_models_to_interval_covers_every_monomial_and_bites(monkeypatch):
    """The range of c + a eps + q_00 eps0^2 + q_01 eps0 eps1 + ... + [-e, e] over the
    symbols' box, against a dense grid (a diagonal coefficient moves one bound only);
    then a whole ODE, and the conversion without remainder must fail the arb check."""
    m, mq = 2, 2
    F = np.zeros(model_length(m, mq))
    F[0], F[1], F[2] = 0.5, 0.25, -0.125
    F[3:6] = [0.75, -0.5, -0.25]  # q00, q01, q11 (np.triu_indices order)
    F[-1] = 1e-3
    lo, hi = models_to_interval(F[None], m, mq)
    e = np.linspace(-1, 1, 201)
    E0, E1 = np.meshgrid(e, e)
    vals = F[0] + F[1] * E0 + F[2] * E1 + F[3] * E0**2 + F[4] * E0 * E1 + F[5] * E1**2
    assert lo[0] <= vals.min() - F[-1] and vals.max() + F[-1] <= hi[0]
    # termwise: +-(0.25 + 0.125) linear, +-0.5 for eps0 eps1, [0, 0.75] and [-0.25, 0] for the squares
    assert lo[0] == pytest.approx(0.5 - 0.375 - 0.5 - 0.25 - 1e-3, abs=1e-11)
    assert hi[0] == pytest.approx(0.5 + 0.375 + 0.5 + 0.75 + 1e-3, abs=1e-11)

    g = case_graph("sin")
    args = ([-1.0], [1.5], 6, [1.5], [2.0])
    check_tm(g, *args)
    real = tm.models_to_interval

    def no_remainder(F, m, mq):
        F = F.copy()
        F[..., -1] = 0.0
        return real(F, m, mq)

    monkeypatch.setattr(tm, "models_to_interval", no_remainder)
    with pytest.raises(AssertionError, match="outside"):
        check_tm(g, *args)


def test_three_link_arm_jacobian_tight_and_contains_exact(arm_pin):
    """The reason for the models: d qdd / dq of the 3-link arm over q0 +- 0.01 (qd = 0).
    Measured: sampled spread x 1.08-1.10 against 2.0-3.4 in affine arithmetic; required
    here: < 1.25 and < 0.6 x affine in every entry, exact values at the corners inside."""
    from verified.series.variational import variational_graph

    chain, g = _arm()
    vg = variational_graph(g)
    n = 6
    x0 = np.concatenate([ARM_Q0, np.zeros(3)])
    r = np.r_[[0.01] * 3, [0.0] * 3]
    lo = np.r_[x0 - r, np.eye(n).ravel()]
    hi = np.r_[x0 + r, np.eye(n).ravel()]
    C = TaylorModelODE(vg).coefficients(Interval(lo, hi)[None], 1)
    A = AffineTaylorODE(vg).coefficients(Interval(lo, hi)[None], 1)
    D_tm = C[0, 1, n:].width().reshape(n, n)[3:, :3]
    D_af = A[0, 1, n:].width().reshape(n, n)[3:, :3]
    # sampled spread of d qdd / dq: central differences of Pinocchio's aba
    qdd = arm_pin[2]
    rng = np.random.default_rng(0)
    pts = box_samples(np.atleast_2d(x0 - r), np.atleast_2d(x0 + r), 200, rng)[:, 0]
    step = 1e-6
    D = np.array([np.stack([(qdd(x[:3] + step * e, x[3:]) - qdd(x[:3] - step * e, x[3:])) / (2 * step)
                            for e in np.eye(3)], axis=1) for x in pts])
    spread = np.ptp(D, axis=0)
    assert (D_tm < 1.25 * spread).all(), (D_tm / spread)
    assert (D_tm < 0.6 * D_af).all(), (D_tm / D_af)
    # every sampled Jacobian inside (difference quotients: a 1e-5 allowance for their error)
    Dlo = C[0, 1, n:].lo.reshape(n, n)[3:, :3]
    Dhi = C[0, 1, n:].hi.reshape(n, n)[3:, :3]
    assert ((D >= Dlo - 1e-5) & (D <= Dhi + 1e-5)).all()


@pytest.mark.parametrize("quad", [1, 12])
def test_series_on_caller_forms_with_parameters(quad):
    """The solver's path: forms over a set's own symbols (more symbols than get quadratic
    monomials, in any order: the widest are picked), parameters without symbols."""
    rng = np.random.default_rng(21)
    check_tm_series(_dp_graph(), random_forms(4, 2, 8, rng), 5, quadratic_symbols=quad, seed=1)
    g = trace(lambda x, p: [-p[0] * x[0] + p[1] * np.sin(x[1]), x[0] * x[1]], 2, 2)
    check_tm_series(g, random_forms(2, 2, 3, np.random.default_rng(4), scale=0.3), 4, [0.8, -0.5], [1.2, 0.5],
                    quadratic_symbols=quad, n_random=8)


def test_all_ops_batch_with_interval_parameter():
    """Every opcode as a 4-state ODE, a batch of random boxes (some points), a parameter box."""
    g = trace(lambda x, p: all_ops((x[0], x[1]), p), 4, 1)
    rng = np.random.default_rng(5)
    lo, hi = random_boxes(4, 4, rng, center_scale=1.0, max_rad=0.1)
    check_tm(g, lo, hi, 5, [0.6], [0.8], n_random=2, seed=1)


def test_bad_arguments_are_clear_errors():
    g = trace(lambda x, p: [x[0] + x[1]], 2)
    with pytest.raises(ValueError, match="as many outputs as inputs"):
        TaylorModelODE(g)
    with pytest.raises(ValueError, match="quadratic_symbols"):
        TaylorModelODE(_dp_graph(), quadratic_symbols=-1)
    with pytest.raises(ValueError, match="cubic_symbols"):
        TaylorModelODE(_dp_graph(), cubic_symbols=-2)
    with pytest.raises(ValueError, match="quartic_symbols"):
        TaylorModelODE(_dp_graph(), quartic_symbols=-1)
    with pytest.raises(ValueError, match="cubic symbols <= quadratic symbols"):
        tm.product_table(4, 2, 3)
    with pytest.raises(ValueError, match="quartic symbols <= cubic symbols"):
        tm.product_table(4, 3, 2, 3)
    with pytest.raises(ValueError, match="order"):
        TaylorModelODE(_dp_graph()).coefficients(Interval(np.zeros(4), np.ones(4))[None], 0)
    with pytest.raises(ValueError, match="forms must have shape"):
        TaylorModelODE(_dp_graph()).series(np.zeros((3, 1, 4)), 2)


def test_domain_violation_and_nan_are_unbounded():
    """log over a box reaching 0 and a NaN input: the whole real line, never a finite wrong box."""
    g = trace(lambda x, p: [np.log(x[0])], 1)
    C = TaylorModelODE(g).coefficients(Interval(np.array([[-0.5]]), np.array([[0.5]])), 3)
    assert np.isinf(C.lo[0, 1:]).all() and np.isinf(C.hi[0, 1:]).all()
    X = np.zeros((4, 1, 4))
    X[0, 0, 0] = np.nan
    C = TaylorModelODE(_dp_graph()).series(X, 2)
    assert np.isneginf(C.lo[0, 1:]).any() and np.isposinf(C.hi[0, 1:]).any()


# --------------------------------------------------------------------------- sweeps


@pytest.mark.parametrize("name", [c[0] for c in CASES])
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_each_operation_contains_exact_coefficients(name, data):
    """x' = f(x, p) with one operation of interest, random box and parameter box, any order."""
    _, _, _, (clo, chi), xrad, (pclo, pchi), prad = next(c for c in CASES if c[0] == name)
    g = case_graph(name)
    c, r = data.draw(st.floats(clo, chi), "x centre"), data.draw(_radius(xrad), "x radius")
    pc, pr = data.draw(st.floats(pclo, pchi), "p centre"), data.draw(_radius(prad), "p radius")
    order = data.draw(st.integers(1, 8), "order")
    quad = data.draw(st.sampled_from(QUAD), "quadratic_symbols")
    cubic = data.draw(st.sampled_from(CUBIC), "cubic_symbols")
    quartic = data.draw(st.sampled_from(QUARTIC), "quartic_symbols")
    star = data.draw(st.sampled_from(STAR), "star_symbols")
    check_tm(g, [c - r], [c + r], order, [pc - pr], [pc + pr], quadratic_symbols=quad, cubic_symbols=cubic,
             quartic_symbols=quartic, star_symbols=star, n_random=3,
             seed=data.draw(st.integers(0, 2**32 - 1)))


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(program=_program, seed=st.integers(0, 2**32 - 1), order=st.integers(1, 6), quad=st.sampled_from(QUAD),
       cubic=st.sampled_from(CUBIC), quartic=st.sampled_from(QUARTIC), star=st.sampled_from(STAR))
def test_random_programs_contain_exact_coefficients(program, seed, order, quad, cubic, quartic, star):
    g = _program_ode(program)
    rng = np.random.default_rng(seed)
    lo, hi = random_boxes(2, 3, rng, center_scale=1.0, max_rad=0.2)
    check_tm(g, lo, hi, order, quadratic_symbols=quad, cubic_symbols=cubic, quartic_symbols=quartic,
             star_symbols=star, n_random=2, seed=seed)


@pytest.mark.parametrize("cubic, quartic", [(0, 0), (4, 0), (4, 4)])
@pytest.mark.parametrize("rad", [0.0, 1e-4, 1e-2, 0.1])
def test_double_pendulum_coefficients(rad, cubic, quartic):
    from models import double_pendulum as dp

    x0 = dp.initial_point()
    check_tm(_dp_graph(), np.stack([x0 - rad, dp.initial_box()[0]]), np.stack([x0 + rad, dp.initial_box()[1]]), 8,
             cubic_symbols=cubic, quartic_symbols=quartic, n_random=6, seed=int(rad * 1e9))


@pytest.mark.parametrize("cubic, quartic", [(0, 0), (3, 0), (6, 0), (6, 3)])
def test_three_link_arm_coefficients(cubic, quartic):
    """crba/rnea + preconditioned solve (6 states), order 5, box +-0.01 in q, 0.05 in qd."""
    _, g = _arm()
    x0 = np.concatenate([ARM_Q0, [0.1, -0.2, 0.3]])
    r = np.array([0.01] * 3 + [0.05] * 3)
    check_tm(g, x0 - r, x0 + r, 5, cubic_symbols=cubic, quartic_symbols=quartic, n_random=4, seed=3)


def test_degree_three_is_tighter_on_the_arm(arm_pin):
    """The reason for degree 3: over the 3-link arm's box q0 +- 0.05, qd +- 0.05, the
    enclosure of qdd (order-1 coefficient) against the sampled range (Pinocchio's aba).
    Measured: 1.30-1.33x the sampled width at degree 2, 1.10-1.13x at degree 3 (all six
    symbols cubic; the sampled width is itself a lower bound); required: degree 3 within
    1.2x, and at most half of degree 2's excess over the sampled width."""
    _, g = _arm()
    x0 = np.concatenate([ARM_Q0, np.zeros(3)])
    r = np.full(6, 0.05)
    box = Interval(x0 - r, x0 + r)[None]
    w2 = TaylorModelODE(g, 6, 0).coefficients(box, 1)[0, 1, 3:].width()
    C3 = TaylorModelODE(g, 6, 6).coefficients(box, 1)[0, 1, 3:]
    w3 = C3.width()
    qdd = arm_pin[2]
    pts = box_samples(np.atleast_2d(x0 - r), np.atleast_2d(x0 + r), 400, np.random.default_rng(2))[:, 0]
    vals = np.array([qdd(x[:3], x[3:]) for x in pts])
    sampled = np.ptp(vals, axis=0)
    assert ((C3.lo <= vals) & (vals <= C3.hi)).all()
    assert (w3 < 1.2 * sampled).all(), w3 / sampled
    assert (2.0 * (w3 - sampled) < w2 - sampled).all(), (w2 / sampled, w3 / sampled)


def _mutant_kernel(monkeypatch, func, cut, replacement):
    """Recompile ``func`` (a compiled helper, a rule ``_tm_*`` of the model table or the
    kernel's entry) with ``cut`` replaced, and everything that calls it, so the mutant is
    what runs: the helpers above the rules, every rule, registered for a table class of
    their own (the engine is compiled once per table class, with the rules it found then),
    and the entry :func:`_model_kernel` building that table."""
    from collections import namedtuple

    from numba import njit
    from verified.series import recursion

    def recompile(name, cut=None, replacement=None):
        f = getattr(tm, name)
        jitted = hasattr(f, "py_func")
        src = inspect.getsource(f.py_func if jitted else f)
        if jitted:
            src = src.split("\n", 1)[1]  # without the decorator
        if cut is not None:
            assert cut in src
            src = src.replace(cut, replacement)
        namespace = dict(vars(tm))
        exec(src, namespace)
        options = {k: v for k, v in getattr(f, "targetoptions", {}).items() if k != "nopython"}  # (its flags kept)
        monkeypatch.setattr(tm, name, njit(**options)(namespace[name]) if jitted else namespace[name])

    if func != "_model_kernel":
        recompile(func, cut, replacement)
    for caller in ("_unary_into", "_sqrconv", "_quotient_step", "_conv_pre", "_sqrconv_pre", "_quotient_step_pre",
                   "_quotient_rule"):  # (in the order they call each other)
        if caller != func:
            recompile(caller)
    for rule in recursion.RULES:
        if "_tm_" + rule != func:
            recompile("_tm_" + rule)
    table = namedtuple("MutantModelTable", tm.ModelTable._fields)
    recursion.register(table, **{rule: getattr(tm, "_tm_" + rule) for rule in recursion.RULES})
    monkeypatch.setattr(tm, "ModelTable", table)
    if func == "_model_kernel":
        recompile("_model_kernel", cut, replacement)
    else:
        recompile("_model_kernel")


@pytest.mark.parametrize("cubic, quartic", [(0, 0), (1, 0), (1, 1)])
def test_oracle_catches_a_product_without_its_truncation_bound(monkeypatch, cubic, quartic):
    """A kernel whose products drop the bound of the monomials past the model's degree
    (the ``dropped`` term of ``_acc_mul``) must fail the check, at degree 2, 3 and 4."""
    g = case_graph("mul")
    args = ([-1.2], [0.2], 5, [-0.9], [-0.4])
    check_tm(g, *args, cubic_symbols=cubic, quartic_symbols=quartic, n_random=6)
    _mutant_kernel(monkeypatch, "_acc_mul", "nl = dropped + ", "nl = 0.0 + ")
    with pytest.raises(AssertionError, match="outside"):
        check_tm(g, *args, cubic_symbols=cubic, quartic_symbols=quartic, n_random=6)


@pytest.mark.parametrize("quad, cubic, quartic, star", [(0, 0, 0, 0), (1, 0, 0, 0), (2, 0, 0, 0), (2, 1, 0, 0),
                                                         (2, 2, 0, 0), (2, 2, 1, 0), (2, 2, 2, 0), (1, 0, 0, 1),
                                                         (1, 1, 0, 1), (1, 1, 1, 1)])
@pytest.mark.parametrize("c, r", [([0.375, -0.25], [0.125, 0.25]), ([1.5, 0.5], [0.0625, 0.5])])
def test_models_contain_exact_coefficients_pointwise(c, r, quad, cubic, quartic, star):
    check_models_pointwise(_pointwise_ode(), c, r, 4, quadratic_symbols=quad, cubic_symbols=cubic,
                           quartic_symbols=quartic, star_symbols=star)


@pytest.mark.parametrize("quad, cubic, quartic, star", [(2, 0, 0, 0), (2, 2, 0, 0), (1, 1, 1, 1), (2, 2, 2, 0)])
@pytest.mark.parametrize("c, r", [([0.375, -0.25], [0.125, 0.25]), ([1.5, 0.5], [0.0625, 0.5])])
def test_models_with_fresh_symbols_contain_exact_coefficients_pointwise(c, r, quad, cubic, quartic, star):
    check_models_pointwise(_pointwise_ode(), c, r, 4, quadratic_symbols=quad, cubic_symbols=cubic,
                           quartic_symbols=quartic, star_symbols=star, fresh=True)


@pytest.mark.parametrize("quad, cubic, quartic, star", [(2, 0, 0, 0), (2, 2, 0, 0), (1, 1, 1, 1)])
@pytest.mark.parametrize("c, r", [([0.375, -0.25], [0.125, 0.25]), ([1.5, 0.5], [0.0625, 0.5])])
@pytest.mark.parametrize("pool, fresh, orders", [(3, False, 1), (20, True, 1), (40, True, 3), (12, False, 4)])
def test_models_with_pool_symbols_contain_exact_coefficients_pointwise(c, r, quad, cubic, quartic, star, pool, fresh,
                                                                        orders):
    """Remainders born inside the graph moved into symbols of their own (a pool of 3
    runs out; one of 20 does not), with and without the coefficients' fresh symbols, at
    order 0 only or at the first 3 / 4 orders of the recursion."""
    assert check_models_pointwise(_pointwise_ode(), c, r, 4, quadratic_symbols=quad, cubic_symbols=cubic,
                                  quartic_symbols=quartic, star_symbols=star, fresh=fresh, pool=pool,
                                  pool_orders=orders)


@pytest.mark.parametrize("quad, cubic, quartic, star", [(2, 0, 0, 0), (2, 2, 0, 0), (1, 1, 1, 1), (2, 2, 2, 0)])
@pytest.mark.parametrize("product_orders", [0, 1, 3])
@pytest.mark.parametrize("fresh", [False, True])
def test_models_without_products_at_high_orders_contain_exact_coefficients_pointwise(quad, cubic, quartic, star,
                                                                                     product_orders, fresh):
    """``TaylorModelODE.product_orders``: the orders from ``product_orders`` on keep no
    product of two non-constant monomials (each bounded into the remainder), at order 5,
    so that 2 to 5 of the orders run without them."""
    check_models_pointwise(_pointwise_ode(), [0.375, -0.25], [0.125, 0.25], 5, quadratic_symbols=quad,
                           cubic_symbols=cubic, quartic_symbols=quartic, star_symbols=star, fresh=fresh,
                           product_orders=product_orders)


def _pointwise_ode_more():
    """Two states through the operations :func:`_pointwise_ode` leaves out (log, tan,
    atan, squares, negation, a quotient of two states)."""
    return trace(lambda x, p: [np.log(2.0 + x[0] * x[1]) - x[1] ** 2 + np.tan(0.25 * x[0]),
                               -np.arctan(x[0]) + x[1] / (2.0 + x[0] ** 2)], 2)


@pytest.mark.parametrize("quad, cubic, quartic, star", [(2, 0, 0, 0), (2, 2, 0, 0), (1, 1, 1, 1), (2, 2, 2, 0)])
@pytest.mark.parametrize("product_orders", [1, 3])
@pytest.mark.parametrize("fresh, pool", [(False, 0), (True, 0), (True, 12)])
@pytest.mark.parametrize("ode", [_pointwise_ode, _pointwise_ode_more])
def test_linear_orders_contain_exact_coefficients_pointwise(quad, cubic, quartic, star, product_orders, fresh,
                                                                 pool, ode):
    """``TaylorModelODE.linear_orders``: the orders from ``product_orders`` on carry
    centre, linear part and remainder only (the lower orders' nonlinear blocks times the
    centres bounded into the remainder, ``x_[product_orders]``'s own block swept into it;
    with fresh symbols only the prefix of the orders so far is read), at order 6, with a
    pool handed out over the first 4 orders (past ``product_orders`` = 3 too)."""
    check_models_pointwise(ode(), [0.375, -0.25], [0.125, 0.25], 6, quadratic_symbols=quad, cubic_symbols=cubic,
                           quartic_symbols=quartic, star_symbols=star, fresh=fresh, pool=pool, pool_tol=0.0,
                           pool_orders=4 if pool else 1, product_orders=product_orders, linear_orders=product_orders)


@pytest.mark.parametrize("ode", [_pointwise_ode, _pointwise_ode_more])
def test_default_linear_orders_contain_exact_coefficients_pointwise(ode):
    """The shipped settings (products to order 5, linear from 6) at order 8 with fresh
    and pool symbols."""
    ev = TaylorModelODE(ode(), 2, 2)
    assert 0 <= ev.product_orders < ev.linear_orders < 8
    check_models_pointwise(ode(), [0.375, -0.25], [0.125, 0.25], 8, quadratic_symbols=2, cubic_symbols=2,
                           fresh=True, pool=12, pool_tol=0.0, pool_orders=3)


def _pointwise_ode_big_centres():
    """States whose high-order coefficients have large centres and no spread (x2' = 4
    x2 from a point) times models with nonlinear blocks (x0^2, 1 / (2 + x3^2), x3
    constant): the products' centre-times-block terms are not covered by any other
    bound, so a linear order that loses them fails."""
    return trace(lambda x, p: [-x[1], x[0] * x[0] * x[2], 4.0 * x[2], 0.0 * x[3], x[2] / (2.0 + x[3] * x[3])], 5)


@pytest.mark.parametrize("func, cut, replacement", [
    # the lower orders' blocks times the centres, lost in a convolution
    ("_conv_pre", "nl = _pm(sx, sy) * _UPF + swept + ", "nl = _pm(sx, sy) * _UPF + 0.0 + "),
    # ... in a product with the order-0 reciprocal (div, sqrt, log, atan)
    ("_acc_mul_pre", "nl = dropped + swept + ", "nl = dropped + 0.0 + "),
    # x_[product_orders]'s own block dropped, not swept into its remainder
    ("_sweep_nonlinear", "Y[E] = _up(Y[E] + s)", "Y[E] = _up(Y[E] + 0.0)"),
    # a prefix one order short: the newest fresh symbols' terms ignored
    ("_model_kernel", "min(q0, 1 + fresh0 + k * n)", "min(q0, 1 + fresh0 + (k - 1) * n)"),
])
def test_oracle_catches_linear_orders_that_lose_terms(monkeypatch, func, cut, replacement):
    """Each shortcut of the linear orders, broken so that a term is dropped without its
    bound in the remainder, must fail the pointwise check (the unbroken kernel passes),
    from product_orders 1 and 3."""
    args = (_pointwise_ode_big_centres(), [0.5, 0.25, 1.0, 0.5, 0.0], [0.25, 0.25, 0.0, 0.25, 0.0], 6)
    kw = dict(quadratic_symbols=5, cubic_symbols=2, fresh=True, linear_orders=0)
    for po in (1, 3):
        check_models_pointwise(*args, **kw, product_orders=po)
    _mutant_kernel(monkeypatch, func, cut, replacement)
    for po in (1, 3):
        with pytest.raises(AssertionError, match="outside its model"):
            check_models_pointwise(*args, **kw, product_orders=po)


def test_oracle_catches_high_orders_that_drop_products_without_their_bound(monkeypatch):
    """Products dropped at the orders past ``product_orders`` without their bound in the
    remainder (a product whose ``dropped`` term is lost) must fail the pointwise check;
    with every order truncated (0) and with the default."""
    args = (_pointwise_ode(), [0.375, -0.25], [0.125, 0.25], 5)
    for k in (0, 3):
        check_models_pointwise(*args, cubic_symbols=2, product_orders=k)
    _mutant_kernel(monkeypatch, "_acc_mul", "nl = dropped + ", "nl = 0.0 + ")
    for k in (0, 3):
        with pytest.raises(AssertionError, match="outside its model"):
            check_models_pointwise(*args, cubic_symbols=2, product_orders=k)


def test_oracle_catches_pool_symbols_that_lose_the_remainder(monkeypatch):
    """A kernel that clears a slot's remainder without moving it into its pool symbol
    must fail the pointwise check."""
    args = (_pointwise_ode(), [0.375, -0.25], [0.125, 0.25], 3)
    assert check_models_pointwise(*args, cubic_symbols=2, pool=8, pool_orders=3)
    _mutant_kernel(monkeypatch, "_tm_slot_done", "Z[1 + ar.pool0 + used[b]] = Z[E]",
                   "Z[1 + ar.pool0 + used[b]] = 0.0")
    with pytest.raises(AssertionError, match="outside its model"):
        check_models_pointwise(*args, cubic_symbols=2, pool=8, pool_orders=3)


def test_pool_symbols_tighten_the_arm_and_stay_clear_of_the_quadratic_ones():
    """On the 3-link arm's right-hand side over a set with more symbols than quadratic
    and cubic monomials (12 symbols, 4 quadratic, 2 cubic: the products past the caps
    are bounded where they arise), the pool's symbols make the qdd enclosure at least
    2x narrower (the cancellations downstream of where remainders are born are kept;
    measured 3.6 / 3.2 / 2.5x); a pool that would overlap the quadratic symbols is
    refused."""
    from models.planar import planar_chain
    from mbs.simulate import system_for

    g = system_for(planar_chain(3), "i").rhs
    n, m0, mq, m3 = 6, 12, 4, 2
    ev = TaylorModelODE(g, mq, m3, 0, 0)
    A = np.random.default_rng(0).normal(size=(n, m0)) * np.array([0.01] * 3 + [0.1] * 3)[:, None] / np.sqrt(m0)
    widths = []
    for pool in (0, 64):
        m = m0 + pool
        X = np.zeros((n, 1, m + 2))
        X[:, 0, 0] = [0.5, -0.3, 0.2, 0.0, 0.0, 0.0]
        X[:, 0, 1: m0 + 1] = A
        out = ev._run(tm.forms_to_models(X, mq, m3), np.zeros((0, 1, model_length(m, mq, m3))), 1, m, mq, m3,
                      pool=pool)
        lo, hi = tm.models_to_interval(out[3:, 1], m, mq)
        widths.append(hi - lo)
    assert (widths[1] < 0.5 * widths[0]).all(), widths
    with pytest.raises(ValueError, match="overlap"):
        ev._run(np.zeros((n, 1, model_length(8, 6, 6))), np.zeros((0, 1, model_length(8, 6, 6))), 1, 8, 6, 6,
                pool=4)


def test_oracle_catches_fresh_symbols_that_lose_the_remainder(monkeypatch):
    """A kernel that clears each coefficient's remainder without moving it into its fresh
    symbol must fail the pointwise check."""
    args = (_pointwise_ode(), [0.375, -0.25], [0.125, 0.25], 3)
    check_models_pointwise(*args, cubic_symbols=2, fresh=True)
    _mutant_kernel(monkeypatch, "_tm_integrate", "Y[1 + ar.fresh0 + k * n + i] = Y[E]",
                   "Y[1 + ar.fresh0 + k * n + i] = 0.0")
    with pytest.raises(AssertionError, match="outside its model"):
        check_models_pointwise(*args, cubic_symbols=2, fresh=True)


def test_oracle_catches_star_products_stored_in_the_wrong_monomial(monkeypatch):
    """A product table whose star pairs (eps_0 eps_1 with one quadratic symbol) are
    counted as kept but added to eps_0^2 instead must fail the pointwise check; with the
    star pairs dropped from the table (bounded, not kept) it passes."""
    args = (_pointwise_ode(), [0.375, -0.25], [0.125, 0.25], 3)
    check_models_pointwise(*args, quadratic_symbols=1, star_symbols=1)
    real = tm.product_table

    def wrong(m, mq, m3=0, m4=0, ms=0, ns=None):
        A, B, C = real(m, mq, m3, m4, ms, ns)
        C = np.where(C >= tm.star_base(m, mq, m3, m4), m + 1, C)  # into the first quadratic monomial
        return A, B, C

    monkeypatch.setattr(tm, "product_table", wrong)
    with pytest.raises(AssertionError, match="outside its model"):
        check_models_pointwise(*args, quadratic_symbols=1, star_symbols=1)


def test_oracle_catches_a_cubic_expansion_without_its_lagrange_term(monkeypatch):
    """The unary expansions at degree 3 without the bound of ``f3(xi)/6 d^3``'s spread
    must fail the pointwise check."""
    args = (_pointwise_ode(), [0.375, -0.25], [0.125, 0.25], 3)
    check_models_pointwise(*args, cubic_symbols=2)
    _mutant_kernel(monkeypatch, "_unary_into", "_pm(rl, _pm(W2, W))", "0.0")
    with pytest.raises(AssertionError, match="outside its model"):
        check_models_pointwise(*args, cubic_symbols=2)


def test_oracle_catches_a_quartic_expansion_without_its_lagrange_term(monkeypatch):
    """The unary expansions at degree 4 without the bound of ``f4(xi)/24 d^4``'s spread
    must fail the pointwise check (at a box where that spread is what the remainder needs:
    the cubic test's box passes without it, other bounds cover it there)."""
    args = (_pointwise_ode(), [1.5, 0.5], [0.25, 0.75], 2)
    check_models_pointwise(*args, cubic_symbols=2, quartic_symbols=2)
    _mutant_kernel(monkeypatch, "_unary_into", "_pm(rl, _pm(W3, W))", "0.0")
    with pytest.raises(AssertionError, match="outside its model"):
        check_models_pointwise(*args, cubic_symbols=2, quartic_symbols=2)


def test_degree_four_is_tighter_on_the_arm():
    """The reason for degree 4: the remainder of qdd over the 3-link arm's box q0 +- 0.05,
    qd +- 0.05 (the part bounded, not carried), all six symbols cubic, with and without
    four quartic symbols. Measured: 7.3-7.9x smaller (all six quartic: 15-16x); required:
    4x."""
    _, g = _arm()
    x0 = np.concatenate([ARM_Q0, np.zeros(3)])
    r = np.full(6, 0.05)
    X = np.zeros((6, 1, 8))
    X[:, 0, 0] = x0
    X[np.arange(6), 0, 1 + np.arange(6)] = r
    rem = {}
    for m4 in (0, 4):
        ev = TaylorModelODE(g, 6, 6, m4)
        out = ev._run(tm.forms_to_models(X, 6, 6, m4), np.zeros((0, 1, model_length(6, 6, 6, m4))), 1, 6, 6, 6, m4)
        rem[m4] = out[3:, 1, 0, -1]
    assert (4.0 * rem[4] < rem[0]).all(), rem[0] / rem[4]


def test_star_monomials_are_tighter_on_the_arm():
    """The reason for star monomials: the 3-link arm's right-hand side over six wide
    symbols (q0 +- 0.01, qd +- 0.05) and 30 narrow ones (1e-4 on every state, the shape
    of a set after absorbing its error), all wide symbols cubic: the remainder of qdd
    with the six wide symbols' star monomials against without. Measured 9.4x smaller
    (3 star symbols: 3.5x); required 4x."""
    _, g = _arm()
    rng = np.random.default_rng(0)
    m = 36
    X = np.zeros((6, 1, m + 2))
    X[:, 0, 0] = np.concatenate([ARM_Q0, np.zeros(3)])
    X[np.arange(6), 0, 1 + np.arange(6)] = [0.01] * 3 + [0.05] * 3
    X[:, 0, 7: m + 1] = rng.uniform(-1, 1, (6, 30)) * 1e-4
    rem = {}
    for ms in (0, 6):
        out = TaylorModelODE(g, 6, 6, 0, ms)._run(tm.forms_to_models(X, 6, 6, 0, ms),
                                                  np.zeros((0, 1, model_length(m, 6, 6, 0, ms))), 1, m, 6, 6, 0, ms)
        rem[ms] = out[3:, 1, 0, -1]
    assert (4.0 * rem[6] < rem[0]).all(), rem[0] / rem[6]


# --------------------------------------------------------------------------- solver level


def test_solver_taylor_model_arm_contains_pinocchio_trajectories(arm_pin):
    """solve(arithmetic="taylor_model"): the 3-link arm from q0 +- 1e-3, T = 0.3, absorbing
    errors: DOP853 trajectories with Pinocchio's aba inside every output box and the tube
    (measured: T = 0.44 s reached against 0.38 s with affine Jacobians, +- 1e-4: 1.73 s
    against 1.04 s)."""
    from oracles.sampling import misses, sample_initial_points, trajectories
    from verified.solver import VerifiedODE, solve

    chain, g, qdd = arm_pin
    ode = VerifiedODE(g, "taylor_model")
    assert isinstance(ode.variational, TaylorModelODE) and isinstance(ode.second_variational_over_set, TaylorModelODE)
    x0 = np.concatenate([ARM_Q0, np.zeros(3)])
    r = np.array([1e-3] * 3 + [0.0] * 3)
    lo, hi = x0 - r, x0 + r
    T = 0.3
    sol = solve(ode, Interval(lo, hi), (0.0, T), absorb=True, t_eval=np.linspace(0, T, 7), order=8, tol=1e-10)
    assert sol.success, sol.reason

    def f(x):
        return np.concatenate([x[3:], qdd(x[:3], x[3:])])

    sols = trajectories(f, np.unique(sample_initial_points(lo, hi, 12), axis=0), T)
    assert misses(sol, sols, per_step=2) == []

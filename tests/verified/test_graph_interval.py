"""Soundness of interval evaluation of graphs: enclosures contain sampled values.

Two oracles:

* float samples: ``graph.eval_float`` at box corners, the center and random points must
  lie in ``graph.eval_interval(box)`` (with a tiny allowance for the float reference's
  own rounding error, far below any real bug);
* exact samples: the same points evaluated in python-flint ``arb`` at 256 bits through
  a test-only :class:`ArbDomain` (tests/oracles/arb_graph.py, which also shows that
  evaluators are pluggable); containment is checked with certain comparisons, no
  allowance. Constants are taken at their double value, a point of their enclosure, so
  by inclusion isotonicity the interval result must contain the arb result; that
  constants' enclosures contain the exact constants is tested in test_graph.py.
"""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from oracles.arb_graph import (_program, assert_encloses_float, box_samples, check_graph_enclosure, random_boxes,
                               run_program)
from oracles.graph_models import all_ops, double_pendulum_rhs, generic_model, pendulum_energy
from verified.graph import evaluate as ev
from verified.graph import trace
from verified.arith.interval import Interval

GRAPHS = {
    "double_pendulum": (trace(lambda x, p: double_pendulum_rhs(x), 4), None),
    "energy": (trace(pendulum_energy, 2, 3), np.array([1.0, 1.0, 9.81])),
    "all_ops": (trace(all_ops, 2, 1), np.array([0.7])),
}


# --------------------------------------------------------------------------- tests


def _box_strategy(n):
    center = st.lists(st.floats(-2.5, 2.5), min_size=n, max_size=n)
    rad = st.lists(st.floats(0.0, 0.4), min_size=n, max_size=n)
    return st.tuples(center, rad)


@pytest.mark.parametrize("name", sorted(GRAPHS))
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_interval_eval_contains_float_samples(name, data):
    graph, P = GRAPHS[name]
    center, rad = data.draw(_box_strategy(graph.n_inputs))
    c, r = np.array(center), np.array(rad)
    lo, hi = (c - r)[None], (c + r)[None]
    check_graph_enclosure(graph, lo, hi, P, n_random=16, rng=np.random.default_rng(data.draw(st.integers(0, 2**32 - 1))))


@pytest.mark.parametrize("name", sorted(GRAPHS))
def test_interval_eval_contains_exact_samples(name):
    graph, P = GRAPHS[name]
    rng = np.random.default_rng(7)
    lo, hi = random_boxes(graph.n_inputs, 6, rng)
    check_graph_enclosure(graph, lo, hi, P, n_random=4, rng=rng, exact=True)


@pytest.mark.parametrize("name", sorted(GRAPHS))
def test_interval_jacobian_contains_sampled_jacobians(name):
    graph, P = GRAPHS[name]
    rng = np.random.default_rng(11)
    lo, hi = random_boxes(graph.n_inputs, 20, rng)
    check_graph_enclosure(graph, lo, hi, P, n_random=8, rng=rng, jacobian=True)
    lo, hi = random_boxes(graph.n_inputs, 4, rng)
    check_graph_enclosure(graph, lo, hi, P, n_random=2, rng=rng, jacobian=True, exact=True)


def test_double_pendulum_paper_initial_box():
    """RHS and Jacobian enclosures over the paper's initial box, eq. (25)."""
    graph = GRAPHS["double_pendulum"][0]
    lo = np.array([[0.99 * 3 * np.pi / 4, -11 * np.pi / 20, 0.43, 0.67]])
    hi = np.array([[1.01 * 3 * np.pi / 4, -11 * np.pi / 20, 0.43, 0.67]])
    check_graph_enclosure(graph, lo, hi, n_random=200)
    check_graph_enclosure(graph, lo, hi, n_random=20, exact=True)
    check_graph_enclosure(graph, lo, hi, n_random=50, jacobian=True)
    Y = graph.eval_interval(Interval(lo, hi))
    assert np.all(np.isfinite(Y.lo)) and np.all(Y.width() < 1.0)  # the factored determinant keeps it tight


def test_interval_eval_with_interval_params_contains_samples():
    graph = GRAPHS["energy"][0]
    rng = np.random.default_rng(3)
    X = Interval(np.array([[2.1, 3.1]]), np.array([[2.2, 3.2]]))
    Pbox = Interval(np.array([0.9, 0.95, 9.8]), np.array([1.1, 1.05, 9.82]))
    Y = graph.eval_interval(X, Pbox)
    xs = box_samples(X.lo, X.hi, 20, rng)[:, 0]  # (S, 2)
    ps = box_samples(Pbox.lo[None], Pbox.hi[None], 20, rng)[:, 0]  # (S', 3)
    y = graph.eval_float(xs[:, None, :], ps[None, :, :])  # (S, S', 1)
    assert_encloses_float(Y[0], y)


def test_generic_code_on_intervals_matches_graph():
    """Model code run directly on Intervals and the traced graph give identical enclosures."""
    graph = trace(lambda v, p: generic_model(v[0], p[0], p[1], v[1]), 2, 2)
    q, x = Interval(np.array([0.1, -1.0]), np.array([0.3, 1.0])), Interval(np.array([2.0, 0.5]), np.array([2.5, 0.6]))
    direct = generic_model(q, 2.0, 3.0, x)
    box = Interval(np.stack([q.lo, x.lo], -1), np.stack([q.hi, x.hi], -1))
    via_graph = graph.eval_interval(box, [2.0, 3.0])
    np.testing.assert_array_equal(via_graph.lo[:, 0], direct.lo)
    np.testing.assert_array_equal(via_graph.hi[:, 0], direct.hi)


def test_point_boxes_are_tight():
    graph = GRAPHS["double_pendulum"][0]
    X = np.random.default_rng(5).uniform(-2, 2, size=(50, 4))
    Y = graph.eval_interval(X)  # floats -> point intervals
    y = graph.eval_float(X)
    assert_encloses_float(Y, y)
    assert np.all(Y.width() <= 1e-12 * (1 + np.abs(y)))


def test_sqr_node_is_tight():
    graph = trace(lambda x, p: x[0] * x[0], 1)
    Y = graph.eval_interval(Interval(np.array([[-1.0]]), np.array([[2.0]])))
    assert Y.lo[0, 0] == 0.0 and 4.0 <= Y.hi[0, 0] <= np.nextafter(4.0, 5.0)  # x*x would give [-2, 4]


def test_interval_input_errors():
    graph = GRAPHS["energy"][0]
    with pytest.raises(ValueError, match="NaN"):
        graph.eval_interval(np.array([[np.nan, 1.0]]), [1.0, 1.0, 9.81])
    with pytest.raises(ValueError, match=r"got shape \(1, 3\)"):
        graph.eval_interval(Interval(np.zeros((1, 3))), [1.0, 1.0, 9.81])
    with pytest.raises(ValueError, match=r"p must have shape \(\.\.\., 3\)"):
        graph.jacobian_interval(Interval(np.zeros((1, 2))), Interval(np.zeros(2)))


# --------------------------------------------------------------------------- the oracle bites


def test_containment_oracles_catch_an_unsound_sin(monkeypatch):
    """A sin that returns the float sin of the midpoint (no enclosure) must be caught."""
    graph = trace(lambda x, p: [np.sin(x[0]) * x[1] + x[1]], 2)
    rng = np.random.default_rng(1)
    lo, hi = random_boxes(2, 10, rng, max_rad=0.2)
    check_graph_enclosure(graph, lo, hi)  # sound evaluator passes
    check_graph_enclosure(graph, lo, hi, exact=True)

    def midpoint_sin(self, a):
        return Interval(np.sin(a.mid()))

    monkeypatch.setattr(ev.IntervalDomain, "sin", midpoint_sin)
    with pytest.raises(AssertionError, match="outside"):
        check_graph_enclosure(graph, lo, hi)
    with pytest.raises(AssertionError, match="outside"):
        check_graph_enclosure(graph, lo, hi, exact=True)
    with pytest.raises(AssertionError, match="outside"):
        check_graph_enclosure(graph, lo, hi, jacobian=True)


def test_containment_oracle_catches_a_wrong_derivative_rule(monkeypatch):
    """d/dx cos = +sin (sign error) in the dual domain must be caught."""
    graph = trace(lambda x, p: [np.cos(x[0]) * x[1]], 2)
    rng = np.random.default_rng(2)
    lo, hi = random_boxes(2, 10, rng, center_scale=1.0, max_rad=0.1)
    lo[:, 0], hi[:, 0] = lo[:, 0] + 1.0, hi[:, 0] + 1.0  # sin(x) > 0 there

    def bad_cos(self, a):
        B = self.base
        return (B.cos(a[0]), None if a[1] is None else self._scale(B.sin(a[0]), a[1]))

    check_graph_enclosure(graph, lo, hi, jacobian=True)
    monkeypatch.setattr(ev.DualDomain, "cos", bad_cos)
    with pytest.raises(AssertionError, match="outside"):
        check_graph_enclosure(graph, lo, hi, jacobian=True)


# (a CI run found it: a subexpression of constants, pow3 of it, was computed with
# numpy's scalar kernel in the graph and with its array (SIMD) kernel in the model code,
# 1 ulp apart; eval_float now computes constants as arrays of the batch's shape)
@example(program=[("sub", 0, 0, 0), ("expsin", 0, 0, 0), ("add", 0, 0, 0), ("add", 0, 0, 0), ("add", 0, 0, 0),
                  ("add", 0, 0, 0), ("sin", 4, 0, 0), ("add", 0, 0, 0), ("add", 0, 0, 0), ("add", 0, 0, 0),
                  ("add", 0, 0, 0), ("sub", 0, 0, 0), ("expsin", 0, 0, 0), ("sub", 0, 6, 0), ("pow3", 0, 0, 0)],
         seed=0)
@settings(max_examples=300, deadline=None)
@given(program=_program, seed=st.integers(0, 2**32 - 1))
def test_random_programs_float_exact_and_interval_sound(program, seed):
    """Build-time simplifications are exact: the graph's float evaluation is bit-identical
    to running the same code on numpy arrays; interval evaluation contains the samples."""
    graph = trace(lambda x, p: run_program(program, x[0], x[1]), 2)
    rng = np.random.default_rng(seed)
    X = rng.uniform(-1.5, 1.5, size=(64, 2))
    want = np.array([np.broadcast_to(v, (64,)) for v in run_program(program, X[:, 0], X[:, 1])]).T
    assert want.shape == (64, graph.n_outputs)
    np.testing.assert_array_equal(graph.eval_float(X), want)
    lo, hi = random_boxes(2, 4, rng, center_scale=1.0, max_rad=0.2)
    check_graph_enclosure(graph, lo, hi, n_random=8, rng=rng)

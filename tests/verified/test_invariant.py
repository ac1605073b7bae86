"""The rigorous pieces of verified.consistency.invariant on their own: the positive-definiteness
margin of interval matrices, the ratio bound of two quadratic forms and the second-order
upper bound of a function over an affine set, against sampled members / points."""
import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from verified.consistency import invariant as inv
from verified.graph import trace
from verified.arith.interval import Interval
from verified.sets.first_order import DoubletonSets


def _members(m, r, count, rng):
    for _ in range(count):
        d = rng.uniform(-1.0, 1.0, m.shape) * r
        yield m + 0.5 * (d + d.T)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 10_000), st.integers(2, 6), st.floats(1e-4, 0.5), st.floats(0.5, 3.0))
def test_psd_margin_holds_for_every_member(seed, k, rel, spread):
    """Badly scaled SPD midpoints (diagonal over 10^spread) with entrywise radii: where a
    margin is claimed, every sampled member has lambda_min(D S D) >= margin."""
    rng = np.random.default_rng(seed)
    G = rng.normal(size=(k, k))
    s = 10.0 ** rng.uniform(-spread, spread, k)
    m = (G @ G.T + k * np.eye(k)) * s[:, None] * s[None, :]
    r = rel * np.abs(m) * rng.uniform(0, 1, (k, k))
    r = np.maximum(r, r.T)
    got = inv._psd_margin(m, r)
    if got is None:
        return
    d2, margin, rho = got
    d = np.sqrt(d2)
    for S in _members(m, r, 30, rng):
        assert np.linalg.eigvalsh(S * d[:, None] * d[None, :])[0] >= margin * (1 - 1e-9)


def test_psd_margin_without_the_radius_is_caught():
    """Mutant: a margin that ignores the radius claims positive definiteness for an
    interval matrix with indefinite members."""
    m = np.array([[1.0, 0.9], [0.9, 1.0]])
    r = np.full((2, 2), 0.2)
    assert inv._psd_margin(m, r) is None
    d2, margin, _ = inv._psd_margin(m, 0 * r)  # the broken version
    S = np.array([[1.0, 1.1], [1.1, 1.0]])      # a member: eigenvalue -0.1
    d = np.sqrt(d2)
    assert np.linalg.eigvalsh(S * d[:, None] * d[None, :])[0] < margin


def test_max_ratio_bounds_the_quadratic_forms():
    rng = np.random.default_rng(0)
    for _ in range(20):
        A, B = rng.normal(size=(2, 5, 5))
        p_hi, p_low = A @ A.T + 0.1 * np.eye(5), B @ B.T + 0.5 * np.eye(5)
        mu = inv._max_ratio(p_hi, p_low)
        y = rng.normal(size=(200, 5))
        ratio = np.einsum("si,ij,sj->s", y, p_hi, y) / np.einsum("si,ij,sj->s", y, p_low, y)
        assert ratio.max() <= mu


def _set(rng, n=3, m=3):
    c = rng.normal(size=(1, n))
    C = rng.normal(size=(1, n, m)) * 0.2
    r0 = Interval(-np.full((1, m), 0.3), np.full((1, m), 0.3))
    Q = np.eye(n)[None] * 0.1
    r = Interval(-np.full((1, n), 0.05), np.full((1, n), 0.02))
    return DoubletonSets(c=c, C=C, r0=r0, Q=Q, r=r)


def test_second_order_upper_bound_holds_and_a_dropped_hessian_is_caught():
    """``g(x) = sum x_i^2 + sin(x_0 x_1)`` over random affine sets: the bound is above
    every sampled value; without its Hessian term (a mutant) it is below some."""
    g = trace(lambda x, p: [x[0] * x[0] + x[1] * x[1] + x[2] * x[2] + (x[0] * x[1]).sin()], 3)
    grad = inv.gradient_graph(g)
    rng = np.random.default_rng(1)
    caught = False
    for _ in range(10):
        S = _set(rng)
        A = np.concatenate([S.C, S.Q], axis=2)
        R = Interval(np.concatenate([S.r0.lo, S.r.lo], axis=1), np.concatenate([S.r0.hi, S.r.hi], axis=1))
        ub = inv._second_order_upper(g, grad, S.c, A, R)[0]
        pts = rng.uniform(R.lo[0], R.hi[0], (2000, A.shape[2]))
        pts[:64] = np.where(rng.random((64, A.shape[2])) < 0.5, R.lo[0], R.hi[0])
        X = S.c[0] + pts @ A[0].T
        vals = (X ** 2).sum(axis=1) + np.sin(X[:, 0] * X[:, 1])
        assert vals.max() <= ub
        # the mutant: first order at the centre only
        from verified.graph.evaluate import eval_interval
        C = Interval(S.c)
        first = (eval_interval(g, C)[:, 0] + (inv.linalg.matmul(eval_interval(grad, C).reshape(1, 1, 3), A)
                                             .reshape(1, -1) * R).sum(axis=-1)).hi[0]
        caught |= vals.max() > first
    assert caught

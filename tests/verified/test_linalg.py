"""Interval matrix products and the verified linear solve."""

import flint
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from verified.arith.interval import Interval
from verified.arith.linalg import SingularMatrixError, matmul, matvec, solve


def random_interval_matrix(rng, shape, radius):
    mid = rng.uniform(-1, 1, shape)
    rad = rng.uniform(0, radius, shape)
    return Interval(mid - rad, mid + rad)


def samples_inside(rng, x, count):
    """Float points inside Interval ``x``: its corners' extremes plus uniform samples."""
    t = rng.uniform(0, 1, (count,) + x.shape)
    t[0] = 0.0
    t[1] = 1.0
    return x.lo + t * (x.hi - x.lo)


def test_matmul_contains_sampled_products_and_matches_arb_for_points():
    rng = np.random.default_rng(0)
    a = random_interval_matrix(rng, (5, 3, 4), 0.1)
    b = random_interval_matrix(rng, (5, 4, 2), 0.1)
    c = a @ b
    assert c.shape == (5, 3, 2)
    for pa, pb in zip(samples_inside(rng, a, 50), samples_inside(rng, b, 50)):
        assert c.contains(pa @ pb).all()
    # point matrices: the result must contain arb's exact product
    pa = rng.uniform(-1, 1, (3, 4))
    pb = rng.uniform(-1, 1, (4, 2))
    c = matmul(Interval(pa), Interval(pb))
    exact = flint.arb_mat(pa.tolist()) * flint.arb_mat(pb.tolist())
    for i in range(3):
        for j in range(2):
            assert bool(flint.arb(c.lo[i, j]) <= exact[i, j]) and bool(flint.arb(c.hi[i, j]) >= exact[i, j])


def test_matvec_batches_and_broadcasts():
    rng = np.random.default_rng(1)
    a = random_interval_matrix(rng, (3, 3), 0.01)  # one matrix for a batch of vectors
    x = random_interval_matrix(rng, (7, 3), 0.01)
    y = matvec(a, x)
    assert y.shape == (7, 3)
    for pa, px in zip(samples_inside(rng, a, 30), samples_inside(rng, x, 30)):
        assert y.contains(np.einsum("ij,bj->bi", pa, px)).all()


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 6), st.floats(0.0, 0.02), st.integers(0, 2**31))
def test_solve_contains_all_sampled_solutions(n, radius, seed):
    rng = np.random.default_rng(seed)
    mid = rng.uniform(-1, 1, (4, n, n)) + 3 * np.eye(n)  # well conditioned
    a = Interval(mid - radius, mid + radius)
    b = random_interval_matrix(rng, (4, n), radius)
    x = solve(a, b)
    assert x.shape == (4, n)
    for pa, pb in zip(samples_inside(rng, a, 40), samples_inside(rng, b, 40)):
        # (LAPACK's float solution is itself off by a few ulps: at a corner sample the exact
        # solution is on the enclosure's edge, n = 1, radius 0.0078, seed 882 fell 1 ulp out)
        v = np.linalg.solve(pa, pb[..., None])[..., 0]
        slack = 8 * np.spacing(np.abs(v))
        assert ((x.lo <= v + slack) & (v - slack <= x.hi)).all()


def test_solve_contains_arb_solution_and_is_tight_for_point_systems():
    rng = np.random.default_rng(3)
    for n in (2, 4, 7):
        a = rng.uniform(-1, 1, (n, n)) + 2 * np.eye(n)
        b = rng.uniform(-1, 1, n)
        x = solve(Interval(a), Interval(b))
        exact = flint.arb_mat(a.tolist()).solve(flint.arb_mat([[v] for v in b]))
        for i in range(n):
            assert bool(flint.arb(x.lo[i]) <= exact[i, 0]) and bool(flint.arb(x.hi[i]) >= exact[i, 0])
        assert (x.width() < 1e-13).all()


def test_solve_mass_matrix_of_double_pendulum_over_a_box():
    # M(q) of the paper's double pendulum in relative coordinates (DESIGN.md).
    q2 = Interval(-1.8, -1.7)
    c = np.cos(q2)
    m11 = 3.0 + 2.0 * c
    m12 = 1.0 + c
    M = Interval(np.zeros((2, 2)))
    M[0, 0] = m11
    M[0, 1] = m12
    M[1, 0] = m12
    M[1, 1] = Interval(1.0)
    rhs = Interval([1.0, -2.0])
    x = solve(M, rhs)
    for t in np.linspace(-1.8, -1.7, 21):
        cm = np.cos(t)
        pm = np.array([[3 + 2 * cm, 1 + cm], [1 + cm, 1.0]])
        assert x.contains(np.linalg.solve(pm, [1.0, -2.0])).all()


def test_singular_matrix_raises_clear_error_or_gives_entire():
    a = Interval(np.array([[[1.0, 2.0], [2.0, 4.0]], [[2.0, 0.0], [0.0, 2.0]]]))
    b = Interval(np.ones((2, 2)))
    with pytest.raises(SingularMatrixError, match=r"1 of 2 .*batch indices \[\(0,\)\]"):
        solve(a, b)
    x = solve(a, b, on_failure="entire")
    assert np.isinf(x.lo[0]).all() and np.isinf(x.hi[0]).all()
    assert np.allclose(x.mid()[1], 0.5)
    # an interval matrix that contains a singular matrix
    wide = Interval([[0.5, 1.0], [1.0, 0.5]], [[1.5, 1.0], [1.0, 1.5]])
    with pytest.raises(SingularMatrixError):
        solve(wide, Interval([1.0, 1.0]))


def test_shape_errors_are_clear():
    with pytest.raises(ValueError, match="square"):
        solve(Interval(np.ones((2, 3))), Interval(np.ones(2)))
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 2\)"):
        solve(Interval(np.eye(2)), Interval(np.ones(3)))
    with pytest.raises(ValueError, match="align"):
        matmul(Interval(np.ones((2, 3))), Interval(np.ones((2, 3))))


def test_inverse_diagonal_encloses_every_member():
    from verified.arith.linalg import inverse_diagonal
    rng = np.random.default_rng(2)
    G = rng.normal(size=(4, 3, 3))
    mid = G @ G.transpose(0, 2, 1) + 3 * np.eye(3)
    box = Interval(mid - 0.05, mid + 0.05)
    d = inverse_diagonal(box)
    assert d.shape == (4, 3)
    for _ in range(50):
        M = mid + rng.uniform(-0.05, 0.05, mid.shape)
        assert (d.lo <= np.diagonal(np.linalg.inv(M), axis1=1, axis2=2)).all()
        assert (np.diagonal(np.linalg.inv(M), axis1=1, axis2=2) <= d.hi).all()
    assert not np.isfinite(inverse_diagonal(np.zeros((2, 2))).hi).any()   # singular: entire

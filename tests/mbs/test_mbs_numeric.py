"""Numeric (SMARTMOBILE-like) model over floats, batches, intervals and tracers."""
import numpy as np
import pytest

from mbs.numeric import ldl_solve
from models import planar, puma560, robots


@pytest.fixture(scope="module")
def ur5():
    return robots.ur5()


def test_batch_equals_loop(ur5):
    num = ur5.numeric()
    rng = np.random.default_rng(0)
    Q, QD, TAU = (rng.normal(size=(6, 5)) for _ in range(3))
    A = num.acceleration(Q, QD, TAU)
    M = num.mass_matrix(Q)
    K = num.kinetic_energy(Q, QD)
    assert A.shape == (6, 5) and M.shape == (6, 6, 5) and K.shape == (5,)
    for b in range(5):
        assert np.allclose(A[:, b], num.acceleration(Q[:, b], QD[:, b], TAU[:, b]), atol=1e-12)
        assert np.allclose(M[:, :, b], num.mass_matrix(Q[:, b]), atol=1e-14)


def test_intervals_enclose_floats(ur5):
    from verified.arith.interval import Interval
    num = ur5.numeric()
    rng = np.random.default_rng(1)
    q, qd = rng.normal(size=6), rng.normal(size=6)
    qi = [Interval(v - 1e-6, v + 1e-6) for v in q]
    qdi = [Interval(v - 1e-6, v + 1e-6) for v in qd]
    for dq in (np.zeros(6), rng.uniform(-1e-6, 1e-6, 6)):
        af = num.acceleration(q + dq, qd)
        ai = num.acceleration(qi, qdi)
        assert all(bool(a.contains(f)) for a, f in zip(ai, af))
        Hi = num.hamiltonian(qi, qdi)
        assert bool(Hi.contains(num.hamiltonian(q + dq, qd)))


def test_traced_graphs(ur5):
    num = ur5.numeric()
    g, e = num.rhs_graph(), num.energy_graph()
    x = np.random.default_rng(2).normal(size=12)
    assert np.allclose(g.eval_float(x), num.rhs(x), rtol=1e-13, atol=1e-13)
    assert e.eval_float(x)[0] == pytest.approx(num.hamiltonian(x[:6], x[6:]), rel=1e-14)


def test_ldl_solve():
    rng = np.random.default_rng(3)
    A = rng.normal(size=(6, 6))
    M = A @ A.T + 6 * np.eye(6)
    b = rng.normal(size=6)
    x = ldl_solve(M.tolist(), list(b))
    assert np.allclose(x, np.linalg.solve(M, b), atol=1e-13)


def test_kinetic_energy_is_quadratic_form(ur5):
    num = ur5.numeric()
    rng = np.random.default_rng(4)
    q, qd = rng.normal(size=6), rng.normal(size=6)
    assert num.kinetic_energy(q, qd) == pytest.approx(0.5 * qd @ num.mass_matrix(q) @ qd, rel=1e-13)


def test_gravity_is_gradient_of_potential(ur5):
    num = ur5.numeric()
    q = np.random.default_rng(5).normal(size=6)
    h = 1e-6
    grad = [(num.potential_energy(q + h * e) - num.potential_energy(q - h * e)) / (2 * h)
            for e in np.eye(6)]
    assert np.allclose(num.gravity_torque(q), grad, atol=1e-7)


def test_energy_balance_along_motion():
    """dH/dt along the ODE (finite differences) equals qd^T (tau - D qd), eq. (7)."""
    chain = planar.planar_chain(3, damping=[0.3, 0.1, 0.2])
    num = chain.numeric()
    rng = np.random.default_rng(6)
    x, tau = rng.normal(size=6), rng.normal(size=3)
    f = np.asarray(num.rhs(x, tau))
    h = 1e-6
    H = lambda y: num.hamiltonian(y[:3], y[3:])
    dH = (H(x + h * f) - H(x - h * f)) / (2 * h)
    assert dH == pytest.approx(num.energy_rate(x[:3], x[3:], tau), rel=1e-6)


def test_rnea_inverts_acceleration():
    chain = puma560.puma560()
    num = chain.numeric()
    rng = np.random.default_rng(7)
    q, qd, tau = rng.normal(size=6), rng.normal(size=6), rng.normal(size=6)
    qdd = num.acceleration(q, qd, tau)
    assert np.allclose(num.rnea(q, qd, qdd), tau, atol=1e-12)


def test_interval_batch_arrays(ur5):
    """x as one Interval array of shape (2n, B): each row is a batch of intervals."""
    from verified.arith.interval import Interval
    num = ur5.numeric()
    x = np.random.default_rng(8).normal(size=(12, 4))
    X = Interval(x - 1e-9, x + 1e-9)
    r = num.rhs(X)
    f = num.rhs(x)
    assert len(r) == 12 and r[6].shape == (4,)
    assert all(bool(np.all(ri.contains(fi))) for ri, fi in zip(r, f))


def test_ldl_solve_intervals_are_sound():
    from verified.arith.interval import Interval
    rng = np.random.default_rng(12)
    A = rng.normal(size=(5, 5))
    M = A @ A.T + 5 * np.eye(5)
    b = rng.normal(size=5)
    r = 1e-3 * np.abs(M)
    Mi = [[Interval(M[i, j] - r[i, j], M[i, j] + r[i, j]) for j in range(5)] for i in range(5)]
    bi = [Interval(v - 1e-3, v + 1e-3) for v in b]
    x = ldl_solve(Mi, bi)
    for _ in range(200):
        E = rng.uniform(-1, 1, size=(5, 5))
        E = (E + E.T) / 2           # symmetric samples (the solver reads the upper triangle)
        Ms = M + E * r
        bs = b + rng.uniform(-1e-3, 1e-3, 5)
        xs = np.linalg.solve(Ms, bs)
        assert all(bool(xi.contains(v)) for xi, v in zip(x, xs))

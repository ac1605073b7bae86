"""Ready models: the paper's pendulum and double pendulum (three constructions),
planar chains, Puma 560 in both DH conventions."""
import math
from fractions import Fraction

import numpy as np
import pytest
import sympy

from models import double_pendulum as dp, pendulum, planar, puma560


@pytest.fixture(scope="module")
def three_ways():
    return dp.dh_chain().numeric(), dp.urdf_chain().numeric()


def _states(n, seed):
    rng = np.random.default_rng(seed)
    return [np.concatenate([rng.uniform(-np.pi, np.pi, 2), rng.normal(scale=2, size=2)])
            for _ in range(n)]


def test_double_pendulum_three_ways_agree(three_ways):
    dh, urdf = three_ways
    for x in _states(20, 0):
        a_hand = np.array(dp.rhs(x), dtype=float)[2:]
        H_hand = dp.hamiltonian(x)
        for num in (dh, urdf):
            assert np.allclose(num.acceleration(x[:2], x[2:]), a_hand, rtol=1e-12, atol=1e-12)
            assert num.hamiltonian(x[:2], x[2:]) == pytest.approx(H_hand, rel=1e-12, abs=1e-12)
            assert np.allclose(num.mass_matrix(x[:2]), np.array(dp.mass_matrix(x), float), atol=1e-13)


def test_eq23_is_not_the_relative_mass_matrix(three_ways):
    dh, _ = three_ways
    x = np.array([0.3, 1.0, 0.0, 0.0])
    assert not np.allclose(dh.mass_matrix(x[:2]), np.array(dp.mass_matrix_eq23(x), float))
    # it is the mass matrix for the absolute rates: M_rel = J^T M_abs J
    J = np.array([[1.0, 0.0], [1.0, 1.0]])
    Mabs = np.array(dp.mass_matrix_eq23(x), float)
    assert np.allclose(J.T @ Mabs @ J, dh.mass_matrix(x[:2]), atol=1e-14)


def test_eq22_as_sympy_and_generic():
    xs, f, H = dp.sympy_model()
    assert len(f) == 4 and all(isinstance(e, sympy.Expr) for e in f)
    fn = sympy.lambdify(xs, f + [H], "numpy")
    for x in _states(5, 1):
        vals = fn(*x)
        assert np.allclose(vals[:4], np.array(dp.rhs(x), float), rtol=1e-13)
        assert vals[4] == pytest.approx(dp.hamiltonian(x), rel=1e-13)
    # the determinant is written factored (sin(x2)**2), and equals the naive one
    x2 = xs[1]
    assert f[2].has(sympy.sin(x2) ** 2)
    m1 = m2 = l1 = l2 = 1
    c = sympy.cos(x2)
    naive = (m1 * l1 + m2 * (l1 + l2 * c)) * m2 * l2 - m2 * l2 * c * m2 * (l1 * c + l2)
    assert sympy.simplify(naive - m2 * l1 * l2 * (m1 + m2 * sympy.sin(x2) ** 2)) == 0


def test_eq22_traces_and_factored_determinant_avoids_zero():
    from verified.graph import trace, from_sympy
    from verified.arith.interval import Interval
    g = trace(dp.rhs, 4)
    xs, f, _ = dp.sympy_model()
    g2 = from_sympy(f, xs)
    x = _states(1, 2)[0]
    assert np.allclose(g.eval_float(x), dp.rhs(x), rtol=1e-14)
    assert np.allclose(g2.eval_float(x), dp.rhs(x), rtol=1e-13)
    # over a wide box the factored determinant stays >= m1 = 1, the naive one contains 0
    s2 = np.sin(Interval(-3.0, 3.0))
    c2 = np.cos(Interval(-3.0, 3.0))
    factored = 1.0 * (1.0 + np.square(s2))
    naive = (1.0 + (1.0 + c2)) * 1.0 - c2 * (c2 + 1.0)
    assert float(factored.lo) >= 0.999
    assert float(naive.lo) <= 0.0 <= float(naive.hi)
    # the interval rhs over the initial box is finite
    lo, hi = dp.initial_box()
    enc = g.eval_interval(Interval(lo, hi))
    assert np.all(np.isfinite(enc.lo)) and np.all(np.isfinite(enc.hi))


def test_initial_box_eq25_encloses_exact_values():
    lo, hi = dp.initial_box()
    exact = [(Fraction(99, 100) * Fraction(3, 4), Fraction(101, 100) * Fraction(3, 4)),
             (Fraction(-11, 20), Fraction(-11, 20))]
    for k, (a, b) in enumerate(exact):
        va = sympy.N(sympy.Rational(a.numerator, a.denominator) * sympy.pi, 50)
        vb = sympy.N(sympy.Rational(b.numerator, b.denominator) * sympy.pi, 50)
        assert sympy.Float(lo[k], 50) < va and vb < sympy.Float(hi[k], 50)
    assert Fraction(lo[2]) <= Fraction(43, 100) <= Fraction(hi[2])
    assert Fraction(lo[3]) <= Fraction(67, 100) <= Fraction(hi[3])
    assert hi[1] - lo[1] < 1e-15 and hi[0] - lo[0] == pytest.approx(0.02 * 3 * math.pi / 4)


def test_pendulum():
    num = pendulum.chain().numeric()
    for x in _states(5, 3):
        q, qd = x[0], x[2]
        assert num.acceleration([q], [qd])[0] == pytest.approx(pendulum.rhs([q, qd])[1], rel=1e-13)
        H19 = pendulum.hamiltonian([q, qd])
        assert num.hamiltonian([q], [qd]) == pytest.approx(H19 - 9.81, rel=1e-13, abs=1e-13)
    lo, hi = pendulum.initial_box()
    assert lo[0] <= 2.1 <= hi[0] and Fraction(lo[0]) <= Fraction(21, 10) <= Fraction(hi[0])


def test_planar_point_mass_chain_is_double_pendulum():
    c = planar.planar_chain(2, point_masses=True)
    x = np.array([0.4, -1.2])
    assert np.allclose(c.numeric().mass_matrix(x), np.array(dp.mass_matrix(x), float), atol=1e-14)


@pytest.mark.parametrize("n", [2, 3, 6])
def test_planar_standard_equals_modified(n):
    a = planar.planar_chain(n, lengths=np.linspace(0.3, 1.0, n), masses=np.linspace(1, 2, n))
    b = planar.planar_chain(n, lengths=np.linspace(0.3, 1.0, n), masses=np.linspace(1, 2, n),
                            convention="modified")
    rng = np.random.default_rng(n)
    q, qd = rng.normal(size=n), rng.normal(size=n)
    assert np.allclose(a.numeric().acceleration(q, qd), b.numeric().acceleration(q, qd), atol=1e-11)
    assert a.numeric().hamiltonian(q, qd) == pytest.approx(b.numeric().hamiltonian(q, qd), rel=1e-13)


def test_puma_standard_equals_modified():
    a, b = puma560.puma560("standard").numeric(), puma560.puma560("modified").numeric()
    rng = np.random.default_rng(9)
    for _ in range(3):
        q, qd = rng.normal(size=6), rng.normal(size=6)
        assert np.allclose(a.mass_matrix(q), b.mass_matrix(q), atol=1e-14)
        assert np.allclose(a.acceleration(q, qd), b.acceleration(q, qd), rtol=1e-10, atol=1e-10)
        assert a.potential_energy(q) == pytest.approx(b.potential_energy(q), abs=1e-12)

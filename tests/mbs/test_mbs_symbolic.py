"""Symbolic model: closed forms, laziness, EOM, eq. (5)-(7), graphs."""
import numpy as np
import pytest
import sympy

from mbs import cache, chain_from_dh
from models import pendulum, planar, robots


@pytest.fixture(autouse=True, scope="module")
def _tmp_cache(tmp_path_factory):
    cache.set_cache_dir(tmp_path_factory.mktemp("mbs-cache"))
    yield
    cache.set_cache_dir(None)


def _subs(expr, s, q, qd, tau=None, qdd=None, p=None):
    d = dict(zip(s.q, q))
    d.update(zip(s.qd, qd))
    if tau is not None:
        d.update(zip(s.tau, tau))
    if qdd is not None:
        d.update(zip(s.qdd, qdd))
    if p is not None:
        d.update(zip(s.p, p))
    return np.array(sympy.Matrix(expr).xreplace(d).evalf(), dtype=float)


def test_pendulum_closed_forms():
    s = pendulum.chain().symbolic()
    q, = s.q
    m, l, g = pendulum.M, pendulum.L, pendulum.G
    assert sympy.simplify(s.M[0, 0] - m * l**2) == 0
    assert sympy.simplify(s.P + m * g * l * sympy.cos(q)) == 0
    assert sympy.simplify(s.gravity[0] - m * g * l * sympy.sin(q)) == 0
    assert s.coriolis[0] == 0
    # eq. (19) has its zero level at the lowest point: H_chain = H_19 - m g l
    _, _, H19 = pendulum.sympy_model()
    qq, qqd = sympy.symbols("q qd", real=True)
    H19 = H19.subs({qq: q, qqd: s.qd[0]})
    assert sympy.simplify(s.H - (H19 - m * g * l)) == 0
    # eq. (3): H(q, p) = p^2 / (2 m l^2) + P
    assert sympy.simplify(s.H_of_p() - (s.p[0] ** 2 / (2 * m * l**2) + s.P)) == 0


def test_lazy():
    s = planar.planar_chain(3).symbolic()
    s.M
    for name in ("coriolis", "P", "gravity", "K", "H", "eom"):
        assert name not in s.__dict__
    s.K
    assert "P" not in s.__dict__ and "coriolis" not in s.__dict__


@pytest.fixture(scope="module")
def damped3():
    return planar.planar_chain(3, lengths=[0.6, 0.5, 0.4], masses=[1.2, 0.8, 0.5], damping=[0.1, 0.2, 0.3])


def test_mass_matrix_symmetric(damped3):
    s = damped3.symbolic()
    assert s.M.shape == (3, 3)
    assert s.M == s.M.T


def test_eom_vanishes_at_numeric_acceleration(damped3):
    s, num = damped3.symbolic(), damped3.numeric()
    rng = np.random.default_rng(0)
    for _ in range(3):
        q, qd, tau = rng.normal(size=3), rng.normal(size=3), rng.normal(size=3)
        qdd = num.acceleration(q, qd, tau)
        r = _subs(s.eom, s, q, qd, tau, qdd)
        assert np.abs(r).max() < 1e-11


def test_energy_balance_eq7(damped3):
    """dH/dt unsimplified (chain rule with the solved EOM) == qd^T (tau - D qd)."""
    s = damped3.symbolic()
    un = s.dHdt_unsimplified(explicit=False)   # in terms of qdd symbols
    num = damped3.numeric()
    rng = np.random.default_rng(1)
    for _ in range(3):
        q, qd, tau = rng.normal(size=3), rng.normal(size=3), rng.normal(size=3)
        qdd = num.acceleration(q, qd, tau)
        a = _subs([un], s, q, qd, tau, qdd)[0, 0]
        b = _subs([s.dHdt], s, q, qd, tau)[0, 0]
        assert a == pytest.approx(b, rel=1e-10, abs=1e-12)
        assert b == pytest.approx(qd @ (tau - np.array([0.1, 0.2, 0.3]) * qd), rel=1e-12)


def test_dHdt_unsimplified_explicit_is_not_simplified():
    """Paper sec. 5.1: the pendulum's dH/dt is not symbolically 0 before simplification."""
    s = pendulum.chain().symbolic()
    un = s.dHdt_unsimplified()          # explicit for n <= 2
    assert s.qdd[0] not in un.free_symbols and un != 0
    assert sympy.simplify(un.subs(s.tau[0], 0)) == 0


def test_canonical_equations_5_6(damped3):
    """pdot of eq. (6) == d/dt (M qd) along the motion = tau_tot - c - g + Mdot qd."""
    s = damped3.symbolic()
    can = s.canonical()
    Mdot_qd = sum((s.dMdq[k] * s.qd[k] for k in range(3)), sympy.zeros(3, 3)) * s.qd
    expected = s.generalized_forces - s.coriolis - s.gravity + Mdot_qd
    rng = np.random.default_rng(2)
    q, qd, tau = rng.normal(size=3), rng.normal(size=3), rng.normal(size=3)
    a = _subs(can["pdot"], s, q, qd, tau)
    b = _subs(expected, s, q, qd, tau)
    assert np.allclose(a, b, rtol=1e-10, atol=1e-12)
    # eq. (5): qdot = M^{-1} p with p = M qd
    p = _subs(can["p"], s, q, qd)
    assert np.allclose(_subs(can["qdot"], s, q, qd, p=p.ravel()).ravel(), qd, atol=1e-12)


def test_coriolis_equals_christoffel_form():
    """c = Mdot qd - dK/dq (checks the Kane-style projection against differentiation)."""
    c = chain_from_dh([dict(joint="R", a=0.5, alpha=0.4, mass=1.0, com=(-0.2, 0.05, 0.01),
                            inertia=(0.01, 0.02, 0.015)),
                       dict(joint="P", theta=0.3, d=0.2, mass=0.7, com=(0.0, 0.1, -0.1),
                            inertia=(0.01, 0.01, 0.01)),
                       dict(joint="R", a=0.3, mass=0.4, com=(-0.1, 0, 0), inertia=(0.001, 0.003, 0.003))])
    s = c.symbolic()
    n = 3
    Mdot = sum((s.M.diff(s.q[k]) * s.qd[k] for k in range(n)), sympy.zeros(n, n))
    expected = Mdot * s.qd - sympy.Matrix([s.K.diff(qi) for qi in s.q])
    rng = np.random.default_rng(3)
    q, qd = rng.normal(size=3), rng.normal(size=3)
    assert np.allclose(_subs(s.coriolis, s, q, qd), _subs(expected, s, q, qd), atol=1e-12)


# (UR5: 10 s, behind the slow marker to keep the default run under 3 minutes)
@pytest.mark.parametrize("make", [lambda: planar.planar_chain(2, damping=0.05),
                                  pytest.param(robots.ur5, marks=pytest.mark.slow, id="ur5")])
def test_graphs_match_numeric(make):
    from verified.arith.interval import Interval
    chain = make()
    s, num = chain.symbolic(), chain.numeric()
    g = s.rhs_graph()
    e = s.energy_graph()
    x = np.random.default_rng(4).normal(size=2 * chain.n)
    assert np.allclose(g.eval_float(x), num.rhs(x), rtol=1e-11, atol=1e-11)
    H, = e.eval_float(x)
    assert H == pytest.approx(num.hamiltonian(x[:chain.n], x[chain.n:]), rel=1e-12)
    rate = num.energy_rate(x[:chain.n], x[chain.n:])
    assert s.energy_rate_graph(simplified=True).eval_float(x)[0] == pytest.approx(rate, abs=1e-14)
    un = s.energy_rate_graph()
    assert un.eval_float(x)[0] == pytest.approx(rate, abs=1e-9 * max(1.0, abs(H)))
    # unsimplified: the interval enclosure is not a point even without damping
    if chain.n == 6:
        w = un.eval_interval(Interval(x - 1e-6, x + 1e-6))
        assert float(w.hi[0] - w.lo[0]) > 0 and bool(w.contains(rate)[0])
    box = Interval(x - 1e-8, x + 1e-8)
    enc = g.eval_interval(box)
    assert np.all(enc.contains(g.eval_float(x)))
    # the graph can be serialized (used by the disk cache)
    from verified.graph import Graph
    assert Graph.from_dict(g.to_dict()) == g


def test_compile_generic_rationals_exact_on_intervals():
    from verified.arith.interval import Interval
    from mbs.sympy_eval import compile_generic
    x, y = sympy.symbols("x y")
    f = compile_generic([x / 3 + y**2 / 2, sympy.cos(x) * sympy.Rational(1, 10)], [x, y])
    assert f(1.0, 2.0)[0] == pytest.approx(1 / 3 + 2)
    batch = f(np.array([1.0, 2.0]), np.array([2.0, 3.0]))[0]
    assert batch.dtype == float and np.allclose(batch, [1 / 3 + 2, 2 / 3 + 4.5])
    enc = f(Interval(1.0, 1.0), Interval(2.0, 2.0))[0]
    # 1/3 is not a double: the enclosure must be a proper interval around 7/3
    assert float(enc.lo) < 7 / 3 < float(enc.hi) or float(enc.lo) < float(enc.hi)
    from fractions import Fraction
    assert Fraction(float(enc.lo)) <= Fraction(7, 3) <= Fraction(float(enc.hi))

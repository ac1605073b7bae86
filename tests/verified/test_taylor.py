"""Interval Taylor coefficients of ODE solutions (verified.series.taylor) against exact series."""

import math
from fractions import Fraction

import mpmath
import numpy as np
import pytest
import sympy as sp

from verified.graph import trace
from verified.arith.interval import Interval
from verified.series.taylor import TaylorODE


def contains_exact(iv_lo, iv_hi, exact):
    """lo <= exact <= hi with exact an mpmath/sympy number (compared exactly)."""
    e = mpmath.mpf(exact) if not isinstance(exact, mpmath.mpf) else exact
    return mpmath.mpf(float(iv_lo)) <= e <= mpmath.mpf(float(iv_hi))


def test_harmonic_oscillator_coefficients_contain_exact_series():
    ode = TaylorODE(trace(lambda x, p: [x[1], -x[0]], 2))
    c = ode.coefficients(Interval([0.7, -0.3]), 12)
    assert c.shape == (13, 2)
    # x(t) = x0 cos t + y0 sin t, y = x'
    for k in range(13):
        fk = Fraction(1, math.factorial(k))
        cos_k = [1, 0, -1, 0][k % 4] * fk
        sin_k = [0, 1, 0, -1][k % 4] * fk
        exact_x = Fraction(0.7) * cos_k + Fraction(-0.3) * sin_k
        assert float(c.lo[k, 0]) <= exact_x <= float(c.hi[k, 0])
        assert c.width()[k, 0] <= 1e-15


def test_exponential_decay_with_interval_parameter():
    ode = TaylorODE(trace(lambda x, p: [-p[0] * x[0]], 1, 1))
    a = Interval(0.9, 1.1)
    c = ode.coefficients(Interval([2.0]), 8, params=Interval([0.9], [1.1]))
    for k in range(9):
        for av in (0.9, 1.0, 1.1):
            exact = 2.0 * (-av) ** k / math.factorial(k)
            assert c.lo[k, 0] <= exact <= c.hi[k, 0]
    with pytest.raises(ValueError, match="parameters"):
        ode.coefficients(Interval([2.0]), 3)
    del a


T0 = sp.Rational(3, 10)
_t = sp.symbols("t")
# (name, sympy function of u, generic-scalar function, inner polynomial u(t))
CASES = [
    ("mul", lambda u: u * (u + 2), lambda u: u * (u + 2)),
    ("sqr", lambda u: u**2, lambda u: u**2),
    ("pow5", lambda u: u**5, lambda u: u**5),
    ("div", lambda u: 1 / (2 + u), lambda u: 1 / (2 + u)),
    ("sqrt", lambda u: sp.sqrt(2 + u), lambda u: np.sqrt(2 + u)),
    ("exp", sp.exp, np.exp),
    ("log", lambda u: sp.log(2 + u), lambda u: np.log(2 + u)),
    ("sin", sp.sin, np.sin),
    ("cos", sp.cos, np.cos),
    ("sin*cos", lambda u: sp.sin(u) * sp.cos(u), lambda u: np.sin(u) * np.cos(u)),
    ("tan", sp.tan, np.tan),
    ("atan", sp.atan, np.arctan),
    ("neg-sub", lambda u: 1 - u - (-u) ** 3, lambda u: 1 - u - (-u) ** 3),
]


# (exp: 4-8 s of sympy series, behind the slow marker to keep the default run under 3 minutes)
@pytest.mark.parametrize("name, fsym, fnum", [pytest.param(*c, id=c[0], marks=[pytest.mark.slow] if c[0] == "exp" else [])
                                              for c in CASES])
def test_each_recurrence_against_sympy_series(name, fsym, fnum):
    """State (t, y) with t' = 1, y' = g(t), g = f(u(t)), u(t) = t^2 - t/2 + 1/5:
    y_[k+1] = g_[k] / (k + 1), compared with sympy's Taylor series of g at t0."""
    order = 9
    u_sym = _t**2 - _t / 2 + sp.Rational(1, 5)
    g = fsym(u_sym)
    ser = sp.series(g, _t, T0, order).removeO()
    coeffs = sp.Poly(sp.expand(ser.subs(_t, _t + T0)), _t).all_coeffs()[::-1]

    def rhs(x, p):
        t = x[0]
        return [1, fnum(t * t - t * Fraction(1, 2) + Fraction(1, 5))]

    ode = TaylorODE(trace(rhs, 2))
    t0 = Interval(0.3).widen_ulps(1)  # encloses the decimal 3/10
    c = ode.coefficients(Interval([float(t0.lo), 0.0], [float(t0.hi), 0.0]), order)
    for k in range(order):
        exact = sp.N(coeffs[k] / (k + 1), 40) if k < len(coeffs) else 0
        with mpmath.workdps(40):
            assert contains_exact(c.lo[k + 1, 1], c.hi[k + 1, 1], mpmath.mpf(str(exact))), (name, k)
        assert c.width()[k + 1, 1] < 1e-9, (name, k)


def test_box_coefficients_contain_point_coefficients():
    from models import double_pendulum as dp

    ode = TaylorODE(trace(dp.rhs, 4))
    lo, hi = dp.initial_box()
    box = Interval(lo, hi)
    cb = ode.coefficients(box, 10)
    rng = np.random.default_rng(0)
    pts = lo + rng.uniform(0, 1, (20, 4)) * (hi - lo)
    cp = ode.coefficients(Interval(pts), 10)
    assert cb.shape == (11, 4) and cp.shape == (20, 11, 4)
    assert cp.issubset(cb[None]).all()


def test_taylor_polynomial_matches_dop853_for_small_step():
    from models import double_pendulum as dp
    from oracles.sampling import states_at

    ode = TaylorODE(trace(dp.rhs, 4))
    x0 = dp.initial_point()
    h = 0.05
    c = ode.coefficients(Interval(x0), 20).mid()
    poly = sum(c[k] * h**k for k in range(21))
    ref = states_at(dp.rhs, [x0], [h], rtol=1e-13, atol=1e-13)[0, -1]
    assert np.allclose(poly, ref, rtol=0, atol=1e-10)


def test_bad_arguments():
    with pytest.raises(ValueError, match="as many outputs as inputs"):
        TaylorODE(trace(lambda x, p: [x[0]], 2))
    ode = TaylorODE(trace(lambda x, p: [x[1], -x[0]], 2))
    with pytest.raises(ValueError, match="order"):
        ode.coefficients(Interval([1.0, 0.0]), 0)
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 2\)"):
        ode.coefficients(Interval([1.0, 0.0, 3.0]), 3)

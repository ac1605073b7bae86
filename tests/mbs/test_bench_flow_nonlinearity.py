"""benchmarks/bench_flow_nonlinearity.py: the polynomial fit measures what it claims.

A flow map that is a polynomial of degree d is fitted exactly from degree d on (and not
below), a folded map is not fitted by any low degree, and the sampler reproduces a
closed-form flow."""

import sys
from math import comb
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

import bench_flow_nonlinearity as fn  # noqa: E402


def test_monomials_count_every_exponent_once():
    for m, d in ((1, 4), (3, 2), (6, 3)):
        e = fn.monomials(m, d)
        assert len(e) == comb(m + d, d)
        assert len({tuple(r) for r in e}) == len(e)
        assert e.sum(axis=1).max() == d


def _fit(fun, degrees, m=3, seed=0):
    rng = np.random.default_rng(seed)
    tr, te = rng.uniform(-1, 1, (200, m)), rng.uniform(-1, 1, (100, m))
    return fn.fit_residuals(tr, fun(tr), te, fun(te), degrees)[1]


def test_quadratic_map_is_fitted_from_degree_two():
    def fun(x):
        return np.stack([x[:, 0] + 0.3 * x[:, 1] * x[:, 2], 2 * x[:, 1] - x[:, 0] ** 2], axis=1)
    r = _fit(fun, (1, 2, 3))
    assert r[1] > 0.05  # the quadratic term is 10-20 % of the width: degree 1 misses it
    assert r[2] < 1e-12 and r[3] < 1e-12


def test_folded_map_is_not_fitted_by_low_degrees():
    def fun(x):
        return np.stack([np.sin(6 * x[:, 0]) * np.cos(5 * x[:, 1])], axis=1)
    r = _fit(fun, (1, 2, 3))
    assert min(r.values()) > 0.2


def test_flow_samples_follow_a_closed_form_flow():
    # x' = A x (harmonic oscillator): x(t) = expm(A t) x0, an affine map of the box
    def f(X):
        return np.array([X[1], -X[0]])
    centre, radius = np.array([1.0, 0.0]), np.array([0.1, 0.05])
    xi = np.random.default_rng(1).uniform(-1, 1, (8, 2))
    y = fn.flow_samples(f, centre, radius, xi, np.array([0.5, 1.0]))
    x0 = centre + radius * xi
    for k, t in enumerate((0.5, 1.0)):
        exact = np.stack([x0[:, 0] * np.cos(t) + x0[:, 1] * np.sin(t), -x0[:, 0] * np.sin(t) + x0[:, 1] * np.cos(t)], 1)
        assert np.abs(y[:, k] - exact).max() < 1e-10

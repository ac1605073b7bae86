"""Recentring and merging of set parameters (first- and second-order sets) are exact or
covering: every point of the old set, written in the new set's coordinates, lies in
its boxes. A mutant that forgets the quadratic term's linear shift is caught."""

from __future__ import annotations

import numpy as np
import pytest

from verified.arith.interval import Interval
from verified.sets.second_order import QuadraticSets
from verified.sets.first_order import DoubletonSets


def _random_doubletons(rng, nb=2, n=3, m=7):
    lo = rng.uniform(-1, 1, (nb, m))
    return DoubletonSets(c=rng.normal(size=(nb, n)), C=rng.normal(size=(nb, n, m)),
                         r0=Interval(lo, lo + rng.uniform(0.01, 0.5, (nb, m))),  # not centred, need not hold 0
                         Q=np.linalg.qr(rng.normal(size=(nb, n, n)))[0],
                         r=Interval(-rng.uniform(0, 0.1, (nb, n)), rng.uniform(0, 0.2, (nb, n))))


def _random_quadratic(rng, nb=2, n=3, m=7):
    d = _random_doubletons(rng, nb, n, m)
    S = rng.normal(size=(nb, n, m, m)) * 0.3
    S = 0.5 * (S + S.transpose(0, 1, 3, 2))
    return QuadraticSets(c=d.c, C=d.C, r0=d.r0, S=S, Q=d.Q, r=d.r)


def _samples(s, rng, k=300):
    """Parameters u (k, B, m), errors w (k, B, n): vertices first, then random points."""
    nb, m = s.r0.shape
    n = s.c.shape[1]
    t = rng.uniform(0, 1, (k, nb, m))
    t[: k // 3] = np.round(t[: k // 3])
    u = s.r0.lo + t * s.r0.width()
    w = s.r.lo + rng.uniform(0, 1, (k, nb, n)) * s.r.width()
    return u, w


def _points(s, u, w):
    x = s.c + np.einsum("bij,kbj->kbi", s.C, u) + np.einsum("bij,kbj->kbi", s.Q, w)
    if isinstance(s, QuadraticSets):
        x = x + np.einsum("kbj,bijl,kbl->kbi", u, s.S, u)
    return x


def _error_coordinates(new, x, u_new):
    """omega = Q^-1 (x - c - C u - q(u)): the error part the point needs in the new set."""
    rest = x - new.c - np.einsum("bij,kbj->kbi", new.C, u_new)
    if isinstance(new, QuadraticSets):
        rest = rest - np.einsum("kbj,bijl,kbl->kbi", u_new, new.S, u_new)
    return np.linalg.solve(new.Q[None], rest[..., None])[..., 0]


def _inside(iv, v, rel=1e-10):
    slack = rel * (1.0 + np.abs(v))
    return ((v >= iv.lo - slack) & (v <= iv.hi + slack)).all()


@pytest.mark.parametrize("kind", ["doubleton", "quadratic"])
def test_recentring_is_exact(kind):
    rng = np.random.default_rng(3)
    s = _random_doubletons(rng) if kind == "doubleton" else _random_quadratic(rng)
    new = s.recentred()
    np.testing.assert_allclose(new.r0.mid(), 0.0, atol=1e-12)
    assert np.abs(new.r.mid()).max() < 1e-9
    u, w = _samples(s, rng)
    x = _points(s, u, w)
    u_new = u - s.r0.mid()
    assert _inside(new.r0, u_new)
    assert _inside(new.r, _error_coordinates(new, x, u_new))


def test_recentring_mutant_without_the_linear_shift_is_caught(monkeypatch):
    """QuadraticSets.recentred without C += 2 S mu: points leave the error box."""
    rng = np.random.default_rng(4)
    s = _random_quadratic(rng)
    real = QuadraticSets.recentred

    def no_shift(self):
        out = real(self)
        return QuadraticSets(c=out.c, C=self.C, r0=out.r0, S=out.S, Q=out.Q, r=out.r)

    u, w = _samples(s, rng)
    x = _points(s, u, w)
    bad = no_shift(s)
    assert not _inside(bad.r, _error_coordinates(bad, x, u - s.r0.mid()))


@pytest.mark.parametrize("kind", ["doubleton", "quadratic"])
def test_merging_covers_the_set(kind):
    """merge_params(count, keep_first): the kept parameters unchanged, the merged ones
    (and, for quadratic sets, every quadratic term they are in) covered by n new ones."""
    rng = np.random.default_rng(5)
    s = _random_doubletons(rng) if kind == "doubleton" else _random_quadratic(rng)
    s = s.recentred()
    n, m = s.c.shape[1], s.C.shape[2]
    new = s.merge_params(4, keep_first=n)
    assert new.C.shape[2] == m - 4 + n
    np.testing.assert_array_equal(new.C[:, :, :n], s.C[:, :, :n])
    # which parameters were kept: the columns of s.C that reappear in new.C
    keep = [j for j in range(m) if any(np.array_equal(s.C[:, :, j], new.C[:, :, i]) for i in range(m - 4))]
    sel = [j for j in range(m) if j not in keep]
    assert len(keep) == m - 4
    u, w = _samples(s, rng)
    x = _points(s, u, w)
    Bq = new.C[:, :, -n:]
    merged = np.einsum("bij,kbj->kbi", s.C[:, :, sel], u[:, :, sel])
    if kind == "quadratic":
        S_cross = s.S.copy()
        S_cross[np.ix_(range(s.S.shape[0]), range(n), keep, keep)] = 0.0
        merged = merged + np.einsum("kbj,bijl,kbl->kbi", u, S_cross, u)
    beta = np.linalg.solve(Bq[None], merged[..., None])[..., 0]
    assert _inside(new.r0[:, -n:], beta)
    u_new = np.concatenate([u[:, :, keep], beta], axis=2)
    assert _inside(new.r, _error_coordinates(new, x, u_new))

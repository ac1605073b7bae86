"""Absorbing the error part of first-order sets into parameters
(:meth:`verified.sets.first_order.DoubletonSets.absorb_error`, ``solve(absorb=...)``): exactness,
the shared-symbol affine forms, soundness against sampled trajectories (Pinocchio's
``aba`` for the arm) and a mutant that drops the absorbed error."""

from __future__ import annotations

import numpy as np
import pytest

from oracles.sampling import misses, sample_initial_points, trajectories
from oracles.taylor_cases import ARM_Q0  # the arm_pin fixture: tests/verified/conftest.py
from verified.sets import first_order
from verified.series.affine_taylor import forms_to_interval
from verified.graph import trace
from verified.arith.interval import Interval
from verified.solver import solve

from models import double_pendulum as dp
from models import pendulum as pd


def _random_sets(rng, nb=2, n=3, m=3):
    s = first_order.DoubletonSets(
        c=rng.normal(size=(nb, n)), C=rng.normal(size=(nb, n, m)),
        r0=Interval(-rng.uniform(0.1, 1, (nb, m)), rng.uniform(0.1, 1, (nb, m))),
        Q=np.linalg.qr(rng.normal(size=(nb, n, n)))[0],
        r=Interval(-rng.uniform(0, 0.1, (nb, n)), rng.uniform(0, 0.2, (nb, n))))
    return s


def _points(s, rng, k):
    u = s.r0.lo + rng.uniform(0, 1, (k,) + s.r0.shape) * s.r0.width()
    w = s.r.lo + rng.uniform(0, 1, (k,) + s.r.shape) * s.r.width()
    return u, w, s.c + np.einsum("bij,kbj->kbi", s.C, u) + np.einsum("bij,kbj->kbi", s.Q, w)


def test_absorbing_is_exact_and_batches_pad():
    rng = np.random.default_rng(4)
    s = _random_sets(rng)
    a = s.absorb_error()
    assert a.C.shape == (2, 3, 6) and (a.r.lo == 0).all() and (a.r.hi == 0).all()
    u, w, x = _points(s, rng, 20)
    x_new = a.c + np.einsum("bij,kbj->kbi", a.C, np.concatenate([u, w], axis=2))
    np.testing.assert_allclose(x_new, x, rtol=1e-12, atol=1e-12)
    assert (a.hull().lo <= s.hull().lo + 1e-12).all() and (a.hull().hi >= s.hull().hi - 1e-12).all()
    both = first_order.DoubletonSets.concatenate([s, a])  # 3 and 6 parameters: padded with zeros
    assert both.C.shape == (4, 3, 6)
    np.testing.assert_allclose(both.hull().lo[:2], s.hull().lo, rtol=1e-14, atol=1e-14)


@pytest.mark.parametrize("own", [None, 3, 5])
def test_affine_forms_with_shared_symbols_cover_the_set(own):
    """Forms over the set's own parameters, with the absorbed ones (beyond ``own``)
    sharing one symbol per state: every sampled point of the set and the centre lie in
    their range."""
    rng = np.random.default_rng(5)
    s = _random_sets(rng).absorb_error().absorb_error()  # n = 3 states, m = 9 parameters
    s.r = Interval(-rng.uniform(0, 0.1, (2, 3)), rng.uniform(0, 0.1, (2, 3)))
    F = s.affine_forms(extra=2, own_symbols=own)
    lo, hi = forms_to_interval(F)  # (n + extra, B)
    assert (np.abs(lo[3:]) < 1e-299).all() and (np.abs(hi[3:]) < 1e-299).all()
    _, _, x = _points(s, rng, 200)
    assert (x >= lo[:3].T - 1e-12).all() and (x <= hi[:3].T + 1e-12).all()
    assert (s.c >= lo[:3].T).all() and (s.c <= hi[:3].T).all()
    if own is not None and own < 9:
        assert F.shape[2] == own + 3 + 3 + 2  # own, shared (n), r (n), centre, error


def test_solve_absorb_arguments():
    g = trace(pd.rhs, 2)
    lo, hi = pd.initial_box()
    with pytest.raises(ValueError, match="absorb must be True or False"):
        solve(g, Interval(lo, hi), (0.0, 0.1), absorb="yes")
    with pytest.raises(ValueError, match="absorb is not a setting of method 'second_order'"):
        solve(g, Interval(lo, hi), (0.0, 0.1), absorb=True, set_order=2)


# (5-9 s: behind the slow marker to keep the default run under 3 minutes)
@pytest.mark.slow
def test_arm_absorbed_contains_pinocchio_trajectories_and_is_tighter(arm_pin):
    """3-link arm, q +- 1e-5, T = 1, affine: DOP853 with Pinocchio's aba inside every
    output box and the tube; absorbing the error part gives a narrower final hull
    (order 8: 4.0e-4 against 2.4e-3 wide; measured 1e-6 to T = 2: worst ratio 16.97
    without, 1.19 with)."""
    chain, g, qdd = arm_pin
    x0 = np.concatenate([ARM_Q0, np.zeros(3)])
    r = np.array([1e-5] * 3 + [0.0] * 3)
    lo, hi = x0 - r, x0 + r
    T = 1.0
    kw = dict(arithmetic="affine", t_eval=[0.25, 0.5, 0.75, 1.0], order=8, tol=1e-10)
    on = solve(g, Interval(lo, hi), (0.0, T), absorb=True, **kw)
    off = solve(g, Interval(lo, hi), (0.0, T), **kw)
    assert on.success, on.reason
    assert on.stats["absorbed"] >= 1 and off.stats["absorbed"] == 0

    def f(x):
        return np.concatenate([x[3:], qdd(x[:3], x[3:])])

    sols = trajectories(f, np.unique(sample_initial_points(lo, hi, 12), axis=0), T)
    assert misses(on, sols, per_step=2) == []
    assert off.success, off.reason
    assert on.hull[-1].width().max() < 0.5 * off.hull[-1].width().max()


def _dp_quarter(T=0.6, **kw):
    lo, hi = dp.initial_box()
    c = 0.5 * (lo + hi)
    lo, hi = c - 0.25 * (c - lo), c + 0.25 * (hi - c)
    sol = solve(trace(dp.rhs, 4), Interval(lo, hi), (0.0, T), t_eval=np.linspace(0, T, 11), absorb=True, **kw)
    return sol, trajectories(lambda x: dp.rhs(x), sample_initial_points(lo, hi, 30), T)


def test_double_pendulum_absorbed_contains_trajectories():
    sol, sols = _dp_quarter()
    assert sol.success and sol.stats["absorbed"] >= 1
    assert misses(sol, sols) == []


def test_oracle_bites_when_the_absorbed_error_is_dropped(monkeypatch):
    """A broken absorption that keeps ``C <- [C | Q]`` but replaces ``r`` by 0 in the new
    parameters loses the accumulated error: sampled trajectories must leave it."""
    def broken(self):
        nb, n = self.c.shape
        return first_order.DoubletonSets(c=self.c, C=np.concatenate([self.C, self.Q], axis=2),
                                   r0=first_order.concatenate([self.r0, first_order.point(np.zeros((nb, n)))], axis=1),
                                   Q=np.broadcast_to(np.eye(n), (nb, n, n)).copy(), r=first_order.point(np.zeros((nb, n))))
    monkeypatch.setattr(first_order.DoubletonSets, "absorb_error", broken)
    sol, sols = _dp_quarter()
    assert misses(sol, sols) != []


# --------------------------------------------------------------------------- merging at the cap


def test_merging_covers_the_merged_parameters_exactly():
    """merge_params: sum_{j in S} C_j a_j lies in B b for every a in r0 (vertices and random
    points), the kept parameters are untouched, the count is m - count + n."""
    rng = np.random.default_rng(7)
    s = _random_sets(rng, nb=2, n=3, m=3)
    for _ in range(4):  # 3 + 4 * 3 = 15 parameters
        s = first_order.DoubletonSets(s.c, s.C, s.r0, s.Q, Interval(-rng.uniform(0, 0.1, (2, 3)), rng.uniform(0, 0.1, (2, 3))))
        s = s.absorb_error()
    m = s.C.shape[2]
    merged = s.merge_params(6, keep_first=3)
    assert merged.C.shape == (2, 3, m - 6 + 3)
    np.testing.assert_array_equal(merged.C[:, :, :3], s.C[:, :, :3])  # the initial box stays first
    w = np.abs(s.C).sum(axis=1) * s.r0.width()
    w[:, :3] = np.inf
    sel = np.sort(np.argsort(w.max(axis=0), kind="stable")[:6])
    Bq, b = merged.C[:, :, -3:], merged.r0[:, -3:]
    for k in range(200):
        if k < 64:  # vertices of the merged parameters' box
            bits = (k >> np.arange(6)) & 1
            a = np.where(bits, s.r0.hi[:, sel], s.r0.lo[:, sel])
        else:
            a = s.r0.lo[:, sel] + rng.uniform(0, 1, (2, 6)) * s.r0.width()[:, sel]
        v = np.einsum("bij,bj->bi", s.C[:, :, sel], a)
        beta = np.linalg.solve(Bq, v[..., None])[..., 0]
        slack = 1e-12 * (1 + np.abs(beta))
        assert ((beta >= b.lo - slack) & (beta <= b.hi + slack)).all()
    assert (merged.hull().lo <= s.hull().lo + 1e-12).all() and (merged.hull().hi >= s.hull().hi - 1e-12).all()


# (5-8 s: behind the slow marker to keep the default run under 3 minutes)
@pytest.mark.slow
def test_arm_with_merging_contains_pinocchio_trajectories(arm_pin):
    """3-link arm, q +- 1e-4, T = 1.3, affine, absorbing with merging at the cap (it merges
    here: 3 times): DOP853 with Pinocchio's aba inside every output box."""
    chain, g, qdd = arm_pin
    x0 = np.concatenate([ARM_Q0, np.zeros(3)])
    r = np.array([1e-4] * 3 + [0.0] * 3)
    lo, hi = x0 - r, x0 + r
    T = 1.3
    sol = solve(g, Interval(lo, hi), (0.0, T), absorb=True, arithmetic="affine", t_eval=np.linspace(0, T, 14),
                order=8, tol=1e-10)
    assert sol.success, sol.reason
    assert sol.stats["merged"] >= 1

    def f(x):
        return np.concatenate([x[3:], qdd(x[:3], x[3:])])

    sols = trajectories(f, np.unique(sample_initial_points(lo, hi, 12), axis=0), T)
    assert misses(sol, sols, per_step=2) == []


# (4-6 s: behind the slow marker to keep the default run under 3 minutes)
@pytest.mark.slow
def test_oracle_bites_when_merged_parameters_are_dropped(monkeypatch):
    """A broken merge that removes the merged parameters without the n covering ones loses
    part of the set: sampled trajectories must leave it (double pendulum, quarter box,
    with the cap lowered so that it merges)."""
    import verified.steppers.lohner as vl

    def broken(self, count, keep_first, steer=None):
        nb, n = self.c.shape
        m = self.C.shape[2]
        w = np.abs(self.C[:, :steer]).sum(axis=1) * self.r0.width()
        w[:, :keep_first] = np.inf
        sel = np.sort(np.argsort(w.max(axis=0), kind="stable")[:count])
        rest = np.setdiff1d(np.arange(m), sel)
        zero = np.zeros((nb, n, n))
        return first_order.DoubletonSets(self.c, np.concatenate([self.C[:, :, rest], zero], axis=2),
                                   first_order.concatenate([self.r0[:, rest], first_order.point(np.zeros((nb, n)))], axis=1),
                                   self.Q, self.r)

    real_init = vl.LohnerStepper.__init__

    def low_cap(self, *a, **k):
        real_init(self, *a, **k)
        self.max_params = 3 * self.n

    monkeypatch.setattr(vl.LohnerStepper, "__init__", low_cap)
    sol, sols = _dp_quarter(T=1.0)
    assert sol.stats["merged"] >= 1
    assert misses(sol, sols) == []
    monkeypatch.setattr(first_order.DoubletonSets, "merge_params", broken)
    sol, sols = _dp_quarter(T=1.0)
    assert sol.stats["merged"] >= 1
    assert misses(sol, sols) != []

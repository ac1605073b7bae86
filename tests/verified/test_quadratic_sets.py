"""Second-order sets (verified.sets.second_order, solve(..., set_order=2)).

Oracles: exact rationals for the quadratic forms' ranges; scipy DOP853 trajectories
(tests/oracles/sampling.py) for the solver, with Pinocchio's aba as right-hand side for the arm;
finite differences for the second variational equations.
"""
from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from oracles.sampling import misses, sample_initial_points, trajectories
from oracles.taylor_cases import ARM_Q0  # the arm_pin fixture: tests/verified/conftest.py
from verified.sets import second_order as second_order_sets
from verified.steppers import second_order as second_order_step
from verified.graph import trace
from verified.arith.interval import Interval
from verified.solver import VerifiedODE, solve
from verified.series.variational import pair_index, second_variational_graph

from models import double_pendulum as dp
from models import pendulum as pd


@pytest.mark.parametrize("p", [None, 1, 2, 3])
def test_second_variational_graph_matches_finite_differences(p):
    """All n directions (p = None), or directions=p: V is n x p and W_ab the second
    derivative along V's columns a and b."""
    g = trace(dp.rhs, 4)
    g2 = second_variational_graph(g) if p is None else second_variational_graph(g, directions=p)
    n = 4
    p = n if p is None else p
    P = pair_index(p)
    assert g2.n_inputs == n + n * p + n * len(P) == g2.n_outputs
    rng = np.random.default_rng(p)
    x = rng.uniform(-1, 1, n)
    V = rng.normal(size=(n, p))
    W = rng.normal(size=(len(P), n))
    out = g2.eval_float(np.r_[x, V.ravel(), W.ravel()])
    np.testing.assert_allclose(out[:n], g.eval_float(x), rtol=1e-14)
    np.testing.assert_allclose(out[n:n + n * p].reshape(n, p), g.jacobian_float(x) @ V, rtol=1e-12, atol=1e-12)
    dW = out[n + n * p:].reshape(len(P), n)
    eps = 1e-6
    for k, (a, b) in enumerate(P):
        d2 = (g.jacobian_float(x + eps * V[:, b]) @ V[:, a] - g.jacobian_float(x - eps * V[:, b]) @ V[:, a]) / (2 * eps)
        np.testing.assert_allclose(dW[k], d2 + g.jacobian_float(x) @ W[k], rtol=1e-6, atol=1e-6)
    with pytest.raises(ValueError, match="directions"):
        second_variational_graph(g, directions=5)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10**6), n=st.integers(1, 4))
def test_quadratic_range_encloses_exact_values(seed, n):
    rng = np.random.default_rng(seed)
    S = rng.normal(size=(1, n, n, n))
    S = 0.5 * (S + S.transpose(0, 1, 3, 2))
    lo = -rng.uniform(0, 1, n)
    hi = rng.uniform(0, 1, n)
    rng_box = second_order_sets.quadratic_range(S, Interval(lo, hi)[None])
    for _ in range(20):
        u = [Fraction(float(v)) for v in lo + rng.uniform(0, 1, n) * (hi - lo)]
        for i in range(n):
            q = sum(Fraction(float(S[0, i, j, k])) * u[j] * u[k] for j in range(n) for k in range(n))
            assert Fraction(float(rng_box.lo[0, i])) <= q <= Fraction(float(rng_box.hi[0, i]))


def _pendulum_run(T=1.2, arithmetic="interval", box_scale=1.0):
    lo, hi = pd.initial_box()
    c = 0.5 * (lo + hi)
    lo, hi = c - box_scale * (c - lo), c + box_scale * (hi - c)
    sol = solve(VerifiedODE(trace(pd.rhs, 2), arithmetic), Interval(lo, hi), (0.0, T),
                t_eval=np.linspace(0, T, 7), set_order=2)
    sols = trajectories(lambda x: pd.rhs(x), sample_initial_points(lo, hi, 30), T)
    return sol, sols


@pytest.mark.parametrize("arithmetic", ["interval", "affine"])
def test_pendulum_second_order_contains_trajectories(arithmetic):
    sol, sols = _pendulum_run(arithmetic=arithmetic)
    assert sol.status == "completed", sol
    assert misses(sol, sols) == []


def test_double_pendulum_second_order_contains_trajectories_and_goes_further():
    lo, hi = dp.initial_box()
    T = 0.55
    graph = trace(dp.rhs, 4)
    first = solve(graph, Interval(lo, hi), (0.0, T), t_eval=np.linspace(0, T, 12), method="lohner")
    second = solve(graph, Interval(lo, hi), (0.0, T), t_eval=np.linspace(0, T, 12), set_order=2)
    sols = trajectories(lambda x: dp.rhs(x), sample_initial_points(lo, hi, 40), T)
    assert second.status == "completed", second
    assert misses(second, sols) == []
    # one box: the first-order sets break down near 0.45 s (measured 0.453)
    assert first.t_reached < T


@pytest.mark.slow  # default-run budget (CI's cold default step measured 170-183 s of 180 at 1e891d1/1caded6)
def test_arm_second_order_contains_pinocchio_trajectories(arm_pin):
    """3-link arm (preconditioned numeric model), q +- 1e-3, T = 0.2, affine: DOP853
    trajectories with Pinocchio's aba as right-hand side in every output box and the tube."""
    chain, g, qdd = arm_pin
    x0 = np.concatenate([ARM_Q0, np.zeros(3)])
    r = np.array([1e-3] * 3 + [0.0] * 3)
    lo, hi = x0 - r, x0 + r
    sol = solve(g, Interval(lo, hi), (0.0, 0.2), arithmetic="affine", t_eval=[0.1, 0.2], set_order=2)
    assert sol.success, sol.reason

    def f(x):
        return np.concatenate([x[3:], qdd(x[:3], x[3:])])

    sols = trajectories(f, np.unique(sample_initial_points(lo, hi, 12), axis=0), 0.2)
    assert misses(sol, sols, per_step=2) == []


def test_oracle_bites_when_third_order_terms_are_dropped(monkeypatch):
    """Without the cubic and Lagrange terms (the curvature beyond what S carries) the
    enclosure must miss sampled states."""
    def zero(H, a, b):
        return second_order_sets.Interval(np.zeros(a.shape))
    monkeypatch.setattr(second_order_step, "_bilinear", zero)
    sol, sols = _pendulum_run(T=2.0, box_scale=3.0)
    assert misses(sol, sols) != []


def _cubic_shear_run(monkeypatch, lagrange=None):
    """x1' = 0, x2' = x1^3 from x1 in [-0.5, 0.5], x2 = 0.2 exact: a set that extends in
    one direction of two (the directional Hessian path), whose whole curvature is third
    order (x2(t) = 0.2 + t x1^3, closed form). Returns (misses, calls of the path)."""
    calls = []
    real = second_order_step.QuadraticStepper._directional_lagrange

    def spy(self, sets, live, *args):
        calls.append(live.size)
        out = real(self, sets, live, *args)
        return out if lagrange is None else lagrange(out)
    monkeypatch.setattr(second_order_step.QuadraticStepper, "_directional_lagrange", spy)
    real_directions = second_order_step.QuadraticStepper._directions

    def from_two_states(self, sets):  # (the path is meant for big systems; force it here)
        self.directional_min_states = 2
        return real_directions(self, sets)
    monkeypatch.setattr(second_order_step.QuadraticStepper, "_directions", from_two_states)
    g = trace(lambda x, p: [x[0] * 0.0, x[0] * x[0] * x[0]], 2)
    sol = solve(VerifiedODE(g, "affine"), Interval(np.array([-0.5, 0.2]), np.array([0.5, 0.2])), (0.0, 1.0),
                t_eval=[0.5, 1.0], set_order=2)
    assert sol.success, sol.reason
    u = np.linspace(-0.5, 0.5, 101)
    out = sum(int(((x2 < b.lo[0, 1]) | (x2 > b.hi[0, 1])).sum())
              for t, b in zip(sol.t, sol.boxes) for x2 in [0.2 + t * u**3])
    return out, calls


def test_directional_hessian_path_is_taken_and_sound(monkeypatch):
    misses_, calls = _cubic_shear_run(monkeypatch)
    assert calls and set(calls) == {1}
    assert misses_ == 0


def test_oracle_bites_when_the_directional_lagrange_term_is_dropped(monkeypatch):
    misses_, calls = _cubic_shear_run(monkeypatch, lagrange=lambda out: second_order_sets.Interval(np.zeros(out.shape)))
    assert calls and misses_ > 0


@pytest.mark.slow  # (~5-8 s: the default run stays under 3 minutes)
def test_oracle_bites_when_the_quadratic_part_is_dropped(monkeypatch):
    real = second_order_step.QuadraticStepper.step

    def no_quadratic(self, sets, h, X, E, cE):
        res = real(self, sets, h, X, E, cE)
        res.sets.S = np.zeros_like(res.sets.S)
        return res
    monkeypatch.setattr(second_order_step.QuadraticStepper, "step", no_quadratic)
    sol, sols = _pendulum_run(T=2.0, box_scale=3.0)
    assert misses(sol, sols) != []


def test_set_order_arguments():
    g = trace(pd.rhs, 2)
    lo, hi = pd.initial_box()
    with pytest.raises(ValueError, match="set_order must be 1 or 2"):
        solve(g, Interval(lo, hi), (0.0, 0.1), set_order=3)


def test_absorbing_the_error_part_is_exact():
    """c + C u + q(u) + Q r and its absorbed form [C | Q] [u; r] describe the same points."""
    rng = np.random.default_rng(2)
    n = 3
    boxes = Interval(-rng.uniform(0.1, 1, (2, n)), rng.uniform(0.1, 1, (2, n)))
    s = second_order_sets.QuadraticSets.from_boxes(boxes)
    s.C = rng.normal(size=(2, n, n))
    S = rng.normal(size=(2, n, n, n))
    s.S = 0.5 * (S + S.transpose(0, 1, 3, 2))
    s.Q = np.linalg.qr(rng.normal(size=(2, n, n)))[0]
    s.r = Interval(-rng.uniform(0, 0.1, (2, n)), rng.uniform(0, 0.1, (2, n)))
    a = s.absorb_error()
    assert a.C.shape == (2, n, 2 * n) and a.S.shape == (2, n, 2 * n, 2 * n)
    assert (a.r.lo == 0).all() and (a.r.hi == 0).all()
    for _ in range(10):
        u = s.r0.lo + rng.uniform(0, 1, (2, n)) * s.r0.width()
        w = s.r.lo + rng.uniform(0, 1, (2, n)) * s.r.width()
        x_old = s.c + np.einsum("bij,bj->bi", s.C, u) + np.einsum("bj,bijk,bk->bi", u, s.S, u) \
            + np.einsum("bij,bj->bi", s.Q, w)
        uw = np.concatenate([u, w], axis=1)
        x_new = a.c + np.einsum("bij,bj->bi", a.C, uw) + np.einsum("bj,bijk,bk->bi", uw, a.S, uw)
        np.testing.assert_allclose(x_new, x_old, rtol=1e-12, atol=1e-12)
    assert (a.hull().lo <= s.hull().lo + 1e-12).all() and (a.hull().hi >= s.hull().hi - 1e-12).all()


@pytest.mark.slow  # 1.7 s; absorption is exercised by every second-order robot test
def test_absorption_happens_and_stays_sound():
    """Double pendulum quarter box, T = 0.8: the error part is absorbed at least once and
    DOP853 trajectories stay inside."""
    import verified.driver.batch as vb  # (the one-batch driver solve runs)
    lo, hi = dp.initial_box()
    c = 0.5 * (lo + hi)
    lo, hi = c - 0.25 * (c - lo), c + 0.25 * (hi - c)
    seen = {}
    real = vb._stepper

    def spy(*args, **kwargs):
        st = real(*args, **kwargs)
        seen["stepper"] = st
        return st
    import unittest.mock as um
    with um.patch.object(vb, "_stepper", spy):
        sol = solve(trace(dp.rhs, 4), Interval(lo, hi), (0.0, 0.8), t_eval=np.linspace(0, 0.8, 9), set_order=2)
    assert sol.success, sol
    assert seen["stepper"].absorbed >= 1
    sols = trajectories(lambda x: dp.rhs(x), sample_initial_points(lo, hi, 30), 0.8)
    assert misses(sol, sols) == []


def test_params_per_state_argument_and_cap():
    """``params_per_state`` reaches both steppers; bad values are a one-line error."""
    import unittest.mock as um

    import verified.driver.batch as vb  # (the one-batch driver solve runs)
    g = trace(pd.rhs, 2)
    lo, hi = pd.initial_box()
    for bad in (0, -1, 2.5, True, "8"):
        with pytest.raises(ValueError, match=r"params_per_state must be an integer in \[1, "):
            solve(g, Interval(lo, hi), (0.0, 0.1), params_per_state=bad)
    seen = []
    real = vb._stepper

    def spy(*args, **kwargs):
        seen.append(real(*args, **kwargs))
        return seen[-1]
    with um.patch.object(vb, "_stepper", spy):
        solve(g, Interval(lo, hi), (0.0, 0.05), set_order=2, params_per_state=6)
        solve(g, Interval(lo, hi), (0.0, 0.05), absorb=True, params_per_state=3)
        solve(g, Interval(lo, hi), (0.0, 0.05), set_order=2)
    assert [s.max_params for s in seen] == [12, 6, 8]


@pytest.mark.slow
def test_double_pendulum_one_box_past_one_second_with_more_parameters():
    """Issue 17's one-box target: the paper's box (25) without subdivision verified past
    1.0 s (second-order Taylor-model sets, 12 parameters per state, order 6; measured
    1.012 s, against 0.949 s with the default 4), sampled trajectories inside every
    output box and the tube."""
    lo, hi = dp.initial_box()
    T = 1.0
    sol = solve(trace(dp.rhs, 4), Interval(lo, hi), (0.0, T), t_eval=np.linspace(0, T, 21), order=6, tol=1e-10,
                set_order=2, error_basis="auto", arithmetic="taylor_model", params_per_state=12)
    assert sol.status == "completed", sol
    sols = trajectories(lambda x: dp.rhs(x), sample_initial_points(lo, hi, 40), T)
    assert misses(sol, sols) == []


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10**6), n=st.integers(1, 3), m=st.integers(1, 4))
def test_set_hull_encloses_exact_values_and_is_no_wider(seed, n, m):
    """QuadraticSets.hull (one quadratic per parameter, ends and vertex) holds the set's
    points (exact rationals) and is never wider than bounding C u and q(u) apart."""
    rng = np.random.default_rng(seed)
    nb = 2
    C = rng.normal(size=(nb, n, m))
    S = rng.normal(size=(nb, n, m, m)) * rng.choice([0.0, 0.1, 3.0])
    S = 0.5 * (S + S.transpose(0, 1, 3, 2))
    lo = -rng.uniform(0, 1, (nb, m)) * rng.choice([0.0, 1.0])
    hi = rng.uniform(0, 1, (nb, m))
    sets = second_order_sets.QuadraticSets(c=rng.normal(size=(nb, n)), C=C, r0=Interval(lo, hi), S=S,
                                   Q=np.broadcast_to(np.eye(n), (nb, n, n)).copy(),
                                   r=Interval(np.zeros((nb, n)), np.zeros((nb, n))))
    box = sets.hull()
    old = sets.doubleton().hull() + sets.q_range()
    assert (box.width() <= old.width() * (1 + 1e-12) + 1e-300).all()
    F = Fraction
    for _ in range(20):
        b = int(rng.integers(nb))
        u = lo[b] + rng.uniform(0, 1, m) * (hi[b] - lo[b])
        if rng.uniform() < 0.3:  # a vertex of some component's quadratic, when inside
            j = int(rng.integers(m))
            i = int(rng.integers(n))
            if S[b, i, j, j] != 0:
                u[j] = min(max(-C[b, i, j] / (2 * S[b, i, j, j]), lo[b, j]), hi[b, j])
        for i in range(n):
            x = (F(float(sets.c[b, i])) + sum(F(float(C[b, i, j])) * F(float(u[j])) for j in range(m))
                 + sum(F(float(S[b, i, j, k])) * F(float(u[j])) * F(float(u[k])) for j in range(m) for k in range(m)))
            assert F(float(box.lo[b, i])) <= x <= F(float(box.hi[b, i]))


def test_split_halves_cover_the_set():
    """Every point of a second-order set (random parameters and errors, exact rationals)
    lies in the hull of one of its two halves, and each half is narrower along the cut."""
    rng = np.random.default_rng(5)
    nb, n, m = 3, 2, 3
    S = rng.normal(size=(nb, n, m, m))
    S = 0.5 * (S + S.transpose(0, 1, 3, 2))
    sets = second_order_sets.QuadraticSets(c=rng.normal(size=(nb, n)), C=rng.normal(size=(nb, n, m)),
                                   r0=Interval(-rng.uniform(0.1, 1, (nb, m)), rng.uniform(0.1, 1, (nb, m))), S=S,
                                   Q=np.linalg.qr(rng.normal(size=(nb, n, n)))[0],
                                   r=Interval(-rng.uniform(0, 0.5, (nb, n)), rng.uniform(0, 0.5, (nb, n))))
    mask = np.array([True, False, True])
    out = sets.split(mask)
    assert out.n_sets == 5
    F = Fraction
    # the halves of set 0 and set 2 are the last four, in the order (0 low, 2 low, 0 high, 2 high)
    halves = {0: [out.take([1]), out.take([3])], 2: [out.take([2]), out.take([4])]}
    for b in (0, 2):
        boxes = [h.hull() for h in halves[b]]
        for _ in range(40):
            u = sets.r0.lo[b] + rng.uniform(0, 1, m) * (sets.r0.hi[b] - sets.r0.lo[b])
            e = sets.r.lo[b] + rng.uniform(0, 1, n) * (sets.r.hi[b] - sets.r.lo[b])
            x = [F(float(sets.c[b, i])) + sum(F(float(sets.C[b, i, j])) * F(float(u[j])) for j in range(m))
                 + sum(F(float(S[b, i, j, k])) * F(float(u[j])) * F(float(u[k])) for j in range(m) for k in range(m))
                 + sum(F(float(sets.Q[b, i, k])) * F(float(e[k])) for k in range(n)) for i in range(n)]
            assert any(all(F(float(bx.lo[0, i])) <= x[i] <= F(float(bx.hi[0, i])) for i in range(n))
                       for bx in boxes)
    assert out.take([0]).c.tolist() == sets.take([1]).c.tolist()  # the unselected set is unchanged


@pytest.mark.parametrize("set_step", [pytest.param("mean_value", marks=pytest.mark.slow), "composition"])
def test_adaptive_second_order_sets_split_and_contain_trajectories(set_step):
    """The pendulum from q in [0.8, 1.2], qd in [-0.2, 0.2] to T = 2, adaptive splitting
    on: sets are split, every sampled trajectory stays in the union at every output time
    and in the tube, and the final hull is narrower than without splitting (measured
    0.32 / 1.6 against 0.68-0.81 / 2.9-3.3)."""
    lo, hi = np.array([0.8, -0.2]), np.array([1.2, 0.2])
    T = 2.0
    g = trace(pd.rhs, 2)
    sol = solve(g, Interval(lo, hi), (0.0, T), t_eval=np.linspace(0, T, 5), set_order=2, set_step=set_step,
                adaptive=True, split_ratio=0.03, max_boxes=16)
    plain = solve(g, Interval(lo, hi), (0.0, T), t_eval=np.linspace(0, T, 5), set_order=2, set_step=set_step)
    assert sol.status == "completed", sol.reason
    assert sol.stats["splits"] > 0
    assert (sol.hull.width()[-1] < plain.hull.width()[-1]).all()
    sols = trajectories(lambda x: pd.rhs(x), sample_initial_points(lo, hi, 30), T)
    assert misses(sol, sols) == []


# --------------------------------------------------------------------------- merging at the cap
def _solve_exact(A, v):
    """A^-1 v in exact rationals (Gauss-Jordan), A (n, n) and v (n,) of Fractions."""
    n = len(v)
    M = [list(A[i]) + [v[i]] for i in range(n)]
    for col in range(n):
        piv = max(range(col, n), key=lambda r: abs(M[r][col]))
        M[col], M[piv] = M[piv], M[col]
        for r in range(n):
            if r != col and M[r][col] != 0:
                f = M[r][col] / M[col][col]
                M[r] = [a - f * b for a, b in zip(M[r], M[col])]
    return [M[i][n] / M[i][i] for i in range(n)]


def _disparate_sets(seed, nb=2, n=3, m=9):
    """Sets whose states differ in scale by 1000x (as a robot's q and qd), with quadratic terms."""
    rng = np.random.default_rng(seed)
    scale = np.array([1e-2, 1.0, 10.0])[:n]
    C = rng.normal(size=(nb, n, m)) * scale[None, :, None]
    S = rng.normal(size=(nb, n, m, m)) * 0.05 * scale[None, :, None, None]
    S = 0.5 * (S + S.transpose(0, 1, 3, 2))
    w = rng.uniform(0.05, 1.0, m)
    return second_order_sets.QuadraticSets(c=rng.normal(size=(nb, n)), C=C, r0=Interval(-w * np.ones((nb, m)), w * np.ones((nb, m))),
                                   S=S, Q=np.broadcast_to(np.eye(n), (nb, n, n)).copy(),
                                   r=Interval(np.zeros((nb, n)), np.zeros((nb, n))))


def _merged_part_is_covered(s, merged, count, keep_first, rng, points=60):
    """Every point's merged part, C_S u_S plus each quadratic term with a merged parameter
    in it (exact rationals), is B beta with beta in the new parameters' box."""
    F = Fraction
    nb, n = s.c.shape
    m = s.C.shape[2]
    w = np.abs(s.C).sum(axis=1) * s.r0.width() + np.einsum("bijk,bk->bj", np.abs(s.S), s.r0.mag()) * s.r0.mag()
    w[:, :keep_first] = np.inf
    sel = set(np.sort(np.argsort(w.max(axis=0), kind="stable")[:count]).tolist())
    Bq, b = merged.C[:, :, -n:], merged.r0[:, -n:]
    for k in range(points):
        bb = int(rng.integers(nb))
        u = s.r0.lo[bb] + rng.uniform(0, 1, m) * s.r0.width()[bb]
        if k % 3 == 0:  # a vertex
            u = np.where(rng.uniform(size=m) < 0.5, s.r0.lo[bb], s.r0.hi[bb])
        uf = [F(float(x)) for x in u]
        v = []
        for i in range(n):
            t = sum(F(float(s.C[bb, i, j])) * uf[j] for j in sel)
            t += sum(F(float(s.S[bb, i, j, l])) * uf[j] * uf[l] for j in range(m) for l in range(m)
                     if j in sel or l in sel)
            v.append(t)
        beta = _solve_exact([[F(float(x)) for x in row] for row in Bq[bb]], v)
        for i in range(n):
            if not F(float(b.lo[bb, i])) <= beta[i] <= F(float(b.hi[bb, i])):
                return False
    return True


@pytest.mark.parametrize("scaled", [True, False])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_merging_covers_the_merged_parameters_and_their_quadratic_terms(monkeypatch, seed, scaled):
    """QuadraticSets.merge_params: the merged part (linear and every quadratic term with a
    merged parameter) lies in the new parameters' box, in the scaled basis as in the raw
    one; kept parameters, their quadratic block and the count are as documented."""
    monkeypatch.setattr(second_order_sets.QuadraticSets, "SCALED_MERGE", scaled)
    s = _disparate_sets(seed)
    merged = s.merge_params(5, keep_first=3)
    assert merged.C.shape == (2, 3, 9 - 5 + 3)
    np.testing.assert_array_equal(merged.C[:, :, :3], s.C[:, :, :3])
    assert _merged_part_is_covered(s, merged, 5, 3, np.random.default_rng(seed))


def test_merging_oracle_bites_when_the_quadratic_terms_are_dropped(monkeypatch):
    """The same check fails when merge_params leaves out the merged quadratic terms."""
    s = _disparate_sets(5)
    real = second_order_sets.quadratic_range

    def dropped(S, u):
        return real(np.zeros_like(S), u)

    monkeypatch.setattr(second_order_sets, "quadratic_range", dropped)
    merged = s.merge_params(5, keep_first=3)
    assert not _merged_part_is_covered(s, merged, 5, 3, np.random.default_rng(5), points=200)


def test_scaled_merge_does_not_smear_the_wide_states_into_the_narrow_one(monkeypatch):
    """Merged in a basis orthonormal in units of each state's extent, the narrow state
    (1000x narrower than the widest) keeps its width; the raw orthonormal basis mixes the
    wide states' range into it (3-link arm +- 0.01: q3 x3.4 against x1.2)."""
    s = _disparate_sets(2, nb=1)
    before = s.hull().width()[0]
    widths = {}
    for scaled in (True, False):
        monkeypatch.setattr(second_order_sets.QuadraticSets, "SCALED_MERGE", scaled)
        widths[scaled] = s.merge_params(5, keep_first=3).hull().width()[0]
    assert widths[True][0] < 0.5 * widths[False][0]  # (0.119 against 0.285)
    # the worst widening relative to each state's width is smaller too (1.5 against 3.3)
    assert (widths[True] / before).max() < (widths[False] / before).max()

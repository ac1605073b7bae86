"""The energy test on second-order sets (verified.sets.second_order.QuadraticSets with
solve(..., set_order=2, consistency=EnergyTest(...)); issues 13 and 17).

Oracles: exact rationals for the set algebra (mean-value columns, subdivision, the
appended energy state, the contraction's kept parameters); scipy DOP853 trajectories
(tests/oracles/sampling.py) for whole runs, with Pinocchio's aba as right-hand side
for the arm. Mutants that cut too far are caught on both levels.
"""
from __future__ import annotations

from fractions import Fraction as F

import numpy as np
import pytest

from oracles.mutants import keeps_lower_quarter
from oracles.sampling import misses, sample_initial_points, trajectories
from oracles.taylor_cases import ARM_Q0  # the arm_pin fixture: tests/verified/conftest.py
from verified.consistency import energy_contraction as ec
from verified.consistency.energy_test import EnergyTest
from verified.consistency.graphs import lift_graphs
from verified.consistency.energy_state import initial_sets
from verified.graph import trace
from verified.arith.interval import Interval
from verified.sets.second_order import QuadraticSets
from verified.solver import solve

from models import pendulum as pd


def _random_sets(seed, nb=3, n=2, m=3, scale=0.5):
    rng = np.random.default_rng(seed)
    S = rng.normal(size=(nb, n, m, m))
    S = 0.5 * (S + S.transpose(0, 1, 3, 2))
    return rng, QuadraticSets(c=rng.normal(size=(nb, n)), C=rng.normal(size=(nb, n, m)),
                              r0=Interval(-rng.uniform(0.1, scale, (nb, m)), rng.uniform(0.1, scale, (nb, m))), S=S,
                              Q=np.linalg.qr(rng.normal(size=(nb, n, n)))[0],
                              r=Interval(-rng.uniform(0, 0.1, (nb, n)), rng.uniform(0, 0.1, (nb, n))))


def _point(sets, b, u, e):
    """The point x(u, e) of set b, exact rationals."""
    n, m = sets.C.shape[1:]
    return [F(float(sets.c[b, i])) + sum(F(float(sets.C[b, i, j])) * F(float(u[j])) for j in range(m))
            + sum(F(float(sets.S[b, i, j, k])) * F(float(u[j])) * F(float(u[k])) for j in range(m) for k in range(m))
            + sum(F(float(sets.Q[b, i, k])) * F(float(e[k])) for k in range(n)) for i in range(n)]


def _sample(rng, iv, b):
    return iv.lo[b] + rng.uniform(0, 1, iv.shape[1]) * (iv.hi[b] - iv.lo[b])


def _in(x, box, b=0):
    return all(F(float(box.lo[b, i])) <= x[i] <= F(float(box.hi[b, i])) for i in range(len(x)))


# ----------------------------------------------------------------------------- set algebra
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_direction_columns_hold_the_exact_mean_value_columns(seed):
    """x(u, e) - c = (C + S u) u + Q e exactly, and C + S u lies in direction_columns."""
    rng, sets = _random_sets(seed)
    cols = sets.direction_columns()
    nb, n, m = sets.C.shape
    for b in range(nb):
        for _ in range(20):
            u, e = _sample(rng, sets.r0, b), _sample(rng, sets.r, b)
            x = _point(sets, b, u, e)
            A = [[F(float(sets.C[b, i, j])) + sum(F(float(sets.S[b, i, j, k])) * F(float(u[k])) for k in range(m))
                  for j in range(m)] + [F(float(sets.Q[b, i, k])) for k in range(n)] for i in range(n)]
            p = [F(float(v)) for v in u] + [F(float(v)) for v in e]
            for i in range(n):
                assert x[i] - F(float(sets.c[b, i])) == sum(A[i][j] * p[j] for j in range(m + n))
                assert all(F(float(cols.lo[b, i, j])) <= A[i][j] <= F(float(cols.hi[b, i, j])) for j in range(m + n))


@pytest.mark.parametrize("pieces", [2, 3])
def test_subdivided_parts_cover_the_set(pieces):
    """Every point of a set (parameter and error directions alike) lies in the hull of
    one of its parts, cut along the direction asked for; parts are set-major."""
    rng, sets = _random_sets(7)
    nb, n, m = sets.C.shape
    which = np.array([0, m + 1, 2])  # a parameter, an error component, a parameter
    out = sets.subdivide_along(which, pieces)
    assert out.n_sets == nb * pieces
    for b in range(nb):
        boxes = [out.take([b * pieces + k]).hull() for k in range(pieces)]
        for _ in range(30):
            x = _point(sets, b, _sample(rng, sets.r0, b), _sample(rng, sets.r, b))
            assert any(_in(x, bx) for bx in boxes)
        # cut along the direction asked for: that parameter's (or error's) interval
        # is 1/pieces as wide in every part (recentring adds only rounding)
        parts = out.take(list(range(b * pieces, (b + 1) * pieces)))
        R0, R = np.concatenate([sets.r0.width(), sets.r.width()], 1), np.concatenate([parts.r0.width(), parts.r.width()], 1)
        assert np.allclose(R[:, which[b]], R0[b, which[b]] / pieces, rtol=1e-9)


def _poly_energy():
    """H(x) = x0^2 + x0 x1 + 3 x1 (a polynomial: exact rationals check its values)."""
    rhs = trace(lambda x, p: [x[1], -x[0]], 2)
    H = trace(lambda x, p: [x[0] * x[0] + x[0] * x[1] + 3.0 * x[1]], 2)
    return rhs, H


def test_appended_energy_state_encloses_H_over_the_set():
    """h(0) = H(x0) for every point of a second-order set: the appended component
    c_h + C_h u + e_h (e_h in its error interval) holds H(x(u, e)) for the same u."""
    rhs, H = _poly_energy()
    rng, sets = _random_sets(11, scale=0.2)
    lifted = lift_graphs(rhs, rhs, 2, None, H, "derive", (), check_claim=False)
    out = initial_sets(lifted, sets)
    nb, n, m = sets.C.shape
    assert isinstance(out, QuadraticSets) and out.c.shape == (nb, n + 1) and out.C.shape == (nb, n + 1, m + 1)
    assert np.all(out.S[:, n] == 0) and np.array_equal(out.S[:, :n, :m, :m], sets.S)
    for b in range(nb):
        for _ in range(30):
            u, e = _sample(rng, sets.r0, b), _sample(rng, sets.r, b)
            x = _point(sets, b, u, e)
            Hx = x[0] * x[0] + x[0] * x[1] + 3 * x[1]
            base = F(float(out.c[b, n])) + sum(F(float(out.C[b, n, j])) * F(float(u[j])) for j in range(m))
            # Q's h row is (0, ..., 0, 1): e_h = H - base must lie in r_h
            assert F(float(out.r.lo[b, n])) <= Hx - base <= F(float(out.r.hi[b, n]))
            assert out.Q[b, n, n] == 1.0 and np.all(out.Q[b, n, :n] == 0)


def _bent_case():
    """States (x, h), residual x - h. x = u + u^2 / 2 over u in [-1, 1] (c = 0, C = 1,
    S = 1/2), h = 0.75 + e with e in [-0.25, 0.25]: the true states have x = h in
    [0.5, 1], i.e. u in [sqrt(2) - 1, sqrt(3) - 1] ~ [0.414, 0.732]."""
    res = trace(lambda z, p: [z[0] - z[1]], 2)
    S = np.zeros((1, 2, 2, 2))
    S[0, 0, 0, 0] = 0.5
    sets = QuadraticSets(c=np.array([[0.0, 0.75]]), C=np.array([[[1.0, 0.0], [0.0, 0.0]]]),
                         r0=Interval(np.array([[-1.0, 0.0]]), np.array([[1.0, 0.0]])), S=S,
                         Q=np.eye(2)[None].copy(), r=Interval(np.array([[0.0, -0.25]]), np.array([[0.0, 0.25]])))
    return res, sets


def _true_params(rng, k=200):
    """Parameters (u, 0, 0, e) of true states of the bent case, edges included."""
    us = np.concatenate([[np.sqrt(2) - 1, np.sqrt(3) - 1], rng.uniform(np.sqrt(2) - 1, np.sqrt(3) - 1, k)])
    return [(F(float(u)), F(float(u)) + F(float(u)) ** 2 / 2 - F(3, 4)) for u in us]


def test_contraction_of_a_bent_set_keeps_every_true_state_and_narrows():
    res, sets = _bent_case()
    out = ec.EnergyContraction(res).contract(sets)
    assert not out.empty.any() and out.ratio[0] < 0.8  # it narrows (u from width 2)
    R = out.params[0]  # (u, 0, 0, e) in the input parametrization
    # the row's column C + S u is [0.5, 1.5] over u in [-1, 1]: u narrows to [0, 1]
    # (rounding aside), around the true [0.414, 0.732]
    assert -1e-12 < R.lo[0] < 0.3 and 0.85 < R.hi[0] <= 1 + 1e-12
    rng = np.random.default_rng(0)
    X = out.sets.hull()
    for u, e in _true_params(rng):
        x = u + u * u / 2
        if not (F(1, 2) <= x <= 1 and -F(1, 4) <= e <= F(1, 4)):
            continue  # (a rounded edge sample outside the true range)
        assert F(float(R.lo[0])) <= u <= F(float(R.hi[0])) and F(float(R.lo[3])) <= e <= F(float(R.hi[3]))
        assert _in([x, x], X)
    # recentred: the parameter box holds 0 again
    assert (out.sets.r0.lo <= 0).all() and (out.sets.r0.hi >= 0).all()


def test_a_bent_set_contraction_that_cuts_too_far_is_caught(monkeypatch):
    """A contractor keeping the lower quarter of each narrowed component loses the true
    states near u = sqrt(3) - 1: the check above must see it."""
    monkeypatch.setattr(ec, "contract_linear_row", keeps_lower_quarter(ec.contract_linear_row))
    res, sets = _bent_case()
    R = ec.EnergyContraction(res).contract(sets).params[0]
    u = F(float(np.sqrt(3) - 1))
    assert not (F(float(R.lo[0])) <= u <= F(float(R.hi[0])))


# ----------------------------------------------------------------------------- whole runs
COMPOSITION = dict(set_order=2, set_step="composition", arithmetic="taylor_model", error_basis="auto")


def _pendulum():
    rhs = trace(pd.rhs, 2, input_names=["q", "qd"])
    H = trace(lambda x, p: [pd.hamiltonian(x)], 2, input_names=["q", "qd"])
    return rhs, H


def test_pendulum_second_order_with_the_energy_test_prunes_and_keeps_every_trajectory():
    """The paper's pendulum box to T = 0.3, the test (branch and prune at t*, 16
    parts per set, every consistent part kept): parts are pruned (measured 265), and
    every sampled trajectory stays inside."""
    rhs, H = _pendulum()
    lo, hi = pd.initial_box()
    test = EnergyTest(H, "derive", test_interval=0.1, test_splits=16, min_gain=0.0)
    sol = solve(rhs, Interval(lo, hi), (0.0, 0.3), t_eval=np.linspace(0.1, 0.3, 3), consistency=test,
                **COMPOSITION)
    assert sol.status == "completed" and sol.stats["tests"] > 0 and sol.stats["pruned_boxes"] > 0
    sols = trajectories(lambda x: pd.rhs(x), sample_initial_points(lo, hi, 20), 0.3)
    assert misses(sol, sols, per_step=2) == []


def test_a_pruning_test_that_drops_consistent_parts_is_caught(monkeypatch):
    """The same run with a test that also discards every cut part whose energy
    residual's enclosure is centred above 0 (consistent ones too): the sampling
    oracle must see states outside (so the test above can fail). (Measured: 49.)
    The mutant drops one part more than the real test; the step control's remainder
    cut is pinned at 1.2 (the default is 1.5), whose ten steps and five tests put the
    sampled trajectories through that part (with 1.5: five steps, three tests, and
    none goes through it; a mutant dropping every other part instead drops every set
    in the bisection and ends the run at the first test). The cut's share guard is off
    (``REMAINDER_SHARE = 0``, as when this was measured): with it the run takes four
    steps and no sampled trajectory passes the dropped part."""
    from verified.consistency import branch_prune as bp
    from verified.steppers.tm_flow import TaylorModelFlowStepper
    monkeypatch.setattr(TaylorModelFlowStepper, "REMAINDER_GROWTH", 1.2)
    monkeypatch.setattr(TaylorModelFlowStepper, "REMAINDER_SHARE", 0.0)
    real = bp.inconsistent

    def drops_more(checks):
        bad = real(checks)
        if bad.size == 1:  # (the set itself: dropping it would end the run at the test)
            return bad
        return bad | (checks[0][0].mid()[:, 0] > 0)

    monkeypatch.setattr(bp, "inconsistent", drops_more)
    rhs, H = _pendulum()
    lo, hi = pd.initial_box()
    test = EnergyTest(H, "derive", test_interval=0.1, test_splits=16, min_gain=0.0)
    sol = solve(rhs, Interval(lo, hi), (0.0, 0.3), t_eval=np.linspace(0.1, 0.3, 3), consistency=test,
                **COMPOSITION)
    sols = trajectories(lambda x: pd.rhs(x), sample_initial_points(lo, hi, 20), sol.t_reached)
    assert misses(sol, sols, per_step=2)


def test_arm_mode_ii_second_order_contains_pinocchio_trajectories(arm_pin):
    """3-link arm, q +- 1e-3, mode ii through simulate() with composition sets to
    T = 0.3: the energy state rides along, and Pinocchio-aba trajectories stay in
    every output box and the tube."""
    from mbs.simulate import simulate
    chain, _, qdd = arm_pin
    x0 = np.concatenate([ARM_Q0, np.zeros(3)])
    r = np.array([1e-3] * 3 + [0.0] * 3)
    lo, hi = x0 - r, x0 + r
    sol = simulate(chain, Interval(lo, hi), 0.3, mode="ii", output_dt=0.1, progress=False, order=8, tol=1e-10,
                   **COMPOSITION)
    assert sol.status == "completed" and sol.stats["contractions"] > 0 and sol.consistency is not None

    def f(x):
        return np.concatenate([x[3:], qdd(x[:3], x[3:])])

    sols = trajectories(f, np.unique(sample_initial_points(lo, hi, 12), axis=0), 0.3)
    assert misses(sol, sols, per_step=2) == []


def test_second_order_sets_refuse_what_they_cannot_do():
    rhs, H = _pendulum()
    lo, hi = pd.initial_box()
    with pytest.raises(ValueError, match="reset_h=True needs first-order sets"):
        solve(rhs, Interval(lo, hi), (0.0, 0.1), consistency=EnergyTest(H, "derive", reset_h=True), **COMPOSITION)
    with pytest.raises(ValueError, match="backward test.*needs first-order sets"):
        solve(rhs, Interval(lo, hi), (0.0, 0.1), consistency=EnergyTest(H, "derive", backward_depth=1),
              **COMPOSITION)


def test_contractions_back_off_where_they_narrow_nothing():
    """On second-order sets a contraction that narrowed nothing makes the next 1, 2,
    4, ... (at most 16) steps skip theirs; contract_backoff=0 contracts every step."""
    rhs, H = _pendulum()
    lo, hi = pd.initial_box()
    runs = {}
    for backoff in (None, 0):
        test = EnergyTest(H, "derive", prune=False, contract_backoff=backoff)
        sol = solve(rhs, Interval(lo, hi), (0.0, 0.5), consistency=test, **COMPOSITION)
        assert sol.status == "completed"
        runs[backoff] = sol.stats
    assert runs[None]["contractions_skipped"] > 0 and runs[0]["contractions_skipped"] == 0
    assert runs[None]["contractions"] + runs[None]["contractions_skipped"] == runs[0]["contractions"]
    with pytest.raises(ValueError, match="contract_backoff"):
        EnergyTest(H, "derive", contract_backoff=-1)


def test_symbols_are_ordered_by_the_steering_states():
    """set_models(..., steer=k) orders parameters and errors by their width in the
    first k states: a parameter (and an error) wide only in an appended state (h, in
    J) comes after the ones the states need, so the quadratic monomials go to those."""
    from verified.steppers.tm_flow import set_models
    nb, n, m = 1, 3, 3
    C = np.zeros((nb, n, m))
    C[0, 2, 0] = 50.0  # parameter 0: only in h
    C[0, 0, 1] = 1.0   # parameter 1: in the first state
    C[0, 1, 2] = 0.5   # parameter 2: in the second state
    Q = np.eye(n)[None].copy()
    r = Interval(-np.array([[1e-3, 2e-3, 1.0]]), np.array([[1e-3, 2e-3, 1.0]]))  # h's error the widest
    sets = QuadraticSets(c=np.zeros((nb, n)), C=C, r0=Interval(-np.ones((nb, m)), np.ones((nb, m))),
                         S=np.zeros((nb, n, m, m)), Q=Q, r=r)
    _, live_all, errors_all, _, _ = set_models(sets, 3)
    _, live, errors, _, _ = set_models(sets, 3, steer=2)
    assert live_all.tolist() == [0, 1, 2] and errors_all[0] == 2
    assert live.tolist() == [1, 2, 0] and errors.tolist() == [1, 0, 2]


def test_back_off_waits_1_2_4_up_to_its_cap_and_resets_on_a_gain():
    from verified.consistency.energy_test import BackOff
    b = BackOff(4)
    pattern = []
    for gained in (False, False, False, False, True):
        b.done(gained)
        skipped = 0
        while b.skip():
            skipped += 1
        pattern.append(skipped)
    assert pattern == [1, 2, 4, 4, 0]
    never = BackOff(0)
    never.done(False)
    assert not never.skip()


@pytest.mark.slow  # ~3 s: the default run's budget is tight (CI 168 s of 180)
def test_tests_back_off_where_they_prune_nothing():
    """The 3-link arm +- 1e-3 in mode ii's graphs, composition sets, T = 0.6: an RA
    peak that comes while the last test pruned nothing is passed by (test_backoff None
    = 16 on second-order sets; measured 6 tests, 1 passed by); test_backoff=0 tests at
    every peak (measured 7)."""
    from mbs.simulate import system_for
    from models.planar import planar_chain
    system = system_for(planar_chain(3), "ii")
    x0 = np.concatenate([ARM_Q0, np.zeros(3)])
    r = np.array([1e-3] * 3 + [0.0] * 3)
    stats = {}
    for backoff in (None, 0):
        # (the test kept on: with the default cadence it would step aside after two idle tests)
        test = EnergyTest(system.energy, system.energy_rate, test_backoff=backoff, suspend_after=0)
        sol = solve(system.rhs, Interval(x0 - r, x0 + r), (0.0, 0.6), consistency=test, order=8, tol=1e-10,
                    **COMPOSITION)
        assert sol.status == "completed"
        stats[backoff] = sol.stats
    assert stats[None]["tests_skipped"] > 0 and stats[0]["tests_skipped"] == 0
    assert stats[None]["tests"] < stats[0]["tests"] and stats[0]["pruned_boxes"] == 0
    with pytest.raises(ValueError, match="test_backoff"):
        EnergyTest(system.energy, "derive", test_backoff=1.5)


@pytest.mark.parametrize("kind", ["quadratic", "doubleton"])
def test_merging_keeps_the_parameters_the_steering_states_need(kind):
    """merge_params(..., steer=1) ranks parameters by their width in the first state
    only: the two that matter for h alone (row 2, in J) are merged, the two the state
    needs are kept; without steer it is the other way round. Either way the merged
    set still covers every point (the merge's own tests), so this is about tightness."""
    from verified.sets.first_order import DoubletonSets
    nb, n, m = 1, 2, 6
    C = np.array([[[1.0, 1.0, 1e-3, 1e-3, 1.0, 1.0], [0.0, 0.0, 100.0, 100.0, 0.0, 0.0]]])
    r0 = Interval(-np.ones((nb, m)), np.ones((nb, m)))
    r = Interval(np.zeros((nb, n)), np.zeros((nb, n)))
    if kind == "quadratic":
        sets = QuadraticSets(c=np.zeros((nb, n)), C=C, r0=r0, S=np.zeros((nb, n, m, m)), Q=np.eye(n)[None].copy(), r=r)
    else:
        sets = DoubletonSets(np.zeros((nb, n)), C, r0, np.eye(n)[None].copy(), r)
    kept_all = sets.merge_params(2, keep_first=2).C[0, :, :4]
    kept_steer = sets.merge_params(2, keep_first=2, steer=1).C[0, :, :4]
    assert np.array_equal(kept_all, C[0][:, [0, 1, 2, 3]])
    assert np.array_equal(kept_steer, C[0][:, [0, 1, 4, 5]])

"""Energy contraction of QR-Lohner sets (verified/consistency/energy_contraction.py), the per-set
RA(t) of eq. (16), and the check of declared energy rates (issue 13).

Soundness: sampled DOP853 trajectories stay inside every contracted enclosure (output
times and tube); the contraction must actually narrow something in those runs (else
the check proves nothing), and mutants that cut too far are caught: one ulp on a set
whose boundary point is known exactly, 20 % on a real run by the sampling oracle.
"""
import numpy as np
import pytest

from oracles.mutants import keeps_lower_quarter
from oracles.sampling import misses, sample_initial_points, trajectories
from verified.consistency import energy_contraction as ec
from verified.consistency.energy_test import EnergyClaimError, EnergyTest, prove_energy_rate
from verified.graph import trace
from verified.graph.ops import rate_along
from verified.arith.interval import Interval
from verified.sets.first_order import DoubletonSets
from verified.solver import solve

from models import double_pendulum as dp
from models import pendulum as pd


def _pendulum():
    rhs = trace(pd.rhs, 2, input_names=["q", "qd"])
    H = trace(lambda x, p: [pd.hamiltonian(x)], 2, input_names=["q", "qd"])
    return rhs, H


def _dp():
    rhs = trace(dp.rhs, 4, input_names=["x1", "x2", "x3", "x4"])
    H = trace(lambda x, p: [dp.hamiltonian(x)], 4, input_names=["x1", "x2", "x3", "x4"])
    return rhs, H


def _point_in_set(x, s: DoubletonSets, k=0):
    """x inside the hull of set k, exactly (no slack)."""
    X = s.hull()[k]
    return bool(np.all((X.lo <= x) & (x <= X.hi)))


def _param_in(p, R):
    return bool(np.all((R.lo <= p) & (p <= R.hi)))


# ----------------------------------------------------------------------------- unit
def _linear_case():
    """States (x, h), residual x - h; set x in [-1, 1] (r0), h in [0, 0.5] (r):
    x - h = 0 leaves x in [0, 0.5]; the point (0.5, 0.5) is a true state on the edge."""
    res = trace(lambda z, p: [z[0] - z[1]], 2)
    c = np.zeros((1, 2))
    eye = np.eye(2)[None]
    r0 = Interval(np.array([[-1.0, 0.0]]), np.array([[1.0, 0.0]]))
    r = Interval(np.array([[0.0, 0.0]]), np.array([[0.0, 0.5]]))
    return res, DoubletonSets(c, eye.copy(), r0, eye.copy(), r)


def test_linear_row_narrows_to_the_exact_edge_and_keeps_the_edge_point():
    res, s = _linear_case()
    out = ec.EnergyContraction(res).contract(s)
    R = out.params[0]  # (a_x, a_h, b_x, b_h)
    # the consistent range of x is [0, 0.5]; only the mean-value form's rounding is added
    assert -1e-14 < R.lo[0] <= 0.0 and 0.5 <= R.hi[0] < 0.5 + 1e-14
    # the true states (0.5, 0.5) and (0, 0): parameters a = (x, 0), b = (0, h)
    assert _param_in(np.array([0.5, 0.0, 0.0, 0.5]), R) and _param_in(np.array([0.0, 0.0, 0.0, 0.0]), R)
    X = out.sets.hull()[0]
    assert np.all(X.lo <= [0.0, 0.0]) and np.all(X.hi >= [0.5, 0.5]) and X.width()[0] < 0.5 + 1e-12
    assert out.ratio[0] < 0.5 and not out.empty.any()
    # recentred: 0 in r0 and r again (the Lohner step and merge need it)
    assert (out.sets.r0.lo <= 0).all() and (out.sets.r0.hi >= 0).all()
    assert (out.sets.r.lo <= 0).all() and (out.sets.r.hi >= 0).all()


def test_a_contractor_that_cuts_one_ulp_too_far_is_caught(monkeypatch):
    """The mutant cuts the narrowed upper end of x to one float below the true edge 0.5
    (the sound result lies a few ulps above it, the rounding of the mean-value form):
    the parameter of the true state (0.5, 0.5) leaves the box, and the check above sees it."""
    res, s = _linear_case()
    real = ec.contract_linear_row

    def one_ulp_too_far(a, g0, r, rem=0.0, **k):
        R, empty = real(a, g0, r, rem, **k)
        hi = R.hi.copy()
        hi[:, 0] = np.where(hi[:, 0] < r.hi[:, 0], np.nextafter(np.minimum(hi[:, 0], 0.5), -np.inf), hi[:, 0])
        return Interval._from_bounds(R.lo, hi), empty

    monkeypatch.setattr(ec, "contract_linear_row", one_ulp_too_far)
    out = ec.EnergyContraction(res).contract(s)
    assert not _param_in(np.array([0.5, 0.0, 0.0, 0.5]), out.params[0])


def test_an_inconsistent_set_is_dropped_and_a_consistent_one_kept():
    res, s = _linear_case()
    far = DoubletonSets(np.array([[5.0, 0.0]]), s.C, s.r0, s.Q, s.r)  # x in [4, 6], h in [0, 0.5]
    both = DoubletonSets.concatenate([s, far])
    out = ec.EnergyContraction(res).contract(both)
    assert out.empty.tolist() == [False, True] and out.sets.n_sets == 1


def test_recentre_covers_the_original_set():
    rng = np.random.default_rng(3)
    nb, n = 20, 3
    c = rng.normal(size=(nb, n))
    C = rng.normal(size=(nb, n, n))
    Q = np.linalg.qr(rng.normal(size=(nb, n, n)))[0]
    lo0 = rng.uniform(0.1, 1, (nb, n))
    r0 = Interval(lo0, lo0 + rng.uniform(0, 1, (nb, n)))  # excludes 0
    lo = -rng.uniform(0, 1, (nb, n)) * 1e-3
    r = Interval(lo, lo + rng.uniform(0, 2e-3, (nb, n)))
    out = ec.recentre(c, C, r0, Q, r)
    for _ in range(200):
        a = r0.lo + rng.uniform(0, 1, (nb, n)) * r0.width()
        b = r.lo + rng.uniform(0, 1, (nb, n)) * r.width()
        x = c + np.einsum("bij,bj->bi", C, a) + np.einsum("bij,bj->bi", Q, b)
        X = out.hull()
        assert np.all((X.lo - 1e-12 <= x) & (x <= X.hi + 1e-12))
    assert np.allclose(out.r0.mid(), 0, atol=1e-15)


# ----------------------------------------------------------------------------- oracle runs
def _check(sol, f, lo, hi, t_end, n_random=30):
    sols = trajectories(f, sample_initial_points(lo, hi, n_random), t_end)
    bad = misses(sol, sols, per_step=2)
    assert not bad, f"{len(bad)} sampled states outside, first at t = {bad[0][0]}"


def test_pendulum_contracted_every_step_keeps_every_sampled_trajectory():
    rhs, H = _pendulum()
    lo, hi = pd.initial_box()
    test = EnergyTest(H, "derive", contract="step", prune=False)
    # the QR-Lohner method (the default before method="auto"), whose sets the contraction narrows here
    sol = solve(rhs, Interval(lo, hi), (0.0, 1.0), t_eval=np.linspace(0.1, 1.0, 10), consistency=test,
                method="lohner")
    assert sol.status == "completed"
    assert sol.stats["contraction_ratio_min"] < 0.9  # the contraction bites: the check is meaningful
    _check(sol, lambda x: pd.rhs(x), lo, hi, 1.0)


@pytest.mark.parametrize("scale,t_end,pieces,bites", [
    pytest.param(1, 1.0, 64, True, marks=pytest.mark.slow),  # default-run budget (CI cold: 187 s of 180 at ec9790f)
    (10, 0.3, 16, False), (100, 0.1, 16, False)])
def test_double_pendulum_contracted_boxes_keep_every_sampled_trajectory(scale, t_end, pieces, bites):
    """Box (25) and boxes 10x and 100x as wide (around its centre), mode (iii)'s graphs.
    (On the wide boxes the contraction barely narrows: the mean-value remainder over a
    wide set swamps the row; the runs check that nothing true is lost.)"""
    rhs, H = _dp()
    lo0, hi0 = dp.initial_box()
    mid, rad = (lo0 + hi0) / 2, (hi0 - lo0) / 2
    lo, hi = mid - scale * rad, mid + scale * rad
    rate = trace(lambda x, p: [0.0 * x[0]], 4)  # conservative: the claim is checked too
    test = EnergyTest(H, rate, contract="step", prune=False)
    sol = solve(rhs, Interval(lo, hi), (0.0, t_end), t_eval=np.linspace(t_end / 4, t_end, 4),
                subdivision=[pieces, 1, 1, 1], consistency=test, method="lohner")  # (first-order sets' contraction)
    assert sol.t_reached > 0 and sol.stats["contractions"] > 0
    if bites:
        assert sol.stats["contraction_ratio_min"] < 0.97
    _check(sol, lambda x: dp.rhs(x), lo, hi, sol.t_reached, n_random=20)


@pytest.mark.slow  # default-run budget; the default run keeps the exact one-ulp bite above
def test_a_contraction_that_cuts_too_far_is_caught_by_the_sampling_oracle(monkeypatch):
    """The same run with a contractor keeping only the lower quarter of every narrowed component: the oracle must see sampled states outside (so the test above can fail)."""
    monkeypatch.setattr(ec, "contract_linear_row", keeps_lower_quarter(ec.contract_linear_row))
    rhs, H = _dp()
    lo, hi = dp.initial_box()
    test = EnergyTest(H, "derive", contract="step", prune=False)
    sol = solve(rhs, Interval(lo, hi), (0.0, 1.0), t_eval=np.linspace(0.25, 1.0, 4), subdivision=[64, 1, 1, 1],
                consistency=test, method="lohner")  # (the monkeypatched contraction is the first-order sets')
    sols = trajectories(lambda x: dp.rhs(x), sample_initial_points(lo, hi, 20), sol.t_reached)
    assert misses(sol, sols, per_step=2)


@pytest.mark.slow  # ~11 s: the default run's largest (keeps it under 3 min on CI's 2 cores)
def test_contraction_with_pruning_and_the_backward_test_is_sound():
    rhs, H = _pendulum()
    lo, hi = pd.initial_box()
    test = EnergyTest(H, "derive", contract="step", test_interval=0.1, test_splits=16, min_gain=0.0, backward_depth=1)
    # (the backward test runs on first-order sets: method="lohner")
    sol = solve(rhs, Interval(lo, hi), (0.0, 0.8), t_eval=np.linspace(0.1, 0.8, 8), consistency=test, method="lohner")
    assert sol.status == "completed" and sol.stats["tests"] > 0
    _check(sol, lambda x: pd.rhs(x), lo, hi, 0.8)


@pytest.mark.slow  # ~90 s: DOP853 over the numeric URDF model in Python
def test_damped_urdf_double_pendulum_mode_ii_contracted_and_sound():
    from mbs.simulate import simulate
    from models.robots import double_pendulum
    chain = double_pendulum()
    num = chain.numeric()
    lo = np.array([np.pi - 0.3, 0.0, 0.0, 0.0])
    hi = np.array([np.pi - 0.29, 0.0, 0.0, 0.0])
    sol = simulate(chain, Interval(lo, hi), 0.3, mode="ii", output_dt=0.1, subdivision=[4, 1, 1, 1],
                   progress=False)
    assert sol.status == "completed" and sol.stats["contractions"] > 0
    _check(sol, lambda x: num.rhs(list(x)), lo, hi, 0.3, n_random=12)


# ----------------------------------------------------------------------------- RA(t) per set
def test_ra_is_per_set_and_has_a_first_local_maximum_on_the_pendulum():
    rhs, H = _pendulum()
    lo, hi = pd.initial_box()
    test = EnergyTest(H, "derive", contract="off", test_interval=1.0, test_splits=16, min_gain=0.0)
    sol = solve(rhs, Interval(lo, hi), (0.0, 1.0), t_eval=[1.0], consistency=test)
    rec = sol.consistency
    assert rec.tests, "no test ran"
    t_star = rec.tests[0].t
    assert t_star < 1.0  # a local maximum, not the interval cap
    assert rec.tests[0].trigger == "RA maximum"
    k = int(np.searchsorted(rec.ra_t, t_star))
    assert rec.ra[k] >= rec.ra[max(k - 1, 0)] and rec.ra[k] > rec.ra[k + 1]
    # RA of one set never exceeds the width of that set's H_H (eq. (16))
    assert np.all(rec.ra <= rec.h_h_set.width() * (1 + 1e-12) + 1e-300)


def test_each_test_records_why_it_ran():
    """A test at a local maximum of RA says "RA maximum", one that ran because
    test_interval passed says "interval" (Fig. 2 draws them apart). One box, no
    contraction: RA peaks at the first step, is 0 from 0.24 s, so both kinds occur."""
    rhs, H = _pendulum()
    lo, hi = pd.initial_box()
    test = EnergyTest(H, "derive", contract="off", test_interval=0.1, test_splits=4)
    sol = solve(rhs, Interval(lo, hi), (0.0, 0.6), t_eval=[0.6], consistency=test, order=12, tol=1e-10)
    rec = sol.consistency
    assert {r.trigger for r in rec.tests} == {"RA maximum", "interval"}
    last = 0.0
    for r in rec.tests:
        k = int(np.argmin(np.abs(rec.ra_t - r.t)))
        assert abs(rec.ra_t[k] - r.t) < 1e-12
        if r.trigger == "RA maximum":
            assert rec.ra[k] > 0 and (k + 1 == rec.ra.size or rec.ra[k] > rec.ra[k + 1])
        else:
            assert r.t - last >= test.test_interval * (1 - 1e-12)
        last = r.t


# ----------------------------------------------------------------------------- declared claims
def test_a_false_conservative_claim_is_refused_before_the_first_step():
    rhs, _ = _pendulum()
    fake = trace(lambda x, p: [x[0] * x[1]], 2)
    lo, hi = pd.initial_box()
    with pytest.raises(EnergyClaimError, match="declared energy rate is wrong"):
        solve(rhs, Interval(lo, hi), (0.0, 0.4), consistency=EnergyTest(fake, "zero"))


def test_a_wrong_energy_rate_graph_is_refused():
    rhs, H = _pendulum()
    wrong = trace(lambda x, p: [0.01 * x[1] * x[1]], 2)  # claims a power input that is not there
    lo, hi = pd.initial_box()
    with pytest.raises(EnergyClaimError):
        solve(rhs, Interval(lo, hi), (0.0, 0.2), consistency=EnergyTest(H, wrong))


def test_a_claim_that_fails_only_later_is_caught_during_the_run():
    """The wrong rate is 0 at the initial centre, near 0 on the initial box, and wrong
    where the pendulum goes later."""
    rhs, H = _pendulum()
    wrong = trace(lambda x, p: [10.0 * (x[0] - 2.15) ** 3], 2)
    lo, hi = pd.initial_box()  # q in [2.1, 2.2], qd > 3: q moves away from 2.15
    with pytest.raises(EnergyClaimError, match=r"t = 0\.[0-9]"):
        solve(rhs, Interval(lo, hi), (0.0, 0.5), consistency=EnergyTest(H, wrong))


def test_true_claims_are_not_refused_and_sympy_proves_them():
    rhs, H = _pendulum()
    zero = trace(lambda x, p: [0.0 * x[0]], 2)
    lo, hi = pd.initial_box()
    sol = solve(rhs, Interval(lo, hi), (0.0, 0.3), consistency=EnergyTest(H, "zero"))
    assert sol.status == "completed"
    assert prove_energy_rate(rhs, H, None) and prove_energy_rate(rhs, H, zero)
    assert prove_energy_rate(rhs, H, rate_along(H, rhs))
    assert not prove_energy_rate(rhs, H, trace(lambda x, p: [0.01 * x[1] * x[1]], 2))


# ----------------------------------------------------------------------------- BlockBasis
def test_block_basis_keeps_the_states_enclosure_of_the_run_without_the_test():
    """With h in its own block of the error basis, the energy test's augmented run
    encloses the states exactly as the run without it (same steps); the contraction
    can then only narrow. Sound against the sampling oracle."""
    from verified.sets.bases import BlockBasis
    rhs, H = _dp()
    lo, hi = dp.initial_box()
    kw = dict(t_eval=[0.25, 0.5], subdivision=[16, 1, 1, 1], h_max=0.1)
    plain = solve(rhs, Interval(lo, hi), (0.0, 0.5), method="lohner", **kw)  # (the sets aug's are compared with)
    aug = solve(rhs, Interval(lo, hi), (0.0, 0.5), consistency=EnergyTest(H, "derive", contract="off", prune=False),
                error_basis=BlockBasis("qr", 4), **kw)
    assert plain.stats["steps"] == aug.stats["steps"]
    np.testing.assert_allclose(aug.hull.lo, plain.hull.lo, rtol=0, atol=1e-13)
    np.testing.assert_allclose(aug.hull.hi, plain.hull.hi, rtol=0, atol=1e-13)
    con = solve(rhs, Interval(lo, hi), (0.0, 0.5), consistency=EnergyTest(H, "derive", prune=False),
                error_basis=BlockBasis("qr", 4), **kw)
    assert (con.hull[-1].width() <= plain.hull[-1].width() * (1 + 1e-9)).all()
    _check(con, lambda x: dp.rhs(x), lo, hi, 0.5, n_random=10)

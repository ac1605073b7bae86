"""Declared invariants as contractors (verified.consistency.conservation, issue 43 item 2): proven or
refused, sound against dense scipy samples (mbs.app.sampling), and narrowing."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from mbs.app.sampling import dop853, radau
from verified.consistency.conservation import Conserved, InvariantHook, InvariantWarning, NonIncreasing
from verified.graph import trace
from verified.arith.interval import Interval
from verified.solver import solve

A, B, C = 0.4, 1e2, 1e3   # Robertson, the mildest ARCH-COMP setting


def _rob(x, p=None):
    return [-A * x[0] + B * x[1] * x[2], A * x[0] - B * x[1] * x[2] - C * x[1] * x[1], C * x[1] * x[1]]


def _pd(x, p):
    r = x[0] * x[1] / (1 + x[0])
    return [-r, r - p[0] * x[1], p[0] * x[1]]


ROB = trace(_rob, 3)
PD = trace(_pd, 3, 1)
SLACK = 1e-10


def _sum_width(sol, k=-1) -> float:
    """Width of x + y + z over the solver's sets at output k (their linear view)."""
    v = sol.views[k]
    sv = Interval(v.c, v.c).sum(axis=1) + (v.A.sum(axis=1) * v.R).sum(axis=1)
    return float(np.max(sv.hi) - np.min(sv.lo))


def _misses(sol, trajectories) -> int:
    """Sampled true states outside the union of the output boxes (every output time)
    and of the tube's boxes (three times inside every step)."""
    tt = np.asarray(sol.tube_t, float)
    steps = len(sol.tube)
    inner = (tt[:steps, None] + np.array([0.25, 0.5, 0.75])[None, :] * np.diff(tt)[:steps, None])
    bad = 0
    for s in trajectories:
        for k, t in enumerate(sol.t):
            bad += not _inside(s(float(t)), sol.boxes[k])
        for j in range(steps):
            bad += sum(not _inside(s(float(t)), sol.tube[j]) for t in inner[j])
    return bad


def _inside(x, boxes: Interval) -> bool:
    n = x.size
    tol = SLACK * (1 + np.abs(x))
    return bool(np.any(np.all((boxes.lo[:, :n] - tol <= x) & (x <= boxes.hi[:, :n] + tol), axis=1)))


def _robertson_run():
    x0 = Interval([1.0, 0.0, 0.0], [1.0, 0.0, 0.0])
    return solve(ROB, x0, (0.0, 0.5), method="lohner", t_eval=[0.25, 0.5], invariants=[Conserved([1, 1, 1])])


@pytest.fixture(scope="module")
def robertson_truth():
    r = radau(lambda t, x: np.array(_rob(x)), np.array([1.0, 0.0, 0.0]), 0.5, rtol=1e-12, atol=1e-20)
    return [lambda t, r=r: r.sol(t)]


def test_a_linear_invariant_is_imposed_on_the_sets_and_stays_sound(robertson_truth):
    x0 = Interval([1.0, 0.0, 0.0], [1.0, 0.0, 0.0])
    plain = solve(ROB, x0, (0.0, 0.5), method="lohner", t_eval=[0.25, 0.5])
    held = _robertson_run()
    assert plain.status == held.status == "completed"
    assert held.stats["invariant_projected"] >= 1
    # x + y + z over the sets: rounding-level with the invariant, the wrapping without
    assert _sum_width(held) < 1e-12 < 1e-3 * _sum_width(plain)
    assert held.hull[-1].width()[0] < plain.hull[-1].width()[0]
    assert _misses(held, robertson_truth) == 0


def _pd_run():
    x0 = Interval([9.9, 0.01, 0.01], [10.0, 0.01, 0.01])
    return solve(PD, x0, (0.0, 2.0), params=Interval([0.29], [0.31]), method="second_order", t_eval=[1.0, 2.0],
                 invariants=[Conserved([1, 1, 1])])


@pytest.fixture(scope="module")
def pd_truth():
    """12 DOP853 runs (rtol = atol = 1e-12) from random x(0) and a of the boxes of _pd_run."""
    rng = np.random.default_rng(3)
    runs = []
    for _ in range(12):
        x = np.array([rng.uniform(9.9, 10.0), 0.01, 0.01])
        p = [rng.uniform(0.29, 0.31)]
        r = dop853(lambda t, y, p=p: np.array(_pd(y, p)), x, 2.0, rtol=1e-12, atol=1e-12)
        runs.append(lambda t, r=r: r.sol(t))
    return runs


def test_production_destruction_with_an_uncertain_rate_is_sound(pd_truth):
    """Production-Destruction, x(0) and a both wide (a carried as a state): every sample
    lies in the contracted enclosure."""
    sol = _pd_run()
    assert sol.status == "completed"
    lo, hi = sol.stats["invariant_levels"]["'x0 + x1 + x2'"]
    assert lo <= 9.92 and 10.02 <= hi and hi - lo < 0.1 + 1e-9
    assert _misses(sol, pd_truth) == 0


def test_a_contractor_that_shrinks_too_much_is_caught(pd_truth, monkeypatch):
    """The oracle is strong enough to see a box contraction that cuts too much (each
    box halved about its middle: it still meets x + y + z = k, so the hook's own
    emptiness check cannot see it)."""
    import verified.consistency.conservation as cons
    real = cons.contract_linear_row

    def broken(*args, **kw):
        Yn, empty = real(*args, **kw)
        m, r = Yn.mid(), Yn.rad() * 0.5
        return Interval(m - r, m + r), empty
    monkeypatch.setattr(cons, "contract_linear_row", broken)
    sol = _pd_run()
    assert sol.stats["invariant_resets"] >= 1
    assert _misses(sol, pd_truth) > 0


def test_false_or_malformed_declarations_are_refused():
    x0 = Interval([1.0, 0.0, 0.0], [1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="not proven conserved"):
        solve(ROB, x0, (0.0, 0.1), invariants=[Conserved([1, 1, 0])])          # x + y is not conserved
    with pytest.raises(ValueError, match="not proven conserved"):
        solve(ROB, x0, (0.0, 0.1), invariants=[Conserved(lambda x, p: x[0] * x[0] + x[1] + x[2])])
    with pytest.raises(ValueError, match="2 weights for an ODE of 3 states"):
        solve(ROB, x0, (0.0, 0.1), invariants=[Conserved([1, 1])])
    with pytest.raises(ValueError, match="finite"):
        Conserved([1, np.nan, 1])
    with pytest.raises(ValueError, match="all 0"):
        Conserved([0, 0, 0])
    with pytest.raises(ValueError, match="1-D"):
        Conserved([[1, 1, 1]])
    with pytest.raises(ValueError, match="Conserved or NonIncreasing"):
        solve(ROB, x0, (0.0, 0.1), invariants=[[1, 1, 1]])
    with pytest.raises(ValueError, match="one value"):
        solve(ROB, x0, (0.0, 0.1), invariants=[Conserved(trace(lambda x, p: [x[0], x[1]], 3))])
    wrong_rate = trace(lambda x, p: [0.0 * x[0]], 3)
    with pytest.raises(ValueError, match="rate is not proven"):
        solve(ROB, x0, (0.0, 0.1), invariants=[NonIncreasing(lambda x, p: x[0], rate=wrong_rate)])


G_, D_ = 9.81, 0.5   # a damped pendulum: H = qd^2 / 2 + G (1 - cos q), dH/dt = -D qd^2


def _pend(x, p=None):
    return [x[1], -G_ * np.sin(x[0]) - D_ * x[1]]


PEND = trace(_pend, 2)
H_PEND = trace(lambda x, p: [0.5 * x[1] ** 2 + G_ * (1 - np.cos(x[0]))], 2)
RATE = trace(lambda x, p: [-D_ * x[1] ** 2], 2)


@pytest.fixture(scope="module")
def pendulum_truth():
    rng = np.random.default_rng(5)
    out = []
    for _ in range(10):
        x = np.array([rng.uniform(2.9, 3.0), rng.uniform(0.0, 0.1)])
        r = dop853(lambda t, y: np.array(_pend(y)), x, 1.0, rtol=1e-12, atol=1e-12)
        out.append(lambda t, r=r: r.sol(t))
    return out


def test_a_non_increasing_energy_with_a_proven_rate_holds_the_sets(pendulum_truth):
    box = Interval([2.9, 0.0], [3.0, 0.1])
    kw = dict(method="lohner", t_eval=[0.5, 1.0], max_width=1e6)
    plain = solve(PEND, box, (0.0, 1.0), **kw)
    held = solve(PEND, box, (0.0, 1.0), invariants=[NonIncreasing(H_PEND, rate=RATE, name="H")], **kw)
    assert held.stats["invariant_level_rise"] < 1e-9           # -D qd^2 <= 0 shown on every step
    assert held.stats["invariant_resets"] + held.stats["invariant_narrowed"] >= 1
    assert held.hull[-1].width()[1] < plain.hull[-1].width()[1]
    assert _misses(held, pendulum_truth) == 0


def test_a_false_non_increasing_claim_is_not_trusted(pendulum_truth):
    """-H rises along the damped pendulum: the check fails, the bound follows the
    enclosure (reported by a warning) and every sample stays inside."""
    box = Interval([2.9, 0.0], [3.0, 0.1])
    neg = trace(lambda x, p: [-(0.5 * x[1] ** 2 + G_ * (1 - np.cos(x[0])))], 2)
    with warnings.catch_warnings(record=True) as got:
        warnings.simplefilter("always")
        sol = solve(PEND, box, (0.0, 1.0), method="lohner", t_eval=[0.5, 1.0], max_width=1e6,
                    invariants=[NonIncreasing(neg, name="-H")])
    assert sol.stats["invariant_unverified_steps"] >= 1 and sol.stats["invariant_level_rise"] > 1
    assert [w.filename for w in got if issubclass(w.category, InvariantWarning)] == [__file__]  # (the caller's line)
    assert _misses(sol, pendulum_truth) == 0

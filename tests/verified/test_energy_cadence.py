"""The energy test steps aside while it gains nothing (verified.consistency.energy_cadence, issue 40).

The paper's pendulum swinging near the bottom: the test on second-order sets prunes
nothing, so the run drops ``h``, goes on without the test, and resumes it with ``h``
restarted from ``H`` over the sets. Oracle: DOP853 (rtol = atol = 1e-12) from sampled
initial points; every sampled state at every output must lie in the union of that
output's boxes, across every suspension and resumption. A cadence that loses part of
the sets where it drops ``h`` must fail that check.
"""
import numpy as np
import pytest
from mbs.app.sampling import dop853

import verified.consistency.energy_cadence as cadence
from models import pendulum as pd
from verified.consistency.energy_test import EnergyTest
from verified.graph import trace
from verified.arith.interval import Interval
from verified.methods import Composition, Lohner
from verified.driver.solution import Start
from verified.solver import solve

BOX = Interval([0.30, 0.0], [0.31, 0.01])
T_EVAL = np.linspace(0.0, 3.0, 31)


def _run(method=Composition(), **test_kw):
    rhs = trace(pd.rhs, 2, input_names=["q", "qd"])
    H = trace(lambda x, p: [pd.hamiltonian(x)], 2, input_names=["q", "qd"])
    test = EnergyTest(H, "derive", test_interval=0.1, **test_kw)
    return solve(rhs, BOX, (0.0, 3.0), method=method, t_eval=T_EVAL, consistency=test)


def _misses(sol, count=60, seed=5) -> int:
    rng = np.random.default_rng(seed)
    pts = np.concatenate([rng.uniform(BOX.lo, BOX.hi, (count, 2)),
                          np.array([[a, b] for a in (0.30, 0.31) for b in (0.0, 0.01)])])
    ys = np.array([dop853(lambda t, x: pd.rhs(x), p, 3.0, t_eval=T_EVAL, dense=False).y.T for p in pts])
    miss = 0
    for k, b in enumerate(sol.boxes):
        x = ys[:, k, :]
        lo, hi = np.asarray(b.lo), np.asarray(b.hi)
        inside = ((x[:, None, :] >= lo[None] - 1e-12) & (x[:, None, :] <= hi[None] + 1e-12)).all(axis=2).any(axis=1)
        miss += int((~inside).sum())
    return miss


def test_an_idle_test_is_suspended_and_resumed_and_loses_no_state():
    sol = _run()
    assert sol.status == "completed", sol.reason
    assert sol.stats["energy_test_phases"] >= 3  # on, off, on again (a probe)
    assert 0 < sol.stats["energy_test_off_s"] < 3.0
    assert list(sol.t) == list(T_EVAL) and np.all(np.diff(sol.tube_t) >= 0)
    # the record has the tests of every phase with the test on, in time order
    tests = [r.t for r in sol.consistency.tests]
    assert len(tests) >= 3 and tests == sorted(tests)
    assert _misses(sol) == 0


@pytest.mark.slow  # (default-run budget)
def test_suspend_after_0_keeps_the_test_on():
    sol = _run(suspend_after=0)
    assert sol.status == "completed" and "energy_test_phases" not in sol.stats
    assert _misses(sol) == 0


@pytest.mark.slow  # (default-run budget)
def test_first_order_sets_keep_the_test_on_by_default():
    sol = _run(method=Lohner(error_basis="auto"))
    assert "energy_test_phases" not in sol.stats


def test_a_cadence_that_loses_part_of_the_sets_is_caught(monkeypatch):
    """The oracle bites: dropping h while keeping only the middle of each set."""
    real = cadence.drop_appended

    def lossy(start, n_run):
        st = real(start, n_run)
        s = st.sets
        shrunk = type(s)(c=s.c, C=0.5 * s.C, r0=s.r0, S=0.25 * s.S, Q=s.Q, r=s.r * 0.5)
        return Start(sets=shrunk, t_exact=st.t_exact, h_limit=st.h_limit)
    monkeypatch.setattr(cadence, "drop_appended", lossy)
    sol = _run()
    assert sol.status == "completed" and sol.stats["energy_test_phases"] >= 2
    assert _misses(sol) > 0


def test_drop_appended_projects_the_sets():
    """Sampled points of a set with h mixed into its error basis, projected, lie in the
    set without h."""
    from verified.sets.second_order import QuadraticSets
    rng = np.random.default_rng(0)
    B, n, m = 3, 3, 3
    c = rng.normal(size=(B, n))
    C = rng.normal(size=(B, n, m))
    S = rng.normal(size=(B, n, m, m)) * 0.1
    S = S + S.transpose(0, 1, 3, 2)
    Q = rng.normal(size=(B, n, n))
    r0 = Interval(-np.ones((B, m)), np.ones((B, m)))
    r = Interval(-0.1 * np.ones((B, n)), 0.1 * np.ones((B, n)))
    full = QuadraticSets(c=c, C=C, r0=r0, S=S, Q=Q, r=r)
    from fractions import Fraction
    part = cadence.drop_appended(Start(sets=full, t_exact=Fraction(1)), 2).sets
    H = part.hull()
    for _ in range(200):
        u = rng.uniform(-1, 1, (B, m))
        e = rng.uniform(-0.1, 0.1, (B, n))
        x = c + np.einsum("bij,bj->bi", C, u) + np.einsum("bj,bijk,bk->bi", u, S, u) + np.einsum("bij,bj->bi", Q, e)
        assert np.all(x[:, :2] >= H.lo - 1e-12) and np.all(x[:, :2] <= H.hi + 1e-12)

"""Second-order sets advanced by composition in Taylor models (verified.steppers.tm_flow,
solve(..., set_order=2, set_step="composition")).

Oracles: the closed-form solution of x' = x^2; scipy DOP853 trajectories
(tests/oracles/sampling.py) for the pendulum, with Pinocchio's aba as right-hand side
for the 3-link arm; exact rationals for the models of a set.
"""
from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from oracles.sampling import misses, sample_initial_points, trajectories
from oracles.taylor_cases import ARM_Q0  # the arm_pin fixture: tests/verified/conftest.py
from verified.steppers import tm_flow
from verified.graph import trace
from verified.arith.interval import Interval
from verified.sets.second_order import QuadraticSets
from verified.solver import VerifiedODE, solve
from verified.series.taylor_model import TaylorModelODE, _pairs, _star_pairs, star_base

from models import pendulum as pd


def _riccati(x, p=()):
    return [x[0] * x[0]]


def _riccati_run(lo=0.5, hi=1.5, T=0.5, set_step="composition", **kw):
    return solve(trace(_riccati, 1), Interval([lo], [hi]), (0.0, T), t_eval=np.linspace(0, T, 6),
                 set_order=2, set_step=set_step, order=8, **kw)


def _riccati_exact(x0, t):
    return x0 / (1.0 - x0 * t)


@pytest.mark.parametrize("degree", [2, 3, 4])
def test_riccati_encloses_closed_form_and_beats_the_mean_value_step(degree):
    """x' = x^2 from [0.5, 1.5] to T = 0.5 (x(T) from 0.667 to 6, far from quadratic in
    x0): every output box holds the closed form at 41 initial points, and is narrower
    than the mean-value step's (measured at degree 2: 1.0002 / 1.002 / 1.010 / 1.036 /
    1.12 times the true width against 1.002 / 1.007 / 1.020 / 1.056 / 1.16)."""
    sol = _riccati_run(model_degree=degree)
    ref = _riccati_run(set_step="mean_value")
    assert sol.status == "completed", sol.reason
    x0 = np.linspace(0.5, 1.5, 41)
    ratios = []
    for t, boxes, other in zip(sol.t, sol.boxes, ref.boxes):
        x = _riccati_exact(x0, float(t))
        assert (boxes.lo[:, 0].min() <= x).all() and (x <= boxes.hi[:, 0].max()).all(), t
        width = boxes.hi[:, 0].max() - boxes.lo[:, 0].min()
        if t > 0:
            assert width < other.hi[:, 0].max() - other.lo[:, 0].min(), t
            ratios.append(width / (x.max() - x.min()))
    assert ratios[-1] < 1.13


@pytest.mark.parametrize("fresh", [False, True])
def test_oracle_bites_when_the_model_remainder_is_dropped(monkeypatch, fresh):
    """Drop the remainder of the composed models (the third- and higher-order terms and
    the rounding): the enclosure of x' = x^2 must miss the closed form. With fresh
    symbols the coefficients' remainders live in those symbols' coefficients: drop
    them as well."""
    monkeypatch.setattr(tm_flow.TaylorModelFlowStepper, "FRESH_SYMBOLS", fresh)
    real = tm_flow._horner_models
    real_run = TaylorModelODE._run

    def no_remainder(out, h):
        y = real(out, h)
        y[..., -1] = 0.0
        return y

    def no_fresh(self, X, P, order, m, *caps, fresh=False, pool=0, **pool_args):
        out = real_run(self, X, P, order, m, *caps, fresh=fresh, pool=pool, **pool_args)
        if fresh or pool:
            f0 = m - (self.n * order if fresh else 0) - pool
            out[..., 1 + f0: 1 + m] = 0.0
        return out

    monkeypatch.setattr(tm_flow, "_horner_models", no_remainder)
    monkeypatch.setattr(TaylorModelODE, "_run", no_fresh)
    sol = _riccati_run()
    x0 = np.linspace(0.5, 1.5, 41)
    missed = False
    for t, boxes in zip(sol.t, sol.boxes):
        x = _riccati_exact(x0, float(t))
        missed |= bool((x < boxes.lo[:, 0].min()).any() or (x > boxes.hi[:, 0].max()).any())
    assert missed


def _tube_misses(sol):
    """Closed-form states of x' = x^2 outside the tube boxes, at 3 times inside every step."""
    x0 = np.linspace(0.5, 1.5, 41)
    bad = 0
    for j, box in enumerate(sol.tube):
        for f in (0.25, 0.5, 0.75):
            t = sol.tube_t[j] + f * (sol.tube_t[j + 1] - sol.tube_t[j])
            x = _riccati_exact(x0, t)
            bad += int(((x < box.lo[:, 0].min()) | (x > box.hi[:, 0].max())).sum())
    return bad


def test_apriori_model_holds_the_solutions_and_the_oracle_bites(monkeypatch):
    """The a-priori enclosures (a model over the set and the step's time) hold the closed
    form inside every step; bounding the coefficients' spread over the set by 0 instead
    (a dropped term of the enclosure) must lose some of it."""
    sol = _riccati_run()
    assert sol.status == "completed" and _tube_misses(sol) == 0
    monkeypatch.setattr(tm_flow, "_spread_about", lambda rng, centre: np.zeros_like(centre))
    assert _tube_misses(_riccati_run()) > 0


def test_pendulum_composition_contains_trajectories():
    """The pendulum from a box 4x the paper's to T = 1.2: every sampled trajectory in every
    output box and tube box."""
    lo, hi = pd.initial_box()
    c = 0.5 * (lo + hi)
    lo, hi = c - 4 * (c - lo), c + 4 * (hi - c)
    T = 1.2
    sol = solve(trace(pd.rhs, 2), Interval(lo, hi), (0.0, T), t_eval=np.linspace(0, T, 7), set_order=2,
                set_step="composition")
    assert sol.status == "completed", sol.reason
    sols = trajectories(lambda x: pd.rhs(x), sample_initial_points(lo, hi, 30), T)
    assert misses(sol, sols) == []


@pytest.mark.parametrize("quadratic_cap,star_cap", [(3, 0), (2, 0), (2, 1), (1, 1)])
def test_set_models_enclose_the_set(quadratic_cap, star_cap):
    """The degree-2 models of a set (parameters and error part as symbols) hold the set's
    points: exact rationals at random parameter and error values. The last parameter is
    1e-13 as wide as the others: bounded into the remainder, linear and quadratic terms
    (without that bound the check fails). With fewer quadratic symbols than parameters,
    the pairs past the cap are bounded, or kept as star monomials (``star_cap``)."""
    rng = np.random.default_rng(3)
    nb, n, m = 2, 3, 4
    c = rng.normal(size=(nb, n))
    C = rng.normal(size=(nb, n, m))
    S = rng.normal(size=(nb, n, m, m)) * 0.3
    S = 0.5 * (S + S.transpose(0, 1, 3, 2))
    C[:, :, :-1] *= 1e4
    C[:, :, -1] *= 1e-9
    S[:, :, -1, :] *= 1e-9
    S[:, :, :, -1] *= 1e-9
    Q = np.linalg.qr(rng.normal(size=(nb, n, n)))[0]
    r0 = Interval(-rng.uniform(0.1, 1, (nb, m)), rng.uniform(0.1, 1, (nb, m)))
    r = Interval(-rng.uniform(0, 0.1, (nb, n)), rng.uniform(0, 0.1, (nb, n)))
    sets = QuadraticSets(c=c, C=C, r0=r0, S=S, Q=Q, r=r).recentred()
    X, live, errors, rho, caps = tm_flow.set_models(sets, quadratic_cap=quadratic_cap, star_cap=star_cap)
    mq = caps.mq
    M = live.size + n
    assert m - 1 not in live and live.size == m - 1
    assert (mq, caps.ms, caps.ns) == (quadratic_cap, star_cap, M - mq)
    pi, pj = _pairs(mq)
    si, sj = _star_pairs(M, mq, caps.ms, caps.ns)
    sb = star_base(M, mq, caps.m3, caps.m4)
    if star_cap:
        assert np.abs(X[:, :, sb: -1]).max() > 0  # the star holds some of S
    F = Fraction
    for _ in range(30):
        b = int(rng.integers(nb))
        u = sets.r0.lo[b] + rng.uniform(0, 1, m) * (sets.r0.hi[b] - sets.r0.lo[b])
        e = sets.r.lo[b] + rng.uniform(0, 1, n) * (sets.r.hi[b] - sets.r.lo[b])
        # the symbols that give this point: u = rho eps, r = mid r + rad r delta
        eps = [F(float(u[j])) / F(float(rho[b, j])) for j in live]
        rm, rr = sets.r.mid()[b], sets.r.rad()[b]
        delta = [(F(float(e[i])) - F(float(rm[i]))) / F(float(rr[i])) if rr[i] > 0 else F(0) for i in range(n)]
        sym = eps + [delta[k] for k in errors]
        for i in range(n):
            x = (F(float(sets.c[b, i])) + sum(F(float(sets.C[b, i, j])) * F(float(u[j])) for j in range(m))
                 + sum(F(float(sets.S[b, i, j, k])) * F(float(u[j])) * F(float(u[k]))
                       for j in range(m) for k in range(m))
                 + sum(F(float(sets.Q[b, i, k])) * F(float(e[k])) for k in range(n)))
            mod = X[i, b]
            val = F(float(mod[0])) + sum(F(float(mod[1 + s])) * sym[s] for s in range(M))
            val += sum(F(float(mod[M + 1 + k])) * sym[a] * sym[bb] for k, (a, bb) in enumerate(zip(pi, pj)))
            val += sum(F(float(mod[sb + k])) * sym[a] * sym[bb] for k, (a, bb) in enumerate(zip(si, sj)))
            assert abs(x - val) <= F(float(mod[-1])), (b, i)


@pytest.mark.parametrize("degree", [3, 4])
def test_arm_composition_contains_pinocchio_trajectories(arm_pin, degree):
    """3-link arm, q +- 1e-3, T = 0.2: DOP853 trajectories with Pinocchio's aba as
    right-hand side in every output box and the tube, in models of degree 3 and 4."""
    chain, g, qdd = arm_pin
    x0 = np.concatenate([ARM_Q0, np.zeros(3)])
    r = np.array([1e-3] * 3 + [0.0] * 3)
    lo, hi = x0 - r, x0 + r
    sol = solve(VerifiedODE(g, "affine"), Interval(lo, hi), (0.0, 0.2), t_eval=[0.1, 0.2], set_order=2,
                set_step="composition", order=8, model_degree=degree)
    assert sol.success, sol.reason

    def f(x):
        return np.concatenate([x[3:], qdd(x[:3], x[3:])])

    sols = trajectories(f, np.unique(sample_initial_points(lo, hi, 12), axis=0), 0.2)
    assert misses(sol, sols, per_step=2) == []


def test_set_step_arguments_are_checked():
    g = trace(_riccati, 1)
    with pytest.raises(ValueError, match="set_step must be"):
        solve(g, Interval([0.5], [0.6]), (0.0, 0.1), set_order=2, set_step="taylor")
    with pytest.raises(ValueError, match="needs set_order=2"):
        solve(g, Interval([0.5], [0.6]), (0.0, 0.1), set_step="composition")
    with pytest.raises(ValueError, match="model_degree must be 2, 3 or 4"):
        solve(g, Interval([0.5], [0.6]), (0.0, 0.1), set_order=2, set_step="composition", model_degree=5)
    with pytest.raises(ValueError, match="model_degree is not a setting of method 'second_order'"):
        solve(g, Interval([0.5], [0.6]), (0.0, 0.1), set_order=2, model_degree=3)


@pytest.mark.slow
def test_ur5_degree_three_contains_pinocchio_trajectories():
    """UR5 (example-robot-data, no damping), q0 +- 1e-3, qd = 0, T = 0.15: the composition
    in degree-3 models on the numeric model's right-hand side (mode i), absorbing at 1 %
    (6 states or more): DOP853 trajectories with Pinocchio's aba as right-hand side in
    every output box and the tube."""
    import pinocchio as pin

    from mbs.pinocchio_check import _QMap
    from mbs.simulate import system_for
    from models.robots import ur5

    chain = ur5()
    model = chain.to_pinocchio()
    data = model.createData()
    qm = _QMap(chain, model)
    zero = np.zeros(chain.n)

    def f(x):
        q, qd = x[:6], x[6:]
        return np.concatenate([qd, qm.back(pin.aba(model, data, qm.q(q), qm.v(qd), qm.v(zero)).copy())])

    x0 = np.r_[0.0, -1.0, 1.0, -0.5, 0.5, 0.0, np.zeros(6)]
    r = np.r_[np.full(6, 1e-3), np.zeros(6)]
    lo, hi = x0 - r, x0 + r
    sol = solve(VerifiedODE(system_for(chain, "i").rhs, "taylor_model"), Interval(lo, hi), (0.0, 0.15),
                t_eval=[0.05, 0.1, 0.15], set_order=2, set_step="composition", model_degree=3,
                error_basis="auto", order=8, params_per_state=12)
    assert sol.status == "completed", sol.reason
    sols = trajectories(f, np.unique(sample_initial_points(lo, hi, 12), axis=0), 0.15)
    assert misses(sol, sols, per_step=2) == []


def _fold_misses(fold):
    """Points of random models over 3 + 4 symbols (the last 4 fresh: linear only) outside
    the folded models' ranges over the first 3, evaluated exactly at random symbol values
    (the fresh ones at +-1 as well)."""
    rng = np.random.default_rng(5)
    M, M_all, mq = 3, 7, 2
    L = tm_flow.model_length(M_all, mq)
    X = rng.normal(size=(2, 4, L))
    X[..., -1] = np.abs(X[..., -1]) * 1e-3
    folded = fold(X, M, M_all)
    lo, hi = tm_flow.models_to_interval(folded, M, mq)
    pi, pj = _pairs(mq)
    F = Fraction
    bad = 0
    for _ in range(40):
        e = list(rng.uniform(-1, 1, M)) + list(rng.choice([-1.0, 1.0], M_all - M))
        for a in range(2):
            for b in range(4):
                x = X[a, b]
                v = F(float(x[0])) + sum(F(float(x[1 + s])) * F(float(e[s])) for s in range(M_all))
                v += sum(F(float(x[M_all + 1 + k])) * F(float(e[i])) * F(float(e[j])) for k, (i, j) in enumerate(zip(pi, pj)))
                r = F(float(x[-1]))  # the remainder at either end
                bad += int(not (F(float(lo[a, b])) <= v - r and v + r <= F(float(hi[a, b]))))
    return bad


def test_folding_fresh_symbols_keeps_the_range_and_the_oracle_bites():
    """fold_symbols (the fresh symbols bounded into the remainder for the a-priori test):
    the folded models' ranges hold the models' values at any value of the fresh symbols;
    a fold that drops them without the bound must miss some."""
    assert _fold_misses(tm_flow.fold_symbols) == 0
    assert _fold_misses(lambda X, M, M_all: np.concatenate([X[..., : M + 1], X[..., M_all + 1:]], axis=-1)) > 0


@pytest.mark.slow
def test_arm_composition_past_the_old_break_down_with_fresh_symbols_and_star(arm_pin):
    """The 3-link arm, q0 +- 1e-3, to T = 1.5 (bench_robots.py case 8's setting): it broke
    down at 1.27 s before fresh symbols and star monomials (1.34 s with fresh symbols
    alone), and without fresh symbols it took ~10x the steps (4814 against 507 to T = 2).
    Required: completes in fewer than 1000 steps, every DOP853 trajectory with Pinocchio's
    aba inside every output box and the tube."""
    chain, g, qdd = arm_pin
    x0 = np.concatenate([ARM_Q0, np.zeros(3)])
    r = np.array([1e-3] * 3 + [0.0] * 3)
    lo, hi = x0 - r, x0 + r
    T = 1.5
    sol = solve(VerifiedODE(g, "taylor_model"), Interval(lo, hi), (0.0, T), t_eval=np.linspace(0, T, 7),
                set_order=2, set_step="composition", order=8, tol=1e-10, error_basis="auto", params_per_state=12)
    assert sol.success, sol.reason
    assert sol.stats["steps"] < 1000, sol.stats["steps"]

    def f(x):
        return np.concatenate([x[3:], qdd(x[:3], x[3:])])

    sols = trajectories(f, np.unique(sample_initial_points(lo, hi, 12), axis=0), T)
    assert misses(sol, sols, per_step=2) == []


def _random_tube(rng, n, nb, M, mq, centre, lin=1e-3, quad=3e-4, rem=2e-2):
    """Random models (n, nb, L) over M symbols (mq quadratic) about ``centre``, with a
    per-state remainder ``rem`` wider than their linear part (as an a-priori box is)."""
    L = tm_flow.model_length(M, mq)
    X = np.zeros((n, nb, L))
    X[:, :, 0] = np.asarray(centre)[:, None]
    X[:, :, 1: M + 1] = rng.uniform(-lin, lin, (n, nb, M))
    X[:, :, M + 1: -1] = rng.uniform(-quad, quad, (n, nb, L - M - 2))
    X[:, :, -1] = rem * rng.uniform(0.5, 1.0, (n, nb))
    return X


def _tube_check(order=6, seed=3, _forms=tm_flow.models_to_forms):
    """tube_coefficients over random tubes about the paper's double pendulum's box,
    checked against exact (arb) coefficients at points of the tube (remainder extremes
    included: tests/oracles/arb_series.check_series_contains)."""
    from oracles.arb_series import check_series_contains
    from models import double_pendulum as dp
    g = trace(dp.rhs, 4)
    rng = np.random.default_rng(seed)
    lo, hi = dp.initial_box()
    M, mq = 5, 3
    tube = _random_tube(rng, 4, 2, M, mq, 0.5 * (lo + hi))
    forms = _forms(tube, M, mq)  # (the oracle's points: the real conversion, bound before any patch)
    C = tm_flow.tube_coefficients(TaylorModelODE(g), tube, M, mq, order, quadratic_cap=4, cubic_cap=2)
    assert np.isfinite(C.lo).all() and np.isfinite(C.hi).all()
    check_series_contains(g, forms, C, order, n_random=6, seed=seed)
    return C


def test_tube_coefficients_contain_exact_coefficients_and_the_oracle_bites(monkeypatch):
    """The a-priori test's x_[0..K] over a tube (verified.steppers.tm_flow.tube_coefficients, each
    state's remainder on a symbol of its own) hold the exact coefficients at points of
    the tube; dropping the remainder on its way to those symbols must be caught."""
    _tube_check()
    real = tm_flow.models_to_forms

    def no_remainder(X, M, mq):
        F = real(X, M, mq)
        F[..., -1] = 0.0
        return F

    monkeypatch.setattr(tm_flow, "models_to_forms", no_remainder)
    with pytest.raises(AssertionError, match="outside"):
        _tube_check()


def test_tube_coefficients_are_tighter_than_affine_over_a_tube():
    """Over a tube whose remainder is wide, the remainder on symbols of its own keeps
    x_[K] narrower than affine arithmetic over the same forms (the reason the a-priori
    test uses them: Panda +- 1e-3, 140x at order 8)."""
    from models import double_pendulum as dp
    from verified.series.affine_taylor import AffineTaylorODE
    g = trace(dp.rhs, 4)
    rng = np.random.default_rng(3)
    lo, hi = dp.initial_box()
    M, mq, K = 5, 3, 6
    tube = _random_tube(rng, 4, 2, M, mq, 0.5 * (lo + hi))
    C = tm_flow.tube_coefficients(TaylorModelODE(g), tube, M, mq, K)
    A = AffineTaylorODE(g).series(tm_flow.models_to_forms(tube, M, mq), K)
    assert (C[:, K].width() < 0.5 * A[:, K].width()).all(), (C[:, K].width(), A[:, K].width())


def test_tube_coefficients_with_graph_parameters_contain_exact_coefficients():
    """A graph with parameters (a damped pendulum x'' = -k sin x - d x' with k, d in
    boxes): tube_coefficients takes the parameter box as intervals; the exact
    coefficients at sampled points of the tube and of the parameter box are inside."""
    from oracles.arb_series import check_series_contains

    def damped(x, p):
        return [x[1], -p[0] * np.sin(x[0]) - p[1] * x[1]]

    g = trace(damped, 2, 2)
    rng = np.random.default_rng(7)
    M, mq, K = 4, 2, 6
    tube = _random_tube(rng, 2, 2, M, mq, [0.8, -0.3], lin=2e-3, quad=5e-4, rem=1e-2)
    plo, phi = np.array([9.5, 0.1]), np.array([10.0, 0.2])
    C = tm_flow.tube_coefficients(TaylorModelODE(g), tube, M, mq, K, Interval(plo, phi)[None, :])
    check_series_contains(g, tm_flow.models_to_forms(tube, M, mq), C, K, plo, phi, n_random=6, seed=7)
    with pytest.raises(ValueError, match="parameters"):
        tm_flow.tube_coefficients(TaylorModelODE(g), tube, M, mq, K, None)


@pytest.mark.slow
def test_four_link_chain_to_one_second_with_more_monomials():
    """The planar 4-link chain, q0 +- 1e-3, to T = 1 with solve(model_caps={"quadratic": 32,
    "cubic": 16}) (the default caps break down at 0.95 s): completed, and every trajectory
    sampled with Pinocchio's aba (DOP853) is inside at every output time and in the tube."""
    import pinocchio as pin

    from mbs.pinocchio_check import _QMap
    from mbs.simulate import system_for
    from models.planar import planar_chain

    chain = planar_chain(4)
    q0 = np.array([0.5, -0.3, 0.2, -0.3])
    lo = np.r_[q0 - 1e-3, np.zeros(4)]
    hi = np.r_[q0 + 1e-3, np.zeros(4)]
    sol = solve(system_for(chain, "i").rhs, Interval(lo, hi), (0.0, 1.0), t_eval=np.linspace(0, 1, 21), order=8,
                tol=1e-10, error_basis="auto", set_order=2, set_step="composition", arithmetic="taylor_model",
                params_per_state=12, model_caps={"quadratic": 32, "cubic": 16})
    assert sol.status == "completed", sol.reason
    model = chain.to_pinocchio()
    data = model.createData()
    qm = _QMap(chain, model)

    def f(x):
        q, qd = x[:4], x[4:]
        return np.r_[qd, qm.back(pin.aba(model, data, qm.q(q), qm.v(qd), qm.v(np.zeros(4))))]

    sols = trajectories(f, sample_initial_points(lo, hi, 12), 1.0)
    assert misses(sol, sols) == []


def test_an_uncertain_frequency_does_not_cut_the_steps_to_nothing(monkeypatch):
    """x' = p y, y' = -p x, p in [0.95, 1.05] (carried in the models), x(0) in 1 +- 1e-3,
    y(0) = 0: the powers of p make the coefficients' remainders grow combinatorially with
    the order, and the growth cut of ``suggest_step`` alone held the steps near 1e-4 s.
    With ``REMAINDER_SHARE`` it stops once a step adds less than that share of the set's
    width: T = 5 in a few dozen steps, and every closed-form state (x0 cos pt, -x0 sin pt)
    is inside at every output. Unguarded, the same run does not get past t = 0.5 in 400 steps."""
    from verified.methods import Composition
    from verified.solver import solve

    g = trace(lambda x, p: [p[0] * x[1], -p[0] * x[0]], 2, 1)
    x0, P = Interval([1.0 - 1e-3, 0.0], [1.0 + 1e-3, 0.0]), Interval([0.95], [1.05])
    t_eval = np.linspace(0.0, 5.0, 11)
    sol = solve(g, x0, (0.0, 5.0), params=P, method=Composition(), t_eval=t_eval, max_steps=400)
    assert sol.status == "completed" and sol.stats["steps"] < 100, sol.reason
    a, p = np.meshgrid(np.linspace(1.0 - 1e-3, 1.0 + 1e-3, 5), np.linspace(0.95, 1.05, 41))
    a, p = a.ravel(), p.ravel()
    for k, t in enumerate(np.asarray(sol.t, float)):
        states = np.c_[a * np.cos(p * t), -a * np.sin(p * t)]
        box = sol.hull[k]
        assert (states >= np.asarray(box.lo) - 1e-12).all() and (states <= np.asarray(box.hi) + 1e-12).all(), t
    monkeypatch.setattr(tm_flow.TaylorModelFlowStepper, "REMAINDER_SHARE", 0.0)
    stalled = solve(g, x0, (0.0, 5.0), params=P, method=Composition(), max_steps=400)
    assert stalled.status == "breakdown" and stalled.t_reached < 0.5

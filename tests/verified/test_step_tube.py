"""The composition step's tube (:func:`verified.steppers.tm_flow.step_tube`): a box per step,
inside the a-priori enclosure, that holds every solution from the sets over the whole
step, checked against dense DOP853 trajectories at times inside every step."""

import numpy as np

from mbs.app.sampling import dop853
from verified.steppers import tm_flow
from verified.graph import trace
from verified.arith.interval import Interval
from verified.solver import solve


def _vdp(x, p):
    return [x[1], (1 - x[0] * x[0]) * x[1] - x[0]]


def _run(x0: Interval, T: float):
    return solve(trace(_vdp, 2, 0), x0, (0.0, T), method="composition")


def _tube_misses(sol, x0: Interval, T: float, per_step: int = 9) -> int:
    """Sampled states (a 3 x 3 grid of the initial box, DOP853 at rtol 1e-12) outside the
    step's tube box at ``per_step`` times strictly inside every step."""
    trajs = [dop853(lambda t, x: np.array(_vdp(x, None), float), np.array([a, b]), T).sol
             for a in np.linspace(x0.lo[0], x0.hi[0], 3) for b in np.linspace(x0.lo[1], x0.hi[1], 3)]
    bad = 0
    for j, box in enumerate(sol.tube):
        t0, t1 = float(sol.tube_t[j]), float(sol.tube_t[j + 1])
        for f in np.linspace(0.0, 1.0, per_step + 2)[1:-1]:
            X = np.stack([tr(t0 + f * (t1 - t0)) for tr in trajs])   # (samples, n)
            inside = np.all((X[:, None] >= box.lo[None] - 1e-10) & (X[:, None] <= box.hi[None] + 1e-10), axis=2)
            bad += int((~inside.any(axis=1)).sum())
    return bad


def _without_step_tube(monkeypatch):
    """The tube as before: the a-priori enclosure alone."""
    def everything(out, cE, h_top, M, mq, pieces=tm_flow.TUBE_PIECES):
        B, n = cE.shape[0], cE.shape[2]
        return Interval._from_bounds(np.full((B, n), -np.inf), np.full((B, n), np.inf))
    monkeypatch.setattr(tm_flow, "step_tube", everything)


def test_the_step_tube_holds_the_solutions_and_is_narrower_than_the_apriori_enclosure(monkeypatch):
    """Van der Pol from the ARCH-COMP box to T = 7: every sample in the tube at 9 times
    inside each step; the tube's max of y is below the a-priori enclosures' (2.97 before)."""
    x0 = Interval([1.25, 2.35], [1.55, 2.45])
    sol = _run(x0, 7.0)
    assert sol.status == "completed" and _tube_misses(sol, x0, 7.0) == 0
    narrow = float(np.max(sol.tube_hull.hi[:, 1]))
    with monkeypatch.context() as m:
        _without_step_tube(m)
        wide = _run(x0, 7.0)
    assert len(wide.tube) == len(sol.tube)   # (the same steps: only the tube differs)
    assert narrow < float(np.max(wide.tube_hull.hi[:, 1])) - 0.05
    for a, b in zip(sol.tube, wide.tube):
        assert np.all(a.lo >= b.lo) and np.all(a.hi <= b.hi)


def _oscillator_misses(sol, x0: Interval, per_step: int = 9) -> int:
    """Closed-form states of x' = y, y' = -x (x = a cos t + b sin t, y = b cos t - a sin t)
    from a 5 x 5 grid of the initial box outside the step's tube box at ``per_step``
    times strictly inside every step."""
    a, b = (v.ravel() for v in np.meshgrid(np.linspace(x0.lo[0], x0.hi[0], 5), np.linspace(x0.lo[1], x0.hi[1], 5)))
    bad = 0
    for j, box in enumerate(sol.tube):
        t0, t1 = float(sol.tube_t[j]), float(sol.tube_t[j + 1])
        for t in t0 + np.linspace(0.0, 1.0, per_step + 2)[1:-1] * (t1 - t0):
            X = np.stack([a * np.cos(t) + b * np.sin(t), b * np.cos(t) - a * np.sin(t)], axis=1)
            inside = np.all((X[:, None] >= box.lo[None] - 1e-12) & (X[:, None] <= box.hi[None] + 1e-12), axis=2)
            bad += int((~inside.any(axis=1)).sum())
    return bad


def test_the_oracle_bites_when_the_motion_between_the_points_is_dropped(monkeypatch):
    """The harmonic oscillator from a small box to T = 6 (its peaks fall inside steps):
    the tube holds the closed form; a tube made of the sets at the step's two ends only
    (their hull, without the bound between them) misses the curvature at the peaks, and
    the closed form must catch it."""
    g = trace(lambda x, p: [x[1], -x[0]], 2, 0)
    x0 = Interval([1.0 - 1e-4, -1e-4], [1.0 + 1e-4, 1e-4])
    sol = solve(g, x0, (0.0, 6.0), method="composition")
    assert sol.status == "completed" and _oscillator_misses(sol, x0) == 0

    def ends_only(out, cE, h_top, M, mq, pieces=tm_flow.TUBE_PIECES):
        K = out.shape[1]
        tube = None
        for tau in (0.0, h_top):
            x = tm_flow._model_ranges(tm_flow._horner_models(np.ascontiguousarray(out), tau), M, mq) \
                + cE[:, K] * Interval(tau) ** K
            tube = x if tube is None else tube.hull(x)
        return tube
    monkeypatch.setattr(tm_flow, "step_tube", ends_only)
    broken = solve(g, x0, (0.0, 6.0), method="composition")
    assert broken.status == "completed" and _oscillator_misses(broken, x0) > 0

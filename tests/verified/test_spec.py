"""``method=Auto(spec=...)``: bounds on states over the whole run that ``auto`` works to
prove (:mod:`verified.spec`, :func:`verified.auto.spec_proof._prove_spec`).

Van der Pol (mu = 1) from x in [1.25, 1.55], y in [2.35, 2.45] (the ARCH-COMP box): x
rises to about 2.124 at t = 0.55 and falls back; over [0, 1.5] the plain run's tube
reaches 2.127, so ``x <= 2.126`` is true but not proven without refining, and
``x <= 2`` is false between the output times 0 and 1.5 (x is 1.55 and 1.69 there).
"""

import numpy as np
import pytest

import verified.spec as spec_mod
from mbs.app.sampling import dop853
from verified.graph import trace
from verified.arith.interval import Interval
from verified.methods import Auto
from verified.solver import solve
from verified.spec import Bounds

X0 = Interval([1.25, 2.35], [1.55, 2.45])


def _vdp(x, p):
    return [x[1], (1 - x[0] * x[0]) * x[1] - x[0]]


def _graph():
    return trace(_vdp, 2, 0)


def _samples(T, k=5):
    """Dense DOP853 trajectories (rtol 1e-12) from a k x k grid of the initial box."""
    out = []
    for a in np.linspace(1.25, 1.55, k):
        for b in np.linspace(2.35, 2.45, k):
            out.append(dop853(lambda t, x: np.array(_vdp(x, None), float), np.array([a, b]), T).sol)
    return out


def _assert_sound(sol, state: int, bound: float, T: float):
    """Where the spec ``x_state <= bound`` is claimed proven: every sampled trajectory
    keeps below it at 4001 times in [0, T] (not only the output times) and lies in the
    tube's boxes there."""
    if not sol.spec_proven:
        return
    ts = np.linspace(0.0, T, 4001)
    tt = np.asarray(sol.tube_t)
    j = np.clip(np.searchsorted(tt, ts, side="right") - 1, 0, len(sol.tube) - 1)
    X = np.stack([traj(ts).T for traj in _samples(T)], axis=1)   # (times, samples, n)
    assert np.all(X[..., state] <= bound + 1e-9), f"a proven spec is violated: {X[..., state].max()} > {bound}"
    for step in np.unique(j):
        box, P = sol.tube[step], X[j == step].reshape(-1, X.shape[-1])
        inside = np.all((P[:, None] >= box.lo[None] - 1e-9) & (P[:, None] <= box.hi[None] + 1e-9), axis=2)
        assert inside.any(axis=1).all(), f"a sample outside the tube on step {step}"


def test_a_spec_the_plain_run_does_not_prove_is_proven_and_holds():
    g = _graph()
    plain = solve(g, X0, (0.0, 1.5))
    assert plain.spec_proven is None and float(np.max(plain.tube_hull.hi[:, 0])) > 2.126
    sol = solve(g, X0, (0.0, 1.5), method=Auto(spec=Bounds({"x0": (None, 2.126)})))
    assert sol.status == "completed" and sol.spec_proven and sol.stats["spec"] == "proven"
    assert sol.spec_check.worst <= 0 and float(np.max(sol.tube_hull.hi[:, 0])) <= 2.126
    assert sol.stats["spec_rounds"] >= 1 and "spec x0 <= 2.126: proven" in sol.method
    assert any("spec round 1" in e.get("spec", "") for e in sol.method_log)
    _assert_sound(sol, 0, 2.126, 1.5)


def test_a_false_spec_is_reported_false_not_proven():
    """x <= 2 holds at both output times (x = 1.55, 1.69) but not at t = 0.55."""
    sol = solve(_graph(), X0, (0.0, 1.5), t_eval=[0.0, 1.5], method=Auto(spec={0: (None, 2.0)}))
    assert float(np.max(sol.hull.hi[:, 0])) < 2.0   # (the outputs alone would pass)
    assert sol.spec_check.status == "false" and sol.spec_proven is False
    t, x = sol.spec_check.witness
    assert 0.3 < t < 0.8 and x[0] > 2.1
    assert sol.stats["spec_rounds"] == 0 and "false" in sol.method


def test_a_check_from_the_output_times_only_would_be_caught(monkeypatch):
    """A check that read the output boxes instead of the tube claims x <= 2 proven;
    the samples between the outputs catch it."""
    def outputs_only(sol, lo, hi, t0, t1, names):
        ok = bool(np.all(np.asarray(sol.hull.hi) <= hi) and np.all(np.asarray(sol.hull.lo) >= lo))
        return spec_mod.SpecCheck("proven" if ok else "not proven", 0.0, "", "outputs only")

    monkeypatch.setattr(spec_mod, "check_tube", outputs_only)
    sol = solve(_graph(), X0, (0.0, 1.5), t_eval=[0.0, 1.5], method=Auto(spec={0: (None, 2.0)}))
    assert sol.spec_proven   # (the broken check claims it)
    with pytest.raises(AssertionError, match="proven spec is violated"):
        _assert_sound(sol, 0, 2.0, 1.5)


def test_van_der_pol_arch_spec_is_proven_by_splitting():
    """The ARCH-COMP spec y < 2.75 over [0, 7]: one piece's tube reaches 2.99; auto splits."""
    sol = solve(_graph(), X0, (0.0, 7.0), method=Auto(spec={"x1": (None, 2.75)}))
    assert sol.spec_proven and float(np.max(sol.tube_hull.hi[:, 1])) < 2.75
    assert sol.stats["auto_pieces"] > 1 and "split" in sol.method
    _assert_sound(sol, 1, 2.75, 7.0)


@pytest.mark.parametrize("spec, message", [
    ({"z": (None, 1.0)}, "unknown state 'z' (states: x0, x1)"),
    ({5: (None, 1.0)}, "state index 5 out of range"),
    ({"x0": (None, 1.0), 0: (0.0, None)}, "state 'x0' is given twice"),
])
def test_specs_that_do_not_fit_the_ode_are_refused_before_any_work(spec, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")) as e:
        solve(_graph(), X0, (0.0, 1.0), method=Auto(spec=spec))
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("spec, message", [
    ({"x0": (3.0, 2.0)}, "auto: spec: the bounds of 'x0' are empty: lo = 3 > hi = 2"),
    ({"x0": (float("nan"), 2.0)}, "auto: spec: lower bound of 'x0' is NaN"),
    ({"x0": (None, None)}, "auto: spec: 'x0' has no bound"),
    ({"x0": 2.0}, "auto: spec: the bounds of 'x0' must be a pair"),
    ({-1: (None, 2.0)}, "auto: spec: a state is a name or an index >= 0"),
    ({}, "auto: spec: Bounds needs at least one state"),
    ("x0 < 2", "auto: spec must be None, a verified.spec.Bounds or a dict"),
])
def test_bad_specs_are_refused_in_one_line(spec, message):
    with pytest.raises(ValueError) as e:
        Auto(spec=spec)
    assert str(e.value).startswith(message) and "\n" not in str(e.value)


def test_bounds_are_a_method_setting():
    a = Auto(spec={"x1": (None, 2.75)})
    assert a == Auto(spec=Bounds(x1=(None, 2.75))) and hash(a) == hash(Auto(spec=Bounds(x1=(None, 2.75))))
    assert a.describe() == "auto(spec=Bounds({'x1': (None, 2.75)}))"
    lo, hi = a.spec.resolve(("x0", "x1"))
    assert np.all(lo == -np.inf) and hi[0] == np.inf and hi[1] == 2.75


def test_the_tube_rows_are_told_apart_by_piece_and_restricted_exactly():
    """The pieces kept and the pieces split must be told apart exactly (soundness rests
    on it): x's peak rises with x(0), so the piece with the largest x(0) has the largest
    excess; the restricted runs' boxes together are the run's boxes."""
    from verified.auto import spec_proof
    sol = solve(_graph(), X0, (0.0, 1.5), subdivision=[4, 1])
    pieces = sol.boxes[0]
    lo, hi = np.array([-np.inf, -np.inf]), np.array([2.0, np.inf])
    pe = spec_proof._piece_excess(sol, 4, lo, hi, pieces)
    assert pe is not None and list(np.argsort(pe)) == [0, 1, 2, 3]
    assert spec_proof._piece_excess(sol, 4, lo, hi, pieces[::-1]) is None   # (rows not in the pieces' order)
    keep = pe < pe.max()
    a, b = spec_proof._restrict(sol, keep), spec_proof._restrict(sol, ~keep)
    for j, box in enumerate(sol.tube):
        assert np.array_equal(np.r_[a.tube[j].hi, b.tube[j].hi], box.hi[np.r_[np.flatnonzero(keep), 3]])

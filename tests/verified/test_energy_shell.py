"""The energy shell as a solver hook (:mod:`verified.consistency.energy_shell`): the paper's
pendulum over the top, one box, held inside ``H <= hmax`` -- bounded where the plain
run grows to widths of thousands, sampled trajectories (DOP853) inside every output box
and the tube, and a shell that cuts too far is caught by the samples."""

from __future__ import annotations

import numpy as np
import pytest

from oracles.sampling import misses, sample_initial_points, trajectories
from verified.consistency.contractor import EnergyShell
from verified.consistency.energy_shell import EnergyShellHook, max_energy
from verified.graph import trace
from verified.arith.interval import Interval
from verified.solver import solve

from models import pendulum as pd

T = 2.4  # the plain run's qd enclosure passes the shell's bound (+-6.5) at ~1.6 s


def _shell():
    M = trace(lambda q, p: [q[0] * 0.0 + pd.M * pd.L ** 2], 1)
    V = trace(lambda q, p: [pd.M * pd.G * pd.L * (1.0 - np.cos(q[0]))], 1)
    return EnergyShell(M, V)


def _hmax(lo, hi):
    return max_energy(trace(lambda x, p: [pd.hamiltonian(x)], 2), Interval(lo, hi))


def _run(hooks, T=T, **kw):
    lo, hi = pd.initial_box()
    return solve(trace(pd.rhs, 2), Interval(lo, hi), (0.0, T), t_eval=np.linspace(0, T, 13), error_basis="auto",
                 max_width=1e6, hooks=hooks, **kw)


SECOND_ORDER = dict(set_order=2, set_step="composition", arithmetic="taylor_model", order=12, tol=1e-10)


@pytest.fixture(scope="module")
def samples():
    lo, hi = pd.initial_box()
    return trajectories(lambda x: pd.rhs(x), sample_initial_points(lo, hi, 40), T)


def test_max_energy_bounds_the_initial_energy():
    lo, hi = pd.initial_box()
    hmax = _hmax(lo, hi)
    x = sample_initial_points(lo, hi, 200)
    H = 0.5 * x[:, 1] ** 2 + pd.G * (1 - np.cos(x[:, 0]))
    assert H.max() <= hmax < H.max() + 1.0  # measured 21.17 against 20.70


@pytest.mark.slow  # 5 s; tests/mbs/test_simulate_energy_options.py holds the pendulum in the shell by default
def test_pendulum_over_the_top_held_in_the_shell(samples):
    lo, hi = pd.initial_box()
    hook = EnergyShellHook(_shell(), _hmax(lo, hi))
    held = _run([hook])
    plain = _run([])
    assert held.status == "completed", held
    assert held.stats["shell_resets"] >= 1
    assert misses(held, samples, per_step=2) == []
    # |qd| <= sqrt(2 hmax / (m l^2)) = 6.5: the shell holds qd; the plain run does not
    vmax = np.sqrt(2 * _hmax(lo, hi))
    assert held.hull[-1].width()[1] <= 2 * vmax * 1.01 / hook.cut  # (reset once cut below hook.cut)
    assert held.hull[-1].width()[1] < 0.5 * plain.hull[-1].width()[1]


@pytest.mark.slow  # 4 s
def test_second_order_sets_are_held_in_the_shell(samples):
    """Second-order sets by composition: reset sets become fresh second-order sets
    with the batch's parameter count; every sampled trajectory stays inside (outputs
    and tube), and qd is narrower than without the shell."""
    lo, hi = pd.initial_box()
    hook = EnergyShellHook(_shell(), _hmax(lo, hi))
    held = _run([hook], **SECOND_ORDER)
    plain = _run([], **SECOND_ORDER)
    assert held.status == "completed", held
    assert held.stats["shell_resets"] >= 1
    assert misses(held, samples, per_step=2) == []
    assert held.hull[-1].width()[1] < 0.7 * plain.hull[-1].width()[1]


@pytest.mark.slow  # 4 s
def test_oracle_bites_when_a_second_order_reset_keeps_too_little(samples, monkeypatch):
    """A reset that keeps the middle 80 % of the contracted box's parameters must
    lose sampled trajectories."""
    from verified.sets.second_order import QuadraticSets
    real = QuadraticSets.replaced

    def shrunk(self, idx, part):
        return real(self, idx, QuadraticSets(c=part.c, C=part.C, r0=part.r0 * 0.8, S=part.S, Q=part.Q, r=part.r))
    monkeypatch.setattr(QuadraticSets, "replaced", shrunk)
    lo, hi = pd.initial_box()
    held = _run([EnergyShellHook(_shell(), _hmax(lo, hi))], **SECOND_ORDER)
    assert misses(held, samples, per_step=2) != []


def test_quadratic_sets_with_params_and_replaced_are_exact():
    from verified.sets.second_order import QuadraticSets
    rng = np.random.default_rng(3)
    lo = rng.normal(size=(3, 2))
    sets = QuadraticSets.from_boxes(Interval(lo, lo + 0.5))
    sets = QuadraticSets(c=sets.c, C=sets.C, r0=sets.r0, S=rng.normal(size=(3, 2, 2, 2)) * 0.01, Q=sets.Q,
                         r=sets.r)
    wide = sets.with_params(5)
    assert wide.C.shape == (3, 2, 5) and wide.S.shape == (3, 2, 5, 5) and wide.r0.shape == (3, 5)
    # the same sets: the hull may only gain the rounding of the added zero terms
    assert (wide.hull().lo <= sets.hull().lo).all() and (wide.hull().hi >= sets.hull().hi).all()
    assert np.allclose(wide.hull().lo, sets.hull().lo, rtol=1e-14, atol=0)
    assert np.allclose(wide.hull().hi, sets.hull().hi, rtol=1e-14, atol=0)
    box = Interval(np.array([[10.0, 20.0]]), np.array([[11.0, 22.0]]))
    out = wide.replaced(np.array([1]), QuadraticSets.from_boxes(box).with_params(5))
    h = out.hull()
    assert (h.lo[1] <= box.lo[0]).all() and (h.hi[1] >= box.hi[0]).all()
    assert np.allclose(h.lo[1], box.lo[0]) and np.allclose(h.hi[1], box.hi[0])
    for k in (0, 2):  # the others untouched
        assert np.array_equal(h.lo[k], wide.hull().lo[k]) and np.array_equal(h.hi[k], wide.hull().hi[k])
    with pytest.raises(ValueError, match="fewer"):
        wide.with_params(2)


@pytest.mark.slow  # 3 s: the default run stays under 3 minutes
def test_oracle_bites_when_the_shell_cuts_too_far(samples, monkeypatch):
    """A shell whose velocity bound is 5 % too small (6.2 against the true 6.43 at the
    bottom) must lose sampled trajectories."""
    lo, hi = pd.initial_box()
    real = EnergyShell.ellipsoid_bound

    def tight(self, boxes, hmax, params=None, *, pieces=256):
        b = real(self, boxes, hmax, params, pieces=pieces)
        return np.where(b > 0, b * 0.95, b)
    monkeypatch.setattr(EnergyShell, "ellipsoid_bound", tight)
    held = _run([EnergyShellHook(_shell(), _hmax(lo, hi), cut=0.9)])
    assert misses(held, samples, per_step=2) != []


def test_sets_inside_the_shell_are_left_and_the_rest_contracted_as_alone():
    """One after_step on a batch: sets whose hull lies inside the shell (H over the hull
    <= hmax: no contraction can cut them) come back unchanged, the others exactly as the
    shell contracts their hull alone (replaced when cut to less than half, dropped when
    outside)."""
    from types import SimpleNamespace

    from verified.sets.first_order import DoubletonSets
    sh = _shell()
    hmax = 20.0  # |qd| <= sqrt(40) = 6.32 at q = 0
    boxes = Interval(np.array([[0.0, 1.0], [0.0, -30.0], [3.0, 0.0], [0.0, 5.0]]),
                     np.array([[0.1, 1.1], [0.1, 30.0], [3.1, 0.1], [0.1, 9.0]]))
    sets = DoubletonSets.from_boxes(boxes)
    hook = EnergyShellHook(sh, hmax)
    stopped = []
    out = hook.after_step(SimpleNamespace(t=0.1), sets, SimpleNamespace(stop=lambda *a: stopped.append(a)))
    alone = sh.contract(boxes, hmax, pieces=hook.pieces)
    # set 0 inside (kept as is), set 1 cut to |qd| <= 6.32 (replaced), set 2 near the top
    # (V = 19.5, H <= 19.53: inside), set 3 partly outside (cut)
    assert not stopped
    assert not alone.empty.any()
    kept = np.flatnonzero(~alone.empty)
    assert out.n_sets == kept.size
    h = out.hull()
    for j, i in enumerate(kept):
        cut = (alone.boxes.width()[i] < hook.cut * boxes.width()[i]).any()
        want = alone.boxes[i] if cut else boxes[i]
        assert (h.lo[j] <= want.lo + 1e-12).all() and (h.hi[j] >= want.hi - 1e-12).all()
        assert (h.width()[j] <= want.width() * (1 + 1e-9) + 1e-12).all()
    assert hook.resets >= 1  # set 1 at least


def test_bad_shell_arguments():
    lo, hi = pd.initial_box()
    sh = _shell()
    with pytest.raises(ValueError, match="hmax must be a finite number"):
        EnergyShellHook(sh, float("nan"))
    with pytest.raises(ValueError, match="cut must be in"):
        EnergyShellHook(sh, 30.0, cut=0.0)
    with pytest.raises(TypeError, match="EnergyShell"):
        EnergyShellHook("shell", 30.0)
    with pytest.raises(ValueError, match="outside the energy shell"):
        _run([EnergyShellHook(sh, 10.0)], T=0.1)  # the box's energy is 19.6-20.7 J
    # between the box's smallest and largest energy (19.57 / 20.70 J): the shell cuts
    # the box's q (to q <= 2.14) instead of emptying it -- the run would lose true states
    with pytest.raises(ValueError, match="cuts initial box 0"):
        _run([EnergyShellHook(sh, 19.9)], T=0.1)
    # the same mistake from a shell whose V has another zero than the H that hmax came
    # from (0.8 J here; the chain's pivot zero against eq. (19)'s bottom zero is 9.81 J)
    V_shifted = trace(lambda q, p: [pd.M * pd.G * pd.L * (1.0 - np.cos(q[0])) + 0.8], 1)
    with pytest.raises(ValueError, match="cuts initial box 0"):
        _run([EnergyShellHook(EnergyShell(sh.M_graph, V_shifted), _hmax(lo, hi))], T=0.1)
    with pytest.raises(ValueError, match="one value"):
        max_energy(trace(pd.rhs, 2), Interval(lo, hi))

"""Boxes from the energy bound after a break-down (:mod:`verified.consistency.shell_boxes`): the
paper's pendulum over the top, made to break down early (a small ``max_width``), carried
on to T by the shell; every sampled trajectory (DOP853, rtol 1e-13) inside the outputs
and the tube, a too-small speed bound caught by the samples, wrong claims refused."""

from __future__ import annotations

import numpy as np
import pytest
from oracles.sampling import misses, sample_initial_points, trajectories

import verified.consistency.shell_boxes as sb
from models import pendulum as pd
from verified.consistency.contractor import EnergyShell
from verified.consistency.energy_shell import max_energy
from verified.graph import trace
from verified.arith.interval import Interval
from verified.consistency.shell_boxes import continue_in_shell, min_value
from verified.solver import solve

T = 3.0
T_EVAL = np.linspace(0.0, T, 16)
C = np.array([1.0 / (pd.M * pd.L ** 2)])  # (M^-1)_11, exact for the pendulum
TWO_PI = np.array([2 * np.pi])


def _shell():
    M = trace(lambda q, p: [q[0] * 0.0 + pd.M * pd.L ** 2], 1)
    V = trace(lambda q, p: [pd.M * pd.G * pd.L * (1.0 - np.cos(q[0]))], 1)
    return EnergyShell(M, V)


@pytest.fixture(scope="module")
def broken():
    lo, hi = pd.initial_box()
    sol = solve(trace(pd.rhs, 2), Interval(lo, hi), (0.0, T), t_eval=T_EVAL, max_width=0.5, method="lohner")
    assert sol.status == "breakdown" and 0 < sol.t_reached < 1.0
    hmax = max_energy(trace(lambda x, p: [pd.hamiltonian(x)], 2), Interval(lo, hi))
    return sol, hmax


@pytest.fixture(scope="module")
def samples():
    lo, hi = pd.initial_box()
    return trajectories(lambda x: pd.rhs(x), sample_initial_points(lo, hi, 30), T, rtol=1e-13, atol=1e-13)


def test_carried_on_to_T_and_every_sample_inside(broken, samples):
    sol, hmax = broken
    out = continue_in_shell(sol, _shell(), hmax, C, T_EVAL, T, periods=TWO_PI)
    assert out.status == "completed" and out.t_reached == T
    assert out.stats["shell_from"] == sol.t_reached and "broke down" in out.reason
    assert len(out.t) == len(T_EVAL) and out.tube_t[-1] == T and len(out.tube) == len(out.tube_t) - 1
    assert all(np.isfinite(b.lo).all() and np.isfinite(b.hi).all() for b in out.boxes + out.tube)
    # |qd| <= sqrt(2 hmax / (m l^2)) (V >= 0): 6.5 rad/s here
    assert out.stats["shell_speed"][0] <= np.sqrt(2 * hmax / (pd.M * pd.L ** 2)) * (1 + 1e-9)
    assert misses(out, samples, per_step=6) == []
    assert sol.status == "breakdown"  # the argument is left as it was


def test_a_too_small_speed_bound_is_caught_by_the_samples(broken, samples, monkeypatch):
    sol, hmax = broken
    real = sb.speed_bound
    monkeypatch.setattr(sb, "speed_bound", lambda *a, **k: 0.5 * real(*a, **k))
    out = continue_in_shell(sol, _shell(), hmax, C, T_EVAL, T, periods=TWO_PI)
    assert len(misses(out, samples, per_step=6)) > 0


def test_wrong_claims_are_refused(broken):
    sol, hmax = broken
    with pytest.raises(ValueError, match="below"):
        continue_in_shell(sol, _shell(), hmax, 0.5 * C, T_EVAL, T)
    with pytest.raises(ValueError, match="not periodic"):
        continue_in_shell(sol, _shell(), hmax, C, T_EVAL, T, periods=[3.0])
    with pytest.raises(ValueError, match="finite"):
        continue_in_shell(sol, _shell(), float("inf"), C, T_EVAL, T)
    with pytest.raises(ValueError, match="no speed bound"):
        continue_in_shell(sol, _shell(), hmax, [np.inf], T_EVAL, T)


def test_a_completed_run_is_returned_as_it_is():
    lo, hi = pd.initial_box()
    sol = solve(trace(pd.rhs, 2), Interval(lo, hi), (0.0, 0.1), method="lohner")
    assert continue_in_shell(sol, _shell(), 100.0, C, None, 0.1) is sol


def test_min_value_bounds_below_and_is_close():
    V = trace(lambda q, p: [q[0] * q[0] - q[0] * q[1] + np.cos(q[1])], 2)
    Q = Interval(np.array([-2.0, -3.0]), np.array([2.5, 1.0]))
    lowest = min_value(V, Q)
    g = np.stack(np.meshgrid(np.linspace(-2, 2.5, 301), np.linspace(-3, 1, 301)), -1).reshape(-1, 2)
    sampled = float(np.min(V.eval_float(g, None)))
    assert lowest <= sampled and sampled - lowest < 0.05
    # a periodic component wider than its period is evaluated over one period
    Vp = trace(lambda q, p: [-np.cos(q[0])], 1)
    assert min_value(Vp, Interval(np.array([-100.0]), np.array([100.0])), periods=[2 * np.pi]) >= -1.0 - 1e-9

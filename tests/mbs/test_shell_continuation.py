"""A passive chain carried on past a break-down by the energy shell (issue 43, item 3,
:mod:`mbs.shell_continuation`): ``simulate(..., energy_shell=True)`` completes where the
sets break down, and every sampled trajectory (Pinocchio's ``aba`` with the joints'
damping, DOP853 at rtol 1e-13) lies inside its outputs and tube; what it cannot carry on
stays a break-down that says why."""

from __future__ import annotations

import math

import numpy as np
import pytest

import verified.consistency.shell_boxes as sb
from mbs.app.sampling import (
    Ensemble,
    count_outside,
    passive_plant,
    sample_points,
)
from mbs.simulate import simulate
from models import double_pendulum as dp_paper
from models.robots import double_pendulum, panda_arm
from verified.arith.interval import Interval


def _dp_box():
    return np.array([2.0, -0.3, 0.0, 0.0]), np.array([2.2, -0.1, 0.0, 0.0])


@pytest.fixture(scope="module")
def dp_samples():
    lo, hi = _dp_box()
    return Ensemble(passive_plant(double_pendulum()), sample_points(lo, hi, 25), 1.0, rtol=1e-13, atol=1e-13)


def _dp_run():
    lo, hi = _dp_box()
    return simulate(double_pendulum(), Interval(lo, hi), 1.0, mode="i", method="lohner", output_dt=0.1,
                    progress=False, workers=1, energy_shell=True)


def test_a_damped_double_pendulum_is_carried_on_past_its_breakdown(dp_samples):
    sol = _dp_run()
    assert sol.status == "completed" and sol.t_reached == 1.0
    assert 0 < sol.stats["shell_from"] < 0.01  # the sets break down at 1.8 ms (stiff damping, a wide box)
    assert "energy shell" in sol.reason and "energy-shell boxes" in sol.method
    assert np.allclose(sol.t, np.linspace(0, 1.0, 11))
    assert all(np.isfinite(b.lo).all() and np.isfinite(b.hi).all() for b in sol.boxes + sol.tube)
    outside, checked = count_outside(sol, dp_samples, 200)
    assert checked > 250 and outside == 0


@pytest.fixture(scope="module")
def paper_run():
    """The paper's double pendulum (point masses, no damping) from box (25), first-order
    sets, broken down at 0.28 s, and its samples."""
    chain = dp_paper.dh_chain()
    lo, hi = dp_paper.initial_box()
    ens = Ensemble(passive_plant(chain), sample_points(lo, hi, 25), 1.5, rtol=1e-13, atol=1e-13)

    def run():
        return simulate(chain, Interval(lo, hi), 1.5, mode="i", method="lohner", output_dt=0.1, progress=False,
                        workers=1, energy_shell=True)
    return run, ens


def test_the_paper_double_pendulum_is_carried_on(paper_run):
    run, ens = paper_run
    sol = run()
    assert sol.status == "completed" and 0.1 < sol.stats["shell_from"] < 0.5
    # sampled max |qd| 6.6, 11.2 rad/s; the bounds 8.6, 19.3
    assert np.all(np.array(sol.stats["shell_speed"]) < 3 * np.array([6.6, 11.2]))
    assert count_outside(sol, ens, 200) == (0, 1200)


def test_a_too_small_speed_bound_is_caught_by_the_pinocchio_samples(paper_run, monkeypatch):
    run, ens = paper_run
    real = sb.speed_bound
    monkeypatch.setattr(sb, "speed_bound", lambda *a, **k: 0.3 * real(*a, **k))
    assert count_outside(run(), ens, 200)[0] > 0


def test_by_default_a_passive_chain_is_carried_on_and_false_turns_it_off(paper_run):
    """With no ``energy_shell`` setting (None) a passive chain's break-down is carried on
    by the shell's boxes, which no sample leaves; ``energy_shell=False`` keeps the
    break-down; no shell is held during the run, so the sets up to the break-down are
    those of the run without it."""
    chain = dp_paper.dh_chain()
    lo, hi = dp_paper.initial_box()
    _, ens = paper_run
    kw = dict(mode="i", method="lohner", output_dt=0.1, progress=False, workers=1)
    off = simulate(chain, Interval(lo, hi), 1.5, energy_shell=False, **kw)
    sol = simulate(chain, Interval(lo, hi), 1.5, **kw)
    assert off.status == "breakdown" and "energy shell" not in off.reason
    assert sol.status == "completed" and sol.stats["shell_from"] == off.t_reached
    assert "energy-shell boxes" in sol.method and "broke down" in sol.reason
    k = len(off.t)
    assert np.array_equal(np.asarray(sol.hull.lo)[:k], np.asarray(off.hull.lo)[:k])
    assert count_outside(sol, ens, 200) == (0, 1200)


def test_by_default_what_the_shell_cannot_carry_stays_a_quiet_breakdown():
    """The default fallback applies only where it is sound and possible: uncertain
    parameters (no bound of M(q)^-1 over them) and a controller (which can add energy)
    keep their break-down, without a note about a shell nobody asked for."""
    from mbs.control import PD
    chain = double_pendulum()
    lo, hi = _dp_box()
    kw = dict(mode="i", method="lohner", progress=False, workers=1)
    sol = simulate(chain, Interval(lo, hi), 1.0, params={"mass_scale": [0.95, 1.05]}, **kw)
    assert sol.status == "breakdown" and "shell" not in sol.reason and "shell_from" not in sol.stats
    sol = simulate(chain, Interval(lo, hi), 1.0, control=PD(1.0, 0.1), **kw)
    assert sol.status == "breakdown" and "shell" not in sol.reason and "shell_from" not in sol.stats


def test_uncertain_parameters_are_not_carried_on():
    chain = double_pendulum()
    lo, hi = _dp_box()
    sol = simulate(chain, Interval(lo, hi), 1.0, mode="i", method="lohner", progress=False, workers=1,
                   energy_shell=True, params={"mass_scale": [0.95, 1.05]})
    assert sol.status == "breakdown" and "cannot carry the run on: uncertain parameters" in sol.reason


@pytest.mark.slow  # ~100 s CPU (130 s wall loaded): the sets up to their break-down at 0.46 s, then the shell
def test_free_falling_panda_never_breaks_down_to_5_s():
    chain = panda_arm()
    q0 = np.array((0.0, -math.pi / 4, 0.0, -3 * math.pi / 4, 0.0, math.pi / 2, math.pi / 4))
    lo, hi = np.r_[q0 - 1e-3, np.zeros(7)], np.r_[q0 + 1e-3, np.zeros(7)]
    T = 5.0
    sol = simulate(chain, Interval(lo, hi), T, mode="i", method="composition", output_dt=0.1, progress=False,
                   energy_shell=True, max_wall=600)
    assert sol.status == "completed" and sol.t_reached == T
    assert 0.1 < sol.stats["shell_from"] < T
    assert all(np.isfinite(b.lo).all() and np.isfinite(b.hi).all() for b in sol.boxes + sol.tube)
    ens = Ensemble(passive_plant(chain), sample_points(lo, hi, 24), T, rtol=1e-13, atol=1e-13)
    outside, checked = count_outside(sol, ens, 400)
    assert checked > 1000 and outside == 0

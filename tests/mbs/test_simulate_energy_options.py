"""``simulate(..., contract=, prune=)`` and the scene keys ``[consistency] contract`` /
``prune``: the energy test's contraction and its branch and prune, chosen by the user."""

from __future__ import annotations

import numpy as np
import pytest

from mbs.app.scene import SceneError, loads_scene
from mbs.simulate import simulate
from models import pendulum as pd
from verified.arith.interval import Interval

from oracles.sampling import misses, sample_initial_points, trajectories


def _run(**kw):
    """The pendulum with first-order sets (method="lohner"): the tests below compare its
    mode-ii sets with mode i's, which the composition's h state changes."""
    lo, hi = pd.initial_box()
    return simulate("pendulum_paper", Interval(lo, hi), 1.0, output_dt=0.25, progress=False, method="lohner", **kw)


def test_contract_and_prune_reach_the_energy_test_and_stay_sound():
    off = _run(mode="ii", contract="off", prune=False)
    step = _run(mode="ii", contract="step", prune=False)
    plain = _run(mode="i")
    assert off.status == step.status == "completed"
    # with neither, the energy test changes no set: mode i's enclosure
    np.testing.assert_allclose(off.hull.lo, plain.hull.lo, rtol=0, atol=1e-12)
    np.testing.assert_allclose(off.hull.hi, plain.hull.hi, rtol=0, atol=1e-12)
    assert off.stats.get("pruned_boxes", 0) == 0
    # the contraction can only narrow
    assert (step.hull.width() <= off.hull.width() * (1 + 1e-9) + 1e-15).all()
    lo, hi = pd.initial_box()
    sols = trajectories(lambda x: pd.rhs(x), sample_initial_points(lo, hi, 20), 1.0)
    assert misses(step, sols) == []


def test_bad_contract_is_a_clear_error():
    with pytest.raises(ValueError, match="contract must be"):
        _run(mode="ii", contract="always")


SCENE = """
name = "t"
[model]
name = "pendulum_paper"
[initial]
x1 = [2.1, 2.2]
x2 = [3.1, 3.2]
[simulation]
t_end = 0.5
mode = "ii"
[consistency]
"""


def test_scene_keys():
    s = loads_scene(SCENE + 'contract = "test"\nprune = false\n')
    kw = s.simulate_kwargs(["x1", "x2"])
    assert kw["contract"] == "test" and kw["prune"] is False
    with pytest.raises(SceneError, match="contract"):
        loads_scene(SCENE + 'contract = "sideways"\n')
    with pytest.raises(SceneError, match="prune"):
        loads_scene(SCENE + 'prune = "no"\n')


@pytest.mark.slow  # default-run budget (CI's cold default step measured 170-183 s of 180 at 1e891d1/1caded6)
def test_energy_shell_through_simulate_holds_the_pendulum_and_stays_sound():
    """``simulate(..., energy_shell=True)``: the chain's M(q) and P(q) give the shell, the
    initial box its hmax; the pendulum over the top (mode i)
    keeps |qd| within the shell where the plain run's enclosure grows, samples inside."""
    lo, hi = pd.initial_box()
    T = 2.0
    kw = dict(mode="i", output_dt=0.25, error_basis="auto", max_width=1e6, progress=False)
    held = simulate("pendulum_paper", Interval(lo, hi), T, energy_shell=True, **kw)
    plain = simulate("pendulum_paper", Interval(lo, hi), T, **kw)
    assert held.status == "completed", held
    assert held.stats["shell_resets"] >= 1 and "shell_resets" not in plain.stats
    assert held.hull[-1].width()[1] < 0.5 * plain.hull[-1].width()[1]
    sols = trajectories(lambda x: pd.rhs(x), sample_initial_points(lo, hi, 30), T)
    assert misses(held, sols, per_step=2, states=2) == []


def test_energy_shell_refuses_what_it_cannot_bound():
    from mbs.control import PD
    from mbs.system import System
    from verified.graph import trace
    lo, hi = pd.initial_box()
    box = Interval(lo, hi)
    with pytest.raises(ValueError, match="without control inputs"):
        simulate("pendulum_paper", box, 0.1, mode="i", control=PD(1.0, 1.0), energy_shell=True, progress=False)
    with pytest.raises(ValueError, match="energy_shell must be True, False or None"):
        simulate("pendulum_paper", box, 0.1, mode="i", energy_shell="yes", progress=False)
    bare = System(name="bare", rhs=trace(pd.rhs, 2))
    with pytest.raises(ValueError, match="needs its energy"):
        simulate(bare, box, 0.1, mode="i", energy_shell=True, progress=False)
    # (a declared rate is proven before the run: a wrong one is refused)
    wrong = System(name="bare", rhs=trace(pd.rhs, 2), energy=trace(lambda x, p: [pd.hamiltonian(x)], 2),
                   energy_rate=trace(lambda x, p: [x[1] ** 2], 2))
    with pytest.raises(ValueError, match="not proven equal"):
        simulate(wrong, box, 0.1, mode="i", energy_shell=True, progress=False)


@pytest.mark.slow  # (two 2 s runs and 20 DOP853 samples)
def test_energy_shell_with_uncertain_parameters_holds_the_pendulum_and_stays_sound():
    """Issue 43 item 3: the shell of a passive chain with uncertain mass and damping
    (hmax over the parameter box, each set held with its own parameter columns)."""
    from mbs.app.sampling import dop853
    lo, hi = pd.initial_box()
    T = 2.0
    prm = {"mass_scale": [0.9, 1.1], "damping": [0.0, 0.05]}
    kw = dict(mode="i", output_dt=0.5, error_basis="auto", max_width=1e6, progress=False, params=prm)
    held = simulate("pendulum_paper", Interval(lo, hi), T, energy_shell=True, **kw)
    plain = simulate("pendulum_paper", Interval(lo, hi), T, **kw)
    assert held.status == "completed" and held.stats["shell_resets"] >= 1
    assert held.hull[-1].width()[1] < 0.5 * plain.hull[-1].width()[1]
    rng = np.random.default_rng(7)
    bad = 0
    for x in sample_initial_points(lo, hi, 20):
        s, d = rng.uniform(0.9, 1.1), rng.uniform(0.0, 0.05)
        # m = s m0 (m0 = l = 1): qdd = -(g / l) sin q - d qd / (m l^2)
        r = dop853(lambda t, y, s=s, d=d: np.array([y[1], -pd.G / pd.L * np.sin(y[0]) - d * y[1] / (s * pd.M * pd.L ** 2)]),
                   np.asarray(x, float), T, rtol=1e-12, atol=1e-12)
        for k, t in enumerate(held.t):
            B = held.boxes[k]
            y = r.sol(float(t))
            bad += not np.any(np.all((B.lo[:, :2] - 1e-9 <= y) & (y <= B.hi[:, :2] + 1e-9), axis=1))
    assert bad == 0


@pytest.mark.slow  # (two 2-3 s runs)
def test_energy_shell_on_a_bare_system_with_a_declared_energy():
    """A bare System with H (declared conserved, proven) gets the shell as an invariant;
    its enclosure matches the chain's over the top of the pendulum (sound: the chain's
    slow test samples it)."""
    from mbs.system import System
    from verified.graph import trace
    lo, hi = pd.initial_box()
    H = trace(lambda x, p: [0.5 * pd.M * pd.L ** 2 * x[1] ** 2 + pd.M * pd.G * pd.L * (1 - np.cos(x[0]))], 2)
    bare = System(name="bare", rhs=trace(lambda x, p: pd.rhs(x), 2), energy=H, energy_rate="zero")
    kw = dict(mode="i", error_basis="auto", max_width=1e6, progress=False)
    held = simulate(bare, Interval(lo, hi), 2.0, energy_shell=True, **kw)
    assert held.status == "completed" and held.stats["invariant_resets"] >= 1
    lo_h, hi_h = held.stats["invariant_levels"]["'H'"]
    assert lo_h <= 19.62 and 20.6 <= hi_h
    chain = simulate("pendulum_paper", Interval(lo, hi), 2.0, energy_shell=True, **kw)
    assert np.all(held.hull[-1].width() <= 1.5 * chain.hull[-1].width())

"""``simulate(..., contract=, prune=)`` and the scene keys ``[consistency] contract`` /
``prune``: the energy test's contraction and its branch and prune, chosen by the user."""

from __future__ import annotations

import numpy as np
import pytest

from mbs.app.scene import SceneError, loads_scene
from mbs.simulate import simulate
from models import pendulum as pd
from verified.interval import Interval

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
    with pytest.raises(ValueError, match="energy_shell must be True or False"):
        simulate("pendulum_paper", box, 0.1, mode="i", energy_shell="yes", progress=False)
    bare = System(name="bare", rhs=trace(pd.rhs, 2))
    with pytest.raises(ValueError, match="chain model"):
        simulate(bare, box, 0.1, mode="i", energy_shell=True, progress=False)
    with pytest.raises(ValueError, match="uncertain parameters"):
        simulate("pendulum_paper", box, 0.1, mode="i", params={"mass_scale": [0.9, 1.1]}, energy_shell=True, progress=False)

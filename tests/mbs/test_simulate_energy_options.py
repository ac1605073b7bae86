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
    lo, hi = pd.initial_box()
    return simulate("pendulum_paper", Interval(lo, hi), 1.0, output_dt=0.25, progress=False, **kw)


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

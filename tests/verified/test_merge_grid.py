"""Merging chunk Solutions (:func:`verified.execution.merge.merge_solutions`) on a grid of step
boundaries whose last step is one ulp long: each grid step is found by its start, since
its midpoint rounds to its end (auto's spec refinement merged two groups whose tubes ended
with such a step and failed with an IndexError)."""

import numpy as np

from verified.graph import trace
from verified.arith.interval import Interval
from verified.execution.merge import merge_solutions
from verified.solver import solve


def _chunk(x0):
    sol = solve(trace(lambda x, p: [-x[0]], 1, 0), Interval([x0], [x0 + 0.01]), (0.0, 1.0), method="lohner")
    assert sol.status == "completed" and len(sol.tube) >= 2
    tt = np.asarray(sol.tube_t, float).copy()
    tt[-2] = np.nextafter(tt[-1], 0.0)   # (the last step one ulp long)
    sol.tube_t = tt
    return sol


def test_a_last_step_one_ulp_long_is_merged_into_its_own_box():
    a, b = _chunk(1.0), _chunk(2.0)
    initial = Interval([[1.0], [2.0]], [[1.01], [2.01]])
    out = merge_solutions([a, b], [(0, 1), (1, 2)], initial, np.asarray(a.t, float), 0.0, ("x",))
    assert len(out.tube) == len(a.tube) and out.tube_t[-1] == 1.0
    last = out.tube[-1]
    assert np.all(last.lo[0] == a.tube[-1].lo) and np.all(last.hi[1] == b.tube[-1].hi)

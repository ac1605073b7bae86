"""RA(t) and the test times t* (paper eq. (16)), tracked apart from the pruning."""
import numpy as np

import verified.consistency.energy_test as consistency
import verified.consistency.reduction_area as reduction_area
from verified.arith.interval import Interval
from verified.consistency.reduction_area import ReductionArea


class _Lifted:
    """H(x) = x over one state; h is the second component of the sets."""

    def __init__(self, energy=True):
        self.energy = object() if energy else None
        self.n_s = 1

    def eval(self, g, X):
        return X[:, :1]


class _Sets:
    def __init__(self, x, h):
        # one set: x (lo, hi) and h (lo, hi)
        self._hull = Interval(np.array([[x[0], h[0]]]), np.array([[x[1], h[1]]]))
        self.n_sets = 1

    def hull(self):
        return self._hull


def test_the_records_are_reexported_by_consistency():
    assert consistency.ConsistencyRecord is reduction_area.ConsistencyRecord
    assert consistency.TestRecord is reduction_area.TestRecord


def test_t_star_is_the_first_local_maximum_of_ra():
    ra = ReductionArea(_Lifted(), test_interval=1.0, t0=0.0)
    # H_H = [0, w], H_V = [0, 0.1]: RA = w - 0.1 (w >= 0.1)
    assert ra.observe(0.1, _Sets((0, 0.2), (0, 0.1))) is None      # RA 0.1
    assert ra.observe(0.2, _Sets((0, 0.4), (0, 0.1))) is None      # RA 0.3, rising
    assert ra.observe(0.3, _Sets((0, 0.3), (0, 0.1))) == "previous"  # RA 0.2: the peak was at 0.2
    assert ra.peaked.tolist() == [True]
    ra.forget_last()  # the solver rolled back to t = 0.2
    ra.tested(0.2)
    rec = ra.finish()
    assert rec.ra_t.tolist() == [0.1, 0.2]
    np.testing.assert_allclose(rec.ra, [0.1, 0.3])
    assert rec.h_h.shape == (2,) and rec.tests == []


def test_without_energy_only_the_interval_triggers_a_test():
    ra = ReductionArea(_Lifted(energy=False), test_interval=0.25, t0=0.0)
    assert ra.observe(0.1, _Sets((0, 1), (0, 1))) is None
    assert ra.observe(0.25, _Sets((0, 1), (0, 1))) == "now"
    ra.tested(0.25, "a test record")
    assert ra.last_test_t == 0.25 and ra.record.tests == ["a test record"]
    assert ra.observe(0.3, _Sets((0, 1), (0, 1))) is None

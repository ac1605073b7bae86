"""When to test: the reduction area ``RA(t)`` and the test times ``t*`` (paper eq. (16), Fig. 2).

This module owns the per-step bookkeeping of the energy consistency test and the
records it hands back, and nothing that changes the sets:

- :class:`ReductionArea` records, after every step, ``H_H`` (the energy ``H`` in J
  over each set's hull), ``H_V`` (the integrated state ``h``) and
  ``RA = diam H_H - diam(H_H ∩ H_V)`` per set, and decides whether a test is due
  (:meth:`ReductionArea.observe`): at the first local maximum of ``RA`` after the
  previous test, and at the latest ``test_interval`` seconds after it;
- :class:`ConsistencyRecord` (what a run saw: ``RA(t)``, the energy enclosures per
  step, every test) and :class:`TestRecord` (one test at ``t*``).

The sets are ``B`` doubleton sets over ``n_s`` solver states followed by ``h``; the
energy graph comes lifted onto them (:class:`verified.consistency.graphs.LiftedGraphs`).
The hook that runs the tests is :class:`verified.consistency.energy_test.EnergyTest`, which
re-exports both record classes.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from verified.arith.interval import Interval, concatenate, hull

__all__ = ["ConsistencyRecord", "ReductionArea", "TestRecord"]


@dataclass
class TestRecord:
    """One consistency test at time ``t`` (the paper's ``t*``)."""

    t: float
    candidates: Interval  # (k, n): hulls of the parts tested (state components only)
    kept: np.ndarray  # (k,) bool
    h_v: Interval  # scalar: H_V at t (hull over the sets), or empty without energy
    sets_before: int
    sets_after: int
    backward_deleted: int = 0
    backward_runs: int = 0
    #: why the test ran: "RA maximum" (the first local maximum of RA(t) after the last
    #: test, the paper's t*) or "interval" (``test_interval`` passed without one)
    trigger: str = "interval"


@dataclass
class ConsistencyRecord:
    """What the tests saw: ``RA(t)`` and the energy enclosures per step, and each test."""

    ra_t: np.ndarray
    ra: np.ndarray
    h_h: Interval
    h_v: Interval
    tests: list = field(default_factory=list)
    #: ``H_H`` and ``H_V`` of the set with the largest ``RA`` at each step (``ra`` is its RA)
    h_h_set: Interval | None = None
    h_v_set: Interval | None = None


class ReductionArea:
    """``RA(t)`` over one run and the decision when to test.

    ``lifted``: the run's :class:`verified.consistency.graphs.LiftedGraphs`
    (``lifted.energy`` None: constraints only, ``RA`` is 0 and only the interval
    triggers tests); ``test_interval``: the longest time (s) between two tests;
    ``t0``: the start of the run, where the interval to the first test starts.

    :attr:`record` is the :class:`ConsistencyRecord` being filled (tests are added by
    :meth:`tested`, the per-step series by :meth:`finish`); :attr:`peaked` the sets
    to test after ``observe`` said "previous"; :attr:`last_test_t` the time of the
    last test.
    """

    def __init__(self, lifted, test_interval: float, t0: float = 0.0):
        self._lifted = lifted
        self.test_interval = float(test_interval)
        self.record = ConsistencyRecord(np.zeros(0), np.zeros(0), Interval(np.zeros(0)), Interval(np.zeros(0)))
        self._ra_t, self._ra, self._hh, self._hv = [], [], [], []
        self._hh_set, self._hv_set, self._ra_sets, self._ra_sets_t = [], [], [], []
        self.peaked = None
        self.last_test_t = float(t0)  # the interval to the first test starts at t0

    def observe(self, t: float, sets) -> str | None:
        """Record ``RA(t)`` (eq. (16)) for the sets after a step and say whether to test:
        "previous" (some set's ``RA`` had its first local maximum at the previous step),
        "now" (the longest interval has passed), or None.

        ``RA`` is evaluated per set, ``diam H_H(S) - diam(H_H(S) ∩ H_V(S))`` with both
        enclosures of the same set ``S`` (eq. (16) for that set; a sum over sets would
        compare the energy spread *between* sets, which is no overestimation). The
        record (Fig. 2) keeps the largest per-set value, ``H_H`` and ``H_V`` of that
        set, and the hulls over all sets. ``t*`` is the first local maximum of that
        record; the sets with ``RA > 0`` there are the ones tested (:attr:`peaked`)."""
        self.peaked = None
        lifted = self._lifted
        if lifted.energy is not None:
            X = sets.hull()
            hh = lifted.eval(lifted.energy, X[:, : lifted.n_s])[:, 0]
            hv = X[:, lifted.n_s]
            inter = hh.intersect(hv)
            wi = np.where(inter.is_empty(), 0.0, inter.width())
            ra_b = np.nan_to_num(hh.width() - wi, nan=0.0, posinf=np.finfo(float).max)
            k = int(np.argmax(ra_b)) if ra_b.size else 0
            ra = float(ra_b[k]) if ra_b.size else 0.0
            self._hh.append(hull(hh, axis=0))
            self._hv.append(hull(hv, axis=0))
            self._hh_set.append(hh[k] if ra_b.size else Interval(np.nan))
            self._hv_set.append(hv[k] if ra_b.size else Interval(np.nan))
        else:
            ra_b = np.zeros(sets.n_sets)
            ra = 0.0
        self._ra_t.append(t)
        self._ra.append(ra)
        since = t - self.last_test_t
        hist = self._ra_sets
        if hist and hist[-1].shape != ra_b.shape:
            hist.clear()  # the batch changed (pruned, split): start the per-set history again
        hist.append(ra_b)
        del hist[:-3]
        self._ra_sets_t.append(t)
        del self._ra_sets_t[:-3]
        # t*: the first local maximum of the recorded RA (the largest per-set value)
        # after the previous test; RA(t0) = 0 (H_V(0) is H_H(0)), so the first step can
        # be one too. Tested then: the sets with overestimation (per-set RA > 0) at t*.
        # (Not every set at its own maximum: with many sets that tests at almost every
        # step, slower and no narrower; docs/lab/code_notes.md.)
        ra_hist, t_hist = self._ra, self._ra_t
        if len(ra_hist) >= 2 and t_hist[-2] > self.last_test_t:
            before = ra_hist[-3] if len(ra_hist) >= 3 and t_hist[-3] > self.last_test_t else 0.0
            if ra_hist[-2] > ra_hist[-1] and ra_hist[-2] >= before and ra_hist[-2] > 0:
                if len(hist) >= 2:
                    self.peaked = hist[-2] > 0
                return "previous"
        if since >= self.test_interval * (1 - 1e-12):
            return "now"
        return None

    def forget_last(self):
        """The solver rolled the last step back (the test runs at the step before)."""
        for lst in (self._ra_t, self._ra, self._hh, self._hv, self._hh_set, self._hv_set, self._ra_sets,
                    self._ra_sets_t):
            if lst:
                lst.pop()

    def tested(self, t: float, test: TestRecord | None = None):
        """A test ran at ``t`` (the next interval starts there); ``test`` its record,
        if it pruned (a contraction-only test leaves none)."""
        if test is not None:
            self.record.tests.append(test)
        self.last_test_t = t

    def finish(self) -> ConsistencyRecord:
        """The record with the per-step series filled in."""
        self.record.ra_t = np.array(self._ra_t)
        self.record.ra = np.array(self._ra)
        empty = Interval._from_bounds(np.zeros(0), np.zeros(0))
        self.record.h_h = concatenate([h.reshape((1,)) for h in self._hh], axis=0) if self._hh else empty
        self.record.h_v = concatenate([h.reshape((1,)) for h in self._hv], axis=0) if self._hv else empty
        self.record.h_h_set = concatenate([h.reshape((1,)) for h in self._hh_set], axis=0) if self._hh_set else empty
        self.record.h_v_set = concatenate([h.reshape((1,)) for h in self._hv_set], axis=0) if self._hv_set else empty
        return self.record

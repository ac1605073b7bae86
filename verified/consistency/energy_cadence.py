"""The energy test gets out of the way when it gains nothing (paper mode ii, issue 40).

Mode (ii) integrates the energy state ``h`` (``H_V``, eq. (12)) beside the states. On
second-order sets advanced by composition its rate ``dH/dt = grad H . f`` runs through
the Taylor models with everything else, and a run costs far more than without the test
even where the test never prunes (a robot near rest). So an :class:`~verified.consistency.energy_test.
EnergyTest` whose last ``suspend_after`` tests pruned and narrowed nothing stops the run
(:data:`verified.consistency.energy_test.IDLE`); :func:`solve_with_cadence` then

1. continues from those sets without ``h`` (:func:`drop_appended`) and without the test,
   for a span that doubles each time the test comes back without a gain;
2. resumes the test from the sets where that span ended: ``h`` is appended afresh,
   ``h = H(x)`` in the mean-value form over the sets (as at ``t0``; every true
   trajectory has ``h(t) = H(x(t))`` at every time), so ``RA`` starts from 0 and rises
   again where the sets overestimate the energy; the test runs at its peaks as before.

Every phase continues from exactly the sets the previous one ended with, at their exact
time, and the Solution is the phases laid end to end
(:func:`verified.driver.time_chain.chain_in_time`): sound as the runs it is made of. The test
records are concatenated, with no entries while the test was off.
"""

from __future__ import annotations

import copy
import time
import warnings

import numpy as np

from verified.consistency.graphs import EnergyClaimWarning
from verified.driver.hooks import Hook, caps_from
from verified.arith.interval import matvec
from verified.sets.second_order import QuadraticSets
from verified.sets.first_order import DoubletonSets
from verified.driver.solution import Start
from verified.driver.time_chain import chain_in_time

__all__ = ["solve_with_cadence", "drop_appended", "PauseAt", "FIRST_OFF_TESTS", "PROBE_TESTS"]

#: tests without a gain that suspend a resumed test again
PROBE_TESTS = 1
#: the first span without the test, in test intervals (it doubles after every phase in
#: which the resumed test gained nothing, and starts over after one that gained)
FIRST_OFF_TESTS = 8


class PauseAt(Hook):
    """Stop the run at the first step that ends at or after ``t`` (status "stopped")
    and keep where it stands in :attr:`point` (a :class:`~verified.driver.solution.Start`);
    not on the step that records the last output (the run is done then)."""

    def __init__(self, t: float):
        self.t = float(t)
        self.point = None

    def after_step(self, step, sets, run):
        if step.t >= self.t and not run.status and not run.landed_on_last_output(step):
            self.point = run.resume_point()
            run.stop(f"paused at t = {step.t:g} (the energy test resumes)", "stopped")
        return None


def drop_appended(start: Start, n_run: int) -> Start:
    """``start``'s sets without the states appended after the first ``n_run`` (the
    energy test's ``h``): the projection of each set onto its first ``n_run``
    components. The error part ``Q r`` keeps its own basis where ``Q`` does not mix the
    dropped components into the kept ones; otherwise the kept rows of ``Q r`` are
    enclosed in a box (``Q = I``, ``r`` that box). The parameters stay (``h``'s own,
    of width 0, included)."""
    sets = start.sets
    N = sets.c.shape[1]
    if N == n_run:
        return start
    if N < n_run:
        raise ValueError(f"the sets have {N} components, fewer than the run's {n_run}")
    k = n_run
    c = np.ascontiguousarray(sets.c[:, :k])
    C = np.ascontiguousarray(sets.C[:, :k])
    r0 = sets.r0
    Q = sets.Q
    if np.all(Q[:, :k, k:] == 0):
        Qk, rk = np.ascontiguousarray(Q[:, :k, :k]), sets.r[:, :k]
    else:  # (the kept rows of Q r, enclosed in a box: outward rounded)
        rk = matvec(np.ascontiguousarray(Q[:, :k, :]), sets.r)
        Qk = np.broadcast_to(np.eye(k), (c.shape[0], k, k)).copy()
    if isinstance(sets, QuadraticSets):
        S = np.ascontiguousarray(sets.S[:, :k])
        new = QuadraticSets(c=c, C=C, r0=r0, S=S, Q=Qk, r=rk)
    elif isinstance(sets, DoubletonSets):
        new = DoubletonSets(c, C, r0, Qk, rk)
    else:
        raise TypeError(f"cannot drop states from {type(sets).__name__}")
    return Start(sets=new, t_exact=start.t_exact, h_limit=start.h_limit, split_scale=None)


def solve_with_cadence(run, x0, t_span, test, hooks, n_state: int, n_run: int, test_interval: float):
    """The run with an energy test that is suspended while idle (module docstring).
    ``run(x0, start, consistency, hooks)`` is one in-process batch run
    (:func:`verified.driver.batch.solve_batch` with the caller's other arguments); ``n_run``
    the number of states the run integrates without the test (the ``n_state`` states
    and the parameters carried as states); ``test_interval`` the test's longest
    interval (s)."""
    started = time.perf_counter()
    t1 = float(t_span[1])
    template = copy.deepcopy(test)  # (each resumed phase gets a fresh test with the same settings)
    test.can_suspend = True
    sol = run(x0, None, test, caps_from(hooks, started))
    parts = [sol]
    off = FIRST_OFF_TESTS * test_interval
    current = test
    while current.idle_point is not None and sol.status == "stopped":
        stop = current.idle_point
        quiet = drop_appended(stop, n_run)
        t_stop = float(stop.t_exact)
        pause = PauseAt(min(t1, t_stop + off))
        X = quiet.sets.hull()[:, :n_state]
        sol = run(X, quiet, None, caps_from(hooks, started) + [pause])
        parts.append(sol)
        if pause.point is None or sol.status != "stopped":
            break
        current = copy.deepcopy(template)
        current.can_suspend = True
        # a probe: one test without a gain suspends it again (the first phase needed more to
        # show that the test gains nothing here)
        current.suspend_after = min(PROBE_TESTS, current.suspend_after or PROBE_TESTS)
        X = pause.point.sets.hull()[:, :n_state]
        with warnings.catch_warnings():  # (said once, by the first phase)
            warnings.simplefilter("ignore", EnergyClaimWarning)
            sol = run(X, pause.point, current, caps_from(hooks, started))
        parts.append(sol)
        gained = (current.stats.get("pruned_boxes", 0) > 0 or current.stats.get("contraction_ratio_min", 1.0) < 1.0)
        off = FIRST_OFF_TESTS * test_interval if gained else 2 * off
    out = chain_in_time(parts)
    if len(parts) > 1:
        out.stats["energy_test_phases"] = len(parts)
        out.stats["energy_test_off_s"] = float(sum(p.t_reached - p.tube_t[0] for p in parts[1::2]))
    return out


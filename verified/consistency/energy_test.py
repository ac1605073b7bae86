"""Consistency tests that cut physically impossible parts out of enclosures (paper sec. 4).

The energy (Hamiltonian) test evaluates the energy of a dynamical system in two
"computationally different but effectively identical" ways:

- ``H_H``: the Hamiltonian ``H(x)`` evaluated on a state enclosure (eqs. (3)/(4));
- ``H_V``: ``H(0) + int_0^t dH/dt`` (eq. (12)), carried as an extra state ``h`` of the
  verified integration, ``h' = dH/dt(x)`` (``0`` for a conservative system whose
  rate was simplified, the unsimplified chain rule, or ``qd^T tau`` with damping).

Every true trajectory has ``h(t) = H(x(t))``. A part of an enclosure whose ``H_H``
misses its ``H_V`` holds no true state and is discarded (branch and prune).

Here ``h`` starts correlated with the initial states: ``h(0) = H(c) + DH(X0) (x0 - c)``
enters the set's linear part, so ``H_V`` of a part of a set is the energy range of the
initial values that part came from, not of the whole initial box. The pruning test of
a part ``S = c + C r0 + Q r`` is the paper's ``H_H(S) ∩ H_V(S) = ∅``, evaluated both
naively on the hull and in mean-value form over the set's parameters,
``G(S) ⊆ G(c) + (DG C) r0 + (DG Q) r`` with ``G = H(x) - h``; either excluding 0
proves the part empty of true states.

When to test (``t*``): the reduction area ``RA(t) = diam H_H - diam(H_H ∩ H_V)``
(eq. (16)) is tracked after every step (per set; the record keeps the largest); the test
runs at its first local maximum after the previous test, and at the latest
``test_interval`` seconds after it.

Further constraints (paper sec. 3) use the same machinery: holonomic ``g(x, t) = 0``
and inequalities such as a kinetic-energy bound, see :class:`Constraint`.

The backward test (sec. 4, cases A/B/C) integrates the parts that survive the energy
test back over the last step and compares with the forward sets there.

This module owns :class:`EnergyTest`, the solver hook that composes the pieces
below, keeps the statistics and hands the record to the Solution. The pieces:

- :mod:`verified.consistency.graphs`: the energy, its rate claim and the constraints
  lifted onto the integrated states, and the proof and refutation of a declared rate
  (:class:`Constraint`, :class:`EnergyClaimError`, :class:`EnergyClaimWarning`,
  :func:`prove_energy_rate` live there and are re-exported here);
- :mod:`verified.consistency.energy_state`: ``h(0)`` correlated with the initial states, and
  restarting ``h``;
- :mod:`verified.consistency.branch_prune`: the pruning test and the cutting at ``t*``;
- :mod:`verified.consistency.backward_test`: the backward test;
- :mod:`verified.consistency.reduction_area`: ``RA(t)`` and when to test (``t*``), and the
  records (:class:`ConsistencyRecord`, :class:`TestRecord`, re-exported here);
- :mod:`verified.consistency.energy_contraction`: contracting the sets with ``H(x) - h = 0``.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from verified.consistency.backward_test import backward_test
from verified.consistency.branch_prune import STRATEGIES, branch_and_prune
from verified.consistency.graphs import (
    Constraint, EnergyClaimError, EnergyClaimWarning, lift_graphs, prove_energy_rate, refute_claim
)
from verified.consistency.energy_contraction import EnergyContraction
from verified.consistency.energy_rate import SYSTEM_RATES, check_energy_rate, deprecated
from verified.consistency.energy_state import assign, initial_sets, reset_h
from verified.graph import Graph
from verified.graph.ops import negated
from verified.driver.hooks import Hook
from verified.driver.user_warnings import warn_at_caller
from verified.arith.interval import Interval, concatenate, hull, point
from verified.consistency.reduction_area import ConsistencyRecord, ReductionArea, TestRecord
from verified.sets.first_order import DoubletonSets

__all__ = ["Constraint", "EnergyTest", "ConsistencyRecord", "TestRecord", "STRATEGIES", "EnergyClaimError",
           "EnergyClaimWarning", "prove_energy_rate"]


#: the reason of a run stopped by an idle energy test (EnergyTest.suspend_after)
IDLE = "energy test idle"


def _renamed(value, old_value, name: str, old_name: str, default):
    """The value of a keyword given under its name or its old name (not both)."""
    if old_value is not None:
        if value is not None:
            raise TypeError(f"EnergyTest: give {name} or its old name {old_name}, not both")
        return old_value
    return default if value is None else value


class BackOff:
    """Skip an optional, sound-either-way action after it gained nothing: wait 1, 2,
    4, ... calls (at most ``cap``) after each fruitless one, none after one that
    gained. ``cap = 0``: never skip."""

    def __init__(self, cap: int = 0):
        self.cap = int(cap)
        self.wait = self.idle = 0

    def skip(self) -> bool:
        """Whether to skip this call (counts the wait down)."""
        if self.idle > 0:
            self.idle -= 1
            return True
        return False

    def done(self, gained: bool) -> None:
        """After the action: reset the wait if it gained, else double it."""
        self.wait = 0 if gained or self.cap == 0 else min(max(1, 2 * self.wait), self.cap)
        self.idle = self.wait


class EnergyTest(Hook):
    """The energy consistency test, optional further constraints, and the backward test.

    A solver hook (:mod:`verified.driver.hooks`; ``solve(..., consistency=test)`` or
    ``hooks=[test]``): ``before_run`` appends the energy state ``h`` and caps the step
    at ``test_interval``; ``after_step`` records ``RA(t)`` and, at ``t*``, prunes the sets
    (rolling the last step back when ``RA`` peaked at the step before);
    ``after_run`` attaches the record and the statistics to the Solution.

    Parameters
    ----------
    energy : Graph or None
        ``H(x, p)`` (1 output, J) over the ODE's states and parameters; ``None`` for
        constraints only.
    energy_rate : "derive", "zero" or Graph
        How ``dH/dt(x, p)``, integrated into ``H_V`` (eq. (12)), is obtained (the
        vocabulary: :mod:`verified.consistency.energy_rate`): "derive" forms ``grad H . f`` by
        forward-mode differentiation (mode (ii)); "zero" declares the system
        conservative (``H_V = H(0)``); a Graph is the rate itself. ``None``
        (deprecated) means "zero". A declared rate ("zero" or a Graph) is used only
        when proven identically equal to ``grad H . f`` (exact symbolic proof at
        set-up, :func:`verified.consistency.graphs.prove_claim`); an unproven one is
        replaced by the derived rate, with one :class:`EnergyClaimWarning`
        (``claim_proof`` says why; ``stats["energy_rate_unproven"]`` is 1). Either
        way it is refuted on intervals at the initial sets and over every step's
        tube: a refuted claim raises :class:`EnergyClaimError`.
    constraints : sequence of Constraint
    test_interval : float
        Longest time (s) between two tests (the paper: 0.1 s in mode (ii), 0.01 s in (iii));
        the same name as :func:`mbs.simulate.simulate`'s, scenes' and
        :class:`mbs.modes.Mode`'s (``max_interval``, its old name, still works).
    test_splits : int
        Parts per set at a test (paper: 10 and 50; old name ``splits``). "gradient"/"widest" bisect
        ``round(log2(splits))`` times, pruning between rounds; "grid" cuts the two
        directions that widen ``H_H`` most into a ``k x k`` grid, ``k^2 ~ splits``.
    split_strategy : "gradient" (default), "widest" or "grid"
        Direction choice: largest ``|dG/dx . column| x width`` (the part of ``H_H``'s
        width a direction causes), largest share of the set's own width, or a grid
        (the name :func:`mbs.simulate.simulate` and scenes use; old name ``strategy``).
    refine : "pruned" or "always"
        "pruned" (default): a set is replaced by its surviving parts (as the largest
        consistent subtrees) only when that narrows its hull by at least
        ``min_gain`` in some component; otherwise it stays whole (and is dropped
        only when no part survives). Every part costs integration time, and
        scattered small cuts multiply the sets without narrowing the enclosure.
        "always": keep every surviving part.
    min_gain : float
        Relative narrowing that justifies replacing a set by its parts (default 0.1).
    backward_depth : int
        Backward consistency test on parts the energy test keeps: 0 = off; else the
        bisection depth for undecided parts (case C).
    max_boxes : int
        Refinement is skipped when the batch would exceed this many sets.
    contract : "step" (default), "test" or "off"
        Where the sets are contracted with ``H(x) - h = 0``
        (:mod:`verified.consistency.energy_contraction`): after every step, only at the tests, or never.
    contract_backoff : int or None
        With ``contract="step"``: after a contraction that narrowed nothing, skip the
        next 1, 2, 4, ... steps' contractions, at most this many in a row; any
        narrowing resets the wait. (Skipping a contraction is always sound: it only
        narrows.) None: 16 on second-order sets, where contractions rarely narrow
        anything (docs/lab/code_notes.md), 0 (every step) on doubletons.
    check_claim : bool
        True (default): prove and refute a declared ``energy_rate`` (above). False:
        use it as given, unproven and unrefuted (the caller vouches for it: a wrong
        rate removes true states).
    suspend_after : int or None
        After this many tests in a row that pruned nothing (and contractions between them
        that narrowed nothing), the run without the test is cheaper: the energy state
        ``h`` is dropped, the run goes on without the test for a while, and the test
        resumes with ``h`` restarted from ``H`` over the sets (:mod:`verified.consistency.energy_cadence`;
        only in one in-process batch, which continues the run from its sets). 0: never.
        None: 2 on second-order sets where ``h`` integrates the derived rate
        ``grad H . f`` (there it costs most: the rate runs through the composition's
        Taylor models), else 0 (doubletons; a declared rate such as ``dH/dt = 0``).
    test_backoff : int or None
        The same for the tests at ``RA``'s peaks (``t*``): after a test that pruned
        nothing, the next 1, 2, 4, ... (at most this many) steps' peaks are passed by;
        a test due by ``test_interval`` always runs. None: 16 on second-order sets, 0 on
        doubletons. (On robots tests at the peaks can prune nothing while each rolls
        the run back a step; docs/lab/code_notes.md.)
    """

    def __init__(self, energy: Graph | None = None, energy_rate="derive", constraints=(), *,
                 test_interval: float | None = None, test_splits: int | None = None,
                 split_strategy: str | None = None, refine: str = "pruned", min_gain: float = 0.1,
                 backward_depth: int = 0, max_boxes: int = 4096, contract: str = "step",
                 prune: bool = True, align=None, check_claim: bool = True, reset_h: bool = False,
                 max_interval: float | None = None, splits: int | None = None, contract_backoff: int | None = None,
                 test_backoff: int | None = None, strategy: str | None = None, suspend_after: int | None = None):
        # one name per knob (issue 15): test_interval / test_splits / split_strategy as everywhere else;
        # the old names are accepted so that existing callers keep working, and the
        # error messages below name whichever the caller used
        interval_name = "max_interval" if max_interval is not None else "test_interval"
        splits_name = "splits" if splits is not None else "test_splits"
        strategy_name = "strategy" if strategy is not None else "split_strategy"
        test_interval = _renamed(test_interval, max_interval, "test_interval", "max_interval", 0.1)
        test_splits = _renamed(test_splits, splits, "test_splits", "splits", 10)
        split_strategy = _renamed(split_strategy, strategy, "split_strategy", "strategy", "gradient")
        if energy is None and not constraints:
            raise ValueError("EnergyTest needs an energy graph or at least one constraint")
        if energy is not None and (not isinstance(energy, Graph) or energy.n_outputs != 1):
            raise ValueError("energy must be a Graph with one output (H)")
        if energy_rate is None:
            # None always reached lift_graphs as "no rate graph", i.e. a declared 0
            deprecated("EnergyTest(energy, None)")
            energy_rate = "zero"
        check_energy_rate(energy_rate, SYSTEM_RATES, "EnergyTest", graph=True)
        if split_strategy not in STRATEGIES:
            raise ValueError(f"{strategy_name} must be one of {STRATEGIES}, got {split_strategy!r}")
        if contract not in ("step", "test", "off"):
            raise ValueError(f"contract must be 'step', 'test' or 'off', got {contract!r}")
        if refine not in ("pruned", "always"):
            raise ValueError(f"refine must be 'pruned' or 'always', got {refine!r}")
        if not (np.isfinite(test_interval) and test_interval > 0):
            raise ValueError(f"{interval_name} must be a positive number of seconds, got {test_interval!r}")
        if int(test_splits) < 2:
            raise ValueError(f"{splits_name} must be >= 2, got {test_splits!r}")
        if int(backward_depth) < 0:
            raise ValueError(f"backward_depth must be >= 0, got {backward_depth!r}")
        self.energy = energy
        self.energy_rate = energy_rate
        self.constraints = tuple(constraints)
        self.test_interval = float(test_interval)
        self.test_splits = int(test_splits)
        self.split_strategy = split_strategy
        self.refine = refine
        if not 0 <= float(min_gain) < 1:
            raise ValueError(f"min_gain must be in [0, 1), got {min_gain!r}")
        self.min_gain = float(min_gain)
        self.backward_depth = int(backward_depth)
        self.max_boxes = int(max_boxes)
        self.contract = contract
        for name, value in (("contract_backoff", contract_backoff), ("test_backoff", test_backoff),
                            ("suspend_after", suspend_after)):
            if value is not None and (isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer))
                                      or value < 0):
                raise ValueError(f"{name} must be an integer >= 0 or None, got {value!r}")
        self.contract_backoff = contract_backoff
        self.test_backoff = test_backoff
        self.suspend_after = suspend_after
        #: set by verified.consistency.energy_cadence, the only driver that continues a suspended run
        self.can_suspend = False
        #: where the run stopped because the test was idle (a Start with the sets and h), or None
        self.idle_point = None
        self.prune = bool(prune)
        if align is not None and not callable(getattr(align, "set_direction", None)):
            raise ValueError("align must be an error-basis policy with set_direction "
                             "(verified.sets.bases.EnergyAlignedBasis) or None")
        self.align = align
        self.check_claim = bool(check_claim)
        self.reset_h = bool(reset_h)

    # ------------------------------------------------------------------ solver hook
    def before_run(self, setup):
        """Bind to the run (see :meth:`prepare`): the graph with ``h`` appended, the
        initial sets with ``h(0)``, steps of at most ``test_interval``."""
        if not isinstance(setup.sets, DoubletonSets):
            # (both rebuild doubleton sets: h restarted in a doubleton's C row, the
            # backward test's parts run through a first-order stepper's set algebra)
            if self.reset_h:
                raise ValueError("reset_h=True needs first-order sets (set_order=1)")
            if self.backward_depth:
                raise ValueError(f"backward_depth={self.backward_depth!r}: the backward test needs first-order sets "
                                 "(set_order=1); second-order sets run the energy test without it")
        graph = self.prepare(setup.user_graph, setup.graph, setup.n_state, setup.params, t0=setup.t0)
        # (see contract_backoff, test_backoff)
        self._set_waits(0 if isinstance(setup.sets, DoubletonSets) else 16)
        derived = (isinstance(self.energy_rate, str) and self.energy_rate == "derive") or self._lifted.rate_unproven
        if self.suspend_after is None and not derived:
            self._suspend_after = 0  # (a declared rate, e.g. dH/dt = 0: h costs little, nothing to save)
        self._refute_claim(setup.sets.hull(), setup.sets.c, setup.t0)
        self._warn_unproven()
        # "a test at least every test_interval seconds" (contraction alone needs no cap:
        # it runs after every step, and a cap changes the steps of the run it is compared with)
        tests = self.prune or self.contract == "test"
        return replace(setup, graph=graph, sets=self.initial_sets(setup.sets),
                       h_max=min(setup.h_max, self.test_interval) if tests else setup.h_max)

    def after_step(self, step, sets, run):
        out = self._after_step(step, sets, run)
        if self.align is not None and self._lifted.energy is not None:
            final = sets if out is None else out
            g = None
            if final.n_sets:
                with np.errstate(all="ignore"):
                    g = self._lifted.jac(self._lifted.residual, point(final.c))[:, 0, :].mid()
            self.align.set_direction(g)
        if (self.can_suspend and self._suspend_after and self._idle_tests >= self._suspend_after
                and not run.status and not run.landed_on_last_output(step)):
            # idle: the run stops here and verified.consistency.energy_cadence goes on without the test
            final = sets if out is None else out
            self.idle_point = replace(run.resume_point(), sets=final)
            self.stats["suspensions"] = self.stats.get("suspensions", 0) + 1
            run.stop(f"{IDLE}: {self._idle_tests} tests in a row pruned and narrowed nothing", "stopped")
        return out

    @property
    def claim_proof(self):
        """The :class:`verified.consistency.graphs.ClaimProof` of the declared rate in
        the last run (None: none was checked, or no run yet)."""
        lifted = getattr(self, "_lifted", None)
        return None if lifted is None else lifted.proof

    def _warn_unproven(self):
        """One :class:`EnergyClaimWarning` when the declared rate was not proven (the
        run integrates ``grad H . f`` instead, :func:`lift_graphs`)."""
        if not self._lifted.rate_unproven:
            return
        decl = ("energy_rate='zero' (dH/dt = 0)" if isinstance(self.energy_rate, str)
                else "the energy_rate graph")
        warn_at_caller(EnergyClaimWarning(
            f"{decl} could not be proven equal to grad H . f ({self._lifted.proof.reason}); the energy test "
            "does not use it and integrates the derived rate grad H . f instead (pass energy_rate='derive' to "
            "skip the proof)"))

    def _refute_claim(self, boxes: Interval, points: np.ndarray, t: float):
        """See :func:`verified.consistency.graphs.refute_claim`."""
        refute_claim(self._lifted, boxes, points, t, self.energy_rate)

    def _after_step(self, step, sets, run):
        """Contract the sets with ``H(x) - h = 0`` (``contract="step"``), record
        ``RA(t)``; at ``t*`` branch and prune (returns the surviving sets)."""
        changed = False
        if self.reset_h and self._lifted.energy is not None:
            sets, ch = self._reset_h(sets)
            changed |= ch
        if self._lifted.claim is not None:
            # the claim over every state the step's tube encloses, and at the new centres
            self._refute_claim(step.tube, sets.c, step.t)
        if self.contract == "step" and self._contraction is not None and self._contract_wait.skip():
            self.stats["contractions_skipped"] += 1
        elif self.contract == "step" and self._contraction is not None:
            sets, ch, narrowed = self._contract(sets)
            self._contract_wait.done(narrowed)
            self._narrowed_since_test |= narrowed
            changed |= ch
            if sets.n_sets == 0:
                run.stop("the energy contraction removed every set (inconsistent model or energy rate?)",
                         "breakdown")
                return sets
        decision = self.observe(step.t, sets)
        if self._test_wait.skip() and decision == "previous":
            decision = None  # (backing off: an RA peak, but the last tests pruned nothing)
            self.stats["tests_skipped"] += 1
        only = None
        trigger = "RA maximum" if decision == "previous" else "interval"
        if decision == "previous":
            only = self._tracker.peaked  # the sets whose RA peaked (same order before and after the step)
            back = run.rollback() if not changed else None
            if back is not None:
                # RA(t) peaked at the previous step: t* is there, roll back to it
                step, sets = back
                self.forget_last()
            # else (the sets were replaced since: no rollback) test now, one step after the peak
            decision = "now"
        if decision != "now" or not (self.prune or self.contract == "test"):
            if decision == "now":
                self._tracker.tested(step.t)
            return sets if changed else None
        if self.contract == "test" and self._contraction is not None:
            sets, _, _ = self._contract(sets)
        if self.prune:
            prev = (step.previous, step.h, run.make_stepper) if self.backward_depth else None
            pruned_before = self.stats["pruned_boxes"]
            if only is not None and only.shape == (sets.n_sets,) and not only.all():
                # test only the sets whose RA peaked; the others continue unchanged
                tested = self.apply(step.t, step.t_enclosure, sets.take(np.flatnonzero(only)), prev,
                                    trigger=trigger)
                sets = type(sets).concatenate([sets.take(np.flatnonzero(~only)), tested])
            else:
                sets = self.apply(step.t, step.t_enclosure, sets, prev, trigger=trigger)
            gained = self.stats["pruned_boxes"] > pruned_before
            self._test_wait.done(gained)
            self._idle_tests = 0 if gained or self._narrowed_since_test else self._idle_tests + 1
            self._narrowed_since_test = False
        else:
            self._tracker.tested(step.t)
        if sets.n_sets == 0:
            run.stop("the consistency test removed every set (inconsistent model or constraints?)", "breakdown")
        return sets

    def _reset_h(self, sets):
        """``(sets, changed)``: ``h`` restarted from ``H`` where ``H_V`` became wider
        than ``H_H`` (:func:`verified.consistency.energy_state.reset_h`, in place: never a change
        the solver must take over)."""
        sets, resets = reset_h(self._lifted, sets)
        self.stats["h_resets"] += resets
        return sets, False

    def _contract(self, sets):
        """``(sets, changed, narrowed)``: the sets contracted with ``H(x) - h = 0``
        (:mod:`verified.consistency.energy_contraction`); empty sets dropped (``changed``: the batch
        was replaced; ``narrowed``: some set was narrowed or dropped)."""
        w0 = time.perf_counter()
        lifted = self._lifted
        res = self._contraction.contract(sets, lifted.p(sets.n_sets) if lifted.residual.n_params else None)
        self.stats["contractions"] += 1
        self.stats["contracted_empty"] += int(res.empty.sum())
        if res.ratio.size:
            self.stats["contraction_ratio_min"] = min(self.stats["contraction_ratio_min"], float(res.ratio.min()))
        self.stats["contraction_s"] += time.perf_counter() - w0
        if res.empty.any():
            return res.sets, True, True
        narrowed = bool((res.ratio < 1).any())
        if narrowed:
            assign(sets, res.sets)
        return sets, False, narrowed

    def after_run(self, solution):
        solution.consistency = self.finish()
        solution.stats.update(self.stats)

    # ------------------------------------------------------------------ set-up
    def prepare(self, rhs: Graph, integrated: Graph, n_x: int, params: Interval | None, t0: float = 0.0):
        """Bind to one solve: ``rhs`` is the user's ODE over ``(x, p)``; ``integrated``
        the graph the solver runs (its parameters possibly turned into states after
        ``x``). Returns the graph to integrate (with ``h`` appended when there is an
        energy) and remembers how to evaluate the constraints on the solver's sets
        (:func:`verified.consistency.graphs.lift_graphs`)."""
        lifted = lift_graphs(rhs, integrated, n_x, params, self.energy, self.energy_rate, self.constraints,
                             check_claim=self.check_claim)
        self._lifted = lifted
        self._contraction = None
        if lifted.energy is not None and self.contract != "off":
            self._contraction = EnergyContraction(lifted.residual)
        self._backward = None
        self._tracker = ReductionArea(lifted, self.test_interval, t0)
        self.record = self._tracker.record
        self.stats = dict(tests=0, pruned_boxes=0, test_s=0.0, backward_s=0.0, backward_runs=0,
                          backward_deleted=0, refinements_skipped=0, contractions=0, contracted_empty=0,
                          contraction_s=0.0, contraction_ratio_min=1.0, h_resets=0, contractions_skipped=0,
                          tests_skipped=0, energy_rate_unproven=int(lifted.rate_unproven))
        self._set_waits(0)
        return lifted.graph

    def _set_waits(self, default_cap: int):
        """The back-offs of the contraction and the RA-peak tests: the caps given, or
        ``default_cap`` where None was (0 on doubletons, 16 on second-order sets); the
        idle tests before a suspension likewise (0 on doubletons, 2 on second-order sets)."""
        def cap(value):
            return default_cap if value is None else value
        self._contract_wait = BackOff(cap(self.contract_backoff))
        self._test_wait = BackOff(cap(self.test_backoff))
        self._suspend_after = (2 if default_cap else 0) if self.suspend_after is None else int(self.suspend_after)
        self._idle_tests = 0
        self._narrowed_since_test = False

    def initial_sets(self, sets):
        """Append ``h(0) = H(x0)`` to the initial sets, correlated with ``r0``
        (:func:`verified.consistency.energy_state.initial_sets`)."""
        return initial_sets(self._lifted, sets)

    # ------------------------------------------------------------------ RA(t)
    def observe(self, t: float, sets) -> str | None:
        """Record ``RA(t)`` and say whether to test
        (:meth:`verified.consistency.reduction_area.ReductionArea.observe`)."""
        return self._tracker.observe(t, sets)

    def forget_last(self):
        """The solver rolled the last step back (the test runs at the step before)."""
        self._tracker.forget_last()

    @property
    def peaked(self):
        """The sets whose ``RA`` peaked at ``t*`` (:class:`verified.consistency.reduction_area.ReductionArea`)."""
        return self._tracker.peaked

    # ------------------------------------------------------------------ branch and prune
    def apply(self, t: float, t_iv: Interval, sets, previous=None, trigger: str = "interval"):
        """Branch and prune all sets at time ``t`` (enclosed by ``t_iv``); returns the
        surviving sets.

        Each set is cut (bisection rounds, or one grid) into a tree of parts; parts
        inconsistent with a constraint are discarded between rounds. What survives
        is returned as the largest consistent subtrees: a node none of whose
        descendants was pruned stays one set (``refine="pruned"``), so splitting
        costs integration time only where something was cut away
        (:func:`verified.consistency.branch_prune.branch_and_prune`).

        ``previous``: ``(sets, h_step, make_stepper)`` of the step before, for the
        backward test (or None). ``trigger``: why the test runs, kept in its
        :class:`~verified.consistency.reduction_area.TestRecord` ("RA maximum" or "interval")."""
        w0 = time.perf_counter()
        nb0 = sets.n_sets
        res = branch_and_prune(self._lifted, sets, t_iv, strategy=self.split_strategy, test_splits=self.test_splits,
                               refine=self.refine, min_gain=self.min_gain)
        parts, root = res.parts, res.root
        tested_hulls, tested_kept = res.tested_hulls, res.tested_kept
        self.stats["test_s"] += time.perf_counter() - w0
        # backward consistency test on the parts the energy test could not decide
        removed_back = 0
        if self.backward_depth and previous is not None and parts.n_sets:
            parts, root, gone = self._backward_test(parts, root, previous)
            removed_back = gone.size
        w1 = time.perf_counter()
        out = parts
        if out.n_sets > self.max_boxes:
            # too many sets: keep whole every set with a consistent part
            self.stats["refinements_skipped"] += 1
            out = sets.take(np.unique(root))
        self.stats["tests"] += 1
        self.stats["pruned_boxes"] += res.n_pruned + removed_back
        n_s = self._lifted.n_s
        hv = hull(sets.hull()[:, n_s], axis=0) if self._lifted.energy is not None else None
        empty = Interval._from_bounds(np.zeros((0, self._lifted.n_x)), np.zeros((0, self._lifted.n_x)))
        self._tracker.tested(t, TestRecord(
            t=t,
            candidates=concatenate(tested_hulls, axis=0) if tested_hulls else empty,
            kept=np.concatenate(tested_kept) if tested_kept else np.zeros(0, bool),
            h_v=hv, sets_before=nb0, sets_after=out.n_sets,
            backward_deleted=removed_back, trigger=trigger))
        self.stats["test_s"] += time.perf_counter() - w1
        return out

    # ------------------------------------------------------------------ backward (cases A, B, C)
    def _backward_test(self, parts, root, previous):
        """The backward test (:func:`verified.consistency.backward_test.backward_test`) on the parts
        the energy test kept, with the negated ODE's stepper made once per run; returns
        the kept parts, their root set indices, and the root index of each deleted part."""
        w0 = time.perf_counter()
        prev_sets, h_step, make_stepper = previous
        if self._backward is None:
            self._backward = make_stepper(negated(self._lifted.graph))
        parts, root, gone, runs = backward_test(parts, root, prev_sets, h_step, self._backward,
                                                self.backward_depth)
        self.stats["backward_runs"] += runs
        self.stats["backward_deleted"] += int(gone.size)
        self.stats["backward_s"] += time.perf_counter() - w0
        return parts, root, gone

    # ------------------------------------------------------------------ results
    def finish(self) -> ConsistencyRecord:
        """The run's :class:`ConsistencyRecord` (:meth:`verified.consistency.reduction_area.ReductionArea.finish`)."""
        return self._tracker.finish()

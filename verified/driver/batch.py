# Whole: the driver loop (_Run) and its set-up (_setup, VerifiedODE) share the run's state.
"""One in-process batch of :func:`verified.solver.solve`: the driver loop.

:func:`solve_batch` is what ``solve`` runs once it has decided on one batch in this
process (``workers=1``, or the default on a small batch), and what
:mod:`verified.execution` runs for each chunk: the initial boxes (or the sets of a
:class:`~verified.driver.solution.Start`) advance together with one common step size through
the batched QR-Lohner step of :mod:`verified.steppers.lohner`.

The driver loop: per step it takes the hull of the sets, asks the step control
(:mod:`verified.driver.control`) for a step size the stepper (a
:class:`verified.steppers.protocol.Stepper` of the run's set kind, :mod:`verified.steppers.set_kinds`) can
validate, advances the sets (:mod:`verified.sets`) to a
:class:`~verified.steppers.protocol.StepResult`, records it, and calls the hooks
(:mod:`verified.driver.hooks`: progress, the consistency test, stop rules); adaptive splitting
and merging follow. See ``docs/architecture.md``.

Imports: this module sits below :mod:`verified.execution` and :mod:`verified.solver`
(``solver -> parallel -> batch -> solution``) and imports neither.
"""

from __future__ import annotations

import copy
import math
import time
from dataclasses import replace
from fractions import Fraction
from functools import partial

import numpy as np

from verified.series.affine_taylor import AffineTaylorODE
from verified.arith.exact import enclose_fraction
from verified.graph import Graph
from verified.driver.hooks import ProgressHook, RunSetup, check_hooks
from verified.arith.interval import Interval, concatenate, hull, stack_hulls
from verified.arith.linalg import SingularMatrixError
from verified.steppers.lohner import LohnerStepper
from verified.sets.bases import BlockBasis
from verified.driver.control import MergePolicy, SplitPolicy, StepControl, WrapControl
from verified.steppers.set_kinds import SetKind, set_kind
from verified.sets.second_order import QuadraticSets
from verified.sets.first_order import DoubletonSets
from verified.sets.protocol import SetView, set_view
from verified.driver.solution import Failure, PieceResult, Solution, Start, pieces_summary
from verified.driver.solver_args import check_arithmetic, check_graph, check_params, check_settings, initial_boxes
from verified.series.taylor import TaylorODE
from verified.series.taylor_model import TaylorModelODE
from verified.series.variational import params_as_states, second_variational_graph, variational_graph

__all__ = ["solve_batch", "VerifiedODE", "MODEL_CAPS"]


class VerifiedODE:
    """An ODE graph prepared for verified integration (Taylor tapes built once).

    Reuse one instance across :func:`solve` calls to skip the preparation.
    """

    #: fresh symbols for the variational series in affine arithmetic (one set at a
    #: time), on variational tapes of at least DEEP_TAPE slots (a 6-dof arm's: 28-37k;
    #: small graphs have few paths for a lumped error to fan out along)
    FRESH_SLOTS = 24
    DEEP_TAPE = 10_000

    def __init__(self, graph: Graph, arithmetic: str = "interval"):
        self.graph = check_graph(graph)
        self.arithmetic = check_arithmetic(arithmetic)
        if arithmetic in ("affine", "taylor_model"):
            # fresh symbols for the errors of the solution's own coefficients only: for
            # the variational series they cost more and change nothing (docs/lab/code_notes.md)
            self.taylor = AffineTaylorODE(graph)
        else:
            self.taylor = TaylorODE(graph)
        self.n = graph.n_inputs
        self._augmented = None
        self._variational = None

    @property
    def variational(self):
        """Evaluator of the variational equations (built on first use: the first-order and
        mean-value steps need it, the composition does not, and on a robot's graph the
        variational graph takes a large share of the preparation)."""
        if self._variational is None:
            self._variational = self._variational_evaluator()
        return self._variational

    def _variational_evaluator(self):
        graph = self.graph
        if self.arithmetic == "affine":
            variational = AffineTaylorODE(variational_graph(graph), fresh_symbols=0)
            if variational._tape.op.size >= self.DEEP_TAPE:
                # fresh symbols for the errors of the slots that create the most error
                # in the Jacobian (AffineTaylorODE fresh_slots; one set at a time):
                # narrower at the same cost on deep robot graphs (docs/lab/code_notes.md).
                # A fixed count, so that an inert extra state (a controller's time)
                # changes nothing.
                variational.fresh_slots = self.FRESH_SLOTS
            return variational
        if self.arithmetic == "taylor_model":
            # the Jacobian over a set in degree-2 Taylor models (verified.series.taylor_model):
            # its spread is what the QR-Lohner error part grows by every step, and
            # it is tighter than affine (docs/lab/code_notes.md). The solution's own
            # coefficients stay affine: with fresh symbols
            # per order they are tighter at high orders than models without.
            return TaylorModelODE(variational_graph(graph))
        return TaylorODE(variational_graph(graph))

    @property
    def second_variational(self) -> TaylorODE:
        """Interval Taylor evaluator of the second variational equations (built on first
        use: only second-order sets need it)."""
        if getattr(self, "_second", None) is None:
            self._second = TaylorODE(second_variational_graph(self.graph))
        return self._second

    def second_variational_along(self, directions: int):
        """Evaluator over a set's own forms (affine, or Taylor models with
        ``arithmetic="taylor_model"``) of the second variational equations along
        ``directions`` columns (:func:`verified.series.variational.second_variational_graph`),
        built on first use for each count."""
        cache = self.__dict__.setdefault("_second_along", {})
        if directions not in cache:
            graph = second_variational_graph(self.graph, directions)
            cache[directions] = (AffineTaylorODE(graph, fresh_symbols=0) if self.arithmetic == "affine"
                                 else TaylorModelODE(graph))
        return cache[directions]

    @property
    def second_variational_over_set(self):
        """Affine (or, with ``arithmetic="taylor_model"``, degree-2 Taylor model) evaluator
        of the second variational equations over a set's own forms (None for interval
        arithmetic)."""
        if self.arithmetic == "interval":
            return None
        if getattr(self, "_second_affine", None) is None:
            graph = self.second_variational.graph
            self._second_affine = (AffineTaylorODE(graph, fresh_symbols=0) if self.arithmetic == "affine"
                                   else TaylorModelODE(graph))
        return self._second_affine

    @property
    def set_models(self) -> TaylorModelODE:
        """Degree-2 Taylor-model evaluator of the right-hand side itself, for
        ``set_step="composition"`` (built on first use)."""
        if getattr(self, "_set_models", None) is None:
            self._set_models = TaylorModelODE(self.graph)
        return self._set_models

    def with_params_as_states(self) -> "VerifiedODE":
        """The same ODE with its parameters as extra constant states (built once)."""
        if self._augmented is None:
            self._augmented = VerifiedODE(params_as_states(self.graph), self.arithmetic)
        return self._augmented


def solve_batch(
    ode,
    x0,
    t_span,
    *,
    params=None,
    t_eval=None,
    order: int = 12,
    tol: float = 1e-10,
    subdivision=None,
    h_max: float | None = None,
    h_min: float = 1e-9,
    max_steps: int = 100_000,
    max_width: float = 1e3,
    adaptive: bool = False,
    split_ratio: float = 0.01,
    max_boxes: int = 4096,
    wrap_target: float = 0.03,
    merge_slack: float | None = None,
    error_basis: str = "qr",
    arithmetic: str | None = None,
    set_order: int = 1,
    set_step: str = "mean_value",
    model_degree: int | None = None,
    model_caps: dict | None = None,
    min_order: int | None = None,
    absorb: bool = False,
    params_per_state: int | None = None,
    consistency=None,
    hooks=(),
    progress=None,
    start: Start | None = None,
    prepared: dict | None = None,
) -> Solution:
    """:func:`verified.solver.solve` as one batch in this process (its arguments but the
    chunking ones: ``workers``, ``client``, ``chunks``, ``rechunk``; see its docstring).
    Every argument is checked, in ``solve``'s order, before the tapes are built and before
    any step. ``prepared``: a dict in which the VerifiedODEs this run builds are kept
    by graph, for runs that continue each other on the same graphs
    (:mod:`verified.consistency.energy_cadence`); None: built for this run only."""
    wall0 = time.perf_counter()
    # every argument is checked before the tapes are built and before any step
    t0, t1, outs, h_max = check_settings(
        t_span=t_span, t_eval=t_eval, order=order, tol=tol, h_max=h_max, h_min=h_min, max_steps=max_steps,
        max_width=max_width, adaptive=adaptive, split_ratio=split_ratio, max_boxes=max_boxes,
        wrap_target=wrap_target, merge_slack=merge_slack, error_basis=error_basis, progress=progress)
    # (the method settings were checked by the method they describe, verified.methods,
    # before solve handed them here: only what depends on the run is checked below)
    model_caps = None if model_caps is None else dict(model_caps)
    if absorb and (set_order != 1 or adaptive or consistency is not None):
        # (a consistency test's contraction works on sets with one parameter per state;
        # adaptive splitting would split along absorbed errors without end)
        raise ValueError("absorb=True needs set_order=1, adaptive=False, no consistency test and no "
                         "states appended by a hook")
    hook_list = ([ProgressHook(progress, t1)] if progress is not None else []) \
        + check_hooks([] if consistency is None else [consistency]) + check_hooks(hooks)
    kind = set_kind(set_order, set_step)
    setup, prob, param_boxes, boxes = _setup(ode, x0, t0, h_max, params, subdivision, arithmetic, kind.sets,
                                             prepared)
    if start is not None:
        setup, boxes = _resume(setup, start, boxes, kind, consistency)
    for hook in hook_list:
        setup = hook.before_run(setup) or setup
    appended = setup.graph is not prob.graph
    if appended:  # a hook appended states (the energy test's h)
        prob = _verified_ode(setup.graph, prob.arithmetic, prepared)
        if setup.graph.n_inputs > setup.n_steer and isinstance(error_basis, str):
            # appended states keep a box of their own in the error basis: rotated into the
            # states' basis, h's error widened the states, second-order sets too
            # (docs/energy_contraction.md, docs/lab/code_notes.md)
            error_basis = BlockBasis(error_basis, setup.n_steer)
    if absorb and appended:
        raise ValueError("absorb=True needs set_order=1, adaptive=False, no consistency test and no "
                         "states appended by a hook")
    stepper = _stepper(kind, prob, order, setup.params, error_basis, bool(absorb), params_per_state, model_degree,
                       model_caps, min_order)
    stepper.steer = setup.n_steer
    control = StepControl(tol=tol, h_min=h_min, h_max=setup.h_max, steer=setup.n_steer)
    wrap = WrapControl(target=wrap_target, h_max=setup.h_max, steer=setup.n_steer)
    if start is not None:
        wrap.h_limit = float(start.h_limit)
        if adaptive and start.split_scale is not None:  # (an (N,) ratio: SplitPolicy broadcasts it)
            split_ratio = split_ratio * np.asarray(start.split_scale, float)
    split = SplitPolicy(split_ratio, max_boxes, tol) if adaptive else None
    merge = MergePolicy(merge_slack) if adaptive and merge_slack is not None else None
    def make_stepper(graph):  # a stepper of this run's kind for another graph (backward tests)
        return _stepper(kind, VerifiedODE(graph, prob.arithmetic), order, setup.params, error_basis,
                        model_degree=model_degree, model_caps=model_caps)

    run = _Run(setup, boxes[:, :setup.n_state], outs, make_stepper, None if start is None else start.t_exact,
               wrap=wrap)
    steps = 0
    try:
        while run.next_out < outs.size:
            if steps >= max_steps:
                run.stop(f"maximum number of steps ({max_steps}) reached", "breakdown")
                break
            X = run.hull_for_step(param_boxes, setup.n_state, setup.n_steer, max_width)
            if X is None:
                break
            step = _try_step(run, stepper, control, wrap, X, h_min)
            if step is _END:
                break
            if step is _RETRY:
                continue
            steps += 1
            wrap.update(step)
            run.call_hooks(hook_list, step)
            if step.landed and run.sets.n_sets:
                run.record_output()
            if run.status or not _split_and_merge(run, split, merge, step):
                break
    except KeyboardInterrupt:
        # Ctrl-C: everything recorded so far is verified; return it
        run.stop(f"interrupted (KeyboardInterrupt) after t = {run.tube_t[-1]:g}", "interrupted")
    result = run.solution(setup.n_state, order, boxes.shape[0], steps, tuple(prob.graph.input_names[:setup.n_state]))
    result.stats["absorbed"] = stepper.absorbed
    result.stats["merged"] = stepper.merged
    if getattr(stepper, "steps_by_order", None):  # (a per-step order: how many steps ran at each)
        result.stats["steps_by_order"] = dict(sorted(stepper.steps_by_order.items()))
    result.stats["wall_s"] = time.perf_counter() - wall0
    for hook in hook_list:
        hook.after_run(result)  # records and statistics of the hooks
    result = run.by_pieces(result, continuable=consistency is None)
    result.stats["wall_s"] = time.perf_counter() - wall0
    return result


#: :func:`_try_step`'s answers other than a step: the run ends / the loop tries again
#: (some sets failed and were dropped; the others take the step without them)
_END = object()
_RETRY = object()


def _try_step(run, stepper, control: StepControl, wrap: WrapControl, X: Interval, h_min: float):
    """One step of every set of ``run`` from their hull boxes ``X``: the Taylor
    coefficients, an a-priori enclosure validated by ``control``, then the sets advanced.
    Returns the step, or :data:`_RETRY` where the sets that broke down were dropped (the
    others try again), or :data:`_END` where the run stops (its reason set)."""
    stepper.begin(run.sets)
    cX = stepper.coefficients(X)
    run.evaluations += 1
    bounded = np.isfinite(cX.lo).all(axis=(1, 2)) & np.isfinite(cX.hi).all(axis=(1, 2))
    if not bounded.all():
        # those sets' pieces break down; the others take this step without them
        if run.fail(~bounded, "Taylor coefficients are unbounded (an operation left its domain over the "
                              "sets, e.g. a division by an interval containing zero, or overflowed)") is None:
            return _END
        return _RETRY
    gap_lo, gap_hi = run.gap()
    found = control.validate(stepper, X, cX, control.propose(stepper, cX, wrap.h_limit, gap_lo, gap_hi))
    run.evaluations += found.evaluations
    run.rejected += found.rejected
    if found.enclosure is None:
        why = f"step size underflow: no a-priori enclosure validated with h >= {h_min:g}"
        bad, tries = _unvalidated(stepper, run.sets, X, found.h)
        run.evaluations += tries
        if bad is None:
            run.stop(why, "breakdown")
            return _END
        if run.fail(bad, why) is None:  # (the sets that fail alone; the others go on)
            return _END
        return _RETRY
    try:
        return run.advance(stepper, X, found, gap_lo, gap_hi)
    except SingularMatrixError as exc:
        # a set so wide that its basis or its recentring cannot be inverted any
        # more (non-finite or singular enclosures): everything up to here stands
        run.stop(f"set update failed at t = {run.t:g}: {exc}", "breakdown")
        return _END


def _split_and_merge(run, split: SplitPolicy | None, merge: MergePolicy | None, step) -> bool:
    """Adaptive splitting and merging of ``run``'s sets after ``step`` (each where its
    policy is given); False where the run ends (every piece over the sets' budget)."""
    if split is not None:
        before = run.sets
        run.sets, n_split, reason = split.apply(step, run.sets)
        if reason:
            # over the budget of sets: the pieces whose sets ask to be split now
            # break down (all of them when they are all of them)
            if run.fail(split.select(step), reason) is None:
                return False
        if n_split:
            run.pieces.split(split.select(step), before, run.sets)
        run.splits += n_split
        run.max_sets = max(run.max_sets, run.sets.n_sets)
    if merge is not None:
        run.sets, merged = merge.apply(run.sets)
        if merged:
            run.pieces.replaced(run.sets.n_sets, run.t)  # (which sets merged: not told)
        run.merges += merged
    return True


def _unvalidated(stepper, sets, X: Interval, h: float):
    """The sets (B,) bool whose a-priori enclosure does not validate on their own with
    the step ``h`` (the smallest the batch tried), found by bisecting the batch (each
    group tested as a batch of its own: ``begin``, coefficients, ``apriori``); None
    when no set fails alone (the batch as a whole failed: no culprit to drop). Returns
    ``(bad, evaluations)``."""
    B = sets.n_sets
    if B < 2:
        return None, 0
    bad = np.zeros(B, dtype=bool)
    evaluations = 0
    todo = [np.arange(B // 2, B), np.arange(B // 2)]  # (the whole batch failed: start from its halves)
    while todo:
        idx = todo.pop()
        sub = sets.take(idx)
        stepper.begin(sub)
        Xs = X[idx]
        cXs = stepper.coefficients(Xs)
        evaluations += 2
        ok = bool(np.isfinite(cXs.lo).all() and np.isfinite(cXs.hi).all()) and stepper.apriori(Xs, cXs, h) is not None
        if ok:
            continue
        if idx.size == 1:
            bad[idx] = True
        else:
            todo += [idx[idx.size // 2:], idx[:idx.size // 2]]
    return (bad if bad.any() else None), evaluations


def _verified_ode(graph, arithmetic: str, prepared: dict | None) -> "VerifiedODE":
    """``VerifiedODE(graph, arithmetic)``, kept in ``prepared`` by the graph's
    fingerprint when that dict is given (building one costs its tapes)."""
    if prepared is None:
        return VerifiedODE(graph, arithmetic)
    key = (graph.fingerprint(), arithmetic)
    if key not in prepared:
        prepared[key] = VerifiedODE(graph, arithmetic)
    return prepared[key]


def _setup(ode, x0, t0, h_max, params, subdivision, arithmetic, sets_type=DoubletonSets, prepared=None):
    """The checked problem: ``(RunSetup, VerifiedODE, param_boxes, boxes)``. Uncertain
    parameters become constant states after the ODE's (``param_boxes`` (p,): their
    hull over the initial boxes, else None); ``boxes`` (B, N) the initial boxes, the
    initial sets ``sets_type.from_boxes`` (:mod:`verified.steppers.set_kinds`)."""
    graph = check_graph(ode.graph if isinstance(ode, VerifiedODE) else ode)
    n = graph.n_inputs
    boxes = initial_boxes(x0, n, subdivision)
    nb = boxes.shape[0]
    params = check_params(params, graph, nb, subdivision)
    if isinstance(ode, VerifiedODE):
        if arithmetic is not None and check_arithmetic(arithmetic) != ode.arithmetic:
            raise ValueError(f"arithmetic={arithmetic!r} differs from the VerifiedODE's {ode.arithmetic!r}")
        prob = ode
    else:
        prob = _verified_ode(graph, "interval" if arithmetic is None else arithmetic, prepared)
    param_boxes = None
    if params is not None and (params.width() > 0).any():
        # Uncertain parameters become constant states, so their influence is carried
        # by the linear part of the set instead of being wrapped every step.
        prob = prob.with_params_as_states()
        p_boxes = params.broadcast_to((nb, params.shape[-1])) if params.ndim == 1 else params
        boxes = concatenate([boxes, p_boxes], axis=1)
        param_boxes = hull(p_boxes, axis=0)  # (p,): valid for every set, also after splits
        params = None
    setup = RunSetup(user_graph=graph, graph=prob.graph, n_state=n, n_steer=prob.n, params=params, t0=t0,
                     sets=sets_type.from_boxes(boxes), h_max=h_max)
    return setup, prob, param_boxes, boxes


def _resume(setup: RunSetup, start: Start, boxes: Interval, kind: SetKind, consistency):
    """``(setup, boxes)`` continuing from ``start`` (``solve(start=)``): its sets and
    time instead of the sets made from ``x0``, after the checks that they fit. A
    consistency test starts afresh there: the sets hold the run's states only, and the
    test appends its energy state ``h`` to them at the start time, as at ``t0``
    (``h = H(x)`` holds along every true trajectory at every time)."""
    sets = start.sets
    if not isinstance(sets, kind.sets):
        raise ValueError(f"start.sets must be {kind.sets.__name__} for this set_order/set_step, "
                         f"got {type(sets).__name__}")
    X = sets.hull()
    if X.shape != boxes.shape:
        raise ValueError(f"start.sets have hull shape {X.shape}, the run expects {boxes.shape} "
                         "(x0: their hull boxes; params: as the run that made them)")
    if not isinstance(start.t_exact, Fraction):
        raise ValueError("start.t_exact must be a Fraction (the exact time of the sets)")
    if not float(start.t_exact) >= setup.t0:
        raise ValueError(f"start.t_exact = {float(start.t_exact):g} is before t_span[0] = {setup.t0:g}")
    return replace(setup, sets=sets, t0=float(start.t_exact)), X


def _state_view(view, n_sets: int, n_state: int):
    """The first ``n_state`` states of a step's tube view (copied, so that the step's
    full arrays are not kept alive for every step of a run), or None."""
    if view is None or view.n_sets != n_sets:
        return None
    A = np.ascontiguousarray(view.A.lo[:, :n_state])  # (a point matrix)
    return SetView(c=np.ascontiguousarray(view.c[:, :n_state]), A=Interval._from_bounds(A, A), R=view.R)


class _PieceBook:
    """Which initial pieces (the run's initial boxes) each set may hold solutions of,
    and which pieces broke down where.

    Every set carries one piece (``origin``, (B,)), and the pieces form groups
    (``group``, (P,): the smallest piece of each piece's group): a set may hold
    solutions of every piece of its origin's group. At the start each initial box is
    its own set and its own group. The driver's own operations keep the
    correspondence: a set pruned (its row goes), a split (both halves keep their
    parent's piece), a break-down (:meth:`fail`: every set of the failed groups goes).
    Where the driver cannot tell which new set came from which (a hook that returned
    new sets, a merge of neighbouring sets, initial sets a hook returned in another
    number), every live piece joins one group (:meth:`replaced`): a later failure then
    fails them all together, as every failure did before per-piece break-downs.

    The invariant (what keeps dropping sets sound): the solutions from a live piece P
    lie, at the run's time, in the union of the sets whose origin is in P's group. A
    failure kills whole groups, so the sets kept hold every solution of every live
    piece. The origin arrays are replaced, never changed in place: the records of
    outputs and steps share them while they do not change.
    """

    def __init__(self, n_pieces: int, n_sets: int):
        self.group = np.arange(n_pieces)
        self.alive = np.ones(n_pieces, dtype=bool)
        self.event = np.full(n_pieces, -1)  # index into events of the failure that ended each piece
        self.events = []  # (t, reason) of each failure, in the order they happened
        self.linked_at = None  # the time all live pieces were first linked (None: never)
        self.origin = np.arange(n_pieces)
        if n_sets != n_pieces:
            self.replaced(n_sets, None)

    def take(self, keep: np.ndarray) -> None:
        """The sets kept by the mask ``keep`` (sets pruned)."""
        self.origin = self.origin[keep]

    def replaced(self, n_sets: int, t) -> None:
        """New sets (``n_sets``) whose provenance is unknown: every live piece joins one
        group, which every new set carries."""
        live = np.flatnonzero(self.alive)
        if live.size == 0:
            self.origin = np.zeros(n_sets, dtype=np.intp)
            return
        root = int(live[0])
        if (self.group[live] != root).any() and self.linked_at is None:
            self.linked_at = t
        self.group = np.where(self.alive, root, self.group)
        self.origin = np.full(n_sets, root, dtype=np.intp)

    def link(self, pieces: np.ndarray) -> int:
        """Join the groups of ``pieces`` (indices) into one; returns its root."""
        roots = np.unique(self.group[pieces])
        root = int(roots[0])
        if roots.size > 1:
            self.group = np.where(np.isin(self.group, roots), root, self.group)
        return root

    def split(self, mask: np.ndarray, before, after) -> None:
        """The sets ``mask`` of ``before`` were split in two (``after = before.split(mask)``:
        the sets not split in their order, then the halves). Both halves keep their
        parent's piece: the layout of the halves is that of ``before``'s type (set-major
        for doubletons, side-major for second-order sets), checked against the parents'
        hulls; where it does not fit, the parents' groups are joined instead."""
        idx = np.flatnonzero(mask)
        parents = self.origin[idx]
        rest = self.origin[~mask]
        k = idx.size
        if after.n_sets != before.n_sets + k:
            self.replaced(after.n_sets, None)  # (not a split of those sets: provenance unknown)
            return
        if k == 0 or (self.group[parents] == self.group[parents[0]]).all():
            self.origin = np.concatenate([rest, np.full(2 * k, parents[0] if k else 0, dtype=np.intp)])
            return
        if isinstance(before, DoubletonSets):
            which = np.repeat(np.arange(k), 2)  # set-major: a1 a2 b1 b2 ...
        elif isinstance(before, QuadraticSets):
            which = np.tile(np.arange(k), 2)  # side-major: a1 b1 ... a2 b2 ...
        else:
            which = None
        if which is not None:
            # a half lies in its parent's hull (up to the rounding its recentring folds
            # into the set): the layout above is the split's
            P = before.take(idx).hull()
            H = after.take(np.arange(before.n_sets - k, after.n_sets)).hull()
            lo, hi = P.lo[which], P.hi[which]
            slack = 1e-6 * (np.abs(lo) + np.abs(hi) + (hi - lo)) + 1e-300
            with np.errstate(invalid="ignore"):
                fits = bool(((H.lo >= lo - slack) & (H.hi <= hi + slack)).all())
            if fits:
                self.origin = np.concatenate([rest, parents[which]])
                return
        root = self.link(parents)
        self.origin = np.concatenate([rest, np.full(2 * k, root, dtype=np.intp)])

    def fail(self, bad: np.ndarray, t: float, reason: str) -> np.ndarray:
        """The sets ``bad`` (B,) cannot be continued: every piece of their groups breaks
        down at ``t`` with ``reason``. Returns the mask (B,) of the sets to keep (those
        of the live pieces)."""
        roots = np.unique(self.group[self.origin[bad]])
        dead = np.isin(self.group, roots) & self.alive
        self.alive = self.alive & ~dead
        self.event = np.where(dead, len(self.events), self.event)
        self.events.append((float(t), reason))
        keep = self.alive[self.origin]
        self.origin = self.origin[keep]
        return keep

    def results(self, boxes: Interval, status: str, t_reached: float, reason: str) -> list:
        """:class:`~verified.driver.solution.PieceResult` per piece: a dead piece's failure, a
        live one with the run's ``status``, ``t_reached`` and ``reason``."""
        out = []
        for i in range(self.group.size):
            e = int(self.event[i])
            if e >= 0:
                t, why = self.events[e]
                out.append(PieceResult(i, boxes[i], "breakdown", t, why))
            else:
                out.append(PieceResult(i, boxes[i], status, float(t_reached), reason))
        return out


class _Run:
    """The state of one integration: the sets, the exact time, what has been recorded,
    and the counters. It is the :class:`~verified.driver.hooks.RunControl` the hooks get."""

    def __init__(self, setup: RunSetup, initial: Interval, outs: np.ndarray, make_stepper, t_exact=None, wrap=None):
        self.sets = setup.sets
        self.outs = outs  # (k,) output times, outs[0] = t0
        self.make_stepper = make_stepper
        self.next_out = 1
        # Time is kept exactly (a sum of float steps) so that every enclosure belongs to
        # the time it is reported at; a step landing on an output time uses an interval
        # step [h] that encloses the exact remaining gap.
        self.t_exact = Fraction(setup.t0) if t_exact is None else t_exact
        self.t = setup.t0
        if t_exact is not None:  # solve(start=): the outputs after the start (setup.t0 = float(t_exact))
            while self.next_out < outs.size and Fraction(float(outs[self.next_out])) <= t_exact:
                self.next_out += 1
        self.out_t, self.out_boxes = [setup.t0], [initial]  # initial (B, n_state): the boxes at t0
        # the sets at each output time over their own parameters (Solution.views)
        self.out_views = [set_view(setup.sets, setup.n_state)] if initial.shape[0] == setup.sets.n_sets else [None]
        self.tube_t, self.tube, self.tube_views = [setup.t0], [], []
        self.step = None  # the last accepted step (after a rollback: the one before)
        self.recent = []  # the last two steps since a hook last replaced the sets (for rollback)
        self.status, self.reason = "", ""
        self.evaluations = self.rejected = self.splits = self.merges = self.pruned = 0
        self.max_sets = self.sets.n_sets
        self.resumes = {}  # failure event -> Start of the sets it dropped (fail)
        self.stop_point = None  # Start of the sets at a break-down of the whole run (stop)
        self.n_state = setup.n_state
        self.wrap = wrap  # the wrapping control (resume_point: a run continued from here keeps its limit)
        # The initial pieces (the rows of ``initial``) and which of them each set may hold
        # solutions of (see _PieceBook): a piece whose sets cannot be continued breaks down
        # alone, the others go on
        self.pieces = _PieceBook(initial.shape[0], self.sets.n_sets)
        self.out_pieces = [np.arange(initial.shape[0])]  # per output: each box's piece
        self.tube_pieces = []  # per step: each tube box's piece
        self.initial = initial

    # ------------------------------------------------------------------ RunControl
    def stop(self, reason: str, status: str = "stopped") -> None:
        if not self.status:  # the first reason wins
            self.status, self.reason = status, reason
            if status == "breakdown" and self.sets.n_sets:
                # (the sets are those at self.t_exact: every stop comes before a step
                # replaces them or after it did; Solution.failures continues from here)
                self.stop_point = self.resume_point()

    def resume_point(self) -> Start:
        return Start(sets=self.sets, t_exact=self.t_exact,
                     h_limit=math.inf if self.wrap is None else float(self.wrap.h_limit))

    def landed_on_last_output(self, step) -> bool:
        # (hooks run before the landed output is recorded: next_out still points at it)
        return bool(step.landed) and self.next_out + 1 >= self.outs.size

    def rollback(self):
        if self.step is None or self.step.landed or len(self.recent) < 2:
            return None
        last = self.recent.pop()
        self.tube.pop()
        self.tube_t.pop()
        self.tube_views.pop()
        self.tube_pieces.pop()  # (the step kept every set's row: the pieces stay as they are)
        self.sets, self.t, self.t_exact = last.previous, last.t_start, last.t_exact_start
        self.step = self.recent[-1]
        return self.step, self.sets

    # ------------------------------------------------------------------ one step
    def hull_for_step(self, param_boxes, n_state: int, n_steer: int, max_width: float):
        """The hull (B, N) of the sets to take the step's coefficients over, or None
        (a break-down: not finite or wider than ``max_width``). Sets that are not finite
        or too wide break down their pieces alone (:meth:`fail`) when other pieces
        remain: the hull of the remaining sets is returned."""
        X = self.sets.hull()
        if param_boxes is not None:
            # Parameters never change: their true values stay in the given boxes, so
            # the hull used for the Taylor coefficients and the Jacobian may be cut
            # down to them (wrapping may have smeared error into those components).
            X[:, n_state:n_steer] = X[:, n_state:n_steer].intersect(param_boxes)
            # A set (for example one half of a split error box) whose parameter range
            # misses the parameter boxes holds no true solution: drop it.
            feasible = ~X.is_empty().any(axis=1)
            if not feasible.all():
                self.sets = self.sets.take(np.flatnonzero(feasible))
                self.pieces.take(feasible)
                X = X[feasible]
                self.pruned += int((~feasible).sum())
        finite = np.isfinite(X.lo).all(axis=1) & np.isfinite(X.hi).all(axis=1)
        if not finite.all():
            keep = self.fail(~finite, "enclosure is not finite (an operation overflowed, or divided by an interval "
                                      "containing zero)")
            if keep is None:
                return None
            X = X[keep]
        with np.errstate(invalid="ignore"):
            wide = (X[:, :n_steer].width() > max_width).any(axis=1)  # not states a hook appended (h)
        if wide.any():
            keep = self.fail(wide, f"enclosure too wide (a component exceeds width {max_width:g})")
            if keep is None:
                return None
            X = X[keep]
        return X

    def fail(self, bad: np.ndarray, reason: str):
        """The sets ``bad`` (B,) cannot be continued: the pieces they may hold solutions
        of break down at ``t`` with ``reason`` and every set of those pieces is dropped.
        Returns the mask (B,) of the sets kept, or None when none is (the run stops:
        a break-down)."""
        keep = self.pieces.fail(bad, self.t, reason)
        # the sets of the failing pieces where they stop, to go on from (Solution.failures)
        self.resumes[len(self.pieces.events) - 1] = Start(
            sets=self.sets.take(np.flatnonzero(~keep)), t_exact=self.t_exact,
            h_limit=math.inf if self.wrap is None else float(self.wrap.h_limit))
        if not keep.any():
            self.stop(reason, "breakdown")
            return None
        self.sets = self.sets.take(np.flatnonzero(keep))
        self.recent = []  # no rollback to sets that held the dropped ones
        return keep

    def gap(self):
        """Floats ``lo <= exact time to the next output <= hi``."""
        gap = Fraction(float(self.outs[self.next_out])) - self.t_exact
        return enclose_fraction(gap)  # the exact gap between two doubles

    def advance(self, stepper, X, found, gap_lo, gap_hi):
        """Take the validated step ``found`` (:class:`~verified.driver.control.Validated`),
        stamp its times and record its tube; returns the StepResult."""
        E, cE = found.enclosure
        h = found.h
        landing = h == gap_hi
        if landing:
            h_step = h if gap_lo == gap_hi else Interval(gap_lo, gap_hi)  # encloses the exact gap
            t_exact = Fraction(float(self.outs[self.next_out]))
        else:
            h_step = h
            t_exact = self.t_exact + Fraction(h)
        step = stepper.step(self.sets, h_step, X, E, cE)
        self.evaluations += 2
        step.t_start, step.t_exact_start = self.t, self.t_exact
        step.t = float(self.outs[self.next_out]) if landing else float(t_exact)
        step.t_exact, step.landed = t_exact, landing
        self.sets, self.t, self.t_exact, self.step = step.sets, step.t, t_exact, step
        self.recent = (self.recent + [step])[-2:]
        self.tube.append(step.tube[:, :self.n_state])  # (E, or a narrower box the stepper proved)
        self.tube_views.append(_state_view(step.tube_view, E.shape[0], self.n_state))
        self.tube_pieces.append(self.pieces.origin)
        self.tube_t.append(step.t)
        return step

    def call_hooks(self, hooks, step):
        for hook in hooks:
            new = hook.after_step(self.step, self.sets, self)
            if new is not None:
                if new is not self.sets:
                    self.pieces.replaced(new.n_sets, self.t)  # (which set came from which: unknown)
                self.sets = new
                self.recent = []  # no rollback past sets a hook replaced
            if self.status:
                return
        if self.sets.n_sets == 0:
            self.stop("a hook removed every set", "breakdown")
        self.max_sets = max(self.max_sets, self.sets.n_sets)

    def record_output(self):
        boxes = self.sets.hull()[:, :self.n_state]
        self.out_views.append(set_view(self.sets, self.n_state))
        self.out_t.append(self.t)
        self.out_boxes.append(boxes)
        self.out_pieces.append(self.pieces.origin)
        self.next_out += 1

    # ------------------------------------------------------------------ result
    def solution(self, n: int, order: int, n_boxes: int, steps: int, state_names: tuple) -> "Solution":
        # consistent lengths also when a KeyboardInterrupt arrived between two appends
        k = min(len(self.out_t), len(self.out_boxes))
        status, reason = self.status or "completed", self.reason
        if status == "stopped" and self.next_out == self.outs.size:
            status, reason = "completed", ""  # a stop asked for after the last output changes nothing
        n_tube = min(len(self.tube), len(self.tube_t) - 1)
        out_boxes, tube, tube_t = self.out_boxes[:k], self.tube[:n_tube], self.tube_t[:n_tube + 1]
        return Solution(
            t=np.array(self.out_t[:k]),
            boxes=out_boxes,
            hull=stack_hulls(out_boxes),
            tube_t=np.array(tube_t),
            tube=tube,
            tube_hull=stack_hulls(tube) if n_tube else Interval._from_bounds(np.zeros((0, n)), np.zeros((0, n))),
            t_reached=tube_t[-1],
            status=status,
            reason=reason,
            stats=dict(
                steps=steps,
                rejected_steps=self.rejected,
                boxes=n_boxes,
                final_boxes=self.sets.n_sets,
                splits=self.splits,
                merges=self.merges,
                pruned_sets=self.pruned,
                max_boxes=self.max_sets,
                taylor_evaluations=self.evaluations,
                order=order,
            ),
            state_names=state_names,
            views=(self.out_views + [None] * k)[:k],
            tube_views=(self.tube_views + [None] * n_tube)[:n_tube],
            piece_results=self.pieces.results(self.initial, status, tube_t[-1], reason),
        )

    def by_pieces(self, full: Solution, continuable: bool = True) -> Solution:
        """The run's Solution from ``full`` (what :meth:`solution` made, after the hooks'
        ``after_run``): ``full`` itself when no piece broke down on its own; else the
        run up to the first failure, when every piece was still verified (status
        "breakdown", ``t_reached`` that time), with ``surviving`` the whole run over
        the pieces that did not break down (None when none went on)."""
        book = self.pieces
        results = full.piece_results
        for p in results:  # (a hook's after_run may have changed the run's own outcome)
            if not p.failed:
                p.status, p.t_reached, p.reason = full.status, float(full.t_reached), full.reason
        failures = self._failures(full) if continuable else None
        if not book.events:
            full.failures = failures
            return full
        T = min(t for t, _ in book.events)
        main = _until(full, T)
        main.status = "breakdown"
        main.reason = pieces_summary(results) or book.events[0][1]
        main.piece_results = results
        main.stats["pieces_failed"] = int((~book.alive).sum())
        if full.status != "breakdown" and book.alive.any() and self.sets.n_sets:
            main.surviving = _restricted(full, book.alive, self.out_pieces, self.tube_pieces)
        main.failures = failures
        return main

    def _failures(self, full: Solution) -> list:
        """:class:`~verified.driver.solution.Failure` per group of pieces that broke down: each
        failure event's pieces (their record up to the event, the sets it dropped), and
        the pieces still alive when the whole run broke down (the sets at the stop)."""
        book = self.pieces
        out = []
        for e, (t, reason) in enumerate(book.events):
            dead = book.event == e
            start = self.resumes.get(e)
            if start is None or not dead.any():
                continue
            out.append(Failure(np.flatnonzero(dead), float(t), reason, start,
                               partial(_record_of, full, dead, t, self.out_pieces, self.tube_pieces)))
        if full.status == "breakdown" and self.stop_point is not None and book.alive.any():
            alive = book.alive.copy()
            make = (partial(_restricted, full, alive, self.out_pieces, self.tube_pieces) if book.events
                    else (lambda: full))
            out.append(Failure(np.flatnonzero(alive), float(full.t_reached), full.reason, self.stop_point, make))
        return out


def _record_of(full: Solution, pieces: np.ndarray, t: float, out_pieces: list, tube_pieces: list) -> Solution:
    """``full`` up to ``t``, restricted to ``pieces`` (a Failure's record)."""
    return _restricted(_until(full, t), pieces, out_pieces, tube_pieces)


def _until(sol: Solution, T: float) -> Solution:
    """A copy of ``sol`` with what it verified up to time ``T`` (a step boundary): the
    outputs at times <= T, the steps that end by T, the consistency record up to T."""
    keep = np.flatnonzero(np.asarray(sol.t) <= T)
    steps = int(np.sum(np.asarray(sol.tube_t)[1:] <= T))
    views = [sol.views[i] if i < len(sol.views) else None for i in keep] if sol.views else []
    n = sol.hull.shape[-1]
    return Solution(
        t=np.asarray(sol.t)[keep], boxes=[sol.boxes[i] for i in keep], hull=sol.hull[keep],
        tube_t=np.asarray(sol.tube_t)[:steps + 1], tube=list(sol.tube[:steps]),
        tube_hull=sol.tube_hull[:steps] if steps else Interval._from_bounds(np.zeros((0, n)), np.zeros((0, n))),
        t_reached=float(sol.tube_t[steps]), status=sol.status, reason=sol.reason, stats=dict(sol.stats),
        state_names=sol.state_names, consistency=_record_until(sol.consistency, T), views=views,
        tube_views=list(sol.tube_views[:steps]) if sol.tube_views else [])


def _record_until(rec, T: float):
    """A copy of a consistency record (:class:`verified.consistency.reduction_area.ConsistencyRecord`)
    with its series and tests up to time ``T``."""
    if rec is None or not hasattr(rec, "ra_t"):
        return rec
    rec = copy.copy(rec)
    ra_t = np.asarray(rec.ra_t)
    m = ra_t <= T
    for name in ("ra_t", "ra", "h_h", "h_v", "h_h_set", "h_v_set"):
        v = getattr(rec, name, None)
        if v is not None and np.shape(v)[:1] == m.shape:
            setattr(rec, name, v[m] if isinstance(v, Interval) else np.asarray(v)[m])
    rec.tests = [r for r in rec.tests if r.t <= T]
    return rec


def _restricted(sol: Solution, alive: np.ndarray, out_pieces: list, tube_pieces: list) -> Solution:
    """A copy of ``sol`` with the boxes of the pieces ``alive`` (P,) only: at each output
    and step the rows whose piece is alive (``out_pieces``, ``tube_pieces``: each row's
    piece, as recorded; rows past the record, which a hook's ``after_run`` appended
    for the sets the run ended with, are kept whole)."""

    def rows(pieces, j, m):
        if j < len(pieces) and pieces[j].shape[0] == m:
            return np.flatnonzero(alive[pieces[j]])
        return np.arange(m)

    keep_out = [rows(out_pieces, j, b.shape[0]) for j, b in enumerate(sol.boxes)]
    keep_tube = [rows(tube_pieces, j, b.shape[0]) for j, b in enumerate(sol.tube)]
    boxes = [b[r] for b, r in zip(sol.boxes, keep_out)]
    tube = [b[r] for b, r in zip(sol.tube, keep_tube)]
    n = sol.hull.shape[-1]
    empty = Interval._from_bounds(np.zeros((0, n)), np.zeros((0, n)))

    def view_rows(views, j, r, m):
        v = views[j] if j < len(views) else None
        if v is None or v.n_sets != m:
            return None
        return SetView(c=v.c[r], A=v.A[r], R=v.R[r])

    views = [view_rows(sol.views, j, r, b.shape[0]) for j, (b, r) in enumerate(zip(sol.boxes, keep_out))] \
        if sol.views else []
    tube_views = [view_rows(sol.tube_views, j, r, b.shape[0]) for j, (b, r) in enumerate(zip(sol.tube, keep_tube))] \
        if sol.tube_views else []
    out = Solution(
        t=np.asarray(sol.t), boxes=boxes, hull=stack_hulls(boxes), tube_t=np.asarray(sol.tube_t),
        tube=tube, tube_hull=stack_hulls(tube) if tube else empty, t_reached=float(sol.t_reached),
        status=sol.status, reason=sol.reason, stats=dict(sol.stats), state_names=sol.state_names,
        consistency=sol.consistency, views=views, tube_views=tube_views, piece_results=sol.piece_results)
    out.stats["pieces"] = int(alive.sum())
    return out


def _stepper(kind: SetKind, prob: VerifiedODE, order, params, error_basis, absorb=False,
             params_per_state=None, model_degree=None, model_caps=None, min_order=None) -> LohnerStepper:
    """The stepper of the run's set kind (:mod:`verified.steppers.set_kinds`) for ``prob``."""
    max_params = None if params_per_state is None else params_per_state * prob.n
    return kind.stepper(prob, order, params, error_basis, max_params, absorb, model_degree, model_caps, min_order)


#: the keys of ``solve(model_caps=...)``: the symbols with quadratic, cubic, quartic and
#: star monomials in the composition's Taylor models, and the pool of symbols for the
#: remainders born inside the graph (verified.steppers.tm_flow.TaylorModelFlowStepper)
MODEL_CAPS = ("quadratic", "cubic", "quartic", "star", "pool")

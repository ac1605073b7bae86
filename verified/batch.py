"""One in-process batch of :func:`verified.solver.solve`: the driver loop.

:func:`solve_batch` is what ``solve`` runs once it has decided on one batch in this
process (``workers=1``, or the default on a small batch), and what
:mod:`verified.parallel` runs for each chunk: the initial boxes (or the sets of a
:class:`~verified.solution.Start`) advance together with one common step size through
the batched QR-Lohner step of :mod:`verified.lohner`.

The driver loop: per step it takes the hull of the sets, asks the step control
(:mod:`verified.policies`) for a step size the stepper (a
:class:`verified.stepper.Stepper` of the run's set kind, :mod:`verified.set_kinds`) can
validate, advances the sets (:mod:`verified.sets`) to a
:class:`~verified.stepper.StepResult`, records it, and calls the hooks
(:mod:`verified.hooks`: progress, the consistency test, stop rules); adaptive splitting
and merging follow. See ``docs/architecture.md``.

Imports: this module sits below :mod:`verified.parallel` and :mod:`verified.solver`
(``solver -> parallel -> batch -> solution``) and imports neither.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from fractions import Fraction

import numpy as np

from .affine_taylor import AffineTaylorODE
from .exact import enclose_fraction
from .graph import Graph
from .hooks import ProgressHook, RunSetup, check_hooks
from .interval import Interval, concatenate, hull, stack_hulls
from .linalg import SingularMatrixError
from .lohner import LohnerStepper
from .policies import BlockBasis, MergePolicy, SplitPolicy, StepControl, WrapControl
from .set_kinds import SetKind, set_kind, set_kind_names
from .sets import DoubletonSets, SetView, set_view
from .solution import Solution, Start
from .solver_args import (check_arithmetic, check_graph, check_model_cap, check_params, check_params_per_state,
                          check_settings, initial_boxes)
from .taylor import TaylorODE
from .taylor_model import TaylorModelODE
from .variational import params_as_states, second_variational_graph, variational_graph

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
            # the variational series they cost 2.5x and changed nothing measurable
            self.taylor = AffineTaylorODE(graph)
            if arithmetic == "affine":
                self.variational = AffineTaylorODE(variational_graph(graph), fresh_symbols=0)
                if self.variational._tape.op.size >= self.DEEP_TAPE:
                    # fresh symbols for the errors of the slots that create the most error
                    # in the Jacobian (AffineTaylorODE fresh_slots; one set at a time):
                    # UR5 PD payload scene, one payload piece, to T = 2 at the same CPU
                    # time, final widths 2-5x narrower; capped runs reach 3.41 s instead
                    # of 2.56 s. A fixed count, so that an inert extra state (a
                    # controller's time) changes nothing.
                    self.variational.fresh_slots = self.FRESH_SLOTS
            else:
                # the Jacobian over a set in degree-2 Taylor models (verified.taylor_model):
                # its spread is what the QR-Lohner error part grows by every step (3-link
                # arm, q0 +- 0.01: d qdd / dq 1.1x the sampled spread against 2-3.4x
                # affine). The solution's own coefficients stay affine: with fresh symbols
                # per order they are tighter at high orders than models without.
                self.variational = TaylorModelODE(variational_graph(graph))
        else:
            self.taylor = TaylorODE(graph)
            self.variational = TaylorODE(variational_graph(graph))
        self.n = graph.n_inputs
        self._augmented = None

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
        ``directions`` columns (:func:`verified.variational.second_variational_graph`),
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
    absorb: bool = False,
    params_per_state: int | None = None,
    consistency=None,
    hooks=(),
    progress=None,
    start: Start | None = None,
) -> Solution:
    """:func:`verified.solver.solve` as one batch in this process (its arguments but the
    chunking ones: ``workers``, ``client``, ``chunks``, ``rechunk``; see its docstring).
    Every argument is checked, in ``solve``'s order, before the tapes are built and before
    any step."""
    wall0 = time.perf_counter()
    # every argument is checked before the tapes are built and before any step
    t0, t1, outs, h_max = check_settings(
        t_span=t_span, t_eval=t_eval, order=order, tol=tol, h_max=h_max, h_min=h_min, max_steps=max_steps,
        max_width=max_width, adaptive=adaptive, split_ratio=split_ratio, max_boxes=max_boxes,
        wrap_target=wrap_target, merge_slack=merge_slack, error_basis=error_basis, progress=progress)
    orders, steps = set_kind_names()
    if set_order not in orders or isinstance(set_order, bool):
        raise ValueError(f"set_order must be {' or '.join(map(str, orders))}, got {set_order!r}")
    if set_step not in steps:
        raise ValueError(f"set_step must be {' or '.join(map(repr, steps))}, got {set_step!r}")
    if set_step == "composition" and set_order != 2:
        raise ValueError("set_step='composition' advances second-order sets: it needs set_order=2")
    if model_degree is not None:
        if isinstance(model_degree, (bool, np.bool_)) or model_degree not in (2, 3, 4):
            raise ValueError(f"model_degree must be 2, 3 or 4, got {model_degree!r}")
        if set_step != "composition":
            raise ValueError("model_degree is the degree of set_step='composition''s Taylor models: "
                             "it needs set_order=2, set_step='composition'")
    model_caps = _check_model_caps(model_caps, set_step)
    if not isinstance(absorb, (bool, np.bool_)):
        raise ValueError(f"absorb must be True or False, got {absorb!r}")
    params_per_state = check_params_per_state(params_per_state)
    if absorb and (set_order != 1 or adaptive or consistency is not None):
        # (a consistency test's contraction works on sets with one parameter per state;
        # adaptive splitting would split along absorbed errors without end)
        raise ValueError("absorb=True needs set_order=1, adaptive=False, no consistency test and no "
                         "states appended by a hook")
    hook_list = ([ProgressHook(progress, t1)] if progress is not None else []) \
        + check_hooks([] if consistency is None else [consistency]) + check_hooks(hooks)
    kind = set_kind(set_order, set_step)
    setup, prob, param_boxes, boxes = _setup(ode, x0, t0, h_max, params, subdivision, arithmetic, kind.sets)
    if start is not None:
        setup, boxes = _resume(setup, start, boxes, kind, consistency)
    for hook in hook_list:
        setup = hook.before_run(setup) or setup
    appended = setup.graph is not prob.graph
    if appended:  # a hook appended states (the energy test's h)
        prob = VerifiedODE(setup.graph, prob.arithmetic)
        if setup.graph.n_inputs > setup.n_steer and isinstance(error_basis, str):
            # appended states keep a box of their own in the error basis: rotated into the
            # states' basis, h's error widened the states (docs/energy_contraction.md;
            # second-order sets too: the UR5 quintic in mode ii, q3 at 2 s 0.141 -> 0.132)
            error_basis = BlockBasis(error_basis, setup.n_steer)
    if absorb and appended:
        raise ValueError("absorb=True needs set_order=1, adaptive=False, no consistency test and no "
                         "states appended by a hook")
    stepper = _stepper(kind, prob, order, setup.params, error_basis, bool(absorb), params_per_state, model_degree,
                       model_caps)
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
            stepper.begin(run.sets)
            cX = stepper.coefficients(X)
            run.evaluations += 1
            if not (np.isfinite(cX.lo).all() and np.isfinite(cX.hi).all()):
                run.stop("Taylor coefficients are unbounded (an operation left its domain over the sets, e.g. a "
                         "division by an interval containing zero, or overflowed)", "breakdown")
                break
            gap_lo, gap_hi = run.gap()
            found = control.validate(stepper, X, cX, control.propose(stepper, cX, wrap.h_limit, gap_lo, gap_hi))
            run.evaluations += found.evaluations
            run.rejected += found.rejected
            if found.enclosure is None:
                run.stop(f"step size underflow: no a-priori enclosure validated with h >= {h_min:g}", "breakdown")
                break
            try:
                step = run.advance(stepper, X, found, gap_lo, gap_hi)
            except SingularMatrixError as exc:
                # a set so wide that its basis or its recentring cannot be inverted any
                # more (non-finite or singular enclosures): everything up to here stands
                run.stop(f"set update failed at t = {run.t:g}: {exc}", "breakdown")
                break
            steps += 1
            wrap.update(step)
            run.call_hooks(hook_list, step)
            if step.landed and run.sets.n_sets:
                run.record_output()
            if run.status:
                break
            if split is not None:
                run.sets, n_split, reason = split.apply(step, run.sets)
                if reason:
                    run.stop(reason, "breakdown")
                    break
                run.splits += n_split
                run.max_sets = max(run.max_sets, run.sets.n_sets)
            if merge is not None:
                run.sets, merged = merge.apply(run.sets)
                run.merges += merged
    except KeyboardInterrupt:
        # Ctrl-C: everything recorded so far is verified; return it
        run.stop(f"interrupted (KeyboardInterrupt) after t = {run.tube_t[-1]:g}", "interrupted")
    result = run.solution(setup.n_state, order, boxes.shape[0], steps, tuple(prob.graph.input_names[:setup.n_state]))
    result.stats["absorbed"] = stepper.absorbed
    result.stats["merged"] = stepper.merged
    result.stats["wall_s"] = time.perf_counter() - wall0
    for hook in hook_list:
        hook.after_run(result)  # records and statistics of the hooks
    result.stats["wall_s"] = time.perf_counter() - wall0
    return result


def _setup(ode, x0, t0, h_max, params, subdivision, arithmetic, sets_type=DoubletonSets):
    """The checked problem: ``(RunSetup, VerifiedODE, param_boxes, boxes)``. Uncertain
    parameters become constant states after the ODE's (``param_boxes`` (p,): their
    hull over the initial boxes, else None); ``boxes`` (B, N) the initial boxes, the
    initial sets ``sets_type.from_boxes`` (:mod:`verified.set_kinds`)."""
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
        prob = VerifiedODE(graph, "interval" if arithmetic is None else arithmetic)
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
    time instead of the sets made from ``x0``, after the checks that they fit."""
    if consistency is not None:
        raise ValueError("start= does not continue a consistency test")
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


class _Run:
    """The state of one integration: the sets, the exact time, what has been recorded,
    and the counters. It is the :class:`~verified.hooks.RunControl` the hooks get."""

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
        self.n_state = setup.n_state
        self.wrap = wrap  # the wrapping control (resume_point: a run continued from here keeps its limit)

    # ------------------------------------------------------------------ RunControl
    def stop(self, reason: str, status: str = "stopped") -> None:
        if not self.status:  # the first reason wins
            self.status, self.reason = status, reason

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
        self.sets, self.t, self.t_exact = last.previous, last.t_start, last.t_exact_start
        self.step = self.recent[-1]
        return self.step, self.sets

    # ------------------------------------------------------------------ one step
    def hull_for_step(self, param_boxes, n_state: int, n_steer: int, max_width: float):
        """The hull (B, N) of the sets to take the step's coefficients over, or None
        (a break-down: not finite or wider than ``max_width``)."""
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
                X = X[feasible]
                self.pruned += int((~feasible).sum())
        if not (np.isfinite(X.lo).all() and np.isfinite(X.hi).all()):
            self.stop("enclosure is not finite (an operation overflowed, or divided by an interval containing zero)",
                      "breakdown")
            return None
        if (X[:, :n_steer].width() > max_width).any():  # not states a hook appended (h)
            self.stop(f"enclosure too wide (a component exceeds width {max_width:g})", "breakdown")
            return None
        return X

    def gap(self):
        """Floats ``lo <= exact time to the next output <= hi``."""
        gap = Fraction(float(self.outs[self.next_out])) - self.t_exact
        return enclose_fraction(gap)  # the exact gap between two doubles

    def advance(self, stepper, X, found, gap_lo, gap_hi):
        """Take the validated step ``found`` (:class:`~verified.policies.Validated`),
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
        self.tube.append(E[:, :self.n_state])
        self.tube_views.append(_state_view(step.tube_view, E.shape[0], self.n_state))
        self.tube_t.append(step.t)
        return step

    def call_hooks(self, hooks, step):
        for hook in hooks:
            new = hook.after_step(self.step, self.sets, self)
            if new is not None:
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
        )


def _stepper(kind: SetKind, prob: VerifiedODE, order, params, error_basis, absorb=False,
             params_per_state=None, model_degree=None, model_caps=None) -> LohnerStepper:
    """The stepper of the run's set kind (:mod:`verified.set_kinds`) for ``prob``."""
    max_params = None if params_per_state is None else params_per_state * prob.n
    return kind.stepper(prob, order, params, error_basis, max_params, absorb, model_degree, model_caps)


#: the keys of ``solve(model_caps=...)``: the symbols with quadratic, cubic, quartic and
#: star monomials in the composition's Taylor models, and the pool of symbols for the
#: remainders born inside the graph (verified.tm_flow.TaylorModelFlowStepper)
MODEL_CAPS = ("quadratic", "cubic", "quartic", "star", "pool")


def _check_model_caps(model_caps, set_step):
    if model_caps is None:
        return None
    if set_step != "composition":
        raise ValueError("model_caps are the caps of set_step='composition''s Taylor models: "
                         "it needs set_order=2, set_step='composition'")
    if not isinstance(model_caps, dict):
        raise ValueError(f"model_caps must be a dict with keys among {', '.join(MODEL_CAPS)}, got {model_caps!r}")
    for k, v in model_caps.items():
        if k not in MODEL_CAPS:
            raise ValueError(f"model_caps: unknown key {k!r} (known: {', '.join(MODEL_CAPS)})")
        check_model_cap(k, v)
    return dict(model_caps)

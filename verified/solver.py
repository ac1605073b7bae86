"""``verified.solve``: enclosures of every solution of an ODE from a set of initial values.

In the spirit of ``scipy.integrate.solve_ivp``::

    sol = verified.solve(graph, x0, (0.0, 1.0), t_eval=np.linspace(0, 1, 11))
    sol.hull[-1]          # Interval (n,): encloses x(1) for every x(0) in x0
    sol.tube_hull         # Interval (steps, n): encloses x(t) on each step interval
    sol.status, sol.reason

The ODE is an autonomous expression :class:`~verified.graph.Graph` ``x' = f(x, p)``;
``x0`` a box (or a batch of boxes, or a list of them); ``params`` exact floats or
intervals (uncertain parameters, constant in time). The initial boxes may be split
into a uniform grid (``subdivision``). All boxes advance together with one common step
size through the batched QR-Lohner step of :mod:`verified.lohner`.

A break-down is a result, not an exception: everything up to the last verified time is
returned with ``status = "breakdown"`` and the reason.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np

from .graph import Graph
from .interval import Interval, concatenate, hull, stack
from .lohner import DoubletonSets, LohnerStepper
from .affine_taylor import AffineTaylorODE
from .solver_args import check_arithmetic, check_graph, check_params, check_settings, initial_boxes
from .taylor import TaylorODE
from .variational import params_as_states, variational_graph

__all__ = ["solve", "Solution", "VerifiedODE"]


class VerifiedODE:
    """An ODE graph prepared for verified integration (Taylor tapes built once).

    Reuse one instance across :func:`solve` calls to skip the preparation.
    """

    def __init__(self, graph: Graph, arithmetic: str = "interval"):
        self.graph = check_graph(graph)
        self.arithmetic = check_arithmetic(arithmetic)
        if arithmetic == "affine":
            # fresh symbols for the errors of the solution's own coefficients only: for
            # the variational series they cost 2.5x and changed nothing measurable
            self.taylor = AffineTaylorODE(graph)
            self.variational = AffineTaylorODE(variational_graph(graph), fresh_symbols=0)
        else:
            self.taylor = TaylorODE(graph)
            self.variational = TaylorODE(variational_graph(graph))
        self.n = graph.n_inputs
        self._augmented = None

    def with_params_as_states(self) -> "VerifiedODE":
        """The same ODE with its parameters as extra constant states (built once)."""
        if self._augmented is None:
            self._augmented = VerifiedODE(params_as_states(self.graph), self.arithmetic)
        return self._augmented


@dataclass
class Solution:
    """Result of :func:`solve`.

    Attributes
    ----------
    t : ndarray (k,)
        Output times reached (the requested ``t_eval`` up to ``t_reached``).
    boxes : list of Interval (B_j, n)
        For each output time, boxes whose union encloses every solution.
    hull : Interval (k, n)
        The hull of ``boxes`` at each output time.
    tube_t : ndarray (s + 1,)
        Step boundaries ``t_0 < t_1 < ... < t_s``.
    tube : list of Interval (B_j, n)
        For each step, boxes whose union encloses every solution on ``[t_j, t_j+1]``.
    tube_hull : Interval (s, n)
    t_reached : float
        The last time up to which the enclosure is verified.
    status : "completed" or "breakdown"
    reason : str
        Why the integration stopped early ("" when completed).
    stats : dict
        steps, boxes, rejected steps, Taylor evaluations, ``max_boxes`` (most sets
        at any time), wall time (s); with a consistency test also ``tests``,
        ``pruned_boxes``, ``test_s`` and ``backward_s`` (seconds in the tests).
    state_names : tuple of str
    consistency : verified.consistency.ConsistencyRecord or None
        RA(t), H_H and H_V per step and a record of every test (paper Figs. 2-3).
    mode : str
        Set by :func:`mbs.simulate.simulate` ("i", "ii", "iii"; "" otherwise).
    """

    t: np.ndarray
    boxes: list
    hull: Interval
    tube_t: np.ndarray
    tube: list
    tube_hull: Interval
    t_reached: float
    status: str
    reason: str
    stats: dict = field(default_factory=dict)
    state_names: tuple = ()
    consistency: object = None
    mode: str = ""

    @property
    def success(self) -> bool:
        return self.status == "completed"

    def __repr__(self):
        return (
            f"Solution(status={self.status!r}, t_reached={self.t_reached:g}, outputs={len(self.t)}, "
            f"steps={self.stats.get('steps')}, boxes={self.stats.get('boxes')}, reason={self.reason!r})"
        )


def solve(
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
    consistency=None,
    progress=None,
) -> Solution:
    """Verified enclosure of all solutions of ``x' = f(x, p)`` from ``x0``.

    Parameters
    ----------
    ode : Graph or VerifiedODE
        The right-hand side (``n`` inputs, ``n`` outputs, ``p`` parameters).
    x0 : Interval (n,) or (B, n), or a list of them
        Initial boxes (their union is the initial set).
    t_span : (t0, t1) with t1 > t0
    params : Interval or floats, shape (p,) (or (B, p) per initial box)
    t_eval : sorted (non-decreasing) finite output times in [t0, t1] (default: t1 only;
        t0 is always included; repeated times are reported once)
    order : Taylor order K (default 12)
    tol : target size of the order-K term per step (absolute, state units; default
        1e-10). Defaults chosen from the double pendulum's work-precision table
        (benchmarks/bench_solver.py --work-precision): higher orders with loose
        tolerances take long steps over which the Jacobian of a wide set varies
        too much.
    subdivision : int >= 1 or a sequence of n ints >= 1: split each initial box into a
        uniform grid (pieces per state)
    h_max, h_min : step-size bounds (h_max None: t1 - t0; 0 < h_min < h_max); a step
        that cannot be validated above h_min breaks down
    max_steps : break down after this many steps
    max_width : break down when a component's enclosure gets wider than this
    adaptive : split a set in two (along its widest direction) when the error its
        linearization injects per unit time exceeds ``split_ratio`` (1/s) times the
        width of the union of all sets, i.e. when one linearization no longer
        follows the curved reachable set closely enough
    max_boxes : adaptive splitting stops (break-down) beyond this many boxes
    merge_slack : with ``adaptive``, merge neighbouring sets when one set covering
        both is at most ``1 + merge_slack`` times as wide as their union's hull
        (default None: never). Off by default: on the double pendulum merging turned
        linear parts into wrapped error boxes and made enclosures wider
        (T = 1, 64 pieces adaptive: worst ratio 1.010 unmerged, 5.9 with slack 0.1).
    error_basis : "qr" (Lohner's QR basis for the error part; default) or "auto"
        (per set and step, the QR basis or a plain box, whichever is tighter now).
        Measured on the double pendulum: "auto" gives tighter short-horizon results
        (T = 1, 256 pieces: worst ratio 1.004 vs 1.012; single box verified to 0.635
        vs 0.465) but breaks down on long horizons where "qr" does not (T = 2,
        256 pieces: break-down at 1.93 vs ratio 1.23).
    arithmetic : "interval" (default) or "affine": how the Taylor coefficients of the
        solution and of the variational equations are enclosed over boxes.
        "affine" carries every coefficient as an affine form in the box's own
        symbols (:mod:`verified.affine_taylor`), so first-order dependence through a
        deep model graph (a robot's crba/rnea and elimination) is kept instead of
        compounding order by order. Measured: a 3-link arm from a box of radius 1e-6
        is verified to T = 2 (interval: break-down at 0.69 s); the double pendulum,
        256 pieces, T = 1: worst ratio 1.003 in 15 s against 1.012 in 3-4 s.
        A VerifiedODE carries its own (a different value given here is an error).
    consistency : verified.consistency.EnergyTest or None
        Energy (Hamiltonian) consistency test, further constraints and the backward
        test (paper sec. 4): branch and prune at the first local maximum of the
        reduction area RA(t), at least every ``max_interval`` seconds. Its record
        (RA(t), H_H, H_V, every test) is returned as ``Solution.consistency``.
    progress : callable(t, t_end) or None
        Called after every accepted step (for progress bars).
    wrap_target : wrapping control: the next step is shortened when a step injected
        more than this fraction of a set's linear size through the spread of the
        Jacobian over the set (np.inf turns the control off)

    Returns
    -------
    Solution

    Raises
    ------
    ValueError
        for a bad argument, before any work (see :mod:`verified.solver_args`): for
        example ``tol`` or ``h_max`` not a finite number > 0, NaN in ``t_eval`` or
        ``x0``, an empty batch of boxes, or ``subdivision`` of the wrong length.
    TypeError
        when ``ode`` is not a Graph or VerifiedODE.
    """
    wall0 = time.perf_counter()
    # every argument is checked before the tapes are built and before any step
    t0, t1, outs, h_max = check_settings(
        t_span=t_span, t_eval=t_eval, order=order, tol=tol, h_max=h_max, h_min=h_min, max_steps=max_steps,
        max_width=max_width, adaptive=adaptive, split_ratio=split_ratio, max_boxes=max_boxes,
        wrap_target=wrap_target, merge_slack=merge_slack, error_basis=error_basis, progress=progress)
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
    n_state = n
    param_boxes = None
    if params is not None and (params.width() > 0).any():
        # Uncertain parameters become constant states, so their influence is carried
        # by the linear part of the set instead of being wrapped every step.
        prob = prob.with_params_as_states()
        p_boxes = params.broadcast_to((nb, params.shape[-1])) if params.ndim == 1 else params
        boxes = concatenate([boxes, p_boxes], axis=1)
        param_boxes = hull(p_boxes, axis=0)  # (p,): valid for every set, also after splits
        params = None
    n_solver = prob.n  # states the solver integrates before any energy state
    test = consistency
    if test is not None:
        user_graph = ode.graph if isinstance(ode, VerifiedODE) else ode
        prob = VerifiedODE(test.prepare(user_graph, prob.graph, n_state, params, t0=t0), prob.arithmetic)
    stepper = _stepper(prob, order, params, error_basis)
    sets = DoubletonSets.from_boxes(boxes)
    if test is not None:
        sets = test.initial_sets(sets)
    history = []  # (sets, t_exact, t, h_step) before the last accepted steps
    max_sets = sets.n_sets
    if test is not None:
        h_max = min(h_max, test.max_interval)  # "a test at least every max_interval seconds"

    out_t, out_boxes = [t0], [boxes[:, :n_state]]
    tube_t, tube = [t0], []
    # Time is kept exactly (a sum of float steps) so that every enclosure belongs to
    # the time it is reported at; a step landing on an output time uses an interval
    # step [h] that encloses the exact remaining gap.
    t_exact = Fraction(t0)
    t = t0
    next_out = 1
    status, reason = "completed", ""
    steps = rejected = evaluations = splits = merges = pruned = 0
    h_wrap = np.inf  # step limit from wrapping control (see below)
    while next_out < outs.size:
        if steps >= max_steps:
            status, reason = "breakdown", f"maximum number of steps ({max_steps}) reached"
            break
        X = sets.hull()
        if param_boxes is not None:
            # Parameters never change: their true values stay in the given boxes, so
            # the hull used for the Taylor coefficients and the Jacobian may be cut
            # down to them (wrapping may have smeared error into those components).
            X[:, n_state:n_solver] = X[:, n_state:n_solver].intersect(param_boxes)
            # A set (for example one half of a split error box) whose parameter range
            # misses the parameter boxes holds no true solution: drop it.
            feasible = ~X.is_empty().any(axis=1)
            if not feasible.all():
                sets = sets.take(np.flatnonzero(feasible))
                X = X[feasible]
                pruned += int((~feasible).sum())
        if not (np.isfinite(X.lo).all() and np.isfinite(X.hi).all()):
            status, reason = "breakdown", "enclosure is not finite (division by an interval containing zero?)"
            break
        if (X.width() > max_width).any():
            status, reason = "breakdown", f"enclosure too wide (a component exceeds width {max_width:g})"
            break
        cX = stepper.coefficients(X)
        evaluations += 1
        if not (np.isfinite(cX.lo).all() and np.isfinite(cX.hi).all()):
            status, reason = "breakdown", "Taylor coefficients are unbounded (division by an interval containing zero)"
            break
        gap = Fraction(float(outs[next_out])) - t_exact
        gap_lo, gap_hi = _round_down(gap), _round_up(gap)
        # an energy state added by a consistency test does not steer the step size:
        # its rate is ~0 with wide interval coefficients (unsimplified dH/dt)
        h = min(stepper.suggest_step(cX, tol, n_solver), h_max, h_wrap, gap_hi)
        if h >= gap_lo:
            h = gap_hi  # land on the output time; validate the enclosure up to gap_hi
        validated = None
        while True:
            validated = stepper.apriori(X, cX, h)
            evaluations += 1
            if validated is not None:
                # Remainder control: h was chosen from the order-K coefficient over the
                # hull X, but the Lagrange remainder takes it over the wider a-priori
                # enclosure E. Over a deep model graph that can be many orders larger
                # (measured: 7e-4 instead of 1e-10 on a 3-link arm's first step), and a
                # remainder far above tol wrecks a narrow set for good.
                rem = float(np.max(validated[1][:, stepper.order, :n_solver].mag())) * h**stepper.order
                if not rem > REMAINDER_SLACK * tol or h < h_min:
                    break
                validated = None
                h *= max(0.2, min(0.9, (REMAINDER_SLACK * tol / rem) ** (1.0 / stepper.order)))
            elif h < h_min:
                break
            else:
                h *= 0.5
            rejected += 1
        if validated is None:
            status, reason = "breakdown", f"step size underflow: no a-priori enclosure validated with h >= {h_min:g}"
            break
        E, cE = validated
        landing = h == gap_hi
        t_exact_before = t_exact
        if landing:
            h_step = h if gap_lo == gap_hi else Interval(gap_lo, gap_hi)  # encloses the exact gap
            t_exact = Fraction(float(outs[next_out]))
        else:
            h_step = h
            t_exact += Fraction(h)
        history = (history + [(sets, t_exact_before, t, h_step)])[-2:]
        sets = stepper.step(sets, h_step, X, E, cE)
        evaluations += 2
        t = float(outs[next_out]) if landing else float(t_exact)
        tube.append(E[:, :n_state])
        tube_t.append(t)
        steps += 1
        if progress is not None:
            progress(t, t1)
        # Wrapping control: the error a step injects through the spread of the
        # Jacobian over a wide set grows faster than the step itself, so keep it at
        # about wrap_target times the set's linear size by adapting the next step.
        ratio = float(np.max(stepper.last_nonlinear_width[:, :n_solver].max(axis=1)
                            / (sets.linear_width()[:, :n_solver].max(axis=1) + 1e-300)))
        if ratio > wrap_target:
            h_wrap = h * max(0.2, np.sqrt(wrap_target / ratio))
        elif ratio < 0.25 * wrap_target:
            h_wrap = min(2.0 * h_wrap, h_max)  # (unbounded doubling overflowed on long runs)
        if test is not None:
            decision = test.observe(t, sets)
            if decision == "previous" and not landing and len(history) == 2:
                # RA(t) peaked at the previous step: t* is there, roll back to it
                sets, t_exact, t, _ = history.pop()
                tube.pop()
                tube_t.pop()
                test.forget_last()
                decision = "now"
            if decision == "now":
                t_iv = Interval(_round_down(t_exact), _round_up(t_exact))
                prev = None
                if test.backward_depth and history:
                    prev_sets, _, _, prev_h = history[-1]
                    prev = (prev_sets, prev_h, lambda g: _stepper(VerifiedODE(g, prob.arithmetic), order, params, error_basis))
                sets = test.apply(t, t_iv, sets, prev)
                history = []
                if sets.n_sets == 0:
                    status, reason = "breakdown", "the consistency test removed every set (inconsistent model or constraints?)"
                    break
            max_sets = max(max_sets, sets.n_sets)
        if landing:
            out_t.append(t)
            out_boxes.append(sets.hull()[:, :n_state])
            next_out += 1
        if adaptive:
            # One linearization per set stops following the curved reachable set when
            # the error it injects per unit time (the Jacobian's spread over the set
            # times the set's linear part) is a sizeable fraction of the width of the
            # whole union, which bounds what that error costs: split such sets.
            # Halving a set roughly quarters its injection.
            injected = stepper.last_nonlinear_width / h  # (B, n)
            union_width = hull(X, axis=0).width()  # (n,)
            grow = (injected > split_ratio * union_width + 1e3 * tol).any(axis=1)
            if grow.any():
                if sets.n_sets + int(grow.sum()) > max_boxes:
                    status, reason = "breakdown", f"adaptive splitting needs more than max_boxes={max_boxes} boxes"
                    break
                sets = sets.split(grow)
                splits += int(grow.sum())
                max_sets = max(max_sets, sets.n_sets)
            if merge_slack is not None and sets.n_sets > 1:
                sets, merged = sets.merge_overlapping(merge_slack)
                merges += merged
    n_tube = len(tube)
    result = Solution(
        t=np.array(out_t),
        boxes=out_boxes,
        hull=_stack_hulls(out_boxes),
        tube_t=np.array(tube_t),
        tube=tube,
        tube_hull=_stack_hulls(tube) if n_tube else Interval._from_bounds(np.zeros((0, n)), np.zeros((0, n))),
        t_reached=t,
        status=status,
        reason=reason,
        stats=dict(
            steps=steps,
            rejected_steps=rejected,
            boxes=nb,
            final_boxes=sets.n_sets,
            splits=splits,
            merges=merges,
            pruned_sets=pruned,
            max_boxes=max_sets,
            taylor_evaluations=evaluations,
            order=order,
            wall_s=time.perf_counter() - wall0,
        ),
        state_names=tuple(prob.graph.input_names[:n_state]),
    )
    if test is not None:
        result.consistency = test.finish()
        result.stats.update(test.stats)
        result.stats["wall_s"] = time.perf_counter() - wall0
    return result


#: a step is retried smaller when its remainder exceeds this many times ``tol``
REMAINDER_SLACK = 10.0


def _stepper(prob: VerifiedODE, order, params, error_basis) -> LohnerStepper:
    return LohnerStepper(prob.taylor, prob.variational, order, params, error_basis)


def _round_up(q: Fraction) -> float:
    f = float(q)
    return f if Fraction(f) >= q else float(np.nextafter(f, np.inf))


def _round_down(q: Fraction) -> float:
    f = float(q)
    return f if Fraction(f) <= q else float(np.nextafter(f, -np.inf))


def _stack_hulls(list_of_boxes):
    return stack([hull(b, axis=0) for b in list_of_boxes], axis=0)

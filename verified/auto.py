"""``method="auto"``: choose the method from the problem and do not give up while a
stronger one exists.

The ladder (:class:`verified.methods.Auto`): the initial pieces are advanced with the
first rung (:func:`default_rungs`: second-order sets by composition for systems of up to
:data:`COMPOSITION_MAX_STATES` states, first-order QR-Lohner sets beyond). A piece whose
sets cannot be continued is taken up by the next rung from where its sets stopped
(``Solution.failures``: the sets at the last verified time, :func:`switch_start`), and
after the last rung its initial box is split (:func:`split_boxes`: bisected along its
widest components; with uncertain parameters, :func:`split_pieces`: along the states
and parameters that move the states most, each part with its own parameter box) and
its parts are run from ``t0`` with the last rung, until every piece reaches ``t1`` or
the pieces would exceed ``max_pieces``. (Splitting the sets
where they failed, or half-way there, was measured on the 3-link arm at +-0.01 rad:
those sets are already too wide to gain from halving, see ``docs/lab``.) A
continuation that gets no further than where it started (sets already too wide for
any method) runs that rung from ``t0`` instead. The pieces that reached ``t1`` are kept
as they are (a one-batch run goes on with the pieces that did not fail:
``Solution.surviving``). An attempt whose first steps are so short that the span would
take more than :data:`STALL_STEPS` of them is stopped (:class:`StallGuard`) and its
pieces go on with :data:`FALLBACK` (first-order sets), which splits on its own when it
must.

Soundness: every attempt starts from sets that enclose every true state at its start
time: a continuation from the failed attempt's own sets at exactly their time (or their
hull boxes, when the next method advances another kind of set), a restart from the
piece's own initial box at ``t0``. The Solution of a continued piece is the failed
attempt's record up to the switch followed by the continuation
(:func:`verified.time_chain.chain_in_time`), and the result is the union of the attempts that
together cover every initial piece (:func:`verified.parallel.merge_solutions`). A
piece that fails on every rung keeps the failed attempt's enclosure, verified up to
where that attempt got, and the run is a break-down at the earliest such time, naming
what was tried. A run with a consistency test is never continued from sets (they carry
the test's energy state): its pieces restart from ``t0``.

``Solution.method_log`` lists the attempts: which method advanced which pieces over
which span, how it ended, and why the next one was tried.
"""

from __future__ import annotations

import copy
import time
from dataclasses import dataclass

import numpy as np

from .hooks import Hook, caps_from
from .interval import Interval, concatenate
from .methods import Auto, Composition, Lohner, Method
from .solution import Failure, Solution, Start
from .time_chain import chain_in_time

__all__ = ["solve_auto", "default_rungs", "split_boxes", "split_pieces", "influences", "COMPOSITION_MAX_STATES"]

#: up to this many states (parameters carried as states included) the first rung is the
#: composition: on every case measured for issue 40 (3-link arm, double pendulum, the
#: paper's pendulum, Laub-Loomis, x'' = -x - 2 x^2 x') it went further than first-order
#: sets at a similar or lower cost; its Taylor models grow with the square of the states
COMPOSITION_MAX_STATES = 24
#: from this many states on (a 5-DOF robot and up) the composition runs at order
#: LARGE_ORDER with LARGE_PARAMS_PER_STATE parameters per state: shorter Taylor series
#: of a deep graph, more of the accumulated error carried exactly (the robots' best
#: setting in benchmarks/bench_robots.py; docs/lab/auto.md)
LARGE_STATES = 10
LARGE_ORDER = 8
LARGE_PARAMS_PER_STATE = 12
#: at most this many components are bisected at once when a piece is split (a piece of a
#: 7-state box bisected in every component would become 128)
SPLIT_DIMS = 3
#: split pieces must get further than their parent by this fraction of the time span, or
#: splitting stops (what stops them is then not the width of the set)
MIN_GAIN = 0.01


def default_rungs(graph, boxes: Interval, params=None) -> tuple[Method, ...]:
    """The rungs ``auto`` tries, weakest first, for ``graph`` from ``boxes`` (B, n)."""
    n = graph.n_inputs
    # (uncertain parameters are carried as constant states)
    p_wide = 0 if params is None else int(np.count_nonzero(np.any(np.atleast_2d(params.width()) > 0, axis=0)))
    if n + p_wide <= COMPOSITION_MAX_STATES:
        if n + p_wide >= LARGE_STATES:
            return (Composition(order=LARGE_ORDER, params_per_state=LARGE_PARAMS_PER_STATE),)
        return (Composition(),)
    return (Lohner(arithmetic="affine"), Lohner(arithmetic="affine", error_basis="auto"))


def split_boxes(boxes: Interval, max_dims: int = SPLIT_DIMS) -> Interval:
    """Each box (B, n) bisected along its widest components (those at least half as wide
    as its widest, at most ``max_dims`` of them): (B * 2^d, n), every point of a box in
    one of its parts (the cut is shared by both halves)."""
    out = []
    for b in range(boxes.shape[0]):
        lo, hi = np.asarray(boxes.lo[b], float), np.asarray(boxes.hi[b], float)
        with np.errstate(over="ignore"):  # (a box of +-1.7e308 is wider than the largest float)
            w = np.where(np.isfinite(hi - lo), hi - lo, 0.0)
        order = np.argsort(-w, kind="stable")
        dims = [int(j) for j in order[:max_dims] if w[j] > 0 and w[j] >= 0.5 * w[order[0]]]
        parts = [(lo.copy(), hi.copy())]
        for j in dims:
            cut = 0.5 * (lo[j] + hi[j])
            nxt = []
            for a, c in parts:
                a1, c1 = a.copy(), c.copy()
                c1[j] = cut
                a2, c2 = a.copy(), c.copy()
                a2[j] = cut
                nxt += [(a1, c1), (a2, c2)]
            parts = nxt
        out += parts
    return Interval(np.array([a for a, _ in out]), np.array([c for _, c in out]))


#: a component of a piece with uncertain parameters (a state or a parameter) is bisected
#: when moving it across its interval alone moves some state at the failure time at least
#: this share as much as the component that moves that state most (:func:`influences`)
INFLUENCE_SHARE = 0.5


def influences(graph, lo, hi, plo, phi, T: float):
    """How much each component of a piece -- its states ``lo..hi`` (n,), then its
    parameters ``plo..phi`` (p,) -- moves the states at time ``T``: float trajectories
    (DOP853, rtol = atol = 1e-8) from the piece's centre with that one component at its
    lower and at its upper end; for each state, the distance between the two ends
    relative to the largest such distance among the components; the largest over the
    states. Shape (n + p,), 0 for components of zero or infinite width; None where the
    integration fails. It guides splitting only, never an enclosure."""
    from scipy.integrate import solve_ivp

    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    plo, phi = np.asarray(plo, float), np.asarray(phi, float)
    n, q = lo.size, plo.size
    zlo, zhi = np.concatenate([lo, plo]), np.concatenate([hi, phi])
    with np.errstate(over="ignore", invalid="ignore"):
        w = zhi - zlo
    dims = [j for j in range(n + q) if np.isfinite(w[j]) and w[j] > 0]
    out = np.zeros(n + q)
    if not dims or T <= 0:
        return out
    Z = np.tile(0.5 * (zlo + zhi), (2 * len(dims), 1))
    for k, j in enumerate(dims):
        Z[2 * k, j], Z[2 * k + 1, j] = zlo[j], zhi[j]
    S = Z.shape[0]
    X0, P = Z[:, :n], (Z[:, n:] if q else None)

    def f(t, y):
        return graph.eval_float(y.reshape(S, n), P).reshape(-1)
    with np.errstate(all="ignore"):
        r = solve_ivp(f, (0.0, float(T)), X0.reshape(-1), method="DOP853", rtol=1e-8, atol=1e-8)
    if not r.success or not np.all(np.isfinite(r.y[:, -1])):
        return None
    end = r.y[:, -1].reshape(len(dims), 2, n)
    moved = np.abs(end[:, 1] - end[:, 0])  # (dims, n)
    top = moved.max(axis=0)
    ok = top > 0
    if ok.any():
        out[dims] = (moved[:, ok] / top[ok]).max(axis=1)
    return out


def split_pieces(graph, boxes: Interval, params, span: float):
    """The failed pieces ``boxes`` (B, n) with their parameters ``params`` ((p,) for all,
    (B, p) rows, or None), split: ``(parts, part_params)``. Without uncertain parameters,
    :func:`split_boxes` and the rows repeated. With them, each piece is bisected along the
    components -- states and parameters alike -- that move its states most over ``span``
    (:func:`influences`, at least :data:`INFLUENCE_SHARE` of the most, at most
    :data:`SPLIT_DIMS` of them; the widest parameter with the states' choice where the
    integration fails), and every part gets its own parameter row: ``part_params`` (parts,
    p). Every state and parameter of a piece lies in one of its parts (the cut is shared
    by both halves), so the parts cover the pieces."""
    wide = params is not None and isinstance(params, Interval) and bool(np.any(params.width() > 0))
    if not wide:
        parts = split_boxes(boxes)
        return parts, _repeat_rows(params, parts.shape[0] // boxes.shape[0])
    n = boxes.shape[-1]
    out_x, out_p = [], []
    for b in range(boxes.shape[0]):
        lo, hi = np.asarray(boxes.lo[b], float), np.asarray(boxes.hi[b], float)
        row = params if params.ndim == 1 else params[b]
        plo, phi = np.asarray(row.lo, float), np.asarray(row.hi, float)
        infl = influences(graph, lo, hi, plo, phi, span)
        if infl is None or not np.any(infl > 0):
            # (the states' own choice, and the widest parameter relative to its size)
            parts = split_boxes(boxes[b:b + 1])
            dims = [j for j in range(n) if np.any(parts.lo[:, j] != lo[j]) or np.any(parts.hi[:, j] != hi[j])]
            rel = np.where(phi > plo, (phi - plo) / np.maximum(np.abs(0.5 * (plo + phi)), 1e-300), 0.0)
            dims = dims[:SPLIT_DIMS - 1] + [n + int(np.argmax(rel))]
        else:
            order = np.argsort(-infl, kind="stable")
            dims = [int(j) for j in order[:SPLIT_DIMS] if infl[j] > 0 and infl[j] >= INFLUENCE_SHARE * infl[order[0]]]
        zlo, zhi = np.concatenate([lo, plo]), np.concatenate([hi, phi])
        cuts = [(zlo, zhi)]
        for j in dims:
            cut = 0.5 * (zlo[j] + zhi[j])
            nxt = []
            for a, c in cuts:
                a1, c1, a2, c2 = a.copy(), c.copy(), a.copy(), c.copy()
                c1[j] = cut
                a2[j] = cut
                nxt += [(a1, c1), (a2, c2)]
            cuts = nxt
        out_x += [(a[:n], c[:n]) for a, c in cuts]
        out_p += [(a[n:], c[n:]) for a, c in cuts]
    return (Interval(np.array([a for a, _ in out_x]), np.array([c for _, c in out_x])),
            Interval(np.array([a for a, _ in out_p]), np.array([c for _, c in out_p])))


@dataclass
class _Task:
    boxes: Interval          # (k, n) initial pieces
    params: object           # the run's params ((p,) for all) or (k, p) rows, or None
    rung: int                # index into the rungs
    splits: int = 0          # how often these pieces were split
    parent_t: float = -np.inf  # where the pieces they were split from broke down
    failure: Failure | None = None  # a continuation: the failed attempt's record and sets to go on from


def switch_start(failure: Failure, method: Method) -> Start:
    """The sets ``method`` continues ``failure``'s pieces from, at exactly its time: the
    failed attempt's own sets where ``method`` advances sets of that kind, else their
    hull boxes as ``method``'s initial sets (a box holds every point of the sets it is
    the hull of; the correlation between the sets' components is lost)."""
    from .set_kinds import set_kind

    st = method.settings()
    kind = set_kind(st.get("set_order", 1), st.get("set_step", "mean_value"))
    sets = failure.start.sets
    if not isinstance(sets, kind.sets):
        sets = kind.sets.from_boxes(sets.hull())
    return Start(sets=sets, t_exact=failure.start.t_exact, h_limit=failure.start.h_limit)


def _continuable(failure: Failure, params, n_run: int) -> bool:
    """Whether a failure's sets can be continued by another method: they carry the run's
    states only (no state appended by a hook, such as the energy test's ``h``), and the
    parameters are the same for every piece (per-piece exact parameter rows cannot
    follow sets that mixed pieces)."""
    if failure.start is None or failure.start.sets.n_sets == 0:
        return False
    if failure.start.sets.hull().shape[-1] != n_run:
        return False
    return params is None or not isinstance(params, Interval) or params.ndim == 1


def _rows(params, idx):
    """The parameter rows of pieces ``idx`` (params per piece (k, p)), or params as is."""
    if params is None or not isinstance(params, Interval) or params.ndim != 2:
        return params
    return params[np.asarray(idx, dtype=int)]


def _repeat_rows(params, times: int):
    if params is None or not isinstance(params, Interval) or params.ndim != 2:
        return params
    idx = np.repeat(np.arange(params.shape[0]), times)
    return params[idx]


def solve_auto(solve, ode, x0, t_span, *, method: Auto, params=None, t_eval=None, subdivision=None,
               consistency=None, hooks=(), progress=None, **common) -> Solution:
    """Run :class:`~verified.methods.Auto`'s ladder (module docstring). ``solve`` is
    :func:`verified.solver.solve` (passed in: this module is imported by it);
    ``common`` the rest of its keyword arguments (step bounds, adaptive splitting,
    execution), the same for every attempt. With ``method.target_ratio``, the ladder is
    repeated on split pieces while its final enclosure is wider than that ratio times
    the sampled spread (:func:`sampled_spread`)."""
    from .batch import VerifiedODE
    from .solver_args import check_graph, check_params, initial_boxes

    wall0 = time.perf_counter()
    graph = check_graph(ode.graph if isinstance(ode, VerifiedODE) else ode)
    boxes = initial_boxes(x0, graph.n_inputs, subdivision)
    pv = check_params(params, graph, boxes.shape[0], subdivision)
    kw = dict(method=method, t_eval=t_eval, consistency=consistency, hooks=hooks, progress=progress,
              started=wall0, **common)
    sol, pieces = _ladder(solve, ode, graph, boxes, pv, t_span, **kw)
    target = method.target_ratio
    if target is not None and sol.status == "completed" and (pv is None or pv.ndim == 1):
        log = list(sol.method_log)
        # the sampled spread depends on the initial set and the span only: integrated once
        spread = sampled_spread(graph, boxes, pv, float(sol.t[-1]) - float(sol.t[0]))
        best, best_w, ratio = sol, _final_width(sol), _ratio(sol, spread)
        log[-1]["ratio_estimate"] = ratio
        while ratio > target:
            # the pieces the tightest run ended with, each split (its failures are not repeated),
            # as often at once as the excess width asks for (_splits_for)
            parts = split_boxes(pieces)
            for _ in range(_splits_for(ratio, target) - 1):
                more = split_boxes(parts)
                if more.shape[0] > method.max_pieces:
                    break
                parts = more
            if parts.shape[0] > method.max_pieces:
                break
            nxt, pieces = _ladder(solve, ode, graph, parts, pv, t_span, **kw)
            log += nxt.method_log
            if nxt.status != "completed":
                break
            w = _final_width(nxt)
            new_ratio = _ratio(nxt, spread)
            log[-1]["ratio_estimate"] = new_ratio
            if not np.all(w <= best_w):  # (no tighter in every state: more pieces do not pay)
                break
            best, best_w, ratio = nxt, w, new_ratio
        best.method_log = log
        best.method = _summary(log)
        sol = best
    sol.stats["wall_s"] = time.perf_counter() - wall0
    return sol


#: how much one split is taken to cut a piece's excess width (ratio - 1) by, at least:
#: second-order sets leave an excess about quadratic in a piece's width, and halving
#: the widest components cut it several-fold on the double pendulum (docs/lab/code_notes.md)
SPLIT_GAIN = 6.0


def _splits_for(ratio: float, target: float) -> int:
    """How many rounds of splitting (1 to 3) are expected to bring ``ratio`` to
    ``target`` when each cuts the excess by :data:`SPLIT_GAIN` (rounded down: one round
    too few costs one more refinement, one too many doubles the pieces)."""
    if not (np.isfinite(ratio) and ratio > target > 1.0):
        return 1
    rounds = int(np.floor(np.log((ratio - 1.0) / (target - 1.0)) / np.log(SPLIT_GAIN)))
    return int(min(3, max(1, rounds)))


def _final_width(sol) -> np.ndarray:
    return np.asarray(sol.hull[-1].width(), float)


def sampled_spread(graph, boxes: Interval, params, T: float, per_box: int = 8, seed: int = 0):
    """Per state, the spread at time ``T`` of float trajectories (DOP853, rtol = atol =
    1e-10) from the corners (up to 2^6) and ``per_box`` random points of every initial
    box: a lower bound of the true spread, up to the integrator's error, that guides
    ``target_ratio`` (never the enclosure). None where the integration fails."""
    from scipy.integrate import solve_ivp

    rng = np.random.default_rng(seed)
    n = graph.n_inputs
    pts = []
    for b in range(boxes.shape[0]):
        lo, hi = np.asarray(boxes.lo[b], float), np.asarray(boxes.hi[b], float)
        k = min(n, 6)
        corners = np.array(np.meshgrid(*[[0.0, 1.0]] * k, indexing="ij")).reshape(k, -1).T
        c = np.tile(0.5 * (lo + hi), (corners.shape[0], 1))
        c[:, :k] = lo[:k] + corners * (hi[:k] - lo[:k])
        pts.append(c)
        pts.append(lo + (hi - lo) * rng.random((per_box, n)))
    pts = np.concatenate(pts)
    p = None if params is None else np.asarray(params.mid() if params.ndim == 1 else params.hull(axis=0).mid(),
                                               float)
    S = pts.shape[0]

    def f(t, y):
        return graph.eval_float(y.reshape(S, n), p).reshape(-1)
    if T <= 0:
        return np.zeros(n)
    with np.errstate(all="ignore"):
        r = solve_ivp(f, (0.0, T), pts.reshape(-1), method="DOP853", rtol=1e-10, atol=1e-10)
    if not r.success:
        return None
    end = r.y[:, -1].reshape(S, n)
    return end.max(axis=0) - end.min(axis=0)


def _ratio(sol, spread) -> float:
    """Worst state's ratio of ``sol``'s final enclosure width to ``spread``
    (:func:`sampled_spread`): inf where that failed, 1 where nothing spreads."""
    if spread is None:
        return float("inf")
    enc = _final_width(sol)[:spread.size]
    ok = spread > 1e-12
    return float(np.max(enc[ok] / spread[ok])) if ok.any() else 1.0


#: the method that takes over the pieces of an attempt that stalled
FALLBACK = Lohner(arithmetic="affine", error_basis="auto")
#: an attempt stalls when its first STALL_MIN_STEPS steps would need more than
#: STALL_STEPS steps for the whole span (far more than the robots' runs take;
#: docs/lab/code_notes.md)
STALL_MIN_STEPS = 1000
STALL_STEPS = 20_000
STALLED = "stalled"


class StallGuard(Hook):
    """Stop an attempt (a break-down whose reason starts with ``"stalled"``) whose first
    :data:`STALL_MIN_STEPS` steps are so short that the span would take more than
    :data:`STALL_STEPS` of them."""

    def __init__(self, t0: float, t1: float):
        self.t0, self.t1, self.steps = float(t0), float(t1), 0

    def after_step(self, step, sets, run):
        self.steps += 1
        done = float(step.t) - self.t0
        # judged once, at the STALL_MIN_STEPS-th step: a run whose steps shrink only near its
        # end (a set blowing up before a break-down) is not a stall, it is a split's business
        if self.steps == STALL_MIN_STEPS and done * STALL_STEPS < self.steps * (self.t1 - self.t0):
            run.stop(f"{STALLED}: {self.steps} steps to t = {step.t:g} (about "
                     f"{self.steps * (self.t1 - self.t0) / max(done, 1e-300):.3g} for the span)", "breakdown")
        return None


def _one_batch(common: dict) -> dict:
    """``common`` for a run continued from sets (``solve(start=)``: one batch here)."""
    return {**common, "workers": 1, "client": None, "chunks": None, "rechunk": None}


def _carried(params) -> int:
    """How many parameters a run carries as states (all of them when any is uncertain)."""
    if params is None or not isinstance(params, Interval) or not bool(np.any(params.width() > 0)):
        return 0
    return int(params.shape[-1])


def _summary(log) -> str:
    return "auto: " + "; ".join(f"{e['method']} on {e['pieces']} piece(s) {e['status']} to t = {e['t_span'][1]:g}"
                                for e in log)


def _ladder(solve, ode, graph, boxes: Interval, pv, t_span, *, method: Auto, t_eval, consistency, hooks, progress,
            started: float, **common) -> Solution:
    """One pass of the ladder from ``boxes`` (module docstring)."""
    from .parallel import merge_solutions
    from .solver_args import check_settings

    n = graph.n_inputs
    t0, t1, outs, _ = check_settings(
        t_span=t_span, t_eval=t_eval, order=method.order, tol=method.tol, h_max=common.get("h_max"),
        h_min=common.get("h_min", 1e-9), max_steps=common.get("max_steps", 100_000),
        max_width=common.get("max_width", 1e3), adaptive=common.get("adaptive", False),
        split_ratio=common.get("split_ratio", 0.01), max_boxes=common.get("max_boxes", 4096),
        wrap_target=common.get("wrap_target", 0.03), merge_slack=common.get("merge_slack"),
        error_basis="qr", progress=progress)
    rungs = list(method.rungs or default_rungs(graph, boxes, pv))
    # the method a stalled attempt's pieces go to: first-order sets take long steps where
    # the composition's remainders keep its steps tiny (docs/lab/code_notes.md)
    rungs.append(FALLBACK)
    fallback = len(rungs) - 1
    for r in rungs:
        r.refuse(adaptive=bool(common.get("adaptive")), consistency=consistency is not None,
                 params=pv is not None and bool(np.any(pv.width() > 0)))
    hooks = list(hooks)

    todo = [_Task(boxes, pv, 0)]
    first = None
    done: list[tuple[Interval, Solution]] = []
    log: list[dict] = []
    pieces_total = boxes.shape[0]
    give_up = None
    while todo:
        task = todo.pop(0)
        rung = rungs[task.rung]
        t_start = time.perf_counter()
        cont = task.failure
        t_from = float(t0) if cont is None else float(cont.t)
        guard = [] if task.rung == fallback else [StallGuard(t_from, t1)]
        if cont is None:
            sol = solve(ode, task.boxes, (t0, t1), method=rung, params=task.params, t_eval=t_eval,
                        consistency=None if consistency is None else copy.deepcopy(consistency),
                        hooks=caps_from(hooks, started) + guard, progress=progress, **common)
        else:
            # continued from the failed attempt's sets at exactly their time (switch_start)
            start = switch_start(cont, rung)
            sol = solve(ode, start.sets.hull()[:, :n], (t0, t1), method=rung, params=task.params, t_eval=t_eval,
                        start=start, hooks=caps_from(hooks, started) + guard, progress=progress,
                        **_one_batch(common))
        entry = dict(method=rung.describe(), pieces=int(task.boxes.shape[0]), splits=task.splits,
                     t_span=(t_from, float(sol.t_reached)), status=sol.status, reason=sol.reason,
                     wall_s=time.perf_counter() - t_start)
        if cont is not None:
            entry["continued"] = f"from the sets of {task.boxes.shape[0]} piece(s) at t = {t_from:g}"
        log.append(entry)
        if first is None and cont is None and task.boxes.shape[0] == boxes.shape[0] and task.rung == 0 \
                and task.splits == 0:
            first = sol  # (the first attempt, on every initial piece)
        if cont is not None and sol.status != "breakdown":
            sol = chain_in_time([cont.record, sol])
        if sol.status != "breakdown":  # completed, or stopped / interrupted: nothing more is tried
            done.append((task.boxes, sol))
            if sol.status != "completed":
                give_up = sol.status
                for rest in todo:  # (not run: their pieces are verified at t0 only)
                    done.append((rest.boxes, None))
                todo = []
            continue
        if cont is not None and float(sol.t_reached) <= t_from + MIN_GAIN * (t1 - t0):
            # the sets where the weaker method stopped were too far gone for this one too
            # (an enclosure already too wide, say): this method takes the pieces from t0
            todo.append(_Task(task.boxes, task.params, task.rung, task.splits, task.parent_t))
            entry["next"] = f"the continuation got no further: {rung.describe()} from t0"
            continue
        if cont is not None:
            # a continuation that broke down: its sets mix its pieces, which go back to t0
            # and are split there (below); the failed attempt's record stands for them
            failed, failures = list(range(task.boxes.shape[0])), []
            sol = chain_in_time([cont.record, sol])
        else:
            failed = [p.index for p in (sol.piece_results or ()) if p.failed]
            if not failed or sol.surviving is None:
                failed = list(range(task.boxes.shape[0]))
            failures = [f for f in (sol.failures or ()) if _continuable(f, task.params, n + _carried(pv))]
        kept = [i for i in range(task.boxes.shape[0]) if i not in set(failed)]
        last = fallback if task.rung == fallback else fallback - 1  # (the rung splitting continues with)
        stalled = sol.reason.startswith(STALLED) and task.rung != fallback
        if stalled or (task.rung + 1 < fallback and cont is None):
            # the next rung takes the failed pieces over: from where their sets stopped
            # (Solution.failures), else (sets that cannot be continued) from t0
            to = fallback if stalled else task.rung + 1
            why = " (stalled)" if stalled else ""
            covered = set()
            for f in failures:
                idx = [int(i) for i in f.pieces]
                covered |= set(idx)
                todo.append(_Task(task.boxes[np.asarray(idx)], task.params, to, task.splits, task.parent_t,
                                  failure=f))
            rest = [i for i in failed if i not in covered]
            if rest:
                todo.append(_Task(task.boxes[np.asarray(rest)], _rows(task.params, rest), to, task.splits,
                                  task.parent_t))
            if kept:
                done.append((task.boxes[np.asarray(kept)], sol.surviving))
            entry["next"] = f"{len(failed)} piece(s) to {rungs[to].describe()}{why}" + (
                f", continued from their sets at t = {min(f.t for f in failures):g}" if failures else "")
            continue
        fb, fp = task.boxes[np.asarray(failed)], _rows(task.params, failed)
        # splitting: the failed pieces' initial boxes, split, from t0 (splitting the sets
        # where they failed gained less: docs/lab, issue 40)
        if cont is not None:
            t_fail = float(sol.t_reached)
        else:
            t_fail = min((p.t_reached for p in (sol.piece_results or ()) if p.failed), default=sol.t_reached)
        parts, part_params = split_pieces(graph, fb, fp, float(t_fail) - float(t0))
        why = None
        if parts.shape[0] == fb.shape[0]:
            why = "the pieces cannot be split (no state or parameter of finite, nonzero width)"
        elif pieces_total - fb.shape[0] + parts.shape[0] > method.max_pieces:
            why = f"splitting {len(failed)} piece(s) would make more than max_pieces = {method.max_pieces}"
        elif t_fail <= task.parent_t + MIN_GAIN * (t1 - t0):
            # splitting did not take the pieces further: the cause is not the sets' width
            # (a blow-up, a singularity, a step-size limit), and more pieces will not help
            why = (f"the split pieces broke down at t = {t_fail:g}, no later than the piece they were "
                   f"split from (t = {task.parent_t:g})")
        if why is not None:
            entry["next"] = f"gave up: {why}"
            done.append((task.boxes, sol))  # (the failed attempt encloses all its pieces up to its end)
            give_up = "breakdown"
            continue
        if kept:
            done.append((task.boxes[np.asarray(kept)], sol.surviving))
        pieces_total += parts.shape[0] - fb.shape[0]
        todo.append(_Task(parts, part_params, last, task.splits + 1, t_fail))
        entry["next"] = f"{len(failed)} piece(s) split into {parts.shape[0]}, with {rungs[last].describe()}"

    pieces = concatenate([b for b, _ in done], axis=0)
    if len(done) == 1 and done[0][1] is not None:
        result = done[0][1]
    else:
        initial = concatenate([b for b, _ in done], axis=0)
        ends = np.cumsum([b.shape[0] for b, _ in done])
        ranges = list(zip(np.concatenate([[0], ends[:-1]]).tolist(), ends.tolist()))
        result = merge_solutions([s for _, s in done], ranges, initial, outs, t0,
                                 tuple(graph.input_names[:n]), interrupted=give_up == "interrupted")
        result.chunks = None  # (the attempts are in method_log)
    if result.status != "completed" and first is not None and first.t_reached > result.t_reached:
        # the later attempts ended earlier than the first one, which ran every initial
        # piece (stopped by a wall-clock cap while splitting, say): its enclosure of the
        # whole initial set, verified further, is the result
        why = result.reason
        result = first
        result.reason = f"{first.reason} (later attempts: {why})"
        give_up = give_up or result.status
    if result.status == "breakdown" and give_up == "breakdown":
        tried = ", ".join(dict.fromkeys(e["method"] for e in log))
        result.reason = (f"{result.reason} (auto tried {tried} on up to {pieces_total} pieces; "
                         f"see Solution.method_log)")
    result.method_log = log
    result.method = _summary(log)
    # (per-piece params rows follow the pieces only without splitting of per-box params)
    result.stats["auto_pieces"] = int(pieces.shape[0])
    return result, pieces

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
(:func:`verified.driver.time_chain.chain_in_time`), and the result is the union of the attempts that
together cover every initial piece (:func:`verified.execution.merge.merge_solutions`). A
piece that fails on every rung keeps the failed attempt's enclosure, verified up to
where that attempt got, and the run is a break-down at the earliest such time, naming
what was tried. A run with a consistency test is never continued from sets (they carry
the test's energy state): its pieces restart from ``t0``.

``Solution.method_log`` lists the attempts: which method advanced which pieces over
which span, how it ended, and why the next one was tried.
"""

from __future__ import annotations

import time

import numpy as np

from verified.arith.interval import Interval
from verified.methods import Auto
from verified.driver.solution import Solution
from verified.auto.ladder import _ladder, _summary
from verified.auto.spec_proof import _StepEnds, _prove_spec
from verified.auto.splitting import split_boxes

__all__ = ["solve_auto"]


def solve_auto(solve, ode, x0, t_span, *, method: Auto, params=None, t_eval=None, subdivision=None,
               consistency=None, hooks=(), progress=None, **common) -> Solution:
    """Run :class:`~verified.methods.Auto`'s ladder (module docstring). ``solve`` is
    :func:`verified.solver.solve` (passed in: this module is imported by it);
    ``common`` the rest of its keyword arguments (step bounds, adaptive splitting,
    execution), the same for every attempt. With ``method.target_ratio``, the ladder is
    repeated on split pieces while its final enclosure is wider than that ratio times
    the sampled spread (:func:`sampled_spread`)."""
    from verified.driver.batch import VerifiedODE
    from verified.driver.solver_args import check_graph, check_params, initial_boxes

    wall0 = time.perf_counter()
    graph = check_graph(ode.graph if isinstance(ode, VerifiedODE) else ode)
    boxes = initial_boxes(x0, graph.n_inputs, subdivision)
    pv = check_params(params, graph, boxes.shape[0], subdivision)
    kw = dict(method=method, t_eval=t_eval, consistency=consistency, hooks=hooks, progress=progress,
              started=wall0, **common)
    rec = None
    if method.spec is not None:   # (names checked before any work; the step ends recorded)
        n = graph.n_inputs
        rec = _StepEnds(*method.spec.resolve(graph.input_names[:n]), n)
    sol, pieces, piece_params = _ladder(solve, ode, graph, boxes, pv, t_span,
                                        **(kw if rec is None else {**kw, "hooks": list(hooks) + [rec]}))
    first = sol
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
            nxt, nxt_pieces, nxt_params = _ladder(solve, ode, graph, parts, pv, t_span, **kw)
            log += nxt.method_log
            if nxt.status != "completed":
                break
            w = _final_width(nxt)
            new_ratio = _ratio(nxt, spread)
            log[-1]["ratio_estimate"] = new_ratio
            if not np.all(w <= best_w):  # (no tighter in every state: more pieces do not pay)
                break
            best, best_w, ratio = nxt, w, new_ratio
            pieces, piece_params = nxt_pieces, nxt_params
        best.method_log = log
        best.method = _summary(log)
        sol = best
    if method.spec is not None:
        ends = rec.worst if sol is first and rec.steps else np.nan
        sol = _prove_spec(solve, ode, graph, boxes, pv, t_span, method, kw, sol, pieces, piece_params, ends)
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

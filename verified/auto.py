# Whole for now: the ladder and the spec proof call each other (_ladder <-> _prove_spec).
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

import copy
import time
from dataclasses import dataclass

import numpy as np

from verified.driver.hooks import Hook, caps_from
from verified.arith.interval import Interval, concatenate
from verified.methods import Auto, Composition, Lohner, Method
from verified.driver.solution import Failure, Solution, Start
from verified.driver.time_chain import chain_in_time

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


def _widest_dims(lo, hi, max_dims: int) -> list[int]:
    """The components of a box at least half as wide as its widest (finite, nonzero
    widths), widest first, at most ``max_dims``."""
    with np.errstate(over="ignore"):  # (a box of +-1.7e308 is wider than the largest float)
        w = np.where(np.isfinite(hi - lo), hi - lo, 0.0)
    order = np.argsort(-w, kind="stable")
    return [int(j) for j in order[:max_dims] if w[j] > 0 and w[j] >= 0.5 * w[order[0]]]


def _bisect(lo, hi, dims) -> list[tuple[np.ndarray, np.ndarray]]:
    """The box ``lo..hi`` bisected along each of ``dims``: 2^len(dims) parts (lo, hi),
    every point of the box in one of them (the cut is shared by both halves)."""
    parts = [(np.array(lo, float), np.array(hi, float))]
    for j in dims:
        cut = 0.5 * (lo[j] + hi[j])
        nxt = []
        for a, c in parts:
            a1, c1, a2, c2 = a.copy(), c.copy(), a.copy(), c.copy()
            c1[j] = cut
            a2[j] = cut
            nxt += [(a1, c1), (a2, c2)]
        parts = nxt
    return parts


def split_boxes(boxes: Interval, max_dims: int = SPLIT_DIMS) -> Interval:
    """Each box (B, n) bisected along its widest components (those at least half as wide
    as its widest, at most ``max_dims`` of them): (B * 2^d, n), every point of a box in
    one of its parts (the cut is shared by both halves)."""
    out = []
    for b in range(boxes.shape[0]):
        lo, hi = np.asarray(boxes.lo[b], float), np.asarray(boxes.hi[b], float)
        out += _bisect(lo, hi, _widest_dims(lo, hi, max_dims))
    return Interval(np.array([a for a, _ in out]), np.array([c for _, c in out]))


#: a component of a piece with uncertain parameters (a state or a parameter) is bisected
#: when moving it across its interval alone moves some state at the failure time at least
#: this share as much as the component that moves any state most (:func:`influences`)
INFLUENCE_SHARE = 0.5


def influences(graph, lo, hi, plo, phi, T: float):
    """How much each component of a piece -- its states ``lo..hi`` (n,), then its
    parameters ``plo..phi`` (p,) -- moves the states at time ``T``: float trajectories
    (DOP853, rtol = atol = 1e-8) from the piece's centre with that one component at its
    lower and at its upper end: the largest distance between the two ends over the
    states, relative to the largest such distance of any component. Shape (n + p,), 0
    for components of zero or infinite width; None where the integration fails. It
    guides splitting only, never an enclosure.

    The distances are compared across states, in the states' own units (as
    :func:`split_boxes` compares widths). Relative to each state's own largest mover
    instead, a state that barely moves but is moved most by its own initial width
    scored as high as the parameter that moves the wide states, and a robot holding an
    uncertain payload was split along joint angles of +- 1 mrad beside the mass
    (docs/lab/robot_speed.md)."""
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
    top = moved.max()
    if top > 0:
        out[dims] = moved.max(axis=1) / top
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
            rel = np.where(phi > plo, (phi - plo) / np.maximum(np.abs(0.5 * (plo + phi)), 1e-300), 0.0)
            dims = sorted(_widest_dims(lo, hi, SPLIT_DIMS))[:SPLIT_DIMS - 1] + [n + int(np.argmax(rel))]
        else:
            order = np.argsort(-infl, kind="stable")
            dims = [int(j) for j in order[:SPLIT_DIMS] if infl[j] > 0 and infl[j] >= INFLUENCE_SHARE * infl[order[0]]]
        cuts = _bisect(np.concatenate([lo, plo]), np.concatenate([hi, phi]), dims)
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
    from verified.steppers.set_kinds import set_kind

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


# ---------------------------------------------------------------- a spec to prove (Auto(spec=...))

#: rounds of refinement toward a spec, at most
SPEC_ROUNDS = 8
#: a refinement is kept when it cuts the excess of the tube over the bounds by at least
#: this share (else the other refinement is tried, then the pieces are left as they are)
SPEC_GAIN = 0.1
#: shortening the steps: the new ``h_max`` is this share of the longest step whose tube
#: leaves the bounds, at least and at most (within: what a tube excess over the sets at
#: the step ends shrinking in proportion to the step would need, with a 0.8 margin)
SPEC_STEP_SHARE = (0.25, 0.7)
#: a sampled float trajectory is taken to leave the bounds when it is out by more than
#: this times (1 + |bound|) (the sampler's error, DOP853 at rtol = atol = 1e-10)
SAMPLE_SLACK = 1e-6
#: sampled trajectories: per initial box the corners (up to 2^6) and this many random
#: points; at most SAMPLE_BOXES boxes (drawn at random among more)
SAMPLE_PER_BOX = 8
SAMPLE_BOXES = 32


class _StepEnds(Hook):
    """Records how far the sets at the step ends reach out of the bounds (their hull
    boxes over the ``n`` states; the largest excess over all steps and sets). Guides
    the choice between splitting and shorter steps; never a proof."""

    def __init__(self, lo, hi, n: int):
        self.lo, self.hi, self.n = lo, hi, n
        self.worst, self.steps = -np.inf, 0

    def after_step(self, step, sets, run):
        from verified.spec import tube_excess
        e = tube_excess(sets.hull()[:, :self.n], self.lo, self.hi)
        self.worst = max(self.worst, float(np.max(e)) if e.size else -np.inf)
        self.steps += 1
        return None


@dataclass
class _Group:
    """Pieces run together toward the spec, and how they fared."""
    boxes: Interval          # (k, n)
    params: object           # the run's params, or rows (k, p)
    h_max: float | None
    sol: Solution
    ends: float              # worst excess of the sets at the step ends (nan: not recorded)
    excess: float            # worst excess of the tube over the bounds (inf: not completed)
    tried: tuple = ()        # refinements that did not gain on these pieces


def _group_excess(sol, lo, hi, t0, t1) -> float:
    from verified.spec import check_tube
    c = check_tube(sol, lo, hi, t0, t1, [f"x{i}" for i in range(lo.size)])
    return c.worst if sol.status == "completed" else np.inf


def _piece_excess(sol, k: int, lo, hi, pieces: Interval):
    """Per piece of a one-attempt, one-batch completed run whose every output and step
    keeps one box per piece and whose first output is the pieces themselves, in order:
    the worst excess of its tube boxes over the bounds (k,); None where the rows cannot
    be told apart (merged attempts, chunks, adaptive splitting, pruning). (Soundness
    rests on it: the pieces kept and the pieces split must be told apart exactly.)"""
    from verified.spec import tube_excess
    if sol.status != "completed" or len(sol.method_log or ()) != 1 or not sol.tube or sol.chunks is not None:
        return None
    if any(b.shape[0] != k for b in sol.tube) or any(b.shape[0] != k for b in sol.boxes):
        return None
    first = sol.boxes[0]
    if not (np.array_equal(np.asarray(first.lo), np.asarray(pieces.lo))
            and np.array_equal(np.asarray(first.hi), np.asarray(pieces.hi))):
        return None
    return np.max(np.stack([tube_excess(b, lo, hi) for b in sol.tube]), axis=0)


def _restrict(sol, keep: np.ndarray):
    """``sol`` with the boxes of the pieces ``keep`` (bool (k,)) only (one box per piece
    at every output and step: :func:`_piece_excess`)."""
    from verified.driver.batch import _restricted
    k = keep.size
    ident = np.arange(k)
    out = _restricted(sol, keep, [ident] * len(sol.boxes), [ident] * len(sol.tube))
    out.piece_results = None
    out.method_log = sol.method_log
    return out


def _step_share(g: _Group) -> float:
    """How much shorter the longest offending steps should get (:data:`SPEC_STEP_SHARE`)."""
    lo_s, hi_s = SPEC_STEP_SHARE
    if not (np.isfinite(g.ends) and g.ends <= 0 < g.excess):
        return lo_s
    return float(np.clip(0.8 * (-g.ends) / (g.excess - g.ends), lo_s, hi_s))


def sampled_violation(graph, boxes: Interval, params, t0: float, t1: float, lo, hi, seed: int = 0):
    """Float trajectories (DOP853, rtol = atol = 1e-10, dense) from the corners (up to
    2^6) and :data:`SAMPLE_PER_BOX` random points of the initial boxes (parameters: at
    their middle for the corners, random in their row for the random points, and their
    corners from the box's centre), evaluated on 2001 times in [t0, t1]: ``(excess, t,
    x)``, the largest excess over the bounds and where (``excess`` < 0: inside by that
    margin). A float finding that stops refining when it is out by more than
    :data:`SAMPLE_SLACK`; never a proof. None where the integration fails."""
    from scipy.integrate import solve_ivp

    from verified.spec import tube_excess

    rng = np.random.default_rng(seed)
    n = graph.n_inputs
    B = boxes.shape[0]
    pick = np.arange(B) if B <= SAMPLE_BOXES else np.sort(rng.choice(B, SAMPLE_BOXES, replace=False))
    has_p = params is not None and isinstance(params, Interval)
    pts, prs = [], []
    for b in pick:
        blo, bhi = np.asarray(boxes.lo[b], float), np.asarray(boxes.hi[b], float)
        if has_p:
            row = params if params.ndim == 1 else params[int(b)]
            plo, phi = np.asarray(row.lo, float), np.asarray(row.hi, float)
        else:
            plo = phi = np.zeros(0)
        k = min(n, 6)
        corners = np.array(np.meshgrid(*[[0.0, 1.0]] * k, indexing="ij")).reshape(k, -1).T
        c = np.tile(0.5 * (blo + bhi), (corners.shape[0], 1))
        c[:, :k] = blo[:k] + corners * (bhi[:k] - blo[:k])
        pts.append(c)
        prs.append(np.tile(0.5 * (plo + phi), (c.shape[0], 1)))
        pts.append(blo + (bhi - blo) * rng.random((SAMPLE_PER_BOX, n)))
        prs.append(plo + (phi - plo) * rng.random((SAMPLE_PER_BOX, plo.size)))
        wide = np.flatnonzero(phi > plo)[:4]
        if wide.size:
            pc = np.array(np.meshgrid(*[[0.0, 1.0]] * wide.size, indexing="ij")).reshape(wide.size, -1).T
            pp = np.tile(0.5 * (plo + phi), (pc.shape[0], 1))
            pp[:, wide] = plo[wide] + pc * (phi[wide] - plo[wide])
            pts.append(np.tile(0.5 * (blo + bhi), (pc.shape[0], 1)))
            prs.append(pp)
    X0, P = np.concatenate(pts), np.concatenate(prs)
    S = X0.shape[0]
    P = P if has_p else None

    def f(t, y):
        return graph.eval_float(y.reshape(S, n), P).reshape(-1)
    if not t1 > t0:
        return None
    with np.errstate(all="ignore"):
        r = solve_ivp(f, (float(t0), float(t1)), X0.reshape(-1), method="DOP853", rtol=1e-10, atol=1e-10,
                      dense_output=True)
    if not r.success:
        return None
    ts = np.linspace(float(t0), float(t1), 2001)
    Y = r.sol(ts).T.reshape(ts.size, S, n)
    if not np.all(np.isfinite(Y)):
        return None
    flat = Y.reshape(-1, n)
    e = tube_excess(Interval._from_bounds(flat, flat), lo, hi)
    bound = np.where(np.isfinite(hi), np.abs(hi), np.where(np.isfinite(lo), np.abs(lo), 0.0))
    # (the excess beyond the sampler's slack, per point: the largest over the states)
    with np.errstate(invalid="ignore"):
        per = np.max(np.maximum(flat - hi, lo - flat) - SAMPLE_SLACK * (1.0 + bound), axis=1)
    j = int(np.argmax(per))
    return float(e[j]), float(ts[j // S]), flat[j].copy(), bool(per[j] > 0)


def _prove_spec(solve, ode, graph, boxes, pv, t_span, method: Auto, kw: dict, sol, pieces, piece_params,
                ends: float = np.nan):
    """Refine ``sol`` (a finished run of the ladder on ``pieces``) toward
    ``method.spec``: while the tube leaves the bounds and a refinement still cuts the
    excess by :data:`SPEC_GAIN`, the offending pieces are split (where the sets at the
    step ends leave the bounds too: only narrower sets help) or the steps shortened
    (where the step ends keep inside and only the tube between them leaves); a
    refinement that does not gain is undone and the other one tried. The result is the
    union of the groups of pieces (:func:`verified.execution.merge.merge_solutions`), its spec
    judged on its own tube (:func:`verified.spec.check_tube`). Sampled trajectories that
    leave the bounds (:func:`sampled_violation`) make the spec "false" and stop it."""
    from verified.execution.merge import merge_solutions
    from verified.spec import FALSE, check_tube, describe, tube_excess

    n = graph.n_inputs
    names = tuple(graph.input_names[:n])
    lo, hi = method.spec.resolve(names)
    t0, t1 = float(t_span[0]), float(t_span[1])
    text = describe(lo, hi, names)
    check = check_tube(sol, lo, hi, t0, t1, names)
    log = list(sol.method_log or ())
    if check.proven or sol.status != "completed":
        if not check.proven:   # (the sampled verdict still tells a false spec)
            found = sampled_violation(graph, boxes, pv, t0, t1, lo, hi)
            if found is not None:
                check.sampled = found[0]
                if found[3]:
                    check.status, check.witness = FALSE, (found[1], found[2])
                    check.detail = (f"{text}: false (a sampled trajectory reaches {_point(found, names)}); "
                                    f"{check.detail.split(': ', 1)[1]}")
        return _with_spec(sol, check, log, 0)
    found = sampled_violation(graph, boxes, pv, t0, t1, lo, hi)
    if found is not None and found[3]:
        check.status, check.witness, check.sampled = FALSE, (found[1], found[2]), found[0]
        check.detail = f"{text}: false (a sampled trajectory reaches {_point(found, names)}); not refined"
        return _with_spec(sol, check, log, 0)
    sampled = None if found is None else found[0]

    user_hooks = list(kw.get("hooks") or ())

    def run(bx, prm, h, why):
        rec = _StepEnds(lo, hi, n)
        s, pcs, pprm = _ladder(solve, ode, graph, bx, prm, t_span, **{**kw, "hooks": user_hooks + [rec], "h_max": h})
        entries = list(s.method_log or ())
        if entries:
            entries[0] = {**entries[0], "spec": why}
        log.extend(entries)
        ends = rec.worst if rec.steps else np.nan
        return _Group(pcs, pprm, h, s, ends, _group_excess(s, lo, hi, t0, t1))

    first = _Group(pieces, piece_params, kw.get("h_max"), sol, ends, check.worst)
    final: list[_Group] = []
    active = [first]
    rounds, stop = 0, False
    while rounds < SPEC_ROUNDS and not stop:
        todo = [g for g in active if g.excess > 0 and _action(g) is not None]
        if not todo:
            break
        rounds += 1
        nxt = [g for g in active if not (g.excess > 0 and _action(g) is not None)]
        total = sum(g.boxes.shape[0] for g in active) + sum(g.boxes.shape[0] for g in final)
        for g in todo:
            act = _action(g)
            k = g.boxes.shape[0]
            if act == "split":
                pe = _piece_excess(g.sol, k, lo, hi, g.boxes)
                bad = np.ones(k, bool) if pe is None else pe > 0
                idx = np.flatnonzero(bad)
                parts, part_params = split_pieces(graph, g.boxes[idx], _rows(g.params, idx), t1 - t0)
                for _ in range(_spec_splits(g.excess, sampled) - 1):   # (as often at once as the excess asks)
                    more, more_params = split_pieces(graph, parts, part_params, t1 - t0)
                    if more.shape[0] == parts.shape[0] or total - idx.size + more.shape[0] > method.max_pieces:
                        break
                    parts, part_params = more, more_params
                if parts.shape[0] == idx.size or total - idx.size + parts.shape[0] > method.max_pieces:
                    g.tried += ("split",)
                    nxt.append(g)
                    continue
                parent = g
                if not bad.all():   # (the pieces whose tube keeps inside stay as they are)
                    good = _restrict(g.sol, ~bad)
                    final.append(_Group(g.boxes[np.flatnonzero(~bad)], _rows(g.params, np.flatnonzero(~bad)),
                                        g.h_max, good, g.ends, _group_excess(good, lo, hi, t0, t1)))
                    part = _restrict(g.sol, bad)
                    parent = _Group(g.boxes[idx], _rows(g.params, idx), g.h_max, part, g.ends,
                                    _group_excess(part, lo, hi, t0, t1), g.tried)
                why = (f"spec round {rounds}: {text} exceeded by {parent.excess:.3g}; {idx.size} of {k} piece(s) "
                       f"split into {parts.shape[0]}")
                child = run(parts, part_params, g.h_max, why)
                total += parts.shape[0] - idx.size
            else:
                dt = np.diff(np.asarray(g.sol.tube_t, float))
                per = np.array([float(np.max(tube_excess(b, lo, hi))) for b in g.sol.tube])
                h_long = float(np.max(dt[per > 0])) if np.any(per > 0) else float(np.max(dt))
                h = _step_share(g) * h_long
                if g.h_max is not None:
                    h = min(h, float(g.h_max))
                why = (f"spec round {rounds}: {text} exceeded by {g.excess:.3g}; h_max {h:.3g} "
                       f"(offending steps up to {h_long:.3g})")
                parent = g
                child = run(g.boxes, g.params, h, why)
            if child.sol.status in ("stopped", "interrupted"):
                stop = True
            if child.excess <= 0 or (child.sol.status == "completed"
                                     and child.excess <= (1 - SPEC_GAIN) * parent.excess):
                nxt.append(child)
            else:
                log[-1]["next"] = f"spec: {act} did not cut the excess ({parent.excess:.3g} -> {child.excess:.3g})"
                if not np.isfinite(parent.ends) and np.isfinite(child.ends) and act == "step":
                    parent.ends = child.ends
                parent.tried += (act,)
                nxt.append(parent)
            if stop:
                nxt += [h for h in todo if h is not g and h not in nxt]
                break
        active = nxt
    groups = final + active
    if len(groups) == 1:
        result = groups[0].sol
    else:
        initial = concatenate([g.boxes for g in groups], axis=0)
        ends = np.cumsum([g.boxes.shape[0] for g in groups])
        ranges = list(zip(np.concatenate([[0], ends[:-1]]).tolist(), ends.tolist()))
        result = merge_solutions([g.sol for g in groups], ranges, initial, np.asarray(sol.t, float), t0, names)
        result.chunks = None
    result.stats["auto_pieces"] = int(sum(g.boxes.shape[0] for g in groups))
    check = check_tube(result, lo, hi, t0, t1, names)
    check.sampled = sampled
    return _with_spec(result, check, log, rounds)


#: how much one round of splitting is taken to cut the overestimation of the tube (its
#: excess over the sampled extreme) by: on Van der Pol (mu = 1, T = 7) 1 -> 2 pieces cut
#: it 2.8x, 2 -> 8 pieces 1.7x (there the steps' share remains); rounded up, at most
#: SPEC_MAX_SPLITS rounds at once
SPEC_SPLIT_GAIN = 4.0
SPEC_MAX_SPLITS = 3


def _spec_splits(excess: float, sampled) -> int:
    """Rounds of splitting (1 to :data:`SPEC_MAX_SPLITS`) expected to bring the tube's
    overestimation ``excess - sampled`` (``sampled``: the sampled trajectories' excess
    over the bound, < 0) below the sampled margin ``-sampled``."""
    if sampled is None or not (np.isfinite(excess) and sampled < 0 < excess):
        return 1
    need = (excess - sampled) / (-sampled)
    return int(min(SPEC_MAX_SPLITS, max(1, np.ceil(np.log(need) / np.log(SPEC_SPLIT_GAIN)))))


def _action(g: _Group):
    """The next refinement of a group: splitting where the sets at the step ends leave
    the bounds (or where that is not known), shorter steps where only the tube between
    them does; then the other; None when both were tried without gain."""
    prefer = "step" if (np.isfinite(g.ends) and g.ends <= 0) else "split"
    for a in (prefer, "split" if prefer == "step" else "step"):
        if a not in g.tried:
            return a
    return None


def _point(found, names) -> str:
    return f"{', '.join(f'{nm} = {v:.6g}' for nm, v in zip(names, found[2]))} at t = {found[1]:.4g}"


def _with_spec(sol, check, log, rounds: int):
    sol.spec_check = check
    sol.method_log = log
    sol.method = _summary(log) + f"; spec {check.detail}"
    sol.stats["spec"] = check.status
    sol.stats["spec_rounds"] = rounds
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
                                + (" (spec: split)" if "split into" in e.get("spec", "") else
                                   " (spec: shorter steps)" if "h_max" in e.get("spec", "") else "")
                                for e in log)


def _stack_rows(parts, pv):
    """The parameters of the pieces of ``parts`` ((count, params) each, in order): ``pv``
    itself where every part has it unchanged (None, or one row for all), else one row
    per piece (count, p) stacked."""
    if all(p is pv for _, p in parts) or pv is None:
        return pv
    rows = []
    for k, p in parts:
        if p.ndim == 1:
            p = Interval(np.tile(np.asarray(p.lo, float), (k, 1)), np.tile(np.asarray(p.hi, float), (k, 1)))
        rows.append(p)
    return concatenate(rows, axis=0)


def _ladder(solve, ode, graph, boxes: Interval, pv, t_span, *, method: Auto, t_eval, consistency, hooks, progress,
            started: float, **common):
    """One pass of the ladder from ``boxes`` (module docstring): (the Solution, the
    pieces it ended with (k, n), their parameters: ``pv`` as given, or rows (k, p)
    where splitting gave the parts their own)."""
    from verified.execution.merge import merge_solutions
    from verified.driver.solver_args import check_settings

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
    covers = []  # [(boxes, Solution, params), ...] of failed attempts that, with the pieces done, covered everything
    done: list[tuple[Interval, Solution, object]] = []  # (pieces, their Solution, their params)
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
            done.append((task.boxes, sol, task.params))
            if sol.status != "completed":
                give_up = sol.status
                for rest in todo:  # (not run: their pieces are verified at t0 only)
                    done.append((rest.boxes, None, rest.params))
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
                done.append((task.boxes[np.asarray(kept)], sol.surviving, _rows(task.params, kept)))
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
        if not todo:
            # this attempt's pieces and the finished ones cover every initial piece: their
            # enclosure, verified to where this attempt got, stands if later attempts end earlier
            covers.append(list(done) + [(task.boxes, sol, task.params)])
        if why is not None:
            entry["next"] = f"gave up: {why}"
            done.append((task.boxes, sol, task.params))  # (the failed attempt encloses all its pieces up to its end)
            give_up = "breakdown"
            continue
        if kept:
            done.append((task.boxes[np.asarray(kept)], sol.surviving, _rows(task.params, kept)))
        pieces_total += parts.shape[0] - fb.shape[0]
        todo.append(_Task(parts, part_params, last, task.splits + 1, t_fail))
        entry["next"] = f"{len(failed)} piece(s) split into {parts.shape[0]}, with {rungs[last].describe()}"

    pieces = concatenate([b for b, _, _ in done], axis=0)
    piece_params = _stack_rows([(b.shape[0], p) for b, _, p in done], pv)

    def merged(parts):
        if len(parts) == 1 and parts[0][1] is not None:
            return parts[0][1]
        initial = concatenate([b for b, _, _ in parts], axis=0)
        ends = np.cumsum([b.shape[0] for b, _, _ in parts])
        ranges = list(zip(np.concatenate([[0], ends[:-1]]).tolist(), ends.tolist()))
        out = merge_solutions([s for _, s, _ in parts], ranges, initial, outs, t0,
                              tuple(graph.input_names[:n]), interrupted=give_up == "interrupted")
        out.chunks = None  # (the attempts are in method_log)
        return out

    result = merged(done)
    if result.status != "completed":
        # the later attempts ended earlier than an earlier one that, with the pieces done
        # by then, covered every initial piece (a wall-clock cap striking while auto
        # splits, say): that enclosure of the whole initial set, verified further, is the
        # result (the first attempt, or a split attempt that broke down later)
        best = first if first is not None and first.t_reached > result.t_reached else None
        for parts in covers:
            if min(float(s.t_reached) for _, s, _ in parts if s is not None) <= float(
                    (result if best is None else best).t_reached):
                continue  # (a merge reaches no further than its earliest part)
            cand = merged(parts)
            if cand.t_reached > (result if best is None else best).t_reached:
                best, pieces = cand, concatenate([b for b, _, _ in parts], axis=0)
                piece_params = _stack_rows([(b.shape[0], p) for b, _, p in parts], pv)
        if best is not None:
            why = result.reason
            result = best
            result.reason = f"{best.reason} (later attempts: {why})"
            give_up = give_up or result.status
    if result.status == "breakdown" and give_up == "breakdown":
        tried = ", ".join(dict.fromkeys(e["method"] for e in log))
        result.reason = (f"{result.reason} (auto tried {tried} on up to {pieces_total} pieces; "
                         f"see Solution.method_log)")
    result.method_log = log
    result.method = _summary(log)
    # (per-piece params rows follow the pieces only without splitting of per-box params)
    result.stats["auto_pieces"] = int(pieces.shape[0])
    return result, pieces, piece_params

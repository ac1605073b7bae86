"""M(q) > 0 for a run of a chain: the checks before :func:`mbs.simulate.simulate`
integrates, and the proof on the boxes it integrated.

A verified run of a chain is only meaningful where M(q) is positive definite (else
qdd is not defined).  Model validation catches massless subtrees; masses on joint
axes (M = 0, M = diag(2, 0), singular configurations) are caught here:

- before integrating: a constant zero LDL^T pivot raises while the graphs are
  traced (mbs.numeric.ldl_factor), and M at the centre of each initial box must be
  nonsingular in floats (SingularMassMatrixError naming the joints;
  :func:`check_initial`);
- after integrating: the interval pivots D_k(q) of M must be proven > 0 on every
  box the solver used (the tube: each step's a-priori enclosure contains the sets
  the step starts from).  A zero pivot usually makes the rhs enclosure unbounded
  (a break-down), but [0, 0] / D = [0, 0] for D containing 0, so this does not rely
  on it; where the proof fails the run is cut back to that time and reported as a
  break-down naming the joint (:func:`apply_proof`).

The proof runs as the solver hook :class:`MassMatrixProof`, at the stage
``after_solve`` (:mod:`verified.driver.hooks`): once, on the whole run ``solve``
returns, because its cut and the pieces' record (``piece_results``, ``surviving``, the
reason's summary of the pieces) belong to the merged run, not to a chunk of a chunked
run or to an attempt of ``auto``.
"""
from __future__ import annotations

import itertools

import numpy as np

from verified.series.affine_taylor import affine_range
from verified.arith.interval import Interval
from verified.driver.hooks import Hook
from verified.solver import Solution

from ..errors import ModelError
from ..numeric import PIVOT_TOL


class MassMatrix:
    """What the M(q) > 0 checks of a chain need: a float model (centre checks, messages),
    the pivot graph (inputs q, then the parameters if any) and the parameter box."""

    def __init__(self, chain, cparams=None):
        self.chain = chain
        self.cparams = cparams
        if cparams is None:
            self.num = chain.numeric()
            self.graph = self.num.pivot_graph()
            self.pbox = None
        else:
            self.num = cparams.float_model()
            self.graph = cparams.pivot_graph()
            self.pbox = (cparams.lo, cparams.hi) if cparams.n else None
        self.n = chain.n


class MassMatrixProof(Hook):
    """The solver hook that proves M(q) > 0 on every box of the whole run
    (:func:`apply_proof` at the stage ``after_solve``; ``masses`` a :class:`MassMatrix`
    or a Chain)."""

    def __init__(self, masses):
        self.masses = masses

    def after_solve(self, solution) -> None:
        apply_proof(self.masses, solution)


def apply_proof(masses, sol: Solution) -> None:
    """Prove M(q) positive definite on every box of ``sol`` (a run of the chain behind
    ``masses``, a :class:`MassMatrix` or a Chain) and, where that fails, edit ``sol`` in
    place: cut back to the time of the first unproven box and made a break-down naming
    the joint, its pieces' outcomes and its ``surviving`` part brought in line."""
    summary = sol.pieces_summary()
    _prove_mass_matrix(masses, sol)
    _clip_failed_pieces(sol, summary)
    _prove_surviving(masses, sol)


def check_initial(masses, box: Interval):
    """Raise SingularMassMatrixError (naming the joints) if M is singular for every q
    (a constant zero pivot, found while tracing) or at the centre of an initial box
    (with uncertain parameters: at their midpoints)."""
    if not isinstance(masses, MassMatrix):  # a Chain
        masses = MassMatrix(masses)
    num = masses.num
    n = num.n
    mids = np.atleast_2d(box.mid())[:, :n]
    with np.errstate(divide="ignore", invalid="ignore"):
        D = np.asarray(num.mass_matrix_pivots(mids.T), dtype=float).reshape(n, -1)
    M = np.asarray(num.mass_matrix(mids.T), dtype=float).reshape(n, n, -1)
    tol = PIVOT_TOL * n * np.max(np.abs(np.diagonal(M, axis1=0, axis2=1)), axis=-1)
    for b in np.flatnonzero(~(D > tol).all(axis=0)):  # at most one raises, normally the first
        num.check_mass_matrix(mids[b], where=f"at q = [{', '.join(f'{v:.6g}' for v in mids[b])}] "
                                              "(centre of the initial box)")


_CHUNK_ROWS = 8192
_BISECTIONS = 6
_MAX_BISECTED = 64


def pivots_proven(graph, lo: np.ndarray, hi: np.ndarray, depth: int = _BISECTIONS) -> np.ndarray:
    """Which rows (boxes of q, shape (B, n)) have every pivot proven > 0: simulate()'s
    M(q) > 0 proof on boxes. ``graph``: the LDL^T pivots of M as a graph of q (and the
    parameters after q), e.g. ``chain.numeric().pivot_graph()``; ``lo``, ``hi``: (B, inputs)
    bounds; returns a (B,) bool array. Interval evaluation first, affine arithmetic
    where that does not prove a row. A box that
    fails is bisected along its widest component, up to ``depth`` times, so that
    interval overestimation alone does not fail it (only the first
    ``_MAX_BISECTED`` failing rows: the earliest failure is the one that counts)."""
    ok = np.zeros(lo.shape[0], dtype=bool)
    finite = np.isfinite(lo).all(axis=1) & np.isfinite(hi).all(axis=1)
    if finite.any():
        D = graph.eval_interval(Interval(lo[finite], hi[finite]))
        ok[finite] = np.all(D.lo > 0, axis=-1)
    retry = np.flatnonzero(~ok & finite)
    if retry.size:
        # affine arithmetic keeps the pivots' dependence on q (where an interval pivot
        # contains 0; docs/lab/code_notes.md), so a run verified with it is not cut back
        D = affine_range(graph, Interval(lo[retry], hi[retry]))
        ok[retry] = np.all(D.lo > 0, axis=-1)
    if depth == 0:
        return ok
    rows = np.flatnonzero(~ok & finite)[:_MAX_BISECTED]
    j = np.argmax(hi[rows] - lo[rows], axis=1)
    splittable = hi[rows, j] > lo[rows, j]  # a point box stays failed
    rows, j = rows[splittable], j[splittable]
    if rows.size == 0:
        return ok
    cut = 0.5 * (lo[rows, j] + hi[rows, j])
    lower_hi, upper_lo = hi[rows].copy(), lo[rows].copy()
    lower_hi[np.arange(rows.size), j] = cut
    upper_lo[np.arange(rows.size), j] = cut
    halves = pivots_proven(graph, np.concatenate([lo[rows], upper_lo]), np.concatenate([lower_hi, hi[rows]]), depth - 1)
    ok[rows] = halves[:rows.size] & halves[rows.size:]
    return ok


def _first_unproven(graph, pieces, n, pbox=None):
    """(index, q-box lo, q-box hi) of the first of ``pieces`` (Interval (B, >= n) each,
    in time order) with a box on which M is not proven positive definite, or None.
    ``pbox``: (lo, hi) of the parameters, appended to every q-box (the graph's inputs
    are q, then the parameters); the returned boxes include them."""
    los = [p.lo.reshape(-1, p.shape[-1])[:, :n] for p in pieces]
    his = [p.hi.reshape(-1, p.shape[-1])[:, :n] for p in pieces]
    if pbox is not None:
        los = [np.concatenate([a, np.broadcast_to(pbox[0], (a.shape[0], len(pbox[0])))], axis=1) for a in los]
        his = [np.concatenate([a, np.broadcast_to(pbox[1], (a.shape[0], len(pbox[1])))], axis=1) for a in his]
    start = 0
    while start < len(pieces):
        stop, rows = start + 1, los[start].shape[0]
        while stop < len(pieces) and rows + los[stop].shape[0] <= _CHUNK_ROWS:
            rows += los[stop].shape[0]
            stop += 1
        lo, hi = np.concatenate(los[start:stop]), np.concatenate(his[start:stop])
        ok = pivots_proven(graph, lo, hi)
        if not ok.all():
            i = int(np.flatnonzero(~ok)[0])
            owner = start + int(np.searchsorted(np.cumsum([x.shape[0] for x in los[start:stop]]), i, side="right"))
            return owner, lo[i], hi[i]
        start = stop
    return None


def _prove_mass_matrix(masses, sol: Solution):
    """Prove M(q) positive definite on every box of ``sol`` (and every parameter value
    in the parameter box); where that fails, cut the solution back to that time and
    make it a break-down that names the joint."""
    if not isinstance(masses, MassMatrix):  # a Chain
        masses = MassMatrix(masses)
    num, n, graph, chain = masses.num, masses.n, masses.graph, masses.chain
    # (time, boxes, the time in words): the initial sets, then each step's tube boxes
    # (a-priori enclosure over [t_j, t_j+1], which contains the sets the step started
    # from), and after a break-down at an output time the sets the failed step had
    pieces = [(float(sol.t[0]), sol.boxes[0], f"t = {float(sol.t[0]):.6g}")]
    pieces += [(float(sol.tube_t[j]), sol.tube[j], f"t in [{float(sol.tube_t[j]):.6g}, {float(sol.tube_t[j + 1]):.6g}]")
               for j in range(len(sol.tube))]
    if sol.status != "completed" and len(sol.t) > 1 and sol.t[-1] >= sol.t_reached:
        pieces.append((float(sol.t[-1]), sol.boxes[-1], f"t = {float(sol.t[-1]):.6g}"))
    found = _first_unproven(graph, [p[1] for p in pieces], n, masses.pbox)
    if found is None:
        return
    piece, lo, hi = found
    T, _, span = pieces[piece]
    names = chain.joint_names
    D = graph.eval_interval(Interval(lo, hi))
    k = int(np.flatnonzero(~(D.lo > 0))[0])
    box = ", ".join(f"{names[i]} in [{lo[i]:.6g}, {hi[i]:.6g}]" for i in range(n))
    if masses.pbox is not None:
        box += " and the parameter box"
    reason = (f"mass matrix M(q) not proven positive definite on the enclosure for {span}: the LDL^T "
              f"pivot of joint {names[k]!r} encloses [{float(D.lo[k]):.3g}, {float(D.hi[k]):.3g}] for {box}")
    try:
        num.check_mass_matrix(0.5 * (lo[:n] + hi[:n]), where="at the centre of that box")
    except ModelError as e:
        reason += f"; {e}"
    else:
        reason += _pivot_diagnosis(num, lo[:n], hi[:n], names, k)
    if sol.status == "completed" or T < sol.t_reached:
        _truncate(sol, T)
        reason = reason if not sol.reason else f"{reason} (the integration then stopped: {sol.reason})"
    else:
        reason = f"{sol.reason}; {reason}"
    sol.status, sol.reason = "breakdown", reason


#: configurations sampled in a box whose pivot proof failed, to tell the model's
#: singularity from the width of the set (the centre and corners come first)
_DIAGNOSIS_SAMPLES = 512
#: a sampled pivot below this fraction of M's largest diagonal entry counts as a (near)
#: singular configuration of the model (samples rarely hit the exact one); it lies
#: between a true singularity's pivots and a wide box's (docs/lab/code_notes.md)
_NEAR_SINGULAR = 1e-6


def _pivot_diagnosis(num, lo: np.ndarray, hi: np.ndarray, names, k: int) -> str:
    """Why the pivot proof failed on the q-box ``[lo, hi]``, in words: M(q) sampled in
    floats at the centre, the corners (up to 2^8) and random points of the box. A
    singular sample names the model (a configuration where M is singular); none means
    the interval pivot is too wide over a box this size: the set, not the model, and
    splitting it is what helps. (A diagnosis only: soundness does not rest on it.)"""
    rng = np.random.default_rng(0)
    n = lo.size
    corners = np.array(list(itertools.product(*zip(lo, hi)))[:256]) if n <= 8 else np.empty((0, n))
    Q = np.concatenate([[0.5 * (lo + hi)], corners,
                        lo + (hi - lo) * rng.random((_DIAGNOSIS_SAMPLES - 1 - len(corners), n))])
    with np.errstate(all="ignore"):
        D = np.asarray(num.mass_matrix_pivots(Q.T), dtype=float).reshape(n, -1)
        M = np.asarray(num.mass_matrix(Q.T), dtype=float).reshape(n, n, -1)
    scale = np.max(np.abs(np.diagonal(M, axis1=0, axis2=1)), axis=-1)
    ratio = np.min(D, axis=0) / np.where(scale > 0, scale, 1.0)
    worst = int(np.nanargmin(np.where(np.isnan(ratio), -np.inf, ratio)))
    widest = int(np.argmax(hi - lo))
    if not (ratio[worst] > _NEAR_SINGULAR):
        q = ", ".join(f"{v:.6g}" for v in Q[worst])
        return (f" (the model: M(q) is singular or nearly so at q = [{q}] inside that box, smallest LDL^T "
                f"pivot {np.min(D[:, worst]):.3g}: do the links joint {names[k]!r} moves have inertia about "
                "its axis? Keep the box away from that configuration)")
    return (f" (the set, not the model: M(q) is positive definite at the centre and at {Q.shape[0] - 1} sampled "
            f"points of that box (smallest pivot {np.min(D):.3g}), but the box is {hi[widest] - lo[widest]:.3g} "
            f"wide in {names[widest]!r} and the interval pivot over it is too wide to exclude 0; what helps: "
            "split the initial box (subdivision=, or [solver] subdivision in a scene) into pieces, a smaller "
            "box, or second-order sets (set_order=2, set_step='composition'))")


def _truncate(sol: Solution, T: float):
    """Keep only what ``sol`` verified up to time ``T``."""
    keep = np.flatnonzero(sol.t <= T)
    sol.t = sol.t[keep]
    sol.boxes = [sol.boxes[i] for i in keep]
    if sol.views:
        sol.views = [sol.views[i] if i < len(sol.views) else None for i in keep]
    sol.hull = sol.hull[keep]
    steps = int(np.sum(sol.tube_t[1:] <= T))
    sol.tube = sol.tube[:steps]
    if sol.tube_views:
        sol.tube_views = sol.tube_views[:steps]
    sol.tube_t = sol.tube_t[:steps + 1]
    sol.tube_hull = sol.tube_hull[:steps]
    sol.t_reached = T
    rec = sol.consistency
    if rec is not None:
        m = np.asarray(rec.ra_t) <= T
        rec.ra_t, rec.ra = np.asarray(rec.ra_t)[m], np.asarray(rec.ra)[m]
        if rec.h_h.shape[:1] == m.shape:
            rec.h_h = rec.h_h[m]
        if rec.h_v.shape[:1] == m.shape:
            rec.h_v = rec.h_v[m]
        rec.tests = [r for r in rec.tests if r.t <= T]


def _clip_failed_pieces(sol: Solution, summary: str):
    """After the M(q) > 0 proof (which may cut ``sol`` back): the pieces that broke down
    are verified up to its ``t_reached`` at most (which of them the proof failed on is
    not known here); without a surviving part the others share the run's outcome (the
    pieces that went on are proven on their own, ``sol.surviving``)."""
    T = float(sol.t_reached)
    changed = False
    for p in sol.piece_results or ():
        if p.failed and p.t_reached > T:
            p.t_reached, changed = T, True
        elif not p.failed and sol.surviving is None:
            p.status, p.t_reached, p.reason = sol.status, T, sol.reason
    after = sol.pieces_summary()
    if changed and summary and after and summary in sol.reason:
        sol.reason = sol.reason.replace(summary, after, 1)


def _prove_surviving(masses, sol: Solution):
    """M(q) > 0 on the enclosures of the pieces that went on after others broke down
    (``sol.surviving``, :func:`_prove_mass_matrix`). Where that fails, those pieces
    break down too, at the time it names, and ``sol`` keeps no surviving part."""
    surv = sol.surviving
    if surv is None:
        return
    _prove_mass_matrix(masses, surv)
    if surv.status != "breakdown":
        return
    before = sol.pieces_summary()
    for p in sol.piece_results or ():
        if not p.failed:
            p.status, p.t_reached, p.reason = "breakdown", float(surv.t_reached), surv.reason
    sol.surviving = None
    after = sol.pieces_summary()
    if after and before and before in sol.reason:
        sol.reason = sol.reason.replace(before, after, 1)
    elif after:
        sol.reason = after

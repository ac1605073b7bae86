"""Working to prove ``Auto(spec=...)``: where the tube leaves the bounds, which pieces and
steps are to blame, and the rounds of splitting or narrower steps that try to close the gap
(:func:`_prove_spec`); sampled trajectories that refute a spec (:func:`sampled_violation`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from verified.driver.hooks import Hook
from verified.arith.interval import Interval, concatenate
from verified.methods import Auto
from verified.driver.solution import Solution
from verified.auto.ladder import _ladder, _rows, _summary, merge_parts
from verified.auto.splitting import split_pieces


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
    from verified.spec import FALSE, check_tube, describe

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
    refine = _Refinement(solve, ode, graph, t_span, method, kw, lo, hi, text, log,
                         sampled=None if found is None else found[0])
    groups, rounds = refine.run(_Group(pieces, piece_params, kw.get("h_max"), sol, ends, check.worst))
    result = refine.merged(groups, np.asarray(sol.t, float))
    check = check_tube(result, lo, hi, t0, t1, names)
    check.sampled = refine.sampled
    return _with_spec(result, check, log, rounds)


class _Refinement:
    """The rounds of :func:`_prove_spec`: the groups of pieces whose tube leaves the
    bounds ``lo``, ``hi`` are split (:meth:`_split`) or run with shorter steps
    (:meth:`_shorter_steps`), each refinement kept where it cuts the excess
    (:meth:`_judge`). ``log`` (``method_log``) receives every run's records."""

    def __init__(self, solve, ode, graph, t_span, method: Auto, kw: dict, lo, hi, text: str, log: list, sampled):
        self.solve, self.ode, self.graph, self.t_span, self.method, self.kw = solve, ode, graph, t_span, method, kw
        self.lo, self.hi, self.text, self.log, self.sampled = lo, hi, text, log, sampled
        self.t0, self.t1 = float(t_span[0]), float(t_span[1])
        self.n = graph.n_inputs
        self.names = tuple(graph.input_names[:self.n])
        self.user_hooks = list(kw.get("hooks") or ())
        self.final: list[_Group] = []   # groups whose tube keeps inside (split off a group that did not)

    def _run(self, bx, prm, h, why) -> _Group:
        """The ladder on pieces ``bx`` with ``h_max = h``, its log records marked ``why``."""
        rec = _StepEnds(self.lo, self.hi, self.n)
        s, pcs, pprm = _ladder(self.solve, self.ode, self.graph, bx, prm, self.t_span,
                               **{**self.kw, "hooks": self.user_hooks + [rec], "h_max": h})
        entries = list(s.method_log or ())
        if entries:
            entries[0] = {**entries[0], "spec": why}
        self.log.extend(entries)
        ends = rec.worst if rec.steps else np.nan
        return _Group(pcs, pprm, h, s, ends, _group_excess(s, self.lo, self.hi, self.t0, self.t1))

    def run(self, first: _Group):
        """Refine from ``first`` for up to :data:`SPEC_ROUNDS` rounds: (the groups, rounds)."""
        active = [first]
        rounds, stop = 0, False
        while rounds < SPEC_ROUNDS and not stop:
            todo = [g for g in active if g.excess > 0 and _action(g) is not None]
            if not todo:
                break
            rounds += 1
            nxt = [g for g in active if not (g.excess > 0 and _action(g) is not None)]
            total = sum(g.boxes.shape[0] for g in active) + sum(g.boxes.shape[0] for g in self.final)
            for g in todo:
                act = _action(g)
                if act == "split":
                    tried = self._split(g, rounds, total)
                    if tried is None:
                        nxt.append(g)
                        continue
                    parent, child, added = tried
                    total += added
                else:
                    parent, child = g, self._shorter_steps(g, rounds)
                if child.sol.status in ("stopped", "interrupted"):
                    stop = True
                nxt.append(self._judge(parent, child, act))
                if stop:
                    nxt += [h for h in todo if h is not g and h not in nxt]
                    break
            active = nxt
        return self.final + active, rounds

    def _split(self, g: _Group, rounds: int, total: int):
        """Split the pieces of ``g`` whose tube leaves the bounds (as often at once as the
        excess asks, within ``max_pieces`` with ``total`` pieces now) and run them:
        (the group they came from, the run, pieces added); None where they cannot be
        split (``g`` then notes it tried)."""
        lo, hi, t0, t1 = self.lo, self.hi, self.t0, self.t1
        k = g.boxes.shape[0]
        pe = _piece_excess(g.sol, k, lo, hi, g.boxes)
        bad = np.ones(k, bool) if pe is None else pe > 0
        idx = np.flatnonzero(bad)
        parts, part_params = split_pieces(self.graph, g.boxes[idx], _rows(g.params, idx), t1 - t0)
        for _ in range(_spec_splits(g.excess, self.sampled) - 1):   # (as often at once as the excess asks)
            more, more_params = split_pieces(self.graph, parts, part_params, t1 - t0)
            if more.shape[0] == parts.shape[0] or total - idx.size + more.shape[0] > self.method.max_pieces:
                break
            parts, part_params = more, more_params
        if parts.shape[0] == idx.size or total - idx.size + parts.shape[0] > self.method.max_pieces:
            g.tried += ("split",)
            return None
        parent = g
        if not bad.all():   # (the pieces whose tube keeps inside stay as they are)
            good = _restrict(g.sol, ~bad)
            self.final.append(_Group(g.boxes[np.flatnonzero(~bad)], _rows(g.params, np.flatnonzero(~bad)),
                                     g.h_max, good, g.ends, _group_excess(good, lo, hi, t0, t1)))
            part = _restrict(g.sol, bad)
            parent = _Group(g.boxes[idx], _rows(g.params, idx), g.h_max, part, g.ends,
                            _group_excess(part, lo, hi, t0, t1), g.tried)
        why = (f"spec round {rounds}: {self.text} exceeded by {parent.excess:.3g}; {idx.size} of {k} piece(s) "
               f"split into {parts.shape[0]}")
        return parent, self._run(parts, part_params, g.h_max, why), parts.shape[0] - idx.size

    def _shorter_steps(self, g: _Group, rounds: int) -> _Group:
        """``g``'s pieces again with steps shorter than the longest step whose tube left
        the bounds (:func:`_step_share` of it)."""
        from verified.spec import tube_excess

        dt = np.diff(np.asarray(g.sol.tube_t, float))
        per = np.array([float(np.max(tube_excess(b, self.lo, self.hi))) for b in g.sol.tube])
        h_long = float(np.max(dt[per > 0])) if np.any(per > 0) else float(np.max(dt))
        h = _step_share(g) * h_long
        if g.h_max is not None:
            h = min(h, float(g.h_max))
        why = (f"spec round {rounds}: {self.text} exceeded by {g.excess:.3g}; h_max {h:.3g} "
               f"(offending steps up to {h_long:.3g})")
        return self._run(g.boxes, g.params, h, why)

    def _judge(self, parent: _Group, child: _Group, act: str) -> _Group:
        """The child where it cut the excess by :data:`SPEC_GAIN` (or removed it), else
        the parent, noting that ``act`` was tried on it."""
        if child.excess <= 0 or (child.sol.status == "completed"
                                 and child.excess <= (1 - SPEC_GAIN) * parent.excess):
            return child
        self.log[-1]["next"] = f"spec: {act} did not cut the excess ({parent.excess:.3g} -> {child.excess:.3g})"
        if not np.isfinite(parent.ends) and np.isfinite(child.ends) and act == "step":
            parent.ends = child.ends
        parent.tried += (act,)
        return parent

    def merged(self, groups, outs):
        """One Solution of ``groups`` (output times ``outs``)."""
        if len(groups) == 1:
            result = groups[0].sol
        else:
            result = merge_parts([g.sol for g in groups], [g.boxes.shape[0] for g in groups],
                                 concatenate([g.boxes for g in groups], axis=0), outs, self.t0, self.names)
        result.stats["auto_pieces"] = int(sum(g.boxes.shape[0] for g in groups))
        return result


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

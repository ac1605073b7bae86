"""Carry a passive mechanical system on past a break-down with boxes from its energy bound
(issue 43, item 3).

For ``x = (q, qd)`` with energy ``H = qd^T M(q) qd / 2 + V(q)`` that never rises above
``hmax`` along the solutions (a passive system: no input power, damping >= 0), and
constants ``c_i >= (M(q)^-1)_ii`` valid for every ``q``, every true state satisfies

    |qd_i| <= u_i = sqrt(2 (hmax - min V(Q)) c_i)          (q in Q)

(for fixed ``q``, ``min {qd^T M qd : qd_i = v} = v^2 / (M^-1)_ii``). So after the
Taylor sets of a chaotic run break down at ``t_b`` with the states in a box ``X_b``,
the positions stay in ``Q_b + [-u, u] (t - t_b)`` and the rates in ``[-u, u]``: a crude
enclosure, but finite and sound at every later time. :func:`continue_in_shell` appends
it to a broken-down :class:`~verified.driver.solution.Solution`, one step per output interval.

Proof of a step ``[t_k, t_k+1]`` (length ``h``), positions ``Q_k`` at ``t_k``: the
whole continuation first finds ``u`` with ``u >= u(Q_b + [-u, u] (T - t_b))`` (an
a-priori box: a trajectory leaving it would have had a larger speed than ``u``
somewhere inside it, a contradiction). The step's positions lie in
``Q_k + [-u, u] h`` (inside that box), so the speed bound over that smaller box,
``u_k <= u``, holds on the step, and ``Q_k+1 = Q_k + [-u_k, u_k] h``. Where the shell's
interval bound of ``M(q)^-1`` is finite on the step's positions
(:meth:`verified.consistency.contractor.EnergyShell.ellipsoid_bound`, narrow boxes just after the
break-down) the smaller of the two is used.

``min V`` over a box is a branch-and-bound lower bound of interval evaluations. A
component declared periodic (``periods[i] = P``: ``V`` and ``M`` unchanged by
``q_i -> q_i + P``, a revolute joint) is evaluated over one period once the box is wider
than that.

The verified side knows nothing of robots: ``V``, ``M`` come as graphs (an
:class:`~verified.consistency.contractor.EnergyShell`), and ``hmax``, ``c`` and the periods are the
caller's claims (``mbs.shell_bounds.inverse_mass_bounds`` proves ``c`` for a chain).
What can be checked is: ``c_i`` against ``(M^-1)_ii`` in floats at the break-down box's
centre, the periods of ``V`` at sample points, ``hmax`` finite.
"""
from __future__ import annotations

import dataclasses
import itertools

import numpy as np

from verified.arith import interval as iv
from verified.consistency.contractor import EnergyShell
from verified.graph.evaluate import eval_interval, jacobian_interval
from verified.arith.interval import Interval
from verified.driver.solution import Solution

__all__ = ["continue_in_shell", "min_value", "speed_bound"]

_EVALS = 16384  # interval evaluations of V per lower bound (branch and bound)
_APRIORI_TRIES = 40


def min_value(V, Q: Interval, params=None, *, periods=None, evals: int = _EVALS, memo: dict | None = None) -> float:
    """A lower bound of ``V(q)`` (a one-output graph) over the box ``Q`` (n_q,): branch
    and bound on interval evaluations, about ``evals`` of them, always splitting the box
    with the lowest bound along the component with the largest ``width * |dV/dq_i|``
    (interval derivative; the widest where that is not finite). Components with a
    period ``P`` and a width of at least ``P`` are evaluated over ``[0, P]``. ``memo``:
    a dict that keeps the results by box (a run's later steps ask for the same full
    periods again)."""
    lo, hi = _one_period(np.asarray(Q.lo, float), np.asarray(Q.hi, float), periods)
    key = (lo.tobytes(), hi.tobytes(), evals)
    if memo is not None and key in memo:
        return memo[key]
    lo, hi = lo[None], hi[None]
    lb, smear = _bound(V, lo, hi, params)
    used = 1
    best = float(V.eval_float(0.5 * (lo + hi), params)[0, 0])
    while used < evals:
        k = min(64, lo.shape[0], max(1, (evals - used) // 2))
        order = np.argsort(lb)
        pick, rest = order[:k], order[k:]
        if not lb[pick[0]] < best - 1e-9 * max(1.0, abs(best)):
            break  # proven within rounding of the best sampled value
        plo, phi = lo[pick], hi[pick]
        j = np.argmax(smear[pick], axis=1)
        rows = np.arange(k)
        cut = 0.5 * (plo[rows, j] + phi[rows, j])
        alo, ahi, blo, bhi = plo.copy(), phi.copy(), plo.copy(), phi.copy()
        ahi[rows, j] = cut
        blo[rows, j] = cut
        nlo, nhi = np.concatenate([alo, blo]), np.concatenate([ahi, bhi])
        nlb, nsmear = _bound(V, nlo, nhi, params)
        used += 2 * k
        best = min(best, float(np.min(V.eval_float(0.5 * (nlo + nhi), params)[:, 0])))
        lo, hi = np.concatenate([lo[rest], nlo]), np.concatenate([hi[rest], nhi])
        lb, smear = np.concatenate([lb[rest], nlb]), np.concatenate([smear[rest], nsmear])
    out = float(np.min(lb))
    if memo is not None:
        memo[key] = out
    return out


def _bound(V, lo, hi, params):
    """(lower bounds (B,), split scores (B, n)) of V over the boxes."""
    X = Interval(lo, hi)
    with np.errstate(all="ignore"):
        r = eval_interval(V, X, params)[..., 0]
        J = jacobian_interval(V, X, params)[..., 0, :]
        mag = np.maximum(np.abs(np.asarray(J.lo, float)), np.abs(np.asarray(J.hi, float)))
        smear = np.where(np.isfinite(mag), mag * (hi - lo), np.inf)
        smear = np.where(np.isnan(smear), np.inf, smear)
    smear = np.where(np.isinf(smear).any(axis=1, keepdims=True), hi - lo, smear)  # (the widest)
    out = np.asarray(r.lo, float)
    return np.where(np.isnan(out), -np.inf, out), smear


def _one_period(lo, hi, periods):
    if periods is None:
        return lo, hi
    P = np.asarray(periods, float)
    wide = np.isfinite(P) & (hi - lo >= P)
    return np.where(wide, 0.0, lo), np.where(wide, P, hi)


def speed_bound(shell: EnergyShell, hmax: float, inv_mass_diag, Q: Interval, params=None, *,
                periods=None, evals: int = _EVALS, memo: dict | None = None) -> np.ndarray:
    """Upper bounds (n_q,) of ``|qd_i|`` over the states with ``H <= hmax`` and ``q`` in
    ``Q``: ``sqrt(2 (hmax - min V(Q)) c_i)`` (rounded up), and the shell's interval
    ellipsoid bound where that is finite and smaller."""
    c = np.asarray(inv_mass_diag, float)
    vlow = min_value(shell.V_graph, Q, params, periods=periods, evals=evals, memo=memo)
    if not np.isfinite(vlow):
        return np.full(shell.nq, np.inf)
    slack = max(float((iv.point(hmax) - iv.point(vlow)).hi), 0.0)
    u = np.asarray(iv.sqrt(iv.point(2.0 * slack) * Interval(c, c)).hi, float) if slack > 0 else np.zeros_like(c)
    u = np.where(np.isfinite(c), u, np.inf)
    lo, hi = _one_period(np.asarray(Q.lo, float), np.asarray(Q.hi, float), periods)
    box = Interval(np.r_[lo, np.zeros(shell.nq)], np.r_[hi, np.zeros(shell.nq)]).reshape(1, -1)
    with np.errstate(all="ignore"):
        e = shell.ellipsoid_bound(box, hmax, params, pieces=256)[0]
    e = np.where(e < 0, 0.0, e)  # (no state of the shell in the box: speed 0 is as good as any)
    return np.minimum(u, e)


def _check_claims(shell, hmax, c, X, params, periods):
    nq = shell.nq
    if not np.isfinite(hmax):
        raise ValueError(f"hmax must be a finite number, got {hmax!r}")
    if c.shape != (nq,) or np.any(np.isnan(c)) or np.any(c <= 0):
        raise ValueError(f"inv_mass_diag must be {nq} positive numbers (inf: no bound), got {c!r}")
    q = np.asarray(X.mid(), float)[:nq]
    p = None if params is None else np.asarray(Interval(params).mid() if not isinstance(params, Interval)
                                              else params.mid(), float).reshape(-1)
    M = np.asarray(shell.M_graph.eval_float(q[None], p), float).reshape(nq, nq)
    d = np.diag(np.linalg.inv(0.5 * (M + M.T)))
    if np.any(d > c * (1 + 1e-9)):
        i = int(np.argmax(d / c))
        raise ValueError(f"inv_mass_diag[{i}] = {c[i]:g} is below (M(q)^-1)_{i}{i} = {d[i]:g} at q = {q.tolist()}: "
                         "not a bound for every q")
    if periods is not None:
        P = np.asarray(periods, float)
        if P.shape != (nq,) or np.any(P <= 0):
            raise ValueError(f"periods must be {nq} positive numbers (inf: not periodic), got {periods!r}")
        rng = np.random.default_rng(0)
        Qs = q + rng.uniform(-3.0, 3.0, (8, nq))
        for i in np.flatnonzero(np.isfinite(P)):
            shifted = Qs.copy()
            shifted[:, i] += P[i]
            a, b = shell.V_graph.eval_float(Qs, p)[:, 0], shell.V_graph.eval_float(shifted, p)[:, 0]
            if not np.allclose(a, b, rtol=1e-9, atol=1e-9 * max(1.0, float(np.max(np.abs(a))))):
                raise ValueError(f"V is not periodic in q{i + 1} with period {P[i]:g}")


def continue_in_shell(sol: Solution, shell: EnergyShell, hmax: float, inv_mass_diag, t_eval, t_end: float, *,
                      start: Interval | None = None, params=None, periods=None, evals: int = _EVALS) -> Solution:
    """``sol`` (a run that broke down before ``t_end``) carried on to ``t_end`` with boxes
    from the energy bound (module docstring): a new Solution whose outputs at the
    ``t_eval`` times after ``sol.t_reached`` and tube steps (one per output interval)
    come from the shell; ``status="completed"``, ``reason`` says where the sets gave up
    and the shell took over, ``stats["shell_from"]`` that time and
    ``stats["shell_speed"]`` the final speed bounds. ``sol`` itself is unchanged.

    The states must be ``(q, qd)`` exactly (``2 n_q``); ``start``: the box the run
    started from, used when ``sol`` has no step; ``hmax``, ``inv_mass_diag`` (``c``)
    and ``periods`` are the caller's claims (checked where possible, see the module
    docstring). Returns ``sol`` unchanged when it did not break down. Raises
    ValueError when no finite speed bound can be proven (an ``inf`` in ``c``, ``V``
    unbounded below on the reachable positions)."""
    if sol.status != "breakdown":
        return sol
    nq = shell.nq
    if sol.tube:
        X = iv.hull(sol.tube[-1], axis=0) if sol.tube[-1].ndim == 2 else sol.tube[-1]
    elif start is not None:
        X = iv.hull(start, axis=0) if start.ndim == 2 else start
    else:
        raise ValueError("the run has no step; pass the initial box as start=")
    n = X.shape[-1]
    if n != 2 * nq:
        raise ValueError(f"the shell's boxes need the states (q, qd) only: {2 * nq} states, the run has {n}")
    c = np.asarray(inv_mass_diag, float)
    hmax = float(hmax)
    _check_claims(shell, hmax, c, X, params, periods)
    if not np.all(np.isfinite(c)):
        raise ValueError("no speed bound: inv_mass_diag has no finite bound for "
                         f"q{', q'.join(str(i + 1) for i in np.flatnonzero(~np.isfinite(c)))}")
    # the states at tb lie in X: the last step's tube box (it ends at tb), or the start box
    tb, T = float(sol.tube_t[-1]) if sol.tube else float(sol.t_reached), float(t_end)
    Qb = Interval(np.asarray(X.lo, float)[:nq], np.asarray(X.hi, float)[:nq])
    span = iv.point(T) - iv.point(tb)
    memo = {}

    def grown(Q, u, dt):
        return Q + Interval(-np.ones(nq), np.ones(nq)) * (Interval(u, u) * dt)

    # the a-priori box over [tb, T]
    cand = speed_bound(shell, hmax, c, Qb, params, periods=periods, evals=evals, memo=memo)
    for _ in range(_APRIORI_TRIES):
        w = speed_bound(shell, hmax, c, grown(Qb, cand, span), params, periods=periods, evals=evals, memo=memo)
        if np.all(w <= cand):
            u_all = w  # (speeds <= w on the box, so the positions stay in the smaller grown(Qb, w, span))
            break
        cand = 2.0 * np.maximum(w, cand)
    else:
        raise ValueError(f"no a-priori speed bound over [{tb:g}, {T:g}]: the bound grows with the positions "
                         "(is V bounded below?)")
    t_eval = [T] if t_eval is None else t_eval
    times = np.asarray([t for t in np.asarray(t_eval, float) if tb < t <= T], float)
    edges = np.unique(np.r_[tb, times, T])
    Q = Qb
    new_t, new_boxes, new_tube = [], [], []
    u_k = u_all
    for a, b in itertools.pairwise(edges):
        h = iv.point(b) - iv.point(a)
        Qstep = grown(Q, u_all, h)
        u_k = np.minimum(u_all, speed_bound(shell, hmax, c, Qstep, params, periods=periods, evals=evals, memo=memo))
        Qstep = grown(Q, u_k, h)
        V = Interval(-u_k, u_k)
        new_tube.append(iv.concatenate([Qstep, V]).reshape(1, -1))
        Q = grown(Q, u_k, h)
        if b in times:
            new_t.append(b)
            new_boxes.append(iv.concatenate([Q, V]).reshape(1, -1))
    out = dataclasses.replace(sol)
    out.t = np.r_[np.asarray(sol.t, float), new_t]
    out.boxes = list(sol.boxes) + new_boxes
    out.hull = iv.stack_hulls(out.boxes)
    out.tube_t = np.r_[np.asarray(sol.tube_t, float) if len(sol.tube_t) else [tb], edges[1:]]
    out.tube = list(sol.tube) + new_tube
    out.tube_hull = iv.stack_hulls(out.tube)
    if sol.views is not None and len(sol.views) == len(sol.t):
        out.views = list(sol.views) + [None] * len(new_boxes)
    if sol.tube_views is not None and len(sol.tube_views) == len(sol.tube):
        out.tube_views = list(sol.tube_views) + [None] * len(new_tube)
    out.t_reached = T
    out.status = "completed"
    out.reason = (f"the sets broke down at t = {tb:g} ({sol.reason}); from there to t = {T:g} the enclosure is "
                  f"the energy shell's boxes (|qd_i| <= {', '.join(f'{v:.3g}' for v in u_k)})")
    out.stats = dict(sol.stats, shell_from=tb, shell_speed=[float(v) for v in u_k])
    out.method = (sol.method + "; " if sol.method else "") + f"energy-shell boxes from t = {tb:g}"
    return out

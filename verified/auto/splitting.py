"""Splitting a failed piece: its box bisected along the widest components
(:func:`split_boxes`), or, with uncertain parameters, along the states and parameters whose
ends move the states most (:func:`influences`, :func:`split_pieces`).
"""

from __future__ import annotations

import numpy as np

from verified.arith.interval import Interval

__all__ = ["split_boxes", "split_pieces", "influences", "SPLIT_DIMS", "SPLIT_DIMS_AGAIN"]


#: at most this many components are bisected at once when a piece is split (a piece of a
#: 7-state box bisected in every component would become 128)
SPLIT_DIMS = 3
#: at most this many when the piece itself came from a split (``auto``'s ladder): where
#: the first split gained, its pieces need a little less width, not 2^3 times fewer
#: pieces. The 3-link arm +- 0.01 to T = 2 went 1 -> 8 -> 32 pieces at 0.64x the CPU of
#: 1 -> 8 -> 64, its enclosure 4 % wider (ratio 1.16 against 1.12); with one component
#: (16 pieces) 0.43x, but 1.71 (docs/lab/auto.md)
SPLIT_DIMS_AGAIN = 2


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


def split_pieces(graph, boxes: Interval, params, span: float, max_dims: int = SPLIT_DIMS):
    """The failed pieces ``boxes`` (B, n) with their parameters ``params`` ((p,) for all,
    (B, p) rows, or None), split: ``(parts, part_params)``. Without uncertain parameters,
    :func:`split_boxes` and the rows repeated. With them, each piece is bisected along the
    components -- states and parameters alike -- that move its states most over ``span``
    (:func:`influences`, at least :data:`INFLUENCE_SHARE` of the most, at most
    ``max_dims`` of them; the widest parameter with the states' choice where the
    integration fails), and every part gets its own parameter row: ``part_params`` (parts,
    p). Every state and parameter of a piece lies in one of its parts (the cut is shared
    by both halves), so the parts cover the pieces."""
    wide = params is not None and isinstance(params, Interval) and bool(np.any(params.width() > 0))
    if not wide:
        parts = split_boxes(boxes, max_dims)
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
            dims = sorted(_widest_dims(lo, hi, max_dims))[:max_dims - 1] + [n + int(np.argmax(rel))]
        else:
            order = np.argsort(-infl, kind="stable")
            dims = [int(j) for j in order[:max_dims] if infl[j] > 0 and infl[j] >= INFLUENCE_SHARE * infl[order[0]]]
        cuts = _bisect(np.concatenate([lo, plo]), np.concatenate([hi, phi]), dims)
        out_x += [(a[:n], c[:n]) for a, c in cuts]
        out_p += [(a[n:], c[n:]) for a, c in cuts]
    return (Interval(np.array([a for a, _ in out_x]), np.array([c for _, c in out_x])),
            Interval(np.array([a for a, _ in out_p]), np.array([c for _, c in out_p])))


def _repeat_rows(params, times: int):
    if params is None or not isinstance(params, Interval) or params.ndim != 2:
        return params
    idx = np.repeat(np.arange(params.shape[0]), times)
    return params[idx]

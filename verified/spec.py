"""Specifications that ``method=Auto(spec=...)`` works to prove: bounds on states that
must hold at every time of the run, ``lo <= x_i(t) <= hi`` for all t in [t0, t1].

    from verified.methods import Auto
    from verified.spec import Bounds
    sol = solve(g, x0, (0, 7), method=Auto(spec=Bounds({"x1": (None, 2.75)})))
    sol.spec_proven            # True only from the verified tube over [t0, t1]
    sol.spec_check.detail      # "x1 <= 2.75: proven (max over the tube 2.7358)"

A state is named as the graph names its inputs (``Solution.state_names``) or by its
index; ``None`` is no bound on that side. A bound is closed (``<=``); a strict spec
(``y < 2.75``) is proven as well when the tube's maximum is below the bound, which
:attr:`SpecCheck.worst` (the largest excess of the tube over a bound, < 0 inside)
shows.

**Proven** is read only from the verified enclosure of a completed run: the tube
(``Solution.tube``: boxes that enclose every solution over each step, so every time in
[t0, t1] and not only the output times) lies inside the bounds (:func:`check_tube`).
**False** is a float finding, not a proof: a sampled trajectory (scipy's DOP853 from
points of the initial set, :func:`verified.auto.spec_proof.sampled_violation`) leaves the bounds
by more than the sampler's error. Anything else is **not proven**.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np

__all__ = ["Bounds", "SpecCheck", "as_spec", "check_tube", "tube_excess"]

PROVEN, NOT_PROVEN, FALSE = "proven", "not proven", "false"


def _bound(key, side: str, v):
    if v is None:
        return None
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (numbers.Real, np.floating, np.integer)):
        raise ValueError(f"spec: {side} bound of {key!r} must be a number or None, got {v!r}")
    v = float(v)
    if math.isnan(v):
        raise ValueError(f"spec: {side} bound of {key!r} is NaN")
    return v


@dataclass(frozen=True, init=False)
class Bounds:
    """Bounds on states over the whole run: ``Bounds({"y": (None, 2.75), 0: (0, None)})``
    (a state by name or index, ``(lo, hi)`` with None for no bound), or by keywords
    ``Bounds(y=(None, 2.75))``. Checked here (a one-line ValueError): a pair of numbers
    or None, no NaN, ``lo <= hi``, at least one bound per state; the names and indices
    against the ODE when the run starts (:meth:`resolve`)."""

    items: tuple  # ((key, lo or None, hi or None), ...): key a state name (str) or index (int)

    def __init__(self, bounds=None, /, **named):
        if bounds is None:
            bounds = {}
        if isinstance(bounds, Bounds):
            bounds = {k: (lo, hi) for k, lo, hi in bounds.items}
        if not hasattr(bounds, "items") or not callable(bounds.items):
            raise ValueError(f"spec: Bounds takes a dict {{state: (lo, hi)}}, got {bounds!r}")
        items = []
        for key, pair in list(bounds.items()) + list(named.items()):
            if isinstance(key, (bool, np.bool_)) or not isinstance(key, (str, numbers.Integral, np.integer)) \
                    or (not isinstance(key, str) and key < 0):
                raise ValueError(f"spec: a state is a name or an index >= 0, got {key!r}")
            key = key if isinstance(key, str) else int(key)
            if not isinstance(pair, (tuple, list)) or len(pair) != 2:
                raise ValueError(f"spec: the bounds of {key!r} must be a pair (lo, hi), None for no bound; "
                                 f"got {pair!r}")
            lo, hi = _bound(key, "lower", pair[0]), _bound(key, "upper", pair[1])
            if (lo is None or lo == -math.inf) and (hi is None or hi == math.inf):
                raise ValueError(f"spec: {key!r} has no bound (lo and hi are both None or infinite)")
            if lo is not None and hi is not None and lo > hi:
                raise ValueError(f"spec: the bounds of {key!r} are empty: lo = {lo:g} > hi = {hi:g}")
            items.append((key, lo, hi))
        if not items:
            raise ValueError("spec: Bounds needs at least one state with a bound")
        object.__setattr__(self, "items", tuple(items))

    def __repr__(self):
        return "Bounds({" + ", ".join(f"{k!r}: ({lo!r}, {hi!r})" for k, lo, hi in self.items) + "})"

    def resolve(self, names) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi), each (n,) with -inf / inf where a state has no bound, for the
        states ``names`` (the ODE's, in order); a one-line ValueError for an unknown
        name, an index out of range or a state given twice."""
        names = tuple(names)
        n = len(names)
        lo, hi = np.full(n, -np.inf), np.full(n, np.inf)
        seen = set()
        for key, a, b in self.items:
            if isinstance(key, str):
                if key not in names:
                    raise ValueError(f"spec: unknown state {key!r} (states: {', '.join(names)})")
                i = names.index(key)
            else:
                if key >= n:
                    raise ValueError(f"spec: state index {key} out of range ({n} states: {', '.join(names)})")
                i = key
            if i in seen:
                raise ValueError(f"spec: state {names[i]!r} is given twice")
            seen.add(i)
            lo[i] = -np.inf if a is None else a
            hi[i] = np.inf if b is None else b
        return lo, hi


def as_spec(spec):
    """A :class:`Bounds` from a Bounds or a dict (None stays None)."""
    if spec is None or isinstance(spec, Bounds):
        return spec
    if isinstance(spec, dict):
        return Bounds(spec)
    raise ValueError(f"spec must be None, a verified.spec.Bounds or a dict {{state: (lo, hi)}}, "
                     f"got {type(spec).__name__}")


def describe(lo: np.ndarray, hi: np.ndarray, names) -> str:
    """``"x1 <= 2.75, 0 <= x3"``: the resolved bounds in words."""
    words = []
    for i, name in enumerate(names):
        a, b = lo[i], hi[i]
        if np.isfinite(a) and np.isfinite(b):
            words.append(f"{a:g} <= {name} <= {b:g}")
        elif np.isfinite(b):
            words.append(f"{name} <= {b:g}")
        elif np.isfinite(a):
            words.append(f"{name} >= {a:g}")
    return ", ".join(words)


def tube_excess(boxes, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Per box of ``boxes`` (Interval (B, n)): how far it reaches out of the bounds,
    the largest over the states of ``box.hi - hi`` and ``lo - box.lo`` (< 0: inside
    with that margin; +inf where a bound is NaN or the box is not finite)."""
    blo, bhi = np.asarray(boxes.lo, float), np.asarray(boxes.hi, float)
    with np.errstate(invalid="ignore"):
        e = np.maximum(bhi - hi, lo - blo)
    e = np.where(np.isnan(e), np.inf, e)
    return e.max(axis=-1)


@dataclass
class SpecCheck:
    """The spec's verdict on a run (``Solution.spec_check``).

    status : "proven" (the verified tube over [t0, t1] lies in the bounds), "false" (a
        sampled float trajectory leaves them) or "not proven"
    worst : the largest excess of the tube over a bound (< 0: inside, by that margin;
        over the part verified when the run did not complete)
    where : the state, the side and the time span of the worst step
    detail : one line: the spec, the verdict and why
    sampled : the largest excess of the sampled trajectories (float; None: not sampled)
    witness : for "false": (t, state values) of a sampled point outside
    """

    status: str
    worst: float
    where: str
    detail: str
    sampled: float | None = None
    witness: tuple | None = None

    @property
    def proven(self) -> bool:
        return self.status == PROVEN


def check_tube(sol, lo: np.ndarray, hi: np.ndarray, t0: float, t1: float, names) -> SpecCheck:
    """The spec ``lo <= x(t) <= hi`` on ``sol``'s tube: proven when the run completed,
    its steps cover [t0, t1] without a gap and every step's boxes lie in the bounds
    (never from output times or samples)."""
    text = describe(lo, hi, names)
    tube = list(sol.tube or ())
    tt = np.asarray(sol.tube_t, float)
    if not tube:
        return SpecCheck(NOT_PROVEN, math.inf, "", f"{text}: not proven (no verified step)")
    # (from the step boxes themselves, not a summary of them)
    th_lo = np.array([np.min(np.asarray(b.lo, float), axis=0) if b.shape[0] else lo * np.nan for b in tube])
    th_hi = np.array([np.max(np.asarray(b.hi, float), axis=0) if b.shape[0] else hi * np.nan for b in tube])
    with np.errstate(invalid="ignore"):
        ex = np.stack([th_hi - hi, lo - th_lo])          # (2, steps, n): above hi, below lo
    ex = np.where(np.isnan(ex), np.inf, ex)
    side, j, i = np.unravel_index(int(np.argmax(ex)), ex.shape)
    worst = float(ex[side, j, i])
    span = f"t in [{tt[j]:g}, {tt[j + 1]:g}]" if j + 1 < tt.size else ""
    if side == 0:
        where = f"{names[i]} up to {th_hi[j, i]:.6g} on {span}"
        extreme = f"max of {names[i]} over the tube {float(np.max(th_hi[:, i])):.6g}"
    else:
        where = f"{names[i]} down to {th_lo[j, i]:.6g} on {span}"
        extreme = f"min of {names[i]} over the tube {float(np.min(th_lo[:, i])):.6g}"
    complete = (sol.status == "completed" and tt.size == len(tube) + 1 and tt[0] <= t0 and tt[-1] >= t1
                and bool(np.all(np.diff(tt) >= 0)))
    if complete and worst <= 0:
        return SpecCheck(PROVEN, worst, where, f"{text}: proven ({extreme})")
    why = extreme if complete else f"run {sol.status} at t = {float(sol.t_reached):g}; {extreme} up to there"
    return SpecCheck(NOT_PROVEN, worst, where, f"{text}: not proven ({why})")

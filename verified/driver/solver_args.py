"""Argument checks of :func:`verified.solver.solve`.

Every argument is checked before any work is done (before the Taylor tapes are built
and before the first step), and a bad one raises a one-line :class:`ValueError` (a
:class:`TypeError` for an ODE that is not a graph) naming the argument and the value
it got. Without these checks ``tol=0`` or ``h_max=0`` took zero-length steps until
``max_steps``, ``tol=nan`` surfaced as an interval NaN error and ``h_max=nan`` was
ignored.
"""
from __future__ import annotations

import math
import numbers

import numpy as np

from verified.graph import Graph
from verified.arith.interval import Interval, _as_interval, concatenate

__all__ = ["check_graph", "check_settings", "initial_boxes", "check_params", "check_arithmetic",
           "check_params_per_state", "check_model_cap", "ERROR_BASES", "ARITHMETICS", "MAX_ORDER", "MAX_STEPS",
           "MAX_BOXES"]

ERROR_BASES = ("qr", "auto")
ARITHMETICS = ("interval", "affine", "taylor_model")


def check_arithmetic(arithmetic) -> str:
    """``arithmetic`` of :func:`~verified.solver.solve`, refused unless one of ARITHMETICS."""
    if arithmetic not in ARITHMETICS:
        raise ValueError(f"arithmetic must be one of {ARITHMETICS}, got {arithmetic!r}")
    return arithmetic


def check_graph(graph) -> Graph:
    """The ODE's graph, refused unless it is a :class:`Graph` with at least one state."""
    if not isinstance(graph, Graph):
        raise TypeError(f"expected a verified.graph.Graph, got {type(graph).__name__}")
    if graph.n_inputs < 1:
        raise ValueError("the ODE has no states (a zero-dimensional system): nothing to integrate")
    if graph.n_outputs != graph.n_inputs:
        raise ValueError(f"an ODE right-hand side needs as many outputs as inputs, got {graph.n_inputs} "
                         f"inputs and {graph.n_outputs} outputs")
    return graph


def _real(name: str, value) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Real, np.floating, np.integer)):
        raise ValueError(f"{name} must be a number, got {value!r}")
    return float(value)


def _positive(name: str, value, *, allow_inf: bool = False, or_none: bool = False) -> float:
    """A number > 0 (not NaN; +inf only when ``allow_inf``)."""
    v = _real(name, value)
    if not (v > 0) or (v == math.inf and not allow_inf):
        what = ("None or " if or_none else "") + ("a number > 0" if allow_inf else "a finite number > 0")
        raise ValueError(f"{name} must be {what}, got {value!r}")
    return v


#: upper bounds of the size arguments: beyond them a run does not fail, it runs for hours
#: or exhausts memory before its first step (docs/lab/code_notes.md). Taylor coefficients of order > 60 underflow the step's h^k for any step
#: the solver takes; 10^8 steps are days of work; each box holds n x n float matrices.
MAX_ORDER = 60
MAX_STEPS = 10**8
MAX_BOXES = 2**21
#: parameters per state a set may carry (``params_per_state``): a second-order set's cost
#: grows with the square of its parameter count
MAX_PARAMS_PER_STATE = 64
#: symbols given quadratic/cubic/quartic/star monomials or claimed by the remainder pool
#: (``model_caps``): the monomial count grows with the cap to the power of the degree
MAX_MODEL_CAP = {"quadratic": 512, "cubic": 96, "quartic": 48, "star": 512, "pool": 4096}


def _count(name: str, value, minimum: int, maximum: int | None = None) -> int:
    want = f"an integer >= {minimum}" if maximum is None else f"an integer in [{minimum}, {maximum}]"
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Integral, np.integer)):
        raise ValueError(f"{name} must be {want}, got {value!r}")
    if value < minimum or (maximum is not None and value > maximum):
        raise ValueError(f"{name} must be {want}, got {value!r}")
    return int(value)


def check_settings(*, t_span, t_eval, order, tol, h_max, h_min, max_steps, max_width, adaptive,
                   split_ratio, max_boxes, wrap_target, merge_slack, error_basis, progress):
    """Check the scalar settings of :func:`~verified.solver.solve`.

    Returns ``(t0, t1, outs, h_max)``: the time span as floats, the output times
    (``t0`` first, then the sorted distinct ``t_eval``; ``t1`` when ``t_eval`` is
    None) and the step bound (``t1 - t0`` when ``h_max`` is None).
    """
    try:
        t0, t1 = t_span
    except (TypeError, ValueError):
        raise ValueError(f"t_span must be a pair (t0, t1), got {t_span!r}") from None
    t0, t1 = _real("t_span[0]", t0), _real("t_span[1]", t1)
    if not (math.isfinite(t0) and math.isfinite(t1)) or not t1 > t0:
        raise ValueError(f"t_span must be finite with t1 > t0, got {t_span!r}")
    if t_eval is None:
        outs = np.array([t1])
    else:
        try:
            outs = np.asarray(t_eval, dtype=float).ravel()
        except (TypeError, ValueError):
            raise ValueError(f"t_eval must be an array of times, got {t_eval!r}") from None
        if not np.isfinite(outs).all():
            raise ValueError(f"t_eval must be finite, got {float(outs[~np.isfinite(outs)][0])!r} in it")
        if outs.size and (outs.min() < t0 or outs.max() > t1):
            bad = float(outs[(outs < t0) | (outs > t1)][0])
            raise ValueError(f"t_eval must lie within t_span [{t0!r}, {t1!r}], got {bad!r}")
        if np.any(np.diff(outs) < 0):
            k = int(np.flatnonzero(np.diff(outs) < 0)[0])
            raise ValueError(f"t_eval must be sorted (non-decreasing), got {float(outs[k])!r} "
                             f"before {float(outs[k + 1])!r}")
    outs = np.unique(np.concatenate([[t0], outs]))

    # order 1 would leave the variational (Jacobian) series of the Lohner step empty
    _count("order", order, 2, MAX_ORDER)
    _positive("tol", tol)
    # h_min = 0 would let the step-size halving reach a step of length 0
    h_min = _positive("h_min", h_min)
    if h_max is None:
        h_max = t1 - t0  # (not compared with h_min: the default h_min must not refuse short spans)
    else:
        h_max = _positive("h_max", h_max, allow_inf=True, or_none=True)
        if not h_min < h_max:
            raise ValueError(f"h_min must be smaller than h_max, got h_min={h_min!r} and h_max={h_max!r}")
    _count("max_steps", max_steps, 1, MAX_STEPS)
    _count("max_boxes", max_boxes, 1, MAX_BOXES)
    _positive("max_width", max_width, allow_inf=True)
    if not isinstance(adaptive, (bool, np.bool_)):
        raise ValueError(f"adaptive must be True or False, got {adaptive!r}")
    _positive("split_ratio", split_ratio, allow_inf=True)
    _positive("wrap_target", wrap_target, allow_inf=True)
    if merge_slack is not None:
        v = _real("merge_slack", merge_slack)
        if not v >= 0:
            raise ValueError(f"merge_slack must be None or a number >= 0, got {merge_slack!r}")
    if isinstance(error_basis, str) and error_basis in ERROR_BASES:
        pass
    elif isinstance(error_basis, str) or not callable(getattr(error_basis, "update", None)):
        # a policy object of verified.sets.bases (BlockBasis, EnergyAlignedBasis) is accepted too
        raise ValueError(f"error_basis must be 'qr' or 'auto', got {error_basis!r}")
    if progress is not None and not callable(progress):
        raise ValueError(f"progress must be None or a callable(t, t_end), got {progress!r}")
    return t0, t1, outs, h_max


def _subdivision(subdivision, n: int) -> np.ndarray:
    if isinstance(subdivision, (numbers.Integral, np.integer)) and not isinstance(subdivision, (bool, np.bool_)):
        pieces = [subdivision]
    else:
        try:
            pieces = list(subdivision)
        except TypeError:
            pieces = None
        if pieces is None or isinstance(subdivision, (str, dict)):
            raise ValueError(f"subdivision must be an integer >= 1 or a sequence of {n} integers >= 1 "
                             f"(pieces per state), got {subdivision!r}")
        if len(pieces) != n:
            raise ValueError(f"subdivision must have one entry per state ({n}), got {len(pieces)}: {subdivision!r}")
    for p in pieces:
        if isinstance(p, (bool, np.bool_)) or not isinstance(p, (numbers.Integral, np.integer)) or p < 1:
            raise ValueError(f"subdivision entries must be integers >= 1, got {subdivision!r}")
    return np.broadcast_to(np.array(pieces, dtype=int), (n,))


def initial_boxes(x0, n: int, subdivision) -> Interval:
    """The initial boxes as an Interval (B, n), ``B >= 1``, subdivided."""
    pieces = None if subdivision is None else _subdivision(subdivision, n)
    _refuse_bounds_pair(x0, n)
    try:
        if isinstance(x0, (list, tuple)) and x0 and isinstance(x0[0], Interval):
            parts = [_as_interval(b) for b in x0]
            for b in parts:
                if b.shape[-1:] != (n,):
                    raise ValueError(f"x0: every box must have {n} components (last axis), got shape {b.shape}")
            boxes = concatenate([b.reshape(-1, n) for b in parts], axis=0)
        else:
            boxes = _as_interval(x0)
    except ValueError as e:  # IntervalError (NaN, inverted bounds) is a ValueError
        msg = str(e)
        raise ValueError(msg if msg.startswith("x0") else f"x0: {msg}") from None
    except TypeError:
        raise ValueError(f"x0 must be an Interval (n,) or (B, n), or a list of them, got {type(x0).__name__}") \
            from None
    if boxes.ndim == 0 or boxes.shape[-1] != n:
        raise ValueError(f"x0 must have {n} components (last axis), got shape {boxes.shape}")
    boxes = boxes.reshape(-1, n)
    if boxes.shape[0] == 0:
        raise ValueError(f"x0 is an empty batch of boxes (shape {boxes.shape})")
    if np.isnan(boxes.lo).any() or np.isnan(boxes.hi).any():
        raise ValueError("x0 has NaN bounds")
    if boxes.is_empty().any():
        raise ValueError(f"x0: box {int(np.flatnonzero(boxes.is_empty().any(axis=1))[0])} is empty (lo > hi)")
    if not (np.isfinite(boxes.lo).all() and np.isfinite(boxes.hi).all()):
        raise ValueError("x0 must be bounded (finite bounds)")
    if pieces is not None:
        total = boxes.shape[0] * math.prod(int(k) for k in np.broadcast_to(pieces, (n,)))
        if total > MAX_INITIAL_BOXES:
            raise ValueError(f"subdivision {subdivision!r} of {boxes.shape[0]} box(es) makes {total} boxes, more "
                             f"than the {MAX_INITIAL_BOXES} supported (each set holds two {n}x{n} matrices)")
        boxes = boxes.subdivide(pieces).reshape(-1, n)
    return boxes


def _refuse_bounds_pair(x0, n: int) -> None:
    """``x0 = (lo, hi)`` (a tuple or list of two vectors, as ``initial_box()`` functions
    return them) would be taken as two *point* states: a run from two points where a
    box was meant, with no error. Refused unless the two are equal (then it is the same
    point twice, whichever was meant)."""
    if not isinstance(x0, (list, tuple)) or len(x0) != 2 or any(isinstance(v, Interval) for v in x0):
        return
    try:
        a, b = (np.asarray(v, dtype=float) for v in x0)
    except (TypeError, ValueError):
        return
    if a.shape == b.shape == (n,) and not np.array_equal(a, b):
        raise ValueError(f"x0 is a pair of {n}-vectors, which would be two point states; for the box between "
                         "them pass Interval(lo, hi), for two points a (2, n) array")


#: initial boxes at most (after subdivision): [1000] * 4 used to die in a MemoryError
MAX_INITIAL_BOXES = MAX_BOXES


def check_params_per_state(params_per_state) -> int | None:
    """``params_per_state`` of :func:`~verified.solver.solve`: None or an int in
    [1, MAX_PARAMS_PER_STATE]."""
    if params_per_state is None:
        return None
    return _count("params_per_state", params_per_state, 1, MAX_PARAMS_PER_STATE)


def check_model_cap(key: str, value) -> int:
    """One entry of ``model_caps``: an int in [0, MAX_MODEL_CAP[key]]."""
    return _count(f"model_caps[{key!r}]", value, 0, MAX_MODEL_CAP[key])


def check_params(params, graph: Graph, nb: int, subdivision):
    """The parameters as an Interval (p,) or (nb, p), or None for an ODE without any."""
    p = graph.n_params
    if not p:
        empty = (isinstance(params, (list, tuple)) and len(params) == 0) or \
            (isinstance(params, np.ndarray) and params.size == 0)
        if params is not None and not empty:
            raise ValueError(f"the ODE has no parameters, got params={params!r}")
        return None
    if params is None:
        raise ValueError(f"the ODE has parameters {graph.param_names}: pass params")
    try:
        params = _as_interval(params)
    except (TypeError, ValueError) as e:
        raise ValueError(f"params: {e}") from None
    if np.isnan(params.lo).any() or np.isnan(params.hi).any():
        raise ValueError("params has NaN bounds")
    if not (np.isfinite(params.lo).all() and np.isfinite(params.hi).all()):
        raise ValueError("params must be bounded (finite bounds)")
    if params.ndim not in (1, 2) or params.shape[-1] != p:
        raise ValueError(f"params must have shape ({p},) or (boxes, {p}), got shape {params.shape}")
    if params.is_empty().any():
        raise ValueError("params: an interval is empty (lo > hi)")
    if params.ndim == 2 and params.shape[0] != nb:
        if subdivision is not None:
            raise ValueError("per-box params cannot be combined with subdivision")
        raise ValueError(f"per-box params need one row per initial box ({nb}), got {params.shape[0]}")
    return params

"""Evaluators for :class:`verified.graph.Graph`: one pass over the node list per call.

An evaluator is a :class:`Domain`: an object with one method per opcode
(``const, add, sub, mul, div, neg, sqr, pow, sqrt, exp, log, sin, cos, tan, atan, mid``)
plus ``pack``/``point``/``expand`` helpers. :func:`evaluate` walks the graph once and
calls the domain method of each node on the values of its arguments; values are
whole batches (arrays over boxes), so there is one numpy/Interval call per node and
no Python loop over boxes. A new evaluator (e.g. interval Taylor series) is a new
Domain subclass.

Domains here:

* :class:`FloatDomain`     -- float64 ndarrays of the batch shape.
* :class:`IntervalDomain`  -- :class:`verified.arith.interval.Interval` of the batch shape.
* :class:`DualDomain`      -- forward-mode derivatives over any base domain: a value is
  a pair ``(v, d)`` with ``v`` of the batch shape and ``d`` of batch shape + ``(k,)``
  (``None`` when the node does not depend on the differentiation variables).
  ``DualDomain(FloatDomain())`` gives float Jacobians, ``DualDomain(IntervalDomain())``
  interval Jacobians (an enclosure of the Jacobian over each box).
"""
from __future__ import annotations

from typing import Any, Protocol, Sequence

import numpy as np

from verified.arith import interval as _interval
from verified.graph.forward_rules import RULES, Algebra
from verified.graph.opcodes import Node, Op


class Graph(Protocol):
    """What the evaluators read of a graph (:class:`verified.graph.Graph`, which calls
    them from its methods: so this module names the shape, not that class, and the two
    do not import each other)."""

    nodes: Sequence[Node]
    outputs: Sequence[int]
    input_names: Sequence[str]
    param_names: Sequence[str]
    _release_plan: Any

    @property
    def n_inputs(self) -> int: ...

    @property
    def n_params(self) -> int: ...

__all__ = [
    "Domain",
    "FloatDomain",
    "IntervalDomain",
    "DualDomain",
    "evaluate",
    "eval_float",
    "eval_interval",
    "jacobian_float",
    "jacobian_interval",
    "SympyDomain",
    "to_sympy",
]


class Domain:
    """Arithmetic on one kind of (batched) value; subclass and fill in the methods.

    Binary methods must accept a Python float for either argument (the dual domain
    passes constants such as ``2.0``); float arguments are exact.
    """

    def const(self, lo: float, hi: float, value: float):
        """Value of a constant whose exact value lies in ``[lo, hi]`` (nearest double ``value``)."""
        raise NotImplementedError

    def add(self, a, b):
        return a + b

    def sub(self, a, b):
        return a - b

    def mul(self, a, b):
        return a * b

    def div(self, a, b):
        return a / b

    def neg(self, a):
        return -a

    def sqr(self, a):
        raise NotImplementedError

    def pow(self, a, k: int):
        raise NotImplementedError

    def sqrt(self, a):
        raise NotImplementedError

    def exp(self, a):
        raise NotImplementedError

    def log(self, a):
        raise NotImplementedError

    def sin(self, a):
        raise NotImplementedError

    def cos(self, a):
        raise NotImplementedError

    def tan(self, a):
        raise NotImplementedError

    def atan(self, a):
        raise NotImplementedError

    def mid(self, a):
        """A point of ``a`` (see :meth:`verified.graph.GraphBuilder.mid`)."""
        raise NotImplementedError

    # helpers used by DualDomain and the Graph methods

    def point(self, array):
        """Exact value of a float array / float (used for derivative seeds and zeros)."""
        raise NotImplementedError

    def expand(self, a):
        """``a`` with a trailing length-1 axis (to broadcast against derivatives)."""
        raise NotImplementedError

    def pack(self, values: Sequence, shape: tuple[int, ...], axis: int = -1):
        """Broadcast each value to ``shape`` and stack them along a new ``axis``."""
        raise NotImplementedError


def _handler_table(domain: Domain) -> list:
    """``table[op]`` = bound domain method for the opcode (None for leaves)."""
    table: list = [None] * len(Op)
    for op in Op:
        if op not in (Op.CONST, Op.INPUT, Op.PARAM):
            table[op] = getattr(domain, op.name.lower())
    return table


def evaluate(graph: Graph, domain: Domain, inputs: Sequence, params: Sequence = ()) -> list:
    """Values of the graph's outputs in ``domain``.

    Args:
        graph: the Graph.
        domain: a :class:`Domain`.
        inputs: ``n`` domain values (one per input, each of the batch shape).
        params: ``p`` domain values (one per parameter).

    Returns: list of ``m`` domain values (constant outputs may be unbroadcast scalars).
    """
    table = _handler_table(domain)
    vals: list[Any] = [None] * len(graph.nodes)
    release = graph._release_plan
    for i, (op, args, data) in enumerate(graph.nodes):
        if op == Op.CONST:
            v = domain.const(*data)
        elif op == Op.INPUT:
            v = inputs[data]
        elif op == Op.PARAM:
            v = params[data]
        elif op == Op.POW:
            v = table[op](vals[args[0]], data)
        elif len(args) == 2:
            v = table[op](vals[args[0]], vals[args[1]])
        else:
            v = table[op](vals[args[0]])
        vals[i] = v
        for j in release[i]:  # free values nobody needs any more
            vals[j] = None
    return [vals[o] for o in graph.outputs]


# --------------------------------------------------------------------------- float


class FloatDomain(Domain):
    """float64 ndarrays; constants are their nearest double (numpy scalars, so that
    division by an exact 0 gives inf/nan with a warning rather than an exception).

    ``shape``: constants as arrays of the batch's shape instead. Then a subexpression
    of constants is computed with the same numpy kernels as everything else: numpy's
    scalar and array kernels of ``power``, ``exp``, ``sin``, ... may differ in the last
    bit (SIMD), and :func:`eval_float` should equal the model code run on arrays."""

    def __init__(self, shape=None):
        self.shape = shape

    def const(self, lo, hi, value):
        v = np.float64(value)
        return v if self.shape is None else np.full(self.shape, v)

    def sqr(self, a):
        return a * a

    def pow(self, a, k):
        return a**k

    sqrt = staticmethod(np.sqrt)
    exp = staticmethod(np.exp)
    log = staticmethod(np.log)
    sin = staticmethod(np.sin)
    cos = staticmethod(np.cos)
    tan = staticmethod(np.tan)
    atan = staticmethod(np.arctan)

    def mid(self, a):
        return a

    def point(self, array):
        return np.asarray(array, dtype=np.float64)

    def expand(self, a):
        return np.asarray(a)[..., None]

    def pack(self, values, shape, axis=-1):
        if not values:  # np.stack needs at least one array
            return np.moveaxis(np.zeros(shape + (0,)), -1, axis)
        return np.stack([np.broadcast_to(v, shape) for v in values], axis=axis)


# --------------------------------------------------------------------------- interval


def _iv():
    """The interval module."""
    return _interval


class IntervalDomain(Domain):
    """:class:`verified.arith.interval.Interval` values; constants are their enclosures.

    Every method is outward rounded by the Interval implementation, so each node's
    value encloses the exact value for every point of the input boxes.
    """

    def __init__(self):
        self.iv = _iv()
        self.Interval = self.iv.Interval

    def const(self, lo, hi, value):
        return self.Interval(lo, hi)

    def sqr(self, a):
        return self.iv.sqr(a)

    def pow(self, a, k):
        return self.iv.ipow(a, k)

    def sqrt(self, a):
        return self.iv.sqrt(a)

    def exp(self, a):
        return self.iv.exp(a)

    def log(self, a):
        return self.iv.log(a)

    def sin(self, a):
        return self.iv.sin(a)

    def cos(self, a):
        return self.iv.cos(a)

    def tan(self, a):
        return self.iv.tan(a)

    def atan(self, a):
        return self.iv.atan(a)

    def mid(self, a):
        # A point interval: the same float wherever this node's value is used, which is
        # all a preconditioner needs.  An unbounded argument has no point worth taking:
        # it stays the whole line, and an empty one stays empty, so that nothing turns
        # 'unknown' into a definite (possibly singular) preconditioner.
        lo, hi = np.asarray(a.lo, dtype=np.float64), np.asarray(a.hi, dtype=np.float64)
        with np.errstate(invalid="ignore", over="ignore"):
            m = 0.5 * lo + 0.5 * hi
        finite = np.isfinite(lo) & np.isfinite(hi)
        empty = lo > hi
        return self.Interval._from_bounds(np.where(finite, m, np.where(empty, lo, -np.inf)),
                                          np.where(finite, m, np.where(empty, hi, np.inf)))

    def point(self, array):
        return self.Interval(np.asarray(array, dtype=np.float64))

    def expand(self, a):
        return self.Interval._from_bounds(np.asarray(a.lo)[..., None], np.asarray(a.hi)[..., None])

    def pack(self, values, shape, axis=-1):
        if not values:
            z = FloatDomain().pack([], shape, axis)
            return self.Interval(z)
        lo = np.stack([np.broadcast_to(v.lo, shape) for v in values], axis=axis)
        hi = np.stack([np.broadcast_to(v.hi, shape) for v in values], axis=axis)
        return self.Interval._from_bounds(lo, hi)


# --------------------------------------------------------------------------- dual numbers


class DualDomain(Domain):
    """Forward-mode derivatives over a base domain.

    Values are pairs ``(v, d)``: ``v`` a base value of the batch shape, ``d`` a base
    value of batch shape + ``(k,)`` holding the partial derivatives with respect to the
    ``k`` seeded variables, or ``None`` for zero (constants, unseeded leaves). The
    derivative rules are :data:`verified.graph.forward_rules.RULES` (shared with
    :func:`verified.graph.ops.forward_mode`); they use only base-domain operations, so in an interval base domain
    they enclose the derivative over the box (the chain rule evaluated in interval
    arithmetic).
    """

    def __init__(self, base: Domain):
        self.base = base
        self._algebra = _DualAlgebra(base)

    def seed(self, value, index: int | None, k: int):
        """Dual value of a variable: derivative is unit vector ``index`` of length ``k`` (None: not seeded)."""
        if index is None:
            return (value, None)
        e = np.zeros(k)
        e[index] = 1.0
        return (value, self.base.point(e))

    def _scale(self, factor, d):
        """``factor * d`` with ``factor`` of the batch shape (broadcast over the last axis)."""
        return self._algebra.d_scale(factor, d)

    def _apply(self, op, a, b=None, k=None):
        """Dual value of ``op`` by :data:`verified.graph.forward_rules.RULES`; the factor only
        when the derivative is nonzero."""
        rule, A = RULES[op], self._algebra
        u, du = a
        w, dw = b if b is not None else (None, None)
        v = rule.value(A, u, w, k)
        if du is None and dw is None:
            return (v, None)
        f = rule.factor(A, u, v, k) if rule.factor is not None else None
        return (v, rule.deriv(A, du, dw, u, w, v, f, k))

    def const(self, lo, hi, value):
        return (self.base.const(lo, hi, value), None)

    def add(self, a, b):
        return self._apply(Op.ADD, a, b)

    def sub(self, a, b):
        return self._apply(Op.SUB, a, b)

    def mul(self, a, b):
        return self._apply(Op.MUL, a, b)

    def div(self, a, b):
        return self._apply(Op.DIV, a, b)

    def neg(self, a):
        return self._apply(Op.NEG, a)

    def sqr(self, a):
        return self._apply(Op.SQR, a)

    def pow(self, a, k):
        return self._apply(Op.POW, a, k=k)

    def sqrt(self, a):
        return self._apply(Op.SQRT, a)

    def exp(self, a):
        return self._apply(Op.EXP, a)

    def log(self, a):
        return self._apply(Op.LOG, a)

    def sin(self, a):
        return self._apply(Op.SIN, a)

    def cos(self, a):
        return self._apply(Op.COS, a)

    def tan(self, a):
        return self._apply(Op.TAN, a)

    def atan(self, a):
        return self._apply(Op.ATAN, a)

    def mid(self, a):
        return self._apply(Op.MID, a)


class _DualAlgebra(Algebra):
    """The algebra of :mod:`verified.graph.forward_rules` over a base domain: values are base
    values of the batch shape, derivatives base values with a trailing axis of
    directions (None: zero); value operations are the base domain's."""

    def __init__(self, base: Domain):
        super().__init__(base)
        self.base = base

    def num(self, c):
        return float(c)

    def d_scale(self, f, p):
        """``f * p`` with ``f`` of the batch shape (broadcast over the last axis)."""
        return None if p is None else self.base.mul(self.base.expand(f), p)

    def d_div(self, p, x):
        return None if p is None else self.base.div(p, self.base.expand(x))


# --------------------------------------------------------------------------- entry points


def _check_last_dim(name: str, shape: tuple, expected: int, names: Sequence[str], fn: str) -> None:
    if len(shape) == 0 or shape[-1] != expected:
        listed = ", ".join(names) if len(names) <= 12 else ", ".join(names[:12]) + ", ..."
        raise ValueError(
            f"{fn}: {name} must have shape (..., {expected}) for ({listed}); got shape {tuple(shape)}"
        )


def _float_array(graph: Graph, name: str, a, fn: str) -> np.ndarray:
    expected = graph.n_inputs if name == "x" else graph.n_params
    names = graph.input_names if name == "x" else graph.param_names
    if a is None:
        if expected:
            raise ValueError(f"{fn}: the graph has {expected} {'inputs' if name == 'x' else 'parameters'} "
                             f"({', '.join(names)}); pass {name} of shape (..., {expected})")
        return np.zeros((0,))
    a = np.asarray(a, dtype=np.float64)
    _check_last_dim(name, a.shape, expected, names, fn)
    return a


def _columns(a: np.ndarray) -> list[np.ndarray]:
    """Contiguous per-variable arrays of shape ``a.shape[:-1]``."""
    moved = np.ascontiguousarray(np.moveaxis(a, -1, 0))
    return list(moved)


def _float_inputs(graph: Graph, x, p, fn: str):
    x = _float_array(graph, "x", x, fn)
    p = _float_array(graph, "p", p, fn)
    shape = np.broadcast_shapes(x.shape[:-1], p.shape[:-1])
    return _columns(x), _columns(p), shape


def _interval_array(graph: Graph, name: str, a, fn: str):
    Interval = _iv().Interval
    if not isinstance(a, Interval):
        a = _float_array(graph, name, a, fn)
        if np.isnan(a).any():
            raise ValueError(f"{fn}: {name} contains NaN")
        return Interval(a)
    expected = graph.n_inputs if name == "x" else graph.n_params
    names = graph.input_names if name == "x" else graph.param_names
    _check_last_dim(name, a.shape, expected, names, fn)
    return a


def _interval_inputs(graph: Graph, x, p, fn: str):
    Interval = _iv().Interval
    x = _interval_array(graph, "x", x, fn)
    p = _interval_array(graph, "p", p, fn)
    shape = np.broadcast_shapes(x.shape[:-1], p.shape[:-1])

    def cols(a):
        return [Interval._from_bounds(lo, hi) for lo, hi in zip(_columns(np.asarray(a.lo)), _columns(np.asarray(a.hi)))]

    return cols(x), cols(p), shape


def eval_float(graph: Graph, x, p=None) -> np.ndarray:
    """Float values: ``x`` (..., n), ``p`` (..., p) / (p,) -> ndarray (..., m)."""
    xs, ps, shape = _float_inputs(graph, x, p, "eval_float")
    domain = FloatDomain(shape)
    return domain.pack(evaluate(graph, domain, xs, ps), shape)


def eval_interval(graph: Graph, x, p=None):
    """Interval enclosure: ``x`` Interval/floats (..., n), ``p`` likewise -> Interval (..., m)."""
    xs, ps, shape = _interval_inputs(graph, x, p, "eval_interval")
    domain = IntervalDomain()
    return domain.pack(evaluate(graph, domain, xs, ps), shape)


def _seed_indices(graph: Graph, wrt: str) -> tuple[list, list, int]:
    n, p = graph.n_inputs, graph.n_params
    if wrt == "x":
        return list(range(n)), [None] * p, n
    if wrt == "p":
        return [None] * n, list(range(p)), p
    if wrt == "xp":
        return list(range(n)), list(range(n, n + p)), n + p
    raise ValueError(f"wrt must be 'x', 'p' or 'xp', got {wrt!r}")


def _jacobian(graph: Graph, base: Domain, xs, ps, shape, wrt: str):
    dual = DualDomain(base)
    xi, pi, k = _seed_indices(graph, wrt)
    xd = [dual.seed(v, i, k) for v, i in zip(xs, xi)]
    pd = [dual.seed(v, i, k) for v, i in zip(ps, pi)]
    outs = evaluate(graph, dual, xd, pd)
    zero = base.point(0.0)
    return base.pack([zero if d is None else d for _, d in outs], shape + (k,), axis=-2)


def jacobian_float(graph: Graph, x, p=None, *, wrt: str = "x") -> np.ndarray:
    """Forward-mode Jacobian ``df/dx`` (wrt="x"), ``df/dp`` ("p") or both ("xp") -> (..., m, k)."""
    xs, ps, shape = _float_inputs(graph, x, p, "jacobian_float")
    return _jacobian(graph, FloatDomain(), xs, ps, shape, wrt)


def jacobian_interval(graph: Graph, x, p=None, *, wrt: str = "x"):
    """Interval enclosure of the Jacobian over each box -> Interval (..., m, k); see :func:`jacobian_float`."""
    xs, ps, shape = _interval_inputs(graph, x, p, "jacobian_interval")
    return _jacobian(graph, IntervalDomain(), xs, ps, shape, wrt)


# --------------------------------------------------------------------------- sympy


class SympyDomain(Domain):
    """sympy expressions (a debugging aid, not rigorous): constants that are exact
    doubles become exact sympy numbers, enclosed constants (e.g. pi, 1/3) the Float of
    their nearest double; ``mid`` is the identity (exact math: the frozen point may be
    the value itself)."""

    def __init__(self):
        import sympy  # (import here: sympy, ~0.4 s, only when a graph is printed as sympy)

        self.sympy = sympy

    def const(self, lo, hi, value):
        sp = self.sympy
        return sp.Integer(int(value)) if lo == hi and value.is_integer() else sp.Float(value)

    def sqr(self, a):
        return a**2

    def pow(self, a, k):
        return a**k

    def sqrt(self, a):
        return self.sympy.sqrt(a)

    def exp(self, a):
        return self.sympy.exp(a)

    def log(self, a):
        return self.sympy.log(a)

    def sin(self, a):
        return self.sympy.sin(a)

    def cos(self, a):
        return self.sympy.cos(a)

    def tan(self, a):
        return self.sympy.tan(a)

    def atan(self, a):
        return self.sympy.atan(a)

    def mid(self, a):
        return a


def to_sympy(graph: Graph, inputs=None, params=None) -> list:
    """Debugging aid: the graph's outputs as sympy expressions of ``inputs``/``params``
    (default: Symbols named after the graph's inputs and parameters); see :class:`SympyDomain`."""
    domain = SympyDomain()
    sp = domain.sympy
    xs = list(inputs) if inputs is not None else [sp.Symbol(n) for n in graph.input_names]
    ps = list(params) if params is not None else [sp.Symbol(n) for n in graph.param_names]
    return evaluate(graph, domain, xs, ps)

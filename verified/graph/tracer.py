"""Tracing front end: run model code on :class:`Tracer` scalars to record a :class:`Graph`.

This is the "generic scalar" protocol: model code such as ``np.sin(q) * l + m * x``
runs unchanged on floats, numpy arrays, :class:`verified.arith.interval.Interval` and
:class:`Tracer`. A Tracer supports ``+ - * /``, unary ``-``, ``**`` with integer (or
half-integer) exponents, mixing with Python ``int``/``float``/``Fraction`` and numpy
scalars, and the numpy ufuncs listed in :data:`SUPPORTED_UFUNCS`. Object arrays of
Tracers work too (numpy calls the operators / ``.sin()`` ... methods per element).

Python floats in traced code are exact constants (the double itself); ints and
Fractions are enclosed outward when they are not doubles. Irrational constants can be
given as sympy numbers (``sympy.pi / 3``, ``sympy.sqrt(2)``: converted like
:func:`~verified.graph.from_sympy` does) or as a 0-d :class:`~verified.arith.interval.Interval` enclosing
them; both become rigorous constant enclosures. (A float such as ``math.pi`` is taken
as the exact double, which is *not* pi.)

Anything that needs a concrete value -- ``bool()``, comparisons, ``float()`` -- raises
``TypeError``: data-dependent control flow cannot be traced.
"""
from __future__ import annotations

import sys
from fractions import Fraction
from typing import Callable, Sequence

import numpy as np

from verified.graph.ir import Graph, GraphBuilder

__all__ = ["Tracer", "trace", "SUPPORTED_UFUNCS"]

_NO_CONTROL_FLOW = (
    "data-dependent control flow cannot be traced: a Tracer has no concrete value "
    "(comparisons, bool(), if/while on traced values, float() are not allowed)"
)


class Tracer:
    """A scalar placeholder recording operations into a :class:`GraphBuilder`.

    Attributes:
        builder: the GraphBuilder being recorded into.
        node: this value's node id in ``builder``.
    """

    __slots__ = ("builder", "node")
    # make numpy defer binary operators with ndarrays / numpy scalars to us
    __array_priority__ = 1000.0

    def __init__(self, builder: GraphBuilder, node: int):
        self.builder = builder
        self.node = node

    # -- coercion

    def _lift(self, other) -> int:
        """Node id of ``other`` (Tracer of the same trace or exact Python/numpy number)."""
        return _lift(self.builder, other)

    def _new(self, node: int) -> "Tracer":
        return Tracer(self.builder, node)

    def _binary(self, method: str, a, b) -> "Tracer":
        try:
            na, nb = self._lift(a), self._lift(b)
        except TypeError:
            return NotImplemented
        return self._new(getattr(self.builder, method)(na, nb))

    # -- arithmetic operators

    def __add__(self, other):
        return self._binary("add", self, other)

    def __radd__(self, other):
        return self._binary("add", other, self)

    def __sub__(self, other):
        return self._binary("sub", self, other)

    def __rsub__(self, other):
        return self._binary("sub", other, self)

    def __mul__(self, other):
        return self._binary("mul", self, other)

    def __rmul__(self, other):
        return self._binary("mul", other, self)

    def __truediv__(self, other):
        return self._binary("div", self, other)

    def __rtruediv__(self, other):
        return self._binary("div", other, self)

    def __neg__(self):
        return self._new(self.builder.neg(self.node))

    def __pos__(self):
        return self

    def __pow__(self, exponent, modulo=None):
        if modulo is not None:
            raise TypeError("pow() with a modulus is not supported on Tracers")
        return self._new(_power(self.builder, self.node, exponent))

    def __rpow__(self, base):
        raise NotImplementedError(
            "a traced value as an exponent (c ** x) is not in the op set; write np.exp(x * np.log(c))"
        )

    # -- methods numpy calls on object arrays (np.sin(obj_array) -> elem.sin())

    def sin(self):
        return self._new(self.builder.sin(self.node))

    def cos(self):
        return self._new(self.builder.cos(self.node))

    def tan(self):
        return self._new(self.builder.tan(self.node))

    def arctan(self):
        return self._new(self.builder.atan(self.node))

    def exp(self):
        return self._new(self.builder.exp(self.node))

    def log(self):
        return self._new(self.builder.log(self.node))

    def sqrt(self):
        return self._new(self.builder.sqrt(self.node))

    def mid(self):
        """A frozen point of this value (:meth:`verified.graph.GraphBuilder.mid`)."""
        return self._new(self.builder.mid(self.node))

    # -- numpy ufunc protocol

    def __array_ufunc__(self, ufunc, method, *inputs, **kwargs):
        if method != "__call__" or kwargs:
            return NotImplemented
        if any(isinstance(v, np.ndarray) and v.ndim > 0 for v in inputs):
            # elementwise over an array: let numpy loop over an object array, which
            # calls our operators / methods per element
            obj = [np.asarray(v, dtype=object) if isinstance(v, np.ndarray) else _object_scalar(v) for v in inputs]
            return ufunc(*obj)
        handler = _UFUNC_HANDLERS.get(ufunc)
        if handler is None:
            raise TypeError(
                f"numpy ufunc {ufunc.__name__!r} is not supported by the graph tracer; "
                f"supported: {', '.join(sorted(u.__name__ for u in _UFUNC_HANDLERS))}"
            )
        return handler(self, *inputs)

    # -- no concrete value

    def __bool__(self):
        raise TypeError(_NO_CONTROL_FLOW)

    def __lt__(self, other):
        raise TypeError(_NO_CONTROL_FLOW)

    __le__ = __gt__ = __ge__ = __lt__

    def __eq__(self, other):
        raise TypeError(_NO_CONTROL_FLOW)

    def __ne__(self, other):
        raise TypeError(_NO_CONTROL_FLOW)

    __hash__ = object.__hash__

    def __float__(self):
        raise TypeError(_NO_CONTROL_FLOW)

    __int__ = __index__ = __complex__ = __float__

    def _sympy_(self):
        # lets ``sympy_number + tracer`` fall back to Tracer.__radd__ (sympy's operators
        # return NotImplemented on SympifyError) instead of failing in float(tracer)
        import sympy

        raise sympy.SympifyError(self, "a Tracer is not a sympy expression")

    def __abs__(self):
        raise NotImplementedError("abs is not in the graph op set (it is not smooth)")

    def __repr__(self):
        return f"Tracer(%{self.node}: {self.builder.node(self.node).op.name.lower()})"


def _object_scalar(v):
    """0-d object array holding ``v`` (so a ufunc on it loops in Python, per element)."""
    out = np.empty((), dtype=object)
    out[()] = v
    return out


def _power(builder: GraphBuilder, node: int, exponent) -> int:
    """Node for ``x ** exponent``: integer exponents, and half-integers via sqrt."""
    if isinstance(exponent, Tracer):
        raise NotImplementedError("a traced exponent (x ** y) is not in the op set; write np.exp(y * np.log(x))")
    if isinstance(exponent, np.ndarray) and exponent.ndim == 0:
        exponent = exponent[()]
    try:
        q = Fraction(exponent)
    except (OverflowError, ValueError):  # inf, nan
        raise ValueError(f"exponent {exponent!r} is not finite") from None
    except TypeError:
        raise TypeError(f"unsupported exponent {exponent!r}") from None
    if abs(q) >= 2**62:
        raise ValueError(f"exponent {exponent!r} is too large (|n| < 2**62 supported)")
    if q.denominator == 1:
        return builder.pow(node, q.numerator)
    if q.denominator == 2:
        # x**(k/2) = sqrt(x)**k (x >= 0 is required by both sides)
        return builder.pow(builder.sqrt(node), q.numerator)
    raise NotImplementedError(f"only integer and half-integer exponents are in the op set, got {exponent!r}")


def _ufunc_power(t: Tracer, base, exponent):
    if not isinstance(base, Tracer):
        return t.__rpow__(base)
    return base ** exponent


_UFUNC_HANDLERS: dict = {
    np.add: lambda t, a, b: t._binary("add", a, b),
    np.subtract: lambda t, a, b: t._binary("sub", a, b),
    np.multiply: lambda t, a, b: t._binary("mul", a, b),
    np.true_divide: lambda t, a, b: t._binary("div", a, b),
    np.negative: lambda t, a: -a,
    np.positive: lambda t, a: a,
    np.square: lambda t, a: a._new(a.builder.sqr(a.node)),
    np.reciprocal: lambda t, a: 1.0 / a,
    np.power: _ufunc_power,
    np.sqrt: lambda t, a: a.sqrt(),
    np.exp: lambda t, a: a.exp(),
    np.log: lambda t, a: a.log(),
    np.sin: lambda t, a: a.sin(),
    np.cos: lambda t, a: a.cos(),
    np.tan: lambda t, a: a.tan(),
    np.arctan: lambda t, a: a.arctan(),
}
SUPPORTED_UFUNCS = tuple(_UFUNC_HANDLERS)


def _output_nodes(builder: GraphBuilder, result) -> list[int]:
    """Flatten the traced function's result into output node ids."""
    if isinstance(result, np.ndarray):
        items = list(result.ravel())
    elif isinstance(result, (list, tuple)):
        items = []
        for r in result:
            items.extend(list(np.asarray(r, dtype=object).ravel()) if isinstance(r, (list, tuple, np.ndarray)) else [r])
    else:
        items = [result]
    nodes = []
    for k, item in enumerate(items):
        try:
            nodes.append(_lift(builder, item))
        except TypeError:
            raise TypeError(
                f"traced function returned {type(item).__name__} {item!r} as output {k}; "
                "expected Tracers or numbers"
            ) from None
        except ValueError as exc:
            raise ValueError(f"output {k}: {exc}") from None
    return nodes


def _lift(builder: GraphBuilder, value) -> int:
    """Node id of ``value``: a Tracer of ``builder`` or an exact Python/numpy number."""
    if isinstance(value, Tracer):
        if value.builder is not builder:
            raise ValueError("cannot mix Tracers from different traces")
        return value.node
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value[()]
    if isinstance(value, (bool, np.bool_)):
        value = int(value)
    if isinstance(value, (int, np.integer)):
        return builder.const(Fraction(int(value)))
    if isinstance(value, Fraction):
        return builder.const(value)
    if isinstance(value, (float, np.float64, np.float32, np.float16)):
        return builder.const(float(value))
    interval_mod = sys.modules.get("verified.arith.interval")
    if interval_mod is not None and isinstance(value, interval_mod.Interval) and value.ndim == 0:
        # an enclosure of a constant (e.g. of pi) used in generic model code
        lo, hi = float(value.lo), float(value.hi)
        return builder.const_enclosure(lo, hi, lo if lo == hi else 0.5 * lo + 0.5 * hi)
    if type(value).__module__.startswith("sympy"):
        from verified.graph.sympy_convert import sympy_number_node  # (import here: sympy only for sympy numbers)

        return sympy_number_node(builder, value)
    raise TypeError(f"cannot use {type(value).__name__} {value!r} in a traced expression")


def trace(
    fn: Callable,
    n_inputs: int,
    n_params: int = 0,
    *,
    input_names: Sequence[str] | None = None,
    param_names: Sequence[str] | None = None,
    output_names: Sequence[str] | None = None,
) -> Graph:
    """Record ``fn(x, p)`` as a :class:`Graph`.

    ``fn`` is called once with ``x`` a list of ``n_inputs`` Tracers and ``p`` a list of
    ``n_params`` Tracers (empty if none). It must return a scalar (Tracer or number) or
    a sequence / array of them; numbers become constant outputs. Output ``k`` of the
    graph is the ``k``-th element of the flattened result.
    """
    builder = GraphBuilder(n_inputs, n_params, input_names, param_names)
    x = [Tracer(builder, builder.input(i)) for i in range(n_inputs)]
    p = [Tracer(builder, builder.param(i)) for i in range(n_params)]
    result = fn(x, p)
    return builder.build(_output_nodes(builder, result), output_names)

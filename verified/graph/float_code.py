"""A graph as straight-line Python code, for fast float evaluation at one point.

:meth:`verified.graph.ir.Graph.eval_float` walks the graph node by node with numpy arrays: a
numpy call per node whatever the batch size, which is right for many points at once and
slow for one (times: ``benchmarks/bench_float_model.py``, docs/lab/auto.md).
:func:`compile_float` writes the graph once as a Python function of plain floats, one
line per node, which runs at the speed of Python float arithmetic.

Float semantics, not interval semantics: constants are their nearest double (as
``eval_float``); ``+ - * /`` are IEEE double operations (correctly rounded, as numpy's);
``sqrt``, ``exp``, ... are the C library's (``math``), which may differ from numpy's in
the last bit. Where Python raises instead of returning inf or nan (division by zero, a
square root of a negative number, an overflow), the point is evaluated by ``eval_float``
instead, so the result is the same as there. Nothing here is rigorous: it serves float
simulations and oracles, never an enclosure.
"""

from __future__ import annotations

import math

import numpy as np

from verified.graph.opcodes import Op

__all__ = ["compile_float", "FloatFunction"]

_UNARY = {Op.NEG: "-{0}", Op.SQR: "{0} * {0}", Op.SQRT: "_sqrt({0})", Op.EXP: "_exp({0})",
          Op.LOG: "_log({0})", Op.SIN: "_sin({0})", Op.COS: "_cos({0})", Op.TAN: "_tan({0})",
          Op.ATAN: "_atan({0})", Op.MID: "{0}"}
_BINARY = {Op.ADD: "{0} + {1}", Op.SUB: "{0} - {1}", Op.MUL: "{0} * {1}", Op.DIV: "{0} / {1}"}


class FloatFunction:
    """``f(x, p=None) -> ndarray (m,)``: the graph's outputs at one point ``x`` (n,)
    with parameters ``p`` (p,) (:func:`compile_float`)."""

    def __init__(self, graph, fn, source: str):
        self.graph = graph
        self._fn = fn
        self.source = source

    def __call__(self, x, p=None) -> np.ndarray:
        g = self.graph
        xs = [float(v) for v in np.asarray(x, dtype=float).reshape(-1)]
        if len(xs) != g.n_inputs:
            raise ValueError(f"expected {g.n_inputs} inputs, got {len(xs)}")
        ps = [] if p is None else [float(v) for v in np.asarray(p, dtype=float).reshape(-1)]
        if len(ps) != g.n_params:
            raise ValueError(f"expected {g.n_params} parameters, got {len(ps)}")
        try:
            return np.array(self._fn(xs, ps), dtype=float)
        except (ZeroDivisionError, ValueError, OverflowError):
            # (where Python raises, numpy gives inf or nan: the graph's own float evaluation)
            with np.errstate(all="ignore"):
                return np.asarray(g.eval_float(np.asarray(xs), np.asarray(ps) if ps else None), dtype=float)


def compile_float(graph) -> FloatFunction:
    """The graph as a :class:`FloatFunction` (module docstring)."""
    lines = ["def f(x, p):"]
    names = {}
    for i, (op, args, data) in enumerate(graph.nodes):
        v = f"v{i}"
        if op == Op.CONST:
            expr = repr(float(data[2]))
        elif op == Op.INPUT:
            expr = f"x[{int(data)}]"
        elif op == Op.PARAM:
            expr = f"p[{int(data)}]"
        elif op == Op.POW:
            expr = f"{names[args[0]]} ** {int(data)}"
        elif op in _BINARY:
            expr = _BINARY[op].format(names[args[0]], names[args[1]])
        elif op in _UNARY:
            expr = _UNARY[op].format(names[args[0]])
        else:  # (an opcode added to the IR but not here)
            raise NotImplementedError(f"compile_float: no code for {op.name}")
        lines.append(f"    {v} = {expr}")
        names[i] = v
    lines.append("    return (" + "".join(f"{names[o]}, " for o in graph.outputs) + ")")
    source = "\n".join(lines) + "\n"
    scope = {"_sqrt": math.sqrt, "_exp": math.exp, "_log": math.log, "_sin": math.sin, "_cos": math.cos,
             "_tan": math.tan, "_atan": math.atan}
    exec(compile(source, f"<compile_float {len(graph.nodes)} nodes>", "exec"), scope)
    return FloatFunction(graph, scope["f"], source)

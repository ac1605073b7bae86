"""Expression graph ("IR"): the seam between modeling (``mbs``) and the rigorous side.

A :class:`Graph` is a vector function ``f: R^n x R^p -> R^m`` (``n`` inputs, ``p``
parameters, ``m`` outputs) stored as a DAG of elementary operations in topological
order: every node's arguments come before it, so an evaluator walks the node list once.

Opcodes (:class:`Op`)::

    const  input  param                          leaves
    add sub mul div                               binary
    neg sqr sqrt exp log sin cos tan atan         unary
    pow                                           unary, integer exponent k >= 3 in ``data``

Constants are rigorous: a constant node stores ``(lo, hi, value)`` floats with
``lo <= exact <= hi`` (outward rounded enclosure of the exact value) and ``value`` the
double nearest to it. Interval evaluation uses ``[lo, hi]``, float evaluation ``value``.

Graphs are built by :class:`GraphBuilder` (hash-consing: equal subexpressions become
one node; arguments of the commutative ``add``/``mul`` are put in a canonical order;
trivial simplifications only where exact for every finite argument). Two front ends
produce graphs: :func:`from_sympy` (sympy expressions) and :func:`trace` (run a Python
function on :class:`~verified.graph.tracer.Tracer` scalars). Evaluators live in
:mod:`verified.graph.evaluate`.

This module is the public front: it re-exports the IR and the front ends. The code
lives in modules that import only the ones before them (no import cycle)::

    opcodes (Op, Node)  ->  evaluate  ->  ir (Graph, GraphBuilder)  ->  tracer, graph_sympy  ->  graph
"""
from __future__ import annotations

from typing import Sequence

from verified.graph.ir import FORMAT_NAME, FORMAT_VERSION, Graph, GraphBuilder, enclose_approximation, enclose_rational
from verified.graph.opcodes import BINARY_OPS, COMMUTATIVE_OPS, LEAF_OPS, UNARY_OPS, Node, Op
from verified.graph.tracer import Tracer, trace

__all__ = [
    "Op",
    "Node",
    "Graph",
    "GraphBuilder",
    "enclose_rational",
    "enclose_approximation",
    "from_sympy",
    "trace",
    "Tracer",
]
__all__ += ["FORMAT_NAME", "FORMAT_VERSION", "LEAF_OPS", "BINARY_OPS", "UNARY_OPS", "COMMUTATIVE_OPS"]


# --------------------------------------------------------------------------- front ends


def from_sympy(exprs, inputs, params=(), *, cse: bool = True, output_names: Sequence[str] | None = None) -> Graph:
    """Graph of sympy expression(s) after ``sympy.cse``.

    Args:
        exprs: a sympy expression, a (nested) list/tuple of them, or a Matrix (flattened
            row-major into the ``m`` outputs).
        inputs: the ``n`` input symbols (Symbols, or atoms such as ``q(t)``, ``Derivative(q(t), t)``).
        params: the ``p`` parameter symbols.
        cse: run ``sympy.cse`` first.
        output_names: optional names of the outputs (default ``y0, y1, ...``).

    Supported: ``+ - * /``, integer powers, half-integer powers (via sqrt), sin, cos, tan,
    atan, exp, log, and numbers (Integer/Rational/Float exactly enclosed; pi, E, ... to
    40 digits, enclosed outward). Raises ``ValueError`` for symbols that are neither
    inputs nor params, ``NotImplementedError`` for anything else (Abs, sign, Piecewise,
    ``x**(1/3)``, ...), naming the offending subexpression. Details in
    :mod:`verified.graph.sympy_convert`.
    """
    # (import here: sympy, ~0.4 s, only for sympy input; verified.graph.sympy_convert does not import this module)
    from verified.graph.sympy_convert import from_sympy as _from_sympy

    return _from_sympy(exprs, inputs, params, cse=cse, output_names=output_names)

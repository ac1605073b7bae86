"""Everything rigorous: interval arithmetic, the expression graph and its evaluators,
Taylor coefficients of ODE solutions, and (later) the verified ODE solver and the
consistency tests. Knows nothing about robots."""

from verified.graph import Graph, GraphBuilder, Op, Tracer, from_sympy, trace
from verified.arith.interval import Interval, IntervalError
from verified.series.taylor import TaylorODE

__all__ = ["Interval", "IntervalError", "Graph", "GraphBuilder", "Op", "Tracer", "from_sympy", "trace", "TaylorODE"]

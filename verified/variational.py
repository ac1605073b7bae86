"""The variational equations of an ODE graph, built as another graph.

For ``x' = f(x, p)`` the sensitivity ``V = dx(t)/dx(t0)`` satisfies ``V' = Df(x) V``,
``V(t0) = I``. The Taylor coefficients of ``V`` are the derivatives of the Taylor
coefficients of ``x`` with respect to the initial value, so running the ordinary
Taylor interpreter (:mod:`verified.taylor`) on the graph built here encloses the
Jacobian of the Taylor map over a box -- what the Lohner step needs.

The graph has inputs ``(x_1..x_n, V_11, V_12, .., V_nn)`` (V row-major) and outputs
``(f_1..f_n, (Df V)_11, .., (Df V)_nn)``. Derivatives are formed by forward-mode
rules node by node, one direction per column of ``V``, with zeros tracked
symbolically so constants and parameters cost nothing.
"""

from __future__ import annotations

from .graph import Graph, GraphBuilder, Op
from .graph_ops import embed, forward_mode

__all__ = ["variational_graph"]


def variational_graph(graph: Graph) -> Graph:
    """Return the graph of ``(x, V) -> (f(x, p), Df(x, p) V)`` for a square ``graph``."""
    n = graph.n_inputs
    if graph.n_outputs != n:
        raise ValueError(f"variational equations need a square ODE graph, got {n} inputs and {graph.n_outputs} outputs")
    names = list(graph.input_names) + [f"V_{i}_{j}" for i in range(n) for j in range(n)]
    b = GraphBuilder(n + n * n, graph.n_params, input_names=names, param_names=graph.param_names)
    x = [b.input(i) for i in range(n)]
    p = [b.param(i) for i in range(graph.n_params)]
    # column j of V is the seed of direction j
    seeds = [[b.input(n + i * n + j) for j in range(n)] for i in range(n)]
    values, derivatives = forward_mode(b, graph, x, p, seeds)
    zero = b.const(0)
    outputs = list(values)
    for di in derivatives:
        outputs += [zero if dij is None else dij for dij in di]
    out_names = list(graph.output_names) + [f"dV_{i}_{j}" for i in range(n) for j in range(n)]
    return b.build(outputs, out_names)


def params_as_states(graph: Graph) -> Graph:
    """The ODE ``(x, p)' = (f(x, p), 0)``: parameters become constant states.

    Uncertain parameters then enter the solver's linear part (the matrix acting on the
    initial box) instead of being re-wrapped into the error term every step.
    """
    n, p = graph.n_inputs, graph.n_params
    b = GraphBuilder(n + p, 0, input_names=list(graph.input_names) + list(graph.param_names))
    outputs = embed(b, graph, [b.input(i) for i in range(n)], [b.input(n + k) for k in range(p)])
    outputs += [b.const(0)] * p
    return b.build(outputs, list(graph.output_names) + [f"d{name}" for name in graph.param_names])

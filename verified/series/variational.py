"""The variational equations of an ODE graph, built as another graph.

For ``x' = f(x, p)`` the sensitivity ``V = dx(t)/dx(t0)`` satisfies ``V' = Df(x) V``,
``V(t0) = I``. The Taylor coefficients of ``V`` are the derivatives of the Taylor
coefficients of ``x`` with respect to the initial value, so running the ordinary
Taylor interpreter (:mod:`verified.series.taylor`) on the graph built here encloses the
Jacobian of the Taylor map over a box -- what the Lohner step needs.

The graph has inputs ``(x_1..x_n, V_11, V_12, .., V_nn)`` (V row-major) and outputs
``(f_1..f_n, (Df V)_11, .., (Df V)_nn)``. Derivatives are formed by forward-mode
rules node by node, one direction per column of ``V``, with zeros tracked
symbolically so constants and parameters cost nothing.
"""

from __future__ import annotations

from verified.graph import Graph, GraphBuilder
from verified.graph.ops import embed, forward_mode

__all__ = ["variational_graph", "second_variational_graph", "pair_index", "params_as_states"]


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


def pair_index(n: int) -> list[tuple[int, int]]:
    """The pairs ``(a, b)``, ``a <= b < n``, in the order :func:`second_variational_graph`
    stores ``W_ab``."""
    return [(a, b) for a in range(n) for b in range(a, n)]


def second_variational_graph(graph: Graph, directions: int | None = None) -> Graph:
    """The graph of ``(x, V, W) -> (f, Df V, W')`` with, for each pair ``a <= b``,

        W_ab' = D^2 f[V_a, V_b] + Df W_ab,      W_ab(t0) = 0,  V(t0) = I,

    the second variational equations: ``W_ab`` is the second derivative
    ``d^2 x(t) / dx_a(t0) dx_b(t0)`` (``V_a`` = column ``a`` of ``V``). Run through a
    Taylor interpreter from ``(c, I, 0)``, the coefficients of ``W`` are the Hessians
    of the Taylor coefficients ``x_[k]`` at ``c`` (over a box: enclosures of them over
    the box) -- what a second-order set step needs (:mod:`verified.sets.second_order`).

    Inputs ``(x_1..x_n, V row-major, W_ab for pair_index(p), each an n-vector)``;
    outputs in the same layout. Built by forward mode twice: once for ``Df(x) v`` as a
    graph of ``(x, v)``, then again on that graph in the directions ``(V_b, W_ab)``.

    ``directions=p`` (default ``n``) makes ``V`` an ``n x p`` matrix: started from
    ``V(t0) = C`` (n, p), ``W_ab`` is then the second derivative along columns ``a``
    and ``b`` of ``C``, ``C_a^T D^2 x(t) C_b``. That costs ``1 + p + p(p+1)/2`` times
    the right-hand side instead of ``1 + n + n(n+1)/2``: what a second-order set whose
    parameters move it in ``p < n`` directions needs (a UR5 with an uncertain pose and
    an exact velocity: p = 6 of n = 12).
    """
    n = graph.n_inputs
    if graph.n_outputs != n:
        raise ValueError(f"variational equations need a square ODE graph, got {n} inputs and {graph.n_outputs} outputs")
    p_dir = n if directions is None else int(directions)
    if not 1 <= p_dir <= n:
        raise ValueError(f"directions must be in [1, {n}], got {directions!r}")
    pairs = pair_index(p_dir)
    # F1(x, v) = Df(x) v
    b1 = GraphBuilder(2 * n, graph.n_params, param_names=graph.param_names)
    x1 = [b1.input(i) for i in range(n)]
    p1 = [b1.param(i) for i in range(graph.n_params)]
    _, d1 = forward_mode(b1, graph, x1, p1, [[b1.input(n + i)] for i in range(n)])
    zero1 = b1.const(0)
    F1 = b1.build([zero1 if di[0] is None else di[0] for di in d1])

    names = (list(graph.input_names) + [f"V_{i}_{j}" for i in range(n) for j in range(p_dir)]
             + [f"W_{a}_{c}_{i}" for a, c in pairs for i in range(n)])
    b = GraphBuilder(n + n * p_dir + n * len(pairs), graph.n_params, input_names=names, param_names=graph.param_names)
    x = [b.input(i) for i in range(n)]
    p = [b.param(i) for i in range(graph.n_params)]
    V = [[b.input(n + i * p_dir + j) for j in range(p_dir)] for i in range(n)]  # V[i][j]
    W = {pc: [b.input(n + n * p_dir + k * n + i) for i in range(n)] for k, pc in enumerate(pairs)}
    values, dV = forward_mode(b, graph, x, p, V)  # seeds[i][j] = V[i][j]: direction j = column j
    zero = b.const(0)
    outputs = list(values)
    for di in dV:
        outputs += [zero if dij is None else dij for dij in di]
    dW = {}
    for a in range(p_dir):
        partners = [c for c in range(a, p_dir)]
        # directions k <-> pair (a, partners[k]): dx = V_c, dv = W_ac
        seeds = [[V[i][c] for c in partners] for i in range(n)] + [[W[(a, c)][i] for c in partners] for i in range(n)]
        _, d = forward_mode(b, F1, x + [V[i][a] for i in range(n)], p, seeds)
        for k, c in enumerate(partners):
            dW[(a, c)] = [zero if d[i][k] is None else d[i][k] for i in range(n)]
    for pc in pairs:
        outputs += dW[pc]
    out_names = (list(graph.output_names) + [f"dV_{i}_{j}" for i in range(n) for j in range(p_dir)]
                 + [f"dW_{a}_{c}_{i}" for a, c in pairs for i in range(n)])
    return b.build(outputs, out_names)

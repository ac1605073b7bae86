"""Building graphs from graphs: embedding, forward-mode derivatives, ODE augmentation.

Everything here copies the nodes of existing graphs into a :class:`GraphBuilder`
(hash-consing merges common subexpressions of the pieces), so the results are plain
graphs that every evaluator and the Taylor interpreter run unchanged.

- :func:`embed` -- the outputs of a graph applied to node ids of a builder;
- :func:`forward_mode` -- values and directional derivatives (several seeds at once),
  the rule set the variational equations and ``dH/dt`` share;
- :func:`rate_along` -- ``dH/dt = grad H(x) . f(x)`` of a scalar function along an
  ODE, by forward-mode differentiation (the paper's FADBAD++ step in mode (ii));
- :func:`augment_with_rate` -- the ODE ``(x, h)' = (f(x), r(x))``, the extra state
  carrying ``H_V`` of eq. (12);
- :func:`negated` -- ``x' = -f(x)``: the same ODE backward in time.
"""

from __future__ import annotations

from typing import Sequence

from verified.graph.forward_rules import RULES, Algebra
from verified.graph import Graph, GraphBuilder, Op

__all__ = ["embed", "forward_mode", "rate_along", "augment_with_rate", "negated", "difference"]


def _copy_node(b: GraphBuilder, op: Op, args: list[int], data):
    if op == Op.CONST:
        return b.const_enclosure(*data)
    if op == Op.POW:
        return b.pow(args[0], data)
    return getattr(b, op.name.lower())(*args)


def embed(b: GraphBuilder, graph: Graph, inputs: Sequence[int], params: Sequence[int] = ()) -> list[int]:
    """Copy ``graph`` into builder ``b`` with its inputs bound to the node ids ``inputs``
    (and parameters to ``params``); returns the node ids of its outputs."""
    if len(inputs) != graph.n_inputs or len(params) != graph.n_params:
        raise ValueError(f"embedding needs {graph.n_inputs} inputs and {graph.n_params} params, "
                         f"got {len(inputs)} and {len(params)}")
    ids: list[int] = []
    for node in graph.nodes:
        if node.op == Op.INPUT:
            ids.append(inputs[node.data])
        elif node.op == Op.PARAM:
            ids.append(params[node.data])
        else:
            ids.append(_copy_node(b, node.op, [ids[a] for a in node.args], node.data))
    return [ids[o] for o in graph.outputs]


class _BuilderAlgebra(Algebra):
    """The algebra of :mod:`verified.graph.forward_rules` on node ids of a builder: values and
    derivatives (one direction each) are nodes, ``None`` a structural zero."""

    def __init__(self, b: GraphBuilder):
        super().__init__(b)
        self.b = b

    def num(self, c):
        return self.b.const(c)

    def d_scale(self, f, p):
        return None if p is None else self.b.mul(f, p)

    def d_div(self, p, x):
        return None if p is None else self.b.div(p, x)


def forward_mode(b: GraphBuilder, graph: Graph, inputs: Sequence[int], params: Sequence[int],
                 seeds: Sequence[Sequence[int | None]]):
    """Values and directional derivatives of ``graph``'s outputs, built into ``b``.

    ``seeds[i][k]`` is the node id of the derivative of input ``i`` in direction ``k``
    (``None`` = structurally zero). Returns ``(values, derivatives)``: the output node
    ids and, per output, a list of ``k`` node ids or ``None`` (zero). The rules are
    :data:`verified.graph.forward_rules.RULES` (shared with :class:`verified.graph.evaluate.DualDomain`).
    """
    n_dir = len(seeds[0]) if seeds else 0
    A = _BuilderAlgebra(b)
    val: list[int] = []
    der: list[list[int | None]] = []
    for node in graph.nodes:
        op, args, data = node.op, node.args, node.data
        if op == Op.CONST:
            v, d = b.const_enclosure(*data), [None] * n_dir
        elif op == Op.INPUT:
            v, d = inputs[data], list(seeds[data])
        elif op == Op.PARAM:
            v, d = params[data], [None] * n_dir
        else:
            rule = RULES.get(op)
            if rule is None:  # pragma: no cover
                raise NotImplementedError(f"no derivative rule for {op.name}")
            u, du = val[args[0]], der[args[0]]
            w, dw = (val[args[1]], der[args[1]]) if len(args) == 2 else (None, [None] * n_dir)
            v = rule.value(A, u, w, data)
            f = rule.factor(A, u, v, data) if rule.factor is not None else None
            d = [rule.deriv(A, p, q, u, w, v, f, data) for p, q in zip(du, dw)]
        val.append(v)
        der.append(d)
    return [val[o] for o in graph.outputs], [der[o] for o in graph.outputs]


def gradient_graph(func: Graph, n_wrt: int | None = None, names=None) -> Graph:
    """The graph of ``(x, p) -> d func / d x_i``, ``i < n_wrt`` (default: every input), for
    a scalar ``func``, by forward mode with one unit seed per input; same inputs and
    parameters as ``func``."""
    if func.n_outputs != 1:
        raise ValueError(f"gradient_graph needs a scalar function, got {func.n_outputs} outputs")
    n = func.n_inputs if n_wrt is None else int(n_wrt)
    b = GraphBuilder(func.n_inputs, func.n_params, input_names=func.input_names, param_names=func.param_names)
    x = [b.input(i) for i in range(func.n_inputs)]
    p = [b.param(k) for k in range(func.n_params)]
    one = b.const(1.0)
    seeds = [[one if i == k else None for k in range(n)] for i in range(func.n_inputs)]
    _, (d,) = forward_mode(b, func, x, p, seeds)
    return b.build([b.const(0) if v is None else v for v in d],
                   list(names) if names is not None else [f"d{nm}" for nm in func.input_names[:n]])


def params_to_inputs(graph: Graph) -> Graph:
    """``graph(x, p)`` as a graph of ``y = (x, p)`` without parameters (as the solver
    carries uncertain parameters: constant states after the ODE's)."""
    if graph.n_params == 0:
        return graph
    n, p = graph.n_inputs, graph.n_params
    b = GraphBuilder(n + p, 0, input_names=list(graph.input_names) + list(graph.param_names))
    outs = embed(b, graph, [b.input(i) for i in range(n)], [b.input(n + k) for k in range(p)])
    return b.build(outs, list(graph.output_names))


def _check_same_inputs(a: Graph, b: Graph, what: str):
    if a.n_inputs != b.n_inputs:
        raise ValueError(f"{what}: the graphs take {a.n_inputs} and {b.n_inputs} inputs")
    if a.n_params != b.n_params:
        raise ValueError(f"{what}: the graphs take {a.n_params} and {b.n_params} parameters")


def rate_along(func: Graph, rhs: Graph, name: str = "dHdt") -> Graph:
    """The graph of ``x -> grad func(x) . f(x)``: the rate of the scalar ``func`` along
    the ODE ``x' = f(x)`` (eq. (7) evaluated without simplification), by forward-mode
    automatic differentiation with the single seed ``dx = f(x)``."""
    _check_same_inputs(func, rhs, "rate_along")
    if func.n_outputs != 1:
        raise ValueError(f"rate_along needs a scalar function, got {func.n_outputs} outputs")
    b = GraphBuilder(rhs.n_inputs, rhs.n_params, input_names=rhs.input_names, param_names=rhs.param_names)
    x = [b.input(i) for i in range(rhs.n_inputs)]
    p = [b.param(i) for i in range(rhs.n_params)]
    f = embed(b, rhs, x, p)
    (_,), (d,) = forward_mode(b, func, x, p, [[fi] for fi in f])
    return b.build([b.const(0) if d[0] is None else d[0]], [name])


def augment_with_rate(rhs: Graph, rate: Graph | None, name: str = "h") -> Graph:
    """The ODE ``(x, h)' = (f(x), rate(x))`` with one extra state ``h`` (appended last).

    ``rate=None`` means ``h' = 0`` (a conserved quantity: ``h`` keeps its initial
    enclosure and its correlation with the initial states)."""
    n = rhs.n_inputs
    if rate is not None:
        _check_same_inputs(rhs, rate, "augment_with_rate")
    b = GraphBuilder(n + 1, rhs.n_params, input_names=list(rhs.input_names) + [name], param_names=rhs.param_names)
    x = [b.input(i) for i in range(n)]
    p = [b.param(i) for i in range(rhs.n_params)]
    outs = embed(b, rhs, x, p)
    outs.append(b.const(0) if rate is None else embed(b, rate, x, p)[0])
    return b.build(outs, list(rhs.output_names) + [f"d{name}"])


def difference(func: Graph, n_inputs: int, index: int, name: str = "residual") -> Graph:
    """The graph of ``(x_1..x_n_inputs) -> func(x_1..x_m) - x_index`` (``m`` = func's
    inputs, ``m <= n_inputs``): e.g. ``H(x) - h`` on the augmented state, which is 0
    on every true trajectory."""
    if func.n_outputs != 1 or func.n_inputs > n_inputs or not 0 <= index < n_inputs:
        raise ValueError("difference needs a scalar function of the leading inputs and a valid index")
    b = GraphBuilder(n_inputs, func.n_params, param_names=func.param_names)
    xs = [b.input(i) for i in range(n_inputs)]
    (v,) = embed(b, func, xs[:func.n_inputs], [b.param(i) for i in range(func.n_params)])
    return b.build([b.sub(v, xs[index])], [name])


def negated(rhs: Graph) -> Graph:
    """``x' = -f(x)``: solutions are those of ``f`` run backward in time."""
    b = GraphBuilder(rhs.n_inputs, rhs.n_params, input_names=rhs.input_names, param_names=rhs.param_names)
    outs = embed(b, rhs, [b.input(i) for i in range(rhs.n_inputs)], [b.param(i) for i in range(rhs.n_params)])
    return b.build([b.neg(o) for o in outs], [f"-{name}" for name in rhs.output_names])

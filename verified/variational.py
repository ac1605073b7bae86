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

__all__ = ["variational_graph"]


def variational_graph(graph: Graph) -> Graph:
    """Return the graph of ``(x, V) -> (f(x, p), Df(x, p) V)`` for a square ``graph``."""
    n = graph.n_inputs
    if graph.n_outputs != n:
        raise ValueError(f"variational equations need a square ODE graph, got {n} inputs and {graph.n_outputs} outputs")
    names = list(graph.input_names) + [f"V_{i}_{j}" for i in range(n) for j in range(n)]
    b = GraphBuilder(n + n * n, graph.n_params, input_names=names, param_names=graph.param_names)
    val = []  # new node id of each original node
    der = []  # per original node: list of n new ids (None = structurally zero)

    def dsum(x, y):
        if x is None:
            return y
        if y is None:
            return x
        return b.add(x, y)

    def dscale(factor, d):
        return None if d is None else b.mul(factor, d)

    for node in graph.nodes:
        op, args, data = node.op, node.args, node.data
        if op == Op.CONST:
            v = b.const_enclosure(*data)
            d = [None] * n
        elif op == Op.INPUT:
            v = b.input(data)
            d = [b.input(n + data * n + j) for j in range(n)]
        elif op == Op.PARAM:
            v = b.param(data)
            d = [None] * n
        else:
            u = val[args[0]]
            du = der[args[0]]
            if op in (Op.ADD, Op.SUB, Op.MUL, Op.DIV):
                w = val[args[1]]
                dw = der[args[1]]
            if op == Op.ADD:
                v = b.add(u, w)
                d = [dsum(p, q) for p, q in zip(du, dw)]
            elif op == Op.SUB:
                v = b.sub(u, w)
                d = [p if q is None else (b.neg(q) if p is None else b.sub(p, q)) for p, q in zip(du, dw)]
            elif op == Op.MUL:
                v = b.mul(u, w)
                d = [dsum(dscale(w, p), dscale(u, q)) for p, q in zip(du, dw)]
            elif op == Op.DIV:
                v = b.div(u, w)
                # (u / w)' = (u' - v w') / w
                d = []
                for p, q in zip(du, dw):
                    num = p if q is None else (b.neg(b.mul(v, q)) if p is None else b.sub(p, b.mul(v, q)))
                    d.append(None if num is None else b.div(num, w))
            elif op == Op.NEG:
                v = b.neg(u)
                d = [None if p is None else b.neg(p) for p in du]
            elif op == Op.SQR:
                v = b.sqr(u)
                two_u = b.mul(b.const(2), u)
                d = [dscale(two_u, p) for p in du]
            elif op == Op.POW:
                v = b.pow(u, data)
                factor = b.mul(b.const(data), b.pow(u, data - 1))
                d = [dscale(factor, p) for p in du]
            elif op == Op.SQRT:
                v = b.sqrt(u)
                d = [None if p is None else b.div(p, b.mul(b.const(2), v)) for p in du]
            elif op == Op.EXP:
                v = b.exp(u)
                d = [dscale(v, p) for p in du]
            elif op == Op.LOG:
                v = b.log(u)
                d = [None if p is None else b.div(p, u) for p in du]
            elif op == Op.SIN:
                v = b.sin(u)
                c = b.cos(u)
                d = [dscale(c, p) for p in du]
            elif op == Op.COS:
                v = b.cos(u)
                ms = b.neg(b.sin(u))
                d = [dscale(ms, p) for p in du]
            elif op == Op.TAN:
                v = b.tan(u)
                sec2 = b.add(b.const(1), b.sqr(v))
                d = [dscale(sec2, p) for p in du]
            elif op == Op.ATAN:
                v = b.atan(u)
                den = b.add(b.const(1), b.sqr(u))
                d = [None if p is None else b.div(p, den) for p in du]
            else:  # pragma: no cover
                raise NotImplementedError(f"no derivative rule for {op.name}")
        val.append(v)
        der.append(d)

    zero = b.const(0)
    outputs = [val[o] for o in graph.outputs]
    for i in range(n):
        di = der[graph.outputs[i]]
        outputs += [zero if di[j] is None else di[j] for j in range(n)]
    out_names = list(graph.output_names) + [f"dV_{i}_{j}" for i in range(n) for j in range(n)]
    return b.build(outputs, out_names)


def params_as_states(graph: Graph) -> Graph:
    """The ODE ``(x, p)' = (f(x, p), 0)``: parameters become constant states.

    Uncertain parameters then enter the solver's linear part (the matrix acting on the
    initial box) instead of being re-wrapped into the error term every step.
    """
    n, p = graph.n_inputs, graph.n_params
    b = GraphBuilder(n + p, 0, input_names=list(graph.input_names) + list(graph.param_names))
    ids = []
    for node in graph.nodes:
        op, args, data = node.op, [ids[a] for a in node.args], node.data
        if op == Op.CONST:
            ids.append(b.const_enclosure(*data))
        elif op == Op.INPUT:
            ids.append(b.input(data))
        elif op == Op.PARAM:
            ids.append(b.input(n + data))
        elif op == Op.POW:
            ids.append(b.pow(args[0], data))
        else:
            ids.append(getattr(b, op.name.lower())(*args))
    zero = b.const(0)
    outputs = [ids[o] for o in graph.outputs] + [zero] * p
    return b.build(outputs, list(graph.output_names) + [f"d{name}" for name in graph.param_names])

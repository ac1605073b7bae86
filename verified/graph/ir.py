# Whole: Graph and GraphBuilder are one data structure.
"""The expression graph itself: :class:`Graph` (an immutable DAG) and :class:`GraphBuilder`.

The IR is described in :mod:`verified.graph`, the public front that also re-exports
the front ends (:func:`~verified.graph.trace`, :func:`~verified.graph.from_sympy`).
Layering (each module imports only the ones before it, so there is no import cycle)::

    opcodes  ->  evaluate  ->  ir  ->  tracer, graph_sympy  ->  graph (re-exports)

Opcodes and :class:`Node` live in :mod:`verified.graph.opcodes`; the evaluators that
:meth:`Graph.eval_float` and friends call live in :mod:`verified.graph.evaluate`.

Constants are rigorous: a constant node stores ``(lo, hi, value)`` floats with
``lo <= exact <= hi`` (outward rounded enclosure of the exact value) and ``value`` the
double nearest to it. Interval evaluation uses ``[lo, hi]``, float evaluation ``value``.
"""
from __future__ import annotations

import hashlib
import json
import math
from fractions import Fraction
from typing import Any, Iterable, Sequence

import numpy as np

from verified.graph import evaluate as _evaluate
from verified.arith.exact import enclose_approximation, enclose_fraction
from verified.graph.opcodes import _ARITY, _BY_NAME, LEAF_OPS, Node, Op

__all__ = ["Graph", "GraphBuilder", "enclose_rational", "enclose_approximation"]

FORMAT_NAME = "verified.graph"
FORMAT_VERSION = 1


# --------------------------------------------------------------------------- constants


def enclose_rational(q: Fraction | int) -> tuple[float, float, float]:
    """Tightest double enclosure ``(lo, hi, value)`` of the exact rational ``q``.

    ``value`` is ``q`` rounded to nearest (Python's int/int division is correctly
    rounded); ``lo == hi == value`` when ``q`` is a double. Raises ``ValueError`` if
    ``q`` is outside the finite double range.
    """
    q = Fraction(q)
    try:
        lo, hi = enclose_fraction(q)
    except OverflowError:
        raise ValueError(f"constant {q} is outside the double range") from None
    # + 0.0: no negative zero in constants (a tiny negative q rounds to -0.0): it would
    # split hash-consing of 0
    f = float(q) + 0.0
    lo, hi = lo + 0.0, hi + 0.0
    if not (math.isfinite(f) and math.isfinite(lo) and math.isfinite(hi)):
        raise ValueError(f"constant {q} is outside the double range")
    return lo, hi, f


def _check_enclosure(lo: float, hi: float, value: float) -> tuple[float, float, float]:
    lo, hi, value = float(lo), float(hi), float(value)
    if not all(math.isfinite(t) for t in (lo, hi, value)):
        raise ValueError(f"constant enclosure must be finite, got [{lo!r}, {hi!r}] value {value!r}")
    if not lo <= value <= hi:
        raise ValueError(f"constant enclosure needs lo <= value <= hi, got {lo!r}, {value!r}, {hi!r}")
    # normalize -0.0 so that equal constants share one node
    return lo + 0.0, hi + 0.0, value + 0.0


# --------------------------------------------------------------------------- graph


def _default_names(prefix: str, count: int, names: Sequence[str] | None, what: str) -> tuple[str, ...]:
    if names is None:
        return tuple(f"{prefix}{i}" for i in range(count))
    names = tuple(str(s) for s in names)
    if len(names) != count:
        raise ValueError(f"expected {count} {what} names, got {len(names)}: {names}")
    return names


class Graph:
    """Immutable expression DAG for ``f: R^n x R^p -> R^m``.

    Attributes:
        nodes: tuple of :class:`Node` in topological order (arguments first).
        outputs: node index of each of the ``m`` outputs.
        input_names, param_names, output_names: tuples of str.
        n_inputs, n_params, n_outputs: ``n``, ``p``, ``m``.

    Evaluate with :meth:`eval_float`, :meth:`eval_interval`, :meth:`jacobian_float`,
    :meth:`jacobian_interval` (all batched over leading axes), or with any
    :class:`verified.graph.evaluate.Domain` through :func:`verified.graph.evaluate.evaluate`.
    """

    def __init__(
        self,
        nodes: Sequence[Node],
        outputs: Sequence[int],
        input_names: Sequence[str],
        param_names: Sequence[str] = (),
        output_names: Sequence[str] | None = None,
    ):
        self.input_names = tuple(str(s) for s in input_names)
        self.param_names = tuple(str(s) for s in param_names)
        self.nodes = tuple(self._check_node(i, node) for i, node in enumerate(nodes))
        self.outputs = tuple(int(o) for o in outputs)
        for o in self.outputs:
            if not 0 <= o < len(self.nodes):
                raise ValueError(f"output node {o} out of range (graph has {len(self.nodes)} nodes)")
        self.output_names = _default_names("y", len(self.outputs), output_names, "output")
        self._release_plan = self._plan_releases()

    # -- construction helpers

    def _check_node(self, i: int, node: Sequence) -> Node:
        op, args, data = node
        op = Op(op)
        args = tuple(int(a) for a in args)
        if len(args) != _ARITY[op]:
            raise ValueError(f"node {i}: {op.name.lower()} takes {_ARITY[op]} arguments, got {len(args)}")
        if any(not 0 <= a < i for a in args):
            raise ValueError(f"node {i}: arguments {args} must refer to earlier nodes (topological order)")
        if op == Op.CONST:
            data = _check_enclosure(*data)
        elif op in (Op.INPUT, Op.PARAM):
            count = len(self.input_names) if op == Op.INPUT else len(self.param_names)
            data = int(data)
            if not 0 <= data < count:
                raise ValueError(f"node {i}: {op.name.lower()} index {data} out of range (have {count})")
        elif op == Op.POW:
            if int(data) != data or data < 3:
                raise ValueError(f"node {i}: pow exponent must be an integer >= 3, got {data!r}")
            data = int(data)
        else:
            data = None
        return Node(op, args, data)

    def _plan_releases(self) -> tuple[tuple[int, ...], ...]:
        """For each node i, the nodes whose value is not needed after evaluating i.

        Evaluators drop those values to bound memory on large graphs x large batches.
        """
        last_use = list(range(len(self.nodes)))
        for i, node in enumerate(self.nodes):
            for a in node.args:
                last_use[a] = i
        keep = set(self.outputs)
        plan: list[list[int]] = [[] for _ in self.nodes]
        for j, i in enumerate(last_use):
            if j not in keep:
                plan[i].append(j)
        return tuple(tuple(p) for p in plan)

    # -- sizes and names

    @property
    def n_inputs(self) -> int:
        return len(self.input_names)

    @property
    def n_params(self) -> int:
        return len(self.param_names)

    @property
    def n_outputs(self) -> int:
        return len(self.outputs)

    @property
    def n_nodes(self) -> int:
        """All nodes, including constants, inputs and parameters."""
        return len(self.nodes)

    @property
    def n_ops(self) -> int:
        """Number of operation nodes (everything except const/input/param)."""
        return sum(1 for node in self.nodes if node.op not in LEAF_OPS)

    def op_counts(self) -> dict[str, int]:
        """Histogram of opcodes, e.g. ``{'mul': 12, 'sin': 2, ...}``."""
        counts: dict[str, int] = {}
        for node in self.nodes:
            name = node.op.name.lower()
            counts[name] = counts.get(name, 0) + 1
        return counts

    # -- evaluation (implementations in verified.graph.evaluate)

    def eval_float(self, x, p=None) -> np.ndarray:
        """Float evaluation. ``x``: (..., n), ``p``: (..., p) or (p,) -> ndarray (..., m)."""
        return _evaluate.eval_float(self, x, p)

    def eval_interval(self, x, p=None):
        """Interval enclosure. ``x``: Interval or floats (..., n); ``p`` likewise -> Interval (..., m)."""
        return _evaluate.eval_interval(self, x, p)

    def jacobian_float(self, x, p=None, *, wrt: str = "x") -> np.ndarray:
        """Forward-mode Jacobian -> (..., m, k); ``wrt`` is "x" (k = n), "p" (k = p) or "xp" (k = n + p)."""
        return _evaluate.jacobian_float(self, x, p, wrt=wrt)

    def evaluate(self, domain, inputs: Sequence, params: Sequence = ()) -> list:
        """Outputs in any :class:`verified.graph.evaluate.Domain`, given one domain value per
        input and per parameter (see :func:`verified.graph.evaluate.evaluate`)."""
        return _evaluate.evaluate(self, domain, inputs, params)

    def jacobian_interval(self, x, p=None, *, wrt: str = "x"):
        """Interval enclosure of the Jacobian over the box -> Interval (..., m, k); see :meth:`jacobian_float`."""
        return _evaluate.jacobian_interval(self, x, p, wrt=wrt)

    # -- serialization

    def to_dict(self) -> dict:
        """JSON-able description; constants are exact (``float.hex`` strings)."""
        nodes = []
        for node in self.nodes:
            if node.op == Op.CONST:
                data = [float.hex(t) for t in node.data]
            else:
                data = node.data
            nodes.append([node.op.name.lower(), list(node.args), data])
        return {
            "format": FORMAT_NAME,
            "version": FORMAT_VERSION,
            "inputs": list(self.input_names),
            "params": list(self.param_names),
            "outputs": list(self.output_names),
            "nodes": nodes,
            "output_nodes": list(self.outputs),
        }

    @classmethod
    def from_dict(cls, d: dict) -> "Graph":
        """Inverse of :meth:`to_dict`; validates the structure (raises ``ValueError``)."""
        if not isinstance(d, dict) or d.get("format") != FORMAT_NAME:
            raise ValueError(f"not a serialized graph (expected format {FORMAT_NAME!r})")
        if d.get("version") != FORMAT_VERSION:
            raise ValueError(f"unsupported graph format version {d.get('version')!r} (expected {FORMAT_VERSION})")
        nodes = []
        for i, entry in enumerate(d["nodes"]):
            name, args, data = entry
            if name not in _BY_NAME:
                raise ValueError(f"node {i}: unknown opcode {name!r}")
            op = _BY_NAME[name]
            if op == Op.CONST:
                data = tuple(float.fromhex(t) if isinstance(t, str) else float(t) for t in data)
            nodes.append((op, args, data))
        return cls(nodes, d["output_nodes"], d["inputs"], d["params"], d["outputs"])

    def fingerprint(self) -> str:
        """SHA-256 hex digest of the canonical serialized form (a cache key; equal
        graphs, including names, have equal fingerprints)."""
        text = json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()

    def select(self, outputs: Sequence[int | str]) -> "Graph":
        """Graph of a subset of the outputs (by index or name), pruned to what they need.

        Inputs and parameters are kept (same ``n`` and ``p``), so boxes still fit."""
        idx = []
        for o in outputs:
            if isinstance(o, str):
                if o not in self.output_names:
                    raise ValueError(f"no output named {o!r}; outputs are {self.output_names}")
                o = self.output_names.index(o)
            if not -self.n_outputs <= int(o) < self.n_outputs:
                raise IndexError(f"output index {o} out of range (graph has {self.n_outputs} outputs)")
            idx.append(int(o) % self.n_outputs)
        nodes, new_outputs = _prune(self.nodes, [self.outputs[i] for i in idx])
        return Graph(nodes, new_outputs, self.input_names, self.param_names, [self.output_names[i] for i in idx])

    def to_sympy(self, inputs=None, params=None) -> list:
        """Debugging aid: list of ``m`` sympy expressions (constants as their float value);
        see :func:`verified.graph.evaluate.to_sympy`."""
        return _evaluate.to_sympy(self, inputs, params)

    # -- dunder

    def __eq__(self, other) -> bool:
        if not isinstance(other, Graph):
            return NotImplemented
        return (
            self.nodes == other.nodes
            and self.outputs == other.outputs
            and self.input_names == other.input_names
            and self.param_names == other.param_names
            and self.output_names == other.output_names
        )

    def __hash__(self) -> int:
        return hash((self.nodes, self.outputs))

    def _node_label(self, i: int) -> str:
        node = self.nodes[i]
        if node.op == Op.INPUT:
            return f"input {self.input_names[node.data]}"
        if node.op == Op.PARAM:
            return f"param {self.param_names[node.data]}"
        if node.op == Op.CONST:
            lo, hi, value = node.data
            return f"const {value!r}" if lo == hi else f"const {value!r} in [{lo!r}, {hi!r}]"
        args = ", ".join(f"%{a}" for a in node.args)
        if node.op == Op.POW:
            args += f", {node.data}"
        return f"{node.op.name.lower()}({args})"

    def pretty(self, max_lines: int | None = None) -> str:
        """Multi-line listing: one line per node, then the outputs."""
        head = (
            f"Graph(n_inputs={self.n_inputs}, n_params={self.n_params}, "
            f"n_outputs={self.n_outputs}, n_ops={self.n_ops}, n_nodes={self.n_nodes})"
        )
        lines = [f"  %{i} = {self._node_label(i)}" for i in range(len(self.nodes))]
        if max_lines is not None and len(lines) > max_lines:
            lines = lines[:max_lines] + [f"  ... ({len(self.nodes) - max_lines} more nodes)"]
        outs = ", ".join(f"{name}=%{o}" for name, o in zip(self.output_names, self.outputs))
        return "\n".join([head, *lines, f"  outputs: {outs}"])

    def __repr__(self) -> str:
        return self.pretty(max_lines=40)


def _prune(nodes: Sequence[Node], outputs: Sequence[int]) -> tuple[list[Node], list[int]]:
    """Keep only the nodes the outputs depend on, renumbered in the same (topological) order."""
    needed = set()
    stack = list(outputs)
    while stack:
        i = stack.pop()
        if i not in needed:
            needed.add(i)
            stack.extend(nodes[i].args)
    order = sorted(needed)
    renumber = {old: new for new, old in enumerate(order)}
    kept = [Node(nodes[i].op, tuple(renumber[a] for a in nodes[i].args), nodes[i].data) for i in order]
    return kept, [renumber[o] for o in outputs]


# --------------------------------------------------------------------------- builder


class GraphBuilder:
    """Appends nodes in topological order, sharing equal subexpressions.

    Every method returns a node id (int). Simplifications applied at build time are
    exact for every finite argument value (so interval and float semantics are both
    preserved): ``x+0 -> x``, ``x-0 -> x``, ``0-x -> -x``, ``x-x -> 0``, ``x*1 -> x``,
    ``x*(-1) -> -x``, ``x*0 -> 0``, ``x*x -> sqr(x)``, ``x/1 -> x``, ``x/(-1) -> -x``,
    ``x+(-y) -> x-y``, ``x-(-y) -> x+y``, ``-(-x) -> x``, ``sqr(-x) -> sqr(x)``,
    ``(-x)*y -> -(x*y)``, ``(-x)/y -> -(x/y)`` (negations move outward to be absorbed),
    ``x**0 -> 1``, ``x**1 -> x``, ``x**2 -> sqr(x)``, ``x**-k -> 1/x**k``; constant
    folding only when the double result is exact (checked with rationals).
    """

    def __init__(
        self,
        n_inputs: int,
        n_params: int = 0,
        input_names: Sequence[str] | None = None,
        param_names: Sequence[str] | None = None,
    ):
        self.input_names = _default_names("x", n_inputs, input_names, "input")
        self.param_names = _default_names("p", n_params, param_names, "param")
        self._nodes: list[Node] = []
        self._index: dict[tuple, int] = {}

    def __len__(self) -> int:
        return len(self._nodes)

    def node(self, i: int) -> Node:
        return self._nodes[i]

    def _add_node(self, op: Op, args: tuple[int, ...] = (), data: Any = None) -> int:
        key = (op, args, data)
        found = self._index.get(key)
        if found is not None:
            return found
        self._nodes.append(Node(op, args, data))
        self._index[key] = len(self._nodes) - 1
        return len(self._nodes) - 1

    def _check_id(self, a: int) -> int:
        if not isinstance(a, (int, np.integer)) or not 0 <= a < len(self._nodes):
            raise ValueError(f"{a!r} is not a node of this builder")
        return int(a)

    # -- leaves

    def input(self, i: int) -> int:
        if not 0 <= i < len(self.input_names):
            raise IndexError(f"input index {i} out of range (have {len(self.input_names)})")
        return self._add_node(Op.INPUT, (), int(i))

    def param(self, i: int) -> int:
        if not 0 <= i < len(self.param_names):
            raise IndexError(f"param index {i} out of range (have {len(self.param_names)})")
        return self._add_node(Op.PARAM, (), int(i))

    def const(self, value: float | int | Fraction) -> int:
        """Constant of an exact Python number: a float is taken as exact; int and
        Fraction are enclosed outward if not representable."""
        if isinstance(value, Fraction):
            return self.const_enclosure(*enclose_rational(value))
        if isinstance(value, (bool, int, np.integer)):
            return self.const_enclosure(*enclose_rational(Fraction(int(value))))
        if isinstance(value, (float, np.floating)) and not isinstance(value, np.longdouble):
            v = float(value)
            return self.const_enclosure(v, v, v)
        raise TypeError(f"unsupported constant type {type(value).__name__}: {value!r}")

    def const_enclosure(self, lo: float, hi: float, value: float) -> int:
        """Constant with exact value in ``[lo, hi]`` and nearest double ``value``."""
        return self._add_node(Op.CONST, (), _check_enclosure(lo, hi, value))

    def _exact(self, a: int) -> float | None:
        """The value of node ``a`` if it is a constant that is exactly a double."""
        node = self._nodes[a]
        if node.op == Op.CONST and node.data[0] == node.data[1]:
            return node.data[2]
        return None

    def _fold(self, exact_result: Fraction | None) -> int | None:
        """Constant node for an exact rational result if it is a double, else None."""
        if exact_result is None:
            return None
        try:
            lo, hi, value = enclose_rational(exact_result)
        except ValueError:
            return None
        return self.const_enclosure(lo, hi, value) if lo == hi else None

    def _is_neg(self, a: int) -> int | None:
        node = self._nodes[a]
        return node.args[0] if node.op == Op.NEG else None

    # -- binary

    def add(self, a: int, b: int) -> int:
        a, b = self._check_id(a), self._check_id(b)
        ca, cb = self._exact(a), self._exact(b)
        if ca is not None and cb is not None:
            folded = self._fold(Fraction(ca) + Fraction(cb))
            if folded is not None:
                return folded
        if ca == 0.0:
            return b
        if cb == 0.0:
            return a
        nb, na = self._is_neg(b), self._is_neg(a)
        if nb is not None:
            return self.sub(a, nb)
        if na is not None:
            return self.sub(b, na)
        return self._add_node(Op.ADD, (min(a, b), max(a, b)))

    def sub(self, a: int, b: int) -> int:
        a, b = self._check_id(a), self._check_id(b)
        if a == b:
            return self.const(0.0)
        ca, cb = self._exact(a), self._exact(b)
        if ca is not None and cb is not None:
            folded = self._fold(Fraction(ca) - Fraction(cb))
            if folded is not None:
                return folded
        if cb == 0.0:
            return a
        if ca == 0.0:
            return self.neg(b)
        nb = self._is_neg(b)
        if nb is not None:
            return self.add(a, nb)
        return self._add_node(Op.SUB, (a, b))

    def mul(self, a: int, b: int) -> int:
        a, b = self._check_id(a), self._check_id(b)
        if a == b:
            return self.sqr(a)
        ca, cb = self._exact(a), self._exact(b)
        if ca is not None and cb is not None:
            folded = self._fold(Fraction(ca) * Fraction(cb))
            if folded is not None:
                return folded
        for c, other in ((ca, b), (cb, a)):
            if c == 0.0:
                return self.const(0.0)
            if c == 1.0:
                return other
            if c == -1.0:
                return self.neg(other)
        # move negations outward ((-a)*b = -(a*b) exactly) where add/sub can absorb them
        na, nb = self._is_neg(a), self._is_neg(b)
        if na is not None or nb is not None:
            product = self.mul(a if na is None else na, b if nb is None else nb)
            return product if (na is None) == (nb is None) else self.neg(product)
        return self._add_node(Op.MUL, (min(a, b), max(a, b)))

    def div(self, a: int, b: int) -> int:
        a, b = self._check_id(a), self._check_id(b)
        ca, cb = self._exact(a), self._exact(b)
        if cb == 0.0:
            raise ZeroDivisionError("division by the constant 0 in the expression graph")
        if ca is not None and cb is not None:
            folded = self._fold(Fraction(ca) / Fraction(cb))
            if folded is not None:
                return folded
        if cb == 1.0:
            return a
        if cb == -1.0:
            return self.neg(a)
        na, nb = self._is_neg(a), self._is_neg(b)
        if na is not None or nb is not None:  # (-a)/b = -(a/b) exactly
            quotient = self.div(a if na is None else na, b if nb is None else nb)
            return quotient if (na is None) == (nb is None) else self.neg(quotient)
        return self._add_node(Op.DIV, (a, b))

    # -- unary

    def neg(self, a: int) -> int:
        a = self._check_id(a)
        node = self._nodes[a]
        if node.op == Op.NEG:
            return node.args[0]
        if node.op == Op.CONST:  # negation is exact: flip the enclosure
            lo, hi, value = node.data
            return self.const_enclosure(-hi, -lo, -value)
        return self._add_node(Op.NEG, (a,))

    def sqr(self, a: int) -> int:
        a = self._check_id(a)
        na = self._is_neg(a)
        if na is not None:
            a = na
        ca = self._exact(a)
        if ca is not None:
            folded = self._fold(Fraction(ca) ** 2)
            if folded is not None:
                return folded
        return self._add_node(Op.SQR, (a,))

    def pow(self, a: int, k: int) -> int:
        """``a ** k`` for an integer ``k`` (negative k gives ``1 / a**|k|``)."""
        a = self._check_id(a)
        if int(k) != k:
            raise ValueError(f"pow needs an integer exponent, got {k!r}")
        k = int(k)
        if k < 0:
            return self.div(self.const(1.0), self.pow(a, -k))
        if k == 0:
            return self.const(1.0)
        if k == 1:
            return a
        if k == 2:
            return self.sqr(a)
        ca = self._exact(a)
        if ca is not None and k <= 64 and abs(ca) <= 2.0**64:  # keep the exact check cheap
            folded = self._fold(Fraction(ca) ** k)
            if folded is not None:
                return folded
        return self._add_node(Op.POW, (a,), k)

    def sqrt(self, a: int) -> int:
        a = self._check_id(a)
        ca = self._exact(a)
        if ca is not None and ca >= 0.0:
            r = math.sqrt(ca)
            if Fraction(r) ** 2 == Fraction(ca):
                return self.const(r)
        return self._add_node(Op.SQRT, (a,))

    def _unary(self, op: Op, a: int, identity: tuple[float, float] | None) -> int:
        """Elementary function; folds only the exact identity ``f(x0) = y0``."""
        a = self._check_id(a)
        if identity is not None and self._exact(a) == identity[0]:
            return self.const(identity[1])
        return self._add_node(op, (a,))

    def exp(self, a: int) -> int:
        return self._unary(Op.EXP, a, (0.0, 1.0))

    def log(self, a: int) -> int:
        return self._unary(Op.LOG, a, (1.0, 0.0))

    def sin(self, a: int) -> int:
        return self._unary(Op.SIN, a, (0.0, 0.0))

    def cos(self, a: int) -> int:
        return self._unary(Op.COS, a, (0.0, 1.0))

    def tan(self, a: int) -> int:
        return self._unary(Op.TAN, a, (0.0, 0.0))

    def atan(self, a: int) -> int:
        return self._unary(Op.ATAN, a, (0.0, 0.0))

    def mid(self, a: int) -> int:
        """A *point* of ``a``'s enclosure, frozen: the identity over floats, the midpoint
        of an interval, the centre of an affine form, a constant Taylor series (its
        derivatives are 0).

        Only for expressions whose value does not depend on which point is taken: a
        preconditioner ``K`` from ``mid(M)`` in ``K^T (K M K^T)^-1 K b = M^-1 b`` (see
        :meth:`solve`). Every evaluator then encloses the true function, and forward
        derivatives (which treat ``C`` as constant) are exact too, because the
        identity holds for every fixed ``C``
        (:func:`verified.graph.preconditioned.solve` builds such a solve)."""
        a = self._check_id(a)
        node = self._nodes[a]
        if node.op == Op.MID:
            return a
        if node.op == Op.CONST:  # any point of the enclosure will do: its nearest double
            return self.const_enclosure(node.data[2], node.data[2], node.data[2])
        return self._add_node(Op.MID, (a,))

    # -- finish

    def build(self, outputs: Iterable[int], output_names: Sequence[str] | None = None) -> Graph:
        """Graph of the given output node ids, keeping only nodes they depend on
        (renumbered, still in topological order)."""
        outputs = [self._check_id(o) for o in outputs]
        nodes, new_outputs = _prune(self._nodes, outputs)
        return Graph(nodes, new_outputs, self.input_names, self.param_names, output_names)

"""sympy <-> :class:`verified.graph.Graph` conversion (imported lazily: sympy is slow to import).

:func:`from_sympy` maps sympy expressions to the IR after ``sympy.cse``:

* ``Add``/``Mul`` with many arguments -> chains of binary nodes; terms with a negative
  numeric coefficient become ``sub``, factors with negative integer exponents are
  collected into one ``div``.
* ``Pow`` with exponent 2 -> ``sqr``; other integers -> ``pow`` (negative: ``1/pow``);
  ``1/2`` -> ``sqrt``; ``-1/2`` -> ``1/sqrt``; other half-integers ``k/2`` ->
  ``pow(sqrt(x), k)``.
* ``sin cos tan atan exp log``.
* Numbers: ``Integer``/``Rational``/``Float`` are exact rationals, enclosed outward
  (exact when a double); rational multiples of ``pi`` are enclosed by
  :func:`verified.arith.exact.pi_multiple_enclosure`; ``E`` and other ``NumberSymbol`` are
  evaluated at 40 digits and enclosed by stepping outward.

Anything else raises ``NotImplementedError`` (unsupported operation) or ``ValueError``
(symbol that is neither an input nor a parameter), naming the subexpression.
"""
from __future__ import annotations

from fractions import Fraction
from typing import Sequence

import sympy

from verified.graph.evaluate import to_sympy
from verified.arith.exact import enclose_approximation, pi_multiple_enclosure
from verified.graph.ir import Graph, GraphBuilder, enclose_rational

__all__ = ["from_sympy", "graph_to_sympy", "sympy_constant_enclosure", "sympy_number_node"]

# evalf precision for irrational constants, and the relative error we trust of it
_DIGITS = 40
_TRUSTED_REL_ERR = Fraction(1, 10**35)


def sympy_constant_enclosure(c) -> tuple[float, float, float]:
    """``(lo, hi, value)`` with ``lo <= c <= hi`` for a real sympy number atom.

    Rationals and Floats are exact rationals (a sympy Float is a binary number);
    rational multiples of pi are enclosed by :func:`verified.arith.exact.pi_multiple_enclosure`
    (the tightest doubles); other NumberSymbols (E, ...) and products go through a
    40-digit evalf.
    """
    if isinstance(c, (sympy.Rational, sympy.Float)):  # Integer is a Rational
        if isinstance(c, sympy.Float) and not c.is_finite:
            raise ValueError(f"non-finite constant {c}")
        p, q = sympy.Rational(c).as_numer_denom()
        return enclose_rational(Fraction(int(p), int(q)))
    if _is_constant_product(c) and c.is_real:
        q = c / sympy.pi
        if q.is_Rational:  # a rational multiple of pi: exactly, by verified.arith.exact
            return pi_multiple_enclosure(0, Fraction(int(q.p), int(q.q)))
        approx = sympy.Rational(c.evalf(_DIGITS))
        p, q = approx.as_numer_denom()
        return enclose_approximation(Fraction(int(p), int(q)), _TRUSTED_REL_ERR)
    raise NotImplementedError(f"unsupported numeric constant {c} ({type(c).__name__})")


def _is_constant_product(c) -> bool:
    """A NumberSymbol, or a product of Rationals and NumberSymbols (like ``pi/3``)."""
    if isinstance(c, sympy.NumberSymbol):
        return True
    return bool(c.is_Mul) and all(isinstance(f, (sympy.Rational, sympy.NumberSymbol)) for f in c.args)


def _flatten(exprs) -> list:
    if isinstance(exprs, sympy.MatrixBase):
        return list(exprs)  # row-major
    if isinstance(exprs, (list, tuple)):
        out = []
        for e in exprs:
            out.extend(_flatten(e) if isinstance(e, (list, tuple, sympy.MatrixBase)) else [e])
        return out
    return [exprs]


class _Converter:
    """Walks sympy expressions, memoizing node ids per subexpression."""

    _FUNCS = {
        sympy.sin: "sin",
        sympy.cos: "cos",
        sympy.tan: "tan",
        sympy.atan: "atan",
        sympy.exp: "exp",
        sympy.log: "log",
    }

    def __init__(self, builder: GraphBuilder, leaves: dict, originals: dict):
        self.b = builder
        self.memo = dict(leaves)
        self.originals = originals  # fresh leaf symbol -> the user's symbol
        self.replacements: list = []  # cse (symbol, subexpression) pairs, in order

    def show(self, e) -> str:
        """``e`` in the user's terms (cse symbols expanded, leaves restored) for messages."""
        for sym, sub in reversed(self.replacements):
            e = e.xreplace({sym: sub})
        return str(e.xreplace(self.originals))

    def node(self, e) -> int:
        found = self.memo.get(e)
        if found is None:
            found = self._convert(e)
            self.memo[e] = found
        return found

    def _convert(self, e) -> int:
        b = self.b
        if isinstance(e, (int, float)):
            e = sympy.sympify(e)
        if e.is_Number or isinstance(e, sympy.NumberSymbol):
            if e.is_Number and not (e.is_Rational or e.is_Float):
                raise NotImplementedError(f"unsupported numeric constant {self.show(e)}")
            return b.const_enclosure(*sympy_constant_enclosure(e))
        if e.is_Symbol:
            raise ValueError(f"unknown symbol {self.show(e)} (not among the inputs or params)")
        if e.is_Add:
            return self._add(e)
        if e.is_Mul:
            return self._mul(e)
        if e.is_Pow:
            return self._pow(e.base, e.exp, e)
        name = self._FUNCS.get(e.func)
        if name is not None:
            if len(e.args) != 1:
                raise NotImplementedError(f"{e.func} with {len(e.args)} arguments in {self.show(e)}")
            return getattr(b, name)(self.node(e.args[0]))
        if isinstance(e, sympy.core.function.AppliedUndef) or isinstance(e, sympy.Derivative):
            raise ValueError(f"unknown symbol {self.show(e)} (not among the inputs or params)")
        raise NotImplementedError(
            f"unsupported sympy operation {type(e).__name__} in subexpression {self.show(e)}; the graph op set is "
            "+ - * / integer and half-integer powers, sqrt, exp, log, sin, cos, tan, atan"
        )

    def _add(self, e) -> int:
        """Sum left to right; a term ``-c*t`` (c > 0) is subtracted instead of added."""
        b = self.b
        acc = None
        for term in e.args:
            coeff, rest = term.as_coeff_Mul()
            negative = coeff.is_negative is True and rest != 1
            node = self.node(-term) if negative else self.node(term)
            if acc is None:
                acc = b.neg(node) if negative else node
            else:
                acc = b.sub(acc, node) if negative else b.add(acc, node)
        return acc

    def _mul(self, e) -> int:
        """Product of the factors; factors ``x**-k`` are collected into one division."""
        b = self.b
        coeff, rest = e.as_coeff_Mul()
        if coeff == -1:
            return b.neg(self.node(rest))
        num, den = [], []
        factors = list(e.args)
        constants = [f for f in factors if f.is_Rational or isinstance(f, sympy.NumberSymbol)]
        if len(constants) >= 2 and any(isinstance(f, sympy.NumberSymbol) for f in constants):
            # enclose e.g. pi/3 as one constant (one rounding instead of one per factor)
            factors = [f for f in factors if f not in constants]
            num.append(b.const_enclosure(*sympy_constant_enclosure(sympy.Mul(*constants))))
        for f in factors:
            if f.is_Pow and f.exp.is_Rational and f.exp.is_negative:
                den.append(self._pow(f.base, -f.exp, sympy.Pow(f.base, -f.exp, evaluate=False)))
            else:
                num.append(self.node(f))
        top = self._product(num)
        if not den:
            return top
        bottom = self._product(den)
        return b.div(top if top is not None else b.const(1.0), bottom)

    def _product(self, nodes: Sequence[int]) -> int | None:
        acc = None
        for n in nodes:
            acc = n if acc is None else self.b.mul(acc, n)
        return acc

    def _pow(self, base, exp, whole) -> int:
        b = self.b
        if not exp.is_Rational:
            raise NotImplementedError(
                f"power with non-constant or irrational exponent in {self.show(whole)}; only integer and "
                "half-integer exponents are supported (write exp(y*log(x)) explicitly if intended)"
            )
        p, q = int(exp.p), int(exp.q)
        if q == 1:
            return b.pow(self.node(base), p)
        if q == 2:
            root = b.sqrt(self.node(base))
            return b.pow(root, p)  # p = 1: sqrt; p = -1: 1/sqrt; else sqrt(x)**p
        raise NotImplementedError(
            f"rational exponent {exp} in {self.show(whole)}: only integer and half-integer exponents are supported"
        )


def sympy_number_node(builder: GraphBuilder, value) -> int:
    """Node id of a constant sympy expression (``pi/3``, ``sqrt(2)``, ``Rational(1, 3)``) in ``builder``.

    Raises TypeError for non-numbers (e.g. an expression with free symbols)."""
    value = sympy.sympify(value)
    if not value.is_number:
        raise TypeError(f"cannot use the sympy expression {value} (it has free symbols) as a traced constant")
    try:
        return _Converter(builder, {}, {}).node(value)
    except NotImplementedError as exc:
        raise TypeError(str(exc)) from None


def from_sympy(exprs, inputs, params=(), *, cse: bool = True, output_names: Sequence[str] | None = None) -> Graph:
    """Graph of sympy expressions.

    Args:
        exprs: a sympy expression, a (nested) list/tuple of them, or a Matrix (row-major).
        inputs: the ``n`` input symbols (Symbols, or any sympy atoms such as ``q(t)``).
        params: the ``p`` parameter symbols.
        cse: run ``sympy.cse`` first (recommended: shared subexpressions are also shared by
            hash-consing, but cse finds more and speeds up the conversion).
        output_names: optional names of the ``m`` outputs.

    Raises:
        ValueError: a symbol that is neither an input nor a parameter; duplicated symbols.
        NotImplementedError: an operation outside the op set (Abs, Piecewise, x**(1/3), ...).
    """
    inputs = _flatten(inputs)
    params = _flatten(params)
    flat = [sympy.sympify(e) for e in _flatten(exprs)]
    all_leaves = inputs + params
    if len(set(all_leaves)) != len(all_leaves):
        raise ValueError(f"inputs and params must be distinct symbols, got {all_leaves}")
    builder = GraphBuilder(len(inputs), len(params), [str(s) for s in inputs], [str(s) for s in params])
    # Replace the leaves by fresh symbols first: inputs may be compound atoms such as
    # q(t) or Derivative(q(t), t), which cse would otherwise rewrite inside.
    fresh = [sympy.Dummy(str(s)) for s in all_leaves]
    flat = [e.xreplace(dict(zip(all_leaves, fresh))) for e in flat]
    leaves = {s: builder.input(i) for i, s in enumerate(fresh[: len(inputs)])}
    leaves.update({s: builder.param(i) for i, s in enumerate(fresh[len(inputs):])})
    conv = _Converter(builder, leaves, dict(zip(fresh, all_leaves)))
    if cse and flat:
        replacements, reduced = sympy.cse(flat, symbols=sympy.numbered_symbols("cse", cls=sympy.Dummy))
        for sym, sub in replacements:
            conv.memo[sym] = conv.node(sub)
            conv.replacements.append((sym, sub))
        flat = list(reduced)
    outputs = [conv.node(e) for e in flat]
    return builder.build(outputs, output_names)


# sympy expressions of a graph's outputs: an evaluator like the others (one home, in
# verified.graph.evaluate, so that Graph.to_sympy needs no import of this module)
graph_to_sympy = to_sympy

"""Forward-mode derivative rules, written once for every graph operation.

Two places differentiate a graph forward: :func:`verified.graph.ops.forward_mode`
builds the derivative as another graph (node ids in a :class:`~verified.graph.ir.GraphBuilder`),
and :class:`verified.graph.evaluate.DualDomain` evaluates dual numbers over a base domain
(floats, intervals). Both use the table :data:`RULES` here, over a small algebra:

value operations (of the values of nodes)
    ``add sub mul div neg sqr pow sqrt exp log sin cos tan atan mid`` and ``num(c)``,
    the exact number ``c`` (a Python int) as a value;
derivative operations (``None`` is a structural zero)
    ``d_add(p, q)``, ``d_sub(p, q)``, ``d_neg(p)``, ``d_scale(f, p)`` (``f * p``, ``f``
    a value) and ``d_div(p, x)`` (``p / x``, ``x`` a value). Each returns ``None`` when
    the result is zero (``d_sub(None, q)`` is ``-q``).

A rule is ``(value, factor, deriv)``:

- ``value(A, u, w, k)``: the node's value (``w`` the second argument of a binary op,
  ``k`` the exponent of ``pow``);
- ``factor(A, u, v, k)`` or None: a value the derivative needs in every direction
  (``cos u`` for ``sin``), computed once per node;
- ``deriv(A, p, q, u, w, v, f, k)``: the derivative in one direction, from the
  arguments' derivatives ``p``, ``q`` in that direction, the arguments ``u``, ``w``,
  the value ``v`` and the factor ``f``.

:func:`verified.graph.ops.forward_mode` calls ``deriv`` once per direction (one node
per direction and nonzero entry) and computes the factor for every node, as before;
:class:`~verified.graph.evaluate.DualDomain` calls it once on whole derivative arrays (last
axis the directions) and skips the factor when the node's derivative is zero. The
rules use only the algebra's operations, so in an interval base domain the derivative
is the chain rule evaluated in (outward rounded) interval arithmetic: an enclosure.
"""
from __future__ import annotations

from typing import Callable, NamedTuple

from verified.graph.opcodes import Op

__all__ = ["Rule", "RULES", "Algebra", "VALUE_OPS"]


#: the value operations of the algebra (taken from the underlying domain or builder)
VALUE_OPS = ("add", "sub", "mul", "div", "neg", "sqr", "pow", "sqrt", "exp", "log",
             "sin", "cos", "tan", "atan", "mid")


class Algebra:
    """What both algebras share: the value operations of ``ops`` (a domain or a graph
    builder) and the derivative sums with ``None`` as a structural zero. Subclasses
    give ``num``, ``d_scale`` and ``d_div``."""

    def __init__(self, ops):
        for name in VALUE_OPS:
            setattr(self, name, getattr(ops, name))

    def d_add(self, p, q):
        return q if p is None else p if q is None else self.add(p, q)

    def d_sub(self, p, q):
        return p if q is None else self.neg(q) if p is None else self.sub(p, q)

    def d_neg(self, p):
        return None if p is None else self.neg(p)


class Rule(NamedTuple):
    value: Callable
    factor: Callable | None
    deriv: Callable


def _pow_factor(A, u, v, k):
    # k u^(k-1); u^1 and u^2 spelled out (the builder's pow(u, 1) is u, pow(u, 2) is sqr u).
    # The constant first: forward_mode's graphs keep their node order (and fingerprints)
    c = A.num(k)
    lower = u if k == 2 else A.sqr(u) if k == 3 else A.pow(u, k - 1)
    return A.mul(c, lower)


RULES: dict[Op, Rule] = {
    Op.ADD: Rule(lambda A, u, w, k: A.add(u, w), None,
                 lambda A, p, q, u, w, v, f, k: A.d_add(p, q)),
    Op.SUB: Rule(lambda A, u, w, k: A.sub(u, w), None,
                 lambda A, p, q, u, w, v, f, k: A.d_sub(p, q)),
    Op.MUL: Rule(lambda A, u, w, k: A.mul(u, w), None,  # (u w)' = w u' + u w'
                 lambda A, p, q, u, w, v, f, k: A.d_add(A.d_scale(w, p), A.d_scale(u, q))),
    Op.DIV: Rule(lambda A, u, w, k: A.div(u, w), None,  # (u / w)' = (u' - v w') / w
                 lambda A, p, q, u, w, v, f, k: A.d_div(A.d_sub(p, A.d_scale(v, q)), w)),
    Op.NEG: Rule(lambda A, u, w, k: A.neg(u), None,
                 lambda A, p, q, u, w, v, f, k: A.d_neg(p)),
    Op.SQR: Rule(lambda A, u, w, k: A.sqr(u), lambda A, u, v, k: A.mul(A.num(2), u),
                 lambda A, p, q, u, w, v, f, k: A.d_scale(f, p)),
    Op.POW: Rule(lambda A, u, w, k: A.pow(u, k), _pow_factor,
                 lambda A, p, q, u, w, v, f, k: A.d_scale(f, p)),
    Op.SQRT: Rule(lambda A, u, w, k: A.sqrt(u), None,  # sqrt(u)' = u' / (2 v)
                  lambda A, p, q, u, w, v, f, k: None if p is None else A.d_div(p, A.mul(A.num(2), v))),
    Op.EXP: Rule(lambda A, u, w, k: A.exp(u), lambda A, u, v, k: v,
                 lambda A, p, q, u, w, v, f, k: A.d_scale(f, p)),
    Op.LOG: Rule(lambda A, u, w, k: A.log(u), None,
                 lambda A, p, q, u, w, v, f, k: A.d_div(p, u)),
    Op.SIN: Rule(lambda A, u, w, k: A.sin(u), lambda A, u, v, k: A.cos(u),
                 lambda A, p, q, u, w, v, f, k: A.d_scale(f, p)),
    Op.COS: Rule(lambda A, u, w, k: A.cos(u), lambda A, u, v, k: A.neg(A.sin(u)),
                 lambda A, p, q, u, w, v, f, k: A.d_scale(f, p)),
    # tan' = 1 + tan^2 (reuses v; sound in interval arithmetic)
    Op.TAN: Rule(lambda A, u, w, k: A.tan(u), lambda A, u, v, k: A.add(A.num(1), A.sqr(v)),
                 lambda A, p, q, u, w, v, f, k: A.d_scale(f, p)),
    Op.ATAN: Rule(lambda A, u, w, k: A.atan(u), lambda A, u, v, k: A.add(A.num(1), A.sqr(u)),
                  lambda A, p, q, u, w, v, f, k: A.d_div(p, f)),
    # a frozen point (a preconditioner): exact derivatives of the value-invariant
    # expressions it is used in treat it as constant
    Op.MID: Rule(lambda A, u, w, k: A.mid(u), None,
                 lambda A, p, q, u, w, v, f, k: None),
}

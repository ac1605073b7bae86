"""Opcodes of the expression graph (:class:`Op`) and its node type (:class:`Node`).

The bottom of the graph modules: imports nothing of the project, so evaluators
(:mod:`verified.graph.evaluate`) dispatch on opcodes without importing the graph.
"""
from __future__ import annotations

import enum
from typing import Any, NamedTuple

__all__ = ["Op", "Node", "LEAF_OPS", "BINARY_OPS", "UNARY_OPS", "COMMUTATIVE_OPS"]


class Op(enum.IntEnum):
    """Opcodes of the IR. The numbering is part of no file format (names are used)."""

    CONST = 0
    INPUT = 1
    PARAM = 2
    ADD = 3
    SUB = 4
    MUL = 5
    DIV = 6
    NEG = 7
    SQR = 8
    POW = 9
    SQRT = 10
    EXP = 11
    LOG = 12
    SIN = 13
    COS = 14
    TAN = 15
    ATAN = 16
    MID = 17



LEAF_OPS = frozenset({Op.CONST, Op.INPUT, Op.PARAM})
BINARY_OPS = frozenset({Op.ADD, Op.SUB, Op.MUL, Op.DIV})
UNARY_OPS = frozenset(
    {Op.NEG, Op.SQR, Op.POW, Op.SQRT, Op.EXP, Op.LOG, Op.SIN, Op.COS, Op.TAN, Op.ATAN, Op.MID}
)
COMMUTATIVE_OPS = frozenset({Op.ADD, Op.MUL})
_ARITY = {**{op: 0 for op in LEAF_OPS}, **{op: 2 for op in BINARY_OPS}, **{op: 1 for op in UNARY_OPS}}
_BY_NAME = {op.name.lower(): op for op in Op}


class Node(NamedTuple):
    """One IR node.

    ``data`` depends on ``op``: ``(lo, hi, value)`` floats for CONST, the input/param
    index (int) for INPUT/PARAM, the integer exponent (>= 3) for POW, else ``None``.
    """

    op: Op
    args: tuple[int, ...]
    data: Any

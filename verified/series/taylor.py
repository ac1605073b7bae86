"""Interval Taylor coefficients of ODE solutions by automatic differentiation.

For an autonomous ODE ``x' = f(x, p)`` given as an expression :class:`~verified.graph.Graph`
with ``n`` inputs and ``n`` outputs, :class:`TaylorODE` computes enclosures of the
normalized Taylor coefficients ``x_[k] = x^(k)(t0) / k!`` of every solution through a
box of initial values, for a whole batch of boxes at once:

    x_[0] = x(t0),      x_[k+1] = f_[k] / (k + 1),

where ``f_[k]`` is the k-th Taylor coefficient of ``t -> f(x(t), p)``, obtained node by
node with the classical recurrences (Moore 1966; Griewank & Walther, ch. 13):

    (u v)_[k]   = sum_j u_[j] v_[k-j]
    (u / v)_[k] = (u_[k] - sum_{j>=1} v_[j] w_[k-j]) / v_[0]
    exp:  w_[k] = (1/k) sum_{j>=1} j u_[j] w_[k-j]
    sin, cos together:  s_[k] = (1/k) sum j u_[j] c_[k-j],  c_[k] = -(1/k) sum j u_[j] s_[k-j]
    ...

The graph is flattened once into a *tape* of integer arrays, and one compiled (numba)
interpreter runs any tape, so no model needs compiling of its own: the recursion of
:mod:`verified.series.recursion` with the interval table of this module
(:class:`IntervalTable`, its rules ``_iv_*``). Every arithmetic step is an
outward-rounded interval operation from :mod:`verified.arith._kernels`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from verified.arith import _kernels as _k
from verified.arith.interval import Interval, _as_interval
from verified.graph import Graph, Op
from verified.series.recursion import (
    T_ADD, T_ATAN, T_AUX, T_CONST, T_COS, T_DIV, T_EXP, T_INPUT, T_LOG, T_MID, T_MUL, T_NEG, T_PARAM, T_SIN, T_SQR,
    T_SQRT, T_SUB, T_TAN, recursion, register, rules_named
)

__all__ = ["TaylorODE"]

# Integer constants handed to other compiled functions are written ``np.int64(k)``, not ``k``:
# numba compiles a callee once per distinct integer *literal* argument, so the eight kinds of
# the unary expansion were eight compilations of it and of everything it calls, which
# multiplied a first run's compile time (docs/lab/code_notes.md, compile time).

# The tape opcodes T_* are defined with the engine (verified.series.recursion); the affine
# and Taylor-model kernels import them from here.

_SIMPLE = {
    Op.ADD: T_ADD,
    Op.SUB: T_SUB,
    Op.MUL: T_MUL,
    Op.DIV: T_DIV,
    Op.NEG: T_NEG,
    Op.SQR: T_SQR,
    Op.SQRT: T_SQRT,
    Op.EXP: T_EXP,
    Op.LOG: T_LOG,
}


class _Tape:
    """Flat arrays describing the recurrences of one graph (see :mod:`verified.series.recursion`).

    ``cst[s]`` marks slots whose series is constant in time (built from constants,
    parameters and frozen points ``mid`` only): their coefficients of order >= 1 are
    exactly 0, so the kernels compute order 0 only, and a product or quotient with
    such a slot is a scaling (``(c u)_[k] = c_[0] u_[k]``) instead of a convolution.
    Both give the same numbers as the full recurrences (the skipped terms are exact
    zeros), in O(1) instead of O(k) per coefficient."""

    def __init__(self, graph: Graph):
        op, a0, a1, aux, idx, clo, chi = [], [], [], [], [], [], []
        cst = []  # per slot: constant series?

        def emit(o, x=-1, y=-1, index=-1, lo=0.0, hi=0.0):
            op.append(o)
            a0.append(x)
            a1.append(y)
            aux.append(-1)
            idx.append(index)
            clo.append(lo)
            chi.append(hi)
            if o in (T_CONST, T_PARAM, T_MID):
                cst.append(True)
            elif o == T_INPUT:
                cst.append(False)
            elif o == T_AUX:  # the partner of the slot emitted just before it
                cst.append(cst[-1])
            else:
                cst.append(cst[x] and (y < 0 or cst[y]))
            return len(op) - 1

        slot = {}  # graph node -> tape slot
        partner = {}  # (kind, arg slot) -> slot of an existing sin/cos of that argument
        for i, node in enumerate(graph.nodes):
            o, args, data = node.op, [slot[a] for a in node.args], node.data
            if o == Op.CONST:
                slot[i] = emit(T_CONST, lo=data[0], hi=data[1])
            elif o == Op.INPUT:
                slot[i] = emit(T_INPUT, index=data)
            elif o == Op.PARAM:
                slot[i] = emit(T_PARAM, index=data)
            elif o in _SIMPLE:
                slot[i] = emit(_SIMPLE[o], *args)
            elif o == Op.POW:
                slot[i] = self._emit_pow(emit, args[0], data)
            elif o in (Op.SIN, Op.COS):
                kind, other = ("sin", "cos") if o == Op.SIN else ("cos", "sin")
                existing = partner.get((other, args[0]))
                if existing is not None and op[existing] == T_AUX:
                    # The partner already computes this series: reuse its auxiliary slot.
                    slot[i] = existing
                    partner[(kind, args[0])] = existing
                    continue
                s = emit(T_SIN if o == Op.SIN else T_COS, args[0])
                a = emit(T_AUX)
                aux[s] = a
                slot[i] = s
                partner[(kind, args[0])] = s
                partner[(other, args[0])] = a
            elif o in (Op.TAN, Op.ATAN):
                s = emit(T_TAN if o == Op.TAN else T_ATAN, args[0])
                aux[s] = emit(T_AUX)
                slot[i] = s
            elif o == Op.MID:
                slot[i] = emit(T_MID, args[0])
            else:  # pragma: no cover - every Op is handled above
                raise NotImplementedError(f"no Taylor recurrence for {o.name}")
        self.cst = np.array(cst, dtype=np.bool_)
        self.op = np.array(op, dtype=np.int64)
        self.a0 = np.array(a0, dtype=np.int64)
        self.a1 = np.array(a1, dtype=np.int64)
        self.aux = np.array(aux, dtype=np.int64)
        self.idx = np.array(idx, dtype=np.int64)
        self.clo = np.array(clo, dtype=np.float64)
        self.chi = np.array(chi, dtype=np.float64)
        self.outputs = np.array([slot[o] for o in graph.outputs], dtype=np.int64)

    @staticmethod
    def _emit_pow(emit, base, m):
        """``base ** m`` as squarings and products (binary powering)."""
        result = None
        square = base
        while True:
            if m & 1:
                result = square if result is None else emit(T_MUL, result, square)
            m >>= 1
            if not m:
                return result
            square = emit(T_SQR, square)


# --------------------------------------------------------------------------
# The interval table of the recursion (verified.series.recursion): lo[s, k, b], hi[s, k, b]
# hold coefficient k of tape slot s for box b; every rule loops over the boxes.
# --------------------------------------------------------------------------
@njit(cache=True)
def _frozen_point(lo, hi):
    """The value of the graph op ``mid`` (:meth:`verified.graph.GraphBuilder.mid`):
    the midpoint of a bounded interval as a point; an unbounded one stays the whole
    line and an empty one stays empty (no definite point is made up from nothing)."""
    if lo > hi:
        return lo, hi
    if math.isfinite(lo) and math.isfinite(hi):
        m = 0.5 * lo + 0.5 * hi
        return m, m
    return -math.inf, math.inf


@njit(cache=True)
def _conv(tlo, thi, u, v, k, j0, b):
    """sum_{j=j0}^{k} T[u, j] * T[v, k-j] for box b."""
    sl = 0.0
    sh = 0.0
    for j in range(j0, k + 1):
        pl, ph = _k.mul(tlo[u, j, b], thi[u, j, b], tlo[v, k - j, b], thi[v, k - j, b])
        sl, sh = _k.add(sl, sh, pl, ph)
    return sl, sh


@njit(cache=True)
def _wconv(tlo, thi, u, v, k, j1, b):
    """sum_{j=1}^{j1} j * T[u, j] * T[v, k-j] for box b (j is exact)."""
    sl = 0.0
    sh = 0.0
    for j in range(1, j1 + 1):
        pl, ph = _k.mul(tlo[u, j, b], thi[u, j, b], tlo[v, k - j, b], thi[v, k - j, b])
        pl, ph = _k.mul(float(j), float(j), pl, ph)
        sl, sh = _k.add(sl, sh, pl, ph)
    return sl, sh


@njit(cache=True)
def _sqrconv(tlo, thi, u, k, j0, b):
    """sum_{j=j0}^{k-j0} T[u, j] T[u, k-j], pairing equal terms (the middle one squared)."""
    sl = 0.0
    sh = 0.0
    for j in range(j0, (k + 1) // 2):
        pl, ph = _k.mul(tlo[u, j, b], thi[u, j, b], tlo[u, k - j, b], thi[u, k - j, b])
        sl, sh = _k.add(sl, sh, pl, ph)
    sl, sh = _k.mul(2.0, 2.0, sl, sh)
    if k % 2 == 0 and k // 2 >= j0:
        ql, qh = _k.sqr(tlo[u, k // 2, b], thi[u, k // 2, b])
        sl, sh = _k.add(sl, sh, ql, qh)
    return sl, sh


class IntervalTable(NamedTuple):
    """Interval coefficients of every tape slot and of the state, for a batch of boxes
    (the table of :func:`verified.series.recursion.recursion` that :class:`TaylorODE` runs).
    Its rules are the functions ``_iv_*`` below (plain functions: numba compiles them into
    the engine); every arithmetic step of theirs is an outward-rounded interval operation
    of :mod:`verified.arith._kernels`, box by box."""

    lo: np.ndarray  # (slots, order + 1, B): coefficient k of slot s for box b
    hi: np.ndarray
    xlo: np.ndarray  # (n, order + 1, B): x_[k] of state i
    xhi: np.ndarray
    plo: np.ndarray  # (p, B): the parameters
    phi: np.ndarray


def _iv_const(ar, s, lo, hi):
    for b in range(ar.lo.shape[2]):
        ar.lo[s, 0, b] = lo
        ar.hi[s, 0, b] = hi


def _iv_mid(ar, s, u):  # a frozen point of u_[0]: a constant series
    tlo, thi = ar.lo, ar.hi
    for b in range(tlo.shape[2]):
        tlo[s, 0, b], thi[s, 0, b] = _frozen_point(tlo[u, 0, b], thi[u, 0, b])


def _iv_param(ar, s, i):
    for b in range(ar.lo.shape[2]):
        ar.lo[s, 0, b] = ar.plo[i, b]
        ar.hi[s, 0, b] = ar.phi[i, b]


def _iv_state(ar, s, k, i):
    for b in range(ar.lo.shape[2]):
        ar.lo[s, k, b] = ar.xlo[i, k, b]
        ar.hi[s, k, b] = ar.xhi[i, k, b]


def _iv_add(ar, s, k, u, v):
    tlo, thi = ar.lo, ar.hi
    for b in range(tlo.shape[2]):
        tlo[s, k, b], thi[s, k, b] = _k.add(tlo[u, k, b], thi[u, k, b], tlo[v, k, b], thi[v, k, b])


def _iv_sub(ar, s, k, u, v):
    tlo, thi = ar.lo, ar.hi
    for b in range(tlo.shape[2]):
        tlo[s, k, b], thi[s, k, b] = _k.sub(tlo[u, k, b], thi[u, k, b], tlo[v, k, b], thi[v, k, b])


def _iv_neg(ar, s, k, u):
    tlo, thi = ar.lo, ar.hi
    for b in range(tlo.shape[2]):
        tlo[s, k, b] = -thi[u, k, b]
        thi[s, k, b] = -tlo[u, k, b]


def _iv_mul_const(ar, s, k, u, v, ku, kv):
    tlo, thi = ar.lo, ar.hi
    for b in range(tlo.shape[2]):
        tlo[s, k, b], thi[s, k, b] = _k.mul(tlo[u, ku, b], thi[u, ku, b], tlo[v, kv, b], thi[v, kv, b])


def _iv_mul(ar, s, k, u, v):
    tlo, thi = ar.lo, ar.hi
    for b in range(tlo.shape[2]):
        tlo[s, k, b], thi[s, k, b] = _conv(tlo, thi, u, v, k, np.int64(0), b)


def _iv_sqr(ar, s, k, u):
    tlo, thi = ar.lo, ar.hi
    for b in range(tlo.shape[2]):
        tlo[s, k, b], thi[s, k, b] = _sqrconv(tlo, thi, u, k, np.int64(0), b)


def _iv_div_const(ar, s, k, u, v):  # w_k = u_k / v_0
    tlo, thi = ar.lo, ar.hi
    for b in range(tlo.shape[2]):
        tlo[s, k, b], thi[s, k, b] = _k.div(tlo[u, k, b], thi[u, k, b], tlo[v, 0, b], thi[v, 0, b])


def _iv_div(ar, s, k, u, v):
    tlo, thi = ar.lo, ar.hi
    for b in range(tlo.shape[2]):
        # w_k = (u_k - sum_{j=1}^k v_j w_{k-j}) / v_0
        sl, sh = _conv(tlo, thi, v, s, k, np.int64(1), b)
        sl, sh = _k.sub(tlo[u, k, b], thi[u, k, b], sl, sh)
        tlo[s, k, b], thi[s, k, b] = _k.div(sl, sh, tlo[v, 0, b], thi[v, 0, b])


def _iv_sqrt0(ar, s, u):
    tlo, thi = ar.lo, ar.hi
    for b in range(tlo.shape[2]):
        tlo[s, 0, b], thi[s, 0, b] = _k.sqrt(tlo[u, 0, b], thi[u, 0, b])


def _iv_sqrt(ar, s, k, u):
    tlo, thi = ar.lo, ar.hi
    for b in range(tlo.shape[2]):
        # w_k = (u_k - sum_{j=1}^{k-1} w_j w_{k-j}) / (2 w_0)
        sl, sh = _sqrconv(tlo, thi, s, k, np.int64(1), b)
        sl, sh = _k.sub(tlo[u, k, b], thi[u, k, b], sl, sh)
        dl, dh = _k.mul(2.0, 2.0, tlo[s, 0, b], thi[s, 0, b])
        tlo[s, k, b], thi[s, k, b] = _k.div(sl, sh, dl, dh)


def _iv_exp0(ar, s, u):
    tlo, thi = ar.lo, ar.hi
    for b in range(tlo.shape[2]):
        tlo[s, 0, b], thi[s, 0, b] = _k.exp(tlo[u, 0, b], thi[u, 0, b])


def _iv_exp(ar, s, k, u):
    tlo, thi = ar.lo, ar.hi
    fk = float(k)
    for b in range(tlo.shape[2]):
        sl, sh = _wconv(tlo, thi, u, s, k, k, b)
        tlo[s, k, b], thi[s, k, b] = _k.div(sl, sh, fk, fk)


def _iv_log0(ar, s, u):
    tlo, thi = ar.lo, ar.hi
    for b in range(tlo.shape[2]):
        tlo[s, 0, b], thi[s, 0, b] = _k.log(tlo[u, 0, b], thi[u, 0, b])


def _iv_log(ar, s, k, u):
    tlo, thi = ar.lo, ar.hi
    fk = float(k)
    for b in range(tlo.shape[2]):
        # w_k = (u_k - (1/k) sum_{j=1}^{k-1} j w_j u_{k-j}) / u_0
        sl, sh = _wconv(tlo, thi, s, u, k, k - 1, b)
        sl, sh = _k.div(sl, sh, fk, fk)
        sl, sh = _k.sub(tlo[u, k, b], thi[u, k, b], sl, sh)
        tlo[s, k, b], thi[s, k, b] = _k.div(sl, sh, tlo[u, 0, b], thi[u, 0, b])


def _iv_sincos0(ar, ss, cs, u):
    tlo, thi = ar.lo, ar.hi
    for b in range(tlo.shape[2]):
        tlo[ss, 0, b], thi[ss, 0, b] = _k.sin(tlo[u, 0, b], thi[u, 0, b])
        tlo[cs, 0, b], thi[cs, 0, b] = _k.cos(tlo[u, 0, b], thi[u, 0, b])


def _iv_sincos(ar, ss, cs, k, u):
    tlo, thi = ar.lo, ar.hi
    fk = float(k)
    for b in range(tlo.shape[2]):
        sl, sh = _wconv(tlo, thi, u, cs, k, k, b)
        tlo[ss, k, b], thi[ss, k, b] = _k.div(sl, sh, fk, fk)
        sl, sh = _wconv(tlo, thi, u, ss, k, k, b)
        tlo[cs, k, b], thi[cs, k, b] = _k.div(-sh, -sl, fk, fk)


def _iv_tan0(ar, s, vs, u):  # vs: v = 1 + tan^2 = tan'
    tlo, thi = ar.lo, ar.hi
    for b in range(tlo.shape[2]):
        tl, th = _k.tan(tlo[u, 0, b], thi[u, 0, b])
        tlo[s, 0, b] = tl
        thi[s, 0, b] = th
        ql, qh = _k.sqr(tl, th)
        tlo[vs, 0, b], thi[vs, 0, b] = _k.add(1.0, 1.0, ql, qh)


def _iv_tan(ar, s, vs, k, u):
    tlo, thi = ar.lo, ar.hi
    fk = float(k)
    for b in range(tlo.shape[2]):
        sl, sh = _wconv(tlo, thi, u, vs, k, k, b)
        tlo[s, k, b], thi[s, k, b] = _k.div(sl, sh, fk, fk)
        tlo[vs, k, b], thi[vs, k, b] = _sqrconv(tlo, thi, s, k, np.int64(0), b)


def _iv_atan0(ar, s, vs, u):  # vs: v = 1 + u^2, atan(u)' = u' / v
    tlo, thi = ar.lo, ar.hi
    for b in range(tlo.shape[2]):
        tlo[s, 0, b], thi[s, 0, b] = _k.atan(tlo[u, 0, b], thi[u, 0, b])
        ql, qh = _k.sqr(tlo[u, 0, b], thi[u, 0, b])
        tlo[vs, 0, b], thi[vs, 0, b] = _k.add(1.0, 1.0, ql, qh)


def _iv_atan(ar, s, vs, k, u):
    tlo, thi = ar.lo, ar.hi
    fk = float(k)
    for b in range(tlo.shape[2]):
        tlo[vs, k, b], thi[vs, k, b] = _sqrconv(tlo, thi, u, k, np.int64(0), b)
        sl, sh = _wconv(tlo, thi, s, vs, k, k - 1, b)
        sl, sh = _k.div(sl, sh, fk, fk)
        sl, sh = _k.sub(tlo[u, k, b], thi[u, k, b], sl, sh)
        tlo[s, k, b], thi[s, k, b] = _k.div(sl, sh, tlo[vs, 0, b], thi[vs, 0, b])


def _iv_slot_done(ar, s, k):  # nothing after a slot (inlined: no code)
    pass


def _iv_integrate(ar, i, o, k):  # x_[k+1] = f_[k] / (k + 1)
    tlo, thi = ar.lo, ar.hi
    fk = float(k)
    for b in range(tlo.shape[2]):
        ar.xlo[i, k + 1, b], ar.xhi[i, k + 1, b] = _k.div(tlo[o, k, b], thi[o, k, b], fk + 1.0, fk + 1.0)


register(IntervalTable, **rules_named(globals(), "_iv_"))


@njit(cache=True)
def _interval_coefficients(op, a0, a1, aux, idx, cst, clo, chi, outputs, xlo, xhi, plo, phi, order):
    """Coefficients x_[0..order] for boxes ``x`` (shape (n, B)) and params (p, B): the
    recursion with the interval table. Returns lo, hi arrays of shape (n, order + 1, B)."""
    nslots = op.size
    n, nb = xlo.shape
    ar = IntervalTable(np.zeros((nslots, order + 1, nb)), np.zeros((nslots, order + 1, nb)),
                       np.empty((n, order + 1, nb)), np.empty((n, order + 1, nb)), plo, phi)
    for i in range(n):  # (a loop: a slice assignment compiles numba's broadcasting errors, ~3 s)
        for b in range(nb):
            ar.xlo[i, 0, b] = xlo[i, b]
            ar.xhi[i, 0, b] = xhi[i, b]
    recursion(op, a0, a1, aux, idx, cst, clo, chi, outputs, order, ar)
    return ar.xlo, ar.xhi


class TaylorODE:
    """Taylor-coefficient evaluator for the autonomous ODE ``x' = f(x, p)``.

    Parameters
    ----------
    graph : Graph
        ``f`` with ``n`` inputs (the state) and ``n`` outputs (its derivative), and
        ``p`` parameters (constant in time).
    """

    def __init__(self, graph: Graph):
        if graph.n_outputs != graph.n_inputs:
            raise ValueError(
                f"an ODE right-hand side needs as many outputs as inputs, got {graph.n_inputs} "
                f"inputs and {graph.n_outputs} outputs"
            )
        self.graph = graph
        self.n = graph.n_inputs
        self.n_params = graph.n_params
        self._tape = _Tape(graph)

    def coefficients(self, x, order, params=None):
        """Enclosures of ``x_[0..order]`` for all solutions starting in the boxes ``x``.

        Parameters
        ----------
        x : Interval or float array, shape ``(..., n)``
        order : int >= 1
        params : Interval or float array, shape ``(..., p)`` or ``(p,)``; required if p > 0

        Returns
        -------
        Interval of shape ``(..., order + 1, n)``; entry ``[..., k, i]`` encloses
        ``x_i^(k)(t0) / k!``.
        """
        order = int(order)
        if order < 1:
            raise ValueError(f"order must be >= 1, got {order}")
        x = _as_interval(x)
        if x.ndim < 1 or x.shape[-1] != self.n:
            raise ValueError(f"state boxes must have shape (..., {self.n}), got {x.shape}")
        batch = x.shape[:-1]
        if self.n_params:
            if params is None:
                raise ValueError(f"this ODE has {self.n_params} parameters {self.graph.param_names}; pass params")
            p = _as_interval(params)
            if p.shape[-1:] != (self.n_params,):
                raise ValueError(f"params must have shape (..., {self.n_params}), got {p.shape}")
            try:
                p = p.broadcast_to(batch + (self.n_params,))
            except ValueError:
                raise ValueError(f"params of shape {p.shape} do not broadcast to the batch {batch}") from None
        else:
            p = Interval._from_bounds(np.zeros(batch + (0,)), np.zeros(batch + (0,)))
        nb = int(np.prod(batch, dtype=int))
        xlo = _k.kernel_array(x.lo.reshape(nb, self.n).T)
        xhi = _k.kernel_array(x.hi.reshape(nb, self.n).T)
        plo = _k.kernel_array(p.lo.reshape(nb, self.n_params).T)
        phi = _k.kernel_array(p.hi.reshape(nb, self.n_params).T)
        t = self._tape
        lo, hi = _interval_coefficients(t.op, t.a0, t.a1, t.aux, t.idx, t.cst, t.clo, t.chi, t.outputs, xlo, xhi, plo,
                                        phi, order)
        # (n, order+1, B) -> (..., order+1, n)
        lo = np.moveaxis(lo, 2, 0).transpose(0, 2, 1).reshape(batch + (order + 1, self.n))
        hi = np.moveaxis(hi, 2, 0).transpose(0, 2, 1).reshape(batch + (order + 1, self.n))
        return Interval._from_bounds(np.ascontiguousarray(lo), np.ascontiguousarray(hi))

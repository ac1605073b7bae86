"""Taylor coefficients of ODE solutions as second-degree Taylor models in a set's symbols.

Affine arithmetic (:mod:`verified.affine_taylor`) carries the first-order dependence
of every intermediate on the set's noise symbols exactly and bounds every product's
quadratic part by its full range. In a robot's model graph those quadratic parts
cancel (entries of ``K M K^T`` near 0 at the centre, differences of large torques),
but their bounds add up: for the 3-link arm over ``q0 +- 0.01`` the enclosure of
``qdd`` came out 1.8x the sampled range and that of ``d qdd / dq`` 1.9-3.3x (at
``+- 0.05``: 6.7x and 8-23x), and inside the solver the Jacobian's spread over a set
was 5-1000x the true one, which made the QR-Lohner error part grow ~10 % per step
whatever the step size. Here every value is a *Taylor model* of degree 2 (COSY-VI,
Flow*, TaylorModels.jl; Makino & Berz 2003)::

    x  =  c + sum_i a_i eps_i + sum_{i <= j < mq} q_ij eps_i eps_j + [-e, e]

over ``m`` symbols ``eps_i in [-1, 1]``, with the quadratic monomials kept for the
first ``mq`` symbols (the set's own, widest ones) and a rigorous remainder radius
``e >= 0``. Quadratic terms are carried exactly, so cancellations of second-order
effects are exact; only third- and fourth-order terms, products with the symbols past
``mq`` and rounding are bounded. The same prototype measured 1.02x on ``qdd`` and
1.03-1.05x on ``d qdd / dq`` at ``+- 0.01`` (1.2x and 1.4-1.9x at ``+- 0.05``).

Rules (``R`` = sum of |linear coefficients|, ``RQ`` = sum of |quadratic
coefficients|, ``t`` = sum over the linear coefficients past ``mq``; all bounds
rounded upward by :func:`verified.affine_taylor._up`, every float coefficient's
rounding error added to ``e``):

* ``x + y``, ``x - y``, ``x / k``, ``d x``: coefficient by coefficient.
* ``x * y``: centre ``c_x c_y``, linear ``c_x b + c_y a``, quadratic
  ``c_x Q_y + c_y Q_x + sym(a b^T)`` on the first ``mq`` symbols; ``e`` gains
  ``t_x R_y + R^q_x t_y`` (linear products not kept), ``R_x RQ_y + RQ_x R_y +
  RQ_x RQ_y`` (degrees 3 and 4), ``(|c_x| + R_x + RQ_x) e_y + (|c_y| + R_y + RQ_y) e_x
  + e_x e_y``.
* ``f(x)`` for sqrt, exp, log, sin, cos, tan, atan and ``1/x``: the second-order
  expansion about the centre ``c`` with ``d = x - c`` (a model with centre 0),
  ``f(c) + f'(c) d + f''(xi)/2 d^2``: the model ``f0 + d1 d + s (d * d)`` with
  ``f0, d1`` the midpoints of enclosures of ``f(c), f'(c)`` and ``s`` that of
  ``f''(X)/2`` over the range ``X`` of ``x``; ``e`` gains their radii times ``1, W,
  W^2`` (``W >= |d|``). Where that error alone exceeds the plain image ``f(X)``, the
  image replaces the model (as in the affine kernel).
* Higher orders in time: the recurrences of :mod:`verified.taylor`, built from these.

A NaN anywhere gives ``[-inf, inf]``; a domain violation or overflow an infinite ``e``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from . import _kernels as _k
from .affine_taylor import _U, _UPF, _TINY, _deriv, _pm, _up, _value, _wide_symbol_forms, box_forms
from .interval import Interval, _as_interval
from .taylor import (T_ADD, T_ATAN, T_AUX, T_CONST, T_COS, T_DIV, T_EXP, T_INPUT, T_LOG, T_MID, T_MUL, T_NEG,
                     T_PARAM, T_SIN, T_SQR, T_SQRT, T_SUB, T_TAN, _Tape)

__all__ = ["TaylorModelODE", "model_length", "forms_to_models", "models_to_interval", "QUADRATIC_SYMBOLS"]

INF = math.inf

#: default cap on the symbols that get quadratic monomials (the rest stay linear):
#: the model's length grows as mq^2 / 2 and a product's cost with it
QUADRATIC_SYMBOLS = 12


def model_length(m: int, mq: int) -> int:
    """Length of a model over ``m`` symbols, ``mq`` of them with quadratic monomials:
    centre, ``m`` linear, ``mq (mq + 1) / 2`` quadratic coefficients, remainder."""
    return m + mq * (mq + 1) // 2 + 2


def _pairs(mq: int) -> tuple[np.ndarray, np.ndarray]:
    """Symbol indices (i, j), i <= j < mq, of the quadratic coefficients, in storage order."""
    pi, pj = np.triu_indices(mq)
    return pi.astype(np.int64), pj.astype(np.int64)


# --------------------------------------------------------------------------
# Model operations on 1-D arrays of length L = m + nq + 2: [0] centre, [1..m] linear,
# [m+1 .. m+nq] quadratic (pair p = (PI[p], PJ[p])), [L-1] remainder radius.
# --------------------------------------------------------------------------
@njit(cache=True)
def _clear(T):
    for i in range(T.size):
        T[i] = 0.0


@njit(cache=True)
def _poison(T):
    """The model that stands for 'unknown': all of the real line."""
    _clear(T)
    T[T.size - 1] = INF


@njit(cache=True)
def _norms(x, m, mq):
    """(sum |a_i| for i < mq, sum |a_i| for i >= mq, sum |q_p|), each rounded up."""
    rq = 0.0
    for i in range(1, mq + 1):
        rq += abs(x[i])
    t = 0.0
    for i in range(mq + 1, m + 1):
        t += abs(x[i])
    RQ = 0.0
    for p in range(m + 1, x.size - 1):
        RQ += abs(x[p])
    return _up(rq), _up(t), _up(RQ)


@njit(cache=True)
def _width_bound(x, m, mq):
    """An upper bound of |x - c| over the symbols' box (linear + quadratic + remainder)."""
    rq, t, RQ = _norms(x, m, mq)
    return _up(_up(rq + t) + RQ + x[x.size - 1])


@njit(cache=True)
def _acc_mul(T, x, y, m, mq, PI, PJ, w):
    """T += w * x * y, truncated to degree 2 (``w`` any float: its rounding is bounded)."""
    E = T.size - 1
    x0 = x[0]
    y0 = y[0]
    t0 = w * (x0 * y0)
    c = T[0] + t0
    rnd = 2.0 * abs(t0) + abs(c)
    T[0] = c
    for i in range(1, m + 1):
        xi = x[i]
        yi = y[i]
        p1 = w * (x0 * yi)
        p2 = w * (y0 * xi)
        ti = T[i] + (p1 + p2)
        rnd += 2.0 * (abs(p1) + abs(p2)) + abs(ti)
        T[i] = ti
    aw = abs(w)
    for p in range(PI.size):
        i = PI[p] + 1
        j = PJ[p] + 1
        s = m + 1 + p
        A = x0 * y[s]
        B = y0 * x[s]
        if i == j:
            Cc = x[i] * y[i]
            Dd = 0.0
        else:
            Cc = x[i] * y[j]
            Dd = x[j] * y[i]
        ts = T[s] + w * (A + B + (Cc + Dd))
        rnd += 3.0 * aw * (abs(A) + abs(B) + abs(Cc) + abs(Dd)) + abs(ts)
        T[s] = ts
    rqx, tx, RQx = _norms(x, m, mq)
    rqy, ty, RQy = _norms(y, m, mq)
    Rx = _up(rqx + tx)
    Ry = _up(rqy + ty)
    ex = x[E]
    ey = y[E]
    nl = (_pm(tx, Ry) + _pm(rqx, ty) + _pm(Rx, RQy) + _pm(RQx, Ry) + _pm(RQx, RQy)
          + _pm(abs(x0) + Rx + RQx, ey) + _pm(abs(y0) + Ry + RQy, ex) + _pm(ex, ey))
    T[E] = _up(T[E] + _pm(aw, _up(nl)) + rnd * _U)


@njit(cache=True)
def _acc_add(T, x, sign):
    """T += sign * x (sign = +1 or -1)."""
    E = T.size - 1
    rnd = 0.0
    for i in range(E):
        t = T[i] + sign * x[i]
        rnd += abs(t)
        T[i] = t
    T[E] = _up(T[E] + x[E] + rnd * _U)


@njit(cache=True)
def _scale_into(Z, x, d):
    """Z = d * x for a float d."""
    E = Z.size - 1
    rnd = 0.0
    for i in range(E):
        t = d * x[i]
        rnd += abs(t)
        Z[i] = t
    Z[E] = _up(_pm(abs(d), x[E]) + rnd * _U)


@njit(cache=True)
def _div_int_into(Z, x, kf):
    """Z = x / kf for a positive integer kf."""
    E = Z.size - 1
    rnd = 0.0
    for i in range(E):
        t = x[i] / kf
        rnd += abs(t)
        Z[i] = t
    Z[E] = _up(x[E] / kf + rnd * _U)


@njit(cache=True)
def _frozen_point_into(Z, x, m, mq):
    """Z = the graph op ``mid``: the model's centre as an exact point (unknown stays unknown)."""
    c = x[0]
    w = _width_bound(x, m, mq)
    _clear(Z)
    if math.isfinite(c) and math.isfinite(w):
        Z[0] = c
    else:
        Z[Z.size - 1] = INF


@njit(cache=True)
def _deriv2(kind, lo, hi):
    """Interval enclosure of f'' over [lo, hi] (kinds as :func:`verified.affine_taylor._deriv`)."""
    if kind == 0:  # sqrt: -1 / (4 x sqrt(x))
        sl, sh = _k.sqrt(lo, hi)
        pl, ph = _k.mul(lo, hi, sl, sh)
        ql, qh = _k.mul(4.0, 4.0, pl, ph)
        rl, rh = _k.div(1.0, 1.0, ql, qh)
        return -rh, -rl
    if kind == 1:  # exp
        return _k.exp(lo, hi)
    if kind == 2:  # log: -1 / x^2
        ql, qh = _k.sqr(lo, hi)
        rl, rh = _k.div(1.0, 1.0, ql, qh)
        return -rh, -rl
    if kind == 3:  # sin: -sin
        sl, sh = _k.sin(lo, hi)
        return -sh, -sl
    if kind == 4:  # cos: -cos
        cl, ch = _k.cos(lo, hi)
        return -ch, -cl
    if kind == 5:  # tan: 2 t (1 + t^2)
        tl, th = _k.tan(lo, hi)
        ql, qh = _k.sqr(tl, th)
        al, ah = _k.add(1.0, 1.0, ql, qh)
        pl, ph = _k.mul(tl, th, al, ah)
        return _k.mul(2.0, 2.0, pl, ph)
    if kind == 6:  # atan: -2 x / (1 + x^2)^2
        ql, qh = _k.sqr(lo, hi)
        al, ah = _k.add(1.0, 1.0, ql, qh)
        bl, bh = _k.sqr(al, ah)
        nl, nh = _k.mul(-2.0, -2.0, lo, hi)
        return _k.div(nl, nh, bl, bh)
    # 7: reciprocal: 2 / x^3
    cl, ch = _k.ipow(lo, hi, 3)
    return _k.div(2.0, 2.0, cl, ch)


@njit(cache=True)
def _unary_into(Z, x, m, mq, PI, PJ, kind, D, known_lo=-INF):
    """Z = f(x) by the second-order expansion about the centre (module docstring);
    ``D`` is scratch of the model's length. ``known_lo``: a lower bound of x known from
    elsewhere (1 for ``1 + u^2``); the range used for f'' is cut to it."""
    E = Z.size - 1
    c = x[0]
    W = _width_bound(x, m, mq)
    if not (math.isfinite(c) and math.isfinite(W)):
        _poison(Z)
        return
    xlo = max(_k.rd(c - W), min(known_lo, c))
    xhi = _k.ru(c + W)
    if not xlo <= xhi:
        _poison(Z)
        return
    fl, fh = _value(kind, c, c)
    dl, dh = _deriv(kind, c, c)
    sl, sh = _deriv2(kind, xlo, xhi)
    if not (fl <= fh and dl <= dh and sl <= sh):
        _poison(Z)  # outside the domain, or a pole within reach
        return
    if not (math.isfinite(fl) and math.isfinite(fh) and math.isfinite(dl) and math.isfinite(dh)
            and math.isfinite(sl) and math.isfinite(sh)):
        _poison(Z)
        return
    f0 = 0.5 * fl + 0.5 * fh
    frad = max(fh - f0, f0 - fl)
    d1 = 0.5 * dl + 0.5 * dh
    r1 = max(dh - d1, d1 - dl)
    hl = 0.5 * sl  # f''/2 (halving is exact away from underflow; _TINY in _up covers that)
    hh = 0.5 * sh
    s = 0.5 * hl + 0.5 * hh
    r2 = max(hh - s, s - hl)
    # D = x - c: the same model with centre 0 (exact)
    for i in range(D.size):
        D[i] = x[i]
    D[0] = 0.0
    _scale_into(Z, D, d1)  # d1 d, with the remainder |d1| e_x and the rounding
    Z[0] = f0
    _acc_mul(Z, D, D, m, mq, PI, PJ, s)  # + s d^2 (truncated, bounded)
    W2 = _pm(W, W)
    Z[E] = _up(Z[E] + _up(frad) + _pm(_up(r1) + _up(r1) * _U, W) + _pm(_up(r2) + _up(r2) * _U, W2)
               + _TINY)
    gl, gh = _value(kind, xlo, xhi)
    if gl <= gh and math.isfinite(gl) and math.isfinite(gh):
        g0 = 0.5 * gl + 0.5 * gh
        grad = _up(max(gh - g0, g0 - gl))
        if grad < Z[E]:
            _clear(Z)
            Z[0] = g0
            Z[E] = grad


@njit(cache=True)
def _sqrconv(Z, F, u, k, j0, b, m, mq, PI, PJ):
    """Z += sum_{j=j0}^{k-j0} F[u, j] F[u, k-j] (pairs of equal terms once, times 2)."""
    for j in range(j0, (k + 1) // 2):
        _acc_mul(Z, F[u, j, b], F[u, k - j, b], m, mq, PI, PJ, 2.0)
    if k % 2 == 0 and k // 2 >= j0:
        _acc_mul(Z, F[u, k // 2, b], F[u, k // 2, b], m, mq, PI, PJ, 1.0)


@njit(cache=True)
def _quotient_step(Z, F, s, u, v, k, b, m, mq, PI, PJ, rec, T, S):
    """Z = (F[u, k] - (1/k) sum_{j=1}^{k-1} j F[s, j] F[v, k-j]) * rec (log, atan)."""
    _clear(S)
    for j in range(1, k):
        _acc_mul(S, F[s, j, b], F[v, k - j, b], m, mq, PI, PJ, float(j))
    _div_int_into(T, S, float(k))
    _clear(S)
    _acc_add(S, F[u, k, b], 1.0)
    _acc_add(S, T, -1.0)
    _clear(Z)
    _acc_mul(Z, S, rec, m, mq, PI, PJ, 1.0)


@njit(cache=True)
def _model_kernel(op, a0, a1, aux, idx, cst, clo, chi, outputs, X, P, order, m, mq, PI, PJ):
    """Taylor models of x_[0..order]; X (n, B, L) and P (p, B, L) are the input models.

    Returns (n, order + 1, B, L). The loop is the one of
    :func:`verified.affine_taylor._affine_kernel_reference`, with model operations."""
    nslots = op.size
    n, nb, L = X.shape
    E = L - 1
    F = np.zeros((nslots, order + 1, nb, L))
    REC = np.zeros((nslots, nb, L))  # reciprocal of the order-0 divisor of a slot
    out = np.zeros((n, order + 1, nb, L))
    out[:, 0, :, :] = X
    T = np.zeros(L)
    S = np.zeros(L)
    D = np.zeros(L)
    for k in range(order):
        fk = float(k)
        for s in range(nslots):
            o = op[s]
            u = a0[s]
            v = a1[s]
            if o == T_AUX or (k > 0 and cst[s]):
                continue  # a constant's coefficients >= 1 stay exactly 0
            for b in range(nb):
                Z = F[s, k, b]
                if o == T_CONST:
                    if k == 0:
                        mid = 0.5 * clo[s] + 0.5 * chi[s]
                        Z[0] = mid
                        Z[E] = _up(max(chi[s] - mid, mid - clo[s]))
                elif o == T_PARAM:
                    if k == 0:
                        Z[:] = P[idx[s], b]
                elif o == T_MID:
                    if k == 0:
                        _frozen_point_into(Z, F[u, 0, b], m, mq)
                elif o == T_INPUT:
                    Z[:] = out[idx[s], k, b]
                elif o == T_ADD or o == T_SUB:
                    _clear(Z)
                    _acc_add(Z, F[u, k, b], 1.0)
                    _acc_add(Z, F[v, k, b], 1.0 if o == T_ADD else -1.0)
                elif o == T_NEG:
                    for i in range(E):
                        Z[i] = -F[u, k, b, i]
                    Z[E] = F[u, k, b, E]
                elif o == T_MUL:
                    _clear(Z)
                    if cst[u]:
                        _acc_mul(Z, F[u, 0, b], F[v, k, b], m, mq, PI, PJ, 1.0)
                    elif cst[v]:
                        _acc_mul(Z, F[u, k, b], F[v, 0, b], m, mq, PI, PJ, 1.0)
                    else:
                        for j in range(k + 1):
                            _acc_mul(Z, F[u, j, b], F[v, k - j, b], m, mq, PI, PJ, 1.0)
                elif o == T_SQR:
                    _clear(Z)
                    _sqrconv(Z, F, u, k, 0, b, m, mq, PI, PJ)
                elif o == T_DIV:
                    if k == 0:
                        _unary_into(REC[s, b], F[v, 0, b], m, mq, PI, PJ, 7, D)
                    _clear(T)
                    _acc_add(T, F[u, k, b], 1.0)
                    if not cst[v]:
                        for j in range(1, k + 1):
                            _acc_mul(T, F[v, j, b], F[s, k - j, b], m, mq, PI, PJ, -1.0)
                    _clear(Z)
                    _acc_mul(Z, T, REC[s, b], m, mq, PI, PJ, 1.0)
                elif o == T_SQRT:
                    if k == 0:
                        _unary_into(Z, F[u, 0, b], m, mq, PI, PJ, 0, D)
                        _scale_into(T, Z, 2.0)
                        _unary_into(REC[s, b], T, m, mq, PI, PJ, 7, D)
                    else:
                        _clear(T)
                        _acc_add(T, F[u, k, b], 1.0)
                        _clear(S)
                        _sqrconv(S, F, s, k, 1, b, m, mq, PI, PJ)
                        _acc_add(T, S, -1.0)
                        _clear(Z)
                        _acc_mul(Z, T, REC[s, b], m, mq, PI, PJ, 1.0)
                elif o == T_EXP:
                    if k == 0:
                        _unary_into(Z, F[u, 0, b], m, mq, PI, PJ, 1, D)
                    else:
                        _clear(T)
                        for j in range(1, k + 1):
                            _acc_mul(T, F[u, j, b], F[s, k - j, b], m, mq, PI, PJ, float(j))
                        _div_int_into(Z, T, fk)
                elif o == T_LOG:
                    if k == 0:
                        _unary_into(Z, F[u, 0, b], m, mq, PI, PJ, 2, D)
                        _unary_into(REC[s, b], F[u, 0, b], m, mq, PI, PJ, 7, D)
                    else:
                        _quotient_step(Z, F, s, u, u, k, b, m, mq, PI, PJ, REC[s, b], T, S)
                elif o == T_SIN or o == T_COS:
                    ss = s if o == T_SIN else aux[s]
                    cs = aux[s] if o == T_SIN else s
                    if k == 0:
                        _unary_into(F[ss, 0, b], F[u, 0, b], m, mq, PI, PJ, 3, D)
                        _unary_into(F[cs, 0, b], F[u, 0, b], m, mq, PI, PJ, 4, D)
                    else:
                        _clear(T)
                        for j in range(1, k + 1):
                            _acc_mul(T, F[u, j, b], F[cs, k - j, b], m, mq, PI, PJ, float(j))
                        _div_int_into(F[ss, k, b], T, fk)
                        _clear(T)
                        for j in range(1, k + 1):
                            _acc_mul(T, F[u, j, b], F[ss, k - j, b], m, mq, PI, PJ, -float(j))
                        _div_int_into(F[cs, k, b], T, fk)
                elif o == T_TAN:
                    vs = aux[s]  # v = 1 + tan^2 = tan'
                    if k == 0:
                        _unary_into(Z, F[u, 0, b], m, mq, PI, PJ, 5, D)
                        V = F[vs, 0, b]
                        _clear(V)
                        V[0] = 1.0
                        _acc_mul(V, Z, Z, m, mq, PI, PJ, 1.0)
                    else:
                        _clear(T)
                        for j in range(1, k + 1):
                            _acc_mul(T, F[u, j, b], F[vs, k - j, b], m, mq, PI, PJ, float(j))
                        _div_int_into(Z, T, fk)
                        V = F[vs, k, b]
                        _clear(V)
                        _sqrconv(V, F, s, k, 0, b, m, mq, PI, PJ)
                elif o == T_ATAN:
                    vs = aux[s]  # v = 1 + u^2, atan(u)' = u' / v
                    if k == 0:
                        _unary_into(Z, F[u, 0, b], m, mq, PI, PJ, 6, D)
                        V = F[vs, 0, b]
                        _clear(V)
                        V[0] = 1.0
                        _acc_mul(V, F[u, 0, b], F[u, 0, b], m, mq, PI, PJ, 1.0)
                        _unary_into(REC[s, b], V, m, mq, PI, PJ, 7, D, 1.0)  # v0 >= 1
                    else:
                        V = F[vs, k, b]
                        _clear(V)
                        _sqrconv(V, F, u, k, 0, b, m, mq, PI, PJ)
                        _quotient_step(Z, F, s, u, vs, k, b, m, mq, PI, PJ, REC[s, b], T, S)
        # x_[k+1] = f_[k] / (k + 1)
        for i in range(n):
            o = outputs[i]
            for b in range(nb):
                _div_int_into(out[i, k + 1, b], F[o, k, b], fk + 1.0)
    return out


# --------------------------------------------------------------------------
# Affine forms / boxes <-> models <-> intervals
# --------------------------------------------------------------------------
def forms_to_models(F: np.ndarray, mq: int) -> np.ndarray:
    """Affine forms ``(..., m + 2)`` (centre, ``m`` symbols, error radius) as models with
    zero quadratic part, ``(..., L)``."""
    m = F.shape[-1] - 2
    out = np.zeros(F.shape[:-1] + (model_length(m, mq),))
    out[..., : m + 1] = F[..., : m + 1]
    out[..., -1] = F[..., -1]
    return out


def models_to_interval(F: np.ndarray, m: int, mq: int) -> tuple[np.ndarray, np.ndarray]:
    """Interval ranges of models ``(..., L)`` (rounded outward); NaN gives ``[-inf, inf]``.

    ``eps_i^2`` lies in ``[0, 1]``, so a diagonal coefficient ``q_ii`` moves only one
    bound; every other monomial lies in ``[-1, 1]``."""
    pi, pj = _pairs(mq)
    diag = (pi == pj)
    c = F[..., 0]
    with np.errstate(invalid="ignore", over="ignore"):
        Q = F[..., m + 1: -1]
        qd = Q[..., diag]
        R = (np.abs(F[..., 1: m + 1]).sum(axis=-1) + np.abs(Q[..., ~diag]).sum(axis=-1)) * _UPF + _TINY
        pos = np.maximum(qd, 0.0).sum(axis=-1) * _UPF + _TINY
        neg = np.maximum(-qd, 0.0).sum(axis=-1) * _UPF + _TINY
        e = F[..., -1]
        lo = c - ((R + neg + e) * _UPF + _TINY)
        hi = c + ((R + pos + e) * _UPF + _TINY)
        lo = lo - (np.abs(lo) * _k.EPS + _k.ETA)
        hi = hi + (np.abs(hi) * _k.EPS + _k.ETA)
    bad = np.isnan(lo) | np.isnan(hi)
    return np.where(bad, -np.inf, lo), np.where(bad, np.inf, hi)


class TaylorModelODE:
    """Taylor-coefficient enclosures like :class:`verified.affine_taylor.AffineTaylorODE`,
    computed in degree-2 Taylor models over the symbols of the inputs.

    ``quadratic_symbols``: at most this many symbols (the first ones: a set's own
    parameters come first in :meth:`verified.sets.DoubletonSets.affine_forms`) get
    quadratic monomials; the others stay linear. Cost per product grows as its square.
    One box at a time (no batching over boxes inside the kernel): meant for few sets of
    deep graphs (robots), where the affine kernel's batching gains little.
    """

    #: a set's forms should give every parameter a symbol of its own (the linear part
    #: costs O(m) per operation; the quadratic monomials go to the widest ones)
    all_symbols = True

    def __init__(self, graph, quadratic_symbols: int = QUADRATIC_SYMBOLS):
        if graph.n_outputs != graph.n_inputs:
            raise ValueError(
                f"an ODE right-hand side needs as many outputs as inputs, got {graph.n_inputs} "
                f"inputs and {graph.n_outputs} outputs"
            )
        q = int(quadratic_symbols)
        if q < 0:
            raise ValueError(f"quadratic_symbols must be >= 0, got {quadratic_symbols!r}")
        self.graph = graph
        self.n = graph.n_inputs
        self.n_params = graph.n_params
        self.quadratic_symbols = q
        self._tape = _Tape(graph)

    def _run(self, X, P, order, m, mq):
        t = self._tape
        pi, pj = _pairs(mq)
        return _model_kernel(t.op, t.a0, t.a1, t.aux, t.idx, t.cst, t.clo, t.chi, t.outputs,
                             np.ascontiguousarray(X), np.ascontiguousarray(P), int(order), m, mq, pi, pj)

    def _interval(self, out, m, mq):
        lo, hi = models_to_interval(out, m, mq)  # (n, K + 1, B)
        return Interval._from_bounds(np.ascontiguousarray(lo.transpose(2, 1, 0)),
                                     np.ascontiguousarray(hi.transpose(2, 1, 0)))

    def series(self, X, order, params=None) -> Interval:
        """Interval enclosures of ``x_[0..order]`` from input affine forms ``X``
        (n, B, m + 2) over ``m`` symbols of the caller's choosing (a set's own
        parameters first). Parameters are intervals without symbols. (B, order + 1, n)."""
        n, nb, m2 = X.shape
        if n != self.n:
            raise ValueError(f"forms must have shape ({self.n}, B, m + 2), got {X.shape}")
        m = m2 - 2
        mq = min(m, self.quadratic_symbols)
        # the widest symbols (over the batch) first: they get the quadratic monomials
        widths = np.abs(X[:, :, 1: m + 1]).sum(axis=0).max(axis=0)
        perm = np.argsort(-widths, kind="stable")
        X = np.concatenate([X[:, :, :1], X[:, :, 1: m + 1][:, :, perm], X[:, :, m + 1:]], axis=2)
        Xm = forms_to_models(X, mq)
        P = np.zeros((self.n_params, nb, model_length(m, mq)))
        if self.n_params:
            p = _as_interval(params).broadcast_to((nb, self.n_params))
            P = forms_to_models(box_forms(p.lo, p.hi, np.full(self.n_params, -1), m), mq)
        return self._interval(self._run(Xm, P, int(order), m, mq), m, mq)

    def coefficients(self, x, order, params=None) -> Interval:
        """Interval enclosures of ``x_[0..order]`` over boxes ``x`` (B, n) (one symbol
        per wide input or parameter), shape (B, order + 1, n)."""
        order = int(order)
        if order < 1:
            raise ValueError(f"order must be >= 1, got {order}")
        X, P, m = _wide_symbol_forms(self.graph, x, params, extra=0)
        mq = min(m, self.quadratic_symbols)
        return self._interval(self._run(forms_to_models(X, mq), forms_to_models(P, mq), order, m, mq), m, mq)

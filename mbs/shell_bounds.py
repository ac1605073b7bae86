"""Bounds on a chain's inverse mass matrix valid for every configuration (issue 43, item 3).

:func:`inverse_mass_bounds` returns constants ``c_i`` with ``(M(q)^-1)_ii <= c_i`` for
*every* ``q``, proven. With an energy bound ``H = qd^T M(q) qd / 2 + V(q) <= hmax`` they
bound every joint rate, whatever the positions:

    qd_i^2 <= 2 (hmax - V(q)) (M(q)^-1)_ii <= 2 (hmax - min V) c_i

(for fixed ``q``, ``min {qd^T M qd : qd_i = v} = v^2 / (M^-1)_ii``). That is what lets
:mod:`verified.consistency.shell_boxes` continue a passive chain's enclosure after its Taylor sets
break down (a chaotic free fall): the positions there grow past any box on which an
interval evaluation of ``M(q)^-1`` could be proven.

How ``c_i`` is proven (revolute joint ``i`` of body ``i``, parent body ``p``):
``1 / (M(q)^-1)_ii = min {qd^T M(q) qd : qd_i = 1}``, and ``qd^T M qd`` is twice the
kinetic energy, a sum over the bodies. Dropping every body but ``i`` and ``p`` and
letting ``p`` move freely (any twist ``V_p``, not only what its own joints allow) can
only lower the minimum, so

    1 / (M^-1)_ii >= w(q_i) = min over V_p of V_p^T I_p V_p + (Y V_p + S)^T I_i (Y V_p + S)

with ``I_p``, ``I_i`` the bodies' spatial inertias, ``S`` the joint's axis and ``Y`` the
motion transform from ``p``'s frame to ``i``'s, which depends on ``q_i`` alone. With
``P(q_i) = Y^-T I_p Y^-1`` (the parent's inertia in ``i``'s frame), ``w(q_i) >= L`` holds
exactly when the 7 x 7 matrix ``[[P + I_i, I_i S], [S^T I_i, S^T I_i S - L]]`` is
positive semidefinite (Schur complement). That matrix is a polynomial in ``cos q_i``,
``sin q_i``; its LDL^T pivots are proven positive over pieces covering one turn of
``q_i`` (:func:`mbs.simulate.mass_matrix.pivots_proven`) for ``L`` a little below the
float minimum of ``w`` on a grid. A joint on the fixed base has ``V_p = 0`` and
``w = S^T I_i S``. Where the parent is itself a revolute joint on the fixed base, its
twist is ``S_p t`` only, and ``w(q_i) = M22 - M12^2 / M11`` of the two bodies' own 2 x 2
mass matrix (tighter, and it needs no positive definite spatial inertia: point masses
work), proven the same way. Then ``c_i = 1 / L``.

No bound (``inf``) for a prismatic joint (its range is not one turn), for a joint where
neither relaxation applies (a parent not on the base and a body without positive
definite spatial inertia), or for a chain with symbolic (non-numeric) data. Uncertain
parameters are not covered: the bounds are of the chain as given
(:mod:`mbs.shell_continuation` does not carry such runs on).
"""
from __future__ import annotations

import numpy as np

from verified.graph import trace
from verified.arith.interval import Interval

__all__ = ["inverse_mass_bounds"]

_PIECES = 256  # pieces of one turn of q_i for the pivot proof
_GRID = 2048  # float grid for the minimum of w


def _skew(v):
    return [[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]]


def _mat(A, B):
    return [[sum(A[i][k] * B[k][j] for k in range(len(B))) for j in range(len(B[0]))] for i in range(len(A))]


def _T(A):
    return [list(r) for r in zip(*A)]


def _spatial(m, c, Ic):
    """6 x 6 spatial inertia at a frame's origin (angular first) of a body with mass
    ``m``, centre of mass ``c`` and rotational inertia ``Ic`` about it (that frame's
    axes); nested lists, entries floats or tracers."""
    C = _skew(c)
    CtC = _mat(_T(C), C)
    top = [[Ic[i][j] + m * CtC[i][j] for j in range(3)] + [m * C[i][j] for j in range(3)] for i in range(3)]
    bot = [[m * C[j][i] for j in range(3)] + [m if i == j else 0.0 for j in range(3)] for i in range(3)]
    return top + bot


def _rot(a, c, s):
    """Rotation by the angle with cosine c, sine s about the unit axis a."""
    A = _skew(a)
    A2 = _mat(A, A)
    return [[(1.0 if i == j else 0.0) + s * A[i][j] + (1.0 - c) * A2[i][j] for j in range(3)] for i in range(3)]


def _floats(body):
    """(mass, com, Ic, axis, (R, p), kind) of a body as floats, or None if symbolic."""
    try:
        m = float(body.inertia.mass)
        com = [float(v) for v in body.inertia.com]
        Ic = [[float(v) for v in row] for row in body.inertia.inertia]
        a = np.array([float(v) for v in body.joint.axis])
        R = [[float(v) for v in row] for row in body.joint.placement[0]]
        p = [float(v) for v in body.joint.placement[1]]
    except (TypeError, ValueError):
        return None
    a = a / np.linalg.norm(a)
    return m, com, Ic, list(a), (R, p), body.joint.kind


def _parent_in_child(parent, child, c, s):
    """The parent's spatial inertia expressed in the child's body frame, the child's
    joint at angle (cos, sin) = (c, s)."""
    mp, comp, Icp = parent[:3]
    a, (R, p) = child[3], child[4]
    Rpc = _mat(R, _rot(a, c, s))  # child frame axes in the parent frame
    Rt = _T(Rpc)
    d = [comp[k] - p[k] for k in range(3)]
    cc = [sum(Rt[i][k] * d[k] for k in range(3)) for i in range(3)]
    Ic = _mat(_mat(Rt, Icp), Rpc)
    return _spatial(mp, cc, Ic)


def _w_float(parent, child, q):
    """w(q) of the module docstring in floats, for an array of angles."""
    Ii = np.array(_spatial(*child[:3]))
    S = np.r_[child[3], 0.0, 0.0, 0.0]
    Iinv = np.linalg.inv(Ii)
    out = np.empty(len(q))
    for k, qk in enumerate(q):
        P = np.array(_parent_in_child(parent, child, np.cos(qk), np.sin(qk)))
        out[k] = S @ np.linalg.solve(Iinv + np.linalg.inv(P), S)
    return out


def _pivots(K):
    """LDL^T pivots of the symmetric matrix K (nested lists of tracers or floats)."""
    n = len(K)
    L = [[None] * n for _ in range(n)]
    D = []
    for k in range(n):
        d = K[k][k]
        for j in range(k):
            d = d - L[k][j] * L[k][j] * D[j]
        D.append(d)
        for i in range(k + 1, n):
            v = K[i][k]
            for j in range(k):
                v = v - L[i][j] * L[k][j] * D[j]
            L[i][k] = v / d
    return D


def _proven_floor(parent, child, L: float, pieces: int) -> bool:
    """Whether w(q) >= L for every q (the 7 x 7 matrix's pivots > 0 over one turn)."""
    from .simulate.mass_matrix import (
        pivots_proven,  # (mbs.simulate imports this module's users)
    )
    Ii = _spatial(*child[:3])
    S = list(child[3]) + [0.0, 0.0, 0.0]
    IS = [sum(Ii[r][k] * S[k] for k in range(6)) for r in range(6)]
    SIS = sum(S[r] * IS[r] for r in range(6))

    def fn(x, _p):
        P = _parent_in_child(parent, child, np.cos(x[0]), np.sin(x[0]))
        K = [[P[r][k] + Ii[r][k] for k in range(6)] + [IS[r]] for r in range(6)] + [IS + [SIS - L]]
        return _pivots(K)

    g = trace(fn, 1)
    e = np.linspace(-np.pi, np.pi, pieces + 1)
    e[0], e[-1] = -4.0, 4.0  # the ends widened past +-pi (one turn is covered whatever rounding)
    return bool(pivots_proven(g, e[:-1, None], e[1:, None]).all())


def _axis_floor(child) -> float:
    """A proven lower bound of S^T I_i S (interval arithmetic)."""
    m, com, Ic, a = child[:4]
    I = Interval
    av = [I(v) for v in a]
    cv = [I(v) for v in com]
    # S^T (Ic + m C^T C) S = a^T Ic a + m |c x a|^2
    rot = sum((av[i] * I(Ic[i][j]) * av[j] for i in range(3) for j in range(3)), I(0.0))
    cx = [cv[1] * av[2] - cv[2] * av[1], cv[2] * av[0] - cv[0] * av[2], cv[0] * av[1] - cv[1] * av[0]]
    val = rot + I(m) * (cx[0] * cx[0] + cx[1] * cx[1] + cx[2] * cx[2])
    return float(np.asarray(val.lo))


def _child_in_parent(parent, child, c, s):
    """(M11, M12, M22) of the two bodies alone with the parent on a fixed revolute joint
    (the fixed-base mass matrix of joints p, i), all in the parent's frame: the child's
    inertia moved there (it turns with q_i), the child's joint axis as the constant
    twist ``[R a; p x R a]``, the parent's ``[a_p; 0]``."""
    m, com, Ic, a, (R, p) = child[:5]
    Rpc = _mat(R, _rot(a, c, s))
    cc = [sum(Rpc[r][k] * com[k] for k in range(3)) + p[r] for r in range(3)]
    Icc = _mat(_mat(Rpc, Ic), _T(Rpc))
    Ii = _spatial(m, cc, Icc)
    Ip = _spatial(*parent[:3])
    Ra = [sum(R[r][k] * a[k] for k in range(3)) for r in range(3)]
    S = Ra + [p[1] * Ra[2] - p[2] * Ra[1], p[2] * Ra[0] - p[0] * Ra[2], p[0] * Ra[1] - p[1] * Ra[0]]
    Sp = list(parent[3]) + [0.0, 0.0, 0.0]

    def quad(u, A, v):
        return sum(u[r] * sum(A[r][k] * v[k] for k in range(6) if v[k] != 0.0) for r in range(6) if u[r] != 0.0)
    return quad(Sp, Ip, Sp) + quad(Sp, Ii, Sp), quad(Sp, Ii, S), quad(S, Ii, S)


def _w_base_float(parent, child, q):
    """w(q) = M22 - M12^2 / M11 of :func:`_child_in_parent` in floats."""
    out = np.empty(len(q))
    for k, qk in enumerate(q):
        a, b, d = _child_in_parent(parent, child, np.cos(qk), np.sin(qk))
        out[k] = d - b * b / a
    return out


def _proven_floor_base(parent, child, L: float, pieces: int) -> bool:
    """Whether M22 - M12^2 / M11 >= L over one turn (pivots of [[M11, M12], [M12, M22 - L]] > 0)."""
    from .simulate.mass_matrix import pivots_proven

    def fn(x, _p):
        a, b, d = _child_in_parent(parent, child, np.cos(x[0]), np.sin(x[0]))
        return _pivots([[a, b], [b, d - L]])

    e = np.linspace(-np.pi, np.pi, pieces + 1)
    e[0], e[-1] = -4.0, 4.0
    return bool(pivots_proven(trace(fn, 1), e[:-1, None], e[1:, None]).all())


def _floor(parent, child, w_float, proven, pieces) -> float:
    """1 / L rounded up for the largest L in (0.98, 0.9, 0.7, 0.5) x the float grid
    minimum of w (``w_float(parent, child, q)``) that ``proven(parent, child, L, pieces)``
    proves; inf if none."""
    try:
        wmin = float(np.min(w_float(parent, child, np.linspace(-np.pi, np.pi, _GRID))))
    except np.linalg.LinAlgError:
        return np.inf
    if not wmin > 0:
        return np.inf
    for frac in (0.98, 0.9, 0.7, 0.5):
        L = frac * wmin
        if proven(parent, child, L, pieces):
            return float(np.nextafter(1.0 / L, np.inf))  # (the next float above the quotient)
    return np.inf


def inverse_mass_bounds(chain, *, pieces: int = _PIECES) -> np.ndarray:
    """Proven upper bounds ``c`` (n,) of the diagonal of ``M(q)^-1`` valid for every
    configuration ``q`` of ``chain`` (an :class:`mbs.Chain` with numeric data; see the
    module docstring for the proof); ``inf`` where no bound is proven."""
    data = [_floats(b) for b in chain.bodies]
    out = np.full(chain.n, np.inf)
    for i, child in enumerate(data):
        if child is None or child[5] != "revolute":
            continue
        par = chain.bodies[i].joint.parent
        if par < 0:
            low = _axis_floor(child)
            if low > 0:
                out[i] = float(np.nextafter(1.0 / low, np.inf))
            continue
        parent = data[par]
        if parent is None:
            continue
        if parent[5] == "revolute" and chain.bodies[par].joint.parent < 0:
            # the parent turns about its fixed axis only: the two bodies' own mass matrix
            out[i] = _floor(parent, child, _w_base_float, _proven_floor_base, pieces)
        if np.isinf(out[i]) and min(np.linalg.eigvalsh(np.array(_spatial(*d[:3])))[0] for d in (parent, child)) > 0:
            # the parent free to move (whatever its own joint)
            out[i] = _floor(parent, child, _w_float, _proven_floor, pieces)
    return out

"""3-vectors, 3x3 matrices and rigid transforms over a generic scalar.

Vectors are tuples of 3 scalars, matrices tuples of 3 row tuples.  Scalars may be floats,
numpy batch arrays, intervals, expression-graph tracers or sympy expressions (see
:mod:`mbs.scalar`).  Nothing here compares or branches on a state value.

Conventions (Pinocchio/Featherstone): a placement ``(R, p)`` of frame B in frame A maps
B-coordinates to A-coordinates, ``x_A = R x_B + p``.  Spatial motion vectors are pairs
``(w, v)`` (angular, linear at the frame origin), spatial forces ``(n, f)`` (moment about
the frame origin, force), both expressed in the frame they belong to.
"""
from __future__ import annotations

from .scalar import add, sub, mul, neg, dot, cos, sin, is_zero

ZERO3 = (0, 0, 0)
EYE3 = ((1, 0, 0), (0, 1, 0), (0, 0, 1))


def vadd(a, b):
    return (add(a[0], b[0]), add(a[1], b[1]), add(a[2], b[2]))


def vsub(a, b):
    return (sub(a[0], b[0]), sub(a[1], b[1]), sub(a[2], b[2]))


def vneg(a):
    return (neg(a[0]), neg(a[1]), neg(a[2]))


def vscale(s, a):
    return (mul(s, a[0]), mul(s, a[1]), mul(s, a[2]))


def vdot(a, b):
    return dot(a, b)


def cross(a, b):
    return (sub(mul(a[1], b[2]), mul(a[2], b[1])),
            sub(mul(a[2], b[0]), mul(a[0], b[2])),
            sub(mul(a[0], b[1]), mul(a[1], b[0])))


def mv(R, v):
    """R @ v."""
    return (dot(R[0], v), dot(R[1], v), dot(R[2], v))


def mtv(R, v):
    """R.T @ v."""
    return (dot((R[0][0], R[1][0], R[2][0]), v),
            dot((R[0][1], R[1][1], R[2][1]), v),
            dot((R[0][2], R[1][2], R[2][2]), v))


def transpose(A):
    return tuple(tuple(A[j][i] for j in range(3)) for i in range(3))


def mm(A, B):
    """A @ B."""
    Bt = transpose(B)
    return tuple(tuple(dot(A[i], Bt[j]) for j in range(3)) for i in range(3))


def madd(A, B):
    return tuple(tuple(add(A[i][j], B[i][j]) for j in range(3)) for i in range(3))


def mscale(s, A):
    return tuple(tuple(mul(s, A[i][j]) for j in range(3)) for i in range(3))


def rotate_inertia(R, I):
    """R @ I @ R.T (inertia tensor re-expressed in the frame R maps into)."""
    return mm(mm(R, I), transpose(R))


def axis_rotation(axis, c, s):
    """Rotation matrix about the constant unit ``axis`` given cos ``c`` and sin ``s``
    of the angle (Rodrigues: R = c E + s [a]x + (1 - c) a a^T).  Exact-zero axis
    components are folded away, so a rotation about z has only 4 non-trivial entries."""
    x, y, z = axis
    one_c = sub(1, c)
    def outer(i, j):
        return mul(mul(axis[i], axis[j]), one_c)
    return (
        (add(c, outer(0, 0)) if not is_zero(x) else c,
         sub(outer(0, 1), mul(z, s)),
         add(outer(0, 2), mul(y, s))),
        (add(outer(1, 0), mul(z, s)),
         add(c, outer(1, 1)) if not is_zero(y) else c,
         sub(outer(1, 2), mul(x, s))),
        (sub(outer(2, 0), mul(y, s)),
         add(outer(2, 1), mul(x, s)),
         add(c, outer(2, 2)) if not is_zero(z) else c),
    )


def _simplify_axis_rotation(axis, c, s):
    """Same as :func:`axis_rotation`, with the exact forms for +-x, +-y, +-z."""
    x, y, z = axis
    for k in range(3):
        others = [axis[i] for i in range(3) if i != k]
        if all(is_zero(o) for o in others) and (axis[k] == 1 or axis[k] == -1):
            sk = s if axis[k] == 1 else neg(s)
            if k == 0:
                return ((1, 0, 0), (0, c, neg(sk)), (0, sk, c))
            if k == 1:
                return ((c, 0, sk), (0, 1, 0), (neg(sk), 0, c))
            return ((c, neg(sk), 0), (sk, c, 0), (0, 0, 1))
    return axis_rotation(axis, c, s)


def joint_rotation(axis, q):
    """Rotation of a revolute joint about constant unit ``axis`` by angle ``q``."""
    return _simplify_axis_rotation(axis, cos(q), sin(q))


# --- rigid transforms -------------------------------------------------------------

def compose(T1, T2):
    """(R1, p1) * (R2, p2) = (R1 R2, R1 p2 + p1)."""
    R1, p1 = T1
    R2, p2 = T2
    return (mm(R1, R2), vadd(mv(R1, p2), p1))


def apply(T, x):
    R, p = T
    return vadd(mv(R, x), p)


# --- spatial algebra (body frames) ------------------------------------------------

def motion_to_child(R, p, w, v):
    """Motion vector of the parent frame, expressed in the child frame whose placement
    in the parent is (R, p):  w' = R^T w,  v' = R^T (v + w x p)."""
    return mtv(R, w), mtv(R, vadd(v, cross(w, p)))


def force_to_parent(R, p, n, f):
    """Force (n, f) in the child frame re-expressed in the parent frame:
    f' = R f,  n' = R n + p x f'."""
    fp = mv(R, f)
    return vadd(mv(R, n), cross(p, fp)), fp


def motion_cross_motion(w, v, w2, v2):
    """(w, v) x (w2, v2) = (w x w2, w x v2 + v x w2)."""
    return cross(w, w2), vadd(cross(w, v2), cross(v, w2))


def motion_cross_force(w, v, n, f):
    """(w, v) x* (n, f) = (w x n + v x f, w x f)."""
    return vadd(cross(w, n), cross(v, f)), cross(w, f)


def inertia_times_motion(m, h, I_o, w, v):
    """Spatial inertia (mass m, first moment h = m c, rotational inertia I_o about the
    frame origin) times motion (w, v):  n = I_o w + h x v,  f = m v + w x h."""
    return vadd(mv(I_o, w), cross(h, v)), vadd(vscale(m, v), cross(w, h))


def inertia_about_origin(m, c, I_c):
    """Rotational inertia about the frame origin from the one about the centre of mass
    (parallel-axis theorem): I_o = I_c + m (|c|^2 E - c c^T)."""
    cc = dot(c, c)
    return tuple(tuple(add(I_c[i][j], mul(m, sub(cc if i == j else 0, mul(c[i], c[j]))))
                       for j in range(3)) for i in range(3))


def inertia_to_parent(R, p, m, h, I_o):
    """Spatial inertia (m, h, I_o) of a body given in the child frame, re-expressed in
    the parent frame (child placement (R, p)).  Returns (m, h', I_o')."""
    hr = mv(R, h)
    Ir = rotate_inertia(R, I_o)
    h2 = vadd(hr, vscale(m, p))
    # I about new origin: I_o' = Ir + 2 (p.hr) E - p hr^T - hr p^T + m (|p|^2 E - p p^T)
    ph = dot(p, hr)
    pp = dot(p, p)
    I2 = tuple(tuple(
        add(Ir[i][j],
            sub(add(mul(2, ph) if i == j else 0, mul(m, pp) if i == j else 0),
                add(add(mul(p[i], hr[j]), mul(hr[i], p[j])), mul(m, mul(p[i], p[j])))))
        for j in range(3)) for i in range(3))
    return m, h2, I2

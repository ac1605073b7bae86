"""Reference models as generic-scalar code (moved from tests/test_graph.py): F is a
namespace of elementary functions, NP (numpy) or SP (sympy), so one definition gives
the float reference, the traced graph and the sympy expression."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import sympy as sp

# --------------------------------------------------------------------------- models
# Generic-scalar model code: F is a namespace of elementary functions (numpy or sympy).

NP = SimpleNamespace(sin=np.sin, cos=np.cos, tan=np.tan, atan=np.arctan, exp=np.exp, log=np.log, sqrt=np.sqrt)
SP = SimpleNamespace(sin=sp.sin, cos=sp.cos, tan=sp.tan, atan=sp.atan, exp=sp.exp, log=sp.log, sqrt=sp.sqrt)


def double_pendulum_matrices(x, F=NP, m1=1.0, m2=1.0, l1=1.0, l2=1.0, g=9.81):
    """A(x), b(x) of the paper's eq. (22) (lower-right 2x2 block of A, last two entries of b)."""
    x1, x2, x3, x4 = x
    c = F.cos(x2)
    A = [[m1 * l1 + m2 * (l1 + l2 * c), m2 * l2 * c], [m2 * (l1 * c + l2), m2 * l2]]
    b = [
        -g * (m1 + m2) * F.sin(x1) + m2 * l2 * F.sin(x2) * (x3 + x4) ** 2,
        -g * m2 * F.sin(x1 + x2) - m2 * l1 * F.sin(x2) * x3**2,
    ]
    return A, b


def double_pendulum_rhs(x, F=NP, m1=1.0, m2=1.0, l1=1.0, l2=1.0, g=9.81):
    """x_dot = A(x)^-1 b(x) of eq. (22) written out (Cramer's rule, factored determinant)."""
    (a11, a12), (a21, a22) = double_pendulum_matrices(x, F, m1, m2, l1, l2, g)[0]
    b1, b2 = double_pendulum_matrices(x, F, m1, m2, l1, l2, g)[1]
    det = m2 * l1 * l2 * (m1 + m2 * F.sin(x[1]) ** 2)  # = a11 a22 - a12 a21
    return [x[2], x[3], (a22 * b1 - a12 * b2) / det, (a11 * b2 - a21 * b1) / det]


def pendulum_energy(x, p, F=NP):
    """H(q, qd) = 0.5 m l^2 qd^2 + m g l (1 - cos q); p = (m, l, g)."""
    q, qd = x
    m, l, g = p
    return 0.5 * m * l**2 * qd**2 + m * g * l * (1 - F.cos(q))


def all_ops(x, p, F=NP):
    """Exercises every opcode on domains where it is defined for all real a, b."""
    a, b = x
    c = p[0]
    u = a * a + 1.0  # >= 1
    return [
        F.exp(0.3 * a) - F.log(u) + F.sqrt(u) * b,
        F.tan(0.5 * F.sin(b)) + F.atan(a / u) - b**3 + c * a**4 / u**2,
        (a - b) * (a + b) / (2 + F.cos(a)) + F.exp(-(b * b)) * c,
        F.sqrt(u) ** 3 - 1 / F.sqrt(u) + u**-2,
    ]


def generic_model(q, l, m, x):
    """Generic scalar code: runs on floats, ndarrays, Intervals and Tracers."""
    return np.sin(q) * l + m * x

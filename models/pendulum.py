"""Simple pendulum of paper sec. 5.1: point mass m on a massless rod of length l.

The paper does not publish the parameters; we use m = 1 kg, l = 1 m, g = 9.81 m/s^2.
Coordinates: q = phi (angle from the downward vertical) [rad], state x = (q, qd).

- eq. (18): qdd = -(g/l) sin q
- eq. (19): H = 1/2 m ((l sin q qd)^2 + (l cos q qd)^2) + m g (l - l cos q)
  (zero level at the lowest point; the chain models put it at the pivot, i.e.
  H_chain = H_19 - m g l).
- initial box of sec. 5.1: q(0) in [2.1, 2.2], qd(0) in [3.1, 3.2].
"""
from __future__ import annotations

from fractions import Fraction

import numpy as np

from mbs import chain_from_dh
from verified.arith.exact import enclose_fraction

from .double_pendulum import _cos, _sin, _sq

M, L, G = 1.0, 1.0, 9.81
#: initial box of sec. 5.1 (these bounds are doubles exactly as printed... see below)
INITIAL_BOX = ((2.1, 3.1), (2.2, 3.2))


def initial_box():
    """(lo, hi) float arrays enclosing [2.1, 2.2] x [3.1, 3.2] (rounded outward)."""
    lo = np.array([enclose_fraction(Fraction(21, 10))[0], enclose_fraction(Fraction(31, 10))[0]])
    hi = np.array([enclose_fraction(Fraction(22, 10))[1], enclose_fraction(Fraction(32, 10))[1]])
    return lo, hi


def rhs(x, p=None, m=M, l=L, g=G):
    """eq. (18) over the generic scalar: x = (q, qd) -> (qd, -(g/l) sin q)."""
    q, qd = x[0], x[1]
    return [qd, -(g / l) * _sin(q)]


def hamiltonian(x, p=None, m=M, l=L, g=G):
    """eq. (19), written as in the paper (not simplified)."""
    q, qd = x[0], x[1]
    return 0.5 * m * (_sq(l * _sin(q) * qd) + _sq(l * _cos(q) * qd)) \
        + m * g * (l - l * _cos(q))


def sympy_model(m=M, l=L, g=G):
    """(x symbols, [rhs exprs], H expr) of eqs. (18)-(19)."""
    import sympy  # (sympy only for the symbolic model: 0.4 s the numeric modes never need)
    q, qd = sympy.symbols("q qd", real=True)
    f = [qd, -sympy.Float(g) / sympy.Float(l) * sympy.sin(q)]
    H = sympy.Rational(1, 2) * m * ((l * sympy.sin(q) * qd) ** 2 + (l * sympy.cos(q) * qd) ** 2) \
        + m * g * (l - l * sympy.cos(q))
    return [q, qd], f, H


def chain(m=M, l=L, g=G):
    """The pendulum as a one-link DH chain: a = l, point mass at the tip, gravity along
    +x of the base frame (so q is the angle from the downward vertical)."""
    return chain_from_dh([dict(joint="R", a=l, mass=m)], gravity=(g, 0.0, 0.0),
                         name="pendulum")

"""The paper's double pendulum (sec. 5.2): point masses m1, m2 on massless rods l1, l2.

Parameters (Rauh, Hofer, Auer, SCAN 2006): m1 = m2 = 1 kg, l1 = l2 = 1 m, g = 9.81 m/s^2.
Coordinates (DH): x1 = phi1, x2 = phi2 - phi1 (relative angle), x3 = x1', x4 = x2'
(angles from the downward vertical), eq. (21).

Three constructions that agree (tests/mbs/test_mbs_models.py):

1. :func:`rhs` / :func:`sympy_model` -- eq. (22) by hand.  The 2x2 matrix of eq. (22)
   is *not* the mass matrix (it is not symmetric) but eq. (22) is a correct equation of
   motion.  We solve it with Cramer's rule and the determinant in the factored form
   ``m2 l1 l2 (m1 + m2 sin(x2)^2)`` (a square, never ``s*s``): in interval arithmetic
   this stays away from zero, the naive ``A11 A22 - A12 A21`` can contain zero.
2. :func:`dh_chain` -- a standard-DH planar chain, a_i = l_i, point masses at the DH frame
   origins (link ends), gravity along +x of the base frame.
3. :func:`urdf_chain` -- a small URDF (joints about -y, masses hanging along -z, the usual
   gravity (0, 0, -9.81)).

Eq. (23) cannot be used as it stands: it is the mass matrix for the *absolute* angle
rates (phi1', phi2') (and it misses nothing else), but the state uses the relative angle
x2 = phi2 - phi1.  In (x1, x2) the mass matrix is J^T M_abs J with J = [[1, 0], [1, 1]]:
``M11 = (m1+m2) l1^2 + m2 l2^2 + 2 m2 l1 l2 cos x2``, ``M12 = m2 l2^2 + m2 l1 l2 cos x2``,
``M22 = m2 l2^2`` (:func:`mass_matrix`), which is what the chain models produce.

The energy eq. (24) with eq. (20): :func:`hamiltonian` (zero level at the pivot, like the
chain models).  Initial box eq. (25): :func:`initial_box`.
"""
from __future__ import annotations

from fractions import Fraction

import numpy as np

from mbs import chain_from_dh, chain_from_urdf
from mbs.scalar import cos, sin, square
from verified.arith.exact import enclose_fraction, enclose_pi_multiple
from verified.graph import trace

M1 = M2 = 1.0
L1 = L2 = 1.0
G = 9.81
PARAMS = dict(m1=M1, m2=M2, l1=L1, l2=L2, g=G)


def _sin(x):
    return sin(x)


def _cos(x):
    return cos(x)


def _sq(x):
    return square(x)


def rhs(x, p=None, m1=M1, m2=M2, l1=L1, l2=L2, g=G):
    """eq. (22) over the generic scalar (floats, batches, Interval, Tracer, sympy):
    x = (x1, x2, x3, x4) -> (x3, x4, x3', x4').  ``p`` is ignored (trace signature)."""
    x1, x2, x3, x4 = x[0], x[1], x[2], x[3]
    s2, c2 = _sin(x2), _cos(x2)
    # eq. (22): A [x3', x4']^T = b
    a11 = m1 * l1 + m2 * (l1 + l2 * c2)
    a12 = m2 * l2 * c2
    a21 = m2 * (l1 * c2 + l2)
    a22 = m2 * l2
    b1 = -g * (m1 + m2) * _sin(x1) + m2 * l2 * s2 * _sq(x3 + x4)
    b2 = -g * m2 * _sin(x1 + x2) - m2 * l1 * s2 * _sq(x3)
    det = m2 * l1 * l2 * (m1 + m2 * _sq(s2))   # = a11 a22 - a12 a21, factored
    return [x3, x4, (a22 * b1 - a12 * b2) / det, (a11 * b2 - a21 * b1) / det]


def hamiltonian(x, p=None, m1=M1, m2=M2, l1=L1, l2=L2, g=G):
    """eq. (24) with the positions/velocities of eq. (20), phi1 = x1, phi2 = x1 + x2."""
    x1, x2, x3, x4 = x[0], x[1], x[2], x[3]
    ph1, ph2 = x1, x1 + x2
    w1, w2 = x3, x3 + x4
    py1 = -l1 * _cos(ph1)
    py2 = -l1 * _cos(ph1) - l2 * _cos(ph2)
    vx1, vy1 = l1 * _cos(ph1) * w1, l1 * _sin(ph1) * w1
    vx2 = l1 * _cos(ph1) * w1 + l2 * _cos(ph2) * w2
    vy2 = l1 * _sin(ph1) * w1 + l2 * _sin(ph2) * w2
    return (m1 * g * py1 + m2 * g * py2 + 0.5 * m1 * (_sq(vx1) + _sq(vy1))
            + 0.5 * m2 * (_sq(vx2) + _sq(vy2)))


def mass_matrix(x, m1=M1, m2=M2, l1=L1, l2=L2):
    """Mass matrix in the relative coordinates (x1, x2) (not eq. (23); see module doc)."""
    c2 = _cos(x[1])
    m11 = (m1 + m2) * l1 ** 2 + m2 * l2 ** 2 + 2 * m2 * l1 * l2 * c2
    m12 = m2 * l2 ** 2 + m2 * l1 * l2 * c2
    return [[m11, m12], [m12, m2 * l2 ** 2]]


def mass_matrix_eq23(x, m1=M1, m2=M2, l1=L1, l2=L2):
    """eq. (23) as printed (valid for the absolute rates (phi1', phi2'))."""
    c2 = _cos(x[1])
    return [[(m1 + m2) * l1 ** 2, m2 * l1 * l2 * c2], [m2 * l1 * l2 * c2, m2 * l2 ** 2]]


def sympy_model(**params):
    """(x symbols, [4 rhs expressions of eq. (22)], H of eq. (24)) as sympy."""
    import sympy  # (sympy only for the symbolic model: 0.4 s the numeric modes never need)
    xs = list(sympy.symbols("x1:5", real=True))
    kw = {k: sympy.Float(v) if isinstance(v, float) and not float(v).is_integer() else
          sympy.Integer(int(v)) if float(v).is_integer() else v
          for k, v in {**PARAMS, **params}.items()}
    return xs, rhs(xs, **kw), hamiltonian(xs, **kw)


def initial_box():
    """Initial box eq. (25) as (lo, hi) float arrays, rounded outward:
    x1 in [0.99, 1.01] * 3 pi / 4, x2 = -11 pi / 20, x3 = 0.43, x4 = 0.67 (the point
    values are enclosed by one-ulp intervals)."""
    x1lo = enclose_pi_multiple(0, Fraction(99, 100) * Fraction(3, 4))[0]
    x1hi = enclose_pi_multiple(0, Fraction(101, 100) * Fraction(3, 4))[1]
    x2 = enclose_pi_multiple(0, Fraction(-11, 20))
    x3 = enclose_fraction(Fraction(43, 100))
    x4 = enclose_fraction(Fraction(67, 100))
    return np.array([x1lo, x2[0], x3[0], x4[0]]), np.array([x1hi, x2[1], x3[1], x4[1]])


def initial_point():
    """Midpoint-ish float state of eq. (25): (3 pi / 4, -11 pi / 20, 0.43, 0.67)."""
    return np.array([3 * np.pi / 4, -11 * np.pi / 20, 0.43, 0.67])


def dh_chain(m1=M1, m2=M2, l1=L1, l2=L2, g=G):
    """Standard-DH chain: a_i = l_i, point masses at the link ends, gravity (g, 0, 0)
    (base x axis pointing down), q = (x1, x2)."""
    return chain_from_dh([dict(joint="R", a=l1, mass=m1), dict(joint="R", a=l2, mass=m2)],
                         gravity=(g, 0.0, 0.0), name="double_pendulum_dh")


URDF_TEMPLATE = """<?xml version="1.0"?>
<robot name="paper_double_pendulum">
  <link name="base"/>
  <link name="link1">
    <inertial><origin xyz="0 0 -{l1}" rpy="0 0 0"/><mass value="{m1}"/>
      <inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial>
  </link>
  <link name="link2">
    <inertial><origin xyz="0 0 -{l2}" rpy="0 0 0"/><mass value="{m2}"/>
      <inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial>
  </link>
  <joint name="joint1" type="continuous">
    <parent link="base"/><child link="link1"/>
    <origin xyz="0 0 0" rpy="0 0 0"/><axis xyz="0 -1 0"/>
  </joint>
  <joint name="joint2" type="continuous">
    <parent link="link1"/><child link="link2"/>
    <origin xyz="0 0 -{l1}" rpy="0 0 0"/><axis xyz="0 -1 0"/>
  </joint>
</robot>
"""


def urdf_xml(m1=M1, m2=M2, l1=L1, l2=L2):
    return URDF_TEMPLATE.format(m1=repr(float(m1)), m2=repr(float(m2)), l1=repr(float(l1)),
                                l2=repr(float(l2)))


def urdf_chain(m1=M1, m2=M2, l1=L1, l2=L2, g=G):
    """The double pendulum from a small URDF (joints about -y, masses along -z)."""
    return chain_from_urdf(urdf_xml(m1, m2, l1, l2), gravity=(0.0, 0.0, -g))


def rhs_graph():
    """eq. (22) traced into a ``verified.graph.Graph`` (x -> x')."""
    return trace(rhs, 4, input_names=["x1", "x2", "x3", "x4"],
                 output_names=["dx1", "dx2", "dx3", "dx4"])


def energy_graph():
    """eq. (24) traced: x -> [H] (dH/dt = 0 for this undamped model)."""
    return trace(lambda x, p: [hamiltonian(x)], 4, input_names=["x1", "x2", "x3", "x4"],
                 output_names=["H"])

"""Puma 560: Corke's classic standard DH table and inertial data (Robotics Toolbox
``mdl_puma560``; Armstrong-Helouvry/Corke values), and the same robot in modified DH.

Standard DH rows (theta offset 0 for all joints), units m, kg, kg m^2; the centre of mass
``r`` and inertia ``I`` (about the centre of mass, principal values Ixx, Iyy, Izz) are
given in the standard DH link frame (distal end):

====  ========  =======  =======  ======  =================  ======================
link  d         a        alpha    m       r                  I (xx, yy, zz)
====  ========  =======  =======  ======  =================  ======================
1     0         0        pi/2     0       (0, 0, 0)          (0, 0.35, 0)
2     0         0.4318   0        17.4    (-0.3638, 0.006,   (0.13, 0.524, 0.539)
                                           0.2275)
3     0.15005   0.0203   -pi/2    4.8     (-0.0203, -0.0141, (0.066, 0.086, 0.0125)
                                           0.070)
4     0.4318    0        pi/2     0.82    (0, 0.019, 0)      (1.8e-3, 1.3e-3, 1.8e-3)
5     0         0        -pi/2    0.34    (0, 0, 0)          (0.3e-3, 0.4e-3, 0.3e-3)
6     0         0        0        0.09    (0, 0, 0.032)      (0.15e-3, 0.15e-3, 0.04e-3)
====  ========  =======  =======  ======  =================  ======================

(link 1's inertia diag(0, 0.35, 0) is Corke's lumped value; it is positive
semi-definite.)  Gravity (0, 0, -9.81).

The modified-DH version (Craig's form, rows alpha_{i-1}, a_{i-1}, theta_i, d_i) describes
the same robot: modified frame i = standard frame i * (Tx(a_i) Rx(alpha_i))^-1, so the
inertial data is re-expressed with that transform (:func:`modified_rows`).  Both must give
the same M, energies and accelerations (and both match Pinocchio).
"""
from __future__ import annotations

import math

from mbs import Chain, chain_from_dh
from mbs.dh import Tx, Rx, chain_product
from mbs.inertia import RigidInertia, inertia_from_6

PI2 = math.pi / 2

#: (d, a, alpha, mass, r, (Ixx, Iyy, Izz)) per link, standard DH
STANDARD = [
    (0.0, 0.0, PI2, 0.0, (0.0, 0.0, 0.0), (0.0, 0.35, 0.0)),
    (0.0, 0.4318, 0.0, 17.4, (-0.3638, 0.006, 0.2275), (0.13, 0.524, 0.539)),
    (0.15005, 0.0203, -PI2, 4.8, (-0.0203, -0.0141, 0.070), (0.066, 0.086, 0.0125)),
    (0.4318, 0.0, PI2, 0.82, (0.0, 0.019, 0.0), (1.8e-3, 1.3e-3, 1.8e-3)),
    (0.0, 0.0, -PI2, 0.34, (0.0, 0.0, 0.0), (0.3e-3, 0.4e-3, 0.3e-3)),
    (0.0, 0.0, 0.0, 0.09, (0.0, 0.0, 0.032), (0.15e-3, 0.15e-3, 0.04e-3)),
]


def standard_rows():
    return [dict(joint="R", theta=0.0, d=d, a=a, alpha=al, mass=m, com=r,
                 inertia=inertia_from_6(*I), name=f"joint{i + 1}")
            for i, (d, a, al, m, r, I) in enumerate(STANDARD)]


def modified_rows():
    rows = []
    prev_a, prev_alpha = 0.0, 0.0
    for i, (d, a, al, m, r, I) in enumerate(STANDARD):
        # placement of the standard frame i in the modified frame i
        T = chain_product(Tx(a), Rx(al))
        ri = RigidInertia(m, r, inertia_from_6(*I)).transformed(T)
        rows.append(dict(joint="R", theta=0.0, d=d, a=prev_a, alpha=prev_alpha, mass=m,
                         com=ri.com, inertia=ri.inertia, name=f"joint{i + 1}"))
        prev_a, prev_alpha = a, al
    return rows


def puma560(convention="standard", g=9.81) -> Chain:
    """The Puma 560 as a DH chain in the given convention."""
    rows = standard_rows() if convention == "standard" else modified_rows()
    return chain_from_dh(rows, convention=convention, gravity=(0.0, 0.0, -g),
                         name=f"puma560_{convention}")

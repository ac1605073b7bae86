"""Rigid-body inertial data: validation, transformation and merging.

A :class:`RigidInertia` holds the mass ``m`` [kg], the centre of mass ``com`` [m] (a
3-vector in the body frame) and the rotational inertia ``inertia`` [kg m^2] about the
centre of mass, expressed in the body frame (a symmetric 3x3 matrix).  Entries are
Python floats or sympy expressions (symbolic DH parameters).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import ModelError
from .scalar import is_sympy, is_const
from . import spatial as sp3

#: relative tolerance of the positive-semidefiniteness and symmetry checks
INERTIA_TOL = 1e-9

#: tolerance, relative to the trace, of the triangle inequality I1 + I2 >= I3 of the
#: principal moments: thin rods (0, I, I) and flat plates (I1 + I2 = I3) lie on its edge,
#: and a plate's moments written with 4 significant digits miss it by up to 7.5e-4 of
#: the trace; the violations in example-robot-data's files are 0.1 (allegro's fingers)
#: to 1 (placeholders ixx = ixy = ... = izz = 1e-6), except romeo's shoulders (9e-4)
TRIANGLE_TOL = 1e-3


def _num(x):
    """float(x) for numeric constants, None for symbolic ones."""
    if is_sympy(x):
        return float(x) if x.is_number else None
    return float(x)


@dataclass(frozen=True)
class RigidInertia:
    mass: object
    com: tuple
    inertia: tuple

    @staticmethod
    def zero() -> "RigidInertia":
        return RigidInertia(0, (0, 0, 0), ((0, 0, 0), (0, 0, 0), (0, 0, 0)))

    @staticmethod
    def point(mass, com) -> "RigidInertia":
        return RigidInertia(mass, tuple(com), ((0, 0, 0), (0, 0, 0), (0, 0, 0)))

    def is_zero(self) -> bool:
        return is_const(self.mass) and self.mass == 0 and all(
            is_const(v) and v == 0 for row in self.inertia for v in row)

    def transformed(self, T) -> "RigidInertia":
        """The same body described in a frame A, when T = (R, p) is the placement of the
        body frame in A."""
        R, p = T
        return RigidInertia(self.mass, sp3.apply(T, self.com), sp3.rotate_inertia(R, self.inertia))

    def merged(self, other: "RigidInertia") -> "RigidInertia":
        """Union of two rigid bodies given in the same frame (mass, centre of mass and
        inertia about the common centre of mass combined by the parallel-axis theorem)."""
        if other.is_zero():
            return self
        if self.is_zero():
            return other
        m = self.mass + other.mass
        mn = _num(m)
        if mn is not None and mn == 0.0:
            # two massless bodies with rotational inertia only: inertia adds, com irrelevant
            return RigidInertia(0, (0, 0, 0), sp3.madd(self.inertia, other.inertia))
        c = tuple((self.mass * a + other.mass * b) / m for a, b in zip(self.com, other.com))
        I1 = sp3.inertia_about_origin(self.mass, sp3.vsub(self.com, c), self.inertia)
        I2 = sp3.inertia_about_origin(other.mass, sp3.vsub(other.com, c), other.inertia)
        return RigidInertia(m, c, sp3.madd(I1, I2))

    def validate(self, where: str, *, triangle: bool = False) -> None:
        """Raise :class:`ModelError` naming ``where`` if the data is not physical:
        negative mass, a non-symmetric inertia or one that is not positive
        semi-definite (zero is allowed: point masses).  With ``triangle=True`` also
        principal moments that violate the triangle inequality (each at most the sum
        of the other two, within ``TRIANGLE_TOL`` times the trace: zero inertias, thin
        rods (0, I, I) and flat plates, also with rounded decimals, pass).  Symbolic
        entries are not checked."""
        m = _num(self.mass)
        if m is not None:
            if not np.isfinite(m):
                raise ModelError(f"{where}: mass {m} is not finite")
            if m < 0:
                raise ModelError(f"{where}: negative mass {m} kg")
        com = [_num(v) for v in self.com]
        if all(v is not None for v in com) and not np.all(np.isfinite(com)):
            raise ModelError(f"{where}: centre of mass {com} is not finite")
        vals = [[_num(v) for v in row] for row in self.inertia]
        if any(v is None for row in vals for v in row):
            return
        I = np.array(vals, dtype=float)
        if I.shape != (3, 3) or not np.all(np.isfinite(I)):
            raise ModelError(f"{where}: inertia tensor must be a finite 3x3 matrix, got {vals}")
        scale = max(np.abs(I).max(), 1e-300)
        if np.abs(I - I.T).max() > INERTIA_TOL * scale:
            raise ModelError(f"{where}: inertia tensor is not symmetric:\n{I}")
        ev = np.linalg.eigvalsh(0.5 * (I + I.T))
        if ev[0] < -INERTIA_TOL * scale:
            raise ModelError(
                f"{where}: inertia tensor is not positive (semi-)definite, eigenvalues {ev}")
        # The triangle inequality of the principal moments (I1 + I2 >= I3) holds for
        # every rigid body; it is opt-in (URDF links, mbs.urdf) because classic DH data
        # sets violate it (Corke's Puma 560 link 1: diag(0, 0.35, 0), models.puma560),
        # and Pinocchio accepts them.
        if triangle and ev[0] + ev[1] < ev[2] - TRIANGLE_TOL * max(abs(ev).sum(), scale):
            raise ModelError(
                f"{where}: principal moments of inertia ({ev[0]:.6g}, {ev[1]:.6g}, "
                f"{ev[2]:.6g}) kg m^2 violate the triangle inequality I1 + I2 >= I3; "
                "no rigid body has this inertia")


def inertia_from_6(ixx, iyy, izz, ixy=0, ixz=0, iyz=0):
    return ((ixx, ixy, ixz), (ixy, iyy, iyz), (ixz, iyz, izz))


def as_inertia_matrix(value, where: str):
    """Accept a 3x3 nested sequence/array, 3 principal moments, or the 6 values
    (ixx, iyy, izz, ixy, ixz, iyz); return a tuple-of-tuples 3x3 matrix."""
    if value is None:
        return ((0, 0, 0), (0, 0, 0), (0, 0, 0))
    if hasattr(value, "tolist") and not is_sympy(value):
        value = value.tolist()
    try:
        seq = list(value)
    except TypeError:
        raise ModelError(f"{where}: inertia must be a 3x3 matrix, 3 or 6 numbers; got {value!r}") from None
    if len(seq) == 3 and all(hasattr(r, "__len__") and len(r) == 3 for r in seq):
        return tuple(tuple(_scalar(v, where) for v in r) for r in seq)
    if len(seq) == 3:
        a, b, c = (_scalar(v, where) for v in seq)
        return inertia_from_6(a, b, c)
    if len(seq) == 6:
        return inertia_from_6(*(_scalar(v, where) for v in seq))
    raise ModelError(f"{where}: inertia must be a 3x3 matrix, 3 or 6 numbers; got {value!r}")


def _scalar(v, where):
    if is_sympy(v):
        return v
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise ModelError(f"{where}: expected a number or sympy expression, got {v!r}") from None
    return f


def as_vec3(value, where: str, what: str = "vector"):
    if value is None:
        return (0, 0, 0)
    if hasattr(value, "tolist") and not is_sympy(value):
        value = value.tolist()
    try:
        seq = list(value)
    except TypeError:
        raise ModelError(f"{where}: {what} must have 3 entries, got {value!r}") from None
    if len(seq) != 3:
        raise ModelError(f"{where}: {what} must have 3 entries, got {value!r}")
    return tuple(_scalar(v, where) for v in seq)

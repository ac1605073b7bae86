"""Denavit-Hartenberg tables to :class:`mbs.Chain`.

Row format (one row per joint, base to tip).  Either a mapping with keys

    ``joint``   "revolute"/"R" or "prismatic"/"P"
    ``theta``   joint angle offset [rad] (revolute) or the constant angle (prismatic)
    ``d``       link offset [m] (the constant for revolute; offset for prismatic)
    ``a``       link length [m]
    ``alpha``   link twist [rad]
    ``mass``    [kg] (default 0)
    ``com``     centre of mass [m] in the DH link frame (default origin)
    ``inertia`` about the centre of mass, in the DH link frame [kg m^2]: 3x3, 3 principal
                moments, or (ixx, iyy, izz, ixy, ixz, iyz) (default 0: point mass)
    ``damping`` viscous joint damping (default 0)
    ``name``    joint name (default "joint{i}"; the link is "link{i}")

or a sequence ``(joint, theta, d, a, alpha, mass, com, inertia[, damping])``.
Entries may be numbers or sympy expressions (substitute them with
:meth:`Chain.subs` before asking for the numeric model).

Conventions (``i`` = 1..n, frame 0 = base):

- ``"standard"`` (distal, Spong / Corke ``DH``): ``T_{i-1,i} = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``;
  joint i moves about/along z_{i-1}; the inertial data of link i is given in frame i
  (at the distal end of link i).
- ``"modified"`` (proximal, Craig / Corke ``MDH``): ``T_{i-1,i} = Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i) Tz(d_i)``;
  row i holds ``alpha_{i-1}`` and ``a_{i-1}``; joint i moves about/along z_i; link i's
  inertial data is given in frame i.

Angles that are floats within ``ANGLE_SNAP_TOL`` of a multiple of pi/2 are snapped to the
exact value (so cos(pi/2) is exactly 0 in both models).

Gravity defaults to (0, 0, -9.81) m/s^2 in the base frame (z up); pass ``gravity=``.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

from .chain import Chain, Joint, Body, IDENTITY
from .errors import ModelError
from .inertia import RigidInertia, as_inertia_matrix, as_vec3, _scalar
from .scalar import is_sympy
from . import spatial as sp3

#: floats closer than this to k*pi/2 are treated as exactly k*pi/2 (rad)
ANGLE_SNAP_TOL = 1e-10

_KIND = {"r": "revolute", "revolute": "revolute", "continuous": "revolute",
         "p": "prismatic", "prismatic": "prismatic"}
_KEYS = ("joint", "theta", "d", "a", "alpha", "mass", "com", "inertia", "damping", "name")


def exact_cos_sin(angle):
    """(cos, sin) of a constant angle; exact for (near) multiples of pi/2 and sympy."""
    if is_sympy(angle):
        import sympy  # (sympy only for symbolic angles: models.puma560 imports this module)
        if angle.is_number:
            c, s = sympy.cos(angle), sympy.sin(angle)
            if c.is_Number and s.is_Number:
                return _plain(c), _plain(s)
            return float(c), float(s)
        return sympy.cos(angle), sympy.sin(angle)
    a = float(angle)
    k = round(a / (math.pi / 2))
    if abs(a - k * math.pi / 2) <= ANGLE_SNAP_TOL:
        return [(1, 0), (0, 1), (-1, 0), (0, -1)][k % 4]
    return math.cos(a), math.sin(a)


def _plain(x):
    return int(x) if x.is_Integer else x


def rot(axis: int, angle):
    c, s = exact_cos_sin(angle)
    ax = [(1, 0, 0), (0, 1, 0), (0, 0, 1)][axis]
    if c == 1 and s == 0:
        return sp3.EYE3
    return sp3._simplify_axis_rotation(ax, c, s)


def Rx(a):
    return (rot(0, a), sp3.ZERO3)


def Rz(a):
    return (rot(2, a), sp3.ZERO3)


def Tx(a):
    return (sp3.EYE3, (a, 0, 0))


def Tz(d):
    return (sp3.EYE3, (0, 0, d))


def chain_product(*Ts):
    T = IDENTITY
    for X in Ts:
        T = sp3.compose(T, X)
    return T


def parse_row(row, i):
    """Normalize one DH row to a dict (see module docstring)."""
    where = f"DH row {i} (joint {i + 1})"
    if isinstance(row, Mapping):
        unknown = set(row) - set(_KEYS)
        if unknown:
            raise ModelError(f"{where}: unknown key(s) {sorted(unknown)}; allowed {_KEYS}")
        r = dict(row)
        if "joint" not in r:
            raise ModelError(f"{where}: missing 'joint' (revolute or prismatic)")
    elif isinstance(row, Sequence) and not isinstance(row, str):
        if len(row) not in (8, 9):
            raise ModelError(
                f"{where} has {len(row)} entries; expected 8 or 9: "
                "(joint, theta, d, a, alpha, mass, com, inertia[, damping])")
        r = dict(zip(_KEYS, row))
    else:
        raise ModelError(f"{where}: expected a mapping or a sequence, got {type(row).__name__}")
    kind = _KIND.get(str(r["joint"]).lower())
    if kind is None:
        raise ModelError(f"{where}: unknown joint type {r['joint']!r}; use 'revolute'/'R' "
                         "or 'prismatic'/'P'")
    out = {"joint": kind, "name": str(r.get("name") or f"joint{i + 1}")}
    where = f"DH row {i} (joint {out['name']!r})"
    for k in ("theta", "d", "a", "alpha"):
        out[k] = _scalar(r.get(k, 0), where)
    out["mass"] = _scalar(r.get("mass", 0), where)
    out["com"] = as_vec3(r.get("com"), where, "com")
    out["inertia"] = as_inertia_matrix(r.get("inertia"), where)
    out["damping"] = _scalar(r.get("damping", 0), where)
    return out


def chain_from_dh(rows, convention="standard", *, gravity=(0.0, 0.0, -9.81), base=None,
                  tool=None, name="dh_chain") -> Chain:
    """Build a serial :class:`Chain` from DH rows (see module docstring).

    ``base``: optional placement (R, p) of DH frame 0 in the world/base frame.
    ``tool``: optional placement of a tool frame in the last DH frame (frame "tool").
    Frames "link0" .. "link{n}" are the DH frames; the chain's body frames are the joint
    frames (equal to the DH frames in the modified convention).
    """
    if convention not in ("standard", "modified"):
        raise ModelError(f"unknown DH convention {convention!r}; use 'standard' or 'modified'")
    try:
        rows = list(rows)
    except TypeError:
        raise ModelError("DH table must be a sequence of rows") from None
    if not rows:
        raise ModelError("DH table is empty")
    parsed = [parse_row(r, i) for i, r in enumerate(rows)]
    base = base if base is not None else IDENTITY
    bodies = []
    frames = {"base": (-1, IDENTITY), "link0": (-1, base)}
    prev_T = base  # placement of the next joint frame in the previous body frame
    for i, r in enumerate(parsed):
        kind = r["joint"]
        lname = f"link{i + 1}"
        where = f"link {lname!r} (DH row {i}, joint {r['name']!r})"
        if convention == "standard":
            # motion about/along z_{i-1} first, then the constant part
            post = chain_product(Rz(r["theta"]), Tz(r["d"]), Tx(r["a"]), Rx(r["alpha"]))
            placement = prev_T
            inertia = RigidInertia(r["mass"], r["com"], r["inertia"])
            inertia.validate(where)
            inertia = inertia.transformed(post)
            frames[lname] = (i, post)
            prev_T = post
        else:
            pre = chain_product(Rx(r["alpha"]), Tx(r["a"]), Rz(r["theta"]), Tz(r["d"]))
            placement = sp3.compose(prev_T, pre)
            inertia = RigidInertia(r["mass"], r["com"], r["inertia"])
            frames[lname] = (i, IDENTITY)
            prev_T = IDENTITY
        joint = Joint(r["name"], kind, (0, 0, 1), placement, i - 1, r["damping"])
        bodies.append(Body(lname, joint, inertia))
    if tool is not None:
        frames["tool"] = (len(parsed) - 1, sp3.compose(frames[f"link{len(parsed)}"][1], tool))
    src = {"kind": "dh", "convention": convention, "rows": parsed}
    return Chain(bodies, base_name="base", gravity=gravity, name=name, frames=frames, source=src)

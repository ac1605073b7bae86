"""URDF to :class:`mbs.Chain` (parsed with yourdfpy, no meshes, no scene graph).

Supported: ``revolute``, ``continuous`` (its angle is the coordinate, like revolute
without limits) and ``prismatic`` joints; ``fixed`` joints are merged into the parent
body (mass, centre of mass and inertia combined).  Inertial origins (xyz and rpy) are
honoured.  ``<dynamics damping>`` becomes viscous damping, tau = -D qdot.
``<dynamics friction>`` (Coulomb friction) is not modeled: a model whose kept joints
have a nonzero one gets one ``UserWarning`` naming them, and its enclosures are those of
the model without Coulomb friction (only the viscous damping).

Link inertias must be physical: positive semi-definite, with principal moments that
satisfy the triangle inequality I1 + I2 >= I3 (within ``mbs.inertia.TRIANGLE_TOL`` = 1e-3
of the trace; zero inertias, thin rods and flat plates pass).  Others (ixx = iyy = 0.01,
izz = 1; the placeholder ixx = ixy = ... = izz = 1e-6 some files carry) are refused with
a one-line :class:`ModelError` naming the link.

Refused with :class:`mbs.errors.UnsupportedJointError` (unless locked, see ``lock``):
``floating`` and ``planar`` joints (multi-dof; not supported) and ``mimic`` joints (the
coupled coordinate is not independent; lock it, e.g. panda's fingers).

Rotation entries of joint and inertial origins within ``ROTATION_SNAP_TOL`` of 0 or +-1
are snapped to the exact value (UR5 writes pi/2 as 1.57079632679, whose cosine is
4.9e-12); this changes the model by less than the tolerance.

The root link (and every link welded to it) is the fixed base; its mass only adds a
constant to the potential energy (see :mod:`mbs.symbolic`).
"""
from __future__ import annotations

import io
import logging
import os
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from . import spatial as sp3
from .chain import IDENTITY, RawJoint, build_tree
from .errors import ModelError, UnsupportedJointError
from .inertia import RigidInertia
from .kinematics import joint_motion
from verified.driver.user_warnings import warn_at_caller

#: rotation-matrix entries closer than this to 0 or +-1 are snapped
ROTATION_SNAP_TOL = 1e-10


def _snap_rotation(R):
    R = np.array(R, dtype=float)
    out = R.copy()
    out[np.abs(R) < ROTATION_SNAP_TOL] = 0.0
    out[np.abs(R - 1.0) < ROTATION_SNAP_TOL] = 1.0
    out[np.abs(R + 1.0) < ROTATION_SNAP_TOL] = -1.0
    return out


def _to_float(x):
    f = float(x)
    if f == 0.0:
        return 0.0  # no -0.0 in the content hash
    if f == int(f) and abs(f) < 1e15:
        return int(f)
    return f


def _placement(H, where):
    if H is None:
        return IDENTITY
    H = np.asarray(H, dtype=float)
    if H.shape != (4, 4) or not np.all(np.isfinite(H)):
        raise ModelError(f"{where}: invalid origin {H}")
    R = _snap_rotation(H[:3, :3])
    return (tuple(tuple(_to_float(v) for v in row) for row in R),
            tuple(_to_float(v) for v in H[:3, 3]))


def _is_xml(s: str) -> bool:
    return "<" in s


def _prevalidate(xml: str) -> None:
    """Strict XML parse and structural checks, so errors name the element."""
    try:
        root = ET.fromstring(xml)
    except ET.ParseError as e:
        raise ModelError(f"malformed URDF (XML error: {e})") from None
    if root.tag != "robot":
        raise ModelError(f"malformed URDF: root element is <{root.tag}>, expected <robot>")
    for k, link in enumerate(root.findall("link")):
        if not link.get("name"):
            raise ModelError(f"malformed URDF: <link> number {k + 1} has no name")
    for k, j in enumerate(root.findall("joint")):
        name = j.get("name")
        if not name:
            raise ModelError(f"malformed URDF: <joint> number {k + 1} has no name")
        if not j.get("type"):
            raise ModelError(f"joint {name!r}: missing type attribute")
        for tag in ("parent", "child"):
            e = j.find(tag)
            if e is None or not e.get("link"):
                raise ModelError(f"joint {name!r}: missing <{tag} link=...>")


def load_urdf(path_or_xml):
    """Parse with yourdfpy (no meshes, no scene graph, no collision meshes).
    Returns (yourdfpy.URDF, xml_text)."""
    if isinstance(path_or_xml, (str, os.PathLike)) and not (
            isinstance(path_or_xml, str) and _is_xml(path_or_xml)):
        p = Path(path_or_xml)
        if not p.is_file():
            raise ModelError(f"URDF file {str(p)!r} does not exist")
        xml = p.read_text()
    elif isinstance(path_or_xml, bytes):
        xml = path_or_xml.decode()
    else:
        xml = str(path_or_xml)
    _prevalidate(xml)
    import yourdfpy  # (import here: yourdfpy, ~1.2 s, only when a URDF is parsed; import mbs stays fast)

    log = logging.getLogger("yourdfpy")
    old = log.level
    log.setLevel(logging.CRITICAL)
    try:
        robot = yourdfpy.URDF.load(io.BytesIO(xml.encode()), load_meshes=False,
                                   build_scene_graph=False, load_collision_meshes=False,
                                   build_collision_scene_graph=False)
    except ModelError:
        raise
    except Exception as e:  # lxml / yourdfpy errors
        raise ModelError(f"malformed URDF: {type(e).__name__}: {e}") from e
    finally:
        log.setLevel(old)
    if robot is None or robot.robot is None:
        raise ModelError("malformed URDF: no <robot> element")
    return robot, xml


def chain_from_urdf(path_or_xml, *, lock=None, gravity=(0.0, 0.0, -9.81), name=None):
    """Build a :class:`mbs.Chain` from a URDF path or XML string.

    ``lock``: mapping joint name -> fixed position; these joints (any type, also mimic,
    floating or planar ones given position 0) are welded before the tree is built, e.g.
    panda's fingers.  Returns a chain whose ``source`` remembers the XML and the locked
    joints (used by :meth:`Chain.to_pinocchio`).
    """
    robot, xml = load_urdf(path_or_xml)
    lock = dict(lock or {})
    links = robot.robot.links
    joints = robot.robot.joints
    if not links:
        raise ModelError("malformed URDF: no <link> elements")
    names = [l.name for l in links]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise ModelError(f"malformed URDF: duplicate link name(s) {sorted(dup)}")
    jn = [j.name for j in joints]
    unknown = set(lock) - set(jn)
    if unknown:
        raise ModelError(f"cannot lock unknown joint(s) {sorted(unknown)}; joints are {jn}")

    inertias = _link_inertias(links, joints)
    friction = {}  # kept joints with Coulomb friction (not modeled: one warning below)
    raw = [_raw_joint(j, lock, friction) for j in joints]

    children = {j.child for j in joints}
    roots = [n for n in names if n not in children]
    if len(roots) != 1:
        raise ModelError(f"malformed URDF: expected exactly one root link, found {roots}")
    src = {"kind": "urdf", "xml": xml, "locked": {k: float(v) for k, v in lock.items()}}
    chain = build_tree(roots[0], inertias, raw, gravity=gravity,
                       name=name or robot.robot.name or "urdf", source=src)
    if friction:  # once per model, after it was built (a refused model says only why)
        listed = ", ".join(f"{k!r} ({v:g})" for k, v in friction.items())
        warn_at_caller(
            f"URDF {chain.name!r}: Coulomb friction (<dynamics friction>) of joint(s) {listed} "
            "is not modeled, only the viscous damping: the model and its enclosures are "
            "those without Coulomb friction", UserWarning)
    return chain


def _link_inertias(links, joints) -> dict:
    """{link name: RigidInertia} of the URDF's links, each validated (zero without <inertial>)."""
    inertias = {}
    # the base link is fixed to the world: its inertia never enters the dynamics, so a
    # placeholder tensor there (anymal, go1, hyq ship one) is no reason to refuse the model
    children = {j.child for j in joints}
    for l in links:
        where = f"link {l.name!r}"
        ine = l.inertial
        if ine is None:
            inertias[l.name] = RigidInertia.zero()
            continue
        if ine.mass is None:
            raise ModelError(f"{where}: <inertial> without <mass>")
        if ine.inertia is None:
            raise ModelError(f"{where}: <inertial> without <inertia>")
        I = np.asarray(ine.inertia, dtype=float)
        T = _placement(ine.origin, where + " inertial origin")
        ri = RigidInertia(_to_float(ine.mass), (0, 0, 0),
                          tuple(tuple(_to_float(v) for v in row) for row in I))
        ri.validate(where, triangle=l.name in children)
        inertias[l.name] = ri.transformed(T) if T is not IDENTITY else \
            RigidInertia(ri.mass, T[1], ri.inertia)
    return inertias


def _raw_joint(j, lock: dict, friction: dict) -> RawJoint:
    """The RawJoint of URDF joint ``j``: welded where ``lock`` names it, refused where
    unsupported; a nonzero Coulomb friction goes into ``friction`` (not modeled)."""
    where = f"joint {j.name!r}"
    kind = j.type
    if j.parent is None or j.child is None:
        raise ModelError(f"{where}: missing <parent> or <child>")
    T = _placement(j.origin, where)
    if j.name in lock:
        val = float(lock[j.name])
        if kind in ("revolute", "continuous", "prismatic"):
            axis = _axis(j, where)
            T = sp3.compose(T, joint_motion("revolute" if kind != "prismatic" else "prismatic",
                                            axis, val))
        elif val != 0.0:
            raise ModelError(f"{where}: a {kind} joint can only be locked at 0")
        return RawJoint(j.name, "fixed", j.parent, j.child, T)
    if kind == "fixed":
        return RawJoint(j.name, "fixed", j.parent, j.child, T)
    if kind in ("floating", "planar"):
        raise UnsupportedJointError(
            f"{where}: {kind} joints are not supported (only revolute, continuous, "
            "prismatic and fixed); lock it with lock={...: 0.0} or model a fixed base")
    if kind not in ("revolute", "continuous", "prismatic"):
        raise ModelError(f"{where}: unknown joint type {kind!r}")
    if j.mimic is not None:
        raise UnsupportedJointError(
            f"{where}: mimic joints (mimicking {j.mimic.joint!r}) are not supported; "
            f"lock it, e.g. chain_from_urdf(path, lock={{{j.name!r}: 0.0, ...}})")
    damping = 0.0
    if j.dynamics is not None and j.dynamics.damping is not None:
        try:
            damping = _to_float(j.dynamics.damping)
        except (TypeError, ValueError):
            raise ModelError(f"{where}: damping {j.dynamics.damping!r} is not a number") from None
        if not np.isfinite(damping) or damping < 0:
            raise ModelError(f"{where}: damping {damping} must be finite and >= 0")
    if j.dynamics is not None and j.dynamics.friction is not None:
        try:
            fr = float(j.dynamics.friction)
        except (TypeError, ValueError):
            raise ModelError(f"{where}: friction {j.dynamics.friction!r} is not a number") from None
        if fr != 0.0:
            friction[j.name] = fr
    return RawJoint(j.name, "prismatic" if kind == "prismatic" else "revolute",
                    j.parent, j.child, T, _axis(j, where), damping)


def _axis(j, where):
    ax = np.asarray(j.axis if j.axis is not None else (1.0, 0.0, 0.0), dtype=float)
    nrm = np.linalg.norm(ax)
    if ax.shape != (3,) or not np.isfinite(nrm) or nrm == 0:
        raise ModelError(f"{where}: invalid axis {ax}")
    if abs(nrm - 1.0) > 1e-12:
        ax = ax / nrm  # URDF parsers normalize the axis
    return tuple(_to_float(v) for v in ax)

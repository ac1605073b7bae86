"""The kinematic-tree model shared by DH and URDF inputs.

A :class:`Chain` is a tree of rigid bodies.  Body ``i`` is connected to its parent
``parents[i]`` (``-1`` is the fixed base) by one joint with one degree of freedom
``q[i]`` (revolute: angle [rad] about ``axis``; prismatic: displacement [m] along
``axis``).  Bodies are stored parent-before-child, so ``q`` has the same order.

Frames (the same as Pinocchio's joint frames): joint ``i`` has a constant placement
``(R, p)`` in its parent body's frame; the body frame is the joint frame moved by the
joint, i.e. ``x_parent = R (Rot(axis, q) x + ...) + p``.  Inertial data of body ``i`` is
given in that frame.  Fixed URDF joints are merged into the parent body; the fixed base
(the URDF root link and everything welded to it) keeps its inertia in ``base_inertia``
(it only adds a constant to the potential energy).

Generalized forces: ``tau = tau_ext - D qdot`` with the diagonal viscous damping
``D = diag(damping)`` [N m s/rad or N s/m].
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, replace
from functools import cached_property
from typing import Mapping

import numpy as np

from .errors import ModelError
from .inertia import RigidInertia
from .kinematics import joint_motion
from . import pinocchio_check
from .scalar import is_sympy
from . import spatial as sp3

JOINT_TYPES = ("revolute", "prismatic")
IDENTITY = (sp3.EYE3, sp3.ZERO3)


@dataclass(frozen=True)
class Joint:
    """One joint: ``kind`` in ("revolute", "prismatic"), unit ``axis`` (in the joint
    frame), constant ``placement`` (R, p) of the joint frame in the parent body frame,
    viscous ``damping`` coefficient, and ``parent`` body index (-1: base)."""
    name: str
    kind: str
    axis: tuple
    placement: tuple
    parent: int
    damping: object = 0.0


@dataclass(frozen=True)
class Body:
    name: str
    joint: Joint
    inertia: RigidInertia


@dataclass(frozen=True)
class RawJoint:
    """A joint as read from a description, before fixed joints are merged.
    ``kind`` may also be "fixed"."""
    name: str
    kind: str
    parent: str
    child: str
    placement: tuple
    axis: tuple = (0, 0, 1)
    damping: object = 0.0


def _float_or_none(x):
    try:
        return float(x)
    except (TypeError, ValueError):
        return None


class Chain:
    """A kinematic tree of rigid bodies (see module docstring).

    Build with :func:`mbs.chain_from_dh` or :func:`mbs.chain_from_urdf` (or :func:`build_tree`).  Then:

    - :meth:`symbolic` -- sympy model (M, K, P, gravity torque, Coriolis, EOM, H, dH/dt)
    - :meth:`numeric`  -- generic-scalar recursive algorithms (crba, rnea, aba-like solve)
    - :meth:`to_pinocchio` -- the referee model.
    """

    def __init__(self, bodies, *, base_name="base", base_inertia=None,
                 gravity=(0.0, 0.0, -9.81), name="chain", frames=None, source=None):
        self.bodies = tuple(bodies)
        self.base_name = base_name
        self.base_inertia = base_inertia if base_inertia is not None else RigidInertia.zero()
        self.gravity = tuple(gravity)
        self.name = name
        #: named frames: name -> (body index or -1 for the base, placement (R, p) in that body)
        self.frames = dict(frames or {})
        #: how the chain was made (used by :meth:`to_pinocchio`): dict with key "kind"
        self.source = dict(source or {"kind": "tree"})
        self._validate()

    # ------------------------------------------------------------------ basics
    @property
    def n(self) -> int:
        """Number of degrees of freedom (= len(q))."""
        return len(self.bodies)

    nq = nv = n

    @property
    def parents(self):
        return [b.joint.parent for b in self.bodies]

    @property
    def joint_names(self):
        return [b.joint.name for b in self.bodies]

    @property
    def body_names(self):
        return [b.name for b in self.bodies]

    @property
    def damping(self):
        return [b.joint.damping for b in self.bodies]

    def __repr__(self):
        kinds = "".join("R" if b.joint.kind == "revolute" else "P" for b in self.bodies)
        return f"<Chain {self.name!r}: {self.n} dof ({kinds}), bodies {self.body_names}>"

    def describe(self) -> str:
        """Human-readable table: one line per body (joint, type, parent, mass, damping)."""
        def fmt(x):
            try:
                return f"{float(x):.6g}"
            except (TypeError, ValueError):
                return str(x)
        lines = [f"{self.name}: {self.n} dof, base {self.base_name!r} "
                 f"(mass {fmt(self.base_inertia.mass)} kg), gravity {tuple(fmt(g) for g in self.gravity)}",
                 f"{'#':>3} {'joint':<24} {'type':<10} {'parent':<24} {'body':<24} {'mass':>10} {'damping':>9}"]
        for i, b in enumerate(self.bodies):
            pa = self.base_name if b.joint.parent < 0 else self.bodies[b.joint.parent].name
            lines.append(f"{i:>3} {b.joint.name:<24} {b.joint.kind:<10} {pa:<24} {b.name:<24} "
                         f"{fmt(b.inertia.mass):>10} {fmt(b.joint.damping):>9}")
        return "\n".join(lines)

    def _validate(self):
        if not self.bodies:
            raise ModelError(f"chain {self.name!r} has no movable joints")
        names = set()
        for i, b in enumerate(self.bodies):
            j = b.joint
            if j.kind not in JOINT_TYPES:
                raise ModelError(f"joint {j.name!r}: unknown joint type {j.kind!r}; "
                                 f"expected one of {JOINT_TYPES}")
            if not (-1 <= j.parent < i):
                raise ModelError(f"joint {j.name!r}: parent index {j.parent} must refer to an "
                                 "earlier body (bodies are stored parent-before-child)")
            if j.name in names:
                raise ModelError(f"duplicate joint name {j.name!r}")
            names.add(j.name)
            ax = [_float_or_none(a) for a in j.axis]
            if all(a is not None for a in ax):
                nrm = float(np.linalg.norm(ax))
                if abs(nrm - 1.0) > 1e-9:
                    raise ModelError(f"joint {j.name!r}: axis {j.axis} is not a unit vector")
            d = _float_or_none(j.damping)
            if d is not None and (not np.isfinite(d) or d < 0):
                raise ModelError(f"joint {j.name!r}: damping {d} must be finite and >= 0")
            b.inertia.validate(f"link {b.name!r} (joint {j.name!r})")
        self.base_inertia.validate(f"base link {self.base_name!r}")
        if len(self.gravity) != 3:
            raise ModelError(f"gravity must be a 3-vector, got {self.gravity}")
        # massless subtrees make M singular
        acc = [0.0] * self.n
        known = [True] * self.n
        for i in reversed(range(self.n)):
            m = _float_or_none(self.bodies[i].inertia.mass)
            I = self.bodies[i].inertia.inertia
            rot = [_float_or_none(I[k][k]) for k in range(3)]
            if m is None or any(r is None for r in rot):
                known[i] = False
            else:
                acc[i] += m + sum(rot)
            p = self.bodies[i].joint.parent
            if p >= 0:
                acc[p] += acc[i]
                known[p] = known[p] and known[i]
        for i in range(self.n):
            if known[i] and acc[i] == 0.0:
                raise ModelError(self._massless_message(i))

    def _massless_message(self, i: int) -> str:
        """Why body ``i`` and its subtree make M singular, in the terms of the input
        the chain came from (a DH table, a URDF, or bodies built in code)."""
        b = self.bodies[i]
        head = f"joint {b.joint.name!r} moves only massless links"
        tail = "the mass matrix would be singular"
        rows = self.source.get("rows")  # DH tables (also after subs/lock)
        row = next((k for k, r in enumerate(rows or ()) if r.get("name") == b.joint.name), None)
        if row is not None:
            return (f"{head}: DH row {row} (link {b.name!r}) and the rows after it have mass 0 and "
                    f"inertia 0, so {tail}. Give DH row {row} (or a later row) a mass > 0 or an "
                    "inertia (row entries 'mass', 'inertia'), or lock the joint.")
        if self.source.get("kind") == "urdf":
            return (f"{head} (link {b.name!r} and its children have no mass and no inertia, e.g. a "
                    f"missing <inertial>): {tail}. Give the link an <inertial>, or lock the joint.")
        return (f"{head} (link {b.name!r} and its children have mass 0 and inertia 0): {tail}. "
                "Give the link a mass or an inertia, or lock the joint.")

    # ------------------------------------------------------------------ constructors
    # The parsers are functions of their own modules, which import this one:
    # mbs.chain_from_dh (mbs.dh) and mbs.chain_from_urdf (mbs.urdf). The two old
    # spellings, deprecated since b3cf910, are gone (calling a parser from here closed
    # an import circle); they name the function to call instead.
    @classmethod
    def from_dh(cls, *args, **kwargs) -> "Chain":
        """Removed: use :func:`mbs.chain_from_dh` (same arguments)."""
        raise AttributeError("Chain.from_dh was removed: use mbs.chain_from_dh(rows, ...), same arguments")

    @classmethod
    def from_urdf(cls, *args, **kwargs) -> "Chain":
        """Removed: use :func:`mbs.chain_from_urdf` (same arguments)."""
        raise AttributeError("Chain.from_urdf was removed: use mbs.chain_from_urdf(path_or_xml, ...), "
                             "same arguments")

    # ------------------------------------------------------------------ identity
    def content(self) -> str:
        """Canonical text of everything that defines the dynamics (for cache keys)."""
        parts = [f"gravity={self.gravity!r}", f"base={self.base_inertia!r}"]
        for b in self.bodies:
            parts.append(f"{b.name}|{b.joint!r}|{b.inertia!r}")
        return "\n".join(parts)

    def fingerprint(self) -> str:
        """sha256 of :meth:`content` (the disk-cache key)."""
        return hashlib.sha256(self.content().encode()).hexdigest()

    @cached_property
    def free_symbols(self) -> set:
        syms = set()
        def visit(x):
            if is_sympy(x):
                syms.update(x.free_symbols)
            elif isinstance(x, (tuple, list)):
                for y in x:
                    visit(y)
        for b in self.bodies:
            j = b.joint
            visit(j.axis); visit(j.placement); visit(j.damping)
            visit(b.inertia.mass); visit(b.inertia.com); visit(b.inertia.inertia)
        visit(self.gravity)
        return syms

    def subs(self, values: Mapping) -> "Chain":
        """A copy with sympy symbols (DH parameters, masses, ...) replaced by values."""
        def s(x):
            if is_sympy(x):
                y = x.subs(values)
                return float(y) if y.is_number else y
            if isinstance(x, tuple):
                return tuple(s(v) for v in x)
            return x
        bodies = []
        for b in self.bodies:
            j = b.joint
            j2 = replace(j, axis=s(j.axis), placement=s(j.placement), damping=s(j.damping))
            inn = RigidInertia(s(b.inertia.mass), s(b.inertia.com), s(b.inertia.inertia))
            bodies.append(Body(b.name, j2, inn))
        base = RigidInertia(s(self.base_inertia.mass), s(self.base_inertia.com),
                            s(self.base_inertia.inertia))
        frames = {k: (i, s(T)) for k, (i, T) in self.frames.items()}
        src = dict(self.source)
        src["subs"] = {str(k): v for k, v in dict(values).items()}
        if src.get("kind") == "urdf":
            src["kind"] = "tree"
        return Chain(bodies, base_name=self.base_name, base_inertia=base, gravity=s(self.gravity),
                     name=self.name, frames=frames, source=src if src.get("kind") != "dh" else
                     {**src, "kind": "tree"})

    def lock(self, joints: Mapping[str, float]) -> "Chain":
        """A copy in which the given joints are fixed at the given positions (their
        bodies are merged into the parents).  E.g. panda's fingers:
        ``chain.lock({"panda_finger_joint1": 0.0, "panda_finger_joint2": 0.0})``."""
        unknown = set(joints) - set(self.joint_names)
        if unknown:
            raise ModelError(f"cannot lock unknown joint(s) {sorted(unknown)}; "
                             f"joints are {self.joint_names}")
        raw = []
        inertias = {self.base_name: self.base_inertia}
        for b in self.bodies:
            j = b.joint
            parent = self.base_name if j.parent < 0 else self.bodies[j.parent].name
            inertias[b.name] = b.inertia
            if j.name in joints:
                T = sp3.compose(j.placement, joint_motion(j.kind, j.axis, float(joints[j.name])))
                raw.append(RawJoint(j.name, "fixed", parent, b.name, T))
            else:
                raw.append(RawJoint(j.name, j.kind, parent, b.name, j.placement, j.axis, j.damping))
        extra = {}
        for fname, (bi, T) in self.frames.items():
            owner = self.base_name if bi < 0 else self.bodies[bi].name
            if fname != owner:
                extra[fname] = (owner, T)
        src = dict(self.source)
        src["locked"] = {**src.get("locked", {}), **{k: float(v) for k, v in joints.items()}}
        return build_tree(self.base_name, inertias, raw, gravity=self.gravity, name=self.name,
                          source=src, extra_frames=extra)

    def select(self, joints) -> "Chain":
        """Keep only the listed joints movable; all others are locked at 0."""
        keep = set(joints)
        unknown = keep - set(self.joint_names)
        if unknown:
            raise ModelError(f"unknown joint(s) {sorted(unknown)}; joints are {self.joint_names}")
        return self.lock({n: 0.0 for n in self.joint_names if n not in keep})

    def subtree(self, joint: str) -> "Chain":
        """Keep ``joint`` and every joint below it movable; lock all others at 0
        (e.g. one arm of a two-armed robot)."""
        if joint not in self.joint_names:
            raise ModelError(f"unknown joint {joint!r}; joints are {self.joint_names}")
        root = self.joint_names.index(joint)
        keep = set()
        for i in range(self.n):
            j = i
            while j >= 0 and j != root:
                j = self.bodies[j].joint.parent
            if j == root:
                keep.add(self.bodies[i].joint.name)
        return self.select(keep)

    # ------------------------------------------------------------------ models
    def symbolic(self):
        """The sympy model (:class:`mbs.symbolic.SymbolicModel`), built lazily and cached."""
        if getattr(self, "_symbolic", None) is None:
            from .symbolic import SymbolicModel  # (import here: sympy only for the symbolic model)
            self._symbolic = SymbolicModel(self)
        return self._symbolic

    def numeric(self):
        """The generic-scalar numeric model (:class:`mbs.numeric.NumericModel`)."""
        if getattr(self, "_numeric", None) is None:
            from .numeric import NumericModel  # (import here: keeps verified and numba out of import mbs)
            self._numeric = NumericModel(self)
        return self._numeric

    def to_pinocchio(self, **kwargs):
        """The Pinocchio model of this chain (see :func:`mbs.pinocchio_check.to_pinocchio`)."""
        return pinocchio_check.to_pinocchio(self, **kwargs)


def build_tree(root, link_inertias, raw_joints, *, gravity=(0.0, 0.0, -9.81), name="chain",
               source=None, extra_frames=None) -> Chain:
    """Build a :class:`Chain` from links and joints, merging fixed joints.

    ``link_inertias``: link name -> :class:`RigidInertia` (in the link frame);
    ``raw_joints``: :class:`RawJoint` list (kinds revolute, prismatic, fixed), with the
    child link frame equal to the joint frame (URDF convention).  The tree is walked
    depth-first from ``root`` in the order of ``raw_joints``.
    ``extra_frames``: frame name -> (link name, placement in that link).
    """
    children = {}
    seen_child = {}
    for j in raw_joints:
        if j.child in seen_child:
            raise ModelError(f"link {j.child!r} is the child of two joints "
                             f"({seen_child[j.child]!r} and {j.name!r}): not a tree")
        seen_child[j.child] = j.name
        if j.parent not in link_inertias:
            raise ModelError(f"joint {j.name!r}: parent link {j.parent!r} does not exist")
        if j.child not in link_inertias:
            raise ModelError(f"joint {j.name!r}: child link {j.child!r} does not exist")
        children.setdefault(j.parent, []).append(j)
    if root in seen_child:
        raise ModelError(f"root link {root!r} has a parent joint {seen_child[root]!r}")

    # link name -> (owner body index or -1, placement of link frame in owner frame)
    where = {root: (-1, IDENTITY)}
    owner_inertia = {-1: link_inertias[root]}
    bodies_raw = []  # [name, joint]
    # depth-first, children in given order
    def visit(link):
        for j in children.get(link, []):
            bi, T = where[link]
            if j.kind == "fixed":
                T2 = sp3.compose(T, j.placement)
                where[j.child] = (bi, T2)
                owner_inertia[bi] = owner_inertia[bi].merged(link_inertias[j.child].transformed(T2))
            elif j.kind in JOINT_TYPES:
                idx = len(bodies_raw)
                joint = Joint(j.name, j.kind, tuple(j.axis), sp3.compose(T, j.placement), bi,
                              j.damping)
                bodies_raw.append((j.child, joint))
                where[j.child] = (idx, IDENTITY)
                owner_inertia[idx] = link_inertias[j.child]
            else:
                raise ModelError(f"joint {j.name!r}: unsupported joint type {j.kind!r}")
            visit(j.child)
    visit(root)
    unreachable = set(link_inertias) - set(where)
    if unreachable:
        raise ModelError(f"links {sorted(unreachable)} are not connected to the root link {root!r}")
    bodies = [Body(nm, joint, owner_inertia[i]) for i, (nm, joint) in enumerate(bodies_raw)]
    frames = {ln: (bi, T) for ln, (bi, T) in where.items()}
    for fname, (ln, T) in (extra_frames or {}).items():
        bi, T0 = where[ln]
        frames[fname] = (bi, sp3.compose(T0, T))
    return Chain(bodies, base_name=root, base_inertia=owner_inertia[-1], gravity=gravity,
                 name=name, frames=frames, source=source)

"""Kinematics of a :class:`mbs.Chain`, written once for every scalar backend.

This module owns the joint model and forward kinematics:

- :func:`joint_motion` -- placement of a moved joint frame in its unmoved joint frame,
- :func:`joint_transform` / :func:`joint_transforms` -- placement ``X_i = (R, p)`` of
  body frame ``i`` in its parent's frame at configuration ``q``,
- :func:`world_transforms` -- world placements of the body frames (Pinocchio's
  ``data.oMi[1:]``), and :func:`frame_placement` for a frame fixed in a body,
- :func:`motion_subspace` / :func:`subspace_transpose` -- the joint motion subspace
  ``S_i`` and its transpose acting on a spatial force.

:mod:`mbs.numeric` (floats, batches, intervals, tracers) and :mod:`mbs.symbolic`
(sympy) both call these functions; neither writes its own kinematics.

Units and shapes: ``q[i]`` is an angle [rad] (revolute) or a displacement [m]
(prismatic) along the unit ``axis`` of joint ``i``; lengths are in [m].  Vectors are
tuples of 3 scalars, rotation matrices tuples of 3 row tuples, a placement is a pair
``(R, p)`` mapping child to parent coordinates, ``x_parent = R x_child + p``; motion
vectors are ``(w, v)`` and forces ``(n, f)`` in body coordinates (see
:mod:`mbs.spatial`).  ``q`` is any sequence indexable by joint (a list of generic
scalars, a numpy array, a sympy column Matrix of symbols).

Scalar backend: there is no backend argument.  Every operation goes through
:mod:`mbs.spatial` / :mod:`mbs.scalar`, which dispatch on the scalar's type (``sin``
and ``cos`` to sympy for sympy expressions, to numpy otherwise) and fold exact model
constants 0 and 1.  What differs between the callers -- how model constants were
converted (floats vs exact sympy numbers), where ``q`` comes from, caching, and the
output containers -- stays in the callers.  The expression each function builds is
therefore the same operation sequence for every backend: changing it here changes the
sympy expressions of :mod:`mbs.symbolic` (and the disk-cached graphs built from them)
as well as the numeric graphs.
"""
from __future__ import annotations

from .errors import ModelError
from .scalar import dot
from . import spatial as sp3


def joint_motion(kind, axis, q):
    """Placement (R, p) of the moved joint frame in the joint frame at configuration q."""
    if kind == "revolute":
        return sp3.joint_rotation(axis, q), sp3.ZERO3
    if kind == "prismatic":
        return sp3.EYE3, sp3.vscale(q, axis)
    raise ModelError(f"unknown joint type {kind!r}")


def joint_transform(kind, axis, placement, q):
    """Placement (R, p) of a body frame in its parent's frame: the constant joint
    ``placement`` (Rp, pp) followed by the joint's motion by ``q``."""
    Rp, pp = placement
    # Written out rather than as compose(placement, joint_motion(...)): composing with
    # the zero translation / identity rotation would add folded-away products whose
    # exact-zero constants turn from int into float, and it changes no value.
    if kind == "revolute":
        return sp3.mm(Rp, sp3.joint_rotation(axis, q)), pp
    return Rp, sp3.vadd(pp, sp3.mv(Rp, sp3.vscale(q, axis)))


def joint_transforms(kinds, axes, placements, q):
    """[X_i] = placements (R, p) of the n body frames in their parents' frames at q."""
    return [joint_transform(kinds[i], axes[i], placements[i], q[i]) for i in range(len(kinds))]


def world_transforms(parents, X):
    """World placements [(R, p)] of the body frames from their joint transforms ``X``
    (``parents[i] < 0``: the fixed base; bodies are ordered parent-before-child)."""
    world = []
    for i, Xi in enumerate(X):
        pa = parents[i]
        world.append(Xi if pa < 0 else sp3.compose(world[pa], Xi))
    return world


def frame_placement(world, body, T):
    """World placement of a frame with placement ``T`` in body ``body`` (-1: the base)."""
    return T if body < 0 else sp3.compose(world[body], T)


def motion_subspace(kind, axis):
    """Motion subspace S of a 1-dof joint as a spatial motion (w, v) per unit joint rate.
    Pass a scaled axis (``vscale(s, axis)``) for S s."""
    return (axis, sp3.ZERO3) if kind == "revolute" else (sp3.ZERO3, axis)


def subspace_transpose(kind, axis, n, f):
    """S^T (n, f): the component of the spatial force (n, f) the joint transmits
    (a torque about ``axis`` [N m] or a force along it [N])."""
    return dot(axis, n if kind == "revolute" else f)

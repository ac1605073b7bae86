"""Enclosures of link frames over a verified solution (issue 14 item 3).

``sol.frame("tool0")`` (attached by :func:`mbs.simulate.simulate` to every run of a
chain) returns a :class:`FrameEnclosure`: the frame's world position (m) and rotation
matrix enclosed at every output time (``position``, ``rotation``, per set ``boxes``)
and over every step of the tube (``tube``, ``tube_t``), for every state the solution
encloses and every value of the plant's uncertain parameters.

How: forward kinematics of the frame is traced into a graph ``(q, p) -> (p_xyz,
R)``; over each output box (and tube box) it is evaluated in three ways and the
results intersected (each encloses the true range, so the intersection does too):

- ``mean-value``: ``FK(c) + J_FK(box) (x - c)``, ``c`` the box centre, ``J_FK``
  the interval Jacobian over the box (first-order: the width is ``|J| w``);
- ``affine``: :func:`verified.series.affine_taylor.affine_range` (one noise symbol per wide
  input; keeps the dependence of every intermediate of the kinematic chain);
- ``interval``: plain interval evaluation (only matters for wide boxes).

At the output times the solver also keeps its sets in a linear view over their own
parameters (``sol.views``, :class:`verified.sets.protocol.SetView`: every state is ``c + A' p``,
``p`` in ``R``), and a fourth form is intersected in:

- ``set``: ``FK(c) + (J_FK(box) A) R``, the mean value theorem over the set's own
  parameters: a thin, rotated set is not widened to its hull box first (the
  parameters' box enters as ``J_p (p - mid p)``).

Over the tube (every step) the same forms are taken over the tube boxes, and where the
solver kept the step's a-priori enclosure as a linear view (``sol.tube_views``: the
composition step, ``set_step="composition"``) the ``set`` form over it is intersected
in as well.
``mbs.frames.frame_enclosure(sol, chain, "tool0")`` does the same for a solution of
:func:`verified.solver.solve` whose first ``2 n`` states are ``(q, qd)``.
"""
from __future__ import annotations

import weakref

import numpy as np

from verified.arith import linalg
from verified.series.affine_taylor import affine_range
from verified.graph import trace
from verified.arith.interval import Interval, concatenate
from verified.sets.protocol import SetView

from . import spatial as sp3
from .errors import ModelError
from .scalar import is_sympy

__all__ = ["FrameEnclosure", "Frames", "frame_enclosure", "frame_graph", "attach_frames", "default_frame",
           "default_frame_note",
           "evaluate_frame", "METHODS"]

METHODS = ("both", "set", "mean-value", "affine", "interval")


class FrameEnclosure:
    """Enclosure of one frame's placement over a solution.

    Attributes
    ----------
    name : str
    t : ndarray (k,) output times
    boxes : list of Interval (B_j, 3)  position per set at each output time
    position : Interval (k, 3)  hull over the sets [m]
    rotation : Interval (k, 3, 3)  hull of the rotation matrix entries
    tube_t : ndarray (s + 1,) step boundaries
    tube : Interval (s, 3)  position over every step [t_j, t_j+1]
    tube_boxes : list of Interval (B_j, 3)
    method : str
    """

    def __init__(self, name, t, boxes, rot_boxes, tube_t, tube_boxes, method):
        self.name, self.method = name, method
        self.t = np.asarray(t, float)
        self.boxes = boxes
        self.position = Interval(np.array([np.min(b.lo, axis=0) for b in boxes]),
                                 np.array([np.max(b.hi, axis=0) for b in boxes])) if boxes else Interval(
            np.zeros((0, 3)))
        self.rotation = Interval(np.array([np.min(b.lo, axis=0) for b in rot_boxes]).reshape(-1, 3, 3),
                                 np.array([np.max(b.hi, axis=0) for b in rot_boxes]).reshape(-1, 3, 3)) \
            if rot_boxes else Interval(np.zeros((0, 3, 3)))
        self.tube_t = np.asarray(tube_t, float)
        self.tube_boxes = tube_boxes
        self.tube = Interval(np.array([np.min(b.lo, axis=0) for b in tube_boxes]).reshape(-1, 3),
                             np.array([np.max(b.hi, axis=0) for b in tube_boxes]).reshape(-1, 3)) \
            if tube_boxes else Interval(np.zeros((0, 3)))

    @property
    def tube_hull(self) -> Interval:
        """Hull of the frame's position over the whole run (3,)."""
        if not self.tube_boxes:
            return Interval(self.position.lo.min(axis=0), self.position.hi.max(axis=0))
        return Interval(np.minimum(self.tube.lo.min(axis=0), self.position.lo.min(axis=0)),
                        np.maximum(self.tube.hi.max(axis=0), self.position.hi.max(axis=0)))

    def contains(self, t_index, point, slack=0.0) -> bool:
        """Is ``point`` (3,) inside the union of the position boxes at output ``t_index``?"""
        b = self.boxes[t_index]
        x = np.asarray(point, float)
        return bool(np.any(np.all((b.lo - slack <= x) & (x <= b.hi + slack), axis=-1)))

    def __repr__(self):
        w = np.asarray(self.position.width()[-1]) if len(self.t) else np.zeros(3)
        return (f"FrameEnclosure({self.name!r}, {len(self.t)} output times, {len(self.tube_boxes)} steps, "
                f"widths at t = {self.t[-1] if len(self.t) else 0:g}: {np.array2string(w, precision=3)} m)")


def frame_graph(chain, frame: str, cparams=None):
    """Graph ``(q, plant parameters) -> (x, y, z, R11, ..., R33)`` of ``frame``'s world
    placement (the parameters as inputs after q)."""
    if frame not in chain.frames:
        raise ModelError(f"unknown frame {frame!r}; frames of {chain.name!r}: {', '.join(sorted(chain.frames))}")
    n = chain.n
    npar = cparams.n if cparams is not None else 0
    num = chain.numeric() if cparams is None else None
    bi, T = chain.frames[frame]

    def fn(x, _):
        x = list(x)
        m = num if cparams is None else cparams.bind(x[n:])
        if cparams is None:
            R, p = m.frame_placement(frame, x[:n])
        else:
            def ev(v):
                if isinstance(v, tuple):
                    return tuple(ev(y) for y in v)
                if is_sympy(v) and v.free_symbols:
                    from .sympy_eval import compile_generic  # (import here: sympy only for symbolic chains)
                    syms = list(cparams._symbols)
                    return compile_generic([v], syms, cse=False)(*[x[n + cparams._symbols[s]] for s in syms])[0]
                return float(v) if is_sympy(v) else v
            TT = ev(T)
            if bi < 0:
                R, p = TT
            else:
                R, p = sp3.compose(m.forward_kinematics(x[:n])[bi], TT)
        return list(p) + [R[i][j] for i in range(3) for j in range(3)]
    names = [f"q{i + 1}" for i in range(n)] + (list(cparams.names) if npar else [])
    return trace(fn, n + npar, 0, input_names=names,
                 output_names=["x", "y", "z"] + [f"R{i}{j}" for i in range(1, 4) for j in range(1, 4)])


def _boxes_for(boxes: Interval, n: int, pbox):
    lo = np.asarray(boxes.lo, float).reshape(-1, boxes.shape[-1])[:, :n]
    hi = np.asarray(boxes.hi, float).reshape(-1, boxes.shape[-1])[:, :n]
    if pbox is not None:
        lo = np.concatenate([lo, np.broadcast_to(pbox[0], (lo.shape[0], len(pbox[0])))], axis=1)
        hi = np.concatenate([hi, np.broadcast_to(pbox[1], (hi.shape[0], len(pbox[1])))], axis=1)
    return Interval(lo, hi)


def _mean_value(graph, X: Interval) -> Interval:
    """FK(c) + J(X) (X - c) over each box (rows of X), c = the centres."""
    c = X.mid()
    fc = graph.eval_interval(Interval(c, c))            # (B, m), rounding enclosed
    J = graph.jacobian_interval(X)                      # (B, m, k)
    d = X - Interval(c, c)                              # (B, k)
    out = fc
    for j in range(X.shape[-1]):
        if np.all(d.lo[:, j] == 0) and np.all(d.hi[:, j] == 0):
            continue
        out = out + J[:, :, j] * d[:, j:j + 1]
    return out


def _over_set(graph, view, X: Interval, n: int, pbox) -> Interval:
    """``FK(c, mid p) + (J_q A) R + J_p (p - mid p)`` over the sets of ``view`` (a
    :class:`verified.sets.protocol.SetView` whose first ``n`` states are q), ``J`` the interval
    Jacobian over the box ``X`` (B, n + parameters) widened to hold ``c``: every segment
    from ``(c, mid p)`` into the set lies in it, so the mean value theorem applies
    with ``x_q - c = A' p``, ``A'`` a point matrix of ``A``."""
    cq = view.c[:, :n]
    if pbox is not None:
        pm = 0.5 * (np.asarray(pbox[0], float) + np.asarray(pbox[1], float))
        cfull = np.concatenate([cq, np.broadcast_to(pm, (cq.shape[0], pm.size))], axis=1)
    else:
        cfull = cq
    C = Interval(cfull, cfull)
    fc = graph.eval_interval(C)                             # (B, m), rounding enclosed
    J = graph.jacobian_interval(X.hull(C))                  # (B, m, n + params)
    out = fc + linalg.matvec(linalg.matmul(J[:, :, :n], view.A[:, :n, :]), view.R)
    if pbox is not None:
        P = Interval(np.broadcast_to(np.asarray(pbox[0], float), (cq.shape[0], pm.size)),
                     np.broadcast_to(np.asarray(pbox[1], float), (cq.shape[0], pm.size)))
        out = out + linalg.matvec(J[:, :, n:], P - Interval(cfull[:, n:], cfull[:, n:]))
    return out


def evaluate_frame(graph, X: Interval, method: str = "both", view=None, n: int | None = None,
                   pbox=None) -> Interval:
    """The graph's outputs over boxes ``X`` (B, k) by ``method`` (see module
    docstring); ``view`` (a :class:`verified.sets.protocol.SetView` of the same B sets, its
    first ``n`` states q; ``pbox`` the parameters' (lo, hi)) adds the ``set`` form."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    if X.shape[0] == 0:
        return Interval(np.zeros((0, graph.n_outputs)))
    if method == "set":
        if view is None:
            raise ValueError("method 'set' needs the sets' view (Solution.views)")
        return _over_set(graph, view, X, n, pbox)
    if method == "interval":
        return graph.eval_interval(X)
    if method == "mean-value":
        return _mean_value(graph, X)
    A = affine_range(graph, X)
    if method == "affine":
        return A
    out = _mean_value(graph, X).intersect(A).intersect(graph.eval_interval(X))
    if view is not None:
        out = out.intersect(_over_set(graph, view, X, n, pbox))
    return out


def _tube_over_views(graph, Y: Interval, X: Interval, sizes, views, n: int, pbox) -> Interval:
    """``Y`` (the frame over the stacked tube boxes ``X``) intersected with the set form
    over each step's view (``sol.tube_views``), where the step kept one; the steps'
    views are evaluated in one batch."""
    starts = np.concatenate([[0], np.cumsum(sizes)])
    idx = [j for j, v in enumerate(views) if j < len(sizes) and v is not None and v.n_sets == sizes[j]]
    if not idx:
        return Y
    P = max(views[j].A.shape[-1] for j in idx)

    def padded(a: Interval, width: int) -> Interval:  # (zero columns: the same points)
        extra = P - width
        if not extra:
            return a
        z = np.zeros(a.shape[:-1] + (extra,))
        return Interval(np.concatenate([a.lo, z], axis=-1), np.concatenate([a.hi, z], axis=-1))

    view = SetView(c=np.concatenate([views[j].c for j in idx]),
                   A=concatenate([padded(views[j].A, views[j].A.shape[-1]) for j in idx], axis=0),
                   R=concatenate([padded(views[j].R, views[j].R.shape[-1]) for j in idx], axis=0))
    rows = np.concatenate([np.arange(starts[j], starts[j + 1]) for j in idx])
    over = _over_set(graph, view, X[rows], n, pbox)
    lo, hi = Y.lo.copy(), Y.hi.copy()
    lo[rows] = np.maximum(lo[rows], over.lo)
    hi[rows] = np.minimum(hi[rows], over.hi)
    return Interval._from_bounds(lo, hi)


def frame_enclosure(sol, chain, frame: str, cparams=None, *, method: str = "both",
                    tube: bool = True) -> FrameEnclosure:
    """The :class:`FrameEnclosure` of ``frame`` (a link or frame name of ``chain``)
    over ``sol`` (its first ``chain.n`` states are q); ``cparams``: the plant's
    :class:`mbs.uncertain.ChainParameters` when the run had uncertain parameters
    (geometry or payload symbols enter the kinematics only for DH symbols, but the
    parameter box is appended either way)."""
    g = frame_graph(chain, frame, cparams)
    n = chain.n
    pbox = (cparams.lo, cparams.hi) if cparams is not None and cparams.n else None
    pos, rot = [], []
    views = getattr(sol, "views", None) or []
    for j, b in enumerate(sol.boxes):
        X = _boxes_for(b, n, pbox)
        view = views[j] if j < len(views) else None
        if view is not None and view.n_sets != X.shape[0]:
            view = None
        if method == "set" and view is None:
            Y = evaluate_frame(g, X, "both")  # (an output without sets: boxes a hook wrote)
        else:
            Y = evaluate_frame(g, X, method, view if method in ("both", "set") else None, n, pbox)
        pos.append(Interval(Y.lo[:, :3], Y.hi[:, :3]))
        # a rotation matrix's entries lie in [-1, 1] (its columns are unit vectors)
        rot.append(Interval(np.clip(Y.lo[:, 3:], -1.0, 1.0), np.clip(Y.hi[:, 3:], -1.0, 1.0)))
    tb = []
    if tube and len(sol.tube):
        sizes = [b.reshape(-1, b.shape[-1]).shape[0] if b.ndim > 1 else 1 for b in sol.tube]
        allx = Interval(np.concatenate([_boxes_for(b, n, pbox).lo for b in sol.tube]),
                        np.concatenate([_boxes_for(b, n, pbox).hi for b in sol.tube]))
        Y = evaluate_frame(g, allx, "both" if method == "set" else method)
        if method in ("both", "set"):
            Y = _tube_over_views(g, Y, allx, sizes, getattr(sol, "tube_views", None) or [], n, pbox)
        k = 0
        for s in sizes:
            tb.append(Interval(Y.lo[k:k + s, :3], Y.hi[k:k + s, :3]))
            k += s
    return FrameEnclosure(frame, sol.t, pos, rot, sol.tube_t if tube else np.zeros(0), tb, method)


class Frames:
    """``sol.frame``: call it with a frame name (``sol.frame("tool0")``) for a cached
    :class:`FrameEnclosure`; ``sol.frame.names`` lists the chain's frames."""

    def __init__(self, sol, chain, cparams=None):
        self._sol = weakref.ref(sol)
        self.chain, self.cparams = chain, cparams
        self._cache = {}

    @property
    def names(self) -> list:
        return sorted(self.chain.frames)

    def __call__(self, name: str, *, method: str = "both", tube: bool = True) -> FrameEnclosure:
        key = (name, method, tube)
        if key not in self._cache:
            sol = self._sol()
            if sol is None:  # pragma: no cover
                raise RuntimeError("the solution is gone")
            self._cache[key] = frame_enclosure(sol, self.chain, name, self.cparams, method=method, tube=tube)
        return self._cache[key]

    def __repr__(self):
        return f"<frames of {self.chain.name!r}: {', '.join(self.names)}>"


def default_frame(chain) -> str:
    """The end effector a user means: ``tool0`` / ``tool`` / ``ee_link`` if the chain
    has one, else the frame on the last body farthest from its joint."""
    for k in ("tool0", "tool", "ee_link"):
        if k in chain.frames and chain.frames[k][0] >= 0:
            return k
    last = chain.n - 1
    cand = [(float(np.linalg.norm(np.asarray(T[1], float))), k) for k, (b, T) in chain.frames.items() if b == last]
    if not cand:
        raise ModelError(f"{chain.name!r} has no frame on its last body")
    return max(cand)[1]


def default_frame_note(chain, frame: str | None = None) -> str:
    """One line for the output when the default end effector (:func:`default_frame`, or
    ``frame``) is only the origin of the last joint: a chain without a tool frame (a bare
    URDF whose last link has no fixed child link, a DH chain without a tool offset),
    whose frames on the last body all sit at its joint. "" otherwise."""
    frame = default_frame(chain) if frame is None else frame
    body, T = chain.frames.get(frame, (None, None))
    if body is None or body != chain.n - 1 or float(np.linalg.norm(np.asarray(T[1], float))) > 0:
        return ""
    joint = chain.joint_names[-1]
    return (f"frame: no tool frame given; using the origin of joint {joint!r} (the last joint, frame "
            f"{frame!r}), not the arm's tip; to enclose the tip, add a fixed link at the tip (a tool link) "
            f"to the model and name it in [simulation] frames")


def attach_frames(sol, chain, cparams=None):
    """Give ``sol`` the accessor ``sol.frame`` (:class:`Frames`) of ``chain``."""
    sol.frame = Frames(sol, chain, cparams)
    return sol

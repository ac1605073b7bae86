"""Hold the enclosure inside the energy shell ``H(q, qd) <= hmax`` (issue 13, item 1).

For a conservative or dissipative mechanical system (``dH/dt <= 0`` along every
solution, paper eq. (7) with no input power), every true state at every time satisfies
``H(x(t)) <= hmax`` with ``hmax`` the largest energy of the initial set (eq. (12):
``H_V`` never rises). :class:`verified.consistency.contractor.EnergyShell` contracts a box in
``(q, qd)`` to that shell: the velocities by the exact ellipsoid bound
``|qd_i| <= sqrt(2 (hmax - V(q)) (M(q)^-1)_ii)``, the positions through ``V(q) <= hmax``.

:class:`EnergyShellHook` applies it after every step. A set whose hull the shell cuts
to less than ``cut`` (default 0.9) of its width in some component reaches past what the
physics allows (wrapping over a long horizon, a fold near a saddle): the hook replaces
it by the contracted box (a fresh set: centre, diagonal parameters). That loses the
set's correlations, so it is done only where the cut is worth it; every other set is
left as it is; 0.9 was the narrowest of the cuts tried (docs/lab/code_notes.md).
A set whose box holds no state of the shell holds no true state and is dropped. The
result is bounded and sound where the plain run breaks down "too wide", as on the
paper's pendulum over the top (docs/energy_contraction.md, docs/lab/code_notes.md). First- and second-order sets (``set_order=2``, both
``set_step``s) are held alike: a reset set is the contracted box, a fresh set of the
batch's kind with as many parameters as the others (the new ones 0).

Soundness rests on ``hmax``: the caller states that ``H`` never rises above it along
the solutions from the initial set (:func:`max_energy` gives the bound for a
non-increasing ``H``). The hook checks what it can: ``hmax`` is a finite float and the
initial sets lie in the shell (else the claim is wrong and the run raises).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from verified.consistency.contractor import EnergyShell
from verified.graph.evaluate import eval_interval
from verified.graph import Graph
from verified.driver.hooks import Hook, RunSetup
from verified.arith.interval import Interval
from verified.sets.second_order import QuadraticSets
from verified.sets.first_order import DoubletonSets

__all__ = ["EnergyShellHook", "max_energy"]

# the set types a reset can rebuild from a box (``from_boxes``, ``with_params``,
# ``replaced``); a fresh box set is exact for any of them
_SET_TYPES = (DoubletonSets, QuadraticSets)


class _Contracted(NamedTuple):
    lo: np.ndarray  # (B, 2 n_q) contracted bounds (the hull's where not contracted)
    hi: np.ndarray
    empty: np.ndarray  # (B,) proven outside the shell


def max_energy(H: Graph, boxes: Interval, params=None) -> float:
    """An upper bound of ``H`` over the boxes (Interval (B, n) or (n,)): the ``hmax`` of a
    system whose energy does not rise (interval evaluation, rounded outward)."""
    boxes = boxes if isinstance(boxes, Interval) else Interval(boxes)
    if boxes.ndim == 1:
        boxes = boxes.reshape(1, -1)
    if H.n_outputs != 1 or H.n_inputs != boxes.shape[1]:
        raise ValueError(f"H must map the {boxes.shape[1]} states to one value, got "
                         f"{H.n_inputs} inputs -> {H.n_outputs} outputs")
    hi = float(np.max(eval_interval(H, boxes, params)[..., 0].hi))
    if not np.isfinite(hi):
        raise ValueError("H is unbounded over the initial boxes; no energy shell")
    return hi


def reset_to_contracted(sets, hull: Interval, lo, hi, keep, cut: float):
    """Sets after a contraction of their hulls' first ``m`` columns to ``lo..hi`` (B, m):
    each kept set whose contracted box is narrower than ``cut`` times its hull in some of
    those columns becomes that box (the other columns keep the hull), and the sets not in
    ``keep`` (proven empty) are dropped. Returns ``(sets, resets, dropped)``; ``sets`` is
    the argument itself when nothing changed. Sound: a reset set is a box that holds
    every state of the set the contraction keeps. Shared by the energy shell and the
    declared invariants (:mod:`verified.consistency.conservation`)."""
    m = lo.shape[1]
    width = hull.width()[:, :m]
    new_w = np.where(keep[:, None], hi - lo, width)
    with np.errstate(invalid="ignore", divide="ignore"):
        replace = keep & (new_w < cut * width).any(axis=1)
    out, resets, dropped = sets, 0, 0
    if replace.any():
        idx = np.flatnonzero(replace)
        blo, bhi = hull.lo[idx].copy(), hull.hi[idx].copy()  # (k, N): other states keep their hull
        blo[:, :m], bhi[:, :m] = lo[idx], hi[idx]
        fresh = type(sets).from_boxes(Interval(blo, bhi)).with_params(sets.C.shape[2])
        out = out.replaced(idx, fresh)
        resets = int(idx.size)
    if not keep.all():
        dropped = int((~keep).sum())
        out = out.take(np.flatnonzero(keep))
    return out, resets, dropped


class EnergyShellHook(Hook):
    """Keep every set inside ``H(q, qd) <= hmax`` (see the module docstring).

    Args:
        shell: the :class:`~verified.consistency.contractor.EnergyShell` of the system (``M(q)`` and
            ``V(q)`` graphs); the solver's first ``2 n_q`` states must be ``(q, qd)``.
        hmax: upper bound of ``H`` along every solution from the initial set (J).
        cut: a set is replaced by its contracted box when that box is narrower than
            ``cut`` times the set's hull in some component (default 0.9).
        pieces: sub-boxes of ``q`` for the ellipsoid bound (EnergyShell.contract).
        params: parameters of the shell's graphs (fixed floats or intervals), if any.
            None for a shell with parameters: they are the ODE's own, in its order,
            taken from the run: the fixed values, or, for uncertain ones carried as
            states, each set's own parameter columns (the ``p`` states after the ODE's
            ``n``); the shell then holds the states with ``H(x, p) <= hmax`` for some
            ``p`` of the set, and ``hmax`` must bound ``H`` over the initial box and
            every parameter value (:func:`max_energy` with the parameter box).
    """

    def __init__(self, shell: EnergyShell, hmax: float, *, cut: float = 0.9, pieces: int = 64, params=None):
        if not isinstance(shell, EnergyShell):
            raise TypeError(f"shell must be a verified.consistency.contractor.EnergyShell, got {type(shell).__name__}")
        hmax = float(hmax)
        if not np.isfinite(hmax):
            raise ValueError(f"hmax must be a finite number, got {hmax!r}")
        if not 0.0 < float(cut) <= 1.0:
            raise ValueError(f"cut must be in (0, 1], got {cut!r}")
        self.shell, self.hmax, self.cut, self.pieces, self.params = shell, hmax, float(cut), int(pieces), params
        self._from_run = params is None and shell.M_graph.n_params > 0
        self._pcols = None  # the carried parameter columns (from the run), or None
        self.resets = 0  # sets replaced by their contracted box
        self.dropped = 0  # sets outside the shell

    def before_run(self, setup: RunSetup):
        nq2 = 2 * self.shell.nq
        if setup.n_state < nq2:
            raise ValueError(f"the energy shell needs the first {nq2} states to be (q, qd); "
                             f"the ODE has {setup.n_state}")
        if type(setup.sets) not in _SET_TYPES:
            raise ValueError("the energy shell works on first- and second-order sets (set_order=1 or 2), "
                             f"not on {type(setup.sets).__name__}")
        if self._from_run:
            p = self.shell.M_graph.n_params
            if setup.user_graph.n_params != p:
                raise ValueError(f"the energy shell takes {p} parameters, the ODE has {setup.user_graph.n_params}: "
                                 "pass them as params=")
            if setup.params is not None:
                P = setup.params if isinstance(setup.params, Interval) else Interval(setup.params)
                self.params = P if P.ndim == 1 else Interval(P.lo.min(axis=0), P.hi.max(axis=0))
                self._pcols = None
            else:
                self._pcols = slice(setup.n_state, setup.n_state + p)
        boxes = setup.sets.hull()
        res = self._contract(boxes)
        boxes = boxes[:, :nq2]
        if res.empty.any():
            raise ValueError(f"an initial box lies outside the energy shell H <= {self.hmax!r}: "
                             "hmax is not an upper bound of the initial energy")
        # the contraction never removes a state with H <= hmax, so a box it narrows holds
        # a state above hmax: the claim is wrong (typically hmax taken from an energy
        # whose potential has another zero than the shell's V)
        cut = (res.boxes.lo > boxes.lo) | (res.boxes.hi < boxes.hi)
        if cut.any():
            k = int(np.flatnonzero(cut.any(axis=1))[0])
            raise ValueError(f"the energy shell H <= {self.hmax!r} cuts initial box {k}: hmax is below the "
                             "initial energy 1/2 qd^T M qd + V(q) (is it the bound of an H with the same "
                             "potential V?)")
        return None

    def _params_of(self, hull: Interval):
        """The shell's parameters for sets with these hulls (B, N): the carried columns,
        or the fixed ones."""
        return hull[:, self._pcols] if self._pcols is not None else self.params

    def _contract(self, hull: Interval):
        """The shell's contraction of the ``(q, qd)`` columns of hulls (B, N)."""
        nq2 = 2 * self.shell.nq
        return self.shell.contract(hull[:, :nq2], self.hmax, params=self._params_of(hull), pieces=self.pieces)

    def after_step(self, step, sets, run):
        if type(sets) not in _SET_TYPES:
            return None
        nq2 = 2 * self.shell.nq
        hull = sets.hull()
        # only sets whose hull reaches past the shell can be cut: H over the hull (one
        # interval evaluation per set) sorts out the rest before the dearer contraction
        # (few sets are ever reset; docs/lab/code_notes.md)
        H = eval_interval(self.shell.graph, hull[:, :nq2], self._params_of(hull))[..., 0]
        near = ~(H.hi <= self.hmax)
        if not near.any():
            return None
        idx_near = np.flatnonzero(near)
        sub = self._contract(hull[idx_near])
        empty = np.zeros(sets.n_sets, dtype=bool)
        empty[idx_near] = sub.empty
        c_lo, c_hi = hull.lo[:, :nq2].copy(), hull.hi[:, :nq2].copy()
        c_lo[idx_near], c_hi[idx_near] = sub.boxes.lo, sub.boxes.hi
        res = _Contracted(c_lo, c_hi, empty)
        keep = ~res.empty
        if not keep.any():
            # the initial sets were inside the shell, so some true state is in some set:
            # the claim behind hmax must be wrong
            run.stop(f"energy shell H <= {self.hmax:g} excludes every set at t = {step.t:g}: "
                     "the energy is not bounded by hmax", "breakdown")
            return None
        out, resets, dropped = reset_to_contracted(sets, hull, res.lo, res.hi, keep, self.cut)
        self.resets += resets
        self.dropped += dropped
        return None if out is sets else out

    def after_run(self, solution) -> None:
        solution.stats["shell_resets"] = self.resets
        solution.stats["shell_dropped"] = self.dropped


"""What a run returns and where a run continues from: :class:`Solution` (the result of
:func:`verified.solver.solve`, of one in-process batch as of a chunked run) and
:class:`Start` (``solve(..., start=)``). Plain data: the one-batch driver
(:mod:`verified.batch`) and the chunked execution (:mod:`verified.parallel`) both build
them, so they live below both."""

from __future__ import annotations

from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np

from .interval import Interval

__all__ = ["Solution", "Start"]


@dataclass
class Start:
    """Where a run continues from (``solve(..., start=)``; :mod:`verified.parallel` cuts
    a chunk whose sets split into pieces and continues each from here).

    sets : the run's sets (:class:`~verified.sets.DoubletonSets` or
        :class:`~verified.quadratic.QuadraticSets`, the kind of the run's ``set_order``
        and ``set_step``) at ``t_exact``, with the uncertain parameters carried as states
        when the run carries them (the same columns a run from boxes has)
    t_exact : Fraction, the exact time of the sets (a sum of float steps)
    h_limit : the wrapping control's step limit there (s; inf: none)
    split_scale : None or (N,) factors on ``split_ratio`` per component: adaptive
        splitting compares a set's injection with the width of the union of *all* sets
        of a run, so a piece cut from a wider union judges against that union (the
        piece's union times this scale) rather than its own
    """

    sets: object
    t_exact: Fraction
    h_limit: float = float("inf")
    split_scale: np.ndarray | None = None


@dataclass
class Solution:
    """Result of :func:`verified.solver.solve`.

    Attributes
    ----------
    t : ndarray (k,)
        Output times reached (the requested ``t_eval`` up to ``t_reached``).
    boxes : list of Interval (B_j, n)
        For each output time, boxes whose union encloses every solution.
    hull : Interval (k, n)
        The hull of ``boxes`` at each output time.
    tube_t : ndarray (s + 1,)
        Step boundaries ``t_0 < t_1 < ... < t_s``.
    tube : list of Interval (B_j, n)
        For each step, boxes whose union encloses every solution on ``[t_j, t_j+1]``.
    tube_hull : Interval (s, n)
    t_reached : float
        The last time up to which the enclosure is verified.
    status : "completed", "breakdown", "stopped" or "interrupted"
        "stopped": a hook asked to stop (:mod:`verified.hooks`, e.g. a wall-clock cap);
        "interrupted": ``KeyboardInterrupt`` during the integration. Everything up to
        ``t_reached`` is verified in every case.
    reason : str
        Why the integration stopped early ("" when completed).
    stats : dict
        steps, boxes, rejected steps, Taylor evaluations, ``max_boxes`` (most sets
        at any time), wall time (s); with a consistency test also ``tests``,
        ``pruned_boxes``, ``test_s`` and ``backward_s`` (seconds in the tests).
    state_names : tuple of str
    consistency : verified.consistency.ConsistencyRecord or None
        RA(t), H_H and H_V per step and a record of every test (paper Figs. 2-3).
    views : list of verified.sets.SetView or None
        For each output time (as ``boxes``), the solver's sets there in a linear view
        over their own parameters (:func:`verified.sets.set_view`, the ``n`` states), so
        that a function of the states can be enclosed over the sets rather than their
        hull boxes (:mod:`mbs.frames`); ``None`` where an output has no view (boxes a
        hook wrote), and ``[]`` when the run kept none (the parallel path).
    tube_views : list of verified.sets.SetView or None
        For each step (as ``tube``), the a-priori enclosure as a linear view over
        symbols of its own (the ``n`` states), where the stepper keeps one (the
        composition step, ``set_step="composition"``; None elsewhere, and ``[]`` when
        the run kept none): :mod:`mbs.frames` encloses the frames over the tube in it.
    chunks : list of dict or None
        A chunked run (:mod:`verified.parallel`: ``workers``, ``client`` or ``chunks``):
        per initial chunk its boxes ``(start, stop)``, status, ``t_reached``, steps,
        tube and, with re-chunking, its ``pieces``; None for one in-process batch.
    pieces : list of dict or None
        A chunk's run that was re-chunked: each piece's parent, start time and status
        (:func:`verified.parallel.solve_parallel`); None otherwise.
    """

    t: np.ndarray
    boxes: list
    hull: Interval
    tube_t: np.ndarray
    tube: list
    tube_hull: Interval
    t_reached: float
    status: str
    reason: str
    stats: dict = field(default_factory=dict)
    state_names: tuple = ()
    consistency: object = None
    views: list = field(default_factory=list)
    tube_views: list = field(default_factory=list)
    chunks: list | None = None
    pieces: list | None = None

    @property
    def success(self) -> bool:
        return self.status == "completed"

    def __repr__(self):
        return (
            f"Solution(status={self.status!r}, t_reached={self.t_reached:g}, outputs={len(self.t)}, "
            f"steps={self.stats.get('steps')}, boxes={self.stats.get('boxes')}, reason={self.reason!r})"
        )

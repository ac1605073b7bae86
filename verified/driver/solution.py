"""What a run returns and where a run continues from: :class:`Solution` (the result of
:func:`verified.solver.solve`, of one in-process batch as of a chunked run) and
:class:`Start` (``solve(..., start=)``). Plain data: the one-batch driver
(:mod:`verified.driver.batch`) and the chunked execution (:mod:`verified.execution`) both build
them, so they live below both."""

from __future__ import annotations

from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np

from verified.arith.interval import Interval

__all__ = ["Solution", "Start", "PieceResult", "Failure", "pieces_summary"]


@dataclass
class Start:
    """Where a run continues from (``solve(..., start=)``; :mod:`verified.execution` cuts
    a chunk whose sets split into pieces and continues each from here).

    sets : the run's sets (:class:`~verified.sets.first_order.DoubletonSets` or
        :class:`~verified.sets.second_order.QuadraticSets`, the kind of the run's ``set_order``
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
class PieceResult:
    """How one initial piece of a run fared (``Solution.piece_results``).

    index : int
        The piece's row among the run's initial boxes (after ``subdivision``; with
        ``start=``: the start's set).
    box : Interval (n,)
        Its initial box (states; for a run continued from ``start``: the hull of its set).
    status : "completed", "breakdown", "stopped" or "interrupted"
        "breakdown": the run could not continue this piece's sets (everything up to
        ``t_reached`` is verified for it); the other statuses are the run's own.
    t_reached : float
        The last time up to which every solution from this piece is enclosed.
    reason : str
        Why it broke down or stopped ("" when completed).
    """

    index: int
    box: Interval
    status: str
    t_reached: float
    reason: str = ""

    @property
    def failed(self) -> bool:
        return self.status == "breakdown"


def _index_list(idx, limit: int = 8) -> str:
    """"piece 5" / "pieces 5, 17, 40" / "pieces 0-15, 40" (runs of consecutive indices)
    / "pieces 1, 3, 5, ... (12 more)"."""
    idx = sorted({int(i) for i in idx})
    runs = []
    for i in idx:
        if runs and i == runs[-1][1] + 1:
            runs[-1][1] = i
        else:
            runs.append([i, i])
    words = [str(a) if a == b else f"{a}, {b}" if b == a + 1 else f"{a}-{b}" for a, b in runs]
    more = len(words) - limit
    text = ", ".join(words[:limit]) + (f", ... ({more} more)" if more > 0 else "")
    return f"piece{'s' if len(idx) > 1 else ''} {text}"


def pieces_summary(results, t_end: float | None = None) -> str:
    """One line on the pieces of a run: ``"3 of 64 pieces failed (pieces 5, 17, 40:
    <reason>); 61 pieces verified to t = 2"`` (failures grouped by reason, in the order
    they happened); "" when no piece failed or every piece failed at once (the run's
    own reason says why)."""
    results = list(results or ())
    failed = [p for p in results if p.failed]
    if not failed or (len(failed) == len(results) and len({(p.t_reached, p.reason) for p in failed}) == 1):
        return ""  # (none failed, or all at once: the run's reason says it)
    groups: dict = {}
    for p in sorted(failed, key=lambda p: (p.t_reached, p.index)):
        groups.setdefault(p.reason, []).append(p)
    parts = []
    for reason, ps in groups.items():
        ts = sorted({p.t_reached for p in ps})
        when = f"t = {ts[0]:g}" if len(ts) == 1 else f"t = {ts[0]:g}..{ts[-1]:g}"
        parts.append(f"{_index_list(sorted(p.index for p in ps))} at {when}: {reason}")
    text = f"{len(failed)} of {len(results)} pieces failed ({'; '.join(parts)})"
    rest = [p for p in results if not p.failed]
    if rest:
        t_rest = min(p.t_reached for p in rest)
        statuses = {p.status for p in rest}
        how = "verified" if statuses == {"completed"} else f"verified ({'/'.join(sorted(statuses))})"
        text += f"; {len(rest)} piece{'s' if len(rest) > 1 else ''} {how} to t = {t_rest:g}"
    return text


@dataclass
class Failure:
    """Where some pieces of one batch run could not be continued, and the sets to go on
    from (``Solution.failures``; :mod:`verified.auto` continues them with a stronger
    method or split).

    pieces : (k,) int array
        The initial pieces (rows of the run's initial boxes) that broke down here.
    t : float
        The time up to which they are verified (a step boundary).
    reason : str
        Why their sets could not be continued.
    start : Start
        Their sets at ``t`` (every solution from those pieces is in them at that exact
        time), in the run's set kind: ``solve(..., start=failure.start)`` continues them.
    record : Solution
        The run restricted to those pieces, up to ``t``: its boxes enclose the solutions
        from those pieces only (made when first asked for: a run with many failures
        pays for the records only where a caller continues them).
    """

    pieces: np.ndarray
    t: float
    reason: str
    start: Start
    make_record: object = field(repr=False, default=None)  # () -> Solution

    @property
    def record(self) -> "Solution":
        if not hasattr(self, "_record"):
            self._record = self.make_record()
        return self._record


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
        "stopped": a hook asked to stop (:mod:`verified.driver.hooks`, e.g. a wall-clock cap);
        "interrupted": ``KeyboardInterrupt`` during the integration. Everything up to
        ``t_reached`` is verified in every case.
    reason : str
        Why the integration stopped early ("" when completed).
    stats : dict
        steps, boxes, rejected steps, Taylor evaluations, ``max_boxes`` (most sets
        at any time), wall time (s); with a consistency test also ``tests``,
        ``pruned_boxes``, ``test_s`` and ``backward_s`` (seconds in the tests).
    state_names : tuple of str
    consistency : verified.consistency.energy_test.ConsistencyRecord or None
        RA(t), H_H and H_V per step and a record of every test (paper Figs. 2-3).
    views : list of verified.sets.protocol.SetView or None
        For each output time (as ``boxes``), the solver's sets there in a linear view
        over their own parameters (:func:`verified.sets.protocol.set_view`, the ``n`` states), so
        that a function of the states can be enclosed over the sets rather than their
        hull boxes (:mod:`mbs.frames`); ``None`` where an output has no view (boxes a
        hook wrote), and ``[]`` when the run kept none (the parallel path).
    tube_views : list of verified.sets.protocol.SetView or None
        For each step (as ``tube``), the a-priori enclosure as a linear view over
        symbols of its own (the ``n`` states), where the stepper keeps one (the
        composition step, ``set_step="composition"``; None elsewhere, and ``[]`` when
        the run kept none): :mod:`mbs.frames` encloses the frames over the tube in it.
    chunks : list of dict or None
        A chunked run (:mod:`verified.execution`: ``workers``, ``client`` or ``chunks``):
        per initial chunk its boxes ``(start, stop)``, status, ``t_reached``, steps,
        tube and, with re-chunking, its ``pieces``; None for one in-process batch.
    pieces : list of dict or None
        A chunk's run that was re-chunked: each piece's parent, start time and status
        (:func:`verified.execution.run.solve_parallel`); None otherwise. (Not the initial
        pieces: those are ``piece_results``.)
    piece_results : list of PieceResult or None
        Per initial box of the run (after ``subdivision``): its status, ``t_reached`` and
        reason. When the sets of some pieces cannot be continued (an enclosure not
        finite or too wide, unbounded Taylor coefficients, no step validated), those
        pieces break down and the run continues with the others: then ``status`` is
        "breakdown", ``t_reached`` the time up to which *every* piece is verified, and
        ``t``, ``boxes``, ``hull``, ``tube``... stop there (they enclose every solution
        from the whole initial set); the pieces that went on are in ``surviving``.
        Pieces whose sets were linked (see :func:`verified.driver.batch.solve_batch`) fail
        together.
    surviving : Solution or None
        Only where some pieces broke down and others went on: the run restricted to the
        pieces that did *not* break down (``piece_results`` with status other than
        "breakdown"), up to where they went (its own ``t_reached``/``status``). Its
        boxes enclose the solutions from *those pieces only*, not from the whole
        initial set. None when no piece broke down on its own (the Solution itself
        covers every piece) or none went on.
    method : str
        The method that ran (:mod:`verified.methods`), with the settings that differ
        from its defaults; for ``method="auto"`` the attempts in one line.
    failures : list of Failure or None
        One in-process batch run only (None for chunked runs and for runs with a
        consistency test, which cannot be continued from their sets): per group of pieces
        that broke down, their record and their sets where they stopped
        (:class:`Failure`); ``[]`` when none broke down.
    method_log : list of dict or None
        ``method="auto"`` only (:mod:`verified.auto`): per attempt the method, the number
        of pieces, how often they had been split, the span it verified, its status and
        reason, its wall time and what was tried next (``"next"``).
    spec_check : verified.spec.SpecCheck or None
        ``method=Auto(spec=...)`` only: the spec's verdict ("proven" only from the
        verified tube over the whole span, "false" from a sampled trajectory, else
        "not proven"), the worst excess over a bound and a one-line detail.
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
    piece_results: list | None = None
    surviving: "Solution | None" = None
    method: str = ""
    method_log: list | None = None
    failures: list | None = None
    spec_check: object = None

    @property
    def success(self) -> bool:
        return self.status == "completed"

    @property
    def spec_proven(self) -> bool | None:
        """Whether the spec of ``Auto(spec=...)`` is proven from the tube (None: no spec)."""
        return None if self.spec_check is None else bool(self.spec_check.proven)

    @property
    def failed_pieces(self) -> list:
        """The indices of the initial pieces that broke down (``piece_results``)."""
        return [p.index for p in (self.piece_results or ()) if p.failed]

    def pieces_summary(self) -> str:
        """``"3 of 64 pieces failed (pieces 5, 17, 40 at t = 0.31: <reason>); 61 pieces
        verified to t = 2"``, or "" when no piece broke down on its own
        (:func:`pieces_summary`)."""
        return pieces_summary(self.piece_results)

    def __repr__(self):
        return (
            f"Solution(status={self.status!r}, t_reached={self.t_reached:g}, outputs={len(self.t)}, "
            f"steps={self.stats.get('steps')}, boxes={self.stats.get('boxes')}, reason={self.reason!r})"
        )

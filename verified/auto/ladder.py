# Whole: one pass of the ladder (_Ladder) and the rules by which it judges each attempt.
"""The ladder of ``method="auto"``: the first rung from the problem (:func:`default_rungs`),
each rung continued from the sets where the one before it stopped (:func:`switch_start`), a
stall handed down early (:class:`StallGuard`), and failing pieces split and run again
(:func:`_ladder`).
"""

from __future__ import annotations

import copy
import math
import time
from dataclasses import dataclass

import numpy as np

from verified.driver.hooks import Hook, caps_from
from verified.arith.interval import Interval, concatenate
from verified.methods import Auto, Composition, Lohner, Method
from verified.driver.solution import Failure, Solution, Start
from verified.driver.time_chain import chain_in_time
from verified.auto.splitting import SPLIT_DIMS, SPLIT_DIMS_AGAIN, split_pieces

__all__ = ["default_rungs", "COMPOSITION_MAX_STATES"]


#: up to this many states (parameters carried as states included) the first rung is the
#: composition: on every case measured for issue 40 (3-link arm, double pendulum, the
#: paper's pendulum, Laub-Loomis, x'' = -x - 2 x^2 x') it went further than first-order
#: sets at a similar or lower cost; its Taylor models grow with the square of the states
COMPOSITION_MAX_STATES = 24
#: from this many states on (a 5-DOF robot and up) the composition carries
#: LARGE_PARAMS_PER_STATE parameters per state: more of the accumulated error carried
#: exactly (the robots' best setting in benchmarks/bench_robots.py; docs/lab/auto.md).
#: Its order is the composition's own (12): since the recursion's orders from
#: ``TaylorModelODE.product_orders`` on keep no products, a longer series costs little
#: more per step and takes fewer, longer steps; order 8, the choice before, cost the UR5
#: 1.3x and ended a Panda's payload piece earlier (docs/lab/robot_speed.md)
#: Each step's order is chosen in [LARGE_MIN_ORDER, LARGE_ORDER] (``Composition.min_order``):
#: on robots under a controller the composition's growth cut, not the series' last term,
#: sets the steps, and there a lower order takes the same steps for less
LARGE_STATES = 10
LARGE_ORDER = Composition.order
LARGE_MIN_ORDER = 6
LARGE_PARAMS_PER_STATE = 12
#: from this many states on (parameters carried as states included) the composition
#: runs split pieces each alone, not as one batch: 4 payload pieces of a Panda cost
#: 1.47x the CPU in one batch; the 3-link arm (6 states) cost the same either way, 16
#: pieces of the double pendulum (4 states) 0.71x, and the default tests' small 6-9
#: state systems ~20 % more alone (docs/lab/auto.md)
ALONE_FROM_STATES = LARGE_STATES
#: a piece that reached the end with a final enclosure more than this many times as
#: wide, in some state, as the median of its siblings that reached it too "only just
#: held" (:func:`_loose_pieces`): where other pieces broke down and are split, it is
#: split with them (one such piece, 20-35x its siblings' qd, set a payload run's
#: result; docs/lab/auto.md)
LOOSE_FACTOR = 8.0
#: split pieces must get further than their parent by this fraction of the time span, or
#: splitting stops (what stops them is then not the width of the set)
MIN_GAIN = 0.01


def default_rungs(graph, boxes: Interval, params=None) -> tuple[Method, ...]:
    """The rungs ``auto`` tries, weakest first, for ``graph`` from ``boxes`` (B, n)."""
    n = graph.n_inputs
    # (uncertain parameters are carried as constant states)
    p_wide = 0 if params is None else int(np.count_nonzero(np.any(np.atleast_2d(params.width()) > 0, axis=0)))
    if n + p_wide <= COMPOSITION_MAX_STATES:
        if n + p_wide >= LARGE_STATES:
            return (Composition(order=LARGE_ORDER, params_per_state=LARGE_PARAMS_PER_STATE,
                                min_order=LARGE_MIN_ORDER),)
        return (Composition(),)
    return (Lohner(arithmetic="affine"), Lohner(arithmetic="affine", error_basis="auto"))


@dataclass
class _Task:
    boxes: Interval          # (k, n) initial pieces
    params: object           # the run's params ((p,) for all) or (k, p) rows, or None
    rung: int                # index into the rungs
    splits: int = 0          # how often these pieces were split
    parent_t: float = -np.inf  # where the pieces they were split from broke down
    failure: Failure | None = None  # a continuation: the failed attempt's record and sets to go on from
    probe: Solution | None = None  # the run of boxes[0] alone (a split's probe), reused: only boxes[1:] run


def switch_start(failure: Failure, method: Method) -> Start:
    """The sets ``method`` continues ``failure``'s pieces from, at exactly its time: the
    failed attempt's own sets where ``method`` advances sets of that kind, else their
    hull boxes as ``method``'s initial sets (a box holds every point of the sets it is
    the hull of; the correlation between the sets' components is lost)."""
    from verified.steppers.set_kinds import set_kind

    st = method.settings()
    kind = set_kind(st.get("set_order", 1), st.get("set_step", "mean_value"))
    sets = failure.start.sets
    if not isinstance(sets, kind.sets):
        sets = kind.sets.from_boxes(sets.hull())
    return Start(sets=sets, t_exact=failure.start.t_exact, h_limit=failure.start.h_limit)


def _continuable(failure: Failure, params, n_run: int) -> bool:
    """Whether a failure's sets can be continued by another method: they carry the run's
    states only (no state appended by a hook, such as the energy test's ``h``), and the
    parameters are the same for every piece (per-piece exact parameter rows cannot
    follow sets that mixed pieces)."""
    if failure.start is None or failure.start.sets.n_sets == 0:
        return False
    if failure.start.sets.hull().shape[-1] != n_run:
        return False
    return params is None or not isinstance(params, Interval) or params.ndim == 1


def _rows(params, idx):
    """The parameter rows of pieces ``idx`` (params per piece (k, p)), or params as is."""
    if params is None or not isinstance(params, Interval) or params.ndim != 2:
        return params
    return params[np.asarray(idx, dtype=int)]


#: the method that takes over the pieces of an attempt that stalled
FALLBACK = Lohner(arithmetic="affine", error_basis="auto")
#: an attempt stalls when its first STALL_MIN_STEPS steps would need more than
#: STALL_STEPS steps for the whole span (far more than the robots' runs take;
#: docs/lab/code_notes.md)
STALL_MIN_STEPS = 1000
STALL_STEPS = 20_000
STALLED = "stalled"


class StallGuard(Hook):
    """Stop an attempt (a break-down whose reason starts with ``"stalled"``) whose first
    :data:`STALL_MIN_STEPS` steps are so short that the span would take more than
    :data:`STALL_STEPS` of them."""

    def __init__(self, t0: float, t1: float):
        self.t0, self.t1, self.steps = float(t0), float(t1), 0

    def after_step(self, step, sets, run):
        self.steps += 1
        done = float(step.t) - self.t0
        # judged once, at the STALL_MIN_STEPS-th step: a run whose steps shrink only near its
        # end (a set blowing up before a break-down) is not a stall, it is a split's business
        if self.steps == STALL_MIN_STEPS and done * STALL_STEPS < self.steps * (self.t1 - self.t0):
            run.stop(f"{STALLED}: {self.steps} steps to t = {step.t:g} (about "
                     f"{self.steps * (self.t1 - self.t0) / max(done, 1e-300):.3g} for the span)", "breakdown")
        return None


def _one_batch(common: dict) -> dict:
    """``common`` for a run continued from sets (``solve(start=)``: one batch here)."""
    return {**common, "workers": 1, "client": None, "chunks": None, "rechunk": None}


def _carried(params) -> int:
    """How many parameters a run carries as states (all of them when any is uncertain)."""
    if params is None or not isinstance(params, Interval) or not bool(np.any(params.width() > 0)):
        return 0
    return int(params.shape[-1])


def projected_pieces(pieces: int, factor: float, gain: float, remaining: float) -> float:
    """How many pieces splitting would need to cover ``remaining`` more time, now at
    ``pieces`` pieces whose last split (``factor`` times as many) gained ``gain``: an
    optimistic guess (each further split gaining twice what the one before gained), so
    that ``auto`` stops splitting only where even that would exceed its ``max_pieces``.
    It guides the work, never an enclosure."""
    if remaining <= 0:
        return float(pieces)
    if not gain > 0:
        return math.inf
    levels, reach, step = 0, 0.0, gain
    while reach < remaining:
        step *= 2.0
        reach += step
        levels += 1
        if levels > 64:
            return math.inf
    return pieces * factor ** levels


def _probe_verdict(probe: Solution, parts: int, t_fail: float, span: float, t1: float, pieces: int,
                   factor: float, max_pieces: int) -> tuple[str, str | None]:
    """What a split's probe (part 1 of ``parts``, split from pieces that broke down at
    ``t_fail``) says: ``("stalled", None)`` (not judged), ``("stopped", None)`` (stopped or
    interrupted: nothing more is tried), ``("give up", why)`` (no further than its parent
    by MIN_GAIN of the ``span``, or :func:`projected_pieces` from ``pieces`` pieces, each
    split ``factor`` times as many, beyond ``max_pieces``), else ``("go", None)``."""
    if probe.status == "breakdown" and probe.reason.startswith(STALLED):
        return "stalled", None
    if probe.status not in ("breakdown", "completed"):
        return "stopped", None
    if probe.status == "completed":
        return "go", None
    t_p = _failure_time(probe)
    if t_p <= t_fail + MIN_GAIN * span:
        return "give up", (f"a probe (part 1 of the {parts} the pieces split into) broke down at t = {t_p:g}, "
                           f"no later than the piece(s) it was split from (t = {t_fail:g})")
    need = projected_pieces(pieces, factor, t_p - t_fail, t1 - t_p)
    if need > max_pieces:
        return "give up", (f"a probe (part 1 of the {parts} the pieces split into) got from t = {t_fail:g} to "
                           f"{t_p:g}: even if every further split gained twice as much as the one before, "
                           f"reaching t = {t1:g} would take about {need:.3g} pieces, more than "
                           f"max_pieces = {max_pieces}")
    return "go", None


def _log_entry(method: Method, pieces: int, splits: int, t_from: float, sol: Solution, t_start: float) -> dict:
    """``method_log``'s record of one attempt (``t_start``: its ``time.perf_counter()``)."""
    return dict(method=method.describe(), pieces=int(pieces), splits=splits, t_span=(t_from, float(sol.t_reached)),
                status=sol.status, reason=sol.reason, wall_s=time.perf_counter() - t_start)


def merge_parts(sols, sizes, initial: Interval, outs, t0, names, interrupted: bool = False) -> Solution:
    """One Solution of consecutive parts of the pieces ``initial`` (``sizes[i]`` pieces
    with Solution ``sols[i]``, in order), by :func:`verified.execution.merge.merge_solutions`;
    its ``chunks`` are None (the attempts are in ``method_log``)."""
    from verified.execution.merge import merge_solutions

    ends = np.cumsum(sizes)
    ranges = list(zip([0] + ends[:-1].tolist(), ends.tolist()))
    out = merge_solutions(list(sols), ranges, initial, outs, t0, names, interrupted=interrupted)
    out.chunks = None
    return out


def _loose_pieces(sols) -> list:
    """The indices of the runs in ``sols`` (one piece each, the same output times) that
    completed with a final box wider than :data:`LOOSE_FACTOR` times the median of the
    completed runs' final widths in some state (states where that median is 0 are not
    compared); [] with fewer than 3 completed runs (no median to speak of)."""
    done = [i for i, s in enumerate(sols) if s is not None and s.status == "completed"]
    if len(done) < 3:
        return []
    w = np.stack([np.asarray(sols[i].hull[-1].width(), float) for i in done])  # (pieces, n)
    med = np.median(w, axis=0)
    cmp = med > 0
    if not cmp.any():
        return []
    ratio = (w[:, cmp] / med[cmp]).max(axis=1)
    return [done[j] for j in np.flatnonzero(ratio > LOOSE_FACTOR)]


def _failure_time(sol: Solution) -> float:
    """Where a run's first piece broke down (its end where none did)."""
    return min((p.t_reached for p in (sol.piece_results or ()) if p.failed), default=float(sol.t_reached))


def _summary(log) -> str:
    return "auto: " + "; ".join(f"{e['method']} on {e['pieces']} piece(s) {e['status']} to t = {e['t_span'][1]:g}"
                                + (" (spec: split)" if "split into" in e.get("spec", "") else
                                   " (spec: shorter steps)" if "h_max" in e.get("spec", "") else "")
                                for e in log)


def _stack_rows(parts, pv):
    """The parameters of the pieces of ``parts`` ((count, params) each, in order): ``pv``
    itself where every part has it unchanged (None, or one row for all), else one row
    per piece (count, p) stacked."""
    if all(p is pv for _, p in parts) or pv is None:
        return pv
    rows = []
    for k, p in parts:
        if p.ndim == 1:
            p = Interval(np.tile(np.asarray(p.lo, float), (k, 1)), np.tile(np.asarray(p.hi, float), (k, 1)))
        rows.append(p)
    return concatenate(rows, axis=0)


def _ladder(solve, ode, graph, boxes: Interval, pv, t_span, *, method: Auto, t_eval, consistency, hooks, progress,
            started: float, **common):
    """One pass of the ladder from ``boxes`` (module docstring): (the Solution, the
    pieces it ended with (k, n), their parameters: ``pv`` as given, or rows (k, p)
    where splitting gave the parts their own)."""
    return _Ladder(solve, ode, graph, boxes, pv, t_span, method=method, t_eval=t_eval, consistency=consistency,
                   hooks=hooks, progress=progress, started=started, common=common).run()


class _Ladder:
    """The state one pass of the ladder shares between its attempts: the tasks to run
    (``todo``), the pieces finished with their Solutions (``done``), ``method_log``'s
    records (``log``), the failed attempts that covered every initial piece (``covers``),
    and why the pass ended early (``give_up``; ``later``: a stopped probe's reason).

    :meth:`run` takes one task at a time (:meth:`_take`): its attempt
    (:meth:`_attempt_task`), then, on a break-down, its failed pieces go to the next
    rung (:meth:`_hand_down`) or are split (:meth:`_split`); :meth:`_result` merges
    what is done."""

    def __init__(self, solve, ode, graph, boxes: Interval, pv, t_span, *, method: Auto, t_eval, consistency,
                 hooks, progress, started: float, common: dict):
        from verified.driver.solver_args import check_settings

        self.solve, self.ode, self.graph, self.boxes, self.pv = solve, ode, graph, boxes, pv
        self.method, self.t_eval, self.consistency, self.progress = method, t_eval, consistency, progress
        self.hooks, self.started, self.common = list(hooks), started, common
        self.n = graph.n_inputs
        self.t0, self.t1, self.outs, _ = check_settings(
            t_span=t_span, t_eval=t_eval, order=method.order, tol=method.tol, h_max=common.get("h_max"),
            h_min=common.get("h_min", 1e-9), max_steps=common.get("max_steps", 100_000),
            max_width=common.get("max_width", 1e3), adaptive=common.get("adaptive", False),
            split_ratio=common.get("split_ratio", 0.01), max_boxes=common.get("max_boxes", 4096),
            wrap_target=common.get("wrap_target", 0.03), merge_slack=common.get("merge_slack"),
            error_basis="qr", progress=progress)
        self.rungs = list(method.rungs or default_rungs(graph, boxes, pv))
        # the method a stalled attempt's pieces go to: first-order sets take long steps where
        # the composition's remainders keep its steps tiny (docs/lab/code_notes.md)
        self.rungs.append(FALLBACK)
        self.fallback = len(self.rungs) - 1
        for r in self.rungs:
            r.refuse(adaptive=bool(common.get("adaptive")), consistency=consistency is not None,
                     params=pv is not None and bool(np.any(pv.width() > 0)))
        self.todo = [_Task(boxes, pv, 0)]
        self.later = None  # the reason of a probe stopped or interrupted, for the result's
        self.first = None
        # [(boxes, Solution, params), ...] of failed attempts that, with the pieces done, covered everything
        self.covers = []
        self.done: list[tuple[Interval, Solution, object]] = []  # (pieces, their Solution, their params)
        self.log: list[dict] = []
        self.pieces_total = boxes.shape[0]
        self.give_up = None
        self.names = tuple(graph.input_names[:self.n])

    def run(self):
        while self.todo:
            self._take(self.todo.pop(0))
        return self._result()

    # ------------------------------------------------------------------ attempts
    def _run_hooks(self, r, t_from):
        """The caller's hooks (with what is left of their caps), and a stall guard but on the fallback."""
        return caps_from(self.hooks, self.started) + ([] if r == self.fallback else [StallGuard(t_from, self.t1)])

    def _attempt(self, pieces, params, r, first=None):
        """Rung ``r`` on ``pieces`` from t0: one batch, or each piece alone where
        :meth:`_runs_alone` says so (``first``: piece 0's run, a probe, reused)."""
        k = pieces.shape[0]
        if first is None and not self._runs_alone(k, r):
            consistency = None if self.consistency is None else copy.deepcopy(self.consistency)
            return self.solve(self.ode, pieces, (self.t0, self.t1), method=self.rungs[r], params=params,
                              t_eval=self.t_eval, consistency=consistency, hooks=self._run_hooks(r, self.t0),
                              progress=self.progress, **self.common)
        sols = [] if first is None else [first]
        for i in range(len(sols), k):
            if sols and sols[-1].status in ("stopped", "interrupted"):
                break  # (a cap or Ctrl-C: the pieces after it do not run)
            sols.append(self._one_piece(pieces[i:i + 1], _rows(params, [i]), r))
        return self._alone_merged(sols, pieces)

    def _runs_alone(self, k: int, r: int) -> bool:
        """Whether ``k`` pieces on rung ``r`` run each alone, with its own steps, instead
        of one batch that steps them together: the composition from
        :data:`ALONE_FROM_STATES` states on, where a step's cost is its sets' Taylor
        models rather than Python, and one batch takes every piece's shortest step
        (docs/lab/auto.md). Not where the caller chose ``chunks``, a ``client`` or
        ``workers`` > 1 (their batches are the caller's), and not with a consistency
        test (one batch can suspend an idle one, a piece alone cannot)."""
        workers = self.common.get("workers")
        return (k > 1 and isinstance(self.rungs[r], Composition) and self.consistency is None
                and self.n + _carried(self.pv) >= ALONE_FROM_STATES
                and self.common.get("chunks") is None and self.common.get("client") is None
                and (workers is None or (isinstance(workers, str) and workers == "auto") or workers == 1))

    def _one_piece(self, piece, params, r):
        """Rung ``r`` on one piece (1, n) from t0, with no consistency test (see :meth:`_runs_alone`)."""
        return self.solve(self.ode, piece, (self.t0, self.t1), method=self.rungs[r], params=params,
                          t_eval=self.t_eval, hooks=self._run_hooks(r, self.t0), progress=self.progress,
                          **self.common)

    def _alone_merged(self, sols, pieces):
        """One attempt's Solution from its pieces' own runs (None after a stop), with the
        completed pieces whose enclosure only just held (:func:`_loose_pieces`) taken
        out of ``surviving`` and named in ``stats["loose_pieces"]`` where other pieces
        broke down: those are split with them (a survivor 20-35x its siblings' width
        set a payload run's result; docs/lab/auto.md)."""
        k = pieces.shape[0]
        stop = next((s for s in sols if s.status in ("stopped", "interrupted")), None)
        runs = sols + [None] * (k - len(sols))
        sol = merge_parts(runs, [1] * k, pieces, self.outs, self.t0, self.names,
                          interrupted=stop is not None and stop.status == "interrupted")
        if stop is not None:
            sol.status, sol.reason = stop.status, stop.reason
            return sol
        failed = [i for i, s in enumerate(sols) if s.status == "breakdown"]
        loose = _loose_pieces(sols) if failed else []
        sol.stats["loose_pieces"] = loose
        if loose:
            kept = [i for i in range(k) if i not in set(failed) | set(loose)]
            sol.surviving = None if not kept else merge_parts([sols[i] for i in kept], [1] * len(kept),
                                                             pieces[np.asarray(kept)], self.outs, self.t0,
                                                             self.names)
            if sol.surviving is not None:
                sol.surviving.piece_results = sol.piece_results
        return sol

    def _attempt_task(self, task, t_from):
        """The Solution of ``task``: the rest of a probed split merged with its probe, the
        pieces from t0, or a continuation from the failed attempt's sets."""
        cont = task.failure
        if cont is None and task.probe is not None:
            # a split whose first part ran alone as its probe: the others, then both as one attempt
            k = task.boxes.shape[0]
            if self._runs_alone(k, task.rung):
                return self._attempt(task.boxes, task.params, task.rung, first=task.probe)
            rest = self._attempt(task.boxes[1:], _rows(task.params, range(1, k)), task.rung)
            sol = merge_parts([task.probe, rest], [1, k - 1], task.boxes, self.outs, self.t0, self.names,
                              interrupted=rest.status == "interrupted")
            if rest.status not in ("completed", "breakdown"):
                # (stopped or interrupted: nothing more is tried, whatever the probe did)
                sol.status, sol.reason = rest.status, rest.reason
            return sol
        if cont is None:
            return self._attempt(task.boxes, task.params, task.rung)
        # continued from the failed attempt's sets at exactly their time (switch_start)
        rung = self.rungs[task.rung]
        start = switch_start(cont, rung)
        return self.solve(self.ode, start.sets.hull()[:, :self.n], (self.t0, self.t1), method=rung,
                          params=task.params, t_eval=self.t_eval, start=start,
                          hooks=self._run_hooks(task.rung, t_from), progress=self.progress,
                          **_one_batch(self.common))

    def _stop(self, status):
        """Nothing more is tried: the tasks not run keep their pieces verified at t0 only."""
        self.give_up = status
        for rest in self.todo:
            self.done.append((rest.boxes, None, rest.params))
        self.todo = []

    # ------------------------------------------------------------------ one task
    def _take(self, task):
        """Run ``task`` and decide what becomes of its pieces."""
        rung = self.rungs[task.rung]
        t_start = time.perf_counter()
        cont = task.failure
        t_from = float(self.t0) if cont is None else float(cont.t)
        sol = self._attempt_task(task, t_from)
        entry = _log_entry(rung, task.boxes.shape[0], task.splits, t_from, sol, t_start)
        if cont is not None:
            entry["continued"] = f"from the sets of {task.boxes.shape[0]} piece(s) at t = {t_from:g}"
        self.log.append(entry)
        if self.first is None and cont is None and task.boxes.shape[0] == self.boxes.shape[0] and task.rung == 0 \
                and task.splits == 0:
            self.first = sol  # (the first attempt, on every initial piece)
        if cont is not None and sol.status != "breakdown":
            sol = chain_in_time([cont.record, sol])
        if sol.status != "breakdown":  # completed, or stopped / interrupted: nothing more is tried
            self.done.append((task.boxes, sol, task.params))
            if sol.status != "completed":
                self._stop(sol.status)
            return
        if cont is not None and float(sol.t_reached) <= t_from + MIN_GAIN * (self.t1 - self.t0):
            # the sets where the weaker method stopped were too far gone for this one too
            # (an enclosure already too wide, say): this method takes the pieces from t0
            self.todo.append(_Task(task.boxes, task.params, task.rung, task.splits, task.parent_t))
            entry["next"] = f"the continuation got no further: {rung.describe()} from t0"
            return
        if cont is not None:
            # a continuation that broke down: its sets mix its pieces, which go back to t0
            # and are split there (below); the failed attempt's record stands for them
            failed, failures = list(range(task.boxes.shape[0])), []
            sol = chain_in_time([cont.record, sol])
        else:
            failed = [p.index for p in (sol.piece_results or ()) if p.failed]
            if not failed or sol.surviving is None:
                failed = list(range(task.boxes.shape[0]))
            loose = [i for i in sol.stats.get("loose_pieces", ()) if i not in set(failed)]
            if loose:  # (pieces that only just held: split with the failed ones, out of sol.surviving)
                entry["loose"] = f"{len(loose)} piece(s) completed more than {LOOSE_FACTOR:g}x as wide as " \
                                 "their siblings: split with the failed ones"
                failed = sorted(failed + loose)
            failures = [f for f in (sol.failures or ()) if _continuable(f, task.params, self.n + _carried(self.pv))]
        kept = [i for i in range(task.boxes.shape[0]) if i not in set(failed)]
        stalled = sol.reason.startswith(STALLED) and task.rung != self.fallback
        if stalled or (task.rung + 1 < self.fallback and cont is None):
            self._hand_down(task, sol, entry, failed, failures, kept, stalled)
        else:
            self._split(task, sol, entry, failed, kept)

    def _hand_down(self, task, sol, entry, failed, failures, kept, stalled):
        """The next rung (the fallback after a stall) takes the failed pieces over: from
        where their sets stopped (Solution.failures), else (sets that cannot be
        continued) from t0."""
        to = self.fallback if stalled else task.rung + 1
        why = " (stalled)" if stalled else ""
        covered = set()
        for f in failures:
            idx = [int(i) for i in f.pieces]
            covered |= set(idx)
            self.todo.append(_Task(task.boxes[np.asarray(idx)], task.params, to, task.splits, task.parent_t,
                                   failure=f))
        rest = [i for i in failed if i not in covered]
        if rest:
            self.todo.append(_Task(task.boxes[np.asarray(rest)], _rows(task.params, rest), to, task.splits,
                                   task.parent_t))
        if kept:
            self.done.append((task.boxes[np.asarray(kept)], sol.surviving, _rows(task.params, kept)))
        entry["next"] = f"{len(failed)} piece(s) to {self.rungs[to].describe()}{why}" + (
            f", continued from their sets at t = {min(f.t for f in failures):g}" if failures else "")

    def _split(self, task, sol, entry, failed, kept):
        """Split the failed pieces' initial boxes and run them from t0 (splitting the
        sets where they failed gained less: docs/lab, issue 40), part 1 first as a
        probe; or give up, saying why. Pieces that came from a split are bisected along
        fewer components first (:data:`~verified.auto.splitting.SPLIT_DIMS_AGAIN`), and
        along all it allows where that split's probe gains nothing (the width that ends
        them may be in a component left whole)."""
        last = self.fallback if task.rung == self.fallback else self.fallback - 1  # (the rung splitting continues with)
        fb, fp = task.boxes[np.asarray(failed)], _rows(task.params, failed)
        t_fail = float(sol.t_reached) if task.failure is not None else _failure_time(sol)
        if not self.todo:
            # this attempt's pieces and the finished ones cover every initial piece: their
            # enclosure, verified to where this attempt got, stands if later attempts end earlier
            self.covers.append(list(self.done) + [(task.boxes, sol, task.params)])
        tried = 0
        dim_caps = (SPLIT_DIMS,) if task.splits == 0 else (SPLIT_DIMS_AGAIN, SPLIT_DIMS)
        for i, max_dims in enumerate(dim_caps):
            parts, part_params = split_pieces(self.graph, fb, fp, float(t_fail) - float(self.t0), max_dims)
            if parts.shape[0] <= tried:  # (no more components to split than the split just judged)
                break
            tried = parts.shape[0]
            n_after, probe, why = self._judge_split(task, sol, parts, part_params, last, t_fail, fb.shape[0])
            if probe is _STOPPED:
                return
            if why is None:
                break
            if probe is not None and i + 1 < len(dim_caps):  # (its log entry says why the next split is wider)
                self.log[-1]["next"] = f"{why}: split along more components"
        if why is not None:
            entry["next"] = f"gave up: {why}"
            # (the failed attempt encloses all its pieces up to its end)
            self.done.append((task.boxes, sol, task.params))
            self.give_up = "breakdown"
            return
        if kept:
            self.done.append((task.boxes[np.asarray(kept)], sol.surviving, _rows(task.params, kept)))
        self.pieces_total = n_after
        self.todo.append(_Task(parts, part_params, last, task.splits + 1, t_fail, probe=probe))
        entry["next"] = f"{len(failed)} piece(s) split into {parts.shape[0]}, with {self.rungs[last].describe()}" + (
            ", part 1 run first as a probe" if probe is not None else "")

    def _judge_split(self, task, sol, parts, part_params, last, t_fail, n_failed):
        """(pieces after the split, its probe or None or :data:`_STOPPED`, why to give up
        or None) for the split of ``n_failed`` failed pieces into ``parts``."""
        n_after = self.pieces_total - n_failed + parts.shape[0]
        why = None
        if parts.shape[0] == n_failed:
            why = "the pieces cannot be split (no state or parameter of finite, nonzero width)"
        elif n_after > self.method.max_pieces:
            why = f"splitting {n_failed} piece(s) would make more than max_pieces = {self.method.max_pieces}"
        elif t_fail <= task.parent_t + MIN_GAIN * (self.t1 - self.t0):
            # splitting did not take the pieces further: the cause is not the sets' width
            # (a blow-up, a singularity, a step-size limit), and more pieces will not help
            why = (f"the split pieces broke down at t = {t_fail:g}, no later than the piece they were "
                   f"split from (t = {task.parent_t:g})")
        probe = None
        if why is None and parts.shape[0] > 1:
            probe, why = self._probe(task, sol, parts, part_params, last, t_fail, n_after, n_failed)
        return n_after, probe, why

    def _probe(self, task, sol, parts, part_params, last, t_fail, n_after, n_failed):
        """Run part 1 of a split first: where it gets no further than the piece it was
        split from, neither will its siblings (a give-up takes the earliest part's time),
        and the others are not run for nothing (a passive robot whose break-down is not
        the sets' width paid 2^d full runs for it; docs/lab/auto.md). Returns (the probe
        to reuse or None, why to give up or None), or (:data:`_STOPPED`, None) where the
        probe was stopped or interrupted and the pass ends."""
        p_start = time.perf_counter()
        probe = self._attempt(parts[:1], _rows(part_params, [0]), last)
        self.log.append(dict(_log_entry(self.rungs[last], 1, task.splits + 1, float(self.t0), probe, p_start),
                             probe=f"part 1 of the {parts.shape[0]} run first"))
        verdict, why = _probe_verdict(probe, parts.shape[0], t_fail, float(self.t1) - float(self.t0),
                                      float(self.t1), n_after, parts.shape[0] / n_failed, self.method.max_pieces)
        if verdict == "stalled":
            # (a stall says nothing of the split's gain: the split attempt runs whole and
            # hands its stalled pieces on, as without a probe)
            self.log[-1]["next"] = "stalled: not judged; the split runs whole"
            return None, why
        if verdict == "stopped":  # (stopped or interrupted while probing: nothing more is tried)
            self.log[-1]["next"] = f"{probe.status}: the other parts were not run"
            self.done.append((task.boxes, sol, task.params))
            self.later = probe.reason
            self._stop(probe.status)
            return _STOPPED, None
        return probe, why

    # ------------------------------------------------------------------ the result
    def _merged(self, parts):
        if len(parts) == 1 and parts[0][1] is not None:
            return parts[0][1]
        return merge_parts([s for _, s, _ in parts], [b.shape[0] for b, _, _ in parts],
                           concatenate([b for b, _, _ in parts], axis=0), self.outs, self.t0, self.names,
                           interrupted=self.give_up == "interrupted")

    def _result(self):
        """The done pieces merged into one Solution (or a cover that got further), with
        the log: (Solution, pieces, their parameters)."""
        pv = self.pv
        pieces = concatenate([b for b, _, _ in self.done], axis=0)
        piece_params = _stack_rows([(b.shape[0], p) for b, _, p in self.done], pv)
        result = self._merged(self.done)
        if self.later is not None:
            result.reason = f"{result.reason} (later attempts: {self.later})"
        if result.status != "completed":
            # the later attempts ended earlier than an earlier one that, with the pieces done
            # by then, covered every initial piece (a wall-clock cap striking while auto
            # splits, say): that enclosure of the whole initial set, verified further, is the
            # result (the first attempt, or a split attempt that broke down later)
            first = self.first
            best = first if first is not None and first.t_reached > result.t_reached else None
            for parts in self.covers:
                if min(float(s.t_reached) for _, s, _ in parts if s is not None) <= float(
                        (result if best is None else best).t_reached):
                    continue  # (a merge reaches no further than its earliest part)
                cand = self._merged(parts)
                if cand.t_reached > (result if best is None else best).t_reached:
                    best, pieces = cand, concatenate([b for b, _, _ in parts], axis=0)
                    piece_params = _stack_rows([(b.shape[0], p) for b, _, p in parts], pv)
            if best is not None:
                why = result.reason
                result = best
                result.reason = f"{best.reason} (later attempts: {why})"
                self.give_up = self.give_up or result.status
        if result.status == "breakdown" and self.give_up == "breakdown":
            tried = ", ".join(dict.fromkeys(e["method"] for e in self.log))
            result.reason = (f"{result.reason} (auto tried {tried} on up to {self.pieces_total} pieces; "
                             f"see Solution.method_log)")
        result.method_log = self.log
        result.method = _summary(self.log)
        # (per-piece params rows follow the pieces only without splitting of per-box params)
        result.stats["auto_pieces"] = int(pieces.shape[0])
        return result, pieces, piece_params


#: :meth:`_Ladder._probe`'s mark for a probe that was stopped or interrupted
_STOPPED = object()

"""Per-piece break-downs (issue 39, item 3: "one failing piece discards all the others").

A run over several initial pieces (``subdivision``, several boxes, chunks) whose sets of
some pieces cannot be continued (an enclosure too wide or not finite, unbounded Taylor
coefficients, no step validated, a set budget spent by one piece's splitting) breaks
those pieces down alone: the whole-run result keeps its meaning (status "breakdown",
``t_reached`` the time up to which *every* piece is verified, the enclosures up to
there), ``piece_results`` names each piece's status, time and reason, and
``surviving`` carries the pieces that went on to where they went. Checked against
sampled true trajectories (scipy's DOP853, rtol 1e-12) from random points of the
surviving pieces, and a driver that silently drops a surviving piece is caught.
"""
import numpy as np
import pytest
from mbs.app.sampling import dop853

from verified.driver import batch
from verified.graph import trace
from verified.driver.hooks import Hook
from verified.arith.interval import Interval
from verified.sets.second_order import QuadraticSets
from verified.sets.first_order import DoubletonSets
from verified.driver.solution import PieceResult, pieces_summary
from verified.solver import solve


def _square(x):  # x' = x^2 blows up at t = 1 / x(0); y' = -y
    return np.array([x[0] ** 2, -x[1]])


def _inverse(x):  # x' = 1 / x: unbounded where x = 0
    return np.array([1.0 / x[0], -x[1]])


def _neg_inverse(x):  # x' = -1 / x: x reaches 0 (with infinite slope) at t = x(0)^2 / 2
    return np.array([-1.0 / x[0], -x[1]])


SQUARE = trace(lambda x, p: [x[0] ** 2, -x[1]], 2)
INVERSE = trace(lambda x, p: [1 / x[0], -x[1]], 2)
NEG_INVERSE = trace(lambda x, p: [-1 / x[0], -x[1]], 2)

#: x' = x^2 from x in [0.2, 1.4] in 6 pieces of 0.2: pieces 4 and 5 (x0 >= 1) blow up
#: before T = 0.9 (enclosure too wide at ~0.77 and ~0.67 s), pieces 0-3 go on
BOX = Interval([0.2, 0.9], [1.4, 1.1])
T = 0.9
T_EVAL = np.linspace(0.0, T, 10)
#: one batch in this process, first-order QR-Lohner sets at the defaults (the method
#: named, so that the run is the driver's own, not a method that retries failed pieces)
ONE = dict(workers=1, order=12, tol=1e-10)


def _points(results, count, seed=0):
    """``count`` points (count, n) of the pieces ``results`` (PieceResult): a seeded
    random choice of pieces, random points of each piece's box, plus each box's centre."""
    rng = np.random.default_rng(seed)
    boxes = [(np.asarray(p.box.lo, float), np.asarray(p.box.hi, float)) for p in results]
    pts = [0.5 * (lo + hi) for lo, hi in boxes]
    for j in rng.integers(0, len(boxes), size=count):
        lo, hi = boxes[j]
        pts.append(lo + rng.uniform(0, 1, lo.size) * (hi - lo))
    return np.array(pts)


def _states(f, points, times):
    """True states (S, len(times), n): scipy's DOP853, rtol 1e-12, atol 1e-12."""
    out = np.empty((len(points), len(times), points.shape[1]))
    for i, x0 in enumerate(points):
        s = dop853(lambda t, x: f(x), x0, float(times[-1]), dense=False, t_eval=times)
        out[i] = s.y.T
    return out


def _inside(boxes: Interval, x, slack=1e-9):
    lo, hi = np.asarray(boxes.lo, float), np.asarray(boxes.hi, float)
    tol = slack * (1.0 + np.abs(x))
    return bool(((lo - tol <= x) & (x <= hi + tol)).all(axis=1).any())


def _escapes(sol, f, points):
    """(sample, time) pairs of true states outside ``sol``: at its output times (the
    union of its boxes) and at times inside its steps (the union of that step's tube
    boxes)."""
    steps = np.asarray(sol.tube_t, float)
    inner = 0.5 * (steps[:-1] + steps[1:])
    times = np.unique(np.concatenate([np.asarray(sol.t, float), inner[:: max(1, inner.size // 40)]]))
    X = _states(f, points, times)
    bad = []
    for k, t in enumerate(times):
        out = np.flatnonzero(np.asarray(sol.t, float) == t)
        for s in range(len(points)):
            if out.size and not _inside(sol.boxes[out[0]], X[s, k]):
                bad.append((s, float(t)))
            j = np.searchsorted(steps, t, side="right") - 1
            if 0 <= j < len(sol.tube) and steps[j] < t < steps[j + 1] and not _inside(sol.tube[j], X[s, k]):
                bad.append((s, float(t)))
    return bad


def _alive(sol):
    return [p for p in sol.piece_results if not p.failed]


def _check_whole_run(sol, f, count=12):
    """The whole-run result encloses every piece up to its t_reached."""
    assert sol.status == "breakdown"
    assert sol.t_reached == min(p.t_reached for p in sol.piece_results)
    assert sol.tube_t[-1] == sol.t_reached and (np.asarray(sol.t) <= sol.t_reached).all()
    if sol.t_reached > 0:
        assert _escapes(sol, f, _points(sol.piece_results, count, seed=1)) == []


@pytest.mark.slow  # (~5-8 s: the default run stays under 3 minutes)
def test_failing_pieces_are_named_and_the_others_go_on():
    sol = solve(SQUARE, BOX, (0.0, T), subdivision=[6, 1], t_eval=T_EVAL, **ONE)
    assert sol.failed_pieces == [4, 5]
    t4, t5 = sol.piece_results[4].t_reached, sol.piece_results[5].t_reached
    assert 0.6 < t5 < t4 < 0.85
    assert all(p.status == "completed" and p.t_reached == T and p.reason == "" for p in _alive(sol))
    assert all("enclosure too wide" in sol.piece_results[i].reason for i in (4, 5))
    assert [p.index for p in sol.piece_results] == list(range(6))
    assert sol.piece_results[5].box.lo[0] == pytest.approx(1.2) and sol.piece_results[5].box.hi[0] == 1.4
    # the whole run keeps its meaning: break-down where the first piece broke down
    _check_whole_run(sol, _square)
    assert sol.t_reached == t5 and sol.t[-1] == T_EVAL[6]
    assert sol.reason.startswith("2 of 6 pieces failed (pieces 4, 5 at t = ")
    assert "enclosure too wide" in sol.reason and sol.reason.endswith("4 pieces verified to t = 0.9")
    # the pieces that went on, to the end, and nothing of the failed ones at the end
    s = sol.surviving
    assert s.status == "completed" and s.t_reached == T and np.array_equal(s.t, T_EVAL)
    assert s.surviving is None and s.piece_results is sol.piece_results
    assert s.boxes[0].shape[0] == 4 and s.boxes[-1].shape[0] == 4
    assert s.hull[0].hi[0] == pytest.approx(1.0)  # (the initial boxes of pieces 0-3)
    assert _escapes(s, _square, _points(_alive(sol), 24)) == []
    # the surviving enclosure is what the pieces alone give (their steps were shortened by
    # the failing ones while those lived: not narrower than alone, and not far wider)
    alone = solve(SQUARE, Interval([0.2, 0.9], [1.0, 1.1]), (0.0, T), subdivision=[4, 1], t_eval=T_EVAL, **ONE)
    assert alone.status == "completed"
    assert (s.hull[-1].width() >= 0.9 * alone.hull[-1].width()).all()
    assert (s.hull[-1].width() <= 3.0 * alone.hull[-1].width()).all()


def test_a_driver_that_drops_a_surviving_piece_is_caught(monkeypatch):
    """The containment check is sharp: a driver that drops piece 1's sets at the first
    failure and still reports piece 1 as verified fails it."""
    original = batch._PieceBook.fail

    def fail_and_lose_piece_1(self, bad, t, reason):
        keep = original(self, bad, t, reason)
        lose = self.origin == 1
        if lose.any():
            kept = np.flatnonzero(keep)
            keep[kept[lose]] = False
            self.origin = self.origin[~lose]
        return keep

    monkeypatch.setattr(batch._PieceBook, "fail", fail_and_lose_piece_1)
    sol = solve(SQUARE, BOX, (0.0, T), subdivision=[6, 1], t_eval=T_EVAL, **ONE)
    assert sol.failed_pieces == [4, 5] and sol.surviving is not None
    pts = _points([sol.piece_results[1]], 6)
    assert _escapes(sol.surviving, _square, pts)  # caught
    assert _escapes(sol.surviving, _square, _points([sol.piece_results[0]], 6)) == []


def test_pieces_that_fail_at_t0_do_not_take_the_others_with_them():
    """x' = 1/x: the pieces with x = 0 in their box have unbounded coefficients at t = 0
    ("breakdown at t = 0" for the whole run, as before); the others run to T = 1."""
    sol = solve(INVERSE, Interval([-0.5, 0.9], [1.5, 1.1]), (0.0, 1.0), subdivision=[4, 1],
                t_eval=np.linspace(0, 1, 5), **ONE)
    assert sol.status == "breakdown" and sol.t_reached == 0.0 and list(sol.t) == [0.0]
    assert len(sol.tube) == 0 and sol.boxes[0].shape[0] == 4
    assert sol.failed_pieces == [0, 1]
    assert all(sol.piece_results[i].t_reached == 0.0 and "Taylor coefficients are unbounded"
               in sol.piece_results[i].reason for i in (0, 1))
    assert sol.reason.startswith("2 of 4 pieces failed (pieces 0, 1 at t = 0: Taylor coefficients are unbounded")
    assert sol.reason.endswith("2 pieces verified to t = 1")
    s = sol.surviving
    assert s.status == "completed" and s.t_reached == 1.0 and len(s.t) == 5
    assert _escapes(s, _inverse, _points(_alive(sol), 16)) == []


def test_step_size_underflow_fails_only_the_sets_that_cannot_step():
    """x' = -1/x: the pieces whose x reaches 0 before T find no step above h_min (found
    by bisecting the batch); the others go on."""
    sol = solve(NEG_INVERSE, Interval([0.5, 0.9], [1.5, 1.1]), (0.0, 0.3), subdivision=[4, 1],
                t_eval=np.linspace(0, 0.3, 4), **ONE, h_min=1e-4)
    assert sol.failed_pieces == [0, 1]
    assert all("step size underflow" in sol.piece_results[i].reason for i in (0, 1))
    t0, t1 = sol.piece_results[0].t_reached, sol.piece_results[1].t_reached
    assert t0 < 0.5 ** 2 / 2 and t1 < 0.75 ** 2 / 2 and t0 < t1  # before the true solution reaches 0
    _check_whole_run(sol, _neg_inverse)
    s = sol.surviving
    assert s.status == "completed" and s.t_reached == 0.3
    assert _escapes(s, _neg_inverse, _points(_alive(sol), 16)) == []


def test_adaptive_splitting_follows_each_piece():
    """With adaptive splitting the sets of the blowing-up piece multiply until the budget
    of sets is spent: that piece breaks down (before: the whole run), the halves of the
    others' sets stay with their pieces."""
    sol = solve(SQUARE, BOX, (0.0, 0.75), subdivision=[3, 1], t_eval=np.linspace(0, 0.75, 4), **ONE,
                adaptive=True, split_ratio=0.2, max_boxes=256)
    assert sol.stats["splits"] > 0
    assert sol.failed_pieces == [2] and "max_boxes=256" in sol.piece_results[2].reason
    _check_whole_run(sol, _square)
    s = sol.surviving
    assert s.status == "completed" and s.t_reached == 0.75
    assert _escapes(s, _square, _points(_alive(sol), 16)) == []


@pytest.mark.parametrize("kind", [DoubletonSets, QuadraticSets])
def test_split_halves_keep_their_parents_piece(kind):
    """The halves of a split carry their parent's piece (set-major halves for
    doubletons, side-major for second-order sets): each lies in its piece's box."""
    boxes = Interval(np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]]),
                     np.array([[0.5, 1.0], [1.5, 1.0], [2.5, 1.0], [3.5, 1.0]]))
    sets = kind.from_boxes(boxes)
    book = batch._PieceBook(4, 4)
    mask = np.array([True, False, True, True])
    after = sets.split(mask)
    book.split(mask, sets, after)
    assert sorted(book.origin.tolist()) == [0, 0, 1, 2, 2, 3, 3]
    H = after.hull()
    for row, piece in enumerate(book.origin):
        assert (H.lo[row] >= boxes.lo[piece] - 1e-12).all() and (H.hi[row] <= boxes.hi[piece] + 1e-12).all()
    assert book.group.tolist() == [0, 1, 2, 3]  # nothing linked


class _Replace(Hook):
    """Returns the sets as a new batch after every step: which set came from which is
    not known to the driver any more."""

    def after_step(self, step, sets, run):
        return sets.take(np.arange(sets.n_sets))


def test_sets_a_hook_replaced_fail_together():
    """After a hook returned new sets, the driver cannot tell which piece a set holds:
    every piece is linked, a later failure fails them all (as before per-piece
    break-downs); nothing is reported as surviving."""
    sol = solve(SQUARE, BOX, (0.0, T), subdivision=[6, 1], t_eval=T_EVAL, **ONE, hooks=[_Replace()])
    assert sol.status == "breakdown" and sol.surviving is None
    assert sol.failed_pieces == list(range(6))
    assert len({(p.t_reached, p.reason) for p in sol.piece_results}) == 1
    assert sol.reason.startswith("enclosure too wide") and sol.t_reached == sol.piece_results[0].t_reached
    _check_whole_run(sol, _square)


@pytest.mark.slow  # (~5-8 s: the default run stays under 3 minutes)
def test_chunked_runs_report_every_piece():
    """In chunks (each its own batch) the chunks' reports merge: the failed pieces named
    by their index in the run, the surviving parts of the chunks merged."""
    sol = solve(SQUARE, BOX, (0.0, T), subdivision=[6, 1], t_eval=T_EVAL, **ONE, chunks=3)
    assert [c["status"] for c in sol.chunks] == ["completed", "completed", "breakdown"]
    assert sol.failed_pieces == [4, 5] and [p.index for p in sol.piece_results] == list(range(6))
    _check_whole_run(sol, _square)
    assert sol.reason.startswith("2 of 6 pieces failed (pieces 4, 5 at t = ")
    s = sol.surviving
    assert s.status == "completed" and s.t_reached == T and s.boxes[-1].shape[0] == 4
    assert _escapes(s, _square, _points(_alive(sol), 16)) == []
    # a chunk whose pieces all completed, the other with one piece left
    sol = solve(SQUARE, BOX, (0.0, T), subdivision=[6, 1], t_eval=T_EVAL, **ONE, chunks=2)
    assert sol.failed_pieces == [4, 5] and sol.surviving.boxes[-1].shape[0] == 4
    assert _escapes(sol.surviving, _square, _points(_alive(sol), 12)) == []


def test_one_box_and_runs_without_failures_are_as_before():
    one = solve(SQUARE, Interval([1.2, 0.9], [1.4, 1.1]), (0.0, T), t_eval=T_EVAL, **ONE)
    assert one.status == "breakdown" and one.reason.startswith("enclosure too wide")
    assert one.surviving is None and one.failed_pieces == [0] and one.pieces_summary() == ""
    ok = solve(SQUARE, Interval([0.2, 0.9], [0.6, 1.1]), (0.0, T), subdivision=[2, 1], t_eval=T_EVAL, **ONE)
    assert ok.status == "completed" and ok.surviving is None and ok.failed_pieces == []
    assert [(p.status, p.t_reached) for p in ok.piece_results] == [("completed", T)] * 2


def test_pieces_summary_groups_the_failures_by_reason():
    box = Interval([0.0], [1.0])
    res = [PieceResult(i, box, "completed", 2.0) for i in range(64)]
    for i, (t, why) in {5: (0.31, "A"), 17: (0.31, "A"), 40: (0.5, "B"), 41: (0.6, "B"), 42: (0.7, "B")}.items():
        res[i] = PieceResult(i, box, "breakdown", t, why)
    assert pieces_summary(res) == ("5 of 64 pieces failed (pieces 5, 17 at t = 0.31: A; pieces 40-42 at "
                                   "t = 0.5..0.7: B); 59 pieces verified to t = 2")
    assert pieces_summary(res[:3]) == ""
    every = [PieceResult(i, box, "breakdown", 0.3, "C") for i in range(3)]
    assert pieces_summary(every) == ""  # all at once: the run's reason says it

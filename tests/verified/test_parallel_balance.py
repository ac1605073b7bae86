"""Chunked runs that divide evenly (issue 42 item 2): a piece that lags on the cluster
is paused and its sets cut into new pieces for the free worker (work stealing); every
set goes to exactly one new piece; a run's cuts, replayed in this process
(``with exec_run.replaying(sol): solve(...)``), give its result float for float; families are
stitched as their last piece comes in."""

import numpy as np
import pytest

from models import double_pendulum as dp
from verified.execution import cluster, dask_run, rechunk
from verified.execution import hooks as exec_hooks, run as exec_run
from verified.graph import trace
from verified.driver.hooks import Hook
from verified.arith.interval import Interval
from verified.solver import VerifiedODE, solve

from oracles.sampling import misses, sample_initial_points, trajectories
T = 0.3
EVAL = [0.1, 0.2, T]
SUB = [16, 1, 1, 1]


class SlowAbove(Hook):
    """Sleep after every step of a chunk whose initial boxes reach ``x1 >= above``,
    and of every piece cut from a paused one (one chunk of the test's plan lags;
    module level: Dask workers import it by name)."""

    def __init__(self, seconds, above):
        self.seconds, self.above = seconds, above
        self.slow = False

    def before_run(self, setup):
        hi = float(np.max(np.asarray(setup.sets.hull().hi)[:, 0]))
        self.slow = setup.t0 > 0 or hi >= self.above
        return None

    def after_step(self, step, sets, run):
        import time
        if self.slow:
            time.sleep(self.seconds)
        return None


@pytest.fixture(scope="module")
def ode():
    return VerifiedODE(trace(dp.rhs, 4))


@pytest.fixture(scope="module")
def box():
    lo, hi = dp.initial_box()
    return Interval(lo, hi)


@pytest.fixture(scope="module")
def oracle(box):
    pts = sample_initial_points(np.asarray(box.lo), np.asarray(box.hi), 24, seed=5)
    return trajectories(lambda x: dp.rhs(x), pts, T)


def _same(a, b):
    """Two Solutions equal float for float: outputs, tube, status."""
    assert a.status == b.status and a.t_reached == b.t_reached
    np.testing.assert_array_equal(a.t, b.t)
    for x, y in zip(a.boxes, b.boxes, strict=True):
        np.testing.assert_array_equal(x.lo, y.lo)
        np.testing.assert_array_equal(x.hi, y.hi)
    np.testing.assert_array_equal(a.tube_t, b.tube_t)
    for x, y in zip(a.tube, b.tube, strict=True):
        np.testing.assert_array_equal(x.lo, y.lo)
        np.testing.assert_array_equal(x.hi, y.hi)


def test_a_cut_puts_every_set_in_exactly_one_piece(ode, box):
    """Cut into k = 2 .. more than the sets: the pieces' sets, in order, are the paused
    piece's sets (none dropped, none twice, none empty)."""
    boxes = box.subdivide([12, 1, 1, 1]).reshape(-1, 4)
    pause = exec_hooks._Pause(at_step=3)
    sol = solve(ode, boxes, (0.0, T), hooks=[pause], workers=1)
    assert sol.status == "stopped" and pause.start is not None and pause.steps == 3
    X = pause.start.sets.hull()
    for k in (2, 3, 5, 7, 12, 40):
        pieces = rechunk._Pieces(boxes, [(0, 12)], lambda a, b: None, False, 4096)
        new = pieces.done(0, sol, pause.start, k=k, why="lag")
        assert len(new) == min(k, 12) and all(pieces.items[j].start.sets.n_sets > 0 for j in new)
        got = [pieces.items[j].start.sets.hull() for j in new]
        np.testing.assert_array_equal(np.concatenate([g.lo for g in got]), X.lo)
        np.testing.assert_array_equal(np.concatenate([g.hi for g in got]), X.hi)
        assert [pieces.items[j].path for j in new] == [(0, j) for j in range(len(new))]
        assert pieces.cut_log == [dict(path=[0], steps=None, k=len(new), sets=12, t=float(pause.start.t_exact),
                                       why="lag")]


def test_replayed_cuts_in_process(ode, box, oracle):
    """Cuts given by hand (chunk 1 after 4 steps into 3 pieces, its second piece after 2
    more into 2): the pieces the replay names run, the result contains the samples, is
    stitched per family as the family completes, and replaying its own record gives it
    float for float."""
    cuts = [dict(path=[1], steps=4, k=3), dict(path=[1, 1], steps=2, k=2)]
    kw = dict(t_eval=EVAL, subdivision=SUB, workers=1, chunks=2)
    with exec_run.replaying(cuts):
        sol = solve(ode, box, (0.0, T), **kw)
    assert sol.status == "completed" and sol.t_reached == T and not misses(sol, oracle)
    assert [(c["path"], c["steps"], c["k"], c["why"]) for c in sol.stats["cuts"]] == [
        ([1], 4, 3, "replay"), ([1, 1], 2, 2, "replay")]
    assert sol.stats["pieces"] == 2 + 3 + 2 and sol.stats["rechunks"] == 2
    assert [b.shape for b in sol.boxes] == [(16, 4)] * 4
    assert len(sol.chunks[1]["pieces"]) == 6 and sol.chunks[0]["pieces"] is None
    assert sol.stats["stitch_s"] > 0  # (the families were stitched as they completed)
    with exec_run.replaying(sol):
        _same(solve(ode, box, (0.0, T), **kw), sol)
    # the plain plan (no cuts) differs: per-piece step sizes after the cut
    plain = solve(ode, box, (0.0, T), **kw)
    assert not all(np.array_equal(a.lo, b.lo) for a, b in zip(plain.boxes, sol.boxes))
    with pytest.raises(ValueError, match="replay"), exec_run.replaying([dict(path=[1])]):
        solve(ode, box, (0.0, T), **kw)
    with pytest.raises(ValueError, match="cover"), exec_run.replaying(sol):
        solve(ode, box, (0.0, T), **dict(kw, subdivision=[8, 1, 1, 1]))


@pytest.fixture(scope="module")
def client():
    pytest.importorskip("distributed")
    c = cluster.local_client(2)
    yield c
    cluster.close_local_clients()


@pytest.mark.slow  # ~12 s with the cluster's start (default-run budget); the cuts' replay runs by default above
def test_lagging_chunk_is_stolen_and_replays_in_process(ode, box, oracle, client, monkeypatch):
    """Two chunks on two workers, the second slowed (a loaded machine): once the first
    is done, the second is asked to pause, its sets go to both workers, and the result
    contains the samples; the same cuts replayed in this process give it float for float
    (stealing depends on timing, the result on the cuts only). rechunk=False: no cut."""
    monkeypatch.setattr(rechunk, "STEAL_MIN_SETS", 2)  # (_Pieces)
    monkeypatch.setattr(dask_run, "STEAL_MIN_SETS", 2)  # (_run_on_dask)
    monkeypatch.setattr(dask_run, "STEAL_MIN_S", 0.0)
    q3 = float(box.lo[0] + 0.75 * (box.hi[0] - box.lo[0]))  # (inside the second chunk's first box)
    kw = dict(t_eval=EVAL, subdivision=SUB, chunks=2)
    sol = solve(ode, box, (0.0, T), client=client, hooks=[SlowAbove(0.3, q3)], **kw)
    assert sol.stats["steal"] and sol.status == "completed" and sol.t_reached == T
    lag = [c for c in sol.stats["cuts"] if c["why"] == "lag"]
    assert lag and lag[0]["path"] == [1] and lag[0]["k"] >= 2 and 0 < lag[0]["t"] < T
    assert sol.stats["pieces"] > 2 and len(sol.chunks[1]["pieces"]) > 1
    assert {r["parent"] for r in sol.stats["timeline"] if r["parent"] is not None} == {1}
    assert not misses(sol, oracle)
    assert [b.shape for b in sol.boxes] == [(16, 4)] * 4
    with exec_run.replaying(sol):
        _same(solve(ode, box, (0.0, T), workers=1, **kw), sol)
    off = solve(ode, box, (0.0, T), client=client, rechunk=False, hooks=[SlowAbove(0.05, q3)], **kw)
    assert not off.stats["steal"] and off.stats["cuts"] == [] and off.stats["pieces"] == 2

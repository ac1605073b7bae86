"""Chunked execution (verified/execution/): in-process chunks and Dask workers give
enclosures that contain sampled DOP853 trajectories, with the status and t_reached of
the in-process run; a killed worker's chunk is retried; an unreachable scheduler is a
one-line error; re-chunked runs (sets of adaptive splitting cut into new chunks) contain
them too, and a re-chunking that drops a set is caught."""

import os
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from models import double_pendulum as dp
from verified.execution import cluster, interrupt, merge, plan, rechunk
from verified.execution import hooks as exec_hooks, run as exec_run
from verified.graph import trace
from verified.driver.hooks import StopAfterWall
from verified.arith.interval import Interval
from verified.solver import VerifiedODE, solve

from oracles.hooks import SlowSteps
from oracles.sampling import misses, sample_initial_points, trajectories

distributed = pytest.importorskip("distributed")

T = 0.3
SUB = [16, 1, 1, 1]


@pytest.fixture(scope="module")
def ode():
    return VerifiedODE(trace(dp.rhs, 4))


@pytest.fixture(scope="module")
def box():
    lo, hi = dp.initial_box()
    return Interval(lo, hi)


@pytest.fixture(scope="module")
def oracle(box):
    pts = sample_initial_points(np.asarray(box.lo), np.asarray(box.hi), 24, seed=3)
    return trajectories(lambda x: dp.rhs(x), pts, T)


@pytest.fixture(scope="module")
def client():
    """The local cluster workers=None / "auto" / N start (cluster.local_client: fresh
    worker interpreters with this process's sys.path, so they import this module for
    the hooks below, and tests/ for the oracles)."""
    c = cluster.local_client(2)
    yield c
    cluster.close_local_clients()


@pytest.fixture(scope="module")
def single(ode, box):
    return solve(ode, box, (0.0, T), t_eval=[0.1, 0.2, T], subdivision=SUB)


def test_inprocess_chunks_contain_samples(ode, box, oracle, single):
    sol = solve(ode, box, (0.0, T), t_eval=[0.1, 0.2, T], subdivision=SUB, workers=1, chunks=4)
    assert sol.stats["backend"] == "inprocess" and sol.stats["chunks"] == 4
    assert sol.status == single.status == "completed" and sol.t_reached == single.t_reached == T
    np.testing.assert_array_equal(sol.t, single.t)
    assert all(b.shape == (16, 4) for b in sol.boxes)
    assert not misses(sol, oracle)
    assert not misses(single, oracle)
    # own step sizes: the merged tube is on the union of the chunks' step times, one box per chunk
    assert all(tb.shape == (4, 4) for tb in sol.tube)
    assert np.all(np.diff(sol.tube_t) > 0) and sol.tube_t[0] == 0.0 and sol.tube_t[-1] == T
    for c in sol.chunks:
        assert set(c["tube_t"]).issubset(set(sol.tube_t))
    # the same enclosures up to the step sizes
    w1, w2 = np.asarray(single.hull[-1].width()), np.asarray(sol.hull[-1].width())
    assert np.all(np.abs(w2 / w1 - 1) < 0.01)
    assert sol.stats["steps"] == sum(sol.stats["chunk_steps"])


@pytest.mark.slow  # 2 s; the killed-worker test runs chunks on the same cluster by default
def test_dask_chunks_contain_samples(ode, box, oracle, single, client):
    ticks = []
    sol = solve(ode, box, (0.0, T), t_eval=[0.1, 0.2, T], subdivision=SUB, client=client, chunks=2,
                progress=lambda t, t_end: ticks.append((t, t_end)))
    assert sol.stats["backend"] == "dask" and sol.stats["chunks"] == 2
    assert sol.status == single.status and sol.t_reached == single.t_reached
    assert not misses(sol, oracle)
    w1, w2 = np.asarray(single.hull[-1].width()), np.asarray(sol.hull[-1].width())
    assert np.all(np.abs(w2 / w1 - 1) < 0.01)
    assert ticks and ticks[-1] == (T, T) and all(b[0] >= a[0] for a, b in zip(ticks, ticks[1:]))
    assert sol.stats["sent_bytes"] > 0 and sol.stats["received_bytes"] > 0


@pytest.mark.slow  # default-run budget (CI's cold default step measured 187 s of 180 at ec9790f)
def test_uncertain_parameters_per_chunk(client):
    """Per-box parameter rows travel with their boxes; a graph with parameters ships."""
    g = trace(lambda x, p: [x[1], -p[0] * np.sin(x[0])], 2, 1)
    x0 = Interval([0.5, 0.0], [0.6, 0.0])
    p = Interval([9.7], [9.9])
    a = solve(g, x0, (0.0, 0.5), params=p, subdivision=[4, 1])
    b = solve(g, x0, (0.0, 0.5), params=p, subdivision=[4, 1], client=client, chunks=4)
    assert a.status == b.status == "completed"
    assert np.all(b.hull[-1].lo <= a.hull[-1].hi) and np.all(a.hull[-1].lo <= b.hull[-1].hi)
    w1, w2 = np.asarray(a.hull[-1].width()), np.asarray(b.hull[-1].width())
    assert np.all(w2 < 1.05 * w1)


def test_breakdown_of_one_chunk_is_the_merged_status(ode, box):
    """A wide single box breaks down (~0.45 s) where narrow pieces do not: worst status,
    smallest t_reached, the reason names the piece (sol.chunks the chunk); outputs only
    where every chunk got; the chunk that completed is the surviving part."""
    narrow = box.subdivide([64, 1, 1, 1]).reshape(-1, 4)[:2]
    sol = solve(ode, [narrow, box], (0.0, 0.7), t_eval=[0.2, 0.4, 0.6, 0.7], workers=1, chunks=2)
    c = sol.chunks
    assert c[0]["status"] == "completed" and c[1]["status"] == "breakdown"
    assert sol.status == "breakdown" and sol.t_reached == c[1]["t_reached"] < 0.6
    assert sol.reason.startswith("1 of 3 pieces failed (piece 2 at t = ")
    assert sol.reason.endswith("2 pieces verified to t = 0.7")
    assert sol.failed_pieces == [2] and [p.status for p in sol.piece_results] == ["completed"] * 2 + ["breakdown"]
    assert sol.t[-1] <= sol.t_reached and len(sol.boxes) == len(sol.t)
    assert sol.tube_t[-1] == sol.t_reached
    s = sol.surviving
    assert s.status == "completed" and s.t_reached == 0.7 and [b.shape[0] for b in s.boxes] == [2] * 5



@pytest.mark.slow  # default-run budget (CI's cold default step measured 187 s of 180 at ec9790f)
def test_killed_worker_chunk_is_retried(ode, box, oracle, single, client):
    pids = client.run(os.getpid)
    killed = {}

    def killer():
        deadline = time.time() + 60
        while time.time() < deadline and not killed:
            busy = [w for w, keys in client.processing().items() if any("verified-chunk" in str(k) for k in keys)]
            if busy:
                time.sleep(0.3)  # well inside the chunk (>= 1 s of sleeping steps)
                os.kill(pids[busy[0]], signal.SIGKILL)
                killed[busy[0]] = pids[busy[0]]
                return
            time.sleep(0.05)

    th = threading.Thread(target=killer)
    th.start()
    sol = solve(ode, box, (0.0, T), t_eval=[0.1, 0.2, T], subdivision=SUB, client=client, chunks=2,
                hooks=[SlowSteps(0.1)])
    th.join()
    assert killed, "no worker was busy"
    assert sol.status == "completed" and sol.t_reached == T
    assert all(c["status"] == "completed" for c in sol.chunks)
    # no chunk result came from the killed process
    assert list(killed.values())[0] not in [c["worker_pid"] for c in sol.chunks]
    assert not misses(sol, oracle)
    np.testing.assert_allclose(np.asarray(sol.hull[-1].width()), np.asarray(single.hull[-1].width()), rtol=0.01)


def test_unreachable_scheduler_is_one_line_error(monkeypatch, box):
    monkeypatch.setattr(cluster, "CONNECT_TIMEOUT", 1.0)
    with pytest.raises(cluster.SchedulerError) as e:
        solve(trace(dp.rhs, 4), box, (0.0, 0.1), client="tcp://127.0.0.1:9")
    msg = str(e.value)  # "within 1 s": the timeout given to Dask (no hang: it is what Dask waits)
    assert "tcp://127.0.0.1:9" in msg and "\n" not in msg and "1 s" in msg
    with pytest.raises(ValueError, match="tcp://host:port"):
        cluster.connect("nonsense")


def test_an_address_that_is_no_scheduler_is_one_line_error(monkeypatch):
    """A port that accepts connections but does not answer as a Dask scheduler (the
    dashboard, an HTTP server) hung for ever: the handshake is bounded too."""
    import socket
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(4)
    held = []
    stop = threading.Event()

    def accept():  # accept and say nothing
        srv.settimeout(0.2)
        while not stop.is_set():
            try:
                held.append(srv.accept()[0])
            except OSError:
                pass
    th = threading.Thread(target=accept, daemon=True)
    th.start()
    monkeypatch.setattr(cluster, "HANDSHAKE_GRACE", 1.0)
    address = f"tcp://127.0.0.1:{srv.getsockname()[1]}"
    try:
        with pytest.raises(cluster.SchedulerError) as e:
            cluster.connect(address, timeout=1.0)
    finally:
        stop.set()
        th.join()
        for c in held:
            c.close()
        srv.close()
    assert address in str(e.value) and "\n" not in str(e.value)


def test_interrupt_runs_stops_a_run_waiting_in_a_thread(ode, box, client):
    """A scenario batch waits on Dask in threads, which Ctrl-C does not reach (it hung
    once the local workers died of the same Ctrl-C): interrupt.interrupt_runs() stops
    such a run as Ctrl-C stops one, its chunks cancelled and its Solution "interrupted"."""
    out = {}
    th = threading.Thread(target=lambda: out.setdefault(
        "sol", solve(ode, box, (0.0, T), subdivision=SUB, client=client, chunks=2, hooks=[SlowSteps(0.2)])))
    th.start()
    time.sleep(1.0)
    interrupt.interrupt_runs()
    try:
        th.join(120)  # (a guard against a hang, not a timing)
    finally:
        interrupt.interrupt_runs(False)
    assert not th.is_alive() and out["sol"].status == "interrupted"


def test_merged_consistency_record_is_the_max_over_chunks_not_a_sawtooth():
    """Two chunks' RA series at their own step times merge on the union of the times:
    at each time the largest latest value and the hull of H_H (the series interleaved
    by time alternated between the chunks)."""
    from verified.consistency.reduction_area import ConsistencyRecord
    a = ConsistencyRecord(ra_t=np.array([0.1, 0.3]), ra=np.array([5.0, 6.0]),
                          h_h=Interval([1.0, 1.0], [2.0, 2.0]), h_v=Interval([1.0, 1.0], [2.0, 2.0]))
    b = ConsistencyRecord(ra_t=np.array([0.2, 0.4]), ra=np.array([1.0, 2.0]),
                          h_h=Interval([0.5, 0.5], [1.5, 1.5]), h_v=Interval([0.5, 0.5], [1.5, 1.5]))
    m = merge._merge_records([a, b])
    np.testing.assert_array_equal(m.ra_t, [0.1, 0.2, 0.3, 0.4])
    np.testing.assert_array_equal(m.ra, [5.0, 5.0, 6.0, 6.0])  # (interleaved: 5, 1, 6, 2)
    np.testing.assert_array_equal(m.h_h.lo, [1.0, 0.5, 0.5, 0.5])
    np.testing.assert_array_equal(m.h_h.hi, [2.0, 2.0, 2.0, 2.0])


def test_local_workers_that_cannot_start_are_one_clear_error(monkeypatch):
    """A local cluster that cannot start is one line naming the cause and workers=1; on
    Windows (a LocalCluster, whose spawned workers re-run an unguarded script: Dask's
    bare "Nanny failed to start") it names the main guard too."""
    import distributed

    def failing(*args, **kwargs):
        raise RuntimeError("Nanny failed to start.")
    monkeypatch.setattr(cluster, "_LOCAL", {})
    monkeypatch.setattr(cluster, "start_local_cluster", lambda workers: failing())
    with pytest.raises(cluster.WorkerStartError, match="Nanny failed to start") as e:
        cluster.local_client(2)
    assert "\n" not in str(e.value) and "workers=1" in str(e.value)
    monkeypatch.setattr(cluster, "subprocess_workers_supported", lambda: False)
    monkeypatch.setattr(distributed, "LocalCluster", failing)
    with pytest.raises(cluster.WorkerStartError, match="__name__ == .__main__.") as e:
        cluster.local_client(2)
    assert "\n" not in str(e.value) and "workers=1" in str(e.value)


def test_worker_process_that_exits_at_start_is_one_line_error(tmp_path, monkeypatch):
    """A worker interpreter that dies while starting (here a `dask` package that exits)
    is a WorkerStartError at once, not a wait for LOCAL_START_TIMEOUT."""
    fake = tmp_path / "dask"
    fake.mkdir()
    (fake / "__init__.py").write_text("")
    (fake / "__main__.py").write_text("raise SystemExit(3)\n")
    env = {**os.environ, "PYTHONPATH": str(tmp_path)}
    monkeypatch.setattr(cluster, "_worker_env", lambda: env)
    monkeypatch.setattr(cluster, "_LOCAL", {})
    t = time.perf_counter()
    with pytest.raises(cluster.WorkerStartError, match="exited with code 3") as e:
        cluster.local_client(2)
    assert "\n" not in str(e.value) and time.perf_counter() - t < 30


UNGUARDED = """
import numpy as np
print("TOP LEVEL RAN", flush=True)
from verified.solver import solve
from verified.arith.interval import Interval
from verified.graph import trace
from models import double_pendulum as dp
lo, hi = dp.initial_box()
g = trace(dp.rhs, 4)
kw = dict(t_eval=[0.1, 0.2], subdivision=[256, 1, 1, 1])
par = solve(g, Interval(lo, hi), (0.0, 0.2), **kw)   # workers=None: 256 boxes, every core
one = solve(g, Interval(lo, hi), (0.0, 0.2), workers=1, **kw)
print("BACKEND", par.stats["backend"], par.stats["chunks"], par.status, one.status, par.t_reached, one.t_reached)
lo_d = max(float(np.max(np.abs(a.lo - b.lo))) for a, b in zip(par.boxes, one.boxes))
hi_d = max(float(np.max(np.abs(a.hi - b.hi))) for a, b in zip(par.boxes, one.boxes))
w = float(np.max(np.abs(np.asarray(par.hull[-1].width()) / np.asarray(one.hull[-1].width()) - 1)))
print("DIFF", lo_d, hi_d, w)
"""


@pytest.mark.slow  # ~10-20 s: a fresh interpreter, a cluster start and two 256-box runs
def test_unguarded_script_runs_once_on_every_core(tmp_path):
    """A script without the main guard, run as `python script.py`, that solves 256 boxes
    with the default workers=None: the chunks run on a local cluster of every core, the
    script's top level runs once (the workers never import it), and the enclosures are
    those of one in-process batch (up to the chunks' own step sizes)."""
    import subprocess
    import sys
    script = tmp_path / "unguarded.py"
    script.write_text(UNGUARDED)
    root = Path(__file__).resolve().parents[2]
    env = {**os.environ, "PYTHONPATH": str(root)}
    code = "import os; print(len(os.sched_getaffinity(0)) if hasattr(os, 'sched_getaffinity') else os.cpu_count())"
    cores = int(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True).stdout)
    if cores < 2:
        pytest.skip("one core: workers=None runs in this process")
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=600,
                         cwd=tmp_path, env=env)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.count("TOP LEVEL RAN") == 1, out.stdout
    backend = next(line for line in out.stdout.splitlines() if line.startswith("BACKEND")).split()
    assert backend[1:] == ["dask-local", "2", "completed", "completed", "0.2", "0.2"]
    lo_d, hi_d, w = map(float, next(line for line in out.stdout.splitlines() if line.startswith("DIFF")).split()[1:])
    assert w < 0.01  # worst width ratio at T
    assert lo_d < 1e-6 and hi_d < 1e-6


def test_default_workers_on_a_small_batch_stays_in_process(ode, box, single, monkeypatch):
    """workers=None below AUTO_MIN_PIECES boxes is solve's own batch (no cluster asked
    for), as is workers=1 at any size; None asks for every core from AUTO_MIN_PIECES
    boxes on, only with Dask, more than one core and workers that do not re-run the
    script."""
    def no_cluster(workers):
        raise AssertionError("a local cluster was asked for")
    monkeypatch.setattr(exec_run, "local_client", no_cluster)
    monkeypatch.setattr(plan, "default_workers", lambda: 2)  # (auto_workers)
    monkeypatch.setattr(exec_run, "default_workers", lambda: 2)  # (solve_parallel)
    sol = solve(ode, box, (0.0, T), t_eval=[0.1, 0.2, T], subdivision=SUB)
    assert "backend" not in sol.stats and sol.status == single.status and sol.t_reached == single.t_reached
    np.testing.assert_array_equal(sol.tube_t, single.tube_t)
    np.testing.assert_array_equal(sol.hull[-1].lo, single.hull[-1].lo)
    n = plan.AUTO_MIN_PIECES
    one = solve(ode, box, (0.0, 0.01), subdivision=[n, 1, 1, 1], workers=1)
    assert "backend" not in one.stats and one.status == "completed" and one.boxes[-1].shape == (n, 4)
    auto = plan.auto_workers
    assert auto(ode, box, [n - 1, 1, 1, 1]) is None and auto(ode, box, [n, 1, 1, 1]) == "auto"
    assert auto(ode, box.subdivide([n, 1, 1, 1]).reshape(-1, 4)) == "auto"
    assert auto(ode, "not a box", [n, 1, 1, 1]) is None  # (solve's own checks report it)
    for name, value in (("subprocess_workers_supported", False), ("dask_available", False),
                        ("_in_dask_worker", True)):
        with monkeypatch.context() as m:
            m.setattr(plan, name, lambda value=value: value)
            assert auto(ode, box, [n, 1, 1, 1]) is None
    with monkeypatch.context() as m:  # (the benchmarks' switch: one core against one core)
        m.setattr(plan, "DEFAULT_PARALLEL", False)
        assert auto(ode, box, [n, 1, 1, 1]) is None
    monkeypatch.setattr(plan, "default_workers", lambda: 1)
    assert auto(ode, box, [n, 1, 1, 1]) is None


def test_default_workers_fall_back_to_one_batch_when_no_cluster_starts(ode, box, monkeypatch):
    """workers=None must not fail a run one process can do: a local cluster that cannot
    start is a warning and one in-process batch; an explicit workers=2 raises."""
    def broken(workers):
        raise cluster.WorkerStartError("could not start 2 local Dask worker processes (test)")
    monkeypatch.setattr(exec_run, "local_client", broken)
    monkeypatch.setattr(plan, "default_workers", lambda: 2)  # (auto_workers)
    monkeypatch.setattr(exec_run, "default_workers", lambda: 2)  # (solve_parallel)
    n = plan.AUTO_MIN_PIECES
    with pytest.warns(RuntimeWarning, match="workers=None runs in this process"):
        sol = solve(ode, box, (0.0, 0.01), subdivision=[n, 1, 1, 1])
    assert sol.stats["backend"] == "inprocess" and sol.stats["chunks"] == 1 and sol.status == "completed"
    with pytest.raises(cluster.WorkerStartError):
        solve(ode, box, (0.0, 0.01), subdivision=[n, 1, 1, 1], workers=2)


def test_cli_workers_1_is_one_in_process_batch():
    """--workers 1 (and run_scene's workers=None) pass workers=1 to simulate: its default,
    None, would be every core."""
    from mbs.app.runner import parallel_kwargs
    assert parallel_kwargs(None) == parallel_kwargs(1) == {"workers": 1}
    assert parallel_kwargs("auto") == {"workers": "auto"} and parallel_kwargs(2) == {"workers": 2}


def test_fallbacks_and_bad_arguments(ode, box, monkeypatch):
    # fewer pieces than workers: one chunk, in-process
    sol = solve(ode, box.subdivide([2, 1, 1, 1]).reshape(-1, 4)[:1], (0.0, 0.05), workers=2)
    assert sol.stats["backend"] == "inprocess" and sol.stats["chunks"] == 1
    # Dask missing: an explicit workers > 1 warns and runs in-process; "auto" silently
    monkeypatch.setattr(exec_run, "dask_available", lambda: False)
    with pytest.warns(RuntimeWarning, match="not installed"):
        sol = solve(ode, box, (0.0, 0.05), subdivision=[4, 1, 1, 1], workers=2)
    assert sol.stats["backend"] == "inprocess" and sol.status == "completed"
    sol = solve(ode, box, (0.0, 0.05), subdivision=[4, 1, 1, 1], workers="auto")
    assert sol.stats["backend"] == "inprocess"
    for bad in (dict(workers=0), dict(workers="all"), dict(chunks=0), dict(chunks=1.5)):
        with pytest.raises(ValueError):
            solve(ode, box, (0.0, 0.05), **bad)
    with pytest.raises(ValueError, match="tol"):  # the solver's own checks come first
        solve(ode, box, (0.0, 0.05), workers=1, chunks=2, tol=0)


def test_wall_cap_is_one_deadline(ode, box):
    sol = solve(ode, box, (0.0, 5.0), subdivision=SUB, workers=1, chunks=2, hooks=[StopAfterWall(0.0)])
    assert sol.status == "stopped" and "wall-clock" in sol.reason
    assert all(c["steps"] == 1 for c in sol.chunks)


def test_plan_chunks():
    plan_of, M = plan.plan_chunks, plan.MIN_CHUNK_BOXES
    # default: no chunk below MIN_CHUNK_BOXES boxes, so a small batch is one chunk
    assert plan_of(16, 2) == [(0, 16)]
    assert plan_of(3, 4) == [(0, 3)]
    assert len(plan_of(2 * M - 1, 2)) == 1 and len(plan_of(2 * M, 2)) == 2
    assert len(plan_of(5 * M, 8)) == 5 and all(b - a >= M for a, b in plan_of(5 * M, 8))
    assert plan_of(1024, 2) == [(0, 512), (512, 1024)]
    assert len(plan_of(65536, 64)) == 128
    # more chunks per worker only for big batches; a wall-clock cap: one per worker
    assert len(plan_of(4096, 2)) == 8 and len(plan_of(4096, 2, max_per_worker=1)) == 2
    # explicit chunks are used as given, also below the minimum (never more than boxes)
    assert plan_of(16, 2, 2) == [(0, 8), (8, 16)]
    assert plan_of(16, 1, 4) == [(0, 4), (4, 8), (8, 12), (12, 16)]
    assert plan_of(3, 4, 4) == [(0, 1), (1, 2), (2, 3)]
    r = plan_of(1000, 3, 7)
    assert len(r) == 7 and r[0][0] == 0 and r[-1][1] == 1000
    assert all(a[1] == b[0] for a, b in zip(r, r[1:]))


def test_small_batch_with_workers_is_one_in_process_batch(ode, box, oracle, single, monkeypatch):
    """A plan of one chunk never starts (or uses) a local cluster: the result is the
    in-process batch itself, also with workers="auto" and with a wall-clock cap."""
    def no_cluster(workers):
        raise AssertionError("a local cluster was asked for")
    monkeypatch.setattr(exec_run, "local_client", no_cluster)
    monkeypatch.setattr(plan, "default_workers", lambda: 2)  # (auto_workers)
    monkeypatch.setattr(exec_run, "default_workers", lambda: 2)  # (solve_parallel)
    sol = solve(ode, box, (0.0, T), t_eval=[0.1, 0.2, T], subdivision=SUB, workers=2)
    assert sol.stats["backend"] == "inprocess" and sol.stats["chunks"] == 1 and sol.stats["workers"] == 1
    assert sol.status == single.status and sol.t_reached == single.t_reached
    np.testing.assert_array_equal(sol.tube_t, single.tube_t)
    for a, b in zip(sol.boxes, single.boxes):
        np.testing.assert_array_equal(a.lo, b.lo)
        np.testing.assert_array_equal(a.hi, b.hi)
    assert not misses(sol, oracle)
    n = 2 * plan.MIN_CHUNK_BOXES - 1  # "auto" used a cluster from 32 pieces on before the minimum
    for kw in (dict(workers="auto"), dict(workers=2, hooks=[StopAfterWall(60.0)])):
        s = solve(ode, box, (0.0, 0.02), subdivision=[n, 1, 1, 1], **kw)
        assert s.stats["backend"] == "inprocess" and s.stats["chunks"] == 1 and s.status == "completed"


def test_default_plan_and_explicit_chunks_on_a_cluster(ode, box, oracle, single, client, monkeypatch):
    """workers=2 (the local cluster: here the test's cluster) splits 2 * MIN_CHUNK_BOXES
    boxes in two and honours an explicit chunks= below the minimum; client= runs even a
    one-chunk plan on the cluster."""
    monkeypatch.setattr(exec_run, "local_client", lambda workers: client)
    sol = solve(ode, box, (0.0, T), t_eval=[0.1, 0.2, T], subdivision=SUB, workers=2, chunks=4)
    assert sol.stats["backend"] == "dask-local" and sol.stats["chunks"] == 4
    assert [c["boxes"] for c in sol.chunks] == [(0, 4), (4, 8), (8, 12), (12, 16)]
    assert sol.status == single.status and sol.t_reached == single.t_reached and not misses(sol, oracle)
    one = solve(ode, box, (0.0, T), t_eval=[0.1, 0.2, T], subdivision=SUB, client=client)
    assert one.stats["backend"] == "dask" and one.stats["chunks"] == 1 and one.chunks[0]["boxes"] == (0, 16)
    assert one.chunks[0]["worker_pid"] != os.getpid()
    assert one.status == single.status and one.t_reached == single.t_reached and not misses(one, oracle)
    np.testing.assert_allclose(np.asarray(one.hull[-1].width()), np.asarray(single.hull[-1].width()), rtol=1e-9)
    n = 2 * plan.MIN_CHUNK_BOXES
    two = solve(ode, box, (0.0, 0.02), subdivision=[n, 1, 1, 1], workers=2)
    assert two.stats["backend"] == "dask-local" and [c["boxes"] for c in two.chunks] == [(0, n // 2), (n // 2, n)]
    assert two.status == "completed" and two.boxes[-1].shape == (n, 4)


@pytest.mark.parametrize("method", ["lohner", "second_order", "composition"])
def test_chunked_methods_on_dask_equal_one_process(box, client, method):
    """Issue 42 item 4: first-order, second-order and composition sets run chunked on
    the cluster's worker processes give the in-process result of the same plan, float
    for float (the same operations on the same numbers), and a one-chunk plan on the
    cluster the in-process batch itself."""
    g = trace(dp.rhs, 4)  # a Graph: method= picks the arithmetic
    kw = dict(method=method, subdivision=[4, 1, 1, 1], t_eval=[0.05, 0.1])
    pairs = [(solve(g, box, (0.0, 0.1), workers=1, chunks=2, **kw), solve(g, box, (0.0, 0.1), client=client,
                                                                        chunks=2, **kw)),
             (solve(g, box, (0.0, 0.1), workers=1, **kw), solve(g, box, (0.0, 0.1), client=client, chunks=1, **kw))]
    for here, there in pairs:
        assert here.stats.get("backend", "inprocess") == "inprocess" and there.stats["backend"] == "dask"
        assert here.status == there.status == "completed" and here.method == there.method
        np.testing.assert_array_equal(here.t, there.t)
        for a, b in zip(here.boxes, there.boxes):
            np.testing.assert_array_equal(a.lo, b.lo)
            np.testing.assert_array_equal(a.hi, b.hi)
    assert pairs[0][1].stats["chunks"] == 2 and os.getpid() not in [c["worker_pid"] for c in pairs[0][1].chunks]


def test_simulate_forwards_workers(client):
    """simulate(..., client=) reaches the chunked path, energy test included (mode ii)."""
    from mbs.simulate import simulate
    x0 = Interval([2.1, 3.1], [2.2, 3.2])
    a = simulate("pendulum_paper", x0, 0.3, mode="ii", subdivision=[4, 1], progress=False)
    b = simulate("pendulum_paper", x0, 0.3, mode="ii", subdivision=[4, 1], progress=False, client=client, chunks=2)
    assert a.status == b.status == "completed" and b.stats["chunks"] == 2 and b.stats["backend"] == "dask"
    assert b.consistency is not None and b.stats["tests"] >= a.stats["tests"]
    assert np.all(b.hull[-1].width() < 1.1 * a.hull[-1].width() + 1e-12)


SWEEP = """
name = "pendulum g sweep"
[model]
name = "pendulum_paper"
[parameters]
g = [9.80, 9.81]
[initial]
x1 = ["2.1", "2.15"]
x2 = ["3.1", "3.15"]
[simulation]
t_end = 0.2
output_dt = 0.1
mode = "i"
[solver]
subdivision = [2, 2]

[[scenarios]]
name = "g low"

[[scenarios]]
name = "g high"
parameters = { g = [9.81, 9.82] }
"""


def test_cli_scenarios_one_combined_result(tmp_path, capsys):
    """[[scenarios]]: one run per scenario (here in-process, --workers 1), a combined
    scenarios.json and a per-scenario summary; every sampled trajectory inside."""
    import json
    from mbs.app.cli import main
    scene = tmp_path / "sweep.toml"
    scene.write_text(SWEEP)
    assert main(["simulate", str(scene), "--out", str(tmp_path / "o"), "--samples", "4", "--workers", "1"]) == 0
    data = json.loads((tmp_path / "o" / "scenarios.json").read_text())
    assert data["status"] == "completed" and data["t_reached"] == 0.2
    rows = {r["name"]: r for r in data["scenarios"]}
    assert set(rows) == {"g low", "g high"}
    assert rows["g high"]["parameters"]["g"][0] >= 9.81 - 1e-12 and rows["g low"]["parameters"]["g"][1] <= 9.81
    assert all(r["samples_checked"] == 4 and r["samples_escaped"] == 0 for r in rows.values())
    assert (tmp_path / "o" / "g_low" / "result.json").is_file()
    out = capsys.readouterr().out
    assert "g high" in out and "scenarios.json" in out


def test_scenario_tables_override_at_every_depth(tmp_path):
    """A scenario's payload mass keeps the base payload's link and com (the override
    replaced the whole payload table, dropping com without a word)."""
    from mbs.app.runner import scenario_batch
    text = """
[model]
name = "planar2"
[parameters]
payload = { link = "link2", mass = [0.9, 1.1], com = [0.1, 0.0, 0.0] }
[initial]
q1 = 0.5
q2 = -0.3
qd1 = 0.0
qd2 = 0.0
[simulation]
t_end = 0.1

[[scenarios]]
name = "heavy"
parameters = { payload = { mass = [1.0, 1.2] } }
"""
    path = tmp_path / "p.toml"
    path.write_text(text)
    ((name, scene),) = scenario_batch(path)
    pay = scene.physical["payload"]
    pay = pay[0] if isinstance(pay, list) else pay
    com = np.array(pay["com"], float).reshape(3, -1)  # (parsed to enclosing intervals)
    assert name == "heavy" and pay["link"] == "link2"
    assert np.all(com.min(axis=1) <= [0.1, 0.0, 0.0]) and np.all(com.max(axis=1) >= [0.1, 0.0, 0.0])
    mass = np.array(pay["mass"], float).ravel()
    assert mass.min() <= 1.0 and mass.max() >= 1.2 and mass.min() > 0.95


def test_ctrl_c_stops_an_in_process_scenario_batch(tmp_path, monkeypatch, capsys):
    """With --workers 1, Ctrl-C interrupted only the running scenario and the batch went
    on with the next: it stops the batch now, and the summary names what was not run."""
    from types import SimpleNamespace
    from mbs.app import runner
    from mbs.app.cli import main
    calls = []

    def interrupted_run(scene, out, **kw):
        calls.append(out.name)
        sol = SimpleNamespace(status="interrupted", t_reached=0.05, reason="interrupted (KeyboardInterrupt)",
                              stats={}, params={}, t=np.array([0.0]), hull=None, tube=[])
        return {"solution": sol, "checked": 0, "escaped": 0, "paths": {}}
    monkeypatch.setattr(runner, "run_scene", interrupted_run)
    monkeypatch.setattr(runner, "final_widths", lambda sol: ("at t = 0.05", None))
    scene = tmp_path / "sweep.toml"
    scene.write_text(SWEEP)
    assert main(["simulate", str(scene), "--out", str(tmp_path / "o"), "--workers", "1"]) == 130
    assert calls == ["g_low"]
    assert "not run: g high" in capsys.readouterr().out


def test_cli_scenarios_on_a_cluster(tmp_path, client, monkeypatch, capsys):
    import json
    from mbs.app import runner
    from mbs.app.cli import main
    monkeypatch.setattr(runner, "scheduler_client", lambda address: client)
    scene = tmp_path / "sweep.toml"
    scene.write_text(SWEEP)
    assert main(["simulate", str(scene), "--out", str(tmp_path / "o"), "--samples", "4",
                 "--scheduler", "tcp://given"]) == 0
    data = json.loads((tmp_path / "o" / "scenarios.json").read_text())
    # 4 pieces per scenario: one chunk each (the default plan), on the given cluster
    assert data["status"] == "completed" and all(r["chunks"] == 1 for r in data["scenarios"])
    for r in data["scenarios"]:
        assert json.loads((tmp_path / "o" / r["result"]).read_text())["stats"]["backend"] == "dask"


def test_cli_bad_parallel_flags(tmp_path, monkeypatch, capsys):
    from mbs.app.cli import main
    scene = tmp_path / "s.toml"
    scene.write_text(SWEEP.split("[[scenarios]]")[0])
    assert main(["simulate", str(scene), "--out", str(tmp_path / "o"), "--workers", "0"]) == 2
    assert "--workers" in capsys.readouterr().err
    monkeypatch.setattr(cluster, "CONNECT_TIMEOUT", 1.0)
    assert main(["simulate", str(scene), "--out", str(tmp_path / "o"), "--scheduler", "tcp://127.0.0.1:9"]) == 2
    err = capsys.readouterr().err
    assert "tcp://127.0.0.1:9" in err and err.count("\n") == 1
    bad = tmp_path / "b.toml"
    bad.write_text(SWEEP + '\n[[scenarios]]\nname = "g low"\n')
    assert main(["simulate", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "unique" in capsys.readouterr().err


def test_ctrl_c_while_waiting_returns_what_is_verified(ode, box, client):
    """SIGINT while the workers run: the chunks are cancelled and the Solution says
    "interrupted" with everything verified (here: only t0, no chunk finished)."""
    timer = threading.Timer(1.0, lambda: os.kill(os.getpid(), signal.SIGINT))
    timer.start()
    sol = solve(ode, box, (0.0, T), subdivision=SUB, client=client, chunks=2, hooks=[SlowSteps(0.2)])
    timer.join()
    assert sol.status == "interrupted" and sol.t_reached == 0.0
    assert len(sol.t) == 1 and sol.boxes[0].shape == (16, 4) and not sol.tube


# ----------------------------------------------------------------------------- re-chunking
# pieces of the paper's box and pieces 10x wider (bench_parallel's mixed batch): adaptive
# splitting happens almost only in the wide chunk, which re-chunking cuts into new pieces
RT = 0.4
R_EVAL = [0.1, 0.25, RT]


@pytest.fixture(scope="module")
def mixed(box):
    from verified.arith.interval import concatenate
    lo, hi = np.asarray(box.lo, float), np.asarray(box.hi, float)
    c, r = 0.5 * (lo + hi), 0.5 * (hi - lo)
    wlo, whi = lo.copy(), hi.copy()
    wlo[0], whi[0] = c[0] - 10 * r[0], c[0] + 10 * r[0]
    return concatenate([box.subdivide([4, 1, 1, 1]).reshape(-1, 4),
                        Interval(wlo, whi).subdivide([4, 1, 1, 1]).reshape(-1, 4)], axis=0)


@pytest.fixture(scope="module")
def mixed_oracle(mixed):
    lo, hi = np.asarray(mixed.lo), np.asarray(mixed.hi)  # (only x1 is wide: points along it)
    x1 = np.unique(np.concatenate([np.linspace(lo[:, 0].min(), hi[:, 0].max(), 41), lo[:, 0], hi[:, 0]]))
    pts = np.repeat(lo[:1], x1.size, axis=0)
    pts[:, 0] = x1
    return trajectories(lambda x: dp.rhs(x), pts, RT)


@pytest.fixture(scope="module")
def mixed_plain(ode, mixed):
    return solve(ode, mixed, (0.0, RT), t_eval=R_EVAL, workers=1, chunks=2, adaptive=True, rechunk=False)


def _rechunked(ode, mixed, monkeypatch, **kw):
    monkeypatch.setattr(rechunk, "RECHUNK_MIN_SETS", 8)  # pieces of 8 sets (64 by default)
    kw.setdefault("workers", 1)
    return solve(ode, mixed, (0.0, RT), t_eval=R_EVAL, chunks=2, adaptive=True, **kw)


def _check_rechunked(sol, plain, oracle):
    assert sol.stats["rechunk"] and sol.stats["rechunks"] >= 2 and sol.stats["pieces"] > 2
    assert sol.status == plain.status == "completed" and sol.t_reached == plain.t_reached == RT
    np.testing.assert_array_equal(sol.t, plain.t)
    assert not misses(plain, oracle)
    assert not misses(sol, oracle)
    # the same enclosures up to step sizes and splitting (measured: 0.4-0.7% wider)
    w1, w2 = np.asarray(plain.hull[-1].width()), np.asarray(sol.hull[-1].width())
    assert np.all(np.abs(w2 / w1 - 1) < 0.03)


@pytest.mark.slow  # (with its fixtures ~5 s: the default run stays under its 3-minute budget)
def test_rechunked_run_contains_samples(ode, mixed, mixed_oracle, mixed_plain, monkeypatch):
    sol = _rechunked(ode, mixed, monkeypatch, rechunk=True)
    _check_rechunked(sol, mixed_plain, mixed_oracle)
    assert mixed_plain.stats["rechunks"] == 0 and mixed_plain.stats["pieces"] == 2
    wide = sol.chunks[1]["pieces"]  # the wide chunk was cut, its pieces start later from its sets
    assert len(wide) > 1 and wide[0]["parent"] is None and all(p["t_start"] > 0 for p in wide[1:])
    # the merged Solution stays complete: every output, the tube up to t_reached, the counters
    assert [b.shape[1] for b in sol.boxes] == [4] * len(R_EVAL + [0])
    assert sol.tube_t[0] == 0.0 and sol.tube_t[-1] == RT and np.all(np.diff(sol.tube_t) > 0)
    assert len(sol.tube) == sol.tube_t.size - 1 and all(tb.shape == (2, 4) for tb in sol.tube)
    assert sol.stats["steps"] == sum(p["steps"] for c in sol.chunks for p in (c["pieces"] or [c]))
    assert sol.stats["splits"] > 0 and sol.stats["final_boxes"] >= sol.boxes[-1].shape[0]


@pytest.mark.slow  # (with its fixtures ~5 s: the default run stays under its 3-minute budget)
def test_a_rechunking_that_drops_a_set_is_caught(ode, mixed, mixed_oracle, mixed_plain, monkeypatch):
    cut = rechunk._Pieces._cut

    def dropping(self, index, *args):  # the wide chunk's first cut loses one set of its first piece
        new = cut(self, index, *args)
        if self.items[index].family == 1 and not getattr(self, "dropped", False):
            # (in the narrow chunk the neighbours' hull boxes cover a dropped set; in the
            # wide one dropping set 1, 2, ... or 6 instead of 0 is caught too, set 7 is not)
            self.dropped = True
            p = self.items[new[0]]
            p.start.sets = p.start.sets.take(np.arange(1, p.start.sets.n_sets))
            p.lo, p.hi = p.lo[1:], p.hi[1:]
        return new
    monkeypatch.setattr(rechunk._Pieces, "_cut", dropping)
    sol = _rechunked(ode, mixed, monkeypatch, rechunk=True)
    with pytest.raises(AssertionError):
        _check_rechunked(sol, mixed_plain, mixed_oracle)
    assert misses(sol, mixed_oracle)  # (it is the containment that fails)


@pytest.mark.slow  # 4 s (default-run budget)
def test_rechunked_on_dask_contains_samples(ode, mixed, mixed_oracle, mixed_plain, client, monkeypatch):
    sol = _rechunked(ode, mixed, monkeypatch, client=client)  # rechunk=None: on with adaptive on Dask
    assert sol.stats["backend"] == "dask"
    _check_rechunked(sol, mixed_plain, mixed_oracle)
    assert sol.stats["received_bytes"] > 0


def test_resume_from_a_pause_continues_the_run(ode, box):
    for set_order in (1, 2):
        kw = dict(t_eval=[0.1, 0.2, T], subdivision=[4, 1, 1, 1], set_order=set_order, adaptive=True)
        full = solve(ode, box, (0.0, T), **kw)
        pause = exec_hooks._Pause(6)
        first = solve(ode, box, (0.0, T), hooks=[pause], **kw)
        st = pause.start
        assert first.status == "stopped" and st is not None and st.sets.n_sets >= 6
        kw.pop("subdivision")
        rest = solve(ode, st.sets.hull()[:, :4], (0.0, T), start=st, **kw)
        assert rest.t[0] == rest.tube_t[0] == first.t_reached == float(st.t_exact)
        assert rest.status == "completed" and rest.t_reached == T
        np.testing.assert_array_equal(np.concatenate([first.t, rest.t[1:]]), full.t)
        # (the split due after the step it paused at is decided again by the next run's
        # first step: not bit for bit the uninterrupted run; measured 0.3% apart)
        assert abs(first.stats["steps"] + rest.stats["steps"] - full.stats["steps"]) <= 2
        for a, b in zip(rest.hull[1:], full.hull[len(first.t):]):
            np.testing.assert_allclose(np.asarray(a.width()), np.asarray(b.width()), rtol=0.01)
    with pytest.raises(ValueError, match="start="):
        solve(ode, box, (0.0, T), start=st, chunks=2)
    with pytest.raises(ValueError, match="start.sets"):
        solve(ode, box, (0.0, T), start=st, set_order=1)
    with pytest.raises(ValueError, match="rechunk"):
        solve(ode, box, (0.0, T), chunks=2, rechunk="yes")


def test_warnings_point_at_the_callers_line(ode, box, monkeypatch):
    """A fallback warning is reported at the line that called solve, not inside the
    library (its depth differs by path: solve -> the method's solve -> solve_parallel
    -> the planner)."""
    monkeypatch.setattr(exec_run, "dask_available", lambda: False)
    with pytest.warns(RuntimeWarning, match="not installed") as record:
        solve(ode, box, (0.0, 0.05), subdivision=[4, 1, 1, 1], workers=2)
    assert [w.filename for w in record] == [__file__]


def test_a_client_connected_here_is_closed_when_the_plan_refuses(ode, box, monkeypatch):
    """client='address': the Client solve connects is closed even when the run is
    refused before it starts (a replay whose chunks do not cover the boxes)."""
    closed = []

    class FakeClient:
        def scheduler_info(self):
            return {"workers": {"a": {}, "b": {}}}

        def close(self):
            closed.append(True)
    monkeypatch.setattr(exec_run, "connect", lambda address: FakeClient())
    sol = solve(ode, box, (0.0, 0.05), subdivision=[4, 1, 1, 1], workers=1, chunks=2)
    with pytest.raises(ValueError, match="do not cover"):
        with exec_run.replaying(sol):
            solve(ode, box, (0.0, 0.05), subdivision=[8, 1, 1, 1], client="tcp://127.0.0.1:1")
    assert closed == [True]

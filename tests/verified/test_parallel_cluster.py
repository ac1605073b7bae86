"""client= against a Dask cluster of separate worker processes (issue 42 item 3).

The scheduler and each worker are their own processes started here with ``dask
scheduler`` / ``dask worker --no-nanny``, each worker in its own working and local
directory (as separate machines would have), not the local cluster of
verified.execution. A worker killed mid-run stays dead (no nanny brings it back): its
chunk is run again on the other worker and the result is the in-process result of the
same plan, float for float; when the last worker is gone the run ends with one clear
error instead of waiting for ever.
"""
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from models import double_pendulum as dp
from oracles.hooks import SlowSteps
from verified.execution import dask_run
from verified.graph import trace
from verified.arith.interval import Interval
from verified.solver import VerifiedODE, solve

distributed = pytest.importorskip("distributed")

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
T = 0.3
SUB = [16, 1, 1, 1]



def _spawn(cmd, cwd, env):
    return subprocess.Popen(cmd, cwd=cwd, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)


@pytest.fixture
def separate_cluster(tmp_path):
    """(client, {address: (pid, working directory)}) of a scheduler and two 1-thread
    workers, every one its own process; each worker in its own directory."""
    from distributed import Client

    # the workers import this module (the hook) and models/ like any other package
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(HERE), str(ROOT / "tests"), str(ROOT)]))
    sched = tmp_path / "scheduler.json"
    procs = [_spawn([sys.executable, "-m", "dask", "scheduler", "--host", "127.0.0.1", "--port", "0",
                     "--no-dashboard", "--scheduler-file", str(sched)], tmp_path, env)]
    client = None
    try:
        dirs = []
        for i in range(2):
            d = tmp_path / f"machine{i}"
            d.mkdir()
            dirs.append(d)
            procs.append(_spawn([sys.executable, "-m", "dask", "worker", "--scheduler-file", str(sched),
                                 "--nthreads", "1", "--no-nanny", "--local-directory", str(d / "dask"),
                                 "--name", f"machine{i}"], d, env))
        deadline = time.monotonic() + 60
        while not sched.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        client = Client(scheduler_file=str(sched), timeout=30, set_as_default=False)
        client.wait_for_workers(2, timeout=60)
        pids, cwds = client.run(os.getpid), client.run(os.getcwd)
        yield client, {a: (pids[a], cwds[a]) for a in pids}
    finally:
        if client is not None:
            client.close()
        for p in procs:
            if p.poll() is None:
                p.kill()
            p.wait()


def _kill_when_busy(client, pids, killed, key="verified-chunk"):
    """In a thread: SIGKILL the first worker seen running a chunk (once)."""
    def run():
        deadline = time.time() + 60
        while time.time() < deadline:
            busy = [w for w, keys in client.processing().items() if w in pids and any(key in str(k) for k in keys)]
            if busy:
                time.sleep(0.3)  # inside the chunk (its steps sleep)
                os.kill(pids[busy[0]], signal.SIGKILL)
                killed[busy[0]] = pids[busy[0]]
                return
            time.sleep(0.05)
    th = threading.Thread(target=run, daemon=True)
    th.start()
    return th


@pytest.mark.slow  # a scheduler and two workers started as processes, ~10-20 s on 2 cores
def test_separate_workers_lose_one_then_all(separate_cluster, monkeypatch):
    client, workers = separate_cluster
    assert len({cwd for _, cwd in workers.values()}) == 2  # each worker in its own directory
    ode = VerifiedODE(trace(dp.rhs, 4))
    lo, hi = dp.initial_box()
    box = Interval(lo, hi)
    kw = dict(t_eval=[0.1, 0.2, T], subdivision=SUB, chunks=4)
    ref = solve(ode, box, (0.0, T), workers=1, **kw)  # the same plan in this process
    # one worker killed mid-run: its chunk runs again on the other; the result is complete
    # and the in-process one, float for float
    killed = {}
    th = _kill_when_busy(client, {a: p for a, (p, _) in workers.items()}, killed)
    sol = solve(ode, box, (0.0, T), client=client, hooks=[SlowSteps(0.05)], **kw)
    th.join()
    assert killed, "no worker was busy"
    assert sol.stats["backend"] == "dask" and sol.status == "completed" and sol.t_reached == T
    assert all(c["status"] == "completed" for c in sol.chunks)
    assert list(killed.values())[0] not in [c["worker_pid"] for c in sol.chunks]
    np.testing.assert_array_equal(sol.t, ref.t)
    for a, b in zip(sol.boxes, ref.boxes):
        np.testing.assert_array_equal(a.lo, b.lo)
        np.testing.assert_array_equal(a.hi, b.hi)
    # the last worker killed mid-run: one clear error, not a hang
    monkeypatch.setattr(dask_run, "NO_WORKERS_TIMEOUT", 2.0)
    left = {a: p for a, (p, _) in workers.items() if a not in killed}
    killed2 = {}
    th = _kill_when_busy(client, left, killed2)
    t = time.monotonic()
    with pytest.raises(dask_run.WorkersLostError, match="every Dask worker left"):
        solve(ode, box, (0.0, T), client=client, hooks=[SlowSteps(0.05)], **kw)
    th.join()
    assert killed2 and time.monotonic() - t < 30

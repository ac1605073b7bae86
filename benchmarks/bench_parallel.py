"""Chunked execution (verified/execution/, issue 16): speed-up, per-chunk step sizes,
overhead, scaling, and a paper estimate for a 64-worker cluster.

    python benchmarks/bench_parallel.py                 # everything (~6 min on 2 cores)
    python benchmarks/bench_parallel.py --only speedup --repeat 2
    python benchmarks/bench_parallel.py --quick         # small sizes (smoke test)
    python benchmarks/bench_parallel.py --only first,model16 --repeat 2   # issue 42 (~6 min)
    python benchmarks/bench_parallel.py --only unequal --repeat 2         # issue 42 item 2 (~10 min)

Every timing is printed with the load averages of /proc/loadavg at that moment (other
jobs on the machine distort the ratios: read them next to the load). Sections:

speedup   double pendulum (trace(dp.rhs, 4), box dp.initial_box()), x1(0) in N pieces,
          T = 2: one in-process batch (``workers=1``) against the default from Python
          (``workers=None``: a local Dask cluster of every core, 1 thread each, here 2),
          interleaved, each pair --repeat times; worst ratio = max over states of
          width(x(T)) / width of the true hull (0.14254, 0.04562, 0.36946, 0.18162: bench_solver.
          true_hull_widths(2.0), 2001 DOP853 solutions at 1e-12)
mixed     per-chunk step sizes, one core: pieces of the paper's box together with pieces
          10x wider, T = 0.5: one batch (one step size for all) against the same boxes in
          two in-process chunks (narrow, wide)
overhead  16 pieces, T = 2 (break-down at 0.80 s) and T = 0.5 (short runs), warm local
          clusters, each call against the in-process batch (``workers=1``) measured just
          before it: the default ``workers=None`` (16 boxes: one in-process batch after
          the check), ``workers=2`` (the default plan: what a user gets), ``client=`` a cluster of 2
          with the default plan, and explicit ``chunks=1`` on a cluster of 1 and
          ``chunks=2`` on a cluster of 2 (what every call cost before the plan kept small
          batches in one chunk: Dask's own per-call cost)
rechunk   adaptive splitting concentrated in one chunk: 64 pieces of the paper's box and 64
          pieces 10x wider (the mixed batch), adaptive=True, T = 0.7, a local cluster of 2
          workers, default plan (2 chunks: narrow, wide): rechunk=False (the wide chunk keeps
          every set its splitting makes) against rechunk=True (a chunk that doubles its sets
          pauses and its sets become new chunks), interleaved; wall times, the pieces run, and
          the widths at T of the re-chunked run over the plain one (max and min over states)
start     cluster start, fresh each time: local_client(2) (worker interpreters started as
          ``python -m dask spec``, what workers=None / "auto" / 2 start) against
          ``LocalCluster(2)`` (spawned workers, the previous local cluster), each until
          every worker connected and then after prepare_worker ran in every worker
cluster   the speedup run on both warm local clusters of 2 workers, interleaved:
          local_client against LocalCluster (not in the default list)
first     issue 42: one fresh Python process per row (numba's on-disk cache warm, the
          main process's kernels loaded by a small in-process solve first, as a user's
          script that ran something before), double pendulum, N pieces, T = 2:
          ``workers=1`` (one in-process batch) against ``workers=W`` (a local cluster of
          W, started by that call: "first cluster"), then the same call again in the
          same process ("later cluster"), rows interleaved, --repeat times. Where the
          time of a cluster row went: cluster start, the first task's start (scheduler,
          transfer, imports, kernels loaded), the busiest worker's compute, workers idle
          at the end (imbalance), results arriving after the last chunk ended (transfer),
          merge. Then a model of 16 workers (see ``model16``)
model16   the 16-core numbers modelled from measured costs (issue 42 has no 16-core
          machine here): the same run in-process as 16 chunks one after the other
          (``workers=1, chunks=16``: each chunk's own wall time is what one of 16
          workers would compute, alone on its core, and the merge of 16 chunks is
          timed), plus the cluster start, first-task latency and result latency measured
          in ``first``. It is a model: no memory-bandwidth, turbo or SMT effects of 16
          busy cores
unequal   pieces of very unequal cost (issue 42 item 2; unequal_boxes: x3(0) from 0.43 to 10
          along the pieces, the fast-rotating ones take ~3x the steps), T = 2, a warm local
          cluster of 2: one in-process batch, the plain plan (rechunk=False: one chunk per
          worker) and the default (work stealing), the cluster rows alternated; per row the
          workers' busy time and their tasks' CPU per worker (the balance without the other
          jobs' load), idle at end, results after, merge, the cuts
model16so the issue's second-order target (128 pieces, T = 3, method="second_order"; 176 s on
          one core of the 16-core machine) modelled for 16 workers from one in-process batch
          and 16 in-process chunks of 8 pieces (not run; see section_model16so)
granular  chunk granularity on a warm local cluster of 2 (issue 42 item 2): the speedup run
          with chunks=2 (the default plan for 1024 boxes), 4 and 8, interleaved --repeat
          times: wall, workers idle at the end, the workers' busy time in all
scaling   local clusters of 1, 2, 4 workers (processes, 1 thread each) on the speedup run,
          and from the measured per-chunk costs and message sizes an estimate for 64
          workers and 65,536 pieces
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

import numpy as np


# true hull widths at T = 2: bench_solver.true_hull_widths(2.0) (2001 DOP853 solutions from
# x1(0) across the box, rtol = atol = 1e-12), rounded to 5 digits
TRUE_T2 = np.array([0.14254, 0.04562, 0.36946, 0.18162])


def load() -> str:
    with open("/proc/loadavg") as f:
        return "load " + " ".join(f.read().split()[:3])


def worst_ratio(sol, true=TRUE_T2):
    return float(np.max(np.asarray(sol.hull[-1].width(), float) / true))


def setup():
    from models import double_pendulum as dp
    from verified.graph import trace
    from verified.arith.interval import Interval
    from verified.solver import VerifiedODE
    lo, hi = dp.initial_box()
    return VerifiedODE(trace(dp.rhs, 4)), Interval(lo, hi)


def timed(fn):
    t = time.perf_counter()
    out = fn()
    return time.perf_counter() - t, out


def section_speedup(ode, box, pieces, T, repeat, log):
    from verified.execution.plan import default_workers
    from verified.execution.cluster import local_client
    from verified.solver import solve
    n = default_workers()
    log(f"\n## speedup: double pendulum, {pieces} pieces, T = {T}: workers=1 against the default (None: "
        f"{n} cores here)")
    t, _ = timed(lambda: local_client(n))
    log(f"local cluster of {n} workers started in {t:.1f} s (once per process; {load()})")
    solve(ode, box, (0, 0.05), subdivision=[pieces, 1, 1, 1])  # ship the graph, first steps
    rows = []
    for r in range(repeat):
        l1 = load()
        w1, s1 = timed(lambda: solve(ode, box, (0, T), subdivision=[pieces, 1, 1, 1], workers=1))
        l2 = load()
        w2, s2 = timed(lambda: solve(ode, box, (0, T), subdivision=[pieces, 1, 1, 1]))
        q1, q2 = (worst_ratio(s1), worst_ratio(s2)) if T == 2 else (np.nan, np.nan)
        rows.append(dict(run=r + 1, one_batch_s=w1, two_workers_s=w2, speedup=w1 / w2, ratio_1=q1, ratio_2=q2,
                         ratio_diff=abs(q2 / q1 - 1), status=(s1.status, s2.status), steps=(s1.stats["steps"],
                         s2.stats["chunk_steps"]), load_1=l1, load_2=l2, chunk_wall_s=s2.stats["chunk_wall_s"],
                         received_bytes=s2.stats["received_bytes"], sent_bytes=s2.stats["sent_bytes"]))
        log(f"run {r + 1}: one batch {w1:6.2f} s ({l1}) | default ({s2.stats['backend']}, "
            f"{s2.stats['workers']} workers) {w2:6.2f} s ({l2}) | speed-up {w1 / w2:.2f}x | "
            f"worst ratio {q1:.5f} / {q2:.5f} (diff {100 * abs(q2 / q1 - 1):.3f}%) | {s1.status}/{s2.status}, "
            f"steps {s1.stats['steps']} / chunks {s2.stats['chunk_steps']}, chunk walls "
            f"{', '.join(f'{x:.2f}' for x in s2.stats['chunk_wall_s'])} s")
    return rows


def mixed_boxes(box, n_each):
    from verified.arith.interval import Interval, concatenate
    lo, hi = np.asarray(box.lo, float), np.asarray(box.hi, float)
    narrow = box.subdivide([n_each, 1, 1, 1]).reshape(-1, 4)
    c, r = 0.5 * (lo + hi), 0.5 * (hi - lo)
    wlo, whi = lo.copy(), hi.copy()
    wlo[0], whi[0] = c[0] - 10 * r[0], c[0] + 10 * r[0]
    wide = Interval(wlo, whi).subdivide([n_each, 1, 1, 1]).reshape(-1, 4)  # each piece 10x wider
    return concatenate([narrow, wide], axis=0)


def section_mixed(ode, box, n_each, T, repeat, log):
    from verified.solver import solve
    boxes = mixed_boxes(box, n_each)
    log(f"\n## per-chunk step sizes: {n_each} pieces of the paper's box + {n_each} pieces 10x wider, T = {T}, "
        "one core")
    rows = []
    for r in range(repeat):
        l1 = load()
        w1, s1 = timed(lambda: solve(ode, boxes, (0, T), workers=1))
        l2 = load()
        w2, s2 = timed(lambda: solve(ode, boxes, (0, T), workers=1, chunks=2))
        wn = [np.asarray(s.hull[-1].width(), float) for s in (s1, s2)]
        rows.append(dict(run=r + 1, one_batch_s=w1, chunked_s=w2, drop=1 - w2 / w1, steps_batch=s1.stats["steps"],
                         chunk_steps=s2.stats["chunk_steps"], status=(s1.status, s2.status),
                         width_ratio=float(np.max(wn[1] / wn[0])), load_1=l1, load_2=l2))
        log(f"run {r + 1}: one batch {w1:6.2f} s, {s1.stats['steps']} steps ({l1}) | 2 chunks {w2:6.2f} s, steps "
            f"{s2.stats['chunk_steps']} ({l2}) | wall -{100 * (1 - w2 / w1):.0f}% | widths chunked/batch max "
            f"{np.max(wn[1] / wn[0]):.4f} | {s1.status}/{s2.status}")
    return rows


def section_rechunk(ode, box, n_each, T, repeat, log):
    from verified.execution.cluster import local_client
    from verified.solver import solve
    boxes = mixed_boxes(box, n_each)
    log(f"\n## re-chunking: {n_each} pieces of the paper's box + {n_each} pieces 10x wider, adaptive, T = {T}, "
        "2 workers (default plan: 2 chunks)")
    local_client(2)
    solve(ode, boxes, (0, 0.05), workers=2, adaptive=True)  # graph shipped, first steps
    rows = []
    for r in range(repeat):
        l1 = load()
        w1, s1 = timed(lambda: solve(ode, boxes, (0, T), workers=2, adaptive=True, rechunk=False))
        l2 = load()
        w2, s2 = timed(lambda: solve(ode, boxes, (0, T), workers=2, adaptive=True, rechunk=True))
        k = min(len(s1.t), len(s2.t)) - 1
        wr = np.asarray(s2.hull[k].width(), float) / np.asarray(s1.hull[k].width(), float)
        rows.append(dict(run=r + 1, plain_s=w1, rechunked_s=w2, speedup=w1 / w2, width_ratio_max=float(wr.max()),
                         width_ratio_min=float(wr.min()), status=(s1.status, s2.status),
                         t_reached=(s1.t_reached, s2.t_reached), final_sets=(s1.boxes[-1].shape[0],
                                                                              s2.boxes[-1].shape[0]),
                         splits=(s1.stats["splits"], s2.stats["splits"]), chunk_wall_s=s1.stats["chunk_wall_s"],
                         pieces=s2.stats["pieces"], rechunks=s2.stats["rechunks"],
                         piece_wall_s=[p["wall_s"] for c in s2.chunks for p in (c["pieces"] or [c])],
                         load_1=l1, load_2=l2))
        log(f"run {r + 1}: rechunk=False {w1:6.2f} s ({l1}), chunk walls "
            f"{', '.join(f'{x:.2f}' for x in s1.stats['chunk_wall_s'])} s | rechunk=True {w2:6.2f} s ({l2}), "
            f"{s2.stats['pieces']} pieces ({s2.stats['rechunks']} cuts) | speed-up {w1 / w2:.2f}x | widths at "
            f"t = {s1.t[k]:g} re-chunked/plain {wr.min():.4f}..{wr.max():.4f} | sets {s1.boxes[-1].shape[0]} / "
            f"{s2.boxes[-1].shape[0]}, splits {s1.stats['splits']} / {s2.stats['splits']} | "
            f"{s1.status} at {s1.t_reached:g} / {s2.status} at {s2.t_reached:g}")
    return rows


def section_overhead(ode, box, Ts, repeat, log):
    from verified.execution.cluster import local_client
    from verified.solver import solve
    sub = [16, 1, 1, 1]
    clients = {w: local_client(w) for w in (1, 2)}
    for w in (1, 2):
        solve(ode, box, (0, 0.05), subdivision=sub, client=clients[w], chunks=w)  # graph shipped, first steps
    solve(ode, box, (0, 0.05), subdivision=sub, workers=2)
    solve(ode, box, (0, 0.05), subdivision=sub)
    # (label, keyword arguments of the parallel call)
    cases = [("default (None)", dict()),
             ("workers=2", dict(workers=2)),
             ("client 2w, default plan", dict(client=clients[2])),
             ("client 1w, chunks=1", dict(client=clients[1], chunks=1)),
             ("client 2w, chunks=2", dict(client=clients[2], chunks=2))]
    rows = []
    for T in Ts:
        log(f"\n## overhead: 16 pieces, T = {T}, warm clusters (ratio = call / in-process batch just before it)")
        for r in range(repeat):
            out = dict(T=T, run=r + 1, load=load())
            msg = f"run {r + 1} ({out['load']})"
            for label, kw in cases:
                w0, s0 = timed(lambda: solve(ode, box, (0, T), subdivision=sub, workers=1))
                ww, sw = timed(lambda: solve(ode, box, (0, T), subdivision=sub, **kw))
                backend, chunks = sw.stats.get("backend", "inprocess"), sw.stats.get("chunks", 1)
                out[label] = dict(inprocess_s=w0, parallel_s=ww, ratio=ww / w0, backend=backend,
                                  chunks=chunks, setup_s=sw.stats.get("setup_s"),
                                  status=(s0.status, sw.status), t_reached=(s0.t_reached, sw.t_reached))
                msg += (f" | {label}: {1e3 * w0:.0f} / {1e3 * ww:.0f} ms = {ww / w0:.2f}x "
                        f"({backend}, {chunks} chunk{'s' if chunks > 1 else ''})")
            rows.append(out)
            log(msg + f" | {s0.status} at {s0.t_reached:.3f} / {sw.status} at {sw.t_reached:.3f}")
        for label, _ in cases:
            q = [x[label]["ratio"] for x in rows if x["T"] == T]
            log(f"T = {T}, {label}: ratio median {np.median(q):.2f}x (min {min(q):.2f}x, max {max(q):.2f}x)")
    return rows


def section_start(repeat, log, workers=2):
    """Fresh local clusters: local_client (worker interpreters) against LocalCluster
    (spawned workers; this script has the main guard), until every worker connected,
    then after prepare_worker ran in each (what local_client returns after)."""
    from distributed import Client, LocalCluster

    from verified.execution import cluster
    from verified.execution import run as exec_run
    from verified.execution import worker
    log(f"\n## cluster start: {workers} workers, fresh each time")
    rows = []
    for r in range(repeat):
        cluster.close_local_clients()
        l1 = load()
        t = time.perf_counter()
        cluster, client = cluster.start_local_cluster(workers)
        t_up = time.perf_counter() - t
        client.run(worker.prepare_worker)
        t_warm = time.perf_counter() - t
        client.close()
        cluster.close()
        l2 = load()
        t = time.perf_counter()
        lc = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0",
                          silence_logs=50)
        lcl = Client(lc, set_as_default=False)
        lcl.wait_for_workers(workers)
        l_up = time.perf_counter() - t
        lcl.run(worker.prepare_worker)
        l_warm = time.perf_counter() - t
        lcl.close()
        lc.close()
        rows.append(dict(run=r + 1, subprocess_up_s=t_up, subprocess_warm_s=t_warm, localcluster_up_s=l_up,
                         localcluster_warm_s=l_warm, load_1=l1, load_2=l2))
        log(f"run {r + 1}: local_client workers up {t_up:.2f} s, warm {t_warm:.2f} s ({l1}) | LocalCluster up "
            f"{l_up:.2f} s, warm {l_warm:.2f} s ({l2})")
    return rows


def section_cluster(ode, box, pieces, T, repeat, log, workers=2):
    """The same chunked run on both local clusters, interleaved: local_client (worker
    interpreters under nannies) against LocalCluster (spawned workers), warm."""
    from distributed import Client, LocalCluster

    from verified.execution import cluster
    from verified.execution import run as exec_run
    from verified.execution import worker
    from verified.solver import solve
    log(f"\n## cluster: {pieces} pieces, T = {T}, {workers} workers: local_client against LocalCluster, warm")
    ours = cluster.local_client(workers)
    lc = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0",
                      silence_logs=50)
    theirs = Client(lc, set_as_default=False)
    theirs.wait_for_workers(workers)
    theirs.run(worker.prepare_worker)
    sub = [pieces, 1, 1, 1]
    for c in (ours, theirs):
        solve(ode, box, (0, 0.05), subdivision=sub, client=c)  # graph shipped, first steps
    rows = []
    try:
        for r in range(repeat):
            l1 = load()
            w1, s1 = timed(lambda: solve(ode, box, (0, T), subdivision=sub, client=ours))
            l2 = load()
            w2, s2 = timed(lambda: solve(ode, box, (0, T), subdivision=sub, client=theirs))
            rows.append(dict(run=r + 1, local_client_s=w1, localcluster_s=w2, ratio=w1 / w2,
                             chunk_wall_s=(s1.stats["chunk_wall_s"], s2.stats["chunk_wall_s"]),
                             status=(s1.status, s2.status), load_1=l1, load_2=l2))
            log(f"run {r + 1}: local_client {w1:6.2f} s ({l1}), chunk walls "
                f"{', '.join(f'{x:.2f}' for x in s1.stats['chunk_wall_s'])} s | LocalCluster {w2:6.2f} s ({l2}), "
                f"chunk walls {', '.join(f'{x:.2f}' for x in s2.stats['chunk_wall_s'])} s | ratio {w1 / w2:.2f} | "
                f"{s1.status}/{s2.status}")
    finally:
        theirs.close()
        lc.close()
    return rows


def section_scaling(ode, box, pieces, T, log, workers=(1, 2, 4)):
    from verified.execution.cluster import close_local_clients, local_client
    from verified.solver import solve
    log(f"\n## scaling: {pieces} pieces, T = {T}, local clusters of 1-thread processes")
    rows = []
    for w in workers:
        close_local_clients()
        tc, client = timed(lambda: local_client(w))
        solve(ode, box, (0, 0.05), subdivision=[pieces, 1, 1, 1], client=client)  # graph shipped, first steps
        lw = load()
        ww, sw = timed(lambda: solve(ode, box, (0, T), subdivision=[pieces, 1, 1, 1], client=client))
        rows.append(dict(workers=w, wall_s=ww, cluster_start_s=tc, chunks=sw.stats["chunks"],
                         chunk_wall_s=sw.stats["chunk_wall_s"], chunk_steps=sw.stats["chunk_steps"],
                         received_bytes=sw.stats["received_bytes"], sent_bytes=sw.stats["sent_bytes"],
                         setup_s=sw.stats.get("setup_s"), load=lw, status=sw.status,
                         ratio=worst_ratio(sw) if T == 2 else None))
        log(f"{w} worker(s): {ww:6.2f} s ({lw}), {sw.stats['chunks']} chunks, chunk walls "
            f"{', '.join(f'{x:.2f}' for x in sw.stats['chunk_wall_s'])} s, cluster start {tc:.1f} s, "
            f"sent {sw.stats['sent_bytes'] / 1e3:.0f} kB, received {sw.stats['received_bytes'] / 1e6:.1f} MB, "
            f"{sw.status}")
    close_local_clients()
    return rows


def _child_first(spec: str) -> int:
    """One row of ``first`` in this (fresh) process: prints one JSON line."""
    workers, pieces, T = spec.split(",")
    workers, pieces, T = int(workers), int(pieces), float(T)
    t = time.perf_counter()
    ode, box = setup()
    from verified.solver import solve
    t_import = time.perf_counter() - t
    t = time.perf_counter()
    solve(ode, box, (0, 0.05), subdivision=[4, 1, 1, 1], workers=1)  # this process's kernels (disk cache)
    t_main_warm = time.perf_counter() - t
    out = dict(workers=workers, pieces=pieces, T=T, import_s=t_import, main_warm_s=t_main_warm, calls=[])
    for call in ("first", "later"):
        ld = load()
        w, sol = timed(lambda: solve(ode, box, (0, T), subdivision=[pieces, 1, 1, 1], workers=workers))
        st = sol.stats
        out["calls"].append(dict(call=call, wall_s=w, load=ld, status=sol.status, backend=st.get("backend"),
                                 chunks=st.get("chunks", 1), widths=np.asarray(sol.hull[-1].width(), float).tolist(),
                                 cluster_start_s=st.get("cluster_start_s"), setup_s=st.get("setup_s"),
                                 warm_s=st.get("warm_s"), merge_s=st.get("merge_s"), timeline=st.get("timeline"),
                                 chunk_wall_s=st.get("chunk_wall_s"), received_bytes=st.get("received_bytes")))
    print("CHILD " + json.dumps(out, default=float), flush=True)
    return 0


def breakdown(call: dict, workers: int) -> dict:
    """Where a cluster call's wall time went (from its timeline; seconds)."""
    tl = call.get("timeline") or []
    if not tl:
        return {}
    start = call.get("cluster_start_s") or 0.0
    first_task = min(r["start_s"] for r in tl)
    busy, last = {}, {}
    for r in tl:
        busy[r["worker_pid"]] = busy.get(r["worker_pid"], 0.0) + r["end_s"] - r["start_s"]
        last[r["worker_pid"]] = max(last.get(r["worker_pid"], 0.0), r["end_s"])
    compute_end = max(r["end_s"] for r in tl)
    ends = list(last.values()) + [first_task] * (workers - len(last))  # (a worker without a chunk idles)
    return dict(cluster_start_s=start, to_first_task_s=first_task - start, busiest_s=max(busy.values()),
                busy_total_s=sum(busy.values()), idle_at_end_s=float(np.mean([compute_end - e for e in ends])),
                results_after_s=max(r["received_s"] for r in tl) - compute_end, merge_s=call.get("merge_s") or 0.0)


def section_first(pieces, T, repeat, log, workers=2):
    import subprocess
    log(f"\n## first run (issue 42): {pieces} pieces, T = {T}, fresh process per row: workers=1 against "
        f"workers={workers} (first cluster of the process, then a later call on it)")
    rows = []
    for r in range(repeat):
        for w in (1, workers):
            cmd = [sys.executable, os.path.abspath(__file__), "--child-first", f"{w},{pieces},{T}"]
            t = time.perf_counter()
            p = subprocess.run(cmd, capture_output=True, text=True)
            proc_s = time.perf_counter() - t
            line = [x for x in p.stdout.splitlines() if x.startswith("CHILD ")]
            if p.returncode or not line:
                log(f"child failed ({p.returncode}): {p.stderr[-2000:]}")
                continue
            out = json.loads(line[-1][6:])
            out.update(run=r + 1, process_s=proc_s)
            rows.append(out)
    one = {x["run"]: x for x in rows if x["workers"] == 1}
    log("| run | workers | call | wall s | speed-up over 1 | load | cluster start | to 1st task | busiest worker "
        "| idle at end | results after | merge |")
    log("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for x in rows:
        for c in x["calls"]:
            ref = one.get(x["run"])
            base = ref["calls"][0]["wall_s"] if ref else math.nan
            b = breakdown(c, x["workers"]) if x["workers"] > 1 else {}
            c["breakdown"] = b
            f = (lambda k: f"{b[k]:.2f}" if k in b else "-")
            log(f"| {x['run']} | {x['workers']} | {c['call']} | {c['wall_s']:.2f} | {base / c['wall_s']:.2f} | "
                f"{c['load']} | {f('cluster_start_s')} | {f('to_first_task_s')} | {f('busiest_s')} | "
                f"{f('idle_at_end_s')} | {f('results_after_s')} | {f('merge_s')} |")
    for x in rows:
        if x["workers"] > 1 and x["run"] in one:
            a = np.asarray(one[x["run"]]["calls"][0]["widths"])
            for c in x["calls"]:
                c["width_rel_diff"] = float(np.max(np.abs(np.asarray(c["widths"]) / a - 1)))
    log("widths at T, cluster rows against workers=1 (max relative difference): "
        + ", ".join(f"{c['width_rel_diff']:.1e}" for x in rows for c in x["calls"] if "width_rel_diff" in c))
    log("(each row's process: import " + ", ".join(f"{x['import_s']:.1f}" for x in rows) + " s; main process's "
        "kernels loaded in " + ", ".join(f"{x['main_warm_s']:.1f}" for x in rows) + " s)")
    return rows


def unequal_boxes(box, n, x3_max=10.0):
    """Pieces of very unequal cost (issue 42 item 2): n pieces, each as narrow in x1 as
    one of 65536 pieces of the paper's box (the first n of them), with the start rate x3 a
    point value from the paper's 0.43 up to ``x3_max`` along the pieces: from about 3.2
    on the first link starts with enough energy to pass over the top (beyond the
    separatrix) and the pendulum rotates, faster the higher x3, and the steps shorten
    with it: 110 steps to T = 2 at x3 = 0.43, 135 at 4, 226 at 6, 346 at 10 (one piece
    alone). Neighbouring pieces cost alike (contiguous chunks). Pieces as wide as one of
    1024 break down near the separatrix and beyond (their steps shorten only in the
    last few % of the run, just before)."""
    from verified.arith.interval import Interval
    lo, hi = np.asarray(box.lo, float), np.asarray(box.hi, float)
    w = (hi[0] - lo[0]) / 65536
    L, H = np.repeat(lo[None], n, 0), np.repeat(hi[None], n, 0)
    k = np.arange(n) % 65536
    L[:, 0], H[:, 0] = lo[0] + k * w, lo[0] + (k + 1) * w
    L[:, 2] = H[:, 2] = np.linspace(0.43, x3_max, n)
    return Interval(L, H)


def busy(sol) -> dict:
    """From a cluster call's timeline: the workers' busy time and CPU in all, the
    busiest worker's busy time, the mean time a worker idled after its last piece."""
    tl = sol.stats.get("timeline") or []
    if not tl:
        return {}
    per, last, cpu, work = {}, {}, {}, {}
    for r in tl:
        per[r["worker_pid"]] = per.get(r["worker_pid"], 0.0) + r["end_s"] - r["start_s"]
        cpu[r["worker_pid"]] = cpu.get(r["worker_pid"], 0.0) + r["cpu_s"]
        # (box-steps: steps x sets, the work whatever the load; not adaptive runs' grown sets)
        work[r["worker_pid"]] = work.get(r["worker_pid"], 0) + (r.get("steps") or 0) * r.get("sets", 0)
        last[r["worker_pid"]] = max(last.get(r["worker_pid"], 0.0), r["end_s"])
    end = max(last.values())
    # (cpu_busiest_s: the largest CPU time one worker spent on its pieces, what its busy
    # wall would be on an idle core: the balance measured without the other jobs' load)
    return dict(busy_total_s=sum(per.values()), cpu_total_s=float(np.nansum([r["cpu_s"] for r in tl])),
                cpu_busiest_s=max(cpu.values()), cpu_per_worker_s=sorted(cpu.values()),
                box_steps_per_worker=sorted(work.values()),
                busiest_s=max(per.values()), idle_at_end_s=float(np.mean([end - e for e in last.values()])),
                first_task_s=min(r["start_s"] for r in tl), results_after_s=max(r["received_s"] for r in tl) - end)


def section_unequal(ode, box, pieces, T, repeat, log, workers=2, x3_max=10.0):
    """Pieces of very unequal cost on a warm local cluster: the plain plan without work
    stealing (rechunk=False: one chunk per worker) against the default (a lagging piece
    paused and cut for the free worker), interleaved; for reference one in-process batch
    (one core) and the same pieces as 16 in-process chunks (each chunk's own steps: what
    an ideal cost-based plan could start from)."""
    from verified.execution.cluster import local_client
    from verified.solver import solve
    boxes = unequal_boxes(box, pieces, x3_max)
    log(f"\n## unequal cost: {pieces} pieces, x3(0) from 0.43 to {x3_max} along the pieces, T = {T}, warm local "
        f"cluster of {workers}")
    client = local_client(workers)
    solve(ode, boxes[:workers * 2], (0, 0.05), client=client, chunks=workers)  # graph shipped, first steps
    c0 = time.process_time()
    t, ref = timed(lambda: solve(ode, boxes, (0, T), workers=1, chunks=16))
    ref_cpu = time.process_time() - c0
    log(f"reference, 16 in-process chunks: {t:.2f} s, CPU {ref_cpu:.1f} s ({load()}); chunk steps {ref.stats['chunk_steps']}, "
        f"chunk walls {', '.join(f'{x:.2f}' for x in ref.stats['chunk_wall_s'])} s; {ref.status} at "
        f"{ref.t_reached:g}")
    rows = []
    for r in range(repeat):
        out = dict(run=r + 1)
        cases = [("one batch (1 core)", dict(workers=1)), ("plain plan", dict(client=client, rechunk=False)),
                 ("stealing", dict(client=client))]
        if r % 2:  # (alternate the order of the two cluster rows)
            cases = [cases[0], cases[2], cases[1]]
        for label, kw in cases:
            ld = load()
            c0 = time.process_time()
            w, sol = timed(lambda: solve(ode, boxes, (0, T), **kw))
            cpu_here = time.process_time() - c0
            b = busy(sol)
            out[label] = dict(wall_s=w, load=ld, cpu_here_s=cpu_here, status=sol.status, t_reached=sol.t_reached,
                              widths=np.asarray(sol.hull[-1].width(), float).tolist(), pieces=sol.stats.get("pieces"),
                              cuts=sol.stats.get("cuts"), chunk_steps=sol.stats.get("chunk_steps"),
                              merge_s=sol.stats.get("merge_s"), stitch_s=sol.stats.get("stitch_s"),
                              timeline=sol.stats.get("timeline"), **b)
            extra = ""
            if b:
                extra = (f" | busy {b['busy_total_s']:.1f} s (CPU {b['cpu_total_s']:.1f} s; per worker "
                         f"{', '.join(f'{x:.1f}' for x in b['cpu_per_worker_s'])} s; box-steps per worker "
                         f"{', '.join(str(x) for x in b['box_steps_per_worker'])}), busiest "
                         f"{b['busiest_s']:.1f} s, idle at end {b['idle_at_end_s']:.2f} s, results after "
                         f"{b['results_after_s']:.2f} s, merge {sol.stats['merge_s']:.3f} s (+ stitched during "
                         f"the run {sol.stats['stitch_s']:.3f} s), pieces {sol.stats['pieces']}, cuts "
                         + ", ".join(f"{c['why']}@t={c['t']:.2f}:{c['sets']}->{c['k']}" for c in sol.stats["cuts"]))
            log(f"run {r + 1}, {label}: {w:6.2f} s ({ld}), CPU here {cpu_here:.1f} s, {sol.status} at "
                f"{sol.t_reached:g}{extra}")
        a = np.asarray(out["plain plan"]["widths"])
        for label in ("one batch (1 core)", "stealing"):
            out[label]["width_vs_plain"] = float(np.max(np.abs(np.asarray(out[label]["widths"]) / a - 1)))
        log(f"run {r + 1}: stealing {out['plain plan']['wall_s'] / out['stealing']['wall_s']:.2f}x the plain plan, "
            f"{out['one batch (1 core)']['wall_s'] / out['stealing']['wall_s']:.2f}x one core; widths at T against "
            f"the plain plan: stealing {out['stealing']['width_vs_plain']:.1e}, one batch "
            f"{out['one batch (1 core)']['width_vs_plain']:.1e}")
        rows.append(out)
    return dict(reference=dict(wall_s=t, cpu_s=ref_cpu, chunk_steps=ref.stats["chunk_steps"],
                               chunk_wall_s=ref.stats["chunk_wall_s"]), rows=rows)


def section_granular(ode, box, pieces, T, repeat, log, workers=2, plans=(2, 4, 8)):
    from verified.execution.cluster import local_client
    from verified.solver import solve
    log(f"\n## chunk granularity: {pieces} pieces, T = {T}, warm local cluster of {workers}, chunks = {plans}")
    client = local_client(workers)
    solve(ode, box, (0, 0.05), subdivision=[pieces, 1, 1, 1], client=client)  # graph shipped, first steps
    rows = []
    for r in range(repeat):
        for c in plans:
            ld = load()
            w, sol = timed(lambda: solve(ode, box, (0, T), subdivision=[pieces, 1, 1, 1], client=client, chunks=c))
            b = breakdown(dict(timeline=sol.stats["timeline"], merge_s=sol.stats["merge_s"]), workers)
            rows.append(dict(run=r + 1, chunks=c, wall_s=w, load=ld, **b))
            log(f"run {r + 1}, chunks={c}: {w:6.2f} s ({ld}) | idle at end {b['idle_at_end_s']:.2f} s | busy in all "
                f"{b['busy_total_s']:.1f} s | busiest {b['busiest_s']:.1f} s")
    return rows


def slowest_share(sol, cpu_s) -> float:
    """The slowest chunk of an in-process chunked run on an idle core: the run's CPU
    seconds times that chunk's share of the box-steps (steps x boxes). Single chunks'
    walls carry the other jobs' load (16 chunks of equal steps measured 2.27..10.54 s)."""
    w = np.array([(s or 0) * (b - a) for s, (a, b) in zip(sol.stats["chunk_steps"], [c["boxes"] for c in sol.chunks])],
                 float)
    return float(cpu_s * w.max() / w.sum())


def section_model16(ode, box, pieces, T, first_rows, log, workers=16):
    """16 workers modelled from this machine's measured costs (see the module docstring)."""
    from verified.solver import solve
    log(f"\n## model of {workers} workers (MODELLED from measured costs, not run): {pieces} pieces, T = {T}")
    ld = load()
    c0 = time.process_time()
    w1, _ = timed(lambda: solve(ode, box, (0, T), subdivision=[pieces, 1, 1, 1], workers=1))
    cpu1 = time.process_time() - c0  # (one core, idle: the reference of the speed-ups)
    c0 = time.process_time()
    w, sol = timed(lambda: solve(ode, box, (0, T), subdivision=[pieces, 1, 1, 1], workers=1, chunks=workers))
    cpu16 = time.process_time() - c0
    cw = np.asarray(sol.stats["chunk_wall_s"], float)
    slow_cpu = slowest_share(sol, cpu16)
    merge = float(sol.stats["merge_s"])
    firsts = [c for x in first_rows if x["workers"] > 1 for c in x["calls"] if c.get("breakdown")]
    t1 = cpu1  # (the one batch's CPU here: what one idle core takes; the 'first' rows' walls carry the load)
    if firsts:
        med = (lambda key, call: float(np.median([c["breakdown"][key] for c in firsts if c["call"] == call]))
               if any(c["call"] == call for c in firsts) else 0.0)
        start, lat_first, lat_later = med("cluster_start_s", "first"), med("to_first_task_s", "first"), \
            med("to_first_task_s", "later")
        res = max(med("results_after_s", "first"), med("results_after_s", "later"))
    else:  # (measured earlier: MEASURED_CLUSTER)
        m = MEASURED_CLUSTER
        start, lat_first, lat_later, res = (m["cluster_start_s"], m["to_first_task_first_s"],
                                            m["to_first_task_later_s"], m["results_after_s"])
    model_first = start + lat_first + slow_cpu + res + merge
    model_later = lat_later + slow_cpu + res + merge
    log(f"measured here ({ld}): one batch of {pieces} {w1:.1f} s, {cpu1:.1f} s CPU; 16 chunks in-process {w:.1f} s "
        f"in all, {cpu16:.1f} s CPU (+{100 * (cpu16 / cpu1 - 1):.0f} %); chunk walls {cw.min():.2f}..{cw.max():.2f} s (mean {cw.mean():.2f}), steps "
        f"{sol.stats['chunk_steps']}; slowest chunk by its share of the CPU in box-steps {slow_cpu:.2f} s; merge of "
        f"16 chunks {merge:.2f} s; from "
        f"'first': cluster start {start:.2f} s, to the first task {lat_first:.2f} s (first cluster) / "
        f"{lat_later:.2f} s (later), results after the last chunk {res:.2f} s")
    log(f"model, first cluster: start + to first task + slowest chunk + results + merge = {model_first:.1f} s "
        f"-> {t1 / model_first:.1f}x one core; later cluster: {model_later:.1f} s -> {t1 / model_later:.1f}x "
        f"(assumes 16 idle cores as fast as one of these, each worker's start and kernel load in parallel)")
    return dict(inprocess_16_chunks_s=w, inprocess_16_chunks_cpu_s=cpu16, slowest_cpu_s=slow_cpu, one_batch_s=w1,
                one_batch_cpu_s=cpu1,
                chunk_wall_s=cw.tolist(), chunk_steps=sol.stats["chunk_steps"], merge_s=merge,
                cluster_start_s=start, to_first_task_first_s=lat_first, to_first_task_later_s=lat_later,
                results_after_s=res, model_first_s=model_first, model_later_s=model_later,
                speedup_first=t1 / model_first, speedup_later=t1 / model_later, load=ld)


#: cluster costs measured on the 2-core machine (docs/lab/exec_run.md: the 'first' row of
#: 2026-11-28 18:18 UTC with work stealing, --only first --repeat 1), used by model16 and
#: model16so when 'first' did not run in the same call
MEASURED_CLUSTER = dict(cluster_start_s=3.82, to_first_task_first_s=0.74, to_first_task_later_s=0.03,
                        results_after_s=0.03)


def section_model16so(box, log, pieces=128, T=3.0, workers=16, first_rows=None, issue_one_core_s=176.0):
    """The issue's second-order target modelled for 16 workers (not run): double pendulum,
    ``method="second_order"``, 128 pieces, T = 3. Measured here: one in-process batch
    (one core) and the same pieces as 16 in-process chunks of 8 (each chunk's own wall
    and the CPU of all: what each of 16 workers would compute alone; 8 boxes a chunk
    pay the fixed cost of a step 16 times), the merge of 16 chunks. Model as model16:
    cluster start + first task + slowest chunk + results + merge, each chunk scaled to
    the issue's machine by its one-core time (``issue_one_core_s``) over ours."""
    from models import double_pendulum as dp
    from verified.graph import trace
    from verified.solver import solve
    g = trace(dp.rhs, 4)
    kw = dict(method="second_order", subdivision=[pieces, 1, 1, 1])
    log(f"\n## model of {workers} workers, second-order sets (MODELLED, not run): {pieces} pieces, T = {T}")
    solve(g, box, (0, 0.05), workers=1, **kw)  # this process's kernels
    ld1 = load()
    c0 = time.process_time()
    w1, one = timed(lambda: solve(g, box, (0, T), workers=1, **kw))
    c1 = time.process_time() - c0
    ld16 = load()
    c0 = time.process_time()
    w16, sol = timed(lambda: solve(g, box, (0, T), workers=1, chunks=workers, **kw))
    c16 = time.process_time() - c0
    cw = np.asarray(sol.stats["chunk_wall_s"], float)
    merge = float(sol.stats["merge_s"])
    cost = dict(MEASURED_CLUSTER)
    firsts = [c for x in (first_rows or []) if x["workers"] > 1 for c in x["calls"] if c.get("breakdown")]
    if firsts:
        med = (lambda key, call: float(np.median([c["breakdown"][key] for c in firsts if c["call"] == call])))
        cost = dict(cluster_start_s=med("cluster_start_s", "first"), to_first_task_first_s=med("to_first_task_s", "first"),
                    to_first_task_later_s=med("to_first_task_s", "later"),
                    results_after_s=max(med("results_after_s", "first"), med("results_after_s", "later")))
    # the slowest chunk on an idle core (its share of the CPU), then on the issue's machine
    slow_cpu = slowest_share(sol, c16)
    scale = issue_one_core_s / c1
    tail = cost["results_after_s"] + merge
    m_first = cost["cluster_start_s"] + cost["to_first_task_first_s"] + slow_cpu * scale + tail
    m_later = cost["to_first_task_later_s"] + slow_cpu * scale + tail
    ratios = [r for r in (one.stats.get("steps"),) if r]
    log(f"measured here: one batch {w1:.1f} s wall, {c1:.1f} s CPU ({ld1}), {one.status} at {one.t_reached:g}, "
        f"steps {ratios}; 16 chunks {w16:.1f} s wall, {c16:.1f} s CPU ({ld16}) (+{100 * (c16 / c1 - 1):.0f} % CPU: "
        f"the fixed cost per step and chunk), chunk walls {cw.min():.2f}..{cw.max():.2f} s (mean {cw.mean():.2f}), "
        f"steps {sol.stats['chunk_steps']}, merge {merge:.3f} s")
    log(f"model on the issue's machine (one core {issue_one_core_s:.0f} s = {scale:.2f}x ours): slowest chunk "
        f"{slow_cpu * scale:.1f} s; first cluster {m_first:.1f} s -> {issue_one_core_s / m_first:.1f}x, later cluster "
        f"{m_later:.1f} s -> {issue_one_core_s / m_later:.1f}x (target >= 10x); cluster costs {cost}")
    return dict(one_batch_s=w1, one_batch_cpu_s=c1, chunks16_s=w16, chunks16_cpu_s=c16, chunk_wall_s=cw.tolist(),
                chunk_steps=sol.stats["chunk_steps"], merge_s=merge, cluster=cost, scale=scale,
                slowest_cpu_s=slow_cpu, model_first_s=m_first, model_later_s=m_later,
                speedup_first=issue_one_core_s / m_first, speedup_later=issue_one_core_s / m_later,
                status=(one.status, sol.status), load=(ld1, ld16))


def estimate(scaling, pieces, log, target_pieces=65536, target_workers=64, bandwidth=100e6, task_overhead=0.005):
    """A paper estimate for ``target_workers`` workers on ``target_pieces`` pieces from the
    measured per-chunk costs: a chunk of the planned size costs what the measured chunk
    nearest in size cost (scaled linearly in boxes), every chunk the same number of steps
    (pieces 64x narrower take no more steps: the step size is set by the order-K term,
    not the width); the chunk results (outputs and the tube of every step) go to the
    client at ``bandwidth`` bytes/s; ``task_overhead`` s of scheduling per chunk."""
    from verified.execution.plan import plan_chunks
    ranges = plan_chunks(target_pieces, target_workers)
    per_chunk = target_pieces / len(ranges)
    best = min(scaling, key=lambda r: abs(pieces / r["chunks"] - per_chunk))
    size = pieces / best["chunks"]
    chunk_s = float(np.mean(best["chunk_wall_s"])) * per_chunk / size
    rounds = int(np.ceil(len(ranges) / target_workers))
    bytes_per_box = float(np.mean([r["received_bytes"] / pieces for r in scaling]))
    recv = bytes_per_box * target_pieces
    compute = rounds * chunk_s + len(ranges) * task_overhead / target_workers
    total = compute + recv / bandwidth
    one = min(scaling, key=lambda r: r["workers"])
    one_core = float(one["wall_s"]) * target_pieces / pieces
    log(f"\n## estimate: {target_workers} workers, {target_pieces} pieces (paper)")
    log(f"measured: chunks of {size:.0f} boxes cost {np.mean(best['chunk_wall_s']):.2f} s each "
        f"({best['workers']} workers); {bytes_per_box / 1e3:.1f} kB of result per box")
    log(f"plan: {len(ranges)} chunks of {per_chunk:.0f} boxes, {rounds} per worker: {rounds} x {chunk_s:.1f} s "
        f"+ scheduling {len(ranges)} x {1e3 * task_overhead:.0f} ms / {target_workers} = {compute:.1f} s compute")
    log(f"results: {recv / 1e9:.2f} GB to the client = {recv / bandwidth:.1f} s at {bandwidth / 1e6:.0f} MB/s "
        f"(the per-chunk tubes; hulls only would be ~{len(ranges)}x smaller); total ~{total:.0f} s against "
        f"~{one_core:.0f} s (~{one_core / 3600:.1f} h) on one core ({one['workers']} worker scaled by pieces): "
        f"{one_core / total:.0f}x")
    return dict(chunks=len(ranges), chunk_boxes=per_chunk, chunk_s=chunk_s, rounds=rounds, compute_s=compute,
                received_gb=recv / 1e9, transfer_s=recv / bandwidth, total_s=total, one_core_s=one_core)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--only", default="speedup,mixed,rechunk,overhead,start,scaling")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--quick", action="store_true", help="small sizes (smoke test)")
    ap.add_argument("--json", default=None, help="write the measurements here")
    ap.add_argument("--pieces", type=int, default=None, help="pieces of the speedup/first/model16 runs")
    ap.add_argument("--child-first", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child_first:
        return _child_first(args.child_first)
    only = set(args.only.split(","))
    pieces, T = (64, 0.5) if args.quick else (1024, 2.0)
    if args.pieces:
        pieces = args.pieces
    n_mixed, t_mixed = (16, 0.3) if args.quick else (128, 0.5)
    n_rechunk, t_rechunk = (64, 0.5) if args.quick else (64, 0.7)
    log = print
    log(f"bench_parallel: {os.cpu_count()} CPUs, {load()}, {time.strftime('%H:%M:%S UTC', time.gmtime())}")
    ode, box = setup()
    from verified.solver import solve
    solve(ode, box, (0, 0.05), subdivision=[4, 1, 1, 1])  # numba caches of this process
    res = {}
    if "speedup" in only:
        res["speedup"] = section_speedup(ode, box, pieces, T, args.repeat, log)
    if "mixed" in only:
        res["mixed"] = section_mixed(ode, box, n_mixed, t_mixed, args.repeat, log)
    if "rechunk" in only:
        res["rechunk"] = section_rechunk(ode, box, n_rechunk, t_rechunk, args.repeat, log)
    if "overhead" in only:
        res["overhead"] = section_overhead(ode, box, (0.5,) if args.quick else (2.0, 0.5), args.repeat, log)
    if "start" in only:
        res["start"] = section_start(args.repeat, log)
    if "cluster" in only:
        res["cluster"] = section_cluster(ode, box, pieces, T, args.repeat, log)
    if "first" in only:
        res["first"] = section_first(pieces, T, args.repeat, log)
    if "unequal" in only:
        res["unequal"] = section_unequal(ode, box, 64 if args.quick else (args.pieces or 512), T, args.repeat, log)
    if "granular" in only:
        res["granular"] = section_granular(ode, box, pieces, T, args.repeat, log)
    if "model16" in only:
        res["model16"] = section_model16(ode, box, pieces, T, res.get("first", []), log)
    if "model16so" in only:
        res["model16so"] = section_model16so(box, log, pieces=32 if args.quick else 128, T=0.5 if args.quick else 3.0,
                                             first_rows=res.get("first"))
    if "scaling" in only:
        res["scaling"] = section_scaling(ode, box, pieces, T, log)
        res["estimate"] = estimate(res["scaling"], pieces, log)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(res, f, indent=1, default=str)
    return 0


if __name__ == "__main__":
    sys.exit(main())

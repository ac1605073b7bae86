"""Chunked execution of a verified run: independent pieces, own step sizes, one Solution.

The initial boxes of a run (after ``subdivision``) are independent: the union of
their solutions is the reachable set. :func:`solve_parallel` (what
``solve(..., workers=, client=, chunks=)`` delegates to) partitions them into
contiguous *chunks*, runs each chunk as its own one-batch solve
(:func:`verified.driver.batch.solve_batch`, what ``solve(..., workers=1)`` runs) --
with its own step sizes, wrapping control and (with ``adaptive``) its own splitting
-- and merges the chunk Solutions into one :class:`~verified.solver.Solution`.

Where the chunks run:

* in this process, one after the other (``workers=1`` with ``chunks > 1``, an adaptive
  ``workers=1`` run with ``rechunk=True``, or when Dask is not installed): only the
  per-chunk step sizes change; a plan of one chunk (the default for fewer than
  ``2 * MIN_CHUNK_BOXES`` boxes, :func:`plan_chunks`) with ``workers > 1`` is one
  in-process batch, exactly ``solve``'s result: a local cluster's worker would run it
  on the same cores after a Dask round trip (and, on a first call, the cluster's
  start);
* on a local Dask cluster (one process per worker, 1 thread each), created on first
  use and kept for later calls (:func:`local_client`); each worker loads the kernels a
  run needs from numba's on-disk cache before that run's first chunk
  (:func:`_warm_problem`) and compiles none at start (:func:`prepare_worker`). On
  POSIX the workers are fresh interpreters (``python -m dask spec``, under a nanny that restarts a worker process
  that dies) with the scheduler in this process, not ``LocalCluster``'s spawned
  processes, which re-run the calling script's top level: a script needs no
  ``if __name__ == "__main__":`` guard (:func:`start_local_cluster`). So
  ``workers=None``, the default of ``solve``, means "every core when worthwhile"
  (:func:`auto_workers`: at least ``AUTO_MIN_PIECES`` boxes, Dask installed, more
  than one core; else one in-process batch, also silently without Dask); ``workers=1``
  is one in-process batch;
* on an existing Dask cluster: ``client=`` a ``distributed.Client`` or a scheduler
  address ``"tcp://host:port"`` (:func:`connect`: an unreachable address is a one-line
  :class:`SchedulerError` after ``CONNECT_TIMEOUT`` seconds, never a hang).

On Dask the ODE graph is sent once per worker (one small task returns it; each worker
fetches it from a peer when its first chunk needs it, builds the Taylor tapes once and
keeps them for every chunk; a worker new to it also takes one warm-up step first),
chunks are ordinary tasks, so Dask's scheduler retries a chunk whose worker died (up to
``distributed.scheduler.allowed-failures`` times) and the result is complete; a
cluster left without any worker for ``NO_WORKERS_TIMEOUT`` seconds ends the run with
:class:`WorkersLostError` (Dask would wait for ever). Each
worker process lets glibc keep freed memory (:func:`_tune_malloc`: Dask's
``MALLOC_TRIM_THRESHOLD_=65536`` costs CPU per chunk; docs/lab/code_notes.md).

Re-chunking (``rechunk``; with ``adaptive`` the sets a chunk's splitting creates): a
chunk runs until it holds ``RECHUNK_GROWTH`` (2) times as many sets as it started with
(and at least 2x the plan's mean chunk size and 2x ``RECHUNK_MIN_SETS`` = 64), stops
after that step (a hook, :class:`_Pause`) and returns its Solution so far and its sets
with their exact time (:class:`verified.solver.Start`). The driver cuts the sets into
contiguous pieces of about the plan's mean chunk size (at least ``RECHUNK_MIN_SETS``)
and runs each as a new chunk from that time (``solve(start=)``): on Dask at once, on
whichever worker is free, so the sets of one busy chunk spread over idle workers; in this
process depth-first. Every set goes to exactly one piece, so their union is the paused
chunk's set. What changes against the chunk run whole: each piece has its own step sizes;
a piece starts with the wrapping control's limit of the paused chunk but without the
stepper's guesses from its last step; the split due after the step a chunk paused at is
decided again by its pieces' first step; splitting judges a set against the union the
piece was cut from (``split_ratio`` times the widths of that union over the piece's own,
:attr:`Start.split_scale`); ``max_boxes`` is each initial chunk's budget: a piece may grow
to its parent's budget less the sets its siblings held when cut (so the pieces of one
chunk together may exceed it: each checks only its own). Measured on the mixed batch
(``benchmarks/bench_parallel.py --only rechunk``): see the benchmark. Default
(``rechunk=None``): on for adaptive runs on Dask, off in this process (one core gains
nothing from it); never with a consistency test (its record cannot be continued:
``rechunk=True`` is an error then) or with per-box exact parameters that differ.

Work stealing (on Dask, unless ``rechunk=False``; never with a consistency test): the
driver keeps each running piece's rate from its progress reports (over the last
``RATE_WINDOW`` s: a piece whose steps shorten late would look nearly done at its mean
rate). When a worker thread holds none of the run's pieces, the running piece with the
most time left -- if more than ``STEAL_MIN_S`` and it started with at least
``2 * STEAL_MIN_SETS`` sets -- is asked to pause after its current step (``client.run``
sets a flag in the workers that its :class:`_Pause` hook reads), and its sets are cut, as
above, into twice as many pieces as there are free threads (at least ``STEAL_MIN_SETS``
sets each: the last, smaller pieces even out the end). A piece in which some initial
pieces broke down is not paused (as above). Which pieces are cut, and when, depends on
timing; the result depends only on the cuts: ``Solution.stats["cuts"]`` records each
(the piece's place in the tree ``path``, ``steps`` taken when it paused, ``k`` pieces,
``why``: "sets", "lag" or "replay") and ``with replaying(sol): solve(..., workers=1,
chunks=len(sol.chunks))`` with ``sol``'s arguments reproduces ``sol`` in this process
float for float. When there are no more chunks than workers, chunk i is offered to
worker i first (Dask would otherwise queue several on the worker that holds the graph).

What the merged Solution means (the union is the same set a single batch encloses,
up to the step-size differences):

``t``, ``boxes``, ``hull``
    Every chunk has the same output times; ``boxes[k]`` concatenates the chunks' boxes
    at ``t[k]`` in chunk order (= the order of the initial boxes). Only the output
    times *every* chunk reached are kept.
``tube_t``, ``tube``, ``tube_hull``
    The chunks step at their own times. The merged tube is on the common grid: the
    union of all chunks' step boundaries up to ``t_reached``; ``tube[j]`` holds one box
    per chunk, the hull of that chunk's tube boxes over its step that contains
    ``[tube_t[j], tube_t[j + 1]]`` (sound: that step's boxes enclose the chunk's
    solutions on the whole step). The exact per-chunk tubes, at their own times, are in
    ``sol.chunks[i]["tube_t"]`` / ``["tube"]``.
``t_reached``, ``status``, ``reason``
    ``t_reached`` is the smallest over the chunks; ``status`` the worst
    (breakdown > interrupted > stopped > completed), ``reason`` names the chunk
    (``"chunk 3 (boxes 96..127): ..."``), or, where some initial pieces broke down,
    which (``"3 of 64 pieces failed (pieces 5, 17, 40 at t = 0.31: ...); 61 pieces
    verified to t = 2"``). A chunk that never ran (Ctrl-C, cancelled) counts as
    reaching ``t0``.
``piece_results``, ``surviving``
    Per initial piece its status, ``t_reached`` and reason: a chunk's own report where
    it ran as one batch (its pieces break down alone there, :mod:`verified.driver.batch`),
    else (not run, re-chunked) the chunk's outcome for each of its pieces. ``surviving``
    (where some pieces broke down and others went on): the chunks' parts that went on
    merged as above (a chunk without a failed piece whole, else its ``surviving``). A
    chunk in which a piece broke down is not re-chunked after that.
``stats``
    Counters summed over the chunks (``steps`` is the total of chunk steps,
    ``steps_max`` the longest chunk's), ``wall_s`` of the whole call, plus
    ``chunks``, ``workers``, ``backend`` ("inprocess", "dask-local", "dask"), ``rechunk``
    (on or off), ``pieces`` (solves run: chunks and pieces cut from them), ``rechunks``
    (chunks or pieces that paused and were cut),
    ``chunk_wall_s`` (each chunk's own solve time), ``setup_s`` (cluster start and
    graph shipping), ``sent_bytes`` / ``received_bytes`` (pickled sizes per run),
    ``merge_s`` (stitching and merging the chunks here after the last result; a family
    of pieces is stitched as soon as its last piece is in, during the run: ``stitch_s``),
    ``steal`` (on or off), ``cuts`` (see work stealing); on Dask ``warm_s`` (each new
    worker's first step of this problem: its kernels loaded) and ``timeline`` (per
    piece run: worker pid, parent piece, sets, start time, steps, task start and end on
    the worker, its thread's CPU seconds, result here, why it paused; seconds after the
    call: where the time went, benchmarks/bench_parallel.py).
``chunks``
    Per initial chunk: boxes, status, steps, its tube, ...; with re-chunking ``pieces``:
    each piece's parent, start time, sets at its start, status, steps, wall time, worker.
    A re-chunked chunk's outputs are the boxes of its pieces that recorded each output
    (depth-first order), its tube one box per piece live on each interval of the union
    of its pieces' step times (the hull of that piece's step), ``t_reached`` and
    ``status`` those of its earliest worst piece not cut.
``consistency``
    With an energy test: the chunks' records interleaved by time (RA(t), H_H, H_V
    points of every chunk sorted by t; the tests of every chunk); each chunk's own
    record in ``sol.chunks[i]["consistency"]``.

Hooks: on Dask every chunk gets its own (pickled) copy of ``hooks`` and
``consistency``; in-process the hooks are shared by the chunks (one run after the
other) and ``consistency`` is copied per chunk. :class:`verified.driver.hooks.StopAfterWall`
becomes one wall-clock deadline for the whole call (a chunk that starts after it stops
after one step). ``progress(t, t_end)`` is called in this process with the chunks'
mean time reached (workers report every ~0.3 s). Ctrl-C while waiting cancels the
chunks still running and returns what is verified (``status="interrupted"``).

This module knows nothing about robots.
"""

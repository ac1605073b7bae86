"""Compile the numba kernels once, ahead of use: ``python -m verified.warmup [--jobs N] [FAMILY ...]``.

The kernels are compiled on first use and cached on disk (``cache=True``), which costs
seconds to a minute per family the first time (the longest: the affine Taylor kernel,
the Taylor-model kernels, the affine reference kernel and the interval loops, none of
which the demo's double pendulum uses; docs/lab/code_notes.md).
This module runs tiny verified integrations that go through every family (interval,
affine with fresh symbols, Taylor models of degree 2, 3 and 4 with the composition
step, interval parameters, the rigorous linear solve), so that later runs start warm.
``python -m mbs demo`` starts it in a background process on the machine's other core, and
building the package (``pip install .``: ``setup.py``) runs it with ``--jobs 2``, so that
the installed package carries the compiled kernels in its numba cache.

Nothing here is needed for correctness: a kernel that is not warm compiles when it is
first called.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

__all__ = ["compile_kernels", "compile_in_processes", "start_in_background", "finish_background"]


def _rhs(x, p):
    """A small ODE whose graph has every operation the Taylor kernels implement."""
    q, v = x
    s = (q * q + 1.0).sqrt()
    return [v, -p[0] * q.sin() + 0.1 * q.cos() * v / s + 0.01 * (q.exp() + (s + 1.0).log() + (0.1 * q).tan()
                                                                  + q.arctan() + v ** 2 * v.mid())]


#: what compile_kernels can warm: the kernel families (as :data:`mbs.progress.KERNEL_FAMILIES`
#: names them), and ``"affine_range"``, the affine graph range alone (a robot's frame
#: enclosures: :func:`verified.series.affine_taylor.affine_range`), the first step of ``"affine"``
FAMILIES = ("interval", "affine", "Taylor-model", "affine_range")


def compile_kernels(log=None, families=None) -> float:
    """Run the tiny integrations (about 2 minutes cold on 2 shared cores, a second warm);
    returns the wall time in s. ``families``: a subset of :data:`FAMILIES` (None: the
    three families); the interval kernels are compiled with any family (every run uses
    them), not with ``"affine_range"`` alone."""
    families = FAMILIES[:3] if families is None else tuple(families)
    unknown = [f for f in families if f not in FAMILIES]
    if unknown:
        raise ValueError(f"unknown kernel families {unknown}; known: {', '.join(FAMILIES)}")
    # (import here: the solver and the kernels (~1.5 s) only in the process that compiles;
    # mbs.app.demo imports this module to start that process)
    from verified.arith import interval as iv, linalg
    from verified.series.affine_taylor import AffineTaylorODE, affine_range, box_forms
    from verified.arith.interval import Interval, point
    from verified.solver import solve
    from verified.graph.tracer import trace

    t0 = time.perf_counter()

    def said(what):
        if log is not None:
            log(f"warm: {what} ({time.perf_counter() - t0:.0f} s)")

    graph = trace(_rhs, 2, n_params=1)
    x0 = Interval(np.array([0.4, -0.1]), np.array([0.41, -0.09]))
    p = Interval(np.array([9.8]), np.array([9.82]))
    boxes = x0.subdivide([2, 2]).reshape(-1, 2)
    if "affine" in families or "affine_range" in families:
        affine_range(graph, boxes, p.broadcast_to((boxes.shape[0], 1)))
        said("affine range")
    if not set(families) & set(FAMILIES[:3]):
        return time.perf_counter() - t0
    runs = [dict()]
    if "affine" in families:
        runs.append(dict(arithmetic="affine", error_basis="auto"))
    if "Taylor-model" in families:
        runs += [dict(arithmetic="taylor_model", set_order=2, error_basis="auto"),
                 dict(arithmetic="taylor_model", set_order=2, set_step="composition", model_degree=2),
                 dict(arithmetic="taylor_model", set_order=2, set_step="composition", model_degree=3,
                      error_basis="auto"),
                 dict(arithmetic="taylor_model", set_order=2, set_step="composition", model_degree=4)]
    for opts in runs:
        solve(graph, x0, (0.0, 0.05), params=p, order=6, tol=1e-9, **opts)
        said(opts or "interval")
    # the same without graph parameters, over a batch of boxes (other array shapes), the
    # graph's interval and affine evaluation over boxes, interval operations and solves
    free = trace(lambda x, _: _rhs(x, [9.81]), 2)
    solve(free, boxes, (0.0, 0.05), order=6, tol=1e-9)
    graph.eval_interval(boxes, p.broadcast_to((boxes.shape[0], 1)))
    if "affine" in families:
        solve(free, boxes, (0.0, 0.05), order=6, tol=1e-9, arithmetic="affine")
        # (one set: the affine kernel ranks its slots for fresh symbols)
        AffineTaylorODE(graph, fresh_slots=2).series(box_forms(x0.lo[None], x0.hi[None], np.arange(2), 2), 4, p)
    for op in (iv.sin, iv.cos, iv.tan, iv.exp, iv.log, iv.sqrt, iv.atan, iv.sqr):
        op(boxes)
    (boxes * boxes - boxes / (boxes + 2.0)) ** 3
    linalg.solve(point(np.array([[[2.0, 0.1], [0.1, 1.0]]])), boxes[:1])
    said("batches, graph evaluation, interval operations")
    return time.perf_counter() - t0


def start_in_background(families=None):
    """``python -m verified.warmup [FAMILY ...]`` in a child process (the same ``verified``
    package as this one, so the kernels land in the same cache), or None on a machine with
    one core (it would slow the caller down) or when ``MBS_NO_WARMUP`` is set.
    ``families``: as :func:`compile_kernels` (None: all)."""
    families = () if families is None else tuple(families)
    unknown = [f for f in families if f not in FAMILIES]
    if unknown:
        raise ValueError(f"unknown kernel families {unknown}; known: {', '.join(FAMILIES)}")
    if (os.cpu_count() or 1) < 2 or os.environ.get("MBS_NO_WARMUP"):
        return None
    try:
        return subprocess.Popen([sys.executable, "-m", "verified.warmup", *families], stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL, env=_child_env())
    except OSError:
        return None


def _child_env() -> dict:
    """The environment of a child ``python -m verified.warmup``: this ``verified`` package
    first on its path, so that the kernels land in the same cache."""
    root = str(Path(__file__).resolve().parents[1])
    return dict(os.environ, PYTHONPATH=os.pathsep.join([root] + [p for p in [os.environ.get("PYTHONPATH")] if p]))


def finish_background(proc, timeout: float = 300.0) -> str:
    """Wait for :func:`start_in_background`'s child (at most ``timeout`` s, then stop it);
    a one-line report."""
    if proc is None:
        return ""
    t0 = time.perf_counter()
    try:
        rc = proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
        return f"kernel warm-up stopped after {timeout:.0f} s (the kernels compile on first use instead)"
    waited = time.perf_counter() - t0
    if rc != 0:
        return f"kernel warm-up exited with code {rc} (the kernels compile on first use instead)"
    return (f"the other arithmetics' kernels were compiled in the background for later runs"
            f"{f' (waited {waited:.0f} s for them)' if waited >= 1 else ''}")


#: the families one process each warms with ``--jobs`` 2 or more: the two longest compiles
#: side by side (each compiles the interval kernels too, which every run uses)
_JOB_FAMILIES = (("Taylor-model",), ("affine",))


def compile_in_processes(jobs: int, log=None) -> float:
    """:func:`compile_kernels` for the three families, in up to ``jobs`` child processes at
    once (the Taylor-model and the affine family side by side; one process where ``jobs``
    is 1); returns the wall time in s. Raises RuntimeError naming a child that failed."""
    t0 = time.perf_counter()
    if jobs <= 1:
        compile_kernels(log=log)
        return time.perf_counter() - t0
    procs = [subprocess.Popen([sys.executable, "-m", "verified.warmup", *fam], env=_child_env())
             for fam in _JOB_FAMILIES[:jobs]]
    failed = [" ".join(fam) for fam, p in zip(_JOB_FAMILIES, procs) if p.wait() != 0]
    if failed:
        raise RuntimeError(f"the kernel warm-up of {', '.join(failed)} failed")
    return time.perf_counter() - t0


def _main(argv) -> int:
    """``python -m verified.warmup [--jobs N] [FAMILY ...]``."""
    log = (lambda s: print(s, file=sys.stderr, flush=True))
    jobs = 1
    if argv[:1] == ["--jobs"]:
        try:
            jobs = int(argv[1])
        except (IndexError, ValueError):
            print("usage: python -m verified.warmup [--jobs N] [FAMILY ...]", file=sys.stderr)
            return 2
        argv = argv[2:]
    if jobs > 1 and not argv:
        wall = compile_in_processes(jobs, log)
    else:
        wall = compile_kernels(log=log, families=argv or None)
    print(f"numba kernels warm ({wall:.1f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))

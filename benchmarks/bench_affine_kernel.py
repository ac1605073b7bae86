"""Per box-step cost of the affine Taylor kernel against the interval kernel.

Run:  python benchmarks/bench_affine_kernel.py [--baseline PATH] [--quick] [--only dp,arm,ur5] [--order K]

For each graph and batch size B it times, in one process (the machine is shared: the
ratios are what counts),

* ``TaylorODE(g).coefficients(X, K)``          (interval kernel, verified/series/taylor.py)
* ``AffineTaylorODE(g).coefficients(X, K)``    (affine, n fresh symbols per order)
* ``AffineTaylorODE(variational_graph(g), fresh_symbols=0).series(forms, K - 1)``
  (the variational use of verified/steppers/lohner.py, forms over a set's 2n parameters)

and prints CPU microseconds per box-step and the ratio affine / interval. With
``--baseline PATH`` (a copy of an older ``verified/series/affine_taylor.py`` whose relative
imports were made absolute) the old affine kernel is timed in the same run too, and
its results are compared with today's: ``same`` means bit-identical enclosures,
otherwise the largest relative width change (today / old - 1) is shown.

Graphs: the paper's double pendulum ``trace(models.double_pendulum.rhs, 4)`` over its
initial box cut into B pieces along x1; the 3-link planar arm
``planar_chain(3).numeric().rhs_graph()`` over q0 +- 0.01, qd +- 0.01, and the UR5
``models.robots.ur5().numeric().rhs_graph()`` over q0 +- 1e-3, qd +- 1e-3 (cut
into B pieces along q1).
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time

import numpy as np

from verified.series.affine_taylor import AffineTaylorODE
from verified.graph import trace
from verified.arith.interval import Interval
from verified.sets.first_order import DoubletonSets
from verified.series.taylor import TaylorODE
from verified.series.variational import variational_graph

Q0_ARM3 = (0.5, -0.3, 0.2)
Q0_UR5 = (0.0, -1.0, 1.0, -0.5, 0.5, 0.0)


def _pieces(lo, hi, nb, axis=0):
    """The box [lo, hi] cut into nb equal pieces along ``axis``: Interval (nb, d)."""
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    edges = np.linspace(lo[axis], hi[axis], nb + 1)
    L = np.tile(lo, (nb, 1))
    H = np.tile(hi, (nb, 1))
    L[:, axis] = edges[:-1]
    H[:, axis] = edges[1:]
    H[-1, axis] = hi[axis]
    return Interval(L, H)


def cases(quick=False, only=("dp", "arm", "ur5")):
    """(name, graph, box factory, batch sizes)."""
    from models import double_pendulum as dp
    from models.planar import planar_chain
    out = []
    if "dp" in only:
        g = trace(dp.rhs, 4)
        lo, hi = dp.initial_box()
        sizes = (1, 64) if quick else (1, 64, 1024)
        out.append(("double pendulum", g, lambda nb, lo=lo, hi=hi: _pieces(lo, hi, nb), sizes))
    if "arm" in only:
        chain = planar_chain(3)
        q0 = np.asarray(Q0_ARM3)
        lo3 = np.r_[q0 - 0.01, -0.01 * np.ones(3)]
        hi3 = np.r_[q0 + 0.01, 0.01 * np.ones(3)]
        out.append(("3-link arm", chain.numeric().rhs_graph(), lambda nb, lo=lo3, hi=hi3: _pieces(lo, hi, nb), (1, 64)))
    if "ur5" in only and not quick:
        from models.robots import ur5
        q0 = np.asarray(Q0_UR5)
        lo6 = np.r_[q0 - 1e-3, -1e-3 * np.ones(6)]
        hi6 = np.r_[q0 + 1e-3, 1e-3 * np.ones(6)]
        out.append(("UR5", ur5().numeric().rhs_graph(), lambda nb, lo=lo6, hi=hi6: _pieces(lo, hi, nb), (1, 64)))
    return out


def best_time(fn, budget=0.6, repeat=3):
    """Best of ``repeat`` CPU timings (each at least ``budget / repeat`` seconds) of fn()
    (CPU time of this process: the machines are shared, waiting for a core is not
    the kernel's cost)."""
    fn()  # compile / warm up
    t0 = time.process_time()
    fn()
    one = time.process_time() - t0
    number = max(1, int(budget / repeat / max(one, 1e-9)))
    best = one
    for _ in range(repeat):
        t0 = time.process_time()
        for _ in range(number):
            fn()
        best = min(best, (time.process_time() - t0) / number)
    return best


def load_baseline(path):
    spec = importlib.util.spec_from_file_location("affine_taylor_baseline", path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # numba's on-disk cache finds its module by name
    spec.loader.exec_module(mod)
    return mod


def compare(new: Interval, old: Interval) -> str:
    """'same' if bit-identical, else the largest relative width change new / old - 1."""
    if np.array_equal(new.lo, old.lo) and np.array_equal(new.hi, old.hi):
        return "same"
    wn, wo = new.width(), old.width()
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = np.where(wo > 0, wn / wo - 1.0, np.where(wn > 0, np.inf, 0.0))
    inside = bool(np.all((new.lo <= old.lo) | (new.hi >= old.hi)))  # not a containment test, just info
    return f"max rel width change {np.nanmax(rel):+.2e} (min {np.nanmin(rel):+.2e}){'' if inside else ' !'}"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", help="path of an older affine_taylor.py to time and compare against")
    ap.add_argument("--quick", action="store_true", help="double pendulum at 1 and 64 boxes, 3-link arm only")
    ap.add_argument("--only", default="dp,arm,ur5", help="comma-separated subset of dp, arm, ur5")
    ap.add_argument("--order", type=int, default=12)
    ap.add_argument("--budget", type=float, default=0.6, help="seconds of timing per measurement")
    args = ap.parse_args(argv)
    base = load_baseline(args.baseline) if args.baseline else None
    K = args.order
    rows = []
    notes = []
    hdr = (f"{'graph':16s} {'B':>5s} {'interval':>9s} {'affine':>9s} {'aff/int':>8s} {'var.ser':>9s} {'ser/int':>8s}"
           + (f" {'old aff':>9s} {'old a/i':>8s} {'old ser':>9s} {'old s/i':>8s} {'new/old':>8s} {'ser n/o':>8s}"
              if base else ""))
    print(f"order {K}; CPU microseconds per box-step (best of 3)")
    print(hdr)
    for name, g, boxes, sizes in cases(args.quick, args.only.split(",")):
        n = g.n_inputs
        vg = variational_graph(g)
        iv = TaylorODE(g)
        af = AffineTaylorODE(g)
        va = AffineTaylorODE(vg, fresh_symbols=0)
        if base is not None:
            af_old = base.AffineTaylorODE(g)
            va_old = base.AffineTaylorODE(vg, fresh_symbols=0)
        for nb in sizes:
            X = boxes(nb)
            forms = DoubletonSets.from_boxes(X).affine_forms(extra=n * n)
            forms[n:, :, 0] = np.eye(n).reshape(-1)[:, None]
            t_i = best_time(lambda: iv.coefficients(X, K), args.budget) / nb * 1e6
            t_a = best_time(lambda: af.coefficients(X, K), args.budget) / nb * 1e6
            t_s = best_time(lambda: va.series(forms, K - 1), args.budget) / nb * 1e6
            line = f"{name:16s} {nb:5d} {t_i:9.1f} {t_a:9.1f} {t_a / t_i:8.2f} {t_s:9.1f} {t_s / t_i:8.2f}"
            if base is not None:
                o_a = best_time(lambda: af_old.coefficients(X, K), args.budget) / nb * 1e6
                o_s = best_time(lambda: va_old.series(forms, K - 1), args.budget) / nb * 1e6
                line += (f" {o_a:9.1f} {o_a / t_i:8.2f} {o_s:9.1f} {o_s / t_i:8.2f} {t_a / o_a:8.2f}"
                         f" {t_s / o_s:8.2f}")
                same_c = compare(af.coefficients(X, K), af_old.coefficients(X, K))
                same_s = compare(va.series(forms, K - 1), va_old.series(forms, K - 1))
                notes.append(f"{name} B={nb}: coefficients {same_c}; series {same_s}")
            print(line, flush=True)
            rows.append(line)
    for s in notes:
        print(s)
    return rows


if __name__ == "__main__":
    # one core against one core (CAPD, earlier runs): workers=None stays one in-process
    # batch here (bench_parallel measures the cluster; explicit workers= are kept)
    import verified.execution.plan
    verified.execution.plan.DEFAULT_PARALLEL = False
    main()

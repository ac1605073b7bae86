"""The paper's double pendulum (eq. 22, initial box 25, m = l = 1, g = 9.81): the
verified solver against the densely sampled true hull.

Run:  python benchmarks/bench_solver.py                    # T = 1: pieces table, break-down
      python benchmarks/bench_solver.py --T 2 --pieces 256 1024
      python benchmarks/bench_solver.py --work-precision     # orders x tolerances
      python benchmarks/bench_solver.py --T 3 --pieces 1024 --order 20 --tol 1e-14
      python benchmarks/bench_solver.py --adaptive 16 64       # adaptive splitting from N pieces

For each number N of pieces (x1(0) split into N equal parts) it prints the width of
each state component at T, its ratio to the true hull (dense DOP853 sampling, all in
this run), the wall time and the steps. The single-box break-down time is the time
the unsplit box stops (enclosure wider than the solver's max_width, or no step can be
validated). Reference numbers (a compiled C++ QR-Lohner solver, order 20, on this kind
of machine; ../shared/DESIGN.md): T = 1, N = 256 -> worst ratio 1.014 in 21.3 s;
single box breaks down at t = 0.62.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from models import double_pendulum as dp
from mbs.app.sampling import Ensemble, hull_widths
from verified.graph import trace
from verified.arith.interval import Interval
from verified.solver import VerifiedODE, solve

DEFAULTS = dict(order=12, tol=1e-10)  # chosen from the work-precision table (T = 1)


def true_hull_widths(t_end, samples=2001):
    """Widths at ``t_end`` of the hull of DOP853 solutions (rtol = atol = 1e-12) from
    ``samples`` values of x1(0) spread over the initial box (the other components are
    points), integrated together as one vectorized system (the sampling oracle's
    ``Ensemble``; the integrator's own states at ``t_end``, no dense output)."""
    lo, hi = dp.initial_box()
    x1 = np.linspace(lo[0], hi[0], samples)
    points = np.column_stack([x1, np.full(samples, lo[1]), np.full(samples, lo[2]), np.full(samples, lo[3])])
    flow = Ensemble(lambda X: np.concatenate(dp.rhs(X)), points, t_end, dense=False)
    return hull_widths(flow.final)


def run_pieces(ode, t_end, pieces, **options):
    """One verified run with x1(0) split into ``pieces``; returns (solution, wall seconds)."""
    lo, hi = dp.initial_box()
    t0 = time.perf_counter()
    sol = solve(ode, Interval(lo, hi), (0.0, t_end), subdivision=[pieces, 1, 1, 1], **{**DEFAULTS, **options})
    return sol, time.perf_counter() - t0


def breakdown_time(ode, horizon=2.0, **options):
    sol, wall = run_pieces(ode, horizon, 1, **options)
    return sol.t_reached, sol.reason, wall


def pieces_table(ode, t_end, pieces_list, true_w, **options):
    rows = []
    for n in pieces_list:
        sol, wall = run_pieces(ode, t_end, n, **options)
        if sol.success:
            w = sol.hull.width()[-1]
            rows.append((n, w, w / true_w, wall, f"{sol.stats['steps']} ({sol.stats['final_boxes']} boxes)", ""))
        else:
            rows.append((n, None, None, wall, sol.stats["steps"], f"breakdown at t = {sol.t_reached:.3f}"))
    return rows


def print_pieces_table(t_end, rows, true_w):
    print(f"\nT = {t_end}: widths at T, ratio to the sampled true hull, wall time")
    print(f"{'pieces':>7} | {'widths x1..x4':^47} | {'ratios':^31} | {'worst':>6} | {'wall s':>7} | steps")
    for n, w, r, wall, steps, note in rows:
        if w is None:
            print(f"{n:>7} | {note:^47} | {'':^31} | {'':>6} | {wall:>7.2f} | {steps}")
        else:
            ws = " ".join(f"{v:11.6f}" for v in w)
            rs = " ".join(f"{v:7.4f}" for v in r)
            print(f"{n:>7} | {ws} | {rs} | {r.max():6.4f} | {wall:>7.2f} | {steps}")
    print(f"{'true':>7} | " + " ".join(f"{v:11.6f}" for v in true_w))


def work_precision(ode, t_end, pieces, true_w, orders=(8, 12, 16, 20), tols=(1e-7, 1e-9, 1e-11)):
    print(f"\nWork-precision, T = {t_end}, {pieces} pieces: worst width ratio / wall s")
    print(f"{'order':>5} | " + " | ".join(f"tol {t:.0e}".center(17) for t in tols))
    for order in orders:
        cells = []
        for tol in tols:
            sol, wall = run_pieces(ode, t_end, pieces, order=order, tol=tol)
            if sol.success:
                cells.append(f"{(sol.hull.width()[-1] / true_w).max():7.4f} / {wall:6.2f}")
            else:
                cells.append(f"fail t={sol.t_reached:.2f}".center(17))
        print(f"{order:>5} | " + " | ".join(cells))


def main(argv=None):
    p = argparse.ArgumentParser(description="double pendulum benchmark of the verified solver")
    p.add_argument("--T", type=float, default=1.0)
    p.add_argument("--pieces", type=int, nargs="+", default=[1, 16, 64, 256, 384])
    p.add_argument("--order", type=int, default=DEFAULTS["order"])
    p.add_argument("--tol", type=float, default=DEFAULTS["tol"])
    p.add_argument("--work-precision", action="store_true")
    p.add_argument("--adaptive", type=int, nargs="*", default=[16, 64],
                   help="initial pieces for runs with adaptive splitting (none: skip)")
    p.add_argument("--split-ratio", type=float, default=0.001)
    p.add_argument("--error-basis", choices=["qr", "auto"], default="qr")
    p.add_argument("--samples", type=int, default=2001)
    args = p.parse_args(argv)
    ode = VerifiedODE(trace(dp.rhs, 4))
    run_pieces(ode, 0.05, 2)  # load compiled kernels before timing
    true_w = true_hull_widths(args.T, args.samples)
    options = dict(order=args.order, tol=args.tol, error_basis=args.error_basis)
    rows = pieces_table(ode, args.T, args.pieces, true_w, **options)
    print(f"order {args.order}, tol {args.tol:g}, error basis {args.error_basis}")
    print_pieces_table(args.T, rows, true_w)
    if args.adaptive:
        rows = pieces_table(ode, args.T, args.adaptive, true_w, adaptive=True, split_ratio=args.split_ratio, **options)
        print(f"\nadaptive splitting (split_ratio {args.split_ratio:g}), starting from N pieces:")
        print_pieces_table(args.T, rows, true_w)
    t_b, reason, wall = breakdown_time(ode, **options)
    print(f"\nsingle box: verified up to t = {t_b:.3f} ({reason}; {wall:.2f} s)")
    if args.work_precision:
        work_precision(ode, args.T, 64, true_w)
    return 0


if __name__ == "__main__":
    # one core against one core (CAPD, earlier runs): workers=None stays one in-process
    # batch here (bench_parallel measures the cluster; explicit workers= are kept)
    import verified.execution.plan
    verified.execution.plan.DEFAULT_PARALLEL = False
    sys.exit(main())

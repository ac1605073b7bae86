"""The Taylor-model kernel with and without products at the recursion's high orders
(``TaylorModelODE.product_orders``, issue 45), side by side in one run.

From order ``product_orders`` on, the kernel keeps no product of two non-constant
monomials: each is bounded into the remainder. This runs ``bench_auto``'s cases with no
solver settings (``auto``), alternating the settings in one process (the kernels
compiled for both before the clock), and prints for each setting the least CPU of
``--repeat`` runs, the steps, the worst ratio of the final width to the sampled spread
(``bench_auto.ratio``) and the CPU and width ratios against the first setting.

    python benchmarks/bench_product_orders.py                       # -1 (all orders) against 5 (shipped)
    python benchmarks/bench_product_orders.py --orders -1,6,5,4 --only arm_small,ur5 --repeat 3
    python benchmarks/bench_product_orders.py --quick               # short horizons, one run each
"""
from __future__ import annotations

import argparse
import time

import numpy as np

import bench_auto
from verified.series.taylor_model import TaylorModelODE

DEFAULT_CASES = "arm_small,ur5,dp1,vdp,laub"


def measure(key: str, orders: list[int], repeat: int, quick: bool, cap: float, out=print) -> list[dict]:
    """Rows (one per setting) for one of ``bench_auto.CASES``."""
    case = bench_auto.CASES[key]()
    T = case.quick_T if quick else case.T
    states = case.sample(T)
    shipped = TaylorModelODE.product_orders
    rows = {k: {"orders": k, "cpu": np.inf} for k in orders}
    try:
        for k in orders:  # (warm: every kernel this case uses, compiled or loaded)
            TaylorModelODE.product_orders = k
            case.run({}, min(T, 0.01), cap)
        for _ in range(repeat):
            for k in orders:
                TaylorModelODE.product_orders = k
                t0 = time.process_time()
                sol = case.run({}, T, cap)
                cpu = time.process_time() - t0
                r = rows[k]
                if cpu < r["cpu"]:
                    done = sol.status == "completed"
                    r.update(cpu=cpu, status=sol.status, t=float(sol.t_reached), steps=sol.stats.get("steps"),
                             ratio=bench_auto.ratio(sol, states) if done else float("nan"),
                             width=float(np.asarray(sol.hull[-1].width(), float).max()) if done else float("nan"))
    finally:
        TaylorModelODE.product_orders = shipped
    first = rows[orders[0]]
    for k in orders:
        r = rows[k]
        out(f"| {case.name} | {'all orders' if k < 0 else f'from order {k}'} | {r['status']} | {r['t']:.4g} | "
            f"{r['steps']} | {r['cpu']:.2f} | {r['ratio']:.4f} | {r['cpu'] / first['cpu']:.2f} | "
            f"{r['width'] / first['width']:.4f} |")
    return [rows[k] for k in orders]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--orders", default="-1,5", help="comma-separated product_orders values (-1: all orders keep products)")
    ap.add_argument("--only", default=DEFAULT_CASES, help="comma-separated bench_auto cases: " + ", ".join(bench_auto.CASES))
    ap.add_argument("--repeat", type=int, default=2, help="runs per setting; the least CPU is reported")
    ap.add_argument("--quick", action="store_true", help="short horizons, one run per setting")
    ap.add_argument("--cap", type=float, default=600.0, help="wall-clock cap per run (s)")
    args = ap.parse_args(argv)
    orders = [int(k) for k in args.orders.split(",")]
    keys = [k for k in args.only.split(",") if k]
    unknown = [k for k in keys if k not in bench_auto.CASES]
    if unknown:
        ap.error(f"unknown case(s) {', '.join(unknown)}; known: {', '.join(bench_auto.CASES)}")
    print(f"TaylorModelODE.product_orders as shipped: {TaylorModelODE.product_orders}; CPU = least of "
          f"{1 if args.quick else args.repeat} run(s), process time\n")
    print("| case | products kept | status | t reached | steps | CPU s | ratio | CPU / first | widest width / first |")
    print("|---|---|---|---|---|---|---|---|---|")
    for key in keys:
        measure(key, orders, 1 if args.quick else args.repeat, args.quick, args.cap)


if __name__ == "__main__":
    main()

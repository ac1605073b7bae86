"""Degree-2 Taylor models for the Jacobian over a set (``arithmetic="taylor_model"``,
issue 17) against affine arithmetic, side by side in one run.

Run:  python benchmarks/bench_taylor_model.py            # every case (~15 min)
      python benchmarks/bench_taylor_model.py --quick    # arm3 only, first-order sets (~2 min)

Tables:

1. Tightness of ``d qdd / dq`` over the 3-link arm's box q0 +- eps (qd = 0), as the
   solver's variational evaluators give it: enclosure width / sampled spread (central
   differences of Pinocchio's ``aba`` at 300 points of the box), worst and median entry.
2. The 3-link planar arm (``models.planar.planar_chain(3)``, mode i rhs), q(0) in q0 +-
   eps, qd(0) = 0, T = 2, order 8, tol 1e-10: first-order sets with ``absorb=True``
   (errors become parameters, merged at the cap, recentred) and second-order sets
   (``set_order=2``), each in affine arithmetic and with Taylor-model Jacobians.
3. UR5 and Panda (fingers locked), eps = 1e-3, T = 1, first-order sets with absorb.

Ratio = enclosure hull width / sampled hull width, worst component, at the last output
time reached (trajectories from the corners, random points and centre of the box by
DOP853 at rtol 1e-12 with Pinocchio's ``aba``: ``bench_robots.Oracle``); sound = every
sample inside every output box. Runs are capped at ``--cap`` seconds of wall time
(``cap`` in the reached column). Walls are of one run on a shared machine.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np


import bench_robots as br
from verified.series.affine_taylor import AffineTaylorODE
from verified.driver.hooks import StopAfterWall
from verified.arith.interval import Interval
from verified.solver import VerifiedODE, solve
from verified.series.taylor import TaylorODE
from verified.series.taylor_model import TaylorModelODE
from verified.series.variational import variational_graph


def _chain(name):
    if name == "arm3":
        from models.planar import planar_chain
        return planar_chain(3), br.Q0_ARM3
    if name == "ur5":
        from models.robots import ur5
        return ur5(), br.Q0_UR5
    from models.robots import panda_arm
    return panda_arm(), br.Q0_PANDA


def jacobian_table(eps_list=(0.01, 0.05)):
    from mbs.simulate import system_for
    chain, q0 = _chain("arm3")
    g = system_for(chain, "i").rhs
    vg = variational_graph(g)
    n = g.n_inputs
    f = br.pinocchio_rhs(chain)
    rows = []
    for eps in eps_list:
        lo, hi = br.chain_box(q0, eps)
        box = Interval(np.r_[lo, np.eye(n).ravel()][None], np.r_[hi, np.eye(n).ravel()][None])
        rng = np.random.default_rng(0)
        pts = lo + (hi - lo) * rng.random((300, n))
        step = 1e-6
        D = np.empty((len(pts), n, n))
        for j in range(n):
            dp, dm = pts.copy(), pts.copy()
            dp[:, j] += step
            dm[:, j] -= step
            D[:, :, j] = ((f(dp.T) - f(dm.T)) / (2 * step)).T
        k = len(q0)
        spread = np.ptp(D, axis=0)[k:, :k]  # d qdd / dq
        row = [f"{eps:g}"]
        for ev in (TaylorODE(vg), AffineTaylorODE(vg, fresh_symbols=0), TaylorModelODE(vg)):
            w = ev.coefficients(box, 1)[0, 1, n:].width().reshape(n, n)[k:, :k] / spread
            row.append(f"{w.max():.3g} / {np.median(w):.3g}")
        rows.append(row)
    return ["eps", "interval: worst / median", "affine", "taylor_model"], rows


def robot_run(name, eps, T, arithmetic, set_order, cap, order=8, tol=1e-10):
    from mbs.simulate import output_times, system_for
    chain, q0 = _chain(name)
    lo, hi = br.chain_box(q0, eps)
    ode = VerifiedODE(system_for(chain, "i").rhs, arithmetic)
    t0 = time.perf_counter()
    sol = solve(ode, Interval(lo, hi), (0.0, T), t_eval=output_times(0.0, T, T / 20), order=order, tol=tol,
                absorb=(set_order == 1), set_order=set_order, hooks=[StopAfterWall(cap)])
    wall = time.perf_counter() - t0
    oracle = br.Oracle(br.pinocchio_rhs(chain), br.sample_points(lo, hi, 40), T, br.chain_names(chain))
    k = len(sol.t) - 1
    inside = all(br.inside_boxes(oracle.states(t), b).all() for t, b in zip(sol.t, sol.boxes))
    ratio = float((sol.hull[k].width() / np.maximum(oracle.hull_width(sol.t[k]), 1e-300)).max()) if k else float("nan")
    tag = "" if sol.success else (" cap" if sol.status == "stopped" else " bd")
    reached = f"{T:g}" if sol.success else f"{sol.t_reached:.3g}{tag}"
    return [reached, f"{ratio:.3g} @ {sol.t[k]:.2g}" if k else "—", f"{wall:.1f}", "SOUND" if inside else "UNSOUND"]


def table(rows, head):
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(out)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="arm3, first-order sets only")
    ap.add_argument("--cap", type=float, default=300.0, help="wall-clock cap per run (s)")
    args = ap.parse_args(argv)
    br.warm_up()
    head, rows = jacobian_table()
    print("### 1. d qdd / dq over the 3-link arm's box: enclosure width / sampled spread\n")
    print(table(rows, head) + "\n", flush=True)

    settings = [("affine", 1), ("taylor_model", 1)] + ([] if args.quick else [("affine", 2), ("taylor_model", 2)])
    head = ["eps"] + [f"{a} set_order={s}: reached / ratio @ t / wall s / sound" for a, s in settings]
    rows = []
    for eps in (1e-4, 1e-3, 1e-2):
        row = [f"{eps:g}"]
        for a, s in settings:
            r = robot_run("arm3", eps, 2.0, a, s, args.cap)
            print(f"arm3 eps {eps:g} {a} set_order={s}: {r}", file=sys.stderr, flush=True)
            row.append(" / ".join(r))
        rows.append(row)
    print("### 2. 3-link arm, T = 2 (target: eps = 0.01, ratio <= 1.5, <= 60 s)\n")
    print(table(rows, head) + "\n", flush=True)
    if args.quick:
        return
    settings = [("affine", 1), ("taylor_model", 1)]
    head = ["robot"] + [f"{a} set_order={s}: reached / ratio @ t / wall s / sound" for a, s in settings]
    rows = []
    for name in ("ur5", "panda"):
        row = [name]
        for a, s in settings:
            r = robot_run(name, 1e-3, 1.0, a, s, args.cap)
            print(f"{name} {a}: {r}", file=sys.stderr, flush=True)
            row.append(" / ".join(r))
        rows.append(row)
    print("### 3. UR5 and Panda, eps = 1e-3, T = 1 (target: ratio <= 1.5, <= 60 s)\n")
    print(table(rows, head) + "\n", flush=True)


if __name__ == "__main__":
    # one core against one core (CAPD, earlier runs): workers=None stays one in-process
    # batch here (bench_parallel measures the cluster; explicit workers= are kept)
    import verified.execution.plan
    verified.execution.plan.DEFAULT_PARALLEL = False
    main()

"""How much the contractors of verified/consistency/contractor.py narrow, and what they cost.

    python benchmarks/bench_contractor.py [--boxes 2000] [--no-lohner]

On the paper's double pendulum (m = l = 1, g = 9.81; models/double_pendulum.py):

1. Energy shell: boxes much wider than the shell H <= Hmax (Hmax = upper end of H over
   the initial box eq. (25)), contracted by :class:`verified.consistency.contractor.EnergyShell`.
2. HC4 on H: boxes around the initial box widened by a factor, contracted under
   H(x) in [H(X0)] (a conservative system keeps H in the initial enclosure).
3. Linear row: QR-Lohner sets c + C r0 + Q r captured from verified.solver.solve (a
   hook) at several times of single-box runs from pieces of eq. (25); the relation
   H(x) - h = 0 in mean-value form narrows r (the error part); reported as width
   ratios of r and of the sets' hulls. Two versions of h: an interval (H over the
   piece: uncorrelated) and h = H(x0) with x0 = c0 + r0 the set's own initial
   parameters (correlated, as an H_V state carried inside the set would be).

Ratios are contracted width / original width (mean over boxes and, where stated, the
worst component); times are per box (wall clock, after a warm-up).
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from models import double_pendulum as dp
from verified.arith import linalg
from verified.consistency.contractor import HC4, EnergyShell, contract_linear_row, mean_value_row
from verified.graph.evaluate import eval_interval
from verified.graph import trace
from verified.arith.interval import Interval


def shell():
    Mg = trace(lambda q, p: [e for row in dp.mass_matrix(q) for e in row], 2)
    Vg = trace(lambda q, p: [-(dp.M1 + dp.M2) * dp.G * dp.L1 * np.cos(q[0])
                             - dp.M2 * dp.G * dp.L2 * np.cos(q[0] + q[1])], 2)
    return EnergyShell(Mg, Vg)


def h_enclosure(H, pieces=256):
    """Enclosure of H over the initial box eq. (25) (x1 cut into pieces, hull)."""
    lo, hi = dp.initial_box()
    X0 = Interval(lo, hi).reshape(1, 4).subdivide([pieces, 1, 1, 1]).reshape(-1, 4)
    v = eval_interval(H, X0)[:, 0]
    return float(v.lo.min()), float(v.hi.max())


def timed(fn, repeat=3):
    fn()  # warm-up (numba kernels, caches)
    best = np.inf
    out = None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return out, best


def report(name, before: Interval, after, empty, seconds):
    B = before.shape[0]
    keep = ~empty
    ratio = after.width()[keep] / before.width()[keep]
    print(f"{name}: {B} boxes, {empty.sum()} proven empty, {1e6 * seconds / B:.1f} us/box")
    print("   mean width ratio per component:", np.array2string(ratio.mean(0), precision=3))
    print("   worst (largest) ratio per component:", np.array2string(ratio.max(0), precision=3))


def bench_shell(nb, rng):
    sh = shell()
    H = dp.energy_graph()
    hlo, hmax = h_enclosure(H)
    print(f"H over the initial box eq. (25): [{hlo:.6f}, {hmax:.6f}]")
    # (a) the whole state space a breakdown could produce: q in [-pi, pi]^2, qd in [-50, 50]^2
    wide = Interval(np.array([[-np.pi, -np.pi, -50.0, -50.0]]), np.array([[np.pi, np.pi, 50.0, 50.0]]))
    res, sec = timed(lambda: sh.contract(wide, hmax))
    print(f"energy shell, one box [-pi, pi]^2 x [-50, 50]^2 -> "
          f"[{', '.join(f'[{a:.3f}, {b:.3f}]' for a, b in zip(res.boxes.lo[0], res.boxes.hi[0]))}] "
          f"in {1e3 * sec:.1f} ms")
    # (b) a batch: centres near the trajectory's states, widths 0.2 rad in q and 40 rad/s in qd
    c = dp.initial_point() + rng.normal(0, [0.5, 0.5, 2.0, 2.0], (nb, 4))
    w = np.array([0.1, 0.1, 20.0, 20.0])
    boxes = Interval(c - w, c + w)
    res, sec = timed(lambda: sh.contract(boxes, hmax))
    report("energy shell, batch (q +- 0.1, qd +- 20)", boxes, res.boxes, res.empty, sec)
    res, sec = timed(lambda: sh.contract(boxes, hmax, pieces=16))
    report("energy shell, same batch, pieces=16", boxes, res.boxes, res.empty, sec)


def bench_hc4(nb, rng):
    H = dp.energy_graph()
    hlo, hhi = h_enclosure(H)
    lo, hi = dp.initial_box()
    hc = HC4(H)
    for factor in (10, 100):
        c = (lo + hi) / 2 + rng.normal(0, 0.02, (nb, 4))
        rad = np.maximum((hi - lo) / 2, 1e-3) * factor
        boxes = Interval(c - rad, c + rad)
        res, sec = timed(lambda: hc.contract(boxes, [hlo], [hhi], max_iter=3))
        report(f"HC4 on H in [H(X0)], boxes {factor}x eq. (25) (min radius 1e-3)", boxes, res.boxes, res.empty, sec)
    c = dp.initial_point() + rng.normal(0, [0.3, 0.3, 1.0, 1.0], (nb, 4))
    rad = np.array([0.05, 0.05, 20.0, 20.0])
    boxes = Interval(c - rad, c + rad)
    res, sec = timed(lambda: hc.contract(boxes, [hlo], [hhi], max_iter=3))
    report("HC4 on H in [H(X0)], boxes q +- 0.05, qd +- 20", boxes, res.boxes, res.empty, sec)


def capture_lohner_sets(box, times):
    """QR-Lohner sets of a single-box double pendulum run from ``box`` at the given
    times (None when this checkout's solver has no hooks or the run fails)."""
    try:
        from verified.driver.hooks import Hook
        from verified.solver import solve
    except ImportError:
        return None
    got = {}

    class Grab(Hook):
        def after_step(self, step, sets, run):
            t = float(getattr(step, "t", np.nan))
            for T in times:
                if T not in got and t >= T:
                    got[T] = (t, sets)
            return None

    try:
        solve(dp.rhs_graph(), box, (0.0, max(times) + 1e-9), hooks=[Grab()])
    except Exception as exc:  # the solver is being restructured: report, do not fail
        print(f"(could not capture Lohner sets: {type(exc).__name__}: {exc})")
        return None
    return got


def energy_difference_graph(H):
    """(x, x0) -> H(x) - H(x0): zero on every trajectory of a conservative system from
    x0; over the joint set (x, x0) = (c, c0) + [[C, Q], [I, 0]] (r0, r) it plays the
    role of H(x) - h with h the H_V state carried in the set (correlated with r0)."""
    from verified.graph import GraphBuilder
    from verified.graph.ops import embed
    n = H.n_inputs
    b = GraphBuilder(2 * n)
    xs = [b.input(i) for i in range(2 * n)]
    (u,) = embed(b, H, xs[:n])
    (v,) = embed(b, H, xs[n:])
    return b.build([b.sub(u, v)], ["G"])


def bench_linear_row(times=(0.2, 0.4, 0.6, 0.8, 1.0), pieces=64, which_pieces=(0, 31, 63)):
    """One piece of eq. (25) (x1 cut into ``pieces``) per run; h = H over that piece
    (a conservative system: the H_V state keeps that enclosure)."""
    H = dp.energy_graph()
    G = energy_difference_graph(H)
    lo, hi = dp.initial_box()
    all_pieces = Interval(lo, hi).reshape(1, 4).subdivide([pieces, 1, 1, 1]).reshape(-1, 4)
    for k in which_pieces:
        box = all_pieces[k]
        hv = eval_interval(H, box.reshape(1, 4).subdivide([16, 1, 1, 1]).reshape(-1, 4))[:, 0]
        hlo, hhi = float(hv.lo.min()), float(hv.hi.max())
        got = capture_lohner_sets(box, times)
        if not got:
            print("linear row: no Lohner sets captured")
            return
        print(f"linear row, piece {k} of {pieces}: h in [{hlo:.6f}, {hhi:.6f}] (width {hhi - hlo:.2e})")
        for T in times:
            if T not in got:
                print(f"   t = {T}: the run did not get there")
                continue
            t, s = got[T]
            B, n = s.c.shape
            A = np.concatenate([s.C, s.Q], axis=2)
            R = Interval(np.concatenate([s.r0.lo, s.r.lo], 1), np.concatenate([s.r0.hi, s.r.hi], 1))
            which = np.r_[np.zeros(n, bool), np.ones(n, bool)]  # narrow the error part r only

            def run():
                a, g0, rem = mean_value_row(H, s.c, A, R, Interval(np.full(B, hlo), np.full(B, hhi)))
                return contract_linear_row(a, g0, R, rem, which=which, sweeps=2)

            # correlated: h = H(x0), x0 = c0 + r0 (the set's own r0; C = I at t = 0)
            c0 = box.mid().reshape(1, n)
            Abig = np.concatenate([A, np.concatenate([np.broadcast_to(np.eye(n), (B, n, n)),
                                                      np.zeros((B, n, n))], axis=2)], axis=1)
            cbig = np.concatenate([s.c, np.broadcast_to(c0, (B, n))], axis=1)

            def run_corr():
                a, g0, rem = mean_value_row(G, cbig, Abig, R)
                return contract_linear_row(a, g0, R, rem, which=which, sweeps=2)

            (R3, _), sec3 = timed(run_corr)
            (R2, empty), sec = timed(run)
            r_ratio = (R2.width()[:, n:] / np.maximum(R.width()[:, n:], 1e-300))
            hull0 = linalg.matvec(s.C, s.r0) + linalg.matvec(s.Q, s.r) + s.c
            r_new = Interval(R2.lo[:, n:], R2.hi[:, n:])
            hull1 = linalg.matvec(s.C, s.r0) + linalg.matvec(s.Q, r_new) + s.c
            Hset = eval_interval(H, hull0)[:, 0]
            print(f"   t = {t:.3f}: {1e6 * sec / B:.0f} us/set; H over the hull width {Hset.width()[0]:.2e}; "
                  f"r widths {np.array2string(R.width()[0, n:], precision=2)} -> ratio "
                  f"{np.array2string(r_ratio[0], precision=3)}; hull width ratio "
                  f"{np.array2string((hull1.width() / hull0.width())[0], precision=3)}")
            r3 = Interval(R3.lo[:, n:], R3.hi[:, n:])
            hull3 = linalg.matvec(s.C, s.r0) + linalg.matvec(s.Q, r3) + s.c
            print(f"      h = H(x0) correlated ({1e6 * sec3 / B:.0f} us/set): r ratio "
                  f"{np.array2string((R3.width()[:, n:] / np.maximum(R.width()[:, n:], 1e-300))[0], precision=3)}"
                  f"; hull width ratio {np.array2string((hull3.width() / hull0.width())[0], precision=3)}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--boxes", type=int, default=2000)
    ap.add_argument("--no-lohner", action="store_true", help="skip the solver run for the linear row")
    args = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    bench_shell(args.boxes, rng)
    bench_hc4(args.boxes, rng)
    if not args.no_lohner:
        bench_linear_row()


if __name__ == "__main__":
    # one core against one core (CAPD, earlier runs): workers=None stays one in-process
    # batch here (bench_parallel measures the cluster; explicit workers= are kept)
    import verified.execution.plan
    verified.execution.plan.DEFAULT_PARALLEL = False
    main()

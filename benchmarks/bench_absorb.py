"""Absorbing the error part into parameters (``solve(..., absorb=True)``, issue 17):
the same runs with and without it, side by side in one run.

Run:  python benchmarks/bench_absorb.py            # every case (~3-4 min)
      python benchmarks/bench_absorb.py --quick    # the short ones (~40 s)

A first-order set is ``c + C r0 + Q r``; the interval error vector ``r`` is multiplied
by ``|Q'^-1 J Q|`` every step, which wraps at the rate of ``||J||`` rather than at the
flow's growth. ``absorb=True`` turns ``Q r`` into new parameters (columns of the float
matrix ``C``) once it is 10 % of the carried part, up to 8 parameters per state
(:meth:`verified.sets.first_order.DoubletonSets.absorb_error`).

Cases:

* the paper's double pendulum (eq. 22 traced, box eq. 25, ``x1(0)`` split into pieces,
  interval arithmetic, order 12, tol 1e-10): ratio = enclosure hull width / true hull
  width (``bench_solver.true_hull_widths``, 2001 points), worst component, at T;
* the 3-link planar arm (``models.planar.planar_chain(3)``, mode i rhs, affine), q(0) in
  q0 +- eps, qd(0) = 0, T = 2; UR5 and Panda at eps = 1e-3, T = 1 (order 8, tol 1e-10):
  ratio against trajectories sampled with Pinocchio's ``aba`` and DOP853
  (``bench_robots.Oracle``) at the last output time reached;
* the counter-case: the 2-link arm under computed-torque control with a 10 % mass error
  (tests/mbs/test_frames.py), where absorbing breaks down earlier; why absorb is off by
  default.

Columns: reached (T or the break-down time), ratio @ t, steps, wall (s), absorbed (how
many times the error part became parameters). Walls are of one run on a shared machine:
compare within a row.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import bench_robots as br
import bench_solver
from verified.graph import trace
from verified.arith.interval import Interval
from verified.solver import VerifiedODE, solve


def dp_case(T, pieces):
    from models import double_pendulum as dp
    ode = VerifiedODE(trace(dp.rhs, 4), "interval")
    lo, hi = dp.initial_box()
    true = bench_solver.true_hull_widths(T, 2001)

    def run(absorb):
        t0 = time.perf_counter()
        sol = solve(ode, Interval(lo, hi), (0.0, T), subdivision=[pieces, 1, 1, 1], order=12, tol=1e-10,
                    absorb=absorb)
        wall = time.perf_counter() - t0
        ratio = float((sol.hull[-1].width() / true).max()) if sol.success else float("nan")
        return sol, ratio, T if sol.success else float("nan"), wall

    return f"double pendulum, {pieces} pieces, T = {T:g}", run


def robot_case(name, eps, T, order, tol):
    from mbs.simulate import output_times, system_for
    if name == "arm3":
        from models.planar import planar_chain
        chain, q0 = planar_chain(3), br.Q0_ARM3
    elif name == "ur5":
        from models.robots import ur5
        chain, q0 = ur5(), br.Q0_UR5
    else:
        from models.robots import panda_arm
        chain, q0 = panda_arm(), br.Q0_PANDA
    lo, hi = br.chain_box(q0, eps)
    ode = VerifiedODE(system_for(chain, "i").rhs, "affine")
    oracle = br.Oracle(br.pinocchio_rhs(chain), br.sample_points(lo, hi, 40), T, br.chain_names(chain))
    te = output_times(0.0, T, T / 20)

    def run(absorb):
        t0 = time.perf_counter()
        sol = solve(ode, Interval(lo, hi), (0.0, T), t_eval=te, order=order, tol=tol, absorb=absorb)
        wall = time.perf_counter() - t0
        k = len(sol.t) - 1
        inside = all(br.inside_boxes(oracle.states(t), b).all() for t, b in zip(sol.t, sol.boxes))
        if not inside:
            raise AssertionError(f"{name}: a sampled trajectory left the enclosure (absorb={absorb})")
        ratio = float((sol.hull[k].width() / np.maximum(oracle.hull_width(sol.t[k]), 1e-300)).max()) if k else float("nan")
        return sol, ratio, float(sol.t[k]), wall

    return f"{name}, eps = {eps:g}, T = {T:g}", run


def controlled_case():
    from mbs.control import ComputedTorque
    from mbs.simulate import simulate
    q0 = np.array([0.5, -0.3])
    x0 = Interval(np.r_[q0 - 1e-2, -1e-2, -1e-2], np.r_[q0 + 1e-2, 1e-2, 1e-2])

    def run(absorb):
        t0 = time.perf_counter()
        sol = simulate("planar2", x0, 0.6, mode="i", output_dt=0.2, order=10, progress=False, absorb=absorb,
                       control=ComputedTorque(kp=25.0, kd=10.0, q_ref=q0, nominal={"mass_scale": 1.1}))
        wall = time.perf_counter() - t0
        return sol, float("nan"), float(sol.t[-1]), wall

    return "2-link arm, computed torque (counter-case), T = 0.6", run


def cell(sol, ratio, t, wall):
    reached = f"{sol.t_reached:.3g}" + ("" if sol.success else " bd")
    r = "—" if not np.isfinite(ratio) else f"{ratio:.4g} @ {t:.3g}"
    return [reached, r, str(sol.stats["steps"]), f"{wall:.1f}", str(sol.stats.get("absorbed", 0))]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    br.warm_up()
    cases = [dp_case(1.0, 256), dp_case(2.0, 256), robot_case("arm3", 1e-6, 2.0, 12, 1e-12)]
    if not args.quick:
        cases += [dp_case(3.0, 256), dp_case(3.0, 1024), robot_case("arm3", 1e-4, 2.0, 12, 1e-12),
                  robot_case("arm3", 1e-2, 2.0, 8, 1e-10), robot_case("ur5", 1e-3, 1.0, 8, 1e-10),
                  robot_case("panda", 1e-3, 1.0, 8, 1e-10), controlled_case()]
    head = ["case", "off: reached", "ratio @ t", "steps", "wall s",
            "on: reached", "ratio @ t", "steps", "wall s", "absorbed"]
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for label, run in cases:
        off, on = cell(*run(False)), cell(*run(True))
        print("| " + " | ".join([label] + off[:4] + on) + " |", flush=True)


if __name__ == "__main__":
    # one core against one core (CAPD, earlier runs): workers=None stays one in-process
    # batch here (bench_parallel measures the cluster; explicit workers= are kept)
    import verified.execution.plan
    verified.execution.plan.DEFAULT_PARALLEL = False
    main()

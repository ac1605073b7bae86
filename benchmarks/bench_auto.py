"""Issue 40: what a user gets with no solver settings, side by side in one run.

For every case, three runs: the default before methods were objects (``method="lohner"``:
QR-Lohner first-order sets, order 12, tol 1e-10), ``method="auto"`` (the default now:
no solver settings at all) and the best hand-picked setting measured before. Each row:
how far it got, CPU seconds, and the worst ratio of the final enclosure's width to
the width of densely sampled true states (DOP853, rtol = atol = 1e-12; robots: with
Pinocchio's ``aba`` as the right-hand side, sharing no code with the library).

    python benchmarks/bench_auto.py                 # every case (~15-25 min on 2 cores)
    python benchmarks/bench_auto.py --only vdp,laub # some cases
    python benchmarks/bench_auto.py --quick         # short horizons (the test runs this)

Targets (issue 40): every case completes; the robots at ratio <= 1.5; ``auto`` within
1.5x of the best hand-picked CPU time at the same ratio.
"""
from __future__ import annotations

import argparse
import time
from dataclasses import dataclass, field

import numpy as np

from verified.graph import trace
from verified.driver.hooks import StopAfterWall
from verified.arith.interval import Interval

#: the hand-picked settings of the robots (docs/robots_benchmark.md, bench_robots case 8)
ROBOT_BEST = dict(method=None, order=8, tol=1e-10, error_basis="auto", set_order=2, params_per_state=12,
                  set_step="composition", arithmetic="taylor_model")
COMPOSITION = dict(order=12, tol=1e-10, error_basis="auto", set_order=2, set_step="composition",
                   arithmetic="taylor_model")


@dataclass
class Case:
    name: str
    T: float
    quick_T: float
    run: object                      # run(settings, T, cap) -> Solution
    sample: object                   # sample(T) -> sampled states at T (S, n)
    best: dict = field(default_factory=dict)
    best_label: str = ""


def _ode_case(name, f, n, x0, T, quick_T, best, label):
    g = trace(f, n)

    def run(settings, t_end, cap):
        from verified.solver import solve
        settings = {k: v for k, v in settings.items() if k != "before"}
        return solve(g, x0, (0.0, t_end), hooks=[StopAfterWall(cap)], **settings)

    def sample(t_end):
        from mbs.app.sampling import sample_initial_points, sample_trajectories
        pts = sample_initial_points(x0.lo, x0.hi, 400, seed=1)
        return sample_trajectories(g, pts, [t_end])[:, -1, :]
    return Case(name, T, quick_T, run, sample, best, label)


def vdp_like():
    """x' = y, y' = -x - 2 y x^2 from [-0.5, 0.5]^2 (issue 40)."""
    return _ode_case("x''=-x-2x^2x', T=3", lambda x, p: [x[1], -x[0] - 2 * x[1] * x[0] * x[0]], 2,
                     Interval([-0.5, -0.5], [0.5, 0.5]), 3.0, 0.5, dict(COMPOSITION, subdivision=2),
                     "composition, 2 x 2 pieces")


def laub_loomis(W=0.01):
    """ARCH-COMP Laub-Loomis with x7' = 1.8 x6 - 1.5 x2 x7 (Ariadne's and Flow*'s
    coefficient), box centre +- W, T = 20."""
    def f(x, p):
        x1, x2, x3, x4, x5, x6, x7 = x
        return [1.4 * x3 - 0.9 * x1, 2.5 * x5 - 1.5 * x2, 0.6 * x7 - 0.8 * x2 * x3, 2 - 1.3 * x3 * x4,
                0.7 * x1 - x4 * x5, 0.3 * x1 - 3.1 * x6, 1.8 * x6 - 1.5 * x2 * x7]
    c = np.array([1.2, 1.05, 1.5, 2.4, 1, 0.1, 0.45])
    return _ode_case(f"Laub-Loomis W={W:g}, T=20", f, 7, Interval(c - W, c + W), 20.0, 2.0,
                     dict(set_order=2), "second_order, one box")


def _old_default(settings: dict) -> dict:
    """``settings`` for ``simulate``: the "before" row without the energy-shell continuation
    of a passive chain's break-down, which the old default did not have."""
    settings = dict(settings)
    if settings.pop("before", False):
        settings["energy_shell"] = False
    return settings


def _chain_case(name, chain, q0, eps, T, quick_T, mode, best, label):
    n = chain.n
    q0 = np.asarray(q0, float)
    x0 = Interval(np.concatenate([q0 - eps, np.zeros(n)]), np.concatenate([q0 + eps, np.zeros(n)]))

    def run(settings, t_end, cap):
        from mbs.simulate import simulate
        settings = _old_default(settings)
        return simulate(chain, x0, t_end, mode=mode, progress=False, max_wall=cap, **settings)

    def sample(t_end):
        from mbs.app.sampling import Ensemble, passive_plant, sample_initial_points
        pts = sample_initial_points(x0.lo, x0.hi, 64, seed=1, corner_limit=64)
        return Ensemble(passive_plant(chain), pts, t_end, dense=False).final
    return Case(name, T, quick_T, run, sample, best, label)


def arm3_small(mode="i"):
    from models.planar import planar_chain
    return _chain_case(f"3-link arm +-1e-3, T=1, mode {mode}", planar_chain(3), (0.3, -0.5, 0.4), 1e-3, 1.0, 0.2,
                       mode, ROBOT_BEST, "composition, order 8, 12 params/state")


def arm3_wide():
    from models.planar import planar_chain
    return _chain_case("3-link arm +-0.01, T=2", planar_chain(3), (0.5, -0.3, 0.2), 0.01, 2.0, 0.2, "i",
                       dict(ROBOT_BEST, subdivision=[3, 3, 3, 1, 1, 1]), "composition, 27 pieces")


def ur5(mode="i"):
    from mbs import robots
    return _chain_case(f"UR5 +-1e-3, T=1, mode {mode}", robots.load("ur5"), (0.0, -1.0, 1.0, -1.0, -1.0, 0.0),
                       1e-3, 1.0, 0.1, mode, ROBOT_BEST, "composition, order 8, 12 params/state")


def panda(mode="i"):
    from mbs import robots
    return _chain_case(f"Panda +-1e-4, T=1, mode {mode}", robots.load("panda"),
                       (0.0, -0.5, 0.0, -2.0, 0.0, 1.5, 0.8), 1e-4, 1.0, 0.1, mode, ROBOT_BEST,
                       "composition, order 8, 12 params/state")


def _paper_case(name, model, box, T, quick_T, mode, best, label, rhs_f):
    def run(settings, t_end, cap):
        from mbs.simulate import simulate
        settings = _old_default(settings)
        return simulate(model, box, t_end, mode=mode, progress=False, max_wall=cap, **settings)

    def sample(t_end):
        from mbs.app.sampling import Ensemble, sample_initial_points
        pts = sample_initial_points(box.lo, box.hi, 400, seed=1)
        return Ensemble(rhs_f, pts, t_end, dense=False).final
    return Case(name, T, quick_T, run, sample, best, label)


def swinging():
    """The paper's pendulum below the top (models/scenes/pendulum_swinging.toml), mode ii."""
    from models import pendulum

    def f(X):
        return np.array(pendulum.rhs(X))
    return _paper_case("pendulum swinging, T=3, mode ii", "pendulum_paper", Interval([1.0, 0.0], [1.1, 0.1]), 3.0,
                       0.5, "ii", dict(COMPOSITION, set_order=2), "composition (the scene's)", f)


def double_pendulum(T):
    """The paper's double pendulum from box (25) (the shipped scene's), mode i."""
    from models import double_pendulum as dp
    lo, hi = dp.initial_box()

    def f(X):
        return np.array(dp.rhs(X))
    return _paper_case(f"double pendulum box (25), T={T:g}", "double_pendulum_paper", Interval(lo, hi), T, 0.3, "i",
                       dict(set_order=2, subdivision=[4, 4, 2, 1] if T <= 1 else [8, 4, 1, 1]),
                       "second_order, 32 pieces", f)


CASES = {"arm_small": arm3_small, "arm_small_ii": lambda: arm3_small("ii"), "arm_wide": arm3_wide,
         "ur5": ur5, "ur5_ii": lambda: ur5("ii"), "panda": panda, "panda_ii": lambda: panda("ii"),
         "dp1": lambda: double_pendulum(1.0), "dp3": lambda: double_pendulum(3.0), "swing": swinging,
         "vdp": vdp_like, "laub": laub_loomis}


def ratio(sol, states) -> float:
    """Worst component of (enclosure hull width) / (sampled hull width) at the last output."""
    enc = np.asarray(sol.hull[-1].width(), float)
    true = np.ptp(states, axis=0)
    ok = true > 1e-12
    return float(np.max(enc[ok] / true[ok])) if ok.any() else float("nan")


def run_case(key: str, quick: bool, cap: float, out=print):
    case = CASES[key]()
    T = case.quick_T if quick else case.T
    states = case.sample(T)
    rows = []
    # ("before": the old default, which also had no energy-shell continuation after a break-down)
    for label, settings in (("before (lohner)", dict(method="lohner", before=True)), ("auto", {}),
                            (f"best: {case.best_label}", {k: v for k, v in case.best.items() if k != "method"})):
        t0 = time.process_time()
        w0 = time.perf_counter()
        sol = case.run(settings, T, cap)
        cpu, wall = time.process_time() - t0, time.perf_counter() - w0
        r = ratio(sol, states) if sol.status == "completed" else float("nan")
        rows.append((label, sol.status, float(sol.t_reached), cpu, wall, r, getattr(sol, "method", "")))
        out(f"| {case.name} | {label} | {sol.status} | {sol.t_reached:.4g} | {cpu:.1f} | {wall:.1f} | "
            f"{r:.4g} | {getattr(sol, 'method', '')[:120]} |")
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default=",".join(CASES), help="comma-separated case keys: " + ", ".join(CASES))
    ap.add_argument("--quick", action="store_true", help="short horizons")
    ap.add_argument("--cap", type=float, default=300.0, help="wall-clock cap per run (s)")
    a = ap.parse_args(argv)
    print("| case | run | status | t reached | CPU s | wall s | ratio | method |")
    print("|---|---|---|---|---|---|---|---|")
    results = {}
    for key in a.only.split(","):
        results[key] = run_case(key.strip(), a.quick, a.cap)
    # auto against the best hand-picked setting, side by side
    print("\n| case | auto CPU / best CPU | auto ratio / best ratio |")
    print("|---|---|---|")
    for key, rows in results.items():
        auto, best = rows[1], rows[2]
        print(f"| {key} | {auto[3] / max(best[3], 1e-9):.2f} | {auto[5] / best[5] if best[5] == best[5] else float('nan'):.3f} |")
    return results


if __name__ == "__main__":
    main()

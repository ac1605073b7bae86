"""Issue 5's results: the energy consistency test in modes (i), (ii), (iii).

    python benchmarks/bench_consistency.py            # full (a few minutes on 2 cores)
    python benchmarks/bench_consistency.py --quick    # seconds; run by the tests
    python benchmarks/bench_consistency.py --only 7 --out docs   # docs/work_precision.{png,json}

Tables:
1. the paper's double pendulum (eq. 22, box 25): widths over time per mode, worst
   ratio to the sampled true hull, tests, pruned parts, time in the tests;
2. single-box break-down time per mode (paper: 0.56 s without, ~0.99 s with its test);
3. split strategies compared (same settings, mode iii);
4. mode (iii) with dH/dt unsimplified vs simplified to 0;
5. the pendulum of sec. 5.1: RA(t), t*, and the parts kept at t*;
6. the damped URDF double pendulum (example-robot-data) with an uncertain angle;
7. work-precision (issue 13): the same solver without the test, with the energy
   contraction, with contraction + pruning, with the energy shell, over piece counts;
   on the pendulum also second-order sets by composition without the energy
   (work_precision.png, work_precision.json in ``--out DIR``, default the current
   working directory; the docs' copies: ``--out docs``; 16 min);
8. long horizon (issue 13): the double pendulum to T = 5 with the test, second-order
   sets by composition, box (25) in 48 pieces along x1 (~20 min).
Ratios are measured side by side in one run (the machine is shared and noisy).
"""
from __future__ import annotations

import argparse
import os
import time
from typing import NamedTuple

import numpy as np

from mbs.simulate import simulate
from models import double_pendulum as dp
from models import pendulum as pd
from mbs.app.sampling import end_states, hull_widths, states_at
from verified.arith.interval import Interval


def sampled_hull(f, lo, hi, ts, n=401):
    """Widths (len(ts), n) of the hull of DOP853 trajectories (rtol = atol = 1e-12) from
    ``n`` points on the box's diagonal, lo to hi, at the times ``ts``."""
    return hull_widths(states_at(f, np.linspace(lo, hi, n), ts))


def _row(name, sol, true_w=None):
    w = sol.hull[-1].width() if sol.success else np.full(4, np.nan)
    ratio = float(np.max(w / true_w)) if (true_w is not None and sol.success) else float("nan")
    st = sol.stats
    return (f"{name:<28} {sol.status:<10} {sol.t_reached:6.3f}  {' '.join(f'{v:.5f}' for v in w)}  "
            f"{ratio:7.3f}  {st.get('tests', 0):5d} {st.get('pruned_boxes', 0):8d} {st.get('max_boxes', 0):6d} "
            f"{st.get('test_s', 0.0):7.2f} {st['wall_s']:7.2f}")


HEADER = (f"{'run':<28} {'status':<10} {'t_end':>6}  {'widths x1..x4 at t_end':<39}  {'ratio':>7}  "
          f"{'tests':>5} {'pruned':>8} {'sets':>6} {'test_s':>7} {'wall_s':>7}")


def double_pendulum_modes(T, pieces, quick):
    lo, hi = dp.initial_box()
    ts = np.round(np.arange(1, int(round(T / 0.1)) + 1) * 0.1, 12)
    true_w = sampled_hull(lambda x: dp.rhs(x), lo, hi, ts, n=101 if quick else 401)
    print(f"\n## 1. Double pendulum, box (25) split into {pieces} pieces along x1, T = {T}")
    print("(i)/(ii): numeric model of the DH chain; (iii): eq. (22)/(24); 'eq22 no test' isolates the test")
    print(HEADER)
    sols = {}
    runs = [("i", dict(mode="i")), ("ii (0.1 s, 10)", dict(mode="ii")), ("iii (0.01 s, 50)", dict(mode="iii")),
            ("iii (0.1 s, 10)", dict(mode="iii", test_interval=0.1, test_splits=10))]
    for name, kw in runs:
        sols[name] = simulate("double_pendulum_paper", Interval(lo, hi), T, output_dt=0.1,
                              subdivision=[pieces, 1, 1, 1], **kw)
        print(_row(name, sols[name], true_w[-1]), flush=True)
    from verified.solver import solve
    ref = solve(dp.rhs_graph(), Interval(lo, hi), (0, T), t_eval=ts, subdivision=[pieces, 1, 1, 1])
    print(_row("eq22 no test", ref, true_w[-1]))
    print("\nwidth over time divided by the sampled true hull (worst state):")
    print("t      " + " ".join(f"{k:>16}" for k in list(sols) + ["eq22 no test"]))
    for j, t in enumerate(ts):
        cells = []
        for s in list(sols.values()) + [ref]:
            k = j + 1
            cells.append(f"{np.max(s.hull[k].width() / true_w[j]):16.3f}" if k < len(s.t) else f"{'-':>16}")
        print(f"{t:4.1f}  " + " ".join(cells))
    a, b = sols["ii (0.1 s, 10)"], sols["iii (0.01 s, 50)"]
    k = min(len(a.t), len(b.t))
    if k > 1:
        dev = np.max(np.abs(a.hull[:k].width() - b.hull[:k].width()), axis=0)
        print(f"\nlargest width deviation (ii) vs (iii) per state up to t = {a.t[k - 1]:.1f}: "
              + ", ".join(f"{v:.4f}" for v in dev) + "   (paper: 0.0018, 0.0072, 0.0066, 0.0444)")
    return sols


def single_box_breakdown(T):
    lo, hi = dp.initial_box()
    print(f"\n## 2. Single-box break-down (box (25) unsplit, up to T = {T})")
    print(HEADER)
    runs = [("i", dict(mode="i")), ("ii", dict(mode="ii")), ("iii", dict(mode="iii")),
            ("iii refine='always'", dict(mode="iii", refine="always", max_boxes=512)),
            ("iii + backward depth 2", dict(mode="iii", backward_depth=2))]
    for name, kw in runs:
        s = simulate("double_pendulum_paper", Interval(lo, hi), T, **kw)
        print(_row(name, s), flush=True)
    from verified.solver import solve
    print(_row("eq22 no test", solve(dp.rhs_graph(), Interval(lo, hi), (0, T))))
    print("(paper: VALENCIA-IVP 0.56 s without its tests, about 0.99 s with them)")
    # second-order sets by composition (issue 17's solver): the same test on them, to T = 3
    # (near its break-down the test cuts sets into parts that crawl on: a 120-s cap)
    so2 = dict(set_order=2, set_step="composition", arithmetic="taylor_model", error_basis="auto", order=6,
               tol=1e-10, params_per_state=12, progress=False, max_wall=120.0)
    print("second-order sets by composition (order 6, tol 1e-10, 'auto', 12 parameters per state), to T = 3, "
          "120-s cap:")
    for name, kw in [("i, composition", dict(mode="i")), ("ii, composition", dict(mode="ii")),
                     ("ii, composition, contract only", dict(mode="ii", prune=False)),
                     ("iii, composition", dict(mode="iii"))]:
        s = simulate("double_pendulum_paper", Interval(lo, hi), 3.0, **kw, **so2)
        print(_row(name, s), flush=True)


def strategies(T, pieces):
    lo, hi = dp.initial_box()
    true_w = sampled_hull(lambda x: dp.rhs(x), lo, hi, np.array([T]), n=201)[-1]
    print(f"\n## 3. Split strategies, mode iii (tests every 0.05 s, 16 parts), {pieces} pieces, T = {T}")
    print(HEADER)
    from verified.solver import solve
    print(_row("eq22 no test", solve(dp.rhs_graph(), Interval(lo, hi), (0, T), subdivision=[pieces, 1, 1, 1]), true_w))
    for strat in ("gradient", "widest", "grid"):
        s = simulate("double_pendulum_paper", Interval(lo, hi), T, mode="iii", subdivision=[pieces, 1, 1, 1],
                     split_strategy=strat, test_interval=0.05, test_splits=16, max_boxes=1024)
        print(_row(strat, s, true_w), flush=True)


def simplified_vs_not(T, pieces):
    lo, hi = dp.initial_box()
    true_w = sampled_hull(lambda x: dp.rhs(x), lo, hi, np.array([T]), n=201)[-1]
    print(f"\n## 4. Mode iii: dH/dt unsimplified (integrated) vs simplified to 0 (0.05 s, 16 parts), {pieces} pieces, T = {T}")
    print(HEADER)
    for er in ("unsimplified", "simplified"):
        s = simulate("double_pendulum_paper", Interval(lo, hi), T, mode="iii", subdivision=[pieces, 1, 1, 1],
                     energy_rate=er, test_interval=0.05, test_splits=16, max_boxes=1024)
        print(_row(er, s, true_w), flush=True)


def pendulum_ra():
    lo, hi = pd.initial_box()
    print("\n## 5. Pendulum of sec. 5.1, box [2.1, 2.2] x [3.1, 3.2], mode iii (dH/dt unsimplified)")
    s = simulate("pendulum_paper", Interval(lo, hi), 1.0, mode="iii", test_interval=0.1, test_splits=50)
    rec = s.consistency
    print(f"status {s.status}, {s.stats['tests']} tests, {s.stats['pruned_boxes']} parts pruned, "
          f"final widths {s.hull[-1].width()}")
    for i in range(0, len(rec.ra_t), max(1, len(rec.ra_t) // 12)):
        print(f"  t = {rec.ra_t[i]:.3f}  RA = {rec.ra[i]:.5f}  H_H = [{rec.h_h.lo[i]:.4f}, {rec.h_h.hi[i]:.4f}]"
              f"  H_V = [{rec.h_v.lo[i]:.4f}, {rec.h_v.hi[i]:.4f}]")
    first = rec.tests[0]
    print(f"first test t* = {first.t:.3f}: {int(first.kept.sum())} of {first.kept.size} parts kept, "
          f"H_V = {first.h_v}")


def urdf_robot(T):
    from models.robots import double_pendulum
    chain = double_pendulum()
    num = chain.numeric()
    lo = np.array([np.pi - 0.3, 0.0, 0.0, 0.0])
    hi = np.array([np.pi - 0.29, 0.0, 0.0, 0.0])
    true_w = sampled_hull(lambda x: num.rhs(list(x)), lo, hi, np.array([T]), n=101)[-1]
    print(f"\n## 6. Damped URDF double pendulum (example-robot-data, damping 0.05), q1(0) in [pi-0.3, pi-0.29],"
          f" 8 pieces, T = {T}")
    print(HEADER)
    for mode in ("i", "ii", "iii"):
        s = simulate(chain, Interval(lo, hi), T, mode=mode, subdivision=[8, 1, 1, 1], test_interval=0.05,
                     test_splits=10)
        print(_row(mode, s, true_w), flush=True)


def long_horizon(T=5.0, pieces=48, cap=900.0):
    """Issue 13's long-horizon target: box (25) to T = 5 with the test (ratio, aim <= 2),
    and the same solver without it (eq. (22) through ``solve``; mode i)."""
    from verified.driver.hooks import StopAfterWall
    from verified.solver import solve
    lo, hi = dp.initial_box()
    ts = np.round(np.arange(1, 6) * (T / 5), 12)  # five output times
    true_w = sampled_hull(lambda x: dp.rhs(x), lo, hi, ts, n=401)
    so2 = dict(set_order=2, set_step="composition", arithmetic="taylor_model", error_basis="auto", order=6,
               tol=1e-10, params_per_state=12)
    print(f"\n## 8. Long horizon: box (25) in {pieces} pieces along x1, T = {T}, second-order sets by "
          f"composition (order 6, tol 1e-10, 'auto', 12 parameters per state), {cap:.0f}-s cap per run")
    print("(i)/(ii): numeric model of the DH chain; (iii): eq. (22)/(24); tests as the modes' defaults")
    print(HEADER)
    sols = {"eq22 no test": solve(dp.rhs_graph(), Interval(lo, hi), (0, T), t_eval=ts,
                                  subdivision=[pieces, 1, 1, 1], hooks=[StopAfterWall(cap)], **so2)}
    print(_row("eq22 no test", sols["eq22 no test"], true_w[-1]), flush=True)
    # mode iii at the paper's settings (tests every 0.01 s, 50 parts) reached 3.9 s of 5 in
    # 600 s with 32 pieces, 434 s of it in tests (33,072 parts pruned): tested every 0.1 s here
    for name, kw in [("i", dict(mode="i")), ("ii (0.1 s, 10)", dict(mode="ii")),
                     ("iii (0.1 s, 10)", dict(mode="iii", test_interval=0.1, test_splits=10))]:
        sols[name] = simulate("double_pendulum_paper", Interval(lo, hi), T, output_dt=T / 5,
                              subdivision=[pieces, 1, 1, 1], progress=False, max_wall=cap, **kw, **so2)
        print(_row(name, sols[name], true_w[-1]), flush=True)
    print("\nworst width ratio to the sampled hull per output time:")
    print("t     " + " ".join(f"{k:>14}" for k in sols))
    for j, t in enumerate(ts):
        cells = []
        for name, s in sols.items():
            k = int(np.searchsorted(s.t, t - 1e-9))
            ok = k < len(s.t) and abs(s.t[k] - t) < 1e-9
            cells.append(f"{np.max(s.hull[k].width() / true_w[j]):14.3f}" if ok else f"{'-':>14}")
        print(f"{t:5.2f} " + " ".join(cells))
    return sols


def _test_for(system, **kw):
    from verified.consistency.energy_test import EnergyTest
    return EnergyTest(system.energy, system.energy_rate, **kw)  # "derive", "zero" or a graph (verified.consistency.energy_rate)


def _shell(mod, lo, hi):
    """``(EnergyShell, hmax)`` of item 1 (``verified.consistency.energy_shell``) as ``simulate(...,
    energy_shell=True)`` builds them (:func:`mbs.simulate.energy_shell_of`), from the
    model's chain: the same physics as eq. 18 / 22, checked against Pinocchio; both
    pendulums are conservative."""
    from mbs.simulate import energy_shell_of
    return energy_shell_of((pd.chain() if mod is pd else dp.dh_chain()).numeric(), Interval(lo, hi))


class _Variant(NamedTuple):
    name: str
    test: dict | None  # EnergyTest keywords, or None: no test
    shell: bool  # the energy shell as a hook
    solver: dict  # solve() keywords beyond the case's
    pendulum_only: bool = False


# the best solver without the energy on the pendulum, so that the shell is compared
# with it too: second-order sets by composition (issue 17), without and with the shell
_SECOND_ORDER = dict(set_order=2, set_step="composition", arithmetic="taylor_model", order=12, tol=1e-10)
_VARIANTS = [_Variant("no test", None, False, {}),
             _Variant("contraction", dict(contract="step", prune=False), False, {}),
             _Variant("contraction + prune", dict(contract="step"), False, {}),
             _Variant("energy shell", None, True, {}),
             _Variant("prune only", dict(contract="off"), False, {}),  # (full_variants only)
             _Variant("no test, second order", None, False, _SECOND_ORDER, pendulum_only=True),
             _Variant("energy shell, second order", None, True, _SECOND_ORDER, pendulum_only=True)]
# branch and prune multiplies the sets: the test's variants (and the second-order runs,
# 94 s at 16 x 16) stop at 16 x 16 on the pendulum (16 x 16 with pruning took ~160 s)
_LARGEST_TESTED_GRID = 16
# and each run with the test stops after this wall time (status "stopped"): on the
# pendulum with "auto" the 4 x 4 grid with pruning ran > 10 min; with a 300-s cap it
# had reached 2.60 s of 3
_TEST_WALL_CAP = 150.0


def work_precision(out_json="work_precision.json", plot="work_precision.png", quick=False,
                   full_variants=False, out="."):
    """Worst ratio (widest state / sampled true hull) against wall time over piece
    counts, the same solver with and without the energy: mode (iii)'s graphs (eq. 22 /
    18) without a test, with the energy contraction every step only, with contraction +
    branch and prune at the per-set RA maxima (modes ii/iii's default), and with the
    energy shell ``H(x) <= hmax`` (item 1, ``simulate(energy_shell=True)``) and no test.
    ``out_json`` and ``plot`` are relative to the directory ``out`` (None: not written)."""
    import json
    from mbs.simulate import system_for
    from verified.consistency.energy_shell import EnergyShellHook
    from verified.driver.hooks import StopAfterWall
    from verified.sets.bases import BlockBasis
    from verified.solver import solve
    # pendulum: "auto" (with "qr" no run without the shell reaches T = 3 below 64 x 64)
    cases = [("double pendulum T=1", "double_pendulum_paper", 1.0, [16, 64, 256], "auto"),
             ("double pendulum T=2", "double_pendulum_paper", 2.0, [64, 256], "qr"),
             ("pendulum T=3", "pendulum_paper", 3.0, [1, 4, 16, 64], "auto")]
    if quick:
        cases = [("double pendulum T=0.5", "double_pendulum_paper", 0.5, [4, 16], "auto")]
    # the test's runs keep h out of the states' error basis (BlockBasis): with one QR
    # basis over (x, h), h's error was rotated into the states' directions and the
    # test made the enclosures wider than without it
    variants = [v for v in _VARIANTS if full_variants or v.name != "prune only"]
    results = []
    print("\n## 7. Work-precision: the same solver (mode iii graphs) with and without the energy")
    print(f"{'case':<22} {'pieces':>6} {'variant':<22} {'status':<10} {'t':>6} {'ratio':>8} {'wall_s':>7}")
    for label, model, T, piece_list, basis in cases:
        mod = pd if model == "pendulum_paper" else dp
        lo, hi = mod.initial_box()
        f = (lambda x: pd.rhs(x)) if mod is pd else (lambda x: dp.rhs(x))
        n = lo.size
        true_w = sampled_hull(f, lo, hi, np.array([T]), n=201 if not quick else 51)[-1] if n == 4 else \
            _grid_hull(f, lo, hi, T)
        system = system_for(model, "iii")
        shell = _shell(mod, lo, hi) if any(v.shell for v in variants) else None
        for pieces in piece_list:
            sub = [pieces, 1, 1, 1] if n == 4 else [pieces, pieces]
            for v in variants:
                if v.pendulum_only and n != 2:
                    continue
                if (v.test is not None or v.solver) and n == 2 and pieces > _LARGEST_TESTED_GRID:
                    continue
                hooks = [EnergyShellHook(*shell)] if v.shell else []  # (a hook counts its own resets)
                if v.test is not None:
                    hooks.append(StopAfterWall(_TEST_WALL_CAP))
                s = solve(system.rhs, Interval(lo, hi), (0, T), t_eval=[T], subdivision=sub,
                          consistency=None if v.test is None else _test_for(system, **v.test),
                          error_basis=basis if v.test is None else BlockBasis(basis, n), hooks=hooks, **v.solver)
                _record(results, label, pieces, v.name, s, true_w, v.shell)
    if out_json or plot:
        os.makedirs(out, exist_ok=True)
    if out_json:
        with open(os.path.join(out, out_json), "w") as fh:
            json.dump(results, fh, indent=1)
    if plot:
        _plot_work_precision(results, os.path.join(out, plot))
    return results


def _record(results, label, pieces, vname, s, true_w, shell):
    """One work-precision row: appended to ``results`` and printed."""
    ratio = float(np.max(s.hull[-1].width() / true_w)) if s.success else float("nan")
    results.append(dict(case=label, pieces=pieces, variant=vname, status=s.status, t_reached=s.t_reached,
                        ratio=ratio, wall_s=s.stats["wall_s"], shell_resets=s.stats.get("shell_resets")))
    print(f"{label:<22} {pieces:>6} {vname:<22} {s.status:<10} {s.t_reached:6.3f} {ratio:8.4f} "
          f"{s.stats['wall_s']:7.2f}" + (f"  resets {s.stats.get('shell_resets', 0)}" if shell else ""), flush=True)


def _grid_hull(f, lo, hi, T, k=41):
    """Widths at T of the hull of DOP853 trajectories (rtol = atol = 1e-12) from a k^n grid."""
    g = np.array(np.meshgrid(*[np.linspace(a, b, k) for a, b in zip(lo, hi)])).reshape(lo.size, -1).T
    return hull_widths(end_states(f, g, T))


def _plot_work_precision(results, path):
    """One panel per case: worst ratio against wall time (log-log) where runs complete;
    where every run of a case breaks down, the break-down time against wall time."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    cases = list(dict.fromkeys(r["case"] for r in results))
    fig, axes = plt.subplots(1, len(cases), figsize=(5 * len(cases), 4), squeeze=False)
    for ax, case in zip(axes[0], cases):
        rows = [r for r in results if r["case"] == case]
        done = any(np.isfinite(r["ratio"]) for r in rows)
        for variant, mk in (("no test", "o-"), ("no test, second order", "o--"), ("contraction", "s-"),
                            ("contraction + prune", "^-"), ("energy shell", "D-"),
                            ("energy shell, second order", "D--"), ("prune only", "v--")):
            pts = [(r["wall_s"], r["ratio"] if done else r["t_reached"], r["pieces"]) for r in rows
                   if r["variant"] == variant and (np.isfinite(r["ratio"]) or not done)]
            if not pts:
                continue
            w, q, p = zip(*pts)
            ax.plot(w, q, mk, label=variant)
            for wi, qi, pi in pts:
                ax.annotate(str(pi), (wi, qi), fontsize=7, xytext=(3, 3), textcoords="offset points")
        ax.set_xscale("log")
        if done:
            fin = [r["ratio"] for r in rows if np.isfinite(r["ratio"])]
            if max(fin) > 1.5 * min(fin):  # (a log axis over a narrow range repeats its labels)
                ax.set_yscale("log")
            else:
                ax.ticklabel_format(axis="y", useOffset=False, style="plain")
                if max(fin) - min(fin) < 1e-3 * max(fin):  # equal to the 4th digit: show them equal
                    ax.set_ylim(0.99 * min(fin), 1.01 * max(fin))
            ax.set_ylabel("worst width ratio to sampled hull (-), lower is better")
        else:
            ax.set_ylabel("break-down time (s), higher is better")
        ax.set_xlabel("wall time (s)")
        ax.set_title(case + " (labels: pieces)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes (seconds)")
    ap.add_argument("--only", type=int, nargs="*", help="run only these sections (1-8)")
    ap.add_argument("--out", default=".", metavar="DIR",
                    help="section 7 writes work_precision.json and .png here (default: the current "
                         "directory; docs/work_precision.*: --out docs)")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    if args.quick:
        double_pendulum_modes(0.3, 4, True)
        pendulum_ra()
    else:
        sections = {1: lambda: double_pendulum_modes(1.0, 64, False), 2: lambda: single_box_breakdown(1.2),
                    3: lambda: strategies(0.8, 16), 4: lambda: simplified_vs_not(0.8, 16), 5: pendulum_ra,
                    6: lambda: urdf_robot(0.3), 7: lambda: work_precision(out=args.out), 8: long_horizon}
        for k in args.only or sorted(sections):
            sections[k]()
    print(f"\ntotal {time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":
    # one core against one core (CAPD, earlier runs): workers=None stays one in-process
    # batch here (bench_parallel measures the cluster; explicit workers= are kept)
    import verified.execution.plan
    verified.execution.plan.DEFAULT_PARALLEL = False
    main()

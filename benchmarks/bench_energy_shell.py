"""The energy shell as a solver hook (issue 13): the paper's pendulum over the top,
with and without :class:`verified.consistency.energy_shell.EnergyShellHook`, side by side in one run.

    python benchmarks/bench_energy_shell.py          # ~3 min
    python benchmarks/bench_energy_shell.py --quick  # 1 piece, T = 3 only

Case: eq. (18), q(0) in [2.1, 2.2], qd(0) in [3.1, 3.2] (the box straddles the
separatrix), ``error_basis="auto"``, order 12, tol 1e-10, max_width 1e6. The shell is
``H = qd^2 / 2 + g (1 - cos q) <= hmax`` with ``hmax`` the interval bound of eq. (19)
over the initial box (the pendulum is conservative). For each grid and horizon: time
reached, widths at the last output time, worst ratio to the sampled hull (DOP853 at
1e-12 from 500 points and 250 per edge of the box), wall, resets, and whether every
sampled state is inside the enclosure at every output time and in the tube.

The C++ QR-Lohner solver (order 20) for comparison: T = 3 from 1 piece widths 5678 /
35040; T = 10 breaks down at 3.67 s (1 piece) and 4.12 s (4 x 4).
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

import bench_robots as br  # (Oracle, sample_points, containment, md_table)
from models import pendulum as pd
from verified.consistency.contractor import EnergyShell
from verified.consistency.energy_shell import EnergyShellHook, max_energy
from verified.graph import trace
from verified.arith.interval import Interval
from verified.solver import solve


def pendulum_shell():
    """EnergyShell of eq. (18)-(19): M = m l^2, V = m g l (1 - cos q)."""
    M = trace(lambda q, p: [q[0] * 0.0 + pd.M * pd.L ** 2], 1)
    V = trace(lambda q, p: [pd.M * pd.G * pd.L * (1.0 - np.cos(q[0]))], 1)
    return EnergyShell(M, V)


def run(k, T, shell, hmax):
    lo, hi = pd.initial_box()
    hooks = [EnergyShellHook(shell, hmax)] if shell is not None else []
    t0 = time.perf_counter()
    sol = solve(trace(pd.rhs, 2), Interval(lo, hi), (0.0, T), t_eval=np.arange(int(round(T * 10)) + 1) / 10,
                subdivision=[k, k], error_basis="auto", max_width=1e6, hooks=hooks)
    return sol, time.perf_counter() - t0


def main(argv=None, out=print):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="1 piece, T = 3 only")
    args = ap.parse_args(argv)
    plan = [(1, 3.0)] if args.quick else [(1, 3.0), (1, 10.0), (4, 10.0), (64, 3.0)]
    lo, hi = pd.initial_box()
    oracle = br.Oracle(br.closed_form_rhs(pd), br.sample_points(lo, hi, 500, edge_points=250),
                       max(T for _, T in plan), ["q", "qd"])
    shell = pendulum_shell()
    hmax = max_energy(trace(lambda x, p: [pd.hamiltonian(x)], 2), Interval(lo, hi))
    out(f"## Energy shell on the paper's pendulum over the top (hmax = {hmax:.4f} J, "
        f"sampled max {float(np.max(0.5 * oracle.points[:, 1] ** 2 + pd.G * (1 - np.cos(oracle.points[:, 0])))):.4f} J)\n")
    rows, sound = [], True
    for k, T in plan:
        for label, sh in (("without", None), ("with shell", shell)):
            sol, wall = run(k, T, sh, hmax)
            t = float(sol.t[-1])
            w = sol.hull[-1].width()
            ratio = float(np.max(w / np.maximum(oracle.hull_width(t), 1e-300)))
            miss, checks = br.containment(sol, oracle)
            sound &= miss == 0
            reached = f"{sol.t_reached:.3g}" + ("" if sol.status == "completed" else " bd")
            rows.append([f"{k}x{k}", f"{T:g}", label, reached, f"{w[0]:.4g} / {w[1]:.4g} @ {t:g}", f"{ratio:.3g}",
                         f"{wall:.1f}", str(sol.stats.get("shell_resets", "")),
                         "SOUND" if miss == 0 else f"UNSOUND ({miss} of {checks})"])
            print(" ".join(rows[-1]), file=sys.stderr, flush=True)
    out(br.md_table(["grid", "T", "run", "reached", "widths q / qd", "ratio", "wall s", "resets", "sound"], rows))
    return sound


if __name__ == "__main__":
    # one core against one core (CAPD, earlier runs): workers=None stays one in-process
    # batch here (bench_parallel measures the cluster; explicit workers= are kept)
    import verified.execution.plan
    verified.execution.plan.DEFAULT_PARALLEL = False
    sys.exit(0 if main() else 1)

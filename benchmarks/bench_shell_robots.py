"""The energy shell on robots (issue 43, item 3): the two targets, measured.

    python benchmarks/bench_shell_robots.py             # both (~5 min CPU)
    python benchmarks/bench_shell_robots.py --only a    # the free-falling Panda
    python benchmarks/bench_shell_robots.py --only b    # the damped double pendulum

(a) The Panda (example-robot-data, fingers locked) falling freely from its ready pose,
q0 +- 1e-3, at rest, mode i, ``method="composition"``, outputs every 0.1 s to T = 5,
without and with ``energy_shell=True``: status, time reached, where the shell's boxes
took over, the speed bounds, CPU seconds, and every sampled trajectory (Pinocchio's
``aba`` with the joints' damping, DOP853 at rtol 1e-13, 24 starts) against the
outputs and the tube.

(b) example-robot-data's double pendulum (damping 0.05 on both joints), q1(0) in
[2.39, 2.41] (``models/scenes/double_pendulum_urdf.toml``: mode ii, tests every
0.25 s, 10 parts; also tests more often, and 8 pieces) and q1(0) in [pi - 0.3,
pi - 0.29] (bench_consistency's case 6: 8 pieces, tests every 0.05 s), widths at
T = 1 in mode i, mode ii and mode ii with the shell, against the sampled hull (401
starts along q1).
"""
from __future__ import annotations

import argparse
import math
import time

import numpy as np

from mbs.app.sampling import (
    Ensemble,
    count_outside,
    passive_plant,
    sample_points,
)
from mbs.simulate import simulate
from models.robots import double_pendulum, panda_arm
from verified.arith.interval import Interval

Q0_PANDA = (0.0, -math.pi / 4, 0.0, -3 * math.pi / 4, 0.0, math.pi / 2, math.pi / 4)


def panda(T=5.0, cap=3000.0):
    chain = panda_arm()
    q0 = np.array(Q0_PANDA)
    lo, hi = np.r_[q0 - 1e-3, np.zeros(7)], np.r_[q0 + 1e-3, np.zeros(7)]
    ens = Ensemble(passive_plant(chain), sample_points(lo, hi, 24), T, rtol=1e-13, atol=1e-13)
    allst = ens.states(np.linspace(0, T, 501))
    print(f"## (a) free-falling Panda, q0 +- 1e-3, T = {T}\n")
    print("sampled max |qd| over [0, T]:", np.array2string(np.abs(allst[..., 7:]).max(axis=(0, 1)), precision=1))
    print("sampled spread of q at T:", np.array2string(np.ptp(allst[-1][:, :7], axis=0), precision=1))
    print("\n| run | status | reached | shell from | widths q1, q7, qd1, qd7 at the last output | |qd| bound | "
          "CPU s | samples outside |")
    print("|---|---|---|---|---|---|---|---|")
    for shell in (False, True):
        t0 = time.process_time()
        sol = simulate(chain, Interval(lo, hi), T, mode="i", method="composition", output_dt=0.1, progress=False,
                       energy_shell=shell, max_wall=cap)
        cpu = time.process_time() - t0
        w = sol.hull[-1].width()
        outside, checked = count_outside(sol, ens, 400)
        speed = sol.stats.get("shell_speed")
        print(f"| {'shell' if shell else 'no shell'} | {sol.status} | {sol.t_reached:.4g} | "
              f"{sol.stats.get('shell_from', float('nan')):.4g} | {w[0]:.3g}, {w[6]:.3g}, {w[7]:.3g}, {w[13]:.3g} "
              f"at {sol.t[-1]:g} | {'-' if speed is None else ', '.join(f'{v:.0f}' for v in speed)} | {cpu:.1f} | "
              f"{outside} of {checked} |", flush=True)


def pendulum(T=1.0):
    chain = double_pendulum()
    f = passive_plant(chain)
    print(f"\n## (b) damped double pendulum (example-robot-data), widths at T = {T}\n")
    scene, case6 = (2.39, 2.41), (np.pi - 0.3, np.pi - 0.29)
    every = (("i", False), ("ii", False), ("ii", True))
    cases = [("scene box q1 in [2.39, 2.41], 1 piece, tests every 0.25 s, 10 parts", scene, None,
              {"test_interval": 0.25, "test_splits": 10}, every),
             ("scene box, 1 piece, tests every 0.05 s", scene, None, {"test_interval": 0.05, "test_splits": 10},
              (("ii", True),)),
             ("scene box, 1 piece, tests every 0.01 s, 50 parts", scene, None,
              {"test_interval": 0.01, "test_splits": 50}, (("ii", True),)),
             ("scene box, 8 pieces, tests every 0.05 s", scene, [8, 1, 1, 1],
              {"test_interval": 0.05, "test_splits": 10}, (("i", False), ("ii", True))),
             ("case 6, q1 in [pi-0.3, pi-0.29], 8 pieces, tests every 0.05 s", case6, [8, 1, 1, 1],
              {"test_interval": 0.05, "test_splits": 10}, every)]
    print("| case | run | widths q1, q2, qd1, qd2 | worst ratio to sampled | pruned | shell resets | CPU s |")
    print("|---|---|---|---|---|---|---|")
    hulls = {}
    for name, (a, b), sub, test, runs in cases:
        if (a, b) not in hulls:
            pts = np.zeros((401, 4))
            pts[:, 0] = np.linspace(a, b, 401)
            hulls[a, b] = Ensemble(f, pts, T, rtol=1e-13, atol=1e-13).hull_width(T)
        true = hulls[a, b]
        lo, hi = np.array([a, 0, 0, 0.]), np.array([b, 0, 0, 0.])
        for mode, shell in runs:
            t0 = time.process_time()
            sol = simulate(chain, Interval(lo, hi), T, mode=mode, output_dt=0.05, subdivision=sub, progress=False,
                           energy_shell=shell, max_wall=900, **(test if mode == "ii" else {}))
            cpu = time.process_time() - t0
            w = sol.hull[-1].width()
            print(f"| {name} | {mode}{' + shell' if shell else ''} | {', '.join(f'{v:.8g}' for v in w[:4])} | "
                  f"{np.max(w[:4] / true):.5f} | {sol.stats.get('pruned_boxes', '-')} | "
                  f"{sol.stats.get('shell_resets', '-')} | {cpu:.1f} |", flush=True)
    for (a, b), true in hulls.items():
        print(f"| q1 in [{a:.6g}, {b:.6g}] | sampled hull | {', '.join(f'{v:.8g}' for v in true)} | 1 | | | |")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", choices=["a", "b"])
    args = ap.parse_args(argv)
    if args.only in (None, "a"):
        panda()
    if args.only in (None, "b"):
        pendulum()


if __name__ == "__main__":
    import verified.execution.plan
    verified.execution.plan.DEFAULT_PARALLEL = False  # one process, CPU seconds comparable
    main()

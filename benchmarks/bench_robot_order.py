"""The Taylor order of ``auto``'s composition on robots, side by side in one run (issue 45).

``auto`` advances systems of 10 states and more (a 5-DOF robot and up) with
``Composition(params_per_state=12, min_order=6)`` at the composition's own order
(``verified.auto.ladder.LARGE_ORDER``, each step's order in [6, 12]). This runs the robot
cases with that rung at each order of ``--orders``
(``Auto(rungs=(Composition(order=K, params_per_state=12),))``, with ``min_order=k`` for
"K/k": the public API, nothing patched), alternating the orders in one process, and
prints per row the CPU seconds of the whole call, the steps, how far it got and the worst ratio of the
final width to the sampled spread (16 samples, Pinocchio's ``aba`` with DOP853).

Cases: ``ur5`` (UR5 from q0 +- 1e-3, T = 1, modes i and ii), ``quintic``
(``models/scenes/ur5_quintic.toml``), ``hold`` (``panda_pd_hold.toml``) and ``payload``
(the same with a 1 kg +- 10 % payload at the hand, T = 5, one piece: ``max_pieces=1``, so
the row says where a single set breaks down).

    python benchmarks/bench_robot_order.py                          # 8, 12 and 12/6 (auto's), every case
    python benchmarks/bench_robot_order.py --orders 8,10,12 --only ur5,quintic --repeat 3
    python benchmarks/bench_robot_order.py --quick                  # short horizons, one run each
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path
import tempfile

import numpy as np

from mbs import robots
from mbs.app.runner import run_scene
from mbs.app.scene import load_scene, parse_scene, tomllib
from mbs.simulate import simulate
from verified import Interval
from verified.methods import Auto, Composition

SCENES = Path(__file__).resolve().parent.parent / "models" / "scenes"
CASES = ("ur5", "quintic", "hold", "payload")


def rung(order: str, max_pieces: int = 256) -> Auto:
    """``auto`` with one rung: ``order`` "K" (every step at K) or "K/k" (each step's
    order in [k, K]: ``Composition.min_order``)."""
    top, _, low = str(order).partition("/")
    return Auto(rungs=(Composition(order=int(top), params_per_state=12, min_order=int(low) if low else None),),
                max_pieces=max_pieces)


def ur5_run(order: str, mode: str, T: float, cap: float):
    chain = robots.load("ur5")
    q0 = np.array((0.0, -1.0, 1.0, -1.0, -1.0, 0.0))
    x0 = Interval(np.concatenate([q0 - 1e-3, np.zeros(6)]), np.concatenate([q0 + 1e-3, np.zeros(6)]))
    sol = simulate(chain, x0, T, mode=mode, method=rung(order), progress=False, max_wall=cap)
    return sol, None


def scene_run(name: str, order: str, T: float | None, cap: float, payload: bool = False):
    path = SCENES / name
    if payload:  # (the shipped scene with a [parameters.payload] table, parsed as a file's)
        data = tomllib.loads(path.read_text())
        data.setdefault("parameters", {})["payload"] = {"link": "panda_hand", "mass": [0.9, 1.1],
                                                        "com": [0, 0, 0.1]}
        scene = parse_scene(data, str(path), path.parent)
    else:
        scene = load_scene(path)
    scene.solver = dict(scene.solver, method=rung(order, max_pieces=1 if payload else 256))
    with tempfile.TemporaryDirectory() as out:
        rep = run_scene(scene, out, t_end=T, samples=16, figures=False, progress=False, max_wall=cap)
    worst = (rep.get("tightness") or {}).get("worst") or {}
    return rep["solution"], worst.get("ratio")


def run(case: str, order: str, quick: bool, cap: float):
    if case.startswith("ur5"):
        return ur5_run(order, case.partition(":")[2] or "i", 0.1 if quick else 1.0, cap)
    if case == "quintic":
        return scene_run("ur5_quintic.toml", order, 0.2 if quick else None, cap)
    if case == "hold":
        return scene_run("panda_pd_hold.toml", order, 0.2 if quick else None, cap)
    return scene_run("panda_pd_hold.toml", order, 0.2 if quick else None, cap, payload=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--orders", default="8,12,12/6",
                    help="comma-separated Taylor orders, K or K/k for a per-step order in [k, K] (default 8,12,12/6)")
    ap.add_argument("--only", default="ur5:i,ur5:ii,quintic,hold,payload",
                    help="comma-separated cases: ur5:i, ur5:ii, quintic, hold, payload")
    ap.add_argument("--repeat", type=int, default=2, help="runs per row; the least CPU is reported")
    ap.add_argument("--cap", type=float, default=300.0, help="wall-clock cap per run (s)")
    ap.add_argument("--quick", action="store_true", help="short horizons, one run each")
    a = ap.parse_args(argv)
    orders = [k.strip() for k in a.orders.split(",")]
    cases = [c.strip() for c in a.only.split(",")]
    for c in cases:
        if c.partition(":")[0] not in CASES:
            ap.error(f"unknown case {c!r} (known: ur5:i, ur5:ii, quintic, hold, payload)")
    repeat = 1 if a.quick else a.repeat
    run(cases[0], orders[0], True, a.cap)  # (kernels compiled before the clock)
    print("| case | order | status | t reached | steps | CPU s (least) | worst ratio |")
    print("|---|---|---|---|---|---|---|")
    for case in cases:
        best = {}
        for _ in range(repeat):
            for k in orders:  # (alternating: the machine's load falls on every order alike)
                t0 = time.process_time()
                sol, ratio = run(case, k, a.quick, a.cap)
                cpu = time.process_time() - t0
                if ratio is None and sol.status == "completed" and case.startswith("ur5"):
                    ratio = float(np.max(sol.hull[-1].width()))  # (no samples here: the widest width)
                if k not in best or cpu < best[k][0]:
                    best[k] = (cpu, sol, ratio)
        for k in orders:
            cpu, sol, ratio = best[k]
            label = "widest width" if case.startswith("ur5") else "ratio"
            shown = "" if ratio is None else f"{ratio:.5g} ({label})"
            print(f"| {case} | {k} | {sol.status} | {float(sol.t_reached):.4g} | {sol.stats.get('steps')} | "
                  f"{cpu:.1f} | {shown} |", flush=True)


if __name__ == "__main__":
    main()

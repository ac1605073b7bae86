"""The numeric model's qdd at one float point, side by side in one run (issue 45).

Per call, at one point (q, qd, tau): the numeric model's recursion
(``NumericModel.acceleration`` before it compiles), the same operations as compiled
straight-line float code (``NumericModel.float_acceleration``, what ``acceleration``
runs from its third float call on), the symbolic model's lambdified evaluator, and
Pinocchio's ``aba`` (C++). Prints microseconds per call and the ratios to the
lambdified symbolic model (issue 45's target: within 2x).

    python benchmarks/bench_float_model.py              # 3-link arm (symbolic too) and UR5
    python benchmarks/bench_float_model.py --no-symbolic
"""
from __future__ import annotations

import argparse
import time

import numpy as np


def _per_call(fn, reps: int) -> float:
    fn()
    t = time.perf_counter()
    for _ in range(reps):
        fn()
    return (time.perf_counter() - t) / reps * 1e6


def run(name, chain, symbolic: bool, out=print):
    import pinocchio as pin

    from mbs import numeric
    from mbs.app.sampling import pinocchio_with
    from mbs.numeric import NumericModel

    n = chain.n
    rng = np.random.default_rng(0)
    q, qd, tau = rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), rng.uniform(-1, 1, n)
    rec = NumericModel(chain)
    comp = NumericModel(chain)
    fast = comp.float_acceleration()
    x = np.concatenate([q, qd, tau])
    float_code_after = numeric.FLOAT_CODE_AFTER
    numeric.FLOAT_CODE_AFTER = float("inf")  # (acceleration never compiles: the recursion)
    try:
        rows = [("numeric, recursion", _per_call(lambda: rec.acceleration(q, qd, tau), 20))]
        a = rec.acceleration(q, qd, tau)
    finally:
        numeric.FLOAT_CODE_AFTER = float_code_after
    rows.append(("numeric, compiled float code", _per_call(lambda: fast(x), 500)))
    b = fast(x)[:n]
    out(f"{name}: compiled vs recursion, max relative difference {np.max(np.abs(a - b) / np.abs(a)):.1e}")
    if symbolic:
        from mbs.symbolic import SymbolicModel
        t = time.perf_counter()
        sym = SymbolicModel(chain).lambdified()
        out(f"{name}: symbolic model derived and lambdified in {time.perf_counter() - t:.1f} s")
        rows.append(("symbolic, lambdified", _per_call(lambda: sym(q, qd, tau), 200)))
    model = pinocchio_with(chain)
    data = model.createData()
    rows.append(("Pinocchio aba (C++)", _per_call(lambda: pin.aba(model, data, q, qd, tau), 2000)))
    ref = dict(rows).get("symbolic, lambdified")
    out(f"\n| {name} | us per call | / symbolic lambdified |\n|---|---|---|")
    for label, us in rows:
        out(f"| {label} | {us:.1f} | {us / ref:.2f} |" if ref else f"| {label} | {us:.1f} | |")
    out("")
    return dict(rows)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--no-symbolic", action="store_true", help="skip the symbolic model (sympy derivation)")
    a = ap.parse_args(argv)
    from mbs import robots
    from models.planar import planar_chain
    run("3-link planar arm", planar_chain(3), not a.no_symbolic)
    run("UR5", robots.load("ur5"), False)


if __name__ == "__main__":
    main()

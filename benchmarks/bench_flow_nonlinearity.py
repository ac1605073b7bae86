"""How curved is the true reachable set?  Polynomial fits of the flow map over the
initial box, for the robot targets of issue 17 (no verified arithmetic involved).

Run:  python benchmarks/bench_flow_nonlinearity.py           # arm3, UR5, Panda (~6 min)
      python benchmarks/bench_flow_nonlinearity.py --quick   # arm3 only, fewer points (~1 min)
      python benchmarks/bench_flow_nonlinearity.py --cases chain4,chain5,chain6,chain7  # planar chains

A verified set that is a polynomial of degree d in the initial parameters (d = 1: the
parallelepiped ``c + C r0`` of a first-order Lohner set; d = 2: ``verified.sets.second_order``'s
second-order sets; higher: the Taylor-model sets of COSY-VI, Flow*, TaylorModels.jl) can
only be as tight as the best degree-d polynomial image of the initial box. This script
measures that floor directly: trajectories from ``xi`` in the initial box (normalised to
``[-1, 1]^m``, ``m`` the wide initial components), integrated by scipy's DOP853 (rtol
1e-12) with Pinocchio's ``aba`` as the right-hand side (no code shared with the library),
give the flow map ``xi -> x(t)``; a least-squares polynomial of total degree d is fitted on
a training set of points and its worst error is measured on held-out points.

Columns at each time t: the widest component of the sampled hull (its width), then per
degree d the worst held-out residual divided by that component's sampled width (worst
over components). A value of 1e-3 means a degree-d set could follow the true set to 0.1 %
of its width; a value near 1 means no degree-d polynomial follows it (the set is folded).

What it says about the targets (numbers in the README and docs/robots_benchmark.md):
the 3-link arm at +- 0.01 and the UR5 at +- 1e-3 stay close to a low-degree polynomial
image up to their horizons, so their targets are reachable in principle by sets of
degree 2-3; the Panda at +- 1e-3 spreads to tens of rad/s by T = 1 and no cubic follows it.
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time

import numpy as np

import bench_robots as br
from mbs.app.sampling import states_at


def _case(name):
    if name == "arm3":
        from models.planar import planar_chain
        return planar_chain(3), br.Q0_ARM3, 0.01, (0.25, 0.5, 0.75, 1.0, 1.5, 2.0), (1, 2, 3, 4)
    if name.startswith("chain"):
        from models.planar import planar_chain
        k = int(name[5:])
        return planar_chain(k), br.chain_q0(k), 1e-3, (0.25, 0.5, 0.75, 1.0), (1, 2, 3)
    if name == "ur5":
        from models.robots import ur5
        return ur5(), br.Q0_UR5, 1e-3, (0.1, 0.25, 0.5, 0.75, 1.0), (1, 2, 3)
    from models.robots import panda_arm
    return panda_arm(), br.Q0_PANDA, 1e-3, (0.1, 0.2, 0.3, 0.5, 0.75, 1.0), (1, 2, 3)


def monomials(m: int, degree: int) -> np.ndarray:
    """Exponents (M, m) of every monomial of total degree <= ``degree`` in m variables."""
    return np.array([e for e in itertools.product(range(degree + 1), repeat=m) if sum(e) <= degree])


def design(xi: np.ndarray, exps: np.ndarray) -> np.ndarray:
    """Design matrix (N, M): every monomial at every point ``xi`` (N, m)."""
    return np.prod(xi[:, None, :] ** exps[None, :, :], axis=2)


def flow_samples(f, x_centre, radius, xi, times):
    """States (N, len(times), 2n) at ``times`` from ``x_centre + radius * xi`` (xi in
    [-1, 1]^m on the components where radius > 0), DOP853 at rtol = atol = 1e-12 (the
    sampling oracle's ``states_at``); ``f`` acts on columns (2n, S)."""
    wide = np.flatnonzero(radius > 0)
    x0 = np.repeat(x_centre[None], len(xi), axis=0)
    x0[:, wide] += radius[wide] * np.asarray(xi, float)
    return states_at(lambda y: f(y[:, None])[:, 0], x0, times)


def fit_residuals(xi_train, y_train, xi_test, y_test, degrees):
    """Per degree: worst held-out residual / sampled width, worst over components, and
    the widest component's width (the widths from train and test points together)."""
    width = np.ptp(np.concatenate([y_train, y_test]), axis=0)
    rows = {}
    for d in degrees:
        exps = monomials(xi_train.shape[1], d)
        coef, *_ = np.linalg.lstsq(design(xi_train, exps), y_train, rcond=None)
        res = np.abs(design(xi_test, exps) @ coef - y_test).max(axis=0)
        rows[d] = float(np.max(res / np.maximum(width, 1e-300)))
    return float(width.max()), rows


def run_case(name, n_points, seed=0, log=print):
    chain, q0, eps, times, degrees = _case(name)
    lo, hi = br.chain_box(q0, eps)
    centre, radius = 0.5 * (lo + hi), 0.5 * (hi - lo)
    m = int((radius > 0).sum())
    rng = np.random.default_rng(seed)
    corners = np.array(list(itertools.product((-1.0, 1.0), repeat=m))) if m <= 7 else np.zeros((0, m))
    train = np.concatenate([corners, rng.uniform(-1, 1, (n_points, m))])
    test = rng.uniform(-1, 1, (max(n_points // 2, 20), m))
    f = br.pinocchio_rhs(chain)
    t0 = time.perf_counter()
    y = flow_samples(f, centre, radius, np.concatenate([train, test]), np.asarray(times, float))
    log(f"{name}: {len(train) + len(test)} trajectories in {time.perf_counter() - t0:.0f} s")
    ytr, yte = y[:len(train)], y[len(train):]
    table = []
    for k, t in enumerate(times):
        wmax, rows = fit_residuals(train, ytr[:, k], test, yte[:, k], degrees)
        table.append([f"{t:g}", f"{wmax:.3g}"] + [f"{rows[d]:.2e}" for d in degrees])
    head = ["t (s)", "widest sampled width"] + [f"degree {d}: residual / width" for d in degrees]
    return f"{name}, q(0) in q0 +- {eps:g}, qd(0) = 0 ({m} initial parameters)", head, table


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="arm3 only, 150 points")
    ap.add_argument("--points", type=int, default=None, help="random training points per case")
    ap.add_argument("--cases", default=None,
                    help="comma-separated: arm3, ur5, panda, chain2 .. chain7 (default: arm3, ur5, panda)")
    args = ap.parse_args(argv)
    cases = ("arm3",) if args.quick else ("arm3", "ur5", "panda")
    if args.cases:
        cases = tuple(c.strip() for c in args.cases.split(","))
        bad = [c for c in cases if c not in ("arm3", "ur5", "panda") and not (c.startswith("chain") and c[5:].isdigit())]
        if bad:
            ap.error(f"unknown case(s) {', '.join(bad)}: arm3, ur5, panda or chainN")
    for name in cases:
        n_points = args.points or (150 if args.quick else (300 if name == "arm3" else 500))
        title, head, rows = run_case(name, n_points, log=lambda s: print(s, file=sys.stderr, flush=True))
        print(f"### {title}\n")
        print(br.md_table(head, rows) + "\n", flush=True)


if __name__ == "__main__":
    main()

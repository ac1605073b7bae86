"""Why the robot runs take small steps: the spread of a step's Jacobian over a set, as
each arithmetic encloses it, against its sampled spread (issues 14 and 17).

Run:  python benchmarks/bench_jacobian_spread.py                 # both cases (~2 min)
      python benchmarks/bench_jacobian_spread.py --case ur5_pd   # one of ur5_pd, arm3

A QR-Lohner step (:mod:`verified.steppers.lohner`) encloses the Jacobian ``J`` of its Taylor map
over the set; ``(J - mid J)`` times the set's linear part is the error the step injects,
and the wrapping control (``verified.driver.control.WrapControl``) shortens the steps until
that error is ``wrap_target`` (3 %) of the set's width. An enclosure of ``J`` wider than
its true spread therefore costs steps one for one, and the injected error feeds the
set's growth. Each case runs the solver as its benchmark does, stops after ``--steps``
steps (a hook keeps the set), and then, for that set:

* ``J`` over the set's own forms, as the solver takes it: affine arithmetic (without
  and with ``fresh_slots``: the solver gives deep tapes 24) and degree-2 Taylor models
  with ``q`` quadratic symbols (``arithmetic="taylor_model"`` uses q = 12); the widest
  entry of the enclosure, and the time;
* the sampled spread: ``J`` at 64 points of the set (the corners of its parameter box
  among them; interval evaluation at points), widest entry: a lower bound of the true
  spread, so the ratio is an upper bound of the overestimation;
* the order-k Taylor coefficients of the solution over the set's hull box (affine with
  fresh symbols, what the step size is chosen from) against those at the centre.

No timing is asserted anywhere; the times printed are for one evaluation each, measured
side by side in one run.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np


from verified.series.affine_taylor import AffineTaylorODE
from verified.driver.hooks import Hook
from verified.arith.interval import Interval, concatenate, point
from verified.steppers.lohner import horner
from verified.series.taylor import TaylorODE
from verified.series.taylor_model import TaylorModelODE
from verified.series.variational import variational_graph


class CaptureAt(Hook):
    """Stop the run after step ``n`` and keep its sets, step size and the solver graph."""

    def __init__(self, n: int):
        self.n, self.count = int(n), 0
        self.graph = self.sets = self.h = self.t = None

    def before_run(self, setup):
        self.graph = setup.graph
        return None

    def after_step(self, step, sets, run):
        self.count += 1
        if self.count == self.n:
            self.sets, self.h, self.t = sets, step.length, step.t
            run.stop(f"captured after step {self.n}", "stopped")
        return None


def set_points(sets, count: int, seed: int = 0) -> np.ndarray:
    """``count`` points (count, N) of the first set of the batch: corners of the parameter
    box first, then random parameters (and random error vectors inside ``r``)."""
    rng = np.random.default_rng(seed)
    lo0, hi0 = sets.r0.lo[0], sets.r0.hi[0]
    u = rng.uniform(lo0, hi0, (count, lo0.size))
    u[0], u[1] = lo0, hi0
    w = rng.uniform(sets.r.lo[0], sets.r.hi[0], (count, sets.r.shape[1]))
    x = sets.c[0] + u @ sets.C[0].T + w @ sets.Q[0].T
    S = getattr(sets, "S", None)
    if S is not None:  # second-order sets: the quadratic part u^T S_i u
        x = x + np.einsum("sj,ijk,sk->si", u, S[0], u)
    return x


def jacobian_over_set(evaluator, sets, order: int, h: float) -> Interval:
    """Enclosure (n, n) of the Taylor map's Jacobian over the first set (as
    ``LohnerStepper.set_jacobian``)."""
    n = sets.c.shape[1]
    one = sets.take(slice(0, 1))
    own = one.C.shape[2] if getattr(evaluator, "all_symbols", False) else None
    forms = one.affine_forms(extra=n * n, own_symbols=own)  # (second-order sets accept and ignore own_symbols)
    forms[n:, :, 0] = np.eye(n).reshape(-1)[:, None]
    vc = evaluator.series(forms, order - 1, None)
    return horner(vc[:, :, n:].reshape((1, order, n, n)), h)[0]


def jacobian_at(vgraph, points: np.ndarray, order: int, h: float) -> np.ndarray:
    """The Jacobian (S, n, n) of the Taylor map at each point (midpoints of thin enclosures)."""
    S, n = points.shape
    v0 = point(np.broadcast_to(np.eye(n).reshape(-1), (S, n * n)))
    vc = TaylorODE(vgraph).coefficients(concatenate([point(points), v0], axis=1), order - 1)
    return horner(vc[:, :, n:].reshape((S, order, n, n)), h).mid()


def measure(label: str, cap: CaptureAt, order: int, quadratic=(0, 4, 8, 12), states=None, out=print):
    sets, h, g = cap.sets, cap.h, cap.graph
    if sets is None:
        out(f"{label}: the run ended before step {cap.n}")
        return
    n = g.n_inputs
    states = n if states is None else states
    vg = variational_graph(g)
    pts = set_points(sets, 64)
    Js = jacobian_at(vg, pts, order, h)
    sampled = float((Js.max(axis=0) - Js.min(axis=0))[:states].max())
    hull = sets.take(slice(0, 1)).hull()
    out(f"\n### {label}: after step {cap.n} (t = {cap.t:.4g} s, h = {h:.3g} s, order {order})\n")
    out("set hull widths: " + ", ".join(f"{w:.3g}" for w in hull.width()[0]))
    out("\n| Jacobian over the set | widest entry of the enclosure | / sampled spread | time (s) |")
    out("|---|---|---|---|")
    rows = [("affine", AffineTaylorODE(vg, fresh_symbols=0))]
    rows += [(f"affine, {k} fresh slots", AffineTaylorODE(vg, fresh_symbols=0, fresh_slots=k)) for k in (12, 24, 48)]
    rows += [(f"Taylor models, q = {q}", TaylorModelODE(vg, quadratic_symbols=q)) for q in quadratic]
    for name, ev in rows:
        jacobian_over_set(ev, sets, order, h)  # (compile and warm up)
        t0 = time.perf_counter()
        J = jacobian_over_set(ev, sets, order, h)
        dt = time.perf_counter() - t0
        w = float(J.width()[:states].max())
        out(f"| {name} | {w:.3g} | {w / sampled:.1f} | {dt:.3f} |")
    out(f"| sampled (64 points) | {sampled:.3g} | 1 | |")
    aff = AffineTaylorODE(g)
    cX = aff.coefficients(hull, order)
    cc = aff.coefficients(point(hull.mid()), order)
    ks = list(range(1, order + 1, max(1, order // 5)))
    out("\n| Taylor coefficient x_[k], widest state | " + " | ".join(f"k = {k}" for k in ks) + " |")
    out("|---|" + "---|" * len(ks))
    out("| over the hull box (affine, fresh symbols) | "
        + " | ".join(f"{float(cX[0, k, :states].mag().max()):.3g}" for k in ks) + " |")
    out("| at the centre | " + " | ".join(f"{float(cc[0, k, :states].mag().max()):.3g}" for k in ks) + " |")


def case_ur5_pd(steps: int, out=print):
    """The shipped UR5 PD payload scene, one payload piece (0.9-0.95 kg), affine."""
    from mbs.app.runner import run_scene
    from mbs.app.scene import load_scene, scene_dir

    sc = load_scene(scene_dir() / "ur5_pd_payload.toml")
    sc.solver.pop("param_subdivision", None)
    sc.physical["payload"]["mass"] = (0.9, 0.95)
    cap = CaptureAt(steps)
    sc.solver["hooks"] = [cap]
    run_scene(sc, Path("/tmp") / "bench_jacobian_spread_ur5", t_end=5.0, samples=0, figures=False,
              progress=False)
    measure("UR5 PD hold, payload 0.9-0.95 kg (ur5_pd_payload, one piece), affine", cap, sc.solver["order"],
            states=12, out=out)


def case_arm3(steps: int, out=print):
    """The 3-link arm of bench_robots, q0 +- 0.01, second-order sets, Taylor models, auto."""
    from bench_robots import Q0_ARM3, chain_box

    from mbs.simulate import simulate
    from models.planar import planar_chain

    lo, hi = chain_box(Q0_ARM3, 0.01)
    cap = CaptureAt(steps)
    simulate(planar_chain(3), Interval(lo, hi), 2.0, mode="i", order=8, tol=1e-10, set_order=2,
             arithmetic="taylor_model", error_basis="auto", hooks=[cap], progress=False)
    measure("3-link arm, q0 +- 0.01, set_order=2, Taylor-model Jacobians, auto", cap, 8, out=out)


CASES = {"ur5_pd": (case_ur5_pd, 30), "arm3": (case_arm3, 250)}


def main(argv=None, out=print):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--case", choices=sorted(CASES), action="append", help="case(s) to run (default: all)")
    p.add_argument("--steps", type=int, default=None, help="capture the set after this many steps")
    args = p.parse_args(argv)
    for name in args.case or list(CASES):
        fn, steps = CASES[name]
        fn(args.steps or steps, out=out)


if __name__ == "__main__":
    # one core against one core (CAPD, earlier runs): workers=None stays one in-process
    # batch here (bench_parallel measures the cluster; explicit workers= are kept)
    import verified.execution.plan
    verified.execution.plan.DEFAULT_PARALLEL = False
    main()

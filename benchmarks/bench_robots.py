"""Verified simulation of robots (issue 17): enclosures against sampled trajectories,
plain interval Taylor coefficients side by side with affine-arithmetic ones.

Run:  python benchmarks/bench_robots.py                 # every case (see --cap)
      python benchmarks/bench_robots.py --quick         # small versions (about 1-2 min)
      python benchmarks/bench_robots.py --only 1,7      # some cases (numbers below)
      python benchmarks/bench_robots.py --cap 60        # wall cap per run (s)

Cases (issue 17's targets table):

1. ``arm3``: 3-link planar arm from a DH table (``models.planar.planar_chain(3)``),
   q(0) in q0 +- eps, q0 = (0.5, -0.3, 0.2), qd(0) = 0, mode i, T = 2,
   eps = 0.01 (target: ratio <= 1.5 in <= 60 s) and 1e-3, 1e-4, 1e-6; eps = 0.01 also
   with the q box split into 2^3 and 4^3 pieces.
2. ``ur5``: UR5 (example-robot-data), q0 = (0, -1, 1, -0.5, 0.5, 0), eps = 1e-3, modes
   i and ii, T = 1 (target: ratio <= 1.5 in <= 60 s).
3. ``panda``: Panda arm, fingers locked at 0 (``models.robots.panda_arm``), q0 = the
   usual ready pose (0, -pi/4, 0, -3pi/4, 0, pi/2, pi/4), eps = 1e-3, mode i, T = 1.
4. ``chains``: planar n-link chains n = 2..7 (uniform rods), q0 = (0.5, -0.3, 0.2,
   -0.3, 0.2, ...), eps = 1e-3, T = 1, through ``solve`` on the numeric rhs graph (what
   mode i integrates): simulate()'s M(q) > 0 proof fails on the initial box for n >= 5.
5. ``dp``: the paper's double pendulum (eq. 22 traced, ``models.double_pendulum``,
   initial box eq. 25): one box (break-down time, horizon 3; also with second-order
   sets, Taylor-model Jacobians and 12 parameters per state), T = 1 with 256 pieces
   (target ratio <= 1.02 in <= 10 s), T = 3 with 1024 pieces (target <= 1.1 in <= 60 s).
6. ``pendulum``: the paper's pendulum (eq. 18 traced), q(0) in [2.1, 2.2],
   qd(0) in [3.1, 3.2], T = 3 and T = 10 (one run to 10 serves both), 1 piece, 4x4 and
   64x64 grids; max_width 1e6 (instead of the solver's 1e3) so that widths like the
   C++ solver's 5678 and 35040 can be reached and compared; interval runs also with
   ``error_basis="auto"`` (capped at 300 s on the small grids: no time target there).
7. ``qdd``: enclosure of qdd over the 3-link +-0.01 box (qd = 0) in the evaluators
   the solver uses (order-1 Taylor coefficient of the numeric rhs graph, modes i/ii,
   and of the symbolic one, mode iii) against the sampled range (target: within 2x).
8. ``composition``: second-order sets (``set_order=2``, Taylor-model arithmetic,
   ``error_basis="auto"``, order 8, tol 1e-10, 12 parameters per state) advanced by
   the mean-value step (``set_step="mean_value"``) and by composition in Taylor models
   (``set_step="composition"``, :mod:`verified.steppers.tm_flow`) in Taylor models of degree 2,
   3 and 4 (``model_degree``) side by side, through ``solve``
   on the numeric rhs graph: the 3-link arm (eps 0.01, 1e-3), the UR5 and the Panda
   (eps 1e-3), chains n = 4..7 and the double pendulum from one box; the wall cap is
   ``--cap`` except where a row states its own. Also the worst ratio at every output
   time of the composition runs.
9. ``pendulum_composition``: case 6's pendulum over the top with second-order sets
   advanced by composition (``set_step="composition"``, order 12, tol 1e-10,
   ``error_basis="auto"``, max_width 1e6): 1 piece to T = 3 and T = 10, 4x4 to T = 10,
   16x16 to T = 3, against case 6's oracle (500 random points, 250 per edge).
10. ``arm3_pieces``: case 1's 3-link arm +- 0.01 to T = 2 with case 8's composition
   (degree 3), the q box split into 3 x 3 x 3 pieces, each a chunk of its own (own step
   sizes) on 2 local Dask workers (``PIECES_WORKERS``; wall cap ``PIECES_CAP`` = 1800 s).

Oracle: trajectories from all corners of the box (over its wide components), random
points and the centre (the pendulum: also 250 points per edge), integrated together as
one system by scipy's DOP853 (rtol = atol = 1e-12, dense output): the tests' sampling
oracle, :mod:`mbs.app.sampling` (``Ensemble``, ``sample_initial_points``,
``count_outside``), shared with the other benchmarks. The right-hand side
is Pinocchio's ``aba`` (with ``tau = -D qd`` for URDF damping) on a ``pin.Model``
(URDF robots: Pinocchio's own parser; DH chains: joint by joint,
``mbs.pinocchio_check.to_pinocchio``), so it shares no evaluation code with the project.
The paper's pendulum and double pendulum use their closed-form numpy right-hand sides;
the double pendulum's ratio at T uses ``bench_solver.true_hull_widths`` (2001 points).

Runs: ``mbs.simulate.simulate`` (cases 1-3, outputs every T/20) or
``verified.solver.solve`` (cases 4-6), with a hook that stops a run at the wall cap
(``--cap``, default 60 s = the targets' budget; a setting may carry its own); a
capped run is a solver result like any other, with everything verified up to then
(and for simulate() runs the M(q) > 0 proof).
Several solver settings are tried per case and arithmetic (the same for both); the
summary tables show the best per arithmetic (completed first, then the smallest
ratio, then the fastest; among break-downs the furthest), "All runs" every setting.
Numba kernels are compiled before timing.

Columns:
  reached  -- time verified up to: ``T`` when completed, else ``t bd`` (break-down:
              step size underflow, enclosure wider than max_width, M(q) not proven
              positive definite, ...) or ``t cap`` (stopped at the wall cap)
  ratio @ t -- enclosure hull width / sampled hull width, worst state component,
              at the last completed output time t (the final time when completed;
              for the double pendulum at T against the 2001-point true hull)
  comp     -- the state component giving that worst ratio
  wall s   -- wall time of the run (numba compiled before; cases 1-3 include building
              the model graph and Taylor tapes, which simulate() does per call)
  steps    -- accepted steps
  setting  -- Taylor order / tol (and other solver options) of that run
  sound    -- SOUND: every sampled trajectory lies inside the enclosure (union of
              boxes) at every output time and at the midpoints of (up to 200) steps'
              tube boxes, up to the time reached; UNSOUND otherwise (a bug: report it)
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

import bench_solver  # (true_hull_widths of the double pendulum)
from mbs.simulate import simulate
from models import double_pendulum as dp
from models import pendulum as pd
# the oracle (also for bench_absorb, bench_energy_shell, bench_taylor_model: br.Oracle, br.sample_points)
from mbs.app.sampling import Ensemble as Oracle
from mbs.app.sampling import count_outside, inside_union
from mbs.app.sampling import sample_initial_points as sample_points
from verified.graph import trace
from verified.driver.hooks import Hook
from verified.arith.interval import Interval
from verified.solver import Solution, VerifiedODE, solve

ARITHMETICS = ("interval", "affine")
SLACK = 1e-9  # relative (to max(1, |x|)); DOP853 at 1e-12 is far more accurate
TUBE_CHECKS = 200  # steps whose tube boxes are checked (evenly spread)
#: case 8's columns: the solver options of each
STEPS_8 = {"mean_value": dict(set_step="mean_value"),
           "degree 2": dict(set_step="composition", model_degree=2),
           "degree 3": dict(set_step="composition", model_degree=3),
           "degree 4": dict(set_step="composition", model_degree=4)}

CASES = {1: "arm3", 2: "ur5", 3: "panda", 4: "chains", 5: "dp", 6: "pendulum", 7: "qdd", 8: "composition",
         9: "pendulum_composition", 10: "arm3_pieces"}
#: case 10: local Dask workers (the 27 pieces' chunks), and its own wall cap (s)
PIECES_WORKERS = 2
PIECES_CAP = 1800.0
Q0_ARM3 = (0.5, -0.3, 0.2)
Q0_UR5 = (0.0, -1.0, 1.0, -0.5, 0.5, 0.0)
Q0_PANDA = (0.0, -math.pi / 4, 0.0, -3 * math.pi / 4, 0.0, math.pi / 2, math.pi / 4)


def chain_q0(n):
    """q0 of the n-link chains: (0.5, -0.3, 0.2, -0.3, 0.2, ...) (n = 3: the arm's)."""
    return tuple([0.5] + [(-0.3, 0.2)[i % 2] for i in range(n - 1)])


# ------------------------------------------------------------------ helpers

def _hulls(list_of_boxes, n):
    """(k, n) Interval of the hulls of a list of (B, n) boxes."""
    if not list_of_boxes:
        return Interval(np.zeros((0, n)), np.zeros((0, n)))
    lo = np.stack([b.lo.reshape(-1, n).min(axis=0) for b in list_of_boxes])
    hi = np.stack([b.hi.reshape(-1, n).max(axis=0) for b in list_of_boxes])
    return Interval(lo, hi, allow_unbounded=True)


# ----------------------------------------------------------------------------- oracle

def pinocchio_rhs(chain):
    """x = (q, qd) columns (2n, S) -> x' by Pinocchio's ``aba`` (a pin.Model built by
    Pinocchio's URDF parser, or joint by joint for DH chains), tau = -D qd."""
    import pinocchio as pin

    from mbs.pinocchio_check import to_pinocchio

    model = to_pinocchio(chain)
    data = model.createData()
    n = chain.n
    joints = [model.joints[model.getJointId(name)] for name in chain.joint_names]
    if model.nv != n or any(j.nv != 1 for j in joints):
        raise RuntimeError(f"{chain.name}: Pinocchio model has nv = {model.nv}, the chain {n} dof")
    iq = np.array([j.idx_q for j in joints])
    nq = np.array([j.nq for j in joints])
    iv = np.array([j.idx_v for j in joints])
    damping = np.array([float(d) for d in chain.damping])
    pq = pin.neutral(model)
    pv = np.zeros(model.nv)
    tau = np.zeros(model.nv)

    def f(X):
        X = np.asarray(X, dtype=float)
        out = np.empty_like(X)
        out[:n] = X[n:]
        for s in range(X.shape[1]):
            q, v = X[:n, s], X[n:, s]
            for i in range(n):
                if nq[i] == 1:
                    pq[iq[i]] = q[i]
                else:  # continuous joint: (cos, sin)
                    pq[iq[i]], pq[iq[i] + 1] = math.cos(q[i]), math.sin(q[i])
            pv[iv] = v
            tau[iv] = -damping * v
            out[n:, s] = pin.aba(model, data, pq, pv, tau)[iv]
        return out

    return f


def closed_form_rhs(mod):
    """The paper model's numpy right-hand side on columns (n, S)."""
    return lambda X: np.array(mod.rhs(X), dtype=float)


def inside_boxes(x, boxes):
    """(S,) bool: is each point (S, n) in the union of boxes (B, n)? (relative slack)"""
    return inside_union(x, boxes.lo, boxes.hi, SLACK, relative=True)


def containment(sol, oracle):
    """(misses, checks): sampled states outside the enclosure at the output times and
    at the midpoints of up to TUBE_CHECKS steps (tube boxes), up to the time reached."""
    return count_outside(sol, oracle, TUBE_CHECKS, SLACK, relative=True)


# -------------------------------------------------------------------------- runs

class _WallCap(Hook):
    """Stops a run (``status="stopped"``, reason "wall cap (S s)") once ``cap`` seconds
    have passed since ``start``, checked after every accepted step like
    :class:`verified.driver.hooks.StopAfterWall` (which counts from the integration's start,
    after the tapes are built; the bench counts the set-up too). ``on_progress(t,
    wall)`` is called after every accepted step."""

    def __init__(self, cap, start, on_progress=None):
        self.cap, self.start, self.on_progress = cap, start, on_progress

    def after_step(self, step, sets, run):
        wall = time.perf_counter() - self.start
        if self.on_progress is not None:
            self.on_progress(step.t, wall)
        if wall > self.cap:
            run.stop(f"wall cap ({self.cap:g} s)")


def capped(call, cap, on_progress=None):
    """``call(hooks)`` -> (Solution, wall s), stopped at ``cap`` seconds of wall time:
    ``call`` passes ``hooks`` to ``solve`` or ``simulate``. ``on_progress(t, wall)`` is
    called after every accepted step."""
    start = time.perf_counter()
    sol = call([_WallCap(cap, start, on_progress)])
    return sol, time.perf_counter() - start


def truncated(sol, T):
    """A copy of ``sol`` restricted to [t0, T] (completed when it reached T)."""
    keep = [i for i, t in enumerate(sol.t) if t <= T]
    steps = int(np.sum(sol.tube_t[1:] <= T))
    n = sol.hull.shape[-1]
    boxes = [sol.boxes[i] for i in keep]
    done = sol.t_reached >= T
    return Solution(t=sol.t[keep], boxes=boxes, hull=_hulls(boxes, n), tube_t=sol.tube_t[:steps + 1],
                    tube=sol.tube[:steps], tube_hull=_hulls(sol.tube[:steps], n),
                    t_reached=min(T, sol.t_reached), status="completed" if done else sol.status,
                    reason="" if done else sol.reason, stats=dict(steps=steps))


@dataclass
class Run:
    case: str
    arithmetic: str
    setting: str
    T: float
    sol: Solution
    wall: float
    ratio: float = math.nan
    t_out: float = math.nan
    comp: str = ""
    misses: int = 0
    checks: int = 0
    extra: dict = field(default_factory=dict)

    @property
    def completed(self):
        return self.sol.status == "completed"

    @property
    def sound(self):
        return self.misses == 0

    def reached(self):
        if self.completed:
            return f"{self.T:g}"
        tag = "cap" if self.sol.status == "capped" or self.sol.reason.startswith("wall cap") else "bd"
        return f"{self.sol.t_reached:.3g} {tag}"

    def ratio_cell(self):
        if not math.isfinite(self.ratio):
            return "—"
        return f"{self.ratio:.4g} @ {self.t_out:.3g}"


def measure(case, arithmetic, setting, T, sol, wall, oracle, names, final_widths=None):
    """A Run with the ratio at the last output time > 0 and the containment check.
    ``final_widths``: the sampled hull widths at T to use when the run completed."""
    r = Run(case, arithmetic, setting, T, sol, wall)
    if oracle is not None:
        r.misses, r.checks = containment(sol, oracle)
    k = len(sol.t) - 1
    if k >= 1 and sol.t[k] > 0:
        w = sol.hull.width()[k]
        if final_widths is not None and sol.t[k] == T:
            true = np.asarray(final_widths, float)
        elif oracle is not None and sol.t[k] <= oracle.t_end:
            true = oracle.hull_width(float(sol.t[k]))
        else:
            true = None
        if true is not None:
            with np.errstate(divide="ignore", invalid="ignore"):
                ratios = np.where(true > 0, w / true, np.inf)
            i = int(np.argmax(ratios))
            r.ratio, r.t_out, r.comp = float(ratios[i]), float(sol.t[k]), names[i]
            r.extra["widths"] = w
            r.extra["true"] = true
    return r


def best(runs):
    """Completed runs first (smallest ratio, then fastest), then the furthest reached."""
    def key(r):
        if r.completed:
            return (0, r.ratio if math.isfinite(r.ratio) else math.inf, r.wall)
        return (1, -r.sol.t_reached, r.ratio if math.isfinite(r.ratio) else math.inf)
    return min(runs, key=key)


def setting_label(opts):
    parts = [f"o{opts.get('order', 12)} {opts.get('tol', 1e-10):.0e}"]
    parts += [f"{k}={v}" if k != "cap" else f"cap {v:g} s" for k, v in opts.items() if k not in ("order", "tol")]
    return " ".join(parts)


def sweep(case, settings, run_one, log):
    """Run ``run_one(arithmetic, opts)`` for every arithmetic and setting: {arithmetic: [Run]}."""
    out = {}
    for a in ARITHMETICS:
        out[a] = []
        for opts in settings[a]:
            r = run_one(a, opts)
            out[a].append(r)
            log(r)
    return out


def _ratio_history(sol, oracle, every=2):
    """'t: ratio (component)' at every ``every``-th output time > 0 up to the oracle's end."""
    cells = []
    for k, (t, boxes) in enumerate(zip(sol.t, sol.boxes)):
        if t <= 0 or t > oracle.t_end + 1e-12 or k % every:
            continue
        w = boxes.hi.reshape(-1, boxes.shape[-1]).max(axis=0) - boxes.lo.reshape(-1, boxes.shape[-1]).min(axis=0)
        true = oracle.hull_width(float(t))
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.where(true > 0, w / true, np.inf)
        i = int(np.argmax(r))
        cells.append(f"{t:.2g}: {r[i]:.3g} ({oracle.names[i]})")
    return ", ".join(cells)


def chain_box(q0, eps):
    q0 = np.asarray(q0, float)
    z = np.zeros_like(q0)
    return np.r_[q0 - eps, z], np.r_[q0 + eps, z]


def chain_names(chain):
    return [f"q{i + 1}" for i in range(chain.n)] + [f"qd{i + 1}" for i in range(chain.n)]


def split_opts(opts, cap):
    """(solver options, wall cap): a setting may carry its own ``cap`` (overrides)."""
    opts = dict(opts)
    return opts, float(opts.pop("cap", cap))


def run_chain(chain, lo, hi, T, mode, arithmetic, opts, cap, subdivision=None):
    """``mbs.simulate.simulate`` (outputs every T/20), capped."""
    box = Interval(lo, hi)
    opts, cap = split_opts(opts, cap)

    def call(hooks):
        return simulate(chain, box, T, mode=mode, arithmetic=arithmetic, output_dt=T / 20,
                        subdivision=subdivision, hooks=hooks, **opts)

    return capped(call, cap)


_ODES = {}


def run_chain_solver(chain, lo, hi, T, arithmetic, opts, cap):
    """``verified.solver.solve`` on the numeric model's rhs graph (what mode i integrates),
    outputs every T/20, without simulate()'s M(q) > 0 proof (see case 4)."""
    from mbs.simulate import output_times, system_for
    key = (chain.fingerprint(), arithmetic)
    if key not in _ODES:
        _ODES[key] = VerifiedODE(system_for(chain, "i").rhs, arithmetic)
    opts, cap = split_opts(opts, cap)

    def call(hooks):
        return solve(_ODES[key], Interval(lo, hi), (0.0, T), t_eval=output_times(0.0, T, T / 20),
                     hooks=hooks, **opts)

    return capped(call, cap)


def mass_matrix_proven(chain, lo, hi):
    """Does simulate()'s M(q) > 0 proof (interval LDL^T pivots, bisection) pass on the
    initial q box?"""
    from mbs.simulate import pivots_proven
    n = chain.n
    return bool(pivots_proven(chain.numeric().pivot_graph(), lo[None, :n], hi[None, :n])[0])


# -------------------------------------------------------------------------- tables

def md_table(header, rows):
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def sound_cell(runs):
    runs = [r for r in runs if r.checks]
    if not runs:
        return "—"
    bad = [r for r in runs if not r.sound]
    if not bad:
        return "SOUND"
    return "UNSOUND (" + ", ".join(f"{r.arithmetic} {r.setting}: {r.misses}/{r.checks}" for r in bad) + ")"


SIDE_HEADER = ["interval: reached", "ratio @ t", "comp", "wall s", "setting",
               "affine: reached", "ratio @ t", "comp", "wall s", "setting", "sound"]


def side_cells(by_arith):
    cells = []
    for a in ARITHMETICS:
        if not by_arith[a]:  # (a row run in one arithmetic only)
            cells += ["—", "—", "", "—", "not run"]
            continue
        b = best(by_arith[a])
        cells += [b.reached(), b.ratio_cell(), b.comp, f"{b.wall:.1f}", b.setting]
    cells.append(sound_cell([r for a in ARITHMETICS for r in by_arith[a]]))
    return cells


def all_runs_table(labelled):
    """Every run: [(label, {arithmetic: [Run]})]."""
    rows = []
    for label, by_arith in labelled:
        for a in ARITHMETICS:
            for r in by_arith[a]:
                rows.append([label, r.arithmetic, r.setting, r.reached(), r.ratio_cell(), r.comp, f"{r.wall:.1f}",
                             r.sol.stats.get("steps", ""), "SOUND" if r.sound else f"UNSOUND {r.misses}/{r.checks}",
                             (r.sol.reason or "")[:90].replace("|", "/")])
    return md_table(["run", "arithmetic", "setting", "reached", "ratio @ t", "comp", "wall s", "steps",
                     "sound", "reason"], rows)


# -------------------------------------------------------------------------- cases

class Bench:
    def __init__(self, quick=False, cap=60.0, verbose=True, out=print):
        self.quick, self.cap, self.verbose, self.out = quick, cap, verbose, out
        self.results = {}  # case -> list of (label, {arithmetic: [Run]})

    def log(self, r):
        if self.verbose:
            print(f"  [{r.case}] {r.arithmetic:8s} {r.setting:34s} reached {r.reached():>10s}  "
                  f"ratio {r.ratio_cell():>16s}  wall {r.wall:6.1f}  steps {r.sol.stats.get('steps')}  "
                  f"{'SOUND' if r.sound else 'UNSOUND'}  {r.sol.reason[:80]}", file=sys.stderr, flush=True)

    def robot_settings(self, *extra):
        """Settings tried on the robot cases (the same for both arithmetics)."""
        if self.quick:
            return {a: [dict(order=8, tol=1e-10)] for a in ARITHMETICS}
        base = [dict(order=8, tol=1e-10), dict(order=12, tol=1e-10), dict(order=12, tol=1e-12),
                dict(order=8, tol=1e-10, absorb=True), dict(order=12, tol=1e-12, absorb=True)]
        return {a: base + list(extra) for a in ARITHMETICS}

    def _chain_case(self, label, chain, q0, eps, T, mode="i", subdivision=None, oracle=None, settings=None,
                    case="", runner=None):
        lo, hi = chain_box(q0, eps)
        names = chain_names(chain)
        if oracle is None:
            oracle = Oracle(pinocchio_rhs(chain), sample_points(lo, hi, 60 if self.quick else 100), T, names)
        settings = settings or self.robot_settings()
        if mode != "i":  # absorb=True does not go with the energy test (modes ii, iii)
            settings = {a: [o for o in opts if not o.get("absorb")] for a, opts in settings.items()}

        def one(a, opts):
            if runner is None:
                sol, wall = run_chain(chain, lo, hi, T, mode, a, opts, self.cap, subdivision)
            else:
                sol, wall = runner(chain, lo, hi, T, a, opts, self.cap)
            return measure(case or label, a, setting_label(opts), T, sol, wall, oracle, names)

        return sweep(label, settings, one, self.log), oracle

    # 1 -------------------------------------------------------------------------
    def arm3(self):
        from models.planar import planar_chain
        chain = planar_chain(3)
        T = 0.5 if self.quick else 2.0
        epss = (1e-4, 1e-6) if self.quick else (0.01, 1e-3, 1e-4, 1e-6)
        rows, labelled = [], []
        for eps in epss:
            # error_basis "auto" goes further on the wide boxes but ends in tiny steps: capped at 30 s
            settings = self.robot_settings(*([dict(order=12, tol=1e-10, error_basis="auto", cap=30.0)]
                                             if eps >= 1e-3 else []))
            by, oracle = self._chain_case(f"eps {eps:g}", chain, Q0_ARM3, eps, T, settings=settings, case="arm3")
            rows.append([f"{eps:g}", "1", f"{T:g}"] + side_cells(by))
            labelled.append((f"eps {eps:g}", by))
            if eps == 0.01 and not self.quick:
                for k in (2, 4):
                    sub = [k, k, k, 1, 1, 1]
                    by, _ = self._chain_case(f"eps 0.01, {k}^3 pieces", chain, Q0_ARM3, eps, T,
                                             subdivision=sub, oracle=oracle, case="arm3",
                                             settings={a: [dict(order=8, tol=1e-10)] for a in ARITHMETICS})
                    rows.append([f"{eps:g}", f"{k ** 3}", f"{T:g}"] + side_cells(by))
                    labelled.append((f"eps 0.01, {k}^3 pieces", by))
        self.results["arm3"] = labelled
        return ("### 1. 3-link planar arm (DH), q0 = (0.5, -0.3, 0.2), qd = 0, mode i\n\n"
                "Target: eps = 0.01 verified to T = 2 with ratio <= 1.5 in <= 60 s. Outputs every 0.1 s.\n\n"
                + md_table(["eps", "pieces", "T"] + SIDE_HEADER, rows))

    # 2 -------------------------------------------------------------------------
    def ur5(self):
        from models.robots import ur5
        chain = ur5()
        T = 0.1 if self.quick else 1.0
        rows, labelled, oracle = [], [], None
        for mode in ("i", "ii"):
            by, oracle = self._chain_case(f"UR5 mode {mode}", chain, Q0_UR5, 1e-3, T, mode=mode, oracle=oracle,
                                          case="ur5")
            rows.append([mode, f"{T:g}"] + side_cells(by))
            labelled.append((f"UR5 mode {mode}", by))
        # the setting that meets the target: second-order sets by composition (case 8),
        # through simulate() in both modes (mode ii: the energy state h rides in the sets,
        # contracted and branched-and-pruned at the tests)
        lo, hi = chain_box(Q0_UR5, 1e-3)
        names = chain_names(chain)
        opts = dict(order=8, tol=1e-10, error_basis="auto", set_order=2, params_per_state=12,
                    set_step="composition", cap=max(self.cap, 150.0))
        comp_rows = []
        for mode in ("i", "ii"):
            sol, wall = run_chain(chain, lo, hi, T, mode, "taylor_model", opts, self.cap)
            r = measure("ur5", "composition", setting_label(opts), T, sol, wall, oracle, names)
            self.log(r)
            st = sol.stats
            comp_rows.append([mode, f"{T:g}", r.reached(), r.ratio_cell(), f"{wall:.1f}", str(st.get("steps")),
                              str(st.get("tests", "—")), str(st.get("pruned_boxes", "—")),
                              "—" if mode == "i" else f"{st.get('contractions')} ({st.get('contractions_skipped')} skipped)",
                              "SOUND" if r.sound else "**UNSOUND**"])
            labelled.append((f"UR5 mode {mode}, composition", {"interval": [], "affine": [r]}))
        self.results["ur5"] = labelled
        return ("### 2. UR5, q0 = (0, -1, 1, -0.5, 0.5, 0), eps = 1e-3, qd = 0\n\n"
                "Target: T = 1, ratio <= 1.5 in <= 60 s, modes i and ii. Outputs every 0.05 s.\n\n"
                + md_table(["mode", "T"] + SIDE_HEADER, rows)
                + "\n\nSecond-order sets by composition (`simulate(..., set_order=2, set_step=\"composition\", "
                "arithmetic=\"taylor_model\", error_basis=\"auto\", order=8, tol=1e-10, params_per_state=12)`; "
                "150-s cap). Mode ii carries the energy state and runs the test (contraction with back-off, "
                "branch and prune at t*):\n\n"
                + md_table(["mode", "T", "reached", "ratio @ t", "wall s", "steps", "tests", "pruned",
                            "contractions", "sound"], comp_rows))

    # 3 -------------------------------------------------------------------------
    def panda(self):
        from models.robots import panda_arm
        chain = panda_arm()
        T = 0.05 if self.quick else 1.0
        by, _ = self._chain_case("Panda mode i", chain, Q0_PANDA, 1e-3, T, case="panda")
        self.results["panda"] = [("Panda mode i", by)]
        return ("### 3. Panda (fingers locked), q0 = (0, -pi/4, 0, -3pi/4, 0, pi/2, pi/4), eps = 1e-3, "
                "qd = 0, mode i\n\nTarget: T = 1, ratio <= 1.5 in <= 60 s. Outputs every 0.05 s.\n\n"
                + md_table(["T"] + SIDE_HEADER, [[f"{T:g}"] + side_cells(by)]))

    # 4 -------------------------------------------------------------------------
    def chains(self):
        from models.planar import planar_chain
        T = 0.2 if self.quick else 1.0
        ns = range(2, 5) if self.quick else range(2, 8)
        settings = ({a: [dict(order=8, tol=1e-10)] for a in ARITHMETICS} if self.quick else
                    {a: [dict(order=8, tol=1e-10), dict(order=12, tol=1e-10)] for a in ARITHMETICS})
        rows, labelled = [], []
        for n in ns:
            chain = planar_chain(n)
            lo, hi = chain_box(chain_q0(n), 1e-3)
            proven = mass_matrix_proven(chain, lo, hi)
            by, oracle = self._chain_case(f"n = {n}", chain, chain_q0(n), 1e-3, T, settings=settings,
                                          case="chains", runner=run_chain_solver)
            rows.append([str(n), f"{T:g}", "yes" if proven else "**no**"] + side_cells(by))
            labelled.append((f"n = {n}", by))
        self.results["chains"] = labelled
        return ("### 4. Planar n-link chains (rods), q0 = (0.5, -0.3, 0.2, -0.3, ...), eps = 1e-3, qd = 0\n\n"
                "`solve` on the numeric model's rhs graph (what mode i integrates), outputs every 0.05 s. "
                "simulate() is not used here: its M(q) > 0 proof (interval LDL^T pivots with bisection) fails "
                "on the initial box itself for n >= 5 (column \"M > 0 proven\"), which stops every run at "
                "t = 0; M(q) of these chains is positive definite for every q (rods of positive mass and "
                "inertia), so the solver's own reach is what is shown.\n\n"
                + md_table(["n", "T", "M > 0 proven at t = 0"] + SIDE_HEADER, rows))

    # 5 -------------------------------------------------------------------------
    def dp(self):
        graph = trace(dp.rhs, 4)
        odes = {a: VerifiedODE(graph, a) for a in ARITHMETICS}
        lo, hi = dp.initial_box()
        names = ["x1", "x2", "x3", "x4"]
        both = lambda *s: {a: list(s) for a in ARITHMETICS}  # noqa: E731
        if self.quick:
            plan = [("one box", 1.0, 1, np.arange(21) / 20, False, both(dict(order=12, tol=1e-10))),
                    ("T = 0.5, 16 pieces", 0.5, 16, [0.5], True, both(dict(order=12, tol=1e-10)))]
        else:
            plan = [("one box", 3.0, 1, np.arange(61) / 20, False,
                     both(dict(order=12, tol=1e-10), dict(order=16, tol=1e-12),
                          dict(order=12, tol=1e-10, error_basis="auto"),
                          dict(order=12, tol=1e-10, error_basis="auto", set_order=2))),
                    # the furthest found: Taylor-model Jacobians, second-order sets with 12
                    # parameters per state (4 by default) and order 6 (the affine column:
                    # taylor_model is affine Taylor coefficients plus degree-2 Jacobians)
                    ("one box, taylor_model", 3.0, 1, np.arange(61) / 20, False,
                     {"interval": [], "affine": [dict(order=6, tol=1e-10, error_basis="auto", set_order=2,
                                                      arithmetic="taylor_model", params_per_state=12)]}),
                    ("T = 1, 256 pieces", 1.0, 256, [1.0], True,
                     both(dict(order=12, tol=1e-10), dict(order=8, tol=1e-9), dict(order=12, tol=1e-10, absorb=True))),
                    # second-order sets (verified/sets/second_order.py): far fewer pieces for the same width
                    ("T = 1, 64 pieces, set_order 2", 1.0, 64, [1.0], True,
                     {"interval": [dict(order=12, tol=1e-10, set_order=2)], "affine": []}),
                    # affine at 1024 pieces costs ~4 min per setting: one setting, cap 300 s
                    ("T = 3, 1024 pieces", 3.0, 1024, [3.0], True,
                     {"interval": [dict(order=12, tol=1e-10), dict(order=12, tol=1e-12),
                                   dict(order=12, tol=1e-10, absorb=True)],
                      "affine": [dict(order=12, tol=1e-10, cap=300.0)]}),
                    ("T = 3, 128 pieces, set_order 2", 3.0, 128, [3.0], True,
                     {"interval": [dict(order=12, tol=1e-10, set_order=2)], "affine": []})]
        horizon = max(p[1] for p in plan)
        oracle = Oracle(closed_form_rhs(dp), sample_points(lo, hi, 0 if self.quick else 200), horizon, names)
        rows, labelled = [], []
        for label, T, pieces, t_eval, final, settings in plan:
            true = bench_solver.true_hull_widths(T, 201 if self.quick else 2001) if final else None

            def one(a, setting, T=T, pieces=pieces, t_eval=t_eval, true=true):
                opts, cap = split_opts(setting, self.cap)
                ode = VerifiedODE(graph, opts.pop("arithmetic")) if "arithmetic" in opts else odes[a]

                def call(hooks):
                    return solve(ode, Interval(lo, hi), (0.0, T), t_eval=t_eval,
                                 subdivision=[pieces, 1, 1, 1], hooks=hooks, **opts)
                sol, wall = capped(call, cap)
                return measure("dp", a, setting_label(setting), T, sol, wall, oracle, names, final_widths=true)

            by = sweep(label, settings, one, self.log)
            rows.append([label] + side_cells(by))
            labelled.append((label, by))
        self.results["dp"] = labelled
        return ("### 5. Paper double pendulum (eq. 22, box eq. 25, x1(0) split into pieces)\n\n"
                "Targets: one box verified past 1.0 s; T = 1 (256 pieces) ratio <= 1.02 in <= 10 s; "
                "T = 3 (1024 pieces) ratio <= 1.1 in <= 60 s. One box: horizon 3, outputs every 0.05 s, "
                "ratio at the last one against the sampled hull; pieces: output at T only (as "
                "bench_solver.py), ratio against the 2001-point true hull.\n\n"
                + md_table(["run"] + SIDE_HEADER, rows))

    # 6 -------------------------------------------------------------------------
    def pendulum(self):
        graph = trace(pd.rhs, 2)
        odes = {a: VerifiedODE(graph, a) for a in ARITHMETICS}
        lo, hi = pd.initial_box()
        names = ["q", "qd"]
        T_short, T_long = (1.0, 1.5) if self.quick else (3.0, 10.0)
        grids = (1, 4) if self.quick else (1, 4, 64)
        oracle = Oracle(closed_form_rhs(pd), sample_points(lo, hi, 200 if self.quick else 500,
                                                           edge_points=50 if self.quick else 250), T_long, names)
        t_eval = np.arange(int(round(T_long * 10)) + 1) / 10  # k / 10: T_short is an output time exactly
        rows, labelled = [], []
        per_grid = {}
        for k in grids:
            # error_basis="auto" (the QR basis or a plain box per set and step, whichever is
            # tighter) is what follows the saddle at the top: one box and 4x4 run past the
            # C++ solver's reach, but with steps falling to ~1e-4 s once the sets are 1e3-1e5
            # wide; a cap of 300 s lets those runs end at their break-down (no time target here)
            auto = dict(order=12, tol=1e-10, error_basis="auto")
            if self.quick:
                settings = {a: [dict(order=12, tol=1e-10), auto] for a in ARITHMETICS}
            elif k < 64:
                settings = {a: [dict(order=12, tol=1e-10), dict(order=20, tol=1e-12)] for a in ARITHMETICS}
                settings["interval"].append(dict(auto, cap=max(self.cap, 300.0)))
            else:  # 4096 boxes: few settings (affine: ~0.5 s per step at order 12)
                settings = {a: [dict(order=12, tol=1e-10)] for a in ARITHMETICS}
                settings["interval"].append(auto)
            short, long_ = {a: [] for a in ARITHMETICS}, {a: [] for a in ARITHMETICS}
            for a in ARITHMETICS:
                for opts in settings[a]:
                    # one run to T_long serves both rows: the T_short row is its part up to T_short
                    # (same output grid; wall and steps when it passed T_short)
                    passed = {}

                    def hook(t, wall, passed=passed):
                        passed["steps"] = passed.get("steps", 0) + 1
                        if t >= T_short and "wall" not in passed:
                            passed["wall"], passed["at"] = wall, passed["steps"]

                    run_opts, cap = split_opts(opts, self.cap)

                    def call(hooks, a=a, run_opts=run_opts):
                        return solve(odes[a], Interval(lo, hi), (0.0, T_long), t_eval=t_eval, subdivision=[k, k],
                                     max_width=1e6, hooks=hooks, **run_opts)
                    sol, wall = capped(call, cap, on_progress=hook)
                    r_long = measure("pendulum", a, setting_label(opts), T_long, sol, wall, oracle, names)
                    part = truncated(sol, T_short)
                    r_short = measure("pendulum", a, setting_label(opts), T_short, part,
                                      passed.get("wall", wall), oracle, names)
                    if "at" in passed:
                        part.stats["steps"] = passed["at"]
                    self.log(r_long)
                    short[a].append(r_short)
                    long_[a].append(r_long)
            per_grid[k] = (short, long_)
        for T, idx in ((T_short, 0), (T_long, 1)):
            for k in grids:
                by = per_grid[k][idx]
                cells = side_cells(by)
                ws = []
                for a in ARITHMETICS:
                    b = best(by[a])
                    ws.append(" / ".join(f"{v:.4g}" for v in b.sol.hull.width()[-1]) + f" @ {b.sol.t[-1]:.3g}")
                rows.append([f"{T:g}", f"{k}x{k}"] + cells[:5] + [ws[0]] + cells[5:10] + [ws[1], cells[10]])
                labelled.append((f"T = {T:g}, {k}x{k}", by))
        self.results["pendulum"] = labelled
        header = (["T", "grid"] + SIDE_HEADER[:5] + ["interval widths q / qd"] + SIDE_HEADER[5:10]
                  + ["affine widths q / qd", "sound"])
        return ("### 6. Paper pendulum (eq. 18), q(0) in [2.1, 2.2], qd(0) in [3.1, 3.2], max_width 1e6\n\n"
                "C++ QR-Lohner, order 20: T = 3 completes from 1 piece (widths 5678 / 35040) and from 64x64 "
                "(20.3 / 54.9, ratio 4.39); T = 10 breaks down at 3.67 s (1 piece) and 4.12 s (4x4). "
                f"One run to T = {T_long:g} per grid and setting (outputs every 0.1 s); the T = {T_short:g} rows "
                f"are its part up to {T_short:g} (wall and steps when it passed {T_short:g}). Widths at the "
                "last output time reached.\n\n"
                + md_table(header, rows))

    # 7 -------------------------------------------------------------------------
    def qdd(self):
        from models.planar import planar_chain
        from verified.series.affine_taylor import AffineTaylorODE
        from verified.series.taylor import TaylorODE
        chain = planar_chain(3)
        lo, hi = chain_box(Q0_ARM3, 0.01)
        box = Interval(lo[None], hi[None])
        pts = sample_points(lo, hi, 2000 if self.quick else 20000)
        qdd = pinocchio_rhs(chain)(pts.T)[3:]
        sampled = qdd.max(axis=1) - qdd.min(axis=1)
        graphs = [("numeric (modes i, ii)", chain.numeric().rhs_graph())]
        if not self.quick:
            graphs.append(("symbolic (mode iii)", chain.symbolic().rhs_graph()))
        rows, sound = [], []
        for label, g in graphs:
            for a, ev in (("interval", TaylorODE(g)), ("affine", AffineTaylorODE(g))):
                c = ev.coefficients(box, 1)[:, 1, 3:]
                w = c.width()[0]
                contained = bool(np.all((c.lo[0][:, None] <= qdd) & (qdd <= c.hi[0][:, None])))
                sound.append(contained)
                rows.append([label, a] + [f"{v:.4g}" for v in w]
                            + [" / ".join(f"{v:.3g}" for v in w / sampled), "SOUND" if contained else "UNSOUND"])
        rows.append(["sampled (Pinocchio aba)", f"{pts.shape[0]} points"] + [f"{v:.4g}" for v in sampled]
                    + ["1", ""])
        self.results["qdd"] = sound
        return ("### 7. qdd enclosure over the 3-link box q0 +- 0.01, qd = 0 (order-1 Taylor coefficient)\n\n"
                "`TaylorODE(g).coefficients(box, 1)[:, 1, 3:]` (interval) and "
                "`AffineTaylorODE(g).coefficients(box, 1)[:, 1, 3:]` (affine). Target: within 2x of the "
                "sampled range.\n\n"
                + md_table(["model graph", "evaluator", "qdd1 width", "qdd2 width", "qdd3 width",
                            "width / sampled", "sound"], rows))

    # 8 -------------------------------------------------------------------------
    def composition(self):
        from models.planar import planar_chain
        from models.robots import panda_arm, ur5
        base = dict(order=8, tol=1e-10, error_basis="auto", set_order=2, params_per_state=12)
        if self.quick:
            plan = [("3-link arm, eps 1e-3", planar_chain(3), Q0_ARM3, 1e-3, 0.2, None)]
        else:
            plan = [("3-link arm, eps 0.01", planar_chain(3), Q0_ARM3, 0.01, 2.0, None),
                    ("3-link arm, eps 1e-3", planar_chain(3), Q0_ARM3, 1e-3, 2.0, None),
                    ("UR5, eps 1e-3 (cap 150 s)", ur5(), Q0_UR5, 1e-3, 1.0, 150.0),
                    ("Panda, eps 1e-3", panda_arm(), Q0_PANDA, 1e-3, 1.0, None)]
            plan += [(f"chain n = {n}, eps 1e-3", planar_chain(n), chain_q0(n), 1e-3, 1.0, None) for n in (4, 5, 6, 7)]
        rows, labelled, history = [], [], []
        oracles = {}
        for label, chain, q0, eps, T, cap in plan:
            lo, hi = chain_box(q0, eps)
            names = chain_names(chain)
            key = (chain.name, eps, T)
            if key not in oracles:
                oracles[key] = Oracle(pinocchio_rhs(chain), sample_points(lo, hi, 40 if self.quick else 60), T, names)
            oracle = oracles[key]
            by = {}
            for step, extra in STEPS_8.items():
                opts = dict(base, **extra)
                if cap is not None:
                    opts["cap"] = cap
                sol, wall = run_chain_solver(chain, lo, hi, T, "taylor_model", opts, self.cap)
                r = measure("composition", step, setting_label(opts), T, sol, wall, oracle, names)
                self.log(r)
                by[step] = r
                if step == "degree 3":
                    history.append([label] + [_ratio_history(sol, oracle)])
            rows.append([label, f"{T:g}"] + [c for s in STEPS_8 for c in
                                             (by[s].reached(), by[s].ratio_cell(), f"{by[s].wall:.1f}",
                                              str(by[s].sol.stats.get("steps")))]
                        + ["SOUND" if all(r.sound for r in by.values()) else "**UNSOUND**"])
            labelled.append((label, {"interval": [by["mean_value"]], "affine": [by["degree 3"]]}))
        # the double pendulum from one box (closed-form rhs; its own oracle)
        if not self.quick:
            g = VerifiedODE(trace(dp.rhs, 4), "taylor_model")
            lo, hi = dp.initial_box()
            oracle = Oracle(closed_form_rhs(dp), sample_points(lo, hi, 100), 1.5, ["x1", "x2", "x3", "x4"])
            by = {}
            for step, extra in STEPS_8.items():
                opts = dict(base, order=6, **extra)

                def call(hooks, opts=opts):
                    return solve(g, Interval(lo, hi), (0.0, 3.0), t_eval=np.arange(61) / 20, hooks=hooks,
                                 **opts)

                sol, wall = capped(call, self.cap)
                r = measure("composition", step, setting_label(opts), 3.0, sol, wall, oracle, oracle.names)
                self.log(r)
                by[step] = r
            rows.append(["double pendulum, one box", "3"] + [c for s in STEPS_8 for c in
                                                             (by[s].reached(), by[s].ratio_cell(), f"{by[s].wall:.1f}",
                                                              str(by[s].sol.stats.get("steps")))]
                        + ["SOUND" if all(r.sound for r in by.values()) else "**UNSOUND**"])
            labelled.append(("double pendulum, one box", {"interval": [by["mean_value"]],
                                                          "affine": [by["degree 3"]]}))
        self.results["composition"] = labelled
        head = ["case", "T"] + [f"{s}: {c}" for s in STEPS_8
                                for c in ("reached", "ratio @ t", "wall s", "steps")] + ["sound"]
        return ("### 8. Second-order sets: mean-value step against composition in Taylor models of degree 2, 3 and 4\n\n"
                "`solve(..., set_order=2, arithmetic=\"taylor_model\", error_basis=\"auto\", order=8, tol=1e-10, "
                "params_per_state=12, ...)` on the numeric rhs graph (the double pendulum: eq. 22 traced, order 6), "
                "with `set_step=\"mean_value\"`, and `set_step=\"composition\"` with `model_degree=2`, 3 (the default) and 4. "
                f"Wall cap {self.cap:g} s unless the row says otherwise.\n\n"
                + md_table(head, rows)
                + "\n\nWorst ratio (component) at every output time, composition of degree 3:\n\n"
                + md_table(["case", "t: ratio"], history))

    # 9 -------------------------------------------------------------------------
    def pendulum_composition(self):
        g = VerifiedODE(trace(pd.rhs, 2), "taylor_model")
        lo, hi = pd.initial_box()
        names = ["q", "qd"]
        plan = [(1, 1.5), (2, 1.5)] if self.quick else [(1, 3.0), (1, 10.0), (4, 10.0), (16, 3.0)]
        T_max = max(T for _, T in plan)
        oracle = Oracle(closed_form_rhs(pd), sample_points(lo, hi, 200 if self.quick else 500,
                                                           edge_points=50 if self.quick else 250), T_max, names)
        rows, runs = [], []
        for k, T in plan:
            opts = dict(order=12, tol=1e-10, error_basis="auto", set_order=2, set_step="composition")

            def call(hooks, T=T, k=k):
                return solve(g, Interval(lo, hi), (0.0, T), t_eval=np.arange(int(round(T * 10)) + 1) / 10,
                             subdivision=[k, k], max_width=1e6, hooks=hooks, **opts)

            sol, wall = capped(call, self.cap)
            r = measure("pendulum_composition", "composition", setting_label(opts), T, sol, wall, oracle, names)
            self.log(r)
            runs.append(r)
            w = r.extra.get("widths", [math.nan, math.nan])
            rows.append([f"{k}x{k}", f"{T:g}", r.reached(), r.ratio_cell(), f"{w[0]:.4g} / {w[1]:.4g}",
                         f"{wall:.1f}", str(sol.stats.get("steps")), "SOUND" if r.sound else "**UNSOUND**"])
        self.results["pendulum_composition"] = [(f"{k}x{k}, T = {T:g}", {"interval": [], "affine": [r]})
                                                for (k, T), r in zip(plan, runs)]
        return ("### 9. The pendulum over the top, second-order sets by composition\n\n"
                "q(0) in [2.1, 2.2], qd(0) in [3.1, 3.2]; `solve(..., set_order=2, set_step=\"composition\", "
                "arithmetic=\"taylor_model\", error_basis=\"auto\", order=12, tol=1e-10, max_width=1e6)`. "
                "The C++ QR-Lohner solver (order 20): T = 3 from 1 piece widths 5678 / 35040, from 64x64 "
                "20.3 / 54.9 (ratio 4.39); T = 10 breaks down at 3.67 s (1 piece) and 4.12 s (4x4).\n\n"
                + md_table(["grid", "T", "reached", "ratio @ t", "widths q / qd", "wall s", "steps", "sound"],
                           rows))

    # 10 ------------------------------------------------------------------------
    def arm3_pieces(self):
        """The 3-link arm +- 0.01 (case 1's target) as a 3 x 3 x 3 grid of q pieces, each
        a chunk of its own (own step sizes) on ``PIECES_WORKERS`` local Dask workers,
        second-order sets by composition as case 8 (degree 3): the one box breaks down at
        0.955 s, a +- 0.0033 piece reaches T = 2 (the pool of symbols)."""
        from models.planar import planar_chain
        chain = planar_chain(3)
        quick = self.quick
        eps, T, k = (1e-3, 0.2, 2) if quick else (0.01, 2.0, 3)
        lo, hi = chain_box(Q0_ARM3, eps)
        names = chain_names(chain)
        oracle = Oracle(pinocchio_rhs(chain), sample_points(lo, hi, 40 if quick else 60), T, names)
        opts = dict(order=8, tol=1e-10, error_basis="auto", set_order=2, params_per_state=12,
                    set_step="composition", subdivision=[k, k, k, 1, 1, 1], chunks=k ** 3,
                    workers=1 if quick else PIECES_WORKERS, cap=PIECES_CAP)
        sol, wall = run_chain_solver(chain, lo, hi, T, "taylor_model", opts, self.cap)
        r = measure("arm3_pieces", "degree 3", setting_label(opts), T, sol, wall, oracle, names)
        self.log(r)
        self.results["arm3_pieces"] = [(f"3-link arm, eps {eps:g}, {k}^3 pieces", {"interval": [], "affine": [r]})]
        row = [f"3-link arm, eps {eps:g}", f"{T:g}", f"{k}x{k}x{k}", str(opts["workers"]), r.reached(),
               r.ratio_cell(), f"{wall:.1f}", str(sol.stats.get("steps")), "SOUND" if r.sound else "**UNSOUND**"]
        return ("### 10. The 3-link arm +- 0.01 in pieces, each a chunk of its own\n\n"
                "`solve(..., set_order=2, set_step=\"composition\", arithmetic=\"taylor_model\", error_basis=\"auto\", "
                f"order=8, tol=1e-10, params_per_state=12, subdivision=[{k}, {k}, {k}, 1, 1, 1], chunks={k ** 3}, "
                f"workers=...)`; wall cap {PIECES_CAP:g} s. Steps are summed over the chunks.\n\n"
                + md_table(["case", "T", "pieces", "workers", "reached", "ratio @ t", "wall s", "steps", "sound"], [row]))

    def runs(self):
        """Every Run measured (for tests)."""
        return [r for case, labelled in self.results.items() if case != "qdd"
                for _, by in labelled for a in ARITHMETICS for r in by[a]]

    def all_runs(self):
        parts = []
        for case, labelled in self.results.items():
            if case == "qdd":
                continue
            parts.append(f"#### all runs: {case}\n\n" + all_runs_table(labelled))
        return "\n\n".join(parts)


def warm_up():
    """Compile/load the numba kernels of both arithmetics before timing anything."""
    g = trace(dp.rhs, 4)
    lo, hi = dp.initial_box()
    for a in ARITHMETICS:
        solve(g, Interval(lo, hi), (0.0, 0.02), arithmetic=a, subdivision=[2, 1, 1, 1])


def code_version():
    """``git`` commit of the code measured (and whether verified/, mbs/, models/ differ from it)."""
    import subprocess
    root = Path(__file__).resolve().parents[1]
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True,
                              text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "verified", "mbs", "models"], cwd=root,
                               capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head + (" + uncommitted changes in verified/, mbs/ or models/" if dirty else "")


def parse_only(spec):
    if not spec:
        return list(CASES.values())
    out = []
    for tok in spec.replace(" ", "").split(","):
        name = CASES.get(int(tok)) if tok.isdigit() else tok
        if name not in CASES.values():
            raise SystemExit(f"--only: unknown case {tok!r}; choose from {CASES}")
        out.append(name)
    return out


def main(argv=None, out=print):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--only", default="", help="cases to run: numbers or names, comma-separated, e.g. 1,7 or arm3,qdd")
    p.add_argument("--quick", action="store_true", help="small versions (about 1-2 min in all)")
    p.add_argument("--cap", type=float, default=60.0, help="wall cap per run in seconds (default 60; a "
                   "setting may carry its own: error_basis auto 30 s, affine double pendulum at 1024 pieces 300 s)")
    p.add_argument("--quiet", action="store_true", help="no per-run log on stderr")
    args = p.parse_args(argv)
    cases = parse_only(args.only)
    t0 = time.perf_counter()
    warm_up()
    bench = Bench(quick=args.quick, cap=args.cap, verbose=not args.quiet, out=out)
    cmd = "python benchmarks/bench_robots.py " + " ".join(argv if argv is not None else sys.argv[1:])
    out(f"## Robots benchmark (issue 17): interval vs affine Taylor coefficients\n\n`{cmd.rstrip()}` "
        f"(code at {code_version()})\n")
    for name in cases:
        t = time.perf_counter()
        if not args.quiet:
            print(f"case {name} ...", file=sys.stderr, flush=True)
        out(getattr(bench, name)())
        out(f"\n({name}: {time.perf_counter() - t:.0f} s including the oracle)\n")
    extra = bench.all_runs()
    if extra:
        out("### All runs\n\n" + extra + "\n")
    out(f"total wall {time.perf_counter() - t0:.0f} s")
    return bench


if __name__ == "__main__":
    # one core against one core (CAPD, earlier runs): workers=None stays one in-process
    # batch here (bench_parallel measures the cluster; explicit workers= are kept)
    import verified.execution.plan
    verified.execution.plan.DEFAULT_PARALLEL = False
    main()

"""A stand-in for mbs.simulate used only while the real module is missing (the CLI,
figure and bench tests switch to the real one automatically once it exists).

Mode i is the plain verified solver; modes ii/iii add a consistency record computed
after the fact (H_H over the tube, H_V = [H(x0)] for a conservative model) so that the
figures have something of the right shape to draw. It prunes nothing.
"""
from types import SimpleNamespace

import numpy as np

from verified.interval import Interval, hull
from verified.solver import solve

MODES = ("i", "ii", "iii")


def output_times(t0, t_end, output_dt):
    if output_dt is None:
        return np.array([t_end])
    k = np.arange(1, int(np.floor((t_end - t0) / output_dt * (1 + 1e-12))) + 1)
    ts = t0 + k * output_dt
    ts = ts[ts <= t_end]
    return ts if ts.size and ts[-1] >= t_end * (1 - 1e-12) else np.append(ts, t_end)


def system_for(model, mode="ii", energy_rate="unsimplified"):
    import mbs.runner as r
    import sys
    saved = sys.modules.pop("mbs.simulate")
    try:
        return r.reference_system(model)
    finally:
        sys.modules["mbs.simulate"] = saved


def simulate(model, x0, t_end, *, mode="ii", output_dt=None, params=None, order=12, tol=1e-10,
             subdivision=None, energy_rate="unsimplified", test_interval=0.1, test_splits=10,
             split_strategy="gradient", backward_depth=0, progress=None, **kw):
    system = system_for(model)
    sol = solve(system.rhs, x0, (0.0, t_end), t_eval=output_times(0.0, t_end, output_dt), order=order, tol=tol,
                subdivision=subdivision, **kw)
    if progress is not None:
        for t in sol.tube_t:
            progress(float(t), t_end)
    sol.state_names = system.state_names
    sol.mode = mode
    sol.consistency = None
    sol.stats.update(max_boxes=sol.stats["final_boxes"], pruned_boxes=0, tests=0, test_s=0.0, backward_s=0.0)
    if mode != "i" and system.energy is not None and len(sol.tube):
        hh = system.energy.eval_interval(sol.tube_hull)[..., 0]
        h0 = hull(system.energy.eval_interval(Interval(x0.lo, x0.hi))[..., 0])
        hv = Interval(np.full(hh.shape, float(h0.lo)), np.full(hh.shape, float(h0.hi)))
        cut = hh.intersect(hv)
        ra = np.asarray(hh.width()) - np.where(cut.is_empty(), 0.0, np.asarray(cut.width()))
        k = min(len(sol.t) - 1, max(1, len(sol.t) // 2))
        cand = hull(sol.boxes[k], axis=0).subdivide([test_splits] + [1] * (x0.shape[-1] - 2) + [test_splits])
        cand = cand.reshape(-1, x0.shape[-1])
        hc = system.energy.eval_interval(cand)[..., 0]
        kept = np.asarray(hc.overlaps(Interval(float(h0.lo), float(h0.hi))))
        rec = SimpleNamespace(t=float(sol.t[k]), candidates=cand, kept=kept, h_v=h0)
        sol.consistency = SimpleNamespace(ra_t=np.asarray(sol.tube_t[1:]), ra=ra, h_h=hh, h_v=hv, tests=[rec])
        sol.stats["tests"] = 1
    return sol


def compare_modes(model, x0, t_end, **kw):
    return {m: simulate(model, x0, t_end, mode=m, **kw) for m in MODES}

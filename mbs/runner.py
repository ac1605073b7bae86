"""Run a scene: simulate, check against sampled trajectories, write result.json and
the figures (the body of ``python -m mbs simulate``)."""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from .errors import ModelError
from .scene import Scene, SceneError, output_times

__all__ = ["run_scene", "reference_system", "check_samples"]


def reference_system(model, mode="ii", energy_rate="unsimplified"):
    """The :class:`mbs.system.System` of a model (a name or a Chain) in ``mode``: the
    float right-hand side for sampling and the energy graph for Fig. 3.

    Uses :func:`mbs.simulate.system_for` (the system the simulation integrates);
    falls back to the numeric model / the paper's hand-written equations.
    """
    try:
        from .simulate import system_for
    except ImportError:
        system_for = None
    if system_for is not None:
        return system_for(model, "ii" if mode == "i" else mode, energy_rate=energy_rate)
    from .system import System
    if isinstance(model, System):
        return model
    if isinstance(model, str):
        if model == "double_pendulum_paper":
            from models import double_pendulum as dp
            return System("double_pendulum_paper", dp.rhs_graph(), dp.energy_graph())
        if model == "pendulum_paper":
            from models import pendulum
            from verified.graph import trace
            rhs = trace(pendulum.rhs, 2, input_names=["q", "qd"], output_names=["dq", "dqd"])
            H = trace(lambda x, p: [pendulum.hamiltonian(x)], 2, input_names=["q", "qd"], output_names=["H"])
            return System("pendulum_paper", rhs, H)
        from models.registry import get
        model = get(model)
    num = model.numeric()
    return System(model.name, num.rhs_graph(), num.energy_graph(), num.energy_rate_graph())


def check_samples(sol, samples, slack=1e-9):
    """Indices (sample, output) of sampled states outside the union of the boxes.
    ``samples``: (S, k, n) states at ``sol.t`` (NaN rows are skipped)."""
    bad = []
    for k, boxes in enumerate(sol.boxes):
        lo = np.asarray(boxes.lo, float).reshape(-1, samples.shape[-1])
        hi = np.asarray(boxes.hi, float).reshape(-1, samples.shape[-1])
        x = samples[:, k, :]
        ok_rows = np.isfinite(x).all(axis=1)
        tol = slack * (1.0 + np.abs(x))
        inside = ((lo[None] - tol[:, None] <= x[:, None]) & (x[:, None] <= hi[None] + tol[:, None])).all(-1).any(-1)
        for s in np.flatnonzero(ok_rows & ~inside):
            bad.append((int(s), k))
    return bad


def run_scene(scene: Scene, out, *, mode=None, t_end=None, output_dt=None, samples=None,
              figures=True, log=None, progress=True) -> dict:
    """Simulate ``scene`` and write ``out``/result.json (+ figures). Returns a report
    dict: solution, paths, sample check (``escaped``: sampled states outside)."""
    from .figures import (fig_consistency_plane, fig_enclosures, fig_reduction_area,
                          sample_initial_points, sample_trajectories)
    from .progress import Progress
    from .results import write_result
    from .simulate import simulate

    log = log or (lambda *a, **k: None)
    out = Path(out)
    mode = mode or scene.mode
    t_end = float(t_end if t_end is not None else scene.t_end)
    dt = output_dt if output_dt is not None else scene.output_dt
    samples = 64 if samples is None else int(samples)

    t0 = time.perf_counter()
    model = scene.build_model()
    try:
        system = reference_system(model, mode, scene.consistency.get("energy_rate", "unsimplified"))
    except Exception as e:  # noqa: BLE001 - a model that cannot be built is a scene problem
        raise SceneError(f"{scene.source}: cannot build the model: {type(e).__name__}: {e}") from None
    names = system.state_names
    x0 = scene.initial_box(names)
    kw = scene.simulate_kwargs(names)
    kw["mode"] = mode
    t_model = time.perf_counter() - t0
    log(f"{scene.name}: mode {mode}, {len(names)} states ({', '.join(names)}), t_end = {t_end:g} s")
    bar = Progress(t_end, f"mode {mode}", enabled=None if progress else False)
    try:
        sol = simulate(model, x0, t_end, output_dt=dt, progress=bar, **kw)
    except (ValueError, TypeError, ModelError) as e:  # settings the solver refuses
        raise SceneError(f"{scene.source}: cannot simulate: {e}") from None
    finally:
        bar.close()
    wall = time.perf_counter() - t0
    want = output_times(t_end, dt)
    report = {"solution": sol, "system": system, "escaped": 0, "checked": 0, "paths": {}}

    # sampled true trajectories: soundness check and figure overlay
    traj = traj_t = None
    if samples > 0 and len(sol.t) > 1:
        pts = sample_initial_points(np.asarray(x0.lo, float), np.asarray(x0.hi, float), samples)
        pvals = None
        if system.rhs.n_params:
            pvals = np.array([0.5 * (lo + hi) for lo, hi in (kw.get("params") or {}).values()])
        dense = np.linspace(0.0, float(sol.t[-1]), 201)
        traj_t = np.unique(np.concatenate([np.asarray(sol.t, float), dense]))
        traj = sample_trajectories(system.rhs, pts, traj_t, pvals)
        at_out = traj[:, np.searchsorted(traj_t, np.asarray(sol.t, float)), :]
        bad = check_samples(sol, at_out)
        report["escaped"] = len(bad)
        report["checked"] = int(pts.shape[0])
        if bad:
            log(f"WARNING: {len(bad)} sampled states lie outside the enclosure (first: sample {bad[0][0]} "
                f"at t = {sol.t[bad[0][1]]:g}); this is a bug, please report it")

    extra = {"wall_total_s": wall, "model_s": t_model, "samples_checked": report["checked"],
             "samples_escaped": report["escaped"], "output_times_requested": len(want) + 1}
    path = write_result(out / "result.json", sol, scene=scene.source, mode=mode,
                        state_names=list(getattr(sol, "state_names", None) or names), t_end=t_end,
                        extra_stats=extra)
    report["paths"]["result"] = path
    if figures:
        report["paths"]["enclosures"] = fig_enclosures(
            {mode: sol}, out / "enclosures.png", samples=traj, sample_times=traj_t,
            title=f"{scene.name}: enclosures, mode {mode}")
        cons = getattr(sol, "consistency", None)
        if cons is not None and len(getattr(cons, "ra_t", ())) > 1:
            report["paths"]["reduction_area"] = fig_reduction_area(sol, out / "reduction_area.png")
        if cons is not None and getattr(cons, "tests", None) and system.energy is not None:
            report["paths"]["consistency_plane"] = fig_consistency_plane(
                sol, system.energy, out / "consistency_plane.png")
    st = sol.stats
    w = sol.hull.width()[-1] if len(sol.t) else []
    log(f"{sol.status} at t = {sol.t_reached:g} s{(' (' + sol.reason + ')') if sol.reason else ''}; "
        f"{st.get('steps')} steps, {st.get('wall_s', 0):.2f} s solver, {wall:.2f} s total")
    if len(sol.t):
        log("final widths: " + ", ".join(f"{n} {float(v):.4g}" for n, v in zip(names, w)))
    if report["checked"]:
        log(f"{report['checked']} sampled trajectories: "
            f"{'all inside' if not report['escaped'] else str(report['escaped']) + ' states OUTSIDE'}")
    for k, p in report["paths"].items():
        log(f"wrote {p}")
    return report

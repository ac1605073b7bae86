"""Run a scene: simulate, check against sampled trajectories, write result.json and
the figures (the body of ``python -m mbs simulate``)."""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from .errors import ModelError
from .scene import Scene, SceneError, output_times
from .uncertain import ParameterError

__all__ = ["run_scene", "reference_system", "check_samples", "sample_points", "sample_states", "final_widths"]


def reference_system(model, mode="ii", energy_rate="unsimplified", params=None, control=None, q_init=None):
    """The :class:`mbs.system.System` of a model (a name or a Chain) in ``mode``: the
    float right-hand side for sampling and the energy graph for Fig. 3 (with the
    uncertain ``params`` as graph parameters, see :func:`mbs.simulate.simulate`;
    under ``control`` the closed loop, with the state ``t`` for time-dependent
    references). Uses :func:`mbs.simulate.system_for` (the system the simulation
    integrates)."""
    from .simulate import system_for
    return system_for(model, "ii" if mode == "i" else mode, energy_rate=energy_rate, params=params,
                      control=control, q_init=q_init)


def sample_points(lo, hi, count: int, seed: int = 0) -> np.ndarray:
    """Exactly ``count`` points (count, d) of the box [lo, hi]: its centre, then corners
    (all of them if ``count`` allows, in a fixed pseudo-random order otherwise), then
    uniform random points."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    if count <= 0:
        return np.zeros((0, lo.size))
    rng = np.random.default_rng(seed)
    pts = [(lo + hi) / 2]
    free = np.flatnonzero(hi > lo)
    n_corners = 2 ** free.size if free.size < 62 else None
    want = count - 1
    if n_corners is not None and n_corners <= want:
        codes = np.arange(n_corners)
    else:
        codes = rng.choice(n_corners, size=want, replace=False) if n_corners is not None and n_corners < 2**20 \
            else rng.integers(0, 2, size=(want, free.size))
    for c in codes[:want]:
        p = lo.copy()
        bits = c if isinstance(c, np.ndarray) else np.array([(int(c) >> k) & 1 for k in range(free.size)])
        p[free] = np.where(bits.astype(bool), hi[free], lo[free])
        pts.append(p)
    rest = count - len(pts)
    if rest > 0:
        pts.extend(lo + rng.uniform(0, 1, (rest, lo.size)) * (hi - lo))
    return np.array(pts[:count])


def sample_states(system, x0_lo, x0_hi, count: int, times, params=None, seed: int = 0):
    """(states (S, len(times), n), initial points (S, n + p)): DOP853 trajectories of
    ``system.rhs`` (rtol = atol = 1e-12) from ``count`` points of the initial box times
    the parameter box ``params`` ({name: (lo, hi)}, the graph's parameters; each
    sample has its own parameter values, held constant)."""
    from .figures import sample_trajectories
    g = system.rhs
    n, p = g.n_inputs, g.n_params
    lo, hi = np.asarray(x0_lo, float), np.asarray(x0_hi, float)
    if p:
        plo = np.array([float(params[k][0]) for k in g.param_names])
        phi = np.array([float(params[k][1]) for k in g.param_names])
        lo, hi = np.concatenate([lo, plo]), np.concatenate([hi, phi])
    pts = sample_points(lo, hi, count, seed)
    if not p:
        return sample_trajectories(g, pts, times), pts

    def f(y):  # (n + p, S): the parameters are constant states
        x, pv = y[:n], y[n:]
        return np.vstack([g.eval_float(x.T, pv.T).T, np.zeros_like(pv)])
    return sample_trajectories(f, pts, times)[:, :, :n], pts


def final_widths(sol):
    """(when, widths (n,)) of the last verified enclosure: at ``t_reached`` when that is
    an output time, else (a break-down between output times) the enclosure over the
    last verified step ``[t_s-1, t_reached]`` (contains the sets at ``t_reached``);
    ``(None, None)`` for a run without any output."""
    t = np.asarray(sol.t, float)
    if len(t) and t[-1] >= sol.t_reached:
        return f"t = {t[-1]:g} s", np.asarray(sol.hull.width()[-1], float)
    if len(sol.tube):
        a, b = float(sol.tube_t[-2]), float(sol.tube_t[-1])
        return f"over the last step [{a:g}, {b:g}] s", np.asarray(sol.tube_hull.width()[-1], float)
    if len(t):
        return f"t = {t[-1]:g} s", np.asarray(sol.hull.width()[-1], float)
    return None, None


def _fmt_width(v: float) -> str:
    """A width for a report: 0 for the widths of point values (subnormal: the one-ulp
    outward rounding of [x, x] - x at 0 prints as 4.941e-324)."""
    v = float(v)
    if v < np.finfo(float).tiny:
        return "0"
    return f"{v:.4g}"


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
              figures=True, log=None, progress=True, max_wall=None) -> dict:
    """Simulate ``scene`` and write ``out``/result.json (+ figures). Returns a report
    dict: solution, paths, sample check (``escaped``: sampled states outside).

    ``samples``: exactly this many sampled trajectories (default 64; 0: none).
    ``max_wall``: stop the integration after this many seconds (status "stopped").
    Ctrl-C during the integration ends it with status "interrupted"; during the
    sampling it skips the rest of the sampling and the figures. Either way
    result.json is written with everything verified so far."""
    from .figures import fig_consistency_plane, fig_enclosures, fig_reduction_area
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
    names = None
    kw = scene.simulate_kwargs()
    try:
        system = reference_system(model, mode, scene.consistency.get("energy_rate", "unsimplified"),
                                  params=kw.get("params"))
    except ParameterError as e:  # an unknown link or joint of [parameters]
        msg = str(e)
        raise SceneError(f"{scene.source}: [parameters] {msg[7:] if msg.startswith('params ') else msg}") from None
    except Exception as e:  # noqa: BLE001 - a model that cannot be built is a scene problem
        raise SceneError(f"{scene.source}: cannot build the model: {type(e).__name__}: {e}") from None
    names = system.state_names
    x0 = scene.initial_box(names)
    kw = scene.simulate_kwargs(names)
    if scene.control is not None:
        from .control import ControlError
        try:
            system = reference_system(model, mode, params=kw.get("params"), control=scene.control,
                                      q_init=np.asarray(x0.mid(), float)[:len(names) // 2])
        except ControlError as e:
            msg = str(e)
            raise SceneError(f"{scene.source}: [control] {msg[8:] if msg.startswith('control ') else msg}") \
                from None
        except ParameterError as e:
            raise SceneError(f"{scene.source}: [parameters] {e}") from None
        if system.n > x0.shape[-1]:   # the time as a state: a point at t0 = 0
            from verified.interval import Interval
            x0 = Interval(np.r_[np.asarray(x0.lo, float), 0.0], np.r_[np.asarray(x0.hi, float), 0.0])
    x_user = x0 if scene.control is None else None
    kw["mode"] = mode
    t_model = time.perf_counter() - t0
    log(f"{scene.name}: mode {mode}, {len(names)} states ({', '.join(names)}), t_end = {t_end:g} s")
    if system.rhs.n_params:
        log("uncertain parameters: " + ", ".join(f"{k} in [{lo:.6g}, {hi:.6g}]" for k, (lo, hi) in
                                                 ((k, system.params[k]) for k in system.rhs.param_names)))
    bar = Progress(t_end, f"mode {mode}", enabled=None if progress else False)
    try:
        x_sim = x0 if x_user is not None else x0[:len(names)]
        sol = simulate(model, x_sim, t_end, output_dt=dt, progress=bar, max_wall=max_wall, **kw)
    except (ValueError, TypeError, ModelError) as e:  # settings the solver refuses
        raise SceneError(f"{scene.source}: cannot simulate: {e}") from None
    finally:
        bar.close()
    wall = time.perf_counter() - t0
    want = output_times(t_end, dt)
    report = {"solution": sol, "system": system, "escaped": 0, "checked": 0, "paths": {}}

    # sampled true trajectories: soundness check and figure overlay
    traj = traj_t = None
    interrupted = sol.status == "interrupted"
    if samples > 0 and len(sol.t) > 1 and not interrupted:
        try:
            dense = np.linspace(0.0, float(sol.t[-1]), 201)
            traj_t = np.unique(np.concatenate([np.asarray(sol.t, float), dense]))
            traj, pts = sample_states(system, x0.lo, x0.hi, samples, traj_t, system.params)
        except KeyboardInterrupt:
            interrupted, traj = True, None
            log("interrupted: sampled trajectories skipped")
        else:
            at_out = traj[:, np.searchsorted(traj_t, np.asarray(sol.t, float)), :]
            bad = check_samples(sol, at_out)
            report["escaped"] = len(bad)
            report["checked"] = int(pts.shape[0])
            if bad:
                log(f"WARNING: {len(bad)} sampled states lie outside the enclosure (first: sample {bad[0][0]} "
                    f"at t = {sol.t[bad[0][1]]:g}); this is a bug, please report it")
    report["interrupted"] = interrupted

    extra = {"wall_total_s": wall, "model_s": t_model, "samples_checked": report["checked"],
             "samples_escaped": report["escaped"], "output_times_requested": len(want) + 1}
    frames = []
    if getattr(sol, "frame", None) is not None and len(sol.t):
        from .frames import default_frame
        frames = list(scene.frames) if scene.frames else [default_frame(sol.frame.chain)]
        bad = [f for f in frames if f not in sol.frame.chain.frames]
        if bad:
            raise SceneError(f"{scene.source}: [simulation] frames: unknown frame(s) {', '.join(map(repr, bad))}; "
                             f"frames of the model: {', '.join(sol.frame.names)}")
        t_fr = time.perf_counter()
        for f in frames:
            enc = sol.frame(f)
            log(f"frame {f!r} at t = {enc.t[-1]:g} s: position widths "
                + ", ".join(_fmt_width(v) for v in np.asarray(enc.position.width()[-1], float)) + " m")
        extra["frames_s"] = time.perf_counter() - t_fr
    path = write_result(out / "result.json", sol, scene=scene.source, mode=mode,
                        state_names=list(getattr(sol, "state_names", None) or names), t_end=t_end,
                        extra_stats=extra, frames=frames)
    report["frames"] = frames
    report["paths"]["result"] = path
    if figures and not interrupted and frames:
        from .frame_figures import fig_frame_region
        report["paths"]["frame_region"] = fig_frame_region(
            sol.frame(frames[0]), out / "frame_region.png", title=f"{scene.name}: frame {frames[0]!r}",
            samples=_frame_samples(sol, frames[0], traj, names))
    if figures and not interrupted:
        report["paths"]["enclosures"] = fig_enclosures(
            {mode: sol}, out / "enclosures.png", samples=traj, sample_times=traj_t,
            title=f"{scene.name}: enclosures, mode {mode}")
        cons = getattr(sol, "consistency", None)
        if cons is not None and len(getattr(cons, "ra_t", ())) > 1:
            report["paths"]["reduction_area"] = fig_reduction_area(sol, out / "reduction_area.png")
        if cons is not None and getattr(cons, "tests", None) and system.energy is not None:
            pbox = None
            if system.energy.n_params:  # H over every cell and every parameter value
                from verified.interval import Interval
                pn = system.energy.param_names
                pbox = Interval(np.array([system.params[k][0] for k in pn], float),
                                np.array([system.params[k][1] for k in pn], float))
            report["paths"]["consistency_plane"] = fig_consistency_plane(
                sol, system.energy, out / "consistency_plane.png", params=pbox)
    st = sol.stats
    log(f"{sol.status} at t = {sol.t_reached:g} s{(' (' + sol.reason + ')') if sol.reason else ''}; "
        f"{st.get('steps')} steps, {st.get('wall_s', 0):.2f} s solver, {wall:.2f} s total")
    t_w, w = final_widths(sol)
    if w is not None:
        what = {"completed": "final widths", "breakdown": "widths at the break-down"}.get(
            sol.status, f"widths when {sol.status}")
        log(f"{what} ({t_w}): " + ", ".join(f"{n} {_fmt_width(v)}" for n, v in zip(names, w)))
    if report["checked"]:
        log(f"{report['checked']} sampled trajectories: "
            f"{'all inside' if not report['escaped'] else str(report['escaped']) + ' states OUTSIDE'}")
    for k, p in report["paths"].items():
        log(f"wrote {p}")
    return report


def _frame_samples(sol, frame, traj, names):
    """Positions (S, k, 3) of ``frame`` along sampled trajectories (float kinematics)."""
    if traj is None:
        return None
    chain = sol.frame.chain
    n = chain.n
    num = sol.frame.cparams.float_model() if sol.frame.cparams is not None else chain.numeric()
    q = traj[..., :n].reshape(-1, n)
    pos = np.array([np.asarray(num.frame_placement(frame, qi)[1], float) for qi in q])
    return pos.reshape(traj.shape[:-1] + (3,))

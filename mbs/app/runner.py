# Long (720 lines) on purpose: a scene's run and the scenario batch; tests patch both through this module.
"""Run a scene: simulate, check against sampled trajectories, write result.json and
the figures (the body of ``python -m mbs simulate``)."""
from __future__ import annotations

import json
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib

import numpy as np

from verified.arith.interval import Interval
from verified.execution.cluster import SchedulerError, connect, local_client
from verified.execution.plan import dask_available, default_workers
from verified.execution.interrupt import interrupt_runs
from verified.warmup import finish_background, start_in_background

from ..control import ControlError
from ..errors import ModelError
from ..frames import default_frame, default_frame_note
from ..modes import get_mode
from ..progress import Progress, cold_families, compile_note
from ..simulate import chain_state_names, simulate, system_for
from ..system import System
from .figures import fig_consistency_plane, fig_enclosures, fig_reduction_area
from .frame_figures import fig_frame_region
from .results import format_tightness, tightness, write_result
from .sampling import sample_points, sample_trajectories
from .scene import Scene, SceneError, output_times, parse_scene, scene_dir
from ..uncertain import ParameterError

__all__ = ["run_scene", "reference_system", "check_samples", "sample_points", "sample_states", "final_widths",
           "status_line", "surviving_samples", "sampled_spread", "pruned_anything", "kernel_families"]


def reference_system(model, mode="ii", energy_rate="unsimplified", params=None, control=None, q_init=None):
    """The :class:`mbs.system.System` of a model (a name or a Chain) in ``mode`` (mode i:
    the same numeric model with its energy, as in mode ii): the
    float right-hand side for sampling and the energy graph for Fig. 3 (with the
    uncertain ``params`` as graph parameters, see :func:`mbs.simulate.simulate`;
    under ``control`` the closed loop, with the state ``t`` for time-dependent
    references). Uses :func:`mbs.simulate.system_for` (the system the simulation
    integrates)."""
    return system_for(model, get_mode(mode).with_energy_test, energy_rate=energy_rate, params=params,
                      control=control, q_init=q_init)


def sample_states(system, x0_lo, x0_hi, count: int, times, params=None, seed: int = 0):
    """(states (S, len(times), n), initial points (S, n + p)): DOP853 trajectories of
    ``system.rhs`` (rtol = atol = 1e-12, :func:`mbs.app.sampling.sample_trajectories`)
    from ``count`` points (:func:`mbs.app.sampling.sample_points`) of the initial box times
    the parameter box ``params`` ({name: (lo, hi)}, the graph's parameters; each
    sample has its own parameter values, held constant)."""
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
              figures=True, log=None, progress=True, max_wall=None, workers=None, client=None,
              started=None) -> dict:
    """Simulate ``scene`` and write ``out``/result.json (+ figures). Returns a report
    dict: solution, paths, sample check (``escaped``: sampled states outside),
    ``tightness`` (:func:`mbs.app.results.tightness`: per state the width at the last
    output time, the sampled spread and their ratio; also in result.json).

    ``samples``: exactly this many sampled trajectories (default 64; 0: none).
    ``max_wall``: stop the integration after this many seconds (status "stopped").
    ``workers``, ``client``: chunked execution (:func:`parallel_kwargs`, verified/execution/).
    ``progress``: True (a bar on an interactive stderr: :class:`mbs.progress.Progress`,
    its clock counting from ``started``, ``time.time()`` of the command's start, and its
    description naming the phase: model, compiling, solving, sampling, frame
    enclosures, figures; with a note when the kernels compile first), False (none) or
    a callable ``(t, t_end)`` of the caller's.
    Ctrl-C during the integration ends it with status "interrupted"; during the
    sampling it skips the rest of the sampling and the figures. Either way
    result.json is written with everything verified so far."""
    log = log or (lambda *a, **k: None)
    mode = mode or scene.mode
    t_end = float(t_end if t_end is not None else scene.t_end)
    bar = None if callable(progress) else Progress(t_end, f"mode {mode}", enabled=None if progress else False,
                                                   start=started)
    try:
        return _run_scene(scene, Path(out), bar=bar, progress=progress if bar is None else bar,
                          log=log if bar is None else bar.printing(log), mode=mode, t_end=t_end,
                          output_dt=output_dt, samples=samples, figures=figures, max_wall=max_wall,
                          workers=workers, client=client)
    finally:
        if bar is not None:
            bar.close()


def kernel_families(kw: dict) -> tuple:
    """The numba kernel families (:data:`mbs.progress.KERNEL_FAMILIES`) that simulate
    with the keyword arguments ``kw`` calls first: the interval kernels always, the
    Taylor-model ones for ``method="auto"`` (the default: the composition first) and
    the composition, the affine ones for the affine arithmetic."""
    fam = ["interval"]
    m = kw.get("method")
    name = m if isinstance(m, str) else getattr(m, "name", None)
    arith = getattr(m, "arithmetic", None) or kw.get("arithmetic")
    legacy = m is None and any(k in kw for k in ("order", "tol", "set_order", "set_step", "arithmetic",
                                                   "model_degree", "error_basis"))
    if arith is None and not legacy and (m is None or name in ("auto", "composition")):
        arith = "taylor_model"
    if arith == "taylor_model":
        fam.append("Taylor-model")
    elif arith == "affine":
        fam.append("affine")
    return tuple(fam)


def _start_frame_warmup(model, kw: dict, workers):
    """A background process compiling the affine range (:func:`verified.warmup.start_in_background`)
    while the solver runs, when the run will enclose a robot's frames (a model that is not a
    bare System), the solve itself does not use those kernels, they are cold, and the run
    leaves a core free (one worker). None otherwise. On a first run the frame enclosures
    then find their kernels compiled instead of compiling them after the solve."""
    if isinstance(model, System) or "affine" in kernel_families(kw) or workers not in (None, 1):
        return None
    if cold_families(("affine",)) != ["affine"]:
        return None
    return start_in_background(("affine_range",))


def _phase(bar, name):
    if bar is not None:
        bar.phase(name)


def _scene_system(scene, model, mode):
    """(system, state names, initial box, simulate's keyword arguments with ``mode``) of a
    scene, its system built once: :func:`reference_system`, under ``[control]`` the closed
    loop (a PD without ``q_ref`` holds the centre of the initial q box; its state names
    from :func:`mbs.simulate.chain_state_names` before, the time a point t0 = 0 appended
    to the box). A bad ``[parameters]`` or ``[control]`` table is a SceneError naming it."""
    params = scene.simulate_kwargs().get("params")
    try:
        if scene.control is None:
            system = reference_system(model, mode, scene.consistency.get("energy_rate", "unsimplified"),
                                      params=params)
            names = system.state_names
        else:
            names = chain_state_names(model, params)
    except ParameterError as e:  # an unknown link or joint of [parameters]
        raise SceneError(f"{scene.source}: [parameters] {e.detail}") from None
    except Exception as e:  # noqa: BLE001 - a model that cannot be built is a scene problem
        raise SceneError(f"{scene.source}: cannot build the model: {type(e).__name__}: {e}") from None
    x0 = scene.initial_box(names)
    kw = scene.simulate_kwargs(names)
    if scene.control is not None:
        try:
            system = reference_system(model, mode, params=kw.get("params"), control=scene.control,
                                      q_init=np.asarray(x0.mid(), float)[:len(names) // 2])
        except ControlError as e:
            raise SceneError(f"{scene.source}: [control] {e.detail}") from None
        except ParameterError as e:
            raise SceneError(f"{scene.source}: [parameters] {e}") from None
        if system.n > x0.shape[-1]:   # the time as a state: a point at t0 = 0
            x0 = Interval(np.r_[np.asarray(x0.lo, float), 0.0], np.r_[np.asarray(x0.hi, float), 0.0])
    kw["mode"] = mode
    return system, names, x0, kw


def _run_scene(scene, out, *, bar, progress, log, mode, t_end, output_dt, samples, figures, max_wall,
               workers, client) -> dict:
    """The steps of :func:`run_scene`: the system, the solve, the sampled check, the
    frames, result.json, the figures and the report lines."""
    dt = output_dt if output_dt is not None else scene.output_dt
    samples = 64 if samples is None else int(samples)

    t0 = time.perf_counter()
    _phase(bar, "building the model")
    model = scene.build_model()
    system, names, x0, kw = _scene_system(scene, model, mode)
    t_model = time.perf_counter() - t0
    log(f"{scene.name}: mode {mode}, {len(names)} states ({', '.join(names)}), t_end = {t_end:g} s")
    if system.rhs.n_params:
        log("uncertain parameters: " + ", ".join(f"{k} in [{lo:.6g}, {hi:.6g}]" for k, (lo, hi) in
                                                 ((k, system.params[k]) for k in system.rhs.param_names)))
    frame_warmup = _start_frame_warmup(model, kw, workers)
    _compile_phase(bar, kw)
    try:
        x_sim = x0 if scene.control is None else x0[:len(names)]
        sol = simulate(model, x_sim, t_end, output_dt=dt, progress=progress, max_wall=max_wall, **kw,
                       **parallel_kwargs(workers, client))
    except (ValueError, TypeError, ModelError) as e:  # settings the solver refuses
        raise SceneError(f"{scene.source}: cannot simulate: {e}") from None
    wall = time.perf_counter() - t0
    want = output_times(t_end, dt)
    report = {"solution": sol, "system": system, "escaped": 0, "checked": 0, "paths": {}}

    # sampled true trajectories: soundness check, tightness and figure overlay
    traj, traj_t, spread = _check_sampled(report, sol, system, x0, samples, bar, log)
    surv = getattr(sol, "surviving", None)
    _check_surviving(report, sol, system, samples, kw, log)

    extra = {"wall_total_s": wall, "model_s": t_model, "samples_checked": report["checked"],
             "samples_escaped": report["escaped"], "output_times_requested": len(want) + 1}
    if surv is not None:
        extra["surviving_samples_checked"] = report["surviving_checked"]
    state_names = list(getattr(sol, "state_names", None) or names)
    report["tightness"] = tight = tightness(sol, spread, state_names, report["checked"] if spread is not None else 0)
    frames = _enclose_frames(scene, sol, bar, log, frame_warmup, extra)
    path = write_result(out / "result.json", sol, scene=scene.source, mode=mode, state_names=state_names,
                        t_end=t_end, extra_stats=extra, frames=frames, tightness=tight)
    report["frames"] = frames
    report["paths"]["result"] = path
    not_drawn = []
    if figures and not report["interrupted"]:
        not_drawn = _draw_figures(report, scene, sol, system, out, mode, frames, traj, traj_t, names, bar)
    if bar is not None:
        bar.close()  # (the report below without a bar redrawn after every line)
    _log_summary(log, report, sol, names, wall, not_drawn, tight)
    return report


def _compile_phase(bar, kw):
    """The bar's phase (and note) while the kernels the run needs compile, if they do."""
    if bar is not None and bar.enabled:  # (the cache is read only for a terminal that shows the note)
        families = kernel_families(kw)
        cold = cold_families(families)  # (None: numba's cache could not be read)
        bar.note(compile_note(families) if cold else "")
        bar.phase("compiling" if cold else "solving" if cold is not None else
                  "first step (compiling, on a first run)", then="solving")


def _check_sampled(report, sol, system, x0, samples, bar, log):
    """(trajectories, their times, spread at the last output) of ``samples`` DOP853 runs
    from the initial box (Nones without them), their states checked against the
    enclosures at the output times; sets ``report``'s checked, escaped, interrupted."""
    traj = traj_t = spread = None
    interrupted = sol.status == "interrupted"
    if samples > 0 and len(sol.t) > 1 and not interrupted:
        _phase(bar, f"sampling {samples} trajector{'y' if samples == 1 else 'ies'}")
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
            spread = sampled_spread(at_out[:, -1, :])
            if bad:
                log(f"WARNING: {len(bad)} sampled states lie outside the enclosure (first: sample {bad[0][0]} "
                    f"at t = {sol.t[bad[0][1]]:g}); this is a bug, please report it")
    report["interrupted"] = interrupted
    return traj, traj_t, spread


def _check_surviving(report, sol, system, samples, kw, log):
    """The pieces that went on after others broke down, checked against trajectories
    sampled from their own boxes; sets ``report``'s surviving_checked, surviving_escaped
    (added to escaped) and interrupted."""
    surv = getattr(sol, "surviving", None)
    report["surviving_checked"] = report["surviving_escaped"] = 0
    if samples > 0 and surv is not None and len(surv.t) > 1 and not report["interrupted"] \
            and not kw.get("param_subdivision"):
        # (with the parameter box cut into pieces a piece holds only some parameter
        # values, which its box does not say: not checked then)
        try:
            s_t = np.asarray(surv.t, float)
            s_traj = surviving_samples(system, sol, samples, s_t, system.params)
        except KeyboardInterrupt:
            report["interrupted"] = True
            log("interrupted: sampled trajectories of the surviving pieces skipped")
        else:
            bad = check_samples(surv, s_traj)
            report["surviving_checked"], report["surviving_escaped"] = int(s_traj.shape[0]), len(bad)
            report["escaped"] += len(bad)
            if bad:
                log(f"WARNING: {len(bad)} sampled states of the surviving pieces lie outside their enclosure "
                    f"(first: sample {bad[0][0]} at t = {surv.t[bad[0][1]]:g}); this is a bug, please report it")


def _enclose_frames(scene, sol, bar, log, frame_warmup, extra) -> list:
    """The frames enclosed for result.json (``[simulation] frames``, else the end
    effector; none for a bare System or a run without output), each logged; the
    background compilation of the affine range waited for, or ended when unused;
    ``extra["frames_s"]``: their time."""
    frames = []
    if getattr(sol, "frame", None) is not None and len(sol.t):
        frames = list(scene.frames) if scene.frames else [default_frame(sol.frame.chain)]
        bad = [f for f in frames if f not in sol.frame.chain.frames]
        if bad:
            raise SceneError(f"{scene.source}: [simulation] frames: unknown frame(s) {', '.join(map(repr, bad))}; "
                             f"frames of the model: {', '.join(sol.frame.names)}")
        if not scene.frames:
            said = default_frame_note(sol.frame.chain, frames[0])
            if said:
                log(said)
        _phase(bar, "frame enclosures")
        if frame_warmup is not None:  # (rather than compile the same kernels a second time here)
            if bar is not None and bar.enabled:
                bar.note("waiting for the affine range compiling in the background ...")
            finish_background(frame_warmup)
            frame_warmup = None
        if bar is not None and bar.enabled:
            bar.note(compile_note(("affine",), " for the frame enclosures"))
        t_fr = time.perf_counter()
        for f in frames:
            enc = sol.frame(f)
            log(f"frame {f!r} at t = {enc.t[-1]:g} s: position enclosed to "
                + ", ".join(_fmt_width(v) for v in np.asarray(enc.position.width()[-1], float)) + " m")
        extra["frames_s"] = time.perf_counter() - t_fr
    if frame_warmup is not None:  # (no frame to enclose after all)
        frame_warmup.kill()
        frame_warmup.wait()
    return frames


def _draw_figures(report, scene, sol, system, out, mode, frames, traj, traj_t, names, bar) -> list:
    """frame_region.png, enclosures.png, reduction_area.png and consistency_plane.png
    (Fig. 3) where they apply, their paths in ``report["paths"]``; returns the lines
    saying why a figure was not drawn."""
    _phase(bar, "figures")
    if frames:
        report["paths"]["frame_region"] = fig_frame_region(
            sol.frame(frames[0]), out / "frame_region.png", title=f"{scene.name}: frame {frames[0]!r}",
            samples=_frame_samples(sol, frames[0], traj, names))
    not_drawn = []
    report["paths"]["enclosures"] = fig_enclosures(
        {mode: sol}, out / "enclosures.png", samples=traj, sample_times=traj_t,
        title=f"{scene.name}: enclosures, mode {mode}")
    cons = getattr(sol, "consistency", None)
    if cons is not None and len(getattr(cons, "ra_t", ())) > 1:
        report["paths"]["reduction_area"] = fig_reduction_area(sol, out / "reduction_area.png")
    if cons is not None and getattr(cons, "tests", None) and system.energy is not None:
        if pruned_anything(sol):
            pbox = None
            if system.energy.n_params:  # H over every cell and every parameter value
                pn = system.energy.param_names
                pbox = Interval(np.array([system.params[k][0] for k in pn], float),
                                np.array([system.params[k][1] for k in pn], float))
            report["paths"]["consistency_plane"] = fig_consistency_plane(
                sol, system.energy, out / "consistency_plane.png", params=pbox)
        else:
            not_drawn.append(f"nothing pruned by the {len(cons.tests)} energy test"
                             f"{'s' if len(cons.tests) > 1 else ''}: Fig. 3 (consistency_plane.png) not drawn")
    return not_drawn


def _log_summary(log, report, sol, names, wall, not_drawn, tight):
    """The report's closing lines: status, method, widths, the sampled check, the files."""
    surv = getattr(sol, "surviving", None)
    st = sol.stats
    log(f"{status_line(sol)}; {st.get('steps')} steps, {st.get('wall_s', 0):.2f} s solver, {wall:.2f} s total")
    if getattr(sol, "method", ""):
        log(f"method: {sol.method}")
    if st.get("energy_test_off_s"):
        log(f"energy test: stepped aside for {st['energy_test_off_s']:.3g} s of the run while it pruned "
            f"nothing ({st.get('energy_test_phases')} phases; verified.consistency.energy_cadence)")
    if "invariant_from" in st:
        rates = [float(r) for _, lam in st.get("decay_rates", [])[:1] for r in lam]
        log(f"every time after {st['invariant_from']:g} s proven at once by the closed loop's energy"
            + (f" (decay rates {min(rates):.2g}..{max(rates):.2g} /s)" if rates and max(rates) > 0 else ""))
    t_w, w = final_widths(sol)
    if w is not None:
        what = {"completed": "final widths", "breakdown": "widths at the break-down"}.get(
            sol.status, f"widths when {sol.status}")
        log(f"{what} ({t_w}): " + ", ".join(f"{n} {_fmt_width(v)}" for n, v in zip(names, w)))
    if surv is not None:
        t_s, w_s = final_widths(surv)
        k = sum(1 for p in sol.piece_results if not p.failed)
        log(f"the {k} surviving piece{'s' if k > 1 else ''}: {surv.status} at t = {surv.t_reached:g} s"
            + (f"; widths ({t_s}): " + ", ".join(f"{n} {_fmt_width(v)}" for n, v in zip(names, w_s))
               if w_s is not None else ""))
    if report["checked"]:
        esc = report["escaped"] - report["surviving_escaped"]
        log(f"{report['checked']} sampled trajector{'y' if report['checked'] == 1 else 'ies'}: "
            f"{'all inside' if not esc else str(esc) + ' states OUTSIDE'}")
    if report["surviving_checked"]:
        log(f"{report['surviving_checked']} sampled trajectories from the surviving pieces: "
            f"{'all inside' if not report['surviving_escaped'] else str(report['surviving_escaped']) + ' states OUTSIDE'}")
    for line in not_drawn:
        log(line)
    for k, p in report["paths"].items():
        log(f"wrote {p}")
    if tight is not None:
        log("\n" + format_tightness(tight))


def sampled_spread(states) -> np.ndarray:
    """Per state the spread (max - min) of sampled states (S, n) over the samples whose
    states are all finite (a DOP853 failure leaves NaN rows); NaN when there are none."""
    x = np.asarray(states, float)
    ok = np.isfinite(x).all(axis=1)
    if not ok.any():
        return np.full(x.shape[-1], np.nan)
    return x[ok].max(axis=0) - x[ok].min(axis=0)


def pruned_anything(sol) -> bool:
    """Whether an energy consistency test of ``sol`` pruned a sub-box (Fig. 3 draws the
    test that pruned the most; without one it would show only kept boxes)."""
    cons = getattr(sol, "consistency", None)
    return any((~np.asarray(rec.kept, bool)).any() for rec in (getattr(cons, "tests", None) or ()))


def status_line(sol) -> str:
    """``"completed at t = 2 s"``, ``"breakdown at t = 0.31 s (reason)"``, or where some
    pieces broke down and others went on ``"breakdown at t = 0.31 s: 3 of 64 pieces
    failed (pieces 5, 17, 40 at t = 0.31: <reason>); 61 pieces verified to t = 2"``."""
    head = f"{sol.status} at t = {sol.t_reached:g} s"
    why = sol.reason or ""
    summary = sol.pieces_summary() if hasattr(sol, "pieces_summary") else ""
    if summary and why.startswith(summary):
        return f"{head}: {why}"
    return f"{head} ({why})" if why else head


def surviving_samples(system, sol, count: int, times, params=None, seed: int = 0) -> np.ndarray:
    """States (S, len(times), n) along DOP853 trajectories (:func:`sample_states`) from
    ``count`` points of the pieces of ``sol`` that did not break down
    (``sol.piece_results``): a seeded random choice of those pieces, points of each
    piece's own box (its centre and corners first)."""
    alive = [p for p in sol.piece_results if not p.failed]
    rng = np.random.default_rng(seed)
    pick = np.sort(rng.integers(0, len(alive), size=count))
    parts = []
    for j, k in zip(*np.unique(pick, return_counts=True)):
        box = alive[int(j)].box
        traj, _ = sample_states(system, box.lo, box.hi, int(k), times, params, seed=seed + int(j))
        parts.append(traj)
    return np.concatenate(parts, axis=0)


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


# ---------------------------------------------------------------------- scale-out (issue 16)
def parallel_kwargs(workers=None, client=None) -> dict:
    """Keyword arguments of simulate for chunked execution: ``{"workers": 1}`` for one
    in-process batch (``workers`` None or 1 and no client: simulate's own default, None,
    is every core when worthwhile), else ``workers``/``client`` (see
    :mod:`verified.execution`; ``workers="auto"``: every core when worthwhile)."""
    if client is not None:
        return {"client": client}
    if workers is None or workers == 1:
        return {"workers": 1}
    return {"workers": workers}


def scheduler_client(address):
    """A ``distributed.Client`` for ``--scheduler ADDR``; a SceneError (one line, naming
    the address) when it cannot be reached within verified.execution.cluster.CONNECT_TIMEOUT s."""
    try:
        return connect(address)
    except (SchedulerError, ValueError) as e:
        raise SceneError(f"--scheduler: {e}") from None


def scenario_batch(path):
    """The scenes of a scene file's ``[[scenarios]]`` list, or None when it has none.

    Each ``[[scenarios]]`` entry has a ``name`` and tables that override the base
    scene's tables entry by entry (``[scenarios.parameters]``, ``[scenarios.initial]``,
    ``[scenarios.solver]``, ``[scenarios.simulation]``, ``[scenarios.consistency]``,
    ``[scenarios.control]``)::

        [[scenarios]]
        name = "payload 0-0.5 kg"
        parameters.payload = { link = "link2", mass = [0.0, 0.5] }
        [[scenarios]]
        name = "payload 0.5-1 kg"
        parameters.payload = { link = "link2", mass = [0.5, 1.0] }
    """
    p = Path(path)
    if not p.exists() and not p.suffix and (scene_dir() / f"{p.name}.toml").is_file():
        p = scene_dir() / f"{p.name}.toml"
    if not p.is_file():
        return None
    try:
        data = tomllib.loads(p.read_text())
    except (tomllib.TOMLDecodeError, OSError, UnicodeDecodeError):
        return None  # load_scene reports it
    if "scenarios" not in data:
        return None
    items = data.pop("scenarios")
    src = str(path)
    if not isinstance(items, list) or not items or not all(isinstance(x, dict) for x in items):
        raise SceneError(f"{src}: [[scenarios]] must be a non-empty list of tables")
    parse_scene(dict(data), src, p.parent)  # the base scene must be valid by itself
    scenes, seen = [], set()
    for i, item in enumerate(items):
        name = item.get("name", f"scenario{i + 1}")
        if not isinstance(name, str) or not name or name in seen:
            raise SceneError(f"{src}: [[scenarios]] {i + 1}: name must be a unique non-empty string, got {name!r}")
        seen.add(name)
        merged = _overridden(data, {k: v for k, v in item.items() if k != "name"})
        merged["name"] = f"{data.get('name', p.stem)} [{name}]"
        scenes.append((name, parse_scene(merged, f"{src} [scenario {name!r}]", p.parent)))
    return scenes


def _overridden(base: dict, over: dict) -> dict:
    """``base`` with the entries of ``over``, tables merged at every depth (a scenario's
    ``parameters.payload = { mass = ... }`` keeps the base payload's ``link`` and
    ``com``; it replaced the whole payload table before); anything else replaced."""
    out = dict(base)
    for k, v in over.items():
        out[k] = _overridden(base[k], v) if isinstance(v, dict) and isinstance(base.get(k), dict) else v
    return out


def run_scenarios(scenes, out, *, log=None, workers=None, client=None, **run_kw) -> dict:
    """Run a scenario batch (:func:`scenario_batch`) as one job: with a Dask client (or
    ``workers`` > 1) every scenario's chunks go to the same cluster at once (one thread
    per scenario here waits for them), else one scenario after the other. Writes
    ``out/NAME/result.json`` per scenario (no figures: matplotlib is not thread-safe;
    run a scenario alone for them) and ``out/scenarios.json`` (the combined result:
    status = the worst, t_reached = the smallest, and per scenario its status,
    t_reached, final widths, parameters, samples). Returns ``{"scenarios": [...],
    "status": ..., "solution": None, ...}``."""
    log = log or (lambda *a, **k: None)
    out = Path(out)
    t0 = time.perf_counter()
    client = _batch_client(client, workers)
    lines = {}
    bar = _BatchBar(scenes, run_kw)

    def one(item):
        name, scene = item
        def say(*a, **k):
            lines.setdefault(name, []).append(" ".join(str(x) for x in a))
        rep = run_scene(scene, out / _safe_name(name), log=say, progress=bar.tick(name), figures=False,
                        client=client, workers=None if client is not None else workers, **run_kw)
        return name, scene, rep

    try:
        reports = _on_cluster(scenes, one) if client is not None else _one_by_one(scenes, one, log)
    finally:
        bar.close()
    rows, worst, t_min = _combined(reports, lines, log)
    combined = {"scene": str(scenes[0][1].source).split(" [scenario")[0], "status": worst, "t_reached": t_min,
                "wall_s": time.perf_counter() - t0, "scenarios": rows}
    path = _write_batch(out, combined, log)
    return {"scenarios": rows, "status": worst, "t_reached": t_min, "escaped": sum(r["samples_escaped"] for r in rows),
            "interrupted": any(r["status"] == "interrupted" for r in rows), "paths": {"scenarios": path},
            "solution": None}


def _batch_client(client, workers):
    """The Dask client every scenario's chunks go to: ``client``, or a local cluster of
    ``workers`` (> 1, or "auto": every core) where Dask is installed; None: in process."""
    if client is None and workers not in (None, 1):
        n = default_workers() if workers == "auto" else int(workers)
        if dask_available() and n > 1:
            client = local_client(n)  # one cluster for every scenario's chunks
    return client


class _BatchBar:
    """One bar over the batch: the simulated seconds of every scenario summed
    (interactive only; ``run_kw``'s ``progress`` is taken out of it for the bar)."""

    def __init__(self, scenes, run_kw: dict):
        self.horizon = {name: float(run_kw.get("t_end") or scene.t_end) for name, scene in scenes}
        self.bar = Progress(sum(self.horizon.values()), f"{len(scenes)} scenarios",
                            enabled=run_kw.pop("progress", None))
        self.done, self.lock = dict.fromkeys(self.horizon, 0.0), threading.Lock()

    def tick(self, name):
        """The progress callable of scenario ``name`` (called from its thread)."""
        def tick(t_now, t_end=None):
            with self.lock:
                self.done[name] = min(float(t_now), self.horizon[name])
                self.bar(sum(self.done.values()))
        return tick

    def close(self):
        self.bar.close()


def _on_cluster(scenes, one) -> list:
    """``one`` of every scenario at once, a thread each (their chunks share the cluster)."""
    with ThreadPoolExecutor(max_workers=len(scenes)) as ex:
        futures = [ex.submit(one, x) for x in scenes]
        try:
            return [f.result() for f in futures]
        except KeyboardInterrupt:
            # Ctrl-C reaches this thread only (and the local workers, which die of it):
            # the scenarios' threads wait on Dask, so tell their runs to stop as Ctrl-C
            # stops one, and collect what each verified
            interrupt_runs()
            try:
                return [f.result() for f in futures]
            finally:
                interrupt_runs(False)


def _one_by_one(scenes, one, log) -> list:
    """``one`` of each scenario in turn; an interrupted one (Ctrl-C) stops the batch."""
    reports = []
    for k, x in enumerate(scenes):
        reports.append(one(x))
        if reports[-1][2]["solution"].status == "interrupted":  # Ctrl-C stops the batch
            skipped = [name for name, _ in scenes[k + 1:]]
            if skipped:
                log(f"interrupted: scenario(s) not run: {', '.join(skipped)}")
            break
    return reports


def _combined(reports, lines, log):
    """``(rows, worst status, smallest t_reached)`` of the scenarios' reports; each
    scenario's own log lines are logged after it, prefixed with its name."""
    rank = {"completed": 0, "stopped": 1, "interrupted": 2, "breakdown": 3}
    rows, worst, t_min = [], "completed", float("inf")
    for name, scene, rep in reports:
        sol = rep["solution"]
        rows.append(_scenario_row(name, rep))
        if rank.get(sol.status, 3) > rank[worst]:
            worst = sol.status
        t_min = min(t_min, float(sol.t_reached))
        for line in lines.get(name, []):
            log(f"[{name}] {line}")
    return rows, worst, t_min


def _scenario_row(name, rep) -> dict:
    """One scenario's entry of scenarios.json."""
    sol = rep["solution"]
    t_w, w = final_widths(sol)
    return {"name": name, "status": sol.status, "t_reached": float(sol.t_reached), "reason": sol.reason,
            "widths_at": t_w, "final_widths": None if w is None else [float(v) for v in w],
            "parameters": {k: [float(a), float(b)] for k, (a, b) in (getattr(sol, "params", {}) or {}).items()},
            "samples_checked": rep["checked"], "samples_escaped": rep["escaped"],
            "wall_s": float(sol.stats.get("wall_s", 0.0)), "chunks": sol.stats.get("chunks", 1),
            "result": str(Path(_safe_name(name)) / "result.json")}


def _write_batch(out: Path, combined: dict, log) -> Path:
    """Write ``out/scenarios.json`` and log its table; the path written."""
    out.mkdir(parents=True, exist_ok=True)
    path = out / "scenarios.json"
    path.write_text(json.dumps(combined, indent=1))
    log(f"{'scenario':<24} {'status':<11} {'t_reached':>9} {'wall s':>7}  final widths")
    for r in combined["scenarios"]:
        ws = ", ".join(_fmt_width(v) for v in (r["final_widths"] or []))
        log(f"{r['name']:<24} {r['status']:<11} {r['t_reached']:>9.4g} {r['wall_s']:>7.2f}  {ws}"
            + (f"  ({r['samples_escaped']} sampled states OUTSIDE)" if r["samples_escaped"] else ""))
    log(f"wrote {path}")
    return path


def _safe_name(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in name)


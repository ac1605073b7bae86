"""``python -m mbs demo``: the paper's double pendulum in its three simulation modes.

The scene ``models/scenes/double_pendulum_paper.toml`` (eq. 22, initial box 25, its
energy-test settings) runs in the paper's configuration (:data:`DEMO`: QR-Lohner sets
with ``error_basis="auto"``, x1(0) split into 256 pieces; the scene itself leaves the
method to ``auto``) in modes (i) numeric model without test, (ii) numeric model with the
energy consistency test, (iii) symbolic model with the energy test, each with the same
solver settings. The demo prints the comparison
table (time reached, widths at common output times, pruned boxes, wall time), checks
every enclosure against densely sampled DOP853 trajectories, and writes the paper's
figures (Fig. 5 for the three modes with the sampled trajectories overlaid and their
widths against the samples' spread on a log scale, Figs. 2 and 3 of mode ii; Fig. 3
only when a test pruned a sub-box) into ``--out`` (default ``out/demo``). On a
terminal one progress bar runs over the three modes, the sampling and the figures,
naming the phase, and a first run says when the kernels compile.

It exits with 1 when a sampled state lies outside an enclosure or when a mode breaks
down before ``T`` (the demo must reach what it shows; ``tests/app/test_demo_and_scenes.py``
checks the same settings).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from verified.methods import METHOD_FIELDS, Lohner
from verified.warmup import finish_background, start_in_background

from ..modes import ALL_MODES, MODE_I, MODE_II, MODES, get_mode
from ..progress import Progress, compile_note
from ..simulate import simulate, system_for
from .figures import fig_consistency_plane, fig_enclosures, fig_reduction_area
from .runner import check_samples, kernel_families, pruned_anything
from .sampling import line_points, sample_trajectories
from .scene import load_scene

#: demo settings: the paper's first-order sets, error_basis "auto", x1(0) in 256 pieces
#: (every mode reaches T = 1; fewer pieces or the "qr" basis break down before it,
#: docs/lab/measurements.md)
DEMO = dict(t_end=1.0, output_dt=0.05, pieces=256, samples=401,
            method=Lohner(order=12, tol=1e-10, error_basis="auto"))


def settings(pieces=None):
    """``(x0, kwargs)`` of the demo's runs: the scene's initial box and its solver and
    consistency settings (without ``mode``), x1(0) split into ``pieces`` (default
    ``DEMO["pieces"]``); ``simulate("double_pendulum_paper", x0, T, mode=m,
    output_dt=DEMO["output_dt"], **kwargs)`` is what the demo runs for mode ``m``."""
    scene = load_scene("double_pendulum_paper")
    names = system_for("double_pendulum_paper", "ii").state_names
    x0 = scene.initial_box(names)
    kw = scene.simulate_kwargs(names)
    kw.pop("mode")
    for k in METHOD_FIELDS:  # (the demo runs its own method, whatever the scene names)
        kw.pop(k, None)
    kw["method"] = DEMO["method"]
    kw["subdivision"] = [DEMO["pieces"] if pieces is None else pieces, 1, 1, 1]
    return x0, kw


def _table(rows, header):
    widths = [max(len(str(r[i])) for r in rows + [header]) for i in range(len(header))]
    line = "  ".join(h.ljust(w) for h, w in zip(header, widths))
    out = [line, "-" * len(line)]
    out += ["  ".join(str(c).ljust(w) for c, w in zip(r, widths)) for r in rows]
    return "\n".join(out)


def run(out="out/demo", t_end=None, pieces=None, samples=None, log=print, started=None, progress=None) -> int:
    """The demo (module docstring); 0 when every mode reached ``t_end`` with every sampled
    state inside, else 1. On a machine with two cores or more, the kernels of the other
    arithmetics (affine, Taylor models), which the demo does not use, compile meanwhile in
    a background process (:mod:`verified.warmup`), so that the next runs and the test
    suite start warm; ``MBS_NO_WARMUP=1`` turns that off. ``started``: ``time.time()`` of
    the command's start (the progress bar's clock counts from it); ``progress``: None (a
    bar on an interactive stderr), False (none) or True (always)."""
    warm = start_in_background()
    bar = Progress(len(MODES) * (DEMO["t_end"] if t_end is None else t_end), "demo", start=started,
                   enabled=progress)
    try:
        rc = _run(out, t_end, pieces, samples, bar.printing(log), bar)
    except BaseException:
        bar.close()
        if warm is not None:  # (Ctrl-C or an error: the warm-up is not waited for)
            warm.kill()
            warm.wait()
        raise
    bar.close()
    note = finish_background(warm)
    if note:
        log(note)
    return rc


def _run(out, t_end, pieces, samples, log, bar) -> int:
    t_all = time.perf_counter()
    t_end = DEMO["t_end"] if t_end is None else t_end
    pieces = DEMO["pieces"] if pieces is None else pieces
    samples = DEMO["samples"] if samples is None else samples
    x0, kw = settings(pieces)
    # one process: the background warm-up has the second core, and on a first run the
    # fresh workers of a local cluster would each compile the kernels again
    # (docs/lab/code_notes.md)
    kw["workers"] = 1
    log(f"Double pendulum of the paper (eq. 22, box 25), x1(0) split into {pieces} pieces "
        f"(error basis {kw.get('error_basis', 'qr')!r}), T = {t_end:g} s,")
    tested = [m.name for m in ALL_MODES if m.energy_test]
    log(f"energy test every {kw.get('test_interval', MODE_II.test_interval):g} s with "
        f"{kw.get('test_splits', MODE_II.test_splits)} splits (modes {' and '.join(tested)}).\n")
    sols, walls = {}, {}
    cold = compile_note(kernel_families(kw)) if bar.enabled else ""
    bar.note(cold)
    for k, mode in enumerate(MODES):
        bar.offset = k * t_end  # (one bar over the three modes)
        first = "compiling" if cold and k == 0 else "deriving the model" if get_mode(mode).symbolic else "solving"
        bar.phase(f"mode {mode}: {first}", then=f"mode {mode}: solving")
        t0 = time.perf_counter()
        sols[mode] = simulate("double_pendulum_paper", x0, t_end, mode=mode, output_dt=DEMO["output_dt"],
                              progress=bar, **kw)
        walls[mode] = time.perf_counter() - t0
        s = sols[mode]
        log(f"  mode {mode:>3}: {s.status} at t = {s.t_reached:.3f} s ({walls[mode]:.1f} s)")

    # sampled true trajectories: x1(0) dense over its interval (the other states are points)
    bar.phase(f"sampling {samples} trajectories")
    lo, hi = np.asarray(x0.lo, float), np.asarray(x0.hi, float)
    pts = line_points(lo, hi, samples, 0)
    t_out = max((s.t for s in sols.values()), key=len)
    dense = np.unique(np.concatenate([t_out, np.linspace(0, t_end, 201)]))
    traj = sample_trajectories(system_for("double_pendulum_paper", MODE_I).rhs, pts, dense)
    escaped = 0
    for mode, s in sols.items():
        at = traj[:, np.searchsorted(dense, np.asarray(s.t, float)), :]
        escaped += len(check_samples(s, at))

    _log_widths(sols, walls, traj, dense, t_end, log)
    paths = _figures(out, sols, traj, dense, bar)
    s2 = sols[MODE_II.name]
    bar.close()  # (the report below without a bar redrawn after every line)
    log("\nFigures: " + ", ".join(str(p) for p in paths))
    if s2.consistency is not None and s2.consistency.tests and not pruned_anything(s2):
        log(f"nothing pruned by mode {MODE_II.name}'s {len(s2.consistency.tests)} energy tests: Fig. 3 not drawn")
    verdict = "every enclosure contains all" if not escaped else f"{escaped} sampled states OUTSIDE the enclosures of"
    log(f"Checked against {samples} sampled trajectories: {verdict} sampled states. "
        f"({time.perf_counter() - t_all:.1f} s)")
    short = [m for m, s in sols.items() if s.status != "completed" or s.t_reached < t_end]
    if short:
        log("FAILED: mode " + ", ".join(f"{m} broke down at t = {sols[m].t_reached:.3f} s" for m in short)
            + f" before T = {t_end:g} s")
    return 0 if not escaped and not short else 1


def _log_widths(sols, walls, traj, dense, t_end, log):
    """The demo's two tables: the widths per state at a few common times against the
    sampled ones, and each mode's run (status, steps, tests, pruned boxes, times)."""
    # comparison table: widths per state at a few common times
    common = [t for t in (0.25, 0.5, 0.6, 0.75, 1.0) if t <= t_end]
    rows = []
    for t in common:
        k_true = int(np.argmin(np.abs(dense - t)))
        true_w = traj[:, k_true, :].max(axis=0) - traj[:, k_true, :].min(axis=0)
        for mode, s in sols.items():
            k = np.flatnonzero(np.isclose(s.t, t))
            if k.size == 0:
                rows.append((f"{t:g}", mode, "(broke down before)", "", ""))
                continue
            w = np.asarray(s.hull.width()[k[0]], float)
            rows.append((f"{t:g}", mode, "  ".join(f"{v:8.5f}" for v in w), f"{(w / true_w).max():.3f}",
                         str(np.asarray(s.boxes[k[0]].lo).reshape(-1, 4).shape[0])))
        rows.append((f"{t:g}", "true", "  ".join(f"{v:8.5f}" for v in true_w), "1", ""))
    log("\nWidths of the enclosure (hull of all boxes) at common times; ratio = worst width / sampled width")
    log(_table(rows, ["t [s]", "mode", "widths x1 x2 x3 x4", "ratio", "boxes"]))
    rows = []
    for mode, s in sols.items():
        st = s.stats
        rows.append((mode, s.status, f"{s.t_reached:.3f}", st.get("steps"), st.get("tests", 0),
                     st.get("pruned_boxes", 0), st.get("max_boxes"), f"{st.get('test_s', 0.0):.1f}",
                     f"{walls[mode]:.1f}", s.reason or ""))
    log("\n" + _table(rows, ["mode", "status", "t reached", "steps", "tests", "pruned", "max boxes",
                            "test s", "wall s", "reason"]))


def _figures(out, sols, traj, dense, bar) -> list:
    """Fig. 5 of the three modes, and mode ii's Figs. 2 and 3 (where it pruned); the paths."""
    out = Path(out)
    bar.phase("figures")
    paths = [fig_enclosures(sols, out / "fig5_enclosures.png", samples=traj, sample_times=dense,
                            title="Double pendulum (paper Fig. 5): the enclosures of modes (i), (ii), (iii) "
                                  "and their widths against the samples' spread")]
    s2 = sols[MODE_II.name]  # Figs. 2 and 3: mode ii, as in the paper
    if s2.consistency is not None and len(s2.consistency.ra_t) > 1:
        paths.append(fig_reduction_area(s2, out / "fig2_reduction_area.png"))
    if s2.consistency is not None and s2.consistency.tests and pruned_anything(s2):
        paths.append(fig_consistency_plane(s2, system_for("double_pendulum_paper", MODE_II).energy,
                                           out / "fig3_consistency_plane.png"))
    return paths

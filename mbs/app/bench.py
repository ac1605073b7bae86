"""``python -m mbs bench [--out DIR]``: work-precision table and stress tests.

Writes ``DIR/benchmarks.md`` and ``DIR/bench_work_precision.png``; ``DIR`` defaults to
``out/bench`` under the current working directory (never into the installed package).
The report in a checkout's docs is ``python -m mbs bench --out docs/lab`` (docs/lab/benchmarks.md).

1. Work-precision on the paper's double pendulum (eq. 22, box 25): for each mode
   (i, ii, iii), Taylor order and subdivision of x1(0), the final widths, their
   worst ratio to the hull of densely sampled DOP853 trajectories, and the wall time;
   plus a work-precision plot (``bench_work_precision.png``; not ``work_precision.png``,
   which ``benchmarks/bench_consistency.py --only 7`` writes into the same ``docs/``).
2. Stress cases: long horizon until break-down, growing initial boxes, masses and
   lengths from 1e-3 to 1e3, a nearly singular mass matrix (m2 << m1), high energy,
   a 6-DOF URDF arm (UR5) with uncertain joint angles. Each case must either complete
   or stop with a break-down reason, without an exception, without a NaN, and with
   every sampled trajectory inside the enclosure at every output time.
3. Start-up: cold (empty numba and model caches) and warm wall time of
   ``python -m mbs simulate SCENE`` on a tiny horizon, per shipped scene.

``--quick`` runs a small version of each part (the test suite runs it).
"""
from __future__ import annotations

import math
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from models import double_pendulum as dp
from models.registry import get as get_model
from verified.arith.interval import Interval

from ..modes import MODES, get_mode
from ..simulate import simulate
from . import figures
from .runner import check_samples, reference_system
from .sampling import line_points, sample_initial_points, sample_trajectories
from .scene import scene_dir

__all__ = ["run", "work_precision", "stress_cases", "startup", "run_case"]

#: the directory holding the mbs package (put on the start-up subprocesses' PYTHONPATH)
REPO = Path(__file__).resolve().parents[2]

#: where ``run`` writes without ``out`` (relative to the current working directory)
DEFAULT_OUT = Path("out") / "bench"


def _simulate():
    return simulate


def _paper_box():
    lo, hi = dp.initial_box()
    return Interval(lo, hi)


def _sampled(system, x0, times, n_samples, params=None, seed=0):
    """(S, k, n) DOP853 states at ``times`` from sampled initial points: a dense line
    when one component is uncertain, else corners + random points."""
    lo, hi = np.asarray(x0.lo, float), np.asarray(x0.hi, float)
    free = np.flatnonzero(hi > lo)
    if free.size == 1:
        pts = line_points(lo, hi, n_samples, free[0])
    else:  # (at most 2^10 corners)
        pts = sample_initial_points(lo, hi, n_samples, seed=seed, corner_limit=10)
    return sample_trajectories(system.rhs, pts, times, params)


def run_case(name, model, x0, t_end, *, samples=64, output_dt=None, note="", **kw) -> dict:
    """One verified run, checked against sampled trajectories. A failure of the case
    (bad input, a model error, anything the run raises) is a 'crash' row, not an
    exception; only a NameError (a bug here, not a result) is raised."""
    row = dict(case=name, note=note, t_end=t_end, status="crash", t_reached=0.0, reason="", wall_s=0.0,
               widths=None, worst_ratio=None, escaped=0, checked=0, nan=False, max_boxes=None)
    t0 = time.perf_counter()
    # one in-process batch unless the case says otherwise: a work-precision row must not
    # change machines (a local cluster from 128 pieces on) between piece counts
    kw.setdefault("workers", 1)
    try:
        sol = _simulate()(model, x0, t_end, output_dt=output_dt, **kw)
        row["wall_s"] = time.perf_counter() - t0
        row.update(status=sol.status, t_reached=float(sol.t_reached), reason=sol.reason,
                   max_boxes=sol.stats.get("max_boxes"), pruned=sol.stats.get("pruned_boxes"))
        row["nan"] = bool(any(np.isnan(b.lo).any() or np.isnan(b.hi).any() for b in sol.boxes))
        if len(sol.t):
            row["widths"] = np.asarray(sol.hull.width()[-1], float)
            row["t_last"] = float(sol.t[-1])
        if samples and len(sol.t) > 1:
            system = reference_system(model, params=kw.get("params"))
            pv = None
            if system.rhs.n_params and kw.get("params"):
                pv = np.array([0.5 * (v[0] + v[1]) if isinstance(v, tuple) else v for v in kw["params"].values()])
            traj = _sampled(system, x0, np.asarray(sol.t, float), samples, pv)
            bad = check_samples(sol, traj)
            row["escaped"], row["checked"] = len(bad), int(traj.shape[0])
            fin = traj[:, -1, :]
            true_w = np.nanmax(fin, axis=0) - np.nanmin(fin, axis=0)
            if row["widths"] is not None:
                with np.errstate(divide="ignore", invalid="ignore"):
                    r = np.where(true_w > 1e-12, row["widths"] / true_w, np.nan)
                row["worst_ratio"] = float(np.nanmax(r)) if np.isfinite(r).any() else None
                row["true_widths"] = true_w
        row["solution"] = sol
    except NameError:
        # a name that does not exist is a bug in this code, never a result of the case
        # (one hid a dead branch as a 'crash' row): let it through
        raise
    except Exception as e:  # noqa: BLE001 - a crash is a result of the benchmark
        row["wall_s"] = time.perf_counter() - t0
        row["status"], row["reason"] = "crash", f"{type(e).__name__}: {e}"
    return row


# --------------------------------------------------------------------------- 1.
#: box budget of the stress cases (the energy test's refinement may multiply boxes)
STRESS_MAX_BOXES = 256

#: the energy test settings of the benchmark (the same for modes ii and iii)
TEST = dict(test_interval=0.1, test_splits=10)


def work_precision(t_end=0.5, modes=MODES, orders=(8, 12, 16), pieces=(4, 16, 64),
                   samples=2001, log=print):
    x0 = _paper_box()
    rows = []
    # load the compiled kernels and build each mode's model before timing
    for m in modes:
        run_case("warm-up", "double_pendulum_paper", x0, 0.02, samples=0, mode=m, subdivision=[2, 1, 1, 1])
    for mode in modes:
        for order in orders:
            for n in pieces:
                r = run_case("work-precision", "double_pendulum_paper", x0, t_end, samples=samples, mode=mode,
                             order=order, subdivision=[n, 1, 1, 1], **(TEST if get_mode(mode).energy_test else {}))
                r.update(mode=mode, order=order, pieces=n)
                rows.append(r)
                log(f"  mode {mode:>3} order {order:>2} pieces {n:>4}: {_short(r)}")
    return rows


# --------------------------------------------------------------------------- 2.
def stress_cases(quick=False, log=print):
    box = _paper_box()
    rows = []

    def add(name, *args, **kw):
        r = run_case(name, *args, **kw)
        rows.append(r)
        log(f"  {name:<34} {_short(r)}")

    # long horizon until break-down
    if quick:
        add("long horizon, 1 box, mode i", "double_pendulum_paper", box, 1.0, mode="i", output_dt=0.1, samples=16)
    else:
        add("long horizon, 1 box, mode i", "double_pendulum_paper", box, 3.0, mode="i", output_dt=0.1)
        add("long horizon, 1 box, mode ii", "double_pendulum_paper", box, 3.0, mode="ii", output_dt=0.1)
        add("long horizon, 64 pieces, mode i", "double_pendulum_paper", box, 3.0, mode="i", output_dt=0.1,
            subdivision=[64, 1, 1, 1])
        add("long horizon, 64 pieces, mode ii", "double_pendulum_paper", box, 3.0, mode="ii", output_dt=0.1,
            subdivision=[64, 1, 1, 1])
    # growing initial boxes (pendulum of sec. 5.1 around its box centre)
    c = np.array([2.15, 3.15])
    for hw in ((1e-3, 0.05) if quick else (1e-4, 1e-3, 1e-2, 0.05, 0.2, 0.5)):
        add(f"pendulum box +-{hw:g}", "pendulum_paper", Interval(c - hw, c + hw), 0.5 if quick else 1.0,
            mode="ii", output_dt=0.1, samples=16 if quick else 64, max_boxes=STRESS_MAX_BOXES)
    # masses and lengths over six decades (DH double pendulum, paper box); the
    # horizon scales with the natural period sqrt(l/g)
    scales = [(1e-3, 1.0), (1e3, 1.0), (1.0, 1e-3), (1.0, 1e3)]
    for m, l in (scales[:2] + scales[2:3] if quick else scales):
        chain = dp.dh_chain(m1=m, m2=m, l1=l, l2=l)
        T = min((0.1 if quick else 0.5) * math.sqrt(l), 1.0)
        add(f"m = {m:g} kg, l = {l:g} m", chain, box, T, mode="ii", output_dt=T / 5, subdivision=[8, 1, 1, 1],
            samples=16 if quick else 64, max_boxes=STRESS_MAX_BOXES)
    # nearly singular mass matrix
    for m2 in ((1e-4,) if quick else (1e-2, 1e-4, 1e-6)):
        chain = dp.dh_chain(m1=1.0, m2=m2)
        add(f"m2/m1 = {m2:g}", chain, box, 0.2 if quick else 1.0, mode="ii", output_dt=0.1,
            subdivision=[8, 1, 1, 1], samples=16 if quick else 64, max_boxes=STRESS_MAX_BOXES)
    # high energy: fast spinning double pendulum
    for w in ((10.0,) if quick else (10.0, 30.0)):
        lo, hi = np.array(box.lo, float), np.array(box.hi, float)
        lo[2:] += w
        hi[2:] += w
        add(f"high energy, rates +{w:g} rad/s", "double_pendulum_paper", Interval(lo, hi), 0.1 if quick else 0.5,
            mode="ii", output_dt=0.05, subdivision=[8, 1, 1, 1], samples=16 if quick else 64,
            max_boxes=STRESS_MAX_BOXES)
    # 6-DOF URDF arm, uncertain shoulder and elbow angles
    ur5 = get_model("ur5")
    q = np.array([0.0, -1.2, 1.0, -0.5, 0.3, 0.0])
    for hw in ((1e-3,) if quick else (1e-4, 1e-3, 1e-2)):
        lo = np.concatenate([q, np.zeros(6)])
        hi = lo.copy()
        lo[1:3] -= hw
        hi[1:3] += hw
        add(f"UR5, q2, q3 +-{hw:g} rad", ur5, Interval(lo, hi), 0.02 if quick else 0.2,
            mode="i" if quick else "ii", output_dt=0.01, samples=8 if quick else 32, max_boxes=STRESS_MAX_BOXES)
    return rows


# --------------------------------------------------------------------------- 3.
def startup(scenes=None, t_end=0.01, cold=True, log=print):
    """Wall time of ``python -m mbs simulate SCENE --t-end t_end`` in a subprocess:
    cold (fresh numba cache and model cache) then warm (the same caches again)."""
    scenes = scenes or sorted(scene_dir().glob("*.toml"))
    rows = []
    for scene in scenes:
        tmp = Path(tempfile.mkdtemp(prefix="mbs-startup-"))
        env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""),
               "NUMBA_CACHE_DIR": str(tmp / "numba"), "MBS_CACHE_DIR": str(tmp / "mbs")}
        if not cold:
            env.pop("NUMBA_CACHE_DIR")
            env.pop("MBS_CACHE_DIR")
        cmd = [sys.executable, "-m", "mbs", "simulate", str(scene), "--out", str(tmp / "out"), "--t-end",
               str(t_end), "--output-dt", str(t_end), "--samples", "0", "--no-figures"]
        times = []
        ok = True
        for _ in range(2):
            t0 = time.perf_counter()
            r = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=1800)
            times.append(time.perf_counter() - t0)
            ok = ok and r.returncode == 0
            if r.returncode != 0:
                log(f"  {scene.name}: exit {r.returncode}: {r.stderr.strip()[-300:]}")
        shutil.rmtree(tmp, ignore_errors=True)
        row = dict(scene=scene.name, cold_s=times[0] if cold else None, warm_s=times[1], ok=ok)
        rows.append(row)
        log(f"  {scene.name:<28} cold {row['cold_s'] or float('nan'):6.1f} s   warm {row['warm_s']:6.1f} s")
    return rows


# --------------------------------------------------------------------------- report
def _fmt_w(w):
    return "—" if w is None else ", ".join(f"{v:.3g}" for v in w)


def _short(r):
    if r["status"] == "crash":
        return f"CRASH {r['reason']}"
    s = f"{r['status']:<9} t={r['t_reached']:.3g}"
    if r.get("worst_ratio") is not None:
        s += f" ratio {r['worst_ratio']:.3f}"
    s += f" {r['wall_s']:.2f} s"
    if r["escaped"]:
        s += f" ESCAPED {r['escaped']}"
    if r["reason"]:
        s += f" ({r['reason']})"
    return s


def report_markdown(wp, stress, start, command, wall, t_end) -> str:
    lines = [
        "# Benchmarks",
        "",
        f"Generated by `{command}` ({time.strftime('%Y-%m-%d')}, {wall:.0f} s in total) on "
        f"{platform.machine()} with {os.cpu_count()} cores, Python {platform.python_version()}, "
        f"numpy {np.__version__}.",
        "",
        "## Work-precision: the paper's double pendulum (eq. 22, box 25)",
        "",
        f"Widths at T = {t_end:g} s of the hull of all boxes, and the worst ratio over the four states to the "
        "hull of DOP853 trajectories (rtol = atol = 1e-12) from 2001 values of x1(0) spread over the box. "
        "Energy test (modes ii, iii) every 0.1 s with 10 splits. "
        "Modes: (i) numeric model, no test; (ii) numeric model + energy test; (iii) symbolic model + "
        "energy test. Pieces: x1(0) split into N equal parts. `bench_work_precision.png` plots the same rows.",
        "",
        "| mode | order | pieces | status | widths x1..x4 at T | worst ratio | wall s | max boxes | pruned |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in wp:
        st = r["status"] if r["status"] == "completed" else f"{r['status']} at {r['t_reached']:.3f}"
        ratio = f"{r['worst_ratio']:.4f}" if r.get("worst_ratio") is not None and r["status"] == "completed" else "—"
        w = _fmt_w(r["widths"]) if r["status"] == "completed" else "—"
        lines.append(f"| {r['mode']} | {r['order']} | {r['pieces']} | {st} | {w} | {ratio} | {r['wall_s']:.2f} | "
                     f"{r.get('max_boxes') or '—'} | {r.get('pruned') if r.get('pruned') is not None else '—'} |")
    true_w = next((r["true_widths"] for r in wp if r.get("true_widths") is not None), None)
    if true_w is not None:
        lines += ["", f"Sampled true hull widths at T: {_fmt_w(true_w)}."]
    lines += [
        "",
        "## Stress tests",
        "",
        "Each case either completes or stops with a break-down reason; `escaped` counts sampled "
        "trajectory states (DOP853 from corners, random points and the centre of the initial box) "
        "outside the union of the boxes at any output time (must be 0); `NaN` flags a NaN bound.",
        "",
        "| case | status | t reached / T | final widths | worst ratio | wall s | samples | escaped | NaN | reason |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in stress:
        ratio = f"{r['worst_ratio']:.3g}" if r.get("worst_ratio") is not None else "—"
        reason = (r["reason"] or "").replace("|", "/")
        lines.append(f"| {r['case']} | {r['status']} | {r['t_reached']:.4g} / {r['t_end']:.4g} | "
                     f"{_fmt_w(r['widths'])} | {ratio} | {r['wall_s']:.2f} | {r['checked']} | {r['escaped']} | "
                     f"{'yes' if r['nan'] else 'no'} | {reason} |")
    if start:
        lines += [
            "",
            "## Start-up",
            "",
            "Wall time of `python -m mbs simulate SCENE --t-end 0.01 --samples 0 --no-figures` in a fresh "
            "process: cold = empty numba cache (`NUMBA_CACHE_DIR`) and model cache (`MBS_CACHE_DIR`), "
            "warm = the same command again.",
            "",
            "| scene | cold s | warm s |",
            "|---|---|---|",
        ]
        for r in start:
            cold = f"{r['cold_s']:.1f}" if r["cold_s"] is not None else "—"
            lines.append(f"| {r['scene']} | {cold} | {r['warm_s']:.1f}{'' if r['ok'] else ' (failed)'} |")
    return "\n".join(lines) + "\n"


def run(quick=False, out=None, log=print) -> int:
    """Run the benchmarks; write ``out``/benchmarks.md and bench_work_precision.png (default
    out: :data:`DEFAULT_OUT`, ``out/bench`` in the current working directory, for the
    full run, a temporary directory for --quick). Returns 1 if a case crashed, produced
    a NaN or missed a sampled trajectory."""
    t0 = time.perf_counter()
    out = Path(out) if out else (DEFAULT_OUT if not quick else Path(tempfile.mkdtemp(prefix="mbs-bench-")))
    t_end = 0.3 if quick else 0.5
    log(f"work-precision (double pendulum, T = {t_end:g})")
    if quick:
        wp = work_precision(t_end, orders=(12,), pieces=(4,), samples=201, log=log)
    else:
        wp = work_precision(t_end, log=log)
    log("stress tests")
    stress = stress_cases(quick, log=log)
    log("start-up (cold, warm)")
    scenes = None
    if quick:
            scenes = [scene_dir() / "pendulum_paper.toml"]
    start = startup(scenes, cold=not quick, log=log)
    wall = time.perf_counter() - t0
    command = "python -m mbs bench" + (" --quick" if quick else "")
    out.mkdir(parents=True, exist_ok=True)
    figures.fig_work_precision(wp, out / "bench_work_precision.png",
                       title=f"Double pendulum, T = {t_end:g}: worst width ratio vs wall time")
    (out / "benchmarks.md").write_text(report_markdown(wp, stress, start, command, wall, t_end))
    log(f"wrote {out / 'benchmarks.md'} and {out / 'bench_work_precision.png'} ({wall:.0f} s)")
    bad = [r for r in wp + stress if r["status"] == "crash" or r["nan"] or r["escaped"]]
    for r in bad:
        log(f"FAILED: {r['case']}: {_short(r)}")
    return 1 if bad else 0

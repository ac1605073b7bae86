"""Per-step CPU cost of one set against CAPD, side by side in one run (issue 45).

One initial set, no subdivision, the same right-hand sides formula for formula as the
C++ driver ``probs.cpp`` (``../shared/capd/``: ``dp`` is the paper's double pendulum
eq. (22) from box (25), ``chain3`` the 3-link planar point-mass chain, unit masses and
lengths, absolute angles, an LDL^T solve of M(th) thdd = b), to the same horizon. For
each system: CAPD (QR-Lohner ``C0Rect2Set``, its default order 20 and its cheapest
setting for equal width, order 12 with tolerance 1e-12), then this library with no
settings (``method="auto"``) and with hand-picked settings of low per-step cost. Each row:
steps, CPU seconds (process time, the least of ``--repeat`` runs), CPU per step, the
final hull's widths and the worst width ratio to CAPD's (order 20), and the per-step cost
ratio ours / CAPD (issue 45's target: <= 1).

    python benchmarks/bench_capd_step.py --capd /tmp/capd-probs/capd-probs
    CAPD_PROBS=/tmp/capd-probs/capd-probs python benchmarks/bench_capd_step.py --repeat 3
    python benchmarks/bench_capd_step.py --quick          # tiny horizons, our side only unless CAPD is given

CAPD's step count needs a driver that prints it (``"steps"`` in its JSON line: the copy
of ``probs.cpp`` described in docs/lab/capd_step.md, stopped after every step with
``ITimeMap::stopAfterStep(true)``); with the shared driver, which does not, the steps are
estimated from the horizon and CAPD's largest step (marked ``~``). Our runs are warmed
first (numba kernels compiled or loaded from the cache before the clock starts).
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import time

import numpy as np

from verified.graph import trace
from verified.arith.interval import Interval
from verified.methods import Composition, Lohner

G = 9.81  # the double nearest 9.81 (probs.cpp: interval(9.81) for chain3; 981/100 enclosed for dp)


def dp_rhs(x, p=None):
    """probs.cpp ``dp``: eq. (22), m = l = 1, as the IMap string writes it."""
    x1, x2, x3, x4 = x
    s2, c2 = np.sin(x2), np.cos(x2)
    b1 = -2 * G * np.sin(x1) + s2 * np.square(x3 + x4)
    b2 = -G * np.sin(x1 + x2) - s2 * np.square(x3)
    den = 1 + np.square(s2)
    return [x3, x4, (b1 - c2 * b2) / den, ((2 + c2) * b2 - (c2 + 1) * b1) / den]


def dp_box():
    """Box (25): x1 in [0.99, 1.01] 3 pi / 4, the others points (one-ulp enclosures)."""
    from models.double_pendulum import initial_box
    return initial_box()


def chain3_rhs(x, p=None):
    """probs.cpp ``chain3`` (= ../shared/capd/models3.py)."""
    t1, t2, t3, w1, w2, w3 = x
    s12, c12 = np.sin(t1 - t2), np.cos(t1 - t2)
    s13, c13 = np.sin(t1 - t3), np.cos(t1 - t3)
    s23, c23 = np.sin(t2 - t3), np.cos(t2 - t3)
    w1s, w2s, w3s = w1 * w1, w2 * w2, w3 * w3
    b1 = -(2 * s12 * w2s + s13 * w3s) - 3 * G * np.sin(t1)
    b2 = 2 * s12 * w1s - s23 * w3s - 2 * G * np.sin(t2)
    b3 = s13 * w1s + s23 * w2s - G * np.sin(t3)
    l21, l31 = 2 * c12 / 3, c13 / 3
    d2 = (2 + 4 * (s12 * s12)) / 3
    e = c23 - 2 * c12 * c13 / 3
    l32 = e / d2
    d3 = (2 + s13 * s13) / 3 - e * l32
    z2 = b2 - l21 * b1
    z3 = b3 - l31 * b1 - l32 * z2
    a3 = z3 / d3
    a2 = z2 / d2 - l32 * a3
    a1 = b1 / 3 - l21 * a2 - l31 * a3
    return [w1, w2, w3, a1, a2, a3]


def chain3_box():
    """th1(0) in [0.99, 1.01] pi / 2 (doubles), th2 = pi / 3, th3 = pi / 4, w = (0.43, 0.67, 0)."""
    lo = np.array([0.99 * np.pi / 2, np.pi / 3, np.pi / 4, 0.43, 0.67, 0.0])
    hi = lo.copy()
    hi[0] = 1.01 * np.pi / 2
    return lo, hi


#: our hand-picked settings: CAPD's cheapest setting for equal width (order 12, tol 1e-12)
#: with the QR-or-box error basis (plain QR breaks down before CAPD on both systems), the
#: lowest per-step cost that completes (first-order sets at order 6, tol 1e-8), and the
#: lowest total CPU (composition at order 12, degree-2 Taylor models; also the tightest)
PICKS = [("lohner o12 tol1e-12 auto-basis", Lohner(order=12, tol=1e-12, error_basis="auto")),
         ("lohner o6 tol1e-8 auto-basis", Lohner(order=6, tol=1e-8, error_basis="auto")),
         ("composition o12 degree 2", Composition(order=12, tol=1e-10, model_degree=2))]

#: name -> (rhs, n, box, T, quick T, our hand-picked settings). The horizons: CAPD from one
#: set breaks down at t = 0.623 (dp) and 0.434 (chain3, order 20); ours (QR basis) at 0.45 / 0.2
CASES = {
    "dp": (dp_rhs, 4, dp_box, 0.5, 0.05, PICKS),
    "chain3": (chain3_rhs, 6, chain3_box, 0.3, 0.05, PICKS),
}

#: CAPD settings: (label, order, tol); tol 0 = CAPD's default
CAPD_SETTINGS = [("capd o20 (default)", 20, 0.0), ("capd o12 tol1e-12", 12, 1e-12)]


def run_capd(exe: str, prob: str, T: float, order: int, tol: float, repeat: int) -> dict:
    """Least CPU of ``repeat`` runs of ``probs PROB 1 T ORDER TOL`` (one JSON line each)."""
    best = None
    for _ in range(repeat):
        out = subprocess.run([exe, prob, "1", repr(T), str(order), repr(tol)], capture_output=True, text=True,
                             check=True, timeout=600).stdout
        r = json.loads(out.strip().splitlines()[-1])
        if best is None or r["cpu"] < best["cpu"]:
            best = r
    if "steps" not in best:  # (the shared driver: no step count) estimate from T and CAPD's step sizes
        best["steps_estimated"] = True
    return best


def run_ours(ode, box, T: float, method, repeat: int) -> dict:
    """Least CPU of ``repeat`` runs of ``solve(ode, box, (0, T), method=method)``."""
    from verified.solver import solve
    best = None
    for _ in range(repeat):
        t0 = time.process_time()
        sol = solve(ode, Interval(*box), (0.0, T), method=method)
        cpu = time.process_time() - t0
        if best is None or cpu < best["cpu"]:
            best = {"cpu": cpu, "sol": sol}
    sol = best["sol"]
    return {"cpu": best["cpu"], "status": sol.status, "t_reached": float(sol.t_reached), "steps": int(sol.stats["steps"]),
                "widths": np.asarray(sol.hull[-1].width(), float).tolist() if sol.status == "completed" else None,
                "method": getattr(sol, "method", "")}


def _fmt_w(w):
    return "[" + ", ".join(f"{x:.3g}" for x in w) + "]" if w else "-"


def run_case(key: str, T: float, capd: str | None, repeat: int, extra=(), out=print):
    """One system's table; ``extra``: more (label, ode, method) rows of ours."""
    rhs, n, boxf, _, _, picks = CASES[key]
    g = trace(rhs, n)
    box = boxf()
    from verified.solver import VerifiedODE, solve
    # The hand-picked rows run on the ODE prepared once (its Taylor tapes built before the
    # clock, as probs.cpp builds its IMap before its clock); auto needs the graph and
    # prepares it inside each run (``prep`` below says what that costs)
    prepared, prep = {}, {}
    for _, m in picks:
        if m.arithmetic not in prepared:
            t0 = time.process_time()
            prepared[m.arithmetic] = VerifiedODE(g, m.arithmetic)
            prep[m.arithmetic] = time.process_time() - t0
    solve(g, Interval(*box), (0.0, min(T, 0.02)))  # warm: kernels compiled / loaded from numba's cache
    for _, m in picks:
        solve(prepared[m.arithmetic], Interval(*box), (0.0, min(T, 0.02)), method=m)
    rows = []
    if capd:
        for label, order, tol in CAPD_SETTINGS:
            r = run_capd(capd, key, T, order, tol, repeat)
            steps = r.get("steps")
            est = steps is None
            if est:
                steps = int(np.ceil(T / r.get("h_max", T))) if "h_max" in r else None
            rows.append({"label": label, "status": r["status"], "t_reached": r["t_reached"], "steps": steps, "est": est,
                             "cpu": r["cpu"], "widths": r.get("widths")})
    for label, ode, m in [("ours: auto (no settings)", g, None),
                          *[(f"ours: {lab}", prepared[m.arithmetic], m) for lab, m in picks], *extra]:
        r = run_ours(ode, box, T, m, repeat)
        rows.append({"label": label, "status": r["status"], "t_reached": r["t_reached"], "steps": r["steps"], "est": False,
                         "cpu": r["cpu"], "widths": r["widths"], "method": r["method"]})
    ref = next((r for r in rows if r["label"].startswith("capd") and r["status"] == "completed"), None)
    capd_rows = [r for r in rows if r["label"].startswith("capd") and r["steps"]]
    for r in rows:
        r["per_step"] = r["cpu"] / r["steps"] if r["steps"] else float("nan")
    for r in rows:
        q = [a / b for a, b in zip(r["widths"], ref["widths"]) if b > 0] if ref and r["widths"] else []
        r["wratio"] = (min(q), max(q)) if q else (float("nan"), float("nan"))
        r["step_ratio"] = [r["per_step"] / c["per_step"] for c in capd_rows]
        r["cpu_ratio"] = [r["cpu"] / c["cpu"] for c in capd_rows]
    names = [c["label"].split(" (")[0] for c in capd_rows]
    head = "".join(f" CPU/step / {c} |" for c in names) + "".join(f" CPU / {c} |" for c in names)
    out(f"\n{key}, one set, T = {T:g} (CPU: the least of {repeat} runs)\n")
    out(f"| run | status | steps | CPU s | CPU/step ms | final widths | width / CAPD o20 (min-max) |{head}")
    out("|---|---|---|---|---|---|---|" + "---|" * (2 * len(capd_rows)))
    for r in rows:
        st = r["status"] if r["status"] == "completed" else f"{r['status']} at {r['t_reached']:.4g}"
        steps = ("~" if r["est"] else "") + (str(r["steps"]) if r["steps"] else "-")
        ratios = "".join(f" {x:.2f} |" for x in r["step_ratio"] + r["cpu_ratio"])
        wr = "-" if r["wratio"][0] != r["wratio"][0] else f"{r['wratio'][0]:.3g}-{r['wratio'][1]:.3g}"
        out(f"| {r['label']} | {st} | {steps} | {r['cpu']:.4f} | {r['per_step'] * 1e3:.3f} | {_fmt_w(r['widths'])} | "
            f"{wr} |{ratios}")
    for r in rows:
        if r.get("method"):
            out(f"  {r['label']}: ran {r['method']}")
    out("  preparation outside the clock (VerifiedODE, first run): "
        + ", ".join(f"{a} {t * 1e3:.1f} ms" for a, t in prep.items()) + "; the auto row pays it inside")
    return rows


def _find_capd(arg: str | None) -> str | None:
    exe = arg or os.environ.get("CAPD_PROBS")
    if exe and (os.path.isfile(exe) or shutil.which(exe)):
        return exe
    return None


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--capd", default=None, help="path of CAPD's probs driver (default: $CAPD_PROBS)")
    ap.add_argument("--only", default=",".join(CASES), help="comma-separated cases: " + ", ".join(CASES))
    ap.add_argument("--T", type=float, default=None, help="horizon for every case (default: each case's)")
    ap.add_argument("--repeat", type=int, default=3, help="runs per row; the least CPU is reported")
    ap.add_argument("--quick", action="store_true", help="tiny horizons, one run per row")
    a = ap.parse_args(argv)
    capd = _find_capd(a.capd)
    if capd is None:
        print("note: CAPD's probs driver not found (--capd PATH or CAPD_PROBS; how to build it: "
              "docs/lab/capd_step.md); running this library's side only")
    repeat = 1 if a.quick else a.repeat
    results = {}
    for key in a.only.split(","):
        key = key.strip()
        T = a.T if a.T is not None else CASES[key][4 if a.quick else 3]
        results[key] = run_case(key, T, capd, repeat)
    return results


if __name__ == "__main__":
    main()

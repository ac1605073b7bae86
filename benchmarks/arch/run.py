"""ARCH-COMP "nonlinear continuous systems" (NLN) benchmarks with the verified solver (issue 43).

The models, written from the competition's published definitions (ARCH-COMP NLN category
reports 2020-2023, and the JuliaReach documentation's files for Laub-Loomis and
Production-Destruction):

- **Laub-Loomis** (7 states), box centre (1.2, 1.05, 1.5, 2.4, 1, 0.1, 0.45) +- W for
  W = 0.01, 0.05, 0.1, T = 20; metric: width of x4 at T; spec x4 < 4.5 (< 5 for W = 0.1)
  over the whole time. **Variant: x7' = 1.8 x6 - 1.6 x2 x7, as in JuliaReach's files**
  (ReachabilityAnalysis.jl's model and its ARCH RE packages): the published widths
  compared against (0.00424 / 0.01747 / 0.03371, TMJets) are of that file. Ariadne's and
  Flow*'s files have 1.5 in place of 1.6 (``LL_C7 = 1.5`` switches it).
- **Van der Pol**, mu = 1: x' = y, y' = (1 - x^2) y - x, x in [1.25, 1.55], y in
  [2.35, 2.45], T = 7; spec y < 2.75 over the whole time (checked on the tube hull:
  the upper bound of y over every step); published JuliaReach max y 2.72498.
- **coupled Van der Pol**: (x1, y1, x2, y2), y1' = (1 - x1^2) y1 + b (x2 - x1) - x1,
  y2' = (1 - x2^2) y2 - b (x2 - x1) - x2, x1, x2 in [1.25, 1.55], y1, y2 in
  [2.35, 2.45], b in [1, 3] (an uncertain parameter), T = 7; spec y1, y2 < 2.75 over
  the whole time.
- **Robertson**: x' = -a x + b y z, y' = a x - b y z - c y^2, z' = c y^2, a = 0.4,
  (b, c) in {(1e2, 1e3), (1e3, 1e5), (1e3, 1e7)}, from (1, 0, 0), T = 40; metric: width
  of x + y + z at T (enclosed over the solver's sets in their linear view where there is
  one, else over the boxes). Each run is capped (``--cap``) and the table says how far it got.
- **Production-Destruction**: x' = -x y / (1 + x), y' = x y / (1 + x) - a y, z' = a y,
  x(0) = 9.98, y(0) = z(0) = 0.01, a = 0.3; I: x(0) in [9.5, 10]; P: a in
  [0.296, 0.304]; I&P: x(0) in [9.7, 10] and a in [0.298, 0.302] (the ARCH-COMP 2021+
  I&P; JuliaReach's documentation runs the 2020 one, x(0) in [9.5, 10] and a in
  [0.296, 0.304]); T = 100; spec x, y, z >= 0 (here over the whole tube, stronger than
  the competition's at T) and 10 in x + y + z at T; metric: volume of the final box.

Every case runs with the library's defaults (``solve(graph, x0, (0, T), params=...,
t_eval=...)``: ``method="auto"``), the cases with a spec on the states (Laub-Loomis,
Van der Pol, coupled Van der Pol) also with that spec declared and nothing else
(``method=Auto(spec={state: (None, bound)})``: auto refines until the tube proves it,
:mod:`verified.spec`), and, where it helps, with a hand-picked setting. Each
row: status, the time reached, CPU seconds (``time.process_time``), the metric, whether
the spec is proven (from the tube, only on a completed run), the published number and
"inside": sampled true solutions (corners and random points of the initial box and
parameter box; scipy's DOP853, rtol = atol = 1e-13; Radau with rtol 1e-12 for the stiff
Robertson) lie in the union of the output's boxes at every output time and in the union
of the step's boxes at three times inside every step of the tube (slack 1e-11 (1 + |x|)
for the sampler's own error).

    python benchmarks/arch/run.py                       # every case (cap 120 s per run)
    python benchmarks/arch/run.py --only vdp,ll001      # some cases
    python benchmarks/arch/run.py --quick               # short horizons, default rows only
    python benchmarks/arch/run.py --cap 60              # wall-clock cap per run (s)
    python benchmarks/arch/run.py --only rob23,pdp --invariant both   # each row without and with x + y + z declared

``--invariant on|both`` declares the conserved x + y + z of Robertson and
Production-Destruction (``solve(..., invariants=[Conserved([1, 1, 1])])``,
:mod:`verified.consistency.conservation`: proven, then imposed on the sets after every step).

The table (Markdown) goes to stdout, progress to stderr.
"""
from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from verified.graph import trace
from verified.driver.hooks import StopAfterWall
from verified.arith.interval import Interval

#: Laub-Loomis' coefficient of x2 x7 in x7' (JuliaReach's file: 1.6; Ariadne, Flow*: 1.5)
LL_C7 = 1.6
#: slack for the sampler's own error in the containment check: 1e-11 (1 + |x|)
SLACK = 1e-11
#: output times per run (evenly spaced, T included)
N_OUT = 20


@dataclass
class Case:
    key: str
    name: str
    f: object                      # f(x, p) -> list: traced for the solver, evaluated on floats for scipy
    n: int
    x0: Interval
    params: Interval | None
    T: float
    quick_T: float
    metric_name: str
    metric: object                 # metric(sol) -> float (on a completed run)
    spec: object                   # spec(sol) -> (bool, str) from the tube, or None
    published: str
    hand: list = field(default_factory=list)   # [(label, settings)]; settings may carry x0/params
    stiff: bool = False
    samples: int = 100
    conserved: tuple | None = None   # weights of a linear conserved quantity (x + y + z), for --invariant
    spec_bounds: dict | None = None  # the spec as bounds for Auto(spec=...): the "auto, spec declared" row

    def graph(self):
        return trace(self.f, self.n, 0 if self.params is None else self.params.shape[-1])


# ---------------------------------------------------------------- metrics and specs

def _linear_at_last(sol, w) -> Interval:
    """An enclosure of ``w . x`` at the last output: over the solver's sets in their
    linear view where the run kept one (``c + A R``, interval arithmetic), intersected
    with the enclosure over the output's boxes."""
    w = np.asarray(w, float)
    B = sol.boxes[-1]
    s = (B * w).sum(axis=1)
    lo, hi = float(np.min(s.lo)), float(np.max(s.hi))
    views = sol.views or []
    v = views[-1] if len(views) == len(sol.t) else None
    if v is not None:
        c = Interval(v.c, v.c)
        sv = (c * w).sum(axis=1) + ((v.A * w[None, :, None]).sum(axis=1) * v.R).sum(axis=1)
        lo, hi = max(lo, float(np.min(sv.lo))), min(hi, float(np.max(sv.hi)))
    return Interval([lo], [hi])


def width_of(i):
    return lambda sol: float(sol.hull[-1].width()[i])


def sum_width(sol):
    return float(_linear_at_last(sol, np.ones(3)).width()[0])


def volume(sol):
    return float(np.prod(sol.hull[-1].width()[:3]))


def tube_max(idx):
    return lambda sol: float(np.max(sol.tube_hull.hi[:, idx]))


def upper_spec(idx, bound):
    def spec(sol):
        m = float(np.max(sol.tube_hull.hi[:, idx]))
        return m < bound, f"max {m:.5g}, bound {bound:g}"
    return spec


def pd_spec(sol):
    """The competition's spec, at T: x, y, z >= 0 and 10 in x + y + z (the detail adds
    the lowest bound of x, y, z over the whole tube)."""
    lo_T = float(np.min(sol.boxes[-1].lo[:, :3]))
    lo = float(np.min(sol.tube_hull.lo[:, :3]))
    s = _linear_at_last(sol, np.ones(3))
    ok = lo_T >= 0 and float(s.lo[0]) <= 10 <= float(s.hi[0])
    return ok, f"min at T {lo_T:.3g}, over the tube {lo:.3g}; sum at T in [{float(s.lo[0]):.8g}, {float(s.hi[0]):.8g}]"


# ---------------------------------------------------------------- the models

def laub_loomis(W: float) -> Case:
    def f(x, p):
        x1, x2, x3, x4, x5, x6, x7 = x
        return [1.4 * x3 - 0.9 * x1, 2.5 * x5 - 1.5 * x2, 0.6 * x7 - 0.8 * x2 * x3, 2 - 1.3 * x3 * x4,
                0.7 * x1 - x4 * x5, 0.3 * x1 - 3.1 * x6, 1.8 * x6 - LL_C7 * x2 * x7]
    c = np.array([1.2, 1.05, 1.5, 2.4, 1.0, 0.1, 0.45])
    pub = {0.01: "0.00424", 0.05: "0.01747", 0.1: "0.03371"}[W]
    bound = 5.0 if W == 0.1 else 4.5
    hand = [("composition", dict(method="composition"))]
    if W == 0.05:   # (h_max 0.1: a tighter tube near the maximum of x4, spec proven)
        hand = [("composition, h_max 0.1", dict(method="composition", h_max=0.1))]
    if W > 0.01:
        hand.append(("composition, 2^4 pieces (x1..x4)", dict(method="composition", subdivision=[2, 2, 2, 2, 1, 1, 1])))
    return Case(f"ll{str(W).replace('.', '')}", f"Laub-Loomis W = {W:g}", f, 7, Interval(c - W, c + W), None,
                20.0, 2.0, "width x4(T)", width_of(3), upper_spec(3, bound), pub, hand,
                spec_bounds={3: (None, bound)})


def _vdp(x, p):
    return [x[1], (1 - x[0] * x[0]) * x[1] - x[0]]


def vdp() -> Case:
    return Case("vdp", "Van der Pol mu = 1", _vdp, 2, Interval([1.25, 2.35], [1.55, 2.45]), None, 7.0, 1.0,
                "max y on [0, T]", tube_max(1), upper_spec(1, 2.75), "2.72498",
                [("composition, 2x2 pieces, h_max 0.05", dict(method="composition", subdivision=[2, 2], h_max=0.05)),
                 ("composition, 4x4 pieces", dict(method="composition", subdivision=[4, 4]))],
                spec_bounds={1: (None, 2.75)})


def _cvdp(x, p):
    x1, y1, x2, y2 = x
    b = p[0]
    return [y1, (1 - x1 * x1) * y1 + b * (x2 - x1) - x1, y2, (1 - x2 * x2) * y2 - b * (x2 - x1) - x2]


def _split_params(x0: Interval, params: Interval, k: int, subdivision=None):
    """x0 (cut by ``subdivision``) repeated for each of ``k`` equal parts of the one
    parameter's interval: (boxes (B k, n), params (B k, 1))."""
    boxes = x0.reshape(1, -1)
    if subdivision is not None:
        for axis, m in enumerate(subdivision):
            if m > 1:
                parts = []
                for b in range(boxes.shape[0]):
                    lo, hi = boxes.lo[b].copy(), boxes.hi[b].copy()
                    edges = np.linspace(lo[axis], hi[axis], m + 1)
                    for j in range(m):
                        l, h = lo.copy(), hi.copy()
                        l[axis], h[axis] = edges[j], edges[j + 1]
                        parts.append((l, h))
                boxes = Interval(np.array([q[0] for q in parts]), np.array([q[1] for q in parts]))
    edges = np.linspace(float(params.lo[0]), float(params.hi[0]), k + 1)
    B = boxes.shape[0]
    xs = Interval(np.tile(boxes.lo, (k, 1)), np.tile(boxes.hi, (k, 1)))
    ps = Interval(np.repeat(edges[:-1], B)[:, None], np.repeat(edges[1:], B)[:, None])
    return xs, ps


def coupled_vdp() -> Case:
    x0 = Interval([1.25, 2.35, 1.25, 2.35], [1.55, 2.45, 1.55, 2.45])
    b = Interval([1.0], [3.0])
    from verified.methods import Auto
    xs, ps = _split_params(x0, b, 4, [2, 1, 2, 1])
    xs64, ps64 = _split_params(x0, b, 4, [4, 1, 4, 1])
    spec = {1: (None, 2.75), 3: (None, 2.75)}
    return Case("cvdp", "coupled Van der Pol, b in [1, 3]", _cvdp, 4, x0, b, 7.0, 1.0,
                "max y1, y2 on [0, T]", tube_max([1, 3]), upper_spec([1, 3], 2.75), "(CORA: 13 splits)",
                [("composition, b in 4 x x1, x2 in 2 (16 pieces)", dict(method="composition", x0=xs, params=ps)),
                 # (the pieces CORA-like by hand, then auto refines toward the spec: ~170 s CPU, needs --cap 400)
                 ("spec declared, from b in 4 x x1, x2 in 4 (64 pieces), h_max 0.05",
                  dict(method=Auto(spec=spec), x0=xs64, params=ps64, h_max=0.05))],
                spec_bounds=spec)


def robertson(b: float, c: float) -> Case:
    quick_T = {1e3: 1.0, 1e5: 0.1, 1e7: 0.01}[c]   # (stiffer: shorter steps)
    def f(x, p):
        return [-0.4 * x[0] + b * x[1] * x[2], 0.4 * x[0] - b * x[1] * x[2] - c * x[1] * x[1], c * x[1] * x[1]]
    return Case(f"rob{int(np.log10(b))}{int(np.log10(c))}", f"Robertson b = {b:.0e}, c = {c:.0e}", f, 3,
                Interval([1.0, 0.0, 0.0], [1.0, 0.0, 0.0]), None, 40.0, quick_T, "width x+y+z(T)", sum_width, None,
                "—", [], stiff=True, samples=1, conserved=(1.0, 1.0, 1.0))


def _pd(x, p):
    a = p[0]
    r = x[0] * x[1] / (1 + x[0])
    return [-r, r - a * x[1], a * x[1]]


def production_destruction(variant: str) -> Case:
    x0 = {"I": Interval([9.5, 0.01, 0.01], [10.0, 0.01, 0.01]), "P": Interval([9.98, 0.01, 0.01], [9.98, 0.01, 0.01]),
          "IP": Interval([9.7, 0.01, 0.01], [10.0, 0.01, 0.01])}[variant]
    a = {"I": Interval([0.3], [0.3]), "P": Interval([0.296], [0.304]), "IP": Interval([0.298], [0.302])}[variant]
    label = {"I": "I", "P": "P", "IP": "I&P"}[variant]
    hand = []
    if variant != "I":   # (composition crawls with narrow states and a wide parameter: docs/lab/arch.md)
        xs, ps = _split_params(x0, a, 4)
        hand = [("second_order", dict(method="second_order")),
                ("second_order, a in 4 pieces", dict(method="second_order", x0=xs, params=ps))]
    return Case(f"pd{variant.lower()}", f"Production-Destruction {label}", _pd, 3, x0, a, 100.0, 10.0,
                "volume at T", volume, pd_spec, "—", hand, conserved=(1.0, 1.0, 1.0))


CASES = {
    "ll001": lambda: laub_loomis(0.01), "ll005": lambda: laub_loomis(0.05), "ll01": lambda: laub_loomis(0.1),
    "vdp": vdp, "cvdp": coupled_vdp,
    "rob23": lambda: robertson(1e2, 1e3), "rob35": lambda: robertson(1e3, 1e5), "rob37": lambda: robertson(1e3, 1e7),
    "pdi": lambda: production_destruction("I"), "pdp": lambda: production_destruction("P"),
    "pdip": lambda: production_destruction("IP"),
}


# ---------------------------------------------------------------- sampling (the soundness check)

def sample_starts(case: Case, count: int, seed: int = 1):
    """Initial states and parameter values: the corners of the joint (x0, p) box (up to
    64, the wide directions only) and random points, ``count`` in all (at least 1)."""
    lo = np.concatenate([case.x0.lo, [] if case.params is None else case.params.lo])
    hi = np.concatenate([case.x0.hi, [] if case.params is None else case.params.hi])
    wide = np.flatnonzero(hi > lo)
    pts = []
    if wide.size:
        m = min(wide.size, 6)
        for bits in range(2 ** m):
            q = lo.copy()
            q[wide] = (lo[wide] + hi[wide]) / 2
            for j in range(m):
                q[wide[j]] = hi[wide[j]] if bits >> j & 1 else lo[wide[j]]
            pts.append(q)
    rng = np.random.default_rng(seed)
    while len(pts) < count:
        pts.append(lo + rng.random(lo.size) * (hi - lo))
    pts = np.array(pts[:max(count, 1)] if wide.size else [lo])
    return pts[:, :case.n], pts[:, case.n:]


def check_inside(case: Case, sol, count: int):
    """(all inside, detail): sampled true solutions against the output boxes at every
    output time and against the tube's boxes at three times inside every step."""
    from mbs.app.sampling import dop853, radau
    if sol.t[-1] <= 0:
        return True, "nothing verified"
    xs, ps = sample_starts(case, count)
    steps = len(sol.tube)
    tt = np.asarray(sol.tube_t, float)
    inner = (tt[:steps, None] + np.array([0.25, 0.5, 0.75])[None, :] * np.diff(tt)[:steps, None]).ravel()
    t_end = float(max(sol.t[-1], tt[steps] if steps else 0.0))
    outs, denses = [], []
    for x, p in zip(xs, ps):
        fun = (lambda t, y, p=p: np.array(case.f(y, p), float))
        if case.stiff:
            r = radau(fun, x, t_end, rtol=1e-12, atol=1e-20, strict=False)
        else:
            r = dop853(fun, x, t_end, rtol=1e-13, atol=1e-13, strict=False)
        if r.status != 0:
            return False, f"sampler failed: {r.message}"
        outs.append(r.sol(np.asarray(sol.t, float)).T)             # (k, n)
        denses.append(r.sol(inner).T.reshape(steps, 3, case.n))   # (steps, 3, n)
    out, dense = np.stack(outs, axis=1), np.stack(denses, axis=1)  # (k, S, n), (steps, S, 3, n)
    bad, worst = 0, 0.0
    for k in range(len(sol.t)):
        e = _excess(out[k], sol.boxes[k])
        worst, bad = max(worst, float(e.max())), bad + int(np.count_nonzero(e > 0))
    for j in range(steps):
        e = _excess(dense[j].reshape(-1, case.n), sol.tube[j])
        worst, bad = max(worst, float(e.max())), bad + int(np.count_nonzero(e > 0))
    return bad == 0, ("yes" if bad == 0 else f"NO ({bad} misses, worst {worst:.2g})")


def _excess(X, boxes: Interval) -> np.ndarray:
    """Per point of X (m, n): 0 when it lies in the union of ``boxes`` (B, n) up to the
    slack, else its distance (beyond the slack) to the nearest box."""
    lo, hi = np.asarray(boxes.lo, float), np.asarray(boxes.hi, float)
    tol = SLACK * (1 + np.abs(X))[:, None, :]
    d = np.maximum(lo[None] - X[:, None, :] - tol, X[:, None, :] - hi[None] - tol)   # (m, B, n)
    return np.max(np.maximum(d, 0.0), axis=2).min(axis=1) if X.size else np.zeros(0)


# ---------------------------------------------------------------- running

def run_row(case: Case, label: str, settings: dict, T: float, cap: float, samples: int):
    from verified.solver import solve
    kw = dict(settings)
    x0 = kw.pop("x0", case.x0)
    params = kw.pop("params", case.params)
    g = case.graph()
    t_eval = np.linspace(0.0, T, N_OUT + 1)
    t0 = time.process_time()
    sol = solve(g, x0, (0.0, T), params=params, t_eval=t_eval, hooks=[StopAfterWall(cap)], **kw)
    cpu = time.process_time() - t0
    done = sol.status == "completed"
    metric = case.metric(sol) if done else float("nan")
    if case.spec is None:
        spec = "—"
    else:
        ok, detail = case.spec(sol)
        spec = ("yes" if ok and done else "no") + f" ({detail}{'' if done else ', up to t reached'})"
    inside_ok, inside = check_inside(case, sol, samples)
    return dict(case=case.name, setting=label, status=sol.status, t=float(sol.t_reached), cpu=cpu,
                metric=metric, metric_name=case.metric_name, published=case.published, spec=spec, inside=inside,
                inside_ok=inside_ok, method=sol.method, reason=sol.reason, sol=sol)


HEADER = ("| case | setting | status | t reached | CPU s | metric | ours | published (JuliaReach) | spec proven | "
          "inside | what ran |\n|---|---|---|---|---|---|---|---|---|---|---|")


def format_row(r: dict) -> str:
    m = "—" if not np.isfinite(r["metric"]) else f"{r['metric']:.4g}"
    what = r["method"][:90] + ("" if r["status"] == "completed" else f"; {r['reason'][:80]}")
    sc = getattr(r["sol"], "spec_check", None)
    if sc is not None:   # (auto's own verdict, its pieces and refinement rounds)
        st = r["sol"].stats
        what = (f"auto's spec verdict: {sc.status}; {st.get('auto_pieces')} piece(s), "
                f"{st.get('spec_rounds')} refinement round(s); ") + what
    return (f"| {r['case']} | {r['setting']} | {r['status']} | {r['t']:.4g} | {r['cpu']:.1f} | {r['metric_name']} | "
            f"{m} | {r['published']} | {r['spec']} | {r['inside']} | {what.replace('|', '/')} |")


def with_invariant(case: Case, rows: list, invariant: str) -> list:
    """The rows to run: as they are (``"off"``), with the case's conserved quantity
    declared (``solve(..., invariants=[Conserved(w)])``, ``"on"``), or each both ways
    (``"both"``); cases without one run as they are."""
    if invariant == "off" or case.conserved is None:
        return rows
    from verified.consistency.conservation import Conserved
    w = case.conserved
    name = " + ".join(("" if c == 1 else f"{c:g} ") + v for c, v in zip(w, "xyz"))
    inv = [(f"{label} + invariant {name}", dict(settings, invariants=[Conserved(list(w))]))
           for label, settings in rows]
    if invariant == "on":
        return inv
    return [r for pair in zip(rows, inv) for r in pair]


def run_case(key: str, quick: bool = False, cap: float = 120.0, out=print, log=None, invariant: str = "off"):
    case = CASES[key]()
    T = case.quick_T if quick else case.T
    samples = min(case.samples, 30) if quick else case.samples
    rows = []
    base = [("defaults (auto)", {})]
    if case.spec_bounds is not None:   # (auto told the spec, nothing else: verified.spec, Auto(spec=...))
        from verified.methods import Auto
        base.append(("auto, spec declared", dict(method=Auto(spec=case.spec_bounds))))
    for label, settings in with_invariant(case, base + ([] if quick else case.hand), invariant):
        if log:
            log(f"{case.name}: {label} ...")
        r = run_row(case, label, settings, T, cap, samples)
        rows.append(r)
        out(format_row(r))
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default=",".join(CASES), help="comma-separated case keys: " + ", ".join(CASES))
    ap.add_argument("--quick", action="store_true", help="short horizons, default rows only")
    ap.add_argument("--cap", type=float, default=120.0, help="wall-clock cap per run (s)")
    ap.add_argument("--invariant", choices=("off", "on", "both"), default="off",
                    help="declare the case's conserved x + y + z (Robertson, Production-Destruction): "
                         "off (default), on, or both (each row without, then with it)")
    a = ap.parse_args(argv)
    keys = [k.strip() for k in a.only.split(",") if k.strip()]
    unknown = [k for k in keys if k not in CASES]
    if unknown:
        ap.error(f"unknown case(s) {', '.join(unknown)}; cases: {', '.join(CASES)}")
    print(HEADER, flush=True)
    w0 = time.perf_counter()
    all_ok = True
    for k in keys:
        rows = run_case(k, quick=a.quick, cap=a.cap, out=lambda s: print(s, flush=True),
                        log=lambda s: print(s, file=sys.stderr, flush=True), invariant=a.invariant)
        all_ok &= all(r["inside_ok"] for r in rows)
    print(f"\n{'quick, ' if a.quick else ''}cap {a.cap:g} s per run; {time.perf_counter() - w0:.0f} s wall in all; "
          f"every sample inside: {'yes' if all_ok else 'NO'}", flush=True)
    return 0 if all_ok else 1


if __name__ == "__main__":
    sys.exit(main())

"""The paper's figures from simulation results (matplotlib, Agg backend, PNG files).

* :func:`fig_reduction_area` -- Fig. 2: the reduction area RA(t) of eq. (16) with the
  test times t* marked (and the H_H / H_V enclosures it compares).
* :func:`fig_consistency_plane` -- Fig. 3 (drawn by the CLI and the demo only when a test
  pruned a sub-box): the (q, qd) plane at t*: the regions where
  the energy H is certainly outside [H_V(t*)] (H evaluated in interval arithmetic on a
  grid of cells over the tested box; a shaded cell holds no consistent state), the
  tested sub-boxes, kept ones outlined, pruned ones crossed.
* :func:`fig_enclosures` -- Fig. 5: the hull of the enclosure of each state over time
  for several modes overlaid (solid black (i), thick grey (ii), dashed blue (iii)),
  optionally with sampled true trajectories (:func:`mbs.app.sampling.sample_trajectories`),
  and beside it the enclosure's width over time on a log scale, one line per mode, with
  the samples' spread as the reference, and the excess width over that spread (log
  scale: where the modes differ).
* :func:`fig_work_precision` -- final width ratio against wall time (benchmarks).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from verified.arith.interval import Interval, hull

from ..modes import MODE_I, MODE_II, MODE_III

__all__ = ["fig_reduction_area", "fig_consistency_plane", "fig_enclosures", "fig_work_precision",
           "inconsistent_cells"]

MODE_STYLE = {MODE_I.name: dict(color="black", ls="-", lw=1.2, label=MODE_I.label),
              MODE_II.name: dict(color="0.55", ls="-", lw=2.2, label=MODE_II.label),
              MODE_III.name: dict(color="tab:blue", ls="--", lw=1.2, label=MODE_III.label)}


def _plt():
    import matplotlib  # (matplotlib only when plotting, here and below)
    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt  # (see above)
    return plt


def _save(fig, path):
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    _plt().close(fig)
    return path


# --------------------------------------------------------------------------- Fig. 2
def fig_reduction_area(sol, path, title=None):
    """RA(t) (eq. 16) with t* marked; below it the enclosures [H_H(t)] and [H_V(t)]."""
    plt = _plt()
    c = sol.consistency
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    t = np.asarray(c.ra_t, float)
    ax1.plot(t, np.asarray(c.ra, float), color="black", lw=1.3, label=r"$\mathcal{RA}(t)$")
    # a test at RA's first local maximum (the paper's t*) and one due by test_interval
    # (RA still rising) look alike in the record; the figure tells them apart
    styles = {"RA maximum": (dict(color="tab:red", ls=":", lw=1.0), r"test at a maximum of $\mathcal{RA}$ ($t^*$)"),
              "interval": (dict(color="0.45", ls="--", lw=0.8), "test due by test_interval (no maximum yet)")}
    labelled = set()
    for rec in c.tests:
        style, label = styles[rec.trigger]
        ax1.axvline(rec.t, label=None if label in labelled else label, **style)
        ax2.axvline(rec.t, **style)
        labelled.add(label)
    ax1.set_ylabel(r"$\mathcal{RA}(t)$ [J]")
    ax1.legend(loc="best")
    ax1.set_title(title or r"Reduction area (eq. 16) of the set with the largest one: "
                  "\n" r"$\mathcal{RA}(t) = $ diam$[H_H]$ $-$ diam$([H_H] \cap [H_V])$")
    # the same set's H_H and H_V (RA(t) is computed from them); the hulls over all sets lighter
    per_set = getattr(c, "h_h_set", None) is not None and np.size(c.h_h_set.lo) == t.size
    bands = []
    if per_set:
        bands += [("$[H_H(t)]$ of that set", c.h_h_set, dict(color="tab:blue", alpha=0.35)),
                  ("$[H_V(t)]$ of that set", c.h_v_set, dict(color="tab:orange", alpha=0.55))]
    else:
        bands += [("$[H_H(t)]$", c.h_h, dict(color="tab:blue", alpha=0.25)),
                  ("$[H_V(t)]$", c.h_v, dict(color="tab:orange", alpha=0.45))]
    for name, enc, style in bands:
        lo, hi = np.asarray(enc.lo, float).ravel(), np.asarray(enc.hi, float).ravel()
        ok = np.isfinite(lo) & np.isfinite(hi)
        ax2.fill_between(t[ok], lo[ok], hi[ok], step=None, label=name, **style)
    ax2.set_xlabel("t [s]")
    ax2.set_ylabel("H [J]")
    ax2.legend(loc="best")
    return _save(fig, path)


# --------------------------------------------------------------------------- Fig. 3
def inconsistent_cells(candidates, energy, h_v, pair, grid=160, params=None):
    """Cells of a grid over the hull of ``candidates`` (Interval (k, n)) in the plane of
    the states ``pair = (i, j)`` where the interval enclosure of H (the other states
    over their whole range) lies outside ``h_v = (lo, hi)``: certainly inconsistent.
    Returns (edges_i (grid+1,), edges_j (grid+1,), outside (grid, grid) bool)."""
    n = candidates.shape[-1]
    i, j = pair
    box = hull(candidates, axis=0)
    lo, hi = np.asarray(box.lo, float), np.asarray(box.hi, float)
    ei = np.linspace(lo[i], hi[i], grid + 1)
    ej = np.linspace(lo[j], hi[j], grid + 1)
    ei[0], ei[-1], ej[0], ej[-1] = lo[i], hi[i], lo[j], hi[j]
    cells_lo = np.broadcast_to(lo, (grid, grid, n)).copy()
    cells_hi = np.broadcast_to(hi, (grid, grid, n)).copy()
    cells_lo[..., i] = ei[:-1][:, None]
    cells_hi[..., i] = ei[1:][:, None]
    cells_lo[..., j] = ej[:-1][None, :]
    cells_hi[..., j] = ej[1:][None, :]
    cells = Interval(cells_lo.reshape(-1, n), cells_hi.reshape(-1, n))
    H = energy.eval_interval(cells, params)[..., 0]
    outside = ((np.asarray(H.hi) < h_v[0]) | (np.asarray(H.lo) > h_v[1])).reshape(grid, grid)
    return ei, ej, outside


def fig_consistency_plane(sol, energy, path, test_index=None, pair=None, grid=160, params=None,
                          title=None):
    """The (q, qd) plane at the test time t* (paper Fig. 3).

    ``test_index``: which of ``sol.consistency.tests`` to draw; None (default): the
    one that pruned the most sub-boxes, the earliest of those (the paper's figure shows
    a test that cut something; the first test of a run usually cuts nothing;
    docs/lab/code_notes.md). ``energy``: the Graph x -> [H] (H_H). ``pair``: the two state indices to plot
    (default: the first position and its rate, (0, n/2)). Shaded: cells of a
    ``grid`` x ``grid`` partition of the tested box where the interval enclosure of
    H over the cell (all other states ranging over the tested box) misses [H_V(t*)]:
    no state there is consistent with the energy. Rectangles: the tested sub-boxes,
    kept ones outlined in green, pruned ones grey and crossed.
    """
    plt = _plt()
    tests = sol.consistency.tests
    if test_index is None:
        pruned = [int((~np.asarray(t.kept, bool)).sum()) for t in tests]
        test_index = int(np.argmax(pruned))  # (the first of the largest; 0 when none pruned)
    rec = tests[test_index]
    cand = rec.candidates
    n = cand.shape[-1]
    i, j = pair if pair is not None else (0, n // 2)
    names = list(getattr(sol, "state_names", None) or [f"x{k + 1}" for k in range(n)])
    hv = rec.h_v
    hv_lo, hv_hi = float(np.asarray(hv.lo).ravel()[0]), float(np.asarray(hv.hi).ravel()[0])
    ei, ej, outside = inconsistent_cells(cand, energy, (hv_lo, hv_hi), (i, j), grid, params)
    lo, hi = (ei[0], ej[0]), (ei[-1], ej[-1])

    fig, ax = plt.subplots(figsize=(6.5, 5.5))
    from matplotlib.colors import ListedColormap  # (matplotlib only when plotting)
    ax.pcolormesh(ei, ej, outside.T.astype(float), cmap=ListedColormap(["white", "#f4b6b6"]),
                  vmin=0, vmax=1, shading="flat", rasterized=True)
    from matplotlib.patches import Rectangle  # (matplotlib only when plotting)
    kept = np.asarray(rec.kept, bool)
    clo, chi = np.asarray(cand.lo, float), np.asarray(cand.hi, float)
    for k in range(clo.shape[0]):
        x0, x1, y0, y1 = clo[k, i], chi[k, i], clo[k, j], chi[k, j]
        if kept[k]:
            ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, ec="tab:green", lw=1.2))
        else:
            ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=True, fc="0.85", ec="0.5", lw=0.6,
                                   alpha=0.6))
            ax.plot([x0, x1], [y0, y1], color="0.5", lw=0.5)
            ax.plot([x0, x1], [y1, y0], color="0.5", lw=0.5)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_xlabel(names[i])
    ax.set_ylabel(names[j])
    from matplotlib.patches import Patch  # (matplotlib only when plotting)
    ax.legend(handles=[Patch(fc="#f4b6b6", label="H certainly outside $[H_V(t^*)]$"),
                       Patch(fc="none", ec="tab:green", label=f"kept sub-boxes ({int(kept.sum())})"),
                       Patch(fc="0.85", ec="0.5", label=f"pruned sub-boxes ({int((~kept).sum())})")],
              loc="upper right", fontsize=8, framealpha=0.9)
    ax.set_title(title or f"Energy consistency test at t* = {rec.t:.4g} s, "
                          f"[H_V] = [{hv_lo:.5g}, {hv_hi:.5g}] J")
    return _save(fig, path)


# --------------------------------------------------------------------------- Fig. 5
def _state_units(names, n):
    """Axis units of the states: ``x = (q, qd)`` of a mechanical system, angles in rad
    and rates in rad/s (prismatic joints: m, m/s; not known here)."""
    if n % 2:
        return [""] * n
    return [" [rad]"] * (n // 2) + [" [rad/s]"] * (n // 2)


def _finite_extent(lo, hi, width_cap):
    """(min, max) over the entries whose bounds are finite and width at most ``width_cap``."""
    ok = np.isfinite(lo) & np.isfinite(hi) & ((hi - lo) <= width_cap)
    if not ok.any():
        return None
    return float(lo[ok].min()), float(hi[ok].max())


def _spread_at(samples, sample_times, t):
    """The samples' spread (max - min over the samples whose states are finite), (len(t),
    n), at the times ``t`` that are sample times (NaN at the others)."""
    times = np.asarray(sample_times, float)
    t = np.asarray(t, float)
    x = np.asarray(samples, float)
    out = np.full((t.size, x.shape[-1]), np.nan)
    if not times.size:
        return out
    k = np.searchsorted(times, t).clip(0, times.size - 1)
    for j in np.flatnonzero(np.isclose(times[k], t, rtol=0, atol=1e-12)):
        ok = np.isfinite(x[:, k[j], :]).all(axis=1)
        if ok.any():
            out[j] = x[ok, k[j], :].max(axis=0) - x[ok, k[j], :].min(axis=0)
    return out


#: Fig. 5's excess widths (width / sampled spread - 1) are drawn from this floor up (a
#: log scale has no 0: an enclosure as tight as the samples show)
EXCESS_FLOOR = 1e-6


def fig_enclosures(solutions, path, samples=None, sample_times=None, title=None, tube=True, units=None):
    """Paper Fig. 5, one row per state: the hull of the enclosure over time for each mode
    (solid black (i), thick grey (ii), dashed blue (iii)) with sampled true
    trajectories; its width at the output times on a log scale, one line per mode, with
    the samples' spread (a lower bound of the true width) as the reference; and (with
    samples) the excess width, width / sampled spread - 1, on a log scale (from
    :data:`EXCESS_FLOOR`): there the modes differ even where their bounds and widths
    overlap (a ratio 1.03 against 1.003 is a decade apart).

    ``solutions``: dict mode -> Solution (or a single Solution). ``tube``: draw the
    enclosure over every step (``tube_t``/``tube_hull``) as a staircase, else the
    output times only. ``samples``: (S, k, n) sampled true states at ``sample_times``
    (the widths are compared at the output times that are sample times).
    ``units``: axis unit strings per state (default: rad for the first half, rad/s
    for the second). The left y-axes show the verified enclosures: the last steps before
    a break-down, whose width explodes, are drawn but do not set the axis range (an
    enclosure wider than 4 times the widest output-time width of a completed mode, or
    of the samples' spread, is left out of the range); the log scales show them.
    Widths below 1e-9 of a state's largest (the outward rounding of a point value) are
    not drawn.
    """
    plt = _plt()
    if not isinstance(solutions, dict):
        solutions = {getattr(solutions, "mode", "") or "i": solutions}
    first = next(iter(solutions.values()))
    n = first.hull.shape[-1]
    names = list(getattr(first, "state_names", None) or [f"x{k + 1}" for k in range(n)])
    ncol = 3 if samples is not None else 2
    fig, axes = plt.subplots(n, ncol, figsize=(5.2 * ncol, 2.4 * n + 0.6), squeeze=False, sharex=True)
    units = list(units) if units is not None else _state_units(names, n)
    spread_t = spread = None
    if samples is not None:  # at the output times of every mode
        spread_t = np.unique(np.concatenate([np.asarray(s_.t, float) for s_ in solutions.values()]))
        spread = _spread_at(samples, sample_times, spread_t)
    for k in range(n):
        ax, axw = axes[k][0], axes[k][1]
        axr = axes[k][2] if ncol == 3 else None
        cap, floor = _width_scale(solutions, samples, k)
        ylo, yhi = np.inf, -np.inf
        if samples is not None:
            S = samples.shape[0]
            step = max(1, S // 60)
            for s in range(0, S, step):
                ax.plot(sample_times, samples[s, :, k], color="tab:orange", lw=0.4, alpha=0.35, zorder=1,
                        label="sampled trajectories" if s == 0 else None)
        for mode, sol in solutions.items():
            ext = _draw_mode(ax, axw, axr, mode, sol, k, cap, floor, spread_t, spread, tube)
            if ext is not None:
                ylo, yhi = min(ylo, ext[0]), max(yhi, ext[1])
        if spread is not None:
            sk = spread[:, k]
            ok = np.isfinite(sk) & (sk > floor)
            if ok.any():
                axw.plot(spread_t[ok], sk[ok], color="tab:orange", ls=":", lw=1.6, marker="x", ms=3, zorder=5,
                         label="sampled spread (true width is at least this)")
        if samples is not None and np.isfinite(samples[:, :, k]).any():
            ylo = min(ylo, float(np.nanmin(samples[:, :, k])))
            yhi = max(yhi, float(np.nanmax(samples[:, :, k])))
        _label_state_axes(axes[k], axr, (ylo, yhi), names[k], units[k], first=(k == 0), last=(k == n - 1))
    axes[0][0].set_title("enclosure (hull of all boxes)", fontsize=9)
    axes[0][1].set_title("its width at the output times (log scale)", fontsize=9)
    if ncol == 3:
        axes[0][2].set_title("excess over the sampled spread (log scale)", fontsize=9)
    fig.suptitle(title or "State enclosures over time")
    fig.tight_layout()
    return _save(fig, path)


def _width_scale(solutions, samples, k: int):
    """``(cap, floor)`` of state ``k`` in Fig. 5: enclosures wider than ``cap`` do not set
    the axis range, widths below ``floor`` are not drawn; both from the width scale of
    what was verified well (completed modes' output hulls, the samples)."""
    ref = [np.asarray(s_.hull.width(), float)[:, k] for s_ in solutions.values() if s_.status == "completed"]
    scale = max([float(np.nanmax(w)) for w in ref if w.size] or [0.0])
    if samples is not None:
        sk = samples[:, :, k]
        if np.isfinite(sk).any():
            scale = max(scale, float(np.nanmax(sk) - np.nanmin(sk)))
    if scale <= 0:
        scale = max([float(np.nanmedian(np.asarray(s_.tube_hull.width(), float)[:, k]))
                     for s_ in solutions.values() if len(s_.tube_t) > 1] or [1.0])
    cap = 4.0 * scale
    floor = 1e-9 * scale  # (widths below: the outward rounding of a point value)
    return cap, floor


def _draw_mode(ax, axw, axr, mode, sol, k: int, cap, floor, spread_t, spread, tube: bool):
    """One mode's lines for state ``k`` in Fig. 5: its enclosure on ``ax``, its widths at
    the output times on ``axw``, its excess over the sampled spread on ``axr`` (if any).
    Returns the (lo, hi) extent that may set ``ax``'s range, or None."""
    style = dict(MODE_STYLE.get(mode, dict(color="black", ls="-", lw=1.0, label=str(mode))))
    label = style.pop("label")
    style["zorder"] = 3 + 1.0 / style.get("lw", 1.0)  # (thin lines over thick ones: mode i over ii)
    if sol.status != "completed":
        label += f" (breakdown t={sol.t_reached:.3g})"
    if tube and len(sol.tube_t) > 1:
        tt = np.repeat(np.asarray(sol.tube_t, float), 2)[1:-1]
        lo = np.repeat(np.asarray(sol.tube_hull.lo, float)[:, k], 2)
        hi = np.repeat(np.asarray(sol.tube_hull.hi, float)[:, k], 2)
    else:
        tt = np.asarray(sol.t, float)
        lo, hi = np.asarray(sol.hull.lo, float)[:, k], np.asarray(sol.hull.hi, float)[:, k]
    ax.plot(tt, lo, label=label, **style)
    ax.plot(tt, hi, **style)
    ext = _finite_extent(np.asarray(lo, float), np.asarray(hi, float), cap)
    # the widths at the output times, where the modes are compared
    t_out = np.asarray(sol.t, float)
    w = np.asarray(sol.hull.width(), float)[:, k]
    ok = np.isfinite(w) & (w > floor)
    if ok.any():
        axw.plot(t_out[ok], w[ok], marker="o", ms=2.5, label=label, **style)
    if axr is not None:
        sp = spread[np.searchsorted(spread_t, t_out), k]
        ok = np.isfinite(w) & np.isfinite(sp) & (sp > floor)
        if ok.any():
            excess = np.maximum(w[ok] / sp[ok] - 1.0, EXCESS_FLOOR)
            axr.plot(t_out[ok], excess, marker="o", ms=2.5, label=label, **style)
    return ext


def _label_state_axes(row, axr, extent, name: str, unit: str, first: bool, last: bool):
    """One state's row of axes in Fig. 5 (``axr``, its third, or None): the enclosure's
    range (``extent`` padded by 5 %), labels, log scales where lines were drawn, legends
    on the first row, the time axis on the last."""
    ax, axw = row[0], row[1]
    ylo, yhi = extent
    if np.isfinite(ylo) and np.isfinite(yhi) and yhi > ylo:
        pad = 0.05 * (yhi - ylo)
        ax.set_ylim(ylo - pad, yhi + pad)
    ax.set_ylabel(name + unit)
    axw.set_ylabel(f"width of {name}" + unit)
    for a in (axw, axr):
        if a is None:
            continue
        if a.lines:
            a.set_yscale("log")
        a.grid(True, which="both", alpha=0.25)
    if axr is not None:
        axr.set_ylabel(f"{name}: width / spread - 1")
        if axr.lines:
            axr.set_ylim(bottom=EXCESS_FLOOR * 0.7)
    if last:
        for a in row:
            a.set_xlabel("t [s]")
    if first:
        ax.legend(fontsize=7, loc="best")
        axw.legend(fontsize=7, loc="best")


# --------------------------------------------------------------------------- benchmarks
def fig_work_precision(rows, path, title=None):
    """rows: dicts with "mode", "order", "pieces", "wall_s", "worst_ratio" (None = breakdown)."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 5))
    markers = dict(zip((MODE_I.name, MODE_II.name, MODE_III.name), "os^"))
    orders = sorted({r["order"] for r in rows})
    cmap = plt.get_cmap("viridis")
    for r in rows:
        if r.get("worst_ratio") is None:
            continue
        color = cmap(orders.index(r["order"]) / max(1, len(orders) - 1))
        ax.scatter(r["wall_s"], r["worst_ratio"] - 1.0, marker=markers.get(r["mode"], "o"), color=color,
                   s=20 + 6 * np.log2(max(1, r["pieces"])) ** 2, alpha=0.8, edgecolor="black", lw=0.4)
    from matplotlib.lines import Line2D  # (matplotlib only when plotting)
    handles = [Line2D([], [], marker=markers[m], ls="", color="0.4", label=f"mode {m}") for m in markers
               if any(r["mode"] == m for r in rows)]
    handles += [Line2D([], [], marker="o", ls="", color=cmap(k / max(1, len(orders) - 1)), label=f"order {o}")
                for k, o in enumerate(orders)]
    ax.legend(handles=handles, fontsize=8, title="marker size: pieces", title_fontsize=8)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time [s]")
    ax.set_ylabel("worst width ratio to the sampled true hull, minus 1")
    ax.set_title(title or "Work-precision")
    ax.grid(True, which="both", alpha=0.3)
    return _save(fig, path)

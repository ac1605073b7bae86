"""Figure of a frame's reachable region (issue 14 item 3): the enclosures of
:mod:`mbs.frames` projected on the coordinate planes.

``fig_frame_region(sol.frame("tool0"), "out/frame_region.png", samples=positions)``
draws, per plane (x-y, x-z, y-z; only the planes in which the frame moves), the
tube boxes over every step (light), the boxes at the output times (outlined) and,
if given, sampled positions (dots) that must lie inside.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["fig_frame_region"]

_PLANES = ((0, 1), (0, 2), (1, 2))
_AX = "xyz"


def fig_frame_region(enc, path, *, title: str | None = None, samples=None, max_tube: int = 4000):
    """Write the figure of ``enc`` (:class:`mbs.frames.FrameEnclosure`) to ``path``.
    ``samples``: positions (S, k, 3) or (N, 3) of sampled trajectories (m)."""
    import matplotlib  # (matplotlib only when plotting)
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # (see above; pyplot after use("Agg"))
    from matplotlib.collections import PatchCollection  # (see above)
    from matplotlib.patches import Rectangle  # (see above)

    hull = enc.tube_hull
    lo, hi = np.asarray(hull.lo, float), np.asarray(hull.hi, float)
    span = hi - lo
    planes = [p for p in _PLANES if span[p[0]] > 1e-12 and span[p[1]] > 1e-12] or [(0, 1)]
    fig, axes = plt.subplots(1, len(planes), figsize=(4.6 * len(planes), 4.4), squeeze=False)
    pts = None
    if samples is not None:
        pts = np.asarray(samples, float).reshape(-1, 3)
        pts = pts[np.isfinite(pts).all(axis=1)]
    tube = list(enc.tube_boxes)
    if len(tube) > max_tube:  # thin out very long runs (every box is still inside the hull drawn)
        tube = tube[:: int(np.ceil(len(tube) / max_tube))]
    for ax, (i, j) in zip(axes[0], planes):
        rects = []
        for b in tube:
            for l, h in zip(np.asarray(b.lo, float).reshape(-1, 3), np.asarray(b.hi, float).reshape(-1, 3)):
                rects.append(Rectangle((l[i], l[j]), h[i] - l[i], h[j] - l[j]))
        if rects:
            ax.add_collection(PatchCollection(rects, facecolor="tab:blue", alpha=0.15, edgecolor="none",
                                              label="tube (every step)"))
        outs = []
        for b in enc.boxes:
            for l, h in zip(np.asarray(b.lo, float).reshape(-1, 3), np.asarray(b.hi, float).reshape(-1, 3)):
                outs.append(Rectangle((l[i], l[j]), h[i] - l[i], h[j] - l[j]))
        if outs:
            ax.add_collection(PatchCollection(outs, facecolor="none", edgecolor="tab:red", linewidth=0.8))
        if pts is not None and len(pts):
            ax.plot(pts[:, i], pts[:, j], ".", ms=1.5, color="k", alpha=0.5)
        pad = 0.05 * max(span[i], span[j], 1e-9)
        ax.set_xlim(lo[i] - pad, hi[i] + pad)
        ax.set_ylim(lo[j] - pad, hi[j] + pad)
        ax.set_xlabel(f"{_AX[i]} [m]")
        ax.set_ylabel(f"{_AX[j]} [m]")
        ax.grid(alpha=0.3)
    w = np.asarray(enc.position.width()[-1], float) if len(enc.t) else np.zeros(3)
    ws = ", ".join("0" if v < np.finfo(float).tiny else f"{v:.3g}" for v in w)
    fig.suptitle((title or f"frame {enc.name!r}") + f"\nreachable region to t = {enc.t[-1] if len(enc.t) else 0:g} s,"
                 f" widths at the end {ws} m\nblue: tube (every step), red: output times"
                 + (", dots: sampled trajectories" if pts is not None else ""), fontsize=9)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path

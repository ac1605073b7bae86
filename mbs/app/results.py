"""result.json: the enclosures of a simulation, written so that reading back never
narrows them.

Layout (keys exactly as issue 7 asks)::

    {
      "scene": "models/scenes/double_pendulum_paper.toml",
      "mode": "ii",
      "state_names": ["x1", "x2", "x3", "x4"],
      "t_end": 1.0, "t_reached": 1.0,
      "status": "completed",          # or "breakdown"
      "reason": "",                   # why it broke down ("" when completed)
      "method": "auto: composition on 1 piece(s) completed to t = 1",   # what ran (verified.methods)
      "method_log": [{"method": "composition", "pieces": 1, "t_span": [0, 1], "status": ..., ...}],
      "outputs": [                    # one entry per output time (k * output_dt)
        {"t": 0.05,
         "boxes": [[[lo, hi], [lo, hi], ...], ...],   # boxes whose union encloses x(t)
         "hull":  [[lo, hi], ...]},                  # their hull, per state
        ...
      ],
      "stats": {"wall_s": ..., "steps": ..., "max_boxes": ..., "pruned_boxes": ..., ...},
      "tightness": {"t": 1.0, "method": "...", "samples": 64,   # the enclosure against the
                    "states": [{"name": "x1", "width": ..., "spread": ..., "ratio": ...}, ...],
                    "worst": {"name": "x3", "ratio": 1.17}},    # sampled trajectories at the
                                      # last output time (mbs simulate; see tightness())
      "parameters": {"payload.mass": [lo, hi], ...},  # uncertain parameters (only if any)
      "frames": {"tool0": {"t": [...], "position": [[[lo, hi] x 3] per output time],
                           "rotation": [[[lo, hi] x 9] per output time], "tube_t": [...],
                           "tube": [[[lo, hi] x 3] per step], "method": "both"}},
                                      # frame enclosures (chains; mbs.frames), m
      "control": ["pd", ...],         # controllers of a closed loop (only if any)
      "pieces": {"count": 64, "summary": "3 of 64 pieces failed (...); 61 pieces verified to t = 2",
                 "failed": [{"index": 5, "t_reached": 0.31, "reason": "...", "box": [[lo, hi], ...]}, ...]},
                                      # only when some initial pieces broke down: then
                                      # "outputs" stop at the first failure (every piece)
      "surviving": {"pieces": [0, 1, ...], "t_reached": 2.0, "status": "completed", "reason": "",
                    "outputs": [...]} # the pieces that went on, to where they went (only then)
    }

Bounds are JSON numbers written with Python's ``repr`` (17 significant digits at
most, the shortest string that reads back as the same double), so
``float(text) == bound`` exactly, for subnormals and huge values alike, and ``-0.0``
keeps its sign. Infinite bounds are not JSON numbers: they are written as the strings
``"-inf"`` / ``"inf"`` (read back as floats); a NaN bound is refused
(:class:`ResultError`): an enclosure containing NaN encloses nothing.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from verified.arith.interval import Interval

__all__ = ["ResultError", "solution_to_dict", "write_result", "read_result", "bound_to_json",
           "bound_from_json", "result_boxes", "frame_to_json", "tightness", "format_tightness"]


class ResultError(ValueError):
    """A result that cannot be written soundly (a NaN bound) or read back."""


def bound_to_json(x):
    """A float bound as a JSON value that reads back as exactly the same double."""
    x = float(x)
    if math.isnan(x):
        raise ResultError("a bound is NaN: refusing to write an enclosure that encloses nothing")
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return x  # json writes float.__repr__: round-trips exactly


def bound_from_json(v) -> float:
    if isinstance(v, str):
        if v in ("inf", "-inf"):
            return float(v)
        raise ResultError(f"unexpected bound {v!r} (numbers, 'inf' or '-inf')")
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ResultError(f"unexpected bound {v!r}")
    return float(v)


def _pairs(lo, hi):
    """[[lo, hi], ...] for 1-d bound arrays."""
    return [[bound_to_json(a), bound_to_json(b)] for a, b in zip(np.ravel(lo), np.ravel(hi))]


def frame_to_json(frame) -> dict:
    """result.json's ``frames.<name>`` entry of a :class:`mbs.frames.FrameEnclosure`:
    per output time the position hull ``[[lo, hi]] x 3`` (m) and the rotation matrix
    entries (row-major, 9 pairs), per step the tube's position hull; bounds as above
    (exact doubles)."""
    return {"method": frame.method, "t": [float(x) for x in frame.t],
            "position": [_pairs(p.lo, p.hi) for p in frame.position],
            "rotation": [_pairs(r.lo, r.hi) for r in frame.rotation],
            "tube_t": [float(x) for x in frame.tube_t],
            "tube": [_pairs(p.lo, p.hi) for p in frame.tube]}


def _jsonable(v):
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, np.ndarray):
        return [_jsonable(x) for x in v.tolist()]
    if isinstance(v, (np.bool_, bool)):
        return bool(v)
    if isinstance(v, (np.integer, int)):
        return int(v)
    if isinstance(v, (np.floating, float)):
        f = float(v)
        return f if math.isfinite(f) else repr(f)  # statistics, not bounds: just readable
    if v is None or isinstance(v, str):
        return v
    return str(v)


def tightness(sol, spread=None, state_names=None, samples: int = 0) -> dict | None:
    """How tight the enclosure is at the last output time ``t = sol.t[-1]`` (``t_end``
    for a completed run): per state the enclosure's width (hull of all boxes), the
    spread (max - min) of the sampled true states ``spread`` (n,) at ``t`` and their
    ratio width / spread (None where the spread is 0: a state without uncertainty, or
    no samples), the worst ratio, and ``sol.method`` (what ran; for ``"auto"`` every
    attempt). The true reachable width lies between the spread and the width, so the
    ratio bounds how much wider than necessary the enclosure is. None for a run
    without outputs."""
    if not len(sol.t):
        return None
    widths = np.asarray(sol.hull.width()[-1], float).ravel()
    names = list(state_names if state_names is not None else getattr(sol, "state_names", None) or
                 [f"x{i + 1}" for i in range(widths.size)])
    spread = None if spread is None else np.asarray(spread, float).ravel()
    rows, worst = [], None
    for k, w in enumerate(widths):
        s = None if spread is None or k >= spread.size or not np.isfinite(spread[k]) else float(spread[k])
        ratio = float(w) / s if s is not None and s > 0 else None
        rows.append({"name": names[k] if k < len(names) else f"x{k + 1}", "width": float(w), "spread": s,
                     "ratio": ratio})
        if ratio is not None and (worst is None or ratio > worst["ratio"]):
            worst = {"name": rows[-1]["name"], "ratio": ratio}
    return {"t": float(sol.t[-1]), "method": getattr(sol, "method", "") or "", "samples": int(samples),
            "states": rows, "worst": worst}


def _num(v) -> str:
    if v is None:
        return "-"
    v = float(v)
    if v < np.finfo(float).tiny and v >= 0:
        return "0"  # (the width of a point: one ulp of outward rounding at 0)
    return f"{v:.4g}"


def _ratio(r) -> str:
    """A ratio >= 1 to three decimals (1.000, 1.115; 1.2e+03 when large)."""
    if r is None:
        return "-"
    return f"{r:.3f}" if abs(r) < 100 else f"{r:.3g}"


def format_tightness(summary: dict) -> str:
    """The table of :func:`tightness` and a line with the worst ratio, e.g.::

        at t = 1 s (method: lohner), against 64 sampled trajectories:
          state   enclosure width   sampled spread   ratio
          q1      0.2874            0.2651           1.084
          qd1     0.8277            0.7012           1.180
        worst ratio: 1.180 (qd1): the enclosure is at most 1.180 times as wide as the true set
        (whose width is at least the sampled spread)
    """
    head = ["state", "enclosure width", "sampled spread", "ratio"]
    rows = [[r["name"], _num(r["width"]), _num(r["spread"]), _ratio(r["ratio"])] for r in summary["states"]]
    size = [max(len(x[i]) for x in rows + [head]) for i in range(len(head))]
    n = summary.get("samples") or 0
    lines = [f"at t = {summary['t']:g} s (method: {summary['method'] or '?'}), "
             + (f"against {n} sampled trajector{'y' if n == 1 else 'ies'}:" if n else "no sampled trajectories:")]
    lines += ["  " + "   ".join(c.ljust(w) for c, w in zip(r, size)).rstrip() for r in [head] + rows]
    worst = summary.get("worst")
    if worst is not None:
        lines.append(f"worst ratio: {_ratio(worst['ratio'])} ({worst['name']}): the enclosure is at most "
                     f"{_ratio(worst['ratio'])} times as wide as the true set (whose width is at least the "
                     f"sampled spread)")
    elif n:
        lines.append("worst ratio: - (the samples do not spread: every state's sampled spread is 0)")
    return "\n".join(lines)


def solution_to_dict(sol, scene: str = "", mode: str | None = None, state_names=None,
                     t_end: float | None = None, extra_stats: dict | None = None, frames=(),
                     tightness: dict | None = None) -> dict:
    """The result.json dict of a :class:`verified.solver.Solution` (see module doc);
    ``frames``: frame names whose enclosures (``sol.frame(name)``, :mod:`mbs.frames`)
    go under ``"frames"``; ``tightness``: :func:`tightness`'s dict, under
    ``"tightness"``."""
    names = list(state_names if state_names is not None else getattr(sol, "state_names", ()) or
                 [f"x{i + 1}" for i in range(sol.hull.shape[-1])])
    outputs = _outputs(sol, len(names))
    stats = dict(getattr(sol, "stats", {}) or {})
    stats.setdefault("max_boxes", max((len(np.asarray(b.lo).reshape(-1, len(names))) for b in sol.boxes),
                                      default=0))
    stats.setdefault("pruned_boxes", 0)
    if extra_stats:
        stats.update(extra_stats)
    out = {
        "scene": str(scene),
        "mode": mode if mode is not None else getattr(sol, "mode", ""),
        "state_names": names,
        "t_end": float(t_end if t_end is not None else (sol.t[-1] if len(sol.t) else 0.0)),
        "t_reached": float(sol.t_reached),
        "status": sol.status,
        "reason": sol.reason or "",
        "method": getattr(sol, "method", "") or "",
        "method_log": _jsonable(getattr(sol, "method_log", None) or []),
        "outputs": outputs,
        "stats": _jsonable(stats),
    }
    if tightness is not None:
        out["tightness"] = _jsonable(tightness)
    params = getattr(sol, "params", None)
    if params:
        out["parameters"] = {str(k): [bound_to_json(float(lo)), bound_to_json(float(hi))]
                             for k, (lo, hi) in params.items()}
    fr = getattr(sol, "frame", None)
    if frames and fr is not None:
        out["frames"] = {str(k): frame_to_json(fr(k)) for k in frames}
    control = getattr(sol, "control", None)
    if control is not None:
        out["control"] = [c.name for c in control.controllers]
    results = getattr(sol, "piece_results", None) or []
    if any(p.failed for p in results):
        # some initial pieces broke down: which, when and why; "outputs" above stop at
        # the first failure (they enclose every piece), "surviving" goes on with the rest
        out["pieces"] = {"count": len(results), "summary": sol.pieces_summary(),
                         "failed": [{"index": int(p.index), "t_reached": float(p.t_reached), "reason": p.reason,
                                     "box": _pairs(np.ravel(p.box.lo)[:len(names)], np.ravel(p.box.hi)[:len(names)])}
                                    for p in results if p.failed]}
    surv = getattr(sol, "surviving", None)
    if surv is not None:
        out["surviving"] = {"pieces": [int(p.index) for p in results if not p.failed],
                            "t_reached": float(surv.t_reached), "status": surv.status, "reason": surv.reason or "",
                            "outputs": _outputs(surv, len(names))}
    return out


def _outputs(sol, n: int) -> list:
    """result.json's ``outputs`` of a Solution: per output time its boxes and their hull."""
    outputs = []
    for t, boxes in zip(sol.t, sol.boxes):
        lo, hi = np.asarray(boxes.lo, float), np.asarray(boxes.hi, float)
        lo2, hi2 = lo.reshape(-1, n), hi.reshape(-1, n)
        outputs.append({
            "t": float(t),
            "boxes": [_pairs(a, b) for a, b in zip(lo2, hi2)],
            "hull": _pairs(lo2.min(axis=0), hi2.max(axis=0)),
        })
    return outputs


def write_result(path, sol=None, *, data: dict | None = None, **kwargs) -> Path:
    """Write result.json for a solution (or an already built dict ``data``)."""
    if data is None:
        data = solution_to_dict(sol, **kwargs)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps(data, indent=1, allow_nan=False)
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(text + "\n")
    tmp.replace(path)
    return path


def read_result(path) -> dict:
    """Read result.json; bounds come back as floats (exactly the written doubles)."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise ResultError(f"{path}: cannot read result: {e}") from None
    for out in data.get("outputs", []) + data.get("surviving", {}).get("outputs", []):
        out["boxes"] = [[[bound_from_json(a), bound_from_json(b)] for a, b in box] for box in out["boxes"]]
        out["hull"] = [[bound_from_json(a), bound_from_json(b)] for a, b in out["hull"]]
    for p in data.get("pieces", {}).get("failed", []):
        p["box"] = [[bound_from_json(a), bound_from_json(b)] for a, b in p["box"]]
    return data


def result_boxes(data: dict, k: int):
    """Output ``k``'s boxes as an Interval (B, n)."""
    arr = np.array(data["outputs"][k]["boxes"], dtype=float)  # (B, n, 2)
    return Interval(arr[..., 0], arr[..., 1], allow_unbounded=True)

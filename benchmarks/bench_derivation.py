"""Derivation timings: symbolic model + conversion to expression graphs, cold and cached.

For each model the timed work is: build the chain (parse URDF / DH), derive the symbolic
model (M by body Jacobians, Coriolis Kane-style, P, gravity, H) and convert it to the
expression graphs the verified solver consumes (``SymbolicModel.rhs_graph()``:
x -> (qd, qdd) with an LDL^T solve, and ``energy_graph()``: x -> (H, dH/dt)).

- cold: empty disk cache, fresh Python process (imports excluded from the timing);
- cached: a second fresh process with the cache filled by the first (graphs are loaded
  from ``$MBS_CACHE_DIR``, keyed by the chain's content).

Usage::

    python benchmarks/bench_derivation.py                 # 2-link, 6-link planar, UR5, panda
    python benchmarks/bench_derivation.py --models ur5 --inprocess
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

MODELS = {
    "planar2": "models.planar:planar_chain(2)",
    "planar6": "models.planar:planar_chain(6)",
    "ur5": "models.robots:ur5()",
    "panda": "models.robots:panda_arm()",
}


def make_chain(name):
    mod, call = MODELS[name].split(":")
    import importlib
    m = importlib.import_module(mod)
    fn, args = call.split("(", 1)
    args = args.rstrip(")")
    return getattr(m, fn)(*([int(args)] if args else []))


def measure(name: str) -> dict:
    """Time chain build + derivation + graph conversion in this process (the cache
    directory is whatever :mod:`mbs.cache` currently uses)."""
    import mbs  # noqa: F401  (imports outside the timing)
    import sympy  # noqa: F401
    import verified.graph  # noqa: F401
    import verified.graph.sympy_convert  # noqa: F401
    import yourdfpy  # noqa: F401  (imports trimesh/scipy: ~0.9 s, not part of the derivation)
    t0 = time.perf_counter()
    chain = make_chain(name)
    sym = chain.symbolic()
    rhs = sym.rhs_graph()
    energy = sym.energy_graph()
    t1 = time.perf_counter()
    return {"model": name, "dof": chain.n, "seconds": t1 - t0, "rhs_nodes": rhs.n_nodes,
            "energy_nodes": energy.n_nodes}


def _measure_subprocess(name: str, cache_dir: str) -> dict:
    env = dict(os.environ, MBS_CACHE_DIR=cache_dir)
    # this file's measure() in a fresh interpreter (runpy: not run as __main__)
    code = ("import json, runpy; "
            "measure = runpy.run_path(%r)['measure']; "
            "print(json.dumps(measure(%r)))" % (str(Path(__file__).resolve()), name))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         cwd=str(ROOT))
    if out.returncode != 0:
        raise RuntimeError(f"benchmark of {name} failed:\n{out.stderr}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def run(names, inprocess=False, cache_root=None) -> list:
    """Rows {model, dof, cold, cached, rhs_nodes, energy_nodes} (seconds)."""
    rows = []
    with tempfile.TemporaryDirectory(prefix="mbs-bench-", dir=cache_root) as tmp:
        for name in names:
            d = os.path.join(tmp, name)
            if inprocess:
                from mbs import cache
                with cache.enabled(True, d):
                    cold = measure(name)
                    cached = measure(name)
            else:
                cold = _measure_subprocess(name, d)
                cached = _measure_subprocess(name, d)
            rows.append({"model": name, "dof": cold["dof"], "cold": cold["seconds"],
                         "cached": cached["seconds"], "rhs_nodes": cold["rhs_nodes"],
                         "energy_nodes": cold["energy_nodes"]})
    return rows


def format_table(rows) -> str:
    lines = ["| model | dof | cold [s] | cached [s] | cold/cached | rhs graph nodes | energy graph nodes |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['model']} | {r['dof']} | {r['cold']:.2f} | {r['cached']:.3f} | "
                     f"{r['cold'] / r['cached']:.0f}x | {r['rhs_nodes']} | {r['energy_nodes']} |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", nargs="+", default=list(MODELS), choices=list(MODELS))
    ap.add_argument("--inprocess", action="store_true",
                    help="measure in this process (cold is then not a fresh interpreter)")
    ap.add_argument("--json", action="store_true", help="print JSON rows instead of a table")
    args = ap.parse_args(argv)
    rows = run(args.models, inprocess=args.inprocess)
    print(json.dumps(rows, indent=1) if args.json else format_table(rows))
    return rows


if __name__ == "__main__":
    main()

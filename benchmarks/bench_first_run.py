"""A robot's first run after installing the package, against its second (issue 45: the first
run of a robot never run before <= 2x the warm run).

    python benchmarks/bench_first_run.py                      # ur5_quintic, then panda_pd_hold
    python benchmarks/bench_first_run.py --scenes ur5_quintic --wheel DIST/x.whl   # a wheel built before

Builds a wheel of this checkout as ``pip install .`` does (``pip wheel . --no-deps``: the
build compiles the numba kernels into it, ``setup.py``), installs it into a fresh virtual
environment that reuses this interpreter's packages for the dependencies
(``--system-site-packages``; the wheel's own ``verified`` and ``mbs`` come first), and runs
``mbs simulate SCENE --t-end 0.01 --samples 0 --no-figures`` from a directory outside the
checkout: each scene twice, the first time with an empty model cache (``MBS_CACHE_DIR``),
so that it is a robot this installation never ran. Prints wall and CPU seconds of both runs,
their ratio, and whether the first run wrote any numba cache file (something compiled).
The same command on an empty numba cache (``NUMBA_CACHE_DIR``: a machine on which nothing
was compiled, as an editable install or ``MBS_NO_WARMUP=1`` leaves it) is ``python -m mbs bench``'s
start-up table.
"""
from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _cache_files(site: Path) -> int:
    return sum(1 for p in (site / "verified").rglob("__pycache__/*.nb[ic]"))


def _timed(cmd, env, cwd) -> tuple[float, float, int]:
    """(wall s, CPU s of the child, return code)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    rc = subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, text=True).returncode
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), rc


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default="ur5_quintic,panda_pd_hold", help="scene names (models/scenes/NAME.toml)")
    ap.add_argument("--wheel", help="an already built wheel (default: build one of this checkout)")
    a = ap.parse_args(argv)
    tmp = Path(tempfile.mkdtemp(prefix="mbs-first-run-"))
    wheel = Path(a.wheel) if a.wheel else None
    if wheel is None:
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "pip", "wheel", str(REPO), "--no-deps", "-q", "-w", str(tmp / "dist")],
                       check=True)
        (wheel,) = (tmp / "dist").glob("*.whl")
        print(f"built {wheel.name} in {time.perf_counter() - t0:.0f} s (the kernels compiled into it)")
    venv = tmp / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", str(venv)], check=True)
    py = venv / "bin" / "python"
    subprocess.run([str(py), "-m", "pip", "install", "-q", "--no-deps", "--force-reinstall", str(wheel)], check=True)
    site = Path(subprocess.run([str(py), "-c", "import verified, pathlib; print(pathlib.Path(verified.__file__).parents[1])"],
                               check=True, capture_output=True, text=True, cwd=tmp).stdout.strip())
    print(f"installed into {site}: {_cache_files(site)} numba cache files")
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "PYTHONPATH")}
    env["MBS_CACHE_DIR"] = str(tmp / "mbs-cache")
    print("| scene | first run wall / CPU s | second run wall / CPU s | first / second (wall) | compiled in the first |")
    print("|---|---|---|---|---|")
    for name in a.scenes.split(","):
        scene = REPO / "models" / "scenes" / f"{name}.toml"
        cmd = [str(py), "-m", "mbs", "simulate", str(scene), "--out", str(tmp / "out"), "--t-end", "0.01",
               "--output-dt", "0.01", "--samples", "0", "--no-figures"]
        files = _cache_files(site)
        first = _timed(cmd, env, tmp)
        compiled = _cache_files(site) - files
        second = _timed(cmd, env, tmp)
        ok = "" if first[2] == second[2] == 0 else f" (exit {first[2]}, {second[2]})"
        print(f"| {name}{ok} | {first[0]:.2f} / {first[1]:.2f} | {second[0]:.2f} / {second[1]:.2f} | "
              f"{first[0] / second[0]:.2f} | {compiled} cache files |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

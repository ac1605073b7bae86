"""Every benchmark module imports, in one interpreter started from another directory:
the cheap default-run companion of the slow test_benchmarks_start.py (one interpreter
per ``python benchmarks/X.py --help``, 2-5 s each). Each module is imported as the script
would start (the benchmarks directory first on ``sys.path``, the path reset and the
benchmark and tests/ modules dropped before each one), without running its main; and
after each, ``import mbs`` / ``verified`` / ``models`` must not find a namespace package
on the path it left (tests/mbs first and the root absent shadowed mbs in six benchmarks:
mbs, verified and models stay loaded between modules, so that is checked instead)."""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
BENCHMARKS = sorted((ROOT / "benchmarks").glob("bench_*.py"))

_IMPORT_ALL = r"""
import importlib, importlib.machinery, os, sys
from pathlib import Path
bench = Path(os.path.realpath(sys.argv[1]))
local = (str(bench) + "/", str(bench.parent / "tests") + "/")
sys.path.insert(0, str(bench))  # as `python benchmarks/X.py` starts: the script's directory first
base = list(sys.path)
failed = []
for name in sys.argv[2:]:
    sys.path[:] = base
    for m, mod in list(sys.modules.items()):  # (paths such as benchmarks/../tests/oracles too)
        if os.path.realpath(getattr(mod, "__file__", None) or "/").startswith(local):
            del sys.modules[m]
    try:
        importlib.import_module(name)
        for pkg in ("mbs", "verified", "models"):
            spec = importlib.machinery.PathFinder.find_spec(pkg, sys.path)
            if spec is not None and spec.origin is None:
                raise ImportError(f"'import {pkg}' finds a namespace package at "
                                  f"{list(spec.submodule_search_locations)} on the sys.path it sets up")
    except BaseException as e:  # SystemExit at import too
        failed.append(f"{name}: {type(e).__name__}: {e}")
print("\n".join(failed))
sys.exit(1 if failed else 0)
"""


def test_every_benchmark_module_imports(tmp_path):
    assert len(BENCHMARKS) >= 10
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}  # as a user starts them
    run = subprocess.run([sys.executable, "-c", _IMPORT_ALL, str(ROOT / "benchmarks"), *(p.stem for p in BENCHMARKS)],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, f"benchmark modules that do not import:\n{run.stdout}{run.stderr[-2000:]}"

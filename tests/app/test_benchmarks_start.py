"""Every benchmark script starts as the README runs it (``python benchmarks/X.py``), from
another directory: its imports resolve (``--help`` parses the arguments after every
module-level import). Why: with ``tests/`` first on ``sys.path`` and the repository root
absent, ``import mbs`` found ``tests/mbs`` as a namespace package and six benchmarks
failed at import while the test suite, which puts the root on the path, passed. The
default run has the cheap companion, test_benchmarks_import.py (every module imported in
one interpreter, a few seconds)."""

import subprocess
import sys
from pathlib import Path

import pytest

BENCHMARKS = sorted((Path(__file__).resolve().parents[2] / "benchmarks").glob("bench_*.py"))

pytestmark = pytest.mark.slow  # (one interpreter with numba and pinocchio per script, 2-5 s each)


@pytest.mark.parametrize("script", BENCHMARKS, ids=[p.stem for p in BENCHMARKS])
def test_benchmark_script_starts_from_another_directory(script, tmp_path):
    run = subprocess.run([sys.executable, str(script), "--help"], cwd=tmp_path, capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 0, f"{script.name} --help failed:\n{run.stderr[-2000:]}"
    assert "usage" in run.stdout.lower()

"""Every script in examples/ runs in its short version (MBS_EXAMPLE_SHORT=1), in a fresh
interpreter and an empty working directory, and exits with 0.

The three together take about 15 s of wall time on a shared 2-core machine (most of it
starting interpreters and loading compiled kernels), above the default run's budget for
them, so they are marked slow (``python -m pytest -q -m slow``).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = sorted((ROOT / "examples").glob("*.py"))


def test_examples_exist_and_document_their_short_version():
    assert len(EXAMPLES) >= 3
    for path in EXAMPLES:
        text = path.read_text()
        assert text.startswith('"""') and "Run: python examples/" in text, path.name
        assert "MBS_EXAMPLE_SHORT" in text, f"{path.name}: say what its short version is"


@pytest.mark.slow
@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.stem)
def test_example_runs_short(path, tmp_path):
    env = dict(os.environ, MBS_EXAMPLE_SHORT="1", MPLBACKEND="Agg")
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    proc = subprocess.run([sys.executable, str(path)], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, f"{path.name} exited with {proc.returncode}:\n{proc.stdout[-2000:]}\n{proc.stderr[-4000:]}"
    assert proc.stdout.strip(), f"{path.name} printed nothing"

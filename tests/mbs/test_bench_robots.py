"""benchmarks/bench_robots.py --quick on its smallest case (3-link arm, eps 1e-4 and 1e-6):
every sampled Pinocchio trajectory inside the enclosure (the SOUND column), and the
check fails when the enclosure is too narrow."""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

import bench_robots  # noqa: E402
from oracles.mutants import narrows_output_boxes  # noqa: E402
import mbs.simulate  # noqa: E402
from verified.arith.interval import Interval  # noqa: E402


def _quick(only):
    lines = []
    bench = bench_robots.main(["--quick", "--only", only, "--quiet"], out=lines.append)
    return bench, "\n".join(lines)


# slow: 3.6 s of the default run, whose CI budget (3 min) this session's tests used up
# (CI measured 175.9 s before them); the slow CI step runs it
@pytest.mark.slow
def test_quick_arm3_is_sound():
    bench, text = _quick("1")
    runs = bench.runs()
    assert len(runs) == 4  # eps 1e-4, 1e-6 x interval, affine
    assert all(r.checks > 1000 for r in runs)  # trajectories x (output times + tube steps)
    assert all(r.sound for r in runs), [(r.arithmetic, r.setting, r.misses) for r in runs]
    assert "| SOUND |" in text and "UNSOUND" not in text
    # affine reaches T from the 1e-6 box, close to the sampled hull
    r = [r for r in runs if r.arithmetic == "affine" and r.case == "arm3"][-1]
    assert r.completed and 1.0 <= r.ratio < 1.5


def test_quick_qdd_enclosures_are_sound():
    bench, text = _quick("7")
    assert bench.results["qdd"] and all(bench.results["qdd"])
    assert "UNSOUND" not in text


# (4-5 s: behind the slow marker to keep the default run under 3 minutes)
@pytest.mark.slow
def test_a_too_narrow_enclosure_is_reported_unsound(monkeypatch):
    # 10% narrower about the midpoints: the sampled corners leave the enclosure
    monkeypatch.setattr(mbs.simulate, "solve", narrows_output_boxes(mbs.simulate.solve))
    bench, text = _quick("1")
    assert all(not r.sound for r in bench.runs())
    assert "UNSOUND" in text

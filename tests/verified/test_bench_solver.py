"""A small, fast version of benchmarks/bench_solver.py."""

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

import bench_solver  # noqa: E402
from verified.graph import trace  # noqa: E402
from verified.solver import VerifiedODE  # noqa: E402
from models import double_pendulum as dp  # noqa: E402


def test_small_benchmark_runs_and_encloses_the_sampled_hull():
    ode = VerifiedODE(trace(dp.rhs, 4))
    true_w = bench_solver.true_hull_widths(0.3, samples=101)
    rows = bench_solver.pieces_table(ode, 0.3, [1, 8], true_w)
    for n, w, ratio, wall, steps, note in rows:
        assert note == "" and w is not None
        assert (ratio >= 1.0 - 1e-6).all() and (ratio < 2.5).all()  # sound, and not absurd
    t_b, reason, _ = bench_solver.breakdown_time(ode, horizon=1.0)
    assert 0.3 < t_b < 1.0 and reason


def test_true_hull_matches_design_numbers_at_t1():
    w = bench_solver.true_hull_widths(1.0, samples=401)
    assert np.allclose(w, [0.012830, 0.122919, 0.629345, 1.019084], rtol=2e-3)

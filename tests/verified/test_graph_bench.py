"""Smoke test of benchmarks/bench_graph.py: runs with tiny sizes and returns sane numbers."""
import importlib.util
import math
import os

import numpy as np

_PATH = os.path.join(os.path.dirname(__file__), "..", "..", "benchmarks", "bench_graph.py")


def _load_bench():
    spec = importlib.util.spec_from_file_location("bench_graph", _PATH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_bench_graph_runs_and_reports_every_evaluator():
    bench = _load_bench()
    rows = bench.run(batch=300, repeats=1, small=3)
    assert {r["name"] for r in rows} == set(bench.make_graphs())
    for row in rows:
        assert row["n_ops"] >= 40
        for kind, t in row["times"].items():
            assert math.isfinite(t) and t > 0, (row["name"], kind, t)
        # the batch scaling (time for 100x more boxes; a Python loop over boxes would cost
        # ~100x) is a timing: python benchmarks/bench_graph.py prints it, tests do not assert it
        assert set(row["scaling"]) == set(row["times"]), row
        assert all(math.isfinite(r) and r > 0 for r in row["scaling"].values()), row
    assert next(r for r in rows if r["name"] == "random_100")["n_ops"] >= 100
    text = bench.format_table(rows)
    assert "us/op/call" in text and "interval/float" in text


def test_bench_graphs_are_correct():
    """The benchmark's double pendulum graph agrees with the test suite's reference model."""
    bench = _load_bench()
    from oracles.graph_models import double_pendulum_rhs

    graphs = bench.make_graphs()
    X = np.random.default_rng(0).uniform(-2, 2, size=(20, 4))
    want = np.array(double_pendulum_rhs(X.T)).T
    np.testing.assert_allclose(graphs["double_pendulum_rhs+H"].eval_float(X)[:, :4], want, rtol=1e-12, atol=1e-12)
    P = np.array([1.0, 1.0, 1.0, 1.0, 9.81])
    np.testing.assert_allclose(
        graphs["double_pendulum_rhs+H_params"].eval_float(X, P), graphs["double_pendulum_rhs+H"].eval_float(X), rtol=1e-12
    )


def test_bench_energy_is_conserved_by_the_rhs():
    """dH/dt = grad H . x_dot = 0 for the paper's double pendulum (eq. 22 with eq. 24)."""
    g = _load_bench().make_graphs()["double_pendulum_rhs+H"]
    X = np.random.default_rng(1).uniform(-2, 2, size=(50, 4))
    rhs = g.eval_float(X)[:, :4]
    grad_H = g.jacobian_float(X)[:, 4, :]
    np.testing.assert_allclose(np.einsum("bi,bi->b", grad_H, rhs), 0.0, atol=1e-11)

"""The consistency benchmark's quick version runs and reports every table it promises."""
import os
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "benchmarks"))


# (4-6 s: behind the slow marker to keep the default run under 3 minutes)
@pytest.mark.slow
def test_quick_consistency_benchmark(capsys):
    import bench_consistency

    bench_consistency.main(["--quick"])
    out = capsys.readouterr().out
    assert "## 1. Double pendulum" in out and "## 5. Pendulum" in out
    assert "largest width deviation (ii) vs (iii)" in out
    assert "first test t* =" in out


@pytest.mark.slow
def test_quick_work_precision_has_every_variant():
    """Section 7's quick case: every variant (no test, contraction, contraction + prune,
    energy shell) completes, and no enclosure is narrower than the sampled hull."""
    import bench_consistency

    rows = bench_consistency.work_precision(quick=True, out_json=None, plot=None)
    assert {r["variant"] for r in rows} == {"no test", "contraction", "contraction + prune", "energy shell"}
    assert all(r["status"] == "completed" for r in rows)
    assert all(r["ratio"] >= 0.999 for r in rows)
    assert all(r["shell_resets"] is not None for r in rows if r["variant"] == "energy shell")

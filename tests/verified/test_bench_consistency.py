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

"""python -m mbs bench --quick: every part of the benchmark and every stress case, small."""
from pathlib import Path

import pytest

from mbs.app import bench


# (8-25 s: behind the slow marker to keep the default run under 3 minutes)
@pytest.mark.slow
def test_bench_quick(tmp_path):
    lines = []
    code = bench.run(quick=True, out=tmp_path, log=lines.append)
    text = "\n".join(lines)
    assert code == 0, text
    assert "CRASH" not in text and "ESCAPED" not in text
    md = (tmp_path / "benchmarks.md").read_text()
    assert "python -m mbs bench --quick" in md
    for part in ("Work-precision", "Stress tests", "Start-up", "UR5", "m2/m1", "high energy", "long horizon",
                 "pendulum box", "l = 0.001 m"):
        assert part in md, part
    assert (tmp_path / "bench_work_precision.png").stat().st_size > 5000


def test_stress_case_never_raises():
    # a case whose setup is invalid is reported as a crash row, not an exception
    from verified.arith.interval import Interval
    row = bench.run_case("bad", "pendulum_paper", Interval([0.0, 0.0, 0.0], [1.0, 1.0, 1.0]), 0.1)
    assert row["status"] == "crash" and "states" in row["reason"]


def test_bench_writes_into_out_bench_of_the_working_directory(tmp_path, monkeypatch):
    """Without --out the full run writes out/bench/ under the current directory, not the
    installed package's docs (issue 15); the measurements are stubbed out here."""
    from mbs.app import figures
    monkeypatch.setattr(bench, "work_precision", lambda *a, **k: [])
    monkeypatch.setattr(bench, "stress_cases", lambda *a, **k: [])
    monkeypatch.setattr(bench, "startup", lambda *a, **k: [])
    monkeypatch.setattr(figures, "fig_work_precision", lambda rows, path, title=None: Path(path).write_bytes(b""))
    monkeypatch.chdir(tmp_path)
    assert bench.run(log=lambda *_: None) == 0
    assert (tmp_path / "out" / "bench" / "benchmarks.md").is_file()
    assert (tmp_path / "out" / "bench" / "bench_work_precision.png").is_file()


def test_stress_case_with_an_uncertain_parameter_samples_at_its_midpoint():
    """A case with a parameter given as (lo, hi) samples its trajectories at the midpoint
    (the sampling read undefined names and every such row was a silent 'crash')."""
    from models import pendulum as pd
    from verified.arith.interval import Interval
    lo, hi = pd.initial_box()
    row = bench.run_case("m", "pendulum_paper", Interval(lo, hi), 0.05, samples=4, params={"l": (0.95, 1.05)})
    assert row["status"] == "completed", row["reason"]
    assert row["checked"] >= 4 and row["escaped"] == 0


def test_a_bug_in_the_bench_is_raised_not_reported_as_a_crash_row(monkeypatch):
    """run_case reports what a case raises as a 'crash' row, but a NameError is a bug of
    the bench itself (one hid a dead branch that way) and must surface."""
    from verified.arith.interval import Interval

    def broken(*a, **k):
        return undefined_name  # noqa: F821

    monkeypatch.setattr(bench, "_simulate", lambda: broken)
    with pytest.raises(NameError):
        bench.run_case("bug", "pendulum_paper", Interval([0.0, 0.0], [0.1, 0.0]), 0.01, samples=0)

"""benchmarks/bench_auto.py (issue 40) runs its three variants side by side: a short
run of two cases, where the old default breaks down and ``auto`` completes."""
import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _bench():
    spec = importlib.util.spec_from_file_location("bench_auto", ROOT / "benchmarks" / "bench_auto.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # (its dataclasses look their module up)
    spec.loader.exec_module(mod)
    return mod


def test_quick_rows_old_default_against_auto_and_best():
    lines = []
    rows = _bench().run_case("vdp", quick=True, cap=120.0, out=lines.append)
    before, auto, best = rows
    assert before[0].startswith("before") and auto[0] == "auto" and best[0].startswith("best")
    assert before[1] == "breakdown" and auto[1] == "completed" and best[1] == "completed"
    assert auto[6].startswith("auto:")
    assert 1.0 <= auto[5] < 10.0  # (an enclosure never narrower than the sampled spread)
    assert len(lines) == 3 and all(line.startswith("| x''") for line in lines)

"""benchmarks/arch/run.py (issue 43): the ARCH-COMP NLN benchmarks. The quick version of
three cases (short horizons, library defaults) completes, every sampled true solution
lies in the enclosures (output boxes and tube), and the table rows are printed."""
import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]


def _bench():
    spec = importlib.util.spec_from_file_location("arch_run", ROOT / "benchmarks" / "arch" / "run.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # (its dataclasses look their module up)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.slow  # (62 s, most of it the kernels' first compile in a fresh clone: the slow step)
def test_quick_cases_complete_and_contain_the_samples():
    bench = _bench()
    lines = []
    n_rows = 0
    for key in ("vdp", "ll001", "pdi"):
        # (the defaults' row, and where the case has a spec, auto's row with it declared)
        # (the cap is a safety net, not a timing: on a cold numba cache the first case also
        # compiles the kernels, which took longer than the 60 s it was once)
        rows = bench.run_case(key, quick=True, cap=900.0, out=lines.append)
        assert 1 <= len(rows) <= 2 and rows[0]["setting"].startswith("defaults"), (key, len(rows))
        n_rows += len(rows)
        for row in rows:
            assert row["status"] == "completed", (key, row["reason"])
            assert row["inside_ok"], (key, row["inside"])
            assert np.isfinite(row["metric"]) and row["metric"] > 0
            assert row["spec"].startswith("yes"), (key, row["setting"], row["spec"])
    assert len(lines) == n_rows and all(line.startswith("| ") and line.count("|") == 12 for line in lines)


def test_containment_check_catches_a_wrong_enclosure():
    """The soundness check itself: an enclosure shrunk below the true spread fails it."""
    bench = _bench()
    case = bench.CASES["vdp"]()
    row = bench.run_row(case, "defaults", {}, 0.5, 60.0, 20)
    sol = row["sol"]
    assert bench.check_inside(case, sol, 20)[0]
    from verified.arith.interval import Interval
    last = sol.boxes[-1]
    mid, rad = last.mid(), 0.25 * last.rad()
    sol.boxes[-1] = Interval(mid - rad, mid + rad)
    ok, detail = bench.check_inside(case, sol, 20)
    assert not ok and detail.startswith("NO")

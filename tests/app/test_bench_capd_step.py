"""benchmarks/bench_capd_step.py (issue 45): per-step cost of one set against CAPD. Without
CAPD it says so in one line and runs this library's side; with a driver (a stand-in
printing CAPD's JSON line here) it reads the steps, or estimates them from the horizon
and the largest step when the driver does not print them, and prints the ratios."""
import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _bench():
    spec = importlib.util.spec_from_file_location("bench_capd_step", ROOT / "benchmarks" / "bench_capd_step.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


def test_quick_without_capd_runs_our_side(monkeypatch, capsys):
    monkeypatch.delenv("CAPD_PROBS", raising=False)
    res = _bench().main(["--quick", "--only", "dp"])
    out = capsys.readouterr().out
    assert "CAPD's probs driver not found" in out
    rows = res["dp"]
    assert [r["label"] for r in rows][0] == "ours: auto (no settings)" and len(rows) == 4
    assert all(r["status"] == "completed" and r["steps"] >= 1 and r["cpu"] > 0 for r in rows)


def _fake_driver(tmp_path, steps: bool):
    line = ('{"solver": "capd", "problem": "dp", "pieces": 1, "T": 0.05, "order": 20, "tol": 0, "wall": 0.002, '
            '"cpu": 0.002, ' + ('"steps": 4, ' if steps else "")
            + '"h_min": 0.01, "h_max": 0.02, "status": "completed", "t_reached": 0.05, '
            '"widths": [0.05, 0.001, 0.02, 0.04]}')
    exe = tmp_path / ("probs_steps" if steps else "probs_plain")
    exe.write_text(f"#!{sys.executable}\nprint({line!r})\n")
    exe.chmod(0o755)
    return str(exe)


def test_capd_rows_and_ratios_from_a_driver(tmp_path):
    bench = _bench()
    lines = []
    rows = bench.run_case("dp", 0.05, _fake_driver(tmp_path, True), 1, out=lines.append)
    capd = [r for r in rows if r["label"].startswith("capd")]
    assert [r["steps"] for r in capd] == [4, 4] and not any(r["est"] for r in capd)
    ours = rows[len(capd)]
    assert abs(ours["step_ratio"][0] - ours["per_step"] / 0.0005) < 1e-9
    assert "CPU/step / capd o20" in "\n".join(lines)
    rows = bench.run_case("dp", 0.05, _fake_driver(tmp_path, False), 1, out=lines.append)
    assert [r["steps"] for r in rows if r["label"].startswith("capd")] == [3, 3]  # ceil(0.05 / 0.02), marked ~
    assert any("| ~3 |" in x for x in lines)

"""Disk cache (location, keying) and a small, fast version of the derivation benchmark."""
import importlib.util
import math
import os
from pathlib import Path

import numpy as np

from mbs import cache
from models import planar

ROOT = Path(__file__).resolve().parents[2]


def _bench():
    spec = importlib.util.spec_from_file_location("bench_derivation",
                                                  ROOT / "benchmarks" / "bench_derivation.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_default_cache_dir_is_user_cache_not_repo(monkeypatch):
    monkeypatch.delenv("MBS_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", "/tmp/xdg-test")
    assert cache.cache_dir() == Path("/tmp/xdg-test/mbs-verified")
    monkeypatch.delenv("XDG_CACHE_HOME")
    d = cache.cache_dir()
    assert d == Path(os.path.expanduser("~")) / ".cache" / "mbs-verified"
    assert ROOT not in d.parents
    monkeypatch.setenv("MBS_CACHE_DIR", "/tmp/elsewhere")
    assert cache.cache_dir() == Path("/tmp/elsewhere")
    monkeypatch.setenv("MBS_CACHE_DIR", "off")
    assert cache.cache_dir() is None


def test_cache_hit_returns_equal_graph_and_is_keyed_by_content(tmp_path):
    with cache.enabled(True, tmp_path):
        a = planar.planar_chain(2, masses=1.0)
        g1 = a.symbolic().rhs_graph()
        files = sorted(p.name for p in tmp_path.iterdir())
        assert len(files) == 1
        g2 = planar.planar_chain(2, masses=1.0).symbolic().rhs_graph()   # new object, same content
        assert g1 == g2 and sorted(p.name for p in tmp_path.iterdir()) == files
        b = planar.planar_chain(2, masses=[1.0, 1.5])  # uniform scaling would not change qdd
        gb = b.symbolic().rhs_graph()
        assert len(list(tmp_path.iterdir())) == 2
        x = np.array([0.1, 0.2, 0.3, 0.4])
        assert not np.allclose(g1.eval_float(x), gb.eval_float(x))
        assert np.allclose(gb.eval_float(x), b.numeric().rhs(x), atol=1e-12)
        # a corrupt entry is ignored and rewritten
        for p in tmp_path.iterdir():
            p.write_text("{not json")
        g3 = planar.planar_chain(2, masses=1.0).symbolic().rhs_graph()
        assert g3 == g1


def test_cache_disabled(tmp_path):
    with cache.enabled(False, tmp_path):
        planar.planar_chain(2).symbolic().energy_graph()
    assert list(tmp_path.iterdir()) == []


def test_small_benchmark(tmp_path):
    """The benchmark runs and reports sane rows. How much the cache saves is measured by
    ``python benchmarks/bench_derivation.py`` (timings are not asserted in tests); that
    the cached graphs are the derived ones is checked above."""
    bench = _bench()
    rows = bench.run(["planar2", "planar6"], inprocess=True, cache_root=str(tmp_path))
    table = bench.format_table(rows)
    assert "planar6" in table
    assert [(r["model"], r["dof"]) for r in rows] == [("planar2", 2), ("planar6", 6)]
    for r in rows:
        assert math.isfinite(r["cold"]) and r["cold"] > 0 and math.isfinite(r["cached"]) and r["cached"] > 0
        assert r["rhs_nodes"] > 0 and r["energy_nodes"] > 0

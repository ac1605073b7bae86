"""``pip install .`` builds a wheel that carries the compiled kernels (setup.py): a process
running from the unpacked wheel compiles nothing."""
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _cache_files(root: Path) -> dict:
    """{path: (size, mtime_ns)} of the numba cache files under ``root``/verified."""
    out = {}
    for pattern in ("__pycache__/*.nbi", "__pycache__/*.nbc"):
        for f in (root / "verified").rglob(pattern):
            st = f.stat()
            out[str(f.relative_to(root))] = (st.st_size, st.st_mtime_ns)
    return out


def _warm_up_from(site: Path) -> None:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["PYTHONPATH"] = str(site)
    subprocess.run([sys.executable, "-m", "verified.warmup"], cwd=site, env=env, check=True, timeout=1800,
                   capture_output=True)


@pytest.mark.slow  # (builds a wheel in an isolated environment: numpy and numba from the registry)
def test_the_wheel_carries_every_kernel_the_warm_up_compiles(tmp_path):
    dist = tmp_path / "dist"
    subprocess.run([sys.executable, "-m", "pip", "wheel", str(ROOT), "--no-deps", "-w", str(dist), "-q"],
                   check=True, timeout=3600, capture_output=True)
    (wheel,) = dist.glob("mbs_verified-*.whl")
    assert "none-any" not in wheel.name  # (a platform wheel: it carries machine code)
    site = tmp_path / "site"
    with zipfile.ZipFile(wheel) as z:
        z.extractall(site)
    shipped = _cache_files(site)
    modules = {Path(p).name.split(".")[0] for p in shipped}
    assert {"_kernels", "taylor_model", "affine_taylor", "taylor"} <= modules and len(shipped) > 100
    _warm_up_from(site)
    assert _cache_files(site) == shipped  # nothing compiled, nothing rewritten
    # the check bites: a kernel missing from the wheel is compiled (its cache written) again
    gone = [p for p in shipped if p.endswith(".nbi") and "taylor_model._model_kernel-" in p]
    for p in gone:
        (site / p).unlink()
    _warm_up_from(site)
    assert set(gone) & set(_cache_files(site))

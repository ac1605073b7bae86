"""numba's disk cache is keyed by every compiled source of the package
(verified.arith.numba_cache): a cached kernel is reloaded only while no module that
uses numba changed, since numba itself checks a function's own file only."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

_CALL = """
import numpy as np
from verified.arith import _kernels, numba_cache
a = np.zeros((1, 1, 1)); x = np.zeros((1, 1))
_kernels.matvec_bounds(a, a, x, x)
st = _kernels.matvec_bounds.stats
print(numba_cache.installed_for(_kernels.matvec_bounds), sum(st.cache_hits.values()), sum(st.cache_misses.values()))
"""


def _run(cache_dir, salt=""):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir), VERIFIED_NUMBA_SALT=salt, PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", _CALL], env=env, capture_output=True, text=True, cwd=ROOT,
                         timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    keyed, hits, misses = out.stdout.split()
    return keyed == "True", int(hits), int(misses)


@pytest.mark.slow  # (three fresh interpreters, each compiling or loading a kernel: ~15 s)
def test_a_changed_source_digest_recompiles_every_cached_kernel(tmp_path):
    """A second process loads the kernel from the cache; one whose digest differs (the
    salt stands in for an edit of another module, e.g. verified/arith/_kernels.py)
    compiles it again instead of loading the old machine code."""
    assert _run(tmp_path) == (True, 0, 1)     # compiled and saved
    assert _run(tmp_path) == (True, 1, 0)     # loaded
    assert _run(tmp_path, salt="edited") == (True, 0, 1)   # another digest: compiled again


def test_the_package_kernels_use_the_keyed_locators():
    from verified.arith import _kernels, numba_cache
    from verified.series import taylor
    assert numba_cache.installed_for(_kernels.matvec_bounds)
    assert numba_cache.installed_for(taylor._interval_coefficients)
    assert len(numba_cache.SOURCES_DIGEST) == 64

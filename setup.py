"""The one build step beyond pyproject.toml: ``pip install .`` compiles the numba kernels.

numba compiles the package's kernels on first use and caches the machine code on disk,
which cost a robot's first run a minute or more (issue 45: the first run of a new robot
must not pay minutes). Here, after setuptools has copied the modules (``build_py``),
``python -m verified.warmup --jobs 2`` runs in the source tree: numba caches the kernels
beside their modules (``__pycache__``, keyed by the content of the package's compiled
sources, ``verified/arith/numba_cache.py``), and those cache files are copied into the
wheel. So the installed package starts warm, and so do runs from the checkout (the
README's quick start runs the demo there).

Compiled code is for this machine's CPU and this numba version, so the wheel is tagged
as a platform wheel; where the caches do not fit (another CPU, another numba version),
numba ignores them and compiles on first use, as without them. Nothing is compiled for an
editable install (``pip install -e .``: the kernels compile on first use in the checkout)
or where the environment variable ``MBS_NO_WARMUP`` is set; a warm-up that fails says so
and leaves a wheel without caches.
"""

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

from setuptools import Distribution, setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent
#: numba's cache files: an index per function and its compiled overloads
CACHE_PATTERNS = ("__pycache__/*.nbi", "__pycache__/*.nbc")


def _say(message: str) -> None:
    print(f"mbs-verified build: {message}", file=sys.stderr, flush=True)


def compile_kernels(root: Path) -> bool:
    """Run the warm-up on the package in ``root`` (two processes where there are two
    cores); True when it succeeded."""
    path = os.environ.get("PYTHONPATH")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(root)] + ([path] if path else [])))
    jobs = min(2, os.cpu_count() or 1)
    _say(f"compiling the numba kernels ({jobs} process(es); a few minutes, once; MBS_NO_WARMUP=1 skips it)")
    t0 = time.perf_counter()
    try:
        done = subprocess.run([sys.executable, "-m", "verified.warmup", "--jobs", str(jobs)], cwd=root, env=env,
                              timeout=3600)
    except (OSError, subprocess.TimeoutExpired) as e:
        _say(f"the kernels were not compiled ({e}); they compile on first use")
        return False
    if done.returncode != 0:
        _say(f"the kernel warm-up exited with code {done.returncode}; the kernels compile on first use")
        return False
    _say(f"kernels compiled in {time.perf_counter() - t0:.0f} s")
    return True


def copy_caches(root: Path, build_lib: Path) -> int:
    """Copy ``verified``'s numba cache files from ``root`` into ``build_lib``; their count."""
    count = 0
    for pattern in CACHE_PATTERNS:
        for src in (root / "verified").rglob(pattern):
            dest = build_lib / src.relative_to(root)
            dest.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest)
            count += 1
    return count


class BuildWithKernels(build_py):
    """``build_py``, then the kernels compiled and their caches put into the build."""

    def run(self):
        super().run()
        if getattr(self, "editable_mode", False):
            return
        if os.environ.get("MBS_NO_WARMUP"):
            _say("MBS_NO_WARMUP is set: the kernels compile on first use")
            return
        if compile_kernels(ROOT):
            _say(f"{copy_caches(ROOT, Path(self.build_lib))} numba cache files put into the package")


class PlatformDistribution(Distribution):
    """A platform wheel: the package carries machine code for the CPU it was built on."""

    def has_ext_modules(self):
        return True


setup(cmdclass={"build_py": BuildWithKernels}, distclass=PlatformDistribution)

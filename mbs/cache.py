"""Disk cache for derived models (expression graphs, sympy expressions).

Keys also include :func:`code_fingerprint` (the source of the modules that derive and
build the graphs, and the sympy version), so editing the code invalidates old entries.

Location: ``$MBS_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/mbs-verified``, else
``~/.cache/mbs-verified`` (never inside the repository).  Entries are keyed by
``Chain.fingerprint()`` (sha256 of the chain's content: joints, placements, inertias,
damping, gravity), the kind of artefact and :data:`CACHE_VERSION`, so a changed model
never hits a stale entry.  ``MBS_CACHE_DIR=off`` (or ``enabled(False)``) disables it.

Corrupt or unreadable entries are ignored (recomputed and overwritten).
"""
from __future__ import annotations

import hashlib
import importlib.util
import json
import os
import tempfile
from contextlib import contextmanager
from functools import lru_cache
from pathlib import Path

#: bump when the derivation changes so old entries are not reused
CACHE_VERSION = "mbs-cache-1"

_override = {"dir": None, "enabled": True}


def cache_dir() -> Path | None:
    """The cache directory, or None when caching is disabled."""
    if not _override["enabled"]:
        return None
    if _override["dir"] is not None:
        return Path(_override["dir"])
    env = os.environ.get("MBS_CACHE_DIR")
    if env:
        if env.lower() in ("off", "0", "none", "false"):
            return None
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "mbs-verified"


def set_cache_dir(path) -> None:
    """Use ``path`` as cache directory for this process (None: back to the default)."""
    _override["dir"] = None if path is None else str(path)


@contextmanager
def enabled(flag: bool = True, directory=None):
    """Context manager to disable the cache or redirect it temporarily."""
    old = dict(_override)
    _override["enabled"] = flag
    if directory is not None:
        _override["dir"] = str(directory)
    try:
        yield
    finally:
        _override.update(old)


#: modules whose source defines what a cached artefact contains
CODE_MODULES = ("mbs.scalar", "mbs.spatial", "mbs.chain", "mbs.symbolic", "mbs.numeric",
                "mbs.sympy_eval", "verified.graph", "verified.graph.sympy_convert", "verified.graph.tracer",
                "verified.graph.preconditioned")


@lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """sha256 of the source of :data:`CODE_MODULES` and the sympy version, so that a
    change of the derivation or of the graph builder never reuses stale entries."""
    h = hashlib.sha256()
    try:
        import sympy  # (import here: sympy is not an import-time dependency of mbs)
        h.update(sympy.__version__.encode())
    except ImportError:  # pragma: no cover
        pass
    for name in CODE_MODULES:
        try:
            spec = importlib.util.find_spec(name)
        except (ImportError, ValueError):
            spec = None
        h.update(name.encode())
        if spec is not None and spec.origin and os.path.isfile(spec.origin):
            with open(spec.origin, "rb") as f:
                h.update(f.read())
    return h.hexdigest()


def key(fingerprint: str, kind: str) -> str:
    """Cache key of artefact ``kind`` of the chain with content ``fingerprint``."""
    raw = f"{CACHE_VERSION}|{code_fingerprint()}|{kind}|{fingerprint}"
    return hashlib.sha256(raw.encode()).hexdigest()[:40]


def _path(k: str, ext: str) -> Path | None:
    d = cache_dir()
    if d is None:
        return None
    return d / f"{k}.{ext}"


def _write(path: Path, data: bytes) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-")
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except OSError:
        pass  # a read-only cache dir must not break modeling


def get_json(k: str):
    p = _path(k, "json")
    if p is None or not p.is_file():
        return None
    try:
        return json.loads(p.read_text())
    except (OSError, ValueError):
        return None


def put_json(k: str, obj) -> None:
    p = _path(k, "json")
    if p is not None:
        _write(p, json.dumps(obj).encode())


def clear() -> int:
    """Delete all cache entries; returns how many files were removed."""
    d = cache_dir()
    if d is None or not d.is_dir():
        return 0
    n = 0
    for p in d.iterdir():
        if p.suffix in (".json", ".pkl"):  # .pkl: entries of older versions
            try:
                p.unlink(); n += 1
            except OSError:
                pass
    return n

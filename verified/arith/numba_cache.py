"""numba's disk cache for this package, keyed by every compiled source of it.

numba checks a cached function against its own source file only (``get_source_stamp``:
a hash of that file). Our kernels call compiled code of other files: the outward-rounded
scalar operations of :mod:`verified.arith._kernels`, the recursion engine of
:mod:`verified.series.recursion` inlined into each arithmetic's entry. After a change to
one of those (an editable install after ``git pull``, a branch switch), the callers'
cached machine code would still be loaded and run the old callee: a rounding fix that
does not take effect is a silent soundness bug, and the recursion engine's author met
exactly that (docs/lab/recursion_engine.md).

:func:`install` (run by ``verified/__init__.py`` before any kernel module is imported)
puts cache locators in front of numba's own for this package's files only: the same
cache directories as numba would use, with the source stamp extended by
:data:`SOURCES_DIGEST`, the hash of every module of the package that uses numba. A
change to any of them invalidates every cached kernel of the package at once (the next
call recompiles it); other packages' caches are not touched. ``VERIFIED_NUMBA_SALT``
(an environment variable) enters the digest too: a way to force recompilation.
If numba's (private) locator classes are not what this module expects, nothing is
installed and numba's own per-file checks apply.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

__all__ = ["SOURCES_DIGEST", "install", "installed_for"]

_PACKAGE = Path(__file__).resolve().parents[1]   # verified/
_PREFIX = str(_PACKAGE) + os.sep


def _sources_digest() -> str:
    h = hashlib.sha256(os.environ.get("VERIFIED_NUMBA_SALT", "").encode())
    for path in sorted(_PACKAGE.rglob("*.py")):
        text = path.read_bytes()
        if b"numba" in text:
            h.update(str(path.relative_to(_PACKAGE)).encode() + b"\0" + text + b"\0")
    return h.hexdigest()


#: sha256 over the package's modules that use numba (their paths and bytes) and the salt
SOURCES_DIGEST = _sources_digest()


def _in_package(py_file) -> bool:
    return os.path.abspath(str(py_file)).startswith(_PREFIX)


def _keyed(base):
    """``base`` (a numba locator class) for this package's files, its stamp keyed by the digest."""
    class Locator(base):
        @classmethod
        def from_function(cls, py_func, py_file):
            if not _in_package(py_file):
                return None
            return super().from_function(py_func, py_file)

        def get_source_stamp(self):
            return (super().get_source_stamp(), SOURCES_DIGEST)

    Locator.__name__ = Locator.__qualname__ = f"Verified{base.__name__}"
    return Locator


def install() -> bool:
    """Put the package's locators first in numba's list (once); False where numba's
    locator classes are not there (then numba's own checks apply)."""
    try:
        from numba.core.caching import (CacheImpl, InTreeCacheLocator, UserProvidedCacheLocator,
                                        UserWideCacheLocator)
        classes = CacheImpl._locator_classes
    except (ImportError, AttributeError):
        return False
    if any(getattr(c, "_verified_keyed", False) for c in classes):
        return True
    ours = [_keyed(b) for b in (UserProvidedCacheLocator, InTreeCacheLocator, UserWideCacheLocator)]
    for c in ours:
        c._verified_keyed = True
    classes[:0] = ours
    return True


def installed_for(dispatcher) -> bool:
    """Whether a cached numba ``dispatcher`` of this package uses the keyed locators."""
    cache = getattr(dispatcher, "_cache", None)
    impl = getattr(cache, "_impl", None)
    locator = getattr(impl, "_locator", None)
    return bool(getattr(type(locator), "_verified_keyed", False))

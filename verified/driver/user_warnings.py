"""Warnings attributed to the user's own line, not to the library's insides.

``warnings.warn(..., stacklevel=k)`` needs the depth of the call chain, which differs by
path (``solve`` -> the method's solve -> ``solve_parallel`` -> the planner, or
``mbs.simulate`` -> ``solve`` -> ...) and silently points into the library when a
refactoring adds a frame. :func:`warn_at_caller` counts the frames instead: the warning
is reported at the first frame outside this library's packages (``verified``, ``mbs``,
``models``), as Python 3.12's ``skip_file_prefixes`` does.
"""

from __future__ import annotations

import os
import sys
import warnings

__all__ = ["warn_at_caller"]

_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
#: the library's package directories (as path prefixes)
LIBRARY_PREFIXES = tuple(os.path.join(_ROOT, p) + os.sep for p in ("verified", "mbs", "models"))


def _in_library(filename: str) -> bool:
    return os.path.abspath(filename).startswith(LIBRARY_PREFIXES)


def warn_at_caller(message: str, category: type[Warning] = UserWarning) -> None:
    """``warnings.warn(message, category)`` reported at the first frame outside the
    library (the frame that called into it); at the outermost frame if every frame is
    the library's own."""
    level = 2   # (1 is this function's own line, 2 its caller)
    frame = sys._getframe(1)
    while frame.f_back is not None and _in_library(frame.f_code.co_filename):
        frame = frame.f_back
        level += 1
    warnings.warn(message, category, stacklevel=level)

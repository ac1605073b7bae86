"""Locate the URDF files of the ``example-robot-data`` distribution.

example-robot-data 6.x is a cmeel package: its files live under
``<site-packages>/cmeel.prefix/share/example-robot-data/robots/``.  We find them through
``importlib.metadata`` (no dependency on example-robot-data-loaders).
"""
from __future__ import annotations

import importlib.metadata as md
from functools import lru_cache
from pathlib import Path

from .errors import ModelError

_PREFIX = "cmeel.prefix/share/example-robot-data/robots/"

#: short names for the robots used in this project -> path under robots/
KNOWN = {
    "double_pendulum": "double_pendulum_description/urdf/double_pendulum.urdf",
    "double_pendulum_continuous": "double_pendulum_description/urdf/double_pendulum_continuous.urdf",
    "double_pendulum_simple": "double_pendulum_description/urdf/double_pendulum_simple.urdf",
    "ur5": "ur_description/urdf/ur5_robot.urdf",
    "ur5_robot": "ur_description/urdf/ur5_robot.urdf",
    "panda": "panda_description/urdf/panda.urdf",
}

#: panda's finger joints (one is a mimic joint); lock them for the 7-dof arm
PANDA_FINGERS = ("panda_finger_joint1", "panda_finger_joint2")


@lru_cache(maxsize=None)
def robots_dir() -> Path:
    """The ``robots`` directory of the installed example-robot-data."""
    try:
        dist = md.distribution("example-robot-data")
    except md.PackageNotFoundError:
        raise ModelError("example-robot-data is not installed (pip install example-robot-data)") from None
    for f in dist.files or ():
        s = str(f).replace("\\", "/")
        if s.startswith(_PREFIX) and s.endswith(".urdf"):
            p = Path(dist.locate_file(f))
            root = p
            while root.name != "robots":
                root = root.parent
            return root
    raise ModelError("example-robot-data is installed but ships no URDF files under " + _PREFIX)


def list_urdfs() -> list:
    """All URDF paths (relative to :func:`robots_dir`)."""
    d = robots_dir()
    return sorted(str(p.relative_to(d)) for p in d.rglob("*.urdf"))


def urdf_path(name: str) -> Path:
    """Path of a URDF: a short name from :data:`KNOWN`, or a path relative to robots/
    (e.g. ``"ur_description/urdf/ur5_robot.urdf"``), or a file stem such as
    ``"ur5_gripper"``."""
    d = robots_dir()
    rel = KNOWN.get(name, name)
    p = d / rel
    if p.is_file():
        return p
    hits = [q for q in d.rglob(f"{name}.urdf")]
    if len(hits) == 1:
        return hits[0]
    raise ModelError(f"no example-robot-data URDF named {name!r}; known: {sorted(KNOWN)}; "
                     f"see mbs.robots.list_urdfs()")


def load(name: str, **kwargs):
    """``Chain.from_urdf(urdf_path(name))``; for "panda" the fingers are locked at 0
    unless ``lock`` is given."""
    from .chain import Chain
    if name == "panda" and "lock" not in kwargs:
        kwargs["lock"] = {j: 0.0 for j in PANDA_FINGERS}
    return Chain.from_urdf(urdf_path(name), **kwargs)

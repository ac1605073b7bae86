"""Locate the URDF files of the ``example-robot-data`` distribution.

example-robot-data 6.x is a cmeel package: its files live under
``<site-packages>/cmeel.prefix/share/example-robot-data/robots/``.  We find them through
``importlib.metadata`` (no dependency on example-robot-data-loaders).
"""
from __future__ import annotations

import importlib.metadata as md
from functools import lru_cache
from pathlib import Path

from .chain import Chain
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
    if name == "panda" and "lock" not in kwargs:
        kwargs["lock"] = {j: 0.0 for j in PANDA_FINGERS}
    return Chain.from_urdf(urdf_path(name), **kwargs)


#: names users type for the ready models (also the example-robot-data short names)
ALIASES = {"panda": "panda_arm", "franka": "panda_arm", "ur5_robot": "ur5",
           "double_pendulum": "double_pendulum_urdf"}
ERD_PREFIX = "example-robot-data:"

#: the paper's models (sec. 5.1, 5.2): the names of ``models.registry.SYSTEMS``, System
#: factories (:class:`models.paper.PaperModel`): a DH chain in modes i/ii, the
#: hand-written eqs. (18)/(19), (22)/(24) in mode iii (here too, so that scenes can
#: list them without importing ``models``)
PAPER_MODELS = ("pendulum_paper", "double_pendulum_paper")


def system_entry(name):
    """The registry's System factory for a model name (``models.registry.SYSTEMS``: the
    paper's models, :class:`models.paper.PaperModel`), or None: a name of a chain
    model, or not a name at all. The factory has ``chain(params=None)``,
    ``system(mode, energy_rate, cparams=None)`` (None: integrate the chain;
    ``energy_rate`` one of :data:`verified.energy_rate.MODEL_RATES`) and
    ``param_names``."""
    if not isinstance(name, str):
        return None
    from models.registry import SYSTEMS  # (import here: models imports mbs)
    return SYSTEMS.get(name)


def model_names() -> list:
    """Every model name :func:`load_model` accepts besides paths and
    ``example-robot-data:NAME``: the registry's names and the aliases."""
    from models.registry import NAMES  # (import here: models imports mbs)
    return list(NAMES) + sorted(set(ALIASES) - set(NAMES))


def load_model(spec: str):
    """A :class:`mbs.Chain` from what a user types (the same as a scene's ``[model]``):

    - a ready model, ``models.registry.NAMES`` (``ur5``, ``panda_arm``, ``puma560``, ...),
      or an alias from :data:`ALIASES` (``panda``);
    - ``example-robot-data:NAME`` (a short name of :data:`KNOWN`, a path under
      ``robots/`` or a file stem; panda's fingers are locked);
    - a path to a URDF file.

    Raises :class:`ModelError` (one line) naming what was tried."""
    from models.registry import NAMES, get  # (import here: models imports mbs)
    if not isinstance(spec, str) or not spec:
        raise ModelError(f"expected a model name, example-robot-data:NAME or a URDF path, got {spec!r}")
    if spec in NAMES:
        return get(spec)
    if spec in ALIASES:
        return get(ALIASES[spec])
    if spec.startswith(ERD_PREFIX):
        return load(spec[len(ERD_PREFIX):])
    p = Path(spec)
    if p.suffix.lower() in (".urdf", ".xml") or p.is_file():
        if not p.is_file():
            raise ModelError(f"URDF file {spec!r} not found")
        return Chain.from_urdf(p)
    raise ModelError(f"unknown model {spec!r}; give a name ({', '.join(model_names())}), "
                     "example-robot-data:NAME or a URDF file path")

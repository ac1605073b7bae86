"""Locate the URDF files of the ``example-robot-data`` distribution.

example-robot-data 6.x is a cmeel package: its files live under
``<site-packages>/cmeel.prefix/share/example-robot-data/robots/``.  We find them through
``importlib.metadata`` (no dependency on example-robot-data-loaders).
"""
from __future__ import annotations

import importlib.metadata as md
from collections.abc import Sequence
from functools import lru_cache
from pathlib import Path

from .urdf import chain_from_urdf
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
    """``chain_from_urdf(urdf_path(name))``; for "panda" the fingers are locked at 0
    unless ``lock`` is given."""
    if name == "panda" and "lock" not in kwargs:
        kwargs["lock"] = {j: 0.0 for j in PANDA_FINGERS}
    return chain_from_urdf(urdf_path(name), **kwargs)


#: names users type for the ready models (also the example-robot-data short names)
ALIASES = {"panda": "panda_arm", "franka": "panda_arm", "ur5_robot": "ur5",
           "double_pendulum": "double_pendulum_urdf"}
ERD_PREFIX = "example-robot-data:"

#: the entry-point group through which an installed distribution offers ready models.
#: The modeling core never imports :mod:`models`: this project's pyproject.toml declares
#: ``[project.entry-points."mbs.models"] registry = "models.registry"``, and each entry
#: point of the group names a registry object (here that module) with ``NAMES`` (chain
#: model names), ``get(name)`` (a new :class:`mbs.Chain`) and ``SYSTEMS`` (name ->
#: System factory).
MODELS_GROUP = "mbs.models"

_NOT_INSTALLED = (f"no ready models: no entry point of group {MODELS_GROUP!r} is installed "
                  "(install the package: pip install -e . in the checkout)")


@lru_cache(maxsize=None)
def _entry_points() -> tuple:
    """The entry points of :data:`MODELS_GROUP` (read once: the scan of the installed
    distributions takes a few ms), in the order of their names."""
    return tuple(sorted(md.entry_points(group=MODELS_GROUP), key=lambda ep: (ep.name, ep.value)))


@lru_cache(maxsize=None)
def registries() -> tuple:
    """The registries of ready models offered through :data:`MODELS_GROUP`, loaded
    once, in the order of their entry-point names (a name two registries offer is the
    first one's). Raises :class:`ModelError` (one line, naming the fix) when none is
    installed or one does not load."""
    eps = _entry_points()
    if not eps:
        raise ModelError(_NOT_INSTALLED)
    out = []
    for ep in eps:
        try:
            out.append(ep.load())
        except ImportError as e:  # metadata of an install whose files are gone, a stale egg-link
            raise ModelError(f"the model registry {ep.value!r} (entry point {ep.name!r} of group "
                             f"{MODELS_GROUP!r}) does not import: {e} (reinstall the package: "
                             "pip install -e . in the checkout)") from e
    return tuple(out)


def _installed() -> tuple:
    """:func:`registries`, or () when none is installed (URDF paths and
    example-robot-data names need none); a registry that does not load still raises."""
    if not _entry_points():
        return ()
    return registries()


def system_entry(name):
    """The registry's System factory for a model name (``models.registry.SYSTEMS``: the
    paper's models, :class:`models.paper.PaperModel`), or None: a name of a chain
    model, or not a name at all. The factory has ``chain(params=None)``,
    ``system(mode, energy_rate, cparams=None)`` (None: integrate the chain;
    ``energy_rate`` one of :data:`verified.consistency.energy_rate.MODEL_RATES`) and
    ``param_names``."""
    if not isinstance(name, str):
        return None
    return next((r.SYSTEMS[name] for r in _installed() if name in r.SYSTEMS), None)


def system_names() -> tuple:
    """The names of the registries' System factories (``models.registry.SYSTEMS``: the
    paper's models, sec. 5.1, 5.2, :class:`models.paper.PaperModel`: a DH chain in modes
    i/ii, the hand-written eqs. (18)/(19), (22)/(24) in mode iii), in registry order;
    () when no registry is installed."""
    return tuple(dict.fromkeys(n for r in _installed() for n in r.SYSTEMS))


class _SystemNames(Sequence):
    """:func:`system_names` as a read-only tuple-like constant, read from the registries
    when first used (not at import: the registries import mbs)."""

    def __getitem__(self, i):
        return system_names()[i]

    def __len__(self):
        return len(system_names())

    def __eq__(self, other):
        return tuple(self) == (tuple(other) if isinstance(other, _SystemNames) else other)

    def __hash__(self):
        return hash(tuple(self))

    def __add__(self, other):
        return tuple(self) + other

    def __radd__(self, other):
        return other + tuple(self)

    def __repr__(self):
        return repr(tuple(self))


#: the paper's models: :func:`system_names`, the names of the registries' System
#: factories (re-exported by :mod:`mbs.simulate`); kept as a name for code that reads it
#: as a constant (``name in PAPER_MODELS``, ``tuple(PAPER_MODELS)``)
PAPER_MODELS = _SystemNames()


def model_names() -> list:
    """Every model name :func:`load_model` accepts besides paths and
    ``example-robot-data:NAME``: the registries' names and the aliases."""
    names = list(dict.fromkeys(n for r in registries() for n in r.NAMES))
    return names + sorted(set(ALIASES) - set(names))


def load_model(spec: str):
    """A :class:`mbs.Chain` from what a user types (the same as a scene's ``[model]``):

    - a ready model, ``models.registry.NAMES`` (``ur5``, ``panda_arm``, ``puma560``, ...),
      or an alias from :data:`ALIASES` (``panda``);
    - ``example-robot-data:NAME`` (a short name of :data:`KNOWN`, a path under
      ``robots/`` or a file stem; panda's fingers are locked);
    - a path to a URDF file.

    The ready models come from the registries of :data:`MODELS_GROUP` (:func:`registries`).
    Raises :class:`ModelError` (one line) naming what was tried."""
    if not isinstance(spec, str) or not spec:
        raise ModelError(f"expected a model name, example-robot-data:NAME or a URDF path, got {spec!r}")
    regs = _installed()
    for name in (spec, ALIASES.get(spec)):
        reg = next((r for r in regs if name in r.NAMES), None)
        if reg is not None:
            return reg.get(name)
    if spec.startswith(ERD_PREFIX):
        return load(spec[len(ERD_PREFIX):])
    p = Path(spec)
    if p.suffix.lower() in (".urdf", ".xml") or p.is_file():
        if not p.is_file():
            raise ModelError(f"URDF file {spec!r} not found")
        return chain_from_urdf(p)
    if not regs:
        raise ModelError(f"unknown model {spec!r}: {_NOT_INSTALLED}")
    raise ModelError(f"unknown model {spec!r}; give a name ({', '.join(model_names())}), "
                     "example-robot-data:NAME or a URDF file path")

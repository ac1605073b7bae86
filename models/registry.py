"""Name -> factory for every ready model (handy for CLIs and benchmarks).

- :data:`FACTORIES`: name -> chain factory (:func:`get`, :data:`NAMES`);
- :data:`SYSTEMS`: name -> System factory (:class:`models.paper.PaperModel`) for the
  paper's models, which :func:`mbs.simulate.simulate` builds per mode: the DH chain in
  modes i and ii, the hand-written equations in mode iii.

The modeling core (:mod:`mbs`) does not import this module: pyproject.toml offers it as
the entry point ``registry`` of group ``mbs.models`` (:data:`mbs.robots.MODELS_GROUP`),
through which :func:`mbs.robots.load_model` and :func:`mbs.robots.system_entry` find it.

>>> from models.registry import get, NAMES
>>> chain = get("ur5")
"""
from __future__ import annotations

from mbs import ModelError

from . import double_pendulum, paper, pendulum, planar, puma560, robots

FACTORIES = {
    "pendulum": pendulum.chain,
    "double_pendulum_paper_dh": double_pendulum.dh_chain,
    "double_pendulum_paper_urdf": double_pendulum.urdf_chain,
    "planar2": lambda: planar.planar_chain(2),
    "planar3": lambda: planar.planar_chain(3),
    "planar6": lambda: planar.planar_chain(6),
    "planar2_modified": lambda: planar.planar_chain(2, convention="modified"),
    "planar3_modified": lambda: planar.planar_chain(3, convention="modified"),
    "planar6_modified": lambda: planar.planar_chain(6, convention="modified"),
    "puma560": lambda: puma560.puma560("standard"),
    "puma560_modified": lambda: puma560.puma560("modified"),
    "double_pendulum_urdf": robots.double_pendulum,
    "ur5": robots.ur5,
    "panda_arm": robots.panda_arm,
}
NAMES = tuple(FACTORIES)

#: the paper's models (sec. 5.1, 5.2): System factories; mbs.robots.system_names() (and
#: PAPER_MODELS) read the names from here
SYSTEMS = {m.name: m for m in (paper.PENDULUM, paper.DOUBLE_PENDULUM)}


def get(name: str):
    """The chain of a ready model (see :data:`NAMES`)."""
    try:
        return FACTORIES[name]()
    except KeyError:
        raise ModelError(f"unknown model {name!r}; choose one of {', '.join(NAMES)}") from None

"""The one vocabulary for the energy rate ``dH/dt`` (``H_V' = dH/dt``, paper eqs. (7)/(12)).

This module owns the names, and only the names: how ``dH/dt``, integrated into the
energy state ``h`` (``H_V``), is obtained. Every layer calls the knob
``energy_rate`` and takes its values from :data:`ENERGY_RATES`:

============== ===========================================================================
value          ``dH/dt`` is ...
============== ===========================================================================
"derive"       formed by the library: ``grad H . f`` by forward-mode differentiation of
               the energy graph along the ODE (mode ii; the paper's FADBAD++)
"unsimplified" the symbolic model's expression as the chain rule gives it, integrated as
               a graph (mode iii, as in the paper)
"simplified"   the symbolic model's expression simplified to ``qd^T tau``; identically
               0 for the paper's conservative models, which then declare "zero"
"zero"         declared 0 (a conservative system): ``H_V`` stays ``H(0)``, nothing is
               integrated -- once proven (below)
a ``Graph``    given by the caller (``x, p -> [dH/dt]``, W); proven like "zero"
============== ===========================================================================

A declared rate ("zero" or a graph) is only sound if true, and an interval check
cannot show that it is (around an equilibrium, ``grad H . f - rate`` of a false claim
encloses 0 on every set). So the energy test uses it only when
:func:`verified.consistency.graphs.prove_claim` proves ``grad H . f - rate``
identically 0 (exactly, once at set-up); an unproven one is replaced by the derived
rate ``grad H . f`` with one ``EnergyClaimWarning``, and any declared rate refuted on
intervals during the run raises ``EnergyClaimError``
(:mod:`verified.consistency.graphs`). ``EnergyTest(check_claim=False)`` uses a
declaration unproven (the caller vouches for it).

Which layer takes which (a one-line ``ValueError`` names the allowed ones otherwise):

- :data:`MODEL_RATES` ("unsimplified", "simplified"): a request to the model, in
  :func:`mbs.simulate.simulate`, :func:`mbs.simulate.system_for`, the registry's
  System factories and scene files (``[consistency] energy_rate``). It chooses
  which symbolic expression mode iii integrates; modes i and ii always derive.
- :data:`SYSTEM_RATES` ("derive", "zero") or a graph: what a model hands over, in
  :class:`mbs.system.System` and :class:`verified.consistency.energy_test.EnergyTest`.

Old spellings (:data:`DEPRECATED`) still work and raise a ``DeprecationWarning``
that names the new one.
"""

from __future__ import annotations


from verified.graph import Graph
from verified.driver.user_warnings import warn_at_caller

__all__ = ["DEPRECATED", "ENERGY_RATES", "MODEL_RATES", "SYSTEM_RATES", "check_energy_rate", "deprecated"]

#: every value of the ``energy_rate`` knob (besides a graph), with what it means
ENERGY_RATES = {
    "derive": "grad H . f, derived by forward-mode differentiation of the energy graph along the ODE",
    "unsimplified": "the symbolic model's dH/dt as the chain rule gives it, integrated",
    "simplified": "the symbolic model's dH/dt simplified (qd^T tau; 'zero' for a conservative model)",
    "zero": "declared 0 (conservative): H_V = H(0); used only when proven, else derived",
}

#: what a model is asked for (simulate, system_for, registry factories, scenes)
MODEL_RATES = ("unsimplified", "simplified")

#: what a System and EnergyTest take besides a graph
SYSTEM_RATES = ("derive", "zero")

#: old spelling -> new spelling (each still works, with a DeprecationWarning)
DEPRECATED = {
    "System(conservative=True)": 'System(energy_rate="zero")',
    "System(conservative=False)": 'System(energy_rate="derive") (the default) or a graph',
    "System(energy_rate=None)": 'System(energy_rate="derive")',
    "System.conservative": 'System.energy_rate == "zero"',
    "EnergyTest(energy, None)": 'EnergyTest(energy, "zero")',
}


def deprecated(old: str):
    """Warn (at the user's line) that ``old`` (a key of :data:`DEPRECATED`) is spelt differently now."""
    warn_at_caller(f"{old} is deprecated; use {DEPRECATED[old]}", DeprecationWarning)


def check_energy_rate(value, allowed: tuple, where: str, graph: bool = False):
    """``value`` if it is one of ``allowed`` (or a graph, when ``graph``); else a
    one-line ``ValueError`` that names the allowed values."""
    if graph and isinstance(value, Graph):
        return value
    if isinstance(value, str) and value in allowed:
        return value
    names = ", ".join(repr(a) for a in allowed) + (" or a Graph" if graph else "")
    raise ValueError(f"{where}: energy_rate must be {names}, got {value!r}")

"""The paper's three simulation modes (sec. 5.2) as one small data type.

=====  ===========  ===========  ==========================================
mode   model        energy test  test defaults (the paper's)
=====  ===========  ===========  ==========================================
i      numeric      no           --
ii     numeric      yes          every 0.1 s at the latest, 10 parts per set
iii    symbolic     yes          every 0.01 s at the latest, 50 parts per set
=====  ===========  ===========  ==========================================

"numeric": the recursive algorithms (crba/rnea, :mod:`mbs.numeric`) traced into a
graph, ``dH/dt`` by forward-mode differentiation of ``H`` along the ODE; "symbolic":
the sympy model (:mod:`mbs.symbolic`; for the paper's examples the hand-written eqs.
(18)/(19) and (22)/(24)). :func:`mbs.simulate.simulate`, the runner, bench, figures and
demo read these fields instead of comparing mode names. Everywhere a mode is taken,
its name (``"ii"``) or the :class:`Mode` itself will do; what is stored and written
(``Simulation.mode``, result.json) is the name.
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Mode", "MODE_I", "MODE_II", "MODE_III", "ALL_MODES", "MODES", "get_mode"]


@dataclass(frozen=True)
class Mode:
    """One simulation mode: ``name`` ("i", "ii", "iii"), a short ``description``,
    whether the energy consistency test runs (``energy_test``), which ``model``
    ("numeric" or "symbolic") and the default test settings (``test_interval`` s,
    ``test_splits`` parts; None without a test)."""

    name: str
    description: str
    energy_test: bool
    model: str
    test_interval: float | None = None
    test_splits: int | None = None

    @property
    def symbolic(self) -> bool:
        """True when the mode integrates the symbolic (sympy) model."""
        return self.model == "symbolic"

    @property
    def label(self) -> str:
        """``"(ii) numeric + energy test"``: the figures' legend entry."""
        return f"({self.name}) {self.description}"

    @property
    def with_energy_test(self) -> "Mode":
        """The mode of the same model with the energy test (mode i -> ii): its system
        has an energy graph (used for sampling and Fig. 3)."""
        return self if self.energy_test else next(m for m in ALL_MODES if m.model == self.model and m.energy_test)

    def __str__(self) -> str:
        return self.name


MODE_I = Mode("i", "numeric, no test", energy_test=False, model="numeric")
MODE_II = Mode("ii", "numeric + energy test", energy_test=True, model="numeric", test_interval=0.1, test_splits=10)
MODE_III = Mode("iii", "symbolic + energy test", energy_test=True, model="symbolic", test_interval=0.01,
                test_splits=50)

#: the modes in the paper's order
ALL_MODES = (MODE_I, MODE_II, MODE_III)
#: their names, what users type (``simulate(..., mode="ii")``, scenes, ``--mode``)
MODES = tuple(m.name for m in ALL_MODES)

_BY_NAME = {m.name: m for m in ALL_MODES}


def get_mode(mode) -> Mode:
    """The :class:`Mode` of a name (``"ii"``) or a Mode; ``ValueError`` otherwise."""
    if isinstance(mode, Mode):
        return mode
    try:
        return _BY_NAME[mode]
    except (KeyError, TypeError):
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}") from None

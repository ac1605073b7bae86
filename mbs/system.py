"""The seam handed to the verified side: one ODE plus (optionally) its energy.

A :class:`System` is what a simulation mode needs and nothing robot-specific: the
right-hand side ``x' = f(x, p)`` as an expression graph, and for the energy
consistency test the Hamiltonian ``H(x)`` (``H_H``, paper eqs. (3)/(4)) and its
rate ``dH/dt(x)`` (integrated into ``H_V``, eq. (12)). Chains (DH, URDF), the
paper's hand-written models and Hamiltonians recovered from bare ODEs
(:mod:`mbs.hamiltonian_recovery`) all produce one.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from verified.consistency.energy_rate import SYSTEM_RATES, check_energy_rate, deprecated
from verified.graph import Graph


@dataclass(frozen=True, init=False)
class System:
    """An ODE with optional energy functions, ready for :func:`mbs.simulate.simulate`.

    Attributes
    ----------
    name : str
        Shown in reports and result files.
    rhs : Graph
        ``x -> x'`` with ``n`` inputs and ``n`` outputs (state ``x = (q, qd)`` for
        mechanical systems, angles in rad, rates in rad/s or m/s).
    energy : Graph or None
        ``x -> [H]`` (1 output, J): the constraint ``H_H``.
    energy_rate : "derive", "zero" or Graph
        How ``dH/dt``, integrated alongside the state for ``H_V``, is obtained (the
        vocabulary: :mod:`verified.consistency.energy_rate`). "derive" (default): the verified
        side forms ``dH/dt = grad H(x) . f(x)`` by forward-mode differentiation of the
        graphs (what the paper did with FADBAD++ in mode (ii)); "zero": ``dH/dt`` is
        identically 0 (declared, e.g. after symbolic simplification), ``H_V`` stays
        ``H(0)`` and no rate is integrated; a Graph: ``x -> [dH/dt]`` (1 output, W).
        A declaration is used only once proven exactly equal to ``grad H . f`` (when
        the run starts); an unproven one is replaced by the derived rate, with an
        ``EnergyClaimWarning`` (:mod:`verified.consistency.energy_rate`). Old spellings, with a
        ``DeprecationWarning``: ``None`` for "derive", ``conservative=True`` for "zero".
    params : dict
        Parameter values (numbers or ``(lo, hi)``) by name, if the graphs have any.
    description : str
        One line on where the graphs come from (numeric model, symbolic, recovered).
    """

    name: str
    rhs: Graph
    energy: Graph | None = None
    energy_rate: Graph | str = "derive"
    params: dict = field(default_factory=dict)
    description: str = ""

    def __init__(self, name: str, rhs: Graph, energy: Graph | None = None, energy_rate="derive",
                 conservative: bool | None = None, params: dict | None = None, description: str = ""):
        # the init is written out (not the dataclass's) only to take the old spellings,
        # in their old positions, and map them onto energy_rate
        if conservative is not None:
            deprecated(f"System(conservative={bool(conservative)})")
            if conservative:
                if energy_rate is not None and not _is(energy_rate, "derive"):
                    raise ValueError(f"{name}: a conservative system has no energy_rate graph")
                energy_rate = "zero"
        if energy_rate is None:
            deprecated("System(energy_rate=None)")
            energy_rate = "derive"
        for k, v in (("name", name), ("rhs", rhs), ("energy", energy), ("energy_rate", energy_rate),
                     ("params", {} if params is None else params), ("description", description)):
            object.__setattr__(self, k, v)
        self.__post_init__()

    def __post_init__(self):
        check_energy_rate(self.energy_rate, SYSTEM_RATES, self.name, graph=True)
        n = self.rhs.n_inputs
        if self.rhs.n_outputs != n:
            raise ValueError(f"{self.name}: rhs must map n states to n rates, got {n} inputs "
                             f"and {self.rhs.n_outputs} outputs")
        rate_graph = self.energy_rate if isinstance(self.energy_rate, Graph) else None
        for what, g in (("energy", self.energy), ("energy_rate", rate_graph)):
            if g is None:
                continue
            if g.n_inputs != n or g.n_outputs != 1:
                raise ValueError(f"{self.name}: {what} must map the {n} states to one value, "
                                 f"got {g.n_inputs} inputs and {g.n_outputs} outputs")
        if not _is(self.energy_rate, "derive") and self.energy is None:
            raise ValueError(f"{self.name}: energy_rate {self._rate_name()} given without energy")

    def _rate_name(self) -> str:
        return "graph" if isinstance(self.energy_rate, Graph) else repr(self.energy_rate)

    @property
    def conservative(self) -> bool:
        """Deprecated: ``energy_rate == "zero"``."""
        deprecated("System.conservative")
        return _is(self.energy_rate, "zero")

    @property
    def n(self) -> int:
        return self.rhs.n_inputs

    @property
    def state_names(self) -> tuple[str, ...]:
        return tuple(self.rhs.input_names)

    @property
    def has_energy(self) -> bool:
        return self.energy is not None


def _is(rate, name: str) -> bool:
    """``rate`` is the named value (a Graph is none of them)."""
    return isinstance(rate, str) and rate == name

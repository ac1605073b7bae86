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

from verified.graph import Graph


@dataclass(frozen=True)
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
    energy_rate : Graph or None
        ``x -> [dH/dt]`` (1 output, W) integrated alongside the state for ``H_V``.
        ``None`` with an ``energy`` means "derive it": the verified side forms
        ``dH/dt = grad H(x) . f(x)`` by forward-mode differentiation of the graphs
        (what the paper did with FADBAD++ in mode (ii)).
    conservative : bool
        ``dH/dt`` is identically 0 (declared, e.g. after symbolic simplification):
        ``H_V`` stays ``H(0)`` and no rate is integrated. Only sound if true.
    params : dict
        Parameter values (numbers or ``(lo, hi)``) by name, if the graphs have any.
    description : str
        One line on where the graphs come from (numeric model, symbolic, recovered).
    """

    name: str
    rhs: Graph
    energy: Graph | None = None
    energy_rate: Graph | None = None
    conservative: bool = False
    params: dict = field(default_factory=dict)
    description: str = ""

    def __post_init__(self):
        n = self.rhs.n_inputs
        if self.rhs.n_outputs != n:
            raise ValueError(f"{self.name}: rhs must map n states to n rates, got {n} inputs "
                             f"and {self.rhs.n_outputs} outputs")
        for what, g in (("energy", self.energy), ("energy_rate", self.energy_rate)):
            if g is None:
                continue
            if g.n_inputs != n or g.n_outputs != 1:
                raise ValueError(f"{self.name}: {what} must map the {n} states to one value, "
                                 f"got {g.n_inputs} inputs and {g.n_outputs} outputs")
        if (self.energy_rate is not None or self.conservative) and self.energy is None:
            raise ValueError(f"{self.name}: energy_rate or conservative given without energy")
        if self.conservative and self.energy_rate is not None:
            raise ValueError(f"{self.name}: a conservative system has no energy_rate graph")

    @property
    def n(self) -> int:
        return self.rhs.n_inputs

    @property
    def state_names(self) -> tuple[str, ...]:
        return tuple(self.rhs.input_names)

    @property
    def has_energy(self) -> bool:
        return self.energy is not None

"""The graphs the consistency tests evaluate, lifted onto the solver's states (paper sec. 3/4).

This module owns the set-up half of :class:`verified.consistency.EnergyTest`: what
the user declares (the energy ``H(x, p)`` in J, its rate ``dH/dt`` in W, constraints
``lower <= g(x[, t]) <= upper``) is turned into graphs over the states the verified
solver integrates, ``(x, [p as states], h)``:

- ``x``: the ODE's ``n_x`` states; ``p``: its parameters, appended as constant states
  when the solver carries them that way (``n_s = n_x + n_p`` inputs then, else
  ``n_s = n_x``);
- ``h``: ``H_V``, the energy integrated along the solution (eq. (12)), appended as one
  more state (``n_aug = n_s + 1`` with an energy, ``n_s`` without).

It also owns the declared-rate claim: a rate given as ``"zero"`` or as a graph is
checked (symbolically by :func:`prove_energy_rate`, on intervals by
:func:`refute_claim`), because pruning with a wrong rate removes true states.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .graph import Graph, GraphBuilder
from .graph_ops import augment_with_rate, difference, embed, rate_along
from .interval import Interval, concatenate, point

__all__ = ["Constraint", "EnergyClaimError", "LiftedGraphs", "lift_graphs", "prove_energy_rate", "refute_claim"]


class EnergyClaimError(ValueError):
    """A declared energy rate (``energy_rate="zero"`` or an ``energy_rate`` graph;
    :mod:`verified.energy_rate`) is refuted: ``grad H . f - rate`` excludes 0 somewhere.
    Pruning or contracting with it would remove true states."""


def prove_energy_rate(rhs: Graph, energy: Graph, rate: Graph | None) -> bool:
    """Symbolic proof (sympy) that ``grad H . f - rate`` is identically 0 (``rate``
    None: the claim ``dH/dt = 0``). True when proven; False when sympy cannot
    simplify it to 0 (no refutation: use the interval check)."""
    # (import here: sympy, ~0.4 s, only for this symbolic proof)
    import sympy

    from .graph_sympy import graph_to_sympy
    xs = sympy.symbols(f"x0:{rhs.n_inputs}", real=True)
    ps = sympy.symbols(f"p0:{rhs.n_params}", real=True) if rhs.n_params else ()
    f = graph_to_sympy(rhs, xs, ps)
    (H,) = graph_to_sympy(energy, xs, ps)
    expr = sum(sympy.diff(H, x) * fx for x, fx in zip(xs, f))
    if rate is not None:
        expr = expr - graph_to_sympy(rate, xs, ps)[0]
    return sympy.simplify(expr) == 0


@dataclass(frozen=True)
class Constraint:
    """``lower <= g(x[, t]) <= upper`` for every true state ``x`` (at time ``t``).

    ``graph`` takes the ODE's ``n`` states (plus the time as one more, last input when
    ``time_dependent``) and has ``m`` outputs; ``lower``/``upper`` have ``m`` entries
    (``-inf``/``inf`` for one-sided bounds). Parameters of the ODE are not available
    to constraints (bake exact values into the graph).
    """

    graph: Graph
    lower: tuple
    upper: tuple
    time_dependent: bool = False
    name: str = "constraint"

    def __post_init__(self):
        m = self.graph.n_outputs
        lo = np.broadcast_to(np.asarray(self.lower, dtype=float), (m,))
        hi = np.broadcast_to(np.asarray(self.upper, dtype=float), (m,))
        if np.isnan(lo).any() or np.isnan(hi).any() or (lo > hi).any():
            raise ValueError(f"{self.name}: bounds must satisfy lower <= upper (no NaN), got {lo}, {hi}")
        if self.graph.n_params:
            raise ValueError(f"{self.name}: constraint graphs cannot have parameters")
        object.__setattr__(self, "lower", tuple(lo))
        object.__setattr__(self, "upper", tuple(hi))

    @classmethod
    def equality(cls, graph: Graph, *, time_dependent: bool = False, name: str = "holonomic") -> "Constraint":
        """``g(x[, t]) = 0``, e.g. a holonomic constraint ``g(q, t) = 0``."""
        return cls(graph, (0.0,) * graph.n_outputs, (0.0,) * graph.n_outputs, time_dependent, name)

    @classmethod
    def bounds(cls, graph: Graph, lower=-np.inf, upper=np.inf, *, time_dependent: bool = False,
               name: str = "inequality") -> "Constraint":
        """``lower <= g(x[, t]) <= upper``, e.g. ``K(q, qd) <= K_max``."""
        return cls(graph, lower, upper, time_dependent, name)


@dataclass
class LiftedGraphs:
    """Everything a consistency test evaluates, over the solver's states.

    ``graph`` is the graph to integrate (``integrated`` with ``h`` appended when there
    is an energy); ``energy`` ``H`` over the ``n_s`` states, ``residual`` ``G = H(x) - h``
    over the ``n_s + 1`` states (0 on true trajectories), ``claim`` ``grad H . f - rate``
    over the ``n_s`` states (None when the rate is derived or not checked); all three
    None without an energy. ``constraints`` pairs each :class:`Constraint` with its
    graph over the ``n_aug`` states (plus the time last when time dependent).
    ``params`` are the ODE's parameters, passed to graphs that take them unless the
    solver carries them as states (``p_as_states``).
    """

    graph: Graph
    n_x: int
    n_s: int
    n_aug: int
    params: Interval | None
    p_as_states: bool
    energy: Graph | None = None
    residual: Graph | None = None
    claim: Graph | None = None
    constraints: tuple = ()

    def p(self, nb: int):
        """The parameters for a batch of ``nb`` sets (None when they are states)."""
        if self.params is None or self.p_as_states:
            return None
        p = self.params
        return p if p.ndim == 2 else p.broadcast_to((nb, p.shape[-1]))

    def eval(self, g: Graph, X: Interval, extra=None) -> Interval:
        """``g`` over the boxes ``X`` (B, k), ``extra`` (B, j) appended as inputs."""
        if extra is not None:
            X = concatenate([X, extra], axis=1)
        return g.eval_interval(X, self.p(X.shape[0]) if g.n_params else None)

    def jac(self, g: Graph, X: Interval, extra=None) -> Interval:
        """The Jacobian of ``g`` over the boxes ``X`` (B, m, k + j)."""
        if extra is not None:
            X = concatenate([X, extra], axis=1)
        return g.jacobian_interval(X, self.p(X.shape[0]) if g.n_params else None)


def lift_graphs(rhs: Graph, integrated: Graph, n_x: int, params: Interval | None, energy: Graph | None,
                energy_rate, constraints, *, check_claim: bool = True) -> LiftedGraphs:
    """Bind the declared energy and constraints to one solve: ``rhs`` is the user's ODE
    over ``(x, p)``; ``integrated`` the graph the solver runs (its parameters possibly
    turned into states after ``x``). ``energy_rate`` is "derive", "zero" or a Graph
    (:mod:`verified.energy_rate`)."""
    p_as_states = integrated.n_inputs > n_x
    n_s = integrated.n_inputs

    def lift(g: Graph) -> Graph:
        """``g`` over the solver's states (parameters as states if they are)."""
        if not p_as_states:
            return g
        b = GraphBuilder(n_s, 0, input_names=integrated.input_names)
        xs = [b.input(i) for i in range(n_s)]
        return b.build(embed(b, g, xs[:n_x], xs[n_x:n_x + g.n_params]), g.output_names)

    lifted_energy = residual = claim = None
    graph = integrated
    if energy is not None:
        if energy.n_inputs != n_x or energy.n_params != rhs.n_params:
            raise ValueError(f"the energy graph takes {energy.n_inputs} states and "
                             f"{energy.n_params} parameters; the ODE has {n_x} and {rhs.n_params}")
        if isinstance(energy_rate, Graph):
            rate = energy_rate
            if rate.n_inputs != n_x or rate.n_outputs != 1 or rate.n_params != rhs.n_params:
                raise ValueError("energy_rate must take the ODE's states and parameters and have one output")
        elif energy_rate == "derive":
            rate = rate_along(energy, rhs)
        else:
            rate = None
        if check_claim and energy_rate != "derive":
            # grad H . f - rate: identically 0 if the declared rate is right
            b = GraphBuilder(n_x, rhs.n_params, input_names=rhs.input_names, param_names=rhs.param_names)
            xs_ = [b.input(i) for i in range(n_x)]
            ps_ = [b.param(i) for i in range(rhs.n_params)]
            (d,) = embed(b, rate_along(energy, rhs), xs_, ps_)
            if rate is not None:
                d = b.sub(d, embed(b, rate, xs_, ps_)[0])
            claim = lift(b.build([d], ["dHdt claim residual"]))
        lifted_energy = lift(energy)
        graph = augment_with_rate(integrated, None if rate is None else lift(rate), name="h")
        residual = difference(lifted_energy, n_s + 1, n_s, name="H-h")  # 0 on true trajectories
    n_aug = graph.n_inputs
    lifted_constraints = []
    for c in constraints:
        k = c.graph.n_inputs - (1 if c.time_dependent else 0)
        if k != n_x:
            raise ValueError(f"constraint {c.name!r} takes {k} states; the ODE has {n_x}")
        b = GraphBuilder(n_aug + (1 if c.time_dependent else 0), 0)
        xs = [b.input(i) for i in range(len(b.input_names))]
        args = xs[:n_x] + ([xs[-1]] if c.time_dependent else [])
        lifted_constraints.append((c, b.build(embed(b, c.graph, args), c.graph.output_names)))
    return LiftedGraphs(graph=graph, n_x=n_x, n_s=n_s, n_aug=n_aug, params=params, p_as_states=p_as_states,
                        energy=lifted_energy, residual=residual, claim=claim,
                        constraints=tuple(lifted_constraints))


def refute_claim(lifted: LiftedGraphs, boxes: Interval, points: np.ndarray, t: float, energy_rate) -> None:
    """Raise :class:`EnergyClaimError` when ``grad H . f - rate`` excludes 0 over one
    of ``boxes`` (B, >= n_s) or at one of ``points`` (B, >= n_s): the declared
    rate is then wrong there (every true state of those boxes is a counterexample
    or the point is), and pruning with it would be unsound."""
    if lifted.claim is None:
        return
    n_s = lifted.n_s
    for what, X in (("at the point", point(np.asarray(points)[:, :n_s])), ("over the box", boxes[:, :n_s])):
        with np.errstate(all="ignore"):
            d = lifted.eval(lifted.claim, X)[:, 0]
        bad = (d.lo > 0) | (d.hi < 0)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            decl = "energy_rate='zero' (dH/dt = 0)" if isinstance(energy_rate, str) and energy_rate == "zero" else "the energy_rate graph"
            names = lifted.graph.input_names[:lifted.n_x]
            where = ", ".join(f"{nm}={v}" for nm, v in zip(names, (X[k].mid() if what == "over the box" else X[k].lo)))
            raise EnergyClaimError(
                f"the declared energy rate is wrong: grad H . f - dH/dt is in [{d.lo[k]:.6g}, {d.hi[k]:.6g}] "
                f"(excludes 0) {what} {where} (t = {t:g}); {decl} does not hold for this ODE, so the "
                "energy test cannot use it (pass energy_rate='derive', or fix the model)")

"""The graphs the consistency tests evaluate, lifted onto the solver's states (paper sec. 3/4).

This module owns the set-up half of :class:`verified.consistency.energy_test.EnergyTest`: what
the user declares (the energy ``H(x, p)`` in J, its rate ``dH/dt`` in W, constraints
``lower <= g(x[, t]) <= upper``) is turned into graphs over the states the verified
solver integrates, ``(x, [p as states], h)``:

- ``x``: the ODE's ``n_x`` states; ``p``: its parameters, appended as constant states
  when the solver carries them that way (``n_s = n_x + n_p`` inputs then, else
  ``n_s = n_x``);
- ``h``: ``H_V``, the energy integrated along the solution (eq. (12)), appended as one
  more state (``n_aug = n_s + 1`` with an energy, ``n_s`` without).

It also owns the declared-rate claim, because pruning or contracting with a wrong
rate removes true states. A rate given as ``"zero"`` or as a graph is

- used only when proven: :func:`prove_claim` shows ``grad H . f - rate`` identically
  0 with exact rational arithmetic, once per claim at set-up (deterministic, bounded
  by :data:`PROOF_MAX_TERMS` / :data:`PROOF_MAX_NODES`; sub-second on the paper's
  models). An interval check cannot prove such an identity (over a box around an
  equilibrium the residual of a false claim encloses 0 too), so an unproven claim
  is not used: ``h`` integrates the derived rate ``grad H . f`` instead (always
  right), and :class:`verified.consistency.energy_test.EnergyTest` says so with one
  :class:`EnergyClaimWarning`;
- refuted on intervals (:func:`refute_claim`) at the initial sets and over every
  step's tube, proven or not: a claim shown wrong somewhere raises
  :class:`EnergyClaimError` (the model contradicts its own declaration).

``check_claim=False`` skips both and uses the declaration as given (the caller vouches
for it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from verified.graph import Graph, GraphBuilder
from verified.graph.ops import augment_with_rate, difference, embed, rate_along
from verified.arith.interval import Interval, concatenate, point

__all__ = ["ClaimProof", "Constraint", "EnergyClaimError", "EnergyClaimWarning", "LiftedGraphs", "PROOF_MAX_NODES",
           "PROOF_MAX_TERMS", "claim_graph", "lift_graphs", "prove_claim", "prove_energy_rate", "refute_claim"]


class EnergyClaimError(ValueError):
    """A declared energy rate (``energy_rate="zero"`` or an ``energy_rate`` graph;
    :mod:`verified.consistency.energy_rate`) is refuted: ``grad H . f - rate`` excludes 0 somewhere.
    Pruning or contracting with it would remove true states."""


class EnergyClaimWarning(UserWarning):
    """A declared energy rate could not be proven (:func:`prove_claim`): the energy test
    integrates the derived rate ``grad H . f`` instead of it (sound, see
    :func:`lift_graphs`)."""


#: the most terms (numerator plus denominator) any intermediate rational function of
#: :func:`prove_claim` may have before the proof gives up: above the shipped proofs,
#: below the sizes that take minutes (docs/lab/code_notes.md)
PROOF_MAX_TERMS = 1000

#: claim graphs with more nodes are not tried (the sympy expressions alone take long)
PROOF_MAX_NODES = 20000


@dataclass(frozen=True)
class ClaimProof:
    """The outcome of :func:`prove_claim`: ``proven``, else ``reason`` says why not."""

    proven: bool
    reason: str = ""


class _GiveUp(Exception):
    """The proof stops: the claim is not proven (the message says why)."""


def _exact_domain():
    """A :class:`verified.graph.evaluate.Domain` that evaluates a graph exactly into sympy
    expressions that are rational functions of symbols (no sin, cos, ...), with the
    relations those symbols satisfy:

    - a constant known exactly (``lo == hi``) is that double as a sympy Rational; an
      enclosed one (``lo < hi``: pi, 1/3, ...) a symbol per enclosure, so that what is
      proven holds for every value in it. Constants with the same enclosure are taken
      as one number (as :class:`verified.graph.GraphBuilder` merges them into one
      node), the negated enclosure as its negative;
    - ``sin u``, ``cos u``: sums and integer multiples in ``u`` are expanded
      (``sin(a + b) = ...``), the rest become symbols ``S, C`` per argument with the
      relation ``S^2 + C^2 = 1``; ``tan u = S / C``;
    - ``sqrt, exp, log, atan`` of an argument: one symbol per (function, argument),
      with no relation (an identity that needs one is not proven);
    - ``mid`` (a point the graph may choose freely, e.g. a preconditioner): a fresh
      symbol per node, so the proof holds for every choice.
    """
    import sympy

    from verified.graph.evaluate import Domain

    class ExactDomain(Domain):
        def __init__(self):
            self.pairs = {}     # argument -> (S, C): the sin and cos of a symbol-like argument
            self.opaque = {}    # (function, argument) -> symbol
            self.consts = {}    # (lo, hi) -> symbol
            self.mid_symbols = []

        def const(self, lo, hi, value):
            if not (np.isfinite(lo) and np.isfinite(hi)):
                raise _GiveUp(f"a constant [{lo}, {hi}] is not finite")
            if lo == hi:
                return sympy.Rational(float(lo))
            key = (float(lo), float(hi))
            if key not in self.consts:
                if (-key[1], -key[0]) in self.consts:
                    return -self.consts[(-key[1], -key[0])]
                self.consts[key] = sympy.Symbol(f"_c{len(self.consts)}", real=True)
            return self.consts[key]

        def sqr(self, a):
            return a**2

        def pow(self, a, k):
            return a**int(k)

        def _symbol(self, fn, a):
            key = (fn, a)
            if key not in self.opaque:
                self.opaque[key] = sympy.Symbol(f"_{fn}{len(self.opaque)}", real=True)
            return self.opaque[key]

        def sqrt(self, a):
            return self._symbol("sqrt", a)

        def exp(self, a):
            return self._symbol("exp", a)

        def log(self, a):
            return self._symbol("log", a)

        def atan(self, a):
            return self._symbol("atan", a)

        def _sincos(self, u):
            """(sin u, cos u) as rational expressions in the pair symbols."""
            if u == 0:
                return sympy.Integer(0), sympy.Integer(1)
            if u.is_Add:
                s1, c1 = self._sincos(u.args[0])
                s2, c2 = self._sincos(sympy.Add(*u.args[1:]))
                return s1 * c2 + c1 * s2, c1 * c2 - s1 * s2
            k, v = u.as_coeff_Mul()
            if k.is_Integer and k != 1 and v != 1 and 0 < abs(int(k)) <= 8:
                s1, c1 = self._sincos(v)
                s, c = s1, c1
                for _ in range(abs(int(k)) - 1):
                    s, c = s * c1 + c * s1, c * c1 - s * s1
                return (s, c) if k > 0 else (-s, c)
            if u not in self.pairs:
                i = len(self.pairs)
                self.pairs[u] = (sympy.Symbol(f"_S{i}", real=True), sympy.Symbol(f"_C{i}", real=True))
            return self.pairs[u]

        def sin(self, a):
            return self._sincos(a)[0]

        def cos(self, a):
            return self._sincos(a)[1]

        def tan(self, a):
            s, c = self._sincos(a)
            return s / c

        def mid(self, a):
            self.mid_symbols.append(sympy.Symbol(f"_m{len(self.mid_symbols)}", real=True))
            return self.mid_symbols[-1]

    return ExactDomain()


def _to_field(expr, field, gens: dict, max_terms: int):
    """``expr`` (Add, Mul, integer Pow of symbols and rationals) as an element of the
    rational function field, each distinct subexpression converted once; gives up when
    an intermediate result has more than ``max_terms`` terms."""
    import sympy

    memo = {}

    def check(r):
        n = len(r.numer) + len(r.denom)
        if n > max_terms:
            raise _GiveUp(f"an intermediate rational function has more than {max_terms} terms "
                          "(PROOF_MAX_TERMS)")
        return r

    stack = [(expr, False)]
    while stack:
        u, ready = stack.pop()
        if u in memo:
            continue
        if u.is_Symbol:
            memo[u] = gens[u]
        elif u.is_Rational:
            memo[u] = field(sympy.QQ(int(u.p), int(u.q)))
        elif u.is_Add or u.is_Mul or (u.is_Pow and u.exp.is_Integer):
            args = (u.base,) if u.is_Pow else u.args
            if not ready:
                stack.append((u, True))
                stack.extend((a, False) for a in args if a not in memo)
                continue
            if u.is_Pow:
                k = int(u.exp)
                r = check(memo[u.base] ** abs(k))
                r = r if k >= 0 else check(r ** -1)
            else:
                r = memo[args[0]]
                for a in args[1:]:
                    r = check(r + memo[a] if u.is_Add else r * memo[a])
            memo[u] = r
        else:
            raise _GiveUp(f"it contains {type(u).__name__} ({str(u)[:60]})")
    return memo[expr]


def _symbols_of(expr) -> set:
    """The symbols in ``expr``, each distinct subexpression visited once (sympy's
    ``free_symbols`` walks shared subexpressions again each time: exponential on the
    expressions of a graph)."""
    seen, out, stack = set(), set(), [expr]
    while stack:
        u = stack.pop()
        if u in seen:
            continue
        seen.add(u)
        if u.is_Symbol:
            out.add(u)
        else:
            stack.extend(u.args)
    return out


_PROOFS: dict = {}  # claim graph -> ClaimProof (the proof is deterministic; graphs are hashable)


def prove_claim(claim: Graph, max_terms: int | None = None) -> ClaimProof:
    """Prove that the claim graph (one output, ``grad H . f - rate`` over ``(x, p)``) is
    identically 0, exactly, for every state and every parameter value.

    The graph is evaluated into a rational function of the states, the parameters and
    symbols for what is not rational (:func:`_exact_domain`); it is proven 0 when the
    numerator of that rational function, reduced modulo ``S^2 + C^2 - 1`` for every
    sine/cosine pair (a Groebner basis: the leading terms share no variable), is the
    zero polynomial, and the denominator is not. Exact rational arithmetic throughout
    (no floating point, no heuristic simplification): a proof is a proof. Not proven:
    the claim does not reduce to 0 (it may be false, may hold only through a relation
    the reduction does not know, or may rest on rounded constants, e.g. an inertia 1/3
    enclosed in the ODE but rounded to a double in ``H``), or deciding it needs more
    than ``max_terms`` (:data:`PROOF_MAX_TERMS`) terms or the graph has more than
    :data:`PROOF_MAX_NODES` nodes. Deterministic; cached per claim graph."""
    max_terms = PROOF_MAX_TERMS if max_terms is None else int(max_terms)
    key = (claim, max_terms)
    if key not in _PROOFS:
        if len(_PROOFS) >= 256:
            _PROOFS.pop(next(iter(_PROOFS)))
        _PROOFS[key] = _prove_claim(claim, max_terms)
    return _PROOFS[key]


def _prove_claim(claim: Graph, max_terms: int) -> ClaimProof:
    if len(claim.nodes) > PROOF_MAX_NODES:
        return ClaimProof(False, f"the claim graph has {len(claim.nodes)} nodes, more than the proof tries "
                                 f"(PROOF_MAX_NODES = {PROOF_MAX_NODES})")
    # (import here: sympy, ~0.4 s, only for this symbolic proof)
    import sympy

    from verified.graph.evaluate import evaluate
    try:
        domain = _exact_domain()
        xs = sympy.symbols(f"_x0:{claim.n_inputs}", real=True)
        ps = sympy.symbols(f"_p0:{claim.n_params}", real=True) if claim.n_params else ()
        (expr,) = evaluate(claim, domain, list(xs), list(ps))
        expr = sympy.sympify(expr)
        if expr == 0:
            return ClaimProof(True)
        used = _symbols_of(expr)
        pairs = [p for p in domain.pairs.values() if p[0] in used or p[1] in used]
        gens = sorted(used | {g for p in pairs for g in p}, key=lambda g: g.name)
        field, *elements = sympy.field(gens, sympy.QQ)
        gmap = dict(zip(gens, elements))
        value = _to_field(expr, field, gmap, max_terms)
        relations = [gmap[s].numer ** 2 + gmap[c].numer ** 2 - 1 for s, c in pairs]
        numer, denom = value.numer, value.denom
        if relations:
            numer, denom = numer.rem(relations), denom.rem(relations)
        if numer != 0:
            return ClaimProof(False, "grad H . f - dH/dt does not reduce to 0")
        if denom == 0:
            return ClaimProof(False, "its denominator reduces to 0")
        return ClaimProof(True)
    except _GiveUp as e:
        return ClaimProof(False, f"the proof gave up: {e}")
    except (NotImplementedError, TypeError, ValueError, ZeroDivisionError, RecursionError) as e:
        return ClaimProof(False, f"the proof gave up: {type(e).__name__}: {str(e)[:80]}")


def claim_graph(rhs: Graph, energy: Graph, rate: Graph | None) -> Graph:
    """``(x, p) -> [grad H . f - rate]`` (``rate`` None: the claim ``dH/dt = 0``):
    identically 0 if the declared rate is right."""
    b = GraphBuilder(rhs.n_inputs, rhs.n_params, input_names=rhs.input_names, param_names=rhs.param_names)
    xs_ = [b.input(i) for i in range(rhs.n_inputs)]
    ps_ = [b.param(i) for i in range(rhs.n_params)]
    (d,) = embed(b, rate_along(energy, rhs), xs_, ps_)
    if rate is not None:
        d = b.sub(d, embed(b, rate, xs_, ps_)[0])
    return b.build([d], ["dHdt claim residual"])


def prove_energy_rate(rhs: Graph, energy: Graph, rate: Graph | None) -> bool:
    """Whether ``grad H . f - rate`` is proven identically 0 (``rate`` None: the claim
    ``dH/dt = 0``) by :func:`prove_claim`. False: not proven (no refutation: that is
    :func:`refute_claim`'s)."""
    return prove_claim(claim_graph(rhs, energy, rate)).proven


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
    None without an energy. ``proof`` is the :class:`ClaimProof` of a declared rate
    (None when none was checked); when it failed, ``graph`` integrates ``grad H . f``.
    ``constraints`` pairs each :class:`Constraint` with its graph over the ``n_aug``
    states (plus the time last when time dependent).
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
    proof: ClaimProof | None = None
    constraints: tuple = ()

    @property
    def rate_unproven(self) -> bool:
        """A rate was declared and checked, but not proven: ``graph`` integrates the
        derived rate ``grad H . f`` instead of it."""
        return self.proof is not None and not self.proof.proven

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
    (:mod:`verified.consistency.energy_rate`).

    A declared rate ("zero" or a Graph) is integrated into ``h`` only when
    :func:`prove_claim` proves ``grad H . f - rate`` identically 0; otherwise ``h``
    integrates the derived rate ``grad H . f`` (``proof`` says why; the caller warns).
    ``check_claim=False``: the declared rate is used as given, neither proven nor
    refuted (the caller vouches for it: a wrong rate removes true states)."""
    p_as_states = integrated.n_inputs > n_x
    n_s = integrated.n_inputs

    def lift(g: Graph) -> Graph:
        """``g`` over the solver's states (parameters as states if they are)."""
        if not p_as_states:
            return g
        b = GraphBuilder(n_s, 0, input_names=integrated.input_names)
        xs = [b.input(i) for i in range(n_s)]
        return b.build(embed(b, g, xs[:n_x], xs[n_x:n_x + g.n_params]), g.output_names)

    lifted_energy = residual = claim = proof = None
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
            # grad H . f - rate: identically 0 if the declared rate is right. It is used
            # only when proven; else the derived rate (always right) replaces it. The
            # claim stays, for refute_claim (a refuted claim is a wrong model).
            residual_x = claim_graph(rhs, energy, rate)
            proof = prove_claim(residual_x)
            claim = lift(residual_x)
            if not proof.proven:
                rate = rate_along(energy, rhs)
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
                        energy=lifted_energy, residual=residual, claim=claim, proof=proof,
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

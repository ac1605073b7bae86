"""Conserved and non-increasing quantities of any ODE as contractors (issue 43 item 2).

A caller declares a scalar quantity ``I(x, p)`` of the ODE ``x' = f(x, p)`` and passes
it as ``solve(..., invariants=[...])``:

- :class:`Conserved` ``(I)``: ``I`` is constant along every solution. The claim is
  *proven* when the run is set up: ``dI/dt = grad I . f`` must reduce to 0 identically,
  exactly (rational arithmetic on the expression graph,
  :func:`verified.consistency.graphs.prove_claim`); an unproven claim is a one-line
  ``ValueError`` before any work. A linear invariant is given by its weights,
  ``Conserved([1, 1, 1])`` for ``x + y + z``.
- :class:`NonIncreasing` ``(I, rate=None)``: ``I`` never rises. Checked soundly at every
  step: an interval enclosure of ``dI/dt`` over the step's a-priori enclosure (the tube:
  every solution stays in it over the step) must be ``<= 0``, else the bound is raised
  by what the step may have added (below). ``rate``, a graph of
  ``dI/dt`` in simpler form (``-d qd^2`` rather than ``grad H . f``, which interval
  arithmetic cannot show to be <= 0 where terms cancel), is used only once proven
  identically equal to ``grad I . f`` (else a ``ValueError``).

The level. For a conserved ``I`` every solution keeps the value it started with, so
``I(x(t)) in K`` for all ``t``, with ``K`` an enclosure of ``I`` over the sets the run
starts from (exact for a linear ``I`` over boxes; natural and mean-value form
intersected otherwise). For a non-increasing ``I``, ``I(x(t)) <= L`` with ``L`` the upper
end of that enclosure. Where the check gives only ``dI/dt <= r`` with ``r > 0`` on a step
(the claim not shown there, or only up to rounding), ``I`` rose by at most ``r h`` on it:
the new ``L`` is the smaller of ``L + r h`` and the upper bound of ``I`` over the sets at
the step's end (both hold for every true state), so the contraction is never tighter
than what is proven. Those steps are counted (``stats["invariant_unverified_steps"]``,
the total rise ``stats["invariant_level_rise"]``) and, when ``L`` rose by more than
1e-9, reported by one ``InvariantWarning``.

The contraction, after every accepted step, for each set and each invariant:

0. a linear conserved ``w . x = k`` is imposed on the set itself: with the error part
   absorbed into the set's parameters (``x = c + C u + q(u)``, exact), the state ``i``
   with the widest ``|w_i| x_i`` is rewritten as ``x_i = (k - sum_{j != i} w_j x_j) / w_i``
   over the same parameters, the floats' rounding and the spread of ``k`` over ``K``
   enclosed in the new error part (``r_i``). Every true state keeps its parameters, so it
   stays in the set, and ``w . x`` over the set is ``K`` up to rounding. Kept only where
   the set's hull in ``x_i`` does not get wider or, where the spread of ``w . x`` over the
   set is more than twice ``K``'s (mostly wrapping), at most ``growth`` (25 %) wider (the
   error removed along ``w`` no longer grows from step to step);
1. (a nonlinear or non-increasing ``I``) the set's own parameters (``x = c + A r``,
   ``r in R``, first- and second-order sets)
   are narrowed with the row ``I(c + A r) in K`` in mean-value form
   (:func:`verified.consistency.contractor.mean_value_row`, Gauss-Seidel with
   :func:`verified.consistency.contractor.contract_linear_row`), then recentred, as the energy
   contraction does (:mod:`verified.consistency.energy_contraction`): the set keeps its shape and
   holds every true state it held;
2. the set's hull is contracted to ``I in K``: for a linear ``I`` exactly (each variable
   bounded by the level minus the others, :func:`~verified.consistency.contractor.contract_linear_row`
   on the box: the interval hull of the slab ``w . x in K`` met with the box), else by
   HC4 (:class:`verified.consistency.contractor.HC4`). Where that box is narrower than ``cut`` (0.9)
   times the set's hull in some component, the set is replaced by the box (a fresh set
   of the same kind), as :class:`verified.consistency.energy_shell.EnergyShellHook` does.

A set proven to hold no state with ``I in K`` holds no true state and is dropped; if
every set is dropped the claim was false and the run stops with a breakdown.

Soundness contract: with the claims proven (conserved) or checked (non-increasing) as
above, every true state the sets enclosed before the contraction is enclosed after it.
Parameters carried as states (uncertain ones) are the columns after the ``n`` states;
fixed parameters are taken from the run. States appended by other hooks are left as
they are.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from verified.consistency.graphs import claim_graph, prove_claim
from verified.consistency.contractor import HC4, contract_linear_row, mean_value_row
from verified.consistency.energy_contraction import recentre
from verified.consistency.energy_shell import reset_to_contracted
from verified.graph.evaluate import eval_interval
from verified.graph import Graph, GraphBuilder
from verified.graph.ops import embed, rate_along
from verified.driver.hooks import Hook, RunSetup
from verified.driver.user_warnings import warn_at_caller
from verified.arith.interval import Interval, concatenate, point
from verified.sets.second_order import QuadraticSets, quadratic_range
from verified.sets.first_order import DoubletonSets

__all__ = ["Conserved", "NonIncreasing", "InvariantHook", "InvariantWarning", "invariant_hook"]

_SET_TYPES = (DoubletonSets, QuadraticSets)


class InvariantWarning(UserWarning):
    """A declared non-increasing quantity could not be checked on some steps: the
    contraction was not applied there (``stats["invariant_unverified_steps"]``)."""


def _I(lo, hi=None) -> Interval:
    lo = np.asarray(lo, float)
    return Interval._from_bounds(lo, lo if hi is None else np.asarray(hi, float))


class _Declared:
    """What a declaration says, before it meets an ODE."""

    kind = ""

    def __init__(self, expr, *, name: str | None = None):
        if isinstance(expr, Graph) or callable(expr):
            self.weights = None
        else:
            try:
                w = np.asarray(expr, dtype=float)
            except (TypeError, ValueError):
                raise ValueError(f"an invariant is a Graph, a callable f(x, p) or a sequence of weights, "
                                 f"got {type(expr).__name__}") from None
            if w.ndim != 1 or w.size == 0:
                raise ValueError(f"invariant weights must be a 1-D sequence (one per state), got shape {w.shape}")
            if not np.all(np.isfinite(w)):
                raise ValueError(f"invariant weights must be finite numbers, got {w.tolist()}")
            if not np.any(w != 0):
                raise ValueError("invariant weights are all 0: that declares nothing")
            self.weights = w
        self.expr = expr
        if name is not None and not isinstance(name, str):
            raise ValueError(f"name must be a string, got {name!r}")
        self.name = name

    def __repr__(self):
        return f"{type(self).__name__}({self.name or self.expr!r})"

    # ------------------------------------------------------------------ binding
    def graph_for(self, rhs: Graph) -> Graph:
        """``I`` as a graph over the ODE's states and parameters (one output)."""
        n, p = rhs.n_inputs, rhs.n_params
        if self.weights is not None:
            if self.weights.size != n:
                raise ValueError(f"invariant {self.label(rhs)}: {self.weights.size} weights for an ODE of {n} states")
            b = GraphBuilder(n, p, input_names=rhs.input_names, param_names=rhs.param_names)
            terms = [b.mul(b.const(float(w)), b.input(i)) if w != 1 else b.input(i)
                     for i, w in enumerate(self.weights) if w != 0]
            s = terms[0]
            for t in terms[1:]:
                s = b.add(s, t)
            return b.build([s], ["I"])
        if isinstance(self.expr, Graph):
            g = self.expr
            if g.n_outputs != 1 or g.n_inputs != n or g.n_params != p:
                raise ValueError(f"invariant {self.label(rhs)}: the graph must map the ODE's {n} states and {p} "
                                 f"parameters to one value, got {g.n_inputs} inputs, {g.n_params} parameters, "
                                 f"{g.n_outputs} outputs")
            return g
        from verified.graph.tracer import trace

        fn = self.expr

        def one(x, q):
            v = fn(x, q)
            if isinstance(v, (list, tuple)):
                if len(v) != 1:
                    raise ValueError(f"invariant {self.label(rhs)}: the callable must return one value, got {len(v)}")
                v = v[0]
            return [v]
        return trace(one, n, p, input_names=rhs.input_names, param_names=rhs.param_names, output_names=["I"])

    def label(self, rhs: Graph | None = None) -> str:
        if self.name:
            return repr(self.name)
        if self.weights is not None and rhs is not None and len(rhs.input_names) == self.weights.size:
            parts = [(f"{w:g} " if w != 1 else "") + nm for w, nm in zip(self.weights, rhs.input_names) if w != 0]
            return repr(" + ".join(parts))
        return f"#{id(self) % 10000}"


class Conserved(_Declared):
    """``I(x, p)`` is constant along every solution of the ODE.

    Args:
        expr: the weights of a linear ``I = w . x`` (one per state), a
            :class:`~verified.graph.Graph` ``(x, p) -> [I]`` over the ODE's states and
            parameters, or a callable ``f(x, p) -> I`` (traced).
        name: shown in messages and records.

    ``solve(..., invariants=[Conserved(...)])`` proves ``grad I . f = 0`` identically
    before the run (a ``ValueError`` when it cannot) and contracts the sets to
    ``I in K`` after every step (module docstring).
    """

    kind = "conserved"


class NonIncreasing(_Declared):
    """``I(x, p)`` does not increase along any solution of the ODE.

    Args:
        expr: as for :class:`Conserved`.
        rate: optional Graph ``(x, p) -> [dI/dt]``: proven identically equal to
            ``grad I . f`` before the run (a ``ValueError`` when it cannot), then
            checked ``<= 0`` on every step; without it ``grad I . f`` is checked.
        name: shown in messages and records.

    The sets are contracted to ``I <= L`` after every step on which the check holds
    (module docstring).
    """

    kind = "non_increasing"

    def __init__(self, expr, *, rate: Graph | None = None, name: str | None = None):
        super().__init__(expr, name=name)
        if rate is not None and not isinstance(rate, Graph):
            raise ValueError(f"rate must be a verified.graph.Graph (x, p) -> [dI/dt], got {type(rate).__name__}")
        self.rate = rate


class _Bound:
    """A declaration bound to an ODE: ``graph`` I over (x, p), ``rate`` dI/dt over
    (x, p) (None for a conserved one: it is 0), ``weights`` or None."""

    def __init__(self, decl: _Declared, rhs: Graph):
        self.decl = decl
        self.kind = decl.kind
        self.label = decl.label(rhs)
        self.graph = decl.graph_for(rhs)
        self.weights = decl.weights
        self.rate = None
        if decl.kind == "conserved":
            proof = prove_claim(claim_graph(rhs, self.graph, None))
            if not proof.proven:
                raise ValueError(f"invariant {self.label} is not proven conserved "
                                 f"({proof.reason.replace('grad H . f - dH/dt', 'grad I . f')}); "
                                 "declare it NonIncreasing to have it checked on every step, or fix it")
        else:
            rate = getattr(decl, "rate", None)
            if rate is not None:
                if rate.n_outputs != 1 or rate.n_inputs != rhs.n_inputs or rate.n_params != rhs.n_params:
                    raise ValueError(f"invariant {self.label}: rate must map the ODE's {rhs.n_inputs} states and "
                                     f"{rhs.n_params} parameters to one value, got {rate.n_inputs} inputs, "
                                     f"{rate.n_params} parameters, {rate.n_outputs} outputs")
                proof = prove_claim(claim_graph(rhs, self.graph, rate))
                if not proof.proven:
                    raise ValueError(f"invariant {self.label}: its rate is not proven equal to grad I . f "
                                     f"({proof.reason.replace('grad H . f - dH/dt', 'grad I . f - rate')}); "
                                     "leave rate=None to have grad I . f checked on every step")
                self.rate = rate
            else:
                self.rate = rate_along(self.graph, rhs, "dIdt")


def bind_invariants(invariants, rhs: Graph) -> list[_Bound]:
    """The declarations checked and proven against ``rhs`` (one-line ValueErrors)."""
    if isinstance(invariants, _Declared):
        invariants = [invariants]
    if isinstance(invariants, (str, bytes)) or not hasattr(invariants, "__iter__"):
        raise ValueError(f"invariants must be a sequence of Conserved / NonIncreasing, got {invariants!r}")
    out = []
    for d in invariants:
        if not isinstance(d, _Declared):
            raise ValueError(f"invariants: each entry must be a verified.consistency.conservation.Conserved or NonIncreasing, "
                             f"got {type(d).__name__} (for weights write Conserved([...]))")
        out.append(_Bound(d, rhs))
    return out


def invariant_hook(invariants, rhs: Graph, *, cut: float = 0.9) -> "InvariantHook | None":
    """The :class:`InvariantHook` of ``invariants`` for the ODE ``rhs`` (None for an
    empty list); raises ``ValueError`` for a bad or unproven declaration."""
    bound = bind_invariants(invariants, rhs)
    return InvariantHook(bound, cut=cut) if bound else None


class InvariantHook(Hook):
    """Contract the sets to the declared invariants after every step (module docstring).

    Built by :func:`invariant_hook` (``solve(..., invariants=...)`` does it). ``cut``:
    a set is replaced by its contracted hull box when that box is narrower than ``cut``
    times the set's hull in some component (in (0, 1]; 1: whenever it narrows at all).
    ``growth``: how much wider (relative) the rewritten state of a linear invariant's
    projection may get (step 0; 0: only where it does not widen).
    Records in ``Solution.stats``: ``invariant_levels`` ({label: (lo, hi)} at the end),
    ``invariant_projected`` (sets rewritten onto a linear invariant), ``invariant_narrowed``
    (sets whose parameters were narrowed), ``invariant_resets``, ``invariant_dropped``,
    ``invariant_unverified_steps``, ``invariant_level_rise``.
    """

    def __init__(self, bound: Sequence[_Bound], *, cut: float = 0.9, growth: float = 0.25):
        if not 0.0 < float(cut) <= 1.0:
            raise ValueError(f"cut must be in (0, 1], got {cut!r}")
        if not 0.0 <= float(growth) < np.inf:
            raise ValueError(f"growth must be a number >= 0, got {growth!r}")
        self.bound = list(bound)
        self.cut, self.growth = float(cut), float(growth)
        self._reset_counts()

    def _reset_counts(self):
        self.narrowed = self.resets = self.dropped = self.unverified = self.projected = 0
        self.rise = 0.0
        self.levels = [None] * len(self.bound)

    # ------------------------------------------------------------------ set-up
    def before_run(self, setup: RunSetup):
        self._reset_counts()
        g = setup.user_graph
        self.n, self.p = g.n_inputs, g.n_params
        self.carried = self.p > 0 and setup.params is None
        if self.carried and setup.graph.n_inputs < self.n + self.p:
            raise ValueError("invariants: the run carries fewer parameter states than the ODE has parameters")
        P = setup.params
        if P is not None and self.p:
            P = P if isinstance(P, Interval) else _I(P)
            if P.ndim == 2:
                P = Interval._from_bounds(P.lo.min(axis=0), P.hi.max(axis=0))
        self.P = P if self.p and not self.carried else None
        self.ny = self.n + (self.p if self.carried else 0)   # the columns the invariants read
        # graphs over the first ny set columns (params: the fixed ones, if any)
        self._gy = [self._over_columns(b.graph) for b in self.bound]
        self._ry = [None if b.rate is None else self._over_columns(b.rate) for b in self.bound]
        self._hc4 = [None if b.weights is not None else HC4(self._params_as_inputs(b.graph)) for b in self.bound]
        Y = self._y(setup.sets.hull())
        for k, b in enumerate(self.bound):
            v = self._enclose(k, setup.sets, Y)
            lo, hi = float(np.min(v.lo)), float(np.max(v.hi))
            if not (np.isfinite(lo) and np.isfinite(hi)):
                raise ValueError(f"invariant {b.label} is unbounded over the initial sets")
            self.levels[k] = (lo if b.kind == "conserved" else -np.inf, hi)
        return None

    def _over_columns(self, g: Graph) -> Graph:
        """``g(x, p)`` as a graph of the ``ny`` set columns (carried parameters read
        from their columns; fixed ones stay parameters)."""
        npar = 0 if self.carried else self.p
        b = GraphBuilder(self.ny, npar)
        xs = [b.input(i) for i in range(self.n)]
        ps = [b.input(self.n + i) for i in range(self.p)] if self.carried else [b.param(i) for i in range(npar)]
        return b.build(embed(b, g, xs, ps))

    def _params_as_inputs(self, g: Graph) -> Graph:
        """``g`` over the ``n + p`` columns (x, p): what HC4 contracts (a fixed
        parameter's column is its value, appended to the hull)."""
        b = GraphBuilder(self.n + self.p, 0)
        xs = [b.input(i) for i in range(self.n + self.p)]
        return b.build(embed(b, g, xs[:self.n], xs[self.n:]))

    def _y(self, H: Interval) -> Interval:
        """The first ``ny`` columns of boxes (B, N)."""
        return H[:, :self.ny]

    def _xp(self, Y: Interval) -> Interval:
        """(B, n + p): the state columns and the parameters (carried, or fixed ones appended)."""
        if self.P is None:
            return Y
        B = Y.shape[0]
        return concatenate([Y, self.P.broadcast_to((B, self.p))], axis=1)

    def _pp(self, B: int):
        return None if self.P is None else self.P.broadcast_to((B, self.p))

    def _enclose(self, k: int, sets, Y: Interval) -> Interval:
        """``I_k`` over each set: its natural enclosure over the hull met with the
        mean-value form over the set's parameters (first- and second-order sets)."""
        g = self._gy[k]
        v = eval_interval(g, Y, self._pp(Y.shape[0]))[..., 0]
        if type(sets) in _SET_TYPES:
            c, A, R = self._linear_view(sets)
            with np.errstate(all="ignore"):
                a, g0, rem = mean_value_row(g, c, A, R, 0.0, self._pp(Y.shape[0]))
                mv = g0 + (_I(a) * R).sum(axis=-1) + rem
            ok = np.isfinite(mv.lo) & np.isfinite(mv.hi) & (mv.lo <= v.hi) & (v.lo <= mv.hi)
            v = _I(np.where(ok, np.maximum(v.lo, mv.lo), v.lo), np.where(ok, np.minimum(v.hi, mv.hi), v.hi))
        return v

    def _linear_view(self, sets):
        A = sets.direction_columns()
        R = concatenate([sets.r0, sets.r], axis=1)
        c = np.asarray(sets.c, float)[:, :self.ny]
        A = A[:, :self.ny, :] if isinstance(A, Interval) else np.asarray(A)[:, :self.ny, :]
        return c, A, R

    # ------------------------------------------------------------------ each step
    def after_step(self, step, sets, run):
        out = sets
        for k, b in enumerate(self.bound):
            if b.kind == "non_increasing":
                self._update_level(k, step, out)
            if type(out) not in _SET_TYPES or out.n_sets == 0:
                continue
            if b.kind == "conserved" and b.weights is not None:
                out = self._project(k, out)
            res = self._contract(k, out)
            if res is None:
                run.stop(f"invariant {b.label} in [{self.levels[k][0]:g}, {self.levels[k][1]:g}] excludes every set "
                         f"at t = {step.t:g}: the declaration is false", "breakdown")
                return None if out is sets else out
            out = res
        return None if out is sets else out

    def _update_level(self, k: int, step, sets) -> None:
        """The bound ``L`` of a non-increasing ``I`` after the step: where ``dI/dt <= r``
        over the step's a-priori enclosure with some ``r > 0`` (the claim not shown on
        this step, or only up to rounding), ``I`` rose by at most ``r h``; ``L`` becomes the
        smaller of ``L + r h`` and the bound of ``I`` over the sets at the step's end
        (both hold for every true state)."""
        Y = self._y(step.tube)
        with np.errstate(all="ignore"):
            r = float(np.max(eval_interval(self._ry[k], Y, self._pp(Y.shape[0]))[..., 0].hi))
        if r <= 0.0:
            return
        self.unverified += 1
        old = self.levels[k][1]
        h = float(step.h.hi) if isinstance(step.h, Interval) else float(step.h)
        grown = np.nextafter(old + np.nextafter(r * h, np.inf), np.inf) if np.isfinite(r) else np.inf
        if not grown <= old + 1e-12 * (1.0 + abs(old)):
            v = self._enclose(k, sets, self._y(sets.hull()))
            here = float(np.max(v.hi))
            grown = min(grown, here) if np.isfinite(here) else grown
        self.levels[k] = (-np.inf, float(grown))
        self.rise += float(grown) - old if np.isfinite(grown) and np.isfinite(old) else np.inf

    def _contract_params(self, k: int, sets, K: Interval):
        """Step 1 of the module docstring: ``(sets, empty (B,))``, the sets' own
        parameters narrowed by the mean-value row ``I(c + A r) in K``."""
        B = sets.n_sets
        c, A, R = self._linear_view(sets)
        g = self._gy[k]
        with np.errstate(all="ignore"):
            a, g0, rem = mean_value_row(g, c, A, R, 0.0, self._pp(B))
            ok = np.isfinite(a).all(axis=1) & np.isfinite(g0.lo) & np.isfinite(g0.hi) \
                & np.isfinite(rem.lo) & np.isfinite(rem.hi)
            a = np.where(ok[:, None], a, 0.0)
            G = g0 - K
            G = _I(np.where(ok, G.lo, -np.inf), np.where(ok, G.hi, np.inf))
            Rn, empty = contract_linear_row(a, G, R, rem, sweeps=2)
        empty &= ok
        changed = (Rn.lo > R.lo) | (Rn.hi < R.hi)
        narrowed = changed.any(axis=1) & ~empty
        out = sets
        if narrowed.any():
            idx = np.flatnonzero(narrowed)
            out = out.replaced(idx, self._with_params(sets, idx, Rn[idx]))
            self.narrowed += idx.size
        return out, empty

    def _contract(self, k: int, sets):
        """The sets contracted to ``I_k in K`` (None: every set proven empty)."""
        lo, hi = self.levels[k]
        K = _I(lo, hi)
        B = sets.n_sets
        out = sets
        empty = np.zeros(B, bool)
        if self.bound[k].weights is None or self.bound[k].kind != "conserved":
            out, empty = self._contract_params(k, sets, K)
        # 2. the hull box: exact for a linear invariant, HC4 otherwise
        H = out.hull()
        Y = self._xp(self._y(H))
        with np.errstate(all="ignore"):
            if self.bound[k].weights is not None:
                w = np.zeros(Y.shape[1])
                w[:self.n] = self.bound[k].weights
                Yn, e2 = contract_linear_row(w, -K, Y, sweeps=2)
            else:
                res = self._hc4[k].contract(Y, np.full(1, lo), np.full(1, hi), max_iter=3)
                Yn, e2 = res.boxes, res.empty
        empty |= e2
        keep = ~empty
        if not keep.any():
            return None
        m = self.ny
        out, resets, dropped = reset_to_contracted(out, H, np.asarray(Yn.lo)[:, :m], np.asarray(Yn.hi)[:, :m],
                                                   keep, self.cut)
        self.resets += resets
        self.dropped += dropped
        return out

    #: parameters per state column a projection may leave a set with before it merges
    #: the least wide ones (as the steppers cap theirs)
    PARAMS_PER_STATE = 12

    def _project(self, k: int, sets):
        """Step 0 of the module docstring: the sets with ``w . x in K`` imposed on
        their parametrization (where that does not widen the rewritten state)."""
        n = self.n
        w = self.bound[k].weights
        K = _I(*self.levels[k])
        B, N = sets.c.shape
        r_zero = bool(np.all(sets.r.lo == 0) and np.all(sets.r.hi == 0))
        if r_zero:  # (no error part: Q r = 0 whatever Q is)
            base = sets
        else:
            base = sets
            cap = self.PARAMS_PER_STATE * N
            m = base.C.shape[2]
            if m + N > cap and hasattr(base, "merge_params"):
                base = base.merge_params(m + 2 * N - cap, keep_first=N, steer=self.ny)
                if base.C.shape[2] + N > cap:
                    return sets
            base = base.absorb_error()
        quad = isinstance(base, QuadraticSets)
        old = sets.hull()
        score = np.where(w[None, :] != 0, np.abs(w)[None, :] * old.width()[:, :n], -1.0)
        piv = np.argmax(score, axis=1)
        rows = np.arange(B)
        wi = point(w[piv])                                            # (B,)
        wm = np.where(np.arange(n)[None, :] == piv[:, None], 0.0, w[None, :])  # (B, n): w_j, j != i
        c, C, r0 = base.c, base.C, base.r0
        with np.errstate(all="ignore"):
            c_exact = (K - (point(wm) * point(c[:, :n])).sum(axis=1)) / wi
            c_new = c_exact.mid()
            C_exact = -(point(wm[:, :, None]) * point(C[:, :n, :])).sum(axis=1) / wi[:, None]
            C_new = C_exact.mid()
            e = (c_exact - c_new) + ((C_exact - C_new) * r0).sum(axis=1)
            if quad:
                S_exact = -(point(wm[:, :, None, None]) * point(base.S[:, :n])).sum(axis=1) / wi[:, None, None]
                S_new = S_exact.mid()
                e = e + quadratic_range((S_exact - S_new)[:, None], r0)[:, 0]
        c2, C2 = c.copy(), C.copy()
        c2[rows, piv], C2[rows, piv, :] = c_new, C_new
        rlo, rhi = np.zeros((B, N)), np.zeros((B, N))
        rlo[rows, piv], rhi[rows, piv] = e.lo, e.hi
        eye = np.broadcast_to(np.eye(N), (B, N, N)).copy()
        if quad:
            S2 = base.S.copy()
            S2[rows, piv] = S_new
            new = QuadraticSets(c=c2, C=C2, r0=r0, S=S2, Q=eye, r=_I(rlo, rhi))
        else:
            new = DoubletonSets(c2, C2, r0, eye, _I(rlo, rhi))
        new = new.recentred()
        if r_zero:  # (base kept its Q: the unchanged sets must keep it too)
            base = type(base)(**{**base.__dict__, "Q": eye}) if quad else DoubletonSets(c, C, r0, eye, base.r)
        nw = new.hull().width()[rows, piv]
        # widening x_i is allowed only where most of w . x's spread over the set is excess
        # over K (wrapping to remove), not the spread of K itself: allowed every step
        # on a wide K it would compound
        cs, As, Rs = self._linear_view(sets)
        with np.errstate(all="ignore"):
            wA = (point(np.broadcast_to(w, (B, n))[:, :, None]) * (As[:, :n, :] if isinstance(As, Interval)
                                                                   else point(As[:, :n, :]))).sum(axis=1)
            spread = (wA * Rs).sum(axis=1).width()
        excess = spread > 2.0 * float(K.width())
        allowed = np.where(excess, 1.0 + self.growth, 1.0) * old.width()[rows, piv]
        take = np.isfinite(nw) & np.isfinite(e.lo) & np.isfinite(e.hi) & (nw <= allowed)
        if not take.any():
            return sets
        idx = np.flatnonzero(take)
        self.projected += idx.size
        return base.replaced(idx, new.take(idx))

    @staticmethod
    def _with_params(sets, idx, Rk: Interval):
        """The sets ``idx`` with their parameter boxes ``(r0, r)`` replaced by ``Rk`` and
        recentred (a box that no longer holds 0 is shifted; the shift's rounding is
        enclosed, :func:`verified.consistency.energy_contraction.recentre`)."""
        m = sets.C.shape[2]
        if isinstance(sets, QuadraticSets):
            return QuadraticSets(c=sets.c[idx], C=sets.C[idx], r0=Rk[:, :m], S=sets.S[idx], Q=sets.Q[idx],
                                 r=Rk[:, m:]).recentred()
        part = DoubletonSets(sets.c[idx], sets.C[idx], Rk[:, :m], sets.Q[idx], Rk[:, m:])
        off = ~((Rk.lo <= 0) & (0 <= Rk.hi)).all(axis=1)
        if off.any():
            j = np.flatnonzero(off)
            part = part.replaced(j, recentre(part.c[j], part.C[j], part.r0[j], part.Q[j], part.r[j]))
        return part

    def after_run(self, solution) -> None:
        st = solution.stats
        st["invariant_levels"] = {b.label: tuple(lv) for b, lv in zip(self.bound, self.levels) if lv is not None}
        st["invariant_projected"] = st.get("invariant_projected", 0) + self.projected
        st["invariant_narrowed"] = st.get("invariant_narrowed", 0) + self.narrowed
        st["invariant_resets"] = st.get("invariant_resets", 0) + self.resets
        st["invariant_dropped"] = st.get("invariant_dropped", 0) + self.dropped
        st["invariant_unverified_steps"] = st.get("invariant_unverified_steps", 0) + self.unverified
        st["invariant_level_rise"] = st.get("invariant_level_rise", 0.0) + self.rise
        if self.unverified and not self.rise <= 1e-9:
            names = ", ".join(b.label for b in self.bound if b.kind == "non_increasing")
            warn_at_caller(InvariantWarning(
                f"dI/dt <= 0 could not be verified on {self.unverified} step(s) for {names}: its bound rose by "
                f"{self.rise:.3g} in all (to what the enclosure shows; a rate graph in simpler form may help)"))

# Whole: one stepper and the Taylor-model helpers only it uses (issue 44: one recursion).
"""Second-order sets advanced by composing the Taylor map with the set in Taylor models.

:class:`verified.steppers.second_order.QuadraticStepper` advances a set ``c + C u + q(u) + Q r``
by the Taylor map's derivatives at the centre (second variational equations) and
bounds the third-order rest by the Hessian's spread over the set,
``1/2 (H(U) - H(c))[v, v]``. Over a deep model graph that spread is taken in affine
or degree-2 Taylor-model arithmetic over the whole set, and it is what stops the
robots (issue 17: many times the sampled spread; docs/lab/code_notes.md).

Here the step is the composition itself, as COSY-VI, Flow* and TaylorModels.jl do
it: the set is written as a degree-2 Taylor model over its own symbols,

    x  =  c + sum_j a_j eps_j + sum_{j <= k} s_jk eps_j eps_k + sum_l b_l delta_l,

``eps`` the set's parameters ``u = rho eps`` (``rho`` = the magnitude of ``r0``) and
``delta`` the error vector ``r = mid r + rad r delta``, every symbol in ``[-1, 1]``
(the floats' rounding in a remainder). The Taylor coefficients ``x_[k]``, ``k < K``,
of the solutions from that model are computed in Taylor-model arithmetic of degree 3
(:mod:`verified.series.taylor_model`: the graph's Taylor recursion, quadratic terms exact,
cubic ones exact in the ``CUBIC_CAP`` widest parameters, the higher orders and rounding
in a rigorous remainder per operation; degree 2 on request, or degree 4 with quartic
terms exact in the ``QUARTIC_CAP`` widest), and

    phi(h, x)  in  sum_{k<K} x_[k](x) h^k  +  h^K x_[K](E)

with the Lagrange remainder over the a-priori enclosure ``E`` (as every step here).
The result's linear and quadratic parts in ``eps`` become ``C'`` and ``S'`` (the new
parameter box is ``[-1, 1]`` per live symbol), its linear part in ``delta`` (the
step's Jacobian acting on the error, a float matrix) carries the error part into the
new basis (Lohner's QR or a plain box, by ``error_basis``), and the rest (remainder,
cubic terms, quadratic terms in ``delta``, the Lagrange term) is the error the step
injects. Degree 3 pays because a robot's graph cancels most of its cubic terms:
bounded operation by operation at degree 2, they made the remainder of a robot's qdd
many times its true non-quadratic part (docs/lab/code_notes.md). No variational
equations are integrated and
no Jacobian or Hessian is enclosed over the set: higher-order effects are bounded
where they arise, operation by operation, on the set's own symbols.

Two things keep those bounds from feeding on themselves over a long run:

* *Fresh symbols per coefficient* (``fresh_symbols``, on by default): once ``x_[k]_i``
  is computed, its remainder becomes the coefficient of a symbol of its own
  (:meth:`verified.series.taylor_model.TaylorModelODE._run`), so the later orders of the
  recursion carry it linearly, with its cancellations, instead of multiplying a
  radius through every operation of the graph. The step bounds those symbols' terms with the
  rest of the error. Without them the high orders' remainders grow with every order and
  the step-size cut holds the steps short (docs/lab/code_notes.md).
* *Star monomials* (``star_cap``, :mod:`verified.series.taylor_model`): the widest symbols'
  products with every other symbol of the set are kept, not bounded. A set that
  absorbs its error gathers dozens of narrow parameters past the quadratic cap; their
  cross terms with the wide ones, bounded per operation, fed the error they came from
  and ended robot runs early (docs/lab/code_notes.md).

* *Symbols for the remainders born inside the graph* (``pool_cap``, default ``POOL`` =
  128; ``solve(model_caps={"pool": ...})``): at the first ``POOL_ORDERS`` = 3 orders of
  the recursion, the first slots of the model graph whose remainder is more than
  ``POOL_TOL`` of their magnitude get a symbol of their own for it
  (:meth:`verified.series.taylor_model.TaylorModelODE._run`), so what one product bounds is
  carried linearly through the rest of the graph (the tube's coefficients, order 0). On a robot the
  remainder of ``qdd`` is born in the bias products, spread over every joint's torque
  and recombined by the mass-matrix solve, where the values cancel and independent
  radii did not. The step bounds these symbols' terms with the fresh ones. Robots reach
  further with them, other systems as before (docs/lab/code_notes.md).

Rigor: the input models enclose the set (every float product's rounding is added
to the remainder), the model kernel is checked against arb
(``tests/verified/test_taylor_model.py``), the Horner sum in models rounds into the
remainder (:func:`_horner_models`), and the conversion back is exact up to the
halving of off-diagonal quadratic coefficients (exact for normal floats; a tiny
absolute term covers subnormals).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from verified.arith import _kernels as _k
from verified.arith import linalg
from verified.series.affine_taylor import box_forms
from verified.arith.interval import Interval, _k_round_up, point
from verified.steppers.lohner import LohnerStepper, _inflate, taylor_step
from verified.steppers.protocol import REMAINDER_SLACK
from verified.sets.second_order import QuadraticSets
from verified.sets.protocol import SetView
from verified.steppers.protocol import StepResult
from verified.series.taylor_model import (
    _acc_add, _pairs, _scale_into, _star_pairs, forms_to_models, model_length, models_to_interval, star_base
)

__all__ = ["TaylorModelFlowStepper", "set_models", "ModelCaps", "tube_view", "tube_coefficients", "step_tube"]

#: default cap on the symbols with cubic monomials in degree-3 arithmetic (the set's
#: widest parameters first); a product costs O(cap^3). See TaylorModelFlowStepper.
CUBIC_CAP = 6

#: default cap on the symbols with quartic monomials in degree-4 arithmetic (the widest
#: first, within the cubic ones); a product costs O(cap^4). See TaylorModelFlowStepper.
QUARTIC_CAP = 4

#: default cap on the symbols with quadratic monomials (the set's widest parameters
#: first, then the widest error directions); a product costs O(cap^2)
QUADRATIC_CAP = 16

#: the caps (quadratic, cubic) for systems of at most ``SMALL_SYSTEM`` states (up to 4
#: degrees of freedom, plus an appended energy state), where the step's products are
#: cheap: there larger caps reach further or tighter at moderate cost; above, the
#: smaller caps stay (docs/lab/code_notes.md)
SMALL_SYSTEM_CAPS = (32, 16)
SMALL_SYSTEM = 9

#: default number of the widest symbols whose products with every symbol past the
#: quadratic cap are kept as star monomials (verified.series.taylor_model); a product costs
#: O(cap * symbols) more. See TaylorModelFlowStepper.
STAR_CAP = 6


#: the Taylor models in which the a-priori test takes ``x_[K]`` over the candidate tube
#: (:func:`tube_coefficients`): the tube's widest symbols (the step's motion first) with
#: quadratic monomials, the widest of them cubic ones: ``x_[K]`` over the tube much
#: narrower than in affine arithmetic (docs/lab/code_notes.md)
TUBE_QUADRATIC_CAP = 8
TUBE_CUBIC_CAP = 2


class ModelCaps(NamedTuple):
    """The monomials of the models over a set's symbols (:func:`verified.series.taylor_model.model_length`
    takes them in this order: ``model_length(M, *caps)``): the first ``mq`` symbols
    with quadratic monomials, the first ``m3`` cubic, the first ``m4`` quartic, and the
    first ``ms`` with star monomials reaching the ``ns`` symbols after the quadratic
    ones (the rest of the set's symbols; fresh symbols appended later get none)."""

    mq: int
    m3: int
    m4: int
    ms: int
    ns: int


def _spread_about(rng: Interval, centre: np.ndarray) -> np.ndarray:
    """Upper bound of ``|x - centre|`` over the intervals ``rng`` (same shape)."""
    return np.maximum(_k_round_up(centre - rng.lo), _k_round_up(rng.hi - centre))


def set_models(sets: QuadraticSets, quadratic_cap: int = QUADRATIC_CAP, cubic_cap: int = 0, quartic_cap: int = 0,
               star_cap: int = 0, steer: int | None = None):
    """Taylor models enclosing the sets ``c + C u + q(u) + Q r`` (module docstring),
    over ``M = mu + n`` symbols: the ``mu`` live parameters (widest first) and the ``n``
    components of ``r``.

    Returns ``(X, live, errors, rho, caps)``: ``X`` (n, B, L) the models (``L =
    model_length(M, *caps)``; the cubic and quartic parts, room for the arithmetic's,
    are zero),
    ``live`` (mu,) the parameter columns in symbol order, ``errors`` (n,) the components
    of ``r`` in symbol order (widest first: they follow the parameters, and the first of
    them may still get quadratic monomials), ``rho`` (B, m) the magnitudes of ``r0``
    (``u = rho eps``), ``caps`` a :class:`ModelCaps`: the symbols with quadratic,
    cubic, quartic and star monomials (the first ones). The quadratic terms of a pair
    of parameters that is neither within the first ``mq`` nor a star pair (one of the
    first ``ms`` with one past ``mq``) are bounded into the remainder.

    ``steer``: the widths that order the symbols are taken over the first ``steer``
    states only (None: all). A state appended by a hook (the energy test's ``h``, in
    J) would otherwise give its own parameters and its error the monomials the states
    need: the paper's double pendulum from one box broke down earlier in mode ii than
    without the test (docs/lab/code_notes.md)."""
    nb, n = sets.c.shape
    rho = sets.r0.mag()  # r0 within [-rho, rho]: u = rho eps covers it
    reach = np.abs(sets.C) * rho[:, None, :] + np.einsum("bijk,bk->bij", np.abs(sets.S), rho) * rho[:, None, :]
    width = reach.sum(axis=1).max(axis=0)  # (m,)
    # parameters below 1e-12 of the widest (a zero-width start leaves some at 1e-323)
    # would take symbols, and the quadratic monomials of the first ones, for nothing:
    # they are bounded into the remainder instead (below)
    is_live = width > (width.max() if width.size else 0.0) * 1e-12
    live = np.flatnonzero(is_live)
    rank = width if steer is None else reach[:, :steer].sum(axis=1).max(axis=0)
    live = live[np.lexsort((-width[live], -rank[live]))]  # by the steering states' width, then all
    dead = np.flatnonzero(~is_live & (width > 0))
    mu = live.size
    M = mu + n
    mq = min(M, max(int(quadratic_cap), 0))
    m3 = min(mq, max(int(cubic_cap), 0))
    m4 = min(m3, max(int(quartic_cap), 0))
    ms = min(mq, max(int(star_cap), 0))
    caps = ModelCaps(mq, m3, m4, ms, M - mq)
    mqu = min(mu, mq)  # parameters with quadratic monomials
    L = model_length(M, *caps)
    X = np.zeros((n, nb, L))
    err = np.zeros((nb, n))
    if dead.size:
        # every term with a dead parameter: C_ij u_j, and S_ijk u_j u_k with j or k dead
        # (S symmetric: twice the rows of the dead ones)
        lin = np.abs(sets.C[:, :, dead]) * rho[:, None, dead]
        quad = np.einsum("bijk,bk->bij", np.abs(sets.S[:, :, dead, :]), rho) * rho[:, None, dead]
        err += (lin + 2.0 * quad).sum(axis=-1) * (1.0 + 2.0**-40) + 1e-300

    # centre: c + Q mid(r)
    mr = sets.r.mid()
    centre = point(sets.c) + linalg.matvec(sets.Q, point(mr))
    X[:, :, 0] = centre.mid().T
    err += centre.rad()
    # linear in eps: C rho (live columns)
    if mu:
        a = Interval(sets.C[:, :, live]) * point(rho[:, None, live])  # (B, n, mu)
        X[:, :, 1: mu + 1] = a.mid().transpose(1, 0, 2)
        err += a.rad().sum(axis=-1)
    # linear in delta: Q rad(r)
    rr = sets.r.rad()
    b = Interval(sets.Q) * point(rr[:, None, :])  # (B, n, n)
    bm = np.abs(b.mid())
    errors = np.lexsort((-bm.sum(axis=1).max(axis=0), -bm[:, :steer].sum(axis=1).max(axis=0)))
    X[:, :, mu + 1: M + 1] = b.mid()[:, :, errors].transpose(1, 0, 2)
    err += b.rad().sum(axis=-1)
    # quadratic in eps: S_jj rho_j^2 on the diagonal, (S_jk + S_kj) rho_j rho_k off it
    if mu:
        Sl = sets.S[:, :, live][:, :, :, live]  # (B, n, mu, mu)
        rl = rho[:, live]
        pi, pj = _pairs(mq)
        inside = pj < mqu  # pairs among the quadratic parameters (pi <= pj)
        qi, qj = pi[inside], pj[inside]
        sym = Interval(Sl[:, :, qi, qj]) + Interval(np.where(qi == qj, 0.0, Sl[:, :, qj, qi]))
        coef = sym * point(rl[:, None, qi]) * point(rl[:, None, qj])
        # (rho_j rho_k as a product of two points: each multiplication rounds outward)
        idx = M + 1 + np.flatnonzero(inside)
        X[:, :, idx] = coef.mid().transpose(1, 0, 2)
        err += coef.rad().sum(axis=-1)
        # star: (S_jk + S_kj) rho_j rho_k for j < ms, k a parameter past mq
        si, sj = _star_pairs(M, mq, ms, caps.ns)
        on = (si < mqu) & (sj < mu)  # (mu <= mq leaves none: the star's symbols past mq are errors)
        if on.any():
            ti, tj = si[on], sj[on]
            sym = Interval(Sl[:, :, ti, tj]) + Interval(Sl[:, :, tj, ti])
            coef = sym * point(rl[:, None, ti]) * point(rl[:, None, tj])
            idx = star_base(M, mq, m3, m4) + np.flatnonzero(on)
            X[:, :, idx] = coef.mid().transpose(1, 0, 2)
            err += coef.rad().sum(axis=-1)
        if mqu < mu:
            # quadratic terms with a parameter past mq (and not a star pair): |S_jk| rho_j
            # rho_k into the remainder
            outside = np.ones((mu, mu), dtype=bool)
            outside[:mqu, :mqu] = False
            if on.any():
                outside[ti, tj] = False
                outside[tj, ti] = False
            absS = np.abs(Sl) * outside
            bound = Interval(absS) * point(rl[:, None, :, None]) * point(rl[:, None, None, :])
            err += bound.hi.sum(axis=(-1, -2)) * (1.0 + 2.0**-40)
    X[:, :, -1] = (err * (1.0 + 2.0**-40) + 1e-300).T  # (float sums of up to ~4000 terms)
    bad = ~(np.isfinite(X).all(axis=(0, 2)))
    if bad.any():
        X[:, bad, :] = 0.0
        X[:, bad, -1] = np.inf
    return X, live, errors, rho, caps


def tube_view(models: np.ndarray, M: int, mq: int) -> SetView:
    """The a-priori enclosure's models (n, B, L) over ``M`` symbols (the set's and one
    per power of ``s / h``, :meth:`TaylorModelFlowStepper.apriori`) as a
    :class:`verified.sets.protocol.SetView`: ``x = c + A' p`` with ``A = [linear part | I]``,
    ``p`` the ``M`` symbols in ``[-1, 1]`` and, per state, the range of the rest (the
    monomials of degree 2 and more and the remainder, rounded outward). Every solution
    from the set stays in the models' range over the step, so it is some ``c + A' p``.
    Why: the frames over the tube (:mod:`mbs.frames`) are then taken in mean-value form
    over these symbols, not over the tube's hull box (the step's motion and the set's
    shape stay lines in it)."""
    n, nb, _ = models.shape
    c = np.ascontiguousarray(models[:, :, 0].T)
    A = np.zeros((nb, n, M + n))
    A[:, :, :M] = models[:, :, 1: M + 1].transpose(1, 0, 2)
    A[:, np.arange(n), M + np.arange(n)] = 1.0
    rest = models.copy()
    rest[:, :, : M + 1] = 0.0
    lo, hi = models_to_interval(rest, M, mq)  # (n, B)
    R = Interval._from_bounds(np.concatenate([-np.ones((nb, M)), lo.T], axis=1),
                              np.concatenate([np.ones((nb, M)), hi.T], axis=1))
    return SetView(c=c, A=Interval._from_bounds(A, A), R=R)  # (a point matrix: one array for both bounds)


def tube_coefficients(models, tube: np.ndarray, M: int, mq: int, order: int, params=None,
                      quadratic_cap: int = TUBE_QUADRATIC_CAP, cubic_cap: int = TUBE_CUBIC_CAP,
                      pool: int = 0) -> Interval:
    """Enclosures (B, order + 1, n) of the Taylor coefficients ``x_[0..order]`` over a
    tube given as models ``tube`` (n, B, L) over ``M`` symbols (``mq`` of them with
    quadratic monomials), in Taylor models of their own made for a tube
    (:class:`verified.series.taylor_model.TaylorModelODE` ``models``; ``params`` an Interval
    (B, p) or None).

    A tube is not a set: the step's motion (the first time symbol) is its widest
    direction, and its remainder (the a-priori box) is wide too. So the tube's models
    are taken back to affine forms, each state's remainder becomes the coefficient of a
    symbol of its own, the symbols are sorted by width (the widest ``quadratic_cap``
    get quadratic monomials, the widest ``cubic_cap`` cubic ones: the motion's curvature
    is carried, not bounded per operation) and the recursion runs with fresh symbols
    per coefficient (:meth:`~verified.series.taylor_model.TaylorModelODE.series`). A remainder
    on a symbol of its own is carried linearly through the graph, with its
    cancellations, where a model's remainder is multiplied by every operation. Sound:
    the tube's points are ``p(e) + r`` with ``r`` in the per-state remainder box, each
    ``r_i = rad_i delta_i`` for some ``delta_i`` in ``[-1, 1]``; the symbols' order and
    caps change only which products are kept. ``pool``: symbols for the remainders born
    inside the graph at order 0 (:meth:`~verified.series.taylor_model.TaylorModelODE._run`).

    Against fresh symbols per order in affine arithmetic: ``x_[K]`` over the tube much
    narrower at about the same cost, hence longer steps (docs/lab/code_notes.md)."""
    F = models_to_forms(tube, M, mq)  # (n, B, M + 2)
    n, nb, _ = F.shape
    rem = np.zeros((n, nb, n))
    rem[np.arange(n), :, np.arange(n)] = F[:, :, -1]
    forms = np.concatenate([F[:, :, : M + 1], rem, np.zeros((n, nb, 1))], axis=2)  # (n, B, M + n + 2)
    q = min(int(quadratic_cap), M + n)
    with np.errstate(over="ignore", invalid="ignore"):
        return models.series(forms, order, params, caps=(q, min(int(cubic_cap), q), 0, 0), fresh=True, pool=pool)


def more_symbols(X: np.ndarray, M: int, extra: int) -> np.ndarray:
    """The models ``X`` (..., L) over ``M`` symbols as models over ``M + extra`` with the
    same caps (the new symbols last, every coefficient of theirs 0: their linear ones
    are inserted, every block after them keeps its place relative to the end)."""
    out = np.zeros(X.shape[:-1] + (X.shape[-1] + extra,))
    out[..., : M + 1] = X[..., : M + 1]
    out[..., M + extra + 1:] = X[..., M + 1:]
    return out


def fold_symbols(X: np.ndarray, M: int, M_all: int) -> np.ndarray:
    """The models ``X`` (..., L) over ``M_all`` symbols as models over the first ``M``:
    the linear terms of the others bounded into the remainder (they have no other
    monomials: fresh symbols, past every cap)."""
    if M_all == M:
        return X
    out = np.concatenate([X[..., : M + 1], X[..., M_all + 1:]], axis=-1)
    with np.errstate(over="ignore", invalid="ignore"):
        out[..., -1] = _k_round_up(X[..., -1] + np.abs(X[..., M + 1: M_all + 1]).sum(axis=-1) * (1.0 + 2.0**-40))
    return out


def models_to_forms(X: np.ndarray, M: int, mq: int) -> np.ndarray:
    """Affine forms (..., M + 2) enclosing the models (..., L): the centre and linear
    coefficients kept, every quadratic monomial (in [-1, 1]) bounded into the error."""
    F = np.zeros(X.shape[:-1] + (M + 2,))
    F[..., : M + 1] = X[..., : M + 1]
    with np.errstate(over="ignore", invalid="ignore"):
        q = np.abs(X[..., M + 1: -1]).sum(axis=-1)
        F[..., -1] = (X[..., -1] + q) * (1.0 + 2.0**-40) + 1e-300
    F[..., -1] = np.where(np.isnan(F[..., -1]), np.inf, F[..., -1])
    return F


@njit(cache=True)
def _horner_models(out, h):
    """``sum_k out[:, k] h^k`` in model arithmetic (float ``h``), rounding into the
    remainder: out (n, K, B, L) -> (n, B, L)."""
    n, K, nb, L = out.shape
    y = np.zeros((n, nb, L))
    Z = np.zeros(L)
    T = np.zeros(L)
    for i in range(n):
        for b in range(nb):
            Z[:] = out[i, K - 1, b]
            for k in range(K - 2, -1, -1):
                _scale_into(T, Z, h)
                _acc_add(T, out[i, k, b], 1.0)
                Z[:] = T
            y[i, b] = Z
    return y


@njit(cache=True)
def _derivative_models(out):
    """The models of ``d/dt sum_k out[:, k] t^k``: ``(k + 1) out[:, k + 1]``, rounding into
    the remainder: out (n, K, B, L) -> (n, K - 1, B, L)."""
    n, K, nb, L = out.shape
    d = np.zeros((n, K - 1, nb, L))
    for i in range(n):
        for k in range(1, K):
            for b in range(nb):
                _scale_into(d[i, k - 1, b], out[i, k, b], float(k))
    return d


#: sub-intervals of a step over which :func:`step_tube` bounds the solutions
TUBE_PIECES = 4


@njit(cache=True)
def _horner_at(out, taus):
    """:func:`_horner_models` at each of the times ``taus`` (P,): (P, n, B, L)."""
    n, K, nb, L = out.shape
    y = np.zeros((taus.size, n, nb, L))
    for j in range(taus.size):
        y[j] = _horner_models(out, taus[j])
    return y


def _model_ranges(F: np.ndarray, M: int, mq: int) -> Interval:
    """Ranges of models (..., n, B, L) as intervals (..., B, n)."""
    lo, hi = models_to_interval(F, M, mq)
    return Interval._from_bounds(np.ascontiguousarray(np.swapaxes(lo, -1, -2)),
                                 np.ascontiguousarray(np.swapaxes(hi, -1, -2)))


def step_tube(out: np.ndarray, cE: Interval, h_top: float, M: int, mq: int, pieces: int = TUBE_PIECES) -> Interval:
    """A box (B, n) holding every solution from the sets over a step of length at most
    ``h_top``, narrower than the a-priori enclosure ``E`` the step was validated with.

    ``out`` (n, K, B, L): the models of the Taylor coefficients ``x_[0..K-1]`` over the
    sets' symbols; ``cE`` (B, K + 1, n): the coefficients over ``E``. By Taylor's theorem
    with ``x_[K]`` over ``E``, at every ``tau`` in ``[0, h_top]``

        x(tau)  in  sum_k x_[k] tau^k + cE_K tau^K,
        x'(tau) in  sum_k k x_[k] tau^(k-1) + K cE_K tau^(K-1)

    (the second is the theorem for ``x'``, whose ``(K-1)``-th derivative is ``x^(K)``).
    Both are taken at ``pieces + 1`` points ``tau_j`` as models, whose ranges keep the
    dependence on the set's symbols. Between two points, ``x(tau_j + d) in x(tau_j) +
    x'(tau_j) d + cE_2 d^2`` for ``d`` in ``[0, tau_j+1 - tau_j]`` (``cE_2`` encloses
    ``x''/2`` over ``E``), and the same from the right end; the box is the hull over the
    pieces of the two bounds' intersection. The a-priori enclosure holds the step's
    motion with the slack of its validation; this box is about the sets' own width plus
    the motion, which is what a bound checked on the tube (a spec, a frame) needs."""
    K = out.shape[1]
    h_top = float(h_top)
    if not (0.0 <= h_top < 1e300 and pieces >= 1 and cE.shape[1] > max(K, 2)):
        return _step_tube_np(out, cE, h_top, M, mq, pieces)  # (and its errors)
    out = np.ascontiguousarray(out)
    taus = np.array([h_top * j / pieces for j in range(pieces)] + [h_top])
    xlo, xhi = models_to_interval(_horner_at(out, taus), M, mq)  # (P, n, B)
    vlo, vhi = models_to_interval(_horner_at(_derivative_models(out), taus), M, mq)
    # the interval expressions of _step_tube_np in one compiled pass, bit for bit
    lo, hi = _k.tube_box_bounds(_k.kernel_array(xlo), _k.kernel_array(xhi), _k.kernel_array(vlo),
                                _k.kernel_array(vhi), _k.kernel_array(cE.lo), _k.kernel_array(cE.hi), taus, K)
    return Interval._from_bounds(lo, hi)


def _step_tube_np(out: np.ndarray, cE: Interval, h_top: float, M: int, mq: int, pieces: int = TUBE_PIECES) -> Interval:
    """:func:`step_tube` in interval arithmetic on arrays: the reference its compiled pass
    (``_kernels.tube_box_bounds``) is tested against, and its path for arguments that
    the compiled pass does not take (a step of no finite length, no pieces)."""
    K = out.shape[1]
    out = np.ascontiguousarray(out)
    taus = np.array([h_top * j / pieces for j in range(pieces)] + [h_top])
    return _tube_box_np(_model_ranges(_horner_at(out, taus), M, mq),
                        _model_ranges(_horner_at(_derivative_models(out), taus), M, mq), cE, taus, K)


def _tube_box_np(Xr: Interval, Vr: Interval, cE: Interval, taus: np.ndarray, K: int) -> Interval:
    """The interval part of :func:`_step_tube_np`: ``Xr``, ``Vr`` (P, B, n) the ranges of
    the models of ``x(tau_j)`` and ``x'(tau_j)`` (without the Lagrange terms)."""
    pieces = taus.size - 1
    t = Interval(taus)[:, None, None]                                    # (P, 1, 1)
    cK, c2 = cE[:, K][None], cE[:, 2][None]                               # (1, B, n)
    X = Xr + cK * t ** K          # (P, B, n)
    V = Vr + K * (cK * t ** (K - 1))
    d = Interval(np.zeros(pieces), (Interval(taus[1:]) - Interval(taus[:-1])).hi)[:, None, None]
    bend = c2 * d ** 2
    left = X[:-1] + V[:-1] * d + bend
    right = X[1:] - V[1:] * d + bend
    both = left.intersect(right)
    # (an empty intersection cannot hold a true solution; left alone keeps the box sound anyway)
    empty = both.is_empty()
    lo = np.where(empty, left.lo, both.lo).min(axis=0)
    hi = np.where(empty, left.hi, both.hi).max(axis=0)
    return Interval._from_bounds(lo, hi)


class TaylorModelFlowStepper(LohnerStepper):
    """Verified steps of :class:`~verified.sets.second_order.QuadraticSets` by composition in
    degree-2 Taylor models (module docstring).

    ``taylor``: the evaluator of Taylor coefficients over boxes (step size and a-priori
    enclosure, as every stepper); ``models``: a
    :class:`verified.series.taylor_model.TaylorModelODE` of the same graph; ``degree`` (2, 3 or
    4) that of the arithmetic, with ``cubic_cap`` symbols carrying cubic monomials
    (``quadratic_cap`` / ``cubic_cap`` None: ``SMALL_SYSTEM_CAPS`` for at most
    ``SMALL_SYSTEM`` states, else ``QUADRATIC_CAP`` / ``CUBIC_CAP``; larger caps cost
    more for next to nothing, docs/lab/code_notes.md) and, at degree 4, ``quartic_cap``
    of them quartic ones. The error part is absorbed
    into parameters as :class:`~verified.steppers.second_order.QuadraticStepper` does (``absorb_ratio``,
    up to ``max_params``, default 12 per state, then merged).

    ``star_cap``: the widest symbols that get star monomials (default ``STAR_CAP`` = 6;
    0: none); without them robots break down early (docs/lab/code_notes.md).
    ``fresh_symbols`` (None: ``FRESH_SYMBOLS``, True): see the module docstring.
    ``min_order`` (None: every step at ``order``): each step's order in ``[min_order,
    order]``, chosen from the last step (:meth:`_next_order`): on robots under a
    controller the growth cut, not the series' last term, sets the steps, and a lower
    order takes the same steps for less (docs/lab/robot_speed.md).
    ``pool_cap`` (None: ``POOL`` = 128; 0: off): the symbols the remainders born inside
    the model graph may claim (module docstring; needs ``fresh_symbols``).

    ``absorb_ratio`` None (default): 1 % of the carried width for systems of 6 states or
    more, 10 % (as the mean-value step) below. Why early on robots: the error part is a
    box in a basis, wrapped every step, and over a thousand steps of a robot the
    wrapping, not the injected error, is what grows it; parameters are carried
    exactly. Small systems lose by it: every absorbed parameter past the quadratic cap
    is one more symbol whose products are bounded (docs/lab/code_notes.md)."""

    def __init__(self, taylor, models, order: int, params=None, error_basis="qr", max_params: int | None = None,
                 quadratic_cap: int | None = None, degree: int = 3, cubic_cap: int | None = None,
                 absorb_ratio: float | None = None, quartic_cap: int = QUARTIC_CAP, star_cap: int = STAR_CAP,
                 fresh_symbols: bool | None = None, pool_cap: int | None = None, min_order: int | None = None):
        if absorb_ratio is None:
            absorb_ratio = 0.01 if taylor.n >= 6 else 0.1
        super().__init__(taylor, None, order, params, error_basis, absorb=bool(np.isfinite(absorb_ratio)),
                         max_params=12 * taylor.n if max_params is None else max_params)
        self.absorb_ratio = float(absorb_ratio)
        self.models = models
        small = taylor.n <= SMALL_SYSTEM
        if quadratic_cap is None:
            quadratic_cap = SMALL_SYSTEM_CAPS[0] if small else QUADRATIC_CAP
        if cubic_cap is None:
            cubic_cap = SMALL_SYSTEM_CAPS[1] if small else CUBIC_CAP
        self.quadratic_cap = int(quadratic_cap)
        if degree not in (2, 3, 4):
            raise ValueError(f"degree must be 2, 3 or 4, got {degree!r}")
        self.cubic_cap = int(cubic_cap) if degree >= 3 else 0
        self.quartic_cap = int(quartic_cap) if degree == 4 else 0
        if int(star_cap) < 0:
            raise ValueError(f"star_cap must be >= 0, got {star_cap!r}")
        self.star_cap = int(star_cap)
        self.fresh_symbols = self.FRESH_SYMBOLS if fresh_symbols is None else bool(fresh_symbols)
        if pool_cap is not None and int(pool_cap) < 0:
            raise ValueError(f"pool_cap must be >= 0, got {pool_cap!r}")
        self.pool_cap = self.POOL if pool_cap is None else int(pool_cap)
        if min_order is not None and not 2 <= int(min_order) <= self.order:
            raise ValueError(f"min_order must be None or an integer in [2, order = {self.order}], got {min_order!r}")
        self.min_order = None if min_order is None else int(min_order)
        self.max_order = self.order
        self._pending_order = None
        #: with ``min_order``: {order: steps taken at it} (``Solution.stats["steps_by_order"]``)
        self.steps_by_order: dict[int, int] = {}

    def _param_models(self, nb, M, caps):
        p = self._params(nb)
        np_ = self.models.n_params
        if not np_:
            return np.zeros((0, nb, model_length(M, *caps)))
        return forms_to_models(box_forms(p.lo, p.hi, np.full(np_, -1), M), *caps)

    # ------------------------------------------------------------------ per step
    def begin(self, sets: QuadraticSets) -> None:
        """Called by the driver before each step: the sets' models and their Taylor
        coefficients ``x_[0..K]`` as models, which the step suggestion, the a-priori
        enclosure and the step itself use (instead of coefficients over the hull box,
        which on robots are many orders wider; docs/lab/code_notes.md)."""
        K = self.order
        nb = sets.n_sets
        work = sets.recentred() if self.recentre else sets
        Xs, live, errors, rho, caps = set_models(work, self.quadratic_cap, self.cubic_cap, self.quartic_cap,
                                                 self.star_cap, self.steer)
        M_set = live.size + self.n
        pool = self.pool_cap if self.fresh_symbols else 0
        M = M_set + pool + (self.n * K if self.fresh_symbols else 0)
        Xm = more_symbols(Xs, M_set, M - M_set) if M > M_set else Xs
        out = self.models._run(Xm, self._param_models(nb, M, caps), K, M, *caps,
                               fresh=self.fresh_symbols, pool=pool, pool_tol=self.POOL_TOL,
                               pool_orders=self.POOL_ORDERS)  # (n, K + 1, B, L)
        mq = caps.mq
        cX = self.models._interval(out, M, mq)
        if self.SET_AFFINE_CHECK:
            cX = self._tighter(cX, Xs, M_set, mq, K)
        # what a step bounds of each coefficient: its remainder and its fresh symbols'
        # coefficients (the step-size cut weighs them; see suggest_step)
        bounded = out[..., -1] + np.abs(out[..., M_set + 1: M + 1]).sum(axis=-1)  # (n, K + 1, B)
        self._cur = dict(sets=sets, work=work, live=live, errors=errors, caps=caps, M=M, M_set=M_set, out=out,
                         cX=cX, bounded=bounded)
        self._fresh = True

    def _tighter(self, ranges: Interval, Xm: np.ndarray, M: int, mq: int, K: int) -> Interval:
        """``ranges`` (B, K + 1, N) intersected with the coefficients over the models'
        affine forms from the box evaluator, where it takes forms (affine arithmetic with
        fresh symbols per order): a degree-2 model's remainder grows with every order of
        the recursion, the fresh symbols' does not as fast. On robots the coefficients
        over the models are far wider (docs/lab/code_notes.md)."""
        if not hasattr(self.taylor, "series"):
            return ranges
        aff = self.taylor.series(models_to_forms(Xm, M, mq), K, self._params(Xm.shape[1]))
        lo = np.maximum(ranges.lo, aff.lo)
        hi = np.minimum(ranges.hi, aff.hi)
        if (lo > hi).any():
            # two enclosures of the same coefficients always meet: one of them is wrong,
            # and which cannot be told here (never continue with either)
            raise RuntimeError("internal error: the Taylor-model and affine enclosures of a step's "
                               "coefficients are disjoint (an unsound enclosure); please report it")
        return Interval._from_bounds(lo, hi)

    def coefficients(self, x: Interval) -> Interval:
        """The driver's first call of a step (after :meth:`begin`): the ranges of the
        coefficient models over the sets (B, K + 1, N); otherwise over boxes ``x``."""
        cur = getattr(self, "_cur", None)
        if getattr(self, "_fresh", False) and cur is not None and x.shape[0] == cur["sets"].n_sets:
            self._fresh = False
            return cur["cX"]
        return super().coefficients(x)

    def suggest_step(self, cX: Interval, tol: float, components: int | None = None) -> float:
        """:meth:`_cut_step`; with ``min_order``, the next step's order chosen from it
        (:meth:`_next_order`, applied once this step is taken)."""
        h = self._cut_step(cX, tol, components)
        if self.min_order is not None:
            self._pending_order = self._next_order(cX, tol, components, h)
        return h

    def _cut_step(self, cX: Interval, tol: float, components: int | None = None) -> float:
        """The step of :meth:`LohnerStepper.suggest_step`, cut so that the remainder the
        composition adds per unit time stays within ``REMAINDER_GROWTH`` times its rate
        as ``h -> 0``: with ``e_k`` the remainders of the coefficient models (with fresh
        symbols: those symbols' coefficients), the step adds about ``sum_k e_k h^k``,
        and ``e_k`` grows with ``k`` (a degree-2 model bounds more at every order of
        the recursion), so long steps add more per second than short ones. The factor
        trades reach against steps; 1.5 is the default (docs/lab/code_notes.md).

        Where the leading remainders are only the floats' rounding (the right-hand side
        is a polynomial the models carry exactly: x' = x^2 at degree 4), the rate is
        taken from the first order ``j`` whose remainder is more than that (``e_k >
        2^-30`` times the coefficient's magnitude), as ``sum_{k >= j} e_k h^(k - j)``
        against ``e_j``: a rounding-level floor would cut the step to nothing. The cut
        stops once the remainder the step adds, ``sum_k e_k h^k``, is at most
        :attr:`REMAINDER_SHARE` of the set's widest component."""
        h = super().suggest_step(cX, tol, components)
        cur = getattr(self, "_cur", None)
        if cur is None or not np.isfinite(h) or h <= 0:
            return h
        widen = getattr(self, "_widen", None)
        if widen is not None and widen.shape[0] == cX.shape[2]:
            # the driver's remainder control takes x_[K] over the a-priori enclosure, not
            # over the set: ask for a step it accepts on the first try, from the last
            # step's ratio of the two (Panda: every step validated twice without it)
            h = min(h, taylor_step(cX[:, self.order, :components].mag() * widen[None, :components],
                                   REMAINDER_SLACK * tol, self.order))
        co = cur["out"][:components, 1:]  # (N', K, B, L): models of x_[1..K]
        e = cur["bounded"][:components, 1:]  # their remainders (with the fresh symbols')
        if not np.isfinite(e).all():
            return h
        mag = np.abs(co[..., :-1]).sum(axis=-1) - (e - co[..., -1])  # (without the fresh symbols')
        significant = np.flatnonzero((e > 2.0**-30 * mag).any(axis=(0, 2)))
        if significant.size == 0:
            return h
        e = e[:, significant[0]:]
        floor = float(np.max(e[:, 0]))
        if not floor > 0:
            return h
        powers = np.arange(e.shape[1])  # e_k h^(k - j)
        first = int(significant[0]) + 1  # (the order of e[:, 0])
        # (the widest component of each set: what a remainder is small against)
        width = np.max(np.asarray(cX[:, 0, :components].width(), float), axis=-1)  # (B,)
        for _ in range(40):
            per = np.sum(e * (h ** powers)[None, :, None], axis=1)  # (N', B)
            if np.max(per) <= self.REMAINDER_GROWTH * floor:
                break
            if np.all(np.max(per, axis=0) * h ** first <= self.REMAINDER_SHARE * width):
                break
            h *= 0.8
        return h

    #: with ``min_order``: the next step's order is the lowest whose Taylor step is this
    #: many times the step the growth cut left (see _next_order)
    ORDER_MARGIN = 1.3

    def _next_order(self, cX: Interval, tol: float, components, h: float) -> int:
        """The order of the next step, in ``[min_order, max_order]``, from this step's
        coefficients ``cX`` (B, K + 1, N) and the step ``h`` :meth:`_cut_step` chose.
        Where the growth cut (not the order-K term) set ``h``, a longer series only
        costs (the recursion's work grows as K^2): the lowest order whose term at ``tol``
        allows ``ORDER_MARGIN`` times ``h``. Where the order-K term set it, two orders
        more (up to ``max_order``). A heuristic only: every step is verified at the order
        it runs (its Taylor polynomial and the Lagrange remainder of that order over the
        a-priori tube), whatever the order (docs/lab/robot_speed.md)."""
        K = self.order
        if not (np.isfinite(h) and h > 0):
            return K
        mags = cX[:, :, :components].mag()  # (B, K + 1, N')
        widen = getattr(self, "_widen", None)
        w = widen[None, :components] if widen is not None and widen.shape[0] == cX.shape[2] else 1.0
        if h >= 0.95 * taylor_step(mags[:, K] * w, tol, K):
            return min(K + 2, self.max_order)
        for k in range(self.min_order, K):
            if taylor_step(mags[:, k] * w, tol, k) >= self.ORDER_MARGIN * h:
                return k
        return K

    #: see _cut_step
    REMAINDER_GROWTH = 1.5

    #: the growth cut of suggest_step stops once the remainder the step adds is at most
    #: this share of the set's widest component: below that, shorter steps trade many
    #: steps for nothing. Without it, an uncertain parameter carried in the models (its
    #: powers make ``e_k`` grow combinatorially with ``k``) held the steps near 1e-4 s
    #: (x' = p y, y' = -p x with p in 1 +- 0.05; Production-Destruction with an uncertain
    #: rate): a stall. With it those complete in a few steps, and the robots' steps and
    #: widths stay as they were (docs/lab/robot_speed.md)
    REMAINDER_SHARE = 1e-5

    #: symbols for the remainders born inside the model graph at the first
    #: ``POOL_ORDERS`` orders of the recursion (see TaylorModelODE._run's ``pool`` and
    #: the module docstring), and the relative size that claims one. Orders 0-2 with
    #: 128 reach further on robots than order 0 alone at the same cost per step; more
    #: orders or symbols gain next to nothing (docs/lab/code_notes.md)
    POOL = 128
    POOL_TOL = 1e-8
    POOL_ORDERS = 3

    #: default of ``fresh_symbols``: see TaylorModelODE._run
    FRESH_SYMBOLS = True

    #: intersect the coefficients over the set with the affine evaluation over the set's
    #: affine forms (:meth:`_tighter`), one more evaluation per step. It paid before the
    #: models had fresh symbols per coefficient; with them (the default) it changes no
    #: step and costs time (docs/lab/code_notes.md).
    SET_AFFINE_CHECK = False

    #: the first a-priori candidate's remainder box: this many times the last step's
    #: ratio ``_widen`` of x_[K] over the tube to x_[K] over the set (see apriori)
    APRIORI_GUESS = 8.0

    #: how the a-priori test takes the coefficients over the candidate tube (only the
    #: last one, the Lagrange term, is used):
    #:
    #: * ``"tube_models"`` (default): :func:`tube_coefficients`, Taylor models made for
    #:   the tube: fewer steps than ``"affine"`` at the same widths (the step
    #:   suggestion's cut for x_[K] over the tube, ``_widen``, is what the tighter bound
    #:   lifts; docs/lab/code_notes.md);
    #: * ``"affine"``: affine arithmetic with fresh symbols per order over the tube's
    #:   affine forms (the box evaluator's ``series``);
    #: * ``"set_models"``: the set's own Taylor models and caps, intersected with
    #:   ``"affine"`` (the same steps and widths as ``"affine"`` at a higher cost;
    #:   docs/lab/code_notes.md).
    APRIORI = "tube_models"

    def apriori(self, X: Interval, cX: Interval, h: float, tries: int = 4):
        """A-priori enclosure over ``[0, h]`` of the solutions from the sets, as a model
        (the high-order enclosure test of Nedialkov, Jackson & Pryce over a set that is
        not a box, see below); ``(E, cE)`` with ``E`` its range (B, N) and ``cE`` (B, K +
        1, N) the coefficient ranges over it, or None (the driver shrinks ``h``).

        The candidate is ``E~ = {sum_{i<K} P_i(x0) s^i : x0 in the set, s in [0, h]} + B``,
        ``P_i`` the coefficient models over the set and ``B`` a box. With ``s^i = h^i
        sigma_i``, ``sigma_i = (1 + tau_i) / 2`` a symbol of its own per power (``tau_i``
        in [-1, 1]), ``P_i sigma_i = P_i / 2 + c_i tau_i / 2 + (P_i - c_i) tau_i / 2``, the
        last bounded by the model's range about its centre ``c_i``: a model over the
        set's symbols and ``K - 1`` more. If ``[0, h^K] x_[K](E~)`` lies inside the
        interior of ``B``, then no solution from the set leaves ``E~`` on ``[0, h]`` (at a
        first exit time ``t*``, the Taylor expansion with its Lagrange remainder,
        componentwise over ``[0, t*]`` where the solution is in ``E~``, puts ``x(t*)``
        in the interior of ``E~``) and ``x_[K]`` over ``E~`` bounds the remainder.
        ``x_[K]`` over ``E~`` is taken in Taylor models made for the tube
        (:func:`tube_coefficients`; ``APRIORI`` names the alternatives)."""
        cur = getattr(self, "_cur", None)
        if cur is None or cur["sets"].n_sets != X.shape[0]:
            return super().apriori(X, cX, h, tries)
        K = self.order
        out, M_all, M, caps = cur["out"], cur["M"], cur["M_set"], cur["caps"]
        mq = caps.mq
        n, _, nb, L = out.shape
        M2 = M + K - 1
        # sum_i h^i P_i (1/2 for i >= 1) and the tau coefficients h^i c_i / 2
        half = np.ascontiguousarray(out[:, :K].copy())
        half[:, 1:] *= 0.5  # (exact, barring underflow: covered below)
        base = _horner_models(half, float(h))  # (n, B, L)
        # the fresh symbols are bounded into the remainder: the candidate tube gains
        # nothing from their correlations, and the affine evaluation pays for every symbol
        Em = more_symbols(fold_symbols(base, M, M_all), M, K - 1)
        rng = self.models._interval(out[:, 1:K], M_all, mq)  # (B, K - 1, n)
        cen = out[:, 1:K, :, 0].transpose(2, 1, 0)  # (B, K - 1, n)
        W = _spread_about(rng, cen)
        hp = np.array([float(h) ** i for i in range(1, K)])
        tau = 0.5 * cen * hp[None, :, None]  # (B, K - 1, n)
        Em[:, :, M + 1: M2 + 1] = tau.transpose(2, 0, 1)
        slack = (np.abs(tau).sum(axis=1) * 2.0**-44 + (0.5 * W * hp[None, :, None] * (1.0 + 2.0**-44)).sum(axis=1)
                 + 1e-300)  # (B, n): rounding of h^i c_i / 2, and the bounded parts
        HK = Interval(0.0, float(h)) ** K
        first = (HK * cX[:, K]).hull(0.0)
        widen = getattr(self, "_widen", None)
        if widen is not None and widen.shape[0] == cX.shape[2]:
            # x_[K] over the tube is wider than over the set (by the last step's ratio,
            # _widen): start there, so that the first candidate validates (without it
            # nearly every a-priori test took two evaluations; docs/lab/code_notes.md).
            # Any candidate is sound: the test below decides.
            # (symmetric: over the tube x_[K] may change sign where it kept one over the set)
            g = first.mag() * (widen * self.APRIORI_GUESS)[None, :]
            first = Interval._from_bounds(-g, g).hull(first)
        Bx = _inflate(first)
        how = self.APRIORI
        if how not in ("tube_models", "affine", "set_models"):
            raise ValueError(f"APRIORI must be 'tube_models', 'affine' or 'set_models', got {how!r}")
        if how == "affine" and not hasattr(self.taylor, "series"):
            how = "set_models"  # (a box evaluator that takes no forms)
        P = self._param_models(nb, M2, caps) if how == "set_models" else None
        for _ in range(tries):
            if not (np.isfinite(Bx.lo).all() and np.isfinite(Bx.hi).all()):
                return None
            trial = Em.copy()
            bm, br = Bx.mid(), Bx.rad()
            with np.errstate(over="ignore", invalid="ignore"):
                trial[:, :, 0] += bm.T
                trial[:, :, -1] = _k_round_up(_k_round_up(trial[:, :, -1] + (slack + br).T) + np.abs(trial[:, :, 0]) * 2.0**-52)
            if how == "tube_models":
                cE = tube_coefficients(self.models, trial, M2, mq, K, self._params(nb), pool=self.pool_cap)
            elif how == "set_models":
                co = self.models._run(np.ascontiguousarray(trial), P, K, M2, *caps)
                cE = self._tighter(self.models._interval(co, M2, mq), trial, M2, mq, K)
            else:
                cE = self.taylor.series(models_to_forms(trial, M2, mq), K, self._params(nb))
            new = HK * cE[:, K]
            if new.interior_subset(Bx).all():
                with np.errstate(divide="ignore", invalid="ignore"):
                    w = (cE[:, K].mag() / np.maximum(cX[:, K].mag(), 1e-300)).max(axis=0)
                self._widen = np.where(np.isfinite(w), np.maximum(w, 1.0), 1.0)
                lo, hi = models_to_interval(trial, M2, mq)
                E = Interval._from_bounds(np.ascontiguousarray(lo.T), np.ascontiguousarray(hi.T))
                self._tube = (E, tube_view(trial, M2, mq))
                return E, cE
            Bx = _inflate(Bx.hull(new).hull(0.0), factor=0.5)
        return None

    def step(self, sets: QuadraticSets, h, X: Interval, E: Interval, cE: Interval) -> StepResult:
        K, n, nb = self.order, self.n, sets.n_sets
        cur = getattr(self, "_cur", None)
        if cur is None or cur["sets"] is not sets:
            self.begin(sets)
            cur = self._cur
        self._cur = None  # (used once: the next step begins with its own sets)
        work, live, caps, M = cur["work"], cur["live"], cur["caps"], cur["M"]
        mq = caps.mq
        out = cur["out"][:, :K]
        h_iv = h if isinstance(h, Interval) else Interval(h)
        hm = float(h_iv.mid()) if isinstance(h, Interval) else float(h)
        y = _horner_models(np.ascontiguousarray(out), hm)  # (n, B, L)
        # Lagrange remainder over E, and (h an interval) the distance from h to hm
        extra = cE[:, K] * (h_iv ** K)
        if isinstance(h, Interval):
            rng = self.models._interval(out, M, mq)  # (B, K, n)
            for k in range(1, K):
                extra = extra + rng[:, k] * (h_iv ** k - Interval(hm) ** k)
        centre, lin_u, A, quad, star, s_on, si, sj, rem = _split_flow(y, cur, nb, n)
        pi, pj = _pairs(mq)
        on_u = pj < min(live.size, mq)  # both symbols parameters (pi <= pj)
        nonlinear = _error_terms(quad[:, :, ~on_u], (pi == pj)[~on_u], rem)
        incoming_all = point(centre) + extra + nonlinear
        bad = ~(np.isfinite(incoming_all.lo).all(axis=1) & np.isfinite(incoming_all.hi).all(axis=1)
                & np.isfinite(y).all(axis=(0, 2)))
        c_new = incoming_all.mid()
        incoming = incoming_all - c_new
        C_new, S_new, r0_new, covered = _parameter_images(sets.C.shape[2], live, lin_u, quad[:, :, on_u],
                                                          pi[on_u], pj[on_u], star, si, sj, s_on)
        # (halving a subnormal may round: cover it)
        tiny = Interval._from_bounds(np.full((nb, n), -1e-300), np.full((nb, n), 1e-300))
        incoming = incoming + tiny * float(max(1, covered))
        # the error part: A delta + incoming, delta in [-1, 1] (0 where r had no width)
        has = work.r.rad() > 0
        unit = Interval._from_bounds(np.where(has, -1.0, 0.0), np.where(has, 1.0, 0.0))
        Q_out, r_new = self.basis.update(work.Q, unit, point(A), incoming)
        if bad.any():
            # a model that broke down (an operation left its domain): the set is lost,
            # which the driver reports as a break-down
            r_new = Interval._from_bounds(np.where(bad[:, None], -np.inf, r_new.lo),
                                          np.where(bad[:, None], np.inf, r_new.hi))
        new = QuadraticSets(c=c_new, C=C_new, r0=r0_new, S=S_new, Q=Q_out, r=r_new)
        if self.absorb:
            new = self.absorb_error(new)
        tube = getattr(self, "_tube", None)
        view = tube[1] if tube is not None and tube[0] is E else None
        self._tube = None
        tube_box = _narrowed_tube(out, cE, float(h_iv.hi), E, M, mq)
        if self.min_order is not None:
            self.steps_by_order[K] = self.steps_by_order.get(K, 0) + 1
        if self._pending_order is not None:
            # the next step's order (suggest_step's choice), from here on: begin, the
            # a-priori test and this step ran at one order
            self.order, self._pending_order = self._pending_order, None
        return StepResult(sets=new, previous=sets, h=h, hull=X, tube=tube_box, nonlinear_width=nonlinear.width(),
                          tube_view=view)


def _split_flow(y: np.ndarray, cur: dict, nb: int, n: int):
    """The flow's models ``y`` (n, B, L) at the step split by what becomes of each
    part: ``(centre (B, n), lin_u (B, n, mu): linear in the set's live parameters,
    A (B, n, n): linear in its error symbols, quad (B, n, pairs), star (B, n, star
    pairs), s_on (star pairs of two parameters), si, sj, rem (B, n): the remainder
    with the cubic, quartic and fresh-symbol terms and the stars with an error symbol
    swept in)``. The sets are second order, so their cubic and quartic monomials join
    the error (in [-1, 1]), as do the fresh symbols (the coefficients' remainders)."""
    live, caps, M = cur["live"], cur["caps"], cur["M"]
    mq, mu = caps.mq, live.size
    centre = y[:, :, 0].T  # (B, n)
    lin_u = y[:, :, 1: mu + 1].transpose(1, 0, 2)  # (B, n, mu)
    A = np.empty((nb, n, n))  # (B, n, n): columns back in the order of r's components
    Me = cur["M_set"]  # the set's symbols (parameters and errors); fresh ones follow
    A[:, :, cur["errors"]] = y[:, :, mu + 1: Me + 1].transpose(1, 0, 2)
    nq = mq * (mq + 1) // 2
    quad = y[:, :, M + 1: M + 1 + nq].transpose(1, 0, 2)  # (B, n, pairs)
    sb = star_base(M, mq, caps.m3, caps.m4)
    cubic = np.abs(y[:, :, M + 1 + nq: sb]).sum(axis=-1).T + np.abs(y[:, :, Me + 1: M + 1]).sum(axis=-1).T
    # star monomials (off-diagonal): of two parameters into S, with an error symbol
    # into the error (in [-1, 1])
    si, sj = _star_pairs(M, mq, caps.ms, caps.ns)
    s_on = sj < mu  # (si < ms <= mq <= sj: si is a parameter too)
    star = y[:, :, sb: -1].transpose(1, 0, 2)  # (B, n, star pairs)
    cubic = cubic + np.abs(star[:, :, ~s_on]).sum(axis=-1)
    rem = _k_round_up(y[:, :, -1].T + cubic * (1.0 + 2.0**-40))  # (B, n)
    return centre, lin_u, A, quad, star, s_on, si, sj, rem


def _error_terms(qd: np.ndarray, diag: np.ndarray, rem: np.ndarray) -> Interval:
    """The nonlinear part that goes into the error (B, n), outward: the quadratic terms
    ``qd`` (B, n, k) with an error symbol (eps_j delta_l in [-1, 1], delta_l^2 in [0, 1]
    where ``diag``) and the remainder +- ``rem``."""
    q_lo = np.where(diag, np.minimum(qd, 0.0), -np.abs(qd)).sum(axis=-1)
    q_hi = np.where(diag, np.maximum(qd, 0.0), np.abs(qd)).sum(axis=-1)
    bump = (np.abs(q_lo) + np.abs(q_hi)) * 2.0**-40 + 1e-300  # (the float sums' rounding)
    return Interval._from_bounds(q_lo - bump, q_hi + bump) + Interval._from_bounds(-rem, rem)


def _parameter_images(m: int, live: np.ndarray, lin_u, qu, qi, qj, star, si, sj, s_on):
    """The new set's parameters, eps on [-1, 1] for the ``live`` columns of ``m``, and
    their images: ``(C (B, n, m), S (B, n, m, m), r0 (B, m), count)`` with ``count`` the
    halved quadratic terms (a halved subnormal may round; the caller covers them)."""
    nb, n = lin_u.shape[:2]
    C_new = np.zeros((nb, n, m))
    C_new[:, :, live] = lin_u
    S_new = np.zeros((nb, n, m, m))
    cols_i, cols_j = live[qi], live[qj]
    half = np.where(qi == qj, qu, 0.5 * qu)
    S_new[:, :, cols_i, cols_j] = half
    S_new[:, :, cols_j, cols_i] = half
    if s_on.any():
        half_s = 0.5 * star[:, :, s_on]
        S_new[:, :, live[si[s_on]], live[sj[s_on]]] = half_s
        S_new[:, :, live[sj[s_on]], live[si[s_on]]] = half_s
        qi = np.concatenate([qi, si[s_on]])  # (for the subnormal cover)
    r0_lo = np.zeros((nb, m))
    r0_hi = np.zeros((nb, m))
    r0_lo[:, live] = -1.0
    r0_hi[:, live] = 1.0
    return C_new, S_new, Interval._from_bounds(r0_lo, r0_hi), qi.size


def _narrowed_tube(out: np.ndarray, cE: Interval, h_top: float, E: Interval, M: int, mq: int) -> Interval:
    """The step's tube: the a-priori enclosure ``E`` narrowed by :func:`step_tube` (``E``
    alone on a row that is not finite, a model lost, or where the two do not meet)."""
    with np.errstate(over="ignore", invalid="ignore"):
        narrow = step_tube(out, cE, h_top, M, mq)
    ok = np.isfinite(narrow.lo) & np.isfinite(narrow.hi)
    inside = E.intersect(Interval._from_bounds(np.where(ok, narrow.lo, E.lo), np.where(ok, narrow.hi, E.hi)))
    empty = inside.is_empty()
    return E if empty.any() else inside

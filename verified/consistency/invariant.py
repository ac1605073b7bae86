# Whole: one 740-line class (QuadraticLyapunov); splitting it would change its methods.
"""Invariant sublevel sets of a quadratic Lyapunov function: one box for every later time
(issue 14 item 4; issue 13 item 1, the energy shell for systems with inputs).

Setting. The ODE's states are ``x = (u, z)``: ``n`` positions ``u`` and ``n`` rates ``z``;
its parameters ``p`` are constant along each solution (graph parameters, or the solver's
parameter states). A :class:`QuadraticLyapunov` is a function

    L(x, p) = 1/2 z^T A(u, p) z + 1/2 (e - e*(p))^T K (e - e*(p)) + W(u, p),  e = u - u_ref,

with ``A(u, p)`` symmetric positive definite, ``K`` a constant symmetric positive definite
matrix, and a remainder ``W`` with ``W(u_ref, p) = 0``, ``grad_u W(u_ref, p) = rho(p)`` and
``hess_u W(u, p) = d g(u, p) / du`` for a given graph ``g``. The caller claims that ``L``
does not increase along solutions (for a joint PD controller holding a pose, ``L`` is the
closed-loop energy and ``dL/dt = -qd^T (Kd + D) qd``; :mod:`mbs.lyapunov` builds it and
checks the claim's algebra at sample points; :meth:`QuadraticLyapunov.check` checks the
structure above the same way).

The box. If every state of a set satisfies ``L <= c`` at time ``t1`` (``c`` from the
mean-value form of ``L`` over the set), then ``L(x(t), p) <= c`` for all ``t >= t1``. For a
box ``U`` of positions, ``E = U - u_ref`` and every state with ``u`` in ``U``, ``p`` in ``P``
and ``L <= c``:

- ``W(u, p) = rho(p) . e + 1/2 e^T H e`` with ``H = hess_u W`` at a point of the segment
  ``[u_ref, u]`` (Taylor with the Lagrange remainder), so ``W >= w`` := the lower end of
  ``rho(P) . E + 1/2 E^T H(hull(U, u_ref), P) E``;
- hence ``1/2 (e - e*)^T K (e - e*) <= s := c - w`` and ``1/2 z^T A z <= s``, and the
  ellipsoids' projections give ``e_i in e*_i(P) +- sqrt(2 s (K^-1)_ii)`` and
  ``|z_i| <= sqrt(2 s max (A^-1)_ii(U, P))``.

Call the position part of that box ``U'``. When ``U'`` lies in the interior of ``U`` and the
set's positions lie in ``U``, no solution can leave ``U`` (at the first time it reached the
boundary of ``U`` it would be in ``U'``, inside), so every solution stays in ``U'`` and in
the box above for all ``t >= t1``. Repeating with ``U'`` in place of ``U`` only narrows it.

Decay. ``L`` alone only stops growing. For a mechanical system (a ``dissipation`` graph
``Dm``: ``d/dt (A z) = dT/du - grad_u L - Dm z``), the strict Lyapunov function
``V~ = L + eps (u - u_c(p))^T A z - l_c(p)`` (``u_c = u_ref + e*`` the centre) falls
at a verified rate: :meth:`QuadraticLyapunov.certify` encloses the matrices of
``dV~/dt = -y^T Q y - eps delta^T b`` and ``V~ = b . delta + y^T P y`` over a box the
solutions stay in and proves ``Q - lam P >= margin D^-2`` for every member, so
``V~(t) <= gamma / lam + (V~(t1) - gamma / lam) exp(-lam (t - t1))`` and the boxes shrink
with time towards the spread of the centres ``u_c(P)`` (:meth:`QuadraticLyapunov.chain`
restarts the certificate on the smaller boxes later on, for larger rates).

:class:`InvariantHook` does this once the solver passes a given time and, when every set's
box is verified, ends the integration there: every later output time gets the boxes (the
energy boxes, narrowed by the decay where it is certified), and the tube gets one piece
per output interval up to the end. The run reports ``completed``.
"""

from __future__ import annotations

import itertools

import numpy as np

from verified.arith import interval as iv
from verified.arith import linalg
from verified.graph.evaluate import eval_float, eval_interval, jacobian_float, jacobian_interval
from verified.consistency.contractor import mean_value_row
from verified.graph import Graph, GraphBuilder
from verified.graph.ops import embed, gradient_graph, params_to_inputs
from verified.driver.hooks import Hook
from verified.arith.interval import Interval, concatenate
from verified.sets.first_order import DoubletonSets

__all__ = ["QuadraticLyapunov", "InvariantBoxes", "InvariantHook"]

_UP = 1.0 + 2.0 ** -40  # one-sided widening of float results that feed a bound


def _I(lo, hi=None) -> Interval:
    return Interval._from_bounds(np.asarray(lo, float), np.asarray(lo if hi is None else hi, float))


def _second_order_upper(gy: Graph, grad: Graph, c, A, R) -> np.ndarray:
    """Upper bounds of ``g(c + A r)``, ``r in R``, from Taylor's theorem to second order:
    ``g(c) + grad g(c) A r + 1/2 r^T A^T H A r`` with ``H`` the interval Hessian over
    ``X = c + A hull(R, 0)`` (every segment from ``c``). Near a minimum of ``g``, where the
    mean-value form's first-order spread dominates, this is the tight one
    (docs/lab/code_notes.md)."""
    B, N = c.shape
    m = A.shape[2]
    C = _I(c)
    X = linalg.matvec(A, R.hull(0.0)) + C
    L0 = eval_interval(gy, C)[:, 0]
    g = eval_interval(grad, C)  # (B, N)
    gA = linalg.matmul(g.reshape(B, 1, N), A).reshape(B, m)
    H = jacobian_interval(grad, X)  # (B, N, N)
    S = linalg.matmul(linalg.matmul(np.swapaxes(A, 1, 2), H), A)  # (B, m, m)
    return (L0 + (gA * R).sum(axis=-1) + _half_form(S, R)).hi


def _half_form(S: Interval, R: Interval) -> Interval:
    """``1/2 r^T S r`` over every ``r`` in ``R`` (B, m) and ``S`` in the interval matrices
    (B, m, m): squares on the diagonal (``sqr`` keeps them >= 0 where ``r_i r_i`` would
    not) and each off-diagonal pair once, ``(S_ij + S_ji) r_i r_j``."""
    m = R.shape[1]
    i, j = linalg.upper_pairs(m, 1)
    d = np.arange(m)
    diag = (S[:, d, d] * iv.sqr(R)).sum(axis=-1)
    if i.size == 0:
        return diag * 0.5
    off = ((S[:, i, j] + S[:, j, i]) * (R[:, i] * R[:, j])).sum(axis=-1)
    return (diag + off) * 0.5


class InvariantBoxes:
    """Result of :meth:`QuadraticLyapunov.boxes`.

    Attributes: ``boxes`` Interval (B, N) over the inputs ``y`` (positions, rates, the
    parameters' own boxes, other states as given); ``verified`` (B,) bool: the box holds the
    set's solutions for all later times (where False the row is the set's hull, no claim);
    ``level`` (B,) the ``c`` used; ``slack`` (B,) the ``s`` of the module docstring.
    """

    def __init__(self, boxes, verified, level, slack):
        self.boxes, self.verified, self.level, self.slack = boxes, verified, level, slack


class QuadraticLyapunov:
    """A Lyapunov function of the structure in the module docstring.

    Args:
        level: Graph ``(x, p) -> [L]``.
        mass: Graph ``(x, p) -> n * n`` entries of ``A(u, p)`` (row-major).
        grad: Graph ``(x, p) -> n`` entries of ``g(u, p)`` with ``hess_u W = dg/du``.
        center: Graph ``(x, p) -> n`` entries of ``e*(p)``.
        residual: Graph ``(x, p) -> n`` entries of ``rho(p) = grad_u W(u_ref, p)``.
        K: float (n, n), symmetric positive definite.
        u_ref: float (n,).
        u_index, z_index: the positions and rates among the ``x`` inputs (default
            ``0..n-1`` and ``n..2n-1``).
        dissipation: optional Graph ``(x, p) -> n * n`` entries of ``Dm(u, p)``, the
            Rayleigh matrix of a mechanical system ``d/dt (A z) = dT/du - grad_u L - Dm z``
            (then ``dL/dt = -z^T Dm z``): enables the decay certificate
            (:meth:`certify`, :meth:`chain`).

    All graphs take the same inputs and parameters as the ODE.
    """

    def __init__(self, level: Graph, mass: Graph, grad: Graph, center: Graph, residual: Graph, K, u_ref,
                 u_index=None, z_index=None, dissipation: Graph | None = None):
        K = np.asarray(K, float)
        u_ref = np.asarray(u_ref, float)
        n = u_ref.size
        if K.shape != (n, n) or not np.all(np.isfinite(K)) or not np.all(np.isfinite(u_ref)):
            raise ValueError(f"K must be a finite ({n}, {n}) matrix and u_ref {n} finite numbers, got "
                             f"K of shape {K.shape}")
        if not np.array_equal(K, K.T):
            raise ValueError("K must be exactly symmetric")
        dk = linalg.inverse_diagonal(K).hi
        # (K^-1)_ii from a verified solve; positive definiteness from the float spectrum
        # with a margin far above its backward error (n eps |K|)
        lam = np.linalg.eigvalsh(K)
        if not (lam[0] > 1e-9 * max(abs(lam[-1]), 1e-300) and np.all(np.isfinite(dk)) and np.all(dk > 0)):
            raise ValueError(f"K must be symmetric positive definite (smallest eigenvalue {lam[0]:.3g})")
        self.kinv_diag = dk * _UP
        self.K, self.u_ref, self.n = K, u_ref, n
        self.iu = np.arange(n) if u_index is None else np.asarray(u_index, int)
        self.iz = np.arange(n, 2 * n) if z_index is None else np.asarray(z_index, int)
        named = [("level", level, 1), ("mass", mass, n * n), ("grad", grad, n), ("center", center, n),
                 ("residual", residual, n)]
        if dissipation is not None:
            named.append(("dissipation", dissipation, n * n))
        for name, g, m in named:
            if not isinstance(g, Graph):
                raise TypeError(f"{name} must be a verified.graph.Graph, got {type(g).__name__}")
            if g.n_outputs != m or g.n_inputs != level.n_inputs or g.n_params != level.n_params:
                raise ValueError(f"{name}: expected {level.n_inputs} inputs, {level.n_params} params and {m} "
                                 f"outputs, got {g.n_inputs}, {g.n_params}, {g.n_outputs}")
        self.graphs = {name: g for name, g, _ in named}
        self.n_x, self.n_p = level.n_inputs, level.n_params
        # over y = (x, p): the parameters become inputs, as the solver carries them
        self._y = {k: params_to_inputs(g) for k, g in self.graphs.items()}
        self._grad_level = None  # built on first use (second-order level bound)
        self._decay_graphs = None  # built on first use (decay certificate)
        self._vtilde_graphs = {}  # eps -> (V~, grad V~)
        self._bounded = np.concatenate([self.iu, self.iz])  # the columns a certificate bounds

    # ------------------------------------------------------------------ checks
    def check(self, x, p=None, rtol: float = 1e-8) -> None:
        """Check the structure of the module docstring at sample points (floats: x (S, n_x),
        p (S, n_p)); raises ValueError naming what fails. Not a proof: it catches a
        remainder, mass form or centre that does not belong to ``L``."""
        x = np.atleast_2d(np.asarray(x, float))
        S = x.shape[0]
        p = np.zeros((S, 0)) if p is None else np.broadcast_to(np.asarray(p, float), (S, self.n_p))
        g = self.graphs
        n, iu, iz = self.n, self.iu, self.iz
        x0 = x.copy()
        x0[:, iz] = 0.0
        L = eval_float(g["level"], x, p)[:, 0]
        L0 = eval_float(g["level"], x0, p)[:, 0]
        A = eval_float(g["mass"], x, p).reshape(S, n, n)
        z = x[:, iz]
        T = 0.5 * np.einsum("si,sij,sj->s", z, A, z)
        scale = np.abs(L) + np.abs(L0) + np.abs(T) + 1e-12
        if not np.all(np.abs(L - L0 - T) <= rtol * scale):
            raise ValueError("Lyapunov structure: L(u, z, p) - L(u, 0, p) is not 1/2 z^T A(u, p) z")
        xr = x0.copy()
        xr[:, iu] = self.u_ref
        estar = eval_float(g["center"], xr, p)
        rho = eval_float(g["residual"], xr, p)
        gu = eval_float(g["grad"], x0, p)
        gr = eval_float(g["grad"], xr, p)
        e = x[:, iu] - self.u_ref
        dL = jacobian_float(g["level"], x0, p)[:, 0, :][:, iu]
        want = (e - estar) @ self.K.T + gu - gr + rho
        size = np.abs(e - estar) @ np.abs(self.K).T + np.abs(gu) + np.abs(gr) + np.abs(rho) + np.abs(dL)
        size = size + 1e-6 * size.max() + 1e-12
        if not np.all(np.abs(dL - want) <= rtol * size):
            raise ValueError("Lyapunov structure: grad_u L(u, 0, p) is not K (e - e*) + g(u) - g(u_ref) + rho")
        Lr = eval_float(g["level"], xr, p)[:, 0]
        qe = 0.5 * np.einsum("si,ij,sj->s", estar, self.K, estar)
        if not np.all(np.abs(Lr - qe) <= rtol * (np.abs(Lr) + np.abs(qe) + np.abs(L0) + 1e-9)):
            raise ValueError("Lyapunov structure: L(u_ref, 0, p) is not 1/2 e*^T K e* (W(u_ref) != 0)")

    # ------------------------------------------------------------------ level over sets
    def level_over(self, sets, params=None) -> np.ndarray:
        """Upper bounds (B,) of ``L`` over each set of the solver (over ``y`` = its
        inputs; ``params`` the graph parameters when not carried as states): the smaller
        of the mean-value form and the second-order form over ``c + C r0 + Q r`` for
        first-order sets, over the hull otherwise."""
        return self._upper_over(self._y["level"], self._level_gradient(), sets, params)

    def _level_gradient(self) -> Graph:
        """``grad L`` over ``y`` (built on first use)."""
        if self._grad_level is None:
            self._grad_level = gradient_graph(self._y["level"])
        return self._grad_level

    def _upper_over(self, gy: Graph, grad: Graph, sets, params=None) -> np.ndarray:
        if type(sets) is DoubletonSets or isinstance(sets, _Projected):
            c, A = sets.c, np.concatenate([sets.C, sets.Q], axis=2)
            R = concatenate([sets.r0, sets.r], axis=1)
        else:
            H = sets.hull()
            c = H.mid()
            A = np.broadcast_to(np.eye(c.shape[1]), (c.shape[0],) + (c.shape[1],) * 2)
            R = H - c
        c, A, R = self._with_params(c, A, R, params)
        a, g0, rem = mean_value_row(gy, c, A, R)
        first = (g0 + (_I(a) * R).sum(axis=-1) + rem).hi
        return np.minimum(first, _second_order_upper(gy, grad, c, A, R))

    def _with_params(self, c, A, R, params):
        """Append graph parameters (point or interval, not carried as states) to the set's
        coordinates: a parameter interval becomes one more symbol."""
        if params is None or self.n_p == 0:
            return c, A, R
        B = c.shape[0]
        P = params if isinstance(params, Interval) else _I(params)
        P = P.broadcast_to((B, self.n_p)) if P.ndim == 1 else P
        pm = P.mid()
        m = A.shape[2]
        A2 = np.zeros((B, A.shape[1] + self.n_p, m + self.n_p))
        A2[:, :A.shape[1], :m] = A
        A2[:, A.shape[1]:, m:] = np.eye(self.n_p)
        return (np.concatenate([c, pm], axis=1), A2, concatenate([R, P - pm], axis=1))

    # ------------------------------------------------------------------ boxes
    def boxes(self, c, Y: Interval, *, tries: int = 6, refine: int = 3) -> InvariantBoxes:
        """Boxes over ``y`` that hold every solution with ``L <= c`` whose positions are in
        ``Y``'s position part and parameters in ``Y``'s parameter part, for all later times
        (see the module docstring). ``c`` (B,), ``Y`` Interval (B, N) over ``y = (x, p)``
        (the sets' hulls)."""
        B, N = Y.shape
        c = np.broadcast_to(np.asarray(c, float), (B,)).copy()
        iu = self.iu
        ulo, uhi = Y.lo[:, iu], Y.hi[:, iu]
        # a first guess from the quadratic part alone (W ignored), around the set's hull
        est = self._centre(Y)
        s0 = np.maximum(c, 0.0)
        r0 = np.sqrt(2.0 * s0[:, None] * self.kinv_diag[None, :])
        glo = np.minimum(ulo, self.u_ref + est.lo - r0)
        ghi = np.maximum(uhi, self.u_ref + est.hi + r0)
        centre = self._centre_terms(Y)  # depends on the parameters only: once per call
        verified = np.zeros(B, bool)
        out_lo, out_hi = Y.lo.copy(), Y.hi.copy()
        slack = np.full(B, np.inf)
        mid, rad = 0.5 * (glo + ghi), 0.5 * (ghi - glo)
        Ulo, Uhi = mid - 1.5 * rad - 1e-9, mid + 1.5 * rad + 1e-9
        todo = np.arange(B)
        for _ in range(max(1, int(tries))):
            if todo.size == 0:
                break
            Yk = self._with_u(Y[todo], Ulo[todo], Uhi[todo])
            plo, phi, s = self._position_bound(c[todo], Yk, tuple(v[todo] for v in centre))
            inside = (plo > Ulo[todo]).all(axis=1) & (phi < Uhi[todo]).all(axis=1) & np.isfinite(s)
            ok = todo[inside]
            verified[ok] = True
            out_lo[np.ix_(ok, iu)], out_hi[np.ix_(ok, iu)], slack[ok] = plo[inside], phi[inside], s[inside]
            bad = todo[~inside]
            # widen: the hull of the box and its bound, twice as wide about its middle
            k_bad = np.flatnonzero(~inside)
            blo = np.minimum(Ulo[bad], np.where(np.isfinite(plo[k_bad]), plo[k_bad], Ulo[bad]))
            bhi = np.maximum(Uhi[bad], np.where(np.isfinite(phi[k_bad]), phi[k_bad], Uhi[bad]))
            m2, r2 = 0.5 * (blo + bhi), 0.5 * (bhi - blo)
            Ulo[bad], Uhi[bad] = m2 - 2.0 * r2 - 1e-9, m2 + 2.0 * r2 + 1e-9
            todo = bad
        # narrow the verified boxes: every later state is in U', so in the bound over U'
        idx = np.flatnonzero(verified)
        for _ in range(max(0, int(refine))):
            if idx.size == 0:
                break
            Yk = self._with_u(Y[idx], out_lo[idx][:, iu], out_hi[idx][:, iu])
            plo, phi, s = self._position_bound(c[idx], Yk, tuple(v[idx] for v in centre))
            ok = np.isfinite(s)
            cur_lo, cur_hi = out_lo[np.ix_(idx, iu)], out_hi[np.ix_(idx, iu)]
            out_lo[np.ix_(idx, iu)] = np.where(ok[:, None], np.maximum(plo, cur_lo), cur_lo)
            out_hi[np.ix_(idx, iu)] = np.where(ok[:, None], np.minimum(phi, cur_hi), cur_hi)
            slack[idx] = np.where(ok, np.minimum(slack[idx], s), slack[idx])
        if idx.size:
            Yk = self._with_u(Y[idx], out_lo[idx][:, iu], out_hi[idx][:, iu])
            zb = self._rate_bound(slack[idx], Yk)
            good = np.isfinite(zb).all(axis=1)
            ig, ib = idx[good], idx[~good]
            out_lo[np.ix_(ig, self.iz)], out_hi[np.ix_(ig, self.iz)] = -zb[good], zb[good]
            verified[ib] = False
            out_lo[ib], out_hi[ib] = Y.lo[ib], Y.hi[ib]
        return InvariantBoxes(_I(out_lo, out_hi), verified, c, slack)

    def _with_u(self, Y: Interval, ulo, uhi) -> Interval:
        lo, hi = Y.lo.copy(), Y.hi.copy()
        lo[:, self.iu], hi[:, self.iu] = ulo, uhi
        lo[:, self.iz], hi[:, self.iz] = 0.0, 0.0  # the graphs used here do not read the rates
        return _I(lo, hi)

    def _mean_value(self, name: str, Y: Interval) -> Interval:
        """A graph of ``(u, p)`` over ``Y``: the natural enclosure intersected with the
        mean-value form about ``Y``'s midpoint (the parameters of ``rho`` and ``e*`` appear
        more than once: the natural form loses their correlation)."""
        return self._mean_value_graph(self._y[name], Y)

    def _centre(self, Y: Interval) -> Interval:
        return self._mean_value("center", Y)

    def _centre_terms(self, Y: Interval):
        """``(b, l_c, u_c)`` over ``Y``'s parameters: ``W``'s slope and value at the centre
        ``u_c(p) = u_ref + e*(p)`` (``W(u_c) = l_c``, ``grad W(u_c) = b``), and the centre."""
        parts = self._parts_over(Y)
        return parts[:, :self.n], parts[:, self.n], self._centre(Y) + self.u_ref

    def _position_bound(self, c, Y: Interval, centre=None):
        """``(lo, hi, s)`` of the position bound over ``Y``'s positions (see the module
        docstring); ``s`` is inf where it cannot be bounded.

        ``W``'s lower bound is the better of its Taylor expansions about ``u_ref``
        (``rho . E + 1/2 E^T H E``) and, given ``centre`` (:meth:`_centre_terms`), about the
        centre ``u_c(p)`` (``l_c + b . D + 1/2 D^T H D``, ``D = U - u_c(P)``): with a centre
        that tracks the equilibria, ``rho`` is the second-order offset ``-H e*`` (on robots
        the largest part of the slack; docs/lab/code_notes.md) while ``b`` nearly vanishes."""
        iu = self.iu
        U = Y[:, iu]
        Yx = self._with_u(Y, np.minimum(U.lo, self.u_ref), np.maximum(U.hi, self.u_ref))
        H = jacobian_interval(self._y["grad"], Yx)[:, :, iu]  # (B, n, n): hess_u W over the segment hull
        E = U - self.u_ref
        rho = self._mean_value("residual", Y)
        wlo = (_half_form(H, E) + (rho * E).sum(axis=-1)).lo
        if centre is not None:
            b, lc, uc = centre
            Yc = self._with_u(Y, np.minimum(U.lo, uc.lo), np.maximum(U.hi, uc.hi))
            Hc = jacobian_interval(self._y["grad"], Yc)[:, :, iu]
            D = U - uc
            w2 = (lc + (b * D).sum(axis=-1) + _half_form(Hc, D)).lo
            wlo = np.where(np.isfinite(w2), np.maximum(wlo, w2), wlo)
        with np.errstate(invalid="ignore"):
            s = (_I(c) - _I(wlo)).hi
            s = np.where(np.isfinite(s), np.maximum(s, 0.0), np.inf)
            r = iv.sqrt(_I(2.0 * s[:, None] * self.kinv_diag[None, :] * _UP)).hi * _UP
        uc = centre[2] if centre is not None else self._centre(Y) + self.u_ref  # depends on p only
        lo = (uc - r).lo
        hi = (uc + r).hi
        bad = ~np.isfinite(s)
        lo[bad], hi[bad] = -np.inf, np.inf
        return lo, hi, s

    def _mass_over(self, Y: Interval, dA: Interval | None = None) -> Interval:
        """``A`` over each box (B, n, n): its natural enclosure intersected with its
        mean-value form. The natural one of the composite-rigid-body sum carries every
        product's dependency; the mean-value form is narrower on robots and certifies
        more (docs/lab/code_notes.md)."""
        n, B = self.n, Y.shape[0]
        g = self._y["mass"]
        if dA is None:
            dA = jacobian_interval(g, Y)
        m = Y.mid()
        mv = eval_interval(g, _I(m)) + (dA * (Y - m)[:, None, :]).sum(axis=-1)
        return eval_interval(g, Y).intersect(mv).reshape(B, n, n)

    def _rate_bound(self, s, Y: Interval):
        """``|z_i| <= sqrt(2 s max (A^-1)_ii)`` over ``Y`` (B, n); inf where ``A(Y)`` is not
        verified regular."""
        A = self._mass_over(Y)
        with np.errstate(all="ignore"):
            d = linalg.inverse_diagonal((A + A.swapaxes(-1, -2)) * 0.5).hi
            ok = np.isfinite(d) & (d > 0)
            dd = np.where(ok, d, 1.0)
            b = iv.sqrt(_I(2.0 * np.asarray(s, float)[:, None] * dd * _UP)).hi * _UP
        return np.where(ok, b, np.inf)


    # ------------------------------------------------------------------ decay
    def check_dynamics(self, rhs: Graph, x, p=None, rtol: float = 1e-7) -> None:
        """Check at sample points (floats) that ``rhs`` is the mechanical system the decay
        certificate assumes: ``u' = z`` and ``d/dt (A z) = dT/du - grad_u L(u, 0, p) - Dm z``
        with ``T = 1/2 z^T A z`` and ``Dm`` the ``dissipation`` graph (then
        ``dL/dt = -z^T Dm z``). Raises ValueError naming what fails."""
        if "dissipation" not in self.graphs:
            raise ValueError("no dissipation graph: the decay certificate is not available")
        x = np.atleast_2d(np.asarray(x, float))
        S = x.shape[0]
        p = np.zeros((S, 0)) if p is None else np.broadcast_to(np.asarray(p, float), (S, self.n_p))
        g, n, iu, iz = self.graphs, self.n, self.iu, self.iz
        f = eval_float(rhs, x, p)
        z = x[:, iz]
        if not np.allclose(f[:, iu], z, rtol=rtol, atol=0):
            raise ValueError("Lyapunov dynamics: the position rates are not the z states")
        A = eval_float(g["mass"], x, p).reshape(S, n, n)
        dA = jacobian_float(g["mass"], x, p)[:, :, iu].reshape(S, n, n, n)  # [s, i, j, k] = dA_ij / du_k
        Dm = eval_float(g["dissipation"], x, p).reshape(S, n, n)
        x0 = x.copy()
        x0[:, iz] = 0.0
        gradU = jacobian_float(g["level"], x0, p)[:, 0, iu]
        zd = f[:, iz]
        lhs = np.einsum("sij,sj->si", A, zd) + np.einsum("sijk,sk,sj->si", dA, z, z)
        dT = 0.5 * np.einsum("sjki,sj,sk->si", dA, z, z)
        rhs_ = dT - gradU - np.einsum("sij,sj->si", Dm, z)
        size = np.abs(np.einsum("sij,sj->si", A, zd)) + np.abs(gradU) + np.abs(np.einsum("sij,sj->si", Dm, z)) \
            + np.abs(dT)
        # near an equilibrium every term is ~0 while the rhs rounds at the size of its own
        # intermediates (gravity torques): a floor from the largest sample
        size = size + 1e-6 * size.max() + 1e-12
        if not np.all(np.abs(lhs - rhs_) <= rtol * size):
            raise ValueError("Lyapunov dynamics: d/dt (A z) is not dT/du - grad_u L - Dm z at a sample point")

    def _decay_parts(self) -> Graph:
        """One graph over ``y`` with outputs ``b(p)`` (n: ``grad_u L`` at the centre
        ``u_c(p) = u_ref + e*(p)``, z = 0), ``l_c(p) = L(u_c(p), 0, p)`` and
        ``w(y) = (u - u_c(p))^T A(u, p) z``."""
        if self._decay_graphs is None:
            gy, n = self._y, self.n
            N = gy["level"].n_inputs
            b = GraphBuilder(N, 0, input_names=list(gy["level"].input_names))
            y = [b.input(i) for i in range(N)]
            es = embed(b, gy["center"], y)
            uc = [b.add(b.const(float(self.u_ref[k])), es[k]) for k in range(n)]
            yc = list(y)
            for k, i in enumerate(self.iu):
                yc[i] = uc[k]
            for i in self.iz:
                yc[i] = b.const(0.0)
            gl = embed(b, self._level_gradient(), yc)
            (lc,) = embed(b, gy["level"], yc)
            A = embed(b, gy["mass"], y)
            w = None
            for i in range(n):
                Az = None
                for j in range(n):
                    t = b.mul(A[i * n + j], y[self.iz[j]])
                    Az = t if Az is None else b.add(Az, t)
                t = b.mul(b.sub(y[self.iu[i]], uc[i]), Az)
                w = t if w is None else b.add(w, t)
            self._decay_graphs = b.build([gl[i] for i in self.iu] + [lc, w],
                                         [f"b{k + 1}" for k in range(n)] + ["l_c", "w"])
        return self._decay_graphs

    def _vtilde(self, eps: float):
        """``(V~, grad V~)`` over ``y``, ``V~ = L + eps w - l_c(p)`` (the strict Lyapunov
        function, shifted); kept per ``eps`` (candidates and restarts share them)."""
        key = float(eps)
        if key not in self._vtilde_graphs:
            g = self._vtilde_graph(key)
            self._vtilde_graphs[key] = (g, gradient_graph(g))
        return self._vtilde_graphs[key]

    def _vtilde_graph(self, eps: float) -> Graph:
        parts = self._decay_parts()
        N = parts.n_inputs
        b = GraphBuilder(N, 0, input_names=list(parts.input_names))
        y = [b.input(i) for i in range(N)]
        out = embed(b, parts, y)
        (L,) = embed(b, self._y["level"], y)
        v = b.add(b.sub(L, out[self.n]), b.mul(b.const(float(eps)), out[self.n + 1]))
        return b.build([v], ["V"])

    def certify(self, region: Interval, splits=(1, 2, 3), eps=None) -> "Decay":
        """A decay certificate per box of ``region`` (Interval (B, N) over ``y``: boxes that
        every later state of a set stays in, e.g. :meth:`boxes`), without its starting
        level (``v1`` is inf; :meth:`decay` and :meth:`chain` fill it in).

        ``V~ = L + eps (u - u_c(p))^T A z - l_c(p)`` (``u_c = u_ref + e*``) satisfies
        ``dV~/dt = -y^T Q y - eps delta^T b(p)`` with ``y = (delta, z)``,
        ``delta = u - u_c(p)``, ``b = grad_u L(u_c(p), 0, p)`` and
        ``Q = [[eps Kb, eps Dm / 2], [eps Dm^T / 2, Dm - eps A - eps N / 2]]``
        (``Kb``: ``hess_u L`` averaged along the segment from ``u_c`` to ``u``,
        ``N = sum_k delta_k dA/du_k``), and ``V~ = b . delta + y^T P y`` with
        ``P = [[Kb' / 2, eps A / 2], [eps A / 2, A / 2]]``; both from the mechanical
        structure :meth:`check_dynamics` checks. Enclosing ``Kb``, ``A``, ``dA/du`` and
        ``Dm`` over the region and verifying ``Q - lam P >= margin D^-2`` for every member
        gives ``dV~/dt <= -lam V~ + gamma``, ``gamma = (lam + eps)^2 |D b|^2 / (4 margin)``.

        ``eps``: None (try a few multiples of the damping rate ``A^-1 Dm``) or one value per
        box (a restart keeps its certificate's ``eps``: the metric ``P`` then barely changes).

        ``splits``: the region is also tried cut into ``k^d`` pieces (``k`` in ``splits``,
        ``d <= 3`` positions, those the mass matrix varies most along), each certified with
        the same ``eps``; the rate is the smallest, ``gamma`` the largest, and a state lies
        in one of the pieces, so the box is the hull of each piece's own bound (on
        robots some pieces certify only when cut; docs/lab/code_notes.md).
        """
        if "dissipation" not in self.graphs:
            raise ValueError("no dissipation graph: the decay certificate is not available")
        self._decay_parts()
        n = self.n
        B, N = region.shape
        uc = self._centre(region) + self.u_ref  # (B, n) over the region's parameters
        bsq = self._b_squares(region)  # (B, n): bounds of b_i^2 over the set's parameters
        out = Decay(B, n)
        out.uc_lo, out.uc_hi = uc.lo, uc.hi
        out.beta = np.sqrt(bsq.sum(axis=1)) * _UP
        for k in ([splits] if np.isscalar(splits) else splits):
            pieces, owner = self._pieces(region, int(k))
            mats = self._matrices(pieces, uc[owner])
            for j in range(B):
                mine = np.flatnonzero(owner == j)
                best = self._certify_pieces(mats, mine, bsq[j], None if eps is None else [float(eps[j])])
                if best is not None and best["lam"] > out.lam[j]:
                    best["boxes"] = (pieces.lo[mine], pieces.hi[mine])
                    out.set(j, **best)
        return out

    def _narrowest(self, candidates, t_since: float, ref: Interval) -> "Decay":
        """Per set, the candidate certificate (started: ``v1`` known) whose box
        ``t_since`` after its start is narrowest relative to ``ref``: a larger rate can come
        with a larger floor or a weaker ``P_low`` (smaller pieces), so the rate alone does
        not decide."""
        cols = self._bounded
        widths = np.array([_scaled_width(self._decay_box(c, t_since, _unbounded(ref))[:, cols], ref[:, cols])
                           for c in candidates])
        out = candidates[0]
        for j, k in enumerate(np.argmin(widths, axis=0)):
            if k != 0:
                out.take_row(j, candidates[k], j)
        return out

    def _pieces(self, region: Interval, k: int):
        """``(pieces Interval (B m, N), owner (B m,))``: each box cut in ``k`` along up to 3
        positions, those along which the mass matrix varies most over it."""
        B, N = region.shape
        if k <= 1:
            return region, np.arange(B)
        J = jacobian_interval(self._y["mass"], region)[:, :, self.iu]
        sens = np.maximum(np.abs(J.lo), np.abs(J.hi)).sum(axis=1) * region.width()[:, self.iu]  # (B, n)
        d = min(3, self.n)
        lo_all, hi_all, owner = [], [], []
        for j in range(B):
            dims = self.iu[np.argsort(-sens[j], kind="stable")[:d]]
            lo, hi = region.lo[j], region.hi[j]
            for idx in itertools.product(range(k), repeat=d):
                plo, phi = lo.copy(), hi.copy()
                for dim, i in zip(dims, idx):
                    w = (hi[dim] - lo[dim]) / k
                    plo[dim] = lo[dim] + i * w
                    phi[dim] = hi[dim] if i == k - 1 else lo[dim] + (i + 1) * w
                lo_all.append(plo)
                hi_all.append(phi)
                owner.append(j)
        return _I(np.array(lo_all), np.array(hi_all)), np.array(owner)

    def _matrices(self, pieces: Interval, uc: Interval):
        """``Kb, A, N, Dm, Ds`` (interval (P, n, n) each) over the pieces (see :meth:`certify`)."""
        n, iu, iz = self.n, self.iu, self.iz
        P = pieces.shape[0]
        lo, hi = pieces.lo.copy(), pieces.hi.copy()
        lo[:, iu], hi[:, iu] = np.minimum(lo[:, iu], uc.lo), np.maximum(hi[:, iu], uc.hi)
        Om = _I(lo, hi)  # holds every segment from u_c(p) to a state of the piece
        Hl = jacobian_interval(self._level_gradient(), _zero_rates(Om, iz))
        Kb = Hl[:, iu][:, :, iu]
        Kb = (Kb + Kb.swapaxes(-1, -2)) * 0.5
        dAy = jacobian_interval(self._y["mass"], Om)  # (P, n n, N)
        A = self._mass_over(Om, dAy)
        A = (A + A.swapaxes(-1, -2)) * 0.5
        dA = dAy[:, :, iu].reshape(P, n, n, n)
        Nm = (dA * (pieces[:, iu] - uc)[:, None, None, :]).sum(axis=-1)
        Nm = (Nm + Nm.swapaxes(-1, -2)) * 0.5
        Dm = eval_interval(self._y["dissipation"], Om).reshape(P, n, n)
        Ds = (Dm + Dm.swapaxes(-1, -2)) * 0.5
        return Kb, A, Nm, Dm, Ds

    def _certify_pieces(self, mats, mine, bsq, eps_values=None):
        """The best common certificate over the pieces ``mine`` (dict for :meth:`Decay.set`
        without ``boxes``), or None: for each ``eps`` every piece must certify; the rate is
        the smallest (a piece's inequality holds at any smaller rate, ``P >= 0``), ``gamma``
        the largest."""
        Kb, A, Nm, Dm, Ds = mats
        amid, dmid = A.mid()[mine], Ds.mid()[mine]
        try:
            rate = np.linalg.eigvals(np.linalg.solve(amid, dmid)).real
        except np.linalg.LinAlgError:
            return None
        r = float(np.median(rate)) if np.all(np.isfinite(rate)) and np.median(rate) > 0 else 0.0
        best = None
        for eps in (eps_values if eps_values is not None else [f * r for f in (0.05, 0.1, 0.2, 0.3, 0.45)]):
            if not eps > 0:
                continue
            certs = []
            for i in mine:
                c = self._certify(eps, Kb[i], A[i], Nm[i], Dm[i], Ds[i])
                if c is None:
                    break
                certs.append(c)
            else:
                lam = min(c["lam"] for c in certs)
                if best is not None and lam <= best["lam"]:
                    continue
                gamma = max((lam + eps) ** 2 * float((c["d2"] * bsq).sum()) / (4 * c["margin"]) for c in certs) * _UP
                best = dict(eps=eps, lam=lam, gamma=gamma, p_min=np.array([c["p_min"] for c in certs]),
                            pinv=np.array([c["pinv"] for c in certs]), p_low=np.array([c["p_low"] for c in certs]),
                            p_hi=np.array([c["p_hi"] for c in certs]))
        return best

    def decay(self, sets, region: Interval, params=None, tries: int = 5, horizon: float = 1.0) -> "Decay":
        """:meth:`certify` over ``region`` (boxes every later state stays in), started from
        ``V~`` over the solver's sets; where that fails, over a region of its own.

        A region of its own: a box ``R`` holding the set's hull, certified, whose own box
        ``B`` for the level ``1.001 v1`` lies in ``R``. Then no solution leaves ``B``: while
        in ``R`` its ``V~`` does not rise above ``v1`` (``v1`` above the floor
        ``gamma / lam``), so it stays in the box of level ``v1``, which lies inside ``B``.
        (On robots the energy box alone can be too wide to certify; docs/lab/code_notes.md.)"""
        candidates = []
        for k in (1, 2, 3):  # the region whole and cut in 8 and 27: the narrowest at the horizon
            c = self.certify(region, k)
            self._start_levels(c, sets, params)
            candidates.append(c)
        out = self._narrowest(candidates, horizon, region)
        hull = self._sets_hull(sets, params)
        todo = np.flatnonzero(~((out.lam > 0) & np.isfinite(out.v1)))
        lo, hi = hull.lo[todo].copy(), hull.hi[todo].copy()
        mid, rad = 0.5 * (lo + hi), 0.5 * (hi - lo)
        lo, hi = mid - 1.5 * rad, mid + 1.5 * rad
        for _ in range(max(0, int(tries))):
            if todo.size == 0:
                break
            R = _I(lo, hi)
            own = self.certify(R)
            self._start_levels(own, _select(sets, todo), params)
            ok = (own.lam > 0) & np.isfinite(own.v1) & (own.v1 > own.gamma / np.where(own.lam > 0, own.lam, 1))
            Bx = self._decay_box(_scaled_level(own, 1.001), 0.0, _unbounded(R))
            inside = ok & np.all((Bx.lo >= lo) & (Bx.hi <= hi), axis=1)
            for k in np.flatnonzero(inside):
                out.take_row(todo[k], own, k)
            keep = ~inside
            blo = np.where(np.isfinite(Bx.lo), np.minimum(lo, Bx.lo), lo)[keep]
            bhi = np.where(np.isfinite(Bx.hi), np.maximum(hi, Bx.hi), hi)[keep]
            m2, r2 = 0.5 * (blo + bhi), 0.5 * (bhi - blo)
            lo, hi, todo = m2 - 1.2 * r2, m2 + 1.2 * r2, todo[keep]
        return out

    def _start_levels(self, out: "Decay", sets, params) -> None:
        ok = np.flatnonzero(out.lam > 0)
        for eps in np.unique(out.eps[ok]):
            idx = ok[out.eps[ok] == eps]
            out.v1[idx] = self._upper_over(*self._vtilde(eps), _select(sets, idx), params)

    def _sets_hull(self, sets, params) -> Interval:
        """The sets' hulls over ``y``: the states, then the parameters, carried by the sets
        (``params`` None) or given (graph parameters, point or interval)."""
        H = sets.hull()
        if params is None or self.n_p == 0:
            return H[:, :self.n_x + self.n_p]
        P = params if isinstance(params, Interval) else _I(params)
        P = P.broadcast_to((H.shape[0], self.n_p)) if P.ndim == 1 else P
        return concatenate([H[:, :self.n_x], P], axis=1)

    def chain(self, first: "Decay", region: Interval, horizon: float, stages: int = 12):
        """Certificates one after another: ``[(dt_k, Decay_k)]``, ``dt_0 = 0`` the first.

        Certificate ``k`` holds from ``dt_k`` on; its box at ``dt_(k+1)`` (one e-fold of
        its bound later) holds for all later times, so certificate ``k + 1`` is certified
        over that smaller box (a larger rate) and started from what ``k`` bounds there
        (:meth:`_chain_levels`). Per set the new one is kept where its box at the horizon
        is narrower; candidates: a free ``eps`` and the old one's (the metric barely
        changes, so little is lost in the restart)."""
        out = [(0.0, first)]
        cur, box, t = first, region, 0.0
        cols = self._bounded
        for _ in range(max(0, int(stages))):
            ok = (cur.lam > 0) & np.isfinite(cur.v1)
            if not ok.any():
                break
            step = float(np.max(1.0 / cur.lam[ok]))
            if t + step >= horizon:
                break
            t += step
            box = self._decay_box(cur, step, box)
            rest = horizon - t
            candidates = []
            for eps in (None, np.where(ok, cur.eps, 1.0)):
                cand = self.certify(box, eps=eps)
                self._chain_levels(cand, cur, ok, step)
                candidates.append(cand)
            nxt = self._narrowest(candidates, rest, box)
            w_new = _scaled_width(self._decay_box(nxt, rest, _unbounded(box))[:, cols], box[:, cols])
            w_old = _scaled_width(self._decay_box(cur, step + rest, _unbounded(box))[:, cols], box[:, cols])
            worse = ~np.isfinite(nxt.v1) | (nxt.lam <= 0) | ~self._better(w_new, w_old)
            if worse.all():
                break
            nxt.keep_from(cur, worse)
            for j in np.flatnonzero(worse & ok):  # the old bound, restarted at t
                nxt.v1[j] = self._level_at(cur, j, step)[0]
            out.append((t, nxt))
            cur = nxt
        return out

    @staticmethod
    def _better(w_new, w_old):
        """Where a restart is kept: its box at the horizon is narrower."""
        return w_new < w_old

    def _chain_levels(self, nxt: "Decay", cur: "Decay", ok, step: float) -> None:
        """``nxt.v1`` from what ``cur`` bounds ``step`` after its start: the state lies in
        some old piece (``y^T P_low y <= w``, ``|y| <= Y``) and some new piece (its
        ``P <= P_hi``), so ``V~ <= beta Y + mu w`` with ``mu`` a verified bound of
        ``max y^T P_hi y / y^T P_low y``, over every pair of pieces."""
        for j in np.flatnonzero((nxt.lam > 0) & ok):
            _, ymax, wv = self._level_at(cur, j, step)
            v1 = 0.0
            for hi_new in nxt.p_hi[j]:
                for low_old, y_o, w_o in zip(cur.p_low[j], ymax, wv):
                    mu = _max_ratio(hi_new, low_old)
                    v1 = np.inf if mu is None else max(v1, (nxt.beta[j] * y_o + mu * w_o) * _UP)
            if np.isfinite(v1):
                nxt.v1[j] = v1
            else:
                nxt.lam[j] = 0.0

    def _level_at(self, dec: "Decay", j: int, t_since: float):
        """``(v, Y, w)`` for set ``j`` at ``t_since`` after the certificate's start:
        ``V~ <= v``, and in piece ``i`` ``|y| <= Y[i]`` and ``y^T P_low,i y <= w[i]``."""
        lam, beta, pm = dec.lam[j], dec.beta[j], dec.p_min[j]
        floor = dec.gamma[j] / lam * _UP
        v = max(floor + max(dec.v1[j] - floor, 0.0) * np.exp(-lam * t_since) * _UP, 0.0)
        ymax = (beta + np.sqrt(beta * beta + 4 * pm * v)) / (2 * pm) * _UP
        return v, ymax, (v + beta * ymax) * _UP

    def _decay_box(self, dec: "Decay", t_since: float, boxes: Interval) -> Interval:
        """``boxes`` narrowed by the certificate: a state lies in one of its pieces, where
        ``delta`` and ``z`` are bounded by that piece's ellipsoid; the hull over pieces."""
        lo, hi = boxes.lo.copy(), boxes.hi.copy()
        n, iu, iz = self.n, self.iu, self.iz
        for j in np.flatnonzero((dec.lam > 0) & np.isfinite(dec.v1)):
            _, _, wv = self._level_at(dec, j, t_since)
            r = np.sqrt(wv[:, None] * dec.pinv[j]) * _UP  # (pieces, 2n): delta then z
            plo, phi = dec.boxes[j]
            ulo = np.maximum(plo[:, iu], dec.uc_lo[j] - r[:, :n])
            uhi = np.minimum(phi[:, iu], dec.uc_hi[j] + r[:, :n])
            zlo = np.maximum(plo[:, iz], -r[:, n:])
            zhi = np.minimum(phi[:, iz], r[:, n:])
            live = (ulo <= uhi).all(axis=1) & (zlo <= zhi).all(axis=1)
            if not live.any():
                continue  # no piece holds a state: cannot be, keep the boxes as they are
            lo[j, iu] = np.maximum(lo[j, iu], ulo[live].min(axis=0))
            hi[j, iu] = np.minimum(hi[j, iu], uhi[live].max(axis=0))
            lo[j, iz] = np.maximum(lo[j, iz], zlo[live].min(axis=0))
            hi[j, iz] = np.minimum(hi[j, iz], zhi[live].max(axis=0))
        return _I(lo, hi)

    def decay_boxes(self, chain, t_since: float, energy_boxes: Interval) -> Interval:
        """Boxes (B, N) at ``t_since`` seconds after the first certificate's time: the
        energy boxes intersected with every certificate of ``chain`` (a :meth:`chain`
        list, or one Decay) that has started by then."""
        if isinstance(chain, Decay):
            chain = [(0.0, chain)]
        box = energy_boxes
        for t_k, dec in chain:
            if t_k <= t_since:
                box = self._decay_box(dec, t_since - t_k, box)
        return box

    def _parts_over(self, Om: Interval, pieces: int = 32) -> Interval:
        """The decay parts (``b(p)``, ``l_c(p)``, ``w``) over each box (B, n + 2): the hull of
        their mean-value forms over ``pieces`` slices of the parameter ``b`` spreads most
        along (``b`` and ``l_c`` depend on ``p`` only and nearly vanish: their natural
        enclosures are all dependency)."""
        parts = self._decay_parts()
        B, N = Om.shape
        n = self.n
        pcols = np.setdiff1d(np.arange(N), self._bounded)
        lo, hi = Om.lo, Om.hi
        if pcols.size == 0 or not np.any(hi[:, pcols] > lo[:, pcols]):
            return self._mean_value_graph(parts, Om)
        # slice the parameter b spreads most along (its Jacobian column times the width)
        J = jacobian_interval(parts, Om)[:, :n, :]  # (B, n, N)
        mag = np.maximum(np.abs(J.lo), np.abs(J.hi))
        spread = (mag * (hi - lo)[:, None, :]).sum(axis=1).max(axis=0)  # (N,)
        k = pcols[np.argmax(np.where(np.isfinite(spread[pcols]), spread[pcols], np.inf))]
        edges = lo[:, k][:, None] + (hi[:, k] - lo[:, k])[:, None] * np.linspace(0.0, 1.0, pieces + 1)[None, :]
        edges[:, -1] = hi[:, k]
        slo = np.repeat(lo[:, None, :], pieces, axis=1)
        shi = np.repeat(hi[:, None, :], pieces, axis=1)
        slo[:, :, k], shi[:, :, k] = edges[:, :-1], edges[:, 1:]
        v = self._mean_value_graph(parts, _I(slo.reshape(-1, N), shi.reshape(-1, N)))
        m = v.shape[-1]
        return _I(v.lo.reshape(B, pieces, m).min(axis=1), v.hi.reshape(B, pieces, m).max(axis=1))

    def _b_squares(self, Om: Interval) -> np.ndarray:
        """Upper bounds (B, n) of ``b_i(p)^2`` over each box's parameters."""
        bv = self._parts_over(Om)[:, :self.n]
        return np.maximum(bv.lo ** 2, bv.hi ** 2) * _UP

    def _mean_value_graph(self, g: Graph, Y: Interval) -> Interval:
        nat = eval_interval(g, Y)
        m = Y.mid()
        fm = eval_interval(g, _I(m))
        J = jacobian_interval(g, Y)
        return nat.intersect(fm + (J * (Y - m)[:, None, :]).sum(axis=-1))

    def _certify(self, eps, Kb, A, Nm, Dm, Ds):
        """A verified ``Q - lam P >= margin D^-2`` (``D`` the Jacobi scaling of its
        midpoint) over the interval matrices of one set, as a dict (``eps``, ``lam``,
        ``margin``, ``d2``: the position block of ``D^2``, ``p_min``, ``pinv``: diag of
        ``P_low^-1``, ``p_low``, ``p_hi``: float matrices bounding every member of ``P``),
        or None."""
        import scipy.linalg as sla  # (import here: scipy.linalg, ~0.5 s, only when this check runs)
        n = self.n
        Q = _blocks(Kb * eps, Dm * (0.5 * eps), Dm.swapaxes(-1, -2) * (0.5 * eps), Ds - A * eps - Nm * (0.5 * eps))
        P = _blocks(Kb * 0.5, A * (0.5 * eps), A * (0.5 * eps), A * 0.5)
        Pm, Pr = _mid_rad(P)
        m2 = 2 * n
        got = _psd_margin(Pm, Pr)
        if got is None:
            return None
        d2, _, rho = got  # every member: D (P - Pm) D >= -rho I
        p_low = Pm - rho * np.diag(1.0 / d2)
        p_hi = Pm + rho * np.diag(1.0 / d2)
        p_min = np.linalg.eigvalsh(p_low)[0] * (1 - 1e-9) - 1e-12 * m2 * np.abs(p_low).max()
        if not p_min > 0:
            return None
        Qm, _ = _mid_rad(Q)
        try:
            lam_mid = float(sla.eigh(Qm, Pm, eigvals_only=True)[0])
        except (np.linalg.LinAlgError, ValueError):
            return None
        if not lam_mid > 0:
            return None
        for theta in (0.9, 0.75, 0.6, 0.45, 0.3, 0.15):  # (a finer grid: larger rates, smaller margins, higher floors; measured worse)
            lam = theta * lam_mid
            got = _psd_margin(*_mid_rad(Q - P * lam))
            if got is None:
                continue
            d2s, margin, _ = got  # Q - lam P >= margin D^-2 for every member
            pinv = linalg.inverse_diagonal(p_low).hi * _UP
            if not np.all(np.isfinite(pinv) & (pinv > 0)):
                return None
            return dict(eps=eps, lam=lam, margin=margin * (1 - 1e-9), d2=d2s[:n], p_min=p_min, pinv=pinv,
                        p_low=p_low, p_hi=p_hi)
        return None


class Decay:
    """Per set ``j``: ``eps``, ``lam`` (1/s; 0 where no certificate), ``gamma`` (W: the rate
    bound is ``dV~/dt <= -lam V~ + gamma``), ``beta`` (bound of ``|b|``), ``v1`` (``V~``
    at the certificate's start), ``uc_lo``/``uc_hi`` (the centre over the parameters);
    and per piece of its region (lists indexed by ``j``, arrays over the pieces):
    ``boxes`` (lo, hi), ``p_min``, ``pinv`` (diag of ``P_low^-1``), ``p_low``/``p_hi``
    (float matrices bounding ``P``)."""

    _PER_SET = ("eps", "lam", "gamma", "beta", "v1", "uc_lo", "uc_hi")
    _PER_PIECE = ("boxes", "p_min", "pinv", "p_low", "p_hi")

    def __init__(self, B, n):
        self.eps, self.lam, self.gamma = np.zeros(B), np.zeros(B), np.zeros(B)
        self.beta, self.v1 = np.zeros(B), np.full(B, np.inf)
        self.uc_lo = self.uc_hi = None
        for name in self._PER_PIECE:
            setattr(self, name, [None] * B)

    def set(self, j, eps, lam, gamma, p_min, pinv, p_low, p_hi, boxes):
        self.eps[j], self.lam[j], self.gamma[j] = eps, lam, gamma
        self.p_min[j], self.pinv[j], self.p_low[j], self.p_hi[j], self.boxes[j] = p_min, pinv, p_low, p_hi, boxes

    def take_row(self, j, other: "Decay", k) -> None:
        """Row ``j`` becomes ``other``'s row ``k``."""
        for name in self._PER_SET + self._PER_PIECE:
            getattr(self, name)[j] = getattr(other, name)[k]

    def keep_from(self, other: "Decay", rows) -> None:
        """Take ``other``'s certificates for ``rows`` (where this one is no better)."""
        for j in np.flatnonzero(rows):
            self.take_row(j, other, j)


def _unbounded(like: Interval) -> Interval:
    """Boxes of ``like``'s shape with no bounds (what a certificate's box narrows)."""
    return _I(np.full_like(like.lo, -np.inf), np.full_like(like.hi, np.inf))


def _scaled_level(dec: Decay, f: float) -> Decay:
    out = Decay.__new__(Decay)
    out.__dict__.update(dec.__dict__)
    out.v1 = dec.v1 * f
    return out


def _zero_rates(Y: Interval, iz) -> Interval:
    lo, hi = Y.lo.copy(), Y.hi.copy()
    lo[:, iz], hi[:, iz] = 0.0, 0.0
    return _I(lo, hi)


def _scaled_width(b: Interval, ref: Interval) -> np.ndarray:
    """Sum over components of ``b``'s widths relative to ``ref``'s (inf where unbounded)."""
    w = ref.hi - ref.lo
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.where(w > 0, (b.hi - b.lo) / np.where(w > 0, w, 1.0), 0.0)
    return np.where(np.isfinite(r), r, np.inf).sum(axis=1)


def _blocks(a, b, c, d) -> Interval:
    return concatenate([concatenate([a, b], axis=-1), concatenate([c, d], axis=-1)], axis=-2)


def _mid_rad(S: Interval):
    """Symmetrized midpoint and a radius with ``|S' - mid| <= rad`` for every member."""
    m = 0.5 * (S.lo + S.hi)
    r = np.maximum(S.hi - m, m - S.lo) * _UP
    m = 0.5 * (m + m.T)
    r = np.maximum(r, r.T) + np.abs(m - 0.5 * (S.lo + S.hi)) * _UP
    return m, r


def _psd_margin(m, r):
    """For the symmetric interval matrix ``m`` +- ``r``: ``(d2, margin, rho)`` with
    ``D = diag(d2)^(1/2)`` the Jacobi scaling (``d2 = 1 / diag(m)``), ``rho`` a bound of
    ``||D (S - m) D||_2`` over every member ``S`` and ``margin > 0`` a lower bound of
    ``lambda_min(D S D)`` (Weyl); None when that bound is not positive (or a diagonal
    entry is not)."""
    dg = np.diag(m)
    if not np.all(dg > 0):
        return None
    d = 1.0 / np.sqrt(dg)
    sm = m * d[:, None] * d[None, :]
    k = m.shape[0]
    sr = r * d[:, None] * d[None, :] * _UP
    sr = np.maximum(sr, sr.T)
    # ||S - m||_2 <= ||sr||_2 = its Perron root (sr >= 0 symmetric); the float eigenvalue
    # is backward stable (error <= k eps ||sr||), so a relative 1e-10 covers it. The
    # Frobenius norm, the first choice, is up to sqrt(k) larger: on the UR5's 12 x 12
    # matrices it failed where this holds.
    perron = np.linalg.eigvalsh(sr)[-1] * (1 + 1e-10) + 1e-12 * k * np.abs(sr).max()
    rho = min(np.sqrt((sr ** 2).sum()) * _UP, perron) + 1e-12 * k * np.abs(sm).max()
    margin = np.linalg.eigvalsh(0.5 * (sm + sm.T))[0] - 1e-12 * k * np.abs(sm).max() - rho \
        - np.abs(sm - sm.T).max()
    if not margin > 0:
        return None
    return d * d * (1 + 1e-12), margin, rho


def _max_ratio(p_hi, p_low):
    """A verified ``mu >= max y^T p_hi y / y^T p_low y`` (floats, ``p_low`` positive
    definite): ``mu p_low - p_hi >= 0`` checked with :func:`_psd_margin`; None if not."""
    import scipy.linalg as sla  # (import here: see above)
    try:
        mu = float(sla.eigh(p_hi, p_low, eigvals_only=True)[-1])
    except (np.linalg.LinAlgError, ValueError):
        return None
    for f in (1.0 + 1e-6, 1.01, 1.1):
        diff = mu * f * p_low - p_hi  # its float rounding is covered by the radius
        if _psd_margin(diff, (np.abs(mu * f * p_low) + np.abs(p_hi)) * 4e-16) is not None:
            return mu * f * _UP
    return None


def _select(sets, idx):
    """The sets ``idx`` of a batch (first-order sets, projections or hulls)."""
    if isinstance(sets, _HullOnly):
        return _HullOnly(sets.hull()[idx])
    if isinstance(sets, _Projected):
        out = _Projected.__new__(_Projected)
        out.c, out.C, out.Q, out.r0, out.r = sets.c[idx], sets.C[idx], sets.Q[idx], sets.r0[idx], sets.r[idx]
        return out
    return sets.take(idx)


class InvariantHook(Hook):
    """End the integration once the sets lie in verified invariant boxes (see the module
    docstring) and report those boxes for every later output time.

    From the first step that ends at or after ``t_switch``, after every step: the level
    ``c`` of each set (mean-value form of ``L``) and its box. When every set's box is
    verified, the run stops there; :meth:`after_run` then adds the boxes at the output
    times ``t_eval`` after that time, one tube piece up to ``t_end``, and reports the run
    ``completed`` with ``stats["invariant_from"]`` (s) and ``stats["invariant_level"]``
    (largest ``c``). While some set's box cannot be verified the integration goes on.

    Soundness rests on the claim that ``L`` does not increase along solutions (module
    docstring); the hook calls :meth:`QuadraticLyapunov.check` at the initial sets' corners
    and centre before the first step.
    """

    def __init__(self, lyapunov: QuadraticLyapunov, t_switch: float, t_eval, t_end: float):
        if not isinstance(lyapunov, QuadraticLyapunov):
            raise TypeError(f"lyapunov must be a QuadraticLyapunov, got {type(lyapunov).__name__}")
        t_switch, t_end = float(t_switch), float(t_end)
        if not (np.isfinite(t_switch) and np.isfinite(t_end)):
            raise ValueError(f"t_switch and t_end must be finite, got {t_switch!r}, {t_end!r}")
        self.lyap, self.t_switch, self.t_end = lyapunov, t_switch, t_end
        self.t_eval = np.asarray(t_eval, float)
        self.result = None  # (t, InvariantBoxes)
        self.attempts = 0
        self._wait = 0
        self._reason = None

    def before_run(self, setup):
        ly = self.lyap
        self.n_state = setup.n_state
        if setup.n_state != ly.n_x:
            raise ValueError(f"the Lyapunov function takes {ly.n_x} states, the ODE has {setup.n_state}")
        carried = setup.graph.n_inputs - setup.n_state
        self.params = setup.params
        if setup.params is None and carried < ly.n_p:
            raise ValueError(f"the Lyapunov function takes {ly.n_p} parameters, the run carries {carried}")
        self.n_y = ly.n_x + ly.n_p
        H = setup.sets.hull()
        x = np.concatenate([H.lo[:, :ly.n_x], H.mid()[:, :ly.n_x], H.hi[:, :ly.n_x]], axis=0)
        if setup.params is None:
            p = np.concatenate([H.lo[:, ly.n_x:self.n_y], H.mid()[:, ly.n_x:self.n_y], H.hi[:, ly.n_x:self.n_y]])
        else:
            P = setup.params if isinstance(setup.params, Interval) else _I(setup.params)
            p = np.broadcast_to(P.mid(), (x.shape[0], ly.n_p))
        ly.check(x, p)
        if "dissipation" in ly.graphs:
            ly.check_dynamics(setup.user_graph, x, p)
        return None

    def _sets_y(self, sets):
        """The sets restricted to ``y`` (states and carried parameters; appended states of
        other hooks dropped)."""
        k = self.n_y if self.params is None else self.lyap.n_x  # graph parameters are not in the sets
        if type(sets) is DoubletonSets and sets.c.shape[1] > k:
            return _Projected(sets, k)  # states other hooks appended (h) dropped
        if type(sets) is not DoubletonSets and sets.hull().shape[1] > k:
            return _HullOnly(sets.hull()[:, :k])
        return sets

    def after_step(self, step, sets, run):
        if self.result is not None or step.t < self.t_switch * (1 - 1e-12) - 1e-300:
            return None
        # after a failed attempt wait 1, 2, 4, ... steps: an attempt costs about a step,
        # and attempts may fail for many steps in a row (docs/lab/code_notes.md)
        self._wait -= 1
        if self._wait > 0:
            return None
        self.attempts += 1
        self._wait = 2 ** self.attempts
        c = self.lyap.level_over(self._sets_y(sets), None if self.params is None else self.params)
        res = self.lyap.boxes(c, self.lyap._sets_hull(sets, self.params))
        if res.verified.all():
            dec = None
            if "dissipation" in self.lyap.graphs:
                first = self.lyap.decay(self._sets_y(sets), res.boxes, self.params,
                                        horizon=max(self.t_end - step.t, 0.0))
                dec = self.lyap.chain(first, res.boxes, self.t_end - step.t)
            self.result = (step.t, res, dec)
            self._reason = (f"held from t = {step.t:g} s on by an invariant sublevel set of the "
                            f"Lyapunov function (L <= {np.max(c):.3g})")
            run.stop(self._reason, "stopped")
        return None

    def after_run(self, solution) -> None:
        solution.stats["invariant_attempts"] = self.attempts
        if self.result is None or solution.reason != self._reason:
            return
        t1, res, dec = self.result
        n = self.n_state

        def at(t):
            if dec is None:
                return res.boxes[:, :n]
            return self.lyap.decay_boxes(dec, t - t1, res.boxes)[:, :n]

        later = self.t_eval[(self.t_eval > t1) & (self.t_eval <= self.t_end)]
        solution.t = np.concatenate([solution.t, later])
        solution.boxes = list(solution.boxes) + [at(t) for t in later]
        if solution.views:
            solution.views = list(solution.views) + [None] * len(later)  # (boxes, no sets)
        solution.hull = iv.stack_hulls(solution.boxes)
        if self.t_end > t1:
            # tube pieces at the output times and on a grid of 100 (each the box at its
            # start: the bound of V~ only falls with time; the energy box holds throughout)
            edges = np.unique(np.concatenate([[t1], later, np.linspace(t1, self.t_end, 101)[1:-1],
                                              [self.t_end]]))
            if solution.tube_views:
                solution.tube_views = list(solution.tube_views) + [None] * (edges.size - 1)  # (boxes)
            solution.tube = list(solution.tube) + [at(a) for a in edges[:-1]]
            solution.tube_t = np.concatenate([solution.tube_t, edges[1:]])
            solution.tube_hull = iv.stack_hulls(solution.tube)
        solution.t_reached = max(self.t_end, t1)
        solution.status, solution.reason = "completed", ""
        solution.stats["invariant_from"] = t1
        solution.stats["invariant_level"] = float(np.max(res.level))
        solution.stats["invariant_box"] = res.boxes[:, :n]
        if dec is not None:
            solution.stats["decay_rates"] = [(t1 + t_k, d.lam.copy()) for t_k, d in dec]


class _Projected:
    """First-order sets restricted to their first ``k`` coordinates (rows of c, C, Q)."""

    def __init__(self, sets, k):
        self.c = sets.c[:, :k]
        self.C = sets.C[:, :k, :]
        self.Q = sets.Q[:, :k, :]
        self.r0, self.r = sets.r0, sets.r

    def hull(self):
        return (linalg.matvec(self.C, self.r0) + linalg.matvec(self.Q, self.r)) + self.c


class _HullOnly:
    """Sets known only by their hull boxes."""

    def __init__(self, H):
        self._H = H

    def hull(self):
        return self._H

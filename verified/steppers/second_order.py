"""The mean-value step of second-order sets (:class:`QuadraticStepper`): the QR-Lohner step
plus the second variational equations at the centres, advancing
:class:`verified.sets.second_order.QuadraticSets` (whose docstring derives the step).
"""

from __future__ import annotations

import numpy as np

from verified.arith import linalg
from verified.arith.interval import Interval, concatenate, point
from verified.steppers.lohner import LohnerStepper, horner
from verified.steppers.protocol import StepResult
from verified.series.variational import pair_index
from verified.sets.second_order import QuadraticSets, _bilinear, quadratic_range

__all__ = ["QuadraticStepper"]


class QuadraticStepper(LohnerStepper):
    """Verified steps of :class:`QuadraticSets` (module docstring). ``second`` is a
    Taylor evaluator (``verified.series.taylor.TaylorODE``) of the second variational graph;
    the rest is as :class:`~verified.steppers.lohner.LohnerStepper` (whose a-priori enclosure,
    step-size suggestion and error-basis policy it uses unchanged)."""

    def __init__(self, taylor, variational, second, order: int, params=None, error_basis="qr", second_over_set=None,
                 absorb_ratio: float = 0.1, max_params: int | None = None, second_directional=None,
                 max_directions: int = 8):
        super().__init__(taylor, variational, order, params, error_basis, absorb=bool(np.isfinite(absorb_ratio)))
        # the error part becomes parameters (QuadraticSets.absorb_error) once it is
        # absorb_ratio times the carried part in some component, up to max_params
        # parameters (default 4n). Why: an interval error vector is multiplied by |J|
        # every step, and a strongly non-normal J (a robot's Coriolis shear) grows it
        # fast where the exactly carried part stays near the true hull; absorbed, it
        # is carried exactly (docs/lab/code_notes.md).
        self.absorb_ratio = float(absorb_ratio)
        self.max_params = 4 * self.n if max_params is None else int(max_params)
        self.second = second
        # an affine evaluator of the second variational equations takes the set's own
        # forms for the Hessian in the Lagrange term (over the hull box, interval
        # Taylor coefficients of the Hessian are far too wide on robots; docs/lab/code_notes.md)
        self.second_over_set = second_over_set
        self.pairs = pair_index(self.n)
        # second_directional(p): an evaluator over the set's forms of the second
        # variational equations along p directions (second_variational_graph(g, p)).
        # With it, the Hessian over the set is taken only along the columns of C that
        # carry width (at most max_directions), where the set actually extends; the
        # rest of v (the other columns, q) is paired with the interval Hessian over the
        # hull, and the Jacobian's mean-value form loses the Hessian over the set. Pays
        # where the full second variational system is large, hence only from
        # directional_min_states states on: below, it costs more than it gains
        # (docs/lab/code_notes.md).
        self.second_directional = second_directional
        self.max_directions = int(max_directions)
        self.directional_min_states = 8

    def _derivatives(self, x, h):
        """``DP`` (B, n, n) and ``H`` (B, n, n, n) of the Taylor polynomial map over the
        boxes ``x`` (B, n) (points: thin enclosures at them), or over affine forms
        ``x`` (n + extra, B, m + 2) of :meth:`QuadraticSets.affine_forms`."""
        n, K = self.n, self.order
        npairs = len(self.pairs)
        if isinstance(x, Interval):
            nb = x.shape[0]
            v0 = point(np.broadcast_to(np.eye(n).reshape(-1), (nb, n * n)))
            w0 = point(np.zeros((nb, n * npairs)))
            co = self.second.coefficients(concatenate([x, v0, w0], axis=1), K - 1, self._params(nb))
        else:
            nb = x.shape[1]
            x[n:n + n * n, :, 0] = np.eye(n).reshape(-1)[:, None]
            co = self.second_over_set.series(x, K - 1, self._params(nb))
        D = horner(co[:, :, n:n + n * n], h).reshape((nb, n, n))
        Wp = horner(co[:, :, n + n * n:], h).reshape((nb, npairs, n))  # (pair, component i)
        lo = np.empty((nb, n, n, n))
        hi = np.empty((nb, n, n, n))
        for k, (a, b) in enumerate(self.pairs):
            lo[:, :, a, b] = lo[:, :, b, a] = Wp.lo[:, k, :]
            hi[:, :, a, b] = hi[:, :, b, a] = Wp.hi[:, k, :]
        return D, Interval._from_bounds(lo, hi)

    def _directions(self, sets: QuadraticSets):
        """Indices of the parameters (columns of C) whose range has width in some set of
        the batch, the widest ``max_directions`` of them; None when that is every
        parameter (or none: the full Hessian over the set is then no dearer), or when
        the system has fewer than ``directional_min_states`` states."""
        m = sets.C.shape[2]
        if self.n < self.directional_min_states:
            return None
        rad = sets.r0.rad()  # (B, m)
        reach = (np.abs(sets.C) * rad[:, None, :]).max(axis=1).max(axis=0)  # (m,)
        # (a column whose reach is rounding-level, 1e-323 after a hull with 0, is no
        # direction: it goes with the rest of v, which is bounded all the same)
        live = np.flatnonzero(reach > 1e-12 * reach.max())
        if live.size > self.max_directions:
            live = np.sort(live[np.argsort(-reach[live], kind="stable")[: self.max_directions]])
        if live.size == 0 or live.size >= min(m, self.n):
            return None
        return live

    def _directional_lagrange(self, sets, live, Hc, HU, qb, h) -> Interval:
        """``1/2 (H(xi) - H(c))[v, v]`` over the set, for ``v = C_L u_L + rho``: ``C_L``
        the live columns, ``rho = C_D u_D + q(u)`` the rest (the other columns and the
        quadratic part, in state space).

        ``C_L^T H(xi) C_L`` is enclosed over the set's own forms by the directional
        second variational equations (``V(0) = C_L``, ``W(0) = 0``; their Taylor
        polynomial at ``h`` gives the second derivatives of the Taylor map along the
        columns of ``C_L`` at every point of the set), so ``(C_L u)^T (H(xi) - H(c))
        (C_L u)`` is a quadratic form in ``u_L`` whose range ``quadratic_range`` bounds;
        the cross and ``rho`` terms use ``HU``, the Hessian over the hull box (they are
        second order in the set's size times ``rho``, which is small). Shapes: Hc, HU
        (B, n, n, n) Intervals; qb (B, n); returns (B, n)."""
        n, nb, K = self.n, sets.n_sets, self.order
        p = live.size
        pairs = pair_index(p)
        CL = np.ascontiguousarray(sets.C[:, :, live])  # (B, n, p)
        dead = np.setdiff1d(np.arange(sets.C.shape[2]), live)
        uL = sets.r0[:, live]
        forms = sets.affine_forms(extra=n * p + n * len(pairs))
        forms[n:n + n * p, :, 0] = CL.transpose(1, 2, 0).reshape(n * p, nb)
        co = self.second_directional(p).series(forms, K - 1, self._params(nb))
        Wp = horner(co[:, :, n + n * p:], h).reshape((nb, len(pairs), n))  # (pair, component i)
        lo = np.empty((nb, n, p, p))
        hi = np.empty((nb, n, p, p))
        for k, (a, b) in enumerate(pairs):
            lo[:, :, a, b] = lo[:, :, b, a] = Wp.lo[:, k, :]
            hi[:, :, a, b] = hi[:, :, b, a] = Wp.hi[:, k, :]
        G = Interval._from_bounds(lo, hi)  # C_L^T H(xi) C_L, (B, n, p, p)
        HcL = linalg.matmul(Hc.reshape((nb, n * n, n)), CL).reshape((nb, n, n, p))  # [i, a, l]
        CtHcC = linalg.matmul(np.broadcast_to(CL.transpose(0, 2, 1)[:, None], (nb, n, p, n)), HcL)  # [i, j, l]
        a = linalg.matvec(CL, uL)
        rho = qb if dead.size == 0 else qb + linalg.matvec(np.ascontiguousarray(sets.C[:, :, dead]), sets.r0[:, dead])
        dH = HU - Hc
        return quadratic_range(G - CtHcC, uL) * 0.5 + _bilinear(dH, a, rho) + _bilinear(dH, rho, rho) * 0.5

    def step(self, sets: QuadraticSets, h, X: Interval, E: Interval, cE: Interval) -> StepResult:
        K, n, nb = self.order, self.n, sets.n_sets
        # centre polynomial plus the Lagrange remainder over E (as the doubleton step)
        cP = self.coefficients(point(sets.c))
        y = horner(cP[:, :K], h) + cE[:, K] * (Interval(h) ** K)
        # DP and H at the centres, H over U = c + C r0 + q(r0) (holds every [c, c + v])
        Dc, Hc = self._derivatives(point(sets.c), h)
        Cu = linalg.matvec(sets.C, sets.r0)
        qb = sets.q_range()
        V = (Cu + qb).hull(0.0)  # every v = C u + q(u), and 0
        live = self._directions(sets) if self.second_directional is not None else None
        if live is not None:
            # the Hessian over the hull box (interval) for what pairs with the rest of v;
            # along the live columns of C it is taken over the set (_directional_lagrange)
            _, HU = self._derivatives(X.hull(V + sets.c), h)
        elif self.second_over_set is not None:
            # the set's forms cover every segment from c into the set (r0, r and the
            # range of q hold 0 and are convex): where the Lagrange xi lies, and the xi
            # of the Jacobian's mean value form below
            _, HU = self._derivatives(sets.affine_forms(extra=n * n + n * len(self.pairs)), h)
        else:
            _, HU = self._derivatives(X.hull(V + sets.c), h)  # X holds the set, V + c every [c, c + v]
        # Jacobian over the set for the error part (mean value in w = Q r)
        J = self.set_jacobian(sets, X.hull(V + sets.c), h)
        # ... and in second-order mean value form, J(x) = DP(c) + H(xi)[x - c]: its spread
        # is |H| |x - c| where the first-order enclosure's compounds through the graph
        # (on robots the error part grew fast per step with the first alone;
        # docs/lab/code_notes.md)
        # xi - c on [c + v, c + v + w] lies in the hull of V (every v, and 0) and the set - c
        # (r need not hold 0, so c + v itself need not be in the set)
        d = (sets.hull() - sets.c).hull(V)
        J_mv = Dc + linalg.matvec(HU.reshape((nb, n * n, n)), d).reshape((nb, n, n))
        J = J.intersect(J_mv)
        # linear part
        DC = linalg.matmul(Dc, sets.C)
        C_new = DC.mid()
        err_lin = linalg.matvec(DC - C_new, sets.r0)
        # quadratic part: S'_i = sum_k DP_ik S_k + 1/2 C^T H_i C
        m = sets.C.shape[2]
        DS = linalg.matmul(Dc, sets.S.reshape((nb, n, m * m))).reshape((nb, n, m, m))
        HC = linalg.matmul(Hc.reshape((nb, n * n, n)), sets.C).reshape((nb, n, n, m))  # [i, a, l]
        CtHC = linalg.matmul(np.broadcast_to(sets.C.transpose(0, 2, 1)[:, None], (nb, n, m, n)), HC)  # [i, j, l]
        S_int = DS + CtHC * 0.5
        S_new = S_int.mid()
        S_new = 0.5 * (S_new + S_new.transpose(0, 1, 3, 2))  # exactly symmetric (the rest goes to err)
        err_quad = quadratic_range(S_int - S_new, sets.r0)
        # third and fourth order: H(c)[C u, q] + 1/2 H(c)[q, q]; 1/2 (H(U) - H(c))[v, v]
        cubic = _bilinear(Hc, Cu, qb) + _bilinear(Hc, qb, qb) * 0.5
        if live is not None:
            lagrange = self._directional_lagrange(sets, live, Hc, HU, qb, h)
        else:
            lagrange = _bilinear(HU - Hc, V, V) * 0.5
        c_new = y.mid()
        nonlinear = err_quad + cubic + lagrange
        incoming = (y - c_new) + err_lin + nonlinear
        JQ = linalg.matmul(J, sets.Q)
        Q_out, r_new = self.basis.update(sets.Q, sets.r, JQ, incoming)
        new = QuadraticSets(c=c_new, C=C_new, r0=sets.r0, S=S_new, Q=Q_out, r=r_new)
        if self.absorb:
            new = self.absorb_error(new)
        return StepResult(sets=new, previous=sets, h=h, hull=X, tube=E, nonlinear_width=nonlinear.width())

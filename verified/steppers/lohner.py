"""One verified Taylor step for a batch of doubleton sets (QR-Lohner, as CAPD's Rect2).

A batch of ``B`` sets is carried as

    x  in  c + C r0 + Q r                         (all shapes per box: c (n,), C, Q (n, n))

with ``c`` a float centre, ``C`` a float matrix acting on the fixed initial radius box
``r0`` (so the main linear part of the flow wraps nothing), and ``Q r`` the accumulated
errors, ``Q`` re-orthogonalized every step (Lohner's QR method) and ``r`` an interval
vector. A step of size ``h``:

1. ``X`` = interval hull of the set; Taylor coefficients ``x_[i](X)`` (:mod:`verified.series.taylor`).
2. A-priori enclosure ``E`` of all solutions from ``X`` over ``[0, h]`` by the high-order
   enclosure test of Nedialkov, Jackson & Pryce (2001): if
   ``sum_{i<K} [0,h]^i x_[i](X) + [0,h]^K x_[K](E~) ⊆ E~`` then the solutions exist on
   ``[0, h]`` and stay in ``E~``.
3. ``y = Φ(c) + h^K x_[K](E)``: the Taylor polynomial at the centre plus the Lagrange
   remainder (valid for every solution from ``X``).
4. ``J`` = enclosure of ``DΦ`` over ``X`` from the Taylor coefficients of the variational
   equations (:mod:`verified.series.variational`); by the mean value theorem
   ``φ(h, x) ∈ y + J (x - c)`` for all ``x`` in the set.
5. New set: ``c' = mid(y)``, ``C' = mid(J C)``,
   ``r' = (Q'^-1 J Q) r + Q'^-1 ((J C - C') r0 + y - c')`` with ``Q'`` from the QR
   factorization of ``mid(J Q)`` (columns sorted by their share of the set's size),
   ``Q'^-1`` enclosed rigorously. With ``error_basis="auto"``, ``Q' = I`` (a plain
   box) is used instead for the sets where that encloses the error part more tightly
   at this step: better on short horizons and wide sets, worse on long ones.

Everything is batched: the Taylor coefficients run in the compiled interpreter over all
boxes at once, the interval matrix products in compiled kernels.
"""

from __future__ import annotations

import numpy as np

from verified.arith import _kernels as _k
from verified.arith import linalg
from verified.arith.interval import Interval, concatenate, point
from verified.sets.bases import error_basis_policy, orthonormal_basis
from verified.sets.first_order import DoubletonSets  # (its home is verified.sets.first_order; re-exported here for old imports)
from verified.steppers.protocol import StepResult

__all__ = ["LohnerStepper", "DoubletonSets", "StepResult", "horner"]


def horner(coeffs: Interval, h) -> Interval:
    """``sum_i coeffs[:, i] * h^i`` along axis 1 (``h`` a float or an Interval such as [0, h]).

    Each ``acc * h + coeffs[:, i]`` is rounded outward as the interval operators round
    it; for a scalar ``h`` the sums run in one compiled pass
    (:func:`verified.arith._kernels.horner_loop`), with the same bounds bit for bit."""
    if isinstance(h, Interval):
        if h.size != 1:
            return _horner_python(coeffs, h)
        hl, hh = float(h.lo.reshape(-1)[0]), float(h.hi.reshape(-1)[0])
    else:
        hl = hh = float(h)
        if hl != h or not np.isfinite(hl):  # (not a float: enclose it the operators' way)
            return _horner_python(coeffs, h)
    lo = np.moveaxis(coeffs.lo, 1, -1)
    shape, K = lo.shape[:-1], lo.shape[-1]
    clo = _k.kernel_array(lo.reshape(-1, K))
    chi = _k.kernel_array(np.moveaxis(coeffs.hi, 1, -1).reshape(-1, K))
    out_lo = np.empty(clo.shape[0])
    out_hi = np.empty(clo.shape[0])
    _k.horner_loop(clo, chi, hl, hh, out_lo, out_hi)
    return Interval._from_bounds(out_lo.reshape(shape), out_hi.reshape(shape))


def _horner_python(coeffs: Interval, h) -> Interval:
    """:func:`horner` with the interval operators (any ``h`` they take)."""
    acc = coeffs[:, -1]
    for i in range(coeffs.shape[1] - 2, -1, -1):
        acc = acc * h + coeffs[:, i]
    return acc


def _inflate(x: Interval, factor=0.1, absolute=1e-14) -> Interval:
    r = x.rad() * factor + absolute * (1.0 + x.mag())
    return Interval._from_bounds(x.lo - r, x.hi + r)


def taylor_step(mags: np.ndarray, tol: float, k: int) -> float:
    """``0.9 min (tol / m)^(1/k)`` over the magnitudes ``mags`` of order-``k`` Taylor
    coefficients (each at least 1e-300): the step whose order-``k`` term is about ``tol``
    for every one. A huge tol over a tiny term overflows to inf: no bound from the
    error, the step control's h_max then decides (not worth a RuntimeWarning)."""
    with np.errstate(over="ignore"):
        return float(0.9 * np.min((tol / np.maximum(mags, 1e-300)) ** (1.0 / k)))


class LohnerStepper:
    """Verified steps of order ``order`` for the ODE behind ``taylor`` (and its variational
    ODE), on :class:`~verified.sets.first_order.DoubletonSets` (implements
    :class:`verified.steppers.protocol.Stepper`). ``error_basis``: "qr", "auto" or a policy
    object of :mod:`verified.sets.bases` (the basis of the error part ``Q r``)."""

    #: absorb the error part into parameters once it is this fraction of the carried part
    ABSORB_RATIO = 0.1
    #: ... up to this many parameters per state (then the error part stays in r)
    PARAMS_PER_STATE = 8

    def __init__(self, taylor, variational, order: int, params=None, error_basis="qr", absorb: bool = False,
                 max_params: int | None = None):
        self.basis = error_basis_policy(error_basis)  # QRBasis / AutoBasis (verified.sets.bases)
        self.error_basis = self.basis.name if hasattr(self.basis, "name") else error_basis
        self.taylor = taylor
        self.variational = variational
        self.order = int(order)
        self.n = taylor.n
        # absorb: turn the error part into parameters (DoubletonSets.absorb_error) when it
        # exceeds absorb_ratio of the carried part in some component, up to max_params:
        # parameters are carried exactly, a wrapped error box is not (docs/lab/code_notes.md).
        self.absorb = bool(absorb)
        self.absorb_ratio = self.ABSORB_RATIO
        #: the first states, which decide absorbing (None: all); states past them were
        #: appended by a hook (the solver sets it to its setup's n_steer)
        self.steer = None
        self.max_params = self.PARAMS_PER_STATE * self.n if max_params is None else int(max_params)
        self.absorbed = 0
        # at the cap, merge the least wide absorbed parameters to make room (doubletons)
        self.merge = True
        self.merged = 0
        self.recentre = True
        self.params = params
        # an affine Jacobian evaluator can take the set's own forms (see step)
        self.jacobian_over_set = hasattr(variational, "series")

    # -------------------------------------------------------------- pieces
    def begin(self, sets) -> None:
        """Called by the driver before each step with the sets it starts from: nothing to
        prepare here (:class:`verified.steppers.tm_flow.TaylorModelFlowStepper` takes its
        coefficients over the sets themselves)."""
        return None

    def coefficients(self, x: Interval) -> Interval:
        return self.taylor.coefficients(x, self.order, self._params(x.shape[0]))

    def _params(self, nb):
        if self.params is None:
            return None
        p = self.params
        return p if p.ndim == 2 else p.broadcast_to((nb, p.shape[-1]))

    def apriori(self, X: Interval, cX: Interval, h: float, tries: int = 4):
        """Validated enclosure over [0, h] of all solutions from X, and its coefficients.

        Returns ``(E, cE)`` or ``None`` if the test fails (the caller shrinks ``h``).
        """
        K = self.order
        H = Interval(0.0, h)
        base = horner(cX[:, :K], H)
        HK = H**K
        guess = _inflate(base + HK * cX[:, K])
        for _ in range(tries):
            if not np.isfinite(guess.lo).all() or not np.isfinite(guess.hi).all():
                return None
            cE = self.coefficients(guess)
            new = base + HK * cE[:, K]
            if new.interior_subset(guess).all():
                return new, cE
            guess = _inflate(guess.hull(new), factor=0.5)
        return None

    def suggest_step(self, cX: Interval, tol: float, components: int | None = None) -> float:
        """Step size that makes the order-K term of every box about ``tol`` (x 0.9),
        judged on the first ``components`` states (default: all)."""
        return taylor_step(cX[:, self.order, :components].mag(), tol, self.order)

    def set_jacobian(self, sets, X: Interval, h) -> Interval:
        """Enclosure (B, n, n) of the Jacobian of the Taylor polynomial map on every
        segment from the centre ``c`` to a point of the set (what the mean value form
        needs): over the set's own affine forms (``sets.affine_forms``) when the
        variational evaluator takes them, else over the hull ``X`` joined with ``c``
        (c lies in X whenever r0 and r contain 0, the hull makes it unconditional)."""
        K, n, nb = self.order, self.n, sets.n_sets
        if self.jacobian_over_set:
            # affine forms over the set's own parameters: the set (a parallelepiped
            # plus an error box, often flat in the state space) instead of its hull
            own = sets.C.shape[2] if getattr(self.variational, "all_symbols", False) else None
            forms = sets.affine_forms(extra=n * n, own_symbols=own)
            forms[n:, :, 0] = np.eye(n).reshape(-1)[:, None]
            vc = self.variational.series(forms, K - 1, self._params(nb))
        else:
            Xc = X.hull(point(sets.c))
            v0 = point(np.broadcast_to(np.eye(n).reshape(-1), (nb, n * n)))
            vc = self.variational.coefficients(concatenate([Xc, v0], axis=1), K - 1, self._params(nb))
        return horner(vc[:, :, n:].reshape((nb, K, n, n)), h)

    def step(self, sets: DoubletonSets, h, X: Interval, E: Interval, cE: Interval) -> StepResult:
        """Advance all sets by ``h`` (float, or an Interval enclosing the exact step; s)
        given the hull ``X`` (B, N) of the sets, its a-priori enclosure ``E`` (B, N) over
        ``[0, sup h]`` and the Taylor coefficients ``cE`` (B, K+1, N) over ``E``.

        Returns a :class:`~verified.steppers.protocol.StepResult` with the new sets and the width
        of the error the linearization injected (the driver stamps the times)."""
        K = self.order
        # 3. centre polynomial plus remainder
        cP = self.coefficients(point(sets.c))
        y = horner(cP[:, :K], h) + cE[:, K] * (Interval(h) ** K)
        # 4. Jacobian of the Taylor map over the set
        J = self.set_jacobian(sets, X, h)
        # 5. doubleton update
        c_new = y.mid()
        s = y - c_new
        JC = linalg.matmul(J, sets.C)
        C_new = JC.mid()
        dC = JC - C_new
        JQ = linalg.matmul(J, sets.Q)
        nonlinear = linalg.matvec(dC, sets.r0)
        incoming = nonlinear + s
        Q_out, r_new = self.basis.update(sets.Q, sets.r, JQ, incoming)
        new = DoubletonSets(c=c_new, C=C_new, r0=sets.r0, Q=Q_out, r=r_new)
        if self.absorb:
            new = self.absorb_error(new)
        return StepResult(sets=new, previous=sets, h=h, hull=X, tube=E, nonlinear_width=nonlinear.width())

    def absorb_error(self, sets):
        """``sets`` (doubleton or second-order, anything with ``absorb_error``) with the
        error part absorbed into parameters where it has grown to ``absorb_ratio`` of the
        carried part (per batch: all sets or none, so that the batch keeps one parameter
        count), up to ``max_params`` parameters (then the error stays in ``r``).
        Absorbing lets runs go on longer at little cost (docs/lab/code_notes.md)."""
        m = sets.C.shape[2]
        at_cap = m + self.n > self.max_params
        if at_cap and not (self.merge and hasattr(sets, "merge_params")):
            return sets
        # only the states that steer the step decide (``steer``, set by the solver), as
        # for the step size: a state appended by a hook (the energy test's h) carries
        # next to no width of its own, so any error of its would look large
        k = self.steer
        carried = sets.linear_width()[:, :k]
        err = linalg.matvec(sets.Q, sets.r).width()[:, :k]
        # (an error at the rounding level does not count: an exact state such as the
        # time t of a controller has no carried width, and must not decide anything)
        floor = 1e-12 * (1.0 + np.abs(sets.c[:, :k]))
        if not (err > self.absorb_ratio * carried + floor).any():
            return sets
        if at_cap:
            # make room: the least wide absorbed parameters become n covering ones
            # (DoubletonSets.merge_params), so the error part keeps being absorbed
            # instead of wrapping at the rate of ||J|| from here on
            merged = sets.merge_params(m + 2 * self.n - self.max_params, keep_first=self.n, steer=k)
            if merged.C.shape[2] + self.n > self.max_params:
                return sets
            sets = merged
            self.merged += 1
        self.absorbed += 1
        new = sets.absorb_error()
        return new.recentred() if self.recentre and hasattr(new, "recentred") else new

    _orthonormal_basis = staticmethod(orthonormal_basis)  # (its home is verified.sets.bases)

"""The bases a set keeps its accumulated error in (as CAPD's ``QRPolicy``).

- :class:`QRBasis` / :class:`AutoBasis`: the basis the Lohner step keeps a set's
  accumulated error in (``error_basis="qr"`` / ``"auto"``); :class:`EnergyAlignedBasis`
  and :class:`BlockBasis` for the energy state and appended blocks.

None of them changes what a step encloses, only how the (sound) set is represented.
"""

from __future__ import annotations

import numpy as np

from verified.arith import linalg
from verified.arith.interval import Interval, point

__all__ = ["QRBasis", "AutoBasis", "EnergyAlignedBasis", "BlockBasis", "error_basis_policy"]


# ---------------------------------------------------------------------------- error basis
def orthonormal_basis(A: np.ndarray, widths: np.ndarray) -> np.ndarray:
    """Q of the QR factorization of A (B, n, n) with columns sorted by |A_j| * widths_j
    (Lohner)."""
    size = np.linalg.norm(A, axis=1) * widths
    order = np.argsort(-size, axis=1, kind="stable")
    A_sorted = np.take_along_axis(A, order[:, None, :], axis=2)
    Q, _ = np.linalg.qr(A_sorted)
    return Q


def scaled_basis(A: np.ndarray, widths: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """``D Q'`` with ``D = diag(scale)`` (B, n) and ``Q'`` the sorted QR basis
    (:func:`orthonormal_basis`) of ``D^-1 A``: a basis that is orthonormal in the state
    space measured in units of ``scale`` (the set's extent per state), not in raw units.

    Why: a robot's set is often much wider in qd (rad/s) than in q (rad); an orthonormal
    basis of raw columns mixes a qd-sized range into q when a zonotope is wrapped into
    a parallelepiped; scaling keeps the narrow states narrow (docs/lab/code_notes.md).
    Any invertible basis is sound here: the callers enclose ``B^-1`` rigorously."""
    scale = np.asarray(scale, dtype=float)
    scale = np.where(np.isfinite(scale), scale, 0.0)
    top = np.max(scale, axis=1, keepdims=True)
    d = np.maximum(scale, np.maximum(top * 1e-12, 1e-300))  # (a state without extent)
    Qs = orthonormal_basis(A / d[:, :, None], widths)
    return Qs * d[:, :, None]


class QRBasis:
    """Lohner's QR method: the error part ``Q r`` is carried in the orthonormal basis
    ``Q'`` of ``mid(J Q)`` (columns sorted by the error each carries), so errors are
    not wrapped into axis-parallel boxes at every step."""

    name = "qr"

    def update(self, Q: np.ndarray, r: Interval, JQ: Interval, incoming: Interval):
        """The new error part ``(Q', r')`` with ``Q' r' ⊇ J Q r + incoming``.

        ``Q`` (B, n, n) and ``r`` (B, n) the set's error part before the step, ``JQ``
        (B, n, n) the Jacobian of the step times ``Q``, ``incoming`` (B, n) the error
        the step adds (nonlinear part of ``J C r0`` and the centre's enclosure)."""
        nb, n = r.shape
        # Lohner's ordering: by the error each column carries. Before any error has
        # accumulated (r = 0, the first step) use the error arriving now instead: the
        # column norms alone can put a parameter's column first and smear the error
        # across axes. (Not at every step: that is worse on long horizons; docs/lab/code_notes.md.)
        r_w = r.width()
        arriving = np.einsum("bij,bi->bj", np.abs(Q), incoming.width())
        carried = np.where((r_w.sum(axis=1) > 0)[:, None], r_w, arriving) + 1e-300
        Q_new = orthonormal_basis(JQ.mid(), carried)
        Q_inv = linalg.solve(Q_new[:, None, :, :], point(np.broadcast_to(np.eye(n), (nb, n, n))))  # rows: columns of inverse
        Q_inv = Q_inv.swapaxes(-1, -2)
        r_qr = linalg.matvec(linalg.matmul(Q_inv, JQ), r) + linalg.matvec(Q_inv, incoming)
        return Q_new, r_qr


class AutoBasis(QRBasis):
    """Per set and step, the QR basis or a plain box (``Q' = I``), whichever encloses
    the error part more tightly now. The QR basis can smear an error lying along a
    coordinate axis into the other axes (for example into an uncertain parameter that
    never changes); the plain box ``J Q r + incoming`` cannot. Both are valid
    enclosures. Better on short horizons and wide sets, worse on long ones."""

    name = "auto"

    def update(self, Q, r, JQ, incoming):
        n = r.shape[1]
        Q_new, r_qr = super().update(Q, r, JQ, incoming)
        r_box = linalg.matvec(JQ, r) + incoming
        use_box = r_box.width().sum(axis=1) <= linalg.matvec(Q_new, r_qr).width().sum(axis=1)
        Q_out = np.where(use_box[:, None, None], np.eye(n), Q_new)
        r_new = Interval._from_bounds(
            np.where(use_box[:, None], r_box.lo, r_qr.lo), np.where(use_box[:, None], r_box.hi, r_qr.hi)
        )
        return Q_out, r_new


class EnergyAlignedBasis(QRBasis):
    """Lohner's QR basis with its first column along a given direction per set, e.g.
    the gradient of the energy residual ``G = H(x) - h`` (set by
    :class:`verified.consistency.energy_test.EnergyTest` after every step through
    :meth:`set_direction`). The linear row of the energy contraction
    (:mod:`verified.consistency.energy_contraction`) then has one dominant coefficient, on the
    error component along the gradient, and narrows it instead of sharing the
    constraint among all components.

    Any orthonormal ``Q'`` is sound (``Q'^-1`` is enclosed rigorously), so the
    direction is only a heuristic: when it is missing, not finite, or its batch size
    differs from the step's (sets split, merged or pruned since it was set), the plain
    QR basis is used for that step. The direction is used once.
    """

    name = "energy"

    def __init__(self):
        self.direction = None
        self.used = 0

    def set_direction(self, direction) -> None:
        """``direction``: float (B, N) per set (any length; zero rows fall back to QR), or None."""
        self.direction = None if direction is None else np.asarray(direction, float)

    def update(self, Q, r, JQ, incoming):
        g, self.direction = self.direction, None
        nb, n = r.shape
        if g is None or g.shape != (nb, n):
            return super().update(Q, r, JQ, incoming)
        norm = np.linalg.norm(g, axis=1)
        ok = np.isfinite(norm) & (norm > 0) & np.isfinite(g).all(axis=1)
        if not ok.any():
            return super().update(Q, r, JQ, incoming)
        r_w = r.width()
        arriving = np.einsum("bij,bi->bj", np.abs(Q), incoming.width())
        carried = np.where((r_w.sum(axis=1) > 0)[:, None], r_w, arriving) + 1e-300
        A = JQ.mid()
        size = np.linalg.norm(A, axis=1) * carried
        order = np.argsort(-size, axis=1, kind="stable")
        A_sorted = np.take_along_axis(A, order[:, None, :], axis=2)
        lead = np.where(ok[:, None], g / np.where(ok, norm, 1.0)[:, None], A_sorted[:, :, 0])
        A2 = np.concatenate([lead[:, :, None], A_sorted[:, :, : n - 1]], axis=2)
        A2 = np.where(ok[:, None, None], A2, A_sorted)
        Q_new, _ = np.linalg.qr(A2)
        Q_inv = linalg.solve(Q_new[:, None, :, :], point(np.broadcast_to(np.eye(n), (nb, n, n))))
        Q_inv = Q_inv.swapaxes(-1, -2)
        r_new = linalg.matvec(linalg.matmul(Q_inv, JQ), r) + linalg.matvec(Q_inv, incoming)
        self.used += int(ok.sum())
        return Q_new, r_new


class BlockBasis:
    """The error basis of ``inner`` for the leading ``n_lead`` states, a plain box for
    the states after them (states a hook appended, such as the energy test's ``h``).

    Appended states do not feed back into the ODE (``f`` does not depend on them), so
    with ``Q = diag(Q_x, I)`` the step's ``J Q`` is block lower triangular and the
    leading block's update is exactly the one without the appended states: their
    error (``h``'s can be large: the unsimplified ``dH/dt`` over a wide set) is never
    rotated into the states' basis. (With one QR basis over all states it was, and
    the energy test's run broke down earlier than the run without it;
    docs/lab/code_notes.md.) Sound for any ``inner`` policy: the
    trailing part ``J_hx Q_x r_x + J_hh r_h + incoming_h`` is enclosed directly.
    """

    def __init__(self, inner, n_lead: int):
        self.inner = error_basis_policy(inner)
        self.n_lead = int(n_lead)
        self.name = f"block({getattr(self.inner, 'name', 'custom')})"

    def update(self, Q, r, JQ, incoming):
        k = self.n_lead
        nb, n = r.shape
        if k >= n or k <= 0 or np.any(Q[:, :k, k:] != 0) or np.any(Q[:, k:, :k] != 0):
            return self.inner.update(Q, r, JQ, incoming)  # not block diagonal (yet): plain policy
        Qx, rx = Q[:, :k, :k], r[:, :k]
        # J_xt (the leading states' dependence on the trailing ones) is 0 for appended
        # states; whatever the Jacobian enclosure holds there is carried as incoming error
        inx = incoming[:, :k] + linalg.matvec(JQ[:, :k, k:], r[:, k:])
        JQxx = JQ[:, :k, :k]
        Qx_new, rx_new = self.inner.update(Qx, rx, JQxx, inx)
        # trailing states: a plain box  J_t. Q r + incoming_t  (J_t. Q = rows k: of JQ)
        rt_new = linalg.matvec(JQ[:, k:, :], r) + incoming[:, k:]
        Q_new = np.zeros((nb, n, n))
        Q_new[:, :k, :k] = Qx_new
        Q_new[:, k:, k:] = np.eye(n - k)
        r_new = Interval._from_bounds(np.concatenate([rx_new.lo, rt_new.lo], axis=1),
                                      np.concatenate([rx_new.hi, rt_new.hi], axis=1))
        return Q_new, r_new


_BASES = {"qr": QRBasis, "auto": AutoBasis}


def error_basis_policy(error_basis) -> QRBasis:
    """The policy for ``error_basis`` ("qr", "auto", or a policy object with ``update``)."""
    if isinstance(error_basis, str):
        if error_basis not in _BASES:
            raise ValueError(f"error_basis must be 'qr' or 'auto', got {error_basis!r}")
        return _BASES[error_basis]()
    if not callable(getattr(error_basis, "update", None)):
        raise ValueError(f"error_basis must be 'qr' or 'auto', got {error_basis!r}")
    return error_basis

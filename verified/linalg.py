"""Interval linear algebra for small dense systems, batched over leading axes.

* :func:`matmul` -- interval matrix-matrix and matrix-vector products.
* :func:`solve` -- a verified enclosure of the solution set of ``A x = b`` for
  interval ``A`` (for example a mass matrix ``M(q)`` over a box of ``q``) and
  interval ``b``, by preconditioned interval Gauss elimination:
  ``C = mid(A)^-1`` (floats), then Gauss elimination without pivoting on the
  interval system ``(C A) x = C b``, whose matrix is close to the identity. Every
  ``x`` with ``A~ x = b~`` for some ``A~ in A`` and ``b~ in b`` lies in the result.

Shapes: matrices are ``(..., n, k)``, vectors ``(..., n)``; leading axes broadcast.
All loops run compiled (numba) over the flattened batch.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import _kernels as _k
from .interval import Interval, _as_interval

__all__ = ["matmul", "matvec", "solve", "SingularMatrixError"]


class SingularMatrixError(np.linalg.LinAlgError, ValueError):
    """The interval matrix may contain a singular matrix (or its midpoint is singular).

    Attributes
    ----------
    indices : list of tuple
        Batch indices of the systems that failed.
    """

    def __init__(self, message, indices=()):
        super().__init__(message)
        self.indices = list(indices)


# ----------------------------------------------------------------- kernels
@njit(cache=True)
def _matmul_kernel(alo, ahi, blo, bhi):
    nb, n, k = alo.shape
    m = blo.shape[2]
    clo = np.empty((nb, n, m))
    chi = np.empty((nb, n, m))
    for b in range(nb):
        for i in range(n):
            for j in range(m):
                sl = 0.0
                sh = 0.0
                for t in range(k):
                    pl, ph = _k.mul(alo[b, i, t], ahi[b, i, t], blo[b, t, j], bhi[b, t, j])
                    sl, sh = _k.add(sl, sh, pl, ph)
                clo[b, i, j] = sl
                chi[b, i, j] = sh
    return clo, chi


STATUS_OK = 0
STATUS_SINGULAR_MIDPOINT = 1
STATUS_PIVOT_CONTAINS_ZERO = 2
STATUS_NOT_FINITE = 3


@njit(cache=True)
def _float_inverse(a):
    """Inverse of a small float matrix by Gauss-Jordan with partial pivoting.

    Returns (inverse, ok). Only used as a preconditioner: its accuracy affects the
    width of the enclosure, never its correctness.
    """
    n = a.shape[0]
    w = a.copy()
    inv = np.eye(n)
    for col in range(n):
        p = col
        for r in range(col + 1, n):
            if abs(w[r, col]) > abs(w[p, col]):
                p = r
        if not (abs(w[p, col]) > 0.0):
            return inv, False
        if p != col:
            for c in range(n):
                w[col, c], w[p, c] = w[p, c], w[col, c]
                inv[col, c], inv[p, c] = inv[p, c], inv[col, c]
        piv = w[col, col]
        for c in range(n):
            w[col, c] /= piv
            inv[col, c] /= piv
        for r in range(n):
            if r != col:
                f = w[r, col]
                if f != 0.0:
                    for c in range(n):
                        w[r, c] -= f * w[col, c]
                        inv[r, c] -= f * inv[col, c]
    for r in range(n):
        for c in range(n):
            if not np.isfinite(inv[r, c]):
                return inv, False
    return inv, True


@njit(cache=True)
def _solve_kernel(alo, ahi, blo, bhi):
    nb, n, _ = alo.shape
    xlo = np.empty((nb, n))
    xhi = np.empty((nb, n))
    status = np.zeros(nb, dtype=np.int64)
    plo = np.empty((n, n))
    phi = np.empty((n, n))
    qlo = np.empty(n)
    qhi = np.empty(n)
    for b in range(nb):
        finite = True
        for i in range(n):
            if not (np.isfinite(blo[b, i]) and np.isfinite(bhi[b, i])):
                finite = False
            for j in range(n):
                if not (np.isfinite(alo[b, i, j]) and np.isfinite(ahi[b, i, j])):
                    finite = False
        if not finite:
            status[b] = STATUS_NOT_FINITE
            continue
        mid = 0.5 * alo[b] + 0.5 * ahi[b]
        c, ok = _float_inverse(mid)
        if not ok:
            status[b] = STATUS_SINGULAR_MIDPOINT
            continue
        # Precondition: P = C A, q = C b (C is a point matrix, so each term is a
        # scalar-times-interval product, rounded outward and summed outward).
        for i in range(n):
            for j in range(n):
                sl = 0.0
                sh = 0.0
                for t in range(n):
                    pl, ph = _k.mul(c[i, t], c[i, t], alo[b, t, j], ahi[b, t, j])
                    sl, sh = _k.add(sl, sh, pl, ph)
                plo[i, j] = sl
                phi[i, j] = sh
            sl = 0.0
            sh = 0.0
            for t in range(n):
                pl, ph = _k.mul(c[i, t], c[i, t], blo[b, t], bhi[b, t])
                sl, sh = _k.add(sl, sh, pl, ph)
            qlo[i] = sl
            qhi[i] = sh
        # Gauss elimination without pivoting (P is close to the identity).
        failed = False
        for k in range(n):
            if plo[k, k] <= 0.0 <= phi[k, k]:
                failed = True
                break
            for i in range(k + 1, n):
                fl, fh = _k.div(plo[i, k], phi[i, k], plo[k, k], phi[k, k])
                for j in range(k + 1, n):
                    tl, th = _k.mul(fl, fh, plo[k, j], phi[k, j])
                    plo[i, j], phi[i, j] = _k.sub(plo[i, j], phi[i, j], tl, th)
                tl, th = _k.mul(fl, fh, qlo[k], qhi[k])
                qlo[i], qhi[i] = _k.sub(qlo[i], qhi[i], tl, th)
        if failed:
            status[b] = STATUS_PIVOT_CONTAINS_ZERO
            continue
        for i in range(n - 1, -1, -1):
            sl = qlo[i]
            sh = qhi[i]
            for j in range(i + 1, n):
                tl, th = _k.mul(plo[i, j], phi[i, j], xlo[b, j], xhi[b, j])
                sl, sh = _k.sub(sl, sh, tl, th)
            xlo[b, i], xhi[b, i] = _k.div(sl, sh, plo[i, i], phi[i, i])
    return xlo, xhi, status


# ----------------------------------------------------------------- wrappers
def _batch(x, core_ndim):
    """Split an Interval's shape into (batch shape, core shape)."""
    return x.shape[: x.ndim - core_ndim], x.shape[x.ndim - core_ndim :]


def _flatten(x, batch_shape, core_shape):
    full = batch_shape + core_shape
    lo = np.ascontiguousarray(np.broadcast_to(x.lo, full)).reshape((-1,) + core_shape)
    hi = np.ascontiguousarray(np.broadcast_to(x.hi, full)).reshape((-1,) + core_shape)
    return lo, hi


def matmul(a, b):
    """Interval matrix product ``a @ b`` with numpy's ``matmul`` shape rules.

    Parameters
    ----------
    a : Interval or float array, shape ``(..., n, k)``
    b : Interval or float array, shape ``(..., k, m)``, or ``(k,)`` for one vector
        (use :func:`matvec` for a batch of vectors ``(..., k)``).

    Returns
    -------
    Interval of shape ``(..., n, m)`` (``(..., n)`` for a 1-d ``b``): encloses every
    product of point matrices taken from ``a`` and ``b``. Floats are exact points.
    """
    a = _as_interval(a)
    b = _as_interval(b)
    if b.ndim == 1:
        return matvec(a, b)
    if a.ndim < 2:
        raise ValueError(f"matmul needs a matrix on the left, got shape {a.shape}")
    if a.shape[-1] != b.shape[-2]:
        raise ValueError(
            f"matmul shapes {a.shape} and {b.shape} do not align (inner sizes {a.shape[-1]} vs {b.shape[-2]})"
        )
    try:
        batch = np.broadcast_shapes(a.shape[:-2], b.shape[:-2])
    except ValueError:
        raise ValueError(f"matmul batch shapes {a.shape[:-2]} and {b.shape[:-2]} do not broadcast") from None
    alo, ahi = _flatten(a, batch, a.shape[-2:])
    blo, bhi = _flatten(b, batch, b.shape[-2:])
    clo, chi = _matmul_kernel(alo, ahi, blo, bhi)
    shape = batch + (a.shape[-2], b.shape[-1])
    return Interval._from_bounds(clo.reshape(shape), chi.reshape(shape))


def matvec(a, x):
    """Batched interval matrix-vector product: ``(..., n, k) x (..., k) -> (..., n)``."""
    a = _as_interval(a)
    x = _as_interval(x)
    if x.ndim < 1:
        raise ValueError("matvec needs a vector on the right")
    return matmul(a, x.reshape(x.shape + (1,)))[..., 0]


_FAILURE_TEXT = {
    STATUS_SINGULAR_MIDPOINT: "the midpoint matrix is singular",
    STATUS_PIVOT_CONTAINS_ZERO: "an interval pivot contains zero (the interval matrix may contain a singular matrix)",
    STATUS_NOT_FINITE: "the matrix or right-hand side has non-finite bounds",
}


def solve(a, b, *, on_failure="raise"):
    """Enclose the solutions of ``a x = b`` for every matrix in ``a`` and vector in ``b``.

    Parameters
    ----------
    a : Interval or float array, shape ``(..., n, n)``
    b : Interval or float array, shape ``(..., n)``
    on_failure : {"raise", "entire"}
        What to do for systems that cannot be verified (singular or nearly singular
        interval matrix): raise :class:`SingularMatrixError` naming the batch
        indices, or return ``[-inf, inf]`` for their components.

    Returns
    -------
    Interval of shape ``(..., n)``.
    """
    if on_failure not in ("raise", "entire"):
        raise ValueError(f"on_failure must be 'raise' or 'entire', got {on_failure!r}")
    a = _as_interval(a)
    b = _as_interval(b)
    if a.ndim < 2 or a.shape[-1] != a.shape[-2]:
        raise ValueError(f"solve needs square matrices of shape (..., n, n), got {a.shape}")
    n = a.shape[-1]
    if b.ndim < 1 or b.shape[-1] != n:
        raise ValueError(f"right-hand side must have shape (..., {n}), got {b.shape}")
    try:
        batch = np.broadcast_shapes(a.shape[:-2], b.shape[:-1])
    except ValueError:
        raise ValueError(f"solve batch shapes {a.shape[:-2]} and {b.shape[:-1]} do not broadcast") from None
    alo, ahi = _flatten(a, batch, (n, n))
    blo, bhi = _flatten(b, batch, (n,))
    xlo, xhi, status = _solve_kernel(alo, ahi, blo, bhi)
    bad = status != STATUS_OK
    if bad.any():
        if on_failure == "raise":
            flat = np.flatnonzero(bad)
            idx = [np.unravel_index(i, batch) if batch else () for i in flat[:10]]
            reasons = sorted({_FAILURE_TEXT[int(s)] for s in status[bad]})
            raise SingularMatrixError(
                f"cannot verify {bad.sum()} of {status.size} linear systems: {'; '.join(reasons)}"
                f" (batch indices {[tuple(int(v) for v in i) for i in idx]}{' ...' if flat.size > 10 else ''})",
                indices=[tuple(int(v) for v in np.unravel_index(i, batch)) if batch else () for i in flat],
            )
        xlo[bad] = -np.inf
        xhi[bad] = np.inf
    shape = batch + (n,)
    return Interval._from_bounds(xlo.reshape(shape), xhi.reshape(shape))

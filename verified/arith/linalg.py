"""Interval linear algebra for small dense systems, batched over leading axes.

* :func:`matmul`, :func:`matvec` -- interval matrix-matrix and matrix-vector products
  (defined in :mod:`verified.arith.interval`, which the ``@`` operator of an Interval
  calls, so that the two modules do not import each other; re-exported here).
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

import functools

import numpy as np
from numba import njit

from verified.arith import _kernels as _k
from verified.arith.interval import Interval, _as_interval, _flatten, matmul, matvec  # noqa: F401 (re-exported)

__all__ = ["matmul", "matvec", "solve", "inverse_diagonal", "SingularMatrixError", "upper_pairs"]


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


@functools.lru_cache(maxsize=128)
def upper_pairs(m: int, k: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``np.triu_indices(m, k)`` as read-only int64 arrays, made once per ``(m, k)``: the
    set and model code asks for the same index pairs at every step."""
    i, j = np.triu_indices(m, k)
    i, j = i.astype(np.int64), j.astype(np.int64)
    i.flags.writeable = False
    j.flags.writeable = False
    return i, j


# ----------------------------------------------------------------- kernels
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


def inverse_diagonal(a, *, on_failure="entire"):
    """Enclose the diagonal of ``a^-1`` for every matrix in ``a`` (Interval or float,
    shape ``(..., n, n)``): Interval ``(..., n)``, ``[-inf, inf]`` where a system cannot be
    verified (``on_failure`` as for :func:`solve`). Solves ``a x = e_i`` for every ``i``;
    the ``i``-th entry of the ``i``-th solution is ``(a^-1)_ii``."""
    a = _as_interval(a)
    n = a.shape[-1]
    cols = solve(a.reshape(a.shape[:-2] + (1, n, n)), np.eye(n), on_failure=on_failure)
    return Interval._from_bounds(np.diagonal(cols.lo, axis1=-2, axis2=-1).copy(),
                                 np.diagonal(cols.hi, axis1=-2, axis2=-1).copy())

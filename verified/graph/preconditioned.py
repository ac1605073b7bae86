"""Linear solves ``M x = b`` written so that interval-type evaluators stay tight.

Plain Gaussian elimination over intervals multiplies widths through every pivot: on a
robot's ill-conditioned mass matrix over a small box the enclosure of
``qdd = M(q)^-1 b`` is many times the true range (docs/lab/code_notes.md). Interval
linear algebra avoids this by preconditioning with
a point approximation of the inverse (Hansen 1965; Neumaier, *Interval Methods for
Systems of Equations*, ch. 4; the Krawczyk and Hansen-Bliek methods). For the
symmetric positive definite mass matrices here, the preconditioner is a congruence:
with ``mid(M) = L D L^T`` frozen and ``K = L^-1``,

    x = K^T (K M K^T)^-1 (K b),        K M K^T ~ diag(D),

and the elimination on the nearly diagonal ``K M K^T`` no longer amplifies widths,
while ``K M K^T`` stays symmetric positive definite wherever ``M`` is.

:func:`solve` writes that formula with ordinary scalar operations plus the graph op
``mid`` (:meth:`verified.graph.GraphBuilder.mid`), so it traces into any expression
graph and every evaluator runs it unchanged: floats, intervals, forward-mode
derivatives, interval and affine Taylor coefficients, sympy.
:func:`congruence_pivots` gives the pivots of ``K M K^T``, a tight certificate that
``M`` is positive definite over a box.

Why this is exact, whatever point ``mid`` picks: the identity holds for every
invertible ``K``, and ``K`` (computed from the frozen point, then frozen itself) is
unit lower triangular. Frozen points are constants in time and in the state, so Taylor
coefficients and derivatives of the formula are those of ``M^-1 b`` as well (it is the
same function of the state). An unbounded or empty ``M`` entry has no frozen point
(``mid`` keeps it unbounded or empty), which ends in an unbounded or empty result: a
break-down, never a definite wrong value.
"""

from __future__ import annotations

import numbers
from typing import Sequence

import numpy as np

from verified.graph.evaluate import IntervalDomain
from verified.arith.interval import Interval

__all__ = ["frozen_point", "solve", "congruence_pivots"]


def _is_zero(x) -> bool:
    """A structural zero: an exact Python/numpy number 0 (skipped to keep graphs small)."""
    return isinstance(x, (numbers.Number, np.number)) and not isinstance(x, bool) and x == 0


def frozen_point(x):
    """The graph op ``mid`` on any scalar type the models trace through.

    Tracers (``verified.graph.tracer``) record a ``mid`` node; :class:`~verified.arith.interval.Interval`
    values become the point at their midpoint (unbounded stays unbounded); floats,
    ints, Fractions and sympy expressions are their own point."""
    method = getattr(x, "mid", None)
    if method is None:
        return x
    if isinstance(x, Interval):
        return IntervalDomain().mid(x)
    return method()


def _mul(a, b):
    return 0 if _is_zero(a) or _is_zero(b) else a * b


def _add(a, b):
    if _is_zero(a):
        return b
    if _is_zero(b):
        return a
    return a + b


def _sub(a, b):
    if _is_zero(b):
        return a
    if _is_zero(a):
        return -b
    return a - b


def _ldl(A):
    """Unit lower triangular L and pivots D with A = L diag(D) L^T (no pivoting, no checks)."""
    n = len(A)
    L = [[0] * n for _ in range(n)]
    D = [0] * n
    for j in range(n):
        L[j][j] = 1
        s = A[j][j]
        for k in range(j):
            s = _sub(s, _mul(_mul(L[j][k], L[j][k]), D[k]))
        D[j] = s
        for i in range(j + 1, n):
            t = A[i][j]
            for k in range(j):
                t = _sub(t, _mul(_mul(L[i][k], L[j][k]), D[k]))
            L[i][j] = 0 if _is_zero(t) else t / D[j]
    return L, D


def congruence_pivots(M: Sequence[Sequence]) -> list:
    """LDL^T pivots of ``P = K M K^T`` with ``K = L^-1`` frozen, ``mid(M) = L D L^T``: a
    certificate that a symmetric ``M`` is positive definite.

    By Sylvester's law of inertia ``P`` and ``M`` have the same inertia for every
    invertible ``K``, so ``M`` is positive definite iff every pivot of ``P`` is > 0
    (over intervals: iff every lower bound is > 0 proves it for every matrix in ``M``).
    ``P`` is close to ``diag(D)``, so its pivots stay tight where the pivots of ``M``
    itself spread through the elimination (on robots below 0 over small boxes;
    docs/lab/code_notes.md). ``K`` is unit lower triangular, hence
    invertible whatever ``mid`` picks (a singular ``mid(M)`` gives a zero or unbounded
    pivot, so an unbounded ``K`` and no proof -- never a false one)."""
    n = len(M)
    if any(len(row) != n for row in M):
        raise ValueError(f"congruence_pivots needs a square matrix, got {n} rows of lengths {[len(r) for r in M]}")
    _, P = _congruence(M)
    _, D = _ldl_tight(P)
    return D


def _congruence(M):
    """``(K, P)``: ``K = L^-1`` (frozen points, unit lower triangular) for ``mid(M) = L D
    L^T``, and ``P = K M K^T`` (symmetric, built from its upper triangle)."""
    n = len(M)
    Mp = [[M[i][j] if _is_zero(M[i][j]) else frozen_point(M[i][j]) for j in range(n)] for i in range(n)]
    L, _ = _ldl(Mp)
    # K = L^-1 (unit lower triangular), by forward substitution on the identity
    K = [[0] * n for _ in range(n)]
    for c in range(n):
        K[c][c] = 1
        for i in range(c + 1, n):
            s = 0
            for k in range(c, i):
                s = _sub(s, _mul(L[i][k], K[k][c]))
            K[i][c] = s
    K = [[v if _is_zero(v) else frozen_point(v) for v in row] for row in K]  # exact points
    KM = [[0] * n for _ in range(n)]
    for i in range(n):
        for j in range(n):
            s = 0
            for k in range(i + 1):  # K is lower triangular
                s = _add(s, _mul(K[i][k], M[k][j]))
            KM[i][j] = s
    P = [[0] * n for _ in range(n)]
    for i in range(n):
        for j in range(i, n):  # P is symmetric: build the upper triangle, mirror it
            s = 0
            for k in range(j + 1):
                s = _add(s, _mul(KM[i][k], K[j][k]))
            P[i][j] = P[j][i] = s
    return K, P


def _ldl_tight(A):
    """LDL^T of a symmetric A without pivoting or checks, kept as ``U = D L^T``:
    ``(U, D)``. Diagonal updates are ``A_ii - U_ki^2 / D_k`` (a square, each pivot once
    per term), the form that stays tight over intervals (as mbs.numeric.ldl_factor)."""
    n = len(A)
    A = [list(row) for row in A]
    U = [[0] * n for _ in range(n)]
    D = [0] * n
    for k in range(n):
        D[k] = A[k][k]
        for j in range(k + 1, n):
            U[k][j] = A[k][j]
        for i in range(k + 1, n):
            if _is_zero(U[k][i]):
                continue
            A[i][i] = _sub(A[i][i], U[k][i] ** 2 / D[k])  # ** 2: a square (sqr) for tracers and intervals
            for j in range(i + 1, n):
                if not _is_zero(U[k][j]):
                    A[i][j] = _sub(A[i][j], _mul(U[k][i], U[k][j]) / D[k])
    return U, D


# Kept apart from mbs.numeric.ldl_substitute: skips y[k] = 0 terms (the caller proves these pivots), no +-1 folding.
def _ldl_substitute(U, D, b):
    """``x = A^-1 b`` from :func:`_ldl_tight`'s factors."""
    n = len(b)
    y = [0] * n
    for i in range(n):
        s = b[i]
        for k in range(i):
            if not _is_zero(U[k][i]) and not _is_zero(y[k]):
                s = _sub(s, _mul(U[k][i], y[k]) / D[k])
        y[i] = s
    x = [0] * n
    for i in reversed(range(n)):
        s = y[i]
        for j in range(i + 1, n):
            s = _sub(s, _mul(U[i][j], x[j]))
        x[i] = s / D[i]
    return x


def solve(M: Sequence[Sequence], b: Sequence, *, spd: bool = True) -> list:
    """``x = M^-1 b`` for a symmetric positive definite ``M`` by a frozen congruence:

        x = K^T (K M K^T)^-1 (K b),      K = L^-1,  mid(M) = L D L^T  (frozen),

    with ``(K M K^T)^-1`` by LDL^T without pivoting. ``K`` is unit lower triangular, so
    invertible whatever point ``mid`` freezes, and the identity is exact; ``K M K^T`` is
    symmetric positive definite wherever ``M`` is (Sylvester), so every pivot is > 0 at
    every point of a box where ``M`` is positive definite: the formula is defined
    there, however wide the box. Near the midpoint ``K M K^T ~ diag(D)``, so the
    elimination no longer multiplies widths through the pivots.

    (A first version used ``(C M)^-1 C b`` with ``C = mid(M)^-1``: as tight near the
    midpoint, but ``C M`` is not symmetric and its leading minors can vanish inside a
    wide box -- on an ill-conditioned M a small spread is enough, docs/lab/code_notes.md
    -- which ended runs with 'division by an interval containing zero'.)

    Parameters
    ----------
    M : n x n list of rows of scalars (floats, Intervals, tracers, sympy).
    b : n scalars.

    Returns
    -------
    list of n scalars.

    Whether ``M`` is positive definite on a box is the caller's to prove (e.g. by
    :func:`congruence_pivots`); this function does not check it.
    """
    n = len(b)
    if len(M) != n or any(len(row) != n for row in M):
        raise ValueError(f"solve needs an {n} x {n} matrix for {n} right-hand sides")
    if not spd:
        raise NotImplementedError("only symmetric positive definite matrices (spd=True) are supported")
    K, P = _congruence(M)
    Kb = [0] * n
    for i in range(n):
        s = 0
        for k in range(i + 1):
            s = _add(s, _mul(K[i][k], b[k]))
        Kb[i] = s
    U, D = _ldl_tight(P)
    y = _ldl_substitute(U, D, Kb)
    x = [0] * n
    for i in range(n):  # x = K^T y
        s = 0
        for k in range(i, n):
            s = _add(s, _mul(K[k][i], y[k]))
        x[i] = s
    return x

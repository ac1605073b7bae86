"""What the driver asks of a set batch (:class:`SetBatch`) and the read-only view of a batch's
sets over their own parameters (:class:`SetView`, :func:`set_view`).

A *set batch* holds ``B`` sets of the same kind and dimension ``n``; the solver's
driver (:func:`verified.solver.solve`), its controls (:mod:`verified.driver.control`) and
its hooks (:mod:`verified.driver.hooks`) use only the operations of :class:`SetBatch`, so a
new representation plugs in by implementing them and a stepper that advances it (see
:class:`verified.steppers.protocol.Stepper`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from verified.arith.interval import Interval, concatenate, point

__all__ = ["SetBatch", "SetView", "set_view"]


@runtime_checkable
class SetBatch(Protocol):
    """What the driver, the policies and the hooks need from a batch of ``B`` sets.

    Every method returns new objects (a batch is not changed in place), and every
    operation that changes the sets encloses what it was given: ``split`` returns parts
    whose union covers the set, ``merge_overlapping`` sets that cover the merged ones.
    """

    @property
    def n_sets(self) -> int:
        """``B``, the number of sets."""

    def hull(self) -> Interval:
        """Interval hull of each set, shape (B, n)."""

    def take(self, index) -> "SetBatch":
        """The sets selected by an index array or boolean mask over ``B``."""

    def linear_width(self) -> np.ndarray:
        """Width of each set's part that is carried exactly by the representation
        (no wrapping), per component, shape (B, n): the wrapping control compares a
        step's injected error with it."""

    def split(self, mask: np.ndarray) -> "SetBatch":
        """The sets selected by ``mask`` (B,) cut in two, the others unchanged."""

    def merge_overlapping(self, slack: float) -> tuple["SetBatch", int]:
        """Neighbouring sets merged where one set covering both is at most ``1 + slack``
        times as wide as their union's hull; returns the batch and the number of merges."""


@dataclass
class SetView:
    """The first ``k`` states of a batch of sets in a linear view over the sets' own
    parameters: every point of set ``b`` is ``c[b] + A' p`` for some ``p`` in ``R[b]``
    and some point matrix ``A'`` in ``A[b]`` (``A'`` may depend on ``p``). Doubleton
    sets give ``A = [C | Q]`` (points); second-order sets ``[C + S r0 | Q]``
    (:meth:`verified.sets.second_order.QuadraticSets.direction_columns`).

    Why: a function of the states over a thin, rotated set is much narrower in
    mean-value form over these parameters, ``g(c) + (Dg(X) A) R``, than over the set's
    hull box (the frames of :mod:`mbs.frames` use it). Shapes: c (B, k) float,
    A Interval (B, k, P), R Interval (B, P)."""

    c: np.ndarray
    A: Interval
    R: Interval

    @property
    def n_sets(self) -> int:
        return self.c.shape[0]


def set_view(sets, k: int) -> SetView:
    """The :class:`SetView` of the first ``k`` states of ``sets`` (doubleton or
    second-order, anything with ``direction_columns``, ``r0`` and ``r``)."""
    cols = sets.direction_columns()
    A = cols if isinstance(cols, Interval) else point(np.asarray(cols, float))
    R = concatenate([sets.r0, sets.r], axis=1)
    return SetView(c=np.array(sets.c[:, :k], dtype=float), A=A[:, :k, :], R=R)

"""What one verified step produces (:class:`StepResult`) and what the driver asks of a
stepper (:class:`Stepper`).

The driver (:func:`verified.solver.solve`) owns time and bookkeeping; a stepper owns
the arithmetic of one step for one set representation (:mod:`verified.sets.first_order`).
:class:`verified.steppers.lohner.LohnerStepper` is the stepper for
:class:`~verified.sets.first_order.DoubletonSets`; a Taylor-model stepper would implement the same
four methods for its own sets.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction
from typing import Protocol

import numpy as np

from verified.arith.exact import enclose_fraction
from verified.arith.interval import Interval

__all__ = ["StepResult", "Stepper", "REMAINDER_SLACK"]


#: a step is retried smaller when its remainder exceeds this many times ``tol``
REMAINDER_SLACK = 10.0


@dataclass
class StepResult:
    """One accepted step of every set of a batch, from ``t_start`` to ``t``.

    The stepper fills the first six fields; the driver stamps the times.

    Attributes
    ----------
    sets : SetBatch (B sets)
        The sets at the end of the step: every solution starting in ``previous`` at
        ``t_start`` lies in their union at ``t``.
    previous : SetBatch (B sets)
        The sets at the start of the step (a backward test integrates back to them).
    h : float or Interval
        The step taken (s): a float, or, when the step lands on an output time that
        is not a float distance away, an interval enclosing the exact distance.
    hull : Interval (B, N)
        The hull of each set of ``previous`` the step's Taylor coefficients were
        taken over (``N`` = states integrated, including parameters carried as
        states and states appended by hooks).
    tube : Interval (B, N)
        Every solution from ``previous`` stays in it over ``[t_start, t]``: the
        validated a-priori enclosure (every solution from ``hull`` stays in it), or a
        narrower box inside it that the stepper proved (the composition step:
        :func:`verified.steppers.tm_flow.step_tube`).
    nonlinear_width : ndarray (B, N)
        Width of the error the step's linearization injected into each set (the
        spread of the Jacobian over the set times the set's linear part), in state
        units: drives the wrapping control and adaptive splitting.
    t_start, t : float
        Start and end time (s); ``t`` is the output time itself when ``landed``.
    t_exact_start, t_exact : Fraction
        The exact times (a sum of float steps; every enclosure belongs to them).
    landed : bool
        The step ended on a requested output time.
    tube_view : verified.sets.protocol.SetView or None
        The a-priori enclosure as a linear view over symbols of its own (every
        solution from ``previous`` is some ``c + A' p`` over the step), where the
        stepper keeps one (the composition step, :func:`verified.steppers.tm_flow.tube_view`);
        :mod:`mbs.frames` takes the frames over the tube in it.
    """

    sets: object
    previous: object
    h: float | Interval
    hull: Interval
    tube: Interval
    nonlinear_width: np.ndarray
    t_start: float = math.nan
    t: float = math.nan
    t_exact_start: Fraction | None = None
    t_exact: Fraction | None = None
    landed: bool = False
    tube_view: object = None

    @property
    def length(self) -> float:
        """The float step size the a-priori enclosure was validated for (s): ``h``, or
        its upper end when ``h`` is an interval."""
        return float(self.h.hi) if isinstance(self.h, Interval) else self.h

    @property
    def t_enclosure(self) -> Interval:
        """A scalar interval of floats enclosing the exact time ``t_exact``."""
        return Interval(*enclose_fraction(self.t_exact))


class Stepper(Protocol):
    """One verified step for one set representation, batched over the sets.

    The driver (:func:`verified.solver.solve`) sets ``steer`` once, then calls, per
    step: ``begin(sets)`` with the sets the step starts from, ``coefficients(X)`` on
    the hull ``X`` (B, N) of the sets, ``suggest_step`` for a step size, ``apriori``
    until an enclosure is validated (shrinking ``h`` on failure), then ``step``. After
    the run it reads ``absorbed`` and ``merged`` into the solution's statistics.
    :class:`verified.steppers.lohner.LohnerStepper` implements all of it; the other steppers
    subclass it.
    """

    order: int
    #: the first states, which decide the stepper's own choices (absorbing, symbol
    #: order); states past them were appended by a hook. None: all. Set by the driver.
    steer: int | None
    #: how many times the error part was absorbed into parameters, and how many times
    #: parameters were merged to make room (statistics)
    absorbed: int
    merged: int

    def begin(self, sets) -> None:
        """Before each step, with the sets it starts from (a stepper that takes its
        coefficients over the sets, not their hull, prepares them here)."""

    def coefficients(self, X: Interval) -> Interval:
        """Taylor coefficients of the solutions from the boxes ``X`` (B, N): shape
        (B, order + 1, N)."""

    def suggest_step(self, cX: Interval, tol: float, components: int | None = None) -> float:
        """A step size (s) that makes the order-K term about ``tol`` on the first
        ``components`` states."""

    def apriori(self, X: Interval, cX: Interval, h: float):
        """``(E, cE)``: an enclosure (B, N) of every solution from ``X`` over ``[0, h]``
        and its Taylor coefficients, or None when it cannot be validated."""

    def step(self, sets, h, X: Interval, E: Interval, cE: Interval) -> StepResult:
        """Advance every set by ``h`` (float or Interval, s) given the hull ``X`` and
        its a-priori enclosure ``E``; the times of the result are left to the driver."""

"""The driver's decisions, one small object each (as CAPD's ``StepControl``).

- :class:`StepControl`: the step size from the Taylor coefficients, landing on output
  times, and the retries until an a-priori enclosure is validated with a small enough
  remainder;
- :class:`WrapControl`: shortens the next step when a step injected too much error
  through the Jacobian's spread over a wide set;
- :class:`SplitPolicy`, :class:`MergePolicy`: adaptive splitting and merging of sets.

None of them changes what a step encloses, only which (sound) step is taken next or
how the union of sets is represented. The error bases the sets keep are in
:mod:`verified.sets.bases`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from verified.arith.interval import Interval, hull
from verified.steppers.protocol import REMAINDER_SLACK

__all__ = ["StepControl", "Validated", "WrapControl", "SplitPolicy", "MergePolicy", "LANDING_STRETCH"]


#: a step may grow by this factor to land on an output time instead of stopping just short
#: of it (else many steps are slivers; docs/lab/code_notes.md)
LANDING_STRETCH = 1.2


# ---------------------------------------------------------------------------- step size
@dataclass
class Validated:
    """The outcome of :meth:`StepControl.validate`: ``enclosure = (E, cE)`` or None
    (no step validated above ``h_min``), the step ``h`` (s) to take (``E`` encloses every
    solution over ``[0, h]``: it was validated for ``h`` or for a longer step), and the
    a-priori attempts made (``evaluations``) and rejected."""

    enclosure: tuple | None
    h: float
    evaluations: int
    rejected: int


@dataclass
class StepControl:
    """Step size: the order-K term about ``tol`` (absolute, state units), at most
    ``h_max`` (s), landing on output times; retried smaller until the a-priori
    enclosure validates and the Lagrange remainder is at most ``remainder_slack * tol``
    (or ``h`` falls below ``h_min``).

    ``steer`` states (the first ones) steer the step size: states appended by a hook
    (an energy state, whose rate is ~0 with wide interval coefficients) do not.
    """

    tol: float
    h_min: float
    h_max: float
    steer: int
    remainder_slack: float = REMAINDER_SLACK

    def propose(self, stepper, cX: Interval, limit: float, gap_lo: float, gap_hi: float) -> float:
        """The step (s) to try from the coefficients ``cX`` (B, K+1, N), at most ``limit``
        (the wrapping control's) and the gap to the next output time (``gap_lo <= gap
        <= gap_hi``): when it reaches the gap, or would reach it stretched by
        ``LANDING_STRETCH`` (within ``h_max`` and the stretched limit), it becomes
        ``gap_hi`` (land there)."""
        h = min(stepper.suggest_step(cX, self.tol, self.steer), self.h_max, limit, gap_hi)
        if h * LANDING_STRETCH >= gap_lo and gap_hi <= min(self.h_max, limit * LANDING_STRETCH):
            # land on the output time (validate the enclosure up to gap_hi); a gap a
            # little longer than h is taken in one step rather than leaving a sliver
            # step behind (validate still shrinks it if its remainder is too large)
            h = gap_hi
        return h

    def validate(self, stepper, X: Interval, cX: Interval, h: float) -> Validated:
        """Shrink ``h`` until ``stepper.apriori`` validates an enclosure over ``[0, h]``
        whose remainder is small enough (see the class). The enclosure returned may have
        been validated over a longer step ``[0, h']``, ``h' >= h`` (a step shrunk for its
        remainder keeps the enclosure it has): ``E`` encloses every solution over ``[0,
        h]`` and ``cE`` bounds the Taylor coefficients there, which is all a step uses."""
        K = stepper.order
        limit = self.remainder_slack * self.tol
        evaluations = rejected = 0
        kept = None  # (h_kept, (E, cE), max |x_[K]| over E): the last enclosure validated
        while True:
            if kept is not None and h <= kept[0] and not kept[2] * h**K > limit:
                # E encloses every solution over [0, h_kept], hence over [0, h], and
                # x_[K] over E bounds the Lagrange remainder there: a step shrunk for
                # the remainder alone needs no new a-priori test (one over [0, h] would
                # give a narrower E, which accepts this h too; the step takes its
                # remainder from the E it is given). docs/lab/robot_speed.md
                return Validated(kept[1], h, evaluations, rejected)
            validated = stepper.apriori(X, cX, h)
            evaluations += 1
            if validated is not None:
                # Remainder control: h was chosen from the order-K coefficient over the
                # hull X, but the Lagrange remainder takes it over the wider a-priori
                # enclosure E. Over a deep model graph that can be many orders larger,
                # and a remainder far above tol wrecks a narrow set for good.
                top = float(np.max(validated[1][:, K, :self.steer].mag()))
                rem = top * h**K
                if not rem > limit or h < self.h_min:
                    return Validated(validated, h, evaluations, rejected)
                kept = (h, validated, top)
                # (0.95: the kept enclosure's remainder at the new step is then clearly
                # within the limit, not at it, so whether it is kept is no rounding's call)
                h *= max(0.2, min(0.9, 0.95 * (limit / rem) ** (1.0 / K)))
            elif h < self.h_min:
                return Validated(None, h, evaluations, rejected)
            else:
                h *= 0.5
            rejected += 1


#: see WrapControl.update: the smallest linear size (relative to the state's magnitude)
#: a set's wrapping is measured against
WRAP_FLOOR = 1e-12


@dataclass
class WrapControl:
    """Wrapping control: the error a step injects through the spread of the Jacobian
    over a wide set grows faster than the step itself, so keep it at about ``target``
    times the set's linear size by adapting the next step. ``h_limit`` (s) is the
    current limit (``inf``: none); it grows back by doubling, up to ``h_max``
    (``target = inf`` turns the control off)."""

    target: float
    h_max: float
    steer: int
    h_limit: float = math.inf

    def update(self, step) -> None:
        """Adapt ``h_limit`` after the accepted :class:`~verified.steppers.protocol.StepResult` ``step``."""
        n = self.steer
        # the linear size has a floor of WRAP_FLOOR times the state's magnitude: a point set
        # (width 0: a deterministic run) has no wrapping to control, and the rounding in its
        # nonlinear part over a zero linear size had driven h_limit to 0 (the composition
        # took 0-length steps after landing on an output time until max_steps)
        c = getattr(step.sets, "c", None)  # (the set's centres; a bare set-like object has none)
        floor = WRAP_FLOOR * (1.0 + (0.0 if c is None else np.abs(np.asarray(c, float)[:, :n]).max(axis=1)))
        with np.errstate(invalid="ignore"):  # (a NaN width, a set breaking down, leaves the limit as it is)
            ratio = float(np.max(step.nonlinear_width[:, :n].max(axis=1)
                                 / (step.sets.linear_width()[:, :n].max(axis=1) + floor)))
        h = step.length
        if ratio > self.target:
            self.h_limit = h * max(0.2, np.sqrt(self.target / ratio))
        elif ratio < 0.25 * self.target:
            self.h_limit = min(2.0 * self.h_limit, self.h_max)  # (unbounded doubling overflowed on long runs)


# ---------------------------------------------------------------------------- splitting and merging
@dataclass
class SplitPolicy:
    """Adaptive splitting: one linearization per set stops following the curved
    reachable set when the error it injects per unit time (the Jacobian's spread over
    the set times the set's linear part) is a sizeable fraction of the width of the
    whole union, which bounds what that error costs: split such sets in two (halving
    a set roughly quarters its injection). ``ratio`` in 1/s, ``tol`` the step control's
    (state units), at most ``max_boxes`` sets."""

    ratio: float
    max_boxes: int
    tol: float

    def select(self, step) -> np.ndarray:
        """(B,) bool: the sets of ``step.sets`` to split after the step ``step``."""
        injected = step.nonlinear_width / step.length  # (B, N)
        union_width = hull(step.hull, axis=0).width()  # (N,)
        return (injected > self.ratio * union_width + 1e3 * self.tol).any(axis=1)

    def apply(self, step, sets):
        """``(sets, n_split, reason)``: ``sets`` with the selected ones split, or
        ``reason`` (a break-down) when that would exceed ``max_boxes``.

        The step's widths describe ``step.sets`` only: when a hook replaced them (a
        consistency test pruned or refined), nothing is split after this step. (Applying
        the mask to the replaced batch dropped every set beyond the mask's length:
        unsound.)"""
        if sets is not step.sets:
            return sets, 0, ""
        grow = self.select(step)
        if not grow.any():
            return sets, 0, ""
        if sets.n_sets + int(grow.sum()) > self.max_boxes:
            return sets, 0, f"adaptive splitting needs more than max_boxes={self.max_boxes} boxes"
        return sets.split(grow), int(grow.sum()), ""


@dataclass
class MergePolicy:
    """Merge neighbouring sets when one set covering both is at most ``1 + slack``
    times as wide as their union's hull (see ``DoubletonSets.merge_overlapping``)."""

    slack: float

    def apply(self, sets):
        """``(sets, merges)``."""
        if sets.n_sets > 1:
            return sets.merge_overlapping(self.slack)
        return sets, 0

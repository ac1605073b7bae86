"""The set representations the solver carries and the steppers that advance them.

``solve(..., set_order=, set_step=)`` names a kind; this table says which
:class:`~verified.sets.protocol.SetBatch` type the initial boxes become and which
:class:`~verified.steppers.protocol.Stepper` advances it (as CAPD pairs a ``dynset`` with its
``TimeMap``). A new representation is one more entry here (its sets type and a stepper
factory): neither the driver loop nor the run set-up change.

| ``(set_order, set_step)`` | sets | stepper |
|---|---|---|
| ``(1, "mean_value")`` | :class:`~verified.sets.first_order.DoubletonSets` (``c + C r0 + Q r``, CAPD's Rect2) | :class:`~verified.steppers.lohner.LohnerStepper` (QR-Lohner) |
| ``(2, "mean_value")`` | :class:`~verified.sets.second_order.QuadraticSets` (``c + C u + q(u) + Q r``) | :class:`~verified.steppers.second_order.QuadraticStepper` (second variational equations at the centre) |
| ``(2, "composition")`` | :class:`~verified.sets.second_order.QuadraticSets` | :class:`~verified.steppers.tm_flow.TaylorModelFlowStepper` (the step composed with the set in Taylor models) |

A stepper factory takes the problem (:class:`verified.solver.VerifiedODE`: its
evaluators), the Taylor order, the parameter box (or None), the error basis, the cap on
a set's parameters (None: the stepper's default), ``absorb``, ``model_degree``,
``model_caps`` (the composition's monomial caps, a dict; None: the defaults) and
``min_order`` (the composition's lowest order per step; None: every step at ``order``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from verified.steppers.lohner import LohnerStepper
from verified.sets.second_order import QuadraticSets
from verified.steppers.second_order import QuadraticStepper
from verified.sets.first_order import DoubletonSets
from verified.steppers.tm_flow import TaylorModelFlowStepper

__all__ = ["SetKind", "SET_KINDS", "set_kind", "set_kind_names"]


@dataclass(frozen=True)
class SetKind:
    """A set representation (``sets``: a SetBatch type with ``from_boxes``) and the
    factory of the stepper that advances it (module docstring)."""

    sets: type
    stepper: Callable


def _lohner(prob, order, params, error_basis, max_params, absorb, model_degree, model_caps=None, min_order=None):
    return LohnerStepper(prob.taylor, prob.variational, order, params, error_basis, absorb=absorb,
                         max_params=max_params)


def _mean_value_second_order(prob, order, params, error_basis, max_params, absorb, model_degree, model_caps=None,
                             min_order=None):
    return QuadraticStepper(prob.taylor, prob.variational, prob.second_variational, order, params, error_basis,
                            second_over_set=prob.second_variational_over_set,
                            second_directional=(None if prob.arithmetic == "interval"
                                                else prob.second_variational_along),
                            max_params=max_params)


def _composition(prob, order, params, error_basis, max_params, absorb, model_degree, model_caps=None, min_order=None):
    caps = {f"{k}_cap": int(v) for k, v in (model_caps or {}).items()}
    return TaylorModelFlowStepper(prob.taylor, prob.set_models, order, params, error_basis,
                                  max_params=max_params, degree=3 if model_degree is None else model_degree,
                                  min_order=min_order, **caps)


SET_KINDS: dict[tuple[int, str], SetKind] = {
    (1, "mean_value"): SetKind(DoubletonSets, _lohner),
    (2, "mean_value"): SetKind(QuadraticSets, _mean_value_second_order),
    (2, "composition"): SetKind(QuadraticSets, _composition),
}


def set_kind(set_order: int, set_step: str) -> SetKind:
    """The entry of ``SET_KINDS`` for ``(set_order, set_step)``; a one-line ValueError
    naming the known ones otherwise (:func:`verified.solver.solve` checks each argument
    first, with messages of its own)."""
    kind = SET_KINDS.get((set_order, set_step))
    if kind is None:
        known = ", ".join(f"set_order={o}, set_step={s!r}" for o, s in SET_KINDS)
        raise ValueError(f"no set kind for set_order={set_order!r}, set_step={set_step!r} (known: {known})")
    return kind


def set_kind_names() -> tuple[tuple, tuple]:
    """The ``set_order`` values and the ``set_step`` names of ``SET_KINDS``, each once, in
    the table's order (what :func:`verified.solver.solve` accepts)."""
    return tuple(dict.fromkeys(o for o, _ in SET_KINDS)), tuple(dict.fromkeys(s for _, s in SET_KINDS))

"""Methods of :func:`verified.solver.solve`: how the sets are advanced, as objects.

A method is a frozen dataclass whose fields are its settings, with their defaults and
their checks (``__post_init__``: a one-line ValueError naming the field). It declares
what it supports, so that a combination it cannot run is refused by the method, once,
with one message. A short string names each (``solve(..., method="composition")``);
:data:`METHODS` maps the names to the classes, as scipy's ``solve_ivp`` does.

| name | class | sets | step |
|---|---|---|---|
| ``"lohner"`` | :class:`Lohner` | first order: QR-Lohner doubletons ``c + C r0 + Q r`` (:mod:`verified.sets.first_order`) | Taylor series + first variational equations (:mod:`verified.steppers.lohner`) |
| ``"second_order"`` | :class:`SecondOrder` | second order: ``c + C u + q(u) + Q r`` (:mod:`verified.sets.second_order`) | + second variational equations at the centre (mean value) |
| ``"composition"`` | :class:`Composition` | second order | the Taylor map composed with the set in Taylor models (:mod:`verified.steppers.tm_flow`) |
| ``"auto"`` | :class:`Auto` | any | a ladder of the above, continued from the verified sets (:mod:`verified.auto`) |

A method turns into the driver's settings with :meth:`Method.settings` (the keyword
arguments of :func:`verified.driver.batch.solve_batch`); nothing else in the library needs to
know its fields.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from verified.driver.solver_args import ARITHMETICS, ERROR_BASES, MAX_ORDER, check_model_cap, check_params_per_state

__all__ = ["Method", "Lohner", "SecondOrder", "Composition", "Auto", "METHODS", "as_method", "METHOD_FIELDS"]

#: what a method may support (:attr:`Method.supports`)
CAPABILITIES = ("adaptive", "consistency", "params", "appended_states", "start")

#: the keyword arguments of ``solve`` that a method owns (its fields, spread over the
#: signature before methods were objects): given beside ``method=`` they are refused
METHOD_FIELDS = ("order", "tol", "error_basis", "arithmetic", "set_order", "set_step", "model_degree",
                 "model_caps", "absorb", "params_per_state", "min_order")


def _int_in(name: str, value, lo: int, hi: int) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Integral, np.integer)) \
            or not lo <= value <= hi:
        raise ValueError(f"{name} must be an integer in [{lo}, {hi}], got {value!r}")
    return int(value)


def _positive(name: str, value) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Real, np.floating, np.integer)) \
            or not (math.isfinite(float(value)) and value > 0):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return float(value)


def _choice(name: str, value, choices) -> str:
    if not isinstance(value, str) or value not in choices:
        raise ValueError(f"{name} must be one of {tuple(choices)}, got {value!r}")
    return value


@dataclass(frozen=True)
class Method:
    """Base of the methods: the Taylor order and tolerance every one of them has.

    order : Taylor order K of the step, 2 <= K <= 60
    tol : target size of the order-K term per step (absolute, state units)
    """

    name: ClassVar[str] = ""
    #: what the method can run with (:data:`CAPABILITIES`)
    supports: ClassVar[frozenset] = frozenset()

    order: int = 12
    tol: float = 1e-10

    def __post_init__(self):
        _int_in(f"{self.name}: order", self.order, 2, MAX_ORDER)
        _positive(f"{self.name}: tol", self.tol)

    def settings(self) -> dict:
        """The keyword arguments of :func:`verified.driver.batch.solve_batch` that run this method."""
        raise NotImplementedError

    def refuse(self, *, adaptive=False, consistency=False, params=False, appended_states=False,
               start=False) -> None:
        """A one-line ValueError when the run needs something this method does not support."""
        needs = dict(adaptive=adaptive, consistency=consistency, params=params, appended_states=appended_states,
                     start=start)
        missing = [k for k, v in needs.items() if v and k not in self.supports]
        if missing:
            words = {"adaptive": "adaptive splitting", "consistency": "a consistency (energy) test",
                     "params": "uncertain parameters", "appended_states": "states appended by a hook",
                     "start": "a start from given sets"}
            raise ValueError(f"method {self.name!r} does not support {', '.join(words[m] for m in missing)}")

    def replace(self, **changes) -> "Method":
        """A copy with some fields changed (checked again)."""
        return dataclasses.replace(self, **changes)

    def describe(self) -> str:
        """The method in one line: its name and the fields that differ from the defaults."""
        diff = [f"{f.name}={getattr(self, f.name)!r}" for f in dataclasses.fields(self)
                if f.compare and getattr(self, f.name) != f.default]
        return self.name + (f"({', '.join(diff)})" if diff else "")


@dataclass(frozen=True)
class Lohner(Method):
    """First-order sets ``c + C r0 + Q r`` advanced by the QR-Lohner step (the classic
    method of CAPD and VNODE-LP; :mod:`verified.steppers.lohner`). Cheapest per step; the set's
    curvature is wrapped every step, so wide boxes need pieces.

    error_basis : "qr" (Lohner's QR basis for the error part) or "auto" (per set and
        step, the QR basis or a plain box, whichever is tighter)
    arithmetic : "interval", "affine" or "taylor_model": how the Taylor coefficients and
        the variational equations are enclosed over a set (affine keeps first-order
        dependence through deep model graphs such as a robot's)
    absorb : turn the error part into new parameters of the set once it is 10 % of the
        carried part (no consistency test, appended states or adaptive splitting)
    params_per_state : parameters per state an absorbing set may carry (None: 8)
    """

    name: ClassVar[str] = "lohner"
    supports: ClassVar[frozenset] = frozenset(CAPABILITIES)

    error_basis: str = "qr"
    arithmetic: str = "interval"
    absorb: bool = False
    params_per_state: int | None = None

    def __post_init__(self):
        super().__post_init__()
        _choice(f"{self.name}: error_basis", self.error_basis, ERROR_BASES)
        _choice(f"{self.name}: arithmetic", self.arithmetic, ARITHMETICS)
        if not isinstance(self.absorb, (bool, np.bool_)):
            raise ValueError(f"{self.name}: absorb must be True or False, got {self.absorb!r}")
        check_params_per_state(self.params_per_state)
        if self.absorb:  # (absorbed errors are split without end; the contraction needs plain sets)
            object.__setattr__(self, "supports", frozenset({"params", "start"}))

    def settings(self) -> dict:
        return dict(order=self.order, tol=self.tol, error_basis=self.error_basis, arithmetic=self.arithmetic,
                    set_order=1, set_step="mean_value", absorb=bool(self.absorb),
                    params_per_state=self.params_per_state)


@dataclass(frozen=True)
class SecondOrder(Method):
    """Second-order sets ``c + C u + q(u) + Q r`` advanced by the mean-value step: the
    Taylor map's first and second derivatives at the centre plus the Hessian's spread
    over the set (:mod:`verified.sets.second_order`). Carries the flow's curvature instead of
    wrapping it; costs the second variational equations (n (n + 1) / 2 directions).

    error_basis, arithmetic : as for :class:`Lohner`
    params_per_state : parameters per state a set may carry when it absorbs its error
        part (None: 4)
    """

    name: ClassVar[str] = "second_order"
    supports: ClassVar[frozenset] = frozenset(CAPABILITIES)

    error_basis: str = "qr"
    arithmetic: str = "interval"
    params_per_state: int | None = None

    def __post_init__(self):
        super().__post_init__()
        _choice(f"{self.name}: error_basis", self.error_basis, ERROR_BASES)
        _choice(f"{self.name}: arithmetic", self.arithmetic, ARITHMETICS)
        check_params_per_state(self.params_per_state)

    def settings(self) -> dict:
        return dict(order=self.order, tol=self.tol, error_basis=self.error_basis, arithmetic=self.arithmetic,
                    set_order=2, set_step="mean_value", params_per_state=self.params_per_state)


@dataclass(frozen=True)
class Composition(Method):
    """Second-order sets advanced by composing the step's Taylor map with the set written
    as a Taylor model over its own parameters (as COSY-VI, Flow* and TaylorModels.jl
    do; :mod:`verified.steppers.tm_flow`): no variational equations, higher-order effects bounded
    where they arise. The strongest method on nonlinear systems and robots.

    model_degree : 2, 3 or 4: the degree of the Taylor-model arithmetic
    model_caps : None or a dict: how many of a set's widest symbols get quadratic,
        cubic, quartic and star monomials, and the pool of remainder symbols
        (``verified.steppers.tm_flow``; keys ``quadratic``, ``cubic``, ``quartic``, ``star``, ``pool``)
    error_basis, arithmetic : as for :class:`Lohner` (defaults "auto" and "taylor_model")
    params_per_state : parameters per state a set may carry (None: 4)
    min_order : None (every step at ``order``) or an integer in [2, order]: each step
        runs at an order in ``[min_order, order]`` chosen from the last step (lower
        where the composition's growth cut, not the series' last term, sets the step;
        ``verified.steppers.tm_flow.TaylorModelFlowStepper``). Every step is verified
        at the order it runs.
    """

    name: ClassVar[str] = "composition"
    supports: ClassVar[frozenset] = frozenset(CAPABILITIES)

    error_basis: str = "auto"
    arithmetic: str = "taylor_model"
    model_degree: int = 3
    model_caps: dict | None = field(default=None, hash=False)
    params_per_state: int | None = None
    min_order: int | None = None

    def __post_init__(self):
        super().__post_init__()
        _choice(f"{self.name}: error_basis", self.error_basis, ERROR_BASES)
        _choice(f"{self.name}: arithmetic", self.arithmetic, ARITHMETICS)
        if self.min_order is not None:
            _int_in(f"{self.name}: min_order", self.min_order, 2, self.order)
        if isinstance(self.model_degree, (bool, np.bool_)) or self.model_degree not in (2, 3, 4):
            raise ValueError(f"{self.name}: model_degree must be 2, 3 or 4, got {self.model_degree!r}")
        if self.model_caps is not None:
            if not isinstance(self.model_caps, dict):
                raise ValueError(f"{self.name}: model_caps must be None or a dict, got {self.model_caps!r}")
            from verified.driver.batch import MODEL_CAPS  # (the keys the composition stepper knows)
            for k, v in self.model_caps.items():
                if k not in MODEL_CAPS:
                    raise ValueError(f"{self.name}: model_caps: unknown key {k!r} (known: {', '.join(MODEL_CAPS)})")
                check_model_cap(k, v)
        check_params_per_state(self.params_per_state)

    def settings(self) -> dict:
        return dict(order=self.order, tol=self.tol, error_basis=self.error_basis, arithmetic=self.arithmetic,
                    set_order=2, set_step="composition", model_degree=self.model_degree,
                    model_caps=None if self.model_caps is None else dict(self.model_caps),
                    params_per_state=self.params_per_state, min_order=self.min_order)


@dataclass(frozen=True)
class Auto(Method):
    """Choose the method from the problem and do not give up while a stronger one exists
    (:mod:`verified.auto`).

    The rungs are tried in order; when a rung cannot verify a step, the run continues
    from the last verified sets with the next rung, and after the last rung by splitting
    the pieces that failed (up to ``max_pieces`` pieces). A break-down is reported only
    when every rung has failed; ``Solution.method_log`` says which method advanced which
    time span and why it switched.

    rungs : None (chosen from the problem: :func:`verified.auto.ladder.default_rungs`) or a
        sequence of methods (objects or names), weakest first
    max_pieces : the most pieces splitting may make of the initial set (>= 1). Each split
        is first judged by one of its parts run alone (a probe, reused as part of the
        split attempt): where that part gets no further than the piece it was split from,
        or where reaching ``t1`` would need more than ``max_pieces`` pieces even if every
        further split gained twice what the last one gained
        (:func:`verified.auto.ladder.projected_pieces`), ``auto`` stops splitting there
        and says so in ``method_log``
    target_ratio : None (default) or a number > 1: after the run reaches ``t1``, the
        width of its final enclosure is compared with the spread of sampled true states
        (float trajectories from the corners and random points of the initial boxes;
        an estimate that guides the work, never the enclosure), and while it is wider
        than ``target_ratio`` times that spread every piece is split and the run
        repeated (up to ``max_pieces``); the tightest run is returned
    spec : None (default), a :class:`verified.spec.Bounds` or a dict ``{state: (lo, hi)}``
        (a state by name or index, None for no bound): bounds the states must keep at
        every time of the run. After a completed run the tube is checked against them
        and, while they are not proven and refining still shrinks the excess, the pieces
        whose tube leaves them are split, or the steps shortened where the sets at the
        step ends keep inside and only the tube between them leaves
        (:mod:`verified.auto`). ``Solution.spec_proven`` / ``Solution.spec_check``: proven
        only from the verified tube over the whole span; "false" where a sampled float
        trajectory leaves the bounds (refining then stops)
    """

    name: ClassVar[str] = "auto"
    supports: ClassVar[frozenset] = frozenset(CAPABILITIES) - {"start"}

    rungs: tuple | None = None
    max_pieces: int = 256
    target_ratio: float | None = None
    spec: object = None

    def __post_init__(self):
        super().__post_init__()
        if self.rungs is not None:
            try:
                rungs = tuple(as_method(r) for r in self.rungs)
            except TypeError:
                raise ValueError(f"auto: rungs must be a sequence of methods, got {self.rungs!r}") from None
            if not rungs or any(isinstance(r, Auto) for r in rungs):
                raise ValueError("auto: rungs must be one or more methods other than 'auto'")
            object.__setattr__(self, "rungs", rungs)
        _int_in("auto: max_pieces", self.max_pieces, 1, 2**21)
        if self.target_ratio is not None and not (_positive("auto: target_ratio", self.target_ratio) > 1):
            raise ValueError(f"auto: target_ratio must be None or a number > 1, got {self.target_ratio!r}")
        if self.spec is not None:
            from verified.spec import as_spec
            try:
                object.__setattr__(self, "spec", as_spec(self.spec))
            except ValueError as e:
                raise ValueError(f"auto: {e}") from None

    def settings(self) -> dict:
        raise TypeError("method 'auto' is a ladder of methods, not one set of solver settings "
                        "(verified.auto.solve_auto runs it)")


#: the methods by name (``solve(..., method="composition")``)
METHODS: dict[str, type] = {m.name: m for m in (Lohner, SecondOrder, Composition, Auto)}


def as_method(method) -> Method:
    """A :class:`Method` from a method object or a name in :data:`METHODS`."""
    if isinstance(method, Method):
        return method
    if isinstance(method, type) and issubclass(method, Method) and method is not Method:
        return method()
    if isinstance(method, str):
        cls = METHODS.get(method)
        if cls is None:
            raise ValueError(f"unknown method {method!r}; methods: {', '.join(METHODS)}")
        return cls()
    raise TypeError(f"method must be a name ({', '.join(map(repr, METHODS))}) or a verified.methods.Method, "
                    f"got {type(method).__name__}")


def from_settings(**flags) -> Method:
    """The method the scattered keyword arguments of the old signature describe
    (``set_order``, ``set_step``, ``order``, ...); missing ones at the method's defaults."""
    set_order = flags.pop("set_order", 1)
    set_step = flags.pop("set_step", "mean_value")
    if set_order not in (1, 2) or isinstance(set_order, bool):
        raise ValueError(f"set_order must be 1 or 2, got {set_order!r}")
    if set_step not in ("mean_value", "composition"):
        raise ValueError(f"set_step must be 'mean_value' or 'composition', got {set_step!r}")
    if set_step == "composition" and set_order != 2:
        raise ValueError("set_step='composition' advances second-order sets: it needs set_order=2")
    flags = {k: v for k, v in flags.items() if v is not None}
    if set_order == 1 and set_step == "mean_value":
        cls = Lohner
    elif set_order == 2 and set_step == "mean_value":
        cls = SecondOrder
    elif set_order == 2 and set_step == "composition":
        cls = Composition
    else:
        raise ValueError(f"no method for set_order={set_order!r}, set_step={set_step!r}")
    known = {f.name for f in dataclasses.fields(cls)}
    extra = sorted(set(flags) - known)
    if extra:
        raise ValueError(f"{', '.join(extra)} {'is' if len(extra) == 1 else 'are'} not a setting of method "
                         f"{cls.name!r} (its settings: {', '.join(sorted(known))})")
    return cls(**flags)

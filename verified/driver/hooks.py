"""Hooks: how consistency tests, contractors, progress bars and stop rules plug into
:func:`verified.solver.solve` without editing its loop.

A hook is any object with the three methods of :class:`SolverHook` (subclass
:class:`Hook` for no-op defaults) passed as ``solve(..., hooks=[...])``. The driver
calls, in the order the hooks are given (``progress`` first, then ``consistency``,
then ``hooks``):

``before_run(setup) -> RunSetup | None``
    once, before the first step. A hook may return a changed :class:`RunSetup`: a
    graph with states appended after the solver's (the energy test appends
    ``h' = dH/dt``), initial sets extended to match, a smaller ``h_max``.
``after_step(step, sets, run) -> SetBatch | None``
    after every accepted step, with the :class:`~verified.steppers.protocol.StepResult` and the
    current sets at ``step.t`` (what earlier hooks left). Return None to keep the sets,
    or new sets that enclose every true state the given ones enclose (pruning parts
    that provably hold none, contracting, refining). ``run`` (:class:`RunControl`)
    lets a hook stop the integration (``run.stop(reason)``), roll the last step back
    to test at the step before (``run.rollback()``), and build a stepper of the run's
    kind for another graph (``run.make_stepper(graph)``, for backward tests).
``after_run(solution)``
    once, on the :class:`~verified.solver.Solution` (also a partial one), to attach
    records and statistics. In a chunked run it sees each chunk's Solution.
``after_solve(solution)`` (optional: a hook without it is called at the other three)
    once, on the whole Solution :func:`~verified.solver.solve` returns: after the chunks
    of a chunked run are merged and after every attempt of ``auto``. It may edit that
    Solution in place, for a proof that belongs to the whole run (a proof that fails
    on some box cuts the run back to that time and makes it a break-down). Like
    ``after_step``'s sets, what it leaves is what ``solve`` returns.

Soundness is the hook's responsibility: whatever ``after_step`` returns is what the
solver continues from and reports at output times.

Stopping early: a hook's ``run.stop(reason)`` and a ``KeyboardInterrupt`` (Ctrl-C)
during the integration both end it with the partial :class:`~verified.solver.Solution`
(everything verified so far, ``t_reached`` the last verified time) instead of an
exception: ``status="stopped"`` / ``"interrupted"`` with the reason. A wall-clock cap
is the hook :class:`StopAfterWall`::

    sol = solve(graph, x0, (0, 10), hooks=[StopAfterWall(60.0)])
    if sol.status == "stopped": print(sol.reason, sol.t_reached)
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Protocol, runtime_checkable

if TYPE_CHECKING:  # annotations only
    from verified.graph import Graph
    from verified.arith.interval import Interval

__all__ = ["RunSetup", "RunControl", "SolverHook", "Hook", "StopAfterWall", "ProgressHook", "check_hooks",
           "after_solve", "part_hooks"]


@dataclass
class RunSetup:
    """The run as the hooks see it before the first step (``before_run``).

    Attributes
    ----------
    user_graph : Graph
        The ODE as given: ``n_state`` states, its own parameters.
    graph : Graph
        The graph integrated: the ``n_state`` states, then uncertain parameters carried
        as constant states, then states appended by hooks. A hook that appends states
        returns a new graph (whose first inputs are the old graph's) and matching sets.
    n_state : int
        States of the user's ODE (reported in the Solution).
    n_steer : int
        States that steer the step size and the wrapping control (the user's states
        and parameters carried as states; not states appended by hooks).
    params : Interval (p,) or (B, p), or None
        Parameters passed to ``graph`` (None when carried as states or absent).
    t0 : float
        Start time (s).
    sets : SetBatch
        The initial sets (B sets over ``graph``'s inputs).
    h_max : float
        Largest step (s).
    """

    user_graph: Graph
    graph: Graph
    n_state: int
    n_steer: int
    params: Interval | None
    t0: float
    sets: object
    h_max: float


@runtime_checkable
class RunControl(Protocol):
    """What ``after_step`` may ask of the running integration."""

    def stop(self, reason: str, status: str = "stopped") -> None:
        """End the integration after this step (its sets and, if it landed on one,
        its output are kept): the Solution gets ``status`` ("stopped", or
        "breakdown" for a failure) and ``reason``."""

    def rollback(self):
        """Undo the step just taken and return ``(step, sets)`` for the step before it
        (its StepResult and the sets at its end, ``step.t``), or None when that is not
        possible: the step landed on an output time, or no earlier step was taken since
        the sets were last replaced by a hook. Hooks called later see the earlier step."""

    def make_stepper(self, graph: Graph):
        """A stepper of this run's kind (order, arithmetic, parameters, error basis)
        for another graph over the same inputs, e.g. the negated ODE."""

    def resume_point(self):
        """Where the run stands after this step, as ``solve(start=...)`` continues from
        it: a :class:`verified.solver.Start` with the sets, their exact time and the
        wrapping control's step limit (re-chunking in :mod:`verified.execution`)."""

    def landed_on_last_output(self, step) -> bool:
        """Whether ``step`` landed on the run's last output time (the run ends with it)."""


@runtime_checkable
class SolverHook(Protocol):
    """The hook protocol (see the module docstring for when each is called)."""

    def before_run(self, setup: RunSetup) -> RunSetup | None:
        ...

    def after_step(self, step, sets, run: RunControl):
        ...

    def after_run(self, solution) -> None:
        ...


class Hook:
    """Base class with no-op hook methods: override only what you need."""

    def before_run(self, setup: RunSetup) -> RunSetup | None:
        return None

    def after_step(self, step, sets, run: RunControl):
        return None

    def after_run(self, solution) -> None:
        return None

    def after_solve(self, solution) -> None:
        return None


def after_solve(hooks, solution) -> None:
    """Call the ``after_solve`` stage of every hook in ``hooks`` that has one, in order,
    on the whole ``solution`` (:func:`verified.solver.solve`'s last act)."""
    for h in hooks or ():
        stage = getattr(h, "after_solve", None)
        if stage is not None:
            stage(solution)


class StopAfterWall(Hook):
    """Stop the integration once ``seconds`` of wall-clock time have passed since
    ``before_run`` (the start of the integration, after the Taylor tapes are built).

    The check runs after every accepted step, so a run ends at most one step after
    the limit, with ``status="stopped"`` and everything verified up to then.
    ``clock``: a function returning seconds (default :func:`time.perf_counter`).
    """

    def __init__(self, seconds: float, clock: Callable[[], float] = time.perf_counter):
        s = float(seconds)
        if math.isnan(s) or s < 0:
            raise ValueError(f"seconds must be a number >= 0, got {seconds!r}")
        self.seconds = s
        self.clock = clock
        self._start = None

    def before_run(self, setup):
        self._start = self.clock()
        return None

    def after_step(self, step, sets, run):
        if self.clock() - self._start >= self.seconds:
            run.stop(f"wall-clock limit of {self.seconds:g} s reached")
        return None


class _PartOf(Hook):
    """A hook as one part of a whole run sees it: every stage but ``after_solve``, which
    the whole run's :func:`verified.solver.solve` calls once."""

    def __init__(self, hook):
        self.hook = hook

    def before_run(self, setup):
        return self.hook.before_run(setup)

    def after_step(self, step, sets, run):
        return self.hook.after_step(step, sets, run)

    def after_run(self, solution):
        return self.hook.after_run(solution)


def _own(hook, stage: str) -> bool:
    """Whether ``hook`` has ``stage`` other than :class:`Hook`'s no-op."""
    return getattr(hook, stage, None) is not None and getattr(type(hook), stage, None) is not getattr(Hook, stage)


def part_hooks(hooks) -> list:
    """``hooks`` for one part of a whole run (an attempt of ``auto``, a chunk of a chunked
    run): without their ``after_solve`` stage, which belongs to the whole; a hook that has
    no other stage is left out (a chunk need not carry it to a worker)."""
    out = []
    for h in hooks or ():
        if _own(h, "after_solve"):
            if not any(_own(h, s) for s in ("before_run", "after_step", "after_run")):
                continue
            h = _PartOf(h)
        out.append(h)
    return out


def caps_from(hooks, started: float) -> list:
    """``hooks`` for one of several runs that make up one (the attempts of ``auto``, the
    phases of an energy test that steps aside): a wall-clock cap
    (:class:`StopAfterWall`) counts from ``started`` (``time.perf_counter()`` at the start
    of the whole), not from the start of this run; ``after_solve`` stages are left to the
    whole (:func:`part_hooks`)."""
    out = []
    for h in part_hooks(hooks):
        if isinstance(h, StopAfterWall):
            h = StopAfterWall(max(0.0, h.seconds - (time.perf_counter() - started)), h.clock)
        out.append(h)
    return out


class ProgressHook(Hook):
    """Calls ``progress(t, t_end)`` after every accepted step (``solve(progress=...)``)."""

    def __init__(self, progress: Callable[[float, float], object], t_end: float):
        self.progress = progress
        self.t_end = t_end

    def after_step(self, step, sets, run):
        self.progress(step.t, self.t_end)
        return None


def check_hooks(hooks) -> list:
    """``hooks`` as a list, refused (one-line ValueError) unless every entry has the
    three hook methods."""
    if hooks is None:
        return []
    if isinstance(hooks, (str, bytes)) or not hasattr(hooks, "__iter__"):
        raise ValueError(f"hooks must be a sequence of hook objects, got {hooks!r}")
    out = list(hooks)
    for h in out:
        missing = [m for m in ("before_run", "after_step", "after_run") if not callable(getattr(h, m, None))]
        if missing:
            raise ValueError(f"hook {h!r} lacks {', '.join(missing)} (subclass verified.driver.hooks.Hook)")
    return out

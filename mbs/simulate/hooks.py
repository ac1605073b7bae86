"""The solver hooks :func:`mbs.simulate.simulate` adds to the caller's (the hook
protocol: :mod:`verified.driver.hooks`): the energy consistency test of modes ii and iii, the
energy shell, the invariant of a PD controller holding a pose, the wall-clock limit and
Ctrl-C, which stops the run cleanly after the step in progress."""
from __future__ import annotations

import signal
import sys
import threading

import numpy as np

from verified.consistency.energy_test import STRATEGIES, EnergyTest
from verified.consistency.contractor import EnergyShell
from verified.consistency.energy_shell import EnergyShellHook, max_energy
from verified.graph import Graph
from verified.driver.hooks import StopAfterWall
from verified.arith.interval import Interval
from verified.consistency.invariant import InvariantHook

from ..lyapunov import pd_hold_lyapunov
from ..system import System


def energy_test(system: System, mode, constraints, *, test_interval, test_splits, split_strategy, refine,
                min_gain, backward_depth, max_boxes, contract, prune):
    """The :class:`~verified.consistency.energy_test.EnergyTest` of ``mode`` (None in mode i, which
    refuses ``constraints``); ``test_interval`` and ``test_splits`` default to the
    mode's (:data:`mbs.simulate.TEST_DEFAULTS`)."""
    if split_strategy not in STRATEGIES:
        raise ValueError(f"split_strategy must be one of {STRATEGIES}, got {split_strategy!r}")
    if mode.energy_test:
        return EnergyTest(system.energy, system.energy_rate, constraints,
                          test_interval=mode.test_interval if test_interval is None else test_interval,
                          test_splits=mode.test_splits if test_splits is None else test_splits,
                          split_strategy=split_strategy, refine=refine, min_gain=min_gain, backward_depth=backward_depth,
                          max_boxes=max_boxes, contract=contract, prune=prune)
    if constraints:
        raise ValueError("mode i runs without consistency tests; use mode ii or iii for constraints")
    return None


def shell_hooks(energy_shell, run, model, box: Interval, params) -> list:
    """``[the energy shell's hook]`` with ``energy_shell=True``, else ``[]`` (``run``: a
    :class:`mbs.simulate.model.Resolved`; ``model`` as given to ``simulate``; ``box`` and
    ``params`` what ``solve`` gets). ``None`` (the default) holds no shell during the run
    (only :func:`mbs.shell_continuation.carry_on` after a break-down)."""
    if energy_shell is not None and not isinstance(energy_shell, (bool, np.bool_)):
        raise ValueError(f"energy_shell must be True, False or None, got {energy_shell!r}")
    if not energy_shell:
        return []
    return [_energy_shell_hook(run.masses, run.loop, box, model if isinstance(model, System) else run.system, params)]


def stop_hooks(solver_kwargs: dict, invariant_after, max_wall, loop, t0: float, t_end: float, t_eval, rhs) -> list:
    """The hooks that end a run early: the invariant of a PD hold (``invariant_after``;
    it runs in one process, so the default ``workers`` becomes 1 in ``solver_kwargs``)
    and the wall-clock limit (``max_wall``)."""
    hooks = []
    if invariant_after is not None:
        if solver_kwargs.get("client") is None and solver_kwargs.get("chunks") is None and (
                solver_kwargs.get("workers") is None or isinstance(solver_kwargs["workers"], str)
                and solver_kwargs["workers"] == "auto"):
            solver_kwargs["workers"] = 1  # "every core when worthwhile" (the default): here it is not
        if solver_kwargs.get("workers") != 1 or any(solver_kwargs.get(k) is not None for k in ("client", "chunks")):
            raise ValueError("invariant_after runs in one process (no workers, client or chunks): the "
                             "invariant is proven for every set at once")
        hooks.append(_invariant_hook(loop, invariant_after, t0, t_end, t_eval, rhs))
    if max_wall is not None:
        if isinstance(max_wall, bool) or not isinstance(max_wall, (int, float)) or not max_wall > 0 \
                or not np.isfinite(max_wall):
            raise ValueError(f"max_wall must be a positive number of seconds, got {max_wall!r}")
        hooks.append(StopAfterWall(max_wall))
    return hooks


def _invariant_hook(loop, t_switch, t0: float, t_end: float, t_eval, rhs=None):
    """The InvariantHook of a PD loop holding a pose (:mod:`mbs.lyapunov`): from
    ``t_switch`` on, the run ends as soon as every set lies in a verified invariant box."""
    if isinstance(t_switch, bool) or not isinstance(t_switch, (int, float, np.integer, np.floating)) \
            or not np.isfinite(t_switch) or not t0 <= t_switch <= t_end:
        raise ValueError(f"invariant_after must be a time in [t0, t_end] = [{t0:g}, {t_end:g}], got {t_switch!r}")
    if loop is None:
        raise ValueError("invariant_after needs control: a PD controller holding a pose (its closed-loop "
                         "energy is the Lyapunov function)")
    return InvariantHook(pd_hold_lyapunov(loop, rhs=rhs), float(t_switch), t_eval, t_end)


def _energy_shell_hook(masses, loop, box: Interval, system: System | None = None, params=None):
    """The energy shell's hook (``simulate(energy_shell=True)``).

    A passive chain (no controller; damping >= 0, which :mod:`mbs.uncertain` enforces
    for uncertain damping): :class:`EnergyShellHook` with M(q) and P(q) of its numeric
    model, ``hmax`` the interval bound of ``H = K + P`` over the initial box and, with
    uncertain parameters, over the parameter box too (sound because
    ``dH/dt = -qd^T D qd <= 0`` without inputs, eq. (7), for every parameter value).

    A bare System with an energy: its ``H`` as a :class:`verified.consistency.conservation.NonIncreasing`
    invariant (the rate its ``energy_rate`` declares, proven, else ``grad H . f``, checked
    ``<= 0`` on every step) or, with ``energy_rate="zero"``, a proven
    :class:`~verified.consistency.conservation.Conserved` one (:class:`verified.consistency.conservation.InvariantHook`)."""
    if loop is not None:
        raise ValueError("energy_shell=True needs a system without control inputs (a controller can add energy)")
    if masses is None:
        if system is None or system.energy is None:
            raise ValueError("energy_shell=True on a bare System needs its energy (System(energy=H)); "
                             "without one it has no shell")
        from verified.consistency.conservation import Conserved, NonIncreasing, invariant_hook
        rate = system.energy_rate
        if isinstance(rate, str) and rate == "zero":
            decl = Conserved(system.energy, name="H")
        else:
            decl = NonIncreasing(system.energy, rate=rate if isinstance(rate, Graph) else None, name="H")
        return invariant_hook([decl], system.rhs)
    if masses.cparams is not None and masses.cparams.n:
        cp = masses.cparams
        if system is not None and tuple(system.rhs.param_names) != tuple(cp.names):
            raise ValueError(f"energy_shell=True: the ODE's parameters {tuple(system.rhs.param_names)} are not the "
                             f"chain's {tuple(cp.names)} in order; the shell cannot pair them")
        P = Interval(np.asarray(cp.lo, float), np.asarray(cp.hi, float))
        if params is not None and isinstance(params, Interval) and params.ndim == 2 and box.ndim == 2 \
                and params.shape[0] == box.shape[0]:
            P = params  # (per initial box, after param_subdivision)
        hmax = max_energy(cp.energy_graph(), box, P)
        return EnergyShellHook(EnergyShell(cp.mass_matrix_graph(), cp.potential_graph()), hmax)
    num = masses.num if masses.cparams is None else masses.cparams.float_model()
    return EnergyShellHook(*energy_shell_of(num, box))


def energy_shell_of(num, box: Interval):
    """``(EnergyShell, hmax)`` of a passive chain's numeric model ``num``
    (:class:`mbs.numeric.NumericModel`) over the initial ``box`` ((n,) or (B, n)):
    ``M(q)``, ``P(q)`` and ``hmax`` the interval bound of the model's own ``H = K + P``.
    ``hmax`` must come from the same ``P`` as the shell: an energy whose potential has
    another zero (eq. (19) against the chain's pivot zero) shifts the shell by that much."""
    hmax = max_energy(num.energy_graph(), box)
    return EnergyShell(num.mass_matrix_graph(), num.potential_graph()), hmax


class CtrlC:
    """A solver hook that turns Ctrl-C into a clean stop after the current step.

    While :func:`simulate` integrates (in the main thread, with Python's default SIGINT
    handler in place) the first Ctrl-C only sets a flag; the hook then stops the run
    after the step in progress (``status="interrupted"``, everything verified so far
    kept). A ``KeyboardInterrupt`` raised inside a compiled kernel would surface as a
    numba ``SystemError`` and lose the run. A second Ctrl-C raises ``KeyboardInterrupt``
    at once (the solver still returns what it recorded when it can)."""

    def __init__(self):
        self.requested = False
        self._previous = None

    def __enter__(self):
        if threading.current_thread() is threading.main_thread() \
                and signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            self._previous = signal.signal(signal.SIGINT, self._handle)
        return self

    def __exit__(self, *exc):
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
            self._previous = None
        return False

    def _handle(self, signum, frame):
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True
        print("\nCtrl-C: stopping after the current step (press again to abort at once)", file=sys.stderr)

    # the hook protocol of verified.driver.hooks
    def before_run(self, setup):
        return None

    def after_step(self, step, sets, run):
        if self.requested:
            run.stop(f"interrupted (Ctrl-C) at t = {float(step.t):g}", "interrupted")
        return None

    def after_run(self, solution):
        return None

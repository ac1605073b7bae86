"""Run a model in one of the paper's three simulation modes (sec. 5.2).

- mode ``"i"``: the numeric model (recursive algorithms, SMARTMOBILE-style), no
  consistency test;
- mode ``"ii"``: the numeric model with the energy constraints: ``H_H`` from its
  kinetic and potential energy functions, ``dH/dt`` by forward-mode automatic
  differentiation of ``H`` along the ODE (the paper used FADBAD++);
- mode ``"iii"``: the symbolic model (sympy) with symbolic constraints, ``dH/dt``
  left unsimplified as in the paper (``energy_rate="unsimplified"``) or simplified
  (``"simplified"``: ``qd^T tau``, identically 0 for a conservative system). The
  values of ``energy_rate`` in every layer: :mod:`verified.consistency.energy_rate`.

Example::

    from mbs.simulate import simulate, compare_modes
    from models import double_pendulum as dp
    from verified.arith.interval import Interval
    sol = simulate("double_pendulum_paper", Interval(*dp.initial_box()), 1.0, mode="iii")
    sol.hull[-1], sol.consistency.tests, sol.stats["pruned_boxes"]

Models: a name of :mod:`models.registry`: a chain model (``FACTORIES``) or a System
factory (``SYSTEMS``: ``"pendulum_paper"`` and ``"double_pendulum_paper"``, the numeric
model of a DH chain in modes i/ii and the paper's hand-written eqs. (18)/(19) and
(22)/(24) in mode iii, :mod:`models.paper`); an :class:`mbs.Chain`; or an
:class:`mbs.system.System` (e.g. recovered from a bare ODE). This package names no
model: it asks :func:`mbs.robots.system_entry` and :func:`mbs.robots.load_model`.

The package, in the order of a run: :mod:`.options` (settings, output times, the
initial box), :mod:`.model` (the System of a model in a mode, the chain behind it, the
closed loop), :mod:`.params` (uncertain parameters), :mod:`.hooks` (the solver hooks
``simulate`` adds), then :func:`verified.solver.solve`, then :mod:`.mass_matrix` (the
M(q) > 0 proof, the one place that edits what ``solve`` returned) and :mod:`.results`
(the :class:`Simulation` and width comparisons).
"""
from __future__ import annotations

import numpy as np

from verified.solver import Solution, solve

from .. import progress as _progress
from ..modes import MODES, Mode, get_mode
from ..robots import PAPER_MODELS
from .hooks import CtrlC, energy_shell_of, energy_test, shell_hooks, stop_hooks
from .mass_matrix import (MassMatrixProof, _pivot_diagnosis, _prove_mass_matrix, check_initial,
                          pivots_proven)
from .model import chain_state_names, resolve, system_for
from .options import TEST_DEFAULTS, check_solver_kwargs, method_defaults, output_times
from .params import params_record, solver_params
from ..shell_continuation import carry_on
from .results import Simulation, WidthDeviations, as_simulation, width_deviations

__all__ = ["MODES", "Mode", "PAPER_MODELS", "simulate", "Simulation", "compare_modes", "system_for",
           "width_deviations", "WidthDeviations", "output_times", "pivots_proven",
           "chain_state_names"]
#: names importable from here as before the package, besides __all__ (TEST_DEFAULTS,
#: energy_shell_of; the tests' _prove_mass_matrix and _pivot_diagnosis)
_KEPT = (TEST_DEFAULTS, energy_shell_of, _prove_mass_matrix, _pivot_diagnosis)


def simulate(model, x0, t_end: float, *, mode: str | Mode = "ii", t0: float = 0.0, output_dt: float | None = None,
             params=None, method=None, subdivision=None,
             energy_rate: str = "unsimplified", test_interval: float | None = None, test_splits: int | None = None,
             split_strategy: str = "gradient", refine: str = "pruned", min_gain: float = 0.1,
             backward_depth: int = 0, contract: str = "step", prune: bool = True,
             constraints=(), progress=None, max_wall: float | None = None, control=None,
             param_subdivision: dict | None = None, energy_shell: bool | None = None,
             invariant_after: float | None = None, **solver_kwargs) -> Solution:
    """Verified enclosure of ``model`` from the initial box ``x0`` in simulation ``mode``.

    Parameters
    ----------
    model : str, mbs.Chain or mbs.system.System
    x0 : Interval (n,) or (B, n), or (lo, hi)
        Initial state box, ``x = (q, qd)`` in rad and rad/s (m, m/s for prismatic).
    t_end : float
        Final time (s).
    mode : "i", "ii" or "iii" (or a :class:`mbs.modes.Mode`)
    output_dt : float or None
        Output every ``output_dt`` seconds (at exactly ``k * output_dt``); default: ``t_end`` only.
    params : dict or None
        Uncertain parameters, each a number or ``[lo, hi]``. For a chain (a model name,
        a URDF/DH :class:`mbs.Chain`): the physical parameters of :mod:`mbs.uncertain`
        (``{"payload": {"link": "tool0", "mass": [0.9, 1.1], "com": [0, 0, 0.05]},
        "mass_scale": [0.95, 1.05], "mass": {body: [lo, hi]}, "damping": {joint: [lo, hi]}}``,
        kg, m, N m s/rad) and the chain's sympy symbols (DH tables, e.g. ``"l1"``); for
        the paper's models their parameters (``m1, m2, l1, l2, g`` / ``m, l, g``); for a
        :class:`System` its graph's parameters by name (or a sequence in their order).
        They enter the graphs as parameters (never constants); the verified solver
        carries those with width as constant states. With parameters, ``simulate``
        uses ``error_basis="auto"`` unless told otherwise. ``sol.params`` lists them.
    method : None (default: ``"auto"``), a name (``"lohner"``, ``"second_order"``,
        ``"composition"``, ``"auto"``) or a :mod:`verified.methods` object: how the sets
        are advanced (:func:`verified.solver.solve`). What ran is ``sol.method`` (for
        ``"auto"``: every attempt, also in ``sol.method_log``).
    subdivision : solver setting (see :func:`verified.solver.solve`)
    energy_rate : "unsimplified" or "simplified"
        Which of the symbolic model's ``dH/dt`` mode iii integrates (modes i and ii
        derive it; :mod:`verified.consistency.energy_rate`)
    test_interval, test_splits : longest time between energy tests (s) and parts per
        set at a test; defaults per mode in :data:`TEST_DEFAULTS` (the paper's)
    split_strategy : "gradient", "widest" or "grid" (see :class:`verified.consistency.energy_test.EnergyTest`)
    refine, min_gain : "pruned" (replace a set by its surviving parts only when that
        narrows its hull by ``min_gain``, default 0.1) or "always"
    backward_depth : backward consistency test depth (0 = off)
    contract : "step" (default), "test" or "off": where the energy relation ``H(x) = h``
        contracts the sets (modes ii, iii; :class:`verified.consistency.energy_test.EnergyTest`):
        after every step, only at the tests, or never
    prune : bool (default True): branch and prune at the tests (the paper's test); with
        ``False`` only the contraction narrows the sets
    constraints : further :class:`verified.consistency.energy_test.Constraint` objects (modes ii, iii)
    progress : None, bool or callable(t, t_end)
        Called after every step. ``None`` (default): a tqdm progress bar over simulated
        time in an interactive terminal or notebook (after 2 s), nothing otherwise;
        ``False``: none; ``True``: always.
    max_wall : float or None
        Stop the integration after this many seconds of wall-clock time
        (:class:`verified.driver.hooks.StopAfterWall`): ``status="stopped"`` with everything
        verified so far. Ctrl-C during the integration likewise returns the partial
        solution with ``status="interrupted"`` (after the step in progress; a second
        Ctrl-C aborts at once).
    control : None, a controller of :mod:`mbs.control` (``PD``, ``ComputedTorque``,
        ``Disturbance``, ``FunctionController``), a list of them (torques add up) or a
        scene's ``[control]`` table as a dict. The torque enters the equations of
        motion (eq. (2)); mode ii integrates ``dH/dt = qd^T tau - qd^T D qd`` (eq. (7)).
        A time-dependent reference appends the state ``t`` (``t' = 1``, started at the
        point ``t0``) after ``(q, qd)``: ``sol.state_names`` ends with ``"t"``. ``x0``
        is still the ``(q, qd)`` box. A PD controller without ``q_ref`` holds the
        centre of the initial q box.
    param_subdivision : {parameter name: pieces} or None
        Split uncertain parameters (e.g. ``{"payload.mass": 4}``) into equal pieces,
        one initial set per piece (a single initial box, no ``subdivision``).
        Narrower pieces allow longer steps and reach further (docs/lab/code_notes.md).
    invariant_after : float or None
        With a PD controller holding a pose: from this time (s) on, end the integration
        as soon as every set lies in a verified invariant box of the closed-loop energy
        (:mod:`mbs.lyapunov`, :class:`verified.consistency.invariant.InvariantHook`); every later
        output time then gets those boxes, valid for all later times
        (``stats["invariant_from"]``). While a set's box cannot be verified the
        integration goes on. Runs in one process (the default ``workers=None`` becomes
        ``workers=1`` here; other ``workers``, ``client``, ``chunks`` are refused).
    energy_shell : None (default), True or False
        ``True``: hold the enclosure inside the energy shell ``H(q, qd) <= hmax``
        (:class:`verified.consistency.energy_shell.EnergyShellHook`; ``hmax`` the interval bound of
        ``H`` over the initial box): a set the shell cuts by more than 10 % in some
        component is replaced by its contracted box. Sound for a chain without control
        inputs (its energy never rises: damping only takes it away), also with uncertain
        parameters (``hmax`` then bounds ``H`` over the parameter box as well, and each
        set is held with its own parameter columns). On a bare :class:`System` its
        ``energy`` is the shell: declared ``energy_rate="zero"`` (proven) it is conserved,
        else non-increasing, checked on every step (the declared rate graph, proven equal to
        ``grad H . f``, or ``grad H . f`` itself; :mod:`verified.consistency.conservation`). A
        controller, or a bare System without energy, is a ValueError. It keeps wide enclosures (the pendulum over
        the top) from breaking down (docs/lab/code_notes.md).
        Where a passive chain's sets still break down (a chaotic free fall), the run is
        carried on to ``t_end`` with boxes from the energy bound alone
        (:mod:`mbs.shell_continuation`; revolute joints, no uncertain parameters): every
        joint rate bounded by the energy, the positions grown by it; crude but sound.
        ``status`` is then "completed", while ``reason``, ``method`` and
        ``stats["shell_from"]`` say where the sets gave up.
        ``None`` (default): no shell while the sets hold (on enclosures that stay narrow
        it only costs time), and that carrying on after a break-down wherever it applies
        (a chain without controller or uncertain parameters, revolute joints, every
        piece broken down, and none of the limits ``max_steps``, ``max_width``,
        ``h_min`` passed); elsewhere the break-down is returned as it is. ``False``:
        neither.
    solver_kwargs : passed on to :func:`verified.solver.solve` (h_max, max_boxes, hooks, ...);
        an unknown keyword raises ``TypeError`` naming ``simulate()``. ``workers``: as in
        ``solve``, default None: every core of this machine when worthwhile (>= 128
        initial boxes after ``subdivision`` and dask.distributed installed; else, and
        without Dask silently, one batch in this process); ``workers=1``: one batch in
        this process

    Returns
    -------
    Simulation: a verified.solver.Solution with ``mode``, ``params`` ({name: (lo, hi)}) and
    ``control``, ``state_names`` set, and ``consistency`` (RA(t), H_H, H_V, tests) in modes ii and iii. ``status``:
    "completed", "breakdown", "stopped" (``max_wall``) or "interrupted" (Ctrl-C).
    """
    check_solver_kwargs(solver_kwargs, simulate)
    t0, t_end = float(t0), float(t_end)
    if not (np.isfinite(t_end) and t_end > t0):
        raise ValueError(f"t_end must be a finite time after t0 = {t0}, got {t_end!r}")
    run = resolve(model, x0, mode, params=params, control=control, energy_rate=energy_rate, t0=t0, t_end=t_end,
                  subdivision=subdivision)
    if run.masses is not None:
        check_initial(run.masses, run.box)
    mode = get_mode(mode)  # validated by resolve
    test = energy_test(run.system, mode, constraints, test_interval=test_interval, test_splits=test_splits,
                       split_strategy=split_strategy, refine=refine, min_gain=min_gain,
                       backward_depth=backward_depth, max_boxes=solver_kwargs.get("max_boxes", 4096),
                       contract=contract, prune=prune)
    box, ode_params = solver_params(run, params, param_subdivision)
    method_defaults(method, solver_kwargs, controlled=run.loop is not None, with_params=ode_params is not None)
    hooks = list(solver_kwargs.get("hooks", ())) + shell_hooks(energy_shell, run, model, box, ode_params)
    t_eval = output_times(t0, t_end, output_dt)
    hooks += stop_hooks(solver_kwargs, invariant_after, max_wall, run.loop, t0, t_end, t_eval, run.system.rhs)
    ctrl_c = CtrlC()
    # (the M(q) > 0 proof last, on the whole run: it may cut it back)
    proof = [MassMatrixProof(run.masses)] if run.masses is not None else []
    solver_kwargs["hooks"] = hooks + [ctrl_c] + proof
    sol = _integrate(run.system.rhs, box, (t0, t_end), t_eval, ode_params, method, run.subdivision, test,
                     progress, mode, ctrl_c, solver_kwargs)
    # (by default not where the caller's own limits ended the run: max_steps, max_width, h_min)
    limited = any(solver_kwargs.get(k) is not None for k in ("max_steps", "max_width", "h_min"))
    if energy_shell or (energy_shell is None and run.loop is None and not limited):
        # a passive chain's break-down carried on by the shell's boxes (mbs.shell_continuation);
        # by default only where it applies, and silently not elsewhere
        sol = carry_on(sol, run.masses, hooks, box, t_eval, t_end, quiet=energy_shell is None)
    return as_simulation(sol, mode.name, run, params_record(run.system, ode_params))


def _integrate(rhs, box, t_span, t_eval, params, method, subdivision, test, progress, mode, ctrl_c, solver_kwargs):
    """``solve`` (this module's name, which a test may wrap) with a progress bar
    (``progress`` None or a bool: a tqdm bar over simulated time where enabled) and
    Ctrl-C turned into a clean stop after the step in progress."""
    bar = None
    if progress is None or isinstance(progress, bool):
        bar = _progress.Progress(t_span[1], f"mode {mode}", enabled=None if progress is None else progress)
        progress = bar if bar.enabled else None
    try:
        with ctrl_c:
            return solve(rhs, box, t_span, t_eval=t_eval, params=params, method=method, subdivision=subdivision,
                         consistency=test, progress=progress, **solver_kwargs)
    finally:
        if bar is not None:
            bar.close()


def compare_modes(model, x0, t_end: float, modes=MODES, *, output_dt: float | None = None, **kwargs) -> dict:
    """Run ``model`` in each of ``modes`` with the same settings: ``{mode: Solution}``.

    ``output_dt`` defaults to ``(t_end - t0) / 50``, so that :func:`width_deviations`
    compares the modes at 50 output times, not only at ``t_end``."""
    if output_dt is None:
        output_dt = (float(t_end) - float(kwargs.get("t0", 0.0))) / 50
    return {m: simulate(model, x0, t_end, mode=m, output_dt=output_dt, **kwargs) for m in modes}

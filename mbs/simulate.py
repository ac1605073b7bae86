"""Run a model in one of the paper's three simulation modes (sec. 5.2).

- mode ``"i"``: the numeric model (recursive algorithms, SMARTMOBILE-style), no
  consistency test;
- mode ``"ii"``: the numeric model with the energy constraints: ``H_H`` from its
  kinetic and potential energy functions, ``dH/dt`` by forward-mode automatic
  differentiation of ``H`` along the ODE (the paper used FADBAD++);
- mode ``"iii"``: the symbolic model (sympy) with symbolic constraints, ``dH/dt``
  left unsimplified as in the paper (``energy_rate="unsimplified"``) or simplified
  (``"simplified"``: ``qd^T tau``, identically 0 for a conservative system). The
  values of ``energy_rate`` in every layer: :mod:`verified.energy_rate`.

Example::

    from mbs.simulate import simulate, compare_modes
    from models import double_pendulum as dp
    from verified.interval import Interval
    sol = simulate("double_pendulum_paper", Interval(*dp.initial_box()), 1.0, mode="iii")
    sol.hull[-1], sol.consistency.tests, sol.stats["pruned_boxes"]

Models: a name of :mod:`models.registry`: a chain model (``FACTORIES``) or a System
factory (``SYSTEMS``: ``"pendulum_paper"`` and ``"double_pendulum_paper"``, the numeric
model of a DH chain in modes i/ii and the paper's hand-written eqs. (18)/(19) and
(22)/(24) in mode iii, :mod:`models.paper`); an :class:`mbs.Chain`; or an
:class:`mbs.system.System` (e.g. recovered from a bare ODE). This module names no
model: it asks :func:`mbs.robots.system_entry` and :func:`mbs.robots.load_model`.
"""
from __future__ import annotations

import difflib
import inspect
import itertools
import signal
import sys
import threading
from dataclasses import dataclass, field, fields

import numpy as np

import verified.solver
from verified.affine_taylor import affine_range
from verified.consistency import STRATEGIES, EnergyTest
from verified.contractor import EnergyShell
from verified.energy_rate import MODEL_RATES, check_energy_rate
from verified.energy_shell import EnergyShellHook, max_energy
from verified.graph import Graph
from verified.hooks import StopAfterWall
from verified.interval import Interval, _as_interval
from verified.invariant import InvariantHook
from verified.methods import METHOD_FIELDS
from verified.solver import Solution, solve

from . import progress as _progress
from .chain import Chain
from .control import closed_loop
from .errors import ModelError
from .frames import attach_frames
from .lyapunov import pd_hold_lyapunov
from .modes import ALL_MODES, MODES, Mode, get_mode
from .numeric import PIVOT_TOL
from .robots import PAPER_MODELS, load_model, system_entry
from .system import System
from .uncertain import ChainParameters, parse_value

__all__ = ["MODES", "Mode", "PAPER_MODELS", "simulate", "Simulation", "compare_modes", "system_for",
           "width_deviations", "WidthDeviations", "output_times", "pivots_proven",
           "chain_state_names"]


@dataclass(repr=False)
class Simulation(Solution):
    """What :func:`simulate` returns: the solver's :class:`verified.solver.Solution`
    (every field and property of it) plus what only the modeling side knows.

    Attributes (beyond ``Solution``'s)
    ----------------------------------
    mode : str
        The simulation mode, "i", "ii" or "iii" (paper sec. 5.2; :mod:`mbs.modes`).
    params : dict
        The uncertain physical parameters the run covered, ``{name: (lo, hi)}``.
    control : object or None
        The closed loop (:mod:`mbs.control`) when a controller drove the joints.
    frame : mbs.frames.Frames or None
        Enclosures of the chain's frames over the run (``sol.frame("tool0")``), for runs
        of a chain (:func:`mbs.frames.attach_frames`); None for a bare System.
    """

    mode: str = ""
    params: dict = field(default_factory=dict)
    control: object = None
    frame: object = None

    @classmethod
    def of(cls, sol: Solution, **extra) -> "Simulation":
        """``sol``'s fields (shared, not copied) with ``extra`` set."""
        return cls(**{f.name: getattr(sol, f.name) for f in fields(Solution)}, **extra)

#: consistency-test settings per mode (the paper's: 0.1 s / 10 parts in mode (ii),
#: 0.01 s / 50 parts in mode (iii)); the fields of :mod:`mbs.modes`
TEST_DEFAULTS = {m.name: dict(test_interval=m.test_interval, test_splits=m.test_splits)
                 for m in ALL_MODES if m.energy_test}


def _chain_system(chain, mode: Mode, energy_rate: str, name: str | None = None, cparams=None) -> System:
    name = name or getattr(chain, "name", "chain")
    if cparams is not None:
        if mode.symbolic:
            raise ValueError(f"{name}: uncertain parameters of a chain ({', '.join(cparams.names)}) are "
                             "supported in modes i and ii (the symbolic model of mode iii takes none)")
        rhs = cparams.rhs_graph()
        if not mode.energy_test:
            return System(name=name, rhs=rhs, params=cparams.as_dict(),
                          description="numeric model (crba/rnea) with parameters, no test")
        return System(name=name, rhs=rhs, energy=cparams.energy_graph(), energy_rate="derive", params=cparams.as_dict(),
                      description="numeric model with parameters; dH/dt by forward-mode AD of H along the ODE")
    if not mode.symbolic:
        num = chain.numeric()
        rhs = num.rhs_graph()
        if not mode.energy_test:
            return System(name=name, rhs=rhs, description="numeric model (crba/rnea), no test")
        return System(name=name, rhs=rhs, energy=num.energy_graph(), energy_rate="derive",
                      description="numeric model; dH/dt by forward-mode AD of H along the ODE")
    sym = chain.symbolic()
    rhs = sym.rhs_graph()
    energy = sym.energy_graph()
    rate = sym.energy_rate_graph(simplified=(energy_rate == "simplified"))
    return System(name=name, rhs=rhs, energy=energy, energy_rate=rate,
                  description=f"symbolic model (sympy); dH/dt {energy_rate}")


class _MassMatrix:
    """What the M(q) > 0 checks of a chain need: a float model (centre checks, messages),
    the pivot graph (inputs q, then the parameters if any) and the parameter box."""

    def __init__(self, chain, cparams=None):
        self.chain = chain
        self.cparams = cparams
        if cparams is None:
            self.num = chain.numeric()
            self.graph = self.num.pivot_graph()
            self.pbox = None
        else:
            self.num = cparams.float_model()
            self.graph = cparams.pivot_graph()
            self.pbox = (cparams.lo, cparams.hi) if cparams.n else None
        self.n = chain.n


def system_for(model, mode: str | Mode = "ii", *, energy_rate: str = "unsimplified", params=None, control=None,
               q_init=None) -> System:
    """The :class:`System` that ``mode`` integrates for ``model`` (see module docstring);
    ``params`` and ``control`` as for :func:`simulate` (``q_init``: the pose a PD
    controller without ``q_ref`` holds)."""
    if control is not None:
        return _controlled_system(model, mode, params, control, q_init)[0]
    return _system_and_chain(model, mode, energy_rate, params)[0]


def chain_state_names(model, params=None) -> tuple[str, ...]:
    """The states ``q1..qn, qd1..qdn`` of a chain model (a model name, a URDF or DH
    :class:`mbs.Chain`) without building its System, ``params`` checked against the chain
    (:class:`mbs.uncertain.ParameterError`): the states :func:`system_for` integrates for
    it, and under ``control`` those before the time state ``"t"``. A bare System raises
    ModelError, as under control."""
    n = _model_chain(model, params)[0].n
    return tuple(f"q{i + 1}" for i in range(n)) + tuple(f"qd{i + 1}" for i in range(n))


def _model_chain(model, params):
    """(chain, ChainParameters or None, name) of a chain model (for controllers)."""
    if isinstance(model, System):
        raise ModelError(f"{model.name}: controllers need a chain model (a model name, URDF or mbs.Chain), "
                         "not a bare System; write the torque into the System's rhs instead")
    if isinstance(model, str):
        name = model
        entry = system_entry(model)
        chain = entry.chain(params) if entry is not None else load_model(model)
    elif isinstance(model, Chain):
        chain, name = model, None
    else:
        raise TypeError(f"model must be a model name, an mbs.Chain or an mbs.system.System, "
                        f"got {type(model).__name__}")
    cp = None
    if params is not None or chain.free_symbols:
        _require_dict(params if params is not None else {}, name or chain.name, chain)
        cp = ChainParameters(chain, params or {}, model_name=name)
    return chain, cp, name or chain.name


def _controlled_system(model, mode, params, control, q_init):
    """(System, _MassMatrix, ClosedLoop) of ``model`` under ``control`` (modes i, ii)."""
    mode = get_mode(mode)
    if mode.symbolic:
        raise ValueError("controllers are supported in modes i and ii (the numeric model); "
                         "mode iii's symbolic models take no torque inputs")
    chain, cp, name = _model_chain(model, params)
    loop = closed_loop(chain, control, cp, q_init=q_init, model_name=name)
    rhs = loop.rhs_graph()
    pdict = {k: (float(a), float(b)) for k, a, b in zip(loop.param_names, loop.lo, loop.hi)}
    what = ", ".join(c.name for c in loop.controllers)
    if not mode.energy_test:
        system = System(name=name, rhs=rhs, params=pdict, description=f"numeric model under control ({what}), no test")
    else:
        system = System(name=name, rhs=rhs, energy=loop.energy_graph(), energy_rate=loop.energy_rate_graph(),
                        params=pdict, description=f"numeric model under control ({what}); "
                                                  "dH/dt = qd^T tau - qd^T D qd (eq. 7)")
    return system, _MassMatrix(chain, cp), loop


def _system_and_chain(model, mode: str | Mode, energy_rate: str, params=None):
    """(System, _MassMatrix of the chain behind it or None) -- the chain for the
    mass-matrix checks."""
    mode = get_mode(mode)
    check_energy_rate(energy_rate, MODEL_RATES, "simulate")
    if isinstance(model, System):
        if not mode.energy_test:
            model = System(name=model.name, rhs=model.rhs, params=model.params, description=model.description)
        elif not model.has_energy:
            raise ModelError(f"{model.name}: mode {mode} needs an energy graph (System.energy)")
        return model, None
    if isinstance(model, str):
        entry = system_entry(model)
        if entry is not None:
            # a registry System factory (the paper's models): its chain in modes i and
            # ii, its own System (hand-written, the same M) where it has one
            cp = None
            if params is not None:
                _require_dict(params, model, names=getattr(entry, "param_names", ()))
            if params:
                chain = entry.chain(params)
                cp = ChainParameters(chain, params, model_name=model)
            else:
                chain = entry.chain()
            system = entry.system(mode, energy_rate, cp)
            if system is None:
                system = _chain_system(chain, mode, energy_rate, name=model, cparams=cp)
            return system, _MassMatrix(chain, cp)
        chain = load_model(model)  # registry names, aliases (panda), example-robot-data:NAME, URDF paths
        name = model
    elif isinstance(model, Chain):
        chain = model
        name = None
    else:
        raise TypeError(f"model must be a model name, an mbs.Chain or an mbs.system.System, "
                        f"got {type(model).__name__}")
    if params is not None or chain.free_symbols:
        _require_dict(params if params is not None else {}, name or chain.name, chain)
        cp = ChainParameters(chain, params or {}, model_name=name)
        return _chain_system(chain, mode, energy_rate, name=name, cparams=cp), _MassMatrix(chain, cp)
    return _chain_system(chain, mode, energy_rate, name=name), _MassMatrix(chain)


def _require_dict(params, name, chain=None, names=()):
    if not isinstance(params, dict):
        syms = list(names) or (sorted(str(x) for x in chain.free_symbols) if chain is not None else [])
        own = f", or the model's own parameters by name: {{{', '.join(repr(x) + ': [lo, hi]' for x in syms)}}}" \
            if syms else ""
        raise ValueError(f"params for the chain model {name!r} must be a dict such as "
                         "{'payload': {'link': ..., 'mass': [lo, hi]}, 'mass_scale': [lo, hi], "
                         f"'damping': {{joint: [lo, hi]}}}}{own} (see mbs.uncertain), got {type(params).__name__}")


def _system_params(system: System, params):
    """The ODE parameters for solve: ``params`` (a dict by name, or a sequence in the
    order of ``system.rhs.param_names``), default ``system.params``."""
    names = system.rhs.param_names
    if params is None:
        if not names:
            return None
        params = system.params
        if not params:
            raise ValueError(f"{system.name}: the ODE has parameters {', '.join(names)}: pass params")
    if isinstance(params, dict):
        unknown = [k for k in params if k not in names]
        if unknown:
            raise ValueError(f"params: unknown parameter(s) {', '.join(map(repr, unknown))} for {system.name!r}"
                             + (f"; its parameters: {', '.join(names)}" if names else "; it has no parameters"))
        missing = [k for k in names if k not in params]
        if missing:
            raise ValueError(f"params: missing value for {', '.join(map(repr, missing))} ({system.name!r} "
                             f"has parameters {', '.join(names)})")
        pairs = [parse_value(params[k], f"params {k}") for k in names]
        return Interval(np.array([a for a, _ in pairs]), np.array([b for _, b in pairs]))
    return params


def output_times(t0: float, t_end: float, output_dt: float | None) -> np.ndarray:
    """Output times ``t0 + k * output_dt`` (each computed directly, never accumulated),
    plus ``t_end`` when it is not a multiple."""
    if output_dt is None:
        return np.array([t_end])
    if not (np.isfinite(output_dt) and output_dt > 0):
        raise ValueError(f"output_dt must be a positive number of seconds, got {output_dt!r}")
    k = np.arange(1, int(np.floor((t_end - t0) / output_dt * (1 + 1e-12))) + 1)
    ts = t0 + k * output_dt
    ts = ts[ts <= t_end]
    if ts.size == 0 or ts[-1] < t_end * (1 - 1e-12):
        ts = np.append(ts, t_end)
    return ts


def _initial_box(x0, n: int, name: str) -> Interval:
    if isinstance(x0, tuple) and len(x0) == 2 and not isinstance(x0[0], Interval):
        lo, hi = (np.asarray(v, dtype=float) for v in x0)
        x0 = Interval(lo, hi)
    try:
        box = _as_interval(x0)
    except Exception as e:
        raise ValueError(f"x0 must be an Interval or a (lo, hi) pair of arrays: {e}") from None
    if box.shape[-1] != n:
        raise ValueError(f"{name} has {n} states, but the initial box has shape {box.shape}")
    return box


def simulate(model, x0, t_end: float, *, mode: str | Mode = "ii", t0: float = 0.0, output_dt: float | None = None,
             params=None, method=None, subdivision=None,
             energy_rate: str = "unsimplified", test_interval: float | None = None, test_splits: int | None = None,
             split_strategy: str = "gradient", refine: str = "pruned", min_gain: float = 0.1,
             backward_depth: int = 0, contract: str = "step", prune: bool = True,
             constraints=(), progress=None, max_wall: float | None = None, control=None,
             param_subdivision: dict | None = None, energy_shell: bool = False,
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
        derive it; :mod:`verified.energy_rate`)
    test_interval, test_splits : longest time between energy tests (s) and parts per
        set at a test; defaults per mode in :data:`TEST_DEFAULTS` (the paper's)
    split_strategy : "gradient", "widest" or "grid" (see :class:`verified.consistency.EnergyTest`)
    refine, min_gain : "pruned" (replace a set by its surviving parts only when that
        narrows its hull by ``min_gain``, default 0.1) or "always"
    backward_depth : backward consistency test depth (0 = off)
    contract : "step" (default), "test" or "off": where the energy relation ``H(x) = h``
        contracts the sets (modes ii, iii; :class:`verified.consistency.EnergyTest`):
        after every step, only at the tests, or never
    prune : bool (default True): branch and prune at the tests (the paper's test); with
        ``False`` only the contraction narrows the sets
    constraints : further :class:`verified.consistency.Constraint` objects (modes ii, iii)
    progress : None, bool or callable(t, t_end)
        Called after every step. ``None`` (default): a tqdm progress bar over simulated
        time in an interactive terminal or notebook (after 2 s), nothing otherwise;
        ``False``: none; ``True``: always.
    max_wall : float or None
        Stop the integration after this many seconds of wall-clock time
        (:class:`verified.hooks.StopAfterWall`): ``status="stopped"`` with everything
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
        (:mod:`mbs.lyapunov`, :class:`verified.invariant.InvariantHook`); every later
        output time then gets those boxes, valid for all later times
        (``stats["invariant_from"]``). While a set's box cannot be verified the
        integration goes on. Runs in one process (the default ``workers=None`` becomes
        ``workers=1`` here; other ``workers``, ``client``, ``chunks`` are refused).
    energy_shell : bool
        Hold the enclosure inside the energy shell ``H(q, qd) <= hmax``
        (:class:`verified.energy_shell.EnergyShellHook`; ``hmax`` the interval bound of
        ``H`` over the initial box): a set the shell cuts by more than 10 % in some
        component is replaced by its contracted box. Sound for a chain without control
        inputs (its energy never rises: damping only takes it away), also with uncertain
        parameters (``hmax`` then bounds ``H`` over the parameter box as well, and each
        set is held with its own parameter columns). On a bare :class:`System` its
        ``energy`` is the shell: declared ``energy_rate="zero"`` (proven) it is conserved,
        else non-increasing, checked on every step (the declared rate graph, proven equal to
        ``grad H . f``, or ``grad H . f`` itself; :mod:`verified.conservation`). A
        controller, or a bare System without energy, is a ValueError. It keeps wide enclosures (the pendulum over
        the top) from breaking down (docs/lab/code_notes.md). Default False: on enclosures
        that stay narrow it only costs time.
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
    _check_solver_kwargs(solver_kwargs)
    t0, t_end = float(t0), float(t_end)
    if not (np.isfinite(t_end) and t_end > t0):
        raise ValueError(f"t_end must be a finite time after t0 = {t0}, got {t_end!r}")
    loop = None
    if control is not None:
        n2 = _model_chain(model, params)[0].n * 2 if not isinstance(model, System) else model.n
        box = _initial_box(x0, n2, str(model))
        q_init = np.asarray(box.hull(axis=0).mid() if box.ndim > 1 else box.mid(), float)[:n2 // 2]
        system, masses, loop = _controlled_system(model, mode, params, control, q_init)
        if loop.t_end_max is not None and t_end > loop.t_end_max * (1 + 1e-12):
            raise ValueError(f"t_end = {t_end:g} s is past the end of the reference trajectory "
                             f"({loop.t_end_max:g} s); the quintic is not continued past it")
        if loop.timed:  # the time as the last state, a point: t' = 1
            lo, hi = np.asarray(box.lo, float), np.asarray(box.hi, float)
            tcol = np.full(lo.shape[:-1] + (1,), t0)
            box = Interval(np.concatenate([lo, tcol], axis=-1), np.concatenate([hi, tcol], axis=-1))
            if subdivision is not None and not isinstance(subdivision, (int, np.integer)):
                subdivision = list(subdivision) + [1] * (system.n - len(list(subdivision)))
        params = system.params
        if "arithmetic" not in solver_kwargs and _legacy_method(method, solver_kwargs):
            # a controller doubles the graph's depth; interval arithmetic breaks down early
            # where affine completes (docs/lab/code_notes.md)
            solver_kwargs["arithmetic"] = "affine"
    else:
        system, masses = _system_and_chain(model, mode, energy_rate, params)
        box = _initial_box(x0, system.n, system.name)
    if masses is not None:
        _check_initial_mass_matrix(masses, box)
    if split_strategy not in STRATEGIES:
        raise ValueError(f"split_strategy must be one of {STRATEGIES}, got {split_strategy!r}")
    mode = get_mode(mode)  # validated above (_system_and_chain, _controlled_system)
    test = None
    if mode.energy_test:
        test = EnergyTest(system.energy, system.energy_rate, constraints,
                          test_interval=mode.test_interval if test_interval is None else test_interval,
                          test_splits=mode.test_splits if test_splits is None else test_splits,
                          split_strategy=split_strategy, refine=refine, min_gain=min_gain, backward_depth=backward_depth,
                          max_boxes=solver_kwargs.get("max_boxes", 4096), contract=contract, prune=prune)
    elif constraints:
        raise ValueError("mode i runs without consistency tests; use mode ii or iii for constraints")
    ode_params = _system_params(system, None if ((masses is not None and system.params) or loop is not None)
                                else params)
    if param_subdivision:
        box, ode_params = _split_params(box, ode_params, system, param_subdivision, subdivision)
    if "error_basis" not in solver_kwargs and ode_params is not None and _legacy_method(method, solver_kwargs):
        # with parameters the "qr" error basis breaks down early, "auto" does not
        # (docs/lab/code_notes.md)
        solver_kwargs["error_basis"] = "auto"
    if not isinstance(energy_shell, (bool, np.bool_)):
        raise ValueError(f"energy_shell must be True or False, got {energy_shell!r}")
    if energy_shell:
        solver_kwargs["hooks"] = list(solver_kwargs.get("hooks", ())) + [
            _energy_shell_hook(masses, loop, box, model if isinstance(model, System) else system, ode_params)]
    t_eval = output_times(t0, t_end, output_dt)
    if invariant_after is not None:
        if solver_kwargs.get("client") is None and solver_kwargs.get("chunks") is None and (
                solver_kwargs.get("workers") is None or isinstance(solver_kwargs["workers"], str)
                and solver_kwargs["workers"] == "auto"):
            solver_kwargs["workers"] = 1  # "every core when worthwhile" (the default): here it is not
        if solver_kwargs.get("workers") != 1 or any(solver_kwargs.get(k) is not None for k in ("client", "chunks")):
            raise ValueError("invariant_after runs in one process (no workers, client or chunks): the "
                             "invariant is proven for every set at once")
        solver_kwargs["hooks"] = list(solver_kwargs.get("hooks", ())) + [
            _invariant_hook(loop, invariant_after, t0, t_end, t_eval, system.rhs)]
    if max_wall is not None:
        if isinstance(max_wall, bool) or not isinstance(max_wall, (int, float)) or not max_wall > 0 \
                or not np.isfinite(max_wall):
            raise ValueError(f"max_wall must be a positive number of seconds, got {max_wall!r}")
        solver_kwargs["hooks"] = list(solver_kwargs.get("hooks", ())) + [StopAfterWall(max_wall)]
    ctrl_c = _CtrlC()
    solver_kwargs["hooks"] = list(solver_kwargs.get("hooks", ())) + [ctrl_c]
    bar = None
    if progress is None or isinstance(progress, bool):
        bar = _progress.Progress(t_end, f"mode {mode}", enabled=None if progress is None else progress)
        progress = bar if bar.enabled else None
    try:
        with ctrl_c:
            sol = solve(system.rhs, box, (t0, t_end), t_eval=t_eval, params=ode_params, method=method,
                        subdivision=subdivision, consistency=test, progress=progress, **solver_kwargs)
    finally:
        if bar is not None:
            bar.close()
    if masses is not None:
        summary = sol.pieces_summary()
        _prove_mass_matrix(masses, sol)
        _clip_failed_pieces(sol, summary)
        _prove_surviving(masses, sol)
    record = _params_record(system, ode_params)
    sol = Simulation.of(sol, mode=mode.name, params=record, control=loop)
    sol.state_names = system.state_names
    if sol.surviving is not None:  # (the pieces that went on after others broke down; no frames)
        sol.surviving = Simulation.of(sol.surviving, mode=mode.name, params=record, control=loop)
        sol.surviving.state_names = system.state_names
    if masses is not None:
        attach_frames(sol, masses.chain, loop.cparams if loop is not None else getattr(masses, "cparams", None))
    return sol


def _clip_failed_pieces(sol: Solution, summary: str):
    """After the M(q) > 0 proof (which may cut ``sol`` back): the pieces that broke down
    are verified up to its ``t_reached`` at most (which of them the proof failed on is
    not known here); without a surviving part the others share the run's outcome (the
    pieces that went on are proven on their own, ``sol.surviving``)."""
    T = float(sol.t_reached)
    changed = False
    for p in sol.piece_results or ():
        if p.failed and p.t_reached > T:
            p.t_reached, changed = T, True
        elif not p.failed and sol.surviving is None:
            p.status, p.t_reached, p.reason = sol.status, T, sol.reason
    after = sol.pieces_summary()
    if changed and summary and after and summary in sol.reason:
        sol.reason = sol.reason.replace(summary, after, 1)


def _prove_surviving(masses, sol: Solution):
    """M(q) > 0 on the enclosures of the pieces that went on after others broke down
    (``sol.surviving``, :func:`_prove_mass_matrix`). Where that fails, those pieces
    break down too, at the time it names, and ``sol`` keeps no surviving part."""
    surv = sol.surviving
    if surv is None:
        return
    _prove_mass_matrix(masses, surv)
    if surv.status != "breakdown":
        return
    before = sol.pieces_summary()
    for p in sol.piece_results or ():
        if not p.failed:
            p.status, p.t_reached, p.reason = "breakdown", float(surv.t_reached), surv.reason
    sol.surviving = None
    after = sol.pieces_summary()
    if after and before and before in sol.reason:
        sol.reason = sol.reason.replace(before, after, 1)
    elif after:
        sol.reason = after


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

    A bare System with an energy: its ``H`` as a :class:`verified.conservation.NonIncreasing`
    invariant (the rate its ``energy_rate`` declares, proven, else ``grad H . f``, checked
    ``<= 0`` on every step) or, with ``energy_rate="zero"``, a proven
    :class:`~verified.conservation.Conserved` one (:class:`verified.conservation.InvariantHook`)."""
    if loop is not None:
        raise ValueError("energy_shell=True needs a system without control inputs (a controller can add energy)")
    if masses is None:
        if system is None or system.energy is None:
            raise ValueError("energy_shell=True on a bare System needs its energy (System(energy=H)); "
                             "without one it has no shell")
        from verified.conservation import Conserved, NonIncreasing, invariant_hook
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


class _CtrlC:
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

    # the hook protocol of verified.hooks
    def before_run(self, setup):
        return None

    def after_step(self, step, sets, run):
        if self.requested:
            run.stop(f"interrupted (Ctrl-C) at t = {float(step.t):g}", "interrupted")
        return None

    def after_run(self, solution):
        return None


def _split_params(box, ode_params, system, pieces: dict, subdivision):
    """(boxes (K, n), params (K, p)): the parameter box cut into a grid of ``pieces``."""
    names = list(system.rhs.param_names)
    if not isinstance(pieces, dict):
        raise ValueError(f"param_subdivision must be a dict {{parameter name: pieces}}, got {pieces!r}")
    if subdivision is not None:
        raise ValueError("param_subdivision cannot be combined with subdivision (one initial box per parameter piece)")
    if ode_params is None or ode_params.ndim != 1:
        raise ValueError("param_subdivision needs uncertain parameters (one parameter box)")
    if box.ndim != 1:
        raise ValueError("param_subdivision needs a single initial box")
    cuts = []
    for j, k in enumerate(names):
        m = pieces.get(k, 1)
        if isinstance(m, bool) or not isinstance(m, (int, np.integer)) or m < 1:
            raise ValueError(f"param_subdivision[{k!r}]: expected a positive integer, got {m!r}")
        lo, hi = float(ode_params.lo[j]), float(ode_params.hi[j])
        e = np.linspace(lo, hi, int(m) + 1)
        e[0], e[-1] = lo, hi
        cuts.append(list(zip(e[:-1], e[1:])))
    unknown = [k for k in pieces if k not in names]
    if unknown:
        raise ValueError(f"param_subdivision: unknown parameter(s) {', '.join(map(repr, unknown))}; "
                         f"parameters: {', '.join(names)}")
    rows = list(itertools.product(*cuts))
    plo = np.array([[a for a, _ in r] for r in rows])
    phi = np.array([[b for _, b in r] for r in rows])
    K = len(rows)
    X = Interval(np.tile(np.asarray(box.lo, float), (K, 1)), np.tile(np.asarray(box.hi, float), (K, 1)))
    return X, Interval(plo, phi)


def _params_record(system: System, ode_params) -> dict:
    """{name: (lo, hi)} of the parameters a run used (their hull over the boxes)."""
    names = system.rhs.param_names
    if not names or ode_params is None:
        return {}
    try:
        p = _as_interval(ode_params)
    except (TypeError, ValueError):
        return {}
    lo = np.min(np.asarray(p.lo, float).reshape(-1, len(names)), axis=0)
    hi = np.max(np.asarray(p.hi, float).reshape(-1, len(names)), axis=0)
    return {k: (float(a), float(b)) for k, a, b in zip(names, lo, hi)}


def _legacy_method(method, solver_kwargs: dict) -> bool:
    """Whether the run names its method by the old signature's settings (``order``,
    ``set_order``, ...; no ``method``): then the defaults that method needs with a
    controller or parameters are filled in as before (the methods of
    :mod:`verified.methods` carry their own)."""
    return method is None and any(k in solver_kwargs for k in METHOD_FIELDS)


def _check_solver_kwargs(kwargs: dict):
    """Unknown keyword arguments name :func:`simulate` (not the solver it calls)."""
    ours = set(inspect.signature(simulate).parameters) - {"solver_kwargs"}
    sig = inspect.signature(verified.solver.solve)  # (mbs.simulate.solve may be a test's wrapper)
    # (solve's **method_settings: the old signature's method settings, METHOD_FIELDS)
    theirs = {k for k, p in sig.parameters.items() if p.kind is not inspect.Parameter.VAR_KEYWORD}
    theirs = (theirs | set(METHOD_FIELDS)) - {"ode", "x0", "t_span", "t_eval", "params", "subdivision",
                                              "consistency", "progress", "method"}
    # names users bring from scipy's solve_ivp and what they are called here
    known = {"t_eval": "output_dt", "rtol": "tol", "atol": "tol", "t_span": "t_end"}
    for k in kwargs:
        if k not in theirs:
            close = [known[k]] if k in known else difflib.get_close_matches(k, sorted(ours | theirs), n=1)
            raise TypeError(f"simulate() got an unexpected keyword argument {k!r}"
                            + (f" (did you mean {close[0]!r}?)" if close else "")
                            + f"; solver settings it passes on: {', '.join(sorted(theirs))}")


# ---------------------------------------------------------------------- M(q) > 0
# A verified run of a chain is only meaningful where M(q) is positive definite (else
# qdd is not defined).  Model validation catches massless subtrees; masses on joint
# axes (M = 0, M = diag(2, 0), singular configurations) are caught here:
#  - before integrating: a constant zero LDL^T pivot raises while the graphs are
#    traced (mbs.numeric.ldl_factor), and M at the centre of each initial box must be
#    nonsingular in floats (SingularMassMatrixError naming the joints);
#  - after integrating: the interval pivots D_k(q) of M must be proven > 0 on every
#    box the solver used (the tube: each step's a-priori enclosure contains the sets
#    the step starts from).  A zero pivot usually makes the rhs enclosure unbounded
#    (a break-down), but [0, 0] / D = [0, 0] for D containing 0, so this does not rely
#    on it; where the proof fails the run is cut back to that time and reported as a
#    break-down naming the joint.

def _check_initial_mass_matrix(masses, box: Interval):
    """Raise SingularMassMatrixError (naming the joints) if M is singular for every q
    (a constant zero pivot, found while tracing) or at the centre of an initial box
    (with uncertain parameters: at their midpoints)."""
    if not isinstance(masses, _MassMatrix):  # a Chain
        masses = _MassMatrix(masses)
    num = masses.num
    n = num.n
    mids = np.atleast_2d(box.mid())[:, :n]
    with np.errstate(divide="ignore", invalid="ignore"):
        D = np.asarray(num.mass_matrix_pivots(mids.T), dtype=float).reshape(n, -1)
    M = np.asarray(num.mass_matrix(mids.T), dtype=float).reshape(n, n, -1)
    tol = PIVOT_TOL * n * np.max(np.abs(np.diagonal(M, axis1=0, axis2=1)), axis=-1)
    for b in np.flatnonzero(~(D > tol).all(axis=0)):  # at most one raises, normally the first
        num.check_mass_matrix(mids[b], where=f"at q = [{', '.join(f'{v:.6g}' for v in mids[b])}] "
                                              "(centre of the initial box)")


_CHUNK_ROWS = 8192
_BISECTIONS = 6
_MAX_BISECTED = 64


def pivots_proven(graph, lo: np.ndarray, hi: np.ndarray, depth: int = _BISECTIONS) -> np.ndarray:
    """Which rows (boxes of q, shape (B, n)) have every pivot proven > 0: simulate()'s
    M(q) > 0 proof on boxes. ``graph``: the LDL^T pivots of M as a graph of q (and the
    parameters after q), e.g. ``chain.numeric().pivot_graph()``; ``lo``, ``hi``: (B, inputs)
    bounds; returns a (B,) bool array. Interval evaluation first, affine arithmetic
    where that does not prove a row. A box that
    fails is bisected along its widest component, up to ``depth`` times, so that
    interval overestimation alone does not fail it (only the first
    ``_MAX_BISECTED`` failing rows: the earliest failure is the one that counts)."""
    ok = np.zeros(lo.shape[0], dtype=bool)
    finite = np.isfinite(lo).all(axis=1) & np.isfinite(hi).all(axis=1)
    if finite.any():
        D = graph.eval_interval(Interval(lo[finite], hi[finite]))
        ok[finite] = np.all(D.lo > 0, axis=-1)
    retry = np.flatnonzero(~ok & finite)
    if retry.size:
        # affine arithmetic keeps the pivots' dependence on q (where an interval pivot
        # contains 0; docs/lab/code_notes.md), so a run verified with it is not cut back
        D = affine_range(graph, Interval(lo[retry], hi[retry]))
        ok[retry] = np.all(D.lo > 0, axis=-1)
    if depth == 0:
        return ok
    rows = np.flatnonzero(~ok & finite)[:_MAX_BISECTED]
    j = np.argmax(hi[rows] - lo[rows], axis=1)
    splittable = hi[rows, j] > lo[rows, j]  # a point box stays failed
    rows, j = rows[splittable], j[splittable]
    if rows.size == 0:
        return ok
    cut = 0.5 * (lo[rows, j] + hi[rows, j])
    lower_hi, upper_lo = hi[rows].copy(), lo[rows].copy()
    lower_hi[np.arange(rows.size), j] = cut
    upper_lo[np.arange(rows.size), j] = cut
    halves = pivots_proven(graph, np.concatenate([lo[rows], upper_lo]), np.concatenate([lower_hi, hi[rows]]), depth - 1)
    ok[rows] = halves[:rows.size] & halves[rows.size:]
    return ok


def _first_unproven(graph, pieces, n, pbox=None):
    """(index, q-box lo, q-box hi) of the first of ``pieces`` (Interval (B, >= n) each,
    in time order) with a box on which M is not proven positive definite, or None.
    ``pbox``: (lo, hi) of the parameters, appended to every q-box (the graph's inputs
    are q, then the parameters); the returned boxes include them."""
    los = [p.lo.reshape(-1, p.shape[-1])[:, :n] for p in pieces]
    his = [p.hi.reshape(-1, p.shape[-1])[:, :n] for p in pieces]
    if pbox is not None:
        los = [np.concatenate([a, np.broadcast_to(pbox[0], (a.shape[0], len(pbox[0])))], axis=1) for a in los]
        his = [np.concatenate([a, np.broadcast_to(pbox[1], (a.shape[0], len(pbox[1])))], axis=1) for a in his]
    start = 0
    while start < len(pieces):
        stop, rows = start + 1, los[start].shape[0]
        while stop < len(pieces) and rows + los[stop].shape[0] <= _CHUNK_ROWS:
            rows += los[stop].shape[0]
            stop += 1
        lo, hi = np.concatenate(los[start:stop]), np.concatenate(his[start:stop])
        ok = pivots_proven(graph, lo, hi)
        if not ok.all():
            i = int(np.flatnonzero(~ok)[0])
            owner = start + int(np.searchsorted(np.cumsum([x.shape[0] for x in los[start:stop]]), i, side="right"))
            return owner, lo[i], hi[i]
        start = stop
    return None


def _prove_mass_matrix(masses, sol: Solution):
    """Prove M(q) positive definite on every box of ``sol`` (and every parameter value
    in the parameter box); where that fails, cut the solution back to that time and
    make it a break-down that names the joint."""
    if not isinstance(masses, _MassMatrix):  # a Chain
        masses = _MassMatrix(masses)
    num, n, graph, chain = masses.num, masses.n, masses.graph, masses.chain
    # (time, boxes, the time in words): the initial sets, then each step's tube boxes
    # (a-priori enclosure over [t_j, t_j+1], which contains the sets the step started
    # from), and after a break-down at an output time the sets the failed step had
    pieces = [(float(sol.t[0]), sol.boxes[0], f"t = {float(sol.t[0]):.6g}")]
    pieces += [(float(sol.tube_t[j]), sol.tube[j], f"t in [{float(sol.tube_t[j]):.6g}, {float(sol.tube_t[j + 1]):.6g}]")
               for j in range(len(sol.tube))]
    if sol.status != "completed" and len(sol.t) > 1 and sol.t[-1] >= sol.t_reached:
        pieces.append((float(sol.t[-1]), sol.boxes[-1], f"t = {float(sol.t[-1]):.6g}"))
    found = _first_unproven(graph, [p[1] for p in pieces], n, masses.pbox)
    if found is None:
        return
    piece, lo, hi = found
    T, _, span = pieces[piece]
    names = chain.joint_names
    D = graph.eval_interval(Interval(lo, hi))
    k = int(np.flatnonzero(~(D.lo > 0))[0])
    box = ", ".join(f"{names[i]} in [{lo[i]:.6g}, {hi[i]:.6g}]" for i in range(n))
    if masses.pbox is not None:
        box += " and the parameter box"
    reason = (f"mass matrix M(q) not proven positive definite on the enclosure for {span}: the LDL^T "
              f"pivot of joint {names[k]!r} encloses [{float(D.lo[k]):.3g}, {float(D.hi[k]):.3g}] for {box}")
    try:
        num.check_mass_matrix(0.5 * (lo[:n] + hi[:n]), where="at the centre of that box")
    except ModelError as e:
        reason += f"; {e}"
    else:
        reason += _pivot_diagnosis(num, lo[:n], hi[:n], names, k)
    if sol.status == "completed" or T < sol.t_reached:
        _truncate(sol, T)
        reason = reason if not sol.reason else f"{reason} (the integration then stopped: {sol.reason})"
    else:
        reason = f"{sol.reason}; {reason}"
    sol.status, sol.reason = "breakdown", reason


#: configurations sampled in a box whose pivot proof failed, to tell the model's
#: singularity from the width of the set (the centre and corners come first)
_DIAGNOSIS_SAMPLES = 512
#: a sampled pivot below this fraction of M's largest diagonal entry counts as a (near)
#: singular configuration of the model (samples rarely hit the exact one); it lies
#: between a true singularity's pivots and a wide box's (docs/lab/code_notes.md)
_NEAR_SINGULAR = 1e-6


def _pivot_diagnosis(num, lo: np.ndarray, hi: np.ndarray, names, k: int) -> str:
    """Why the pivot proof failed on the q-box ``[lo, hi]``, in words: M(q) sampled in
    floats at the centre, the corners (up to 2^8) and random points of the box. A
    singular sample names the model (a configuration where M is singular); none means
    the interval pivot is too wide over a box this size: the set, not the model, and
    splitting it is what helps. (A diagnosis only: soundness does not rest on it.)"""
    rng = np.random.default_rng(0)
    n = lo.size
    corners = np.array(list(itertools.product(*zip(lo, hi)))[:256]) if n <= 8 else np.empty((0, n))
    Q = np.concatenate([[0.5 * (lo + hi)], corners,
                        lo + (hi - lo) * rng.random((_DIAGNOSIS_SAMPLES - 1 - len(corners), n))])
    with np.errstate(all="ignore"):
        D = np.asarray(num.mass_matrix_pivots(Q.T), dtype=float).reshape(n, -1)
        M = np.asarray(num.mass_matrix(Q.T), dtype=float).reshape(n, n, -1)
    scale = np.max(np.abs(np.diagonal(M, axis1=0, axis2=1)), axis=-1)
    ratio = np.min(D, axis=0) / np.where(scale > 0, scale, 1.0)
    worst = int(np.nanargmin(np.where(np.isnan(ratio), -np.inf, ratio)))
    widest = int(np.argmax(hi - lo))
    if not (ratio[worst] > _NEAR_SINGULAR):
        q = ", ".join(f"{v:.6g}" for v in Q[worst])
        return (f" (the model: M(q) is singular or nearly so at q = [{q}] inside that box, smallest LDL^T "
                f"pivot {np.min(D[:, worst]):.3g}: do the links joint {names[k]!r} moves have inertia about "
                "its axis? Keep the box away from that configuration)")
    return (f" (the set, not the model: M(q) is positive definite at the centre and at {Q.shape[0] - 1} sampled "
            f"points of that box (smallest pivot {np.min(D):.3g}), but the box is {hi[widest] - lo[widest]:.3g} "
            f"wide in {names[widest]!r} and the interval pivot over it is too wide to exclude 0; what helps: "
            "split the initial box (subdivision=, or [solver] subdivision in a scene) into pieces, a smaller "
            "box, or second-order sets (set_order=2, set_step='composition'))")


def _truncate(sol: Solution, T: float):
    """Keep only what ``sol`` verified up to time ``T``."""
    keep = np.flatnonzero(sol.t <= T)
    sol.t = sol.t[keep]
    sol.boxes = [sol.boxes[i] for i in keep]
    if sol.views:
        sol.views = [sol.views[i] if i < len(sol.views) else None for i in keep]
    sol.hull = sol.hull[keep]
    steps = int(np.sum(sol.tube_t[1:] <= T))
    sol.tube = sol.tube[:steps]
    if sol.tube_views:
        sol.tube_views = sol.tube_views[:steps]
    sol.tube_t = sol.tube_t[:steps + 1]
    sol.tube_hull = sol.tube_hull[:steps]
    sol.t_reached = T
    rec = sol.consistency
    if rec is not None:
        m = np.asarray(rec.ra_t) <= T
        rec.ra_t, rec.ra = np.asarray(rec.ra_t)[m], np.asarray(rec.ra)[m]
        if rec.h_h.shape[:1] == m.shape:
            rec.h_h = rec.h_h[m]
        if rec.h_v.shape[:1] == m.shape:
            rec.h_v = rec.h_v[m]
        rec.tests = [r for r in rec.tests if r.t <= T]


def compare_modes(model, x0, t_end: float, modes=MODES, *, output_dt: float | None = None, **kwargs) -> dict:
    """Run ``model`` in each of ``modes`` with the same settings: ``{mode: Solution}``.

    ``output_dt`` defaults to ``(t_end - t0) / 50``, so that :func:`width_deviations`
    compares the modes at 50 output times, not only at ``t_end``."""
    if output_dt is None:
        output_dt = (float(t_end) - float(kwargs.get("t0", 0.0))) / 50
    return {m: simulate(model, x0, t_end, mode=m, output_dt=output_dt, **kwargs) for m in modes}


class WidthDeviations(np.ndarray):
    """Largest ``|diam a(t) - diam b(t)|`` per state (an ndarray (n,)) that also says
    where it was taken: ``times`` (the output times compared, every one both solutions
    reached), ``argmax_t`` (n,) (the output time of each maximum), ``only_one`` (output
    times only one solution reached: the other broke down or stopped earlier)."""

    times: np.ndarray
    argmax_t: np.ndarray
    only_one: np.ndarray
    state_names: tuple

    def __array_finalize__(self, obj):
        for k in ("times", "argmax_t", "only_one"):
            setattr(self, k, getattr(obj, k, np.zeros(0)))
        self.state_names = getattr(obj, "state_names", ())

    def describe(self) -> str:
        """One line: the deviations, where they occur and what was compared."""
        names = self.state_names or tuple(f"x{i + 1}" for i in range(self.size))
        parts = ", ".join(f"{n} {float(v):.4g} (t = {float(t):g})"
                          for n, v, t in zip(names, np.asarray(self), self.argmax_t))
        ts = self.times
        head = (f"largest width differences over {ts.size} output times t = {ts[0]:g} .. {ts[-1]:g}: "
                if ts.size else "no common output times: ")
        tail = ""
        if self.only_one.size:
            tail = (f"; {self.only_one.size} later output time(s) up to t = {self.only_one[-1]:g} reached by one "
                    "solution only (not compared)")
        return head + parts + tail


def width_deviations(a: Solution, b: Solution) -> WidthDeviations:
    """Largest ``|diam a(t) - diam b(t)|`` per state over every output time both
    solutions reach (the paper's comparison of modes (ii) and (iii): 0.0018, 0.0072,
    0.0066, 0.0444). Returns a :class:`WidthDeviations` (an ndarray (n,)) that says
    which times were compared and where each maximum is (``.describe()``)."""
    ta, tb = np.asarray(a.t, float), np.asarray(b.t, float)
    k = min(ta.size, tb.size)
    if k == 0 or not np.allclose(ta[:k], tb[:k], rtol=1e-12, atol=0):
        raise ValueError("the solutions do not share output times (run them with the same t0, t_end, output_dt)")
    wa, wb = a.hull[:k].width(), b.hull[:k].width()
    dev = np.abs(np.asarray(wa, float) - np.asarray(wb, float))  # (k, n)
    out = np.max(dev, axis=0).view(WidthDeviations)
    out.times = ta[:k]
    out.argmax_t = ta[np.argmax(dev, axis=0)]
    out.only_one = (ta if ta.size > tb.size else tb)[k:]
    out.state_names = tuple(getattr(a, "state_names", ()) or ())
    return out

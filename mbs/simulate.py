"""Run a model in one of the paper's three simulation modes (sec. 5.2).

- mode ``"i"``: the numeric model (recursive algorithms, SMARTMOBILE-style), no
  consistency test;
- mode ``"ii"``: the numeric model with the energy constraints: ``H_H`` from its
  kinetic and potential energy functions, ``dH/dt`` by forward-mode automatic
  differentiation of ``H`` along the ODE (the paper used FADBAD++);
- mode ``"iii"``: the symbolic model (sympy) with symbolic constraints, ``dH/dt``
  left unsimplified as in the paper (``energy_rate="unsimplified"``) or simplified
  (``"simplified"``: ``qd^T tau``, identically 0 for a conservative system).

Example::

    from mbs.simulate import simulate, compare_modes
    from models import double_pendulum as dp
    from verified.interval import Interval
    sol = simulate("double_pendulum_paper", Interval(*dp.initial_box()), 1.0, mode="iii")
    sol.hull[-1], sol.consistency.tests, sol.stats["pruned_boxes"]

Models: a name of :mod:`models.registry` (plus ``"pendulum_paper"`` and
``"double_pendulum_paper"``: the numeric model of a DH chain in modes i/ii and the
paper's hand-written eqs. (18)/(19) and (22)/(24) in mode iii), an :class:`mbs.Chain`,
or an :class:`mbs.system.System` (e.g. recovered from a bare ODE).
"""
from __future__ import annotations

import numpy as np

from verified.affine_taylor import affine_range
from verified.consistency import STRATEGIES, EnergyTest
from verified.interval import Interval, _as_interval
from verified.solver import Solution, solve

from .errors import ModelError
from .numeric import PIVOT_TOL
from .system import System

__all__ = ["MODES", "PAPER_MODELS", "simulate", "compare_modes", "system_for", "width_deviations",
           "output_times"]

MODES = ("i", "ii", "iii")
PAPER_MODELS = ("pendulum_paper", "double_pendulum_paper")

#: consistency-test settings per mode (the paper's: 0.1 s / 10 parts in mode (ii),
#: 0.01 s / 50 parts in mode (iii))
TEST_DEFAULTS = {"ii": dict(test_interval=0.1, test_splits=10), "iii": dict(test_interval=0.01, test_splits=50)}


def _paper_system(name: str, mode: str, energy_rate: str) -> System:
    from verified.graph import from_sympy, trace

    from models import double_pendulum as dp
    from models import pendulum as pd

    if mode != "iii":
        chain = pd.chain() if name == "pendulum_paper" else dp.dh_chain()
        return _chain_system(chain, mode, energy_rate, name=name)
    mod = pd if name == "pendulum_paper" else dp
    xs, f, H = mod.sympy_model()
    names = [str(s) for s in xs]
    rhs = trace(mod.rhs, len(xs), input_names=names, output_names=[f"d{s}" for s in names])
    energy = from_sympy([H], xs, output_names=["H"])
    import sympy
    rate_expr = sum(sympy.diff(H, x) * fx for x, fx in zip(xs, f))  # eq. (7), not simplified
    if energy_rate == "simplified":
        _prove_conservative(mod, len(xs))
        return System(name=name, rhs=rhs, energy=energy, conservative=True,
                      description="paper's symbolic model, dH/dt simplified to 0")
    return System(name=name, rhs=rhs, energy=energy, energy_rate=from_sympy([rate_expr], xs, output_names=["dHdt"]),
                  description="paper's symbolic model, dH/dt unsimplified (grad H . f)")


def _prove_conservative(mod, n: int):
    """dH/dt = grad H . f simplifies to 0 with every parameter a free symbol, so it is
    0 for the float parameter values too (simplifying with the float values leaves
    rounding residues such as 7e-15 x3 sin x1)."""
    import sympy
    import inspect
    xs = list(sympy.symbols(f"x1:{n + 1}", real=True))
    names = [k for k in inspect.signature(mod.rhs).parameters if k not in ("x", "p")]  # m, l, g, ...
    ps = {k: sympy.Symbol(k, positive=True) for k in names}
    f = mod.rhs(xs, **ps)
    H = mod.hamiltonian(xs, **ps)
    rate = sympy.simplify(sum(sympy.diff(H, x) * fx for x, fx in zip(xs, f)))
    if rate != 0:  # pragma: no cover - guards the claim that the paper's models are conservative
        raise ModelError(f"{mod.__name__}: dH/dt does not simplify to 0 ({rate})")


def _chain_system(chain, mode: str, energy_rate: str, name: str | None = None) -> System:
    name = name or getattr(chain, "name", "chain")
    if mode in ("i", "ii"):
        num = chain.numeric()
        rhs = num.rhs_graph()
        if mode == "i":
            return System(name=name, rhs=rhs, description="numeric model (crba/rnea), no test")
        return System(name=name, rhs=rhs, energy=num.energy_graph(), energy_rate=None,
                      description="numeric model; dH/dt by forward-mode AD of H along the ODE")
    sym = chain.symbolic()
    rhs = sym.rhs_graph()
    energy = sym.energy_graph()
    rate = sym.energy_rate_graph(simplified=(energy_rate == "simplified"))
    return System(name=name, rhs=rhs, energy=energy, energy_rate=rate,
                  description=f"symbolic model (sympy); dH/dt {energy_rate}")


def system_for(model, mode: str = "ii", *, energy_rate: str = "unsimplified") -> System:
    """The :class:`System` that ``mode`` integrates for ``model`` (see module docstring)."""
    return _system_and_chain(model, mode, energy_rate)[0]


def _system_and_chain(model, mode: str, energy_rate: str):
    """(System, the Chain behind it or None) -- the chain for the mass-matrix checks."""
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    if energy_rate not in ("unsimplified", "simplified"):
        raise ValueError(f"energy_rate must be 'unsimplified' or 'simplified', got {energy_rate!r}")
    if isinstance(model, System):
        if mode == "i":
            return System(name=model.name, rhs=model.rhs, params=model.params, description=model.description), None
        if not model.has_energy:
            raise ModelError(f"{model.name}: mode {mode} needs an energy graph (System.energy)")
        return model, None
    if isinstance(model, str):
        if model in PAPER_MODELS:
            from models import double_pendulum as dp
            from models import pendulum as pd
            # the paper's models are these chains (mode iii: the same M, hand-written)
            chain = pd.chain() if model == "pendulum_paper" else dp.dh_chain()
            return _paper_system(model, mode, energy_rate), chain
        from models.registry import get
        chain = get(model)
        return _chain_system(chain, mode, energy_rate, name=model), chain
    from .chain import Chain
    if isinstance(model, Chain):
        return _chain_system(model, mode, energy_rate), model
    raise TypeError(f"model must be a model name, an mbs.Chain or an mbs.system.System, got {type(model).__name__}")


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


def simulate(model, x0, t_end: float, *, mode: str = "ii", t0: float = 0.0, output_dt: float | None = None,
             params=None, order: int = 12, tol: float = 1e-10, subdivision=None,
             energy_rate: str = "unsimplified", test_interval: float | None = None, test_splits: int | None = None,
             split_strategy: str = "gradient", refine: str = "pruned", min_gain: float = 0.1,
             backward_depth: int = 0,
             constraints=(), progress=None, **solver_kwargs) -> Solution:
    """Verified enclosure of ``model`` from the initial box ``x0`` in simulation ``mode``.

    Parameters
    ----------
    model : str, mbs.Chain or mbs.system.System
    x0 : Interval (n,) or (B, n), or (lo, hi)
        Initial state box, ``x = (q, qd)`` in rad and rad/s (m, m/s for prismatic).
    t_end : float
        Final time (s).
    mode : "i", "ii" or "iii"
    output_dt : float or None
        Output every ``output_dt`` seconds (at exactly ``k * output_dt``); default: ``t_end`` only.
    params : ODE parameters (for Systems with parameters)
    order, tol, subdivision : solver settings (see :func:`verified.solver.solve`)
    energy_rate : "unsimplified" or "simplified" (mode iii)
    test_interval, test_splits : longest time between energy tests (s) and parts per
        set at a test; defaults per mode in :data:`TEST_DEFAULTS` (the paper's)
    split_strategy : "gradient", "widest" or "grid" (see :class:`verified.consistency.EnergyTest`)
    refine, min_gain : "pruned" (replace a set by its surviving parts only when that
        narrows its hull by ``min_gain``, default 0.1) or "always"
    backward_depth : backward consistency test depth (0 = off)
    constraints : further :class:`verified.consistency.Constraint` objects (modes ii, iii)
    progress : callable(t, t_end) after every step
    solver_kwargs : passed on to :func:`verified.solver.solve` (h_max, max_boxes, ...)

    Returns
    -------
    verified.solver.Solution with ``mode`` and ``state_names`` set, and
    ``consistency`` (RA(t), H_H, H_V, tests) in modes ii and iii.
    """
    system, chain = _system_and_chain(model, mode, energy_rate)
    t0, t_end = float(t0), float(t_end)
    if not (np.isfinite(t_end) and t_end > t0):
        raise ValueError(f"t_end must be a finite time after t0 = {t0}, got {t_end!r}")
    box = _initial_box(x0, system.n, system.name)
    if chain is not None:
        _check_initial_mass_matrix(chain, box)
    if split_strategy not in STRATEGIES:
        raise ValueError(f"split_strategy must be one of {STRATEGIES}, got {split_strategy!r}")
    test = None
    if mode != "i":
        defaults = TEST_DEFAULTS[mode]
        rate = "zero" if system.conservative else ("derive" if system.energy_rate is None else system.energy_rate)
        test = EnergyTest(system.energy, rate, constraints,
                          max_interval=defaults["test_interval"] if test_interval is None else test_interval,
                          splits=defaults["test_splits"] if test_splits is None else test_splits,
                          strategy=split_strategy, refine=refine, min_gain=min_gain, backward_depth=backward_depth,
                          max_boxes=solver_kwargs.get("max_boxes", 4096))
    elif constraints:
        raise ValueError("mode i runs without consistency tests; use mode ii or iii for constraints")
    ode_params = params
    if ode_params is None and system.rhs.n_params:
        ode_params = [system.params[name] for name in system.rhs.param_names]
    sol = solve(system.rhs, box, (t0, t_end), t_eval=output_times(t0, t_end, output_dt), params=ode_params,
                order=order, tol=tol, subdivision=subdivision, consistency=test, progress=progress,
                **solver_kwargs)
    if chain is not None:
        _prove_mass_matrix(chain, sol)
    sol.mode = mode
    sol.state_names = system.state_names
    return sol


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

def _check_initial_mass_matrix(chain, box: Interval):
    """Raise SingularMassMatrixError (naming the joints) if M is singular for every q
    (a constant zero pivot, found while tracing) or at the centre of an initial box."""
    num = chain.numeric()
    num.pivot_graph()
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


def _proven(graph, lo: np.ndarray, hi: np.ndarray, depth: int = _BISECTIONS) -> np.ndarray:
    """Which rows (boxes of q, shape (B, n)) have every pivot proven > 0.  A box that
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
        # affine arithmetic keeps the pivots' dependence on q (5-link arm, q +- 1e-3:
        # interval [-0.29, 0.39], affine > 0), so a run verified with it is not cut back
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
    halves = _proven(graph, np.concatenate([lo[rows], upper_lo]), np.concatenate([lower_hi, hi[rows]]), depth - 1)
    ok[rows] = halves[:rows.size] & halves[rows.size:]
    return ok


def _first_unproven(graph, pieces, n):
    """(index, q-box lo, q-box hi) of the first of ``pieces`` (Interval (B, >= n) each,
    in time order) with a box on which M is not proven positive definite, or None."""
    los = [p.lo.reshape(-1, p.shape[-1])[:, :n] for p in pieces]
    his = [p.hi.reshape(-1, p.shape[-1])[:, :n] for p in pieces]
    start = 0
    while start < len(pieces):
        stop, rows = start + 1, los[start].shape[0]
        while stop < len(pieces) and rows + los[stop].shape[0] <= _CHUNK_ROWS:
            rows += los[stop].shape[0]
            stop += 1
        lo, hi = np.concatenate(los[start:stop]), np.concatenate(his[start:stop])
        ok = _proven(graph, lo, hi)
        if not ok.all():
            i = int(np.flatnonzero(~ok)[0])
            owner = start + int(np.searchsorted(np.cumsum([x.shape[0] for x in los[start:stop]]), i, side="right"))
            return owner, lo[i], hi[i]
        start = stop
    return None


def _prove_mass_matrix(chain, sol: Solution):
    """Prove M(q) positive definite on every box of ``sol``; where that fails, cut the
    solution back to that time and make it a break-down that names the joint."""
    num = chain.numeric()
    n = num.n
    graph = num.pivot_graph()
    # (time, boxes, the time in words): the initial sets, then each step's tube boxes
    # (a-priori enclosure over [t_j, t_j+1], which contains the sets the step started
    # from), and after a break-down at an output time the sets the failed step had
    pieces = [(float(sol.t[0]), sol.boxes[0], f"t = {float(sol.t[0]):.6g}")]
    pieces += [(float(sol.tube_t[j]), sol.tube[j], f"t in [{float(sol.tube_t[j]):.6g}, {float(sol.tube_t[j + 1]):.6g}]")
               for j in range(len(sol.tube))]
    if sol.status != "completed" and len(sol.t) > 1 and sol.t[-1] >= sol.t_reached:
        pieces.append((float(sol.t[-1]), sol.boxes[-1], f"t = {float(sol.t[-1]):.6g}"))
    found = _first_unproven(graph, [p[1] for p in pieces], n)
    if found is None:
        return
    piece, lo, hi = found
    T, _, span = pieces[piece]
    names = chain.joint_names
    D = graph.eval_interval(Interval(lo, hi))
    k = int(np.flatnonzero(~(D.lo > 0))[0])
    box = ", ".join(f"{names[i]} in [{lo[i]:.6g}, {hi[i]:.6g}]" for i in range(n))
    reason = (f"mass matrix M(q) not proven positive definite on the enclosure for {span}: the LDL^T "
              f"pivot of joint {names[k]!r} encloses [{float(D.lo[k]):.3g}, {float(D.hi[k]):.3g}] for {box}")
    try:
        num.check_mass_matrix(0.5 * (lo + hi), where="at the centre of that box")
    except ModelError as e:
        reason += f"; {e}"
    else:
        reason += " (M(q) is singular or nearly so there: do the links this joint moves have inertia about its axis?)"
    if sol.status == "completed" or T < sol.t_reached:
        _truncate(sol, T)
        reason = reason if not sol.reason else f"{reason} (the integration then stopped: {sol.reason})"
    else:
        reason = f"{sol.reason}; {reason}"
    sol.status, sol.reason = "breakdown", reason


def _truncate(sol: Solution, T: float):
    """Keep only what ``sol`` verified up to time ``T``."""
    keep = np.flatnonzero(sol.t <= T)
    sol.t = sol.t[keep]
    sol.boxes = [sol.boxes[i] for i in keep]
    sol.hull = sol.hull[keep]
    steps = int(np.sum(sol.tube_t[1:] <= T))
    sol.tube = sol.tube[:steps]
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


def compare_modes(model, x0, t_end: float, modes=MODES, **kwargs) -> dict:
    """Run ``model`` in each of ``modes`` with the same settings: ``{mode: Solution}``."""
    return {m: simulate(model, x0, t_end, mode=m, **kwargs) for m in modes}


def width_deviations(a: Solution, b: Solution) -> np.ndarray:
    """Largest ``|diam a(t) - diam b(t)|`` per state over the output times both reach
    (the paper's comparison of modes (ii) and (iii): 0.0018, 0.0072, 0.0066, 0.0444)."""
    k = min(len(a.t), len(b.t))
    if k == 0 or not np.allclose(a.t[:k], b.t[:k]):
        raise ValueError("the solutions do not share output times")
    return np.max(np.abs(a.hull[:k].width() - b.hull[:k].width()), axis=0)

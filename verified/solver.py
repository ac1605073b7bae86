"""``verified.solve``: enclosures of every solution of an ODE from a set of initial values.

In the spirit of ``scipy.integrate.solve_ivp``::

    sol = verified.solve(graph, x0, (0.0, 1.0), t_eval=np.linspace(0, 1, 11))
    sol.hull[-1]          # Interval (n,): encloses x(1) for every x(0) in x0
    sol.tube_hull         # Interval (steps, n): encloses x(t) on each step interval
    sol.status, sol.reason

The ODE is an autonomous expression :class:`~verified.graph.Graph` ``x' = f(x, p)``;
``x0`` a box (or a batch of boxes, or a list of them); ``params`` exact floats or
intervals (uncertain parameters, constant in time). The initial boxes may be split
into a uniform grid (``subdivision``). All boxes advance together with one common step
size through the batched QR-Lohner step of :mod:`verified.steppers.lohner`.

A break-down is a result, not an exception: everything up to the last verified time is
returned with ``status = "breakdown"`` and the reason; so is a stop asked for by a hook
(``"stopped"``) and a ``KeyboardInterrupt`` (``"interrupted"``).

:func:`solve` is the public entry: it checks how the run is to be executed and hands it
to the chunked execution (:mod:`verified.execution`: ``workers``, ``client``, ``chunks``,
``rechunk``) or runs it as one batch in this process (:func:`verified.driver.batch.solve_batch`,
the driver loop: per step it takes the hull of the sets, asks the step control
(:mod:`verified.driver.control`) for a step size the stepper (a
:class:`verified.steppers.protocol.Stepper` of the run's set kind, :mod:`verified.steppers.set_kinds`) can
validate, advances the sets (:mod:`verified.sets`) to a
:class:`~verified.steppers.protocol.StepResult`, records it, and calls the hooks
(:mod:`verified.driver.hooks`: progress, the consistency test, stop rules); adaptive splitting
and merging follow). See ``docs/architecture.md``.

Imports go one way: ``solver -> parallel -> batch -> solution`` (``solver`` also imports
``batch`` and ``solution`` directly). :class:`Solution` and :class:`Start`
(:mod:`verified.driver.solution`), :class:`VerifiedODE` and :data:`MODEL_CAPS`
(:mod:`verified.driver.batch`) are importable from here as before; the driver's private
helpers (``_Run``, ``_stepper``, ``_setup``, ...) are in :mod:`verified.driver.batch` only, so
that a test patches them where the driver looks them up.
"""

from __future__ import annotations

import numpy as np

from verified.auto import solve_auto
from verified.driver.batch import MODEL_CAPS, VerifiedODE, solve_batch
from verified.driver.hooks import after_solve
from verified.arith.interval import Interval
from verified.methods import METHOD_FIELDS, METHODS, Auto, as_method, from_settings
from verified.execution.plan import auto_workers
from verified.execution.run import solve_parallel
from verified.driver.solution import Solution, Start

# (Solution, Start, VerifiedODE and MODEL_CAPS live in verified.driver.solution and
# verified.driver.batch; importable from here as before)
__all__ = ["solve", "Solution", "VerifiedODE", "Start", "MODEL_CAPS"]


def solve(
    ode,
    x0,
    t_span,
    *,
    method=None,
    params=None,
    t_eval=None,
    subdivision=None,
    h_max: float | None = None,
    h_min: float = 1e-9,
    max_steps: int = 100_000,
    max_width: float = 1e3,
    adaptive: bool = False,
    split_ratio: float = 0.01,
    max_boxes: int = 4096,
    wrap_target: float = 0.03,
    merge_slack: float | None = None,
    consistency=None,
    hooks=(),
    invariants=(),
    progress=None,
    workers=None,
    client=None,
    chunks=None,
    rechunk=None,
    start: Start | None = None,
    **method_settings,
) -> Solution:
    """Verified enclosure of all solutions of ``x' = f(x, p)`` from ``x0``.

    Parameters
    ----------
    ode : Graph or VerifiedODE
        The right-hand side (``n`` inputs, ``n`` outputs, ``p`` parameters).
    x0 : Interval (n,) or (B, n), or a list of them
        Initial boxes (their union is the initial set).
    t_span : (t0, t1) with t1 > t0
    method : None (default), a name or a :mod:`verified.methods` object
        How the sets are advanced: ``"lohner"`` (:class:`~verified.methods.Lohner`,
        first-order QR-Lohner sets), ``"second_order"``, ``"composition"`` or ``"auto"``
        (:class:`~verified.methods.Auto`, :mod:`verified.auto`: chosen from the problem;
        a piece that cannot be continued is taken up by a stronger method, then split).
        A method's settings (Taylor order, tolerance, error basis, arithmetic, ...) are
        the fields of its object, checked there: ``method=Lohner(order=8)``. None:
        ``"auto"``. What ran is ``Solution.method`` (and, for ``"auto"``,
        ``Solution.method_log``).
    **method_settings : the settings of the signature before methods were objects
        (``order``, ``tol``, ``error_basis``, ``arithmetic``, ``set_order``,
        ``set_step``, ``model_degree``, ``model_caps``, ``min_order``, ``absorb``,
        ``params_per_state``: :data:`verified.methods.METHOD_FIELDS`). Still accepted
        without ``method=``: they select the method they describe
        (:func:`verified.methods.from_settings`) at the old defaults (order 12, tol
        1e-10, first-order sets); beside ``method=`` they are an error. A run
        continued from ``start`` or on a prepared VerifiedODE also runs that way.
    params : Interval or floats, shape (p,) (or (B, p) per initial box)
    t_eval : sorted (non-decreasing) finite output times in [t0, t1] (default: t1 only;
        t0 is always included; repeated times are reported once)
    subdivision : int >= 1 or a sequence of n ints >= 1: split each initial box into a
        uniform grid (pieces per state)
    h_max, h_min : step-size bounds (h_max None: t1 - t0; 0 < h_min < h_max); a step
        that cannot be validated above h_min breaks down
    max_steps : break down after this many steps
    max_width : break down when a component's enclosure gets wider than this
    adaptive : split a set in two (along its widest direction) when the error its
        linearization injects per unit time exceeds ``split_ratio`` (1/s) times the
        width of the union of all sets, i.e. when one linearization no longer
        follows the curved reachable set closely enough
    max_boxes : adaptive splitting stops (break-down) beyond this many boxes
    merge_slack : with ``adaptive``, merge neighbouring sets when one set covering
        both is at most ``1 + merge_slack`` times as wide as their union's hull
        (default None: never). Off by default: merging turns linear parts into wrapped
        error boxes and makes enclosures wider (docs/lab/code_notes.md).
    consistency : verified.consistency.energy_test.EnergyTest or None
        Energy (Hamiltonian) consistency test, further constraints and the backward
        test (paper sec. 4): branch and prune at the first local maximum of the
        reduction area RA(t), at least every ``test_interval`` seconds. Its record
        (RA(t), H_H, H_V, every test) is returned as ``Solution.consistency``. In one
        in-process batch, a test that gains nothing steps aside for a while
        (``EnergyTest.suspend_after``, :mod:`verified.consistency.energy_cadence`).
    hooks : sequence of hook objects (:mod:`verified.driver.hooks`)
        Called before the run, after every accepted step (with the step's
        :class:`~verified.steppers.protocol.StepResult` and the sets; a hook may replace the sets
        by sets enclosing the same true states, roll the step back, or stop the run) and
        on the Solution, in this order after ``progress`` and ``consistency``; a hook's
        ``after_solve`` last, once, on the whole Solution returned (after a chunked run's
        merge and ``auto``'s attempts), which it may cut back. For example
        :class:`verified.driver.hooks.StopAfterWall` caps the wall-clock time.
    invariants : sequence of :class:`verified.consistency.conservation.Conserved` /
        :class:`~verified.consistency.conservation.NonIncreasing`
        Quantities of the ODE that are constant (``Conserved([1, 1, 1])`` for
        ``x + y + z``, or a graph / callable ``I(x, p)``) or never rise along its
        solutions. A conserved one is proven (``grad I . f`` identically 0, exactly)
        before any work, else a ValueError; a non-increasing one is checked on every
        step (``dI/dt <= 0`` over the step's enclosure). After every step the sets are
        contracted to the level the initial sets give (:mod:`verified.consistency.conservation`,
        the hook :class:`~verified.consistency.conservation.InvariantHook`, run before ``hooks``).
    progress : callable(t, t_end) or None
        Called after every accepted step (for progress bars).
    wrap_target : wrapping control: the next step is shortened when a step injected
        more than this fraction of a set's linear size through the spread of the
        Jacobian over the set (np.inf turns the control off)
    workers, client, chunks : chunked execution (:mod:`verified.execution`). With any of
        them given the initial boxes are split into ``chunks`` contiguous chunks, each
        integrated with its own step sizes, and the results merged into one Solution
        (merged tube: one box per chunk on the union of the chunks' step times).
        ``workers``: None (default) or ``"auto"``: every core of this machine when it is
        worthwhile -- dask.distributed installed (an optional extra: without it the run
        is one batch in this process, silently), more than one core, and at least
        ``verified.execution.plan.AUTO_MIN_PIECES`` (128) boxes -- else one batch in this
        process; no ``if __name__ == "__main__":`` guard is needed (the local workers
        are fresh interpreters that do not import the calling script; on Windows None
        stays in this process). ``1``: one batch in this process (``chunks=k``: k
        chunks, one after the other). An int > 1: a local Dask cluster of that many
        1-thread processes. Clusters are kept for later calls.
        ``client``: a ``distributed.Client`` or a scheduler address ``"tcp://host:port"``.
    rechunk : None, True or False (chunked runs with ``adaptive``): a chunk whose sets
        split to twice its size pauses and its sets are cut into new chunks that continue
        from that time, each with its own step sizes (:mod:`verified.execution`). None: on
        Dask workers, off in this process. ``False`` also turns off work stealing (on
        Dask, an idle worker takes over part of the chunk with the most time left).
    start : :class:`Start` or None: continue from these sets at their exact time instead
        of from ``x0`` at ``t_span[0]`` (``x0`` must be their hull boxes over the
        ``n`` states; ``params`` as the run that made them got them, or their hull).
        The Solution's first output is the start itself (``t[0] = float(t_exact)``),
        then the outputs of ``t_eval`` after it; ``tube_t[0] = float(t_exact)``. A
        consistency test starts afresh there (the sets hold the states only; the test
        appends its energy state ``h = H(x)`` at the start time).

    Returns
    -------
    Solution
        Also when the run ends early: ``status="breakdown"`` (the enclosure could not be
        continued), ``"stopped"`` (a hook asked to stop, e.g. a wall-clock cap) or
        ``"interrupted"`` (``KeyboardInterrupt`` during the integration), with the
        reason and everything verified up to ``t_reached``.

    Raises
    ------
    ValueError
        for a bad argument, before any work (see :mod:`verified.driver.solver_args`): for
        example ``tol`` or ``h_max`` not a finite number > 0, NaN in ``t_eval`` or
        ``x0``, an empty batch of boxes, or ``subdivision`` of the wrong length.
    TypeError
        when ``ode`` is not a Graph or VerifiedODE.
    """
    unknown = sorted(set(method_settings) - set(METHOD_FIELDS))
    if unknown:
        raise TypeError(f"solve() got an unexpected keyword argument {unknown[0]!r}")
    method, flags = _method_settings(method, ode, start, {k: method_settings.get(k) for k in METHOD_FIELDS})
    if invariants is not None and not (isinstance(invariants, (tuple, list)) and len(invariants) == 0):
        hooks = _with_invariants(ode, invariants, hooks)
    if isinstance(method, Auto):
        sol = solve_auto(
            solve, ode, x0, t_span, method=method, params=params, t_eval=t_eval, subdivision=subdivision,
            consistency=consistency, hooks=hooks, progress=progress, h_max=h_max, h_min=h_min,
            max_steps=max_steps, max_width=max_width, adaptive=adaptive, split_ratio=split_ratio,
            max_boxes=max_boxes, wrap_target=wrap_target, merge_slack=merge_slack, workers=workers,
            client=client, chunks=chunks, rechunk=rechunk)
        after_solve(hooks, sol)
        return sol
    order, tol, error_basis, arithmetic = flags["order"], flags["tol"], flags["error_basis"], flags["arithmetic"]
    set_order, set_step, model_degree = flags["set_order"], flags["set_step"], flags["model_degree"]
    model_caps, absorb, params_per_state = flags["model_caps"], flags["absorb"], flags["params_per_state"]
    min_order = flags["min_order"]
    sol = _solve_one_method(ode, x0, t_span, params=params, t_eval=t_eval, order=order, tol=tol,
                            subdivision=subdivision, h_max=h_max, h_min=h_min, max_steps=max_steps,
                            max_width=max_width, adaptive=adaptive, split_ratio=split_ratio, max_boxes=max_boxes,
                            wrap_target=wrap_target, merge_slack=merge_slack, error_basis=error_basis,
                            arithmetic=arithmetic, set_order=set_order, set_step=set_step,
                            model_degree=model_degree, model_caps=model_caps, min_order=min_order, absorb=absorb,
                            params_per_state=params_per_state, consistency=consistency, hooks=hooks,
                            progress=progress, workers=workers, client=client, chunks=chunks, rechunk=rechunk,
                            start=start)
    sol.method = method.describe() if method is not None else _legacy_name(flags)
    after_solve(hooks, sol)
    return sol


def _with_invariants(ode, invariants, hooks) -> list:
    """``hooks`` with the :class:`verified.consistency.conservation.InvariantHook` of ``invariants``
    first (the declarations checked and proven against the ODE here, before any work)."""
    from verified.consistency.conservation import invariant_hook
    from verified.driver.hooks import check_hooks
    from verified.driver.solver_args import check_graph

    graph = check_graph(ode.graph if isinstance(ode, VerifiedODE) else ode)
    hook = invariant_hook(invariants, graph)
    return ([hook] if hook is not None else []) + check_hooks(hooks)


#: the solver settings of the signature before methods were objects, at their old
#: defaults (a call that names any of them runs that method, as before)
_LEGACY_DEFAULTS = dict(order=12, tol=1e-10, error_basis="qr", arithmetic=None, set_order=1,
                        set_step="mean_value", model_degree=None, model_caps=None, min_order=None, absorb=False,
                        params_per_state=None)


def _legacy_name(flags: dict) -> str:
    """The method object the old settings describe, in words (``Method.describe``)."""
    fl = dict(flags)
    if fl.get("arithmetic") is None:
        fl["arithmetic"] = "interval"
    if fl["set_order"] != 1 or fl["set_step"] != "mean_value":
        fl.pop("absorb", None)
    if fl["set_step"] != "composition":
        fl.pop("model_degree", None)
        fl.pop("model_caps", None)
        fl.pop("min_order", None)
    try:
        return from_settings(**fl).describe()
    except (TypeError, ValueError):  # (a combination the driver refuses with its own message)
        return f"set_order={flags['set_order']}, set_step={flags['set_step']!r}"


def _method_settings(method, ode, start, flags: dict):
    """(the method or None, the driver's settings). ``method`` None and no method
    setting given: ``Auto()`` (the default), unless the run continues from ``start`` or
    ``ode`` is a prepared VerifiedODE (which carries an arithmetic of its own): then the
    QR-Lohner method at its defaults, as before. Method settings given beside
    ``method=`` are refused: they are the method's fields."""
    given = {k: v for k, v in flags.items() if v is not None}
    if method is not None:
        if given:
            names = ", ".join(sorted(given))
            raise ValueError(f"{names} {'is a setting' if len(given) == 1 else 'are settings'} of the method: "
                             f"pass them to it (e.g. method=verified.methods.Lohner(order=8)), not beside method=")
        method = as_method(method)
        if isinstance(method, Auto):
            if start is not None:
                raise ValueError("method 'auto' cannot continue from start=: name the method the sets were made with")
            return method, None
        return method, {**_LEGACY_DEFAULTS, **method.settings()}
    if given or start is not None or isinstance(ode, VerifiedODE):
        # (checked by the method they describe: the methods own these settings' checks)
        try:
            # (an error-basis policy object, verified.sets.bases, is the driver's own: not a method field)
            from_settings(**{k: v for k, v in given.items()
                             if not (k == "arithmetic" and isinstance(ode, VerifiedODE))
                             and not (k == "error_basis" and not isinstance(v, str))})
        except ValueError as e:  # (named by the setting, as the caller named it: no method prefix)
            msg = str(e)
            for name in METHODS:
                if msg.startswith(f"{name}: "):
                    msg = msg[len(name) + 2:]
            raise ValueError(msg) from None
        return None, {**_LEGACY_DEFAULTS, **given}
    return Auto(), None


def _solve_one_method(ode, x0, t_span, *, params, t_eval, order, tol, subdivision, h_max, h_min, max_steps,
                      max_width, adaptive, split_ratio, max_boxes, wrap_target, merge_slack, error_basis,
                      arithmetic, set_order, set_step, model_degree, model_caps, min_order, absorb, params_per_state,
                      consistency, hooks, progress, workers, client, chunks, rechunk, start) -> Solution:
    """One method's run: chunked (:mod:`verified.execution`) or one batch here."""
    asked_auto = isinstance(workers, str) and workers == "auto"
    if (workers is None or asked_auto) and client is None and chunks is None:
        # None / "auto": every core when worthwhile (verified.execution.plan.auto_workers), else one
        # batch here (which, unlike one chunk of a chunked run, can suspend an idle energy test)
        if start is not None:
            workers = 1
        elif auto_workers(ode, x0, subdivision) is None:
            workers = 1
    one_batch = client is None and chunks is None and not rechunk and (
        isinstance(workers, (int, np.integer)) and not isinstance(workers, (bool, np.bool_)) and workers == 1)
    if not one_batch:  # chunked: verified/execution/
        if start is not None:
            raise ValueError("start= continues one batch: it cannot be combined with workers, client or chunks")
        kw = {k: v for k, v in locals().items()
              if k not in ("ode", "x0", "t_span", "workers", "client", "chunks", "start", "one_batch", "asked_auto")}
        return solve_parallel(ode, x0, t_span, workers=workers, client=client, chunks=chunks, **kw)
    if rechunk is not None and not isinstance(rechunk, (bool, np.bool_)):
        raise ValueError(f"rechunk must be None, True or False, got {rechunk!r}")
    batch = dict(params=params, t_eval=t_eval, order=order, tol=tol, h_max=h_max, h_min=h_min, max_steps=max_steps,
                 max_width=max_width, adaptive=adaptive, split_ratio=split_ratio, max_boxes=max_boxes,
                 wrap_target=wrap_target, merge_slack=merge_slack, error_basis=error_basis, arithmetic=arithmetic,
                 set_order=set_order, set_step=set_step, model_degree=model_degree, model_caps=model_caps,
                 min_order=min_order, absorb=absorb, params_per_state=params_per_state, progress=progress)
    if start is None and getattr(consistency, "can_suspend", None) is not None and (
            params is None or not isinstance(params, Interval) or params.ndim == 1):
        # an energy test that may be suspended while idle (verified.consistency.energy_cadence)
        from verified.consistency.energy_cadence import solve_with_cadence
        from verified.driver.solver_args import check_graph

        n_state = check_graph(ode.graph if isinstance(ode, VerifiedODE) else ode).n_inputs
        carried = params.shape[-1] if isinstance(params, Interval) and bool(np.any(params.width() > 0)) else 0
        prepared = {}  # (the phases run on the same two graphs: their tapes are built once)

        def run(X, st, test, hks):
            return solve_batch(ode, X, t_span, subdivision=subdivision if st is None else None, consistency=test,
                               hooks=hks, start=st, prepared=prepared, **batch)
        sol = solve_with_cadence(run, x0, t_span, consistency, hooks, n_state, n_state + carried,
                                 consistency.test_interval)
    else:
        sol = solve_batch(ode, x0, t_span, subdivision=subdivision, consistency=consistency, hooks=hooks,
                          start=start, **batch)
    if asked_auto and "backend" not in sol.stats:  # ("auto" that chose this process: said as before)
        sol.stats.update(chunks=1, workers=1, backend="inprocess")
    return sol

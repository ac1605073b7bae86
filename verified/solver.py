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
size through the batched QR-Lohner step of :mod:`verified.lohner`.

A break-down is a result, not an exception: everything up to the last verified time is
returned with ``status = "breakdown"`` and the reason; so is a stop asked for by a hook
(``"stopped"``) and a ``KeyboardInterrupt`` (``"interrupted"``).

:func:`solve` is the driver loop: per step it takes the hull of the sets, asks the
step control (:mod:`verified.policies`) for a step size the stepper
(a :class:`verified.stepper.Stepper` of the run's set kind, :mod:`verified.set_kinds`) can
validate, advances the sets (:mod:`verified.sets`) to a
:class:`~verified.stepper.StepResult`, records it, and calls the hooks
(:mod:`verified.hooks`: progress, the consistency test, stop rules); adaptive splitting
and merging follow. See ``docs/architecture.md``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np

from .exact import enclose_fraction
from .graph import Graph
from .hooks import ProgressHook, RunSetup, check_hooks
from .interval import Interval, concatenate, hull, stack_hulls
from .linalg import SingularMatrixError
from .lohner import LohnerStepper
from .affine_taylor import AffineTaylorODE
from .policies import BlockBasis, MergePolicy, SplitPolicy, StepControl, WrapControl
from .sets import DoubletonSets, SetView, set_view
from .set_kinds import SetKind, set_kind, set_kind_names
from .solver_args import check_arithmetic, check_graph, check_params, check_settings, initial_boxes
from .taylor import TaylorODE
from .taylor_model import TaylorModelODE
from .variational import params_as_states, second_variational_graph, variational_graph

__all__ = ["solve", "Solution", "VerifiedODE", "Start"]


@dataclass
class Start:
    """Where a run continues from (``solve(..., start=)``; :mod:`verified.parallel` cuts
    a chunk whose sets split into pieces and continues each from here).

    sets : the run's sets (:class:`~verified.sets.DoubletonSets` or
        :class:`~verified.quadratic.QuadraticSets`, the kind of the run's ``set_order``
        and ``set_step``) at ``t_exact``, with the uncertain parameters carried as states
        when the run carries them (the same columns a run from boxes has)
    t_exact : Fraction, the exact time of the sets (a sum of float steps)
    h_limit : the wrapping control's step limit there (s; inf: none)
    split_scale : None or (N,) factors on ``split_ratio`` per component: adaptive
        splitting compares a set's injection with the width of the union of *all* sets
        of a run, so a piece cut from a wider union judges against that union (the
        piece's union times this scale) rather than its own
    """

    sets: object
    t_exact: Fraction
    h_limit: float = float("inf")
    split_scale: np.ndarray | None = None


class VerifiedODE:
    """An ODE graph prepared for verified integration (Taylor tapes built once).

    Reuse one instance across :func:`solve` calls to skip the preparation.
    """

    #: fresh symbols for the variational series in affine arithmetic (one set at a
    #: time), on variational tapes of at least DEEP_TAPE slots (a 6-dof arm's: 28-37k;
    #: small graphs have few paths for a lumped error to fan out along)
    FRESH_SLOTS = 24
    DEEP_TAPE = 10_000

    def __init__(self, graph: Graph, arithmetic: str = "interval"):
        self.graph = check_graph(graph)
        self.arithmetic = check_arithmetic(arithmetic)
        if arithmetic in ("affine", "taylor_model"):
            # fresh symbols for the errors of the solution's own coefficients only: for
            # the variational series they cost 2.5x and changed nothing measurable
            self.taylor = AffineTaylorODE(graph)
            if arithmetic == "affine":
                self.variational = AffineTaylorODE(variational_graph(graph), fresh_symbols=0)
                if self.variational._tape.op.size >= self.DEEP_TAPE:
                    # fresh symbols for the errors of the slots that create the most error
                    # in the Jacobian (AffineTaylorODE fresh_slots; one set at a time):
                    # UR5 PD payload scene, one payload piece, to T = 2 at the same CPU
                    # time, final widths 2-5x narrower; capped runs reach 3.41 s instead
                    # of 2.56 s. A fixed count, so that an inert extra state (a
                    # controller's time) changes nothing.
                    self.variational.fresh_slots = self.FRESH_SLOTS
            else:
                # the Jacobian over a set in degree-2 Taylor models (verified.taylor_model):
                # its spread is what the QR-Lohner error part grows by every step (3-link
                # arm, q0 +- 0.01: d qdd / dq 1.1x the sampled spread against 2-3.4x
                # affine). The solution's own coefficients stay affine: with fresh symbols
                # per order they are tighter at high orders than models without.
                self.variational = TaylorModelODE(variational_graph(graph))
        else:
            self.taylor = TaylorODE(graph)
            self.variational = TaylorODE(variational_graph(graph))
        self.n = graph.n_inputs
        self._augmented = None

    @property
    def second_variational(self) -> TaylorODE:
        """Interval Taylor evaluator of the second variational equations (built on first
        use: only second-order sets need it)."""
        if getattr(self, "_second", None) is None:
            self._second = TaylorODE(second_variational_graph(self.graph))
        return self._second

    def second_variational_along(self, directions: int):
        """Evaluator over a set's own forms (affine, or Taylor models with
        ``arithmetic="taylor_model"``) of the second variational equations along
        ``directions`` columns (:func:`verified.variational.second_variational_graph`),
        built on first use for each count."""
        cache = self.__dict__.setdefault("_second_along", {})
        if directions not in cache:
            graph = second_variational_graph(self.graph, directions)
            cache[directions] = (AffineTaylorODE(graph, fresh_symbols=0) if self.arithmetic == "affine"
                                 else TaylorModelODE(graph))
        return cache[directions]

    @property
    def second_variational_over_set(self):
        """Affine (or, with ``arithmetic="taylor_model"``, degree-2 Taylor model) evaluator
        of the second variational equations over a set's own forms (None for interval
        arithmetic)."""
        if self.arithmetic == "interval":
            return None
        if getattr(self, "_second_affine", None) is None:
            graph = self.second_variational.graph
            self._second_affine = (AffineTaylorODE(graph, fresh_symbols=0) if self.arithmetic == "affine"
                                   else TaylorModelODE(graph))
        return self._second_affine

    @property
    def set_models(self) -> TaylorModelODE:
        """Degree-2 Taylor-model evaluator of the right-hand side itself, for
        ``set_step="composition"`` (built on first use)."""
        if getattr(self, "_set_models", None) is None:
            self._set_models = TaylorModelODE(self.graph)
        return self._set_models

    def with_params_as_states(self) -> "VerifiedODE":
        """The same ODE with its parameters as extra constant states (built once)."""
        if self._augmented is None:
            self._augmented = VerifiedODE(params_as_states(self.graph), self.arithmetic)
        return self._augmented


@dataclass
class Solution:
    """Result of :func:`solve`.

    Attributes
    ----------
    t : ndarray (k,)
        Output times reached (the requested ``t_eval`` up to ``t_reached``).
    boxes : list of Interval (B_j, n)
        For each output time, boxes whose union encloses every solution.
    hull : Interval (k, n)
        The hull of ``boxes`` at each output time.
    tube_t : ndarray (s + 1,)
        Step boundaries ``t_0 < t_1 < ... < t_s``.
    tube : list of Interval (B_j, n)
        For each step, boxes whose union encloses every solution on ``[t_j, t_j+1]``.
    tube_hull : Interval (s, n)
    t_reached : float
        The last time up to which the enclosure is verified.
    status : "completed", "breakdown", "stopped" or "interrupted"
        "stopped": a hook asked to stop (:mod:`verified.hooks`, e.g. a wall-clock cap);
        "interrupted": ``KeyboardInterrupt`` during the integration. Everything up to
        ``t_reached`` is verified in every case.
    reason : str
        Why the integration stopped early ("" when completed).
    stats : dict
        steps, boxes, rejected steps, Taylor evaluations, ``max_boxes`` (most sets
        at any time), wall time (s); with a consistency test also ``tests``,
        ``pruned_boxes``, ``test_s`` and ``backward_s`` (seconds in the tests).
    state_names : tuple of str
    consistency : verified.consistency.ConsistencyRecord or None
        RA(t), H_H and H_V per step and a record of every test (paper Figs. 2-3).
    views : list of verified.sets.SetView or None
        For each output time (as ``boxes``), the solver's sets there in a linear view
        over their own parameters (:func:`verified.sets.set_view`, the ``n`` states), so
        that a function of the states can be enclosed over the sets rather than their
        hull boxes (:mod:`mbs.frames`); ``None`` where an output has no view (boxes a
        hook wrote), and ``[]`` when the run kept none (the parallel path).
    tube_views : list of verified.sets.SetView or None
        For each step (as ``tube``), the a-priori enclosure as a linear view over
        symbols of its own (the ``n`` states), where the stepper keeps one (the
        composition step, ``set_step="composition"``; None elsewhere, and ``[]`` when
        the run kept none): :mod:`mbs.frames` encloses the frames over the tube in it.
    chunks : list of dict or None
        A chunked run (:mod:`verified.parallel`: ``workers``, ``client`` or ``chunks``):
        per initial chunk its boxes ``(start, stop)``, status, ``t_reached``, steps,
        tube and, with re-chunking, its ``pieces``; None for one in-process batch.
    pieces : list of dict or None
        A chunk's run that was re-chunked: each piece's parent, start time and status
        (:func:`verified.parallel.solve_parallel`); None otherwise.
    """

    t: np.ndarray
    boxes: list
    hull: Interval
    tube_t: np.ndarray
    tube: list
    tube_hull: Interval
    t_reached: float
    status: str
    reason: str
    stats: dict = field(default_factory=dict)
    state_names: tuple = ()
    consistency: object = None
    views: list = field(default_factory=list)
    tube_views: list = field(default_factory=list)
    chunks: list | None = None
    pieces: list | None = None

    @property
    def success(self) -> bool:
        return self.status == "completed"

    def __repr__(self):
        return (
            f"Solution(status={self.status!r}, t_reached={self.t_reached:g}, outputs={len(self.t)}, "
            f"steps={self.stats.get('steps')}, boxes={self.stats.get('boxes')}, reason={self.reason!r})"
        )


def solve(
    ode,
    x0,
    t_span,
    *,
    params=None,
    t_eval=None,
    order: int = 12,
    tol: float = 1e-10,
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
    error_basis: str = "qr",
    arithmetic: str | None = None,
    set_order: int = 1,
    set_step: str = "mean_value",
    model_degree: int | None = None,
    model_caps: dict | None = None,
    absorb: bool = False,
    params_per_state: int | None = None,
    consistency=None,
    hooks=(),
    progress=None,
    workers=None,
    client=None,
    chunks=None,
    rechunk=None,
    start: Start | None = None,
) -> Solution:
    """Verified enclosure of all solutions of ``x' = f(x, p)`` from ``x0``.

    Parameters
    ----------
    ode : Graph or VerifiedODE
        The right-hand side (``n`` inputs, ``n`` outputs, ``p`` parameters).
    x0 : Interval (n,) or (B, n), or a list of them
        Initial boxes (their union is the initial set).
    t_span : (t0, t1) with t1 > t0
    params : Interval or floats, shape (p,) (or (B, p) per initial box)
    t_eval : sorted (non-decreasing) finite output times in [t0, t1] (default: t1 only;
        t0 is always included; repeated times are reported once)
    order : Taylor order K (default 12)
    tol : target size of the order-K term per step (absolute, state units; default
        1e-10). Defaults chosen from the double pendulum's work-precision table
        (benchmarks/bench_solver.py --work-precision): higher orders with loose
        tolerances take long steps over which the Jacobian of a wide set varies
        too much.
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
        (default None: never). Off by default: on the double pendulum merging turned
        linear parts into wrapped error boxes and made enclosures wider
        (T = 1, 64 pieces adaptive: worst ratio 1.010 unmerged, 5.9 with slack 0.1).
    error_basis : "qr" (Lohner's QR basis for the error part; default) or "auto"
        (per set and step, the QR basis or a plain box, whichever is tighter now).
        Measured on the double pendulum: "auto" gives tighter short-horizon results
        (T = 1, 256 pieces: worst ratio 1.004 vs 1.012; single box verified to 0.635
        vs 0.465) but breaks down on long horizons where "qr" does not (T = 2,
        256 pieces: break-down at 1.93 vs ratio 1.23).
    arithmetic : "interval" (default), "affine" or "taylor_model": how the Taylor coefficients of the
        solution and of the variational equations are enclosed over boxes.
        "affine" carries every coefficient as an affine form in the box's own
        symbols (:mod:`verified.affine_taylor`), so first-order dependence through a
        deep model graph (a robot's crba/rnea and elimination) is kept instead of
        compounding order by order. Measured: a 3-link arm from a box of radius 1e-6
        is verified to T = 2 (interval: break-down at 0.69 s); the double pendulum,
        256 pieces, T = 1: worst ratio 1.003 in 15 s against 1.012 in 3-4 s.
        "taylor_model": as "affine", but the Jacobian of each step over the set (the
        variational equations, and the second ones with ``set_order=2``) in degree-2
        Taylor models over the set's parameters (:mod:`verified.taylor_model`), so
        that second-order effects cancel exactly instead of being bounded operation
        by operation; its spread is what the error part grows by every step.
        Measured with ``absorb=True`` (3-link arm, q0 +- eps, order 8, tol 1e-10):
        eps = 1e-4 verified to 1.73 s against 1.04 s affine, eps = 1e-3 0.44 against
        0.38 s, eps = 0.01 0.27 against 0.17 s; UR5 (eps = 1e-3) 0.51 against
        0.46 s at ~3.5x the wall time. For few sets of deep graphs (robots): the
        models are evaluated one set at a time.
        A VerifiedODE carries its own (a different value given here is an error).
    set_order : 1 (default) or 2: the sets carried from step to step. 1: QR-Lohner
        doubletons ``c + C r0 + Q r`` (:mod:`verified.sets`). 2: the same plus a
        quadratic term in the initial box (:mod:`verified.quadratic`), so the flow's
        curvature is carried instead of wrapped every step; costs the second
        variational equations (n (n + 1) / 2 more directions). With ``adaptive=True``
        a set is split along the parameter or error component that gives it the most
        width (:meth:`verified.quadratic.QuadraticSets.split`). With a consistency test
        the energy state ``h`` is carried in the sets, they are contracted with
        ``H(x) - h = 0`` and branched and pruned in their own parameters (not the
        backward test, not ``reset_h``).
    set_step : "mean_value" (default) or "composition": how a second-order set
        (``set_order=2``) is advanced. "mean_value": by the Taylor map's derivatives at
        the centre (second variational equations) plus the Hessian's spread over the
        set (:mod:`verified.quadratic`). "composition": the Taylor map is composed with
        the set written as a Taylor model over its own parameters, and the step's
        Taylor coefficients, its a-priori enclosure and the step-size choice are taken
        over that model instead of the set's hull box (:mod:`verified.tm_flow`): no
        variational equations, higher-order effects bounded where they arise. Measured
        (``python benchmarks/bench_robots.py --only 8,9``): UR5, q0 +- 1e-3,
        ``params_per_state=12``: T = 1 verified in 55 s at ratio 1.24 ("mean_value":
        0.4 s in 150 s); the pendulum over the top from one box to T = 10 (the C++
        QR-Lohner solver breaks down at 3.67 s); the double pendulum from one box to
        1.46 s; 3-link arm +- 0.01: 0.38 s in 4 s ("mean_value": 0.38 s in 60 s).
    model_degree : 2, 3 or 4 (default 3; only with ``set_step="composition"``): the degree
        of the Taylor-model arithmetic the composition runs in
        (:mod:`verified.taylor_model`). At 3, products keep their cubic terms in the
        set's widest parameters (``verified.tm_flow.CUBIC_CAP`` of them) and bound only
        the fourth order and up, where degree 2 bounds the third (the sets themselves stay
        second order). Measured on the UR5's right-hand side over +- 0.05 in all states:
        remainder 13x smaller; UR5 q0 +- 1e-3 to T = 1: ratio 1.24 in 55 s, against a
        break-down at 0.66 s at degree 2 with the same settings. At 4, products also keep
        their quartic terms in the widest ``verified.tm_flow.QUARTIC_CAP`` parameters:
        the UR5 to T = 1 at ratio 1.21 in 51 s (855 steps against 1065), the 3-link arm
        +- 1e-3 to 1.30 s (ratio 1.25 at 1.2 s, against 1.27 s and 1.33), the double
        pendulum from one box to 1.54 s (against 1.46 s) at 1.3x the wall time.
    model_caps : dict or None (only with ``set_step="composition"``): how many of a set's
        widest symbols get quadratic, cubic, quartic and star monomials in the
        composition's Taylor models, e.g. ``{"quadratic": 32, "cubic": 16}``, and
        ``"pool"``: how many symbols the remainders born inside the model graph may claim
        (``verified.tm_flow``, module docstring; 0 turns them off); keys among
        :data:`MODEL_CAPS`, each an int >= 0, missing ones at the defaults
        (``verified.tm_flow``: quadratic 32 and cubic 16 for up to 9 states, else 16 and 6;
        quartic 4, star 6, pool 128). More monomials mean fewer terms bounded at every operation at
        a higher cost per step. Measured (q0 +- 1e-3, degree 3), 32 / 16 against 16 / 6:
        the planar 4-link chain to T = 1 at ratio 1.29 in 20 s (break-down at 0.95 s), the
        3-link arm to T = 2 at ratio 1.21 (1.35) in 2.5x the time, the double pendulum
        from one box to 1.70 s (1.54 s): hence the default for small systems; the 5-, 6-,
        7-link chains to 0.78 / 0.65 / 0.49 s (0.71 / 0.59 / 0.37 s) at 3-4x the time and
        the UR5 to T = 1 at the same ratio (1.13) in 3.7x the time.
    absorb : False (default) or True. With
        ``set_order=1``, turn the error part ``Q r`` into new parameters of the set once
        it is 10 % of the exactly carried part (:meth:`verified.sets.DoubletonSets.absorb_error`;
        at 8 parameters per state the least wide are merged into n covering ones,
        :meth:`~verified.sets.DoubletonSets.merge_params`, and absorbed parameters are
        recentred), so that
        accumulated errors are carried by the float matrix of the set instead of being
        wrapped by the interval Jacobian every step. Measured: a 3-link arm from
        ``q +- 1e-6`` to T = 2, worst ratio 16.97 -> 1.35; the double pendulum, 256
        pieces, T = 3: break-down at 2.3 s -> ratio 1.035; 1024 pieces: 1.052 -> 1.001
        at the same cost. Off by default because with affine Jacobians a 2-link arm
        under computed-torque control (tests/mbs/test_frames.py) breaks down at 0.51 s
        instead of completing 0.6 s (with ``arithmetic="taylor_model"`` it completes,
        with or without absorbing). Not supported with a consistency test,
        states appended by a hook or adaptive splitting (which then splits along
        absorbed errors without end).
        Second-order sets absorb their own way (:mod:`verified.quadratic`).
    params_per_state : int >= 1 or None: how many parameters per state a set may carry
        when it absorbs its error part (``set_order=2``, or ``absorb=True``); beyond it
        the least wide are merged. None: 4 for ``set_order=2``, 8 for ``absorb``. More
        parameters carry more of the accumulated error exactly, at a cost that grows
        with their number (second-order sets: with its square). Measured on the double
        pendulum from one box (``set_order=2``, ``error_basis="auto"``,
        ``arithmetic="taylor_model"``, order 6): 4 per state break down at 0.949 s,
        8 at 1.002 s, 12 at 1.012 s.
    consistency : verified.consistency.EnergyTest or None
        Energy (Hamiltonian) consistency test, further constraints and the backward
        test (paper sec. 4): branch and prune at the first local maximum of the
        reduction area RA(t), at least every ``test_interval`` seconds. Its record
        (RA(t), H_H, H_V, every test) is returned as ``Solution.consistency``.
    hooks : sequence of hook objects (:mod:`verified.hooks`)
        Called before the run, after every accepted step (with the step's
        :class:`~verified.stepper.StepResult` and the sets; a hook may replace the sets
        by sets enclosing the same true states, roll the step back, or stop the run) and
        on the Solution, in this order after ``progress`` and ``consistency``. For
        example :class:`verified.hooks.StopAfterWall` caps the wall-clock time.
    progress : callable(t, t_end) or None
        Called after every accepted step (for progress bars).
    wrap_target : wrapping control: the next step is shortened when a step injected
        more than this fraction of a set's linear size through the spread of the
        Jacobian over the set (np.inf turns the control off)
    workers, client, chunks : chunked execution (:mod:`verified.parallel`). With any of
        them given the initial boxes are split into ``chunks`` contiguous chunks, each
        integrated with its own step sizes, and the results merged into one Solution
        (merged tube: one box per chunk on the union of the chunks' step times).
        ``workers``: None (default) or ``"auto"``: every core of this machine when it is
        worthwhile -- dask.distributed installed (an optional extra: without it the run
        is one batch in this process, silently), more than one core, and at least
        ``verified.parallel.AUTO_MIN_PIECES`` (128) boxes -- else one batch in this
        process; no ``if __name__ == "__main__":`` guard is needed (the local workers
        are fresh interpreters that do not import the calling script; on Windows None
        stays in this process). ``1``: one batch in this process (``chunks=k``: k
        chunks, one after the other). An int > 1: a local Dask cluster of that many
        1-thread processes. Clusters are kept for later calls.
        ``client``: a ``distributed.Client`` or a scheduler address ``"tcp://host:port"``.
    rechunk : None, True or False (chunked runs with ``adaptive``): a chunk whose sets
        split to twice its size pauses and its sets are cut into new chunks that continue
        from that time, each with its own step sizes (:mod:`verified.parallel`). None: on
        Dask workers, off in this process.
    start : :class:`Start` or None: continue from these sets at their exact time instead
        of from ``x0`` at ``t_span[0]`` (``x0`` must be their hull boxes over the
        ``n`` states; ``params`` as the run that made them got them, or their hull).
        The Solution's first output is the start itself (``t[0] = float(t_exact)``),
        then the outputs of ``t_eval`` after it; ``tube_t[0] = float(t_exact)``. No
        consistency test.

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
        for a bad argument, before any work (see :mod:`verified.solver_args`): for
        example ``tol`` or ``h_max`` not a finite number > 0, NaN in ``t_eval`` or
        ``x0``, an empty batch of boxes, or ``subdivision`` of the wrong length.
    TypeError
        when ``ode`` is not a Graph or VerifiedODE.
    """
    if workers is None and client is None and chunks is None:
        # None: every core when worthwhile (verified.parallel.auto_workers), else one batch here
        if start is not None:
            workers = 1
        else:
            from .parallel import auto_workers
            if auto_workers(ode, x0, subdivision) is None:
                workers = 1
    one_batch = client is None and chunks is None and not rechunk and (
        isinstance(workers, (int, np.integer)) and not isinstance(workers, (bool, np.bool_)) and workers == 1)
    if not one_batch:  # chunked: verified/parallel.py
        if start is not None:
            raise ValueError("start= continues one batch: it cannot be combined with workers, client or chunks")
        kw = {k: v for k, v in locals().items()
              if k not in ("ode", "x0", "t_span", "workers", "client", "chunks", "start", "auto_workers",
                           "one_batch")}
        from .parallel import solve_parallel
        return solve_parallel(ode, x0, t_span, workers=workers, client=client, chunks=chunks, **kw)
    if rechunk is not None and not isinstance(rechunk, (bool, np.bool_)):
        raise ValueError(f"rechunk must be None, True or False, got {rechunk!r}")
    wall0 = time.perf_counter()
    # every argument is checked before the tapes are built and before any step
    t0, t1, outs, h_max = check_settings(
        t_span=t_span, t_eval=t_eval, order=order, tol=tol, h_max=h_max, h_min=h_min, max_steps=max_steps,
        max_width=max_width, adaptive=adaptive, split_ratio=split_ratio, max_boxes=max_boxes,
        wrap_target=wrap_target, merge_slack=merge_slack, error_basis=error_basis, progress=progress)
    orders, steps = set_kind_names()
    if set_order not in orders or isinstance(set_order, bool):
        raise ValueError(f"set_order must be {' or '.join(map(str, orders))}, got {set_order!r}")
    if set_step not in steps:
        raise ValueError(f"set_step must be {' or '.join(map(repr, steps))}, got {set_step!r}")
    if set_step == "composition" and set_order != 2:
        raise ValueError("set_step='composition' advances second-order sets: it needs set_order=2")
    if model_degree is not None:
        if isinstance(model_degree, (bool, np.bool_)) or model_degree not in (2, 3, 4):
            raise ValueError(f"model_degree must be 2, 3 or 4, got {model_degree!r}")
        if set_step != "composition":
            raise ValueError("model_degree is the degree of set_step='composition''s Taylor models: "
                             "it needs set_order=2, set_step='composition'")
    model_caps = _check_model_caps(model_caps, set_step)
    if not isinstance(absorb, (bool, np.bool_)):
        raise ValueError(f"absorb must be True or False, got {absorb!r}")
    if params_per_state is not None and (isinstance(params_per_state, (bool, np.bool_))
                                         or not isinstance(params_per_state, (int, np.integer))
                                         or params_per_state < 1):
        raise ValueError(f"params_per_state must be an int >= 1 or None, got {params_per_state!r}")
    if absorb and (set_order != 1 or adaptive or consistency is not None):
        # (a consistency test's contraction works on sets with one parameter per state;
        # adaptive splitting would split along absorbed errors without end)
        raise ValueError("absorb=True needs set_order=1, adaptive=False, no consistency test and no "
                         "states appended by a hook")
    hook_list = ([ProgressHook(progress, t1)] if progress is not None else []) \
        + check_hooks([] if consistency is None else [consistency]) + check_hooks(hooks)
    kind = set_kind(set_order, set_step)
    setup, prob, param_boxes, boxes = _setup(ode, x0, t0, h_max, params, subdivision, arithmetic, kind.sets)
    if start is not None:
        setup, boxes = _resume(setup, start, boxes, kind, consistency)
    for hook in hook_list:
        setup = hook.before_run(setup) or setup
    appended = setup.graph is not prob.graph
    if appended:  # a hook appended states (the energy test's h)
        prob = VerifiedODE(setup.graph, prob.arithmetic)
        if setup.graph.n_inputs > setup.n_steer and isinstance(error_basis, str):
            # appended states keep a box of their own in the error basis: rotated into the
            # states' basis, h's error widened the states (docs/energy_contraction.md;
            # second-order sets too: the UR5 quintic in mode ii, q3 at 2 s 0.141 -> 0.132)
            error_basis = BlockBasis(error_basis, setup.n_steer)
    if absorb and appended:
        raise ValueError("absorb=True needs set_order=1, adaptive=False, no consistency test and no "
                         "states appended by a hook")
    stepper = _stepper(kind, prob, order, setup.params, error_basis, bool(absorb), params_per_state, model_degree,
                       model_caps)
    stepper.steer = setup.n_steer
    control = StepControl(tol=tol, h_min=h_min, h_max=setup.h_max, steer=setup.n_steer)
    wrap = WrapControl(target=wrap_target, h_max=setup.h_max, steer=setup.n_steer)
    if start is not None:
        wrap.h_limit = float(start.h_limit)
        if adaptive and start.split_scale is not None:  # (an (N,) ratio: SplitPolicy broadcasts it)
            split_ratio = split_ratio * np.asarray(start.split_scale, float)
    split = SplitPolicy(split_ratio, max_boxes, tol) if adaptive else None
    merge = MergePolicy(merge_slack) if adaptive and merge_slack is not None else None
    def make_stepper(graph):  # a stepper of this run's kind for another graph (backward tests)
        return _stepper(kind, VerifiedODE(graph, prob.arithmetic), order, setup.params, error_basis,
                        model_degree=model_degree, model_caps=model_caps)

    run = _Run(setup, boxes[:, :setup.n_state], outs, make_stepper, None if start is None else start.t_exact)
    run.wrap = wrap  # (RunControl.resume_point: a run continued from here keeps this limit)
    steps = 0
    try:
        while run.next_out < outs.size:
            if steps >= max_steps:
                run.stop(f"maximum number of steps ({max_steps}) reached", "breakdown")
                break
            X = run.hull_for_step(param_boxes, setup.n_state, setup.n_steer, max_width)
            if X is None:
                break
            stepper.begin(run.sets)
            cX = stepper.coefficients(X)
            run.evaluations += 1
            if not (np.isfinite(cX.lo).all() and np.isfinite(cX.hi).all()):
                run.stop("Taylor coefficients are unbounded (an operation left its domain over the sets, e.g. a "
                         "division by an interval containing zero, or overflowed)", "breakdown")
                break
            gap_lo, gap_hi = run.gap()
            found = control.validate(stepper, X, cX, control.propose(stepper, cX, wrap.h_limit, gap_lo, gap_hi))
            run.evaluations += found.evaluations
            run.rejected += found.rejected
            if found.enclosure is None:
                run.stop(f"step size underflow: no a-priori enclosure validated with h >= {h_min:g}", "breakdown")
                break
            try:
                step = run.advance(stepper, X, found, gap_lo, gap_hi)
            except SingularMatrixError as exc:
                # a set so wide that its basis or its recentring cannot be inverted any
                # more (non-finite or singular enclosures): everything up to here stands
                run.stop(f"set update failed at t = {run.t:g}: {exc}", "breakdown")
                break
            steps += 1
            wrap.update(step)
            run.call_hooks(hook_list, step)
            if step.landed and run.sets.n_sets:
                run.record_output()
            if run.status:
                break
            if split is not None:
                run.sets, n_split, reason = split.apply(step, run.sets)
                if reason:
                    run.stop(reason, "breakdown")
                    break
                run.splits += n_split
                run.max_sets = max(run.max_sets, run.sets.n_sets)
            if merge is not None:
                run.sets, merged = merge.apply(run.sets)
                run.merges += merged
    except KeyboardInterrupt:
        # Ctrl-C: everything recorded so far is verified; return it
        run.stop(f"interrupted (KeyboardInterrupt) after t = {run.tube_t[-1]:g}", "interrupted")
    result = run.solution(setup.n_state, order, boxes.shape[0], steps, tuple(prob.graph.input_names[:setup.n_state]))
    result.stats["absorbed"] = stepper.absorbed
    result.stats["merged"] = stepper.merged
    result.stats["wall_s"] = time.perf_counter() - wall0
    for hook in hook_list:
        hook.after_run(result)  # records and statistics of the hooks
    result.stats["wall_s"] = time.perf_counter() - wall0
    return result


def _setup(ode, x0, t0, h_max, params, subdivision, arithmetic, sets_type=DoubletonSets):
    """The checked problem: ``(RunSetup, VerifiedODE, param_boxes, boxes)``. Uncertain
    parameters become constant states after the ODE's (``param_boxes`` (p,): their
    hull over the initial boxes, else None); ``boxes`` (B, N) the initial boxes, the
    initial sets ``sets_type.from_boxes`` (:mod:`verified.set_kinds`)."""
    graph = check_graph(ode.graph if isinstance(ode, VerifiedODE) else ode)
    n = graph.n_inputs
    boxes = initial_boxes(x0, n, subdivision)
    nb = boxes.shape[0]
    params = check_params(params, graph, nb, subdivision)
    if isinstance(ode, VerifiedODE):
        if arithmetic is not None and check_arithmetic(arithmetic) != ode.arithmetic:
            raise ValueError(f"arithmetic={arithmetic!r} differs from the VerifiedODE's {ode.arithmetic!r}")
        prob = ode
    else:
        prob = VerifiedODE(graph, "interval" if arithmetic is None else arithmetic)
    param_boxes = None
    if params is not None and (params.width() > 0).any():
        # Uncertain parameters become constant states, so their influence is carried
        # by the linear part of the set instead of being wrapped every step.
        prob = prob.with_params_as_states()
        p_boxes = params.broadcast_to((nb, params.shape[-1])) if params.ndim == 1 else params
        boxes = concatenate([boxes, p_boxes], axis=1)
        param_boxes = hull(p_boxes, axis=0)  # (p,): valid for every set, also after splits
        params = None
    setup = RunSetup(user_graph=graph, graph=prob.graph, n_state=n, n_steer=prob.n, params=params, t0=t0,
                     sets=sets_type.from_boxes(boxes), h_max=h_max)
    return setup, prob, param_boxes, boxes


def _resume(setup: RunSetup, start: Start, boxes: Interval, kind: SetKind, consistency):
    """``(setup, boxes)`` continuing from ``start`` (``solve(start=)``): its sets and
    time instead of the sets made from ``x0``, after the checks that they fit."""
    if consistency is not None:
        raise ValueError("start= does not continue a consistency test")
    sets = start.sets
    if not isinstance(sets, kind.sets):
        raise ValueError(f"start.sets must be {kind.sets.__name__} for this set_order/set_step, "
                         f"got {type(sets).__name__}")
    X = sets.hull()
    if X.shape != boxes.shape:
        raise ValueError(f"start.sets have hull shape {X.shape}, the run expects {boxes.shape} "
                         "(x0: their hull boxes; params: as the run that made them)")
    if not isinstance(start.t_exact, Fraction):
        raise ValueError("start.t_exact must be a Fraction (the exact time of the sets)")
    if not float(start.t_exact) >= setup.t0:
        raise ValueError(f"start.t_exact = {float(start.t_exact):g} is before t_span[0] = {setup.t0:g}")
    from dataclasses import replace
    return replace(setup, sets=sets, t0=float(start.t_exact)), X


def _state_view(view, n_sets: int, n_state: int):
    """The first ``n_state`` states of a step's tube view (copied, so that the step's
    full arrays are not kept alive for every step of a run), or None."""
    if view is None or view.n_sets != n_sets:
        return None
    A = np.ascontiguousarray(view.A.lo[:, :n_state])  # (a point matrix)
    return SetView(c=np.ascontiguousarray(view.c[:, :n_state]), A=Interval._from_bounds(A, A), R=view.R)


class _Run:
    """The state of one integration: the sets, the exact time, what has been recorded,
    and the counters. It is the :class:`~verified.hooks.RunControl` the hooks get."""

    def __init__(self, setup: RunSetup, initial: Interval, outs: np.ndarray, make_stepper, t_exact=None):
        self.sets = setup.sets
        self.outs = outs  # (k,) output times, outs[0] = t0
        self.make_stepper = make_stepper
        self.next_out = 1
        # Time is kept exactly (a sum of float steps) so that every enclosure belongs to
        # the time it is reported at; a step landing on an output time uses an interval
        # step [h] that encloses the exact remaining gap.
        self.t_exact = Fraction(setup.t0) if t_exact is None else t_exact
        self.t = setup.t0
        if t_exact is not None:  # solve(start=): the outputs after the start (setup.t0 = float(t_exact))
            while self.next_out < outs.size and Fraction(float(outs[self.next_out])) <= t_exact:
                self.next_out += 1
        self.out_t, self.out_boxes = [setup.t0], [initial]  # initial (B, n_state): the boxes at t0
        # the sets at each output time over their own parameters (Solution.views)
        self.out_views = [set_view(setup.sets, setup.n_state)] if initial.shape[0] == setup.sets.n_sets else [None]
        self.tube_t, self.tube, self.tube_views = [setup.t0], [], []
        self.step = None  # the last accepted step (after a rollback: the one before)
        self.recent = []  # the last two steps since a hook last replaced the sets (for rollback)
        self.status, self.reason = "", ""
        self.evaluations = self.rejected = self.splits = self.merges = self.pruned = 0
        self.max_sets = self.sets.n_sets
        self.n_state = setup.n_state

    # ------------------------------------------------------------------ RunControl
    def stop(self, reason: str, status: str = "stopped") -> None:
        if not self.status:  # the first reason wins
            self.status, self.reason = status, reason

    def resume_point(self) -> Start:
        return Start(sets=self.sets, t_exact=self.t_exact,
                     h_limit=math.inf if getattr(self, "wrap", None) is None else float(self.wrap.h_limit))

    def landed_on_last_output(self, step) -> bool:
        # (hooks run before the landed output is recorded: next_out still points at it)
        return bool(step.landed) and self.next_out + 1 >= self.outs.size

    def rollback(self):
        if self.step is None or self.step.landed or len(self.recent) < 2:
            return None
        last = self.recent.pop()
        self.tube.pop()
        self.tube_t.pop()
        self.tube_views.pop()
        self.sets, self.t, self.t_exact = last.previous, last.t_start, last.t_exact_start
        self.step = self.recent[-1]
        return self.step, self.sets

    # ------------------------------------------------------------------ one step
    def hull_for_step(self, param_boxes, n_state: int, n_steer: int, max_width: float):
        """The hull (B, N) of the sets to take the step's coefficients over, or None
        (a break-down: not finite or wider than ``max_width``)."""
        X = self.sets.hull()
        if param_boxes is not None:
            # Parameters never change: their true values stay in the given boxes, so
            # the hull used for the Taylor coefficients and the Jacobian may be cut
            # down to them (wrapping may have smeared error into those components).
            X[:, n_state:n_steer] = X[:, n_state:n_steer].intersect(param_boxes)
            # A set (for example one half of a split error box) whose parameter range
            # misses the parameter boxes holds no true solution: drop it.
            feasible = ~X.is_empty().any(axis=1)
            if not feasible.all():
                self.sets = self.sets.take(np.flatnonzero(feasible))
                X = X[feasible]
                self.pruned += int((~feasible).sum())
        if not (np.isfinite(X.lo).all() and np.isfinite(X.hi).all()):
            self.stop("enclosure is not finite (division by an interval containing zero?)", "breakdown")
            return None
        if (X[:, :n_steer].width() > max_width).any():  # not states a hook appended (h)
            self.stop(f"enclosure too wide (a component exceeds width {max_width:g})", "breakdown")
            return None
        return X

    def gap(self):
        """Floats ``lo <= exact time to the next output <= hi``."""
        gap = Fraction(float(self.outs[self.next_out])) - self.t_exact
        return enclose_fraction(gap)  # the exact gap between two doubles

    def advance(self, stepper, X, found, gap_lo, gap_hi):
        """Take the validated step ``found`` (:class:`~verified.policies.Validated`),
        stamp its times and record its tube; returns the StepResult."""
        E, cE = found.enclosure
        h = found.h
        landing = h == gap_hi
        if landing:
            h_step = h if gap_lo == gap_hi else Interval(gap_lo, gap_hi)  # encloses the exact gap
            t_exact = Fraction(float(self.outs[self.next_out]))
        else:
            h_step = h
            t_exact = self.t_exact + Fraction(h)
        step = stepper.step(self.sets, h_step, X, E, cE)
        self.evaluations += 2
        step.t_start, step.t_exact_start = self.t, self.t_exact
        step.t = float(self.outs[self.next_out]) if landing else float(t_exact)
        step.t_exact, step.landed = t_exact, landing
        self.sets, self.t, self.t_exact, self.step = step.sets, step.t, t_exact, step
        self.recent = (self.recent + [step])[-2:]
        self.tube.append(E[:, :self.n_state])
        self.tube_views.append(_state_view(step.tube_view, E.shape[0], self.n_state))
        self.tube_t.append(step.t)
        return step

    def call_hooks(self, hooks, step):
        for hook in hooks:
            new = hook.after_step(self.step, self.sets, self)
            if new is not None:
                self.sets = new
                self.recent = []  # no rollback past sets a hook replaced
            if self.status:
                return
        if self.sets.n_sets == 0:
            self.stop("a hook removed every set", "breakdown")
        self.max_sets = max(self.max_sets, self.sets.n_sets)

    def record_output(self):
        boxes = self.sets.hull()[:, :self.n_state]
        self.out_views.append(set_view(self.sets, self.n_state))
        self.out_t.append(self.t)
        self.out_boxes.append(boxes)
        self.next_out += 1

    # ------------------------------------------------------------------ result
    def solution(self, n: int, order: int, n_boxes: int, steps: int, state_names: tuple) -> "Solution":
        # consistent lengths also when a KeyboardInterrupt arrived between two appends
        k = min(len(self.out_t), len(self.out_boxes))
        status, reason = self.status or "completed", self.reason
        if status == "stopped" and self.next_out == self.outs.size:
            status, reason = "completed", ""  # a stop asked for after the last output changes nothing
        n_tube = min(len(self.tube), len(self.tube_t) - 1)
        out_boxes, tube, tube_t = self.out_boxes[:k], self.tube[:n_tube], self.tube_t[:n_tube + 1]
        return Solution(
            t=np.array(self.out_t[:k]),
            boxes=out_boxes,
            hull=stack_hulls(out_boxes),
            tube_t=np.array(tube_t),
            tube=tube,
            tube_hull=stack_hulls(tube) if n_tube else Interval._from_bounds(np.zeros((0, n)), np.zeros((0, n))),
            t_reached=tube_t[-1],
            status=status,
            reason=reason,
            stats=dict(
                steps=steps,
                rejected_steps=self.rejected,
                boxes=n_boxes,
                final_boxes=self.sets.n_sets,
                splits=self.splits,
                merges=self.merges,
                pruned_sets=self.pruned,
                max_boxes=self.max_sets,
                taylor_evaluations=self.evaluations,
                order=order,
            ),
            state_names=state_names,
            views=(self.out_views + [None] * k)[:k],
            tube_views=(self.tube_views + [None] * n_tube)[:n_tube],
        )


def _stepper(kind: SetKind, prob: VerifiedODE, order, params, error_basis, absorb=False,
             params_per_state=None, model_degree=None, model_caps=None) -> LohnerStepper:
    """The stepper of the run's set kind (:mod:`verified.set_kinds`) for ``prob``."""
    max_params = None if params_per_state is None else params_per_state * prob.n
    return kind.stepper(prob, order, params, error_basis, max_params, absorb, model_degree, model_caps)


#: the keys of ``solve(model_caps=...)``: the symbols with quadratic, cubic, quartic and
#: star monomials in the composition's Taylor models, and the pool of symbols for the
#: remainders born inside the graph (verified.tm_flow.TaylorModelFlowStepper)
MODEL_CAPS = ("quadratic", "cubic", "quartic", "star", "pool")


def _check_model_caps(model_caps, set_step):
    if model_caps is None:
        return None
    if set_step != "composition":
        raise ValueError("model_caps are the caps of set_step='composition''s Taylor models: "
                         "it needs set_order=2, set_step='composition'")
    if not isinstance(model_caps, dict):
        raise ValueError(f"model_caps must be a dict with keys among {', '.join(MODEL_CAPS)}, got {model_caps!r}")
    for k, v in model_caps.items():
        if k not in MODEL_CAPS:
            raise ValueError(f"model_caps: unknown key {k!r} (known: {', '.join(MODEL_CAPS)})")
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)) or v < 0:
            raise ValueError(f"model_caps[{k!r}] must be an int >= 0, got {v!r}")
    return dict(model_caps)

"""Dense-sampling oracle for reachable sets: scipy's DOP853 at tight tolerances.

The one home of the sampling oracle: of the application layer (``mbs simulate``'s and
the demo's sample checks and figure overlays, ``mbs.app.bench``), of the tests and of
the benchmarks (``tests/oracles/sampling.py`` re-exports this module). It imports
nothing from verified/ or the modeling core, so that it stays independent of the solver
it checks: the right-hand side is passed in (a closed-form numpy rhs, Pinocchio's
``aba``, an expression graph read through its ``eval_float`` only) and enclosures are
read through their ``lo``/``hi`` arrays only.

* points of a box: :func:`sample_initial_points` (its corners, random points, the
  centre; points along its edges; the tests, benchmarks and ``mbs.app.bench``),
  :func:`sample_points` (exactly ``count`` points: the centre, corners, random points;
  ``mbs simulate --samples``), :func:`line_points` (one component swept, the others at
  the centre; the demo and ``mbs.app.bench``);
* one integration per start point: :func:`dop853` (the one ``solve_ivp`` call),
  :func:`trajectories` (dense solutions), :func:`states_at` (states at given times),
  :func:`end_states` (the integrator's own states at the end);
* all start points integrated together as one system: :class:`Ensemble` (dense output),
  :func:`sample_trajectories` (the states at given times, NaN after a failure);
* the sampled hull: :func:`hull_widths`;
* containment, up to a stated slack (absolute, or relative to max(1, |x|)):
  :func:`inside_union` (points against a union of boxes), :func:`in_union` (one point),
  :func:`misses` (a solution's output and tube boxes against dense trajectories, every
  step) and :func:`count_outside` (against an :class:`Ensemble`, up to a number of
  steps);
* robot plants: :func:`pinocchio_with` (Pinocchio's model of a chain with scaled
  inertias and payloads) and :func:`plant_acceleration` (its ``aba`` with the joints'
  damping, as the library's models have it).
"""
from __future__ import annotations

import itertools
import time

import numpy as np

__all__ = ["SLACK", "sample_initial_points", "sample_points", "line_points", "dop853", "trajectories",
           "states_at", "end_states", "Ensemble", "sample_trajectories", "hull_widths", "inside_union",
           "in_union", "misses", "count_outside", "pinocchio_with", "plant_acceleration", "passive_plant"]

SLACK = 1e-9  # DOP853 at rtol = atol = 1e-12 is accurate to well below this


# --------------------------------------------------------------------------- points
def sample_initial_points(lo, hi, n_random, seed=0, edge_points=0, corner_limit=None):
    """Points (S, n) of the box [lo, hi]: every corner over its wide components (hi > lo;
    the first such component varies slowest, lo before hi), ``n_random`` uniform random
    points (``np.random.default_rng(seed)``), the centre; with ``edge_points``, then that
    many points along every edge (each wide component swept, the others at each of their
    corners; for 2-D boxes the whole boundary). ``corner_limit``: no corners (and no
    edges) when there are more wide components than that (``mbs.app.bench`` passes 10:
    at most 1024 corners)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    wide = np.flatnonzero(hi > lo)
    few = corner_limit is None or wide.size <= corner_limit
    corners = []
    for c in itertools.product(*[(0, 1)] * wide.size) if few else ():
        x = lo.copy()
        x[wide] = np.where(np.array(c, bool), hi[wide], lo[wide])
        corners.append(x)
    rng = np.random.default_rng(seed)
    pts = [np.array(corners).reshape(-1, lo.size), lo + rng.uniform(0, 1, (n_random, lo.size)) * (hi - lo),
           (lo + hi)[None] / 2]
    if edge_points and wide.size and few:
        s = np.linspace(0, 1, edge_points)
        for i in wide:  # edges along component i, at every corner of the others
            others = [j for j in wide if j != i]
            for c in itertools.product(*[(0, 1)] * (wide.size - 1)):
                base = lo.copy()
                base[others] = np.where(np.array(c, bool), hi[others], lo[others])
                e = np.repeat(base[None], edge_points, axis=0)
                e[:, i] = lo[i] + s * (hi[i] - lo[i])
                pts.append(e)
    return np.vstack(pts)


def sample_points(lo, hi, count: int, seed: int = 0) -> np.ndarray:
    """Exactly ``count`` points (count, d) of the box [lo, hi]: its centre, then corners
    (all of them if ``count`` allows, in a fixed pseudo-random order otherwise), then
    uniform random points. (The points ``mbs simulate --samples`` checks; a different
    set from :func:`sample_initial_points`, which does not fix the count.)"""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    if count <= 0:
        return np.zeros((0, lo.size))
    rng = np.random.default_rng(seed)
    pts = [(lo + hi) / 2]
    free = np.flatnonzero(hi > lo)
    n_corners = 2 ** free.size if free.size < 62 else None
    want = count - 1
    if n_corners is not None and n_corners <= want:
        codes = np.arange(n_corners)
    else:
        codes = rng.choice(n_corners, size=want, replace=False) if n_corners is not None and n_corners < 2**20 \
            else rng.integers(0, 2, size=(want, free.size))
    for c in codes[:want]:
        p = lo.copy()
        bits = c if isinstance(c, np.ndarray) else np.array([(int(c) >> k) & 1 for k in range(free.size)])
        p[free] = np.where(bits.astype(bool), hi[free], lo[free])
        pts.append(p)
    rest = count - len(pts)
    if rest > 0:
        pts.extend(lo + rng.uniform(0, 1, (rest, lo.size)) * (hi - lo))
    return np.array(pts[:count])


def line_points(lo, hi, count: int, axis: int) -> np.ndarray:
    """``count`` points (count, d): component ``axis`` evenly from lo to hi (both ends),
    the others at the centre of the box."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    pts = np.repeat(((lo + hi) / 2)[None], count, axis=0)
    pts[:, axis] = np.linspace(lo[axis], hi[axis], count)
    return pts


# --------------------------------------------------------------------------- integration
def dop853(rhs, x0, t_end, rtol=1e-12, atol=1e-12, dense=True, t_eval=None, strict=True):
    """scipy's DOP853 of x' = rhs(t, x) from x(0) = x0 to ``t_end``: the ``solve_ivp``
    result (``.sol`` the dense solution when ``dense``; ``.y[:, -1]`` the integrator's
    last state; with ``t_eval``, ``.y`` the states at those times). RuntimeError when
    the integration fails (``strict=False``: the result up to the failure)."""
    from scipy.integrate import solve_ivp  # (scipy.integrate, ~0.5 s, only when trajectories are sampled)
    s = solve_ivp(rhs, (0.0, t_end), x0, method="DOP853", rtol=rtol, atol=atol, dense_output=dense,
                  t_eval=t_eval)
    if strict and not s.success:
        raise RuntimeError(f"oracle: DOP853 failed: {s.message}")
    return s


def radau(rhs, x0, t_end, rtol=1e-12, atol=1e-20, dense=True, strict=True):
    """scipy's Radau (implicit, for stiff systems such as Robertson's) of x' = rhs(t, x),
    otherwise as :func:`dop853`."""
    from scipy.integrate import solve_ivp
    s = solve_ivp(rhs, (0.0, t_end), x0, method="Radau", rtol=rtol, atol=atol, dense_output=dense)
    if strict and not s.success:
        raise RuntimeError(f"oracle: Radau failed: {s.message}")
    return s


def _autonomous(f):
    return lambda t, x: np.asarray(f(x), dtype=float)


def _columns(f, n, S):
    """The rhs of S copies of x' = f(x) stacked as one system: ``f`` maps (n, S)
    (a column per sample) to (n, S); the state is (n, S) flattened."""
    def rhs(t, y):
        return np.asarray(f(y.reshape(n, S)), dtype=float).reshape(-1)
    return rhs


def trajectories(f, points, t_end, params=None, rtol=1e-12, atol=1e-12):
    """Dense DOP853 solutions for each initial point; f(x) -> dx (numpy floats)."""
    return [dop853(_autonomous(f), x0, t_end, rtol, atol).sol for x0 in points]


def states_at(f, points, times, rtol=1e-12, atol=1e-12):
    """States at ``times`` (from t = 0 to times[-1]) of the :func:`trajectories` from each
    initial point, an array (S, len(times), n)."""
    times = np.asarray(times, dtype=float)
    return np.array([sol(times).T for sol in trajectories(f, points, times[-1], rtol=rtol, atol=atol)])


def end_states(f, points, t_end, rtol=1e-12, atol=1e-12):
    """The integrator's own last states (S, n) at ``t_end`` (no dense output), one
    integration per initial point; f(x) -> dx."""
    return np.array([dop853(_autonomous(f), x0, t_end, rtol, atol, dense=False).y[:, -1] for x0 in points])


class Ensemble:
    """DOP853 from every sample point together, as one system (its error control over all
    of them), dense by default. ``f(X) -> X'`` on columns ``X`` (n, S).

    ``states(t)``: the sampled states (S, n) at t, or (len(t), S, n) (at t = 0 the points
    themselves); ``hull_width(t)``: the sampled hull's widths; ``final`` (S, n): the
    integrator's own states at ``t_end`` (also with ``dense=False``, where ``states`` is
    not available); ``wall``: seconds the integration took."""

    def __init__(self, f, points, t_end, names=None, rtol=1e-12, atol=1e-12, dense=True):
        self.points = np.asarray(points, float)
        S, n = self.points.shape
        self.n, self.S, self.t_end = n, S, float(t_end)
        self.names = names or [f"x{i + 1}" for i in range(n)]
        t0 = time.perf_counter()
        sol = dop853(_columns(f, n, S), self.points.T.reshape(-1), self.t_end, rtol, atol, dense=dense)
        self._sol = sol.sol
        self.final = sol.y[:, -1].reshape(n, S).T
        self.wall = time.perf_counter() - t0

    def states(self, t):
        """Sampled states at time(s) t: (S, n), or (len(t), S, n)."""
        t = np.asarray(t, float)
        if self._sol is None and np.any(t != 0):
            raise ValueError("Ensemble(dense=False): only the states at t = 0 and `final`")
        if t.ndim == 0:
            return self.points.copy() if t == 0 else self._sol(float(t)).reshape(self.n, self.S).T
        y = self._sol(t).reshape(self.n, self.S, t.size)
        y[..., t == 0] = self.points.T[..., None]
        return y.transpose(2, 1, 0)

    def hull_width(self, t):
        return hull_widths(self.states(t))


def sample_trajectories(f, points, times, params=None):
    """States at ``times`` of the float ODE ``x' = f(x)`` from each point (DOP853,
    rtol = atol = 1e-12, all points integrated as one vectorized system, the states at
    ``times`` by ``solve_ivp``'s ``t_eval``; unlike :class:`Ensemble`, a failure is not
    an error).

    ``f`` maps an (n, S) array (column per trajectory) to its (n, S) derivative, or is
    an expression graph (anything with ``eval_float(x (S, n), params)``, evaluated with
    ``params``). Returns (S, len(times), n); trajectories that fail are NaN from the
    failure on.
    """
    pts = np.asarray(points, float)
    S, n = pts.shape
    times = np.asarray(times, float)
    if hasattr(f, "eval_float"):
        graph = f
        p = None if params is None else np.asarray(params, float)

        def fv(x):
            return graph.eval_float(x.T, p).T
    else:
        fv = f

    out = np.full((S, times.size, n), np.nan)
    sol = dop853(_columns(fv, n, S), pts.T.reshape(-1), float(times.max()), dense=False, t_eval=times,
                 strict=False)
    k = sol.y.shape[1]
    out[:, :k, :] = sol.y.reshape(n, S, k).transpose(1, 2, 0)
    return out


# --------------------------------------------------------------------------- containment
def hull_widths(states):
    """Widths of the sampled hull: max - min over the samples (axis 0 of ``states``,
    (S, ..., n) -> (..., n))."""
    states = np.asarray(states, float)
    return states.max(axis=0) - states.min(axis=0)


def inside_union(x, lo, hi, slack=SLACK, relative=False):
    """Is each point of ``x`` (S, n) inside the union of the boxes [lo, hi] (arrays
    (..., n), read as (B, n)) up to ``slack`` (``relative``: slack * max(1, |x|) per
    component)? (S,) bools; for one point x (n,), one bool."""
    x = np.asarray(x, dtype=float)
    one = x.ndim == 1
    X = x[None] if one else x
    n = X.shape[-1]
    lo, hi = np.asarray(lo, float).reshape(-1, n), np.asarray(hi, float).reshape(-1, n)
    s = slack * np.maximum(1.0, np.abs(X)) if relative else np.full(X.shape, float(slack))
    ok = np.zeros(X.shape[0], dtype=bool)
    for b in range(0, lo.shape[0], 256):  # 256 boxes at a time (memory)
        l, h = lo[b:b + 256], hi[b:b + 256]
        ok |= np.any(np.all((l[None] - s[:, None] <= X[:, None]) & (X[:, None] <= h[None] + s[:, None]),
                            axis=-1), axis=1)
        if ok.all():
            break
    return bool(ok[0]) if one else ok


def in_union(x, boxes, slack=SLACK):
    """Is the point x inside the union of boxes (Interval (B, n)), up to slack?"""
    return inside_union(np.asarray(x, float).reshape(-1), boxes.lo, boxes.hi, slack)


def _first(boxes, states):
    """The boxes cut to their first ``states`` components (None: all)."""
    if states is None:
        return boxes
    return type(boxes)(boxes.lo[..., :states], boxes.hi[..., :states])


def misses(solution, sols, per_step=4, states=None):
    """List of (time, point) pairs outside the enclosure (empty list: all inside): each
    dense solution in ``sols`` at every output time and at ``per_step`` times in every
    step (its tube box). ``states``: compare only the first ``states`` components (a
    closed loop whose controller states the sampled plant does not have)."""
    bad = []
    for t, boxes in zip(solution.t, solution.boxes):
        boxes = _first(boxes, states)
        for s in sols:
            x = s(t)
            if not in_union(x, boxes):
                bad.append((t, x))
    for j, tube_boxes in enumerate(solution.tube):
        tube_boxes = _first(tube_boxes, states)
        ta, tb = solution.tube_t[j], solution.tube_t[j + 1]
        for t in np.linspace(ta, tb, per_step):
            for s in sols:
                x = s(t)
                if not in_union(x, tube_boxes):
                    bad.append((t, x))
    return bad


def count_outside(solution, ensemble, tube_checks, slack=SLACK, relative=False):
    """(outside, checked): sampled states of an :class:`Ensemble` (their first n
    components, n the solution's) outside the union of a solution's boxes at every output
    time and at the midpoints of up to ``tube_checks`` steps (evenly spread; their tube
    boxes), up to the ensemble's ``t_end``."""
    n = np.shape(solution.hull.lo)[-1]
    outside = checked = 0
    for t, boxes in zip(solution.t, solution.boxes):
        if t > ensemble.t_end:
            continue
        ok = inside_union(ensemble.states(float(t))[:, :n], boxes.lo, boxes.hi, slack, relative)
        outside += int((~ok).sum())
        checked += ok.size
    steps = len(solution.tube)
    for j in np.unique(np.linspace(0, steps - 1, min(steps, tube_checks)).astype(int)) if steps else ():
        tm = 0.5 * (solution.tube_t[j] + solution.tube_t[j + 1])
        if tm > ensemble.t_end:
            continue
        ok = inside_union(ensemble.states(tm)[:, :n], solution.tube[j].lo, solution.tube[j].hi, slack, relative)
        outside += int((~ok).sum())
        checked += ok.size
    return outside, checked


# --------------------------------------------------------------------------- plants
def plant_acceleration(model):
    """``qdd(q, qd, tau)`` of a Pinocchio model, with its joints' viscous damping
    ``-D qd`` (``model.damping``, from the URDF's ``<dynamics damping=...>``) applied.

    Pinocchio's ``aba`` leaves ``model.damping`` out, while the library's models
    include it (the ``D`` of eq. (7)): an oracle that calls ``aba`` with the controller's
    torque alone differs from the model by ``M^-1 D qd``. On the Panda (0.003 N m s/rad
    per joint) that is 2.5e-4 rad/s^2 in qdd at qd ~ 1e-3, enough to carry samples held at
    a pose by PD control outside a tight enclosure (docs/lab/code_notes.md)."""
    import pinocchio as pin  # (pinocchio only for the robot plants, not to sample a given rhs)
    data = model.createData()
    damping = np.asarray(model.damping, float).copy()

    def qdd(q, qd, tau):
        return pin.aba(model, data, q, qd, np.asarray(tau, float) - damping * qd)
    return qdd


def passive_plant(chain):
    """``f(X)``, the unforced chain's ``x' = (qd, qdd)`` on columns ``X`` (2n, S) by
    Pinocchio's ``aba`` with the joints' damping (:func:`plant_acceleration`): the
    oracle's right-hand side for :class:`Ensemble` and :func:`trajectories`."""
    acc = plant_acceleration(pinocchio_with(chain))
    n = chain.n

    def f(X):
        out = np.empty_like(X)
        out[:n] = X[n:]
        for k in range(X.shape[1]):
            out[n:, k] = acc(X[:n, k], X[n:, k], np.zeros(n))
        return out
    return f


def pinocchio_with(chain, payloads=(), scale=1.0):
    """Pinocchio's model of ``chain`` (its own URDF parser and frames) with every joint's
    inertia scaled by ``scale`` and point-mass payloads [(link, mass, com in the link
    frame)] added to the joint that carries the link: the oracle's plant."""
    import pinocchio as pin  # (see plant_acceleration)
    model = pin.Model(chain.to_pinocchio())
    for j in range(1, model.njoints):
        I = model.inertias[j]
        model.inertias[j] = pin.Inertia(I.mass * scale, I.lever, I.inertia * scale)
    for link, m, com in payloads:
        fr = model.frames[model.getFrameId(link)]
        model.inertias[fr.parentJoint] = model.inertias[fr.parentJoint] + fr.placement.act(
            pin.Inertia(m, np.asarray(com, float), np.zeros((3, 3))))
    return model

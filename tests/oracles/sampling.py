"""Dense-sampling oracle for reachable sets: scipy's DOP853 at tight tolerances.

``check_solution`` integrates many initial points of the initial box (all corners
plus random points) and asserts that every sampled state lies in the union of the
solver's boxes at each output time and in the union of the tube boxes at several
times inside every step.
"""

import itertools

import numpy as np
from scipy.integrate import solve_ivp

SLACK = 1e-9  # DOP853 at rtol = atol = 1e-12 is accurate to well below this


def sample_initial_points(lo, hi, n_random, seed=0):
    rng = np.random.default_rng(seed)
    corners = np.array(list(itertools.product(*zip(lo, hi))), dtype=float)
    rand = lo + rng.uniform(0, 1, (n_random, lo.size)) * (hi - lo)
    return np.vstack([corners, rand, (lo + hi) / 2])


def trajectories(f, points, t_end, params=None, rtol=1e-12, atol=1e-12):
    """Dense DOP853 solutions for each initial point; f(x) -> dx (numpy floats)."""
    sols = []
    for x0 in points:
        s = solve_ivp(lambda t, x: np.asarray(f(x), dtype=float), (0.0, t_end), x0, method="DOP853",
                      rtol=rtol, atol=atol, dense_output=True)
        assert s.success
        sols.append(s.sol)
    return sols


def states_at(f, points, times, rtol=1e-12, atol=1e-12):
    """States at ``times`` (from t = 0 to times[-1]) of the :func:`trajectories` from each
    initial point, an array (S, len(times), n)."""
    times = np.asarray(times, dtype=float)
    return np.array([sol(times).T for sol in trajectories(f, points, times[-1], rtol=rtol, atol=atol)])


def in_union(x, boxes, slack=SLACK):
    """Is the point x inside the union of boxes (Interval (B, n)), up to slack?"""
    return bool(np.any(np.all((boxes.lo - slack <= x) & (x <= boxes.hi + slack), axis=-1)))


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


def pinocchio_with(chain, payloads=(), scale=1.0):
    """Pinocchio's model of ``chain`` (its own URDF parser and frames) with every joint's
    inertia scaled by ``scale`` and point-mass payloads [(link, mass, com in the link
    frame)] added to the joint that carries the link: the oracle's plant."""
    import pinocchio as pin
    model = pin.Model(chain.to_pinocchio())
    for j in range(1, model.njoints):
        I = model.inertias[j]
        model.inertias[j] = pin.Inertia(I.mass * scale, I.lever, I.inertia * scale)
    for link, m, com in payloads:
        fr = model.frames[model.getFrameId(link)]
        model.inertias[fr.parentJoint] = model.inertias[fr.parentJoint] + fr.placement.act(
            pin.Inertia(m, np.asarray(com, float), np.zeros((3, 3))))
    return model

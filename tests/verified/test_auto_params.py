"""``auto`` splits the parameter box where the parameters, not the states, make the
enclosure grow (issue 45: uncertain payloads without a user picking ``param_subdivision``).

:func:`verified.auto.splitting.split_pieces` bisects a failed piece along the components, states and
uncertain parameters alike, whose end-point trajectories move the states most
(:func:`verified.auto.splitting.influences`); every part carries its own parameter row.
"""

import numpy as np
import pytest

from verified.auto import splitting
from verified.graph import trace
from verified.arith.interval import Interval
from verified.solver import solve


def _oscillator():
    """x' = p y, y' = -p x: from (1, 0), x = cos(p t), y = -sin(p t)."""
    return trace(lambda x, p: [p[0] * x[1], -p[0] * x[0]], 2, 1)


def _covered(states, params, parts: Interval, rows: Interval, slack=0.0):
    """For each (state, parameter) point: inside some part and its parameter row."""
    xs = ((states[:, None, :] >= np.asarray(parts.lo)[None] - slack)
          & (states[:, None, :] <= np.asarray(parts.hi)[None] + slack)).all(axis=2)
    ps = ((params[:, None, :] >= np.asarray(rows.lo)[None] - slack)
          & (params[:, None, :] <= np.asarray(rows.hi)[None] + slack)).all(axis=2)
    return (xs & ps).any(axis=1)


def test_a_point_state_with_a_wide_parameter_splits_the_parameter():
    parts, rows = splitting.split_pieces(_oscillator(), Interval([[1.0, 0.0]], [[1.0, 0.0]]),
                                        Interval([0.5], [1.5]), 4.0)
    assert parts.shape == (2, 2) and rows.shape == (2, 1)
    assert np.all(parts.lo == [1.0, 0.0]) and np.all(parts.hi == [1.0, 0.0])
    assert sorted(map(tuple, np.c_[rows.lo, rows.hi])) == [(0.5, 1.0), (1.0, 1.5)]


def test_states_that_matter_more_than_a_parameter_are_split_instead():
    """x' = -x + 1e-6 p over x in [0, 1], p in [0, 1]: the parameter barely moves x."""
    g = trace(lambda x, p: [-x[0] + 1e-6 * p[0]], 1, 1)
    infl = splitting.influences(g, [0.0], [1.0], [0.0], [1.0], 1.0)
    assert infl[0] == 1.0 and infl[1] < 1e-5
    parts, rows = splitting.split_pieces(g, Interval([[0.0]], [[1.0]]), Interval([0.0], [1.0]), 1.0)
    assert parts.shape == (2, 1) and np.all(rows.lo == 0.0) and np.all(rows.hi == 1.0)


def test_a_state_that_only_moves_itself_is_not_split_beside_the_parameter():
    """x' = 0 (x in [0, 1e-3]), y' = p (p in [0, 1]): x is moved only by its own tiny
    width, y by p across [0, T]. Scored against each state's own largest mover, x counted
    as much as p and every piece became four; the parameter alone is split."""
    g = trace(lambda x, p: [0.0 * x[0], p[0]], 2, 1)
    infl = splitting.influences(g, [0.0, 0.0], [1e-3, 0.0], [0.0], [1.0], 2.0)
    assert infl[2] == 1.0 and infl[0] < 1e-2
    parts, rows = splitting.split_pieces(g, Interval([[0.0, 0.0]], [[1e-3, 0.0]]), Interval([0.0], [1.0]), 2.0)
    assert parts.shape == (2, 2) and np.all(parts.hi[:, 0] == 1e-3)
    assert sorted(map(tuple, np.c_[rows.lo, rows.hi])) == [(0.0, 0.5), (0.5, 1.0)]


def test_without_uncertain_parameters_the_states_are_split_as_before():
    boxes = Interval([[0.0, 0.0], [1.0, 1.0]], [[1.0, 0.2], [2.0, 3.0]])
    parts, rows = splitting.split_pieces(_oscillator(), boxes, Interval([1.0], [1.0]), 1.0)
    assert parts.shape == splitting.split_boxes(boxes).shape
    assert np.all(parts.lo == splitting.split_boxes(boxes).lo)
    rows2 = splitting.split_pieces(_oscillator(), boxes, None, 1.0)[1]
    assert rows2 is None


@pytest.mark.parametrize("rows_2d", [False, True])
def test_the_parts_cover_every_state_and_parameter_of_the_pieces(rows_2d):
    """Random (state, parameter) points of two pieces lie in some part with its row; a
    split that loses half of its parts is caught by the same check."""
    rng = np.random.default_rng(3)
    g = trace(lambda x, p: [p[0] * x[1] + p[1], -p[0] * x[0]], 2, 2)
    boxes = Interval([[0.9, -0.1], [1.5, 0.0]], [[1.1, 0.1], [1.5, 0.05]])  # (disjoint pieces)
    params = Interval([0.5, 0.0], [1.5, 0.3])
    if rows_2d:
        params = Interval([[0.5, 0.0], [1.0, 0.1]], [[1.5, 0.3], [1.2, 0.2]])
    parts, rows = splitting.split_pieces(g, boxes, params, 3.0)
    assert parts.shape[0] == rows.shape[0] > 2
    pts, prm = [], []
    for b in range(2):
        lo, hi = np.asarray(boxes.lo[b]), np.asarray(boxes.hi[b])
        row = params if params.ndim == 1 else params[b]
        pts.append(lo + (hi - lo) * rng.random((400, 2)))
        prm.append(np.asarray(row.lo) + np.asarray(row.width()) * rng.random((400, 2)))
    pts, prm = np.concatenate(pts), np.concatenate(prm)
    assert _covered(pts, prm, parts, rows).all()
    half = slice(0, parts.shape[0] // 2)
    assert not _covered(pts, prm, parts[half], rows[half]).all()


def test_influences_are_none_where_the_trajectories_fail():
    g = trace(lambda x, p: [x[0] * x[0] * p[0]], 1, 1)  # blows up before t = 2 from x = 1
    assert splitting.influences(g, [1.0], [1.1], [1.0], [2.0], 2.0) is None
    parts, rows = splitting.split_pieces(g, Interval([[1.0]], [[1.1]]), Interval([1.0], [2.0]), 2.0)
    # (the fallback: the states' own split and the widest parameter)
    assert parts.shape == (4, 1) and rows.shape == (4, 1)


@pytest.mark.slow
def test_auto_splits_the_frequency_of_an_oscillator_and_encloses_it():
    """x' = p y, y' = -p x from the point (1, 0), p in [0.5, 1.5], T = 20: one piece breaks
    down (at 11.3 s; before parameters were split auto gave up there: a point state cannot
    be split); auto splits p and completes. Every closed-form state (x, y) = (cos p t,
    -sin p t) for 401 values of p lies in the enclosure at every output time (~6 s)."""
    t_eval = np.linspace(0.0, 20.0, 21)
    sol = solve(_oscillator(), Interval([1.0, 0.0], [1.0, 0.0]), (0.0, 20.0), params=Interval([0.5], [1.5]),
                t_eval=t_eval)
    assert sol.status == "completed", sol.reason
    assert any("split into" in e.get("next", "") for e in sol.method_log)
    p = np.linspace(0.5, 1.5, 401)
    for k, t in enumerate(np.asarray(sol.t, float)):
        states = np.c_[np.cos(p * t), -np.sin(p * t)]
        box = sol.hull[k]
        assert (states >= np.asarray(box.lo) - 1e-9).all() and (states <= np.asarray(box.hi) + 1e-9).all(), t

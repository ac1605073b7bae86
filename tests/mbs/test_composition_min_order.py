"""``Composition(min_order=k)``: each step of the composition at an order in [k, order],
chosen from the last step (verified.steppers.tm_flow.TaylorModelFlowStepper._next_order).

Under a controller the composition's growth cut, not the series' last term, sets the
steps, and the lower orders run; every step is verified at the order it ran, so the
enclosure must hold every sampled trajectory (Pinocchio's ``aba`` as the plant, the PD
law in numpy, DOP853). Where the last term sets the steps every step keeps the top
order, and the result is the fixed-order one bit for bit."""
import numpy as np
import pinocchio as pin
import pytest

from oracles.closed_loop import corners
from oracles.sampling import misses, pinocchio_with, trajectories
from mbs.control import PD
from mbs.simulate import simulate
from models import double_pendulum as dp
from models.planar import planar_chain
from verified import Interval
from verified.methods import Composition
from verified.solver import solve

Q0 = np.array([0.3, -0.5, 0.4])


def _held_arm(min_order):
    x0 = Interval(np.r_[Q0 - 1e-3, -1e-3 * np.ones(3)], np.r_[Q0 + 1e-3, 1e-3 * np.ones(3)])
    return x0, simulate(planar_chain(3), x0, 2.0, mode="i", output_dt=0.25, progress=False,
                        control=PD(bandwidth=3.0, q_ref=Q0, gravity_compensation=True),
                        method=Composition(params_per_state=12, min_order=min_order))


def _samples(x0, sol):
    """Dense trajectories from corners of ``x0`` under the run's PD law (its Kp, Kd) in
    numpy, the plant in Pinocchio, DOP853."""
    pd = sol.control.controllers[0]
    Kp, Kd = np.asarray(pd.Kp, float), np.asarray(pd.Kd, float)
    plant = pinocchio_with(planar_chain(3))
    data = plant.createData()

    def f(x):
        q, qd = x[:3], x[3:]
        tau = Kp @ (Q0 - q) - Kd @ qd + pin.computeGeneralizedGravity(plant, data, q)
        return np.r_[qd, pin.aba(plant, data, q, qd, tau)]
    return trajectories(f, corners(x0.lo, x0.hi, 6, seed=1), 2.0)


def test_lower_orders_run_under_a_controller_and_every_sample_is_enclosed():
    x0, sol = _held_arm(4)
    assert sol.status == "completed"
    by_order = sol.stats["steps_by_order"]
    assert sum(by_order.values()) == sol.stats["steps"]
    assert min(by_order) < 12 and max(by_order) <= 12 and min(by_order) >= 4, by_order
    assert not misses(sol, _samples(x0, sol), per_step=3, states=6)


def test_the_sample_check_bites(monkeypatch):
    """A step at a lowered order that loses its Lagrange remainder is caught."""
    from verified.steppers.tm_flow import TaylorModelFlowStepper

    step = TaylorModelFlowStepper.step

    def without_remainder(self, sets, h, X, E, cE):
        if self.order < self.max_order:
            cE = Interval(np.zeros_like(cE.lo), np.zeros_like(cE.hi))
        return step(self, sets, h, X, E, cE)
    monkeypatch.setattr(TaylorModelFlowStepper, "step", without_remainder)
    x0, sol = _held_arm(4)
    assert misses(sol, _samples(x0, sol), per_step=3, states=6)


def test_widths_as_at_the_fixed_order():
    """The lower orders take the same steps (the growth cut sets them) and enclosures as
    wide as the fixed order's, within 1 %."""
    _, fixed = _held_arm(None)
    _, adaptive = _held_arm(4)
    assert adaptive.stats["steps"] <= fixed.stats["steps"] + 2
    w_fixed = np.asarray(fixed.hull[-1].width(), float)
    w_adaptive = np.asarray(adaptive.hull[-1].width(), float)
    assert np.all(w_adaptive <= 1.01 * w_fixed), (w_adaptive / w_fixed)


def test_series_bound_steps_keep_the_top_order_bit_for_bit():
    """The paper's double pendulum: the series' last term sets every step, so every step
    runs at order 12 and the result is the fixed-order one, bit for bit."""
    lo, hi = dp.initial_box()
    runs = [solve(dp.rhs_graph(), Interval(lo, hi), (0.0, 0.3), t_eval=[0.15, 0.3],
                  method=Composition(min_order=k)) for k in (None, 4)]
    assert runs[1].stats["steps_by_order"] == {12: runs[1].stats["steps"]}
    for a, b in zip(runs[0].hull, runs[1].hull):
        assert np.array_equal(a.lo, b.lo) and np.array_equal(a.hi, b.hi)


def test_min_order_is_checked_by_the_method():
    for bad in (1, 13, 6.5, True, "6"):
        with pytest.raises(ValueError, match=r"composition: min_order must be an integer in \[2, 12\]"):
            Composition(min_order=bad)
    assert Composition(order=8, min_order=8).describe() == "composition(order=8, min_order=8)"
    with pytest.raises(ValueError, match=r"min_order must be an integer in \[2, 8\]"):
        Composition(order=8, min_order=9)


def test_steps_by_order_survive_the_energy_tests_phases():
    """Mode ii on a passive arm runs in phases (the energy test suspended while idle,
    verified.consistency.energy_cadence); the counts of the phases are added."""
    x0 = Interval(np.r_[Q0 - 1e-3, np.zeros(3)], np.r_[Q0 + 1e-3, np.zeros(3)])
    sol = simulate(planar_chain(3), x0, 0.5, mode="ii", progress=False,
                   method=Composition(params_per_state=12, min_order=4))
    assert sol.stats["energy_test_phases"] >= 2
    assert sum(sol.stats["steps_by_order"].values()) == sol.stats["steps"]

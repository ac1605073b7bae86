"""Closed-loop reference trajectories (moved from tests/test_control.py): Pinocchio's aba
as the plant, the control law written again in numpy floats, DOP853 at rtol = atol =
1e-12; the 2-link arm's set point and initial boxes."""
import numpy as np
import pinocchio as pin

from oracles.sampling import dop853, pinocchio_with, plant_acceleration
from verified.arith.interval import Interval

Q0 = np.array([0.5, -0.3])
E = 1e-3


def box(q0, e=E, ed=E):
    n = len(q0)
    return Interval(np.r_[q0 - e, -ed * np.ones(n)], np.r_[q0 + e, ed * np.ones(n)])


def pin_model(chain, scale=1.0, payloads=()):
    return pinocchio_with(chain, payloads, scale)


def closed_loop_trajectory(plant, law, x0, t_end):
    """DOP853 (rtol = atol = 1e-12) of qdd = aba(q, qd, law(t, q, qd) - D qd)."""
    qdd = plant_acceleration(plant)
    n = plant.nv

    def f(t, x):
        q, qd = x[:n], x[n:]
        return np.r_[qd, qdd(q, qd, law(t, q, qd))]
    return dop853(f, x0, t_end).sol


def corners(lo, hi, k, seed=0):
    rng = np.random.default_rng(seed)
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    pts = [lo, hi, 0.5 * (lo + hi)]
    signs = rng.integers(0, 2, (k, lo.size)).astype(bool)
    pts += [np.where(s, hi, lo) for s in signs]
    return pts


def ct_oracle(chain, x0s, t_end, kp=25.0, kd=10.0, scale=1.1):
    plant, nominal = pin_model(chain), pin_model(chain, scale)
    nd = nominal.createData()

    def law(t, q, qd):
        v = kp * (Q0 - q) + kd * (0 - qd)
        return pin.crba(nominal, nd, q) @ v + pin.nonLinearEffects(nominal, nd, q, qd)
    return [closed_loop_trajectory(plant, law, x0, t_end) for x0 in x0s]

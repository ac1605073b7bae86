"""Interval arithmetic on numpy arrays: rigor, tightness and batching in a few lines.

Run: python examples/interval_basics.py
     (it takes about a second: MBS_EXAMPLE_SHORT=1 and --short change nothing)
"""

from fractions import Fraction

import numpy as np

import verified.arith.interval as iv
from verified import Interval

x = Interval(-1.0, 2.0)
print("x * x      =", x * x, "  (the dependency problem)")
print("sqr(x)     =", iv.sqr(x), "  (tight)")
print("sin([1,2]) =", np.sin(Interval(1.0, 2.0)), "  (reaches the maximum at pi/2)")
print("1/[−1, 1]  =", 1.0 / Interval(-1.0, 1.0), "  (unbounded, never a wrong finite interval)")
print("0.1 as a decimal:", Interval(0.0) + Fraction("0.1"))

# A batch of 100,000 boxes in one call: the pendulum energy of paper eq. (19).
rng = np.random.default_rng(0)
q = rng.uniform(2.1, 2.2, 100_000)
qd = rng.uniform(3.1, 3.2, 100_000)
Q = Interval(q, q + 1e-3)
QD = Interval(qd, qd + 1e-3)
H = 0.5 * (iv.sqr(np.sin(Q) * QD) + iv.sqr(np.cos(Q) * QD)) + 9.81 * (1.0 - np.cos(Q))
print("energy of 100,000 boxes, widths between", H.width().min(), "and", H.width().max())

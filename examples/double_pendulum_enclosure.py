"""The paper's double pendulum (eq. 22, initial box 25) enclosed to T = 1.

Run: python examples/double_pendulum_enclosure.py [pieces]
"""

import sys

import numpy as np

from models import double_pendulum as dp
from verified.graph import trace
from verified.interval import Interval
from verified.solver import solve

pieces = int(sys.argv[1]) if len(sys.argv) > 1 else 256
lo, hi = dp.initial_box()
sol = solve(trace(dp.rhs, 4), Interval(lo, hi), (0.0, 1.0), t_eval=np.linspace(0, 1, 11),
            subdivision=[pieces, 1, 1, 1], order=12, tol=1e-9)
print(sol)
for t, h in zip(sol.t, sol.hull):
    print(f"t = {t:4.2f}  widths " + "  ".join(f"{w:.5f}" for w in h.width()))

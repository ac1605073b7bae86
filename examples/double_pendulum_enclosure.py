"""The paper's double pendulum (eq. 22, box 25) enclosed to T = 1.

Run: python examples/double_pendulum_enclosure.py [pieces]
     (MBS_EXAMPLE_SHORT=1 or --short: T = 0.3 and 16 pieces, as the tests run it)
"""

import os
import sys

import numpy as np

from models import double_pendulum as dp
from verified.graph import trace
from verified import Interval
from verified.solver import solve

argv = [a for a in sys.argv[1:] if a != "--short"]
short = "--short" in sys.argv[1:] or os.environ.get("MBS_EXAMPLE_SHORT") == "1"
T = 0.3 if short else 1.0
pieces = int(argv[0]) if argv else (16 if short else 256)
lo, hi = dp.initial_box()                      # the paper's box (25), rounded outward
sol = solve(trace(dp.rhs, 4), Interval(lo, hi), (0.0, T), t_eval=np.linspace(0, T, 11),
            subdivision=[pieces, 1, 1, 1], method="lohner")
print(sol)
for t, h in zip(sol.t, sol.hull):
    print(f"t = {t:4.2f}  widths " + "  ".join(f"{w:.5f}" for w in h.width()))

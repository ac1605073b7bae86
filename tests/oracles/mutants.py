"""Broken versions of rigorous components, shared by the tests that show an oracle
bites (each test monkeypatches one in and asserts its oracle sees the damage)."""
import numpy as np

from verified.arith.interval import Interval


def keeps_lower_quarter(contract_linear_row):
    """A ``contract_linear_row`` that keeps only the lower quarter of every component
    it narrowed: it cuts true states away."""
    def too_far(a, g0, r, rem=0.0, **k):
        R, empty = contract_linear_row(a, g0, r, rem, **k)
        narrowed = (R.width() < r.width()) & (R.hi >= R.lo)
        return Interval._from_bounds(R.lo, np.where(narrowed, R.lo + 0.25 * R.width(), R.hi)), empty
    return too_far


def narrows_output_boxes(solve, keep=0.9):
    """A ``solve`` whose output boxes are narrowed to ``keep`` of their width about
    their midpoints: sampled corners leave them."""
    def narrowed(*args, **kwargs):
        sol = solve(*args, **kwargs)
        half = 0.5 * keep
        sol.boxes = [Interval(b.mid() - half * b.width(), b.mid() + half * b.width()) for b in sol.boxes]
        return sol
    return narrowed

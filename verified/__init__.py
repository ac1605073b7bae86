"""Everything rigorous: interval arithmetic, the expression graph evaluators, the
verified ODE solver and the consistency tests. Knows nothing about robots."""

from .interval import Interval, IntervalError

__all__ = ["Interval", "IntervalError"]

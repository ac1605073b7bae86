"""Everything rigorous; knows nothing about robots. Its rooms, bottom first (each imports
only the rooms below it): ``arith`` (outward-rounded numbers), ``graph`` (the one IR),
``series`` (Taylor coefficients), ``sets``, ``steppers`` (one step for one set kind),
``driver`` (the loop of one batch), ``consistency`` (tests and contractors), ``execution``
(chunks, Dask); at the top ``solver`` (``solve``), ``methods``, ``auto``, ``spec``, ``warmup``
(docs/architecture.md)."""

from verified.arith import numba_cache as _numba_cache

_numba_cache.install()  # (before any kernel module: numba picks a function's cache locator when it is decorated)

from verified.graph import Graph, GraphBuilder, Op, Tracer, from_sympy, trace  # noqa: E402
from verified.arith.interval import Interval, IntervalError  # noqa: E402
from verified.series.taylor import TaylorODE  # noqa: E402

__all__ = ["Interval", "IntervalError", "Graph", "GraphBuilder", "Op", "Tracer", "from_sympy", "trace", "TaylorODE"]

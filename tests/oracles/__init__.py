"""Oracles and helpers shared by the tests (imported as ``oracles.<module>``; tests/ is put
on sys.path by tests/conftest.py). None of them shares code with what it judges.

* ``sampling``: dense DOP853 sampling of reachable sets (box points, one integration
  per point or all points as one system, the sampled hull) and the containment checks;
  Pinocchio models with scaled masses and payloads. Also the benchmarks' oracle
  (benchmarks/ put tests/ on sys.path).
* ``arb_oracle``: python-flint ``arb`` (256 bits) as the referee of interval operations.
* ``arb_graph``: exact (arb) evaluation of expression graphs, box sampling, random
  straight-line programs.
* ``arb_series``: exact Taylor coefficients of ODE solutions through points (arb
  series, Picard iteration) and the containment check of Taylor enclosures.
* ``graph_models``: reference models as generic-scalar code (numpy or sympy).
* ``taylor_cases``: the ODEs shared by the Taylor-coefficient tests (one per operation,
  the double pendulum, the 3-link arm, random programs and forms).
* ``closed_loop``: closed-loop reference trajectories (Pinocchio aba + a control law).
"""

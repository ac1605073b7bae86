"""Oracles and helpers shared by the tests (imported as ``oracles.<module>``; tests/ is put
on sys.path by tests/conftest.py). None of them shares code with what it judges.

* ``sampling``: dense DOP853 sampling of reachable sets and the containment checks;
  Pinocchio models with scaled masses and payloads.
* ``arb_oracle``: python-flint ``arb`` (256 bits) as the referee of interval operations.
"""

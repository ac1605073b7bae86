import os
import sys

# The shared oracles and helpers (tests/oracles: sampling, arb_oracle, ...) are imported
# as ``oracles.<module>``: put tests/ on the path. The test directories tests/verified,
# tests/mbs and tests/app have no __init__.py on purpose (they would shadow the packages
# verified and mbs); fixtures shared by one of them live in its conftest.py.
sys.path.insert(0, os.path.dirname(__file__))

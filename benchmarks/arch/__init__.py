"""ARCH-COMP "nonlinear continuous systems" (NLN) benchmarks (issue 43): ``run.py``."""

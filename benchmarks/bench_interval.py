"""Throughput of interval *, / and sin against the plain numpy float operations.

Run:  python benchmarks/bench_interval.py [--size N] [--repeat R]

Prints, for each operation, the interval time divided by numpy's float time for the
same array size, both measured side by side in this process (the machines are
shared and noisy: the ratios are what counts). Targets from issue #2: * and /
within 6x, sin within 10x.
"""

from __future__ import annotations

import argparse
import sys
import timeit

import numpy as np

import verified.arith.interval as iv
from verified.arith.interval import Interval

TARGETS = {"mul": 6.0, "div": 6.0, "sin": 10.0}


def _best_time(fn, repeat):
    fn()  # warm up (compilation, allocator)
    number = 5
    return min(timeit.repeat(fn, number=number, repeat=repeat)) / number


def measure(size=1_000_000, repeat=5, seed=0):
    """Return {op: (interval seconds, float seconds, ratio)} for arrays of ``size``."""
    rng = np.random.default_rng(seed)
    a = rng.uniform(-2.0, 2.0, size)
    c = rng.uniform(0.5, 2.0, size)
    x = Interval(a, a + 1e-3)
    y = Interval(c, c + 1e-3)
    cases = {
        "mul": (lambda: x * y, lambda: a * c),
        "div": (lambda: x / y, lambda: a / c),
        "sin": (lambda: iv.sin(x), lambda: np.sin(a)),
    }
    out = {}
    for name, (interval_op, float_op) in cases.items():
        ti = _best_time(interval_op, repeat)
        tf = _best_time(float_op, repeat)
        out[name] = (ti, tf, ti / tf)
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", type=int, default=1_000_000)
    p.add_argument("--repeat", type=int, default=5)
    args = p.parse_args(argv)
    result = measure(args.size, args.repeat)
    print(f"interval / numpy float time, arrays of {args.size:,} elements")
    print(f"{'op':<5} {'ratio':>7} {'target':>7} {'interval ms':>12} {'float ms':>9}")
    ok = True
    for name, (ti, tf, ratio) in result.items():
        ok &= ratio <= TARGETS[name]
        print(f"{name:<5} {ratio:>6.2f}x {TARGETS[name]:>6.0f}x {ti * 1e3:>12.2f} {tf * 1e3:>9.2f}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())

"""python-flint ``arb`` as the referee for interval results.

``exact_image(op, ...)`` returns arb balls enclosing the exact lower and upper end
of the image of an operation over float intervals, and ``check_enclosure`` asserts
that an interval result contains that image and is at most ``max_ulps`` wider.
"""

import math
from fractions import Fraction

import flint

flint.ctx.prec = 256
PI = flint.arb.pi()
MAXF = 1.7976931348623157e308
# pi/2 to 60 digits: for |x| < 2^64 the k of x / (pi/2) it gives is off by < 1e-40
_HALF_PI_LO = Fraction("1.57079632679489661923132169163975144209858469968755291048747")


def A(x):
    return flint.arb(float(x))


def _below(x, ball):
    """True iff the float ``x`` is certainly <= every point of ``ball``."""
    return bool(A(x) <= ball)


def _above(x, ball):
    return bool(A(x) >= ball)


def ulps_outside(x, ball, side):
    """How many ulps (of the exact value) the float bound ``x`` lies outside ``ball``."""
    m = float(ball.mid())
    u = math.ulp(m) if m != 0.0 else 5e-324
    gap = (float((ball - A(x)).mid()) if side == "lo" else float((A(x) - ball).mid()))
    return gap / u


def check_enclosure(lo, hi, exact_lo, exact_hi, max_ulps=None, what=""):
    """Assert ``[lo, hi]`` contains ``[exact_lo, exact_hi]`` (arb balls) and, if
    ``max_ulps`` is given, that each bound is at most that many ulps outside."""
    assert _below(lo, exact_lo), f"{what}: lower bound {lo!r} above exact {exact_lo}"
    assert _above(hi, exact_hi), f"{what}: upper bound {hi!r} below exact {exact_hi}"
    # Tightness is only meaningful where the exact end is a finite float.
    if max_ulps is not None and abs(float(exact_lo.mid())) <= MAXF:
        assert ulps_outside(lo, exact_lo, "lo") <= max_ulps, f"{what}: lower bound {lo!r} too loose vs {exact_lo}"
    if max_ulps is not None and abs(float(exact_hi.mid())) <= MAXF:
        assert ulps_outside(hi, exact_hi, "hi") <= max_ulps, f"{what}: upper bound {hi!r} too loose vs {exact_hi}"


def _minmax(balls):
    lo = balls[0]
    hi = balls[0]
    for b in balls[1:]:
        lo = b if bool(b.mid() < lo.mid()) else lo
        hi = b if bool(b.mid() > hi.mid()) else hi
    return lo, hi


def image_binary(op, a, b, c, d):
    """Exact image ends of ``[a, b] op [c, d]`` for op in + - * / (divisor without 0)."""
    a, b, c, d = A(a), A(b), A(c), A(d)
    if op == "add":
        return a + c, b + d
    if op == "sub":
        return a - d, b - c
    if op == "mul":
        return _minmax([a * c, a * d, b * c, b * d])
    if op == "div":
        return _minmax([a / c, a / d, b / c, b / d])
    raise ValueError(op)


def critical_points(a, b, offset, period_half_steps):
    """Points ``offset + k*pi/2`` (k in the given parity) certainly inside [a, b].

    Returns None if any candidate cannot be decided (the caller skips the example).
    """
    # a / (pi/2) in floats is off by ~|a| 1e-16 (73 at 2^60): bracket k exactly instead
    kmin = math.floor(Fraction(a) / _HALF_PI_LO) - 2
    kmax = math.ceil(Fraction(b) / _HALF_PI_LO) + 2
    inside = []
    for k in range(kmin, kmax + 1):
        if (k - offset) % period_half_steps:
            continue
        p = PI * k / 2
        if bool(A(a) < p) and bool(p < A(b)):
            inside.append(k)
        elif bool(p < A(a)) or bool(p > A(b)):
            continue
        else:
            return None
    return inside


def _clip_unit(ball):
    """sin and cos lie in [-1, 1]: a ball straddling +-1 (such as cos(1e-300), which
    is 1 - 5e-601) stands for the float +-1 so bounds of exactly +-1 are accepted."""
    if bool(ball.upper() > 1):
        return flint.arb(1)
    if bool(ball.lower() < -1):
        return flint.arb(-1)
    return ball


def image_periodic(fn, a, b):
    """Exact image ends of sin or cos over [a, b] (width < 20); None if undecidable."""
    vals = [_clip_unit(getattr(A(a), fn)()), _clip_unit(getattr(A(b), fn)())]
    # sin has maxima at k = 1 mod 4 and minima at k = 3 mod 4 (k in units of pi/2);
    # cos has maxima at k = 0 mod 4 and minima at k = 2 mod 4.
    top, bottom = (1, 3) if fn == "sin" else (0, 2)
    maxima = critical_points(a, b, top, 4)
    minima = critical_points(a, b, bottom, 4)
    if maxima is None or minima is None:
        return None
    if maxima:
        vals.append(flint.arb(1))
    if minima:
        vals.append(flint.arb(-1))
    return _minmax(vals)

"""Exact numbers as tight double enclosures: the one place that rounds outward.

A rational ``q`` (``int``, ``Fraction``) lies between two neighbouring doubles; a
number ``a + b pi`` (``a``, ``b`` rational, ``b != 0``) is irrational and lies strictly
between the doubles either side of its nearest one. Every module that turns an exact
number into floats calls these functions instead of repeating the rule:

- :mod:`verified.arith.interval` (``Fraction``, ``Decimal`` and big-int operands),
- :mod:`verified.graph.ir` (constant nodes, :func:`verified.graph.enclose_rational`),
- :mod:`verified.graph.sympy_convert` (sympy numbers: multiples of pi by :func:`pi_multiple_enclosure`,
  other constants such as ``E`` by :func:`enclose_approximation` of a 40-digit evalf),
- :mod:`verified.consistency.contractor` (pi for the periodic projections),
- :mod:`verified.steppers.protocol` and :mod:`verified.solver` (the exact step times and the gap
  to the next output time),
- :mod:`mbs.app.scene` (numbers and ``pi`` expressions in scene files, read by
  :func:`parse_pi_expression`),
- :mod:`models.pendulum`, :mod:`models.double_pendulum` (the paper's initial boxes).

Rounding is never to nearest: ``lo <= exact <= hi`` always, with ``lo == hi`` only when
the exact number is a double.
"""
from __future__ import annotations

import ast
import math
from fractions import Fraction

__all__ = ["enclose_fraction", "enclose_pi_multiple", "pi_multiple_enclosure", "enclose_approximation",
           "parse_pi_expression", "ExpressionError"]

#: working precision (bits) of the ``a + b pi`` evaluation, raised only when 200 bits
#: cannot tell on which side of its nearest double the number lies
PI_PRECISION_BITS = 200


def enclose_fraction(q: Fraction | int) -> tuple[float, float]:
    """``(lo, hi)``: the tightest doubles with ``lo <= q <= hi`` (``lo == hi == q``
    when ``q`` is a double).

    ``q``: an ``int`` or ``Fraction`` (exact). Raises ``OverflowError`` when ``q``
    rounds beyond the double range (``float(q)`` does); the caller words the error.
    A ``q`` just above the largest double gives ``hi = inf``: callers that need finite
    bounds check for it."""
    f = float(q)  # correctly rounded for int and Fraction
    exact = Fraction(f)
    lo = f if exact <= q else math.nextafter(f, -math.inf)
    hi = f if exact >= q else math.nextafter(f, math.inf)
    return lo, hi


def _mpf_fraction(v) -> Fraction:
    """The exact rational value of an mpmath mpf."""
    man, exp = v.man_exp
    r = Fraction(man) * Fraction(2) ** exp
    return -r if v < 0 else r


def _pi_multiple_nearest(a: Fraction, b: Fraction) -> tuple[float, int]:
    """``(f, side)`` for ``x = a + b pi``, ``b != 0``: ``f`` the double nearest to ``x``
    (nearest to an evaluation within ``tol`` of ``x``) and ``side`` the sign of ``x - f``
    (``x`` is irrational, so it is never ``f``). The evaluation runs at
    :data:`PI_PRECISION_BITS` and, only if that cannot tell the side, at more bits."""
    import mpmath  # (import here: sympy's dependency; intervals do without it)

    bits = PI_PRECISION_BITS
    while True:
        with mpmath.workprec(bits):
            v = mpmath.mpf(a.numerator) / a.denominator + mpmath.mpf(b.numerator) / b.denominator * mpmath.pi
        r = _mpf_fraction(v)
        # five roundings (a, b, pi, the product, the sum), each within 2^-bits of its
        # result: |x - r| <= (2|a| + 16|b|) 2^-bits, whatever the cancellation in a + b pi
        tol = (2 * abs(a) + 16 * abs(b)) / Fraction(2) ** bits
        f = float(r)
        if not math.isfinite(f):
            raise OverflowError(f"{a} + {b} pi is outside the double range")
        gap = r - Fraction(f)
        if abs(gap) > tol:
            return f, (1 if gap > 0 else -1)
        bits *= 2
        if bits > 1 << 16:  # pragma: no cover - would need a + b pi within 2^-65000 of a double
            raise ArithmeticError(f"cannot place {a} + {b} pi beside a double")


def enclose_pi_multiple(a: Fraction, b: Fraction) -> tuple[float, float]:
    """``(lo, hi)`` doubles around ``a + b pi`` (``a``, ``b`` rational).

    ``b == 0``: :func:`enclose_fraction` of ``a``. Otherwise the value is irrational,
    so it is never a double: the nearest double and one ulp either side enclose it
    (two ulps wide; :func:`pi_multiple_enclosure` gives the one-ulp enclosure)."""
    a, b = Fraction(a), Fraction(b)
    if b == 0:
        return enclose_fraction(a)
    f, _ = _pi_multiple_nearest(a, b)
    return math.nextafter(f, -math.inf), math.nextafter(f, math.inf)


def pi_multiple_enclosure(a: Fraction, b: Fraction) -> tuple[float, float, float]:
    """``(lo, hi, value)``: the tightest doubles ``lo <= a + b pi <= hi`` and ``value``
    the nearest double (a constant node's enclosure, as :func:`enclose_approximation`
    gives). ``b != 0``: one ulp wide, ``value`` one of the bounds; ``b == 0``: the
    enclosure of the rational ``a``. E.g. pi itself: ``(math.pi, nextafter(math.pi,
    inf), math.pi)``, float pi being below pi."""
    a, b = Fraction(a), Fraction(b)
    if b == 0:
        lo, hi = enclose_fraction(a)
        return lo, hi, float(a)
    f, side = _pi_multiple_nearest(a, b)
    if side > 0:
        return f, math.nextafter(f, math.inf), f
    return math.nextafter(f, -math.inf), f, f


def enclose_approximation(r: Fraction, rel_err: Fraction) -> tuple[float, float, float]:
    """Enclosure ``(lo, hi, value)`` of an exact real known as ``r`` with ``|exact - r| <= rel_err*|r|``.

    ``rel_err`` must be far below double precision (e.g. 1e-35). The result has width
    at most one or two ulps: the nearest double to ``r`` is one bound whenever the exact
    value is provably on one side of it.
    """
    if r == 0:
        raise ValueError("cannot enclose a value approximated by 0 with a relative error bound")
    f = float(r)
    if not math.isfinite(f):
        raise ValueError(f"constant {float(r)!r} is outside the double range")
    tol = abs(r) * rel_err
    exact_f = Fraction(f)
    if exact_f < r - tol:  # exact value > f
        return f, math.nextafter(f, math.inf), f
    if exact_f > r + tol:  # exact value < f
        return math.nextafter(f, -math.inf), f, f
    return math.nextafter(f, -math.inf), math.nextafter(f, math.inf), f


# ------------------------------------------------------------------ exact expressions
class ExpressionError(ValueError):
    """An expression that :func:`parse_pi_expression` refuses; the message quotes it."""


def parse_pi_expression(text: str) -> tuple[Fraction, Fraction]:
    """Exact value ``a + b pi`` of an expression string, as ``(a, b)`` (Fractions).

    Allowed: decimal numbers (each its literal's exact value: ``"0.1"`` is 1/10, never a
    float), ``pi``, ``+ - * /``, unary minus and parentheses, linear in ``pi``
    (``"0.99*3*pi/4"``, ``"-11*pi/20"``, ``"43/100"``). Anything else raises
    :class:`ExpressionError`. :func:`enclose_pi_multiple` encloses the result."""
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError:
        raise ExpressionError(f"cannot parse expression {text!r}") from None

    def ev(node):
        if isinstance(node, ast.Expression):
            return ev(node.body)
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) \
                and not isinstance(node.value, bool):
            seg = ast.get_source_segment(text.strip(), node)
            try:
                return (Fraction(seg.replace("_", "")), Fraction(0))
            except ValueError:  # (0x10, 0o7, 0b1: Python literals, not decimal numbers)
                raise ExpressionError(f"{text!r}: {seg!r} is not a decimal number") from None
        if isinstance(node, ast.Name) and node.id == "pi":
            return (Fraction(0), Fraction(1))
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            a, b = ev(node.operand)
            return (-a, -b) if isinstance(node.op, ast.USub) else (a, b)
        if isinstance(node, ast.BinOp):
            (a1, b1), (a2, b2) = ev(node.left), ev(node.right)
            if isinstance(node.op, ast.Add):
                return a1 + a2, b1 + b2
            if isinstance(node.op, ast.Sub):
                return a1 - a2, b1 - b2
            if isinstance(node.op, ast.Mult):
                if b1 and b2:
                    raise ExpressionError(f"{text!r} is not linear in pi")
                return a1 * a2, a1 * b2 + b1 * a2
            if isinstance(node.op, ast.Div):
                if b2:
                    raise ExpressionError(f"{text!r} divides by a multiple of pi")
                if a2 == 0:
                    raise ExpressionError(f"{text!r} divides by zero")
                return a1 / a2, b1 / a2
        raise ExpressionError(f"{text!r}: only numbers, pi, + - * / and parentheses are allowed")

    return ev(tree)

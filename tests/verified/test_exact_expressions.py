"""verified.arith.exact.parse_pi_expression: exact ``a + b pi`` of the expression strings that
scene files use (moved here from tests/app/test_scene.py with the parser, which was
mbs.app.scene._eval_expr; the scene's enclose_number wraps it)."""
import math
from fractions import Fraction

import pytest

from verified.arith.exact import ExpressionError, enclose_pi_multiple, parse_pi_expression


def test_decimal_literals_are_exact():
    assert parse_pi_expression("0.43") == (Fraction(43, 100), 0)
    assert parse_pi_expression("1/4") == (Fraction(1, 4), 0)
    assert parse_pi_expression("1_000 + 2e-3") == (Fraction(1000002, 1000), 0)
    assert parse_pi_expression(" -(1 - 0.5) ") == (Fraction(-1, 2), 0)


def test_pi_expressions_are_exact_and_enclosed():
    assert parse_pi_expression("0.99*3*pi/4") == (0, Fraction(99, 100) * Fraction(3, 4))
    assert parse_pi_expression("1 + pi/3") == (1, Fraction(1, 3))
    assert parse_pi_expression("-11*pi/20") == (0, Fraction(-11, 20))
    # compare with 60-digit mpmath
    import mpmath
    mpmath.mp.dps = 60
    for text, val in (("pi", mpmath.pi), ("-11*pi/20", -11 * mpmath.pi / 20),
                      ("0.99*3*pi/4", mpmath.mpf(99) / 100 * 3 * mpmath.pi / 4), ("1 + pi/3", 1 + mpmath.pi / 3)):
        lo, hi = enclose_pi_multiple(*parse_pi_expression(text))
        assert mpmath.mpf(lo) < val < mpmath.mpf(hi)
        assert hi == math.nextafter(math.nextafter(lo, math.inf), math.inf)


@pytest.mark.parametrize("text, words", [("pi*pi", "not linear in pi"), ("1/pi", "divides by a multiple of pi"),
                                         ("1/0", "divides by zero"), ("sin(1)", "only numbers"),
                                         ("2**3", "only numbers"), ("import os", "cannot parse"),
                                         ("x1", "only numbers"), ("1 +", "cannot parse"), ("True", "only numbers"),
                                         ("0x10", "not a decimal number"), ("2*0b1", "not a decimal number")])
def test_bad_expressions(text, words):
    with pytest.raises(ExpressionError) as e:
        parse_pi_expression(text)
    assert words in str(e.value) and repr(text) in str(e.value)
    assert isinstance(e.value, ValueError)

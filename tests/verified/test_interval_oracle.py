"""Interval operations against python-flint's rigorous arb arithmetic.

Every result must contain the exact image of its operands (computed with arb at
256 bits); the basic operations must also be at most a few ulps wider.
"""

import math

import flint
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st

import verified.arith.interval as iv
from verified.arith.interval import Interval
from oracles.arb_oracle import A, check_enclosure, image_binary, image_periodic

BASIC_ULPS = 4  # + - * / sqrt results may be this many ulps outside the exact image
TRANS_ULPS = 24  # transcendental functions: libm error plus our 8-ulp allowance

SETTINGS = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])

finite = st.floats(min_value=-1e300, max_value=1e300, allow_nan=False, allow_infinity=False)
moderate = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False)
tiny = st.floats(min_value=-1e-300, max_value=1e-300, allow_nan=False)  # includes subnormals
near_half_pi = st.builds(
    lambda k, e: k * math.pi / 2 + e, st.integers(-200, 200), st.floats(-1e-9, 1e-9)
)
huge = st.floats(min_value=1e14, max_value=1e16)
any_float = st.one_of(finite, moderate, tiny, near_half_pi)


@st.composite
def intervals(draw, elements=any_float, max_width=None):
    a = draw(elements)
    if max_width is None:
        b = draw(elements)
    else:
        b = a + draw(st.floats(0, max_width))
    lo, hi = min(a, b), max(a, b)
    assume(math.isfinite(lo) and math.isfinite(hi))
    return lo, hi


def one(op, *ivs):
    """Apply an Interval operation to scalar intervals given as (lo, hi) pairs."""
    res = op(*[Interval(lo, hi) for lo, hi in ivs])
    return float(res.lo), float(res.hi)


# ------------------------------------------------------------------ basic ops
@SETTINGS
@given(intervals(), intervals())
@example((0.1, 0.1), (3.0, 3.0))
@example((1e-320, 2e-320), (1e-320, 3e-320))  # subnormal widths
def test_add_sub_mul_contain_exact_image_and_are_tight(x, y):
    for name, op in (("add", lambda p, q: p + q), ("sub", lambda p, q: p - q), ("mul", lambda p, q: p * q)):
        with np.errstate(over="ignore"):
            lo, hi = one(op, x, y)
        elo, ehi = image_binary(name, *x, *y)
        overflow = abs(float(elo.mid())) > 1e308 or abs(float(ehi.mid())) > 1e308
        check_enclosure(lo, hi, elo, ehi, None if overflow else BASIC_ULPS, what=f"{name} {x} {y}")


@SETTINGS
@given(intervals(), intervals())
def test_div_contains_exact_image(x, y):
    assume(y[0] > 0 or y[1] < 0)
    lo, hi = one(lambda p, q: p / q, x, y)
    elo, ehi = image_binary("div", *x, *y)
    overflow = abs(float(elo.mid())) > 1e308 or abs(float(ehi.mid())) > 1e308
    check_enclosure(lo, hi, elo, ehi, None if overflow else BASIC_ULPS, what=f"div {x} {y}")


@pytest.mark.parametrize(
    "x, y, expected",
    [
        ((1.0, 2.0), (0.0, 1.0), (1.0, math.inf)),
        ((1.0, 2.0), (-1.0, 0.0), (-math.inf, -1.0)),
        ((-2.0, -1.0), (0.0, 1.0), (-math.inf, -1.0)),
        ((1.0, 2.0), (-1.0, 1.0), (-math.inf, math.inf)),
        ((-1.0, 2.0), (0.0, 1.0), (-math.inf, math.inf)),
        ((0.0, 2.0), (0.0, 1.0), (0.0, math.inf)),
        ((0.0, 0.0), (-1.0, 1.0), (0.0, 0.0)),
    ],
)
def test_division_by_interval_containing_zero_is_unbounded_hull(x, y, expected):
    lo, hi = one(lambda p, q: p / q, x, y)
    assert lo <= expected[0] and hi >= expected[1]
    # never a wrong finite interval: the unbounded side stays unbounded
    if expected[0] == -math.inf:
        assert lo == -math.inf
    if expected[1] == math.inf:
        assert hi == math.inf
    # and the bounded side is within rounding of the exact end
    if math.isfinite(expected[0]):
        assert expected[0] - lo <= 4 * math.ulp(max(abs(expected[0]), 1e-300))


def test_division_by_zero_point_is_empty():
    assert (Interval(1.0, 2.0) / Interval(0.0)).is_empty()


@SETTINGS
@given(intervals())
@example((-1.0, 2.0))
def test_sqr_is_tight_and_encloses(x):
    lo, hi = one(iv.sqr, x)
    a, b = A(x[0]), A(x[1])
    cands = [a * a, b * b]
    elo = flint.arb(0) if x[0] <= 0 <= x[1] else min(cands, key=lambda v: float(v.mid()))
    ehi = max(cands, key=lambda v: float(v.mid()))
    check_enclosure(lo, hi, elo, ehi, BASIC_ULPS if float(ehi.mid()) < 1e308 else None, what=f"sqr {x}")
    assert lo >= 0.0


def test_square_of_minus_one_two_is_zero_four():
    r = iv.sqr(Interval(-1.0, 2.0))
    assert r.lo == 0.0 and 4.0 <= r.hi <= 4.0 + 4 * math.ulp(4.0)
    r2 = Interval(-1.0, 2.0) * Interval(-1.0, 2.0)  # the dependency problem: x*x is wider
    assert r2.lo <= -2.0


@SETTINGS
@given(intervals(st.floats(-50, 50)), st.integers(-7, 9))
def test_integer_powers(x, n):
    assume(n >= 0 or not (x[0] <= 0 <= x[1]))
    lo, hi = one(lambda p: iv.ipow(p, n), x)
    a, b = A(x[0]), A(x[1])
    cands = [a**n, b**n]
    if n > 0 and n % 2 == 0 and x[0] <= 0 <= x[1]:
        cands.append(flint.arb(0))
    elo = min(cands, key=lambda v: float(v.mid()))
    ehi = max(cands, key=lambda v: float(v.mid()))
    check_enclosure(lo, hi, elo, ehi, 4 * abs(n) + 4, what=f"ipow {x} {n}")


def test_dependency_problem_is_visible():
    x = Interval(0.0, 1.0)
    d = x - x
    assert d.lo <= -1.0 and d.hi >= 1.0  # x - x is not [0, 0] for a wide x


@SETTINGS
@given(intervals(st.floats(0, 1e300)))
def test_sqrt(x):
    lo, hi = one(iv.sqrt, x)
    check_enclosure(lo, hi, A(x[0]).sqrt(), A(x[1]).sqrt(), BASIC_ULPS, what=f"sqrt {x}")


def test_sqrt_and_log_are_restricted_to_their_domain():
    r = iv.sqrt(Interval(-4.0, 4.0))
    assert r.lo == 0.0 and 2.0 <= r.hi <= 2.0 + 4 * math.ulp(2.0)
    assert iv.sqrt(Interval(-4.0, -1.0)).is_empty()
    r = iv.log(Interval(0.0, 1.0))
    assert r.lo == -math.inf and r.hi >= 0.0
    assert iv.log(Interval(-2.0, -1.0)).is_empty()


# ---------------------------------------------------------- transcendentals
@SETTINGS
@given(intervals(st.floats(-745, 709.7)))
def test_exp(x):
    lo, hi = one(iv.exp, x)
    check_enclosure(lo, hi, A(x[0]).exp(), A(x[1]).exp(), TRANS_ULPS, what=f"exp {x}")


def test_exp_overflow_gives_infinite_upper_bound_and_finite_lower():
    r = iv.exp(Interval(700.0, 710.0))
    assert r.hi == math.inf and math.isfinite(r.lo) and bool(A(r.lo) <= A(700.0).exp())
    r = iv.exp(Interval(710.0, 720.0))
    assert r.lo == np.finfo(float).max and r.hi == math.inf


@SETTINGS
@given(intervals(st.floats(1e-300, 1e300)))
def test_log(x):
    lo, hi = one(iv.log, x)
    check_enclosure(lo, hi, A(x[0]).log(), A(x[1]).log(), TRANS_ULPS, what=f"log {x}")


@SETTINGS
@given(intervals(any_float))
def test_atan(x):
    lo, hi = one(iv.atan, x)
    check_enclosure(lo, hi, A(x[0]).atan(), A(x[1]).atan(), TRANS_ULPS, what=f"atan {x}")


@SETTINGS
@given(st.sampled_from(["sin", "cos"]), intervals(st.one_of(near_half_pi, moderate, huge), max_width=8.0))
@example("sin", (1.0, 2.0))
@example("cos", (-0.1, 0.1))
@example("sin", (1e15, 1e15))
@example("cos", (1e15, 1e15))
@example("sin", (math.pi / 2, math.pi / 2))
@example("cos", (math.pi, math.pi))
def test_sin_cos_reach_interior_extrema(fn, x):
    img = image_periodic(fn, *x)
    assume(img is not None)
    lo, hi = one(getattr(iv, fn), x)
    check_enclosure(lo, hi, img[0], img[1], TRANS_ULPS, what=f"{fn} {x}")


@SETTINGS
@given(intervals(st.one_of(near_half_pi, moderate, huge), max_width=3.0))
def test_tan(x):
    lo, hi = one(iv.tan, x)
    # a pole (pi/2 + k pi) inside or undecidable -> must be unbounded
    poles = None
    from oracles.arb_oracle import critical_points

    poles = critical_points(x[0], x[1], 1, 2)
    assume(poles is not None)
    if poles:
        assert lo == -math.inf and hi == math.inf
    else:
        assume(math.isfinite(lo) and math.isfinite(hi))
        check_enclosure(lo, hi, A(x[0]).tan(), A(x[1]).tan(), None, what=f"tan {x}")


def test_sin_huge_argument_point_is_tight():
    r = iv.sin(Interval(1e15))
    exact = A(1e15).sin()
    check_enclosure(float(r.lo), float(r.hi), exact, exact, TRANS_ULPS, what="sin(1e15)")


def test_unbounded_arguments():
    big = Interval(-math.inf, math.inf, allow_unbounded=True)
    assert iv.sin(big).equals(Interval(-1.0, 1.0))
    assert iv.cos(Interval(0.0, math.inf, allow_unbounded=True)).equals(Interval(-1.0, 1.0))
    r = iv.atan(big)
    assert r.lo <= -math.pi / 2 and r.hi >= math.pi / 2 and r.hi < 1.5708
    r = iv.exp(Interval(-math.inf, 0.0, allow_unbounded=True))
    assert r.lo == 0.0 and r.hi >= 1.0


# ------------------------------------------------------------ array behaviour
def test_batched_results_equal_elementwise_results():
    rng = np.random.default_rng(1)
    lo = rng.uniform(-5, 5, (40, 3))
    x = Interval(lo, lo + rng.uniform(0, 2, lo.shape))
    y = Interval(lo.T[0][:, None] + 7.0, lo.T[0][:, None] + 8.0)  # broadcasts (40, 1)
    for op in (lambda p, q: p * q, lambda p, q: p / q, lambda p, q: p - q, lambda p, q: iv.sin(p) + q):
        batch = op(x, y)
        assert batch.shape == (40, 3)
        for i in (0, 17, 39):
            for j in range(3):
                single = op(x[i, j], y[i, 0])
                assert single.lo == batch.lo[i, j] and single.hi == batch.hi[i, j]


def test_numpy_ufuncs_dispatch_to_intervals():
    x = Interval([0.5, 1.0], [0.6, 2.0])
    assert isinstance(np.sin(x), Interval)
    assert np.sin(x).equals(iv.sin(x)).all()
    assert isinstance(np.float64(2.0) * x, Interval)
    assert isinstance(np.array([1.0, 2.0]) + x, Interval)
    assert (np.square(Interval(-1.0, 2.0))).lo == 0.0


@pytest.mark.parametrize(
    "lo, hi, message",
    [
        (np.nan, 1.0, "NaN"),
        (2.0, 1.0, "inverted"),
        ([0.0, 3.0], [1.0, 2.0], "index"),
        (0.0, np.inf, "finite"),
        ("abc", 1.0, "real numbers"),
    ],
)
def test_bad_user_input_raises_clear_error(lo, hi, message):
    with pytest.raises(iv.IntervalError, match=message):
        Interval(lo, hi)


def test_nan_operand_raises():
    with pytest.raises(iv.IntervalError, match="non-finite"):
        Interval(1.0, 2.0) * float("nan")


def test_intervals_refuse_ordering_and_float_conversion():
    x = Interval(0.0, 1.0)
    with pytest.raises(TypeError):
        x < x
    with pytest.raises(TypeError):
        bool(x)
    with pytest.raises(TypeError):
        np.asarray(x, dtype=float)





# -------------------------------------------------- the oracle itself bites
def test_oracle_rejects_unrounded_float_results():
    """A result computed in plain float arithmetic (no outward rounding) misses the
    exact value, and the checker must say so: otherwise the tests above prove nothing."""
    a, c = 0.1, 3.0
    p = a * c  # 0.30000000000000004 > 0.1 * 3 exactly (as binary numbers)
    elo, ehi = image_binary("mul", a, a, c, c)
    with pytest.raises(AssertionError):
        check_enclosure(p, p, elo, ehi)
    lo, hi = one(lambda x, y: x * y, (a, a), (c, c))
    check_enclosure(lo, hi, elo, ehi, BASIC_ULPS)


def test_oracle_rejects_sin_without_extremum_handling():
    a, b = 1.0, 2.0
    naive_hi = max(math.sin(a), math.sin(b))  # misses the maximum 1 at pi/2
    img = image_periodic("sin", a, b)
    with pytest.raises(AssertionError):
        check_enclosure(min(math.sin(a), math.sin(b)), naive_hi, img[0], img[1])

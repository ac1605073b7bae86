"""verified.consistency.contractor against oracles: python-flint ``arb`` decides which sample points
satisfy a constraint; every such point must stay in the contracted box, and a box
declared empty must hold none. Tightness on cases with known answers. Monkeypatched
contractors that cut one ulp too far, or drop the remainder, must be caught.
"""
import math
from fractions import Fraction

import flint
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import oracles.arb_oracle  # noqa: F401  (sets flint.ctx.prec = 256)
from verified.consistency import contractor
from verified.consistency.contractor import EnergyShell, HC4, contract_linear_row, hc4, mean_value_row
from verified.graph import GraphBuilder, trace
from verified.arith.interval import Interval

SETTINGS = settings(max_examples=60, deadline=None, database=None,
                    suppress_health_check=[HealthCheck.too_slow])
A = flint.arb
UP, DOWN = math.inf, -math.inf


def ulp_near(x, y, k=1):
    """|x - y| <= k ulps of y."""
    return abs(x - y) <= k * math.ulp(y) if y != 0 else abs(x) <= k * 5e-324 * 4


# ----------------------------------------------------------------- expression oracle

UNARY = ["neg", "sqr", "pow3", "pow4", "sqrt", "exp", "log", "sin", "cos", "tan", "atan"]
BINARY = ["add", "sub", "mul", "div"]
CONSTS = [0.5, 2.0, -1.5, 3.0, 1.0]


def random_tree(rng, n, depth):
    if depth == 0 or rng.random() < 0.2:
        if rng.random() < 0.8:
            return ("x", int(rng.integers(n)))
        return ("c", float(rng.choice(CONSTS)))
    if rng.random() < 0.5:
        return (str(rng.choice(BINARY)), random_tree(rng, n, depth - 1), random_tree(rng, n, depth - 1))
    return (str(rng.choice(UNARY)), random_tree(rng, n, depth - 1))


def build(tree, n):
    b = GraphBuilder(n)

    def rec(t):
        op = t[0]
        if op == "x":
            return b.input(t[1])
        if op == "c":
            return b.const(t[1])
        if op in BINARY:
            return getattr(b, op)(rec(t[1]), rec(t[2]))
        a = rec(t[1])
        if op == "pow3":
            return b.pow(a, 3)
        if op == "pow4":
            return b.pow(a, 4)
        return getattr(b, op)(a)

    return b.build([rec(tree)])


def arb_eval(tree, x):
    """Ball of g(x) at a float point, or None where g is undefined (or undecidably so)."""
    op = tree[0]
    if op == "x":
        return A(float(x[tree[1]]))
    if op == "c":
        return A(tree[1])
    if op in BINARY:
        u, v = arb_eval(tree[1], x), arb_eval(tree[2], x)
        if u is None or v is None:
            return None
        if op == "div":
            if v.contains(0):
                return None
            return u / v
        return {"add": u + v, "sub": u - v, "mul": u * v}[op]
    u = arb_eval(tree[1], x)
    if u is None:
        return None
    if op in ("sqrt", "log") and not bool(u > 0 if op == "log" else u >= 0):
        return None
    if op == "tan" and (u.cos()).contains(0):
        return None
    r = {"neg": lambda: -u, "sqr": lambda: u * u, "pow3": lambda: u ** 3, "pow4": lambda: u ** 4,
         "sqrt": u.sqrt, "exp": u.exp, "log": u.log, "sin": u.sin, "cos": u.cos, "tan": u.tan,
         "atan": u.atan}[op]()
    if not r.is_finite() or abs(float(r.mid())) > 1e300:
        return None
    return r


def float_below(ball):
    f = float(ball.lower())
    while not bool(A(f) <= ball):
        f = math.nextafter(f, DOWN)
    return f


def float_above(ball):
    f = float(ball.upper())
    while not bool(A(f) >= ball):
        f = math.nextafter(f, UP)
    return f


def satisfies(ball, lo, hi):
    """True only if every point of the ball is certainly in [lo, hi]."""
    if ball is None:
        return False
    return (lo == DOWN or bool(A(lo) <= ball)) and (hi == UP or bool(ball <= A(hi)))


def make_case(seed, n, depth, nb=3, thin_p=0.5, corner_p=0.4):
    """(tree, boxes lo/hi (nb, n), constraint lo/hi (nb, 1), sample points per box)."""
    rng = np.random.default_rng(seed)
    tree = random_tree(rng, n, depth)
    widths = np.array([0.0, 1e-9, 1e-3, 0.1, 1.0, 4.0])
    c = rng.uniform(-3, 3, (nb, n))
    w = rng.choice(widths, (nb, n))
    lo, hi = c - w / 2, c + w / 2
    clo = np.full((nb, 1), DOWN)
    chi = np.full((nb, 1), UP)
    samples = []
    for k in range(nb):
        corner = rng.random() < corner_p
        x0 = np.where(rng.random(n) < 0.5, lo[k], hi[k]) if corner else rng.uniform(lo[k], hi[k])
        g0 = arb_eval(tree, x0)
        if g0 is not None:
            clo[k, 0], chi[k, 0] = float_below(g0), float_above(g0)
            if rng.random() > thin_p:
                pad = float(rng.choice([1e-12, 1e-3, 0.1, 1.0])) * (1.0 + abs(float(g0.mid())))
                clo[k, 0] -= pad
                chi[k, 0] += pad
            if not (math.isfinite(clo[k, 0]) and math.isfinite(chi[k, 0])):
                clo[k, 0], chi[k, 0] = DOWN, UP
        pts = [x0, lo[k], hi[k]]
        pts += [np.where(rng.random(n) < 0.5, lo[k], hi[k]) for _ in range(4)]
        # neighbours of x0 a few ulps away (inside the box): cuts at the ulp level
        for _ in range(6):
            steps = rng.integers(-3, 4, n)
            p = x0.copy()
            for j in range(n):
                for _ in range(abs(int(steps[j]))):
                    p[j] = math.nextafter(p[j], UP if steps[j] > 0 else DOWN)
            pts.append(np.clip(p, lo[k], hi[k]))
        pts += list(rng.uniform(lo[k], hi[k], (30, n)))
        samples.append(pts)
    return tree, lo, hi, clo, chi, samples


def violations(tree, n, lo, hi, clo, chi, samples, max_iter=1):
    """Satisfying samples outside the contracted box, and boxes declared empty that
    hold a satisfying sample (both must be empty lists)."""
    try:
        g = build(tree, n)
    except (ZeroDivisionError, ValueError, OverflowError):  # the builder folded c / 0 etc.
        return []
    res = contractor.HC4(g).contract(Interval(lo, hi), clo, chi, max_iter=max_iter)
    bad = []
    assert res.boxes.shape == lo.shape
    for k, pts in enumerate(samples):
        if not res.empty[k]:
            assert (res.boxes.lo[k] >= lo[k]).all() and (res.boxes.hi[k] <= hi[k]).all()
        for p in pts:
            if not satisfies(arb_eval(tree, p), clo[k, 0], chi[k, 0]):
                continue
            if res.empty[k]:
                bad.append(("empty", k, p))
            elif not ((res.boxes.lo[k] <= p).all() and (p <= res.boxes.hi[k]).all()):
                bad.append(("outside", k, p, res.boxes[k]))
    return bad


# ----------------------------------------------------------------- HC4 soundness


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 3), depth=st.integers(1, 4),
       max_iter=st.sampled_from([1, 3]))
def test_hc4_sound_random_expressions(seed, n, depth, max_iter):
    case = make_case(seed, n, depth)
    assert violations(*case[:1], n, *case[1:], max_iter=max_iter) == []


@pytest.mark.slow
@settings(max_examples=1500, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 3), depth=st.integers(1, 5),
       max_iter=st.sampled_from([1, 4]))
def test_hc4_sound_random_expressions_long(seed, n, depth, max_iter):
    case = make_case(seed, n, depth)
    assert violations(*case[:1], n, *case[1:], max_iter=max_iter) == []


@pytest.mark.parametrize("op", UNARY)
def test_hc4_sound_each_unary_op(op):
    """Every unary projection over many boxes (wide, narrow, across periods/poles)."""
    rng = np.random.default_rng(hash(op) % 2**32)
    for seed in rng.integers(0, 2**32, 12):
        case = make_case(int(seed), 1, 1, nb=6)
        tree = (op, ("x", 0))
        _, lo, hi, clo, chi, samples = case
        # re-aim the constraint at this op
        r2 = np.random.default_rng(int(seed))
        for k in range(lo.shape[0]):
            x0 = samples[k][0]
            g0 = arb_eval(tree, x0)
            if g0 is None:
                clo[k, 0], chi[k, 0] = DOWN, UP
                continue
            clo[k, 0], chi[k, 0] = float_below(g0), float_above(g0)
            if r2.random() < 0.5:
                pad = float(r2.choice([1e-9, 0.1, 0.7]))
                clo[k, 0] -= pad
                chi[k, 0] += pad
        assert violations(tree, 1, lo, hi, clo, chi, samples) == []


def test_hc4_oracle_bites_one_ulp_too_far(monkeypatch):
    """A contractor whose boxes are one ulp narrower on every side must be caught."""
    seeds = range(40)
    cases = [make_case(s, 2, 2, corner_p=0.8) for s in seeds]
    assert all(violations(c[0], 2, *c[1:]) == [] for c in cases)
    orig = contractor.HC4._pass

    def too_far(self, *args):
        nlo, nhi, dead = orig(self, *args)
        return np.nextafter(nlo, UP), np.nextafter(nhi, DOWN), dead

    monkeypatch.setattr(contractor.HC4, "_pass", too_far)
    caught = sum(len(violations(c[0], 2, *c[1:])) > 0 for c in cases)
    assert caught > 0
    # and the simplest case: x + y = 1 with the satisfying corner (1, 0)
    bad = violations(("add", ("x", 0), ("x", 1)), 2, np.array([[0.8, 0.0]]), np.array([[1.0, 1.0]]),
                     np.array([[1.0]]), np.array([[1.0]]), [[np.array([1.0, 0.0])]])
    assert bad


def test_hc4_oracle_bites_one_projection_too_far(monkeypatch):
    """One wrong inverse is caught too: the sqr projection's sqrt cut one ulp past the
    exact root (sqrt(4) = 2 exactly; the mutant's lower bound is the float after 2)."""
    tree = ("sqr", ("x", 0))
    lo, hi = np.array([[0.0], [-5.0]]), np.array([[5.0], [5.0]])
    clo, chi = np.array([[4.0], [4.0]]), np.array([[4.0], [4.0]])
    samples = [[np.array([2.0])], [np.array([-2.0]), np.array([2.0])]]
    assert violations(tree, 1, lo, hi, clo, chi, samples) == []
    orig = contractor.iv.sqrt

    def sqrt_in(x):
        return Interval._from_bounds(np.nextafter(np.sqrt(x.lo), UP), np.sqrt(x.hi))

    monkeypatch.setattr(contractor.iv, "sqrt", sqrt_in)
    assert violations(tree, 1, lo, hi, clo, chi, samples)


def test_hc4_regression_real_value_between_floats():
    """tan((1 + x)^6)^2 at a point x: the value w = (1 + x)^6 is a real strictly inside
    a float interval; a verified cut at a float c must move the bound to c, not to the
    float after c (found by the slow hypothesis run)."""
    case = make_case(2662, 1, 5)
    assert violations(case[0], 1, *case[1:]) == []


def test_hc4_oracle_bites_cut_one_ulp_past_verified_point(monkeypatch):
    """The bug above, reintroduced as a mutant, is caught."""
    case = make_case(2662, 1, 5)
    orig = contractor._mono_cut

    def mutant(a, b, *args):
        na, nb = orig(a, b, *args)
        return (np.where(na > a, np.nextafter(na, UP), na), np.where(nb < b, np.nextafter(nb, DOWN), nb))

    monkeypatch.setattr(contractor, "_mono_cut", mutant)
    assert violations(case[0], 1, *case[1:])


# ----------------------------------------------------------------- HC4 tightness


def test_tight_sum():
    g = trace(lambda x, p: [x[0] + x[1]], 2)
    r = hc4(g, Interval([[0.8, 0.0]], [[1.0, 1.0]]), [1.0], [1.0])
    assert not r.empty[0]
    assert r.boxes.lo[0, 1] == 0.0 and ulp_near(r.boxes.hi[0, 1], 0.2, 2)
    assert r.boxes.lo[0, 0] == 0.8 and r.boxes.hi[0, 0] == 1.0


def test_tight_square():
    g = trace(lambda x, p: [x[0] * x[0]], 1)
    r = hc4(g, Interval([[0.0], [-5.0], [3.0]], [[5.0], [5.0], [5.0]]), [4.0], [4.0])
    assert ulp_near(r.boxes.lo[0, 0], 2.0) and ulp_near(r.boxes.hi[0, 0], 2.0)
    assert ulp_near(r.boxes.lo[1, 0], -2.0) and ulp_near(r.boxes.hi[1, 0], 2.0)
    assert list(r.empty) == [False, False, True]


@pytest.mark.parametrize("fn, box, z, exact", [
    (np.sin, (0.0, 1.5), (0.5, 0.6), (math.asin(0.5), math.asin(0.6))),
    (np.sin, (0.0, 3.0), (0.5, 0.6), (math.asin(0.5), math.pi - math.asin(0.5))),
    (np.sin, (2.0, 3.0), (0.5, 0.6), (math.pi - math.asin(0.6), math.pi - math.asin(0.5))),
    (np.sin, (-10.0, 10.0), (0.5, 0.6), (-10.0, 3 * math.pi - math.asin(0.5))),
    (np.cos, (0.0, 3.0), (0.5, 0.6), (math.acos(0.6), math.acos(0.5))),
    (np.cos, (-1.5, 1.5), (0.9, 2.0), (-math.acos(0.9), math.acos(0.9))),
    (np.exp, (-10.0, 10.0), (1.0, 2.0), (0.0, math.log(2.0))),
    (np.log, (0.1, 10.0), (0.0, 1.0), (1.0, math.e)),
    (np.sqrt, (0.0, 10.0), (1.5, 2.0), (2.25, 4.0)),
    (np.tan, (-1.0, 4.0), (0.5, 1.0), (math.atan(0.5), math.pi + math.atan(1.0))),
    (np.arctan, (-10.0, 10.0), (0.5, 1.0), (math.tan(0.5), math.tan(1.0))),
    (lambda x: x ** 3, (-5.0, 5.0), (8.0, 27.0), (2.0, 3.0)),
    (lambda x: x ** 4, (-5.0, 1.0), (16.0, 81.0), (-3.0, -2.0)),
    (lambda x: 1.0 / x, (-1.0, 3.0), (1.0, 2.0), (0.5, 1.0)),
])
def test_tight_inversions(fn, box, z, exact):
    g = trace(lambda x, p: [fn(x[0])], 1)
    r = hc4(g, Interval([[box[0]]], [[box[1]]]), [z[0]], [z[1]])
    lo, hi = r.boxes.lo[0, 0], r.boxes.hi[0, 0]
    assert lo <= exact[0] + 1e-300 and hi >= exact[1] - 1e-300  # sound
    assert abs(lo - exact[0]) <= 1e-12 * (1 + abs(exact[0]))  # and close
    assert abs(hi - exact[1]) <= 1e-12 * (1 + abs(exact[1]))


def test_gap_in_relational_division():
    """x * y = 1 with y in [-1, 1]: x in (-inf, -1] U [1, inf); met with [0.5, 3] -> [1, 3]."""
    g = trace(lambda x, p: [x[0] * x[1]], 2)
    r = hc4(g, Interval([[0.5, -1.0]], [[3.0, 1.0]]), [1.0], [1.0])
    assert ulp_near(r.boxes.lo[0, 0], 1.0, 2) and r.boxes.hi[0, 0] == 3.0
    assert ulp_near(r.boxes.lo[0, 1], 1 / 3, 2) and r.boxes.hi[0, 1] == 1.0
    # x * y = 0 with both containing 0: nothing is known
    r = hc4(g, Interval([[-1.0, -2.0]], [[3.0, 1.0]]), [0.0], [0.0])
    assert r.boxes.equals(Interval([[-1.0, -2.0]], [[3.0, 1.0]])).all()


def test_shared_node_intersects_projections_and_iteration():
    """x and y used twice: x + y = 1 and x - 2 y = 0 on [0, 1]^2. One pass meets both
    projections (x in [1/2, 1]); iterating converges to (2/3, 1/3) (halving each pass)."""
    g = trace(lambda x, p: [x[0] + x[1], x[0] - 2.0 * x[1]], 2)
    box = Interval([[0.0, 0.0]], [[1.0, 1.0]])
    one = hc4(g, box, [1.0, 0.0], [1.0, 0.0], max_iter=1)
    many = hc4(g, box, [1.0, 0.0], [1.0, 0.0], max_iter=80, tol=0.0)
    sol = np.array([[2 / 3, 1 / 3]])
    assert one.boxes.contains(sol).all() and many.boxes.contains(sol).all()
    assert one.boxes.width().max() <= 0.5 + 1e-15
    assert many.boxes.width().max() < 1e-12
    assert many.iterations > 10


def test_empty_and_params_and_batch_shapes():
    g = trace(lambda x, p: [p[0] * x[0] + x[1]], 2, 1)
    boxes = Interval(np.array([[0.0, 0.0], [0.0, 0.0], [5.0, 5.0]]), np.array([[1.0, 1.0], [1.0, 1.0], [6.0, 6.0]]))
    r = hc4(g, boxes, [[1.0], [3.5], [0.0]], [[1.0], [4.0], [1.0]], params=Interval([2.0], [2.0]))
    assert list(r.empty) == [False, True, True]
    assert np.isinf(r.boxes.lo[1:]).all() and (r.boxes.lo[1:] > r.boxes.hi[1:]).all()
    assert r.boxes[0].contains(np.array([0.5, 0.0])).all()
    single = hc4(g, Interval([0.0, 0.0], [1.0, 1.0]), [1.0], [1.0], params=[2.0])
    assert single.boxes.shape == (2,)


def test_undefined_points_do_not_satisfy():
    """sqrt(x) >= 0 holds only for x >= 0; log(x) <= 0 only on (0, 1]."""
    g = trace(lambda x, p: [np.sqrt(x[0]), np.log(x[1])], 2)
    r = hc4(g, Interval([[-4.0, -4.0]], [[4.0, 4.0]]), [0.0, -np.inf], [np.inf, 0.0])
    assert r.boxes.lo[0, 0] == 0.0 and r.boxes.hi[0, 0] == 4.0
    assert 0.0 <= r.boxes.lo[0, 1] and ulp_near(r.boxes.hi[0, 1], 1.0, 8)


def test_unknown_op_is_not_contracted():
    """An op without a backward rule (MID, or one added later) contracts nothing."""
    b = GraphBuilder(1)
    if not hasattr(b, "mid"):
        pytest.skip("this checkout has no MID op")
    x = b.input(0)
    g = b.build([b.add(b.mid(x), b.const(0.0)), b.sqr(x)])
    r = hc4(g, Interval([[-1.0]], [[3.0]]), [-np.inf, 1.0], [np.inf, 4.0])
    assert not r.empty[0]
    assert r.boxes.lo[0, 0] == -1.0 and ulp_near(r.boxes.hi[0, 0], 2.0)
    # constraining the MID output itself narrows nothing through it (the forward value
    # is what the evaluator says; the argument keeps its box)
    g2 = b.build([b.mid(x)])
    r2 = hc4(g2, Interval([[-1.0]], [[3.0]]), [-np.inf], [np.inf])
    assert r2.boxes.equals(Interval([[-1.0]], [[3.0]])).all()


def test_batch_contraction_equals_box_by_box():
    """A batch of 20000 boxes on the double pendulum's H gives, row for row, what each
    box gives alone (the batch is one vectorised pass: its speed is measured in
    benchmarks/bench_contractor.py, not here)."""
    from models import double_pendulum as dp
    H = dp.energy_graph()
    rng = np.random.default_rng(1)
    c = dp.initial_point() + rng.normal(0, 0.05, (20000, 4))
    boxes = Interval(c - 0.02, c + 0.02)
    h = H.eval_float(dp.initial_point())[0]
    batch = HC4(H).contract(boxes, [h - 0.1], [h + 0.1])
    assert batch.boxes.shape == (20000, 4)
    for i in rng.choice(20000, 12, replace=False):
        one = HC4(H).contract(boxes[i:i + 1], [h - 0.1], [h + 0.1])
        assert one.empty[0] == batch.empty[i]
        if not one.empty[0]:
            np.testing.assert_array_equal(one.boxes.lo[0], batch.boxes.lo[i])
            np.testing.assert_array_equal(one.boxes.hi[0], batch.boxes.hi[i])


# ----------------------------------------------------------------- HC4 on the double pendulum H


def dp_arb_H(x):
    """The double pendulum's H (eq. (24)) at a float state, as an arb ball."""
    from models import double_pendulum as dp
    x1, x2, x3, x4 = (A(float(v)) for v in x)
    m1, m2, l1, l2, g = A(dp.M1), A(dp.M2), A(dp.L1), A(dp.L2), A("9.81")
    c2 = x2.cos()
    m11 = (m1 + m2) * l1 ** 2 + m2 * l2 ** 2 + 2 * m2 * l1 * l2 * c2
    m12 = m2 * l2 ** 2 + m2 * l1 * l2 * c2
    m22 = m2 * l2 ** 2
    T = (m11 * x3 * x3 + 2 * m12 * x3 * x4 + m22 * x4 * x4) / 2
    V = -(m1 + m2) * g * l1 * x1.cos() - m2 * g * l2 * (x1 + x2).cos()
    return T + V


def test_dp_graph_matches_arb_H():
    from models import double_pendulum as dp
    H = dp.energy_graph()
    rng = np.random.default_rng(3)
    for x in rng.uniform(-3, 3, (20, 4)):
        Hi = H.eval_interval(Interval(x[None]))
        assert bool(A(float(Hi.lo[0, 0])) <= dp_arb_H(x)) and bool(dp_arb_H(x) <= A(float(Hi.hi[0, 0])))


def test_hc4_on_double_pendulum_energy_sound():
    from models import double_pendulum as dp
    H = dp.energy_graph()
    rng = np.random.default_rng(7)
    x0 = dp.initial_point()
    h0 = dp_arb_H(x0)
    lo_h, hi_h = float_below(h0) - 0.05, float_above(h0) + 0.05
    c = x0 + rng.normal(0, 0.2, (40, 4))
    w = rng.choice([0.01, 0.1, 0.5], (40, 4))
    boxes = Interval(c - w, c + w)
    res = HC4(H).contract(boxes, [lo_h], [hi_h], max_iter=3)
    n_ok = 0
    for k in range(40):
        pts = rng.uniform(boxes.lo[k], boxes.hi[k], (300, 4))
        for p in pts:
            if satisfies(dp_arb_H(p), lo_h, hi_h):
                n_ok += 1
                assert not res.empty[k]
                assert (res.boxes.lo[k] <= p).all() and (p <= res.boxes.hi[k]).all()
    assert n_ok > 50
    assert res.empty.sum() > 0 and (res.boxes.width()[~res.empty] < boxes.width()[~res.empty]).any()


# ----------------------------------------------------------------- linear row


def _row_case(rng, B=6, m=5, rem=None):
    a = rng.normal(0, 1, (B, m)) * rng.choice([1.0, 1e-3, 0.0], (B, m), p=[0.8, 0.1, 0.1])
    rc = rng.uniform(-1, 1, (B, m))
    rw = rng.choice([0.01, 0.5, 2.0], (B, m))
    R = Interval(rc - rw, rc + rw)
    rstar = rng.uniform(R.lo, R.hi)
    if rem is None:
        rem = Interval(-rng.uniform(0, 0.1, B), rng.uniform(0, 0.1, B))
    s = np.einsum("bm,bm->b", a, rstar)
    band = rng.choice([0.0, 1e-6, 0.3], B)
    # 0 in g0 + a.r* + rem: g0 = -(a.r*) - rem_mid +- band (floats, widened for rounding)
    mid_rem = 0.5 * (rem.lo + rem.hi)
    g0 = Interval(-s - mid_rem - band, -s - mid_rem + band).widen_ulps(4)
    return a, g0, R, rem


def _exact_satisfies(a, g0lo, g0hi, remlo, remhi, r):
    s = sum(Fraction(float(ai)) * Fraction(float(ri)) for ai, ri in zip(a, r))
    return Fraction(g0lo) + Fraction(remlo) <= -s <= Fraction(g0hi) + Fraction(remhi)


def _row_samples(rng, a, g0, R, rem, k, n=300):
    """Points of R[k] on the row's solution band, by solving for one component."""
    m = a.shape[1]
    pts = []
    for _ in range(n):
        r = rng.uniform(R.lo[k], R.hi[k])
        r = np.where(rng.random(m) < 0.2, np.where(rng.random(m) < 0.5, R.lo[k], R.hi[k]), r)
        j = int(rng.integers(m))
        if a[k, j] != 0:
            t = -rng.uniform(g0.lo[k] + rem.lo[k], g0.hi[k] + rem.hi[k])
            r[j] = (t - (a[k] @ r - a[k, j] * r[j])) / a[k, j]
            if not (R.lo[k, j] <= r[j] <= R.hi[k, j]):
                continue
        if _exact_satisfies(a[k], g0.lo[k], g0.hi[k], rem.lo[k], rem.hi[k], r):
            pts.append(r)
    return pts


def row_violations(rng, cases, fn=None):
    fn = fn or (lambda *args: contractor.contract_linear_row(*args))
    bad, n_pts = [], 0
    for a, g0, R, rem in cases:
        r_new, empty = fn(a, g0, R, rem)
        for k in range(R.shape[0]):
            for p in _row_samples(rng, a, g0, R, rem, k):
                n_pts += 1
                if empty[k] or not ((r_new.lo[k] <= p).all() and (p <= r_new.hi[k]).all()):
                    bad.append((k, p))
    return bad, n_pts


# (4-8 s: behind the slow marker to keep the default run under 3 minutes)
@pytest.mark.slow
@SETTINGS
@given(seed=st.integers(0, 2**32 - 1))
def test_linear_row_sound(seed):
    rng = np.random.default_rng(seed)
    bad, n = row_violations(rng, [_row_case(rng)])
    assert bad == []


def test_linear_row_tight_and_empty():
    # r1 + 2 r2 = 2.5 on [-1, 1]^2: r1 in [0.5, 1], r2 in [0.75, 1]
    r, e = contract_linear_row(np.array([1.0, 2.0]), Interval(np.array([-2.5])), Interval([[-1, -1.0]], [[1, 1.0]]))
    assert not e[0]
    assert np.allclose(r.lo, [[0.5, 0.75]], atol=1e-15) and np.allclose(r.hi, [[1.0, 1.0]])
    # r1 + r2 = 3 on [-1, 1]^2 is impossible
    r, e = contract_linear_row(np.array([[1.0, 1.0]]), Interval(np.array([-3.0])), Interval([[-1, -1.0]], [[1, 1.0]]))
    assert e[0]
    # which=: only the second component moves
    r, e = contract_linear_row(np.array([1.0, 2.0]), Interval(np.array([-2.5])), Interval([[-1, -1.0]], [[1, 1.0]]),
                               which=[False, True])
    assert r.lo[0, 0] == -1.0 and abs(r.lo[0, 1] - 0.75) < 1e-15


def test_linear_row_oracle_bites_dropped_rem(monkeypatch):
    rng = np.random.default_rng(11)
    cases = []
    for _ in range(5):
        B = 6
        rem = Interval(np.full(B, 0.3), np.full(B, 0.5))
        cases.append(_row_case(rng, B=B, rem=rem))
    bad, n = row_violations(np.random.default_rng(12), cases)
    assert bad == [] and n > 100
    orig = contractor.contract_linear_row

    def no_rem(a, g0, r, rem=0.0, **kw):
        return orig(a, g0, r, 0.0, **kw)

    monkeypatch.setattr(contractor, "contract_linear_row", no_rem)
    bad, n = row_violations(np.random.default_rng(12), cases)
    assert len(bad) > 0


def test_mean_value_row_on_a_lohner_like_set():
    """x = c + A r (c the paper's initial point, A = [C | Q] as in lohner.DoubletonSets),
    H(x) - h = 0: every sampled r whose x has H(x) in h stays in the narrowed box, and
    the box narrows."""
    from models import double_pendulum as dp
    H = dp.energy_graph()
    rng = np.random.default_rng(5)
    B, n = 4, 4
    c = dp.initial_point() + rng.normal(0, 0.01, (B, n))
    C = np.eye(n) + rng.normal(0, 0.3, (B, n, n))
    Q = np.linalg.qr(rng.normal(0, 1, (B, n, n)))[0]
    Amat = np.concatenate([C, Q], axis=2)  # (B, n, 2n)
    R = Interval(np.concatenate([np.full((B, n), -0.01), np.full((B, n), -0.002)], 1),
                 np.concatenate([np.full((B, n), 0.01), np.full((B, n), 0.002)], 1))
    h0 = np.array([float(dp_arb_H(ci).mid()) for ci in c])
    h = Interval(h0 - 0.005, h0 + 0.005)
    a, g0, rem = mean_value_row(H, c, Amat, R, h)
    R2, empty = contract_linear_row(a, g0, R, rem)
    assert not empty.any()
    assert (R2.width() <= R.width()).all() and (R2.width() < R.width() * 0.99).any()
    n_ok = 0
    for k in range(B):
        rs = rng.uniform(R.lo[k], R.hi[k], (1500, 2 * n))
        for r in rs:
            x = c[k] + Amat[k] @ r  # float: the arb check below is at this float point
            # only points whose float x is (certainly) the exact c + A r matter; use arb
            xa = [A(float(c[k, i])) + sum(A(float(Amat[k, i, j])) * A(float(r[j])) for j in range(2 * n))
                  for i in range(n)]
            Hx = _arb_H_of(xa)
            if satisfies(Hx, h.lo[k], h.hi[k]):
                n_ok += 1
                assert (R2.lo[k] <= r).all() and (r <= R2.hi[k]).all()
    assert n_ok > 50


def _arb_H_of(xa):
    from models import double_pendulum as dp
    x1, x2, x3, x4 = xa
    m1, m2, l1, l2, g = A(dp.M1), A(dp.M2), A(dp.L1), A(dp.L2), A("9.81")
    c2 = x2.cos()
    m11 = (m1 + m2) * l1 ** 2 + m2 * l2 ** 2 + 2 * m2 * l1 * l2 * c2
    m12 = m2 * l2 ** 2 + m2 * l1 * l2 * c2
    T = (m11 * x3 * x3 + 2 * m12 * x3 * x4 + m2 * l2 ** 2 * x4 * x4) / 2
    return T - (m1 + m2) * g * l1 * x1.cos() - m2 * g * l2 * (x1 + x2).cos()


# ----------------------------------------------------------------- energy shell


def dp_shell():
    from models import double_pendulum as dp
    Mg = trace(lambda q, p: [e for row in dp.mass_matrix(q) for e in row], 2)
    Vg = trace(lambda q, p: [-(dp.M1 + dp.M2) * dp.G * dp.L1 * np.cos(q[0])
                             - dp.M2 * dp.G * dp.L2 * np.cos(q[0] + q[1])], 2)
    return EnergyShell(Mg, Vg)


def test_shell_graph_is_the_paper_H():
    from models import double_pendulum as dp
    sh = dp_shell()
    x = np.random.default_rng(0).uniform(-3, 3, (50, 4))
    assert np.allclose(sh.graph.eval_float(x)[:, 0], dp.energy_graph().eval_float(x)[:, 0], rtol=1e-13, atol=1e-12)


def _shell_states(rng, box, hmax, n):
    """States of the box with H <= hmax certainly: random ones and extremal ones
    (qd = s M^-1 e_i at the largest s: the tips of the velocity ellipsoid)."""
    from models import double_pendulum as dp
    out = []
    qs = rng.uniform(box.lo[:2], box.hi[:2], (n, 2))
    for q in qs:
        M = np.array(dp.mass_matrix(q), float)
        V = -(2 * 9.81) * math.cos(q[0]) - 9.81 * math.cos(q[0] + q[1])
        if hmax - V <= 0:
            continue
        Minv = np.linalg.inv(M)
        i = int(rng.integers(2))
        u = Minv[:, i] * rng.choice([-1, 1])
        s = math.sqrt(2 * (hmax - V) / (u @ M @ u)) * (1 - 1e-9)
        for qd in (s * u, rng.uniform(-1, 1, 2) * s * 1.5):
            x = np.concatenate([q, qd])
            if (box.lo <= x).all() and (x <= box.hi).all() and satisfies(dp_arb_H(x), DOWN, hmax):
                out.append(x)
    return out


def test_energy_shell_sound_and_tightens_wide_box():
    from models import double_pendulum as dp
    sh = dp_shell()
    hmax = float_above(dp_arb_H(dp.initial_point())) + 0.05
    boxes = Interval(np.array([[-np.pi, -np.pi, -50.0, -50.0], [1.8, -2.0, -50, -50], [2.0, -1.9, -3, -3]]),
                     np.array([[np.pi, np.pi, 50.0, 50.0], [2.6, -1.3, 50, 50], [2.4, -1.5, 3, 3]]))
    res = sh.contract(boxes, hmax)
    rng = np.random.default_rng(2)
    n_ok = 0
    for k in range(boxes.shape[0]):
        for x in _shell_states(rng, boxes[k], hmax, 400):
            n_ok += 1
            assert not res.empty[k]
            assert (res.boxes.lo[k] <= x).all() and (x <= res.boxes.hi[k]).all(), (k, x, res.boxes[k])
    assert n_ok > 200
    w0, w1 = boxes.width(), res.boxes.width()
    # the wide box: q1 to |q1| <= 2.58 (V <= hmax), velocities to about the shell's extent
    assert w1[0, 0] < 0.83 * w0[0, 0]
    assert w1[0, 2] < 0.25 * w0[0, 2] and w1[0, 3] < 0.5 * w0[0, 3]
    # true extents of the shell (sampled): |x3| <= 8.51, |x4| <= 19.0
    assert res.boxes.hi[0, 2] < 1.25 * 8.51 and res.boxes.hi[0, 3] < 1.25 * 19.03
    assert (w1[1] <= w0[1]).all() and w1[1, 2] < 0.2 * w0[1, 2]


def test_energy_shell_empty_below_potential_minimum():
    sh = dp_shell()
    r = sh.contract(Interval([[-0.1, -0.1, -1, -1], [3.0, 0.0, 0, 0]], [[0.1, 0.1, 1, 1], [3.1, 0.1, 0.1, 0.1]]),
                    -30.0)
    assert list(r.empty) == [True, True]  # min V = -29.43 > -30


def test_energy_shell_hmin_side():
    """hmin <= H: a box at rest near the bottom cannot reach H >= 0."""
    sh = dp_shell()
    r = sh.contract(Interval([[-0.1, -0.1, -0.1, -0.1]], [[0.1, 0.1, 0.1, 0.1]]), 100.0, hmin=0.0)
    assert r.empty[0]

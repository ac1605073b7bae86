"""The proof of a declared energy rate (verified.consistency.graphs.prove_claim) and
what the energy test does without one (issue 39, item 6).

The proof is exact: constants as the doubles (or enclosures) the graphs hold, no
floating-point simplification. A claim it cannot prove is not integrated: ``h``
integrates the derived ``grad H . f`` instead.
"""
import sympy

from verified.consistency.energy_test import EnergyClaimWarning, EnergyTest, prove_energy_rate
from verified.consistency.graphs import PROOF_MAX_TERMS, claim_graph, prove_claim
from verified.graph import from_sympy, trace

from models import double_pendulum as dp


def _dp():
    names = ["x1", "x2", "x3", "x4"]
    rhs = trace(dp.rhs, 4, input_names=names)
    H = trace(lambda x, p: [dp.hamiltonian(x)], 4, input_names=names)
    return rhs, H


def _damped(c):
    rhs = trace(lambda x, p: [x[1], -x[0] - c * x[1] * x[0] * x[0]], 2)
    H = trace(lambda x, p: [0.5 * (x[0] * x[0] + x[1] * x[1])], 2)
    return rhs, H


def test_the_paper_double_pendulum_is_proven_conservative_exactly():
    """sympy's simplify on the graphs' float constants did not get this to 0 (4 s,
    False); the exact reduction proves it in well under a second."""
    rhs, H = _dp()
    assert prove_energy_rate(rhs, H, None)
    proof = prove_claim(claim_graph(rhs, H, None))
    assert proof.proven and proof.reason == ""


def test_a_claim_that_holds_only_up_to_rounding_is_not_proven():
    """g = 1/3 enclosed in the ODE (the true third) but rounded to a double in H: the
    claim dH/dt = 0 is false for these graphs by ~1e-17 qd sin q. The float
    simplification called it proven."""
    q, qd = sympy.symbols("q qd")
    rhs = from_sympy([qd, -sympy.Rational(1, 3) * sympy.sin(q)], [q, qd])
    H = from_sympy([qd**2 / 2 + sympy.Float(1.0 / 3.0) * (1 - sympy.cos(q))], [q, qd])  # the double nearest 1/3
    assert not prove_energy_rate(rhs, H, None)
    # the same third on both sides (the same enclosure): proven, for every value in it
    H13 = from_sympy([qd**2 / 2 + sympy.Rational(1, 3) * (1 - sympy.cos(q))], [q, qd])
    assert prove_energy_rate(rhs, H13, None)


def test_sums_multiples_and_tangents_of_angles_are_reduced():
    x, y = sympy.symbols("x y")
    rhs = from_sympy([1 + 0 * x, 1 + 0 * y], [x, y])
    H = from_sympy([sympy.sin(x) ** 2 + sympy.sin(y) * sympy.cos(x)], [x, y])
    # dH/dt = 2 sin x cos x + cos y cos x - sin y sin x = sin 2x + cos(x + y)
    good = from_sympy([sympy.sin(2 * x) + sympy.cos(x + y)], [x, y])
    assert prove_energy_rate(rhs, H, good)
    assert not prove_energy_rate(rhs, H, from_sympy([sympy.sin(2 * x) + sympy.cos(x - y)], [x, y]))
    t = from_sympy([sympy.tan(x) * sympy.cos(x) - sympy.sin(x)], [x, y])  # identically 0
    assert prove_claim(t).proven


def test_the_proof_gives_up_past_its_size_bound():
    rhs, H = _dp()
    proof = prove_claim(claim_graph(rhs, H, None), max_terms=10)
    assert not proof.proven and "PROOF_MAX_TERMS" in proof.reason
    assert PROOF_MAX_TERMS >= 500


def test_an_unproven_claim_is_not_integrated_and_a_proven_one_is():
    """EnergyTest.prepare returns the graph the solver integrates; its last output is
    h' (0 for a used "zero" claim)."""
    c = 0.5
    rhs, H = _damped(c)
    x = [[1.0, 1.0, 0.0]]
    test = EnergyTest(H, "zero")
    g = test.prepare(rhs, rhs, 2, None)
    assert not test.claim_proof.proven
    assert g.eval_float(x)[0, -1] == -c  # grad H . f = -C x1^2 x0^2, not the claimed 0
    # a true claim is used
    rhs0, H0 = _damped(0.0)
    test0 = EnergyTest(H0, "zero")
    assert test0.prepare(rhs0, rhs0, 2, None).eval_float(x)[0, -1] == 0.0
    assert test0.claim_proof.proven
    # check_claim=False: the caller vouches for the declaration, it is used as given
    trusted = EnergyTest(H, "zero", check_claim=False)
    assert trusted.prepare(rhs, rhs, 2, None).eval_float(x)[0, -1] == 0.0
    assert trusted.claim_proof is None
    assert issubclass(EnergyClaimWarning, UserWarning)

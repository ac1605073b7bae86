"""ODEs shared by the Taylor-coefficient tests (moved from tests/test_affine_taylor.py):
one graph per operation (CASES), the paper's double pendulum, random programs as
ODEs, the 3-link planar arm, random input forms, and Pinocchio's accelerations inside
an enclosure. The arm_pin fixture is in tests/verified/conftest.py."""
from __future__ import annotations

import numpy as np
from hypothesis import strategies as st

from oracles.arb_graph import run_program
from oracles.arb_series import has_op
from verified.graph import Op, trace


# (name, rhs, op that must be in the graph, centre range of x, max radius of x, centre range of p,
#  max radius of p); the ranges keep every operation inside its domain over the box
CASES = [
    ("add", lambda x, p: [x[0] + p[0]], Op.ADD, (-2, 2), 0.5, (-1, 1), 0.3),
    ("sub", lambda x, p: [p[0] - x[0]], Op.SUB, (-2, 2), 0.5, (-1, 1), 0.3),
    ("neg", lambda x, p: [-np.sin(x[0] * p[0])], Op.NEG, (-2, 2), 0.5, (-1, 1), 0.3),
    ("mul", lambda x, p: [x[0] * (p[0] - x[0])], Op.MUL, (-2, 2), 0.5, (-1, 1), 0.3),
    ("sqr", lambda x, p: [p[0] - np.square(x[0])], Op.SQR, (-1.5, 1.5), 0.4, (-1, 1), 0.3),
    ("pow3", lambda x, p: [p[0] * x[0] ** 3], Op.POW, (-1.2, 1.2), 0.3, (-1, 1), 0.3),
    ("pow4", lambda x, p: [x[0] ** 4 - p[0]], Op.POW, (-1.2, 1.2), 0.3, (-1, 1), 0.3),
    ("pow7", lambda x, p: [p[0] * x[0] ** 7], Op.POW, (-1.1, 1.1), 0.2, (-1, 1), 0.3),
    ("div", lambda x, p: [1 / (p[0] + x[0])], Op.DIV, (-2, 2), 0.5, (3, 4), 0.3),
    ("div_series", lambda x, p: [x[0] * p[0] / (1 + x[0] * x[0])], Op.DIV, (-2, 2), 0.5, (-1, 1), 0.3),
    ("sqrt", lambda x, p: [np.sqrt(x[0] * p[0])], Op.SQRT, (0.6, 3), 0.4, (0.5, 2), 0.2),
    ("exp", lambda x, p: [np.exp(p[0] * x[0])], Op.EXP, (-2, 1), 0.5, (-1, 1), 0.3),
    ("log", lambda x, p: [p[0] * np.log(x[0])], Op.LOG, (0.6, 3), 0.4, (-1, 1), 0.3),
    ("sin", lambda x, p: [np.sin(p[0] * x[0])], Op.SIN, (-3, 3), 0.5, (-2, 2), 0.3),
    ("cos", lambda x, p: [np.cos(x[0]) + p[0]], Op.COS, (-3, 3), 0.5, (-1, 1), 0.3),
    ("sin*cos", lambda x, p: [np.sin(x[0]) * np.cos(x[0]) * p[0]], Op.COS, (-3, 3), 0.5, (-2, 2), 0.3),
    ("tan", lambda x, p: [p[0] * np.tan(x[0])], Op.TAN, (-1.1, 1.1), 0.2, (-1, 1), 0.3),
    ("atan", lambda x, p: [np.arctan(p[0] * x[0])], Op.ATAN, (-3, 3), 0.5, (-2, 2), 0.3),
]
_GRAPHS = {}


def case_graph(name):
    if name not in _GRAPHS:
        case = next(c for c in CASES if c[0] == name)
        g = trace(case[1], 1, 1)
        assert has_op(g, case[2]), f"{name}: the traced graph has no {case[2].name}"
        _GRAPHS[name] = g
    return _GRAPHS[name]


def _radius(max_rad):
    # exact points, tiny boxes and wide boxes
    return st.one_of(st.just(0.0), st.floats(0.0, 1e-7), st.floats(0.0, max_rad))


def _dp_graph():
    from models import double_pendulum as dp

    return dp.rhs_graph()


def _program_ode(program):
    """A 2-state ODE from a random straight-line program (oracles.arb_graph.run_program)."""

    def rhs(x, p):
        vals = run_program(program, x[0], x[1])
        return [vals[-1], vals[len(vals) // 2] + x[0] * 0.5]

    return trace(rhs, 2)


def _arm():
    from models.planar import planar_chain

    chain = planar_chain(3)
    return chain, chain.numeric().rhs_graph()


ARM_Q0 = np.array([0.5, -0.3, 0.2])


def random_forms(n, nb, m0, rng, scale=0.05):
    """Input forms (n, B, m0 + 2) as the solver builds them: centre, symbol coefficients,
    an error radius (never below 1e-12 relative, so float samples are inside the set)."""
    X = np.zeros((n, nb, m0 + 2))
    X[..., 0] = rng.uniform(-1.5, 1.5, (n, nb))
    X[..., 1:-1] = rng.uniform(-scale, scale, (n, nb, m0)) * (rng.uniform(size=(n, nb, m0)) < 0.7)
    X[..., -1] = rng.uniform(0, scale / 10, (n, nb)) * (rng.uniform(size=(n, nb)) < 0.5) + 1e-12 * (
        1 + np.abs(X[..., 0]))
    return X


def assert_pin_inside(C, acc, slack=1e-9):
    """Pinocchio's float accelerations inside the enclosure (slack: its own rounding)."""
    ok = (C.lo - slack <= acc) & (acc <= C.hi + slack)
    if not ok.all():
        i = np.argwhere(~ok)[0]
        raise AssertionError(f"pinocchio qdd {acc[tuple(i)]!r} outside [{C.lo[i[-1]]!r}, {C.hi[i[-1]]!r}]")

"""Float evaluation by compiled straight-line code (verified.graph.float_code) and the numeric
model's qdd through it (NumericModel.acceleration at one float point, issue 45).

Oracles: the graph's own numpy evaluation (eval_float) and the numeric model's recursion,
which the compiled code must reproduce (the same operations in the same order: bit for
bit, up to the C library's last bit in sin/exp/...); Pinocchio's aba for the physics."""
import numpy as np
import pytest

import verified.graph.float_code as fc
from mbs import robots
from mbs.dh import chain_from_dh
from mbs.errors import SingularMassMatrixError
from mbs.numeric import FLOAT_CODE_AFTER, NumericModel
from verified.graph import trace
from verified.graph.opcodes import Op


def _all_ops(x, p):
    a, b, c = x
    return [a * b - c / (b + 2.0), (a ** 3 + p[0]) * (b * b), np.sin(a) + np.cos(b) * np.tan(0.3 * c),
            np.exp(0.5 * a) - np.log(2.0 + b * b) + np.sqrt(1.0 + c * c) + np.arctan(a - c), -a]


def test_compiled_code_equals_eval_float():
    g = trace(_all_ops, 3, 1)
    f = fc.compile_float(g)
    rng = np.random.default_rng(0)
    for _ in range(200):
        x, p = rng.uniform(-2, 2, 3), rng.uniform(-1, 1, 1)
        a, b = f(x, p), g.eval_float(x, p)
        assert np.allclose(a, b, rtol=4e-16 * 8, atol=1e-300)


def test_where_python_raises_the_graph_evaluates_as_numpy_does():
    g = trace(lambda x, p: [1.0 / x[0], np.sqrt(x[1])], 2)
    out = fc.compile_float(g)([0.0, -1.0])
    assert out[0] == np.inf and np.isnan(out[1])


def test_compiled_acceleration_is_the_recursion():
    """UR5 and a damped URDF double pendulum: from the third float call on, qdd comes from
    the compiled code (it exists), and equals the recursion's value; both match
    Pinocchio's aba."""
    import pinocchio as pin

    from mbs.app.sampling import pinocchio_with
    rng = np.random.default_rng(1)
    for chain in (robots.load("ur5"), robots.load("double_pendulum")):
        n = chain.n
        fast, slow = NumericModel(chain), NumericModel(chain)
        slow._float_calls = -10**9  # (never compiles)
        model = pinocchio_with(chain)
        data = model.createData()
        for k in range(FLOAT_CODE_AFTER + 5):
            q, qd, tau = rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), rng.uniform(-1, 1, n)
            a, b = fast.acceleration(q, qd, tau), slow.acceleration(q, qd, tau)
            assert np.allclose(a, b, rtol=1e-13, atol=1e-13)
            damping = np.array([float(d) for d in slow.damping])
            ref = pin.aba(model, data, q, qd, tau - damping * qd)
            assert np.allclose(a, ref, rtol=1e-8, atol=1e-8)
        assert getattr(fast, "_float_fn", None) is not None and getattr(slow, "_float_fn", None) is None


def test_a_singular_point_still_names_the_joint():
    """M(q) singular at q2 = pi/2 (a mass on joint 1's axis): the compiled code's pivot
    check hands the point to the recursion, which raises as before."""
    chain = chain_from_dh([dict(joint="R", alpha=np.pi / 2, mass=0.0), dict(joint="R", a=1.0, mass=1.0)],
                          gravity=(0.0, 0.0, -9.81), name="gimbal")
    num = chain.numeric()
    for _ in range(FLOAT_CODE_AFTER):
        num.acceleration([0.1, 0.3], [0.0, 0.0])
    assert num._float_fn is not None
    with pytest.raises(SingularMassMatrixError, match="joint1"):
        num.acceleration([0.1, np.pi / 2], [0.0, 0.0])


def test_a_wrong_code_generator_is_caught(monkeypatch):
    """The oracle bites: code whose products are off by one part in 1e9 differs from the
    recursion (the pivots stay positive, so the compiled result is the one returned)."""
    monkeypatch.setitem(fc._BINARY, Op.MUL, "{0} * {1} * 1.000000001")
    chain = robots.load("ur5")
    fast, slow = NumericModel(chain), NumericModel(chain)
    slow._float_calls = -10**9
    q, qd = np.full(6, 0.2), np.full(6, 0.1)
    for _ in range(FLOAT_CODE_AFTER):
        a = fast.acceleration(q, qd)
    assert fast._float_fn is not None
    assert not np.allclose(a, slow.acceleration(q, qd), rtol=1e-12, atol=0)

"""Fixtures shared by the tests of verified.*."""
import numpy as np
import pytest

from oracles.taylor_cases import _arm


@pytest.fixture(scope="module")
def arm_pin():
    """(chain, graph, pinocchio qdd function) of the 3-link planar arm."""
    from mbs.pinocchio_check import _QMap

    import pinocchio as pin
    chain, g = _arm()
    model = chain.to_pinocchio()
    data = model.createData()
    qm = _QMap(chain, model)
    zero = np.zeros(chain.n)

    def qdd(q, qd):
        return qm.back(pin.aba(model, data, qm.q(q), qm.v(qd), qm.v(zero)).copy())

    return chain, g, qdd

"""A mass matrix that is singular although no link is massless (issue 12, item 4).

Point masses on the joint axes give M(q) = 0 or M(q) = diag(2, 0).  Before the fix the
float ``acceleration`` returned [0, 0] / [-9.76, 0], modes i, ii, iii reported
"completed" with qdd = 0 (``0 / 0`` folded to 0 in the LDL^T solve) and M = diag(2, 0)
gave a ZeroDivisionError traceback from the graph builder.  Now the float path, the
graph builders and ``simulate`` raise :class:`mbs.SingularMassMatrixError` (a
``ModelError``) naming the joints, and a verified run proves M(q) positive definite on
every box it used or stops with a break-down naming the joint.
"""
import numpy as np
import pytest

from mbs import ModelError, SingularMassMatrixError, chain_from_dh, chain_from_urdf
from mbs.numeric import ldl_solve
from mbs.scalar import div
from mbs.simulate import simulate
from verified.arith.interval import Interval

Q = np.array([0.1, 0.2])
BOX = Interval(np.array([0.1, 0.2, 0.0, 0.0]), np.array([0.11, 0.21, 0.0, 0.0]))


def m_zero():
    """Two joints about the base z axis, point masses on that axis: M(q) = 0."""
    return chain_from_dh([dict(joint="R", d=0.5, mass=1.0), dict(joint="R", d=0.5, mass=1.0)], name="m_zero")


def m_diag():
    """Joint 1 swings two unit masses at distance 1 (gravity along -y); joint 2's mass is
    on its own axis: M(q) = diag(2, 0)."""
    return chain_from_dh([dict(joint="R", a=1.0, mass=1.0), dict(joint="R", d=0.5, mass=1.0)],
                         gravity=(0.0, -9.81, 0.0), name="m_diag")


def gimbal(gravity=(0.0, 0.0, -9.81)):
    """Joint 1 about z, joint 2 about a horizontal axis, a unit mass at distance 1 from
    joint 2: M(q) = diag(cos(q2)^2, 1), singular at q2 = pi/2 (mass on joint 1's axis)."""
    return chain_from_dh([dict(joint="R", alpha=np.pi / 2, mass=0.0), dict(joint="R", a=1.0, mass=1.0)],
                         gravity=gravity, name="gimbal")


URDF_ON_AXIS = """<robot name="on_axis">
  <link name="base"/>
  <link name="a"><inertial><origin xyz="0 0 0.3"/><mass value="1.0"/>
    <inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial></link>
  <link name="b"><inertial><origin xyz="0 0 0.2"/><mass value="2.0"/>
    <inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="a"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="a"/><child link="b"/>
    <origin xyz="0 0 0.5"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
</robot>"""


def _one_line(err):
    msg = str(err.value)
    assert "\n" not in msg
    return msg


# ---------------------------------------------------------------------- float path

def test_mass_matrices_are_as_claimed():
    assert np.array_equal(m_zero().numeric().mass_matrix(Q), np.zeros((2, 2)))
    assert np.array_equal(m_diag().numeric().mass_matrix(Q), np.diag([2.0, 0.0]))


def test_float_acceleration_m_zero_raises():
    """Was: array([0., 0.])."""
    with pytest.raises(SingularMassMatrixError, match="singular at q = \\[0.1, 0.2\\]") as err:
        m_zero().numeric().acceleration(Q, np.zeros(2))
    assert err.value.joints == ("joint1", "joint2")
    assert "'joint1', 'joint2' have no inertia" in _one_line(err)


def test_float_acceleration_m_diag_raises():
    """Was: array([-9.76, 0.])."""
    with pytest.raises(ModelError, match="joint 'joint2' has no inertia about its axis") as err:
        m_diag().numeric().acceleration(Q, np.zeros(2))
    assert err.value.joints == ("joint2",)
    _one_line(err)


def test_float_acceleration_singular_configuration_in_a_batch():
    num = gimbal().numeric()
    q = np.array([[0.0, 0.1, 0.2], [1.0, np.pi / 2, 0.3]])  # column 1 is singular
    with pytest.raises(SingularMassMatrixError, match="at q = \\[0.1, 1.5708\\]") as err:
        num.acceleration(q, np.zeros((2, 3)))
    assert err.value.joints == ("joint1",)
    ok = num.acceleration(q[:, [0, 2]], np.zeros((2, 2)))
    assert np.isfinite(ok).all()


def test_coinciding_axes_name_the_dependent_joint():
    """Two joints about the same axis moving the same mass: M = [[1, 1], [1, 1]]."""
    chain = chain_from_dh([dict(joint="R", mass=0.0), dict(joint="R", a=1.0, mass=1.0)], name="coincident")
    with pytest.raises(SingularMassMatrixError, match="joint 'joint2' adds no inertia of its own") as err:
        chain.numeric().acceleration(Q, np.zeros(2))
    assert err.value.joints == ("joint2",)


def test_interval_acceleration_not_proven_positive_definite_raises():
    num = gimbal().numeric()
    with pytest.raises(SingularMassMatrixError, match="not proven positive definite.*joint 'joint1'"):
        num.acceleration([Interval(0.0, 0.1), Interval(1.5, 1.6)], [0.0, 0.0])
    acc = num.acceleration([Interval(0.0, 0.1), Interval(0.9, 1.0)], [0.0, 0.0])
    assert all(np.isfinite(a.lo) and np.isfinite(a.hi) for a in acc)


def test_zero_over_zero_never_folds_to_zero():
    """Was: ldl_solve(0, 0) = [0, 0] and div(0, 0) = 0."""
    with pytest.raises(ZeroDivisionError):
        div(0, 0)
    with pytest.raises(SingularMassMatrixError):
        ldl_solve([[0, 0], [0, 0]], [0, 0])
    with pytest.raises(SingularMassMatrixError):
        ldl_solve([[2.0, 0.0], [0.0, 0.0]], [1.0, 0.0])
    assert div(0, 2.0) == 0


def test_symbolic_float_paths_raise():
    sym = m_diag().symbolic()
    with pytest.raises(SingularMassMatrixError, match="joint 'joint2'"):
        sym.lambdified()(Q, np.zeros(2), np.zeros(2))
    with pytest.raises(SingularMassMatrixError, match="joint 'joint2'"):
        sym.qdd_solution()


# ---------------------------------------------------------------------- simulate

@pytest.mark.parametrize("mode", ["i", "ii", "iii"])
def test_simulate_m_zero_raises_before_integrating(mode):
    """Was: status "completed" with qdd = 0 in all three modes."""
    with pytest.raises(SingularMassMatrixError) as err:
        simulate(m_zero(), BOX, 0.01, mode=mode)
    assert err.value.joints == ("joint1", "joint2")
    _one_line(err)


@pytest.mark.parametrize("mode", ["i", "ii", "iii"])
def test_simulate_m_diag_raises_model_error(mode):
    """Was: ZeroDivisionError traceback (modes i, ii), "completed" with qdd2 = 0 (mode iii)."""
    with pytest.raises(ModelError, match="joint 'joint2' has no inertia about its axis") as err:
        simulate(m_diag(), BOX, 0.01, mode=mode)
    _one_line(err)


def test_simulate_urdf_with_masses_on_the_axes_raises():
    chain = chain_from_urdf(URDF_ON_AXIS)
    with pytest.raises(SingularMassMatrixError) as err:
        simulate(chain, BOX, 0.01, mode="i")
    assert err.value.joints == ("j1", "j2")
    _one_line(err)


def test_simulate_singular_configuration_at_the_box_centre_raises():
    box = Interval(np.array([0.0, np.pi / 2 - 1e-3, 0.0, 0.0]), np.array([0.0, np.pi / 2 + 1e-3, 0.0, 0.0]))
    with pytest.raises(SingularMassMatrixError, match="centre of the initial box.*joint 'joint1'"):
        simulate(gimbal(), box, 0.01, mode="i")


def test_break_down_names_the_joint():
    """The initial box reaches the singular configuration q2 = pi/2 (its centre does
    not): the run breaks down and the reason names joint1.  Was: only "Taylor
    coefficients are unbounded (division by an interval containing zero)"."""
    box = Interval(np.array([0.0, np.pi / 2 - 0.002, 0.0, 0.0]), np.array([0.0, np.pi / 2 + 1e-4, 0.0, 0.0]))
    sol = simulate(gimbal(), box, 0.01, mode="i")  # (auto: the box is split in 2, the piece at q2 = pi/2 fails)
    assert sol.status == "breakdown"
    assert "not proven positive definite" in sol.reason and "joint 'joint1'" in sol.reason
    # (issue 39, item 2) the cause is measured: here the model, at a configuration in the box
    assert "the model: M(q) is singular or nearly so at q = [0, 1.57" in sol.reason
    assert "\n" not in sol.reason


def test_wide_box_blames_the_set_not_the_model():
    """(issue 39, item 2) A box too wide for one piece, on a chain whose M(q) is positive
    definite everywhere: the hint names the set's width and what helps (subdivision),
    not the model's inertia (the old hint asked 'do the links this joint moves have
    inertia about its axis?')."""
    from mbs.simulate import _pivot_diagnosis
    chain = chain_from_dh([dict(joint="R", a=1.0, mass=1.0), dict(joint="R", a=1.0, mass=1.0)], name="planar2")
    num = chain.numeric()
    lo, hi = np.array([-3.0, -3.0]), np.array([3.0, 3.0])
    msg = _pivot_diagnosis(num, lo, hi, chain.joint_names, 1)
    assert "the set, not the model" in msg and "subdivision" in msg and "6 wide" in msg, msg
    assert "inertia about" not in msg
    # the same check finds the model's singular configuration of the gimbal
    g = gimbal()
    msg = _pivot_diagnosis(g.numeric(), np.array([0.0, 1.0]), np.array([0.0, 2.0]), g.joint_names, 0)
    assert "the model" in msg and "joint 'joint1'" in msg, msg


def test_a_completed_run_must_prove_every_box():
    """The check does not rely on the rhs enclosure becoming unbounded ([0, 0] / D is
    [0, 0] for a D containing 0): a run whose tube reaches a singular configuration
    is cut back to the start of that step and becomes a break-down naming the joint."""
    from mbs.simulate import _prove_mass_matrix

    chain = gimbal(gravity=(0.0, 0.0, 0.0))
    box = Interval(np.array([0.0, 1.0, 0.0, 0.0]), np.array([0.0, 1.001, 0.0, 0.0]))
    sol = simulate(chain, box, 0.02, mode="i", output_dt=0.01, h_max=0.005)
    assert sol.status == "completed" and len(sol.tube) >= 3
    _prove_mass_matrix(chain, sol)
    assert sol.status == "completed"  # M(q) is proven positive definite on every box
    bad = sol.tube[1].copy()
    bad.hi[:, 1] = np.pi / 2 + 0.01  # pretend step 1 reached q2 = pi/2
    sol.tube[1] = bad
    t_cut = float(sol.tube_t[1])
    _prove_mass_matrix(chain, sol)
    assert sol.status == "breakdown" and sol.t_reached == t_cut
    assert "joint 'joint1'" in sol.reason and "not proven positive definite" in sol.reason
    assert len(sol.tube) == 1 and len(sol.tube_t) == 2 and (sol.t <= t_cut).all()


# ---------------------------------------------------------------------- positive control

def test_double_pendulum_still_simulates():
    from models import double_pendulum as dp

    chain = dp.dh_chain()
    q = np.array([0.3, -0.2])
    assert np.isfinite(chain.numeric().acceleration(q, np.zeros(2))).all()
    lo, hi = dp.initial_box()
    for mode in ("i", "ii"):
        sol = simulate(chain, Interval(lo, hi), 0.02, mode=mode)
        assert sol.status == "completed", (mode, sol.reason)
        assert sol.t[-1] == 0.02

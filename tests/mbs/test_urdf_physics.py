"""Physics a URDF states that the model cannot honour is not dropped silently (issue 39,
item 5): Coulomb friction (``<dynamics friction>``) is warned about once per model,
naming the joints; an inertia that no rigid body has (principal moments violating the
triangle inequality) is refused with a one-line ModelError naming the link."""
import warnings

import pytest

from mbs import ModelError, chain_from_urdf, robots
from mbs.inertia import TRIANGLE_TOL

ROBOT = """<robot name="r">
  <link name="base"/>
  <link name="arm"><inertial><origin xyz="0 0 0.5" rpy="0.3 0.2 0.1"/><mass value="1.0"/>
    <inertia ixx="{ixx}" ixy="0" ixz="0" iyy="{iyy}" iyz="0" izz="{izz}"/></inertial></link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="arm"/>
    <axis xyz="0 1 0"/>{dyn1}</joint>
  <link name="hand"><inertial><origin xyz="0 0 0.2"/><mass value="0.5"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <joint name="elbow" type="revolute"><parent link="arm"/><child link="hand"/>
    <origin xyz="0 0 1"/><axis xyz="0 1 0"/>{dyn2}</joint>
</robot>"""


def urdf(ixx="0.1", iyy="0.1", izz="0.1", dyn1="", dyn2=""):
    return ROBOT.format(ixx=ixx, iyy=iyy, izz=izz, dyn1=dyn1, dyn2=dyn2)


def load(xml, **kw):
    """chain_from_urdf with every warning recorded: (chain, [messages])."""
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        chain = chain_from_urdf(xml, **kw)
    return chain, [str(w.message) for w in rec if issubclass(w.category, UserWarning)]


# ----------------------------------------------------------------- Coulomb friction
def test_friction_warned_once_naming_the_joints():
    xml = urdf(dyn1='<dynamics damping="0.3" friction="1.5"/>',
               dyn2='<dynamics friction="2"/>')
    chain, msgs = load(xml)
    assert len(msgs) == 1, msgs
    m = msgs[0]
    assert "'shoulder' (1.5)" in m and "'elbow' (2)" in m
    assert "Coulomb friction" in m and "not modeled" in m and "\n" not in m
    assert chain.damping == [0.3, 0]      # the viscous damping beside it is still used


def test_friction_on_one_joint_names_only_that_one():
    _, msgs = load(urdf(dyn2='<dynamics damping="0.1" friction="0.7"/>'))
    assert len(msgs) == 1 and "'elbow' (0.7)" in msgs[0] and "shoulder" not in msgs[0]


@pytest.mark.parametrize("dyn", ["", '<dynamics damping="0.2"/>', '<dynamics friction="0"/>',
                                 '<dynamics damping="0.2" friction="0.0"/>'])
def test_no_warning_without_friction(dyn):
    _, msgs = load(urdf(dyn1=dyn, dyn2=dyn))
    assert msgs == []


def test_friction_of_a_locked_joint_is_not_warned():
    xml = urdf(dyn1='<dynamics friction="1"/>', dyn2='<dynamics friction="3"/>')
    _, msgs = load(xml, lock={"elbow": 0.2})
    assert len(msgs) == 1 and "'shoulder'" in msgs[0] and "elbow" not in msgs[0]


def test_friction_not_a_number_names_joint():
    with pytest.raises(ModelError, match=r"joint 'shoulder': friction 'lots' is not a number"):
        chain_from_urdf(urdf(dyn1='<dynamics friction="lots"/>'))


def test_z1_friction_is_warned():
    """example-robot-data's Unitree z1 has 1-2 N m of Coulomb friction on every joint."""
    try:
        path = robots.urdf_path("z1")
    except ModelError:
        pytest.skip("example-robot-data without z1")
    chain, msgs = load(path)
    assert len(msgs) == 1, msgs
    assert all(f"'{j}'" in msgs[0] for j in chain.joint_names)
    assert "'joint2' (2)" in msgs[0]


@pytest.mark.parametrize("name", sorted(robots.KNOWN))
def test_shipped_robots_load_without_warnings(name):
    _, msgs = load(robots.urdf_path(name),
                   lock={j: 0.0 for j in robots.PANDA_FINGERS} if name == "panda" else None)
    assert msgs == []


# ----------------------------------------------------- inertia: the triangle inequality
def test_triangle_inequality_violation_refused_naming_link():
    with pytest.raises(ModelError, match=r"link 'arm'.*triangle inequality") as e:
        chain_from_urdf(urdf(ixx="0.01", iyy="0.01", izz="1"))
    assert isinstance(e.value, ValueError) and "\n" not in str(e.value)
    assert "(0.01, 0.01, 1)" in str(e.value)


def test_placeholder_inertia_refused():
    """The all-1e-6 placeholder (ixx = ixy = ... = izz) of some files: principal moments
    (0, 0, 3e-6), positive semi-definite but no body's."""
    xml = urdf().replace('<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/>',
                         '<inertia ixx="1e-6" ixy="1e-6" ixz="1e-6" iyy="1e-6" iyz="1e-6" izz="1e-6"/>')
    with pytest.raises(ModelError, match=r"^link 'hand': principal moments .* triangle inequality"):
        chain_from_urdf(xml)


@pytest.mark.parametrize("moments", [
    ("0", "0", "0"),                    # point mass
    ("0", "0.1", "0.1"),                # thin rod along x
    ("0.1", "0", "0.1"),                # thin rod along y
    ("0.3333", "0.08333", "0.4167"),    # flat 1 x 2 plate, 4 significant digits (slightly over)
    ("0.02", "0.03", "0.05"),           # flat plate, exact
    ("0.1", "0.1", "0.1"),
])
def test_edge_inertias_accepted(moments):
    ixx, iyy, izz = moments
    chain, msgs = load(urdf(ixx=ixx, iyy=iyy, izz=izz))
    assert chain.n == 2 and msgs == []


def test_rotated_rod_accepted():
    """A rod along the diagonal (off-diagonal entries, one zero principal moment up to
    round-off) is accepted."""
    c = 1.0 / 3.0
    xml = urdf().replace(
        '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/>',
        f'<inertia ixx="{2 * c!r}" ixy="{-c!r}" ixz="{-c!r}" iyy="{2 * c!r}" iyz="{-c!r}" '
        f'izz="{2 * c!r}"/>')
    assert load(xml)[0].n == 2


def test_tolerance_is_relative_to_trace():
    """Just inside the tolerance passes, clearly outside fails, at any scale."""
    for s in (1e-8, 1.0, 1e4):
        ok = urdf(ixx=repr(s), iyy=repr(s), izz=repr(2 * s * (1 + TRIANGLE_TOL)))
        assert load(ok)[0].n == 2
        bad = urdf(ixx=repr(s), iyy=repr(s), izz=repr(2 * s * (1 + 5 * TRIANGLE_TOL)))
        with pytest.raises(ModelError, match="link 'arm'"):
            chain_from_urdf(bad)


def test_not_positive_semidefinite_still_refused_one_line():
    with pytest.raises(ModelError, match=r"^link 'arm': inertia tensor is not positive") as e:
        chain_from_urdf(urdf(ixx="-0.1"))
    assert "\n" not in str(e.value)


def test_dh_chains_keep_accepting_corkes_puma():
    """The triangle check is for URDF links only: Corke's Puma 560 data (link 1:
    diag(0, 0.35, 0)) is a classic DH data set and stays loadable."""
    from models.puma560 import puma560
    for convention in ("standard", "modified"):
        assert puma560(convention).n == 6


def test_base_link_inertia_is_not_checked():
    """The base link is fixed to the world: its tensor never enters the dynamics, so a
    placeholder there (anymal, go1, hyq ship one) does not refuse the model; the same
    tensor on a moving link does."""
    bad = '<inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="1"/></inertial>'
    xml = urdf().replace('<link name="base"/>', f'<link name="base">{bad}</link>')
    chain, _ = load(xml)
    assert chain is not None
    with pytest.raises(ModelError, match="link 'arm'"):
        load(urdf(ixx="0.01", iyy="0.01", izz="1"))

"""Bad input gives a clear ModelError (a ValueError) naming the link or joint."""
import numpy as np
import pytest
import sympy

import mbs
from mbs import ModelError, UnsupportedJointError, chain_from_dh, chain_from_urdf

GOOD = """<robot name="r">
  <link name="base"/>
  <link name="arm"><inertial><origin xyz="0 0 0.5" rpy="0 0 0"/><mass value="{mass}"/>
    <inertia ixx="{ixx}" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <joint name="shoulder" type="{jtype}"><parent link="base"/><child link="arm"/>
    <axis xyz="0 1 0"/>{extra}</joint>
</robot>"""


def urdf(mass="1.0", ixx="0.1", jtype="revolute", extra=""):
    return GOOD.format(mass=mass, ixx=ixx, jtype=jtype, extra=extra)


def test_good_urdf_loads():
    c = chain_from_urdf(urdf())
    assert c.joint_names == ["shoulder"] and c.n == 1


def test_modelerror_is_valueerror():
    assert issubclass(ModelError, ValueError)
    assert issubclass(UnsupportedJointError, ModelError)


@pytest.mark.parametrize("text", ["<robot><link", "not xml at all <", "<robot name='x'></robot>"])
def test_malformed_urdf(text):
    with pytest.raises(ModelError):
        chain_from_urdf(text)


def test_missing_file():
    with pytest.raises(ModelError, match="does not exist"):
        chain_from_urdf("/nonexistent/robot.urdf")


def test_negative_mass_names_link():
    with pytest.raises(ModelError, match=r"link 'arm'.*negative mass"):
        chain_from_urdf(urdf(mass="-1"))


def test_inertia_not_positive_definite_names_link():
    with pytest.raises(ModelError, match=r"link 'arm'.*positive"):
        chain_from_urdf(urdf(ixx="-0.5"))


def test_inertial_without_inertia():
    xml = urdf().replace('<inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/>', "")
    with pytest.raises(ModelError, match=r"link 'arm'.*without <inertia>"):
        chain_from_urdf(xml)


def test_missing_inertial_on_moving_link():
    xml = urdf().split("<link name=\"arm\">")[0] + '<link name="arm"/>' + \
        urdf().split("</inertial></link>")[1]
    with pytest.raises(ModelError, match=r"joint 'shoulder'.*massless"):
        chain_from_urdf(xml)


def test_unknown_joint_type():
    with pytest.raises(ModelError, match=r"joint 'shoulder'.*unknown joint type 'weird'"):
        chain_from_urdf(urdf(jtype="weird"))


@pytest.mark.parametrize("jtype", ["floating", "planar"])
def test_floating_and_planar_refused(jtype):
    with pytest.raises(UnsupportedJointError, match=rf"joint 'shoulder'.*{jtype}"):
        chain_from_urdf(urdf(jtype=jtype))


def test_mimic_refused_with_hint_and_lock_works():
    xml = """<robot name="m"><link name="b"/>
      <link name="l1"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
      <link name="l2"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
      <joint name="j1" type="revolute"><parent link="b"/><child link="l1"/><axis xyz="0 0 1"/></joint>
      <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><axis xyz="0 0 1"/>
        <mimic joint="j1" multiplier="1"/></joint></robot>"""
    with pytest.raises(UnsupportedJointError, match=r"joint 'j2'.*mimic.*lock"):
        chain_from_urdf(xml)
    c = chain_from_urdf(xml, lock={"j2": 0.3})
    assert c.joint_names == ["j1"]


def test_negative_damping():
    with pytest.raises(ModelError, match=r"joint 'shoulder'.*damping"):
        chain_from_urdf(urdf(extra='<dynamics damping="-1"/>'))


def test_dh_row_wrong_length():
    with pytest.raises(ModelError, match=r"DH row 1 .* has 5 entries"):
        chain_from_dh([("R", 0, 0, 1, 0, 1, None, None), ("R", 0, 0, 1, 0)])


def test_dh_unknown_joint_and_convention_and_keys():
    with pytest.raises(ModelError, match="unknown joint type 'X'"):
        chain_from_dh([dict(joint="X", a=1, mass=1)])
    with pytest.raises(ModelError, match="unknown DH convention"):
        chain_from_dh([dict(joint="R", a=1, mass=1)], convention="weird")
    with pytest.raises(ModelError, match="unknown key"):
        chain_from_dh([dict(joint="R", a=1, mass=1, lenght=2)])
    with pytest.raises(ModelError, match="empty"):
        chain_from_dh([])


def test_dh_negative_mass_and_bad_inertia():
    with pytest.raises(ModelError, match=r"link 'link2'.*negative mass"):
        chain_from_dh([dict(joint="R", a=1, mass=1), dict(joint="R", a=1, mass=-2)])
    with pytest.raises(ModelError, match=r"joint1.*positive"):
        chain_from_dh([dict(joint="R", a=1, mass=1, inertia=[[1, 0, 0], [0, -1, 0], [0, 0, 1]])])
    with pytest.raises(ModelError, match="not symmetric"):
        chain_from_dh([dict(joint="R", a=1, mass=1, inertia=[[1, 0.5, 0], [0, 1, 0], [0, 0, 1]])])
    with pytest.raises(ModelError, match="com must have 3 entries"):
        chain_from_dh([dict(joint="R", a=1, mass=1, com=(1, 2))])
    with pytest.raises(ModelError, match="expected a number"):
        chain_from_dh([dict(joint="R", a="one", mass=1)])


def test_numeric_of_symbolic_chain_asks_for_subs():
    l = sympy.Symbol("l", positive=True)
    c = chain_from_dh([dict(joint="R", a=l, mass=1)])
    with pytest.raises(ModelError, match=r"free symbols.*subs"):
        c.numeric()
    assert c.subs({l: 2.0}).numeric().mass_matrix([0.1])[0, 0] == pytest.approx(4.0)


def test_wrong_state_length_is_a_modelerror():
    c = chain_from_dh([dict(joint="R", a=1, mass=1)])
    with pytest.raises(ModelError, match="q must have 1 entries"):
        c.numeric().mass_matrix([0.1, 0.2])


def test_lock_unknown_joint():
    c = chain_from_urdf(urdf())
    with pytest.raises(ModelError, match="unknown joint"):
        c.lock({"nope": 0.0})


def test_not_a_tree():
    xml = urdf().replace("</robot>", '<joint name="loop" type="fixed"><parent link="arm"/>'
                         '<child link="base"/></joint></robot>')
    with pytest.raises(ModelError):
        chain_from_urdf(xml)


def test_massless_link_message_fits_the_input():
    """Issue 12, item 6: a DH chain is told about its DH row and the DH mass/inertia
    entries, not about URDF <inertial>; a URDF still gets the <inertial> hint."""
    with pytest.raises(ModelError, match=r"joint 'elbow'.*massless.*DH row 1") as info:
        chain_from_dh([dict(joint="R", a=1, mass=1), dict(joint="R", a=1, name="elbow")])
    msg = str(info.value)
    assert "<inertial>" not in msg and "URDF" not in msg and "'mass'" in msg and "'inertia'" in msg, msg
    # also when the zero mass comes from substituting a DH parameter
    m = sympy.Symbol("m", positive=True)
    with pytest.raises(ModelError, match=r"joint 'joint2'.*DH row 1") as info:
        chain_from_dh([dict(joint="R", a=1, mass=1), dict(joint="R", a=1, mass=m)]).subs({m: 0})
    assert "<inertial>" not in str(info.value)
    # a URDF link without <inertial>
    xml = urdf().split("<link name=\"arm\">")[0] + '<link name="arm"/>' + urdf().split("</inertial></link>")[1]
    with pytest.raises(ModelError, match=r"joint 'shoulder'.*massless.*<inertial>") as info:
        chain_from_urdf(xml)
    assert "DH" not in str(info.value)

"""URDF robots of example-robot-data, located via :mod:`mbs.robots`."""
from __future__ import annotations

from mbs import robots as _r


def double_pendulum():
    """example-robot-data's double_pendulum.urdf (damping 0.05 on both joints)."""
    return _r.load("double_pendulum")


def ur5():
    """UR5 (ur5_robot.urdf), 6 dof."""
    return _r.load("ur5")


def panda_arm():
    """Franka panda, arm joints only: the fingers (one is a mimic joint) are locked at 0."""
    return _r.load("panda")


ALL = {"double_pendulum": double_pendulum, "ur5": ur5, "panda_arm": panda_arm}

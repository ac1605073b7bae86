"""mbs -- multibody modeling front-end (DH/URDF chains, symbolic and numeric models).

Main entry points::

    from mbs import chain_from_dh, chain_from_urdf
    chain = chain_from_urdf(mbs.robots.urdf_path("ur5"))
    chain = chain_from_dh(rows, convention="standard")
    sym = chain.symbolic()     # sympy: M, K, P, gravity, coriolis, eom, H, dHdt
    num = chain.numeric()      # generic scalar: mass_matrix (crba), bias (rnea), acceleration
    chain.to_pinocchio()       # the referee; mbs.check.compare_with_pinocchio(chain)
"""
from .errors import ModelError, SingularMassMatrixError, UnsupportedJointError
from .inertia import RigidInertia
from .chain import Chain, Joint, Body, build_tree
from .dh import chain_from_dh
from .urdf import chain_from_urdf
from . import robots, cache
from .check import compare_with_pinocchio

__all__ = ["Chain", "Joint", "Body", "RigidInertia", "ModelError", "SingularMassMatrixError", "UnsupportedJointError",
           "build_tree", "chain_from_dh", "chain_from_urdf", "robots", "cache", "compare_with_pinocchio"]

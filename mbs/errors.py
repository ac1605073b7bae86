"""Exceptions raised by the modeling front-end.

Every problem with user input (a malformed URDF, a bad DH row, a negative mass, an
inertia tensor that is not positive semi-definite, ...) is reported as a
:class:`ModelError`, a subclass of :class:`ValueError`, whose message names the
offending link or joint.  Code that only wants to catch "bad model" errors can
``except mbs.ModelError``.
"""


class ModelError(ValueError):
    """A robot description (URDF, DH table, inertial data) is invalid or unsupported."""


class UnsupportedJointError(ModelError):
    """A joint type (floating, planar, mimic, ...) that this library refuses."""

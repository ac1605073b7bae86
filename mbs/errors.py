"""Exceptions raised by the modeling front-end.

Every problem with user input (a malformed URDF, a bad DH row, a negative mass, an
inertia tensor that is not positive semi-definite, ...) is reported as a
:class:`ModelError`, a subclass of :class:`ValueError`, whose message names the
offending link or joint.  Code that only wants to catch "bad model" errors can
``except mbs.ModelError``.
"""


class ModelError(ValueError):
    """A robot description (URDF, DH table, inertial data) is invalid or unsupported.

    ``detail``: the message without the name of the argument it is about, where the
    messages of a subclass start with one (``prefix``: ``"params "`` for
    :class:`mbs.uncertain.ParameterError`, ``"control "`` for
    :class:`mbs.control.ControlError`), for callers that name that input their own way
    (a scene file's ``[parameters]`` and ``[control]`` tables)."""

    #: the argument name the messages of this class start with ("" : none)
    prefix = ""

    @property
    def detail(self) -> str:
        msg = str(self)
        return msg[len(self.prefix):] if self.prefix and msg.startswith(self.prefix) else msg


class UnsupportedJointError(ModelError):
    """A joint type (floating, planar, mimic, ...) that this library refuses."""


class SingularMassMatrixError(ModelError):
    """The mass matrix M(q) is singular (or not proven positive definite) although the
    model passed validation, e.g. because the links a joint moves have their masses on
    its axis.  ``joints`` names the joints whose LDL^T pivots are zero / not proven
    positive (``indices`` are their positions in ``q``); ``kind`` says how that was
    found: "constant" (for every q), "float" (at a point) or "interval" (on a box)."""

    def __init__(self, message, joints=(), indices=(), kind=None, batch_index=0):
        super().__init__(message)
        self.joints = tuple(joints)
        self.indices = tuple(indices)
        self.kind = kind
        self.batch_index = batch_index

# Long (680 lines) on purpose: references, controllers and the closed loop share one generic-scalar _Context.
"""Joint torques and controllers in the equations of motion (issue 14 item 1).

A closed loop ``M(q) qdd = tau(t, q, qd, p) - D qd - c(q, qd) - g(q)`` (eq. (2)/(6))
is traced into one expression graph: every controller below is written once over the
generic scalar (:mod:`mbs.scalar`), so the same code runs over floats (the sampled
oracle), intervals and graph tracers.  Torques of several controllers add up.

- :class:`PD`: ``tau = Kp (q_ref(t) - q) + Kd (qd_ref(t) - qd)`` (+ ``g_nom(q)`` with
  ``gravity_compensation=True``), gains per joint or as matrices;
  ``bandwidth=w`` picks ``Kp = w^2 M_nom(q_ref(0))``, ``Kd = 2 zeta w M_nom(q_ref(0))``;
- :class:`ComputedTorque`: ``tau = M_nom(q) (qdd_ref + Kp e + Kd e') + b_nom(q, qd)
  + D_nom qd`` with a nominal model that may differ from the plant;
- :class:`Disturbance`: constant unknown joint torques ``w`` in ``[lo, hi]`` (graph
  parameters: every constant value in the box is covered; a disturbance that varies
  in time inside the box is *not* covered by this);
- :class:`FunctionController`: any ``tau(t, q, qd, p)`` over the generic scalar
  (``p``: a dict of the function's own parameters by name).

References: a constant pose (default: the centre of the initial q box),
:class:`Quintic` (rest-to-rest quintic in a given time), or any
:class:`Reference`.  Time-dependent references (and functions of ``t``) add the time
as a last state ``t`` with ``t' = 1``, started at the point ``t0``: its Taylor series
is exact (``t + h``), it contributes nothing to the step-size estimate (its
coefficients of order >= 2 are zero) and its enclosure stays a point up to rounding.

The nominal model of a controller (``nominal=``): ``None`` -- the plant at the
midpoints of its uncertain parameters; a dict of point parameters applied to the
plant's chain (``{"mass_scale": 1.1}``: 10% heavier; see :mod:`mbs.uncertain`); an
:class:`mbs.Chain` or a model name with the same joints.

The energy rate with inputs is ``dH/dt = qd^T tau - qd^T D qd`` (eq. (7)); the
closed loop gives it as a graph so the energy test of mode ii keeps working.
"""
from __future__ import annotations

import math
from numbers import Real

import numpy as np

from verified.graph import Op, trace

from .chain import Chain
from .errors import ModelError
from .robots import load_model
from .scalar import add, mul, sub, total
from .uncertain import ChainParameters, ParameterError, parse_value

__all__ = ["ControlError", "Reference", "Constant", "Quintic", "Controller", "PD", "ComputedTorque",
           "Disturbance", "FunctionController", "ClosedLoop", "parse_control", "closed_loop"]


class ControlError(ModelError, ValueError):
    """A bad control specification (unknown joint, wrong gain shape, NaN gains, ...);
    the messages start with "control" (:attr:`mbs.errors.ModelError.detail`: without it)."""

    prefix = "control "


# ---------------------------------------------------------------------- helpers
class _Context:
    """What controllers resolve their specifications against."""

    def __init__(self, chain, nominal_default, q_init=None, model_name=None):
        self.chain = chain
        self.n = chain.n
        self.joint_names = list(chain.joint_names)
        self.model_name = model_name or chain.name
        self._nominal_default = nominal_default   # float NumericModel (plant at midpoints)
        self.q_init = None if q_init is None else np.asarray(q_init, float)

    def nominal(self, spec, where):
        if spec is None:
            return self._nominal_default
        if isinstance(spec, dict):
            try:
                cp = ChainParameters(self.chain, spec, model_name=self.model_name)
            except ParameterError as e:
                raise ControlError(f"{where} nominal: {e}") from None
            if np.any(cp.lo != cp.hi):
                raise ControlError(f"{where} nominal: a nominal model takes point values, not intervals "
                                   f"({', '.join(k for k, a, b in zip(cp.names, cp.lo, cp.hi) if a != b)})")
            return cp.float_model()
        if isinstance(spec, str):
            spec = load_model(spec)
        if isinstance(spec, Chain):
            if spec.n != self.n:
                raise ControlError(f"{where} nominal: model {spec.name!r} has {spec.n} joints, the plant {self.n}")
            return spec.numeric()
        if hasattr(spec, "_crba") and hasattr(spec, "joint_transforms"):
            return spec
        raise ControlError(f"{where} nominal: expected None, a dict of point parameters, a model name or an "
                           f"mbs.Chain, got {type(spec).__name__}")

    def joint_index(self, name, where):
        if name not in self.joint_names:
            raise ControlError(f"{where}: unknown joint {name!r}; joints of {self.model_name!r}: "
                               f"{', '.join(self.joint_names)}")
        return self.joint_names.index(name)

    def vector(self, value, where, *, default=None, nonneg=False, matrix=False):
        """A per-joint vector (n,) from a number, a sequence of n numbers or a table
        {joint: number} (joints not named get ``default``); with ``matrix`` also an
        (n, n) array: returns ndarray (n,) or (n, n)."""
        n = self.n
        if isinstance(value, dict):
            v = np.full(n, np.nan if default is None else float(default))
            for k, x in value.items():
                v[self.joint_index(k, where)] = _number(x, f"{where}.{k}")
            if np.isnan(v).any():
                missing = [self.joint_names[i] for i in np.flatnonzero(np.isnan(v))]
                raise ControlError(f"{where}: no value for joint(s) {', '.join(missing)}")
        elif isinstance(value, bool):
            raise ControlError(f"{where}: expected a number, {n} numbers or a table joint = number, got {value!r}")
        elif isinstance(value, (Real, np.floating, np.integer)):
            v = np.full(n, _number(value, where))
        else:
            try:
                arr = np.asarray(value, dtype=float)
            except (TypeError, ValueError):
                raise ControlError(f"{where}: expected a number, {n} numbers or a table joint = number, "
                                   f"got {value!r}") from None
            if arr.shape == (n,) or (matrix and arr.shape == (n, n)):
                v = arr
            else:
                shapes = f"({n},)" + (f" or ({n}, {n})" if matrix else "")
                raise ControlError(f"{where}: wrong shape {arr.shape}, expected {shapes} (joints "
                                   f"{', '.join(self.joint_names)})")
        if not np.all(np.isfinite(v)):
            raise ControlError(f"{where}: NaN or infinite entries in {value!r}")
        if nonneg and v.ndim == 1 and np.any(v < 0):
            raise ControlError(f"{where}: gains must be >= 0, got {value!r}")
        return v


def _number(x, where) -> float:
    if isinstance(x, bool) or not isinstance(x, (Real, np.floating, np.integer)):
        raise ControlError(f"{where}: expected a number, got {x!r}")
    v = float(x)
    if not math.isfinite(v):
        raise ControlError(f"{where}: {x!r} is not finite")
    return v


def _matvec(K, v):
    """K v for a gain vector (diagonal) or matrix K (floats) and generic scalars v."""
    n = len(v)
    if K.ndim == 1:
        return [mul(float(K[i]), v[i]) if K[i] != 0 else 0 for i in range(n)]
    return [total(mul(float(K[i, j]), v[j]) for j in range(n) if K[i, j] != 0) for i in range(n)]


def _nominal_dynamics(model, q, qd=None):
    """(M rows, b = c + g, D) of a float numeric model at generic scalars q, qd; a model
    with a factored-out mass scale (:mod:`mbs.uncertain`) is scaled back."""
    n = model.n
    X = model.joint_transforms(q)
    s = getattr(model, "energy_scale", 1)
    M = model._crba(X)
    b = model._rnea(X, [0] * n if qd is None else qd, [0] * n)
    D = list(model.damping)
    if not (isinstance(s, (int, float)) and s == 1):
        s = float(s)
        M = [[mul(s, x) for x in row] for row in M]
        b = [mul(s, x) for x in b]
        D = [mul(s, d) for d in D]
    return M, b, D


# ---------------------------------------------------------------------- references
class Reference:
    """A joint reference ``t -> (q_ref, qd_ref, qdd_ref)`` over the generic scalar."""

    time_dependent = True

    def resolve(self, ctx, where):
        return self

    def __call__(self, t):  # pragma: no cover - interface
        raise NotImplementedError

    def t_end(self):
        """The last time the reference is valid for (None: always)."""
        return None


class Constant(Reference):
    """A constant pose ``q_ref`` (rad, m), zero rates."""

    time_dependent = False

    def __init__(self, q):
        self.q = q

    def resolve(self, ctx, where):
        if self.q is None:
            if ctx.q_init is None:
                raise ControlError(f"{where}: no q_ref and no initial box to take its centre from")
            return Constant(np.array(ctx.q_init[:ctx.n], float))
        return Constant(ctx.vector(self.q, f"{where} q_ref"))

    def __call__(self, t):
        n = len(self.q)
        return [float(v) for v in self.q], [0] * n, [0] * n


class Quintic(Reference):
    """Rest-to-rest quintic ``q(s) = q0 + (q1 - q0)(10 s^3 - 15 s^4 + 6 s^5)``,
    ``s = (t - t0) / duration``; valid for ``t0 <= t <= t0 + duration`` (the
    polynomial is not continued past it: a run longer than that is refused)."""

    def __init__(self, q_start, q_end, duration, t0=0.0):
        self.q_start, self.q_end = q_start, q_end
        self.duration, self.t0 = duration, t0

    def resolve(self, ctx, where):
        d = _number(self.duration, f"{where} duration")
        if not d > 0:
            raise ControlError(f"{where} duration: must be > 0, got {d!r}")
        q0 = ctx.vector(self.q_start if self.q_start is not None else ctx.q_init[:ctx.n], f"{where} q_start")
        q1 = ctx.vector(self.q_end, f"{where} q_end")
        return Quintic(q0, q1, d, _number(self.t0, f"{where} t0"))

    def t_end(self):
        return self.t0 + self.duration

    def __call__(self, t):
        d = self.duration
        s = mul(sub(t, self.t0), 1.0 / d) if self.t0 else mul(t, 1.0 / d)
        s2 = mul(s, s)
        s3 = mul(s2, s)
        # shape and its derivatives in s: 10 s^3 - 15 s^4 + 6 s^5, 30 s^2 - 60 s^3 + 30 s^4, 60 s - 180 s^2 + 120 s^3
        p = mul(s3, add(10, mul(s, add(-15, mul(6, s)))))
        dp = mul(s2, add(30, mul(s, add(-60, mul(30, s)))))
        ddp = mul(s, add(60, mul(s, add(-180, mul(120, s)))))
        q, qd, qdd = [], [], []
        for a, b in zip(self.q_start, self.q_end):
            dq = float(b - a)
            q.append(add(float(a), mul(dq, p)))
            qd.append(mul(dq / d, dp))
            qdd.append(mul(dq / (d * d), ddp))
        return q, qd, qdd


def _reference(spec, ctx, where) -> Reference:
    if spec is None or not isinstance(spec, Reference):
        spec = Constant(spec)
    return spec.resolve(ctx, where)


# ---------------------------------------------------------------------- controllers
class Controller:
    """A joint-torque law ``tau(t, q, qd, p)``.  Subclasses implement :meth:`resolve`
    (check the specification against the model; returns a resolved copy),
    :meth:`parameters` ([(name, lo, hi)] of their own graph parameters) and
    :meth:`torque` (generic scalars in, a list of n torques out)."""

    uses_time = False
    name = "controller"

    def resolve(self, ctx) -> "Controller":  # pragma: no cover - interface
        raise NotImplementedError

    def parameters(self):
        return []

    def torque(self, t, q, qd, p):  # pragma: no cover - interface
        raise NotImplementedError

    def t_end(self):
        return None


class PD(Controller):
    """Joint PD control towards a reference (see the module docstring).

    kp, kd : a number, n numbers, a table {joint: number} (joints not named get 0) or
        an (n, n) matrix; N m/rad and N m s/rad.  Or ``bandwidth`` (rad/s) and
        ``damping_ratio`` (default 1): ``Kp = w^2 M_nom(q_ref(0))``,
        ``Kd = 2 zeta w M_nom(q_ref(0))`` (``gains="mass_matrix"``, default: the
        closed loop linearized at the reference is ``e'' + 2 zeta w e' + w^2 e = 0``
        for every joint) or their diagonals (``gains="diagonal"``: independent joint
        loops, coupled through M); on robots "mass_matrix" verifies much further
        (docs/lab/code_notes.md).
    q_ref : None (the centre of the initial q box), n numbers / {joint: number}, or a
        :class:`Reference` such as :class:`Quintic`.
    gravity_compensation : add ``g_nom(q)`` of the nominal model.
    nominal : see the module docstring.
    """

    name = "pd"

    def __init__(self, kp=None, kd=None, q_ref=None, *, gravity_compensation=False, nominal=None,
                 bandwidth=None, damping_ratio=1.0, gains="mass_matrix"):
        self.kp, self.kd, self.q_ref = kp, kd, q_ref
        self.gains = gains
        self.gravity_compensation = gravity_compensation
        self.nominal = nominal
        self.bandwidth, self.damping_ratio = bandwidth, damping_ratio

    def _bandwidth(self, where):
        """``(w, zeta)`` of a bandwidth specification, checked (1/s, 1)."""
        if self.kp is not None or self.kd is not None:
            raise ControlError(f"{where}: give either kp and kd or bandwidth, not both")
        w = _number(self.bandwidth, f"{where} bandwidth")
        z = _number(self.damping_ratio, f"{where} damping_ratio")
        if not (w > 0 and z >= 0):
            raise ControlError(f"{where}: bandwidth must be > 0 and damping_ratio >= 0, got {w!r}, {z!r}")
        return w, z

    def _gains(self, ctx, where, nominal_model, ref):
        if self.bandwidth is not None:
            w, z = self._bandwidth(where)
            q0 = [float(v) for v in ref(ref.t0 if isinstance(ref, Quintic) else 0.0)[0]]
            M = np.asarray(nominal_model.mass_matrix(np.array(q0)), float) \
                * float(getattr(nominal_model, "energy_scale", 1))
            if self.gains not in ("mass_matrix", "diagonal"):
                raise ControlError(f"{where} gains: 'mass_matrix' or 'diagonal', got {self.gains!r}")
            if self.gains == "diagonal":
                M = np.diag(np.diag(M))
            return w * w * M, 2 * z * w * M
        if self.kp is None or self.kd is None:
            raise ControlError(f"{where}: kp and kd (or bandwidth) are required")
        return (ctx.vector(self.kp, f"{where} kp", default=0, nonneg=True, matrix=True),
                ctx.vector(self.kd, f"{where} kd", default=0, nonneg=True, matrix=True))

    def resolve(self, ctx):
        where = f"control {self.name}"
        if not isinstance(self.gravity_compensation, bool):
            raise ControlError(f"{where} gravity_compensation: expected true or false, "
                               f"got {self.gravity_compensation!r}")
        r = type(self).__new__(type(self))
        r.__dict__.update(self.__dict__)
        r.ref = _reference(self.q_ref, ctx, where)
        r.model = ctx.nominal(self.nominal, where)
        r.Kp, r.Kd = self._gains(ctx, where, r.model, r.ref)
        r.uses_time = r.ref.time_dependent
        return r

    def t_end(self):
        return self.ref.t_end()

    def torque(self, t, q, qd, p):
        qr, qdr, _ = self.ref(t)
        e = [sub(a, b) for a, b in zip(qr, q)]
        ed = [sub(a, b) for a, b in zip(qdr, qd)]
        tau = [add(a, b) for a, b in zip(_matvec(self.Kp, e), _matvec(self.Kd, ed))]
        if self.gravity_compensation:
            _, g, _ = _nominal_dynamics(self.model, q)
            tau = [add(a, b) for a, b in zip(tau, g)]
        return tau


class ComputedTorque(PD):
    """Computed-torque control ``tau = M_nom(q) (qdd_ref + Kp e + Kd e') + b_nom(q, qd)
    + D_nom qd`` (``e = q_ref - q``), with the nominal model ``nominal`` (see the
    module docstring); gains as for :class:`PD` (in 1/s^2 and 1/s: they act on the
    acceleration), ``bandwidth`` gives ``Kp = w^2``, ``Kd = 2 zeta w``."""

    name = "computed_torque"

    def __init__(self, kp=None, kd=None, q_ref=None, *, nominal=None, bandwidth=None, damping_ratio=1.0):
        super().__init__(kp, kd, q_ref, nominal=nominal, bandwidth=bandwidth, damping_ratio=damping_ratio,
                         gains="diagonal")

    def _gains(self, ctx, where, nominal_model, ref):
        if self.bandwidth is not None:
            w, z = self._bandwidth(where)
            return np.full(ctx.n, w * w), np.full(ctx.n, 2 * z * w)
        return super()._gains(ctx, where, nominal_model, ref)

    def resolve(self, ctx):
        r = super().resolve(ctx)
        r.gravity_compensation = False
        return r

    def torque(self, t, q, qd, p):
        qr, qdr, qddr = self.ref(t)
        e = [sub(a, b) for a, b in zip(qr, q)]
        ed = [sub(a, b) for a, b in zip(qdr, qd)]
        v = [add(a, add(b, c)) for a, b, c in zip(qddr, _matvec(self.Kp, e), _matvec(self.Kd, ed))]
        M, b, D = _nominal_dynamics(self.model, q, qd)
        n = len(q)
        return [add(total(mul(M[i][j], v[j]) for j in range(n)), add(b[i], mul(D[i], qd[i]))) for i in range(n)]


class Disturbance(Controller):
    """Constant unknown joint torques (N m, N for prismatic joints): ``torques`` a table
    {joint: [lo, hi]} or n entries (each a number or [lo, hi]).  Each interval becomes
    a graph parameter ``disturbance.<joint>``: the enclosure covers every constant
    torque in the box (not torques that vary in time inside it)."""

    name = "disturbance"

    def __init__(self, torques):
        self.torques = torques

    def resolve(self, ctx):
        where = "control disturbance"
        spec = self.torques
        if isinstance(spec, dict):
            items = [(ctx.joint_index(k, where), v) for k, v in spec.items()]
        elif isinstance(spec, (list, tuple, np.ndarray)) and not isinstance(spec, str):
            if len(spec) != ctx.n:
                raise ControlError(f"{where}: expected {ctx.n} entries (joints {', '.join(ctx.joint_names)}) or a "
                                   f"table joint = [lo, hi], got {len(spec)}")
            items = list(enumerate(spec))
        else:
            raise ControlError(f"{where}: expected a table joint = [lo, hi] or {ctx.n} entries, got {spec!r}")
        r = Disturbance(spec)
        r.index, r.bounds = [], []
        for i, v in items:
            try:
                lo, hi = parse_value(v, f"{where}.{ctx.joint_names[i]}")
            except ParameterError as e:
                raise ControlError(str(e)) from None
            r.index.append(i)
            r.bounds.append((f"disturbance.{ctx.joint_names[i]}", lo, hi))
        r.n = ctx.n
        return r

    def parameters(self):
        return list(self.bounds)

    def torque(self, t, q, qd, p):
        tau = [0] * self.n
        for k, i in enumerate(self.index):
            tau[i] = p[self.bounds[k][0]]
        return tau


class FunctionController(Controller):
    """``tau = fn(t, q, qd, p)`` written over the generic scalar (``+ - * /``, ``**``,
    ``numpy.sin``/``cos``/``exp``/``sqrt``, ... of :mod:`mbs.scalar`-compatible values;
    no ``if`` on the state): ``t`` the time, ``q``, ``qd`` lists of n scalars, ``p`` a
    dict of the function's own parameters (``params={name: number or [lo, hi]}``, graph
    parameters ``fn.<name>``).  Returns n torques.  ``uses_time``: None detects whether
    the torque depends on ``t`` (by tracing)."""

    name = "function"

    def __init__(self, fn, params=None, *, uses_time=None):
        self.fn, self.params, self.uses_time_spec = fn, params or {}, uses_time

    def resolve(self, ctx):
        where = "control function"
        if not callable(self.fn):
            raise ControlError(f"{where}: expected a callable tau(t, q, qd, p), got {self.fn!r}")
        if not isinstance(self.params, dict):
            raise ControlError(f"{where} params: expected a dict name -> number or [lo, hi]")
        r = FunctionController(self.fn, self.params, uses_time=self.uses_time_spec)
        r.n = ctx.n
        r.bounds = []
        for k, v in self.params.items():
            try:
                lo, hi = parse_value(v, f"{where} params.{k}")
            except ParameterError as e:
                raise ControlError(str(e)) from None
            r.bounds.append((f"fn.{k}", lo, hi))
        # check the output shape (and whether t is used) by tracing once
        n = ctx.n
        try:
            g = trace(lambda x, p: r._call(x[2 * n], x[:n], x[n:2 * n], dict(zip([b[0] for b in r.bounds], p))),
                      2 * n + 1, len(r.bounds))
        except ControlError:
            raise
        except Exception as e:
            raise ControlError(f"{where}: tracing tau(t, q, qd, p) failed: {type(e).__name__}: {e}") from None
        used_t = any(nd.op == Op.INPUT and nd.data == 2 * n for nd in g.nodes)
        r.uses_time = used_t if self.uses_time_spec is None else bool(self.uses_time_spec)
        if used_t and not r.uses_time:
            raise ControlError(f"{where}: the torque depends on t but uses_time=False")
        return r

    def parameters(self):
        return list(self.bounds)

    def _call(self, t, q, qd, p):
        own = {k[3:]: v for k, v in p.items() if k.startswith("fn.")}
        tau = self.fn(t, list(q), list(qd), own)
        try:
            tau = list(tau)
        except TypeError:
            raise ControlError(f"control function: tau(t, q, qd, p) must return {self.n} torques, "
                               f"got {type(tau).__name__}") from None
        if len(tau) != self.n:
            raise ControlError(f"control function: tau(t, q, qd, p) must return {self.n} torques, got {len(tau)}")
        return tau

    def torque(self, t, q, qd, p):
        return self._call(t, q, qd, p)


_KINDS = {"pd": PD, "computed_torque": ComputedTorque}


def parse_control(table, where="[control]") -> list:
    """Controllers from a scene's ``[control]`` table (or a list of such tables)::

        [control]
        type = "pd"                     # or "computed_torque"
        kp = [...]                      # or a table joint = number, or one number
        kd = [...]
        # bandwidth = 4.0               # instead of kp, kd (rad/s); damping_ratio = 1.0,
        # gains = "mass_matrix"         # or "diagonal" (pd with bandwidth)
        q_ref = [...]                   # default: the centre of the initial q box
        gravity_compensation = true     # pd only
        nominal = { mass_scale = 1.1 }  # point parameters of the nominal model (or a model name)
        [control.trajectory]            # instead of q_ref: a rest-to-rest quintic
        q_end = [...]                   # q_start: default the centre of the initial box
        duration = 2.0
        [control.disturbance]           # constant unknown torques [N m]
        shoulder_pan_joint = [-0.5, 0.5]
    """
    if isinstance(table, list):
        out = []
        for k, t in enumerate(table):
            out += parse_control(t, f"{where}[{k}]")
        return out
    if not isinstance(table, dict):
        raise ControlError(f"{where}: expected a table, got {table!r}")
    t = dict(table)
    out = []
    dist = t.pop("disturbance", None)
    kind = t.pop("type", None)
    if kind is None and t:
        raise ControlError(f"{where}: missing type (one of {', '.join(_KINDS)})")
    if kind is not None:
        if kind not in _KINDS:
            raise ControlError(f"{where} type: unknown controller {kind!r}; one of {', '.join(_KINDS)}")
        allowed = {"kp", "kd", "q_ref", "trajectory", "nominal", "bandwidth", "damping_ratio"}
        if kind == "pd":
            allowed |= {"gravity_compensation", "gains"}
        extra = sorted(set(t) - allowed)
        if extra:
            raise ControlError(f"{where}: unknown key(s) {', '.join(extra)}; allowed: {', '.join(sorted(allowed))}, "
                               "type, disturbance")
        traj = t.pop("trajectory", None)
        if traj is not None:
            if "q_ref" in t:
                raise ControlError(f"{where}: give q_ref or trajectory, not both")
            if not isinstance(traj, dict):
                raise ControlError(f"{where} trajectory: expected a table with q_end and duration")
            bad = sorted(set(traj) - {"q_start", "q_end", "duration", "t0", "kind"})
            if bad or "q_end" not in traj or "duration" not in traj:
                raise ControlError(f"{where} trajectory: needs q_end and duration (optional q_start, t0)"
                                   + (f"; unknown key(s) {', '.join(bad)}" if bad else ""))
            if traj.get("kind", "quintic") != "quintic":
                raise ControlError(f"{where} trajectory kind: only 'quintic', got {traj['kind']!r}")
            t["q_ref"] = Quintic(traj.get("q_start"), traj["q_end"], traj["duration"], traj.get("t0", 0.0))
        out.append(_KINDS[kind](**t))
    if dist is not None:
        out.append(Disturbance(dist))
    if not out:
        raise ControlError(f"{where}: empty (give type = \"pd\" / \"computed_torque\" and/or a disturbance table)")
    return out


# ---------------------------------------------------------------------- closed loop
class ClosedLoop:
    """The plant (a chain, optionally with uncertain parameters) under ``controllers``.

    Graph inputs ``(q, qd)`` and, when a controller depends on time, ``t`` last
    (``t' = 1``); graph parameters: the plant's (:class:`mbs.uncertain.ChainParameters`)
    then the controllers' (``disturbance.<joint>``, ``fn.<name>``).

    Attributes: ``controllers`` (resolved), ``timed``, ``state_names``,
    ``param_names``, ``lo``, ``hi`` (parameter box), ``n`` (joints), ``t_end_max``.
    """

    def __init__(self, chain, controllers, cparams=None, *, q_init=None, model_name=None):
        if isinstance(controllers, Controller):
            controllers = [controllers]
        controllers = list(controllers or [])
        if not controllers:
            raise ControlError("control: no controller given")
        for c in controllers:
            if not isinstance(c, Controller):
                raise ControlError(f"control: expected mbs.control controllers (PD, ComputedTorque, Disturbance, "
                                   f"FunctionController), got {type(c).__name__}")
        self.chain = chain
        self.cparams = cparams
        self.n = chain.n
        if cparams is not None and cparams.n:
            nominal = cparams.float_model()
        else:
            nominal = chain.numeric() if not chain.free_symbols else cparams.float_model()
        self._plain = None if (cparams is not None and cparams.n) else nominal
        ctx = _Context(chain, nominal, q_init, model_name)
        self.controllers = [c.resolve(ctx) for c in controllers]
        self.timed = any(c.uses_time for c in self.controllers)
        ends = [e for e in (c.t_end() for c in self.controllers) if e is not None]
        self.t_end_max = min(ends) if ends else None
        pnames = list(cparams.names) if cparams is not None else []
        lo = list(cparams.lo) if cparams is not None else []
        hi = list(cparams.hi) if cparams is not None else []
        self.n_plant_params = len(pnames)
        for c in self.controllers:
            for name, a, b in c.parameters():
                if name in pnames:
                    raise ControlError(f"control: parameter {name!r} given twice")
                pnames.append(name)
                lo.append(a)
                hi.append(b)
        self.param_names = tuple(pnames)
        self.lo, self.hi = np.array(lo, float), np.array(hi, float)
        base = [f"q{i + 1}" for i in range(self.n)] + [f"qd{i + 1}" for i in range(self.n)]
        if cparams is not None:
            base = list(cparams._state_names())
        self.state_names = tuple(base + (["t"] if self.timed else []))

    # -- evaluation over any scalar
    def _plant(self, p):
        if self._plain is not None:
            return self._plain
        return self.cparams.bind(list(p[:self.n_plant_params]))

    def split(self, x, t=None):
        n = self.n
        x = list(x)
        q, qd = x[:n], x[n:2 * n]
        if self.timed:
            t = x[2 * n]
        return q, qd, (0.0 if t is None else t)

    def torque(self, x, p, t=None):
        """The total joint torque at state ``x`` (and time ``t`` if not a state)."""
        q, qd, t = self.split(x, t)
        pd = dict(zip(self.param_names, list(p)))
        tau = [0] * self.n
        for c in self.controllers:
            tau = [add(a, b) for a, b in zip(tau, c.torque(t, q, qd, pd))]
        return tau

    def rhs(self, x, p, t=None):
        """(qd, qdd[, 1]) at ``x`` (generic scalars)."""
        q, qd, _ = self.split(x, t)
        tau = self.torque(x, p, t)
        out = list(self._plant(p).rhs(list(q) + list(qd), tau))
        return out + [1] if self.timed else out

    def rhs_float(self, t, y, p):
        """Float right-hand side for (q, qd) at time t (for solve_ivp oracles)."""
        x = list(y[:2 * self.n]) + ([t] if self.timed else [])
        return np.asarray([float(v) for v in self.rhs(x, [float(v) for v in p], t)][:2 * self.n])

    def hamiltonian(self, x, p):
        q, qd, _ = self.split(x)
        return self._plant(p).hamiltonian(q, qd)

    def energy_rate(self, x, p):
        """dH/dt = qd^T tau - qd^T D qd (eq. (7))."""
        q, qd, _ = self.split(x)
        return self._plant(p).energy_rate(q, qd, self.torque(x, p))

    # -- graphs
    def _trace(self, fn, outs):
        return trace(fn, len(self.state_names), len(self.param_names), input_names=self.state_names,
                     param_names=self.param_names, output_names=outs)

    def rhs_graph(self):
        return self._trace(lambda x, p: self.rhs(x, p), [f"d{s}" for s in self.state_names])

    def energy_graph(self):
        return self._trace(lambda x, p: [self.hamiltonian(x, p)], ["H"])

    def energy_rate_graph(self):
        return self._trace(lambda x, p: [self.energy_rate(x, p)], ["dHdt"])


def closed_loop(chain, control, cparams=None, *, q_init=None, model_name=None) -> ClosedLoop:
    """The :class:`ClosedLoop` of ``chain`` under ``control`` (a controller, a list of
    them, or a scene's ``[control]`` table as a dict)."""
    if isinstance(control, dict):
        control = parse_control(control)
    return ClosedLoop(chain, control, cparams, q_init=q_init, model_name=model_name)

"""Uncertain physical parameters of a chain, as PARAMs of the expression graphs.

The verified solver treats the parameters of an ODE graph as interval parameters
(constant states when they have width, see :func:`verified.solver.solve`).  This
module turns a user's description of what is uncertain into such parameters: the
numeric model's recursive algorithms (:mod:`mbs.numeric`) are traced with the
inertial data and the damping written in terms of the parameter tracers, so nothing
uncertain is baked into the graph as a constant.

``params`` (a dict; the same keys in a scene's ``[parameters]`` table)::

    {"payload": {"link": "tool0", "mass": [0.9, 1.1],       # kg
                 "com": [0, 0, [0.04, 0.06]],               # m, in the link's frame
                 "inertia": [[...], [...], [...]]},         # optional, kg m^2 about the com
     "mass_scale": [0.95, 1.05],          # one factor for every moving body, or
     # "mass_scale": {"upper_arm_link": [0.9, 1.1]},        # independent factors per body
     "mass": {"forearm_link": [2.1, 2.4]},                  # body masses [kg]
     "damping": {"elbow_joint": [0.0, 0.1]},                # N m s/rad (N s/m), or
     # "damping": [0.0, 0.1],             # every joint, each its own parameter
     "l1": [0.99, 1.01]}                  # a sympy symbol of the chain (DH tables)

A value is a number (a point) or ``[lo, hi]`` (or a 0-d ``Interval``).  Meanings:

- ``payload`` (or a list of payloads): a rigid body of mass ``mass`` with centre of
  mass ``com`` (in the frame of ``link``, default its origin) and rotational inertia
  ``inertia`` about it (points only; default 0, a point mass), fixed to ``link``
  (any URDF link or frame, also one welded to a body such as ``tool0``).  The mass is
  always a parameter; ``com`` components given as ``[lo, hi]`` with ``lo < hi`` are
  parameters too, exact points are geometry (constants).
- ``mass_scale``: multiplies a body's whole spatial inertia (mass and rotational
  inertia, centre of mass kept): the body's density is uncertain.  A bare interval is
  one factor shared by every moving body (not the payloads; it is factored out of the
  equations of motion, see :class:`_BoundModel`); a table gives each named body its own.
- ``mass``: a body's mass, centre of mass and rotational inertia about it kept.
- ``damping``: the viscous damping coefficient of a joint (``tau = -d qd``), replacing
  the URDF's ``<dynamics damping>``.  A bare interval gives every joint its own
  parameter over that interval.

Bodies are named by their link (``chain.body_names``): the link a moving joint
carries, together with every link welded to it.  The fixed base cannot carry
parameters (it does not move).  Parameter names in the graph: ``payload.mass``,
``payload.com_z`` (``payload2.mass``, ... for more payloads), ``mass_scale``,
``mass_scale.<body>``, ``mass.<body>``, ``damping.<joint>``, symbol names.
"""
from __future__ import annotations

import math
from numbers import Real

import numpy as np

from verified.graph import trace
from verified.arith.interval import Interval
from verified.graph.preconditioned import congruence_pivots

from .errors import ModelError
from .inertia import RigidInertia, as_inertia_matrix
from .numeric import NumericModel, _seq
from .scalar import add, div, dot, is_sympy, mul, neg, square, total
from . import spatial as sp3

__all__ = ["ChainParameters", "PHYSICAL_KEYS", "ParameterError", "parse_value"]

#: the keys of ``params`` that describe physical parameters (everything else names a
#: sympy symbol of the chain)
PHYSICAL_KEYS = ("payload", "mass_scale", "mass", "damping")
_PAYLOAD_KEYS = ("link", "mass", "com", "inertia")


class ParameterError(ModelError, ValueError):
    """A bad parameter specification (unknown link, inverted interval, NaN, wrong shape);
    the messages start with "params" (:attr:`mbs.errors.ModelError.detail`: without it)."""

    prefix = "params "


def parse_value(v, where: str, *, lower: float | None = None, strict: bool = False) -> tuple[float, float]:
    """``(lo, hi)`` floats of a parameter value: a real number (a point), ``[lo, hi]`` /
    ``(lo, hi)``, or a 0-d :class:`verified.arith.interval.Interval`.  ``lower``: the
    smallest allowed value (``strict``: values must exceed it)."""
    if isinstance(v, Interval):
        if v.shape != ():
            raise ParameterError(f"{where}: expected one interval, got an Interval of shape {v.shape}")
        lo, hi = float(v.lo), float(v.hi)
    elif isinstance(v, bool):
        raise ParameterError(f"{where}: expected a number or [lo, hi], got {v!r}")
    elif isinstance(v, (Real, np.floating, np.integer)):
        lo = hi = float(v)
    elif isinstance(v, (list, tuple, np.ndarray)) and not isinstance(v, str):
        seq = list(np.ravel(v)) if isinstance(v, np.ndarray) else list(v)
        if len(seq) != 2 or not all(isinstance(x, (Real, np.floating, np.integer)) and not isinstance(x, bool)
                                    for x in seq):
            raise ParameterError(f"{where}: an interval is [lo, hi] (two numbers), got {v!r}")
        lo, hi = float(seq[0]), float(seq[1])
    else:
        raise ParameterError(f"{where}: expected a number or [lo, hi], got {type(v).__name__} {v!r}")
    if math.isnan(lo) or math.isnan(hi):
        raise ParameterError(f"{where}: NaN in {v!r}")
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise ParameterError(f"{where}: {v!r} is not finite")
    if lo > hi:
        raise ParameterError(f"{where}: inverted interval [{lo!r}, {hi!r}] (lo > hi)")
    if lower is not None and (lo <= lower if strict else lo < lower):
        raise ParameterError(f"{where}: must be {'>' if strict else '>='} {lower:g}, got [{lo!r}, {hi!r}]")
    return lo, hi


def _num(x):
    """A model constant as a float (sympy numbers too); other values unchanged."""
    if is_sympy(x) and not x.free_symbols:
        return float(x)
    return x


class _BoundModel(NumericModel):
    """A :class:`NumericModel` whose inertial data, damping (and, for symbolic chains,
    geometry and gravity) are values of the parameters (floats or tracers).

    Kinetic and potential energy are written with the spatial inertia (m, h = m c,
    I_o) of each body, which stays polynomial in the parameters (the centre of mass of
    a body plus a payload, c = h / m, would divide by a parameter).

    A mass scale ``s`` shared by every body is factored out: with M = s M0 + M_p and
    the bias likewise, ``qdd = (M0 + M_p / s)^{-1} ((tau - D qd) / s - b0 - b_p / s)``
    exactly, so the bodies keep their constant inertia and only the (small) payload,
    the damping and the torques are divided by ``s``; ``H`` and ``dH/dt`` are
    multiplied by ``s``.  (Scaling M and b by an interval [s] entry by entry would
    lose their correlation, which widens qdd on an ill-conditioned M;
    docs/lab/code_notes.md.)
    :meth:`mass_matrix` then returns ``M / s`` (same LDL^T pivot signs)."""

    energy_scale = 1
    _inv_scale = None

    def _total_tau(self, qd, tau):
        if self._inv_scale is not None and tau is not None:
            tau = [mul(t, self._inv_scale) for t in _seq(tau, self.n, "tau")]
        return super()._total_tau(qd, tau)

    def energy_rate(self, q, qd, tau=None):
        """dH/dt = qd^T (tau - D qd) [W] (eq. (7))."""
        return mul(self.energy_scale, super().energy_rate(q, qd, tau))

    def kinetic_energy(self, q, qd):
        """K(q, qd) [J] = sum_i 1/2 m_i |v_i|^2 + v_i . (w_i x h_i) + 1/2 w_i^T I_oi w_i
        (v_i, w_i: velocity of the body frame's origin and angular velocity, body frame)."""
        q = _seq(q, self.n, "q"); qd = _seq(qd, self.n, "qd")
        vs = self._velocities(self.joint_transforms(q), qd)
        terms = []
        for i, (w, v) in enumerate(vs):
            t = mul(self.mass[i], total(square(x) for x in v))
            t = add(t, mul(2, dot(v, sp3.cross(w, self.h[i]))))
            t = add(t, dot(w, sp3.mv(self.I_o[i], w)))
            terms.append(t)
        return mul(mul(0.5, self.energy_scale), total(terms))

    def potential_energy(self, q):
        """P(q) [J] = -sum_i g . (m_i p_i + R_i h_i) + the base's constant (zero level at
        the base frame origin, as :meth:`NumericModel.potential_energy`)."""
        world = self.forward_kinematics(q)
        terms = [self.base_potential]
        for i, (R, p) in enumerate(world):
            mc = sp3.vadd(sp3.vscale(self.mass[i], p), sp3.mv(R, self.h[i]))
            terms.append(neg(dot(self.gravity, mc)))
        return mul(self.energy_scale, total(terms))


class ChainParameters:
    """The uncertain parameters ``params`` (see the module docstring) of ``chain``.

    Attributes
    ----------
    chain : mbs.Chain
    names : tuple of str
        The graph's parameter names, in order (``p`` of them).
    lo, hi : ndarray (p,)
        The parameter intervals.
    """

    def __init__(self, chain, params: dict, *, model_name: str | None = None):
        if not isinstance(params, dict):
            raise ParameterError(f"params must be a dict (name -> number or [lo, hi], or the physical keys "
                                 f"{', '.join(PHYSICAL_KEYS)}), got {type(params).__name__}")
        self.chain = chain
        self.model_name = model_name or chain.name
        self._names, self._lo, self._hi = [], [], []
        self._payloads = []      # (body index, placement T of the link in the body, mass k, com, inertia)
        self._scale_all = None   # parameter index of a shared mass scale
        self._scale = {}         # body index -> parameter index
        self._mass = {}          # body index -> parameter index
        self._damping = {}       # joint index -> parameter index
        self._symbols = {}       # sympy symbol -> parameter index
        syms = {str(s): s for s in chain.free_symbols}
        clash = sorted(set(syms) & set(PHYSICAL_KEYS))
        if clash:
            raise ParameterError(f"model {self.model_name!r}: symbol(s) {clash} clash with the physical "
                                 f"parameter keys {PHYSICAL_KEYS}; rename them")
        for key, value in params.items():
            if not isinstance(key, str):
                raise ParameterError(f"params: keys must be strings, got {key!r}")
            if key == "payload":
                items = value if isinstance(value, (list, tuple)) else [value]
                if not items:
                    raise ParameterError("params payload: an empty list")
                for k, item in enumerate(items):
                    self._add_payload(item, k + 1 if len(items) > 1 else None)
            elif key == "mass_scale":
                if isinstance(value, dict):
                    for body, v in value.items():
                        i = self._body(body, "mass_scale")
                        self._scale[i] = self._add(f"mass_scale.{body}", v, f"params mass_scale.{body}",
                                                   lower=0.0, strict=True)
                else:
                    self._scale_all = self._add("mass_scale", value, "params mass_scale", lower=0.0, strict=True)
            elif key == "mass":
                if not isinstance(value, dict):
                    raise ParameterError("params mass: expected a table body = [lo, hi] (body masses in kg), "
                                         f"got {value!r}")
                for body, v in value.items():
                    i = self._body(body, "mass")
                    self._mass[i] = self._add(f"mass.{body}", v, f"params mass.{body}", lower=0.0)
            elif key == "damping":
                joints = chain.joint_names
                if isinstance(value, dict):
                    for jn, v in value.items():
                        if jn not in joints:
                            raise ParameterError(f"params damping: unknown joint {jn!r}; joints of "
                                                 f"{self.model_name!r}: {', '.join(joints)}")
                        self._damping[joints.index(jn)] = self._add(f"damping.{jn}", v, f"params damping.{jn}",
                                                                    lower=0.0)
                else:
                    lo, hi = parse_value(value, "params damping", lower=0.0)
                    for j, jn in enumerate(joints):
                        self._damping[j] = self._add(f"damping.{jn}", (lo, hi), "params damping")
            elif key in syms:
                self._symbols[syms[key]] = self._add(key, value, f"params {key}")
            else:
                extra = f"; the model's symbols: {', '.join(sorted(syms))}" if syms else ""
                raise ParameterError(f"params: unknown parameter {key!r} for model {self.model_name!r}; "
                                     f"physical parameters: {', '.join(PHYSICAL_KEYS)}{extra}")
        missing = sorted(set(syms) - {str(s) for s in self._symbols})
        if missing:
            raise ParameterError(f"model {self.model_name!r} has symbolic parameters without a value: "
                                 f"{', '.join(missing)} (give them in params)")
        self.names = tuple(self._names)
        self.lo = np.array(self._lo, dtype=float)
        self.hi = np.array(self._hi, dtype=float)
        self._nominal = None

    # ------------------------------------------------------------------ parsing
    def _add(self, name, value, where, **kw) -> int:
        lo, hi = parse_value(value, where, **kw)
        if name in self._names:
            raise ParameterError(f"{where}: parameter {name!r} given twice")
        self._names.append(name)
        self._lo.append(lo)
        self._hi.append(hi)
        return len(self._names) - 1

    def _body(self, name, what) -> int:
        chain = self.chain
        if not isinstance(name, str):
            raise ParameterError(f"params {what}: body names are strings, got {name!r}")
        if name in chain.body_names:
            return chain.body_names.index(name)
        if name in chain.frames:
            bi = chain.frames[name][0]
            if bi < 0:
                raise ParameterError(f"params {what}.{name}: {name!r} is part of the fixed base "
                                     f"{chain.base_name!r}, which does not move")
            raise ParameterError(f"params {what}.{name}: link {name!r} is welded to body "
                                 f"{chain.body_names[bi]!r}; give {what}.{chain.body_names[bi]} (the whole "
                                 f"body) or a payload on {name!r}")
        raise ParameterError(f"params {what}: unknown body {name!r}; bodies of {self.model_name!r}: "
                             f"{', '.join(chain.body_names)}")

    def _add_payload(self, item, k):
        tag = "payload" if k is None else f"payload{k}"
        where = f"params {tag}"
        if not isinstance(item, dict):
            raise ParameterError(f"{where}: expected a table with link, mass (and com, inertia), got {item!r}")
        extra = sorted(set(item) - set(_PAYLOAD_KEYS))
        if extra:
            raise ParameterError(f"{where}: unknown key(s) {extra}; allowed: {', '.join(_PAYLOAD_KEYS)}")
        for req in ("link", "mass"):
            if req not in item:
                raise ParameterError(f"{where}: missing {req!r}")
        link = item["link"]
        frames = self.chain.frames
        if not isinstance(link, str) or link not in frames:
            raise ParameterError(f"{where}: unknown link {link!r}; links of {self.model_name!r}: "
                                 f"{', '.join(sorted(frames))}")
        bi, T = frames[link]
        if bi < 0:
            raise ParameterError(f"{where}: link {link!r} is part of the fixed base {self.chain.base_name!r}; "
                                 "a payload there does not move")
        mass = self._add(f"{tag}.mass", item["mass"], f"{where} mass", lower=0.0)
        com = item.get("com", (0.0, 0.0, 0.0))
        if not isinstance(com, (list, tuple, np.ndarray)) or len(com) != 3:
            raise ParameterError(f"{where} com: expected 3 entries [x, y, z] (m, in the frame of {link!r}), "
                                 f"got {com!r}")
        c = []
        for axis, v in zip("xyz", com):
            lo, hi = parse_value(v, f"{where} com[{axis}]")
            c.append(lo if lo == hi else ("param", self._add(f"{tag}.com_{axis}", (lo, hi), f"{where} com[{axis}]")))
        inertia = item.get("inertia")
        I = ((0, 0, 0), (0, 0, 0), (0, 0, 0))
        if inertia is not None:
            try:
                I = as_inertia_matrix(inertia, f"{where} inertia")
                arr = np.array(I, dtype=float)
            except (ModelError, TypeError, ValueError) as e:
                raise ParameterError(f"{where} inertia: {e}") from None
            if not np.all(np.isfinite(arr)):
                raise ParameterError(f"{where} inertia: not finite")
            try:
                RigidInertia(1.0, (0, 0, 0), I).validate(f"{where} inertia")
            except ModelError as e:
                raise ParameterError(str(e)) from None
        self._payloads.append((bi, T, mass, tuple(c), I))

    # ------------------------------------------------------------------ values
    @property
    def n(self) -> int:
        """Number of parameters ``p``."""
        return len(self.names)

    def interval(self):
        """The parameters as an Interval (p,)."""
        return Interval(self.lo, self.hi)

    def mid(self) -> np.ndarray:
        """Midpoints (p,) (floats)."""
        return 0.5 * (self.lo + self.hi)

    def as_dict(self) -> dict:
        """{name: (lo, hi)} in graph order."""
        return {k: (float(a), float(b)) for k, a, b in zip(self.names, self.lo, self.hi)}

    def nominal(self) -> NumericModel:
        """The float numeric model at the parameters' midpoints (for symbolic chains:
        the chain with the midpoints substituted)."""
        if self._nominal is None:
            chain = self.chain
            if self._symbols:
                mid = self.mid()
                chain = chain.subs({s: float(mid[k]) for s, k in self._symbols.items()})
            self._nominal = chain.numeric()
        return self._nominal

    def bind(self, p) -> NumericModel:
        """The numeric model at parameter values ``p`` (a sequence of ``self.n`` floats,
        float arrays, Intervals or graph tracers)."""
        p = list(p)
        if len(p) != self.n:
            raise ParameterError(f"expected {self.n} parameter values ({', '.join(self.names)}), got {len(p)}")
        base = self.nominal()
        m = _BoundModel.__new__(_BoundModel)
        m.__dict__.update(base.__dict__)
        m.__dict__.pop("_pivot_graph", None)
        chain = self.chain
        n = chain.n
        if self._symbols:
            from .sympy_eval import compile_generic  # (import here: sympy only for symbolic chains)
            syms = list(self._symbols)
            vals = [p[self._symbols[s]] for s in syms]
            cache = {}

            def ev(x):
                if isinstance(x, tuple):
                    return tuple(ev(y) for y in x)
                if is_sympy(x):
                    if not x.free_symbols:
                        return float(x)
                    if x not in cache:
                        cache[x] = compile_generic([x], syms, cse=False)(*vals)[0]
                    return cache[x]
                return x
            m.axes = [ev(b.joint.axis) for b in chain.bodies]
            m.placements = [ev(b.joint.placement) for b in chain.bodies]
            m.damping = [ev(b.joint.damping) for b in chain.bodies]
            m.gravity = ev(chain.gravity)
            mass = [ev(b.inertia.mass) for b in chain.bodies]
            com = [ev(b.inertia.com) for b in chain.bodies]
            I_c = [ev(b.inertia.inertia) for b in chain.bodies]
            bi = chain.base_inertia
            m.base_potential = neg(mul(ev(bi.mass), dot(m.gravity, ev(bi.com))))
        else:
            m.damping = list(base.damping)
            mass, com, I_c = list(base.mass), list(base.com), list(base.I_c)
            m.base_potential = base.base_potential

            def ev(x):  # sympy numbers -> floats (frame placements of DH chains)
                if isinstance(x, tuple):
                    return tuple(ev(y) for y in x)
                return float(x) if is_sympy(x) else x
        for i, k in self._mass.items():
            mass[i] = p[k]
        h = [tuple(mul(mass[i], c) for c in com[i]) for i in range(n)]
        I_o = [sp3.inertia_about_origin(mass[i], com[i], I_c[i]) for i in range(n)]
        for i, k in self._scale.items():
            s = p[k]
            mass[i] = mul(s, mass[i])
            h[i] = tuple(mul(s, x) for x in h[i])
            I_o[i] = sp3.mscale(s, I_o[i])
        inv = None
        if self._scale_all is not None:   # factored out (see _BoundModel)
            s = p[self._scale_all]
            inv = div(1, s)
            m.energy_scale, m._inv_scale = s, inv
            if not (isinstance(m.base_potential, (int, float)) and m.base_potential == 0):
                m.base_potential = mul(m.base_potential, inv)
        for bi, T, k, c, I in self._payloads:
            mp = p[k] if inv is None else mul(p[k], inv)
            c_link = tuple(p[v[1]] if isinstance(v, tuple) else v for v in c)
            T = ev(T)                          # the link's placement in the body (symbolic for DH)
            cb = sp3.apply(T, c_link)          # the payload's centre of mass in the body frame
            Ib = sp3.rotate_inertia(T[0], I)   # its inertia about it, body axes
            mass[bi] = add(mass[bi], mp)
            h[bi] = sp3.vadd(h[bi], tuple(mul(mp, x) for x in cb))
            I_o[bi] = sp3.madd(I_o[bi], sp3.inertia_about_origin(mp, cb, Ib))
        for j, k in self._damping.items():
            m.damping[j] = p[k]
        if inv is not None:
            m.damping = [mul(d, inv) for d in m.damping]
        m.mass, m.h, m.I_o = mass, h, I_o
        m.com = m.I_c = None  # not used by _BoundModel (its energies use m, h, I_o)
        return m

    # ------------------------------------------------------------------ graphs
    def _state_names(self):
        return self.nominal()._names()

    def rhs_graph(self):
        """x = (q, qd), p -> (qd, qdd): the forward dynamics with the parameters as PARAMs."""
        names = self._state_names()
        return trace(lambda x, p: self.bind(p).rhs(list(x)), len(names), self.n, input_names=names,
                     param_names=self.names, output_names=[f"d{s}" for s in names])

    def energy_graph(self):
        """(q, qd), p -> [H] (H = K + P, J)."""
        names = self._state_names()
        n = self.chain.n
        return trace(lambda x, p: [self.bind(p).hamiltonian(list(x)[:n], list(x)[n:])], len(names), self.n,
                     input_names=names, param_names=self.names, output_names=["H"])

    def mass_matrix_graph(self):
        """q, p -> the n * n entries of M(q; p) (row-major; kg m^2), the parameters as
        PARAMs (as :meth:`NumericModel.mass_matrix_graph`; the energy shell's ``M``)."""
        n = self.chain.n
        qn = self._state_names()[:n]

        def fn(q, p):
            M = self.bind(p).mass_matrix(list(q))
            return [M[i][j] for i in range(n) for j in range(n)]
        return trace(fn, n, self.n, input_names=list(qn), param_names=self.names,
                     output_names=[f"M{i + 1}{j + 1}" for i in range(n) for j in range(n)])

    def potential_graph(self):
        """q, p -> [P(q; p)] (J), the potential of :meth:`energy_graph`'s ``H``."""
        n = self.chain.n
        qn = self._state_names()[:n]
        return trace(lambda q, p: [self.bind(p).potential_energy(list(q))], n, self.n, input_names=list(qn),
                     param_names=self.names, output_names=["P"])

    def pivot_graph(self):
        """(q, p) -> (D_1, ..., D_n), pivots whose positivity proves M(q; p) positive
        definite (as :meth:`NumericModel.pivot_graph`), with the parameters as *inputs*
        after q (for proving M positive definite over q-boxes x the parameter box)."""
        n = self.chain.n
        qn = self._state_names()[:n]
        def fn(x, _):
            x = list(x)
            m = self.bind(x[n:])
            if getattr(m, "linear_solve", None) == "preconditioned":
                # as NumericModel.pivot_graph: the pivots of K M K^T, K = L^-1 of mid(M)
                # frozen (same inertia, tight over boxes)
                return congruence_pivots(m._crba(m.joint_transforms(x[:n])))
            return m.mass_matrix_pivots(x[:n])
        return trace(fn, n + self.n, 0, input_names=list(qn) + list(self.names),
                     output_names=[f"D{i + 1}" for i in range(n)])

    def float_model(self, values=None) -> NumericModel:
        """The float model at ``values`` (default: the midpoints)."""
        return self.bind([float(v) for v in (self.mid() if values is None else values)])

"""Symbolic (sympy) model of a :class:`mbs.Chain`.

Everything is derived lazily (``functools.cached_property``): asking for ``M`` does not
derive the Coriolis terms, etc.

Derivation (no Lagrange differentiation of the energies):

- Joint transforms ``X_i``, world placements and motion subspaces ``S_i``:
  :mod:`mbs.kinematics`, the same code as :mod:`mbs.numeric` runs, here on sympy scalars.
- Body Jacobians in body coordinates, built recursively:
  ``J_i = X_{i,parent} J_parent + S_i e_i^T`` (6 x n, angular rows first).
- ``M = sum_i J_i^T I_i J_i`` with the spatial inertia ``I_i`` about the body origin;
  this is the Jacobian formula ``sum Jv^T m Jv + Jw^T R I R^T Jw`` written in body
  coordinates (so no world rotation products appear in M).
- Coriolis/centrifugal terms Kane-style: ``c = sum_i J_i^T (I_i a_i + v_i x* I_i v_i)``
  with the velocity-product acceleration ``a_i = X a_parent + v_i x S_i qd_i`` (qdd = 0).
- ``P = -sum_i m_i g . c_i(q) + P_base`` with world centres of mass ``c_i``; the gravity
  torque ``g(q) = dP/dq`` by differentiation.

Potential-energy reference: the zero level is at the **base frame origin** (URDF root
link frame / DH frame 0), and the fixed base's own mass (root link and links welded to it)
is included as the constant ``P_base = -m_base g . c_base``.  Pinocchio's
``computePotentialEnergy`` leaves the fixed base out, so ``P_ours = P_pinocchio + P_base``.

Equations (paper numbering): EOM ``M qdd + c(q, qd) + g(q) = tau`` with
``tau = tau_ext - D qd`` (viscous damping), Lagrange (2); H = K + P (4) with
K = 1/2 qd^T M qd (13); canonical equations (5)-(6); energy balance (7)
dH/dt = qd^T tau.
"""
from __future__ import annotations

from functools import cached_property

import numpy as np
import sympy

from verified.graph import Graph, from_sympy, trace

from . import cache
from .errors import ModelError, SingularMassMatrixError
from .numeric import float_pivots, ldl_factor, singular_mass_matrix_message, solve_mass_matrix
from .scalar import add, mul, dot, total
from .sympy_eval import compile_generic
from . import kinematics as kin
from . import spatial as sp3


def _S(x):
    """Python float / int / sympy -> sympy (floats exactly, as 53-bit Floats)."""
    if isinstance(x, sympy.Basic):
        return x
    if isinstance(x, int) or (isinstance(x, float) and x.is_integer() and abs(x) < 1e15):
        return sympy.Integer(int(x))
    return sympy.Float(x)


def _SS(T):
    if isinstance(T, tuple):
        return tuple(_SS(t) for t in T)
    return _S(T)


class SymbolicModel:
    """Lazy sympy model; see the module docstring.

    Attributes (sympy column matrices of symbols): ``q``, ``qd``, ``qdd``, ``tau``
    (external generalized forces), ``p`` (momenta).  Properties: ``M``, ``K``, ``P``,
    ``gravity`` (dP/dq), ``coriolis``, ``bias``, ``eom``, ``H``, ``dHdt``,
    ``dHdt_unsimplified``, ``canonical``.
    """

    def __init__(self, chain):
        self.chain = chain
        n = self.n = chain.n
        self.q = sympy.Matrix(sympy.symbols(f"q1:{n + 1}", real=True))
        self.qd = sympy.Matrix(sympy.symbols(f"qd1:{n + 1}", real=True))
        self.qdd = sympy.Matrix(sympy.symbols(f"qdd1:{n + 1}", real=True))
        self.tau = sympy.Matrix(sympy.symbols(f"tau1:{n + 1}", real=True))
        self.p = sympy.Matrix(sympy.symbols(f"p1:{n + 1}", real=True))
        self.parents = chain.parents
        self.kinds = [b.joint.kind for b in chain.bodies]
        self.axes = [_SS(b.joint.axis) for b in chain.bodies]
        self.placements = [_SS(b.joint.placement) for b in chain.bodies]
        self.D = sympy.diag(*[_S(b.joint.damping) for b in chain.bodies]) if n else sympy.Matrix()
        self.gravity_vector = _SS(chain.gravity)
        self.mass = [_S(b.inertia.mass) for b in chain.bodies]
        self.com = [_SS(b.inertia.com) for b in chain.bodies]
        self.I_c = [_SS(b.inertia.inertia) for b in chain.bodies]
        self.h = [tuple(m * c for c in com) for m, com in zip(self.mass, self.com)]
        self.I_o = [sp3.inertia_about_origin(m, c, I) for m, c, I in zip(self.mass, self.com, self.I_c)]
        bi = chain.base_inertia
        self.P_base = -_S(bi.mass) * sum((g * _S(c) for g, c in zip(self.gravity_vector, bi.com)),
                                         sympy.Integer(0))

    # ------------------------------------------------------------------ kinematics
    @cached_property
    def joint_transforms(self):
        """Placement (R, p) of each body frame in its parent frame, as sympy tuples."""
        return kin.joint_transforms(self.kinds, self.axes, self.placements, self.q)

    @cached_property
    def world_transforms(self):
        """World placements (R, p) of the body frames, as sympy tuples (nested 3x3 / 3)."""
        return kin.world_transforms(self.parents, self.joint_transforms)

    def forward_kinematics(self):
        """World placements (R (3x3 Matrix), p (3x1 Matrix)) of the body frames."""
        return [(sympy.Matrix(R), sympy.Matrix(p)) for R, p in self.world_transforms]

    def frame_placement(self, name):
        """World placement (R (3x3 Matrix), p (3x1 Matrix)) of a named frame."""
        bi, T = self.chain.frames[name]
        T = _SS(T)
        if bi < 0:  # a base frame needs no kinematics (world_transforms is lazy)
            return sympy.Matrix(T[0]), sympy.Matrix(T[1])
        R, p = kin.frame_placement(self.world_transforms, bi, T)
        return sympy.Matrix(R), sympy.Matrix(p)

    def _S(self, i):
        return kin.motion_subspace(self.kinds[i], self.axes[i])

    @cached_property
    def body_jacobians(self):
        """J_i as dict column -> (w, v) in body-i coordinates (only ancestor columns)."""
        X = self.joint_transforms
        Js = []
        for i in range(self.n):
            pa = self.parents[i]
            R, p = X[i]
            J = {}
            if pa >= 0:
                for k, (w, v) in Js[pa].items():
                    J[k] = sp3.motion_to_child(R, p, w, v)
            J[i] = self._S(i)
            Js.append(J)
        return Js

    # ------------------------------------------------------------------ dynamics
    @cached_property
    def M(self):
        """Mass matrix M(q) (n x n, symmetric), eq. (4)/(13)."""
        n = self.n
        M = [[sympy.Integer(0)] * n for _ in range(n)]
        for i, J in enumerate(self.body_jacobians):
            cols = sorted(J)
            F = {k: sp3.inertia_times_motion(self.mass[i], self.h[i], self.I_o[i], *J[k]) for k in cols}
            for a in cols:
                wa, va = J[a]
                for b in cols:
                    if b < a:
                        continue
                    nb, fb = F[b]
                    M[a][b] = add(M[a][b], add(dot(wa, nb), dot(va, fb)))
        for a in range(n):
            for b in range(a):
                M[a][b] = M[b][a]
        return sympy.Matrix(M)

    @cached_property
    def body_velocities(self):
        """Spatial velocities (w, v) of the body frames in body coordinates."""
        out = []
        for J in self.body_jacobians:
            w, v = sp3.ZERO3, sp3.ZERO3
            for k, (wk, vk) in J.items():
                w = sp3.vadd(w, sp3.vscale(self.qd[k], wk))
                v = sp3.vadd(v, sp3.vscale(self.qd[k], vk))
            out.append((w, v))
        return out

    @cached_property
    def coriolis(self):
        """Coriolis/centrifugal forces c(q, qd) (n x 1), Kane-style projection."""
        X = self.joint_transforms
        n = self.n
        acc = []
        c = [sympy.Integer(0)] * n
        for i in range(n):
            R, p = X[i]
            pa = self.parents[i]
            a = (sp3.ZERO3, sp3.ZERO3) if pa < 0 else sp3.motion_to_child(R, p, *acc[pa])
            w, v = self.body_velocities[i]
            Sw, Sv = self._S(i)
            Sq = (sp3.vscale(self.qd[i], Sw), sp3.vscale(self.qd[i], Sv))
            cw, cv = sp3.motion_cross_motion(w, v, *Sq)
            a = (sp3.vadd(a[0], cw), sp3.vadd(a[1], cv))
            acc.append(a)
            Ia = sp3.inertia_times_motion(self.mass[i], self.h[i], self.I_o[i], *a)
            Iv = sp3.inertia_times_motion(self.mass[i], self.h[i], self.I_o[i], w, v)
            cf = sp3.motion_cross_force(w, v, *Iv)
            f = (sp3.vadd(Ia[0], cf[0]), sp3.vadd(Ia[1], cf[1]))
            for k, (wk, vk) in self.body_jacobians[i].items():
                c[k] = add(c[k], add(dot(wk, f[0]), dot(vk, f[1])))
        return sympy.Matrix(c)

    @cached_property
    def K(self):
        """Kinetic energy K = 1/2 qd^T M(q) qd [J], eq. (13)."""
        return (self.qd.T * self.M * self.qd)[0, 0] / 2

    @cached_property
    def P(self):
        """Potential energy [J], zero level at the base frame origin, fixed base included."""
        terms = [self.P_base] if self.P_base != 0 else []
        for i, (R, p) in enumerate(self.world_transforms):
            if self.mass[i] == 0:
                continue
            c = sp3.apply((R, p), self.com[i])
            terms.append(mul(-self.mass[i], dot(self.gravity_vector, c)))
        return sympy.sympify(total(terms))

    @cached_property
    def gravity(self):
        """Gravity torque g(q) = dP/dq (n x 1)."""
        return sympy.Matrix([sympy.diff(self.P, qi) for qi in self.q])

    @cached_property
    def bias(self):
        """c(q, qd) + g(q)."""
        return self.coriolis + self.gravity

    @cached_property
    def generalized_forces(self):
        """tau_total = tau - D qd (external torques minus viscous damping)."""
        return self.tau - self.D * self.qd

    @cached_property
    def eom(self):
        """Equations of motion as expressions that vanish:
        M qdd + c(q, qd) + g(q) - (tau - D qd) = 0 (n x 1)."""
        return self.M * self.qdd + self.coriolis + self.gravity - self.generalized_forces

    @cached_property
    def H(self):
        """Hamiltonian H(q, qd) = K + P, eq. (4)."""
        return self.K + self.P

    def H_of_p(self):
        """H(q, p) = 1/2 p^T M^{-1} p + P, eq. (3) (explicit inverse: small n only)."""
        Minv_p = self._solve_M(self.p)
        return (self.p.T * Minv_p)[0, 0] / 2 + self.P

    @cached_property
    def dHdt(self):
        """dH/dt = qd^T (tau - D qd), eq. (7) (the simplified form)."""
        return (self.qd.T * self.generalized_forces)[0, 0]

    def qdd_solution(self):
        """qdd = M^{-1}(tau - D qd - c - g) as explicit sympy (LU solve; small n only)."""
        return self._solve_M(self.generalized_forces - self.bias)

    def dHdt_unsimplified(self, explicit=None):
        """dH/dt by the chain rule, NOT simplified (as the paper uses it in sec. 5.1):
        dH/dt = dH/dq . qd + dH/dqd . qdd.  With ``explicit`` (default: n <= 2) qdd is
        replaced by the solved EOM, giving an expression in (q, qd, tau); otherwise it is
        left in terms of the symbols ``qdd``."""
        if explicit is None:
            explicit = self.n <= 2
        H = self.H
        expr = sum((sympy.diff(H, self.q[i]) * self.qd[i] for i in range(self.n)), sympy.Integer(0))
        qdd = self.qdd_solution() if explicit else self.qdd
        expr += sum((sympy.diff(H, self.qd[i]) * qdd[i] for i in range(self.n)), sympy.Integer(0))
        return expr

    def _solve_M(self, b):
        """M^{-1} b (sympy LU); a singular M raises SingularMassMatrixError naming the
        joints (when the chain has numbers to check), not sympy's error."""
        try:
            return self.M.LUsolve(b)
        except ValueError as e:  # sympy's NonInvertibleMatrixError
            names = self.chain.joint_names
            try:
                num = self.chain.numeric()
                num.check_mass_matrix(np.zeros(self.n), where="for every q (symbolically)")
            except SingularMassMatrixError as named:
                raise named from None
            except ModelError:
                pass
            raise SingularMassMatrixError(f"mass matrix M(q) of chain {self.chain.name!r} is singular for every q "
                                          f"(sympy: {e}); joints {names}", kind="constant") from None

    @cached_property
    def dMdq(self):
        return [self.M.diff(qi) for qi in self.q]

    def canonical(self, explicit=None):
        """Canonical equations (5)-(6) in (q, p).

        Returns a dict: ``p`` = M(q) qd (momenta in terms of qd), ``qdot`` = M^{-1} p
        (explicit LU solve if ``explicit``, default n <= 3, else None), and ``pdot`` =
        -dH/dq + tau_total = 1/2 v^T dM/dq_i v - dP/dq_i + tau_i - (D v)_i written with
        v = qd = M^{-1} p (the symbols ``qd``)."""
        if explicit is None:
            explicit = self.n <= 3
        v = self.qd
        pdot = sympy.Matrix([(v.T * self.dMdq[i] * v)[0, 0] / 2 - self.gravity[i]
                             + self.generalized_forces[i] for i in range(self.n)])
        return {"p": self.M * self.qd, "qdot": self._solve_M(self.p) if explicit else None,
                "pdot": pdot}

    # ------------------------------------------------------------------ evaluation
    def lambdified(self):
        """Float evaluator (q, qd, tau) -> dict fk, M, K, P, g, c, qdd (numpy, cse'd)."""
        n = self.n
        fk = self.world_transforms
        flat_fk = [sympy.sympify(x) for R, p in fk for row in R for x in row] + \
                  [sympy.sympify(x) for R, p in fk for x in p]
        exprs = flat_fk + list(self.M) + [self.K, self.P] + list(self.gravity) + list(self.coriolis)
        args = list(self.q) + list(self.qd)
        f = sympy.lambdify(args, exprs, modules="numpy", cse=True)
        D = np.array([float(d) for d in self.D.diagonal()]) if n else np.zeros(0)
        def ev(q, qd, tau):
            vals = [np.asarray(v, dtype=float) for v in f(*q, *qd)]
            k = 0
            Rs = []
            for i in range(n):
                Rs.append(np.array(vals[k:k + 9], float).reshape(3, 3)); k += 9
            ps = []
            for i in range(n):
                ps.append(np.array(vals[k:k + 3], float)); k += 3
            M = np.array(vals[k:k + n * n], float).reshape(n, n); k += n * n
            K = float(vals[k]); P = float(vals[k + 1]); k += 2
            g = np.array(vals[k:k + n], float); k += n
            c = np.array(vals[k:k + n], float)
            singular = float_pivots(M)[1]
            if singular:
                names = self.chain.joint_names
                raise SingularMassMatrixError(
                    singular_mass_matrix_message(names, self.kinds, M, singular,
                                                 "at q = [" + ", ".join(f"{float(v):.6g}" for v in q) + "]"),
                    joints=[names[j] for j in singular], indices=singular, kind="float")
            qdd = np.linalg.solve(M, np.asarray(tau, float) - D * np.asarray(qd, float) - c - g)
            return {"fk": list(zip(Rs, ps)), "M": M, "K": K, "P": P, "g": g, "c": c, "qdd": qdd}
        return ev

    def generic_functions(self):
        """(mass_and_bias, energy): generic-scalar callables of (q..., qd...) from the
        cse'd symbolic expressions (for intervals, batches and tracing)."""
        args = list(self.q) + list(self.qd)
        mb = compile_generic(list(self.M) + list(self.bias), args)
        en = compile_generic([self.H], args)
        return mb, en


# ---------------------------------------------------------------------- graphs
def _cached_graph(chain, kind, build):
    """Load the graph ``kind`` of ``chain`` from the disk cache or build and store it."""
    k = cache.key(chain.fingerprint(), kind)
    d = cache.get_json(k)
    if d is not None:
        try:
            return Graph.from_dict(d)
        except (ValueError, KeyError, TypeError):
            pass
    g = build()
    cache.put_json(k, g.to_dict())
    return g


def _sym_rhs_graph(self, tau_params=False):
    """Expression graph x = (q, qd) -> (qd, qdd) from the symbolic model: M(q) and the
    bias c + g are the cse'd sympy expressions, qdd = LDL^T solve of
    M qdd = tau - D qd - c - g (tau = 0 unless ``tau_params``: then tau are the graph's
    parameters).  Cached on disk (see :mod:`mbs.cache`)."""
    n = self.n
    def build():
        mb = self.generic_functions()[0]
        def fn(x, p):
            x = list(x)
            vals = mb(*x)
            M = [vals[i * n:(i + 1) * n] for i in range(n)]
            return x[n:] + _qdd(self, M, vals[n * n:], x, p if tau_params else None)
        names = [str(s) for s in list(self.q) + list(self.qd)]
        return trace(fn, 2 * n, n if tau_params else 0, input_names=names,
                     param_names=[str(s) for s in self.tau] if tau_params else None,
                     output_names=[f"d{s}" for s in names])
    return _cached_graph(self.chain, f"sym-rhs-tau{int(bool(tau_params))}", build)


def _qdd(self, M, b, x, tau=None):
    """qdd = M^{-1} (tau - D qd - b) at ``x = (q, qd)``: ``M`` and the bias ``b = c + g``
    evaluated there, ``tau`` the joint torques (None: 0), ``D`` the joints' viscous
    damping (eq. (7)); by LDL^T (:func:`_ldl_solve_named`). The one place the symbolic
    model's graphs form qdd (the right-hand side and the chain-rule dH/dt)."""
    n = self.n
    d = [float(v) for v in self.D.diagonal()] if n else []
    rhs = []
    for i in range(n):
        r = -b[i]
        if d[i] != 0:
            r = r - d[i] * x[n + i]
        if tau is not None:
            r = r + tau[i]
        rhs.append(r)
    return _ldl_solve_named(self, M, rhs, x)


def _ldl_solve_named(self, M, rhs, x):
    """:func:`mbs.numeric.ldl_solve` whose SingularMassMatrixError names the joints."""
    try:
        U, D = ldl_factor(M)
    except SingularMassMatrixError as e:
        try:
            num = self.chain.numeric()
        except ModelError:
            k = e.indices[0]
            raise SingularMassMatrixError(f"{e} (joint {self.chain.joint_names[k]!r})",
                                          joints=[self.chain.joint_names[k]], indices=[k], kind=e.kind) from None
        raise num._singular_error(e, x[:self.n]) from None
    return solve_mass_matrix(M, U, D, rhs, getattr(self, "linear_solve", "preconditioned"))


def _sym_energy_graph(self):
    """Expression graph (q, qd) -> [H], H = K + P (eq. (4)), for the constraint H_H.
    Cached on disk."""
    def build():
        inputs = list(self.q) + list(self.qd)
        return from_sympy([self.H], inputs, output_names=["H"])
    return _cached_graph(self.chain, "sym-energy-H", build)


def _sym_energy_rate_graph(self, simplified=False):
    """Expression graph (q, qd) -> [dH/dt] for the constraint H_V (eq. (12)), tau_ext = 0.

    - ``simplified=True``: eq. (7), dH/dt = qd^T (-D qd) (identically 0 without damping);
    - ``simplified=False`` (the paper's symbolic mode): the chain rule
      dH/dq . qd + dH/dqd . qdd(q, qd) with qdd from the EOM (LDL^T solve in the graph);
      equal to eq. (7) in exact arithmetic, but not symbolically simplified, so its
      interval enclosure is not a point.
    Cached on disk."""
    n = self.n
    inputs = list(self.q) + list(self.qd)
    if simplified:
        def build():
            rate = (self.qd.T * (-self.D * self.qd))[0, 0] if n else sympy.Integer(0)
            return from_sympy([rate], inputs, output_names=["dHdt"])
        return _cached_graph(self.chain, "sym-energy-rate-simplified", build)

    def build():
        H = self.H
        dHdq = [sympy.diff(H, qi) for qi in self.q]
        dHdqd = list(self.M * self.qd)          # dH/dqd = M qd exactly
        f = compile_generic(list(self.M) + list(self.bias) + dHdq + dHdqd, inputs)
        def fn(x, p):
            x = list(x)
            vals = f(*x)
            M = [vals[i * n:(i + 1) * n] for i in range(n)]
            k = n * n
            b, gq, gqd = vals[k:k + n], vals[k + n:k + 2 * n], vals[k + 2 * n:k + 3 * n]
            qdd = _qdd(self, M, b, x)
            r = 0
            for i in range(n):
                r = r + gq[i] * x[n + i] + gqd[i] * qdd[i]
            return [r]
        return trace(fn, 2 * n, 0, input_names=[str(s) for s in inputs], output_names=["dHdt"])
    return _cached_graph(self.chain, "sym-energy-rate-chainrule", build)


SymbolicModel.rhs_graph = _sym_rhs_graph
SymbolicModel.energy_graph = _sym_energy_graph
SymbolicModel.energy_rate_graph = _sym_energy_rate_graph

# Long (700 lines) on purpose: NumericModel's recursive algorithms and the LDL^T of M(q) they all use.
"""Numeric multibody model, the SMARTMOBILE way: recursive algorithms written once over
a generic scalar (see :mod:`mbs.scalar`).

The same code runs on

- Python floats / numpy float vectors ``q`` of shape ``(n,)``,
- batches: ``q`` of shape ``(n, B)`` (each ``q[i]`` is a numpy array of shape ``(B,)``),
- ``verified.arith.interval.Interval``: lists of interval scalars, or one Interval array of
  shape ``(n,)`` / ``(n, B)`` (rows are iterated like numpy arrays),
- ``verified.graph.Tracer`` scalars: :meth:`NumericModel.rhs_graph` and
  :meth:`NumericModel.energy_graph` turn the algorithms into expression graphs for the
  verified solver without sympy.

Algorithms (Featherstone, "Rigid Body Dynamics Algorithms"; Pinocchio's names):

- :meth:`forward_kinematics` -- world placements of the body (joint) frames
  (:mod:`mbs.kinematics`, shared with :mod:`mbs.symbolic`),
- :meth:`kinetic_energy` / :meth:`potential_energy` -- SMARTMOBILE's getKineticEnergy /
  getPotentialEnergy; K [J] = sum 1/2 (m |v_c|^2 + w^T I_c w), P [J] = -sum m g . c
  (reference: base frame origin, fixed base included; see :mod:`mbs.symbolic`),
- :meth:`mass_matrix` -- composite rigid body algorithm (crba), M(q) of eq. (4)/(13),
- :meth:`rnea` / :meth:`bias` / :meth:`gravity_torque` -- recursive Newton-Euler,
- :meth:`acceleration` -- qdd from M qdd = tau - D qd - bias(q, qd).  M is checked by an
  LDL^T factorization written over the generic scalar (M is symmetric positive definite,
  no pivoting, so it traces into a fixed graph): a pivot that is not (proven) positive --
  M singular, e.g. masses on a joint axis -- raises :class:`~mbs.errors.SingularMassMatrixError`
  naming the joints (floats, constants, intervals); never a silent 0.  The solve itself
  is :func:`verified.graph.preconditioned.solve` (a frozen congruence ``K M K^T`` of M) by
  default, which keeps interval-type evaluations of qdd tight; ``linear_solve = "ldl"``
  selects plain LDL^T substitution instead.

Vectors are returned as numpy arrays when every input is a float / float array, else as
Python lists of generic scalars (matrices: list of rows).
"""
from __future__ import annotations

import sys

import numpy as np

from verified.graph import trace
from verified.graph.preconditioned import congruence_pivots, solve as preconditioned_solve

from .errors import ModelError, SingularMassMatrixError
from .scalar import add, sub, mul, div, dot, square, total, is_sympy, is_zero, is_const
from . import kinematics as kin
from . import spatial as sp3


def _f(x, what):
    if is_sympy(x):
        if x.free_symbols:
            raise ModelError(f"{what} is symbolic ({x}); call chain.subs({{...}}) before numeric()")
        x = float(x)
    v = float(x)
    if v == 0.0:
        return 0
    if v == int(v) and abs(v) < 1e15:
        return int(v)
    return v


def _ff(T, what):
    if isinstance(T, tuple):
        return tuple(_ff(t, what) for t in T)
    return _f(T, what)


def _is_plain(x) -> bool:
    if isinstance(x, (float, int, np.floating, np.integer)):
        return True
    if isinstance(x, np.ndarray) and x.dtype.kind in "fiu":
        return True
    return False


#: :meth:`NumericModel.acceleration` at one float point runs compiled float code from
#: this call on (tracing and compiling it costs about as much as 10-50 calls of the
#: recursion: not worth it for a single call)
FLOAT_CODE_AFTER = 3


def _scalar_floats(q, qd, tau, n: int) -> bool:
    """Whether q, qd (and tau unless None) are n plain floats each (not arrays of points,
    intervals, sympy or graph values)."""
    for v in (q, qd) + (() if tau is None else (tau,)):
        if isinstance(v, np.ndarray):
            if v.dtype.kind not in "fiu" or v.shape != (n,):
                return False
            continue
        if not isinstance(v, (list, tuple)) or len(v) != n:
            return False
        if not all(isinstance(e, (float, int, np.floating, np.integer)) and not isinstance(e, bool) for e in v):
            return False
    return True


def _seq(x, n, what):
    if isinstance(x, np.ndarray):
        if x.shape[:1] != (n,):
            raise ModelError(f"{what} must have length {n} along axis 0, got shape {x.shape}")
        return [x[i] for i in range(n)]
    try:
        seq = list(x)
    except TypeError:
        raise ModelError(f"{what} must be a sequence of {n} values, got {type(x).__name__}") from None
    if len(seq) != n:
        raise ModelError(f"{what} must have {n} entries, got {len(seq)}")
    return seq


def _fmt_vec(v) -> str:
    return "[" + ", ".join(f"{float(x):.6g}" for x in np.ravel(v)) + "]"


def _plain_out(vals, *inputs):
    """numpy array (broadcast over a batch) if every input is a float/float array."""
    if not all(_is_plain(v) for inp in inputs for v in inp):
        return vals
    if vals and isinstance(vals[0], list):
        n = len(vals)
        flat = np.broadcast_arrays(*[np.asarray(v, dtype=float) for row in vals for v in row])
        return np.array(flat, dtype=float).reshape((n, n) + flat[0].shape)
    if not vals:
        return np.zeros(0)
    flat = np.broadcast_arrays(*[np.asarray(v, dtype=float) for v in vals])
    return np.array(flat, dtype=float)


#: how :meth:`NumericModel.acceleration` solves M qdd = rhs: "preconditioned"
#: (midpoint-inverse preconditioning, :mod:`verified.graph.preconditioned`) or "ldl"
LINEAR_SOLVES = ("preconditioned", "ldl")


class NumericModel:
    """Recursive generic-scalar algorithms for a :class:`mbs.Chain` (constants as floats).

    ``linear_solve`` (one of :data:`LINEAR_SOLVES`, default "preconditioned") selects
    how qdd is solved from M qdd = rhs in :meth:`acceleration` and the graphs."""

    def __init__(self, chain, linear_solve="preconditioned"):
        if linear_solve not in LINEAR_SOLVES:
            raise ValueError(f"linear_solve must be one of {LINEAR_SOLVES}, got {linear_solve!r}")
        self.linear_solve = linear_solve
        if chain.free_symbols:
            raise ModelError(f"chain {chain.name!r} has free symbols {sorted(map(str, chain.free_symbols))}; "
                             "substitute values with chain.subs({...}) before numeric()")
        self.chain = chain
        self.n = chain.n
        self.parents = chain.parents
        self.kinds = [b.joint.kind for b in chain.bodies]
        self.axes = [_ff(b.joint.axis, "axis") for b in chain.bodies]
        self.placements = [_ff(b.joint.placement, "placement") for b in chain.bodies]
        self.damping = [_f(b.joint.damping, "damping") for b in chain.bodies]
        self.gravity = _ff(chain.gravity, "gravity")
        self.mass = [_f(b.inertia.mass, "mass") for b in chain.bodies]
        self.com = [_ff(b.inertia.com, "com") for b in chain.bodies]
        self.I_c = [_ff(b.inertia.inertia, "inertia") for b in chain.bodies]
        self.h = [tuple(_f(m * c, "h") for c in com) for m, com in zip(self.mass, self.com)]
        self.I_o = [_ff(sp3.inertia_about_origin(m, c, I), "I") for m, c, I in
                    zip(self.mass, self.com, self.I_c)]
        bi = chain.base_inertia
        self.base_potential = -float(bi.mass) * sum(float(g) * float(c) for g, c in
                                                     zip(self.gravity, bi.com))

    # ------------------------------------------------------------------ kinematics
    def joint_transforms(self, q):
        """Placement (R, p) of each body frame in its parent's frame at q."""
        return kin.joint_transforms(self.kinds, self.axes, self.placements, q)

    def forward_kinematics(self, q):
        """World placements [(R, p)] of the n body frames (Pinocchio's ``data.oMi[1:]``)."""
        q = _seq(q, self.n, "q")
        return kin.world_transforms(self.parents, self.joint_transforms(q))

    def frame_placement(self, name, q):
        """World placement of a named frame (URDF link, DH frame "link{i}", "tool")."""
        if name not in self.chain.frames:
            raise ModelError(f"unknown frame {name!r}; frames: {sorted(self.chain.frames)}")
        bi, T = self.chain.frames[name]
        T = _ff(T, "frame")
        if bi < 0:  # a base frame does not depend on q (q is not even checked)
            return T
        return kin.frame_placement(self.forward_kinematics(q), bi, T)

    def _velocities(self, X, qd):
        vs = []
        for i in range(self.n):
            R, p = X[i]
            pa = self.parents[i]
            if pa < 0:
                w, v = sp3.ZERO3, sp3.ZERO3
            else:
                w, v = sp3.motion_to_child(R, p, *vs[pa])
            Sw, Sv = self._S(i, qd[i])
            vs.append((sp3.vadd(w, Sw), sp3.vadd(v, Sv)))
        return vs

    def _S(self, i, s):
        """Motion subspace S_i times scalar s: (w, v)."""
        return kin.motion_subspace(self.kinds[i], sp3.vscale(s, self.axes[i]))

    def _St(self, i, n, f):
        """S_i^T (n, f)."""
        return kin.subspace_transpose(self.kinds[i], self.axes[i], n, f)

    # ------------------------------------------------------------------ energies
    def kinetic_energy(self, q, qd):
        """K(q, qd) [J] = sum_i 1/2 m_i |v_ci|^2 + 1/2 w_i^T I_ci w_i (eq. (13))."""
        q = _seq(q, self.n, "q"); qd = _seq(qd, self.n, "qd")
        vs = self._velocities(self.joint_transforms(q), qd)
        terms = []
        for i, (w, v) in enumerate(vs):
            m = self.mass[i]
            vc = sp3.vadd(v, sp3.cross(w, self.com[i]))
            t = mul(m, total(square(x) for x in vc))
            t = add(t, dot(w, sp3.mv(self.I_c[i], w)))
            terms.append(t)
        return mul(0.5, total(terms))

    def potential_energy(self, q):
        """P(q) [J] = -sum_i m_i g . c_i + const, c_i the world centre of mass; zero level
        at the base frame origin, the fixed base's own mass included (a constant)."""
        world = self.forward_kinematics(q)
        terms = [self.base_potential] if self.base_potential != 0 else []
        for i, T in enumerate(world):
            if self.mass[i] == 0:
                continue
            c = sp3.apply(T, self.com[i])
            terms.append(mul(-self.mass[i], dot(self.gravity, c)))
        return total(terms)

    def hamiltonian(self, q, qd):
        """H = K + P (eq. (4))."""
        return add(self.kinetic_energy(q, qd), self.potential_energy(q))

    def energy_rate(self, q, qd, tau=None):
        """dH/dt = qd^T tau_total (eq. (7)), tau_total = tau - D qd (simplified form)."""
        qd = _seq(qd, self.n, "qd")
        tt = self._total_tau(qd, tau)
        return total(mul(a, b) for a, b in zip(qd, tt))

    # ------------------------------------------------------------------ dynamics
    def mass_matrix(self, q):
        """M(q) by the composite rigid body algorithm (Pinocchio ``crba``)."""
        q = _seq(q, self.n, "q")
        M = self._crba(self.joint_transforms(q))
        return _plain_out(M, q)

    def _crba(self, X):
        n = self.n
        Ic = [(self.mass[i], self.h[i], self.I_o[i]) for i in range(n)]
        for i in reversed(range(n)):
            pa = self.parents[i]
            if pa >= 0:
                R, p = X[i]
                m2, h2, I2 = sp3.inertia_to_parent(R, p, *Ic[i])
                m1, h1, I1 = Ic[pa]
                Ic[pa] = (add(m1, m2), sp3.vadd(h1, h2), sp3.madd(I1, I2))
        M = [[0] * n for _ in range(n)]
        for i in range(n):
            w, v = self._S(i, 1)
            F = sp3.inertia_times_motion(*Ic[i], w, v)
            M[i][i] = self._St(i, *F)
            j = i
            while self.parents[j] >= 0:
                R, p = X[j]
                F = sp3.force_to_parent(R, p, *F)
                j = self.parents[j]
                M[i][j] = M[j][i] = self._St(j, *F)
        return M

    def rnea(self, q, qd, qdd, gravity=True):
        """Inverse dynamics tau = M qdd + c(q, qd) + g(q) (Pinocchio ``rnea``, no damping)."""
        q = _seq(q, self.n, "q"); qd = _seq(qd, self.n, "qd"); qdd = _seq(qdd, self.n, "qdd")
        tau = self._rnea(self.joint_transforms(q), qd, qdd, gravity)
        return _plain_out(tau, q, qd, qdd)

    def _rnea(self, X, qd, qdd, gravity=True):
        n = self.n
        a0 = (sp3.ZERO3, sp3.vneg(self.gravity) if gravity else sp3.ZERO3)
        vs, as_, fs = [], [], []
        for i in range(n):
            R, p = X[i]
            pa = self.parents[i]
            vp, ap = ((sp3.ZERO3, sp3.ZERO3), a0) if pa < 0 else (vs[pa], as_[pa])
            w, v = sp3.motion_to_child(R, p, *vp)
            aw, av = sp3.motion_to_child(R, p, *ap)
            Sqd = self._S(i, qd[i])
            w, v = sp3.vadd(w, Sqd[0]), sp3.vadd(v, Sqd[1])
            Sqdd = self._S(i, qdd[i])
            cw, cv = sp3.motion_cross_motion(w, v, *Sqd)
            aw = sp3.vadd(sp3.vadd(aw, Sqdd[0]), cw)
            av = sp3.vadd(sp3.vadd(av, Sqdd[1]), cv)
            vs.append((w, v)); as_.append((aw, av))
            Ia = sp3.inertia_times_motion(self.mass[i], self.h[i], self.I_o[i], aw, av)
            Iv = sp3.inertia_times_motion(self.mass[i], self.h[i], self.I_o[i], w, v)
            cf = sp3.motion_cross_force(w, v, *Iv)
            fs.append([sp3.vadd(Ia[0], cf[0]), sp3.vadd(Ia[1], cf[1])])
        tau = [0] * n
        for i in reversed(range(n)):
            tau[i] = self._St(i, *fs[i])
            pa = self.parents[i]
            if pa >= 0:
                R, p = X[i]
                fn, ff = sp3.force_to_parent(R, p, *fs[i])
                fs[pa] = [sp3.vadd(fs[pa][0], fn), sp3.vadd(fs[pa][1], ff)]
        return tau

    def bias(self, q, qd):
        """Bias forces c(q, qd) + g(q) = rnea(q, qd, 0) (Pinocchio ``nonLinearEffects``).
        (Gravity enters as the base acceleration -g, Featherstone's trick; in interval
        arithmetic this body-frame recursion encloses tighter than a world-frame
        Jacobian-transpose gravity term, whose rotation products lose correlation.)"""
        return self.rnea(q, qd, [0] * self.n)

    def gravity_torque(self, q):
        """g(q) = dP/dq = rnea(q, 0, 0) (Pinocchio ``computeGeneralizedGravity``)."""
        return self.rnea(q, [0] * self.n, [0] * self.n)

    def _total_tau(self, qd, tau):
        if tau is None:
            tau = [0] * self.n
        else:
            tau = _seq(tau, self.n, "tau")
        return [sub(t, mul(d, v)) for t, d, v in zip(tau, self.damping, qd)]

    def acceleration(self, q, qd, tau=None):
        """qdd = M(q)^{-1} (tau - D qd - c(q, qd) - g(q)) (forward dynamics, like
        Pinocchio ``aba`` with damping added).

        At one float point (every argument a float per joint), from the third such call
        on, the same operations run as straight-line float code compiled from their
        graph (:meth:`float_acceleration`); a point where a pivot of M is not above
        rounding level runs the recursion, which raises the error that names the joint."""
        if _scalar_floats(q, qd, tau, self.n):
            self._float_calls = getattr(self, "_float_calls", 0) + 1
            if self._float_calls >= FLOAT_CODE_AFTER:
                qdd = self._compiled_acceleration(q, qd, tau)
                if qdd is not None:
                    return qdd
        q = _seq(q, self.n, "q"); qd = _seq(qd, self.n, "qd")
        tt = self._total_tau(qd, tau)
        X = self.joint_transforms(q)
        b = self._rnea(X, qd, [0] * self.n)
        M = self._crba(X)
        rhs = [sub(t, bb) for t, bb in zip(tt, b)]
        try:
            U, D = ldl_factor(M)
        except SingularMassMatrixError as e:
            raise self._singular_error(e, q) from None
        qdd = solve_mass_matrix(M, U, D, rhs, self.linear_solve)
        return _plain_out(qdd, q, qd, tt)

    def float_acceleration(self):
        """A :class:`verified.graph.float_code.FloatFunction` of ``x = (q, qd, tau)`` (3n) ->
        ``(qdd, D, diag M)`` (3n): :meth:`acceleration`'s float operations (LDL^T
        substitution, the pivots ``D`` of M unchecked, M's diagonal for the pivot
        threshold), traced once into a graph and written as Python code."""
        if getattr(self, "_float_fn", None) is None:
            from verified.graph.float_code import compile_float
            n = self.n

            def fn(x, p):
                x = list(x)
                q, qd, tau = x[:n], x[n:2 * n], x[2 * n:]
                tt = self._total_tau(qd, tau)
                X = self.joint_transforms(q)
                b = self._rnea(X, qd, [0] * n)
                M = self._crba(X)
                U, D = ldl_factor(M, check=False)
                qdd = ldl_substitute(U, D, [sub(t, bb) for t, bb in zip(tt, b)])
                return list(qdd) + list(D) + [M[k][k] for k in range(n)]
            self._float_fn = compile_float(trace(fn, 3 * n, 0))
        return self._float_fn

    def _compiled_acceleration(self, q, qd, tau):
        """qdd at one float point by :meth:`float_acceleration`, or None where a pivot is
        not above the threshold of :func:`ldl_factor` (or not finite)."""
        n = self.n
        x = np.concatenate([np.asarray(q, float).reshape(n), np.asarray(qd, float).reshape(n),
                            np.zeros(n) if tau is None else np.asarray(tau, float).reshape(n)])
        out = self.float_acceleration()(x)
        qdd, D, diag = out[:n], out[n:2 * n], out[2 * n:]
        tol = PIVOT_TOL * n * np.max(np.abs(diag)) if n else 0.0
        if not (np.all(np.isfinite(out)) and np.all(D > tol)):
            return None
        return qdd

    # ------------------------------------------------------------------ singular M
    def mass_matrix_pivots(self, q):
        """LDL^T pivots D_k(q) of M(q), unchecked: M(q) is positive definite iff every
        D_k > 0 (over intervals: proven positive definite on the box if every lower bound
        is > 0).  Pivot k belongs to joint k."""
        q = _seq(q, self.n, "q")
        M = self._crba(self.joint_transforms(q))
        _, D = ldl_factor(M, check=False)
        return _plain_out(D, q)

    def pivot_graph(self):
        """Expression graph q -> (D_1, ..., D_n): pivots whose positivity proves M(q)
        positive definite (used by :mod:`mbs.simulate` on the boxes of a verified run).
        With ``linear_solve="preconditioned"`` they are the LDL^T pivots of the
        congruence K M K^T, K = L^-1 of mid(M) frozen
        (:func:`verified.graph.preconditioned.congruence_pivots`: same inertia, tight over
        boxes), else the LDL^T pivots of M.  Raises
        :class:`~mbs.errors.SingularMassMatrixError` when a pivot of M is the constant 0
        (M singular for every q)."""
        if getattr(self, "_pivot_graph", None) is None:
            def fn(x, p):
                x = list(x)
                M = self._crba(self.joint_transforms(x))
                try:
                    _, D = ldl_factor(M)
                except SingularMassMatrixError as e:
                    raise self._singular_error(e, x) from None
                return congruence_pivots(M) if self.linear_solve == "preconditioned" else D
            self._pivot_graph = trace(fn, self.n, 0, input_names=self._names()[:self.n],
                                      output_names=[f"D{i + 1}" for i in range(self.n)])
        return self._pivot_graph

    def check_mass_matrix(self, q, where=None):
        """Raise :class:`~mbs.errors.SingularMassMatrixError` naming the joints if M(q) is
        singular (pivots at rounding level) at the float configuration ``q``."""
        qf = np.asarray(q, dtype=float).reshape(self.n)
        M = np.asarray(self.mass_matrix(qf), dtype=float)
        _, sing = float_pivots(M)
        if sing:
            where = where or f"at q = {_fmt_vec(qf)}"
            raise SingularMassMatrixError(
                singular_mass_matrix_message(self.chain.joint_names, self.kinds, M, sing, where),
                joints=[self.chain.joint_names[k] for k in sing], indices=sing, kind="float")

    def _singular_error(self, err, q):
        """The SingularMassMatrixError of a failed pivot check, with joint names."""
        names = self.chain.joint_names
        k = err.indices[0]
        idx = err.batch_index
        if err.kind == "interval":
            parts = []
            for i, v in enumerate(q):
                if _is_interval(v):
                    lo, hi = np.ravel(v.lo), np.ravel(v.hi)
                    j = idx if lo.size > idx else 0
                    parts.append(f"{names[i]} in [{lo[j]:.6g}, {hi[j]:.6g}]")
                elif _is_plain(v) or is_const(v):
                    a = np.ravel(np.asarray(float(v) if is_const(v) else v, dtype=float))
                    parts.append(f"{names[i]} = {a[idx if a.size > idx else 0]:.6g}")
            enclosure = str(err).rsplit("encloses ", 1)[-1]
            return SingularMassMatrixError(
                f"mass matrix M(q) is not proven positive definite for {', '.join(parts)}: the LDL^T pivot "
                f"of joint {names[k]!r} encloses {enclosure} (M(q) may be singular there: do the links it "
                "moves have inertia about its axis?)", joints=[names[k]], indices=[k], kind="interval")
        if err.kind == "float":
            arrs = [np.ravel(np.asarray(v, dtype=float)) for v in q]
            qf = np.array([a[idx] if a.size > idx else a[0] for a in arrs])
            where = f"at q = {_fmt_vec(qf)}"
        elif all(_is_plain(v) or is_const(v) for v in q):  # float q, constant pivot
            qf = np.array([np.ravel(np.asarray(float(v) if is_const(v) else v, dtype=float))[0] for v in q])
            where = f"at q = {_fmt_vec(qf)} and at every other q (a constant zero pivot)"
        else:  # traced: a constant pivot <= 0, singular for every q
            qf = np.zeros(self.n)
            where = "for every q (a constant zero pivot)"
        M = np.asarray(self.mass_matrix(qf), dtype=float)
        sing = float_pivots(M)[1] or [k]
        return SingularMassMatrixError(singular_mass_matrix_message(names, self.kinds, M, sing, where),
                                       joints=[names[j] for j in sing], indices=sing, kind=err.kind)

    def rhs(self, x, tau=None):
        """ODE right-hand side for x = (q, qd): returns (qd, qdd) as one list (eq. (1))."""
        x = _seq(x, 2 * self.n, "x")
        q, qd = x[:self.n], x[self.n:]
        qdd = self.acceleration(q, qd, tau)
        out = list(qd) + list(qdd)
        return _plain_out(out, x) if _is_plain(x[0]) else out

    # ------------------------------------------------------------------ graphs
    def rhs_graph(self):
        """Expression graph x = (q, qd) -> (qd, qdd) (``verified.graph.trace``)."""
        n = self.n
        def fn(x, p):
            return self.rhs(list(x))
        names = self._names()
        return trace(fn, 2 * n, 0, input_names=names, output_names=[f"d{s}" for s in names])

    def _names(self):
        n = self.n
        return [f"q{i + 1}" for i in range(n)] + [f"qd{i + 1}" for i in range(n)]

    def energy_graph(self):
        """Expression graph (q, qd) -> [H] (H = K + P from getKineticEnergy /
        getPotentialEnergy), for the constraint H_H."""
        n = self.n
        def fn(x, p):
            x = list(x)
            return [self.hamiltonian(x[:n], x[n:])]
        return trace(fn, 2 * n, 0, input_names=self._names(), output_names=["H"])

    def mass_matrix_graph(self):
        """Expression graph q -> the n * n entries of M(q) (row-major; kg m^2, crba)."""
        n = self.n
        def fn(q, p):
            M = self.mass_matrix(list(q))
            return [M[i][j] for i in range(n) for j in range(n)]
        return trace(fn, n, 0, input_names=[f"q{i + 1}" for i in range(n)],
                     output_names=[f"M{i + 1}{j + 1}" for i in range(n) for j in range(n)])

    def potential_graph(self):
        """Expression graph q -> [P(q)] (J, ``potential_energy``)."""
        n = self.n
        def fn(q, p):
            return [self.potential_energy(list(q))]
        return trace(fn, n, 0, input_names=[f"q{i + 1}" for i in range(n)], output_names=["P"])

    def energy_rate_graph(self):
        """Expression graph (q, qd) -> [dH/dt] = qd^T (-D qd) (eq. (7), tau_ext = 0).
        (The paper's mode (ii) differentiates H along the ODE by automatic
        differentiation instead; that is the verified side's job: it has both graphs.)"""
        n = self.n
        def fn(x, p):
            x = list(x)
            return [self.energy_rate(x[:n], x[n:])]
        return trace(fn, 2 * n, 0, input_names=self._names(), output_names=["dHdt"])


#: float pivots at or below ``PIVOT_TOL * n * max_k |M_kk|`` count as zero: about the
#: rounding error of the composite-rigid-body sums and of the elimination
PIVOT_TOL = 8 * float(np.finfo(float).eps)


def _is_interval(x) -> bool:
    mod = sys.modules.get("verified.arith.interval")
    return mod is not None and isinstance(x, mod.Interval)


def _pivot_tol(M):
    """Zero threshold for plain-float / constant pivots (array for a batch): rounding
    level relative to the largest plain diagonal entry (0 if there is none)."""
    n = len(M)
    scale = 0.0
    for k in range(n):
        d = M[k][k]
        if is_const(d) or _is_plain(d):
            scale = np.maximum(scale, np.abs(np.asarray(d, dtype=float)))
    return PIVOT_TOL * n * scale


def _check_pivot(k, d, tol):
    """Raise SingularMassMatrixError if the pivot ``d`` of row ``k`` is not (proven)
    positive: a constant or float at or below ``tol``, an Interval whose lower bound is
    not > 0.  A traced (state-dependent) pivot has no value yet: :mod:`mbs.simulate`
    proves it positive on the boxes of a run."""
    if is_const(d) or _is_plain(d):
        v = np.asarray(float(d) if is_const(d) else d, dtype=float)
        bad = np.broadcast_to(v <= tol, np.broadcast_shapes(v.shape, np.shape(tol)))
        if bad.any():
            where = int(np.flatnonzero(bad.ravel())[0])
            kind = "constant" if is_const(d) else "float"
            raise SingularMassMatrixError(
                f"matrix is singular: LDL^T pivot {k} is {float(np.broadcast_to(v, bad.shape).ravel()[where]):.3g}",
                indices=[k], kind=kind, batch_index=where)
    elif _is_interval(d):
        bad = np.asarray(d.lo) <= 0
        if bad.any():
            where = int(np.flatnonzero(bad.ravel())[0])
            raise SingularMassMatrixError(
                f"matrix is not proven positive definite: LDL^T pivot {k} encloses "
                f"[{float(np.ravel(d.lo)[where]):.3g}, {float(np.ravel(d.hi)[where]):.3g}]",
                indices=[k], kind="interval", batch_index=where)


def ldl_factor(M, check=True):
    """LDL^T factorization (kept as U = D L^T) of a symmetric positive definite M (list
    of rows) over the generic scalar, without pivoting (so it traces into a fixed
    graph): returns ``(U, D)``.

    With ``check`` every pivot ``D[k]`` must be (proven) positive before it is used:
    a float or model constant above rounding level (:data:`PIVOT_TOL`), an Interval
    with a positive lower bound; otherwise :class:`~mbs.errors.SingularMassMatrixError`
    (``indices`` = the row).  A zero pivot is never skipped: the elimination skips
    only *constant zero* entries ``U[k][i]``, whose terms ``U^2 / D`` are exactly 0
    once ``D[k] > 0``.

    Written for tight interval enclosures: the diagonal updates are
    ``A_ii - U_ki^2 / D_k`` (a square, each pivot used once per term) rather than
    ``A_ii - L_ik^2 D_k`` with ``L_ik = U_ki / D_k``, which uses the pivot twice."""
    n = len(M)
    A = [list(row) for row in M]
    U = [[0] * n for _ in range(n)]
    D = [0] * n
    tol = _pivot_tol(M) if check else None
    for k in range(n):
        D[k] = A[k][k]
        if check:
            _check_pivot(k, D[k], tol)
        for j in range(k + 1, n):
            U[k][j] = A[k][j]
        for i in range(k + 1, n):
            if is_zero(U[k][i]):
                continue
            A[i][i] = sub(A[i][i], div(square(U[k][i]), D[k]))
            for j in range(i + 1, n):
                if not is_zero(U[k][j]):
                    A[i][j] = sub(A[i][j], div(mul(U[k][i], U[k][j]), D[k]))
    return U, D


# Kept apart from verified.graph.preconditioned._ldl_substitute: 0 / D[k] terms stay (mbs.scalar.div), so every pivot enters x.
def ldl_substitute(U, D, b):
    """Solve with the factors of :func:`ldl_factor`: x = M^{-1} b.  Every pivot enters
    the result (``x[i] = s / D[i]`` is kept even for a constant 0 numerator ``s`` when
    ``D[i]`` is state dependent).  Over intervals a pivot containing 0 then makes the
    result unbounded, except where the numerator is exactly [0, 0] ([0, 0] / D = [0, 0]
    in IEEE 1788): :mod:`mbs.simulate` therefore proves the pivots (:meth:`NumericModel.pivot_graph`)
    on every box of a verified run separately."""
    n = len(b)
    y = [0] * n
    for i in range(n):
        s = b[i]
        for k in range(i):
            if not is_zero(U[k][i]):
                s = sub(s, div(mul(U[k][i], y[k]), D[k]))
        y[i] = s
    x = [0] * n
    for i in reversed(range(n)):
        s = y[i]
        for j in range(i + 1, n):
            s = sub(s, mul(U[i][j], x[j]))
        x[i] = div(s, D[i])
    return x


def solve_mass_matrix(M, U, D, rhs, method="preconditioned"):
    """qdd = M^{-1} rhs given M's checked LDL^T factors (U, D): by
    :func:`verified.graph.preconditioned.solve` (``method="preconditioned"``) or by LDL^T
    substitution (``"ldl"``).  Floats and sympy expressions always take the
    substitution: preconditioning only changes enclosures (intervals, traced graphs),
    and it would bury a symbolic qdd under a symbolic inverse."""
    if method == "preconditioned" and len(rhs) > 1 and not _all_float(M, rhs) \
            and not any(is_sympy(v) for row in M for v in row):
        return preconditioned_solve(M, rhs)
    return ldl_substitute(U, D, rhs)


def _all_float(M, rhs):
    def plain(v):
        return isinstance(v, (int, float, np.floating, np.integer, np.ndarray)) and not isinstance(v, bool)
    return all(plain(v) for v in rhs) and all(plain(v) for row in M for v in row)


def ldl_solve(M, b):
    """Solve M x = b for symmetric positive definite M (list of rows) over the generic
    scalar: symmetric Gaussian elimination without pivoting (:func:`ldl_factor`, which
    refuses a pivot that is not (proven) positive, then :func:`ldl_substitute`)."""
    U, D = ldl_factor(M)
    return ldl_substitute(U, D, b)


def float_pivots(M):
    """Pivots of a float symmetric positive semi-definite matrix (n, n), skipping the
    rows whose pivot is at rounding level (their off-diagonal part is then ~0 too):
    returns ``(pivots, singular)`` with ``singular`` the indices of those rows."""
    A = np.array(M, dtype=float)
    n = A.shape[0]
    tol = PIVOT_TOL * n * (np.max(np.abs(np.diag(A))) if n else 0.0)
    piv, singular = np.zeros(n), []
    for k in range(n):
        d = A[k, k]
        piv[k] = d
        if not d > tol:
            singular.append(k)
            continue
        u = A[k, k + 1:].copy()
        A[k + 1:, k + 1:] -= np.outer(u, u) / d
    return piv, singular


def singular_mass_matrix_message(names, kinds, M, indices, where):
    """One-line description of why M is singular at ``where`` ("at q = [...]"),
    naming the joints ``indices`` (from :func:`float_pivots` of the float ``M``)."""
    M = np.asarray(M, dtype=float)
    tol = PIVOT_TOL * len(M) * (np.max(np.abs(np.diag(M))) if len(M) else 0.0)
    empty = [k for k in indices if not M[k, k] > tol]
    dependent = [k for k in indices if k not in empty]
    parts = []
    if empty:
        ax = lambda k: "about" if kinds[k] == "revolute" else "along"
        js = ", ".join(repr(names[k]) for k in empty)
        if len(empty) == 1:
            k = empty[0]
            parts.append(f"joint {js} has no inertia {ax(k)} its axis (its diagonal entry of M(q) is {M[k, k]:.3g}: "
                         f"the links it moves have their masses on the axis and no rotational inertia {ax(k)} it)")
        else:
            parts.append(f"joints {js} have no inertia about/along their axes (zero diagonal entries of "
                         "M(q): the links they move have their masses on the axes and no rotational inertia "
                         "about them)")
    for k in dependent:
        parts.append(f"joint {names[k]!r} adds no inertia of its own (its column of M(q) is a "
                     "combination of the earlier joints' columns, e.g. coinciding axes)")
    advice = []
    if empty:
        advice.append("give the links mass off the joint axes or rotational inertia")
    if dependent:
        advice.append("separate the joint axes")
    return (f"mass matrix M(q) is singular {where}: " + "; ".join(parts)
            + ". " + ", ".join(advice).capitalize() + ", or lock the joint(s).")

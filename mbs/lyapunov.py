"""The closed-loop energy of a joint PD controller holding a pose, as a Lyapunov function
(issue 14 item 4: "where can the tool be" for all later times).

Plant ``M(q, p) qdd + c(q, qd, p) + g(q, p) = tau - D qd`` (eq. (2)/(6)), controller
``tau = Kp (q_ref - q) - Kd qd (+ g_nom(q))`` with a constant ``q_ref``. With
``e = q - q_ref``, ``V`` the plant's potential energy (``g = dV/dq``) and ``V_nom`` the
nominal model's (only with gravity compensation), the function

    L(q, qd, p) = T(q, qd, p) + 1/2 e^T Kp e + dV(q, p) - phi(p),   dV = V - V_nom,

has ``dL/dt = qd^T (tau - D qd - g) + qd^T Kp e + qd^T (g - g_nom)
= -qd^T (Kd + D) qd <= 0`` (passivity, eq. (7): ``dT/dt = qd^T (tau - D qd - g)``) for any
``phi(p)``: the parameters do not change along a solution. That needs ``Kp`` symmetric,
``Kd + Kd^T`` positive semidefinite and ``D >= 0``, all checked here.

The choice ``phi(p) = dV(q_ref, p) - 1/2 e*^T Kp e*``, with ``e*(p)`` a quadratic in the
parameters fitted to the offsets at which the controller balances the gravity it does not
compensate (:func:`_equilibrium_fit`; any function of ``p`` is sound, a close one keeps
the floor of the decay low), puts ``L``'s minimum near zero for every ``p`` and gives the
structure :class:`verified.consistency.invariant.QuadraticLyapunov` bounds: ``A = M(q, p)``,
``K = Kp``, centre ``e*(p)``, ``grad = G = grad_q dV`` (``hess_q dV = dG/dq``),
``rho(p) = G(q_ref, p) + Kp e*(p)`` (the second-order offset between ``q_ref`` and the
equilibrium) and the dissipation ``Kd + D``.
"""
from __future__ import annotations

import numpy as np

from verified.graph.evaluate import eval_float, jacobian_float
from verified.graph import GraphBuilder
from verified.graph.ops import embed, gradient_graph
from verified.consistency.invariant import QuadraticLyapunov

from . import spatial as sp3
from .control import PD, ClosedLoop, ControlError
from .scalar import add, dot, mul, neg, sub, total

__all__ = ["pd_hold_lyapunov"]


def _gain_matrix(K, n: int) -> np.ndarray:
    K = np.asarray(K, float)
    return np.diag(K) if K.ndim == 1 else K.reshape(n, n)


def _check_loop(loop: ClosedLoop):
    """``(pd, Kp, Kd)`` (gains as matrices) of the controller and plant for which
    ``dL/dt <= 0`` is proven; else a ControlError naming what is not covered."""
    if not isinstance(loop, ClosedLoop):
        raise ControlError(f"an invariant set needs a closed loop (mbs.control.ClosedLoop), got {type(loop).__name__}")
    ctrls = loop.controllers
    if len(ctrls) != 1 or type(ctrls[0]) is not PD:
        kinds = ", ".join(type(c).__name__ for c in ctrls)
        raise ControlError(f"an invariant set is proven for one PD controller holding a pose; this loop has {kinds} "
                           "(computed torque, disturbances and functions can add energy)")
    pd = ctrls[0]
    if pd.ref.time_dependent or loop.timed:
        raise ControlError("an invariant set needs a constant reference q_ref (a moving reference adds energy)")
    n = loop.n
    Kp, Kd = _gain_matrix(pd.Kp, n), _gain_matrix(pd.Kd, n)
    if not np.array_equal(Kp, Kp.T):
        raise ControlError("an invariant set needs a symmetric Kp (a skew part is not a potential force)")
    S = Kd + Kd.T
    lam = np.linalg.eigvalsh(S)
    diag_ok = np.count_nonzero(S - np.diag(np.diag(S))) == 0 and np.all(np.diag(S) >= 0)
    if not (diag_ok or lam[0] > 1e-9 * max(abs(lam[-1]), 1e-300)):
        raise ControlError(f"an invariant set needs Kd + Kd^T positive semidefinite (smallest eigenvalue {lam[0]:.3g})")
    damping = [b.joint.damping for b in loop.chain.bodies]
    if any(isinstance(d, (int, float)) and d < 0 for d in damping):
        raise ControlError("an invariant set needs joint damping >= 0")
    cp = loop.cparams
    if cp is not None and getattr(cp, "_damping", None):
        lo = np.asarray(cp.lo, float)
        if any(lo[k] < 0 for k in cp._damping.values()):
            raise ControlError("an invariant set needs joint damping >= 0 (an uncertain damping reaches below 0)")
    return pd, Kp, Kd


def _inertial_data(m):
    """Masses and first moments ``(m_i, h_i)`` of a model's bodies, its mass scale applied
    (the true values: see :class:`mbs.uncertain._BoundModel`)."""
    s = getattr(m, "energy_scale", 1)
    return ([mul(s, v) for v in m.mass], [[mul(s, c) for c in h] for h in m.h])


def _same_kinematics(loop, nom, tries: int = 3) -> bool:
    """Whether the nominal model moves its bodies as the plant does (same chain geometry
    and gravity): then the potential difference is the potential of the inertia difference."""
    plant = loop._plant(0.5 * (loop.lo + loop.hi)[:loop.n_plant_params]) if loop.n_plant_params else loop._plant([])
    if plant.n != nom.n or not np.allclose(np.asarray(plant.gravity, float), np.asarray(nom.gravity, float),
                                           rtol=0, atol=0):
        return False
    rng = np.random.default_rng(1)
    for _ in range(tries):
        q = rng.uniform(-np.pi, np.pi, plant.n)
        for (R1, p1), (R2, p2) in zip(plant.forward_kinematics(q), nom.forward_kinematics(q)):
            if not (np.allclose(np.asarray(R1, float), np.asarray(R2, float), rtol=0, atol=1e-12)
                    and np.allclose(np.asarray(p1, float), np.asarray(p2, float), rtol=0, atol=1e-12)):
                return False
    return True


def _potential_difference(loop, nom):
    """``dV(q, p) = V(q, p) - V_nom(q)`` over generic scalars (``V_nom = 0`` without gravity
    compensation). Where the nominal model has the plant's kinematics, it is written as the
    potential of the inertia difference, ``-sum_i g . (dm_i p_i(q) + R_i(q) dh_i)``
    (``V`` is linear in the masses and first moments): the two gravity models then cancel
    term by term instead of being enclosed separately and subtracted (that subtraction
    left an interval Hessian much wider than the payload's own; docs/lab/code_notes.md)."""
    if nom is not None and not _same_kinematics(loop, nom):
        return lambda q, p: sub(loop._plant(p).potential_energy(q), nom.potential_energy(q))
    mn, hn = _inertial_data(nom) if nom is not None else (None, None)

    def dV(q, p):
        m = loop._plant(p)
        mp, hp = _inertial_data(m)
        terms = []
        for i, (R, pos) in enumerate(m.forward_kinematics(q)):
            dm = mp[i] if mn is None else sub(mp[i], mn[i])
            dh = hp[i] if hn is None else [sub(a, b) for a, b in zip(hp[i], hn[i])]
            mc = sp3.vadd(sp3.vscale(dm, pos), sp3.mv(R, dh))
            terms.append(neg(dot(m.gravity, mc)))
        return total(terms)
    return dV


def _compose(T_g, dV_g, G_g, K, centre, qref):
    """Graphs of ``L``, ``e*(p)`` and ``rho(p)`` (module docstring) from ``T``, ``dV``,
    ``G = grad_q dV`` and ``centre(b, p) -> e*`` node ids, all over the loop's ``(x, p)``."""
    n = qref.size
    nx, npar = T_g.n_inputs, T_g.n_params
    graphs = []
    for what in ("level", "center", "residual"):
        b = GraphBuilder(nx, npar, input_names=T_g.input_names, param_names=T_g.param_names)
        x = [b.input(i) for i in range(nx)]
        p = [b.param(k) for k in range(npar)]
        xr = [b.const(float(v)) for v in qref] + x[n:]

        def lin(M, v, i):
            terms = [b.mul(b.const(float(M[i, j])), v[j]) for j in range(n) if M[i, j] != 0]
            out = terms[0] if terms else b.const(0.0)
            for t in terms[1:]:
                out = b.add(out, t)
            return out

        def quad(v):
            kv = [lin(K, v, i) for i in range(n)]
            out = b.mul(v[0], kv[0])
            for i in range(1, n):
                out = b.add(out, b.mul(v[i], kv[i]))
            return b.mul(b.const(0.5), out)

        Gr = embed(b, G_g, xr, p)
        es = centre(b, p)
        if what == "center":
            graphs.append(b.build(es, [f"e*{i + 1}" for i in range(n)]))
        elif what == "residual":
            graphs.append(b.build([b.add(Gr[i], lin(K, es, i)) for i in range(n)], [f"rho{i + 1}" for i in range(n)]))
        else:
            (T,) = embed(b, T_g, x, p)
            (dq,) = embed(b, dV_g, x, p)
            (dr,) = embed(b, dV_g, xr, p)
            e = [b.sub(x[i], b.const(float(qref[i]))) for i in range(n)]
            L = b.add(b.add(T, quad(e)), b.add(b.sub(dq, dr), quad(es)))
            graphs.append(b.build([L], ["L"]))
    return graphs


def _equilibrium_fit(G_g, K, qref, lo, hi):
    """A centre ``e*(p)`` that tracks the closed loop's equilibrium ``K e + G(q_ref + e, p) = 0``
    over the parameter box: Newton in floats at the corners and midpoints of the box
    (3 per parameter, at most 3^4 points; more parameters: the centre and the midpoints of
    the faces), then a quadratic in the normalised parameters by least squares. Any
    function of ``p`` is a valid centre (``L`` stays non-increasing); a close one makes
    ``b(p) = K e* + G(q_ref + e*, p)`` small, and that is the floor the decay certificate
    leaves. Returns ``centre(builder, param_nodes) -> n node ids``."""
    n, npar = qref.size, len(lo)
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    mid, rad = 0.5 * (lo + hi), 0.5 * (hi - lo)
    if npar == 0:
        pts = np.zeros((1, 0))
    elif npar <= 4:
        pts = np.stack(np.meshgrid(*[[-1.0, 0.0, 1.0]] * npar, indexing="ij"), axis=-1).reshape(-1, npar)
    else:
        pts = np.concatenate([np.zeros((1, npar)), np.eye(npar), -np.eye(npar)])
    P = mid + pts * rad
    E = np.zeros((len(P), n))
    for k, pk in enumerate(P):
        e = np.zeros(n)
        for _ in range(20):
            x = np.concatenate([qref + e, np.zeros(n)])[None]
            F = K @ e + eval_float(G_g, x, pk[None])[0]
            J = K + jacobian_float(G_g, x, pk[None])[0][:, :n]
            step = np.linalg.solve(J, F)
            e = e - step
            if np.abs(step).max() <= 1e-15 * (1 + np.abs(e).max()):
                break
        E[k] = e

    def basis(t):
        cols = [np.ones(len(t))] + [t[:, i] for i in range(npar)]
        if len(t) > 2 * npar:
            cols += [t[:, i] * t[:, j] for i in range(npar) for j in range(i, npar)]
        return np.stack(cols, axis=1)

    coef = np.linalg.lstsq(basis(pts), E, rcond=None)[0] if np.all(np.isfinite(E)) else np.zeros((1, n))
    full = len(pts) > 2 * npar

    def centre(b, p):
        if npar == 0:
            return [b.const(float(coef[0, i])) for i in range(n)]
        t = [b.mul(b.sub(p[i], b.const(float(mid[i]))), b.const(float(1.0 / rad[i]) if rad[i] > 0 else 0.0))
             for i in range(npar)]
        terms = list(t)
        if full:
            terms += [b.mul(t[i], t[j]) for i in range(npar) for j in range(i, npar)]
        out = []
        for k in range(n):
            acc = b.const(float(coef[0, k]))
            for m, term in enumerate(terms):
                if coef[m + 1, k] != 0:
                    acc = b.add(acc, b.mul(b.const(float(coef[m + 1, k])), term))
            out.append(acc)
        return out
    return centre


def pd_hold_lyapunov(loop: ClosedLoop, samples=None, rhs=None):
    """The :class:`verified.consistency.invariant.QuadraticLyapunov` of ``loop`` (one PD controller
    holding a constant pose; see the module docstring), with graphs over the loop's states
    and parameters (``loop.state_names``, ``loop.param_names``).

    ``samples``: optional ``(x (S, 2n), p (S, n_p))`` floats at which the structure and
    ``dL/dt <= 0`` are checked (a ControlError when ``dL/dt`` comes out positive beyond
    rounding); by default points about ``q_ref`` and the parameter box. ``rhs``: the
    loop's :meth:`~mbs.control.ClosedLoop.rhs_graph`, if the caller has it (traced once).
    """
    pd, K, Kd = _check_loop(loop)
    n = loop.n
    qref = np.asarray(pd.ref.q, float)
    nom = pd.model if pd.gravity_compensation else None
    dV = _potential_difference(loop, nom)

    def kinetic(x, p):
        q, qd, _ = loop.split(x)
        return [loop._plant(p).kinetic_energy(q, qd)]

    def mass(x, p):
        q, _, _ = loop.split(x)
        m = loop._plant(p)
        s = getattr(m, "energy_scale", 1)
        M = m._crba(m.joint_transforms(q))
        return [mul(s, M[i][j]) for i in range(n) for j in range(n)]

    def dissipation(x, p):  # Kd + D(p): the Rayleigh matrix of the closed loop
        m = loop._plant(p)
        s = getattr(m, "energy_scale", 1)
        return [add(float(Kd[i, j]), mul(s, m.damping[i])) if i == j else float(Kd[i, j])
                for i in range(n) for j in range(n)]

    tr = loop._trace
    T_g = tr(kinetic, ["T"])
    dV_g = tr(lambda x, p: [dV(loop.split(x)[0], p)], ["dV"])
    A_g = tr(mass, [f"A{i}{j}" for i in range(n) for j in range(n)])
    D_g = tr(dissipation, [f"D{i}{j}" for i in range(n) for j in range(n)])
    G_g = gradient_graph(dV_g, n, [f"G{i + 1}" for i in range(n)])  # grad_q dV
    centre = _equilibrium_fit(G_g, K, qref, loop.lo, loop.hi)
    level, center, residual = _compose(T_g, dV_g, G_g, K, centre, qref)
    ly = QuadraticLyapunov(level, A_g, G_g, center, residual, K, qref, dissipation=D_g)
    # the claim behind every box: dL/dt = grad L . f <= 0 (checked here at sample points)
    if samples is None:
        rng = np.random.default_rng(0)
        S = 32
        x = np.concatenate([qref + rng.uniform(-0.2, 0.2, (S, n)), rng.uniform(-1.0, 1.0, (S, n))], axis=1)
        p = rng.uniform(np.broadcast_to(loop.lo, (S, loop.lo.size)), np.broadcast_to(loop.hi, (S, loop.hi.size)))
    else:
        x, p = (np.atleast_2d(np.asarray(a, float)) for a in samples)
    rhs = loop.rhs_graph() if rhs is None else rhs
    try:
        ly.check(x, p)
        ly.check_dynamics(rhs, x, p)
    except ValueError as e:  # a builder bug or a loop this proof does not cover
        raise ControlError(f"the closed-loop energy does not fit this loop: {e}") from None
    f = eval_float(rhs, x, p)
    dL = np.einsum("si,si->s", jacobian_float(ly.graphs["level"], x, p)[:, 0, :], f)
    qd = x[:, n:2 * n]
    bound = np.abs(np.einsum("si,ij,sj->s", qd, Kd, qd)) + np.abs(f).sum(axis=1) + 1.0
    if np.any(dL > 1e-8 * bound):
        raise ControlError(f"the closed-loop energy rises along this loop (dL/dt up to {dL.max():.3g} at a "
                           "sample point): no invariant set")
    return ly

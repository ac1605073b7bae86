# Long (1200 lines) on purpose: one pipeline, recover_hamiltonian's phases in order, sharing private problem state.
"""Recover the Hamiltonian form from bare state equations (paper sec. 2 and sec. 4, step 2).

A user may only have ``x' = f(x)`` with ``x = (q, qd)``, ``qd' = Phi(q, qd)`` (for
example the paper's eq. (22)), and no chain.  Section 2 of the paper: the energy test
still applies if a symmetric positive definite mass matrix ``M(q)`` exists such that
``M(q) Phi(q, qd)`` has the structure of a Lagrangian equation of motion (eqs. (9)-(10)).
Section 4, step 2 then rebuilds the potential energy ``P(q)`` by the scalar integrals of
eqs. (14)-(15).  :func:`recover_hamiltonian` does both.

Conditions (all linear in the unknown coefficients of ``M``).  With declared generalized
forces ``tau(q, qd)`` (damping, e.g. ``tau = -d qd``; ``0`` by default) the equations of
motion must read ``M qdd + C(q, qd) qd + dP/dq = tau`` (eq. (2) with eq. (4)), i.e. with
``E(q, qd) = M Phi - tau + C(M) qd``:

(a) ``E(q, qd) - E(q, 0) = 0``.  ``C(M) qd`` is built from the Christoffel symbols of
    ``M``, ``(C qd)_k = (dM/dt qd)_k - 1/2 qd^T (dM/dq_k) qd``.  Differentiating twice in
    ``qd`` gives ``M B_i e_alpha + dM/dq_alpha e_i + dM/dq_i e_alpha - v = 0`` with
    ``v_k = e_i^T (dM/dq_k) e_alpha`` and ``dPhi/dqd_i = B_i(q) qd`` (eq. (9)): this is
    eq. (10) (its last term printed as ``[e_k^T dM/dq_k]_k e_alpha``; the Christoffel form
    above is the one that makes ``M Phi`` a Lagrangian equation).  Condition (a) also
    requires ``M Phi - tau`` to be quadratic in ``qd``.
(b) ``E(q, 0) = M Phi(q, 0) - tau(q, 0) = -dP/dq`` must be a gradient:
    ``d E0_k / d q_l = d E0_l / d q_k`` (the "symmetric gradient" condition that makes the
    integrals (15) independent of the path).

Method.  ``M`` is an ansatz over a basis of functions of ``q`` (default: monomials in
``sin q_i``, ``cos q_i`` of the coordinates that appear inside trigonometric functions of
``f`` (after ``expand_trig``, so ``sin(q1 + q2)`` counts) and in the coordinates that
appear polynomially, up to a total ``degree`` (default 2); ``sin^2`` is left out since
``sin^2 = 1 - cos^2``), one unknown per basis function per upper-triangle entry.  Every
function is written in the variables ``(q_i, S_i = sin q_i, C_i = cos q_i)``; as
functions of ``q`` these are algebraically independent up to ``S_i^2 + C_i^2 = 1``, so
the conditions (a)-(b) are evaluated *exactly* (rational arithmetic) at random rational
points ``(q_i, S_i, C_i) = (r, 2t/(1+t^2), (1-t^2)/(1+t^2))`` and random rational
``qd``, giving a linear system that is enlarged until its rank stops growing.  Free
parameters of ``f`` (``m``, ``l``, ``g`` as symbols) are first set to random positive
rationals to find the solution's support; the small system on that support is then
solved over the field of rational functions of the parameters.  The solution is
afterwards **verified symbolically**: ``M Phi - tau + C(M) qd + dP/dq`` is reduced to a
single fraction whose numerator is reduced modulo ``S_i^2 + C_i^2 - 1`` to the zero
polynomial (an exact identity test, no floating point, no ``simplify`` heuristics).

Scale.  (9)-(10) are homogeneous in ``M``: every positive multiple of a solution is a
solution (with ``P`` scaled alike; the trajectories are the same).  Without declared
``tau`` the scale is fixed by ``scale``: entry ``scale_entry`` (default the last diagonal
entry ``M[s-1][s-1]``) at ``q = 0`` is made equal to ``scale`` (default 1; pass e.g.
``m * l**2`` or a number in kg m^2 to get energies in joules).  A non-zero declared
``tau`` fixes the scale itself (``M Phi - tau`` is not homogeneous in ``M``) and
``scale`` is then ignored.

What is not found.  When no ``M`` in the span of the basis satisfies (a)-(b) (Van der
Pol, a non-conservative force field without declared ``tau``, a gyroscopic-looking linear
term) or every solution fails to be positive definite, :class:`NoHamiltonianError` is
raised, naming the reason; a wrong ``M`` is never returned.

Code.  :func:`recover_hamiltonian` is a short driver; the steps are module functions
below it, in the order it calls them: ``_setup_problem`` (rationalize, trig form) and
``_build_ansatz``; ``_Conditions`` (the rows of (a)-(b) at one point); phase 1
``_sample_until_rank_stable`` and ``_reduced_solution_basis``; ``_choose_definite_member``
(with ``_DefinitenessProbe``); phase 2 ``_solution_over_parameters``; ``_mass_matrix``
(scale); ``_potential`` (eqs. (14)-(15)); ``_verify_equations_of_motion``, ``_energies``,
``_verify_energy_balance``; ``_check_pd``.
"""
from __future__ import annotations

import itertools
import random
import time
from dataclasses import dataclass, field
from fractions import Fraction
from functools import cached_property

import numpy as np
import sympy
from sympy.polys.matrices import DomainMatrix
from sympy.printing.pycode import PythonCodePrinter

from verified.graph import from_sympy
from verified.arith.interval import Interval

from .errors import ModelError
from .system import System

__all__ = ["NoHamiltonianError", "RecoveredHamiltonian", "recover_hamiltonian"]


class NoHamiltonianError(ModelError):
    """No symmetric positive definite ``M(q)`` in the ansatz basis satisfies eqs. (9)-(10)
    (with the gradient condition on the ``qd``-free part)."""


# ----------------------------------------------------------------------------- helpers
class _FractionPrinter(PythonCodePrinter):
    """Prints rationals as ``Fraction(p, q)`` so lambdified code stays exact."""

    def _print_Rational(self, e):
        return f"Fraction({e.p}, {e.q})"

    def _print_Integer(self, e):
        return str(e.p)

    def _print_Half(self, e):
        return "Fraction(1, 2)"


def _lambdify(args, exprs, exact_symbolic=False):
    """Exact evaluator: Fractions in, Fractions out (or sympy numbers if
    ``exact_symbolic``, so that symbolic parameter inputs propagate)."""
    mod = {"Fraction": sympy.Rational if exact_symbolic else Fraction}
    return sympy.lambdify(args, list(exprs), modules=[mod], printer=_FractionPrinter, cse=True)


def _rationalize(expr, how):
    """Floats -> Rationals: ``"exact"`` (the Float's binary value) or ``"nsimplify"``."""
    expr = sympy.sympify(expr)
    floats = expr.atoms(sympy.Float)
    if not floats:
        return expr
    if how == "exact":
        return expr.xreplace({a: sympy.Rational(a) for a in floats})
    if how == "nsimplify":
        return expr.xreplace({a: sympy.nsimplify(a, rational=False) for a in floats})
    raise ValueError(f"rationalize must be 'exact' or 'nsimplify', got {how!r}")


def _pythagorean(rng):
    t = Fraction(rng.randint(-40, 40), rng.randint(1, 40))
    d = 1 + t * t
    return 2 * t / d, (1 - t * t) / d


@dataclass
class _Vars:
    """Symbols of the trig form: q, S = sin q, C = cos q, qd, parameters."""

    q: list
    qd: list
    params: list
    S: list
    C: list

    @property
    def args(self):
        return [*self.q, *self.S, *self.C, *self.qd, *self.params]

    def trig_form(self, expr):
        """q-form -> (q, S, C) form; raises ModelError on unsupported functions of q."""
        e = sympy.sympify(expr)
        e = e.replace(sympy.tan, lambda a: sympy.sin(a) / sympy.cos(a))
        e = e.replace(sympy.cot, lambda a: sympy.cos(a) / sympy.sin(a))
        e = sympy.expand_trig(e)
        rep = {}
        for qi, Si, Ci in zip(self.q, self.S, self.C):
            rep[sympy.sin(qi)] = Si
            rep[sympy.cos(qi)] = Ci
        e = e.xreplace(rep)
        qset = set(self.q)
        for fn in e.atoms(sympy.Function):
            if fn.free_symbols & qset:
                raise ModelError(f"recover_hamiltonian: unsupported function of q: {fn} "
                                 "(only sin/cos/tan of integer combinations of q and rational "
                                 "functions of q are supported)")
        return e

    def q_form(self, expr):
        return sympy.sympify(expr).xreplace(
            {**{S: sympy.sin(q) for S, q in zip(self.S, self.q)},
             **{C: sympy.cos(q) for C, q in zip(self.C, self.q)}})

    def d(self, e, l):
        """d/dq_l of a trig-form expression."""
        return (sympy.diff(e, self.q[l]) + self.C[l] * sympy.diff(e, self.S[l])
                - self.S[l] * sympy.diff(e, self.C[l]))

    @cached_property
    def ring_field(self):
        gens = [*self.params, *self.q, *self.S, *self.C, *self.qd]
        K, *_ = sympy.field(gens, sympy.QQ)
        R = K.ring
        ideal = [R(S ** 2 + C ** 2 - 1) for S, C in zip(self.S, self.C)]
        return K, R, ideal

    def normal_fraction(self, e):
        """(numerator, denominator) PolyElements of a trig-form expression, the numerator
        in normal form modulo S_i^2 + C_i^2 - 1 (lex order, S_i before C_i)."""
        K, R, ideal = self.ring_field
        fr = K.from_expr(sympy.sympify(e))
        num = fr.numer
        if ideal:
            num = num.rem(ideal)
        return num, fr.denom

    def is_zero(self, e):
        """Exact identity test: is the trig-form expression zero as a function of (q, qd)?"""
        return self.normal_fraction(e)[0] == 0

    def normal_expr(self, e):
        num, den = self.normal_fraction(e)
        return sympy.expand(num.as_expr()) / den.as_expr()


def _monomials(gens, S, degree):
    """Monomials of total degree <= degree in gens, without S_i**2 factors."""
    Sset = set(S)
    out = [sympy.Integer(1)]
    for d in range(1, degree + 1):
        for combo in itertools.combinations_with_replacement(gens, d):
            if any(combo.count(s) > 1 for s in Sset if s in combo):
                continue
            out.append(sympy.Mul(*combo))
    return out


def _rref_basis(vectors):
    """Canonical basis (reduced row echelon form) of the span of the given row vectors
    (DomainMatrix rows) -> (DomainMatrix, pivots)."""
    R, piv = vectors.rref()
    return R[:len(piv), :], piv


# ----------------------------------------------------------------------------- result
@dataclass(frozen=True)
class RecoveredHamiltonian:
    """Mass matrix, energies and energy balance recovered from ``qdd = Phi(q, qd)``.

    Attributes
    ----------
    q, qd : tuple of sympy.Symbol, length s
        Generalized coordinates (rad or m) and velocities (rad/s or m/s).
    f : tuple of sympy.Expr, length 2s
        The state rhs ``(qd, Phi)`` as given (floats left as they were).
    tau : tuple of sympy.Expr, length s
        The declared generalized forces (zeros if none) [N m or N].
    M : sympy.Matrix (s, s)
        Symmetric positive definite mass matrix ``M(q)`` [kg m^2 once scaled so], scale
        fixed as described in :func:`recover_hamiltonian` (``scale_note``).
    K, P, H : sympy.Expr
        ``K = 1/2 qd^T M qd`` (eq. (13)), ``P(q)`` from the integrals (15) with ``P(0) = 0``,
        ``H = K + P`` (eq. (4)) [J, in the units of the scale].
    dHdt : sympy.Expr
        ``grad H . f`` as built, not simplified (what the paper integrates for ``H_V``).
    dHdt_simplified : sympy.Expr
        ``qd^T tau`` (eq. (7); ``0`` for conservative systems), proved equal to ``dHdt`` by
        the exact identity test.
    basis : tuple of sympy.Expr
        The ansatz functions of ``q`` used for each entry of ``M``.
    family_dim : int
        Dimension of the solution space of (a)-(b) (homogeneous part; 1 means unique up to
        scale).  With more than one, the first positive definite candidate is returned and
        ``alternatives`` holds the basis of the family.
    pd_report : str
        What was checked about symmetry and positive definiteness, and how.
    positive_definite_proved : bool
        True when the leading minors were proved positive for all q in the checked range.
    scale_note : str
        How the free scale was fixed.
    params : tuple of sympy.Symbol
        Free parameters of ``f`` (other than ``q``, ``qd``); ``M``, ``P`` depend on them.
    timings : dict
        Wall times [s] of the stages.
    """

    q: tuple
    qd: tuple
    f: tuple
    tau: tuple
    M: sympy.Matrix
    K: sympy.Expr
    P: sympy.Expr
    H: sympy.Expr
    dHdt: sympy.Expr
    dHdt_simplified: sympy.Expr
    basis: tuple
    family_dim: int
    pd_report: str
    positive_definite_proved: bool
    scale_note: str
    params: tuple = ()
    alternatives: tuple = ()
    timings: dict = field(default_factory=dict)

    @property
    def s(self) -> int:
        return len(self.q)

    @property
    def momenta(self) -> sympy.Matrix:
        """Generalized momenta ``p = M(q) qd`` (s x 1)."""
        return self.M * sympy.Matrix(self.qd)

    @cached_property
    def canonical(self) -> dict:
        """Canonical equations (5)-(6).

        Returns a dict: ``p`` (symbols ``p1..ps``), ``p_of_qd`` = ``M qd``,
        ``H_of_p`` = ``1/2 p^T M^{-1} p + P`` (eq. (3)), ``qdot`` = ``dH/dp = M^{-1} p``
        (eq. (5)) and ``pdot`` = ``-dH/dq + tau`` (eq. (6)) written with
        ``qd = M^{-1} p`` as ``1/2 qd^T dM/dq_i qd - dP/dq_i + tau_i``."""
        s = self.s
        p = sympy.Matrix(sympy.symbols(f"p1:{s + 1}", real=True))
        qd = sympy.Matrix(self.qd)
        Minv_p = self.M.LUsolve(p)
        pdot = sympy.Matrix([(qd.T * self.M.diff(self.q[i]) * qd)[0, 0] / 2
                             - sympy.diff(self.P, self.q[i]) + self.tau[i] for i in range(s)])
        return {"p": p, "p_of_qd": self.M * qd, "H_of_p": (p.T * Minv_p)[0, 0] / 2 + self.P,
                "qdot": Minv_p, "pdot": pdot}

    def _subs(self, exprs, param_values):
        free = set().union(*(sympy.sympify(e).free_symbols for e in exprs)) - set(self.q) - set(self.qd)
        values = {}
        for k, v in (param_values or {}).items():
            sym = k if isinstance(k, sympy.Symbol) else next((p for p in free if p.name == k), None)
            if sym is not None:
                values[sym] = sympy.nsimplify(v) if isinstance(v, float) else sympy.sympify(v)
        missing = sorted(str(p) for p in free if p not in values)
        if missing:
            raise ValueError(f"system(): give numeric values for the parameters {missing} "
                             "(param_values={name: value})")
        return [sympy.sympify(e).xreplace(values) for e in exprs]

    def system(self, name: str = "recovered", simplified: bool = False, param_values=None):
        """The recovered model as an :class:`mbs.system.System` (mode (iii) input).

        ``rhs`` is the original ODE ``(qd, Phi)`` over the state ``(q..., qd...)``,
        ``energy`` is ``H`` (eq. (4)) and ``energy_rate`` is ``dHdt`` (``grad H . f``,
        exact for the ODE as given even when floats were rationalized) or, with
        ``simplified=True``, ``dHdt_simplified`` (``qd^T tau``, eq. (7)).  Free parameters
        need ``param_values`` (dict name or symbol -> number)."""
        x = [*self.q, *self.qd]
        names = [str(v) for v in x]
        rate = self.dHdt_simplified if simplified else self.dHdt
        f, H, dH = self._subs([*self.f], param_values), *self._subs([self.H, rate], param_values)
        rhs = from_sympy(f, x, output_names=[f"d{n}" for n in names])
        energy = from_sympy([H], x, output_names=["H"])
        energy_rate = from_sympy([dH], x, output_names=["dHdt"])
        return System(name=name, rhs=rhs, energy=energy, energy_rate=energy_rate,
                      description="Hamiltonian recovered from the ODE (paper eqs. 9-10, 14-15)"
                      + (", dH/dt simplified" if simplified else ""))


# ----------------------------------------------------------------------------- driver
def recover_hamiltonian(f, q, qd, *, tau=None, basis=None, degree: int = 2,
                        scale=None, scale_entry=None, rationalize: str = "exact",
                        pd_params=None, q_box=None, seed: int = 0,
                        max_boxes: int = 4000) -> RecoveredHamiltonian:
    """Find ``M(q)``, ``P(q)``, ``H`` for ``qdd = Phi(q, qd)`` (paper eqs. (9)-(10), (14)-(15)).

    Parameters
    ----------
    f : sequence of sympy expressions
        Either the ``s`` accelerations ``Phi(q, qd)`` or the full state rhs ``(qd, Phi)`` of
        length ``2s`` (its first ``s`` entries must be ``qd``).  Symbols other than ``q``,
        ``qd`` are parameters (kept symbolic; the result depends on them).
    q, qd : list of sympy.Symbol, length s
        Coordinates and velocities (the state is ``(q..., qd...)``).
    tau : sequence of s sympy expressions, optional
        Declared generalized forces in ``(q, qd)`` contained in ``Phi`` (e.g. viscous
        damping ``-d*qd``): moved out of ``Phi`` (``M Phi - tau`` must be Lagrangian) and
        kept in the energy balance ``dH/dt = qd^T tau`` (eq. (7)).
    basis : sequence of sympy expressions in q, optional
        Ansatz functions for each entry of ``M`` (default: see the module docstring).
    degree : int
        Total degree of the default basis monomials in ``sin q_i``, ``cos q_i``, ``q_i``.
    scale : number or sympy expression, optional
        Value of ``M[scale_entry]`` at ``q = 0`` (default 1).  Ignored when ``tau`` is
        non-zero (the declared forces fix the scale).
    scale_entry : (int, int), optional
        Entry normalised by ``scale`` (default ``(s-1, s-1)``; must be non-zero at q = 0).
    rationalize : "exact" or "nsimplify"
        How floats in ``f``/``tau`` become rationals for the exact solve: their exact binary
        value (default; the result is exact for the ODE as given) or sympy's ``nsimplify``
        (``9.81 -> 981/100``; the result is then exact for the rationalized ODE, and only
        ``dHdt`` -- built from the original ``f`` -- is exact for the given one).
    pd_params : dict, optional
        Parameter values for the positive definiteness check when ``f`` has free
        parameters (default: the check is attempted symbolically and otherwise done at
        random positive parameter values, and reported as such).
    q_box : sequence of (lo, hi), optional
        Range of each coordinate for the interval check of the leading minors (default
        ``[-3.15, 3.15]`` (a full period) for coordinates in trigonometric functions,
        ``[-1, 1]`` for the others).
    seed : int
        Seed of the random sample points (the result is verified exactly regardless).
    max_boxes : int
        Budget of the interval branch and bound on the minors.

    Returns
    -------
    RecoveredHamiltonian

    Raises
    ------
    NoHamiltonianError
        No symmetric positive definite ``M`` in the span of the basis.
    ModelError
        Unsupported functions of ``q`` in ``f``.
    ValueError, TypeError
        Malformed input (lengths, non-symbols).
    """
    t_start = time.perf_counter()
    timings = {}
    problem = _setup_problem(f, q, qd, tau, scale, rationalize)
    ansatz = _build_ansatz(problem, basis, degree)
    conditions = _Conditions(problem, ansatz)
    timings["setup"] = time.perf_counter() - t_start

    rng = random.Random(seed)
    par_vals = [Fraction(rng.randint(2, 10), rng.randint(2, 4)) for _ in problem.params]

    # phase 1: exact rational system at random parameter values, grown until its rank is stable
    t0 = time.perf_counter()
    sampled = _sample_until_rank_stable(conditions, rng, par_vals)
    null1 = sampled.matrix().nullspace()
    timings["phase1_solve"] = time.perf_counter() - t0
    cols, can1, piv1 = _reduced_solution_basis(null1, ansatz)
    # a positive definite member of the solution family (float screen, phase-1 values)
    probe = _DefinitenessProbe(problem, ansatz, cols, par_vals, q_box, seed)
    chosen, chosen_sign, family_dim = _choose_definite_member(
        _domain_rows(can1), piv1, cols, probe, problem.has_tau, seed)

    # phase 2: the small system on the support, over Q(params)
    t0 = time.perf_counter()
    rows2 = _solution_over_parameters(conditions, sampled, cols, can1, piv1, problem.params)
    vec = _chosen_solution(rows2, chosen, chosen_sign, problem.has_tau)
    timings["phase2_solve"] = time.perf_counter() - t0

    # M(q) with its scale fixed
    basis_q = [problem.V.q_form(b) for b in ansatz.basisT]
    Mq, scale_note = _mass_matrix(vec, cols, ansatz, basis_q, problem, scale_entry)

    # potential energy by the integrals (15), coordinate by coordinate
    t0 = time.perf_counter()
    MT = [[problem.V.trig_form(Mq[a, b]) for b in range(problem.s)] for a in range(problem.s)]
    P = _potential(MT, problem, degree, par_vals, rng)
    PT = problem.V.trig_form(P)
    # grad P == tau - M Phi at qd = 0 is proved below as part of the full identity
    timings["potential"] = time.perf_counter() - t0

    # exact verification: M Phi - tau + C qd + dP/dq == 0 and dH/dt == qd^T tau
    t0 = time.perf_counter()
    _verify_equations_of_motion(MT, PT, problem)
    Mq = Mq.applyfunc(sympy.sympify)
    K, H, dHdt, dHdt_s = _energies(Mq, P, problem)
    _verify_energy_balance(dHdt, dHdt_s, problem.V, rationalize)
    timings["verify"] = time.perf_counter() - t0

    # symmetry and positive definiteness (proved)
    t0 = time.perf_counter()
    pd_ok, pd_report = _check_pd(Mq, problem.V, problem.trig_idx, problem.poly_idx, problem.params,
                                 par_vals, pd_params, q_box, max_boxes)
    timings["pd_check"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_start
    alternatives = ()
    if family_dim > 1:
        alternatives = _family_members(rows2[(1 if problem.has_tau else 0):], cols, ansatz, basis_q)
    return RecoveredHamiltonian(
        q=tuple(problem.V.q), qd=tuple(problem.V.qd), f=tuple(problem.f_given),
        tau=tuple(problem.tau_given), M=Mq, K=K, P=P, H=H, dHdt=dHdt, dHdt_simplified=dHdt_s,
        basis=tuple(basis_q), family_dim=family_dim, pd_report=pd_report,
        positive_definite_proved=pd_ok, scale_note=scale_note, params=tuple(problem.params),
        alternatives=alternatives, timings=timings)


# ----------------------------------------------------------------------------- setup
def _check_inputs(f, q, qd, tau):
    """Validate the input; returns ``(q, qd, Phi, tau)`` as lists of length s (``Phi`` the
    accelerations as given, ``tau`` zeros when not declared)."""
    if not isinstance(q, (list, tuple)) or not isinstance(qd, (list, tuple)):
        raise TypeError("recover_hamiltonian: q and qd must be lists of sympy Symbols")
    q, qd = list(q), list(qd)
    s = len(q)
    if s == 0 or len(qd) != s:
        raise ValueError(f"recover_hamiltonian: q and qd must have the same non-zero length, "
                         f"got {len(q)} and {len(qd)}")
    for v in q + qd:
        if not isinstance(v, sympy.Symbol):
            raise TypeError(f"recover_hamiltonian: q and qd must hold sympy Symbols, got {v!r}")
    if len(set(q + qd)) != 2 * s:
        raise ValueError("recover_hamiltonian: q and qd must be 2s distinct symbols")
    f = [sympy.sympify(e) for e in f]
    if len(f) == 2 * s:
        for i in range(s):
            if sympy.expand(f[i] - qd[i]) != 0:
                raise ValueError(f"recover_hamiltonian: a state rhs of length 2s must start with "
                                 f"qd (entry {i} is {f[i]}, expected {qd[i]})")
        Phi = f[s:]
    elif len(f) == s:
        Phi = f
    else:
        raise ValueError(f"recover_hamiltonian: f must hold s = {s} accelerations or the 2s = "
                         f"{2 * s} entries (qd, qdd), got {len(f)}")
    if tau is None:
        tau_l = [sympy.Integer(0)] * s
    else:
        tau_l = [sympy.sympify(t) for t in tau]
        if len(tau_l) != s:
            raise ValueError(f"recover_hamiltonian: tau must have s = {s} entries, got {len(tau_l)}")
    return q, qd, Phi, tau_l


@dataclass
class _Problem:
    """The ODE ``qdd = Phi(q, qd)`` with declared forces ``tau(q, qd)``, floats
    rationalized and written in the trig form of :class:`_Vars`.

    Lists have length s unless stated.  ``Phi0T``, ``tau0T`` are ``PhiT``, ``tauT`` at
    ``qd = 0``; ``dPhi0T[l][k] = d Phi0_k / d q_l`` and ``dtau0T[l][k] = d tau0_k / d q_l``
    (s x s, the derivatives condition (b) needs)."""

    V: _Vars
    f_given: list           # (qd, Phi) as given, floats kept (length 2s)
    tau_given: list         # tau as given [N m or N]
    tau_r: list             # tau with floats rationalized
    has_tau: bool           # some declared force is non-zero
    scale_r: object         # the scale rationalized (None: not given)
    PhiT: list
    tauT: list
    Phi0T: list
    tau0T: list
    dPhi0T: list
    dtau0T: list
    trig_idx: list          # coordinates that appear inside sin / cos
    poly_idx: list          # coordinates that appear outside them
    gens: list              # S_i, C_i (i in trig_idx), then q_i (i in poly_idx)

    @property
    def s(self) -> int:
        return len(self.V.q)

    @property
    def params(self) -> list:
        return self.V.params


def _setup_problem(f, q, qd, tau, scale, rationalize) -> _Problem:
    """Check the input, rationalize floats (``rationalize``: "exact" or "nsimplify"; the
    scale always "exact"), collect the free parameters (sorted by name) and write ``Phi``
    and ``tau`` in trig form."""
    q, qd, Phi_given, tau_given = _check_inputs(f, q, qd, tau)
    s = len(q)
    Phi = [_rationalize(e, rationalize) for e in Phi_given]
    tau_r = [_rationalize(e, rationalize) for e in tau_given]
    scale_r = None if scale is None else _rationalize(scale, "exact")
    if scale_r is not None and scale_r.free_symbols & set(q + qd):
        raise ValueError(f"recover_hamiltonian: scale must not depend on q or qd, got {scale}")
    extra = scale_r.free_symbols if scale_r is not None else set()
    params = sorted(set().union(extra, *(e.free_symbols for e in Phi + tau_r)) - set(q) - set(qd),
                    key=str)
    V = _Vars(q=q, qd=qd, params=params,
              S=[sympy.Dummy(f"S_{v}") for v in q], C=[sympy.Dummy(f"C_{v}") for v in q])
    PhiT = [V.trig_form(e) for e in Phi]
    tauT = [V.trig_form(e) for e in tau_r]
    zero_qd = {v: 0 for v in qd}
    Phi0T = [e.xreplace(zero_qd) for e in PhiT]
    tau0T = [e.xreplace(zero_qd) for e in tauT]
    used = set().union(*(e.free_symbols for e in PhiT + tauT))
    trig_idx = [i for i in range(s) if V.S[i] in used or V.C[i] in used]
    poly_idx = [i for i in range(s) if q[i] in used]
    return _Problem(
        V=V, f_given=[*qd, *Phi_given], tau_given=tau_given, tau_r=tau_r,
        has_tau=any(t != 0 for t in tau_r), scale_r=scale_r, PhiT=PhiT, tauT=tauT,
        Phi0T=Phi0T, tau0T=tau0T,
        dPhi0T=[[V.d(e, l) for e in Phi0T] for l in range(s)],
        dtau0T=[[V.d(e, l) for e in tau0T] for l in range(s)],
        trig_idx=trig_idx, poly_idx=poly_idx,
        gens=[g for i in trig_idx for g in (V.S[i], V.C[i])] + [q[i] for i in poly_idx])


@dataclass
class _Ansatz:
    """``M(q)_ab = sum_j c_(e,j) basis_j(q)`` for each upper-triangle entry ``e = (a, b)``.

    The unknown of column ``e * nb + j`` is ``c_(e,j)``; with declared forces, column ``N``
    (the last) is the coefficient of ``tau``, which fixes the scale."""

    basisT: list            # the nb basis functions in trig form
    dbasisT: list           # dbasisT[l][j] = d basis_j / d q_l (s x nb)
    entries: list           # the s(s+1)/2 entries (a, b), a <= b
    has_tau: bool

    @property
    def nb(self) -> int:
        return len(self.basisT)

    @property
    def N(self) -> int:
        """Number of unknowns of ``M``; also the index of the tau column."""
        return len(self.entries) * self.nb

    @property
    def ncol(self) -> int:
        return self.N + (1 if self.has_tau else 0)

    def assemble(self, coeff, basis_q) -> sympy.Matrix:
        """The s x s symmetric ``M`` for the coefficients ``coeff`` (dict column -> value,
        columns < N) and the basis ``basis_q`` (functions of q)."""
        s = len(self.dbasisT)
        Mm = sympy.zeros(s, s)
        for c, v in coeff.items():
            e, j = divmod(c, self.nb)
            a, b = self.entries[e]
            Mm[a, b] += v * basis_q[j]
            if a != b:
                Mm[b, a] += v * basis_q[j]
        return Mm


def _build_ansatz(problem, basis, degree) -> _Ansatz:
    """The ansatz for ``M``: the user's ``basis`` (functions of q only) or the monomials of
    total degree <= ``degree`` in ``problem.gens`` (module docstring, "Method")."""
    V, q, s = problem.V, problem.V.q, problem.s
    if basis is None:
        basisT = _monomials(problem.gens, V.S, degree)
    else:
        basisT = []
        for b in basis:
            b = sympy.sympify(b)
            extra = b.free_symbols - set(q)
            if extra:
                raise ValueError(f"recover_hamiltonian: basis functions must depend on q only, "
                                 f"{b} has {sorted(map(str, extra))}")
            basisT.append(V.trig_form(_rationalize(b, "exact")))
    return _Ansatz(basisT=basisT, dbasisT=[[V.d(b, l) for b in basisT] for l in range(s)],
                   entries=[(a, b) for a in range(s) for b in range(a, s)],
                   has_tau=problem.has_tau)


# ----------------------------------------------------------------------------- conditions
class _Conditions:
    """Conditions (a) (eq. (10), s rows) and (b) (the symmetric gradient, s(s-1)/2 rows)
    as rows of a linear system in the ansatz unknowns (length ``ansatz.ncol``), evaluated
    exactly at one sample point."""

    def __init__(self, problem, ansatz):
        V, p = problem.V, problem
        self.problem, self.ansatz = problem, ansatz
        self._phi_exprs = [*p.PhiT, *p.Phi0T, *itertools.chain(*p.dPhi0T)]
        self._tau_exprs = [*p.tauT, *p.tau0T, *itertools.chain(*p.dtau0T)]
        self._ev_phi = _lambdify(V.args, self._phi_exprs)
        self._ev_tau = _lambdify(V.args, self._tau_exprs)
        self._ev_basis = _lambdify(V.args, [*ansatz.basisT, *itertools.chain(*ansatz.dbasisT)])

    @cached_property
    def _ev_symbolic(self):
        """Evaluators of Phi and tau through which symbolic parameters propagate (phase 2)."""
        V = self.problem.V
        return (_lambdify(V.args, self._phi_exprs, exact_symbolic=True),
                _lambdify(V.args, self._tau_exprs, exact_symbolic=True))

    @property
    def per_point(self) -> int:
        s = self.problem.s
        return s + s * (s - 1) // 2

    def rows_at(self, pt, pvals, symbolic=False):
        """The rows (a) then (b) at ``pt = (q, S, C, qd)`` (lists of s exact numbers) and
        parameter values ``pvals`` (numbers, or with ``symbolic`` the parameter symbols).
        Raises ZeroDivisionError where the ODE is singular."""
        s, nb = self.problem.s, self.ansatz.nb
        qv, Sv, Cv, qdv = pt
        args = [*qv, *Sv, *Cv, *qdv, *pvals]
        ev_phi, ev_tau = self._ev_symbolic if symbolic else (self._ev_phi, self._ev_tau)
        vals = ev_phi(*args)
        tvals = ev_tau(*args)
        bvals = self._ev_basis(*args)
        phi, phi0 = vals[:s], vals[s:2 * s]
        dphi0 = [vals[2 * s + l * s: 2 * s + (l + 1) * s] for l in range(s)]
        tv, tv0 = tvals[:s], tvals[s:2 * s]
        dtv0 = [tvals[2 * s + l * s: 2 * s + (l + 1) * s] for l in range(s)]
        B = bvals[:nb]
        dB = [bvals[nb + l * nb: nb + (l + 1) * nb] for l in range(s)]
        return (_condition_a_rows(self.ansatz, qdv, phi, phi0, B, dB, tv, tv0)
                + _condition_b_rows(self.ansatz, phi0, dphi0, B, dB, dtv0))


def _condition_a_rows(ansatz, qdv, phi, phi0, B, dB, tv, tv0):
    """Condition (a), eqs. (9)-(10): for k = 1..s the row of
    ``E_k(q, qd) - E_k(q, 0) = 0`` with ``E = M Phi - tau + C(M) qd`` and
    ``(C qd)_k = (dM/dt qd)_k - 1/2 qd^T (dM/dq_k) qd`` (Christoffel form), at one point.

    ``qdv``, ``phi``, ``phi0``, ``tv``, ``tv0``: length s (``*0`` at ``qd = 0``); ``B``:
    the nb basis values; ``dB[l][j] = d basis_j / d q_l``."""
    s, nb, N = len(qdv), ansatz.nb, ansatz.N
    dphi = [phi[k] - phi0[k] for k in range(s)]
    Bdot = [sum((dB[l][j] * qdv[l] for l in range(s)), 0) for j in range(nb)]
    rows = []
    for k in range(s):
        row = [0] * ansatz.ncol
        for e, (a, b) in enumerate(ansatz.entries):
            w = qdv[a] * qdv[b] * (1 if a == b else 2)
            for j in range(nb):
                val = -dB[k][j] * w / 2
                if k == a:
                    val += B[j] * dphi[b] + Bdot[j] * qdv[b]
                if k == b and a != b:
                    val += B[j] * dphi[a] + Bdot[j] * qdv[a]
                row[e * nb + j] = val
        if ansatz.has_tau:
            row[N] = -(tv[k] - tv0[k])
        rows.append(row)
    return rows


def _condition_b_rows(ansatz, phi0, dphi0, B, dB, dtv0):
    """Condition (b): ``E0 = M Phi(q, 0) - tau(q, 0) = -dP/dq`` is a gradient, so that the
    integrals (15) do not depend on the path: for k < l the row of
    ``d E0_k / d q_l - d E0_l / d q_k = 0`` at one point.

    ``phi0``: length s; ``dphi0[l][k] = d Phi0_k / d q_l``, ``dtv0`` likewise for tau;
    ``B``, ``dB`` as in :func:`_condition_a_rows`."""
    s, nb, N = len(phi0), ansatz.nb, ansatz.N
    rows = []
    for k in range(s):
        for l in range(k + 1, s):
            row = [0] * ansatz.ncol
            for e, (a, b) in enumerate(ansatz.entries):
                for j in range(nb):
                    val = 0
                    # d_l (M_j phi0)_k - d_k (M_j phi0)_l
                    for (kk, ll, sign) in ((k, l, 1), (l, k, -1)):
                        if kk == a:
                            val += sign * (dB[ll][j] * phi0[b] + B[j] * dphi0[ll][b])
                        if kk == b and a != b:
                            val += sign * (dB[ll][j] * phi0[a] + B[j] * dphi0[ll][a])
                    row[e * nb + j] = val
            if ansatz.has_tau:
                row[N] = -(dtv0[l][k] - dtv0[k][l])
            rows.append(row)
    return rows


# ----------------------------------------------------------------------------- phase 1
def _sample_point(rng, s):
    """A random rational point ``(q, S, C, qd)``, four lists of s Fractions, with
    ``S_i^2 + C_i^2 = 1`` (``q`` independent of ``S``, ``C``: see the module docstring)."""
    qv, Sv, Cv = [], [], []
    for _ in range(s):
        Si, Ci = _pythagorean(rng)
        qv.append(Fraction(rng.randint(-30, 30), rng.randint(1, 15)))
        Sv.append(Si)
        Cv.append(Ci)
    qdv = [Fraction(rng.randint(-30, 30), rng.randint(1, 10)) for _ in range(s)]
    return qv, Sv, Cv, qdv


class _SampledSystem:
    """Phase 1: the rows of conditions (a)-(b) over QQ at random points, with the
    parameters at the random rationals ``par_vals``.  ``origin[i] = (point index, row index
    at that point)`` of row i."""

    def __init__(self, conditions, rng, par_vals):
        self.conditions, self.rng, self.par_vals = conditions, rng, par_vals
        self.ncol = conditions.ansatz.ncol
        self.points, self.rows, self.origin = [], [], []

    def add_points(self, n):
        """Add the rows of n more points; points where the ODE is singular are skipped."""
        QQ = sympy.QQ
        added = 0
        tries = 0
        while added < n:
            tries += 1
            if tries > 20 * n + 50:
                raise NoHamiltonianError("recover_hamiltonian: the ODE could not be evaluated at "
                                         "random rational points (division by zero everywhere?)")
            pt = _sample_point(self.rng, self.conditions.problem.s)
            try:
                rs = self.conditions.rows_at(pt, self.par_vals)
            except ZeroDivisionError:
                continue
            self.points.append(pt)
            for r_i, r in enumerate(rs):
                self.rows.append([QQ(v.numerator, v.denominator) if isinstance(v, Fraction)
                                  else QQ(v) for v in r])
                self.origin.append((len(self.points) - 1, r_i))
            added += 1

    def matrix(self) -> DomainMatrix:
        return DomainMatrix(self.rows, (len(self.rows), self.ncol), sympy.QQ)

    def rank(self) -> int:
        return self.matrix().rank()


def _sample_until_rank_stable(conditions, rng, par_vals) -> _SampledSystem:
    """Add sample points until the rank of the phase-1 system is full or has not grown
    for two rounds."""
    sampled = _SampledSystem(conditions, rng, par_vals)
    ncol, per_point = sampled.ncol, conditions.per_point
    sampled.add_points(ncol // per_point + 3)
    r_prev = sampled.rank()
    stable = 0
    while stable < 2 and r_prev < ncol:
        sampled.add_points(max(3, ncol // (4 * per_point)))
        r_new = sampled.rank()
        stable = stable + 1 if r_new == r_prev else 0
        r_prev = r_new
    return sampled


def _domain_rows(mat):
    """The rows of a DomainMatrix as lists of domain elements."""
    return [[mat[i, j].element for j in range(mat.shape[1])] for i in range(mat.shape[0])]


def _reduced_solution_basis(null1, ansatz):
    """The support of the phase-1 null space (the columns some solution uses; the tau
    column ``N`` first, so that its pivot comes first) and the null space restricted to it
    in reduced row echelon form -> ``(cols, can1, piv1)``.  Raises when there is no
    solution, or none with a non-zero tau coefficient."""
    QQ, N, ncol = sympy.QQ, ansatz.N, ansatz.ncol
    if null1.shape[0] == 0:
        raise NoHamiltonianError(
            "recover_hamiltonian: no mass matrix M(q) in the span of the basis "
            f"({ansatz.nb} functions of q per entry, {N} unknowns) satisfies eqs. (9)-(10) and "
            "the gradient condition" + (" with the declared tau" if ansatz.has_tau else
                                        " (non-conservative forces? declare them as tau)"))
    support = sorted({c for i in range(null1.shape[0]) for c in range(ncol)
                      if null1[i, c].element != 0})
    if ansatz.has_tau and N not in support:
        raise NoHamiltonianError(
            "recover_hamiltonian: the declared tau is not consistent with a Lagrangian structure "
            "of the remaining terms (no solution has a non-zero tau coefficient)")
    cols = ([N] if ansatz.has_tau else []) + [c for c in support if c != N]
    null1_r = DomainMatrix([[null1[i, c].element for c in cols] for i in range(null1.shape[0])],
                           (null1.shape[0], len(cols)), QQ)
    can1, piv1 = _rref_basis(null1_r)
    return cols, can1, piv1


# ----------------------------------------------------------------------------- definiteness
class _DefinitenessProbe:
    """A floating-point screen of ``M`` at test points, used only to *choose* a member of
    the solution family (the result is proved positive definite by :func:`_check_pd`).

    Test points: 40 random ``(angles, q)`` with angles in ``[-pi, pi]`` (for S, C) and q in
    ``q_box`` (default ``[-1, 1]``), plus ``q = 0`` when no ``q_box`` is given."""

    def __init__(self, problem, ansatz, cols, par_vals, q_box, seed):
        s = problem.s
        self.s, self.ansatz, self.cols, self.par_vals = s, ansatz, cols, par_vals
        fl_rng = np.random.default_rng(seed)
        self._ev_basis = sympy.lambdify(problem.V.args, ansatz.basisT, modules="numpy")
        box = np.array(q_box, dtype=float) if q_box is not None else np.array([[-1.0, 1.0]] * s)
        self.points = [(fl_rng.uniform(-np.pi, np.pi, s), fl_rng.uniform(box[:, 0], box[:, 1]))
                       for _ in range(40)]
        if q_box is None:
            self.points.insert(0, (np.zeros(s), np.zeros(s)))

    def matrix(self, vec, ang, qv):
        """``M`` (s x s floats) for the coefficients ``vec`` (over ``cols``) at
        ``S = sin(ang)``, ``C = cos(ang)``, ``q = qv``."""
        s, ansatz = self.s, self.ansatz
        Sv, Cv = np.sin(ang), np.cos(ang)
        Bv = self._ev_basis(*qv, *Sv, *Cv, *([0.0] * s), *[float(p) for p in self.par_vals])
        Mf = np.zeros((s, s))
        for ci, c in enumerate(self.cols):
            if c == ansatz.N:
                continue
            e, j = divmod(c, ansatz.nb)
            a, b = ansatz.entries[e]
            Mf[a, b] += float(vec[ci]) * float(Bv[j])
            Mf[b, a] = Mf[a, b]
        return Mf

    def sign(self, vec) -> int:
        """+1 (-1) if ``M`` is positive (negative) definite at every test point, else 0."""
        sign = 0
        for ang, qv in self.points:
            ev = np.linalg.eigvalsh(self.matrix(vec, ang, qv))
            cur = 1 if ev.min() > 0 else (-1 if ev.max() < 0 else 0)
            if cur == 0 or (sign and cur != sign):
                return 0
            sign = cur
        return sign


def _candidate_combinations(d, has_tau, seed):
    """Coefficient tuples tried on the d homogeneous solutions: with declared tau only the
    particular solution (the tau row); otherwise each basis vector, then (for d > 1) their
    sum and 30 random integer combinations."""
    if has_tau:
        return [(1,) + (0,) * d]
    candidates = [tuple(int(i == k) for i in range(d)) for k in range(d)]
    if d > 1:
        candidates.append((1,) * d)
        crng = random.Random(seed + 1)
        candidates += [tuple(crng.randint(-3, 3) for _ in range(d)) for _ in range(30)]
    return candidates


def _choose_definite_member(can1_rows, piv1, cols, probe, has_tau, seed):
    """A member of the phase-1 solution family that the probe finds definite ->
    ``(alpha, sign, family_dim)``: the combination ``alpha`` of the homogeneous rows, the
    sign (-1: flip it; only without tau) and the dimension of the homogeneous family."""
    if has_tau:
        part = can1_rows[0]
        if piv1[0] != 0:
            raise NoHamiltonianError("recover_hamiltonian: the declared tau is not consistent "
                                     "with a Lagrangian structure of the remaining terms")
        hom = can1_rows[1:]
    else:
        hom = can1_rows
    family_dim = len(hom)
    for alpha in _candidate_combinations(family_dim, has_tau, seed):
        if has_tau:
            vec = part
        else:
            vec = [sum(al * r[i] for al, r in zip(alpha, hom)) for i in range(len(cols))]
        sg = probe.sign(vec)
        if sg > 0 or (sg < 0 and not has_tau):
            return alpha, sg, family_dim
    raise NoHamiltonianError(
        "recover_hamiltonian: eqs. (9)-(10) have solutions in the basis "
        f"(a {family_dim}-dimensional family), but none tried is positive definite"
        + (" (with the declared tau fixing the scale)" if has_tau else "")
        + ": the system is not a Hamiltonian system with a mass matrix in this basis")


# ----------------------------------------------------------------------------- phase 2
def _independent_rows_by_point(sampled, cols, need):
    """``need`` linearly independent phase-1 rows (restricted to ``cols``), grouped as
    {point index: [row index at that point]}."""
    QQ = sympy.QQ
    Asub = DomainMatrix([[r[c] for c in cols] for r in sampled.rows],
                        (len(sampled.rows), len(cols)), QQ)
    _, prow = Asub.transpose().rref()
    prow = list(prow)[:need]
    by_point = {}
    for ri in prow:
        pi, k = sampled.origin[ri]
        by_point.setdefault(pi, []).append(k)
    return by_point


def _solution_over_parameters(conditions, sampled, cols, can1, piv1, params):
    """Phase 2: the solution rows (reduced row echelon form over ``cols``, as sympy
    expressions) over the field of rational functions of the parameters, from the same
    points as phase 1 with the parameters kept as symbols.  Without parameters these are
    the phase-1 rows.  Raises when the symbolic solution space differs from phase 1's."""
    QQ = sympy.QQ
    if not params:
        return [[QQ.to_sympy(x) for x in r] for r in _domain_rows(can1)]
    by_point = _independent_rows_by_point(sampled, cols, len(cols) - can1.shape[0])
    sym_rows = []
    for pi, ks in by_point.items():
        pt = sampled.points[pi]
        rs = conditions.rows_at(tuple([sympy.Rational(v.numerator, v.denominator) for v in part_]
                                      for part_ in pt), params, symbolic=True)
        for k in ks:
            sym_rows.append([sympy.sympify(rs[k][c]) for c in cols])
    A2 = DomainMatrix.from_list_sympy(len(sym_rows), len(cols), sym_rows).to_field()
    null2 = A2.nullspace()
    if null2.shape[0] != can1.shape[0]:
        raise NoHamiltonianError("recover_hamiltonian: the solution space for symbolic "
                                 "parameters differs from the generic one; give parameter "
                                 "values")
    can2, piv2 = _rref_basis(null2)
    if list(piv2) != list(piv1):
        raise NoHamiltonianError("recover_hamiltonian: inconsistent pivots between the "
                                 "numeric and symbolic solves; give parameter values")
    K2 = can2.domain
    return [[K2.to_sympy(can2[i, j].element) for j in range(len(cols))]
            for i in range(can2.shape[0])]


def _chosen_solution(rows2, chosen, chosen_sign, has_tau):
    """The coefficient vector (over ``cols``) of the chosen member: the tau row with
    declared tau, else ``chosen_sign * sum_i chosen_i rows2_i``."""
    if has_tau:
        return rows2[0]
    vec = [sum(al * r[i] for al, r in zip(chosen, rows2)) for i in range(len(rows2[0]))]
    return [chosen_sign * v for v in vec]


# ----------------------------------------------------------------------------- M and P
def _mass_matrix(vec, cols, ansatz, basis_q, problem, scale_entry):
    """``M(q)`` (s x s, q-form) from the coefficient vector, scale fixed (see
    :func:`_normalise_scale`), collected in the basis functions -> ``(M, scale_note)``."""
    coeff = {}
    for ci, c in enumerate(cols):
        if c == ansatz.N:
            continue
        coeff[c] = sympy.cancel(vec[ci])
    Mq = ansatz.assemble(coeff, basis_q)
    if problem.has_tau:
        scale_note = "scale fixed by the declared tau (M Phi - tau is not homogeneous in M)"
    else:
        Mq, scale_note = _normalise_scale(Mq, coeff, ansatz, basis_q, problem, scale_entry)
    nb = ansatz.nb
    Mq = Mq.applyfunc(lambda e: sympy.collect(sympy.expand(e), basis_q[1:] if nb > 1 else []))
    return Mq, scale_note


def _normalise_scale(Mq, coeff, ansatz, basis_q, problem, scale_entry):
    """Eqs. (9)-(10) are homogeneous in M: scale it so that ``M[scale_entry]`` at ``q = 0``
    equals the scale (default 1; entry default the last diagonal one, else the first
    diagonal entry non-zero at q = 0) -> ``(M, scale_note)``."""
    s = problem.s
    q0 = {v: 0 for v in problem.V.q}
    if scale_entry is None:
        cand = [(s - 1, s - 1)] + [(i, i) for i in range(s)]
    else:
        cand = [tuple(scale_entry)]
    entry = next((ij for ij in cand if sympy.simplify(Mq[ij].xreplace(q0)) != 0), None)
    if entry is None:
        raise NoHamiltonianError(f"recover_hamiltonian: M{cand[0]} vanishes at q = 0; "
                                 "choose another scale_entry")
    target = sympy.Integer(1) if problem.scale_r is None else problem.scale_r
    factor = sympy.cancel(target / Mq[entry].xreplace(q0))
    coeff = {c: sympy.cancel(v * factor) for c, v in coeff.items()}
    return (ansatz.assemble(coeff, basis_q),
            f"M[{entry[0]}][{entry[1]}] at q = 0 normalised to {target} "
            "(eqs. (9)-(10) are homogeneous in M)")


def _potential(MT, problem, degree, par_vals, rng):
    """``P(q)`` (q-form, ``P(0) = 0``) by the integrals (15), coordinate by coordinate, of
    ``dP/dq = tau - M Phi`` at ``qd = 0`` (eq. (14)); ``MT`` is ``M`` in trig form (s x s
    lists).  The integrand is first fitted as a polynomial in the monomials of degree
    ``degree + 1`` (:func:`_fit_polynomial`).  Raises when the remainder for ``q_i`` still
    depends on ``q_1..q_(i-1)`` (not a gradient)."""
    V, s, q = problem.V, problem.s, problem.V.q
    G = [problem.tau0T[k] - sum((MT[k][m] * problem.Phi0T[m] for m in range(s)), sympy.Integer(0))
         for k in range(s)]        # = dP/dq at qd = 0
    G_poly = _fit_polynomial(G, V, problem.gens, degree + 1, par_vals, problem.params, rng)
    if G_poly is None:      # no fit in the monomials: hand the integrand to sympy as it is
        G_poly = [V.trig_form(sympy.simplify(V.q_form(g))) for g in G]
    P = sympy.Integer(0)
    for i in range(s):
        R_i = V.normal_expr(sympy.expand(G_poly[i] - V.d(V.trig_form(P), i)))
        bad = R_i.free_symbols & {x for j in range(i) for x in (q[j], V.S[j], V.C[j])}
        if bad:
            raise NoHamiltonianError(f"recover_hamiltonian: dP/dq is not a gradient (the "
                                     f"remainder for q{i + 1} still depends on {bad})")
        R_q = sympy.expand(V.q_form(R_i))
        P += sympy.integrate(R_q, q[i])
    q0 = {v: 0 for v in q}
    return sympy.expand(P - P.xreplace(q0))


# ----------------------------------------------------------------------------- verification
def _verify_equations_of_motion(MT, PT, problem):
    """Exact identity test of the whole structure, ``M Phi - tau + C(M) qd + dP/dq == 0``
    (eq. (2) with eq. (4)), equation by equation; ``MT``, ``PT`` in trig form."""
    V, s, qd = problem.V, problem.s, problem.V.qd
    qdv = sympy.Matrix(qd)
    Mdot = sum((sympy.Matrix(MT).applyfunc(lambda e: V.d(e, l)) * qd[l] for l in range(s)),
               sympy.zeros(s, s))
    for k in range(s):
        Cqd_k = (Mdot * qdv)[k] - (qdv.T * sympy.Matrix(MT).applyfunc(lambda e: V.d(e, k))
                                   * qdv)[0, 0] / 2
        res = sum((MT[k][m] * problem.PhiT[m] for m in range(s)), sympy.Integer(0)) \
            - problem.tauT[k] + Cqd_k + V.d(PT, k)
        if not V.is_zero(res):
            raise NoHamiltonianError(f"recover_hamiltonian: verification failed for equation "
                                     f"{k + 1} (the sampled solve found a spurious solution); "
                                     "try another seed or basis")


def _energies(Mq, P, problem):
    """``K = 1/2 qd^T M qd`` (eq. (13)), ``H = K + P`` (eq. (4)), ``dH/dt = grad H . f``
    with ``f`` as given, and ``qd^T tau`` (eq. (7)) -> ``(K, H, dHdt, dHdt_simplified)``."""
    q, qd = problem.V.q, problem.V.qd
    qdv = sympy.Matrix(qd)
    K = sympy.expand((qdv.T * Mq * qdv)[0, 0] / 2)
    H = K + P
    dHdt = sum((sympy.diff(H, x) * fx for x, fx in zip([*q, *qd], problem.f_given)),
               sympy.Integer(0))
    dHdt_s = sympy.expand(sum((a * b for a, b in zip(qd, problem.tau_r)), sympy.Integer(0)))
    return K, H, dHdt, dHdt_s


def _verify_energy_balance(dHdt, dHdt_s, V, rationalize):
    """Exact identity test of eq. (7): ``grad H . f == qd^T tau`` (floats in ``dHdt``
    rationalized as the ODE was)."""
    if not V.is_zero(V.trig_form(_rationalize(dHdt, rationalize)) - V.trig_form(dHdt_s)):
        raise NoHamiltonianError("recover_hamiltonian: dH/dt != qd^T tau (verification failed)")


def _family_members(rows, cols, ansatz, basis_q):
    """The mass matrices of the homogeneous solution rows (``alternatives``)."""
    return tuple(ansatz.assemble({c: r[ci] for ci, c in enumerate(cols) if c != ansatz.N},
                                 basis_q)
                 for r in rows)


def _fit_polynomial(G, V, gens, degree, par_vals, params, rng):
    """Write each trig-form ``G_k`` (the integrand of eq. (15)) as a polynomial in the
    monomials of ``gens`` up to ``degree``: exact interpolation at rational points
    (parameters enter only the right-hand sides, so one exact numeric inverse serves all
    components).  The fit is not trusted: the caller verifies ``grad P`` exactly."""
    mons = _monomials(gens, V.S, degree)
    s = len(G)
    ev_mon = _lambdify(V.args, mons)
    QQ = sympy.QQ
    pts, rows = [], []
    for _ in range(4 * len(mons) + 20):
        qv = [Fraction(rng.randint(-9, 9), rng.randint(1, 5)) for _ in range(s)]
        SC = [_pythagorean(rng) for _ in range(s)]
        pt = qv + [a for a, _ in SC] + [b for _, b in SC]
        vals = ev_mon(*pt, *([0] * s), *par_vals)
        rows.append([QQ(v.numerator, v.denominator) if isinstance(v, Fraction) else QQ(v)
                     for v in vals])
        pts.append(pt)
        if len(rows) >= len(mons) and \
                DomainMatrix(rows, (len(rows), len(mons)), QQ).rank() == len(mons):
            break
    else:
        return None
    _, prow = DomainMatrix(rows, (len(rows), len(mons)), QQ).transpose().rref()
    prow = list(prow)
    Ainv = DomainMatrix([rows[i] for i in prow], (len(prow), len(mons)), QQ).inv()
    ev_G = _lambdify(V.args, G, exact_symbolic=bool(params))
    gvals = []
    for i in prow:
        pt = pts[i]
        if params:
            pt = [sympy.Rational(v.numerator, v.denominator) for v in pt]
            gvals.append([sympy.cancel(v) for v in ev_G(*pt, *([0] * s), *params)])
        else:
            gvals.append([sympy.Rational(v.numerator, v.denominator) if isinstance(v, Fraction)
                          else sympy.sympify(v) for v in ev_G(*pt, *([0] * s))])
    Ainv_s = [[QQ.to_sympy(Ainv[r, c].element) for c in range(len(prow))]
              for r in range(len(mons))]
    out = []
    for k in range(s):
        coeffs = [sympy.cancel(sum((Ainv_s[r][c] * gvals[c][k] for c in range(len(prow))),
                                   sympy.Integer(0))) for r in range(len(mons))]
        out.append(sum((c * m for c, m in zip(coeffs, mons)), sympy.Integer(0)))
    return out


def _check_pd(Mq, V, trig_idx, poly_idx, params, par_vals, pd_params, q_box, max_boxes):
    """Symmetry (exact) and Sylvester's criterion: leading minors > 0, first tried
    symbolically, then by interval branch and bound over ``q_box``."""
    s = Mq.shape[0]
    if (Mq - Mq.T).applyfunc(sympy.expand) != sympy.zeros(s, s):
        raise NoHamiltonianError("recover_hamiltonian: assembled M is not symmetric")
    minors = [sympy.expand(Mq[:k, :k].det(method="berkowitz")) for k in range(1, s + 1)]
    values = {}
    how = ""
    if params:
        if pd_params:
            values = {p: sympy.nsimplify(pd_params[p] if p in pd_params else pd_params[str(p)])
                      for p in params}
            how = f" for the given parameter values {dict((str(k), v) for k, v in values.items())}"
        else:
            pos = {p: sympy.Dummy(str(p), positive=True) for p in params}
            if all(sympy.simplify(m.xreplace(pos)).is_positive for m in minors):
                return True, ("symmetric; leading minors proved positive symbolically for "
                              "positive parameters")
            values = {p: sympy.Rational(v.numerator, v.denominator) for p, v in zip(params, par_vals)}
            how = (" at random positive parameter values "
                   f"{dict((str(k), v) for k, v in values.items())} (symbolic proof inconclusive)")
    minors_v = [m.xreplace(values) for m in minors]
    if all(m.is_positive for m in minors_v):
        return True, "symmetric; leading minors positive constants" + how
    box_lo, box_hi = [], []
    for i in range(s):
        if q_box is not None:
            lo, hi = q_box[i]
        elif i in trig_idx and i not in poly_idx:
            lo, hi = -3.15, 3.15
        else:
            lo, hi = -1.0, 1.0
        box_lo.append(float(lo))
        box_hi.append(float(hi))
    g = from_sympy(minors_v, list(V.q))
    boxes = [(np.array(box_lo), np.array(box_hi))]
    evaluated = 0
    while boxes:
        if evaluated > max_boxes:
            return False, ("symmetric; leading minors NOT proved positive (branch and bound "
                           f"budget {max_boxes} boxes exhausted) over q in "
                           f"{list(zip(box_lo, box_hi))}" + how)
        lo = np.array([b[0] for b in boxes])
        hi = np.array([b[1] for b in boxes])
        enc = g.eval_interval(Interval(lo, hi))
        evaluated += len(boxes)
        keep = []
        for i in range(len(boxes)):
            if np.all(enc.lo[i] > 0):
                continue
            mid = (lo[i] + hi[i]) / 2
            mv = g.eval_float(mid)
            if np.any(mv <= 0):
                raise NoHamiltonianError(
                    f"recover_hamiltonian: the recovered M is not positive definite at q = "
                    f"{mid.tolist()}{how} (leading minors {mv.tolist()})")
            w = hi[i] - lo[i]
            j = int(np.argmax(w))
            a_hi, b_lo = hi[i].copy(), lo[i].copy()
            a_hi[j] = b_lo[j] = mid[j]
            keep += [(lo[i], a_hi), (b_lo, hi[i])]
        boxes = keep
    full = all((i in trig_idx and i not in poly_idx) for i in range(s)) and q_box is None
    where = ("for all q (periodic coordinates, one full period checked)" if full else
             f"over q in {list(zip(box_lo, box_hi))}")
    return True, (f"symmetric; leading minors proved positive by interval branch and bound "
                  f"({evaluated} boxes) {where}" + how)

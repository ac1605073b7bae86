"""One Taylor recursion over a tape; its arithmetics are tables of rules.

The normalized Taylor coefficients ``x_[k] = x^(k)(t0) / k!`` of the solutions of an
autonomous ODE ``x' = f(x, p)`` follow from

    x_[0] = x(t0),      x_[k+1] = f_[k] / (k + 1),

where ``f_[k]`` is the k-th Taylor coefficient of ``t -> f(x(t), p)``, obtained slot by
slot of the tape (:class:`verified.series.taylor._Tape`) with the classical recurrences
(Moore 1966; Griewank & Walther, ch. 13). :func:`recursion` is the one loop that runs
them: for every order ``k = 0 .. order - 1`` it visits the slots in tape order,
dispatches on the opcode, skips what is known to be zero, calls the rule of the
opcode, and then integrates the outputs. *How* a coefficient is represented and
enclosed (an interval, an affine form, a Taylor model) is the business of an
**arithmetic table**: a ``typing.NamedTuple`` whose fields hold its data (its coefficient
arrays, its work space) and whose class names its rules. The engine calls each rule
through a stub of this module (``add(ar, s, k, u, v)``, ...); numba resolves the stub at
compile time to the rule the table registered with :func:`register` (``numba.extending.
overload`` on the table's class), so the engine is compiled once per table, with the
rules inlined and no indirect call, and the compiled code can live in
numba's disk cache (no function address is part of the type, unlike a jitted function
handed in as an argument). scipy's ``integrate/_ivp/rk.py`` is the model: a method is
data (a tableau) on one engine.

Contract of a table
-------------------
A table class registers one rule per stub below (:data:`RULES`); every rule has the
stub's signature and returns nothing: it writes coefficient ``k`` of slot ``s`` (and of
its partner slot, where the stub names one) *for every box of the batch* into the
table's arrays, reading only coefficients already written: orders ``0 .. k`` of earlier
slots, orders ``0 .. k - 1`` of ``s`` itself. ``u = a0[s]``, ``v = a1[s]`` are the
operand slots, ``w = aux[s]`` the partner slot, ``i = idx[s]`` an input or parameter
index. The rules and the equation each implements (``c`` a constant series: a slot
built from constants, parameters and frozen points only, ``cst[c]`` on the tape):

=================  ==========  ============================================================
rule               orders      equation
=================  ==========  ============================================================
``const``          0           ``w_0 = [lo, hi]`` (the tape's constant)
``param``          0           ``w_0 = p_i``
``mid``            0           ``w_0 = mid(u_0)`` (a point; unbounded: the whole line)
``state``          all         ``w_k = x_[k], i`` (the state's coefficient, see ``integrate``)
``add``, ``sub``   all         ``w_k = u_k +- v_k``
``neg``            all         ``w_k = -u_k``
``mul_const``      all         ``w_k = u_[ku] v_[kv]``, ``(ku, kv) = (0, k)`` if ``u`` is
                               constant, else ``(k, 0)`` (``v`` is): the other terms of
                               the convolution are exact zeros
``mul``            all         ``w_k = sum_{j=0}^{k} u_j v_{k-j}`` (neither constant)
``sqr``            all         ``w_k = sum_{j=0}^{k} u_j u_{k-j}``
``div_const``      all         ``w_k = u_k / v_0`` (``v`` constant)
``div``            all         ``w_k = (u_k - sum_{j=1}^{k} v_j w_{k-j}) / v_0``
``sqrt0``          0           ``w_0 = sqrt(u_0)``
``sqrt``           k >= 1      ``w_k = (u_k - sum_{j=1}^{k-1} w_j w_{k-j}) / (2 w_0)``
``exp0``, ``exp``  0, >= 1     ``w_0 = exp(u_0)``; ``w_k = (1/k) sum_{j=1}^{k} j u_j w_{k-j}``
``log0``, ``log``  0, >= 1     ``w_0 = log(u_0)``;
                               ``w_k = (u_k - (1/k) sum_{j=1}^{k-1} j w_j u_{k-j}) / u_0``
``sincos0``        0           ``s_0 = sin(u_0)``, ``c_0 = cos(u_0)`` (slots ``ss``, ``cs``)
``sincos``         k >= 1      ``s_k = (1/k) sum_{j=1}^{k} j u_j c_{k-j}``,
                               ``c_k = -(1/k) sum_{j=1}^{k} j u_j s_{k-j}``
``tan0``           0           ``w_0 = tan(u_0)``, partner ``t_0 = 1 + w_0^2``
``tan``            k >= 1      ``w_k = (1/k) sum_{j=1}^{k} j u_j t_{k-j}``,
                               ``t_k = sum_{j=0}^{k} w_j w_{k-j}``
``atan0``          0           ``w_0 = atan(u_0)``, partner ``t_0 = 1 + u_0^2``
``atan``           k >= 1      ``t_k = sum_{j=0}^{k} u_j u_{k-j}``,
                               ``w_k = (u_k - (1/k) sum_{j=1}^{k-1} j w_j t_{k-j}) / t_0``
``slot_done``      all         nothing required: called after the rule of every slot the
                               engine visits (``s`` the slot, not its partner), for a
                               table's step after a slot (the affine table's fresh symbol
                               of a slot's order-0 error, the Taylor-model table's pool);
                               a no-op in the interval table
``integrate``      all         ``x_[k+1], i = f_[k] / (k + 1)`` with ``f_[k]`` slot ``o``
=================  ==========  ============================================================

What the engine guarantees: the slots are visited in tape order, every order ``k``
before ``k + 1``, and the outputs are integrated after all slots of order ``k``; a
``T_AUX`` slot is never visited (its owner's rule writes it); a constant slot is visited
at order 0 only, so its coefficients of order >= 1 are whatever the table initialised
them to, and they must be exact zeros (the engine relies on that in ``mul_const`` and
``div_const``, which the rules read as "the other terms are zero"). ``state`` at order 0
reads ``x_[0]``, which the table holds before the call. The engine does no arithmetic of
its own: outward rounding (or whatever makes a table's numbers enclosures) lives in the
rules, and a table is verified exactly when each of its rules encloses its equation.

A compiled function a rule calls is compiled with the rule's ``forceinline`` and without
reference counting (numba passes a caller's ``forceinline``, ``nrt``, ``fastmath`` and
``error_model`` on to a callee that sets none of its own), unless it sets them: a helper
that should stay a function of its own, compiled as any other caller would compile it,
sets ``forceinline=False, _nrt=True`` (the Taylor-model and affine tables' helpers do; see
docs/lab/recursion_engine.md, where this cost up to 4x the compile time and changed the last
bits of reassociated sums).

numba caches the engine's compiled code per table only as part of a cached caller: a
table's module calls :func:`recursion` from a ``cache=True`` function of its own, and
the engine itself is not cached, because numba checks a cache entry against the source
file of the function only: a cached engine would outlive a change to a rule in the
table's module (with the caller in that module, such a change recompiles the caller and
the engine with it; a change to this file does not, as with any compiled callee in
another file).
"""

from __future__ import annotations

import inspect

import numpy as np
from numba import njit, types
from numba.extending import overload

__all__ = ["RULES", "recursion", "register", "rules_named"]

# Tape opcodes (independent of Op's numbering).
T_CONST, T_INPUT, T_PARAM, T_ADD, T_SUB, T_MUL, T_DIV, T_NEG, T_SQR = range(9)
T_SQRT, T_EXP, T_LOG, T_SIN, T_COS, T_TAN, T_ATAN, T_AUX, T_MID = range(9, 18)

# --------------------------------------------------------------------------
# The rule stubs: their bodies never run; the table's rule is compiled in their place.
# --------------------------------------------------------------------------
_TABLES: dict = {}  # table class -> {rule name: rule (a plain Python function)}
RULES: dict = {}  # rule name -> stub


def _stub(fn):
    """Make ``fn`` a rule stub: in compiled code a call ``fn(ar, ...)`` is a call of the rule
    of that name registered for ``type(ar)``, compiled as a function of its own marked
    ``alwaysinline`` (LLVM inlines it into the engine, which is then one function, as the
    kernel written out by hand was) and without reference counting. Measured on the
    interval table (docs/lab/recursion_engine.md): a plain call per rule took 1.6x the
    hand-written kernel's time for one box; numba's own inliner (``inline="always"``)
    compiles every rule twice; reference counting costs an atomic increment and decrement
    per read of a table's array, 1.4x for one box."""
    name = fn.__name__

    def typer(ar, *args):
        if isinstance(ar, types.BaseNamedTuple):
            return _TABLES.get(ar.instance_class, {}).get(name)
        return None

    # numba reads the typing function's signature (and checks that the rule it returns
    # has the same parameters, by name): the stub's, not (ar, *args)
    typer.__signature__ = inspect.signature(fn)
    overload(fn, jit_options={"forceinline": True, "_nrt": False, "no_cpython_wrapper": True,
                              "no_cfunc_wrapper": True})(typer)
    RULES[name] = fn
    return fn


def register(table, **rules):
    """Register the rules of the NamedTuple class ``table``: one plain Python function per
    name of :data:`RULES`, with the stub's parameters (by name; the table first). They
    are compiled only inside the engine, which runs without reference counting: a rule
    makes no arrays (work space is a field of the table)."""
    missing = set(RULES) - set(rules)
    extra = set(rules) - set(RULES)
    if missing or extra:
        raise ValueError(f"table {table.__name__}: missing rules {sorted(missing)}, unknown {sorted(extra)}")
    for name, rule in rules.items():
        want = list(inspect.signature(RULES[name]).parameters)
        got = list(inspect.signature(rule).parameters)
        if got != want:
            raise ValueError(f"table {table.__name__}: rule {name}{tuple(got)} must take {tuple(want)}")
    _TABLES[table] = dict(rules)


def rules_named(namespace: dict, prefix: str) -> dict:
    """The rules ``{name: namespace[prefix + name]}`` for every name of :data:`RULES` (a
    table's module names its rules ``_iv_add``, ``_ar_add``, ...): ``register(Table,
    **rules_named(globals(), "_iv_"))``. A rule missing from ``namespace`` is an error
    naming it."""
    missing = [prefix + name for name in RULES if prefix + name not in namespace]
    if missing:
        raise ValueError(f"rules not defined: {', '.join(missing)}")
    return {name: namespace[prefix + name] for name in RULES}


@_stub
def const(ar, s, lo, hi):
    pass


@_stub
def param(ar, s, i):
    pass


@_stub
def mid(ar, s, u):
    pass


@_stub
def state(ar, s, k, i):
    pass


@_stub
def add(ar, s, k, u, v):
    pass


@_stub
def sub(ar, s, k, u, v):
    pass


@_stub
def neg(ar, s, k, u):
    pass


@_stub
def mul_const(ar, s, k, u, v, ku, kv):
    pass


@_stub
def mul(ar, s, k, u, v):
    pass


@_stub
def sqr(ar, s, k, u):
    pass


@_stub
def div_const(ar, s, k, u, v):
    pass


@_stub
def div(ar, s, k, u, v):
    pass


@_stub
def sqrt0(ar, s, u):
    pass


@_stub
def sqrt(ar, s, k, u):
    pass


@_stub
def exp0(ar, s, u):
    pass


@_stub
def exp(ar, s, k, u):
    pass


@_stub
def log0(ar, s, u):
    pass


@_stub
def log(ar, s, k, u):
    pass


@_stub
def sincos0(ar, ss, cs, u):
    pass


@_stub
def sincos(ar, ss, cs, k, u):
    pass


@_stub
def tan0(ar, s, vs, u):
    pass


@_stub
def tan(ar, s, vs, k, u):
    pass


@_stub
def atan0(ar, s, vs, u):
    pass


@_stub
def atan(ar, s, vs, k, u):
    pass


@_stub
def slot_done(ar, s, k):
    pass


@_stub
def integrate(ar, i, o, k):
    pass


# --------------------------------------------------------------------------
# The engine
# --------------------------------------------------------------------------
# not cache=True: cached as part of each table's (cached) caller (see the module docstring);
# no reference counting, as in the rules (see _stub); never called from Python
@njit(_nrt=False, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def recursion(op, a0, a1, aux, idx, cst, clo, chi, outputs, order, ar):
    """Run the recurrences of the tape ``(op, a0, a1, aux, idx, cst, clo, chi, outputs)``
    (:class:`verified.series.taylor._Tape`) for orders ``0 .. order - 1`` with the rules
    of the table ``ar``: afterwards the table holds ``x_[0 .. order]`` (the contract is
    in the module docstring)."""
    nslots = op.size
    for k in range(order):
        for s in range(nslots):
            o = op[s]
            if o == T_AUX or (k > 0 and cst[s]):
                continue  # a constant's coefficients >= 1 stay exactly 0
            u = a0[s]
            v = a1[s]
            if o == T_CONST:
                const(ar, s, clo[s], chi[s])
            elif o == T_MID:
                mid(ar, s, u)
            elif o == T_PARAM:
                param(ar, s, idx[s])
            elif o == T_INPUT:
                state(ar, s, k, idx[s])
            elif o == T_ADD:
                add(ar, s, k, u, v)
            elif o == T_SUB:
                sub(ar, s, k, u, v)
            elif o == T_NEG:
                neg(ar, s, k, u)
            elif o == T_MUL:
                if cst[u]:
                    mul_const(ar, s, k, u, v, np.int64(0), k)
                elif cst[v]:
                    mul_const(ar, s, k, u, v, k, np.int64(0))
                else:
                    mul(ar, s, k, u, v)
            elif o == T_SQR:
                sqr(ar, s, k, u)
            elif o == T_DIV:
                if cst[v]:
                    div_const(ar, s, k, u, v)
                else:
                    div(ar, s, k, u, v)
            elif o == T_SQRT:
                if k == 0:
                    sqrt0(ar, s, u)
                else:
                    sqrt(ar, s, k, u)
            elif o == T_EXP:
                if k == 0:
                    exp0(ar, s, u)
                else:
                    exp(ar, s, k, u)
            elif o == T_LOG:
                if k == 0:
                    log0(ar, s, u)
                else:
                    log(ar, s, k, u)
            elif o == T_SIN or o == T_COS:
                ss = s if o == T_SIN else aux[s]
                cs = aux[s] if o == T_SIN else s
                if k == 0:
                    sincos0(ar, ss, cs, u)
                else:
                    sincos(ar, ss, cs, k, u)
            elif o == T_TAN:
                if k == 0:
                    tan0(ar, s, aux[s], u)
                else:
                    tan(ar, s, aux[s], k, u)
            elif o == T_ATAN:
                if k == 0:
                    atan0(ar, s, aux[s], u)
                else:
                    atan(ar, s, aux[s], k, u)
            slot_done(ar, s, k)
        # x_[k+1] = f_[k] / (k + 1)
        for i in range(outputs.size):
            integrate(ar, i, outputs[i], k)

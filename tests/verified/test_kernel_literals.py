"""Compiled kernels hand no integer or boolean literal to another compiled function.

numba compiles a jitted callee once per distinct literal argument (``f(x, 7)`` from compiled
code types the 7 as ``Literal[int](7)``): the unary expansions' eight kinds, passed as
literals, were compiled eight or nine times over with everything they call, which more than
doubled a first run's compile time (docs/lab/code_notes.md, "compile time: integer
literals"). Constants are passed as ``np.int64(k)``. Checked on the source, so that the
check costs nothing and needs no cold cache. The rules of the recursion's tables
(:mod:`verified.series.recursion`) are plain functions compiled into the engine: they are
checked as compiled callers, and the engine's calls of the rule stubs as calls of
compiled callees.
"""

import ast
import inspect

from verified.arith import _kernels, linalg
from verified.series import affine_taylor, recursion, taylor, taylor_model
from verified.steppers import tm_flow

MODULES = [_kernels, recursion, taylor, taylor_model, affine_taylor, tm_flow, linalg]


def _jitted(tree):
    out = {}
    for node in tree.body:
        if isinstance(node, ast.FunctionDef) and any("njit" in ast.unparse(d) for d in node.decorator_list):
            out[node.name] = node
    return out


def _rules(tree, module):
    """The functions of ``module`` registered as rules of a table (compiled in the engine)."""
    names = {f.__name__ for rules in recursion._TABLES.values() for f in rules.values()
             if f.__module__ == module}
    return {node.name: node for node in tree.body if isinstance(node, ast.FunctionDef) and node.name in names}


def _literal(arg):
    if isinstance(arg, ast.UnaryOp) and isinstance(arg.op, ast.USub):
        arg = arg.operand
    return isinstance(arg, ast.Constant) and isinstance(arg.value, (bool, int))


def literal_calls(modules=MODULES):
    """(module, caller, callee, argument) for every literal int or bool handed from one
    jitted function to another (``_k.f`` resolves to :mod:`verified.arith._kernels`)."""
    trees = {m.__name__: ast.parse(inspect.getsource(m)) for m in modules}
    jitted = {name: set(_jitted(t)) for name, t in trees.items()}
    jitted["verified.series.recursion"] = jitted.get("verified.series.recursion", set()) | set(recursion.RULES)
    found = []
    for mod, tree in trees.items():
        for fname, fn in {**_jitted(tree), **_rules(tree, mod)}.items():
            for call in ast.walk(fn):
                if not isinstance(call, ast.Call):
                    continue
                f = call.func
                if isinstance(f, ast.Name) and f.id in jitted[mod]:
                    callee = f.id
                elif (isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name) and f.value.id == "_k"
                      and f.attr in jitted["verified.arith._kernels"]):
                    callee = "_k." + f.attr
                else:
                    continue
                found += [(mod, fname, callee, ast.unparse(a)) for a in call.args if _literal(a)]
    return found


#: callees that keep their literal argument, and why: ``_abs_sum``'s reassociated sum
#: vectorizes better from a literal start (two small compilations; with ``np.int64`` the
#: whole Taylor-model kernel ran 1.5x slower: docs/lab/robot_speed.md)
LITERAL_OK = {"_abs_sum"}


def test_no_literal_reaches_a_compiled_callee():
    assert [c for c in literal_calls() if c[2] not in LITERAL_OK] == []


def test_the_check_sees_a_literal(monkeypatch):
    """The check bites: a kernel source that passes ``7`` to a jitted helper is reported."""
    src = ("from numba import njit\n@njit(cache=True)\ndef g(x, kind):\n    return x\n"
           "@njit(cache=True)\ndef f(x):\n    return g(x, 7) + g(x, True)\n")

    class Fake:
        pass

    Fake.__name__ = "fake"
    real = inspect.getsource
    monkeypatch.setattr(inspect, "getsource", lambda m: src if m is Fake else real(m))
    assert literal_calls([Fake]) == [("fake", "f", "g", "7"), ("fake", "f", "g", "True")]


def test_the_check_reads_the_rules_and_the_engine():
    """The interval table's rules are read as compiled callers, and the engine's calls of
    the rule stubs as calls of compiled callees."""
    tree = ast.parse(inspect.getsource(taylor))
    assert {"_iv_mul", "_iv_sincos", "_iv_integrate"} <= set(_rules(tree, "verified.series.taylor"))
    assert {"add", "mul_const", "integrate"} <= set(recursion.RULES)

"""Issue 15: no import cycles. The graph modules import in one direction,
opcodes -> evaluate -> ir -> tracer, sympy_convert -> verified.graph (the public front), and
no module of mbs/, models/ or verified/ takes part in a cycle of module-level imports; the
solver imports the chunked execution and the one-batch driver in one direction, also with
the imports inside functions, driver.solution -> driver.batch -> execution -> solver.
Issue 44: verified's rooms (arith, graph, series, sets, steppers, driver, consistency,
execution, then the modules at the top) import only the rooms below them."""
import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("mbs", "models", "verified")


def _modules():
    mods = {}
    for pkg in PACKAGES:
        for p in (ROOT / pkg).rglob("*.py"):
            parts = p.relative_to(ROOT).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            mods[name] = p
    return mods


def _targets(mods, cur, node):
    pkg = cur if mods[cur].name == "__init__.py" else cur.rsplit(".", 1)[0]
    names = []
    if isinstance(node, ast.Import):
        names = [a.name for a in node.names]
    else:
        base = node.module or ""
        if node.level:
            parts = pkg.split(".")[: len(pkg.split(".")) - (node.level - 1)]
            base = ".".join(parts + ([base] if base else []))
        names = [f"{base}.{a.name}" if f"{base}.{a.name}" in mods else base for a in node.names]
    for n in names:
        while n and n not in mods:
            n = n.rsplit(".", 1)[0] if "." in n else ""
        if n and n != cur:
            yield n


def _module_level_imports(mods, name, in_functions=False):
    """Imports executed when the module is imported: not inside functions (with
    ``in_functions``: those too, run when the function is), not under
    ``if TYPE_CHECKING``."""
    out = set()

    def walk(node):
        for ch in ast.iter_child_nodes(node):
            if not in_functions and isinstance(ch, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                continue
            if isinstance(ch, ast.If) and "TYPE_CHECKING" in ast.unparse(ch.test):
                continue
            if isinstance(ch, (ast.Import, ast.ImportFrom)):
                out.update(_targets(mods, name, ch))
            walk(ch)

    walk(ast.parse(mods[name].read_text()))
    return out


def test_no_cycles_of_module_level_imports():
    mods = _modules()
    edges = {m: _module_level_imports(mods, m) for m in mods}
    state, cycles = {}, []

    def visit(m, path):
        state[m] = 1
        for t in sorted(edges[m]):
            if state.get(t) == 1:
                cycles.append(path[path.index(t):] + [t])
            elif t not in state:
                visit(t, path + [t])
        state[m] = 2

    for m in sorted(mods):
        if m not in state:
            visit(m, [m])
    assert cycles == []


def test_graph_modules_import_downward():
    mods = _modules()
    order = ["verified.graph.opcodes", "verified.graph.evaluate", "verified.graph.ir", "verified.graph.tracer", "verified.graph.sympy_convert",
             "verified.graph"]
    for i, m in enumerate(order):
        assert not (_module_level_imports(mods, m) & set(order[i + 1:])), m


def test_solver_parallel_and_the_driver_import_one_way_also_inside_functions():
    """``verified.solver.solve`` dispatches to ``verified.execution``, which runs its chunks
    with ``verified.driver.batch`` (the one-batch driver); ``Solution`` and ``Start`` are in
    ``verified.driver.solution``. No import of a lower one reaches a higher one, not even one
    inside a function (run when it is called), directly or through other modules."""
    mods = _modules()
    edges = {m: _module_level_imports(mods, m, in_functions=True) for m in mods}
    execution = sorted(m for m in mods if m.startswith("verified.execution"))
    order = [["verified.driver.solution"], ["verified.driver.batch"], execution, ["verified.solver"]]
    for i, group in enumerate(order):
        higher = {m for g in order[i + 1:] for m in g}
        for m in group:
            assert not (edges[m] & higher), m
            seen, todo = set(), list(edges[m])
            while todo:
                t = todo.pop()
                if t not in seen:
                    seen.add(t)
                    todo.extend(edges[t])
            forbidden = higher if len(group) > 1 else higher | {m}  # (execution's modules import each other)
            assert not (seen & forbidden), (m, sorted(seen & forbidden))


#: verified's rooms, bottom first; the modules at the top (solver, methods, auto, spec, warmup) may import any
ROOMS = ["arith", "graph", "series", "sets", "steppers", "driver", "consistency", "execution"]
#: the one import that runs up (inside a function): chaining runs in time carries their consistency records
UPWARD = {("verified.driver.time_chain", "verified.consistency.reduction_area")}


def _room(name):
    parts = name.split(".")
    if parts[0] != "verified" or len(parts) == 1:
        return None
    return ROOMS.index(parts[1]) if parts[1] in ROOMS else len(ROOMS)


def test_rooms_import_only_rooms_below_also_inside_functions():
    """A room imports its own modules and the rooms below it, never one above (also not inside
    a function), and nothing of mbs or models; docs/architecture.md draws the same picture."""
    mods = _modules()
    up, out = [], []
    for m in sorted(mods):
        if _room(m) is None:
            continue
        for t in sorted(_module_level_imports(mods, m, in_functions=True)):
            if not t.startswith("verified"):
                out.append((m, t))
            elif _room(t) is not None and _room(t) > _room(m) and (m, t) not in UPWARD:
                up.append((m, t))
    assert out == [] and up == []

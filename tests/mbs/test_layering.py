"""Issue 15 item 2: the modeling core (mbs/*.py) never imports the application layer
(mbs.app); only mbs/__main__.py, the ``python -m mbs`` shim, reaches into it."""
import ast
from pathlib import Path

MBS = Path(__file__).resolve().parents[2] / "mbs"


def _imports(path):
    tree = ast.parse(path.read_text(), filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            yield from (a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            mod = node.module or ""
            if node.level:  # relative to the mbs package
                yield "mbs." + mod if mod else "mbs"
                if not mod:
                    yield from ("mbs." + a.name for a in node.names)
            else:
                yield mod
                yield from (f"{mod}.{a.name}" for a in node.names)


def test_core_does_not_import_the_app_layer():
    bad = {p.name: sorted({m for m in _imports(p) if m == "mbs.app" or m.startswith("mbs.app.")})
           for p in sorted(MBS.glob("*.py")) if p.name != "__main__.py"}
    assert {k: v for k, v in bad.items() if v} == {}


def test_only_robots_reaches_into_models():
    """The core names no model: mbs.simulate asks mbs.robots (system_entry, load_model),
    the one seam to the registry of ready models (models.registry), for a name."""
    users = sorted(p.name for p in MBS.glob("*.py")
                   if any(m == "models" or m.startswith("models.") for m in _imports(p)))
    assert users == ["robots.py"]

"""Issue 15 item 2: the modeling core (mbs/*.py) never imports the application layer
(mbs.app); only mbs/__main__.py, the ``python -m mbs`` shim, reaches into it. Nor does
it import the ready models (models/): it finds them through the entry-point group
``mbs.models`` (pyproject.toml), which points at models.registry."""
import ast
import importlib.metadata as md
from pathlib import Path

import pytest

import mbs.robots
from mbs import ModelError

MBS = Path(__file__).resolve().parents[2] / "mbs"


def _core():
    """The modeling core's files: mbs/*.py and its subpackages (mbs/simulate/), not mbs/app."""
    return sorted(p for p in MBS.rglob("*.py") if p.relative_to(MBS).parts[0] != "app")


def _imports(path):
    tree = ast.parse(path.read_text(), filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            yield from (a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            mod = node.module or ""
            if node.level:  # relative to the file's package (mbs, or mbs.simulate for its files)
                here = ["mbs", *path.relative_to(MBS).parent.parts]
                base = ".".join(here[:len(here) - node.level + 1])
                yield f"{base}.{mod}" if mod else base
                if not mod:
                    yield from (f"{base}.{a.name}" for a in node.names)
            else:
                yield mod
                yield from (f"{mod}.{a.name}" for a in node.names)


def test_core_does_not_import_the_app_layer():
    bad = {str(p.relative_to(MBS)): sorted({m for m in _imports(p) if m == "mbs.app" or m.startswith("mbs.app.")})
           for p in _core() if p.name != "__main__.py"}
    assert {k: v for k, v in bad.items() if v} == {}


def test_core_does_not_import_models():
    """The core names no model: mbs.simulate asks mbs.robots (system_entry, load_model),
    which finds the registry of ready models (models.registry) through the entry points
    of group mbs.robots.MODELS_GROUP, not by importing it (nor by importlib by name)."""
    users = sorted(p.name for p in _core() if any(m == "models" or m.startswith("models.") for m in _imports(p)))
    assert users == []
    assert not [p.name for p in _core() if "import_module" in p.read_text() or "__import__" in p.read_text()]


def test_the_registry_is_an_installed_entry_point():
    """pyproject.toml's [project.entry-points."mbs.models"] is in the installed metadata
    (after editing it: pip install -e . --no-deps) and loads models.registry."""
    import models.registry
    eps = md.entry_points(group=mbs.robots.MODELS_GROUP)
    assert [(ep.name, ep.value) for ep in eps] == [("registry", "models.registry")]
    assert mbs.robots.registries() == (models.registry,)
    assert mbs.robots.load_model("ur5").n == 6 and mbs.robots.model_names()[:1] == ["pendulum"]


@pytest.fixture
def no_registry(monkeypatch):
    """As if the package were not installed: no entry point of the group (importlib's
    own entry_points stays as it is: numba and others read it)."""
    monkeypatch.setattr(mbs.robots, "_entry_points", lambda: ())
    mbs.robots.registries.cache_clear()
    yield
    mbs.robots.registries.cache_clear()


def test_without_the_entry_point_a_one_line_error_names_the_fix(no_registry, capsys):
    from mbs.app import cli
    with pytest.raises(ModelError, match=r"^unknown model 'ur5': no ready models: no entry point of group "
                                         r"'mbs.models' is installed \(install the package: pip install -e \. "):
        mbs.robots.load_model("ur5")
    with pytest.raises(ModelError, match="pip install -e"):
        mbs.robots.registries()
    assert cli.main(["check", "ur5"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "pip install -e ." in err and "Traceback" not in err
    # what needs no registry still works: a URDF path, example-robot-data names, Chains
    assert mbs.robots.system_entry("ur5") is None and mbs.robots.system_entry(None) is None
    assert mbs.robots.load_model("example-robot-data:ur5").n == 6
    assert mbs.robots.load_model(str(mbs.robots.urdf_path("ur5"))).n == 6


def test_a_registry_that_does_not_import_is_a_one_line_error(monkeypatch):
    ep = md.EntryPoint("registry", "no_such_module_xyz.registry", mbs.robots.MODELS_GROUP)
    monkeypatch.setattr(mbs.robots, "_entry_points", lambda: (ep,))
    mbs.robots.registries.cache_clear()
    try:
        with pytest.raises(ModelError, match=r"the model registry 'no_such_module_xyz.registry' .* does not "
                                             r"import: No module named 'no_such_module_xyz' \(reinstall"):
            mbs.robots.load_model("ur5")
    finally:
        mbs.robots.registries.cache_clear()

"""mbs.app.sampling, the one home of the DOP853 sampling oracle (issue 15): the app
layer, the tests and the benchmarks use it; it stays independent of what it checks."""
import ast
import subprocess
import sys
from pathlib import Path

import numpy as np

from mbs.app import bench, demo, runner, sampling

SAMPLING = Path(sampling.__file__)


def test_imports_nothing_from_the_solver_or_the_modeling_core():
    tree = ast.parse(SAMPLING.read_text())
    mods = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    mods |= {("." * n.level) + (n.module or "") for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    assert mods <= {"__future__", "itertools", "time", "numpy", "scipy.integrate", "pinocchio"}, mods


def test_loads_and_samples_without_verified_or_mbs():
    """The file alone (not as mbs.app.sampling, which would run mbs/__init__) samples
    and integrates without importing verified or mbs."""
    code = (f"import importlib.util, sys\n"
            f"spec = importlib.util.spec_from_file_location('lone_sampling', {str(SAMPLING)!r})\n"
            f"m = importlib.util.module_from_spec(spec); spec.loader.exec_module(m)\n"
            f"import numpy as np\n"
            f"e = m.Ensemble(lambda x: np.array([x[1], -x[0]]), m.sample_initial_points([0, 0], [1, 1], 3), 1.0)\n"
            f"assert e.final.shape == (8, 2)\n"
            f"bad = [k for k in sys.modules if k.split('.')[0] in ('verified', 'mbs', 'models')]\n"
            f"assert not bad, bad\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd="/")
    assert r.returncode == 0, r.stderr


def test_one_implementation():
    """The tests' oracles.sampling, the runner, the demo and the bench use these very
    functions (no copies)."""
    import oracles.sampling as tests_oracle
    for name in sampling.__all__:
        assert getattr(tests_oracle, name) is getattr(sampling, name)
    assert runner.sample_points is sampling.sample_points
    assert runner.sample_trajectories is demo.sample_trajectories is bench.sample_trajectories \
        is sampling.sample_trajectories
    assert bench.sample_initial_points is sampling.sample_initial_points


def test_point_sets():
    lo, hi = np.array([0.0, 1.0, 2.0]), np.array([1.0, 1.0, 4.0])  # component 2 is a point
    pts = sampling.sample_initial_points(lo, hi, 3, seed=1)
    assert pts.shape == (4 + 3 + 1, 3) and (pts[:, 1] == 1.0).all()
    assert pts[:4].tolist() == [[0, 1, 2], [0, 1, 4], [1, 1, 2], [1, 1, 4]] and pts[-1].tolist() == [0.5, 1, 3]
    # corner_limit: no corners past it, the same random points and centre
    assert np.array_equal(sampling.sample_initial_points(lo, hi, 3, seed=1, corner_limit=1), pts[4:])
    assert np.array_equal(sampling.sample_initial_points(lo, hi, 3, seed=1, corner_limit=2), pts)
    # the CLI's points: exactly count, centre first, then corners
    sp = sampling.sample_points(lo, hi, 6)
    assert sp.shape == (6, 3) and sp[0].tolist() == [0.5, 1, 3] and len({tuple(p) for p in sp[1:5]}) == 4
    assert sampling.sample_points(lo, hi, 0).shape == (0, 3)
    line = sampling.line_points(lo, hi, 5, 0)
    assert line[:, 0].tolist() == [0, 0.25, 0.5, 0.75, 1] and (line[:, 1:] == [1, 3]).all()


def test_sample_trajectories_nan_after_a_failure_and_agree_with_the_ensemble():
    blow = sampling.sample_trajectories(lambda x: x ** 2, np.array([[1.0], [0.5]]), np.array([0, 0.5, 1.5]))
    assert np.isfinite(blow[:, :2]).all() and np.isnan(blow[:, 2]).all()   # x' = x^2 from 1 ends at t = 1
    f = lambda x: np.array([x[1], -np.sin(x[0])])  # noqa: E731
    pts = sampling.sample_initial_points([0.1, 0.0], [0.2, 0.1], 2)
    t = np.array([0.0, 0.5, 1.0])
    a = sampling.sample_trajectories(f, pts, t)
    b = sampling.Ensemble(f, pts, 1.0).states(t).transpose(1, 0, 2)
    assert np.allclose(a, b, rtol=0, atol=1e-10)


def test_the_only_dop853_call():
    """No other module of the library, the tests or the benchmarks integrates with scipy
    on its own (one home: dop853 here)."""
    root = SAMPLING.parents[2]
    call = "solve_ivp" + "("  # (not spelled out: this file would match)
    users = sorted(str(p.relative_to(root)) for d in ("mbs", "models", "tests", "benchmarks")
                   for p in (root / d).rglob("*.py") if call in p.read_text())
    assert users == ["mbs/app/sampling.py"]


def test_the_plant_applies_the_joints_damping():
    """``plant_acceleration`` is Pinocchio's aba with the URDF's viscous damping ``-D
    qd`` (aba itself leaves ``model.damping`` out): on the Panda (D = 0.003 per joint)
    it agrees with the library's model under a torque, and aba alone does not (the
    oracle of a PD-held Panda missed its model by 5 % of an enclosure for this)."""
    import pinocchio as pin
    from models.robots import panda_arm
    chain = panda_arm()
    plant = sampling.pinocchio_with(chain)
    assert np.all(np.asarray(plant.damping) > 0)
    numeric = chain.numeric()
    rng = np.random.default_rng(3)
    q = np.array([0, -np.pi / 4, 0, -3 * np.pi / 4, 0, np.pi / 2, np.pi / 4]) + rng.uniform(-0.1, 0.1, 7)
    qd = rng.uniform(-0.5, 0.5, 7)
    tau = rng.uniform(-2, 2, 7)
    ours = np.array([float(v) for v in numeric.acceleration(list(q), list(qd), list(tau))])
    oracle = sampling.plant_acceleration(plant)(q, qd, tau)
    assert np.allclose(oracle, ours, rtol=1e-9, atol=1e-9), np.abs(oracle - ours).max()
    bare = pin.aba(plant, plant.createData(), q, qd, tau)
    assert np.abs(bare - ours).max() > 1e-4
